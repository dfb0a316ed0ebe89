//! Online gyro self-calibration of a dual-axis rotating IMU on a static base (paper 004).
//!
//! The mechanism: the inner axis turns the IMU about its own x axis (angle `a_x`), the outer
//! axis turns that about the vehicle's z axis (angle `a_z`): `C_p^b = Rz(a_z) Rx(a_x)`. Each
//! gyro reads `w_out = (1 + dK) w_in + eps + noise`.
//!
//! - [`GyroRls`]: the paper's decoupled recursive least squares. With the base levelled and its
//!   heading known roughly, each gyro's input is known from the latitude, the coarse attitude and
//!   the axis angles and rates ([`expected_rate`]); the small couplings between channels are
//!   neglected, so each gyro is its own two-state problem `X = [eps, dK]`, `H = [1, w_exp]`,
//!   `X0 = 0`, `P0` the squares of the nominal errors, `R` the gyro noise variance.
//! - [`AlignKf`]: the comparison, a 14-state static-base alignment Kalman filter on the
//!   velocity the strapdown navigation computes (zero on a static base): attitude errors (3),
//!   horizontal velocity errors (2), accelerometer biases (3), gyro biases (3) and gyro
//!   scale-factor errors (3), closed loop on attitude and velocity.
//!
//! Units: rad, rad/s, m/s; scale-factor errors as fractions (1e-6 = 1 ppm).

use crate::navigation::earth;
use crate::navigation::strapdown::NavState;
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, UnitQuaternion, Vector2, Vector3};

/// `C_p^b` of the mechanism at axis angles `a_x` (inner, about the IMU's x) and `a_z` (outer,
/// about the vehicle's z), rad.
pub fn c_p_b(a_x: f64, a_z: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a_z)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), a_x)
}

/// The IMU's rate relative to inertial space in its own axes (`w_ip^p`), rad/s, on a static base
/// at latitude `lat` with body-to-ENU attitude `q_nb`, axis angles `[a_x, a_z]` and axis rates
/// `[w_x, w_z]`: the earth's rate seen through the mechanism plus the mechanism's own rates.
pub fn expected_rate(
    lat: f64,
    q_nb: &UnitQuaternion<f64>,
    angles: [f64; 2],
    rates: [f64; 2],
) -> Vector3<f64> {
    table_rate(
        lat,
        q_nb,
        &[
            (Vector3::z_axis(), angles[1], rates[1]),
            (Vector3::x_axis(), angles[0], rates[0]),
        ],
    )
}

/// The rate relative to inertial space, in its own axes, of what a mechanism's axes carry on a
/// static base at latitude `lat` whose attitude is `q_nb` (base to ENU): `axes` from the
/// outermost in, each `(axis, angle rad, rate rad/s)`, the axis fixed in the frame that carries
/// it. Each axis adds its rate to the earth's rate turned into the next frame.
pub fn table_rate(
    lat: f64,
    q_nb: &UnitQuaternion<f64>,
    axes: &[(nalgebra::Unit<Vector3<f64>>, f64, f64)],
) -> Vector3<f64> {
    let mut w = q_nb.inverse() * Vector3::from(earth::earth_rate_enu(lat));
    for (axis, angle, rate) in axes {
        w = UnitQuaternion::from_axis_angle(axis, *angle).inverse() * w + axis.into_inner() * *rate;
    }
    w
}

/// Gyros of paper 001's redundant IMU.
pub const TETRA_GYROS: usize = 4;

