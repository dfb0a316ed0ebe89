//! GPS receiver emulation onto a pty: replay of recorded receiver logs (the gpsd `.log` format:
//! `#` comment lines, then the bytes as the receiver sent them), paced by the sentences' own
//! times. nav opens the pty's path exactly as it opens `/dev/ttyUSB0`.

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

/// Position error of a receiver: a Gauss-Markov part (time constant of minutes, the slow wander
/// of a standalone fix) plus white noise, per axis (east, north, up).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct GpsErrorParams {
    /// Gauss-Markov sigma, horizontal, m.
    pub gm_sigma_m: f64,
    /// Gauss-Markov time constant, s.
    pub gm_tau_s: f64,
    /// White noise, horizontal, m.
    pub white_sigma_m: f64,
    /// Vertical errors are this many times the horizontal ones.
    pub vertical_factor: f64,
    /// Seed.
    pub seed: u64,
}

impl Default for GpsErrorParams {
    /// The paper's receiver class (25 m, standalone L1 C/A without SA).
    fn default() -> Self {
        Self::class_25m()
    }
}

impl GpsErrorParams {
    /// A 25 m class receiver (paper 003's Rockwell Jupiter).
    pub fn class_25m() -> Self {
        Self {
            gm_sigma_m: 12.0,
            gm_tau_s: 300.0,
            white_sigma_m: 6.0,
            vertical_factor: 1.6,
            seed: 5,
        }
    }

    /// A modern few-metre class receiver.
    pub fn class_few_m() -> Self {
        Self {
            gm_sigma_m: 1.5,
            gm_tau_s: 120.0,
            white_sigma_m: 0.8,
            vertical_factor: 1.6,
            seed: 5,
        }
    }
}

/// The error process (call once per fix, in time order).
pub struct GpsError {
    p: GpsErrorParams,
    gm: [f64; 3],
    rng: rand::rngs::StdRng,
    last_t: Option<f64>,
}

impl GpsError {
    /// Start the process.
    pub fn new(p: GpsErrorParams) -> Self {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(p.seed);
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let v = p.vertical_factor;
        let gm = [
            p.gm_sigma_m * n.sample(&mut rng),
            p.gm_sigma_m * n.sample(&mut rng),
            v * p.gm_sigma_m * n.sample(&mut rng),
        ];
        Self {
            p,
            gm,
            rng,
            last_t: None,
        }
    }

    /// The error (east, north, up, m) of the fix at `t`.
    pub fn at(&mut self, t: f64) -> [f64; 3] {
        use rand_distr::{Distribution, Normal};
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let dt = self.last_t.map_or(0.0, |l| (t - l).max(0.0));
        self.last_t = Some(t);
        let phi = (-dt / self.p.gm_tau_s).exp();
        let drive = (1.0 - phi * phi).sqrt();
        let v = self.p.vertical_factor;
        for (i, g) in self.gm.iter_mut().enumerate() {
            let s = self.p.gm_sigma_m * if i == 2 { v } else { 1.0 };
            *g = phi * *g + s * drive * n.sample(&mut self.rng);
        }
        let w = self.p.white_sigma_m;
        [
            self.gm[0] + w * n.sample(&mut self.rng),
            self.gm[1] + w * n.sample(&mut self.rng),
            self.gm[2] + v * w * n.sample(&mut self.rng),
        ]
    }
}

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

#[cfg(test)]
mod error_tests {
    use super::*;

    #[test]
    fn the_25_m_class_has_the_stated_size_and_wanders_slowly() {
        let mut e = GpsError::new(GpsErrorParams::class_25m());
        let xs: Vec<[f64; 3]> = (0..20_000).map(|i| e.at(f64::from(i))).collect();
        let rms_h =
            (xs.iter().map(|x| x[0] * x[0] + x[1] * x[1]).sum::<f64>() / xs.len() as f64).sqrt();
        // sqrt(2 (12^2 + 6^2)) = 19 m horizontal RMS
        assert!((rms_h - 19.0).abs() < 3.0, "{rms_h}");
        // consecutive fixes are strongly correlated (the white part aside)
        let d = (xs
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).powi(2))
            .sum::<f64>()
            / xs.len() as f64)
            .sqrt();
        assert!(d < 10.0, "{d}");
    }
}

