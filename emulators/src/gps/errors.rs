//! The receiver's position errors: a slow Gauss-Markov wander plus white noise, per axis, and
//! what the surroundings add on top ([`Environment`]): the satellites used changing (HDOP
//! changes and the solution steps), multipath bursts, and stretches of poor geometry. The
//! first part is what a navigation filter can model; the second is what makes a real
//! receiver's error non-stationary, which a fixed noise model cannot describe.

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
    /// The surroundings (`[gps.errors.environment]`; default: open sky, nothing added).
    pub environment: Environment,
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
            environment: Environment::default(),
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
            environment: Environment::default(),
        }
    }

    /// The HDOP the receiver reports at its nominal geometry: the surroundings' `hdop`, or the
    /// one consistent with the error size. A filter's `hdop_ref` for this receiver.
    pub fn nominal_hdop(&self) -> f64 {
        if self.environment.hdop > 0.0 {
            self.environment.hdop
        } else {
            self.steady_geometry().1
        }
    }

    /// The satellites used and the HDOP when the surroundings say nothing: consistent with the
    /// error size (a 25 m class receiver: 9 satellites, HDOP 2.2).
    fn steady_geometry(&self) -> (u32, f64) {
        let sats = (12.0 - self.gm_sigma_m.min(20.0) / 4.0)
            .round()
            .clamp(4.0, 12.0) as u32;
        let hdop = (self.gm_sigma_m.hypot(self.white_sigma_m) / 6.0).clamp(0.6, 9.9);
        (sats, hdop)
    }
}

/// Named sets of surroundings.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum EnvironmentPreset {
    /// Nothing added.
    #[default]
    OpenSky,
    /// Paper 003's vehicle test: a 25 m class receiver driven round a campus among buildings
    /// and trees. The satellites used change every two minutes or so (the solution steps by a
    /// few metres, HDOP 1.2-3), and multipath bursts of 5-30 s add a fast-wandering error of
    /// about 20 m every 2.5 minutes. Neither is in a Gauss-Markov-plus-white model.
    #[serde(rename = "paper-003")]
    Paper003,
    /// A street canyon: satellites change every minute, bursts every minute.
    Urban,
}

impl std::fmt::Display for EnvironmentPreset {
    /// Its name in a scenario and on the command line (`open-sky`, `paper-003`, ...).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::OpenSky => "open-sky",
            Self::Paper003 => "paper-003",
            Self::Urban => "urban",
        })
    }
}

/// What the surroundings add to a receiver's steady error (`[gps.errors.environment]`): take a
/// `preset` and change any field.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize, PartialEq)]
#[serde(try_from = "EnvironmentSpec")]
pub struct Environment {
    /// The preset the fields started from.
    pub preset: EnvironmentPreset,
    /// Mean time between changes of the satellites used, s (0: they never change). Each change
    /// adds or drops 1-2 satellites.
    pub constellation_change_every_s: f64,
    /// The step of the position error when they change, per horizontal axis (1 sigma), m.
    pub constellation_step_sigma_m: f64,
    /// Satellites used at the start (0: from the error size).
    pub satellites: u32,
    /// Fewest satellites used (at least 4: a fix needs four).
    pub min_satellites: u32,
    /// HDOP with `satellites` used (0: from the error size). It scales as
    /// `sqrt(satellites / used)`, and the white noise and the steps scale with it.
    pub hdop: f64,
    /// Mean time between multipath bursts, s (0: none).
    pub multipath_every_s: f64,
    /// Shortest and longest burst, s.
    pub multipath_duration_s: [f64; 2],
    /// A burst's error, per horizontal axis (1 sigma), m: a Gauss-Markov process of its own.
    pub multipath_sigma_m: f64,
    /// Its correlation time, s.
    pub multipath_tau_s: f64,
    /// Stretches of poor geometry: [start s, end s, HDOP factor].
    pub degraded: Vec<[f64; 3]>,
}

impl Default for Environment {
    fn default() -> Self {
        Self::preset(EnvironmentPreset::OpenSky)
    }
}

