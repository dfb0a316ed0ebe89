//! The receiver's transports: its serial port as a pty pair, stepped by the bus scheduler
//! ([`GpsDevice`]) or replaying a recorded receiver log ([`replay`]).

use super::{GpsReceiver, GpsRun};
use serialport::{SerialPort, TTYPort};
use std::io::Write;
use std::os::fd::AsRawFd;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use thiserror::Error;

/// pty trouble.
#[derive(Debug, Error)]
pub enum PtyError {
    /// The pty pair could not be created.
    #[error("cannot create a pty pair")]
    Create(#[source] serialport::Error),
    /// A write failed.
    #[error("writing to the GPS pty {path}")]
    Write {
        /// The slave path.
        path: String,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// The device link could not be made.
    #[error("pointing the GPS device link {link} at {target}")]
    Link {
        /// The link.
        link: String,
        /// Where it should point.
        target: String,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// The device could not be given to its reader's account.
    #[error("giving the GPS pty {path} to uid {uid}")]
    Owner {
        /// The slave path.
        path: String,
        /// The reader's user id.
        uid: u32,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
}

/// The emulated receiver's serial port: a pty pair. nav opens [`GpsPty::path`].
pub struct GpsPty {
    master: TTYPort,
    /// Kept open so the master stays usable while no reader is attached.
    _slave: TTYPort,
    path: String,
}

impl GpsPty {
    /// Create the pty pair.
    pub fn open() -> Result<Self, PtyError> {
        let (master, slave) = TTYPort::pair().map_err(PtyError::Create)?;
        // serialport opens the pair without O_CLOEXEC: a process started later (nav) would
        // inherit the master and keep the device alive after the receiver has gone
        for fd in [master.as_raw_fd(), slave.as_raw_fd()] {
            // SAFETY: fcntl(2) on descriptors owned by the ports above.
            if unsafe { libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC) } != 0 {
                return Err(PtyError::Create(serialport::Error::from(
                    std::io::Error::last_os_error(),
                )));
            }
        }
        let path = slave.name().unwrap_or_default();
        Ok(Self {
            master,
            _slave: slave,
            path,
        })
    }

    /// The device path nav opens (`/dev/pts/N`).
    pub fn path(&self) -> &str {
        &self.path
    }

    /// Give the device to the account that reads it (as udev gives a vehicle's serial port to
    /// the navigation service's group): needs root.
    pub fn give_to(&self, uid: u32, gid: u32) -> Result<(), PtyError> {
        std::os::unix::fs::chown(&self.path, Some(uid), Some(gid)).map_err(|source| {
            PtyError::Owner {
                path: self.path.clone(),
                uid,
                source,
            }
        })
    }

    /// Write bytes as the receiver would.
    pub fn write(&mut self, bytes: &[u8]) -> Result<(), PtyError> {
        self.master
            .write_all(bytes)
            .and_then(|_| self.master.flush())
            .map_err(|source| PtyError::Write {
                path: self.path.clone(),
                source,
            })
    }

    /// Discard what no reader has taken yet.
    pub fn clear(&self) {
        let _ = self.master.clear(serialport::ClearBuffer::All);
    }
}

/// One line of a recorded log, with its sentence time of day (when it has one).
#[derive(Debug, Clone, PartialEq)]
pub struct LogLine {
    /// The bytes, line ending included, exactly as recorded.
    pub bytes: Vec<u8>,
    /// Time of day of the sentence, s.
    pub time_of_day: Option<f64>,
}

/// Split a gpsd `.log` into lines (comment lines dropped, bytes untouched).
pub fn parse_log(text: &[u8]) -> Vec<LogLine> {
    text.split_inclusive(|b| *b == b'\n')
        .filter(|l| l.first() != Some(&b'#'))
        .map(|l| LogLine {
            bytes: l.to_vec(),
            time_of_day: sentence_time(l),
        })
        .collect()
}

/// The time field of GGA, RMC, GLL, GNS, ZDA sentences, s of day.
fn sentence_time(l: &[u8]) -> Option<f64> {
    let s = std::str::from_utf8(l).ok()?;
    let f: Vec<&str> = s.trim_end().split(',').collect();
    let kind = f.first()?.get(3..6)?;
    let field = match kind {
        "GGA" | "RMC" | "GNS" | "ZDA" => f.get(1)?,
        "GLL" => f.get(5)?,
        _ => return None,
    };
    let h: f64 = field.get(0..2)?.parse().ok()?;
    let m: f64 = field.get(2..4)?.parse().ok()?;
    let sec: f64 = field.get(4..)?.parse().ok()?;
    Some(h * 3600.0 + m * 60.0 + sec)
}

/// Replay `lines` onto the pty, paced by the sentences' own times at `speed` (a jump forward is
/// capped at 2 s, a jump back costs nothing). Stops early when `stop` is set.
pub fn replay(
    pty: &mut GpsPty,
    lines: &[LogLine],
    speed: f64,
    stop: &AtomicBool,
) -> Result<u64, PtyError> {
    let mut last: Option<f64> = None;
    let mut written = 0u64;
    for l in lines {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        if let Some(t) = l.time_of_day {
            if let Some(p) = last {
                let dt = (t - p).clamp(0.0, 2.0);
                if dt > 0.0 {
                    std::thread::sleep(Duration::from_secs_f64(dt / speed.max(1e-6)));
                }
            }
            last = Some(t);
        }
        pty.write(&l.bytes)?;
        written += l.bytes.len() as u64;
    }
    Ok(written)
}

/// What the GPS adapter did on its pty.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize, PartialEq, Eq)]
pub struct GpsTxStats {
    /// Fix epochs written with a valid fix.
    pub fixes: u64,
    /// Epochs written without a fix (before the first fix, void outages).
    pub void_epochs: u64,
    /// Epochs with no sentences at all (silent outages).
    pub silent_epochs: u64,
    /// Bytes written.
    pub bytes: u64,
    /// Times the port went away and came back (port-drop faults).
    pub port_drops: u64,
    /// Epochs lost because nobody read the port (its buffer was full).
    pub unread_epochs: u64,
}

/// A [`GpsReceiver`] on its pty, as the bus scheduler steps it.
pub struct GpsDevice {
    rx: GpsReceiver,
    pty: GpsPty,
    link: Option<std::path::PathBuf>,
    owner: Option<(u32, u32)>,
    dropped: Option<usize>,
    /// What was written.
    pub stats: GpsTxStats,
}

impl GpsDevice {
    /// The receiver `run` on `pty`, reached by nav through `link` when given.
    pub fn new(run: GpsRun, pty: GpsPty, link: Option<std::path::PathBuf>) -> Self {
        Self {
            rx: GpsReceiver::new(run),
            pty,
            link,
            owner: None,
            dropped: None,
            stats: GpsTxStats::default(),
        }
    }

    /// A device re-plugged (a port-drop fault) is given to this account, like the first.
    pub fn with_owner(mut self, owner: Option<(u32, u32)>) -> Self {
        self.owner = owner;
        self
    }

    /// Simulated time at which the next epoch is written, s.
    pub fn next_write_time(&self) -> f64 {
        self.rx.next_write_time()
    }

    /// The IMU stream has reached `t` (and ends at `duration_s`): write every epoch due by then.
    pub fn poll(&mut self, t: f64, duration_s: f64) -> Result<(), PtyError> {
        while let Some(e) = self.rx.poll(t, duration_s) {
            let st = &mut self.stats;
            // the device disappears and comes back
            match (self.dropped, e.port_drop) {
                (None, Some(i)) => {
                    self.pty = GpsPty::open()?; // the old pair closes: the reader sees EIO
                    if let Some((uid, gid)) = self.owner {
                        self.pty.give_to(uid, gid)?;
                    }
                    if let Some(l) = &self.link {
                        let _ = std::fs::remove_file(l);
                    }
                    self.dropped = Some(i);
                    st.port_drops += 1;
                }
                (Some(_), None) => {
                    if let Some(l) = &self.link {
                        relink(l, self.pty.path())?;
                    }
                    self.dropped = None;
                }
                _ => {}
            }
            if self.dropped.is_some() {
                continue;
            }
            match (e.text.is_empty(), e.valid) {
                (true, _) => st.silent_epochs += 1,
                (false, true) => st.fixes += 1,
                (false, false) => st.void_epochs += 1,
            }
            if !e.text.is_empty() {
                match self.pty.write(e.text.as_bytes()) {
                    Ok(()) => st.bytes += e.text.len() as u64,
                    // nobody reads (nav not started or re-opening): the receiver's output is lost
                    Err(PtyError::Write { source, .. })
                        if source.kind() == std::io::ErrorKind::TimedOut =>
                    {
                        st.unread_epochs += 1;
                        self.pty.clear();
                    }
                    Err(e) => return Err(e),
                }
            }
        }
        Ok(())
    }

    /// The pty (kept open until nav has stopped: a receiver vanishing at the very end would only
    /// add port errors to nav's summary).
    pub fn into_pty(self) -> GpsPty {
        self.pty
    }
}

/// Point the symbolic link `link` at `target` (replacing what was there).
pub fn relink(link: &std::path::Path, target: &str) -> Result<(), PtyError> {
    let _ = std::fs::remove_file(link);
    std::os::unix::fs::symlink(target, link).map_err(|source| PtyError::Link {
        link: link.display().to_string(),
        target: target.into(),
        source,
    })
}

// The writer's tests go through nav's NMEA decoder, so they live in tests/tests/nmea_writer.rs
// (emulators do not depend on nav).

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    #[test]
    fn log_lines_keep_their_bytes_and_times() {
        let log = b"# comment\n$GPGGA,193221.00,2037.72792,N,08704.08478,W,1,04,1.7,-30.40,M,-13.9,M,,*7D\r\n$GPGSA,A,3*00\n";
        let l = parse_log(log);
        assert_eq!(l.len(), 2);
        assert!(l[0].bytes.ends_with(b"\r\n"));
        assert!((l[0].time_of_day.unwrap() - (19.0 * 3600.0 + 32.0 * 60.0 + 21.0)).abs() < 1e-9);
        assert_eq!(l[1].time_of_day, None);
    }

    #[test]
    fn a_reader_of_the_pty_path_gets_the_bytes() {
        let mut pty = GpsPty::open().unwrap();
        let mut reader = serialport::new(pty.path(), 9600)
            .timeout(Duration::from_millis(500))
            .open()
            .unwrap();
        pty.write(b"$GPGSA,A,3*00\r\n").unwrap();
        let mut buf = [0u8; 64];
        let n = reader.read(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"$GPGSA,A,3*00\r\n");
    }

    #[test]
    fn closing_the_pty_hangs_up_its_reader() {
        let pty = GpsPty::open().unwrap();
        let mut reader = serialport::new(pty.path(), 9600)
            .timeout(Duration::from_millis(200))
            .open()
            .unwrap();
        // a process started while the pty is open must not inherit it (nav on the bench)
        let mut child = std::process::Command::new("sleep")
            .arg("2")
            .spawn()
            .unwrap();
        drop(pty);
        let mut buf = [0u8; 64];
        let r = reader.read(&mut buf);
        let _ = child.kill();
        let _ = child.wait();
        assert!(
            !matches!(&r, Err(e) if e.kind() == std::io::ErrorKind::TimedOut),
            "{r:?}"
        );
    }
}
