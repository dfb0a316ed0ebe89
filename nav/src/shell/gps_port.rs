//! The GPS serial port, read in nav's own event loop: a source that opens the device named in
//! the config and yields what it reads, in the loop's order among the CAN frames (nav's
//! pipeline decodes the bytes, [`crate::pipeline::Pipeline::on_gps_bytes`]). When the device
//! fails or vanishes (a pty closing, a USB receiver unplugged) the error is counted and the
//! port opened again every [`RETRY`] until it is back.
//!
//! Reading in the loop (no reader thread) keeps the receiver's bytes in order with the frames:
//! whatever the loop reads from the port is taken after every frame it has read before, and
//! before every frame it reads after. On the bench that is what makes a run's result depend on
//! its data alone (docs/pace.md).
//!
//! With `source = "gpsd"` the bytes come from gpsd instead: nav connects to it over TCP, asks
//! for the receiver's NMEA (`?WATCH={"enable":true,"nmea":true}`) and decodes the sentences
//! exactly as from a port; gpsd's own JSON replies (VERSION, DEVICES, WATCH, ERROR) are taken
//! out of the stream and counted. A connection that closes (gpsd restarting) is made again.

use crate::config::{GpsConfig, GpsSource};
use std::os::fd::AsRawFd;
use std::time::Duration;

/// How often a missing or failed port is tried again.
pub const RETRY: Duration = Duration::from_millis(20);

/// What the receiver's port gave.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GpsEvent {
    /// The port opened (at start, or back after it went away).
    Opened,
    /// The port failed or went away (why).
    Closed(String),
    /// Bytes as read (gpsd's JSON replies taken out), and the wall time (ns since the epoch)
    /// just before the read that got them: every CAN frame received before then came before
    /// them.
    Bytes {
        /// The bytes.
        bytes: Vec<u8>,
        /// Wall time before the read, ns.
        t_ns: u64,
    },
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

    async fn open(&self) -> Result<Conn, String> {
        match self {
            Source::Serial { path, baud } => {
                let port = serialport::new(path, *baud)
                    .timeout(Duration::from_millis(100))
                    .open_native()
                    .map_err(|e| e.to_string())?;
                let fd = port.as_raw_fd();
                // SAFETY: fcntl(2) on the port's own descriptor.
                let r = unsafe {
                    let fl = libc::fcntl(fd, libc::F_GETFL);
                    libc::fcntl(fd, libc::F_SETFL, fl | libc::O_NONBLOCK)
                };
                if r != 0 {
                    return Err(std::io::Error::last_os_error().to_string());
                }
                // SAFETY: the port owns its open descriptor, which stays open and the same until
                // the AsyncFd (its owner now) is dropped.
                let fd = unsafe {
                    tokio::io::unix::AsyncFd::register_with_interest(
                        port,
                        tokio::io::Interest::READABLE,
                    )
                }
                .map_err(|e| e.to_string())?;
                Ok(Conn::Serial(fd))
            }
            Source::Gpsd { addr, device } => {
                let connect = tokio::net::TcpStream::connect(addr.as_str());
                let mut s = tokio::time::timeout(Duration::from_secs(1), connect)
                    .await
                    .map_err(|_| format!("{addr}: no answer within 1 s"))?
                    .map_err(|e| format!("{addr}: {e}"))?;
                let _ = s.set_nodelay(true);
                let watch = match device {
                    Some(d) => serde_json::json!({"enable": true, "nmea": true, "device": d}),
                    None => serde_json::json!({"enable": true, "nmea": true}),
                };
                use tokio::io::AsyncWriteExt;
                s.write_all(format!("?WATCH={watch}\n").as_bytes())
                    .await
                    .map_err(|e| format!("{addr}: {e}"))?;
                Ok(Conn::Gpsd(s, GpsdLines::default()))
            }
        }
    }
}

/// An open source.
enum Conn {
    Serial(tokio::io::unix::AsyncFd<serialport::TTYPort>),
    Gpsd(tokio::net::TcpStream, GpsdLines),
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

/// The receiver's port as nav's loop reads it.
pub struct GpsPort {
    source: Source,
    name: String,
    conn: Option<Conn>,
    retry_at: Option<tokio::time::Instant>,
    warned: bool,
    buf: Vec<u8>,
    gpsd_messages: u64,
    port_errors: u64,
    opens: u64,
}

impl GpsPort {
    /// The port of `cfg`, not opened yet ([`GpsPort::next`] opens it).
    pub fn new(cfg: &GpsConfig) -> Self {
        let source = Source::of(cfg);
        Self {
            name: source.name(),
            source,
            conn: None,
            retry_at: None,
            warned: false,
            buf: vec![0; 4096],
            gpsd_messages: 0,
            port_errors: 0,
            opens: 0,
        }
    }

