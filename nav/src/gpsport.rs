//! The GPS serial port: a reader thread that opens the device named in the config, frames and
//! decodes what arrives, exports every fix as a JSON line, and hands fixes to the navigation
//! loop. When the device fails or vanishes (a pty closing, a USB receiver unplugged) the error is
//! counted and the port re-opened every half second until it is back.

use crate::config::GpsConfig;
use crate::gps::{GpsDecoder, GpsFix, GpsStats};
use std::io::{BufWriter, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use thiserror::Error;

/// Port set-up trouble.
#[derive(Debug, Error)]
pub enum GpsPortError {
    /// The export file could not be created.
    #[error("cannot create the GPS fix export {path}")]
    Export {
        /// File.
        path: std::path::PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
}

#[derive(Default)]
struct Shared {
    stats: GpsStats,
    port_errors: u64,
    opens: u64,
    tx: Option<tokio::sync::mpsc::UnboundedSender<GpsFix>>,
}

/// The running reader.
pub struct GpsPort {
    stop: Arc<AtomicBool>,
    shared: Arc<Mutex<Shared>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// Run the calling thread at a real-time priority when the system allows it (root, or
/// CAP_SYS_NICE): a fix must reach the navigator within `fix_delay_s` of IMU time, and a reader
/// that waits behind busy threads for its turn makes it late. Without the right it stays as it is.
fn realtime_priority() {
    let p = libc::sched_param { sched_priority: 10 };
    // SAFETY: sets the scheduling policy of the calling thread with a valid parameter.
    let r = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &p) };
    if r != 0 {
        tracing::debug!("GPS reader stays at normal priority (pthread_setschedparam: {r})");
    }
}

fn lock(s: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    s.lock().unwrap_or_else(|e| e.into_inner())
}

impl GpsPort {
    /// Start reading the port of `cfg`.
    pub fn start(cfg: &GpsConfig) -> Result<Self, GpsPortError> {
        let mut export = match &cfg.fixes_jsonl {
            Some(p) => Some(BufWriter::new(std::fs::File::create(p).map_err(
                |source| GpsPortError::Export {
                    path: p.clone(),
                    source,
                },
            )?)),
            None => None,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let shared = Arc::new(Mutex::new(Shared::default()));
        let (path, baud) = (cfg.port.to_string_lossy().into_owned(), cfg.baud);
        let thread = {
            let (stop, shared) = (stop.clone(), shared.clone());
            std::thread::Builder::new()
                .name("gps".into())
                .spawn(move || {
                    realtime_priority();
                    let mut dec = GpsDecoder::default();
                    let mut buf = [0u8; 1024];
                    let mut fixes = Vec::new();
                    let mut warned = false;
                    while !stop.load(Ordering::Relaxed) {
                        let mut port = match serialport::new(&path, baud)
                            .timeout(Duration::from_millis(100))
                            .open()
                        {
                            Ok(p) => p,
                            Err(e) => {
                                if !warned {
                                    tracing::warn!(port = %path, "cannot open the GPS port: {e}; retrying");
                                    warned = true;
                                }
                                lock(&shared).port_errors += 1;
                                std::thread::sleep(Duration::from_millis(500));
                                continue;
                            }
                        };
                        warned = false;
                        lock(&shared).opens += 1;
                        tracing::info!(port = %path, "GPS port open");
                        while !stop.load(Ordering::Relaxed) {
                            match port.read(&mut buf) {
                                Ok(0) => {
                                    lock(&shared).port_errors += 1;
                                    break;
                                }
                                Ok(n) => {
                                    dec.push_bytes(&buf[..n], &mut fixes);
                                    let mut sh = lock(&shared);
                                    sh.stats = dec.stats();
                                    for f in fixes.drain(..) {
                                        if let Some(w) = export.as_mut()
                                            && let Ok(j) = serde_json::to_string(&f)
                                        {
                                            let _ = writeln!(w, "{j}");
                                        }
                                        if let Some(tx) = &sh.tx {
                                            let _ = tx.send(f);
                                        }
                                    }
                                }
                                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                                Err(e) => {
                                    tracing::warn!(port = %path, "GPS port: {e}; re-opening");
                                    lock(&shared).port_errors += 1;
                                    std::thread::sleep(Duration::from_millis(500));
                                    break;
                                }
                            }
                        }
                    }
                    if let Some(mut w) = export {
                        let _ = w.flush();
                    }
                })
                .ok()
        };
        Ok(Self {
            stop,
            shared,
            thread,
        })
    }

    /// Send decoded fixes to `tx` from now on.
    pub fn forward(&self, tx: tokio::sync::mpsc::UnboundedSender<GpsFix>) {
        lock(&self.shared).tx = Some(tx);
    }

    /// Stop the reader (after a last read) and return (counters, port errors, opens).
    pub fn finish(mut self) -> (GpsStats, u64, u64) {
        // let the reader take what is still in the device
        std::thread::sleep(Duration::from_millis(200));
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let sh = lock(&self.shared);
        (sh.stats, sh.port_errors, sh.opens)
    }
}
