//! Rates from paper 001's redundant IMU (four gyros, tetrahedral) with one failed gyro detected
//! by the parity check, isolated where the evidence allows, and left out.
//!
//! Four gyros measure three rates: the least-squares rate `w = (H^T H)^-1 H^T m` (`H` the
//! sensitive axes, [`crate::procedures::rotating_estimator::tetra_triad`]) leaves one parity residual `p = v^T m`, with
//! `v^T H = 0`, `|v| = 1` (for the regular tetrahedron `v = [1, 1, 1, 1] / 2`), which is pure
//! noise while every gyro is healthy. Its mean over a window beyond `k` sigma is an alarm.
//!
//! With one parity equation every gyro's failure moves `p` along the same line, so `p` alone
//! cannot say which gyro failed. The monitor isolates with what else there is:
//! - a **reference rate** (a calibration table's, or a vehicle known to be at rest): the gyro
//!   whose output is furthest from the reference, in noise sigmas;
//! - without one, the failure's **signature**: an output that has not changed at all for a
//!   window while the parity alarms (stuck), or a gyro whose scatter (the median square of its
//!   second differences, which ignores smooth motion, its corners and a step) is many times its
//!   noise while the others' is not (noise burst);
//! - otherwise (a bias jump with no reference) the failure is reported as detected but not
//!   isolable, and all four gyros stay in use.
//!
//! Once a gyro is isolated, the rate comes from the other three (exactly determined: no parity
//! is left, so a second failure could not be detected; the status says so).

use crate::procedures::rotating_estimator::{TETRA_GYROS, tetra_triad};
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use std::collections::VecDeque;

/// The parity vector `v` (`v^T H = 0`, `|v| = 1`).
pub fn parity_vector() -> [f64; TETRA_GYROS] {
    // H's columns are orthogonal to [1, 1, 1, 1] (the axes sum to zero); fix the sign so that
    // gyro 1 has +1/2
    [0.5; TETRA_GYROS]
}

/// Least-squares rate from the gyros in `use_` (at least three) of the nominal layout, deg/s.
pub fn rate(outputs: &[f64; TETRA_GYROS], use_: [bool; TETRA_GYROS]) -> Option<Vector3<f64>> {
    rate_through(&std::array::from_fn(|i| tetra_triad(i)[0]), outputs, use_)
}

/// Least-squares rate from the gyros in `use_` whose outputs are `axes[i] . w`, deg/s.
pub fn rate_through(
    axes: &[Vector3<f64>; TETRA_GYROS],
    outputs: &[f64; TETRA_GYROS],
    use_: [bool; TETRA_GYROS],
) -> Option<Vector3<f64>> {
    let (mut hth, mut htm) = (Matrix3::zeros(), Vector3::zeros());
    for i in (0..TETRA_GYROS).filter(|&i| use_[i]) {
        let p = axes[i];
        hth += p * p.transpose();
        htm += p * outputs[i];
    }
    Some(hth.try_inverse()? * htm)
}

/// How many times any other gyro's RMS departure from the reference the failed gyro's must be.
pub const DOMINANCE: f64 = 3.0;

/// How a failure was told apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Isolation {
    /// Against a reference rate.
    Reference,
    /// Its output stopped changing.
    Stuck,
    /// Its scatter grew.
    Noise,
}

/// The monitor's state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum Status {
    /// All four agree.
    Healthy,
    /// The parity alarms but no gyro can be singled out: all four stay in use.
    DetectedNotIsolated {
        /// Sample of the alarm.
        since: u64,
    },
    /// A gyro is left out.
    Isolated {
        /// The gyro (0-based).
        gyro: usize,
        /// How it was told apart.
        by: Isolation,
        /// Sample of the isolation.
        at: u64,
    },
}

/// The parity monitor.
#[derive(Debug, Clone)]
pub struct ParityMonitor {
    sigma: f64,
    k: f64,
    window: usize,
    parity: VecDeque<f64>,
    parity_sum: f64,
    recent: VecDeque<[f64; TETRA_GYROS]>,
    /// The reference rate of each of `recent`'s samples, where there was one.
    references: VecDeque<Option<Vector3<f64>>>,
    n: u64,
    status: Status,
    last_parity: f64,
}

impl ParityMonitor {
    /// A monitor for gyros of white noise `sigma_dps` (per sample), alarming when the parity's
    /// mean over `window` samples passes `k` sigmas of that mean.
    pub fn new(sigma_dps: f64, k: f64, window: usize) -> Self {
        Self {
            sigma: sigma_dps.max(1e-12),
            k,
            window: window.max(2),
            parity: VecDeque::new(),
            parity_sum: 0.0,
            recent: VecDeque::new(),
            references: VecDeque::new(),
            n: 0,
            status: Status::Healthy,
            last_parity: 0.0,
        }
    }

