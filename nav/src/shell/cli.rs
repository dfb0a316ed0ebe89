//! Start-up shared by the bench's binaries: logging to stderr, errors printed once with their causes.

/// Log to stderr with `tracing`, level from `RUST_LOG` (default `info`), colour only on a terminal.
pub fn init_tracing() {
    init_tracing_with("info");
}

/// The same with `default` as the filter when `RUST_LOG` is not set (e.g. `info,nav=warn` in a
/// program that runs many pipelines in process and would otherwise log every one's progress).
pub fn init_tracing_with(default: &str) {
    init_tracing_on(default, std::io::stderr);
}

/// The same, writing through `writer` (a program that keeps a status line on the terminal
/// clears it before each log line); colour only when stderr is a terminal.
pub fn init_tracing_on<W>(default: &str, writer: W)
where
    W: for<'a> tracing_subscriber::fmt::MakeWriter<'a> + Send + Sync + 'static,
{
    tracing_subscriber::fmt()
        .with_ansi(
            std::io::IsTerminal::is_terminal(&std::io::stderr())
                && std::env::var_os("NO_COLOR").is_none(),
        )
        .with_writer(writer)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| default.into()),
        )
        .init();
}

/// Print `program: error: <message and causes>` and give the exit code, or `ok` on success.
pub fn exit_code<T>(program: &str, r: anyhow::Result<T>, ok: impl FnOnce(T) -> i32) -> i32 {
    match r {
        Ok(v) => ok(v),
        Err(e) => {
            eprintln!("{program}: error: {e:#}");
            1
        }
    }
}