/// What the emulated receiver does (the `[gps]` table of a scenario).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ReceiverParams {
    /// Fixes per second (1-10).
    pub rate_hz: f64,
    /// Talker id (`GP`, `GN`, ...).
    pub talker: String,
    /// Position errors.
    pub errors: GpsErrorParams,
    /// Velocity noise (1 sigma), m/s.
    pub velocity_sigma_mps: f64,
    /// Antenna position in the body frame (x right, y forward, z up), m.
    pub lever_arm_m: [f64; 3],
    /// No fix before this time (time to first fix), s.
    pub ttff_s: f64,
    /// Outages (tunnels): [start, end] s; `void` sentences (status V, quality 0) or silence.
    pub outages: Vec<[f64; 2]>,
    /// During outages send void sentences (true) or nothing (false).
    pub outage_void: bool,
    /// Multipath jumps: [time s, duration s, metres] added to the north error.
    pub multipath: Vec<[f64; 3]>,
    /// Periods [start, end] s during which the receiver's device is gone (a USB receiver
    /// resetting): on the bench its pty closes and a new one appears behind the same link.
    pub port_drops: Vec<[f64; 2]>,
}

impl Default for ReceiverParams {
    fn default() -> Self {
        Self {
            rate_hz: 1.0,
            talker: "GP".into(),
            errors: GpsErrorParams::class_25m(),
            velocity_sigma_mps: 0.3,
            lever_arm_m: [0.0, 0.5, 1.2],
            ttff_s: 0.0,
            outages: Vec::new(),
            outage_void: true,
            multipath: Vec::new(),
            port_drops: Vec::new(),
        }
    }
}

/// The truth the receiver sees at a fix: antenna position and velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AntennaTruth {
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Height above the ellipsoid, m.
    pub h_m: f64,
    /// Velocity east, north, up, m/s.
    pub vel_enu: [f64; 3],
}

/// Writes NMEA-0183 sentences for fixes.
pub struct NmeaWriter {
    p: ReceiverParams,
    err: GpsError,
    rng: rand::rngs::StdRng,
}

fn with_checksum(body: &str) -> String {
    let ck = body.bytes().fold(0u8, |a, b| a ^ b);
    format!("${body}*{ck:02X}\r\n")
}

fn dm(deg: f64, deg_digits: usize, pos: char, neg: char) -> (String, char) {
    let a = deg.abs();
    let d = a.floor();
    let m = (a - d) * 60.0;
    let s = format!("{:0w$}{:08.5}", d as u32, m, w = deg_digits);
    (s, if deg >= 0.0 { pos } else { neg })
}