    /// The state.
    pub fn status(&self) -> Status {
        self.status
    }

    /// The latest parity residual, deg/s.
    pub fn parity(&self) -> f64 {
        self.last_parity
    }

    /// One sample of the four gyros (deg/s), with a reference rate (deg/s, body axes) when one
    /// is known; the rate from the gyros in use.
    pub fn update(
        &mut self,
        outputs: &[f64; TETRA_GYROS],
        reference: Option<&Vector3<f64>>,
    ) -> Option<Vector3<f64>> {
        self.n += 1;
        let v = parity_vector();
        let p: f64 = (0..TETRA_GYROS).map(|i| v[i] * outputs[i]).sum();
        self.last_parity = p;
        self.parity.push_back(p);
        self.parity_sum += p;
        if self.parity.len() > self.window {
            self.parity_sum -= self.parity.pop_front().unwrap_or(0.0);
        }
        self.recent.push_back(*outputs);
        self.references.push_back(reference.copied());
        if self.recent.len() > self.window {
            self.recent.pop_front();
            self.references.pop_front();
        }
        let alarm = self.parity.len() == self.window
            && (self.parity_sum / self.window as f64).abs()
                > self.k * self.sigma / (self.window as f64).sqrt();
        if alarm && !matches!(self.status, Status::Isolated { .. }) {
            self.status = match self.isolate(reference) {
                Some((gyro, by)) => Status::Isolated {
                    gyro,
                    by,
                    at: self.n,
                },
                None => match self.status {
                    Status::DetectedNotIsolated { since } => Status::DetectedNotIsolated { since },
                    _ => Status::DetectedNotIsolated { since: self.n },
                },
            };
        }
        let mut use_ = [true; TETRA_GYROS];
        if let Status::Isolated { gyro, .. } = self.status {
            use_[gyro] = false;
        }
        rate(outputs, use_)
    }

    /// The gyro that stands out against the reference over the window ([`Self::isolate`]).
    fn against_reference(&self) -> Option<usize> {
        let mut ss = [0.0; TETRA_GYROS];
        let mut n = 0usize;
        for (o, w) in self.recent.iter().zip(&self.references) {
            let Some(w) = w else { continue };
            n += 1;
            for (i, s) in ss.iter_mut().enumerate() {
                *s += (o[i] - tetra_triad(i)[0].dot(w)).powi(2);
            }
        }
        if n == 0 {
            return None;
        }
        let mut rms: Vec<(usize, f64)> = ss
            .iter()
            .enumerate()
            .map(|(i, s)| (i, (s / n as f64).sqrt()))
            .collect();
        rms.sort_by(|a, b| b.1.total_cmp(&a.1));
        let (i, first) = rms[0];
        let second = rms[1].1;
        (first > self.k * self.sigma && first > DOMINANCE * second).then_some(i)
    }

