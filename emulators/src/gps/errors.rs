//! The receiver's position errors: a slow Gauss-Markov wander plus white noise, per axis.

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
