//! What a north-finding drill can promise before it starts: the heading sigma a sequence of
//! table positions and dwells will give at a latitude, from the gyros' noise figures, and the
//! dwell that meets a tolerance.
//!
//! The drill ([`crate::procedures::north_finding`]) measures the two horizontal gyro rates at each position and
//! solves `g_x = -s cos phi + c sin phi + b_x`, `g_y = s sin phi + c cos phi + b_y` by weighted
//! least squares for `(s, c, b_x, b_y)` (`s = W sin psi`, `c = W cos psi`, `W = W_ie cos L`).
//! The estimate is linear in the measurements, so its error covariance is `M R M^T` exactly,
//! with `M` the least-squares gain and `R` the covariance of the measurement errors:
//!
//! - **angle random walk** `N`: white, `N^2 / D` per position and axis (`D` the dwell);
//! - **bias instability** (first-order Gauss-Markov, sigma `sigma_b`, correlation time `tau`):
//!   the mean of the bias over each dwell, correlated between dwells by the time between them.
//!   A constant bias cancels; what the bias does *during* the drill does not, and grows with
//!   the drill's length, so past some dwell a longer one makes the heading worse;
//! - **end-window noise**: the angle each dwell starts and ends on (pulse quantization and what
//!   the dither filter leaves, averaged over the end windows), `2 e^2 / D^2`;
//! - **indexing**: an error `eps` in the table angle used for a position turns the earth rate
//!   by `eps`: `(W eps)^2`.
//!
//! The heading's variance is `(c^2 S_ss + s^2 S_cc - 2 s c S_sc) / W^4`; over an unknown true
//! heading its mean is `(S_ss + S_cc) / (2 W^2)`, the figure given here. Every term scales with
//! `1 / cos L` but indexing: near the poles no dwell suffices.
//!
//! The same function serves the bench's `hil plan north-finding` (with the emulated IMU's
//! figures) and nav at start-up (with its config's), and `hil experiment north-finding` checks
//! it against the Monte Carlo (docs/north-finding.md).

use crate::navigation::earth;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// The gyros' and the mechanism's error figures the prediction needs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GyroNoise {
    /// Angle random walk, deg/sqrt(h).
    pub arw_dpsh: f64,
    /// Bias instability (first-order Gauss-Markov), 1 sigma, deg/h.
    pub drift_dph: f64,
    /// Its correlation time, s.
    pub drift_tau_s: f64,
    /// Angle noise at each end of a dwell (pulse quantization and dither residue after the end
    /// windows), arcsec.
    pub end_angle_arcsec: f64,
    /// Error of the table angle used for each position, 1 sigma, arcsec.
    pub index_arcsec: f64,
    /// The horizontal gyros' constant bias left after calibration, 1 sigma, deg/h: it cancels
    /// between positions, but bounds a static gyrocompass when the mechanism is lost.
    pub bias_dph: f64,
}

impl Default for GyroNoise {
    /// The paper's RLG (0.1 deg/h white over 1 s, 0.05 deg/h drift over 600 s) on the bench's
    /// encoder-read table.
    fn default() -> Self {
        Self {
            arw_dpsh: 0.1 / 60.0,
            drift_dph: 0.05,
            drift_tau_s: 600.0,
            end_angle_arcsec: 0.085,
            index_arcsec: 0.05,
            bias_dph: 0.1,
        }
    }
}

/// What nav is told to expect of its drill (`[north_finding.plan]`): at start-up it predicts the
/// drill's sigma from these figures and says when the drill cannot meet the tolerance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlanConfig {
    /// The heading tolerance the drill must meet, deg (0: none stated, no check).
    pub tolerance_deg: f64,
    /// Sigmas the tolerance must hold at.
    pub confidence: f64,
    /// Time from one dwell's end to the next one's start on this mechanism (unlock, index,
    /// lock, settle), s.
    pub index_time_s: f64,
    /// The unit's gyros and table (from its datasheet or a calibration).
    pub gyro: GyroNoise,
}

impl Default for PlanConfig {
    fn default() -> Self {
        Self {
            tolerance_deg: 0.0,
            confidence: 3.0,
            index_time_s: 5.5,
            gyro: GyroNoise::default(),
        }
    }
}