    /// The next thing from the port: it opening, bytes, or it going away. Waits as long as it
    /// takes; safe to drop while waiting (nothing read is lost), as `tokio::select!` does.
    pub async fn next(&mut self) -> GpsEvent {
        loop {
            let Some(conn) = self.conn.as_mut() else {
                if let Some(at) = self.retry_at {
                    tokio::time::sleep_until(at).await;
                }
                match self.source.open().await {
                    Ok(c) => {
                        self.conn = Some(c);
                        self.opens += 1;
                        self.retry_at = None;
                        self.warned = false;
                        tracing::info!(source = %self.name, "GPS source open");
                        return GpsEvent::Opened;
                    }
                    Err(e) => {
                        if !self.warned {
                            tracing::warn!(source = %self.name, "cannot open the GPS source: {e}; retrying every {} ms", RETRY.as_millis());
                            self.warned = true;
                        }
                        self.port_errors += 1;
                        self.retry_at = Some(tokio::time::Instant::now() + RETRY);
                        continue;
                    }
                }
            };
            let t_ns;
            let r = match conn {
                Conn::Serial(fd) => {
                    let mut guard = match fd.readable().await {
                        Ok(g) => g,
                        Err(e) => return self.closed(e.to_string()),
                    };
                    let buf = &mut self.buf;
                    t_ns = crate::record::writer::wall_ns();
                    match guard.try_io(|inner| {
                        // SAFETY: read(2) into our buffer, at most its length.
                        let n = unsafe {
                            libc::read(
                                inner.get_ref().as_raw_fd(),
                                buf.as_mut_ptr().cast(),
                                buf.len(),
                            )
                        };
                        if n < 0 {
                            Err(std::io::Error::last_os_error())
                        } else {
                            Ok(n as usize)
                        }
                    }) {
                        Ok(r) => r,
                        Err(_would_block) => continue,
                    }
                }
                Conn::Gpsd(s, _) => {
                    if let Err(e) = s.readable().await {
                        return self.closed(e.to_string());
                    }
                    t_ns = crate::record::writer::wall_ns();
                    s.try_read(&mut self.buf)
                }
            };
            match r {
                // a closed connection (gpsd restarting), a hung-up port
                Ok(0) => return self.closed("end of stream".into()),
                Ok(n) => {
                    let bytes = match self.conn.as_mut() {
                        Some(Conn::Gpsd(_, lines)) => {
                            let mut nmea = Vec::new();
                            lines.push(&self.buf[..n], &mut nmea);
                            self.gpsd_messages = lines.json;
                            nmea
                        }
                        _ => self.buf[..n].to_vec(),
                    };
                    if !bytes.is_empty() {
                        return GpsEvent::Bytes { bytes, t_ns };
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::Interrupted
                    ) => {}
                Err(e) => return self.closed(e.to_string()),
            }
        }
    }

    /// The port failed: counted, closed, tried again after [`RETRY`].
    fn closed(&mut self, why: String) -> GpsEvent {
        tracing::warn!(source = %self.name, "GPS source: {why}; re-opening");
        self.port_errors += 1;
        self.conn = None;
        self.retry_at = Some(tokio::time::Instant::now() + RETRY);
        GpsEvent::Closed(why)
    }

    /// Bytes the port has now, without waiting (at the end: what the device still holds).
    pub fn try_read(&mut self) -> Option<Vec<u8>> {
        let n = match self.conn.as_mut()? {
            Conn::Serial(fd) => {
                // SAFETY: read(2) into our buffer; the descriptor is non-blocking.
                let n = unsafe {
                    libc::read(
                        fd.get_ref().as_raw_fd(),
                        self.buf.as_mut_ptr().cast(),
                        self.buf.len(),
                    )
                };
                usize::try_from(n).ok()?
            }
            Conn::Gpsd(s, _) => s.try_read(&mut self.buf).ok()?,
        };
        if n == 0 {
            return None;
        }
        match self.conn.as_mut() {
            Some(Conn::Gpsd(_, lines)) => {
                let mut nmea = Vec::new();
                lines.push(&self.buf[..n], &mut nmea);
                self.gpsd_messages = lines.json;
                Some(nmea)
            }
            _ => Some(self.buf[..n].to_vec()),
        }
    }

    /// The source's name (the device path, or gpsd's address).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// gpsd's JSON replies taken out of the stream so far (`source = "gpsd"`).
    pub fn gpsd_messages(&self) -> u64 {
        self.gpsd_messages
    }

    /// Port errors (failed opens, reads, the device going away) and opens so far.
    pub fn counters(&self) -> (u64, u64) {
        (self.port_errors, self.opens)
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
