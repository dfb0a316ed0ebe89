//! The SINS/GPS error-state Kalman filter of paper 003, with the receiver's correlated error as
//! three more states: attitude errors (E, N, U), velocity errors (E, N, U), position errors
//! (lat, lon, h), gyro drifts (body x, y, z), accelerometer biases (body x, y, z) - paper 003's
//! 15 states - and the receiver's position error (lat, lon, h), a first-order Gauss-Markov
//! process (`b' = -b / tau + w`, stationary sigma `gps_gm_sigma_m`). Position-only measurements
//! `z = p_INS - p_GPS = dp - b + v`, `H = [0 0 I 0 0 -I]`, `v` white (`gps_sigma_m`).
//!
//! Why the extra states: a standalone receiver's error wanders over minutes (12 m over 300 s for
//! the 25 m class). A filter that takes it for white noise believes each fix is independent and
//! becomes over-confident: its position sigma falls far below its error (NEES about 20 per
//! degree of freedom on the campus loop). With the wander modelled, the reported sigmas match
//! the errors. `gps_gm_sigma_m = 0` gives paper 003's 15-state filter.
//!
//! Error model (ENU, `phi` the computed frame's misalignment: `C_b^n' = (I - phi x) C_b^n`):
//! `phi' = phi x w_in + dw_in - C_b^n eps`,
//! `dv' = f^n x phi + v x (2 dw_ie + dw_en) - (2 w_ie + w_en) x dv + C_b^n nabla`,
//! `dL' = dv_N / (R_M + h) - v_N dh / (R_M + h)^2`,
//! `dlon' = sec L dv_E / (R_N + h) + v_E sec L tan L dL / (R_N + h) - v_E sec L dh / (R_N + h)^2`,
//! `dh' = dv_U`; drifts and biases are random constants.
//!
//! Variants: the standard filter; the fading-memory filter (`P <- s P` before each
//! measurement, `s` = 1.02 by default), which discounts old information and so tolerates a
//! mis-specified GPS noise; and the adaptive filter, which estimates the receiver's white noise
//! from its innovations (Sage-Husa with exponential forgetting:
//! `R_k = b R_{k-1} + (1 - b) (e e^T - H P H^T)`, starting from the configured noise, diagonal,
//! bounded to a quarter and 400 times the configured
//! variance), so that a receiver whose noise changes along the route (multipath, poor geometry)
//! is weighted by what it does rather than by what it was assumed to do. Any kind may scale the
//! white noise with the HDOP the receiver reports (`hdop_ref`). Corrections: closed-loop feedback (the navigation state and the IMU
//! compensation are corrected and the error states reset) or paper 003's output correction (the
//! navigation runs free; its output is corrected). Innovations beyond the gate are rejected and
//! counted (a GPS glitch or multipath jump must not pull the solution).

use crate::earth;
use crate::strapdown::NavState;
use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// States: paper 003's 15 and the receiver's error.
pub const N: usize = 18;
/// The first of the receiver-error states.
const B: usize = 15;
type MatN = SMatrix<f64, N, N>;
type VecN = SVector<f64, N>;