impl PlanConfig {
    /// Refuse figures the prediction cannot use, naming the setting.
    pub fn check(&self) -> Result<(), crate::procedures::turntable_link::SettingError> {
        let bad = |setting, requirement| {
            Err(crate::procedures::turntable_link::SettingError::new(
                "north_finding.plan",
                setting,
                requirement,
            ))
        };
        let g = &self.gyro;
        let non_negative = [
            ("tolerance_deg", self.tolerance_deg),
            ("index_time_s", self.index_time_s),
            ("gyro.arw_dpsh", g.arw_dpsh),
            ("gyro.drift_dph", g.drift_dph),
            ("gyro.end_angle_arcsec", g.end_angle_arcsec),
            ("gyro.index_arcsec", g.index_arcsec),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, "must be a number, 0 or more");
            }
        }
        if !(self.confidence.is_finite() && self.confidence > 0.0) {
            return bad("confidence", "must be a positive number of sigmas");
        }
        if !(g.bias_dph.is_finite() && g.bias_dph > 0.0) {
            return bad("gyro.bias_dph", "must be a positive number of deg/h");
        }
        if !(g.drift_tau_s.is_finite() && g.drift_tau_s > 0.0) {
            return bad("gyro.drift_tau_s", "must be a positive number of seconds");
        }
        Ok(())
    }
}

/// A drill to predict: where, which positions, how long.
#[derive(Debug, Clone, PartialEq)]
pub struct DrillPlan {
    /// Latitude, deg.
    pub latitude_deg: f64,
    /// Table positions in the order visited, deg.
    pub positions_deg: Vec<f64>,
    /// Dwell per position, s.
    pub dwell_s: f64,
    /// Time from one dwell's end to the next one's start (unlock, index, lock, settle), s.
    pub index_time_s: f64,
    /// The gyros and the table.
    pub noise: GyroNoise,
}

/// The predicted heading sigma and its terms (each the sigma the term alone would give; their
/// squares add up to the total's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Prediction {
    /// Heading sigma, deg.
    pub sigma_deg: f64,
    /// Angle random walk's part, deg.
    pub arw_deg: f64,
    /// The bias drifting during the drill, deg.
    pub drift_deg: f64,
    /// End-window angle noise, deg.
    pub end_angle_deg: f64,
    /// Table angle errors, deg.
    pub index_deg: f64,
    /// Horizontal earth rate at the latitude, deg/h.
    pub earth_rate_dph: f64,
    /// Total dwell, s.
    pub total_dwell_s: f64,
    /// Time from the first dwell's start to the last one's end, s.
    pub span_s: f64,
}

/// The answer to "which dwell meets this tolerance".
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DwellAnswer {
    /// The shortest dwell per position (of those tried, 1 s steps) whose sigma times the
    /// confidence is within the tolerance.
    Meets {
        /// Dwell per position, s.
        dwell_s: f64,
        /// Its prediction.
        prediction: Prediction,
    },
    /// No dwell up to the longest allowed suffices; the best one and what it gives.
    Cannot {
        /// The dwell with the smallest sigma, s.
        best_dwell_s: f64,
        /// Its prediction.
        prediction: Prediction,
    },
}

const RAD_PER_ARCSEC: f64 = std::f64::consts::PI / 180.0 / 3600.0;

/// Covariance of the means of a first-order Gauss-Markov process (unit variance, correlation
/// time `tau`) over the windows `[a0, a0 + da]` and `[b0, b0 + db]` (disjoint or equal).
fn gm_mean_cov(tau: f64, a0: f64, da: f64, b0: f64, db: f64) -> f64 {
    if (a0 - b0).abs() < 1e-12 && (da - db).abs() < 1e-12 {
        let x = da / tau;
        return 2.0 * (x - 1.0 + (-x).exp()) / (x * x);
    }
    let (s0, sd, l0, ld) = if a0 <= b0 {
        (a0, da, b0, db)
    } else {
        (b0, db, a0, da)
    };
    let gap = (l0 - (s0 + sd)).max(0.0);
    tau * tau / (sd * ld)
        * (1.0 - (-sd / tau).exp())
        * (1.0 - (-ld / tau).exp())
        * (-gap / tau).exp()
}