impl NmeaWriter {
    /// A receiver with these parameters.
    pub fn new(p: ReceiverParams) -> Self {
        use rand::SeedableRng;
        Self {
            err: GpsError::new(p.errors.clone()),
            rng: rand::rngs::StdRng::seed_from_u64(p.errors.seed ^ 0x5eed),
            p,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &ReceiverParams {
        &self.p
    }

    /// The sentences of the fix at `t` (s since the start; `utc0_s` is the UTC second of the
    /// day at t = 0, `date` is (day, month, year)), and the position error applied (E, N, U, m;
    /// none when there is no fix).
    pub fn fix(
        &mut self,
        t: f64,
        utc0_s: f64,
        date: (u32, u32, u32),
        truth: &AntennaTruth,
    ) -> (String, Option<[f64; 3]>) {
        use rand_distr::{Distribution, Normal};
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let in_outage = self.p.outages.iter().any(|o| t >= o[0] && t < o[1]);
        if in_outage && !self.p.outage_void {
            return (String::new(), None);
        }
        let valid = t >= self.p.ttff_s && !in_outage;
        let mut e = self.err.at(t);
        for m in &self.p.multipath {
            if t >= m[0] && t < m[0] + m[1] {
                e[1] += m[2];
            }
        }
        let (rm, rn) = crate::geodesy::radii(truth.lat_deg.to_radians());
        let lat = truth.lat_deg + (e[1] / rm).to_degrees();
        let lon = truth.lon_deg + (e[0] / (rn * truth.lat_deg.to_radians().cos())).to_degrees();
        let h = truth.h_m + e[2];
        let ve = truth.vel_enu[0] + self.p.velocity_sigma_mps * n.sample(&mut self.rng);
        let vn = truth.vel_enu[1] + self.p.velocity_sigma_mps * n.sample(&mut self.rng);
        let speed = ve.hypot(vn);
        let track = ve.atan2(vn).to_degrees().rem_euclid(360.0);
        let tod = (utc0_s + t).rem_euclid(86_400.0);
        let (hh, mm, ss) = (
            (tod / 3600.0).floor(),
            ((tod % 3600.0) / 60.0).floor(),
            tod % 60.0,
        );
        let time = format!("{:02}{:02}{:05.2}", hh as u32, mm as u32, ss);
        let (dd, mo, yy) = date;
        let (la, ns) = dm(lat, 2, 'N', 'S');
        let (lo, ew) = dm(lon, 3, 'E', 'W');
        // HDOP and satellites consistent with the error size
        let sats: u32 = if valid {
            (12.0 - self.p.errors.gm_sigma_m.min(20.0) / 4.0)
                .round()
                .clamp(4.0, 12.0) as u32
        } else {
            0
        };
        let hdop = if valid {
            (self.p.errors.gm_sigma_m.hypot(self.p.errors.white_sigma_m) / 6.0).clamp(0.6, 9.9)
        } else {
            99.9
        };
        let geoid = 0.0;
        let tk = &self.p.talker;
        let mut out = String::new();
        let (la_s, lo_s) = if valid {
            (la.as_str(), lo.as_str())
        } else {
            ("", "")
        };
        let (ns_s, ew_s) = if valid {
            (ns.to_string(), ew.to_string())
        } else {
            (String::new(), String::new())
        };
        out += &with_checksum(&format!(
            "{tk}GGA,{time},{la_s},{ns_s},{lo_s},{ew_s},{},{sats:02},{hdop:.1},{},M,{geoid:.1},M,,",
            u8::from(valid),
            if valid {
                format!("{h:.1}")
            } else {
                String::new()
            }
        ));
        out += &with_checksum(&format!(
            "{tk}RMC,{time},{},{la_s},{ns_s},{lo_s},{ew_s},{:.1},{:.1},{dd:02}{mo:02}{:02},,,{}",
            if valid { 'A' } else { 'V' },
            speed / 0.514_444,
            track,
            yy % 100,
            if valid { 'A' } else { 'N' }
        ));
        out += &with_checksum(&format!(
            "{tk}VTG,{track:.1},T,,M,{:.1},N,{:.1},K,{}",
            speed / 0.514_444,
            speed * 3.6,
            if valid { 'A' } else { 'N' }
        ));
        let prns: Vec<String> = (1..=12)
            .map(|i| {
                if i <= sats {
                    format!("{:02}", i * 2)
                } else {
                    String::new()
                }
            })
            .collect();
        out += &with_checksum(&format!(
            "{tk}GSA,A,{},{},{:.1},{hdop:.1},{:.1}",
            if valid { 3 } else { 1 },
            prns.join(","),
            hdop * 1.6,
            hdop * 1.3
        ));
        let nsv = sats.max(1).div_ceil(4);
        for k in 0..nsv {
            let mut body = format!("{tk}GSV,{nsv},{},{sats:02}", k + 1);
            for j in 0..4 {
                let i = k * 4 + j;
                if i < sats {
                    body += &format!(
                        ",{:02},{:02},{:03},{:02}",
                        (i + 1) * 2,
                        20 + (i * 7) % 60,
                        (i * 37) % 360,
                        35 + i % 10
                    );
                }
            }
            out += &with_checksum(&body);
        }
        out += &with_checksum(&format!("{tk}ZDA,{time},{dd:02},{mo:02},{yy:04},00,00"));
        (out, valid.then_some(e))
    }
}

/// The antenna's truth on a drive: the vehicle's position and velocity moved by the lever arm
/// (body frame: x right, y forward, z up; the road is level, so only the heading turns it).
pub fn antenna_truth(drive: &crate::drive::Drive, t: f64, lever_arm_m: [f64; 3]) -> AntennaTruth {
    let (lat, lon, h) = drive.position(t);
    let (_, psi, _, psi_rate, _) = drive.kinematics(t);
    let v = drive.velocity(t);
    let [lx, ly, lz] = lever_arm_m;
    let (s, c) = psi.sin_cos();
    // lever arm in ENU and its rate as the vehicle turns
    let (de, dn) = (lx * c + ly * s, -lx * s + ly * c);
    let (ve, vn) = (psi_rate * (-lx * s + ly * c), psi_rate * (-lx * c - ly * s));
    let (rm, rn) = crate::geodesy::radii(lat);
    AntennaTruth {
        lat_deg: (lat + dn / (rm + h)).to_degrees(),
        lon_deg: (lon + de / ((rn + h) * lat.cos())).to_degrees(),
        h_m: h + lz,
        vel_enu: [v.x + ve, v.y + vn, v.z],
    }
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

/// The GPS receiver on a pty during a bench run, stepped on the IMU stream's clock by the bus
/// scheduler ([`crate::bus`]): the fix of each PPS edge (at `k / rate + pps_phase_s`, the same
/// edges the IMU latches) is written `latency_s` after the IMU has passed the edge, as a receiver
/// outputs its fix shortly after the pulse. During the receiver's `port_drops` the device is
/// gone: the pty is closed and a new one appears at `link` afterwards (as a USB receiver
/// re-enumerating behind a `/dev/serial/by-id` link).
pub struct GpsRun {
    /// The sentence writer (receiver model and its errors).
    pub writer: NmeaWriter,
    /// The drive the antenna rides on.
    pub drive: crate::drive::Drive,
    /// The IMU's PPS phase, s.
    pub pps_phase_s: f64,
    /// Delay from the PPS edge to the sentences, s.
    pub latency_s: f64,
    /// UTC second of day at t = 0, and the date (day, month, year).
    pub utc0_s: f64,
    /// Date.
    pub date: (u32, u32, u32),
}

/// One fix epoch as the receiver puts it out.
#[derive(Debug, Clone, PartialEq)]
pub struct Epoch {
    /// Its PPS edge, s.
    pub edge: f64,
    /// The sentences (empty in a silent outage).
    pub text: String,
    /// It carries a valid fix.
    pub valid: bool,
    /// The receiver's device is gone at this epoch (which of its `port_drops`).
    pub port_drop: Option<usize>,
}

/// The receiver on the IMU stream's clock, without I/O: epochs out as simulated time passes.
/// The bench puts them on a pty ([`GpsDevice`]); in-process runs decode them directly.
pub struct GpsReceiver {
    run: GpsRun,
    k: u64,
}

impl GpsReceiver {
    /// The receiver of `run`; its first epoch is the PPS edge at one period.
    pub fn new(run: GpsRun) -> Self {
        Self { run, k: 1 }
    }

    fn period(&self) -> f64 {
        1.0 / self.run.writer.params().rate_hz.clamp(1.0, 10.0)
    }

    /// Simulated time at which the next epoch is put out, s.
    pub fn next_write_time(&self) -> f64 {
        self.k as f64 * self.period() + self.run.pps_phase_s + self.run.latency_s
    }

    /// The next epoch due once the IMU stream has reached `t` (the run ends at `duration_s`).
    pub fn poll(&mut self, t: f64, duration_s: f64) -> Option<Epoch> {
        let edge = self.k as f64 * self.period() + self.run.pps_phase_s;
        if edge > duration_s || t < edge + self.run.latency_s {
            return None;
        }
        self.k += 1;
        let p = self.run.writer.params();
        let port_drop = p
            .port_drops
            .iter()
            .position(|d| edge >= d[0] && edge < d[1]);
        let truth = antenna_truth(&self.run.drive, edge, p.lever_arm_m);
        let (text, err) = self
            .run
            .writer
            .fix(edge.floor(), self.run.utc0_s, self.run.date, &truth);
        Some(Epoch {
            edge,
            text,
            valid: err.is_some(),
            port_drop,
        })
    }
}

/// A [`GpsReceiver`] on its pty, as the bus scheduler steps it.
pub struct GpsDevice {
    rx: GpsReceiver,
    pty: GpsPty,
    link: Option<std::path::PathBuf>,
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
            dropped: None,
            stats: GpsTxStats::default(),
        }
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