/// The nominal triad of gyro `i` (0-based) of paper 001's tetrahedral layout: sensitive axis
/// `P` (gyro 1 along `-z`; gyros 2-4 at 70.53 deg from `z`, azimuths 0, 120, 240 deg) and the
/// two axes `R_j` (horizontal; `x` for gyro 1) and `R_k = P x R_j` of its mounting angles.
pub fn tetra_triad(i: usize) -> [Vector3<f64>; 3] {
    let p = match i {
        0 => -Vector3::z(),
        _ => {
            let cos_t = 1.0 / 3.0;
            let sin_t = (1.0f64 - cos_t * cos_t).sqrt();
            let az = (120.0 * (i - 1) as f64).to_radians();
            Vector3::new(sin_t * az.cos(), sin_t * az.sin(), cos_t)
        }
    };
    let rj = match i {
        0 => Vector3::x(),
        _ => Vector3::z().cross(&p).normalize(),
    };
    [p, rj, p.cross(&rj)]
}

/// Coefficients of one gyro of the redundant IMU: bias `B` (deg/s), scale-factor error `K`,
/// mounting angles `sigma_j`, `sigma_k` (rad), in paper 001's model
/// `w_m = P^T w + R_k^T w sigma_j - R_j^T w sigma_k - K P^T w - B`.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GyroCoefficients {
    /// Bias, deg/s.
    pub bias_dps: f64,
    /// Scale-factor error.
    pub scale_factor: f64,
    /// Mounting angle about `R_j`, rad.
    pub sigma_j: f64,
    /// Mounting angle about `R_k`, rad.
    pub sigma_k: f64,
}

impl GyroCoefficients {
    /// The axis gyro `i` with these coefficients senses (its output plus its bias is this axis
    /// dotted with the rate): `(1 - K) P + sigma_j R_k - sigma_k R_j`.
    pub fn sensing_axis(&self, i: usize) -> Vector3<f64> {
        let [p, rj, rk] = tetra_triad(i);
        p * (1.0 - self.scale_factor) + rk * self.sigma_j - rj * self.sigma_k
    }

    /// Gyro `i`'s output corrected to what a perfect gyro on its nominal axis would read, the
    /// body turning at about `w` (deg/s; its mounting angles' small cross terms only).
    pub fn correct(&self, i: usize, output: f64, w: &Vector3<f64>) -> f64 {
        let [_, rj, rk] = tetra_triad(i);
        (output + self.bias_dps - rk.dot(w) * self.sigma_j + rj.dot(w) * self.sigma_k)
            / (1.0 - self.scale_factor)
    }
}

/// Paper 001's 16-state Kalman calibration: the four gyros' coefficients as constant states,
/// each gyro's output error against the turntable's known rate as the measurement.
#[derive(Debug, Clone)]
pub struct TetraKf {
    x: SVector<f64, 16>,
    p: SMatrix<f64, 16, 16>,
    r: f64,
}

impl TetraKf {
    /// `P0 = p0 I`, `R = r I` (the paper: 1 and 1e-3; rates in deg/s, angles in rad).
    pub fn new(p0: f64, r: f64) -> Self {
        Self {
            x: SVector::zeros(),
            p: SMatrix::identity() * p0,
            r,
        }
    }

    /// One sample: the gyros' outputs (deg/s) and the body rate the table says (deg/s).
    pub fn update(&mut self, outputs: &[f64; TETRA_GYROS], w: &Vector3<f64>) {
        let mut h = SMatrix::<f64, TETRA_GYROS, 16>::zeros();
        let mut z = SVector::<f64, TETRA_GYROS>::zeros();
        for i in 0..TETRA_GYROS {
            let [p, rj, rk] = tetra_triad(i);
            let pw = p.dot(w);
            z[i] = outputs[i] - pw;
            h[(i, 4 * i)] = -1.0;
            h[(i, 4 * i + 1)] = -pw;
            h[(i, 4 * i + 2)] = rk.dot(w);
            h[(i, 4 * i + 3)] = -rj.dot(w);
        }
        let r = SMatrix::<f64, TETRA_GYROS, TETRA_GYROS>::identity() * self.r;
        let s = h * self.p * h.transpose() + r;
        let Some(si) = s.try_inverse() else {
            return;
        };
        let k = self.p * h.transpose() * si;
        self.x += k * (z - h * self.x);
        let ikh = SMatrix::<f64, 16, 16>::identity() - k * h;
        self.p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
    }

