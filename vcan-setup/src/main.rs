//! `vcan-setup`: give a command a real Linux vcan interface, natively or in a QEMU guest.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::time::Duration;
use vcan_setup::{Backend, CanSupport, VmOptions};

#[derive(Parser)]
#[command(
    version,
    about,
    long_about = "Gives a run a real Linux vcan interface: natively where the kernel has CAN, \
otherwise inside a QEMU guest running the stock Debian kernel, with the host folders the run needs \
mounted at the same paths. Exits with the command's own exit status."
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Report whether this kernel has CAN and whether the QEMU guest can be used.
    Check,
    /// Install what the guest needs (Debian packages; needs root).
    Install,
    /// Create a vcan interface on this kernel and bring it up (needs CAP_NET_ADMIN).
    Up {
        /// Interface name.
        #[arg(default_value = "vcan0")]
        name: String,
    },
    /// Run a command where vcan is available (natively, or in the guest), and exit with its status.
    Run {
        /// Host folder to mount in the guest at the same path (repeatable); default: the current folder.
        #[arg(long = "share")]
        shares: Vec<PathBuf>,
        /// Host folder to mount in the guest at the same path read-only, its files cached in
        /// the guest (repeatable): what does not change while the command runs, such as an
        /// interpreter and its packages. Natively: nothing to do.
        #[arg(long = "share-ro")]
        shares_ro: Vec<PathBuf>,
        /// Always use the QEMU guest, even where the host kernel has CAN.
        #[arg(long)]
        vm: bool,
        /// Guest memory in MiB.
        #[arg(long, default_value_t = 2048)]
        memory_mb: u32,
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 2400)]
        timeout_s: u64,
        /// Install missing guest prerequisites first (needs root).
        #[arg(long)]
        install: bool,
        /// Make a TCP port of the guest reachable from the host (repeatable):
        /// `HOST_ADDR:PORT` forwards that host address to the same port in the guest,
        /// `HOST_ADDR:PORT=GUEST_PORT` to another. Natively: nothing to forward.
        #[arg(long = "forward", value_parser = parse_forward)]
        forward: Vec<(std::net::SocketAddr, u16)>,
        /// A program or shared object whose shared libraries the guest needs besides the
        /// command's own (repeatable); a folder: every `*.so` in it (an interpreter's extension
        /// modules, which it loads at run time). Natively: nothing to do.
        #[arg(long = "libs-for")]
        libs_for: Vec<PathBuf>,
        /// The command and its arguments.
        #[arg(trailing_var_arg = true, required = true)]
        command: Vec<String>,
    },
}

/// The files of `--libs-for`: each file as given, each folder's `*.so` files.
fn expand_libs_for(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            for e in std::fs::read_dir(p).with_context(|| format!("--libs-for {}", p.display()))? {
                let f = e?.path();
                if f.extension().is_some_and(|x| x == "so") || f.to_string_lossy().contains(".so.")
                {
                    out.push(f);
                }
            }
        } else if p.is_file() {
            out.push(p.clone());
        } else {
            anyhow::bail!("--libs-for {}: no such file or folder", p.display());
        }
    }
    Ok(out)
}

/// `ADDR:PORT` or `ADDR:PORT=GUEST_PORT`.
fn parse_forward(s: &str) -> Result<(std::net::SocketAddr, u16), String> {
    let (host, guest) = match s.split_once('=') {
        Some((h, g)) => (h, Some(g)),
        None => (s, None),
    };
    let host: std::net::SocketAddr = host
        .parse()
        .map_err(|e| format!("{host:?} is not ADDR:PORT ({e})"))?;
    let guest = match guest {
        Some(g) => g
            .parse()
            .map_err(|e| format!("{g:?} is not a port ({e})"))?,
        None => host.port(),
    };
    Ok((host, guest))
}

fn main() -> std::process::ExitCode {
    match real_main() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("vcan-setup: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn real_main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_ansi(
            std::io::IsTerminal::is_terminal(&std::io::stderr())
                && std::env::var_os("NO_COLOR").is_none(),
        )
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .init();
    match Cli::parse().cmd {
        Cmd::Check => {
            match vcan_setup::can_support() {
                CanSupport::Available => println!("kernel CAN: available (vcan runs natively)"),
                CanSupport::Missing(e) => {
                    println!("kernel CAN: missing ({e}); runs go through the QEMU guest")
                }
            }
            match vcan_setup::prereqs() {
                Ok(p) => println!(
                    "QEMU guest: ready (qemu {}, kernel {}, busybox {})",
                    p.qemu.display(),
                    p.kernel_version,
                    p.busybox.display()
                ),
                Err(e) => println!("QEMU guest: not ready: {e}"),
            }
        }
        Cmd::Install => {
            let p = vcan_setup::install_prereqs()?;
            println!("QEMU guest: ready (kernel {})", p.kernel_version);
        }
        Cmd::Up { name } => {
            vcan_setup::ensure_vcan(&name).with_context(|| format!("setting up {name}"))?;
            println!("{name}: up");
        }
        Cmd::Run {
            shares,
            shares_ro,
            vm,
            memory_mb,
            timeout_s,
            install,
            forward,
            libs_for,
            command,
        } => {
            let native = !vm && matches!(vcan_setup::can_support(), CanSupport::Available);
            if !native && install {
                vcan_setup::install_prereqs()?;
            }
            let shares = if shares.is_empty() {
                vec![std::env::current_dir()?]
            } else {
                shares
            };
            let opts = VmOptions {
                shares,
                shares_ro,
                memory_mb,
                timeout: Duration::from_secs(timeout_s),
                forward_tcp: forward,
                libs_for: expand_libs_for(&libs_for)?,
                ..VmOptions::default()
            };
            let out = if native {
                vcan_setup::run(&command, &opts)?
            } else {
                vcan_setup::run_in_vm(&command, &opts)?
            };
            if out.backend == Backend::Vm {
                eprintln!(
                    "vcan-setup: guest boot {:.1} s, total {:.1} s, exit status {}",
                    out.boot_secs, out.total_secs, out.status
                );
            }
            if out.status != 0 {
                std::process::exit(out.status.clamp(1, 255));
            }
        }
    }
    Ok(())
}