/// Filter settings (the `[filter]` table of nav's config).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct FilterConfig {
    /// `standard`, `fading` or `adaptive`.
    pub kind: FilterKind,
    /// Fading-memory factor (applied at each measurement to the navigation and IMU states).
    /// Paper 003 uses 1.2 with the receiver's error taken for white noise; with the receiver's
    /// wander modelled, 1.02 (a memory of about 50 fixes) keeps the sigmas consistent (see
    /// docs/navigation.md).
    pub fading_factor: f64,
    /// The adaptive filter's forgetting factor `b` (0-1): its noise estimate remembers about
    /// `1 / (1 - b)` fixes.
    pub adaptive_forgetting: f64,
    /// The HDOP at which `gps_sigma_m` and `gps_sigma_h_m` hold: the white noise assumed for
    /// each fix is scaled by its HDOP over this (0: the HDOP is not used).
    pub hdop_ref: f64,
    /// `feedback` (closed loop) or `output` (paper 003's output correction).
    pub correction: Correction,
    /// The receiver's white position noise the filter assumes, per horizontal axis (1 sigma), m.
    pub gps_sigma_m: f64,
    /// Its white height noise, m.
    pub gps_sigma_h_m: f64,
    /// The receiver's correlated (Gauss-Markov) position error, per horizontal axis (stationary
    /// 1 sigma), m; 0: not modelled (paper 003's 15-state filter).
    pub gps_gm_sigma_m: f64,
    /// Its height part, m.
    pub gps_gm_sigma_h_m: f64,
    /// Its correlation time, s.
    pub gps_gm_tau_s: f64,
    /// Gyro white noise (angle random walk), deg/sqrt(h).
    pub gyro_arw_dpsh: f64,
    /// Accelerometer white noise (velocity random walk), m/s/sqrt(s).
    pub accel_vrw_mpss: f64,
    /// Initial attitude sigma (E, N, U), deg.
    pub init_att_deg: [f64; 3],
    /// Initial velocity sigma, m/s.
    pub init_vel_mps: f64,
    /// Initial position sigma, m.
    pub init_pos_m: f64,
    /// Initial gyro drift sigma, deg/h.
    pub init_gyro_dph: f64,
    /// Initial accelerometer bias sigma, m/s^2.
    pub init_accel_mps2: f64,
    /// Reject a fix whose normalized innovation squared exceeds this (3 dof).
    pub gate_nis: f64,
    /// After this many fixes rejected in a row the filter trusts the receiver again: it widens
    /// its position uncertainty to the innovation and takes the fix (0: never). An isolated
    /// jump stays gated out; a filter that has drifted away does not stay lost.
    pub reanchor_after: u32,
    /// Antenna lever arm in the body frame (x right, y forward, z up), m.
    pub lever_arm_m: [f64; 3],
}

impl FilterConfig {
    /// Refuse settings the filter cannot run with, naming the field.
    pub fn check(&self) -> Result<(), String> {
        let positive = [
            ("gps_sigma_m", self.gps_sigma_m),
            ("gps_sigma_h_m", self.gps_sigma_h_m),
            ("gps_gm_tau_s", self.gps_gm_tau_s),
            ("gate_nis", self.gate_nis),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("filter.{name} must be a positive number, got {v}"));
            }
        }
        let non_negative = [
            ("gps_gm_sigma_m", self.gps_gm_sigma_m),
            ("gps_gm_sigma_h_m", self.gps_gm_sigma_h_m),
            ("hdop_ref", self.hdop_ref),
            ("gyro_arw_dpsh", self.gyro_arw_dpsh),
            ("accel_vrw_mpss", self.accel_vrw_mpss),
            ("init_vel_mps", self.init_vel_mps),
            ("init_pos_m", self.init_pos_m),
            ("init_gyro_dph", self.init_gyro_dph),
            ("init_accel_mps2", self.init_accel_mps2),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("filter.{name} must be a number >= 0, got {v}"));
            }
        }
        if !(self.fading_factor.is_finite() && (1.0..=10.0).contains(&self.fading_factor)) {
            return Err(format!(
                "filter.fading_factor must be 1-10 (1: no fading), got {}",
                self.fading_factor
            ));
        }
        if !(0.0..1.0).contains(&self.adaptive_forgetting) {
            return Err(format!(
                "filter.adaptive_forgetting must be in [0, 1), got {}",
                self.adaptive_forgetting
            ));
        }
        if self
            .init_att_deg
            .iter()
            .any(|v| !(v.is_finite() && *v >= 0.0))
        {
            return Err(format!(
                "filter.init_att_deg must be numbers >= 0, got {:?}",
                self.init_att_deg
            ));
        }
        if self.lever_arm_m.iter().any(|v| !v.is_finite()) {
            return Err(format!(
                "filter.lever_arm_m must be finite, got {:?}",
                self.lever_arm_m
            ));
        }
        Ok(())
    }
}

/// Largest attitude error an open-loop filter carries before it folds its estimate into the
/// navigation state, deg (the small-angle error model is good to about 1 % there).
pub const LINEAR_ATTITUDE_DEG: f64 = 0.5;
/// Largest velocity error it carries, m/s (the error model's transport-rate and Coriolis terms
/// are evaluated at the uncorrected velocity).
pub const LINEAR_VELOCITY_MPS: f64 = 2.0;

/// Which filter.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum FilterKind {
    /// Standard Kalman filter.
    Standard,
    /// Fading-memory filter.
    #[default]
    Fading,
    /// Adaptive (Sage-Husa) estimate of the receiver's white noise.
    Adaptive,
}

/// How estimates are applied.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum Correction {
    /// Correct the navigation state and the IMU; reset the error states.
    #[default]
    Feedback,
    /// Leave the navigation free, correct its output.
    Output,
}