    /// The estimates' standard deviations (the filter's own), per gyro, in the units of
    /// [`GyroCoefficients`].
    pub fn sigmas(&self) -> [GyroCoefficients; TETRA_GYROS] {
        let sd = |j: usize| self.p[(j, j)].max(0.0).sqrt();
        std::array::from_fn(|i| GyroCoefficients {
            bias_dps: sd(4 * i),
            scale_factor: sd(4 * i + 1),
            sigma_j: sd(4 * i + 2),
            sigma_k: sd(4 * i + 3),
        })
    }

    /// The estimates, per gyro.
    pub fn coefficients(&self) -> [GyroCoefficients; TETRA_GYROS] {
        std::array::from_fn(|i| GyroCoefficients {
            bias_dps: self.x[4 * i],
            scale_factor: self.x[4 * i + 1],
            sigma_j: self.x[4 * i + 2],
            sigma_k: self.x[4 * i + 3],
        })
    }
}

/// The six-position (rate-reversal) method: each gyro's mean output over a turn at `+rate` and
/// at `-rate` (deg/s) about body x, y and z (`means[axis][0]` for plus, `[1]` for minus). The sum
/// of a pair gives the bias, their difference the sensitivity to that axis; the three
/// sensitivities give the scale factor and the two mounting angles. The earth's rate is
/// neglected, as the method does.
pub fn six_position(
    means: &[[[f64; TETRA_GYROS]; 2]; 3],
    rate_dps: f64,
) -> Option<[GyroCoefficients; TETRA_GYROS]> {
    let mut out = [GyroCoefficients::default(); TETRA_GYROS];
    for (i, c) in out.iter_mut().enumerate() {
        let [p, rj, rk] = tetra_triad(i);
        let b = -(0..3).map(|a| means[a][0][i] + means[a][1][i]).sum::<f64>() / 6.0;
        let d = Vector3::from_fn(|a, _| (means[a][0][i] - means[a][1][i]) / (2.0 * rate_dps));
        // d = A u, A = [P, R_k, -R_j], u = [1 - K, sigma_j, sigma_k]
        let a = Matrix3::from_columns(&[p, rk, -rj]);
        let u = a.try_inverse()? * d;
        *c = GyroCoefficients {
            bias_dps: b,
            scale_factor: 1.0 - u[0],
            sigma_j: u[1],
            sigma_k: u[2],
        };
    }
    Some(out)
}

/// One gyro's recursive least squares on `X = [eps, dK]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rls2 {
    x: Vector2<f64>,
    p: Matrix2<f64>,
    r: f64,
}

impl Rls2 {
    /// `X0 = 0`, `P0 = diag(bias0^2, sf0^2)`, `R = noise^2`.
    pub fn new(bias0: f64, sf0: f64, noise: f64) -> Self {
        Self {
            x: Vector2::zeros(),
            p: Matrix2::new(bias0 * bias0, 0.0, 0.0, sf0 * sf0),
            r: noise * noise,
        }
    }

    /// One observation `z = eps + dK w_exp + v`.
    pub fn update(&mut self, w_exp: f64, z: f64) {
        self.observe([1.0, w_exp], z);
    }

    /// One observation `z = h . X + noise` with any `h` (the integrated form: `h = [T, E]`
    /// for the time since the start and the expected angle since then).
    pub fn observe(&mut self, h: [f64; 2], z: f64) {
        let h = Vector2::from(h);
        let ph = self.p * h;
        let s = h.dot(&ph) + self.r;
        let k = ph / s;
        self.x += k * (z - h.dot(&self.x));
        self.p -= k * ph.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// The estimate's standard deviations `[eps, dK]` (of the filter's own model).
    pub fn sigma(&self) -> [f64; 2] {
        [
            self.p[(0, 0)].max(0.0).sqrt(),
            self.p[(1, 1)].max(0.0).sqrt(),
        ]
    }

    pub fn estimate(&self) -> [f64; 2] {
        [self.x[0], self.x[1]]
    }
}

/// The paper's decoupled RLS for the three gyros.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GyroRls {
    ch: [Rls2; 3],
}