impl Environment {
    /// The fields of a preset.
    pub fn preset(preset: EnvironmentPreset) -> Self {
        let open = Self {
            preset,
            constellation_change_every_s: 0.0,
            constellation_step_sigma_m: 0.0,
            satellites: 0,
            min_satellites: 5,
            hdop: 0.0,
            multipath_every_s: 0.0,
            multipath_duration_s: [5.0, 30.0],
            multipath_sigma_m: 0.0,
            multipath_tau_s: 4.0,
            degraded: Vec::new(),
        };
        match preset {
            EnvironmentPreset::OpenSky => open,
            EnvironmentPreset::Paper003 => Self {
                constellation_change_every_s: 120.0,
                constellation_step_sigma_m: 5.0,
                satellites: 7,
                hdop: 1.6,
                multipath_every_s: 150.0,
                multipath_sigma_m: 20.0,
                ..open
            },
            EnvironmentPreset::Urban => Self {
                constellation_change_every_s: 60.0,
                constellation_step_sigma_m: 8.0,
                satellites: 6,
                hdop: 2.0,
                multipath_every_s: 60.0,
                multipath_duration_s: [3.0, 20.0],
                multipath_sigma_m: 30.0,
                ..open
            },
        }
    }

    /// Anything added at all.
    pub fn is_open_sky(&self) -> bool {
        self.constellation_change_every_s <= 0.0
            && self.multipath_every_s <= 0.0
            && self.degraded.is_empty()
    }
}

/// `[gps.errors.environment]` as written: a preset and the fields that change it.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct EnvironmentSpec {
    #[serde(default)]
    preset: EnvironmentPreset,
    constellation_change_every_s: Option<f64>,
    constellation_step_sigma_m: Option<f64>,
    satellites: Option<u32>,
    min_satellites: Option<u32>,
    hdop: Option<f64>,
    multipath_every_s: Option<f64>,
    multipath_duration_s: Option<[f64; 2]>,
    multipath_sigma_m: Option<f64>,
    multipath_tau_s: Option<f64>,
    degraded: Option<Vec<[f64; 3]>>,
}

impl TryFrom<EnvironmentSpec> for Environment {
    type Error = String;
    fn try_from(s: EnvironmentSpec) -> Result<Self, String> {
        let b = Environment::preset(s.preset);
        let e = Environment {
            preset: s.preset,
            constellation_change_every_s: s
                .constellation_change_every_s
                .unwrap_or(b.constellation_change_every_s),
            constellation_step_sigma_m: s
                .constellation_step_sigma_m
                .unwrap_or(b.constellation_step_sigma_m),
            satellites: s.satellites.unwrap_or(b.satellites),
            min_satellites: s.min_satellites.unwrap_or(b.min_satellites),
            hdop: s.hdop.unwrap_or(b.hdop),
            multipath_every_s: s.multipath_every_s.unwrap_or(b.multipath_every_s),
            multipath_duration_s: s.multipath_duration_s.unwrap_or(b.multipath_duration_s),
            multipath_sigma_m: s.multipath_sigma_m.unwrap_or(b.multipath_sigma_m),
            multipath_tau_s: s.multipath_tau_s.unwrap_or(b.multipath_tau_s),
            degraded: s.degraded.unwrap_or(b.degraded),
        };
        let finite_non_neg = |name: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(format!("{name} must be a finite number >= 0, got {v}"))
            }
        };
        finite_non_neg(
            "constellation_change_every_s",
            e.constellation_change_every_s,
        )?;
        finite_non_neg("constellation_step_sigma_m", e.constellation_step_sigma_m)?;
        finite_non_neg("hdop", e.hdop)?;
        finite_non_neg("multipath_every_s", e.multipath_every_s)?;
        finite_non_neg("multipath_sigma_m", e.multipath_sigma_m)?;
        if !(e.multipath_tau_s.is_finite() && e.multipath_tau_s > 0.0) {
            return Err(format!(
                "multipath_tau_s must be > 0, got {}",
                e.multipath_tau_s
            ));
        }
        let [d0, d1] = e.multipath_duration_s;
        if !(d0.is_finite() && d1.is_finite() && 0.0 < d0 && d0 <= d1) {
            return Err(format!(
                "multipath_duration_s must be [shortest, longest] with 0 < shortest <= longest, got [{d0}, {d1}]"
            ));
        }
        if !(4..=12).contains(&e.min_satellites) {
            return Err(format!(
                "min_satellites must be 4-12, got {}",
                e.min_satellites
            ));
        }
        if e.satellites != 0 && !(e.min_satellites..=12).contains(&e.satellites) {
            return Err(format!(
                "satellites must be 0 (from the error size) or {}-12, got {}",
                e.min_satellites, e.satellites
            ));
        }
        for (i, d) in e.degraded.iter().enumerate() {
            if !(d.iter().all(|v| v.is_finite()) && d[0] <= d[1] && d[2] >= 1.0) {
                return Err(format!(
                    "degraded[{i}] must be [start s, end s, HDOP factor >= 1] with start <= end, got {d:?}"
                ));
            }
        }
        Ok(e)
    }
}

