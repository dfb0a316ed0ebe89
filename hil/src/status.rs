//! Progress for people and for logs. On a terminal, progress is one status line that redraws
//! itself (with a bar where the total is known), and log lines clear it before they print; in a
//! file, a pipe or a CI log every progress report is a plain line of its own, with no control
//! codes (nor colour: `nav::shell::cli`).

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// A status line is on the terminal now (the next write clears it first).
static SHOWN: AtomicBool = AtomicBool::new(false);
/// One writer at a time on stderr.
static LOCK: Mutex<()> = Mutex::new(());

/// stderr is a terminal (and progress may redraw in place).
pub fn interactive() -> bool {
    std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none()
        || std::env::var_os("HIL_PROGRESS").is_some_and(|v| v == "tty")
}

fn clear(err: &mut impl Write) {
    if SHOWN.swap(false, Ordering::Relaxed) {
        let _ = write!(err, "\r\x1b[2K");
    }
}

/// Report progress `text`: redrawn in place on a terminal, a line of its own elsewhere.
pub fn show(text: &str) {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let mut err = std::io::stderr().lock();
    if interactive() {
        clear(&mut err);
        let _ = write!(err, "{text}");
        SHOWN.store(true, Ordering::Relaxed);
    } else {
        let _ = writeln!(err, "{text}");
    }
    let _ = err.flush();
}

/// Progress is over: the status line goes (what follows starts on a clean line).
pub fn finish() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    clear(&mut std::io::stderr().lock());
}

/// A line that stays (a result, a stage's end): the status line goes first.
pub fn line(text: &str) {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let mut err = std::io::stderr().lock();
    clear(&mut err);
    let _ = writeln!(err, "{text}");
}

/// `done` of `total` as a bar of `width` cells.
pub fn bar(done: usize, total: usize, width: usize) -> String {
    let filled = (done.min(total) * width)
        .checked_div(total)
        .unwrap_or(width);
    format!("[{}{}]", "#".repeat(filled), ".".repeat(width - filled))
}

/// A bar of `width` cells filled to `fraction` (0 to 1).
pub fn bar_of(fraction: f64, width: usize) -> String {
    let f = if fraction.is_finite() {
        fraction.clamp(0.0, 1.0)
    } else {
        0.0
    };
    bar((f * 1000.0).round() as usize, 1000, width)
}

/// Progress of `done` of `total` items after `elapsed_s`: a bar and the time left on a
/// terminal; the count alone in a log.
pub fn count(done: usize, total: usize, elapsed_s: f64, what: &str) {
    if interactive() {
        let left = if done > 0 {
            format!(
                ", about {:.0} s left",
                elapsed_s / done as f64 * (total - done.min(total)) as f64
            )
        } else {
            String::new()
        };
        show(&format!(
            "{} {done}/{total} ({elapsed_s:.0} s{left}) {what}",
            bar(done, total, 30)
        ));
    } else {
        show(&format!(
            "hil: {done}/{total} done ({elapsed_s:.0} s): {what}"
        ));
    }
}

/// The writer of log lines: clears a status line before each one.
#[derive(Clone, Copy, Default)]
pub struct LogWriter;

/// One log line's hold on stderr.
pub struct LogLine(std::io::Stderr);

impl Write for LogLine {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
        clear(&mut self.0);
        self.0.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
}

impl<'a> tracing_subscriber::fmt::MakeWriter<'a> for LogWriter {
    type Writer = LogLine;

    fn make_writer(&'a self) -> Self::Writer {
        LogLine(std::io::stderr())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bar_fills_with_the_count() {
        assert_eq!(bar(0, 4, 8), "[........]");
        assert_eq!(bar(1, 4, 8), "[##......]");
        assert_eq!(bar(4, 4, 8), "[########]");
        assert_eq!(bar(9, 4, 8), "[########]");
        assert_eq!(bar(0, 0, 4), "[####]");
    }
}
