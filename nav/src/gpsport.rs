//! The GPS serial port: a reader thread that opens the device named in the config, frames and
//! decodes what arrives, exports every fix as a JSON line, and hands fixes to the navigation
//! loop. When the device fails or vanishes (a pty closing, a USB receiver unplugged) the error is
//! counted and the port re-opened every half second until it is back.
//!
//! With `source = "gpsd"` the bytes come from gpsd instead: nav connects to it over TCP, asks
//! for the receiver's NMEA (`?WATCH={"enable":true,"nmea":true}`) and decodes the sentences
//! exactly as from a port; gpsd's own JSON replies (VERSION, DEVICES, WATCH, ERROR) are taken
//! out of the stream and counted. A connection that closes (gpsd restarting) is made again.

use crate::config::{GpsConfig, GpsSource};
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
    gpsd_messages: u64,
    port_errors: u64,
    opens: u64,
    tx: Option<tokio::sync::mpsc::UnboundedSender<GpsInput>>,
    /// Hand the bytes read on too (nav records them: `/gps/raw`).
    with_bytes: bool,
}

/// What the reader hands the navigation loop, in the order it read it.
#[derive(Debug, Clone)]
pub enum GpsInput {
    /// Bytes as read from the source (gpsd's JSON replies taken out), before decoding: what a
    /// replay puts back on a port. Only when asked for ([`GpsPort::forward`]).
    Bytes {
        /// Read wall time, ns since the epoch.
        t_ns: u64,
        /// The bytes.
        bytes: Vec<u8>,
    },
    /// A decoded fix (after the bytes it came in).
    Fix(GpsFix),
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

/// Where the bytes come from.
enum Source {
    Serial {
        path: String,
        baud: u32,
    },
    Gpsd {
        addr: String,
        device: Option<String>,
    },
}

impl Source {
    fn of(cfg: &GpsConfig) -> Self {
        match cfg.source {
            GpsSource::Serial => Source::Serial {
                path: cfg.port.to_string_lossy().into_owned(),
                baud: cfg.baud,
            },
            GpsSource::Gpsd => Source::Gpsd {
                addr: cfg.gpsd.clone(),
                device: cfg.gpsd_device.clone(),
            },
        }
    }

    fn name(&self) -> String {
        match self {
            Source::Serial { path, .. } => path.clone(),
            Source::Gpsd { addr, device } => {
                format!(
                    "gpsd {addr}{}",
                    device.as_deref().map_or(String::new(), |d| format!(" {d}"))
                )
            }
        }
    }