/// The heading sigma `plan` will give.
pub fn predict(plan: &DrillPlan) -> Prediction {
    let n = plan.positions_deg.len();
    let d = plan.dwell_s;
    let w = earth::OMEGA_IE * plan.latitude_deg.to_radians().cos().abs();
    let nz = &plan.noise;
    let arw = nz.arw_dpsh.to_radians() / 60.0; // rad/sqrt(s)
    let drift = nz.drift_dph.to_radians() / 3600.0; // rad/s
    let end = nz.end_angle_arcsec * RAD_PER_ARCSEC;
    let index = nz.index_arcsec * RAD_PER_ARCSEC;
    // a position repeated in a row is one dwell after another, without a move
    let mut starts = Vec::with_capacity(n);
    let mut t = 0.0;
    for (k, p) in plan.positions_deg.iter().enumerate() {
        if k > 0 {
            t += d + if *p == plan.positions_deg[k - 1] {
                0.0
            } else {
                plan.index_time_s
            };
        }
        starts.push(t);
    }
    // measurements: (position k, axis a) at row 2k + a; unknowns s, c, b_x, b_y
    let m = 2 * n;
    let mut a = DMatrix::<f64>::zeros(m, 4);
    for (k, p) in plan.positions_deg.iter().enumerate() {
        let (sn, cs) = p.to_radians().sin_cos();
        a.row_mut(2 * k).copy_from_slice(&[-cs, sn, 1.0, 0.0]);
        a.row_mut(2 * k + 1).copy_from_slice(&[sn, cs, 0.0, 1.0]);
    }
    // nav weights each position by its measured white noise: equal dwells, equal weights
    let white = arw * arw / d + 2.0 * end * end / (d * d);
    let wgt = 1.0 / white.max(1e-30);
    let ata = a.transpose() * &a * wgt;
    let Some(inv) = ata.try_inverse() else {
        return Prediction {
            sigma_deg: f64::INFINITY,
            arw_deg: f64::INFINITY,
            drift_deg: f64::INFINITY,
            end_angle_deg: f64::INFINITY,
            index_deg: f64::INFINITY,
            earth_rate_dph: w * earth::DEG_PER_HOUR_PER_RAD_S,
            total_dwell_s: d * n as f64,
            span_s: 0.0,
        };
    };
    let gain = inv * a.transpose() * wgt;
    let sigma = |r: &DMatrix<f64>| -> f64 {
        let s = &gain * r * gain.transpose();
        if w <= 0.0 {
            return f64::INFINITY;
        }
        ((s[(0, 0)] + s[(1, 1)]) / (2.0 * w * w))
            .max(0.0)
            .sqrt()
            .to_degrees()
    };
    let diag = |v: f64| DMatrix::<f64>::from_diagonal(&DVector::from_element(m, v));
    let mut r_drift = DMatrix::<f64>::zeros(m, m);
    if drift > 0.0 && nz.drift_tau_s > 0.0 {
        for j in 0..n {
            for k in 0..n {
                let c = drift * drift * gm_mean_cov(nz.drift_tau_s, starts[j], d, starts[k], d);
                // the axes' biases are independent of each other
                r_drift[(2 * j, 2 * k)] = c;
                r_drift[(2 * j + 1, 2 * k + 1)] = c;
            }
        }
    }
    let arw_deg = sigma(&diag(arw * arw / d));
    let end_angle_deg = sigma(&diag(2.0 * end * end / (d * d)));
    let index_deg = sigma(&diag((w * index).powi(2)));
    let drift_deg = sigma(&r_drift);
    let total =
        (arw_deg.powi(2) + end_angle_deg.powi(2) + index_deg.powi(2) + drift_deg.powi(2)).sqrt();
    Prediction {
        sigma_deg: total,
        arw_deg,
        drift_deg,
        end_angle_deg,
        index_deg,
        earth_rate_dph: w * earth::DEG_PER_HOUR_PER_RAD_S,
        total_dwell_s: d * n as f64,
        span_s: starts.last().copied().unwrap_or(0.0) + d,
    }
}