    /// Which gyro failed, and how that is known.
    ///
    /// Against the reference, the gyro whose RMS departure from it over the window is beyond
    /// `k` sigmas and at least [`DOMINANCE`] times any other gyro's: one sample alone is not
    /// enough (where the table starts or stops turning, the reference, a rate from the
    /// encoders over a window, departs from every gyro for a moment, and the largest departure
    /// can then be a healthy gyro's while a stuck one still reads what the table did before).
    /// When the reference decides nothing, the signatures below may.
    fn isolate(&self, reference: Option<&Vector3<f64>>) -> Option<(usize, Isolation)> {
        let last = self.recent.back()?;
        if reference.is_some()
            && let Some(i) = self.against_reference()
        {
            return Some((i, Isolation::Reference));
        }
        // stuck: not a single change over the window, while the others moved
        let still: Vec<usize> = (0..TETRA_GYROS)
            .filter(|&i| self.recent.iter().all(|o| o[i] == last[i]))
            .collect();
        if still.len() == 1 && self.recent.len() == self.window {
            return Some((still[0], Isolation::Stuck));
        }
        // a noise burst: one gyro's scatter far beyond its noise. Second differences take
        // out the motion (a table's constant rates and constant-acceleration ramps leave at most
        // a spike at each corner) and their median ignores such spikes and a bias jump's step;
        // for white noise d2 has variance 6 sigma^2, and the median of its square is 0.455 of it
        let loud: Vec<usize> = (0..TETRA_GYROS)
            .filter(|&i| {
                let mut d2: Vec<f64> = self
                    .recent
                    .iter()
                    .zip(self.recent.iter().skip(1))
                    .zip(self.recent.iter().skip(2))
                    .map(|((a, b), c)| (c[i] - 2.0 * b[i] + a[i]).powi(2))
                    .collect();
                if d2.is_empty() {
                    return false;
                }
                d2.sort_by(f64::total_cmp);
                d2[d2.len() / 2] > 9.0 * 0.455 * 6.0 * self.sigma * self.sigma
            })
            .collect();
        if loud.len() == 1 {
            return Some((loud[0], Isolation::Noise));
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Outputs of healthy gyros at rate `w` with white noise from a small generator.
    struct Gen(u64);
    impl Gen {
        fn gauss(&mut self) -> f64 {
            // sum of 12 uniforms: near enough a unit Gaussian for a test
            (0..12)
                .map(|_| {
                    self.0 = self
                        .0
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (self.0 >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        }
        fn outputs(&mut self, w: &Vector3<f64>, sigma: f64) -> [f64; TETRA_GYROS] {
            std::array::from_fn(|i| tetra_triad(i)[0].dot(w) + sigma * self.gauss())
        }
    }

    fn w_at(k: u64) -> Vector3<f64> {
        let t = k as f64 / 100.0;
        Vector3::new(20.0 * (0.3 * t).sin(), 5.0 * (0.7 * t).cos(), 10.0)
    }

    /// Run 3000 samples with a failure from sample 1000 (`fail` changes the outputs).
    fn scenario(
        mut fail: impl FnMut(u64, &mut [f64; TETRA_GYROS], &[f64; TETRA_GYROS]),
        with_reference: bool,
    ) -> (Status, f64) {
        let sigma = 0.05;
        let mut g = Gen(7);
        let mut m = ParityMonitor::new(sigma, 5.0, 50);
        let mut held = [0.0; TETRA_GYROS];
        let mut worst: f64 = 0.0;
        for k in 0..3000 {
            let w = w_at(k);
            let mut o = g.outputs(&w, sigma);
            if k < 1000 {
                held = o;
            } else {
                fail(k, &mut o, &held);
            }
            let r = m.update(&o, with_reference.then_some(&w)).unwrap();
            if k > 1500 {
                worst = worst.max((r - w).norm());
            }
        }
        (m.status(), worst)
    }

    #[test]
    fn the_parity_vector_is_orthogonal_to_every_axis() {
        let v = parity_vector();
        for j in 0..3 {
            let s: f64 = (0..TETRA_GYROS).map(|i| v[i] * tetra_triad(i)[0][j]).sum();
            assert!(s.abs() < 1e-15);
        }
        assert!((v.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn healthy_gyros_raise_no_alarm() {
        let (st, worst) = scenario(|_, _, _| {}, false);
        assert_eq!(st, Status::Healthy);
        assert!(worst < 0.3, "{worst}");
    }

    /// A stuck gyro, a noise burst and a bias jump (with a reference) are each isolated and the
    /// rate from the other three is right; a bias jump without a reference is detected only.
    #[test]
    fn each_failure_is_detected_and_isolated_where_it_can_be() {
        let stuck = scenario(|_, o, held| o[1] = held[1], false);
        assert!(
            matches!(
                stuck.0,
                Status::Isolated {
                    gyro: 1,
                    by: Isolation::Stuck,
                    ..
                }
            ),
            "{stuck:?}"
        );
        assert!(stuck.1 < 0.5, "{stuck:?}");
        let mut g = Gen(99);
        let burst = scenario(move |_, o, _| o[3] += 2.0 * g.gauss(), false);
        assert!(
            matches!(
                burst.0,
                Status::Isolated {
                    gyro: 3,
                    by: Isolation::Noise,
                    ..
                }
            ),
            "{burst:?}"
        );
        assert!(burst.1 < 0.5, "{burst:?}");
        let jump = scenario(|_, o, _| o[2] += 1.0, true);
        assert!(
            matches!(
                jump.0,
                Status::Isolated {
                    gyro: 2,
                    by: Isolation::Reference,
                    ..
                }
            ),
            "{jump:?}"
        );
        assert!(jump.1 < 0.5, "{jump:?}");
        let blind = scenario(|_, o, _| o[2] += 1.0, false);
        assert!(
            matches!(blind.0, Status::DetectedNotIsolated { since } if since > 1000),
            "{blind:?}"
        );
    }
}
