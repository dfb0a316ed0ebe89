//! A redundant MEMS IMU: four gyros in paper 001's tetrahedral layout, with per-gyro bias,
//! scale-factor error, two mounting angles and noise (the paper's eq. 7), as a pure function of
//! the body rate.
//!
//! Layout: gyro 1 along `-z`; gyros 2, 3, 4 at 70.53 deg from `z` (cos = 1/3), at azimuths 0
//! (in the x-z plane), 120 and 240 deg. Each gyro `i` has its sensitive axis `P_i` and two axes
//! `R_j`, `R_k` completing a right-handed triad; its small mounting angles `sigma_j`, `sigma_k`
//! are rotations about those, so that it reads
//! `w_m = P^T w + R_k^T w sigma_j - R_j^T w sigma_k - K P^T w - B - eta`.

use nalgebra::Vector3;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// Number of gyros.
pub const GYROS: usize = 4;

/// The nominal triad of gyro `i` (0-based): `(P, R_j, R_k)`, unit vectors in body axes.
pub fn triad(i: usize) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let p = if i == 0 {
        Vector3::new(0.0, 0.0, -1.0)
    } else {
        let theta = (1.0f64 / 3.0).acos();
        let az = (120.0 * (i - 1) as f64).to_radians();
        Vector3::new(theta.sin() * az.cos(), theta.sin() * az.sin(), theta.cos())
    };
    // R_j: horizontal, at right angles to P (x for the vertical gyro)
    let rj = if i == 0 {
        Vector3::x()
    } else {
        Vector3::z().cross(&p).normalize()
    };
    let rk = p.cross(&rj);
    (p, rj, rk)
}

/// The four gyros' errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TetraParams {
    /// Bias `B`, deg/s, per gyro.
    pub bias_dps: [f64; GYROS],
    /// Scale-factor error `K`, per gyro (fraction).
    pub scale_factor: [f64; GYROS],
    /// Mounting angle `sigma_j`, deg, per gyro.
    pub sigma_j_deg: [f64; GYROS],
    /// Mounting angle `sigma_k`, deg, per gyro.
    pub sigma_k_deg: [f64; GYROS],
    /// White noise, deg/s, 1 sigma per sample.
    pub noise_dps: f64,
    /// Random seed of the noise.
    pub seed: u64,
}

impl Default for TetraParams {
    /// A MEMS unit of the paper's class (its table of coefficients did not survive in our
    /// copy): biases of a few hundredths of a deg/s, scale factors of 1e-3, mounting angles of
    /// a tenth of a degree; the paper's noise (1e-3 deg/h, next to nothing).
    fn default() -> Self {
        Self {
            bias_dps: [0.05, -0.04, 0.06, -0.03],
            scale_factor: [2e-3, -1.5e-3, 1e-3, 2.5e-3],
            sigma_j_deg: [0.1, -0.08, 0.12, 0.05],
            sigma_k_deg: [-0.1, 0.06, -0.09, 0.07],
            noise_dps: 1e-3 / 3600.0,
            seed: 1,
        }
    }
}

/// The four gyros, sampled.
pub struct TetraGyros {
    p: TetraParams,
    rng: StdRng,
    noise: Normal<f64>,
}

impl TetraGyros {
    /// Gyros with these errors.
    pub fn new(p: TetraParams) -> Self {
        let noise = Normal::new(0.0, p.noise_dps.max(0.0)).unwrap_or_else(|_| {
            Normal::new(0.0, 0.0).expect("a zero-width normal distribution is valid")
        });
        Self {
            rng: StdRng::seed_from_u64(p.seed),
            noise,
            p,
        }
    }

    /// The errors.
    pub fn params(&self) -> &TetraParams {
        &self.p
    }

    /// One sample of the four gyros (deg/s) at body rate `w` (deg/s).
    pub fn sample(&mut self, w: &Vector3<f64>) -> [f64; GYROS] {
        std::array::from_fn(|i| {
            let (p, rj, rk) = triad(i);
            let pw = p.dot(w);
            pw + rk.dot(w) * self.p.sigma_j_deg[i].to_radians()
                - rj.dot(w) * self.p.sigma_k_deg[i].to_radians()
                - self.p.scale_factor[i] * pw
                - self.p.bias_dps[i]
                - self.noise.sample(&mut self.rng)
        })
    }
}

/// A failure of one gyro, from a time on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum GyroFailure {
    /// The output freezes at its last value.
    Stuck {
        /// The gyro (0-based).
        gyro: usize,
        /// From, s.
        at_s: f64,
    },
    /// The bias jumps.
    BiasJump {
        /// The gyro (0-based).
        gyro: usize,
        /// From, s.
        at_s: f64,
        /// The jump, deg/s.
        jump_dps: f64,
    },
    /// The noise grows.
    NoiseBurst {
        /// The gyro (0-based).
        gyro: usize,
        /// From, s.
        at_s: f64,
        /// Noise added, deg/s (1 sigma per sample).
        sigma_dps: f64,
    },
}

/// Applies a [`GyroFailure`] to the outputs, sample by sample.
pub struct FailureInjector {
    failure: GyroFailure,
    held: Option<f64>,
    rng: StdRng,
}

