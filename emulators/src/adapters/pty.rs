//! The receiver's transports: its serial port as a pty pair, stepped by the bus scheduler
//! ([`GpsDevice`]) or replaying a recorded receiver log ([`replay`]).

use crate::gps::Epoch;
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
    /// The log of what was sent could not be written.
    #[error("writing the GPS log {path}")]
    Log {
        /// The log file.
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
///
/// The bench keeps only the master: whether anybody has the device open is then the master's
/// hang-up state ([`GpsPty::reader_attached`]), and what the reader has not taken yet is read
/// through a descriptor of the device opened for the question ([`GpsPty::unread`]).
pub struct GpsPty {
    master: TTYPort,
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
        // no reader until one opens the device (written bytes wait in the device meanwhile)
        drop(slave);
        Ok(Self { master, path })
    }

    /// Somebody (nav, gpsd) has the device open.
    pub fn reader_attached(&self) -> bool {
        let mut p = libc::pollfd {
            fd: self.master.as_raw_fd(),
            events: libc::POLLOUT,
            revents: 0,
        };
        // SAFETY: one valid pollfd for the duration of the call.
        let r = unsafe { libc::poll(&mut p, 1, 0) };
        r >= 0 && p.revents & libc::POLLHUP == 0
    }

    /// Wait until somebody has the device open, at most `timeout` or until `stop` is set;
    /// whether they do.
    pub fn wait_reader_until(&self, timeout: Duration, stop: &AtomicBool) -> bool {
        let start = std::time::Instant::now();
        loop {
            if self.reader_attached() {
                return true;
            }
            if start.elapsed() >= timeout || stop.load(Ordering::Relaxed) {
                return false;
            }
            std::thread::sleep(Duration::from_micros(500));
        }
    }

    /// A descriptor of the device, for asking what is waiting in it (none when it cannot be
    /// opened).
    fn probe(&self) -> Option<std::fs::File> {
        use std::os::unix::fs::OpenOptionsExt;
        std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NOCTTY | libc::O_NONBLOCK)
            .open(&self.path)
            .ok()
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

    /// Bytes written that the reader has not taken yet (none when the pty cannot say).
    pub fn unread(&self) -> Option<usize> {
        unread_in(&self.probe()?)
    }

    /// Wait until the reader has taken everything written, at most `timeout`; whether it did.
    /// A receiver's fix must reach nav before the IMU stream runs on past the time nav applies
    /// it: the bus scheduler and the player hold the stream here, as lockstep holds it for the
    /// frames. The answer comes from the kernel, not from a guess about time (`unread_in`).
    pub fn wait_taken(&self, timeout: Duration) -> bool {
        self.wait_taken_until(timeout, &AtomicBool::new(false))
    }

    /// [`GpsPty::wait_taken`], ending early when `stop` is set.
    pub fn wait_taken_until(&self, timeout: Duration, stop: &AtomicBool) -> bool {
        let start = std::time::Instant::now();
        let Some(probe) = self.probe() else {
            return true;
        };
        loop {
            match unread_in(&probe) {
                None | Some(0) => return true,
                Some(_) => {}
            }
            if start.elapsed() >= timeout || stop.load(Ordering::Relaxed) {
                return false;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }

    /// Discard what no reader has taken yet.
    pub fn clear(&self) {
        let _ = self.master.clear(serialport::ClearBuffer::All);
    }
}

/// What is waiting to be read on the device `f` is open on, bytes still on their way to the
/// reader's side included.
///
/// A pty hands what is written to the reader's side in a kernel work item
/// (`flush_to_ldisc`), so the unread count alone reads 0 both before the bytes arrive and after
/// they are taken. The line discipline's poll, when it finds nothing to read, first waits for
/// that work item to finish (`tty_buffer_flush_work` in `n_tty_poll`): after a poll the count
/// is exact, however late the kernel runs its work.
fn unread_in(f: &std::fs::File) -> Option<usize> {
    let mut pfd = libc::pollfd {
        fd: f.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: poll(2) on one descriptor we hold open, not waiting.
    if unsafe { libc::poll(&mut pfd, 1, 0) } < 0 {
        return None;
    }
    let mut n: libc::c_int = 0;
    // SAFETY: FIONREAD on a descriptor we hold open writes one int.
    let r = unsafe { libc::ioctl(f.as_raw_fd(), libc::FIONREAD, &mut n) };
    (r == 0).then_some(n.max(0) as usize)
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
    /// Epochs the reader had not taken within the wait's limit ([`TAKE_WAIT`] without
    /// lockstep, the stall limit in it) of writing (the stream then went on: a fix may have
    /// reached nav late).
    pub slow_reads: u64,
}

/// How long the stream waits for a reader to open the device or take a receiver's output when
/// nothing follows nav (no lockstep: nav is not ours, or has stopped confirming). In lockstep
/// the scheduler waits as long as it waits for nav's NAV_TIME (its stall limit).
pub const TAKE_WAIT: Duration = Duration::from_millis(50);

/// The receiver's epochs on its pty, as the bus scheduler delivers them.
pub struct GpsDevice {
    pty: GpsPty,
    confirm_on_bus: bool,
    link: Option<std::path::PathBuf>,
    owner: Option<(u32, u32)>,
    dropped: Option<usize>,
    log: Option<(String, std::io::BufWriter<std::fs::File>)>,
    /// What was written.
    pub stats: GpsTxStats,
}

impl GpsDevice {
    /// The receiver's device `pty`, reached by nav through `link` when given.
    pub fn new(pty: GpsPty, link: Option<std::path::PathBuf>) -> Self {
        Self {
            pty,
            confirm_on_bus: true,
            link,
            owner: None,
            dropped: None,
            log: None,
            stats: GpsTxStats::default(),
        }
    }

    /// Keep what the device sends in `path`, in gpsd's `.log` form (the sentences as written,
    /// with a `#` comment line before each epoch giving its simulated time, and one for each
    /// epoch that went nowhere): what the receiver said, for judging a run later and for
    /// replaying it onto a pty ([`parse_log`], [`replay`]).
    pub fn with_log(mut self, path: &std::path::Path) -> Result<Self, PtyError> {
        let name = path.display().to_string();
        let f = std::fs::File::create(path).map_err(|source| PtyError::Log {
            path: name.clone(),
            source,
        })?;
        let mut w = std::io::BufWriter::new(f);
        writeln!(
            w,
            "# GPS emulator output (rlg-hil): sentences as sent to the pty"
        )
        .map_err(|source| PtyError::Log {
            path: name.clone(),
            source,
        })?;
        self.log = Some((name, w));
        Ok(self)
    }

    fn note(&mut self, text: &str) -> Result<(), PtyError> {
        if let Some((path, w)) = self.log.as_mut() {
            w.write_all(text.as_bytes())
                .map_err(|source| PtyError::Log {
                    path: path.clone(),
                    source,
                })?;
        }
        Ok(())
    }

    /// Write out what the log holds (at the end of a run).
    pub fn flush_log(&mut self) -> Result<(), PtyError> {
        if let Some((path, w)) = self.log.as_mut() {
            w.flush().map_err(|source| PtyError::Log {
                path: path.clone(),
                source,
            })?;
        }
        Ok(())
    }

    /// A device re-plugged (a port-drop fault) is given to this account, like the first.
    pub fn with_owner(mut self, owner: Option<(u32, u32)>) -> Self {
        self.owner = owner;
        self
    }

    /// Something else than nav reads the device (gpsd): nav's `GpsRxBytes` does not count
    /// the bytes written, so the scheduler does not wait for it.
    pub fn without_bus_confirmation(mut self) -> Self {
        self.confirm_on_bus = false;
        self
    }

    /// nav's NAV_TIME confirms the bytes written ([`GpsDevice::without_bus_confirmation`]).
    pub fn confirms_on_bus(&self) -> bool {
        self.confirm_on_bus
    }

    /// The device.
    pub fn pty(&self) -> &GpsPty {
        &self.pty
    }

    /// Put out epoch `e`: the device going away or coming back (a port drop), nothing in a
    /// silent outage, otherwise its sentences, once a reader has the device open and until it
    /// has read them, each wait at most `limit` (or until `stop`). None: nothing was written.
    pub fn deliver(
        &mut self,
        e: &Epoch,
        limit: Duration,
        stop: &AtomicBool,
    ) -> Result<Option<Delivered>, PtyError> {
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
            self.note(&format!("# t={:.3} s: device gone (port drop)\n", e.edge))?;
            return Ok(None);
        }
        let st = &mut self.stats;
        match (e.text.is_empty(), e.valid) {
            (true, _) => st.silent_epochs += 1,
            (false, true) => st.fixes += 1,
            (false, false) => st.void_epochs += 1,
        }
        if e.text.is_empty() {
            self.note(&format!("# t={:.3} s: silent\n", e.edge))?;
            return Ok(None);
        }
        let mut d = Delivered::default();
        // nobody has the device open (nav re-opening it after a drop): wait for them, so that
        // what the receiver loses is what the scenario says, not what the host's pace decides
        if !self.pty.reader_attached() {
            d.waited = true;
            if !self.pty.wait_reader_until(limit, stop) {
                d.stalled = true;
            }
        }
        match self.pty.write(e.text.as_bytes()) {
            Ok(()) => {
                self.stats.bytes += e.text.len() as u64;
                if !self.pty.wait_taken_until(limit, stop) {
                    self.stats.slow_reads += 1;
                    d.stalled = true;
                }
                self.note(&format!("# t={:.3} s\n{}", e.edge, e.text))?;
            }
            // nobody reads (nav not started or re-opening): the receiver's output is lost
            Err(PtyError::Write { source, .. })
                if source.kind() == std::io::ErrorKind::TimedOut =>
            {
                self.stats.unread_epochs += 1;
                self.pty.clear();
                self.note(&format!("# t={:.3} s: not read (lost)\n", e.edge))?;
                d.stalled = true;
            }
            Err(e) => return Err(e),
        }
        Ok(Some(d))
    }

    /// The pty (kept open until nav has stopped: a receiver vanishing at the very end would only
    /// add port errors to nav's summary).
    pub fn into_pty(mut self) -> GpsPty {
        if let Err(e) = self.flush_log() {
            tracing::warn!("{e}");
        }
        self.pty
    }
}

/// How an epoch's delivery went.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Delivered {
    /// It waited for a reader to open the device.
    pub waited: bool,
    /// A wait ran out (no reader, or the bytes not read, within the limit).
    pub stalled: bool,
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

    /// What is written stays unread until a reader on the device takes it; waiting for it ends
    /// when it is taken, or at the time limit.
    #[test]
    fn the_writer_sees_when_the_reader_has_taken_its_bytes() {
        let mut pty = GpsPty::open().unwrap();
        let mut reader = serialport::new(pty.path(), 9600)
            .timeout(Duration::from_millis(500))
            .open()
            .unwrap();
        assert_eq!(pty.unread(), Some(0));
        pty.write(b"$GPGGA,1*00\r\n").unwrap();
        // counted at once, though the kernel hands the bytes over in a work item of its own
        assert_eq!(pty.unread(), Some(13));
        let t = std::time::Instant::now();
        assert!(!pty.wait_taken(Duration::from_millis(30)));
        assert!(t.elapsed() >= Duration::from_millis(30));
        let mut buf = [0u8; 64];
        let n = reader.read(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"$GPGGA,1*00\r\n");
        assert!(pty.wait_taken(Duration::from_millis(30)));
    }

    /// Right after each write the count has the bytes, and right after the reader took them it
    /// has none: never a guess from time (the kernel's work item that moves them is waited for).
    #[test]
    fn the_unread_count_is_exact_right_after_each_write_and_each_read() {
        let mut pty = GpsPty::open().unwrap();
        let mut reader = serialport::new(pty.path(), 9600)
            .timeout(Duration::from_millis(500))
            .open()
            .unwrap();
        let line = b"$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A\r\n";
        let mut buf = [0u8; 128];
        for _ in 0..500 {
            pty.write(line).unwrap();
            assert_eq!(pty.unread(), Some(line.len()));
            let mut got = 0;
            while got < line.len() {
                got += reader.read(&mut buf[got..]).unwrap();
            }
            assert_eq!(&buf[..got], line);
            assert!(pty.wait_taken(Duration::ZERO));
        }
    }

    /// The device has a reader while somebody has it open, and none before or after: what
    /// the scheduler waits for after a port drop.
    #[test]
    fn the_device_knows_when_somebody_has_it_open() {
        let pty = GpsPty::open().unwrap();
        assert!(!pty.reader_attached());
        assert!(!pty.wait_reader_until(Duration::from_millis(20), &AtomicBool::new(false)));
        let reader = serialport::new(pty.path(), 9600).open().unwrap();
        assert!(pty.reader_attached());
        // asking what is unread does not count as a reader, nor make the reader go
        assert_eq!(pty.unread(), Some(0));
        assert!(pty.reader_attached());
        drop(reader);
        assert!(!pty.reader_attached());
    }

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

    /// The log of what the device sent holds exactly the bytes its reader got, each epoch
    /// after a comment with its time, and reads back as a gpsd log.
    #[test]
    fn the_device_logs_what_it_sent() {
        let spec = crate::drive::DriveSpec {
            lat_deg: -33.9,
            lon_deg: 18.4,
            height_m: 10.0,
            waypoints: vec![[0.0, 100.0], [100.0, 100.0], [100.0, 0.0], [0.0, 0.0]],
            speed_mps: 5.0,
            accel_mps2: 1.0,
            turn_rate_dps: 20.0,
            lateral_accel_mps2: 2.0,
            laps: 1,
            start_wait_s: 1.0,
            ..Default::default()
        };
        let run = crate::gps::GpsRun {
            writer: crate::gps::NmeaWriter::new(crate::gps::ReceiverParams::default()),
            drive: crate::drive::Drive::plan(&spec).unwrap(),
            pps_phase_s: 0.0,
            latency_s: 0.05,
            utc0_s: 43_200.0,
            date: (21, 11, 2026),
        };
        let pty = GpsPty::open().unwrap();
        let mut reader = serialport::new(pty.path(), 9600)
            .timeout(Duration::from_millis(300))
            .open()
            .unwrap();
        let dir = std::env::temp_dir().join(format!("gps-log-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("gps-sent.log");
        let mut rx = crate::gps::GpsReceiver::new(run);
        let mut dev = GpsDevice::new(pty, None).with_log(&path).unwrap();
        let got = std::thread::spawn(move || {
            let mut all = Vec::new();
            let mut buf = [0u8; 4096];
            while let Ok(n) = reader.read(&mut buf) {
                all.extend_from_slice(&buf[..n]);
            }
            all
        });
        let stop = AtomicBool::new(false);
        while let Some(e) = rx.poll(5.5, 100.0) {
            dev.deliver(&e, Duration::from_secs(5), &stop).unwrap();
        }
        assert_eq!(dev.stats.fixes, 5);
        let _pty = dev.into_pty();
        let got = got.join().unwrap();
        let text = std::fs::read(&path).unwrap();
        let lines = parse_log(&text);
        let sent: Vec<u8> = lines.iter().flat_map(|l| l.bytes.clone()).collect();
        assert_eq!(sent, got);
        let s = String::from_utf8_lossy(&text);
        assert!(
            s.contains("# t=1.000 s\n$GP") && s.contains("# t=5.000 s\n"),
            "{s}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