impl Default for FilterConfig {
    fn default() -> Self {
        Self {
            kind: FilterKind::Fading,
            fading_factor: 1.02,
            adaptive_forgetting: 0.95,
            hdop_ref: 0.0,
            correction: Correction::Feedback,
            // a 25 m class receiver (paper 003's): 12 m over 300 s plus 6 m white per axis, the
            // height 1.6 times the horizontal
            gps_sigma_m: 6.0,
            gps_sigma_h_m: 9.6,
            gps_gm_sigma_m: 12.0,
            gps_gm_sigma_h_m: 19.2,
            gps_gm_tau_s: 300.0,
            gyro_arw_dpsh: 0.1 / 60.0,
            accel_vrw_mpss: 0.001,
            init_att_deg: [0.05, 0.05, 0.1],
            init_vel_mps: 0.1,
            init_pos_m: 10.0,
            init_gyro_dph: 0.1,
            init_accel_mps2: 5e-3 * 9.80665,
            gate_nis: 30.0,
            reanchor_after: 10,
            lever_arm_m: [0.0; 3],
        }
    }
}

/// Filter counters.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct FilterStats {
    /// Fixes used.
    pub updates: u64,
    /// Fixes rejected by the gate.
    pub rejected: u64,
    /// Mean normalized innovation squared of the used fixes.
    pub mean_nis: f64,
    /// Times the filter re-anchored on the receiver after a run of rejections.
    pub reanchors: u64,
    /// Times the open-loop (output correction) filter's error estimate left the range where
    /// its linear model holds and was folded into the navigation state.
    pub relinearised: u64,
    /// Estimated gyro drifts (body x, y, z), deg/h (fed back, plus the pending estimate).
    pub gyro_bias_dph: [f64; 3],
    /// Estimated accelerometer biases (body x, y, z), m/s^2.
    pub accel_bias_mps2: [f64; 3],
    /// The white noise the filter assumes now (north, east, up; 1 sigma at the reference HDOP),
    /// m: the configured one, or the adaptive filter's estimate.
    pub gps_sigma_now_m: [f64; 3],
}

/// The filter.
#[derive(Debug, Clone)]
pub struct Kf {
    cfg: FilterConfig,
    x: VecN,
    p: MatN,
    /// IMU compensation fed back: gyro drift (rad/s) and accelerometer bias (m/s^2), body.
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
    stats: FilterStats,
    nis_sum: f64,
    last_nis: Option<f64>,
    rejected_in_a_row: u32,
    /// Largest variance each state may reach through fading (its initial one, x 100 for the
    /// navigation states): weakly observable states (heading between turns, drifts) would
    /// otherwise grow without bound under the fading factor.
    cap: VecN,
    /// The receiver's white noise variance (north, east, up; at the reference HDOP), m^2: the
    /// configured one, or the adaptive filter's estimate.
    r_m2: [f64; 3],
}