impl FailureInjector {
    /// The failure, with its own random stream (`seed`).
    pub fn new(failure: GyroFailure, seed: u64) -> Self {
        Self {
            failure,
            held: None,
            rng: StdRng::seed_from_u64(seed ^ 0xFA11),
        }
    }

    /// The outputs at `t` s, failed where due.
    pub fn apply(&mut self, t: f64, out: &mut [f64; GYROS]) {
        match self.failure {
            GyroFailure::Stuck { gyro, at_s } => {
                if t < at_s {
                    self.held = Some(out[gyro]);
                } else if let Some(h) = self.held {
                    out[gyro] = h;
                }
            }
            GyroFailure::BiasJump {
                gyro,
                at_s,
                jump_dps,
            } if t >= at_s => out[gyro] += jump_dps,
            GyroFailure::NoiseBurst {
                gyro,
                at_s,
                sigma_dps,
            } if t >= at_s => {
                if let Ok(n) = Normal::new(0.0, sigma_dps) {
                    out[gyro] += n.sample(&mut self.rng);
                }
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The four axes are the tetrahedron's: unit, 109.47 deg apart, summing to zero; each triad
    /// is right-handed and orthonormal.
    #[test]
    fn the_layout_is_a_regular_tetrahedron() {
        let mut sum = Vector3::zeros();
        for i in 0..GYROS {
            let (p, rj, rk) = triad(i);
            sum += p;
            assert!((p.norm() - 1.0).abs() < 1e-15);
            assert!(p.dot(&rj).abs() < 1e-15 && p.dot(&rk).abs() < 1e-15);
            assert!((p.cross(&rj) - rk).norm() < 1e-15);
            for j in 0..i {
                let c = p.dot(&triad(j).0);
                assert!((c + 1.0 / 3.0).abs() < 1e-12, "{i} {j}: {c}");
            }
        }
        assert!(sum.norm() < 1e-12);
        // gyro 2 lies in the x-z plane
        assert!(triad(1).0.y.abs() < 1e-15);
    }

    #[test]
    fn an_error_free_gyro_reads_its_axis_rate() {
        let mut g = TetraGyros::new(TetraParams {
            bias_dps: [0.0; 4],
            scale_factor: [0.0; 4],
            sigma_j_deg: [0.0; 4],
            sigma_k_deg: [0.0; 4],
            noise_dps: 0.0,
            seed: 1,
        });
        let w = Vector3::new(1.0, 2.0, 3.0);
        let o = g.sample(&w);
        for (i, v) in o.iter().enumerate() {
            assert!((v - triad(i).0.dot(&w)).abs() < 1e-15);
        }
    }
}

/// The redundant unit on the bus: its gyros, their pulse weight and an optional failure (the
/// `[imu.tetra]` table of a scenario). It rides on the bench's IMU and is sampled on its strobe:
/// one MEMS_GYRO frame after each IMU sample's frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TetraUnit {
    /// The gyros' errors.
    pub gyros: TetraParams,
    /// Pulse weight, deg per pulse (the 14-bit counters then carry up to
    /// `8191 pulse_deg rate_hz` deg/s).
    pub pulse_deg: f64,
    /// A failure of one gyro.
    pub failure: Option<GyroFailure>,
}

impl Default for TetraUnit {
    fn default() -> Self {
        Self {
            gyros: TetraParams::default(),
            pulse_deg: 1e-4,
            failure: None,
        }
    }
}

/// The redundant unit's state: gyros, failure and pulse counters.
pub struct TetraStream {
    unit: TetraUnit,
    gyros: TetraGyros,
    failure: Option<FailureInjector>,
    counters: [crate::imu::pulse::PulseCounter; GYROS],
}

impl TetraStream {
    /// The unit's stream.
    pub fn new(unit: TetraUnit) -> Self {
        let seed = unit.gyros.seed;
        Self {
            gyros: TetraGyros::new(unit.gyros.clone()),
            failure: unit.failure.map(|f| FailureInjector::new(f, seed)),
            counters: Default::default(),
            unit,
        }
    }

    /// The unit.
    pub fn unit(&self) -> &TetraUnit {
        &self.unit
    }

    /// The frame of the sample ending at `t1` (s), `dt` long, with true body angle increment
    /// `dtheta` (rad), for IMU sample counter `sample_counter`.
    pub fn frame(
        &mut self,
        t1: f64,
        dt: f64,
        dtheta: &Vector3<f64>,
        sample_counter: u16,
    ) -> wire::MemsGyro {
        let w = dtheta.map(f64::to_degrees) / dt;
        let mut out = self.gyros.sample(&w);
        if let Some(f) = self.failure.as_mut() {
            f.apply(t1, &mut out);
        }
        for (c, o) in self.counters.iter_mut().zip(out) {
            c.add(o * dt / self.unit.pulse_deg);
        }
        wire::MemsGyro {
            counts: std::array::from_fn(|i| self.counters[i].total.rem_euclid(1 << 14) as u16),
            sample_counter_low: (sample_counter & 0xFF) as u8,
        }
    }
}