/// One fix's error and the geometry the receiver reports with it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorSample {
    /// Position error (east, north, up), m.
    pub enu: [f64; 3],
    /// Satellites used.
    pub satellites: u32,
    /// Horizontal dilution of precision.
    pub hdop: f64,
    /// A multipath burst is on.
    pub multipath: bool,
    /// The receiver's own 1-sigma estimate of its error per axis (east, north, up), m, as GST
    /// states it: the steady model's stationary sigma, its white part scaled with the HDOP,
    /// and a multipath burst's sigma while one is on (a receiver sees it in its residuals).
    pub sigma_enu: [f64; 3],
}

/// The error process (call once per fix, in time order).
pub struct GpsError {
    p: GpsErrorParams,
    gm: [f64; 3],
    rng: rand::rngs::StdRng,
    last_t: Option<f64>,
    /// The surroundings' own state (none in open sky: the steady process is then exactly what
    /// it was before they existed, draw for draw).
    env: Option<EnvState>,
}

/// The surroundings' process: its own random numbers, so that the steady error's draws do not
/// depend on it.
struct EnvState {
    rng: rand::rngs::StdRng,
    sats: u32,
    next_change: f64,
    next_burst: f64,
    burst_end: f64,
    burst: [f64; 2],
}

fn exp_draw(rng: &mut rand::rngs::StdRng, mean: f64) -> f64 {
    use rand::Rng;
    if mean <= 0.0 {
        return f64::INFINITY;
    }
    -mean * (1.0 - rng.random::<f64>()).ln()
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
        let env = (!p.environment.is_open_sky()).then(|| {
            let e = &p.environment;
            let mut rng = rand::rngs::StdRng::seed_from_u64(p.seed ^ 0xe17_0c0de);
            let sats = if e.satellites == 0 {
                p.steady_geometry().0
            } else {
                e.satellites
            };
            EnvState {
                next_change: exp_draw(&mut rng, e.constellation_change_every_s),
                next_burst: exp_draw(&mut rng, e.multipath_every_s),
                burst_end: f64::NEG_INFINITY,
                burst: [0.0; 2],
                sats,
                rng,
            }
        });
        Self {
            p,
            gm,
            rng,
            last_t: None,
            env,
        }
    }

    /// The error (east, north, up, m) of the fix at `t`.
    pub fn at(&mut self, t: f64) -> [f64; 3] {
        self.sample(t).enu
    }

    /// The error of the fix at `t` with the geometry the receiver reports.
    pub fn sample(&mut self, t: f64) -> ErrorSample {
        use rand::Rng;
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
        let steady_sats = self.p.steady_geometry().0;
        let hdop0 = self.p.nominal_hdop();
        let e = &self.p.environment;
        // the surroundings: satellites changing (the solution steps), multipath bursts,
        // stretches of poor geometry; the white noise scales with the HDOP
        let (mut sats, mut scale, mut extra, mut multipath) = (steady_sats, 1.0, [0.0; 2], false);
        if let Some(s) = self.env.as_mut() {
            let nominal = if e.satellites == 0 {
                steady_sats
            } else {
                e.satellites
            };
            while t >= s.next_change {
                let d: i32 = [-2, -1, 1, 2][s.rng.random_range(0..4)];
                s.sats = (s.sats as i32 + d).clamp(e.min_satellites as i32, 12) as u32;
                let step_scale = (f64::from(nominal) / f64::from(s.sats)).sqrt();
                for (i, g) in self.gm.iter_mut().enumerate() {
                    let k = if i == 2 { v } else { 1.0 };
                    *g += k * e.constellation_step_sigma_m * step_scale * n.sample(&mut s.rng);
                }
                s.next_change += exp_draw(&mut s.rng, e.constellation_change_every_s);
            }
            while t >= s.next_burst {
                let [d0, d1] = e.multipath_duration_s;
                s.burst_end = s.next_burst + d0 + (d1 - d0) * s.rng.random::<f64>();
                s.burst = [
                    e.multipath_sigma_m * n.sample(&mut s.rng),
                    e.multipath_sigma_m * n.sample(&mut s.rng),
                ];
                s.next_burst = s.burst_end + exp_draw(&mut s.rng, e.multipath_every_s);
            }
            if t < s.burst_end {
                let phi = (-dt / e.multipath_tau_s).exp();
                let drive = (1.0 - phi * phi).sqrt();
                for b in &mut s.burst {
                    *b = phi * *b + e.multipath_sigma_m * drive * n.sample(&mut s.rng);
                }
                extra = s.burst;
                multipath = true;
            }
            sats = s.sats;
            scale = (f64::from(nominal) / f64::from(sats)).sqrt();
            for d in &e.degraded {
                if t >= d[0] && t < d[1] {
                    scale *= d[2];
                }
            }
        }
        let w = self.p.white_sigma_m * scale;
        let mp = if multipath { e.multipath_sigma_m } else { 0.0 };
        let sigma_h = (self.p.gm_sigma_m.powi(2) + w * w + mp * mp).sqrt();
        let sigma_v = v * (self.p.gm_sigma_m.powi(2) + w * w).sqrt();
        ErrorSample {
            sigma_enu: [sigma_h, sigma_h, sigma_v],
            enu: [
                self.gm[0] + extra[0] + w * n.sample(&mut self.rng),
                self.gm[1] + extra[1] + w * n.sample(&mut self.rng),
                self.gm[2] + v * w * n.sample(&mut self.rng),
            ],
            satellites: sats,
            hdop: (hdop0 * scale).clamp(0.5, 99.0),
            multipath,
        }
    }
}