impl GyroRls {
    /// Nominal bias (rad/s), scale-factor error (fraction) and noise (rad/s, 1 sigma per sample).
    pub fn new(bias0: f64, sf0: f64, noise: f64) -> Self {
        Self {
            ch: [Rls2::new(bias0, sf0, noise); 3],
        }
    }

    /// One sample: the gyros' measured rates and the rates expected from the coarse attitude and
    /// the mechanism ([`expected_rate`]).
    pub fn update(&mut self, measured: &Vector3<f64>, expected: &Vector3<f64>) {
        for (j, c) in self.ch.iter_mut().enumerate() {
            c.update(expected[j], measured[j] - expected[j]);
        }
    }

    /// Gyro biases, rad/s.
    pub fn bias(&self) -> Vector3<f64> {
        Vector3::from_fn(|j, _| self.ch[j].x[0])
    }

    /// The integrated form, per gyro: `residual = eps T + dK expected`, with `T` the time
    /// since the start and `expected`, `residual` the expected angle since then and what the
    /// gyro measured beyond it (rad).
    pub fn observe_integrated(&mut self, t: f64, expected: &Vector3<f64>, residual: &Vector3<f64>) {
        for (j, c) in self.ch.iter_mut().enumerate() {
            c.observe([t, expected[j]], residual[j]);
        }
    }

    /// Standard deviations of the biases (rad/s) and scale-factor errors.
    pub fn sigmas(&self) -> (Vector3<f64>, Vector3<f64>) {
        (
            Vector3::from_fn(|j, _| self.ch[j].sigma()[0]),
            Vector3::from_fn(|j, _| self.ch[j].sigma()[1]),
        )
    }

    /// Gyro scale-factor errors (fractions).
    pub fn scale_factor(&self) -> Vector3<f64> {
        Vector3::from_fn(|j, _| self.ch[j].x[1])
    }
}

/// States of [`AlignKf`].
pub const KF_STATES: usize = 14;
type Mat = SMatrix<f64, KF_STATES, KF_STATES>;
type Vec14 = SVector<f64, KF_STATES>;
// state layout: phi E N U, dv E N, nabla x y z, eps x y z, dK x y z
const PHI: usize = 0;
const DV: usize = 3;
const NABLA: usize = 5;
const EPS: usize = 8;
const DK: usize = 11;

/// Noise and initial uncertainty of [`AlignKf`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlignKfConfig {
    /// Initial attitude error sigma, level and heading, rad.
    pub attitude0: [f64; 2],
    /// Initial velocity error sigma, m/s.
    pub velocity0: f64,
    /// Accelerometer bias sigma, m/s^2.
    pub accel_bias0: f64,
    /// Gyro bias sigma, rad/s.
    pub gyro_bias0: f64,
    /// Gyro scale-factor sigma (fraction).
    pub gyro_sf0: f64,
    /// Gyro noise, rad/s (1 sigma per sample).
    pub gyro_noise: f64,
    /// Accelerometer noise, m/s^2 (1 sigma per sample).
    pub accel_noise: f64,
    /// Velocity measurement noise, m/s.
    pub velocity_noise: f64,
}

/// The 14-state static-base alignment filter with gyro biases and scale factors in its state.
#[derive(Debug, Clone)]
pub struct AlignKf {
    cfg: AlignKfConfig,
    x: Vec14,
    p: Mat,
    nav: NavState,
    prev_dtheta: Option<Vector3<f64>>,
    home: (f64, f64, f64),
}

