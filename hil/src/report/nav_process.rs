//! What the bench measures of the nav process itself: its resident memory over the run, its
//! CPU time, and what a nav killed outright left behind.

/// What a nav killed outright left behind.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct KillOutcome {
    /// Simulated time the IMU stream had reached at the kill, s.
    pub at_s: f64,
    /// Frames read back from its recording.
    pub recorded_frames: u64,
    /// IMU time of the last sample in the recording, s.
    pub recorded_until_s: f64,
    /// IMU data lost: the kill's time less the last recorded sample's, s.
    pub lost_s: f64,
    /// IMU time of nav's last NAV_TIME on the bus before it died: how far nav had got, s
    /// (none when it sent none).
    #[serde(default)]
    pub nav_reached_s: Option<f64>,
    /// Of `lost_s`, what nav had processed (and published) but its recording lost: the
    /// recorder's own loss, s. The rest, `at_s - nav_reached_s`, was still in nav's socket
    /// when it died (how far nav lagged the stream depends on the machine's load, not on
    /// the recorder).
    #[serde(default)]
    pub unrecorded_s: Option<f64>,
    /// Records that could not be read (the cut end).
    pub bad_records: u64,
}

/// nav's resident memory over a run, read from `/proc/PID/status` once a second of wall time.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct NavMemory {
    /// Simulated time after which the growth is judged (start-up buffers filled), s.
    pub warm_s: f64,
    /// Resident set at the warm-up's end, KiB.
    pub start_kib: u64,
    /// Resident set at the last reading before nav was told to stop, KiB.
    pub end_kib: u64,
    /// Peak resident set (`VmHWM`), KiB.
    pub peak_kib: u64,
    /// Growth after the warm-up, KiB per hour of simulated time (least-squares slope over
    /// the readings; none with fewer than 10 readings).
    pub growth_kib_per_hour: Option<f64>,
    /// Readings: [simulated time s, resident set KiB].
    pub readings: Vec<[f64; 2]>,
    /// CPU time nav had used (user and system) at the last reading, s: what a vehicle's
    /// computer must spare for it at the run's pace.
    #[serde(default)]
    pub cpu_s: Option<f64>,
}

impl NavMemory {
    /// The warm-up for a run of `duration_s`: a tenth of it, at most 60 s.
    pub fn new(duration_s: f64) -> Self {
        Self {
            warm_s: (0.1 * duration_s).min(60.0),
            ..Self::default()
        }
    }

    /// Read process `pid`'s memory at simulated time `t`.
    pub fn read(&mut self, pid: u32, t: f64) {
        let Ok(text) = std::fs::read_to_string(format!("/proc/{pid}/status")) else {
            return;
        };
        let field = |name: &str| {
            text.lines()
                .find(|l| l.starts_with(name))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse::<u64>().ok())
        };
        if let Some(rss) = field("VmRSS:") {
            self.readings.push([t, rss as f64]);
            self.end_kib = rss;
        }
        if let Some(hwm) = field("VmHWM:") {
            self.peak_kib = hwm;
        }
        if let Some(c) = cpu_seconds(&format!("/proc/{pid}/stat")) {
            self.cpu_s = Some(c);
        }
    }

    /// Fill in the warm-up reading and the growth.
    pub fn finish(&mut self) {
        let warm: Vec<[f64; 2]> = self
            .readings
            .iter()
            .copied()
            .filter(|r| r[0] >= self.warm_s)
            .collect();
        self.start_kib = warm.first().map_or(self.end_kib, |r| r[1] as u64);
        if warm.len() >= 10 {
            let n = warm.len() as f64;
            let (mt, mm) = (
                warm.iter().map(|r| r[0]).sum::<f64>() / n,
                warm.iter().map(|r| r[1]).sum::<f64>() / n,
            );
            let sxy: f64 = warm.iter().map(|r| (r[0] - mt) * (r[1] - mm)).sum();
            let sxx: f64 = warm.iter().map(|r| (r[0] - mt).powi(2)).sum();
            if sxx > 0.0 {
                self.growth_kib_per_hour = Some(sxy / sxx * 3600.0);
            }
        }
    }
}
/// User and system CPU time of the process whose `/proc/PID/stat` is `path`, s.
pub fn cpu_seconds(path: &str) -> Option<f64> {
    let text = std::fs::read_to_string(path).ok()?;
    // the command name (field 2) may hold spaces: count fields after its closing parenthesis
    let rest = &text[text.rfind(')')? + 1..];
    let mut f = rest.split_whitespace().skip(11);
    let user: u64 = f.next()?.parse().ok()?;
    let system: u64 = f.next()?.parse().ok()?;
    // SAFETY: sysconf has no preconditions.
    let tick = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    (tick > 0).then(|| (user + system) as f64 / tick as f64)
}
