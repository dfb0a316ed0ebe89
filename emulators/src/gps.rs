//! GPS receiver emulation onto a pty: replay of recorded receiver logs (the gpsd `.log` format:
//! `#` comment lines, then the bytes as the receiver sent them), paced by the sentences' own
//! times. nav opens the pty's path exactly as it opens `/dev/ttyUSB0`.

use serialport::{SerialPort, TTYPort};
use std::io::Write;
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