impl AlignKf {
    /// Start at the coarse attitude `q_np` of the IMU (IMU to ENU) at latitude `lat`, longitude
    /// `lon` and height `h`, at rest.
    pub fn new(cfg: AlignKfConfig, q_np: UnitQuaternion<f64>, lat: f64, lon: f64, h: f64) -> Self {
        let mut sd = [0.0; KF_STATES];
        sd[PHI] = cfg.attitude0[0];
        sd[PHI + 1] = cfg.attitude0[0];
        sd[PHI + 2] = cfg.attitude0[1];
        sd[DV] = cfg.velocity0;
        sd[DV + 1] = cfg.velocity0;
        for j in 0..3 {
            sd[NABLA + j] = cfg.accel_bias0;
            sd[EPS + j] = cfg.gyro_bias0;
            sd[DK + j] = cfg.gyro_sf0;
        }
        let p = Mat::from_diagonal(&Vec14::from_fn(|i, _| sd[i] * sd[i]));
        Self {
            cfg,
            x: Vec14::zeros(),
            p,
            nav: NavState {
                q_nb: q_np,
                v: Vector3::zeros(),
                lat,
                lon,
                h,
            },
            prev_dtheta: None,
            home: (lat, lon, h),
        }
    }

    /// One IMU sample of `dt` s (angle and velocity increments, IMU axes): the strapdown update
    /// (two-sample coning, rotation compensation of the velocity increment) and the covariance
    /// propagation. The position stays where the base is (static base); the vertical velocity is
    /// held at zero.
    pub fn propagate(&mut self, dtheta: &Vector3<f64>, dv: &Vector3<f64>, dt: f64) {
        let phi = dtheta
            + self
                .prev_dtheta
                .map_or(Vector3::zeros(), |p| p.cross(dtheta) / 12.0);
        self.prev_dtheta = Some(*dtheta);
        let dv_c = dv + 0.5 * dtheta.cross(dv);
        let c_pn = self.nav.q_nb.to_rotation_matrix().into_inner();
        let f_n = c_pn * (dv / dt);
        let w = dtheta / dt;
        self.nav.update(phi.into(), dv_c.into(), dt);
        (self.nav.lat, self.nav.lon, self.nav.h) = self.home;
        self.nav.v.z = 0.0;
        // error dynamics
        let w_ie = Vector3::from(earth::earth_rate_enu(self.home.0));
        let mut f = Mat::zeros();
        let skew = |v: &Vector3<f64>| v.cross_matrix();
        f.fixed_view_mut::<3, 3>(PHI, PHI)
            .copy_from(&(-skew(&w_ie)));
        f.fixed_view_mut::<3, 3>(PHI, EPS).copy_from(&(-c_pn));
        f.fixed_view_mut::<3, 3>(PHI, DK)
            .copy_from(&(-c_pn * Matrix3::from_diagonal(&w)));
        // dv' = f x phi + C nabla - 2 w_ie x dv (horizontal rows)
        let fphi = skew(&f_n);
        f.fixed_view_mut::<2, 3>(DV, PHI)
            .copy_from(&fphi.fixed_view::<2, 3>(0, 0));
        f.fixed_view_mut::<2, 3>(DV, NABLA)
            .copy_from(&c_pn.fixed_view::<2, 3>(0, 0));
        let cor = skew(&(2.0 * w_ie)).scale(-1.0);
        f.fixed_view_mut::<2, 2>(DV, DV)
            .copy_from(&cor.fixed_view::<2, 2>(0, 0));
        let phi_m = Mat::identity() + f * dt;
        let mut q = Mat::zeros();
        let (gq, aq) = (
            self.cfg.gyro_noise * self.cfg.gyro_noise * dt * dt,
            self.cfg.accel_noise * self.cfg.accel_noise * dt * dt,
        );
        for j in 0..3 {
            q[(PHI + j, PHI + j)] = gq;
        }
        for j in 0..2 {
            q[(DV + j, DV + j)] = aq;
        }
        self.x = phi_m * self.x;
        self.p = phi_m * self.p * phi_m.transpose() + q;
    }