fn skew(v: &Vector3<f64>) -> SMatrix<f64, 3, 3> {
    SMatrix::<f64, 3, 3>::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

impl Kf {
    /// A filter with these settings at `lat` (rad, for the position sigmas in radians).
    pub fn new(cfg: FilterConfig, lat: f64) -> Self {
        let (rm, rn) = earth::radii(lat);
        let mut p = MatN::zeros();
        let dph = (1.0f64).to_radians() / 3600.0;
        let d = [
            cfg.init_att_deg[0].to_radians(),
            cfg.init_att_deg[1].to_radians(),
            cfg.init_att_deg[2].to_radians(),
            cfg.init_vel_mps,
            cfg.init_vel_mps,
            cfg.init_vel_mps,
            cfg.init_pos_m / rm,
            cfg.init_pos_m / (rn * lat.cos()),
            cfg.init_pos_m,
            cfg.init_gyro_dph * dph,
            cfg.init_gyro_dph * dph,
            cfg.init_gyro_dph * dph,
            cfg.init_accel_mps2,
            cfg.init_accel_mps2,
            cfg.init_accel_mps2,
            cfg.gps_gm_sigma_m / rm,
            cfg.gps_gm_sigma_m / (rn * lat.cos()),
            cfg.gps_gm_sigma_h_m,
        ];
        let r_m2 = [
            cfg.gps_sigma_m.powi(2),
            cfg.gps_sigma_m.powi(2),
            cfg.gps_sigma_h_m.powi(2),
        ];
        let mut cap = VecN::zeros();
        for (i, s) in d.iter().enumerate() {
            p[(i, i)] = s * s;
            cap[i] = s * s * if i < 9 { 100.0 } else { 1.0 };
        }
        Self {
            cap,
            cfg,
            x: VecN::zeros(),
            p,
            gyro_bias: Vector3::zeros(),
            accel_bias: Vector3::zeros(),
            stats: FilterStats::default(),
            nis_sum: 0.0,
            last_nis: None,
            rejected_in_a_row: 0,
            r_m2,
        }
    }

    /// The filter's start after accelerometer levelling at attitude `q_nb`: levelling puts the
    /// horizontal accelerometer bias into the tilt (`f^n x phi + C_b^n nabla = 0` at rest, so
    /// `phi_N = nabla_E / g` and `phi_E = -nabla_N / g`). The tilt variances grow by the bias's
    /// share and the tilt is correlated with the bias states accordingly: the filter then knows
    /// that the two cancel while the vehicle stands, and that they stop cancelling once it turns
    /// (a 5 mg bias is a 0.29 deg tilt). Without this the first turns make the solution's
    /// velocity sigma several times too small.
    pub fn levelled(&mut self, q_nb: &UnitQuaternion<f64>, g: f64) {
        let c = q_nb.to_rotation_matrix().into_inner();
        let sb2 = self.cfg.init_accel_mps2 * self.cfg.init_accel_mps2;
        for j in 0..3 {
            // phi_E = -(C[N,:] nabla) / g, phi_N = (C[E,:] nabla) / g
            let ce = c[(1, j)] * -sb2 / g;
            let cn = c[(0, j)] * sb2 / g;
            self.p[(0, 12 + j)] = ce;
            self.p[(12 + j, 0)] = ce;
            self.p[(1, 12 + j)] = cn;
            self.p[(12 + j, 1)] = cn;
        }
        let t = sb2 / (g * g);
        self.p[(0, 0)] += t;
        self.p[(1, 1)] += t;
        // the rows of C are orthonormal: phi_E and phi_N stay uncorrelated
        let cross = -(0..3).map(|j| c[(1, j)] * c[(0, j)]).sum::<f64>() * t;
        self.p[(0, 1)] += cross;
        self.p[(1, 0)] += cross;
        for i in 0..2 {
            self.cap[i] = self.cap[i].max(self.p[(i, i)] * 100.0);
        }
    }

    /// Counters.
    pub fn stats(&self) -> FilterStats {
        let g = (self.gyro_bias + Vector3::new(self.x[9], self.x[10], self.x[11]))
            * (3600.0f64.to_degrees());
        let a = self.accel_bias + Vector3::new(self.x[12], self.x[13], self.x[14]);
        FilterStats {
            gyro_bias_dph: g.into(),
            accel_bias_mps2: a.into(),
            gps_sigma_now_m: self.r_m2.map(f64::sqrt),
            ..self.stats
        }
    }

    /// The normalized innovation squared of the last fix offered (before any re-anchor).
    pub fn last_nis(&self) -> Option<f64> {
        self.last_nis
    }

    /// Settings.
    pub fn config(&self) -> &FilterConfig {
        &self.cfg
    }

    /// Covariance (for NEES and reports): the states in the order of the module doc.
    pub fn covariance(&self) -> &MatN {
        &self.p
    }

    /// Remove the estimated IMU errors from an update's increments over `t` s (feedback only).
    pub fn compensate(&self, phi: [f64; 3], dv: [f64; 3], t: f64) -> ([f64; 3], [f64; 3]) {
        let g = self.gyro_bias * t;
        let a = self.accel_bias * t;
        (
            [phi[0] - g.x, phi[1] - g.y, phi[2] - g.z],
            [dv[0] - a.x, dv[1] - a.y, dv[2] - a.z],
        )
    }

    /// Propagate the error state over `t` s at navigation state `s` with specific force `f_n`.
    pub fn propagate(&mut self, s: &NavState, f_n: &Vector3<f64>, t: f64) {
        let (rm, rn) = earth::radii(s.lat);
        let (rmh, rnh) = (rm + s.h, rn + s.h);
        let (sl, cl) = s.lat.sin_cos();
        let tl = sl / cl;
        let v = s.v;
        let w = earth::OMEGA_IE;
        let (wie, wen) = s.rates();
        let win = wie + wen;
        let cbn = s.q_nb.to_rotation_matrix().into_inner();
        let mut f = MatN::zeros();
        // attitude
        let m_aa = -skew(&win);
        // d(w_in)/d(dv)
        let mut m_av = SMatrix::<f64, 3, 3>::zeros();
        m_av[(0, 1)] = -1.0 / rmh;
        m_av[(1, 0)] = 1.0 / rnh;
        m_av[(2, 0)] = tl / rnh;
        // d(w_in)/d(dL, dlon, dh)
        let mut m_ap = SMatrix::<f64, 3, 3>::zeros();
        m_ap[(1, 0)] = -w * sl;
        m_ap[(2, 0)] = w * cl + v.x / (rnh * cl * cl);
        m_ap[(0, 2)] = v.y / (rmh * rmh);
        m_ap[(1, 2)] = -v.x / (rnh * rnh);
        m_ap[(2, 2)] = -v.x * tl / (rnh * rnh);
        f.fixed_view_mut::<3, 3>(0, 0).copy_from(&m_aa);
        f.fixed_view_mut::<3, 3>(0, 3).copy_from(&m_av);
        f.fixed_view_mut::<3, 3>(0, 6).copy_from(&m_ap);
        f.fixed_view_mut::<3, 3>(0, 9).copy_from(&(-cbn));
        // velocity
        f.fixed_view_mut::<3, 3>(3, 0).copy_from(&skew(f_n));
        let m_vv = skew(&v) * m_av - skew(&(2.0 * wie + wen));
        f.fixed_view_mut::<3, 3>(3, 3).copy_from(&m_vv);
        let mut dwie = SMatrix::<f64, 3, 3>::zeros();
        dwie[(1, 0)] = -w * sl;
        dwie[(2, 0)] = w * cl;
        let m_vp = skew(&v) * (2.0 * dwie + (m_ap - dwie));
        f.fixed_view_mut::<3, 3>(3, 6).copy_from(&m_vp);
        f.fixed_view_mut::<3, 3>(3, 12).copy_from(&cbn);
        // position
        f[(6, 4)] = 1.0 / rmh;
        f[(6, 8)] = -v.y / (rmh * rmh);
        f[(7, 3)] = 1.0 / (rnh * cl);
        f[(7, 6)] = v.x * tl / (rnh * cl);
        f[(7, 8)] = -v.x / (rnh * rnh * cl);
        f[(8, 5)] = 1.0;
        // the receiver's error: first-order Gauss-Markov (in F before the transition matrix is
        // formed: without its decay the receiver's error became a random walk and the position
        // sigma grew without bound, 14 m to 50 m over the campus loop)
        let tau = self.cfg.gps_gm_tau_s.max(1e-3);
        for i in 0..3 {
            f[(B + i, B + i)] = -1.0 / tau;
        }
        let phi = MatN::identity() + f * t + f * f * (t * t / 2.0);
        let mut q = MatN::zeros();
        let arw = self.cfg.gyro_arw_dpsh.to_radians() / 60.0;
        let vrw = self.cfg.accel_vrw_mpss;
        let gm = [
            self.cfg.gps_gm_sigma_m / rmh,
            self.cfg.gps_gm_sigma_m / (rnh * cl),
            self.cfg.gps_gm_sigma_h_m,
        ];
        for i in 0..3 {
            q[(i, i)] = arw * arw * t;
            q[(3 + i, 3 + i)] = vrw * vrw * t;
            q[(B + i, B + i)] = 2.0 * gm[i] * gm[i] / tau * t;
        }
        self.x = phi * self.x;
        self.p = phi * self.p * phi.transpose() + q;
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// A GPS position (rad, rad, m) measured at the state's time, with the HDOP the receiver
    /// reported. Returns whether it was used.
    pub fn update(
        &mut self,
        s: &mut NavState,
        lat: f64,
        lon: f64,
        h: f64,
        hdop: Option<f64>,
    ) -> bool {
        let (rm, rn) = earth::radii(s.lat);
        // the antenna's position from the INS: lever arm in the navigation frame
        let l = s.q_nb * Vector3::from(self.cfg.lever_arm_m);
        let ant = (
            s.lat + l.y / (rm + s.h),
            s.lon + l.x / ((rn + s.h) * s.lat.cos()),
            s.h + l.z,
        );
        let z = Vector3::new(ant.0 - lat, ant.1 - lon, ant.2 - h);
        // metres per state unit of the position axes (lat, lon, h)
        let m_per = [rm + s.h, (rn + s.h) * s.lat.cos(), 1.0];
        // the white noise of this fix: the assumed (or estimated) one at the reference HDOP,
        // scaled by the fix's HDOP
        let hdop_scale = match hdop {
            Some(d) if self.cfg.hdop_ref > 0.0 && d.is_finite() && d > 0.0 => {
                (d / self.cfg.hdop_ref).clamp(0.2, 20.0)
            }
            _ => 1.0,
        };
        let r_of = |r_m2: &[f64; 3]| {
            SMatrix::<f64, 3, 3>::from_diagonal(&Vector3::from_fn(|i, _| {
                r_m2[i] * hdop_scale * hdop_scale / (m_per[i] * m_per[i])
            }))
        };
        if self.cfg.kind == FilterKind::Fading {
            // fading discounts what the filter learnt of its own horizontal navigation and IMU
            // states; the receiver's error (a model of the receiver, not of the INS) keeps its
            // memory, and so does the vertical channel, which would otherwise follow each fix's
            // white height noise with nothing to check its velocity against: P <- D P D with
            // D = sqrt(s) on those states, 1 on the others (stays positive). The fading may not push a variance over its cap, but never
            // takes back what the propagation put there (after an outage the position variance
            // is rightly large).
            let before = self.p.diagonal();
            let f = self.cfg.fading_factor.sqrt();
            let d = VecN::from_fn(|i, _| {
                if i >= B || i == 5 || i == 8 {
                    return 1.0;
                }
                let v = self.p[(i, i)] * f * f;
                let limit = self.cap[i].max(before[i]);
                if v > limit { f * (limit / v).sqrt() } else { f }
            });
            for i in 0..N {
                for j in 0..N {
                    self.p[(i, j)] *= d[i] * d[j];
                }
            }
        }
        // H = [0 0 I 0 0 -I]: the INS's position error less the receiver's
        let mut h_mat = SMatrix::<f64, 3, N>::zeros();
        for i in 0..3 {
            h_mat[(i, 6 + i)] = 1.0;
            h_mat[(i, B + i)] = -1.0;
        }
        let innov = z - h_mat * self.x;
        let r_before = self.r_m2;
        if self.cfg.kind == FilterKind::Adaptive {
            self.adapt_noise(&h_mat, &innov, &m_per, hdop_scale);
        }
        let r = r_of(&self.r_m2);
        let nis_of = |p: &MatN| {
            let s_mat = h_mat * p * h_mat.transpose() + r;
            let s_inv = s_mat.try_inverse()?;
            let nis = (innov.transpose() * s_inv * innov)[(0, 0)];
            nis.is_finite().then_some((nis, s_inv))
        };
        let Some((mut nis, mut s_inv)) = nis_of(&self.p) else {
            self.last_nis = None;
            return false;
        };
        self.last_nis = Some(nis);
        if nis > self.cfg.gate_nis {
            self.rejected_in_a_row += 1;
            if self.cfg.reanchor_after == 0 || self.rejected_in_a_row < self.cfg.reanchor_after {
                self.stats.rejected += 1;
                // a rejected fix teaches the noise estimate nothing
                if self.cfg.kind == FilterKind::Adaptive {
                    self.r_m2 = r_before;
                }
                return false;
            }
            // lost: widen the position uncertainty to the innovation, then take the fix
            for i in 0..3 {
                self.p[(6 + i, 6 + i)] += innov[i] * innov[i];
            }
            self.stats.reanchors += 1;
            tracing::warn!(
                rejected = self.rejected_in_a_row,
                "filter re-anchored on the receiver after a run of rejected fixes"
            );
            let Some(again) = nis_of(&self.p) else {
                return false;
            };
            (nis, s_inv) = again;
        }
        self.rejected_in_a_row = 0;
        let k = self.p * h_mat.transpose() * s_inv;
        self.x += k * innov;
        let ikh = MatN::identity() - k * h_mat;
        // Joseph form keeps P symmetric and positive
        self.p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
        self.stats.updates += 1;
        self.nis_sum += nis;
        self.stats.mean_nis = self.nis_sum / self.stats.updates as f64;
        match self.cfg.correction {
            Correction::Feedback => self.feedback(s),
            Correction::Output if self.beyond_linear_range() => {
                // the free INS has drifted so far that the error model (small angles, the
                // navigation state as the linearisation point) no longer describes its error:
                // the sigmas would stop meaning anything. Fold the estimate into the
                // navigation state once and go on open loop from there.
                tracing::info!(
                    attitude_deg = Vector3::new(self.x[0], self.x[1], self.x[2])
                        .norm()
                        .to_degrees(),
                    velocity_mps = Vector3::new(self.x[3], self.x[4], self.x[5]).norm(),
                    "output correction: the error estimate left the linear range; folded into the navigation state"
                );
                self.stats.relinearised += 1;
                self.feedback(s);
            }
            Correction::Output => {}
        }
        true
    }

    /// The open-loop error estimate is too large for the linear error model: an attitude error
    /// over [`LINEAR_ATTITUDE_DEG`] or a velocity error over [`LINEAR_VELOCITY_MPS`].
    fn beyond_linear_range(&self) -> bool {
        Vector3::new(self.x[0], self.x[1], self.x[2]).norm() > LINEAR_ATTITUDE_DEG.to_radians()
            || Vector3::new(self.x[3], self.x[4], self.x[5]).norm() > LINEAR_VELOCITY_MPS
    }

    /// Sage-Husa: move the white-noise estimate towards this fix's innovation less what the
    /// filter's own uncertainty explains, with the weight `1 - b` (a memory of `1 / (1 - b)`
    /// fixes; the configured noise is the prior); bounded to [1/4, 400] times the configured
    /// variance.
    fn adapt_noise(
        &mut self,
        h_mat: &SMatrix<f64, 3, N>,
        innov: &Vector3<f64>,
        m_per: &[f64; 3],
        hdop_scale: f64,
    ) {
        let b = self.cfg.adaptive_forgetting.clamp(0.0, 0.999);
        let d = 1.0 - b;
        let hph = h_mat * self.p * h_mat.transpose();
        let base = [
            self.cfg.gps_sigma_m.powi(2),
            self.cfg.gps_sigma_m.powi(2),
            self.cfg.gps_sigma_h_m.powi(2),
        ];
        for i in 0..3 {
            let k2 = m_per[i] * m_per[i] / (hdop_scale * hdop_scale);
            let sample = (innov[i] * innov[i] - hph[(i, i)]) * k2;
            let r = (1.0 - d) * self.r_m2[i] + d * sample;
            self.r_m2[i] = r.clamp(0.25 * base[i], 400.0 * base[i]);
        }
    }

    /// Apply the estimate to the navigation state and the IMU compensation; reset.
    fn feedback(&mut self, s: &mut NavState) {
        *s = correct(&self.x, s);
        self.gyro_bias += Vector3::new(self.x[9], self.x[10], self.x[11]);
        self.accel_bias += Vector3::new(self.x[12], self.x[13], self.x[14]);
        // the navigation and IMU errors were applied; the receiver's error is not ours to remove
        for i in 0..B {
            self.x[i] = 0.0;
        }
    }

    /// The best estimate of the navigation state (output correction applied when the filter
    /// runs open loop).
    pub fn corrected(&self, s: &NavState) -> NavState {
        match self.cfg.correction {
            Correction::Feedback => *s,
            Correction::Output => correct(&self.x, s),
        }
    }
}

/// The navigation state with the error estimate `x` removed.
fn correct(x: &VecN, s: &NavState) -> NavState {
    let phi = Vector3::new(x[0], x[1], x[2]);
    NavState {
        q_nb: UnitQuaternion::from_scaled_axis(phi) * s.q_nb,
        v: s.v - Vector3::new(x[3], x[4], x[5]),
        lat: s.lat - x[6],
        lon: s.lon - x[7],
        h: s.h - x[8],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parked() -> NavState {
        NavState::from_euler(0.0, 0.0, 0.0, Vector3::zeros(), 0.49, 1.97, 0.0)
    }

    /// The horizontal velocity-error rate `f^n x phi + C_b^n nabla` (rows E, N) for specific
    /// force `f_n`: its variance under the filter's covariance.
    fn accel_error_var(k: &Kf, cbn: &SMatrix<f64, 3, 3>, f_n: &Vector3<f64>) -> [f64; 2] {
        let mut h = SMatrix::<f64, 2, N>::zeros();
        let sf = skew(f_n);
        for r in 0..2 {
            for c in 0..3 {
                h[(r, c)] = sf[(r, c)];
                h[(r, 12 + c)] = cbn[(r, c)];
            }
        }
        let v = h * k.covariance() * h.transpose();
        [v[(0, 0)], v[(1, 1)]]
    }

    /// After levelling the tilt and the accelerometer bias cancel while the vehicle stands
    /// (the filter predicts no velocity-error growth beyond the levelling noise), and once the
    /// vehicle has turned half round they add (it predicts twice the bias).
    #[test]
    fn levelling_ties_the_tilt_to_the_accelerometer_bias() {
        let g = 9.8;
        let st = NavState::from_euler(0.7, 0.01, -0.02, Vector3::zeros(), 0.49, 1.97, 0.0);
        let cbn = st.q_nb.to_rotation_matrix().into_inner();
        let f_n = Vector3::new(0.0, 0.0, g);
        let mut k = Kf::new(FilterConfig::default(), st.lat);
        let naive = accel_error_var(&k, &cbn, &f_n);
        k.levelled(&st.q_nb, g);
        let at_rest = accel_error_var(&k, &cbn, &f_n);
        let sb = k.config().init_accel_mps2;
        let lev = g * k.config().init_att_deg[0].to_radians();
        for i in 0..2 {
            assert!(naive[i] > sb * sb, "{naive:?}");
            assert!(
                (at_rest[i] - lev * lev).abs() < 1e-9,
                "{at_rest:?} vs {}",
                lev * lev
            );
        }
        // turned 180 deg about the vertical: the bias's horizontal part flips, the tilt does not
        let turned = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::PI)
            .to_rotation_matrix()
            .into_inner()
            * cbn;
        let after = accel_error_var(&k, &turned, &f_n);
        for v in after {
            // the bias and the tilt that cancelled it now add: (2 sigma_b)^2 per axis
            assert!((v - lev * lev - 4.0 * sb * sb).abs() < 1e-9, "{after:?}");
        }
    }

    /// After a long outage the propagated position variance is large; the fading filter's
    /// variance caps must not shrink it, or the first fix after the outage is gated out and
    /// the filter never recovers.
    #[test]
    fn the_first_fix_after_a_long_outage_is_taken_by_both_filters() {
        for kind in [
            FilterKind::Standard,
            FilterKind::Fading,
            FilterKind::Adaptive,
        ] {
            let mut st = parked();
            let mut k = Kf::new(
                FilterConfig {
                    kind,
                    ..FilterConfig::default()
                },
                st.lat,
            );
            let f = Vector3::new(0.0, 0.0, 9.79);
            for _ in 0..2000 {
                k.propagate(&st, &f, 0.1);
            }
            let sig_n = k.covariance()[(6, 6)].sqrt() * 6.37e6;
            assert!(sig_n > 300.0, "{kind:?}: {sig_n} m after 200 s");
            // the INS has drifted 600 m south: the fix is 600 m north of it
            let (rm, _) = earth::radii(st.lat);
            let lat = st.lat + 600.0 / rm;
            let (lat0, lon0) = (st.lat, st.lon);
            assert!(
                k.update(&mut st, lat, lon0, 0.0, None),
                "{kind:?}: gated out"
            );
            assert!(((st.lat - lat0) * rm - 600.0).abs() < 100.0, "{kind:?}");
        }
    }

    /// An isolated fix kilometres off is rejected and the state is untouched.
    #[test]
    fn a_fix_kilometres_off_is_gated_out() {
        let mut st = parked();
        let mut k = Kf::new(FilterConfig::default(), st.lat);
        k.propagate(&st, &Vector3::new(0.0, 0.0, 9.79), 1.0);
        let before = st;
        let (rm, _) = earth::radii(st.lat);
        let (lat, lon) = (st.lat + 2000.0 / rm, st.lon);
        assert!(!k.update(&mut st, lat, lon, 0.0, None));
        assert_eq!(st, before);
        assert_eq!(k.stats().rejected, 1);
    }

    /// A filter that disagrees with every fix (it has drifted away) re-anchors after
    /// `reanchor_after` rejections in a row instead of coasting forever.
    #[test]
    fn a_run_of_rejections_ends_in_a_reanchor() {
        let mut st = parked();
        let mut k = Kf::new(
            FilterConfig {
                reanchor_after: 5,
                ..FilterConfig::default()
            },
            st.lat,
        );
        let (rm, _) = earth::radii(st.lat);
        let (lat, lon) = (st.lat + 2000.0 / rm, st.lon);
        let taken: Vec<bool> = (0..6)
            .map(|_| {
                k.propagate(&st, &Vector3::new(0.0, 0.0, 9.79), 1.0);
                k.update(&mut st, lat, lon, 0.0, None)
            })
            .collect();
        assert_eq!(taken, [false, false, false, false, true, true]);
        assert_eq!((k.stats().rejected, k.stats().reanchors), (4, 1));
        assert!(((st.lat - lat) * rm).abs() < 50.0);
    }
}