    fn open(&self) -> Result<Box<dyn Read + Send>, String> {
        match self {
            Source::Serial { path, baud } => serialport::new(path, *baud)
                .timeout(Duration::from_millis(100))
                .open()
                .map(|p| Box::new(p) as Box<dyn Read + Send>)
                .map_err(|e| e.to_string()),
            Source::Gpsd { addr, device } => {
                use std::net::ToSocketAddrs;
                let to = addr
                    .to_socket_addrs()
                    .map_err(|e| format!("{addr}: {e}"))?
                    .next()
                    .ok_or_else(|| format!("{addr}: no address"))?;
                let mut s = std::net::TcpStream::connect_timeout(&to, Duration::from_secs(1))
                    .map_err(|e| format!("{addr}: {e}"))?;
                s.set_read_timeout(Some(Duration::from_millis(100)))
                    .map_err(|e| format!("{addr}: {e}"))?;
                let _ = s.set_nodelay(true);
                let watch = match device {
                    Some(d) => serde_json::json!({"enable": true, "nmea": true, "device": d}),
                    None => serde_json::json!({"enable": true, "nmea": true}),
                };
                s.write_all(format!("?WATCH={watch}\n").as_bytes())
                    .map_err(|e| format!("{addr}: {e}"))?;
                Ok(Box::new(s))
            }
        }
    }
}

/// gpsd's stream split into its JSON replies (taken out, counted, errors logged) and the NMEA
/// it passes on. A line is held until its end; one longer than [`GPSD_LINE_MAX`] is dropped
/// (and counted by the NMEA decoder as what it was not).
#[derive(Default)]
struct GpsdLines {
    line: Vec<u8>,
    too_long: bool,
    json: u64,
    dropped: u64,
}

/// Longest line kept from gpsd, bytes (its DEVICES reply with many receivers fits).
const GPSD_LINE_MAX: usize = 16 * 1024;

impl GpsdLines {
    fn push(&mut self, bytes: &[u8], nmea: &mut Vec<u8>) {
        for &b in bytes {
            if self.line.len() < GPSD_LINE_MAX {
                self.line.push(b);
            } else {
                self.too_long = true;
            }
            if b != b'\n' {
                continue;
            }
            if std::mem::take(&mut self.too_long) {
                self.dropped += 1;
                tracing::warn!("gpsd: a line over {GPSD_LINE_MAX} bytes dropped");
            } else if self.line.first() == Some(&b'{') {
                self.json += 1;
                let text = String::from_utf8_lossy(&self.line);
                if text.contains("\"class\":\"ERROR\"") {
                    tracing::warn!("gpsd: {}", text.trim());
                } else {
                    tracing::debug!("gpsd: {}", text.trim());
                }
            } else {
                nmea.extend_from_slice(&self.line);
            }
            self.line.clear();
        }
    }
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
        let source = Source::of(cfg);
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
                    let name = source.name();
                    while !stop.load(Ordering::Relaxed) {
                        let mut port = match source.open() {
                            Ok(p) => p,
                            Err(e) => {
                                if !warned {
                                    tracing::warn!(source = %name, "cannot open the GPS source: {e}; retrying");
                                    warned = true;
                                }
                                lock(&shared).port_errors += 1;
                                std::thread::sleep(Duration::from_millis(500));
                                continue;
                            }
                        };
                        warned = false;
                        lock(&shared).opens += 1;
                        tracing::info!(source = %name, "GPS source open");
                        let mut lines = GpsdLines::default();
                        let mut nmea = Vec::new();
                        while !stop.load(Ordering::Relaxed) {
                            match port.read(&mut buf) {
                                Ok(0) => {
                                    lock(&shared).port_errors += 1;
                                    // a closed connection (gpsd restarting) is tried again
                                    std::thread::sleep(Duration::from_millis(100));
                                    break;
                                }
                                Ok(n) => {
                                    let bytes = match source {
                                        Source::Serial { .. } => &buf[..n],
                                        Source::Gpsd { .. } => {
                                            nmea.clear();
                                            lines.push(&buf[..n], &mut nmea);
                                            &nmea[..]
                                        }
                                    };
                                    let t_ns = crate::record::wall_ns();
                                    dec.push_bytes(bytes, &mut fixes);
                                    let mut sh = lock(&shared);
                                    sh.stats = dec.stats();
                                    sh.gpsd_messages = lines.json;
                                    if sh.with_bytes
                                        && !bytes.is_empty()
                                        && let Some(tx) = &sh.tx
                                    {
                                        let _ = tx.send(GpsInput::Bytes {
                                            t_ns,
                                            bytes: bytes.to_vec(),
                                        });
                                    }
                                    for f in fixes.drain(..) {
                                        if let Some(w) = export.as_mut()
                                            && let Ok(j) = serde_json::to_string(&f)
                                        {
                                            let _ = writeln!(w, "{j}");
                                        }
                                        if let Some(tx) = &sh.tx {
                                            let _ = tx.send(GpsInput::Fix(f));
                                        }
                                    }
                                }
                                Err(e)
                                    if matches!(
                                        e.kind(),
                                        std::io::ErrorKind::TimedOut
                                            | std::io::ErrorKind::WouldBlock
                                    ) => {}
                                Err(e) => {
                                    tracing::warn!(source = %name, "GPS source: {e}; re-opening");
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

    /// Send decoded fixes to `tx` from now on, and the bytes they came in too when
    /// `with_bytes` (each chunk read before the fixes decoded from it).
    pub fn forward(&self, tx: tokio::sync::mpsc::UnboundedSender<GpsInput>, with_bytes: bool) {
        let mut sh = lock(&self.shared);
        sh.tx = Some(tx);
        sh.with_bytes = with_bytes;
    }

    /// gpsd's JSON replies taken out of the stream so far (`source = "gpsd"`).
    pub fn gpsd_messages(&self) -> u64 {
        lock(&self.shared).gpsd_messages
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

#[cfg(test)]
mod tests {
    use super::*;

    /// gpsd's JSON replies come out of the stream wherever the reads split it; the NMEA goes
    /// on byte for byte; an endless line is dropped, not kept.
    #[test]
    fn gpsd_json_is_taken_out_and_nmea_passes_on_however_the_reads_split() {
        let stream = concat!(
            "{\"class\":\"VERSION\",\"release\":\"3.22\"}\r\n",
            "$GPGGA,120001.00,3354.0000,S,01825.2000,E,1,09,0.9,20.0,M,32.0,M,,*4B\r\n",
            "{\"class\":\"WATCH\",\"enable\":true,\"nmea\":true}\r\n",
            "$GPRMC,120001.00,A,3354.0000,S,01825.2000,E,15.5,045.0,211126,,,A*7E\r\n",
        );
        let nmea_only: String = stream
            .lines()
            .filter(|l| l.starts_with('$'))
            .map(|l| format!("{l}\r\n"))
            .collect();
        for cut in [1, 7, 50, 1000] {
            let mut l = GpsdLines::default();
            let mut out = Vec::new();
            for part in stream.as_bytes().chunks(cut) {
                l.push(part, &mut out);
            }
            assert_eq!(String::from_utf8(out).unwrap(), nmea_only, "reads of {cut}");
            assert_eq!(l.json, 2);
        }
        let mut l = GpsdLines::default();
        let mut out = Vec::new();
        l.push(&vec![b'x'; 3 * GPSD_LINE_MAX], &mut out);
        assert!(l.line.len() <= GPSD_LINE_MAX);
        l.push(b"\n$GPGGA\n", &mut out);
        assert_eq!((l.dropped, &out[..]), (1, &b"$GPGGA\n"[..]));
    }
}