#[cfg(test)]
mod error_tests {
    use super::*;

    #[test]
    fn a_preset_is_written_by_its_name_in_a_scenario() {
        for p in [
            EnvironmentPreset::OpenSky,
            EnvironmentPreset::Paper003,
            EnvironmentPreset::Urban,
        ] {
            let name = serde_json::to_value(p).expect("a preset serializes");
            assert_eq!(name, serde_json::Value::String(p.to_string()));
        }
    }

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

    /// The paper's surroundings: the satellites used change (and the HDOP with them), the
    /// solution steps when they do, and multipath bursts come and go; open sky adds nothing.
    #[test]
    fn the_paper_surroundings_change_geometry_and_add_bursts() {
        let mut p = GpsErrorParams::class_25m();
        let mut open = GpsError::new(p.clone());
        p.environment = Environment::preset(EnvironmentPreset::Paper003);
        let mut paper = GpsError::new(p);
        let (mut sats, mut hdops, mut burst_s, mut steps) = (Vec::new(), Vec::new(), 0, 0);
        let mut last_sats = None;
        for i in 0..3600 {
            let t = f64::from(i);
            let o = open.sample(t);
            assert_eq!(
                (o.satellites, o.hdop, o.multipath),
                (9, 12f64.hypot(6.0) / 6.0, false)
            );
            let s = paper.sample(t);
            sats.push(s.satellites);
            hdops.push(s.hdop);
            burst_s += usize::from(s.multipath);
            if last_sats.is_some_and(|l| l != s.satellites) {
                steps += 1;
            }
            last_sats = Some(s.satellites);
        }
        // about 30 changes an hour (every 120 s on average), some clamped to no change
        assert!((12..=45).contains(&steps), "{steps} satellite changes");
        assert!(sats.iter().all(|s| (5..=12).contains(s)), "{sats:?}");
        let (lo, hi) = hdops
            .iter()
            .fold((f64::MAX, 0.0f64), |(a, b), h| (a.min(*h), b.max(*h)));
        assert!(lo < 1.6 && hi > 1.6, "HDOP {lo}-{hi}");
        // bursts of 5-30 s every 150 s + their length: about 15 % of the time
        assert!((150..=1200).contains(&burst_s), "{burst_s} s in bursts");
    }
}