    /// The velocity measurement (the computed horizontal velocity; the truth is zero), then the
    /// closed-loop correction of attitude and velocity.
    pub fn update(&mut self) {
        let z = Vector2::new(self.nav.v.x, self.nav.v.y);
        let mut h = SMatrix::<f64, 2, KF_STATES>::zeros();
        h[(0, DV)] = 1.0;
        h[(1, DV + 1)] = 1.0;
        let r = Matrix2::identity() * self.cfg.velocity_noise.powi(2);
        let s = h * self.p * h.transpose() + r;
        let Some(si) = s.try_inverse() else {
            return;
        };
        let k = self.p * h.transpose() * si;
        self.x += k * (z - h * self.x);
        let ikh = Mat::identity() - k * h;
        self.p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
        // feedback: the computed frame is turned by phi ((I - phi x) C true), the velocity off by dv
        let phi = Vector3::new(self.x[PHI], self.x[PHI + 1], self.x[PHI + 2]);
        self.nav.q_nb = UnitQuaternion::from_scaled_axis(phi) * self.nav.q_nb;
        self.nav.v.x -= self.x[DV];
        self.nav.v.y -= self.x[DV + 1];
        for i in PHI..NABLA {
            self.x[i] = 0.0;
        }
    }

    /// Gyro biases, rad/s.
    pub fn bias(&self) -> Vector3<f64> {
        Vector3::new(self.x[EPS], self.x[EPS + 1], self.x[EPS + 2])
    }

    /// Gyro scale-factor errors (fractions).
    pub fn scale_factor(&self) -> Vector3<f64> {
        Vector3::new(self.x[DK], self.x[DK + 1], self.x[DK + 2])
    }

    /// Standard deviations of the gyro biases (rad/s) and scale-factor errors.
    pub fn sigmas(&self) -> (Vector3<f64>, Vector3<f64>) {
        let sd = |i: usize| self.p[(i, i)].max(0.0).sqrt();
        (
            Vector3::new(sd(EPS), sd(EPS + 1), sd(EPS + 2)),
            Vector3::new(sd(DK), sd(DK + 1), sd(DK + 2)),
        )
    }

    /// The computed IMU attitude (IMU to ENU).
    pub fn attitude(&self) -> UnitQuaternion<f64> {
        self.nav.q_nb
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Noise-free observations of a known bias and scale factor: the RLS finds them.
    #[test]
    fn rls_recovers_a_bias_and_scale_factor_from_exact_data() {
        let (eps, dk) = (5e-8, 1e-5);
        let mut r = Rls2::new(1e-7, 1e-5, 1e-9);
        for k in 0..10_000 {
            let w = 0.087 * (k as f64 * 0.01).sin();
            r.update(w, eps + dk * w);
        }
        let [e, d] = r.estimate();
        assert!((e - eps).abs() < 1e-12, "{e}");
        assert!((d - dk).abs() < 1e-9, "{d}");
    }

    /// With the mechanism at rest at zero angles the expected rate is the earth's rate in body
    /// axes; the axes' rates add along their own axes.
    #[test]
    fn the_expected_rate_is_the_earth_rate_plus_the_mechanism_rates() {
        let lat = 30f64.to_radians();
        let q = UnitQuaternion::identity(); // body = ENU: x east, y north, z up
        let w = expected_rate(lat, &q, [0.0, 0.0], [0.0, 0.0]);
        let e = earth::earth_rate_enu(lat);
        assert!((w - Vector3::from(e)).norm() < 1e-18);
        // inner axis at 90 deg: the IMU's y is the vehicle's z
        let w = expected_rate(lat, &q, [90f64.to_radians(), 0.0], [0.1, 0.2]);
        assert!((w.x - 0.1 - e[0]).abs() < 1e-12, "{w}");
        assert!((w.y - 0.2 - e[2]).abs() < 1e-12, "{w}");
        assert!((w.z + e[1]).abs() < 1e-12, "{w}");
    }
}