/// The shortest dwell per position, from `min_s` to `max_s` in 1 s steps, whose predicted sigma
/// times `confidence` is within `tolerance_deg`; else the dwell that comes closest.
pub fn dwell_for(
    plan: &DrillPlan,
    tolerance_deg: f64,
    confidence: f64,
    min_s: f64,
    max_s: f64,
) -> DwellAnswer {
    let at = |dwell_s: f64| {
        predict(&DrillPlan {
            dwell_s,
            ..plan.clone()
        })
    };
    let mut best = (min_s, at(min_s));
    let mut dwell = min_s.max(1.0).ceil();
    while dwell <= max_s {
        let p = at(dwell);
        if confidence * p.sigma_deg <= tolerance_deg {
            return DwellAnswer::Meets {
                dwell_s: dwell,
                prediction: p,
            };
        }
        if p.sigma_deg < best.1.sigma_deg {
            best = (dwell, p);
        }
        // finer where it matters, coarser on long dwells: 1 s steps to a minute, then 2 %
        dwell = if dwell < 60.0 {
            dwell + 1.0
        } else {
            (dwell * 1.02).ceil()
        };
    }
    DwellAnswer::Cannot {
        best_dwell_s: best.0,
        prediction: best.1,
    }
}

/// The highest latitude (deg, either hemisphere) at which some dwell from `min_s` to `max_s`
/// meets the tolerance at the confidence; `None` when none does even at the equator.
pub fn latitude_limit(
    plan: &DrillPlan,
    tolerance_deg: f64,
    confidence: f64,
    min_s: f64,
    max_s: f64,
) -> Option<f64> {
    let meets = |lat: f64| {
        matches!(
            dwell_for(
                &DrillPlan {
                    latitude_deg: lat,
                    ..plan.clone()
                },
                tolerance_deg,
                confidence,
                min_s,
                max_s
            ),
            DwellAnswer::Meets { .. }
        )
    };
    if !meets(0.0) {
        return None;
    }
    let (mut lo, mut hi) = (0.0, 89.999);
    if meets(hi) {
        return Some(hi);
    }
    for _ in 0..24 {
        let mid = 0.5 * (lo + hi);
        if meets(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(lo)
}

/// Before a drill: its predicted sigma and, when a tolerance is stated and the drill cannot
/// meet it at the confidence, what would (a dwell from 5 s to 600 s), as nav says it at
/// start-up.
pub fn check_drill(plan: &DrillPlan, cfg: &PlanConfig) -> (Prediction, Option<String>) {
    let p = predict(plan);
    let k = cfg.confidence;
    if cfg.tolerance_deg <= 0.0 || k * p.sigma_deg <= cfg.tolerance_deg {
        return (p, None);
    }
    let head = format!(
        "north-finding cannot meet {} deg at {k} sigma with {:.0} s dwells at latitude {:.4} deg: predicted sigma {:.4} deg",
        cfg.tolerance_deg, plan.dwell_s, plan.latitude_deg, p.sigma_deg
    );
    let tail = match dwell_for(plan, cfg.tolerance_deg, k, 5.0, 600.0) {
        DwellAnswer::Meets {
            dwell_s,
            prediction,
        } => format!(
            "; a dwell of {dwell_s:.0} s would (sigma {:.4} deg)",
            prediction.sigma_deg
        ),
        DwellAnswer::Cannot {
            best_dwell_s,
            prediction,
        } => format!(
            "; no dwell up to 600 s would: the best, {best_dwell_s:.0} s, gives {:.4} deg",
            prediction.sigma_deg
        ),
    };
    (p, Some(head + &tail))
}

/// The table positions of an `n`-position drill (2, 4 or 8, equally spaced), visited out and
/// back (`0, 90, 180, 270, 270, 180, 90, 0` for four): every position's mean time is the
/// drill's middle, so a bias drifting linearly cancels like a constant one. The repeated middle
/// position is one dwell after another without a move.
pub fn out_and_back(n: usize) -> Vec<f64> {
    let out = equally_spaced(n);
    out.iter().chain(out.iter().rev()).copied().collect()
}

/// `n` table positions equally spaced from 0 deg (0, 90, 180, 270 for four).
pub fn equally_spaced(n: usize) -> Vec<f64> {
    let step = 360.0 / n.max(1) as f64;
    (0..n).map(|k| k as f64 * step).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(lat: f64, dwell: f64, noise: GyroNoise) -> DrillPlan {
        DrillPlan {
            latitude_deg: lat,
            positions_deg: vec![0.0, 90.0, 180.0, 270.0],
            dwell_s: dwell,
            index_time_s: 6.0,
            noise,
        }
    }

    fn white_only() -> GyroNoise {
        GyroNoise {
            drift_dph: 0.0,
            end_angle_arcsec: 0.0,
            index_arcsec: 0.0,
            ..GyroNoise::default()
        }
    }

    #[test]
    fn white_noise_alone_gives_the_textbook_bound() {
        for (lat, dwell) in [(0.0, 60.0), (28.2, 15.0), (-60.0, 300.0)] {
            let p = predict(&plan(lat, dwell, white_only()));
            let n = (0.1f64 / 60.0).to_radians() / 60.0;
            let w = earth::OMEGA_IE * f64::to_radians(lat).cos();
            let want = (n / (w * (4.0 * dwell).sqrt())).to_degrees();
            assert!((p.sigma_deg / want - 1.0).abs() < 1e-9, "{p:?} {want}");
            assert_eq!(p.drift_deg, 0.0);
        }
    }

    #[test]
    fn a_drifting_bias_has_a_best_dwell_and_out_and_back_cancels_its_linear_part() {
        let noise = GyroNoise {
            arw_dpsh: 0.0,
            end_angle_arcsec: 0.0,
            index_arcsec: 0.0,
            drift_tau_s: 1e6,
            ..GyroNoise::default()
        };
        // a bias wandering like a random walk over the drill: worse the longer it lasts
        let short = predict(&plan(28.2, 30.0, noise));
        let long = predict(&plan(28.2, 300.0, noise));
        assert!(long.drift_deg > 2.0 * short.drift_deg, "{short:?} {long:?}");
        // out and back over the same total dwell: much less of it
        let ob = predict(&DrillPlan {
            positions_deg: out_and_back(4),
            dwell_s: 150.0,
            ..plan(28.2, 300.0, noise)
        });
        assert!(ob.drift_deg < 0.6 * long.drift_deg, "{ob:?} {long:?}");
        // with white noise too, a tolerance is met by a dwell in between, or not at all
        let full = plan(28.2, 60.0, GyroNoise::default());
        match dwell_for(&full, 0.2, 3.0, 5.0, 600.0) {
            DwellAnswer::Meets { dwell_s, .. } => assert!(dwell_s > 5.0 && dwell_s < 600.0),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            dwell_for(&full, 0.1, 3.0, 5.0, 600.0),
            DwellAnswer::Cannot { .. }
        ));
    }

    #[test]
    fn the_latitude_limit_is_where_the_best_dwell_just_meets_the_tolerance() {
        let base = plan(0.0, 60.0, GyroNoise::default());
        // the paper's drift: 0.1 deg at 3 sigma is out of reach even at the equator
        assert_eq!(latitude_limit(&base, 0.1, 3.0, 5.0, 600.0), None);
        let lim = latitude_limit(&base, 0.2, 3.0, 5.0, 600.0).unwrap();
        assert!(lim > 30.0 && lim < 89.0, "{lim}");
        for (lat, meets) in [(lim - 0.5, true), (lim + 0.5, false), (-(lim + 0.5), false)] {
            let p = DrillPlan {
                latitude_deg: lat,
                ..base.clone()
            };
            let a = dwell_for(&p, 0.2, 3.0, 5.0, 600.0);
            assert_eq!(
                matches!(a, DwellAnswer::Meets { .. }),
                meets,
                "{lat}: {a:?}"
            );
        }
        assert_eq!(out_and_back(2), vec![0.0, 180.0, 180.0, 0.0]);
    }

    /// nav's own check at start-up, from its config: silent when the drill meets the stated
    /// tolerance or none is stated, else the dwell that would meet it.
    #[test]
    fn nav_says_before_a_drill_when_its_dwell_cannot_meet_the_tolerance() {
        let mut nf = crate::procedures::north_finding::NorthFindingConfig {
            latitude_deg: -70.0,
            dwell_s: 10.0,
            ..Default::default()
        };
        assert_eq!(nf.check_plan().1, None, "no tolerance stated");
        nf.plan.tolerance_deg = 0.5;
        let (p, why) = nf.check_plan();
        let why = why.unwrap();
        assert!(3.0 * p.sigma_deg > 0.5);
        assert!(
            why.contains("cannot meet 0.5 deg") && why.contains("would"),
            "{why}"
        );
        let d: f64 = why
            .split("a dwell of ")
            .nth(1)
            .and_then(|t| t.split(' ').next())
            .and_then(|t| t.parse().ok())
            .unwrap();
        nf.dwell_s = d;
        assert_eq!(nf.check_plan().1, None, "{d} s meets it");
        nf.plan.confidence = -1.0;
        assert!(nf.check().unwrap_err().to_string().contains("confidence"));
    }
}
