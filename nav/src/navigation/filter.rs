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
//! `dv' = f^n x phi + v x (2 dw_ie + dw_en) - (2 w_ie + w_en) x dv + C_b^n nabla - (dg/dh) dh u`
//! (`u` up: gravity at the computed height),
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

use crate::navigation::earth;
use crate::navigation::strapdown::NavState;
use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// The fading filter does not fade while a zero-velocity update was taken this recently, s
/// (they come each second while the vehicle stands).
pub const STANDING_HOLD_S: f64 = 1.5;

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
    /// Fading-memory factor per second of fixes (applied at each measurement to the navigation
    /// and IMU states, as `s^dt` with `dt` the time since the previous fix, at most 1 s: per
    /// fix at 1 Hz, and the same memory in time at any rate). Paper 003 uses 1.2 at 1 Hz with
    /// the receiver's error taken for white noise; with the receiver's wander modelled, 1.02
    /// (a memory of about 50 s) keeps the sigmas consistent (see docs/navigation.md).
    pub fading_factor: f64,
    /// The adaptive filter's forgetting factor `b` per second of fixes (0-1, as `b^dt` per
    /// fix): its noise estimate remembers about `1 / (1 - b)` seconds.
    pub adaptive_forgetting: f64,
    /// The HDOP at which `gps_sigma_m` and `gps_sigma_h_m` hold: the white noise assumed for
    /// each fix is scaled by its HDOP over this (0: the HDOP is not used). Used only when
    /// neither GST nor `gps_uere_m` states the receiver's accuracy.
    pub hdop_ref: f64,
    /// Take the receiver's own accuracy (NMEA GST) when it states one: the white noise and the
    /// correlated error the filter assumes are scaled together by GST's sigma over the
    /// configured total (`hypot(gps_sigma_m, gps_gm_sigma_m)`, and the same for the height).
    pub use_gst: bool,
    /// Without GST: the receiver's 1-sigma error per horizontal axis per unit of HDOP (white
    /// and wander together), m; each fix's error is its HDOP times this, the height's
    /// `gps_sigma_h_m / gps_sigma_m` times that. 0: HDOP does not set the size (the configured
    /// noise holds).
    pub gps_uere_m: f64,
    /// Where the receiver states no accuracy of its own (no GST), learn the size of its error
    /// from the innovations: the configured (or HDOP-sized) white noise and wander are scaled
    /// together by a factor that brings the normalized innovations to their expected size,
    /// remembering about a minute. A receiver of another class than the configured one then
    /// gets sigmas that fit it.
    pub learn_receiver_scale: bool,
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
    /// Its correlation time, s (for a receiver of the configured size: see
    /// `gps_gm_tau_follows_size`).
    pub gps_gm_tau_s: f64,
    /// A receiver better than the configured one (by GST, HDOP or what the filter learnt) has
    /// a faster wander: the correlation time shrinks with the square root of its size over
    /// the configured, to a fifth at most. false: `gps_gm_tau_s` always.
    pub gps_gm_tau_follows_size: bool,
    /// Gyro white noise (angle random walk), deg/sqrt(h).
    pub gyro_arw_dpsh: f64,
    /// Gyro bias instability: the drift's wander about its turn-on value (first-order
    /// Gauss-Markov, stationary 1 sigma per axis), deg/h; 0: a constant drift. The filter
    /// keeps its drift states a random walk with the same short-term spectrum
    /// (`2 sigma^2 / tau`), the drift's turn-on value being unknown. Without it the drift
    /// states were sure of a drift that had moved on: on an hour's drive with a sub-metre
    /// receiver the velocity NEES per dof rose to 4-5 after half an hour (docs/navigation-results.md).
    pub gyro_bias_instability_dph: f64,
    /// The instability's correlation time, s.
    pub gyro_bias_tau_s: f64,
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
    /// The receiver's whole assumed error (white and wander), 1 sigma per axis, m: horizontal
    /// and vertical.
    pub fn gps_total_sigma_m(&self) -> (f64, f64) {
        (
            self.gps_sigma_m.hypot(self.gps_gm_sigma_m),
            self.gps_sigma_h_m.hypot(self.gps_gm_sigma_h_m),
        )
    }

    /// Refuse settings the filter cannot run with, naming the field.
    pub fn check(&self) -> Result<(), String> {
        let positive = [
            ("gps_sigma_m", self.gps_sigma_m),
            ("gps_sigma_h_m", self.gps_sigma_h_m),
            ("gps_gm_tau_s", self.gps_gm_tau_s),
            ("gyro_bias_tau_s", self.gyro_bias_tau_s),
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
            ("gps_uere_m", self.gps_uere_m),
            ("gyro_arw_dpsh", self.gyro_arw_dpsh),
            ("gyro_bias_instability_dph", self.gyro_bias_instability_dph),
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

impl std::fmt::Display for FilterKind {
    /// Its name in nav's config (`standard`, `fading`, `adaptive`).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Standard => "standard",
            Self::Fading => "fading",
            Self::Adaptive => "adaptive",
        })
    }
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
            use_gst: true,
            gps_uere_m: 0.0,
            learn_receiver_scale: true,
            correction: Correction::Feedback,
            // a 25 m class receiver (paper 003's): 12 m over 300 s plus 6 m white per axis, the
            // height 1.6 times the horizontal
            gps_sigma_m: 6.0,
            gps_sigma_h_m: 9.6,
            gps_gm_sigma_m: 12.0,
            gps_gm_sigma_h_m: 19.2,
            gps_gm_tau_s: 300.0,
            gps_gm_tau_follows_size: true,
            gyro_arw_dpsh: 0.1 / 60.0,
            // the paper's unit: 0.05 deg/h over 600 s
            gyro_bias_instability_dph: 0.05,
            gyro_bias_tau_s: 600.0,
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
    /// Of those, in the filter's first minute (a start that does not fit the receiver: the
    /// wrong height, the wrong size).
    #[serde(default)]
    pub rejected_first_minute: u64,
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
    /// Fixes whose size came from the receiver's GST.
    #[serde(default)]
    pub sized_by_gst: u64,
    /// Fixes whose size came from their HDOP (`gps_uere_m`, or `hdop_ref` for the white part).
    #[serde(default)]
    pub sized_by_hdop: u64,
    /// Fixes sized by the configured noise alone.
    #[serde(default)]
    pub sized_by_config: u64,
    /// The receiver's correlated error the filter assumes now, over the configured one
    /// (north, east, up): follows what the receiver states, smoothed over 10 s.
    #[serde(default)]
    pub receiver_scale: [f64; 3],
    /// The factor learnt from the innovations (horizontal, vertical) where the receiver
    /// states no accuracy (`learn_receiver_scale`).
    #[serde(default)]
    pub learned_scale: [f64; 2],
    /// Zero-velocity updates applied (the vehicle standing, by the IMU's own evidence).
    #[serde(default)]
    pub zero_velocity_updates: u64,
    /// Zero-velocity updates refused by the gate (the INS's velocity too far from zero for
    /// its sigma: not standing after all, or the filter lost).
    #[serde(default)]
    pub zero_velocity_refused: u64,
}

/// What the receiver says of a fix's accuracy.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StatedAccuracy {
    /// GST's 1-sigma errors of latitude (north) and longitude (east), and of altitude when it
    /// gives one, m.
    pub gst: Option<([f64; 2], Option<f64>)>,
    /// GGA's HDOP.
    pub hdop: Option<f64>,
}

/// Where a fix's assumed error came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SizedBy {
    Gst,
    Hdop,
    Config,
}

/// The receiver's correlated error follows what the receiver states with this time constant,
/// s (its statements jitter from fix to fix; the wander they describe does not).
const RECEIVER_SCALE_TAU_S: f64 = 10.0;

/// The learnt receiver scale: the normalized innovations are averaged over this long, s of
/// fixes (over the fixes so far at the start) ...
const LEARN_MEMORY_S: f64 = 20.0;

/// ... and the scale moves to what their average asks with this time constant, s.
const LEARN_TAU_S: f64 = 10.0;

/// A fix's normalized innovation counts at most this much in the learnt scale (a multipath
/// jump that passed the gate must not inflate it).
const LEARN_RHO_MAX: f64 = 9.0;

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
    /// Time propagated since the last fix was offered, s: the fading and the adaptive
    /// forgetting are per second, so that their memory is the same at any fix rate.
    since_update: f64,
    /// Time propagated since the filter started, s.
    age_s: f64,
    /// When (on `age_s`) a zero-velocity update was last taken: the vehicle stands.
    stood_at_s: Option<f64>,
    /// The receiver's correlated error over the configured one (north, east, up), once a fix
    /// has said.
    rx_scale: Option<[f64; 3]>,
    /// The learnt scale (horizontal, vertical), the average normalized innovation it still
    /// has to answer, and the seconds of fixes it has learnt from.
    learned: [f64; 2],
    learn_rho: [f64; 2],
    learned_s: f64,
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
            since_update: 0.0,
            age_s: 0.0,
            stood_at_s: None,
            rx_scale: None,
            learned: [1.0; 2],
            learn_rho: [1.0; 2],
            learned_s: 0.0,
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

    /// The INS starts at a fix (its position, at state `s`): its position error is that fix's
    /// error, the receiver's wander plus a white draw, of the size the receiver stated
    /// ([`StatedAccuracy`], as a fix is sized in [`Kf::update`]). The position variance is set
    /// to that and correlated with the receiver-error states: the filter knows that the INS
    /// and the receiver are off by the same wander at the start. With `init_pos_m` (10 m) and
    /// no correlation, a start at the fix of a 25 m class receiver (21 m vertical) had a
    /// position NEES of 2 on a two-minute drive.
    pub fn started_at_fix(&mut self, acc: &StatedAccuracy, s: &NavState) {
        let (stated, _) = self.stated_scale(acc);
        self.follow_receiver_scale(stated, 1.0);
        let (rm, rn) = earth::radii(s.lat);
        let m_per = [rm + s.h, (rn + s.h) * s.lat.cos(), 1.0];
        for i in 0..3 {
            let white = self.r_m2[i] * stated[i] * stated[i] / (m_per[i] * m_per[i]);
            let pbb = self.p[(B + i, B + i)];
            for j in 0..N {
                self.p[(6 + i, j)] = 0.0;
                self.p[(j, 6 + i)] = 0.0;
            }
            self.p[(6 + i, 6 + i)] = pbb + white;
            self.p[(6 + i, B + i)] = pbb;
            self.p[(B + i, 6 + i)] = pbb;
            self.cap[6 + i] = self.cap[6 + i].max(100.0 * (pbb + white));
        }
    }

    /// Counters.
    pub fn stats(&self) -> FilterStats {
        let g = (self.gyro_bias + Vector3::new(self.x[9], self.x[10], self.x[11]))
            * (3600.0f64.to_degrees());
        let a = self.accel_bias + Vector3::new(self.x[12], self.x[13], self.x[14]);
        let k = self.rx_scale.unwrap_or([1.0; 3]);
        FilterStats {
            gyro_bias_dph: g.into(),
            accel_bias_mps2: a.into(),
            gps_sigma_now_m: std::array::from_fn(|i| self.r_m2[i].sqrt() * k[i]),
            receiver_scale: k,
            learned_scale: self.learned,
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
        // gravity at the computed height: a height error dh changes the gravity nav removes
        // by its gradient (the vertical channel's instability). Without it a receiver's
        // vertical wander of tens of metres over hours (the 25 m class, 2.3 h on a highway)
        // left a vertical velocity error of 0.1 m/s against a sigma of 0.03 (NEES 18).
        f[(5, 8)] = -earth::gravity_gradient(s.lat, s.h);
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
        let tau = self.receiver_tau_s();
        for i in 0..3 {
            f[(B + i, B + i)] = -1.0 / tau;
        }
        let phi = MatN::identity() + f * t + f * f * (t * t / 2.0);
        let mut q = MatN::zeros();
        let arw = self.cfg.gyro_arw_dpsh.to_radians() / 60.0;
        let vrw = self.cfg.accel_vrw_mpss;
        let drift = (self.cfg.gyro_bias_instability_dph / 3600.0).to_radians();
        let drift_q = 2.0 * drift * drift / self.cfg.gyro_bias_tau_s * t;
        let k = self.rx_scale.unwrap_or([1.0; 3]);
        let gm = [
            k[0] * self.cfg.gps_gm_sigma_m / rmh,
            k[1] * self.cfg.gps_gm_sigma_m / (rnh * cl),
            k[2] * self.cfg.gps_gm_sigma_h_m,
        ];
        for i in 0..3 {
            q[(i, i)] = arw * arw * t;
            q[(3 + i, 3 + i)] = vrw * vrw * t;
            q[(9 + i, 9 + i)] = drift_q;
            q[(B + i, B + i)] = 2.0 * gm[i] * gm[i] / tau * t;
        }
        self.since_update += t;
        self.age_s += t;
        self.x = phi * self.x;
        self.p = phi * self.p * phi.transpose() + q;
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// The size of a fix's error over the configured one (north, east, up), and where it came
    /// from: GST, else HDOP times `gps_uere_m`, else the configured noise (scale 1).
    fn stated_scale(&self, acc: &StatedAccuracy) -> ([f64; 3], SizedBy) {
        let c = &self.cfg;
        let (total_h, total_v) = c.gps_total_sigma_m();
        let bound = |v: f64| v.clamp(1e-3, 1e3);
        if c.use_gst
            && let Some(([n, e], u)) = acc.gst
        {
            let h = (0.5 * (n * n + e * e)).sqrt() / total_h;
            let v = u.map_or(h, |u| u / total_v);
            return (
                [bound(n / total_h), bound(e / total_h), bound(v)],
                SizedBy::Gst,
            );
        }
        match acc.hdop {
            Some(d) if c.gps_uere_m > 0.0 && d.is_finite() && d > 0.0 => {
                let k = bound(d * c.gps_uere_m / total_h);
                ([k; 3], SizedBy::Hdop)
            }
            _ => ([1.0; 3], SizedBy::Config),
        }
    }

    /// The correlation time of the receiver's wander the filter assumes, s: the configured one
    /// for a receiver of the configured size or worse; shorter for a better one, as the square
    /// root of its size over the configured (down to a fifth). A receiver whose errors are
    /// corrected (SBAS, DGPS) or dual-frequency has had its slow parts (ionosphere, orbits,
    /// clocks) taken out: what is left, multipath and noise, changes faster. Assuming the
    /// 25 m class's 300 s for a sub-metre receiver whose error changes over a minute made the
    /// filter take the receiver's wander for velocity error: velocity NEES 3.5.
    fn receiver_tau_s(&self) -> f64 {
        let tau = self.cfg.gps_gm_tau_s.max(1e-3);
        if !self.cfg.gps_gm_tau_follows_size {
            return tau;
        }
        let k = self.rx_scale.map_or(1.0, |k| 0.5 * (k[0] + k[1]));
        tau * k.sqrt().clamp(0.2, 1.0)
    }

    /// Follow the receiver's stated size with the correlated error's scale (at once at the
    /// first fix, then over [`RECEIVER_SCALE_TAU_S`]); the receiver-error states' covariance is
    /// rescaled with it, so that what the filter knew of the wander keeps its correlations.
    fn follow_receiver_scale(&mut self, target: [f64; 3], per_s: f64) {
        let old = self.rx_scale.unwrap_or([1.0; 3]);
        let a = match self.rx_scale {
            None => 1.0,
            Some(_) => (per_s / RECEIVER_SCALE_TAU_S).clamp(0.0, 1.0),
        };
        let new: [f64; 3] = std::array::from_fn(|i| old[i] + a * (target[i] - old[i]));
        for i in 0..3 {
            let r = new[i] / old[i];
            for j in 0..N {
                self.p[(B + i, j)] *= r;
                self.p[(j, B + i)] *= r;
            }
        }
        self.rx_scale = Some(new);
    }

    /// Move the learnt receiver scale so that the innovations' normalized squares (`innov_i^2 /
    /// S_ii`, 1 on average when the model fits, at most [`LEARN_RHO_MAX`]) come to their
    /// expected size. Their average `m` over [`LEARN_MEMORY_S`] says how far off the scale is
    /// (the innovations' variance goes with the scale squared); the scale takes `m^(dt/tau)` of
    /// it per fix ([`LEARN_TAU_S`]) and the average is divided by what was taken, so that a
    /// receiver thirty times better than configured is learnt within a minute or two, and one
    /// that fits stays put.
    fn learn_scale(&mut self, innov: &Vector3<f64>, s_diag: &Vector3<f64>, per_s: f64) {
        let rho = |i: usize| (innov[i] * innov[i] / s_diag[i]).clamp(0.0, LEARN_RHO_MAX);
        let rhos = [0.5 * (rho(0) + rho(1)), rho(2)];
        if per_s <= 0.0 || rhos.iter().any(|r| !r.is_finite()) {
            return;
        }
        self.learned_s += per_s;
        let a = (per_s / self.learned_s.min(LEARN_MEMORY_S)).min(1.0);
        for ((m, k), r) in self
            .learn_rho
            .iter_mut()
            .zip(self.learned.iter_mut())
            .zip(rhos)
        {
            *m += a * (r - *m);
            let f = m.max(1e-4).powf(per_s / LEARN_TAU_S);
            let new = (*k * f.sqrt()).clamp(0.02, 50.0);
            *m /= (new / *k).powi(2);
            *k = new;
        }
    }

    /// The size of this fix's error over the configured one (north, east, up), for its white
    /// noise, and whether the scale is being learnt: what the receiver states (GST, or HDOP
    /// times the UERE) scales the white noise at once and the correlated error smoothly
    /// ([`Kf::follow_receiver_scale`]); where it states nothing the learnt scale does; else the
    /// legacy HDOP ratio scales the white part. Counted by where the size came from.
    fn size_fix(&mut self, acc: &StatedAccuracy, per_s: f64) -> ([f64; 3], bool) {
        let (stated, mut by) = self.stated_scale(acc);
        let legacy = match acc.hdop {
            Some(d)
                if by == SizedBy::Config && self.cfg.hdop_ref > 0.0 && d.is_finite() && d > 0.0 =>
            {
                by = SizedBy::Hdop;
                (d / self.cfg.hdop_ref).clamp(0.2, 20.0)
            }
            _ => 1.0,
        };
        match by {
            SizedBy::Gst => self.stats.sized_by_gst += 1,
            SizedBy::Hdop => self.stats.sized_by_hdop += 1,
            SizedBy::Config => self.stats.sized_by_config += 1,
        }
        // where the receiver states nothing of its own, what the innovations taught
        let learn = self.cfg.learn_receiver_scale && by != SizedBy::Gst;
        let stated: [f64; 3] = if learn {
            let [h, v] = self.learned;
            [stated[0] * h, stated[1] * h, stated[2] * v]
        } else {
            stated
        };
        if stated != [1.0; 3] || self.rx_scale.is_some() {
            self.follow_receiver_scale(stated, per_s);
        }
        let white: [f64; 3] = std::array::from_fn(|i| stated[i] * legacy);
        (white, learn)
    }

    /// A GPS position (rad, rad, m) measured at the state's time, with what the receiver said
    /// of its accuracy. Returns whether it was used.
    pub fn update(
        &mut self,
        s: &mut NavState,
        lat: f64,
        lon: f64,
        h: f64,
        acc: &StatedAccuracy,
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
        // the share of a second since the last fix (1 at 1 Hz and after an outage): fading and
        // forgetting per second, not per fix (at 5 Hz a per-fix fading of 1.02 discounted five
        // times as fast, and the fading filter's RMS error rose sixfold)
        let per_s = std::mem::take(&mut self.since_update).clamp(0.0, 1.0);
        let (white, learn) = self.size_fix(acc, per_s);
        let r_of = |r_m2: &[f64; 3]| {
            SMatrix::<f64, 3, 3>::from_diagonal(&Vector3::from_fn(|i, _| {
                r_m2[i] * white[i] * white[i] / (m_per[i] * m_per[i])
            }))
        };
        self.fade(per_s);
        // H = [0 0 I 0 0 -I]: the INS's position error less the receiver's
        let mut h_mat = SMatrix::<f64, 3, N>::zeros();
        for i in 0..3 {
            h_mat[(i, 6 + i)] = 1.0;
            h_mat[(i, B + i)] = -1.0;
        }
        let innov = z - h_mat * self.x;
        let r_before = self.r_m2;
        // the adaptive filter's estimate of the white part, where the receiver states its
        // accuracy; where it does not, the learnt scale does that job for every kind (both at
        // once pulled the white part down and the wander up: position NEES 0.4)
        let adapt = self.cfg.kind == FilterKind::Adaptive && !learn;
        if adapt {
            self.adapt_noise(&h_mat, &innov, &m_per, &white, per_s);
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
        if nis > self.cfg.gate_nis && self.beyond_stated(&innov, &h_mat, &r, &white, &m_per) {
            self.rejected_in_a_row += 1;
            if self.cfg.reanchor_after == 0 || self.rejected_in_a_row < self.cfg.reanchor_after {
                self.stats.rejected += 1;
                if self.age_s < 60.0 {
                    self.stats.rejected_first_minute += 1;
                }
                // a rejected fix teaches the noise estimate nothing
                if adapt {
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
        if learn {
            let s_diag = (h_mat * self.p * h_mat.transpose() + r).diagonal();
            self.learn_scale(&innov, &s_diag, per_s);
        }
        let k = self.p * h_mat.transpose() * s_inv;
        self.x += k * innov;
        let ikh = MatN::identity() - k * h_mat;
        // Joseph form keeps P symmetric and positive
        self.p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
        self.stats.updates += 1;
        self.nis_sum += nis;
        self.stats.mean_nis = self.nis_sum / self.stats.updates as f64;
        self.correct(s);
        true
    }

    /// A zero-velocity update: the vehicle stands (the navigator's judgement, from the IMU's
    /// own evidence), so the INS's velocity is its velocity error, measured with `sigma_mps`
    /// per axis (what standing leaves: the body rocking on its suspension). `H = [0 I 0 0 0
    /// 0]`; refused (and counted) when its NIS passes the gate. Returns whether it was used.
    pub fn zero_velocity(&mut self, s: &mut NavState, sigma_mps: f64) -> bool {
        let z = s.v;
        let mut h_mat = SMatrix::<f64, 3, N>::zeros();
        for i in 0..3 {
            h_mat[(i, 3 + i)] = 1.0;
        }
        let innov = z - h_mat * self.x;
        let r = SMatrix::<f64, 3, 3>::identity() * (sigma_mps * sigma_mps);
        let s_mat = h_mat * self.p * h_mat.transpose() + r;
        let Some(s_inv) = s_mat.try_inverse() else {
            return false;
        };
        let nis = (innov.transpose() * s_inv * innov)[(0, 0)];
        if !(nis.is_finite() && nis <= self.cfg.gate_nis) {
            self.stats.zero_velocity_refused += 1;
            return false;
        }
        let k = self.p * h_mat.transpose() * s_inv;
        self.x += k * innov;
        let ikh = MatN::identity() - k * h_mat;
        self.p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
        self.stats.zero_velocity_updates += 1;
        self.stood_at_s = Some(self.age_s);
        self.correct(s);
        true
    }

    /// The fading filter's discount of what it learnt, for the share `per_s` of a second since
    /// the last fix (nothing for the other kinds).
    fn fade(&mut self, per_s: f64) {
        if self.cfg.kind != FilterKind::Fading {
            return;
        }
        // a standing vehicle teaches the filter nothing new of its heading and drifts: fading
        // them then only drives them to their caps, and the stop's zero-velocity updates meet
        // sigmas that no longer say what the filter knows (over the E6 highway's ten-minute
        // stop, position NEES per dof 4.9, and velocity 0.33 once it drove on)
        if self
            .stood_at_s
            .is_some_and(|t| self.age_s - t <= STANDING_HOLD_S)
        {
            return;
        }
        // fading discounts what the filter learnt of its own horizontal navigation and IMU
        // states; the receiver's error (a model of the receiver, not of the INS) keeps its
        // memory, and so does the vertical channel, which would otherwise follow each fix's
        // white height noise with nothing to check its velocity against: P <- D P D with
        // D = sqrt(s) on those states, 1 on the others (stays positive). The fading may not
        // push a variance over its cap, but never takes back what the propagation put there
        // (after an outage the position variance is rightly large).
        let before = self.p.diagonal();
        let f = self.cfg.fading_factor.powf(per_s).sqrt();
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

    /// The estimate applied to the navigation state: fed back each fix, or (output correction)
    /// once the free INS has left the error model's linear range.
    fn correct(&mut self, s: &mut NavState) {
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
    }

    /// The innovation `innov` is beyond what the receiver's own stated accuracy allows, on
    /// top of the filter's uncertainty: its NIS over the gate with each axis's innovation
    /// variance at least the receiver's whole stated (or learnt) variance, `white` times the
    /// configured total (white and wander). The filter's own innovation covariance may be
    /// smaller, once it has learnt part of the receiver's wander; gating on it alone refused
    /// fixes whose error was within three of the receiver's stated sigma (a good fix, which no
    /// filter may refuse). A jump of many stated sigmas is still refused.
    fn beyond_stated(
        &self,
        innov: &Vector3<f64>,
        h_mat: &SMatrix<f64, 3, N>,
        r: &SMatrix<f64, 3, 3>,
        white: &[f64; 3],
        m_per: &[f64; 3],
    ) -> bool {
        let (total_h, total_v) = self.cfg.gps_total_sigma_m();
        let total = [total_h, total_h, total_v];
        let mut s_mat = h_mat * self.p * h_mat.transpose() + r;
        for i in 0..3 {
            let stated = (white[i] * total[i] / m_per[i]).powi(2);
            s_mat[(i, i)] = s_mat[(i, i)].max(stated);
        }
        match s_mat.try_inverse() {
            Some(s_inv) => (innov.transpose() * s_inv * innov)[(0, 0)] > self.cfg.gate_nis,
            None => true,
        }
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
        white: &[f64; 3],
        per_s: f64,
    ) {
        let b = self.cfg.adaptive_forgetting.clamp(0.0, 0.999).powf(per_s);
        let d = 1.0 - b;
        let hph = h_mat * self.p * h_mat.transpose();
        let base = [
            self.cfg.gps_sigma_m.powi(2),
            self.cfg.gps_sigma_m.powi(2),
            self.cfg.gps_sigma_h_m.powi(2),
        ];
        for i in 0..3 {
            let k2 = m_per[i] * m_per[i] / (white[i] * white[i]);
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

    /// The accelerometer bias estimated but not yet taken out of the IMU's increments, m/s^2
    /// (body): with output correction all that was learnt since the last fold, with feedback
    /// none (it is fed back at each fix).
    pub fn accel_bias_unapplied(&self) -> Vector3<f64> {
        Vector3::new(self.x[12], self.x[13], self.x[14])
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

    /// A parked vehicle and a filter of `kind` with nav's default config otherwise.
    fn parked_filter(kind: FilterKind) -> (NavState, Kf) {
        let st = parked();
        let cfg = FilterConfig {
            kind,
            ..FilterConfig::default()
        };
        (st, Kf::new(cfg, st.lat))
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
            let (mut st, mut k) = parked_filter(kind);
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
                k.update(&mut st, lat, lon0, 0.0, &StatedAccuracy::default()),
                "{kind:?}: gated out"
            );
            assert!(((st.lat - lat0) * rm - 600.0).abs() < 100.0, "{kind:?}");
        }
    }

    /// A fix within 3 of the receiver's stated sigma on every axis is taken, however sure the
    /// filter has become of the receiver's wander; one many sigmas off is still refused.
    #[test]
    fn a_good_fix_is_never_refused_and_a_jump_still_is() {
        for kind in [
            FilterKind::Standard,
            FilterKind::Fading,
            FilterKind::Adaptive,
        ] {
            let mut st = parked();
            let cfg = FilterConfig {
                kind,
                ..FilterConfig::default()
            };
            let (total_h, total_v) = cfg.gps_total_sigma_m();
            let mut k = Kf::new(cfg, st.lat);
            let f = Vector3::new(0.0, 0.0, 9.79);
            // the receiver states its accuracy (GST): what a good fix is measured against
            let acc = StatedAccuracy {
                gst: Some(([total_h, total_h], Some(total_v))),
                hdop: None,
            };
            // ten minutes of fixes on the spot: the filter learns the (zero) wander
            for _ in 0..600 {
                k.propagate(&st, &f, 1.0);
                let (lat, lon, h) = (st.lat, st.lon, st.h);
                k.update(&mut st, lat, lon, h, &acc);
            }
            let (rm, rn) = earth::radii(st.lat);
            let off = |n: f64, e: f64, u: f64, st: &NavState| {
                (st.lat + n / rm, st.lon + e / (rn * st.lat.cos()), st.h + u)
            };
            k.propagate(&st, &f, 1.0);
            let (lat, lon, h) = off(2.9 * total_h, -2.9 * total_h, 2.9 * total_v, &st);
            assert!(
                k.last_nis.is_some() && k.update(&mut st, lat, lon, h, &acc),
                "{kind:?}: a fix 2.9 sigma off on every axis refused (NIS {:?})",
                k.last_nis
            );
            assert!(
                k.last_nis.is_some_and(|n| n > k.config().gate_nis),
                "{kind:?}: the filter's own NIS {:?} would not have refused it: the test proves nothing",
                k.last_nis
            );
            k.propagate(&st, &f, 1.0);
            let (lat, lon, h) = off(50.0 * total_h, 0.0, 0.0, &st);
            assert!(
                !k.update(&mut st, lat, lon, h, &acc),
                "{kind:?}: a 50 sigma jump taken"
            );
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
        assert!(!k.update(&mut st, lat, lon, 0.0, &StatedAccuracy::default()));
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
                k.update(&mut st, lat, lon, 0.0, &StatedAccuracy::default())
            })
            .collect();
        assert_eq!(taken, [false, false, false, false, true, true]);
        assert_eq!((k.stats().rejected, k.stats().reanchors), (4, 1));
        assert!(((st.lat - lat) * rm).abs() < 50.0);
    }

    /// The receiver's own accuracy sizes the fixes: GST's sigmas over the configured total
    /// scale the white noise at once and the correlated error over the next seconds; HDOP times
    /// the UERE does the same when there is no GST; with neither the configured noise holds. A
    /// few-metre receiver's fixes then pull the position sigma down to its size.
    #[test]
    fn the_receivers_stated_accuracy_sizes_its_fixes() {
        let run = |acc: StatedAccuracy, uere: f64| {
            let mut st = parked();
            let mut k = Kf::new(
                FilterConfig {
                    kind: FilterKind::Standard,
                    gps_uere_m: uere,
                    // fixes without noise: nothing to learn from
                    learn_receiver_scale: false,
                    ..FilterConfig::default()
                },
                st.lat,
            );
            let (lat, lon, h) = (st.lat, st.lon, st.h);
            for _ in 0..120 {
                for _ in 0..10 {
                    k.propagate(&st, &Vector3::new(0.0, 0.0, 9.79), 0.1);
                }
                assert!(k.update(&mut st, lat, lon, h, &acc));
            }
            let (rm, _) = earth::radii(st.lat);
            (k.stats(), k.covariance()[(6, 6)].sqrt() * rm)
        };
        // the default filter: a 25 m class receiver, 13.4 m per horizontal axis in all
        let total = 6.0f64.hypot(12.0);
        let few_m = StatedAccuracy {
            gst: Some(([1.7, 1.7], Some(2.7))),
            hdop: Some(0.8),
        };
        let (gst, sig_gst) = run(few_m, 0.0);
        assert_eq!((gst.sized_by_gst, gst.sized_by_hdop), (120, 0));
        assert!(
            (gst.receiver_scale[0] - 1.7 / total).abs() < 1e-9,
            "{gst:?}"
        );
        assert!((gst.gps_sigma_now_m[0] - 6.0 * 1.7 / total).abs() < 1e-9);
        let total_v = 9.6f64.hypot(19.2);
        assert!((gst.receiver_scale[2] - 2.7 / total_v).abs() < 1e-9);
        let (conf, sig_conf) = run(StatedAccuracy::default(), 0.0);
        assert_eq!(conf.sized_by_config, 120);
        assert_eq!(conf.receiver_scale, [1.0; 3]);
        assert!(
            sig_gst < 0.2 * sig_conf && sig_gst > 0.3,
            "north sigma {sig_gst} m with GST, {sig_conf} m without"
        );
        // no GST: HDOP 0.8 times a UERE of 2.1 m is the same 1.7 m
        let hdop_only = StatedAccuracy {
            gst: None,
            hdop: Some(0.8),
        };
        let (hd, sig_hd) = run(hdop_only, 1.7 / 0.8);
        assert_eq!(hd.sized_by_hdop, 120);
        assert!((hd.receiver_scale[0] - 1.7 / total).abs() < 1e-9);
        assert!(
            (sig_hd - sig_gst).abs() < 0.2 * sig_gst,
            "{sig_hd} vs {sig_gst}"
        );
        // GST switched off in the config: the HDOP, then the configured noise
        let mut st = parked();
        let mut k = Kf::new(
            FilterConfig {
                use_gst: false,
                ..FilterConfig::default()
            },
            st.lat,
        );
        k.propagate(&st, &Vector3::new(0.0, 0.0, 9.79), 1.0);
        let (lat, lon, h) = (st.lat, st.lon, st.h);
        assert!(k.update(&mut st, lat, lon, h, &few_m));
        assert_eq!(k.stats().sized_by_config, 1);
    }

    /// The fading filter's memory is in seconds: at 5 Hz it discounts per second what it
    /// discounts at 1 Hz, not five times as much.
    #[test]
    fn fading_is_per_second_at_any_fix_rate() {
        let sigma_after = |rate: f64| {
            let mut st = parked();
            let mut k = Kf::new(FilterConfig::default(), st.lat);
            let (lat, lon, h) = (st.lat, st.lon, st.h);
            let n = (rate * 60.0) as usize;
            for _ in 0..n {
                k.propagate(&st, &Vector3::new(0.0, 0.0, 9.79), 1.0 / rate);
                k.update(&mut st, lat, lon, h, &StatedAccuracy::default());
            }
            k.covariance()[(0, 0)].sqrt()
        };
        let (a, b) = (sigma_after(1.0), sigma_after(5.0));
        // five times the fixes shrink the tilt's sigma a little, never inflate it
        assert!(b <= a * 1.05 && b > 0.3 * a, "1 Hz {a}, 5 Hz {b}");
    }

    /// A standing vehicle (a zero-velocity update each second beside its fixes): the fading
    /// filter does not fade what the stop cannot teach it, so its heading's sigma after ten
    /// minutes is what the standard filter's is, not driven to its cap; once the updates stop
    /// (the vehicle drives off) it fades again.
    #[test]
    fn the_fading_filter_holds_its_memory_while_the_vehicle_stands() {
        // the heading's sigma after ten minutes standing, and after two more without updates
        let heading_sigma = |kind: FilterKind| {
            let (mut st, mut k) = parked_filter(kind);
            let (lat, lon, h) = (st.lat, st.lon, st.h);
            let mut at = [0.0; 2];
            for i in 0..720 {
                k.propagate(&st, &Vector3::new(0.0, 0.0, 9.79), 1.0);
                if i < 600 {
                    assert!(k.zero_velocity(&mut st, 0.01));
                }
                k.update(&mut st, lat, lon, h, &StatedAccuracy::default());
                if i == 599 {
                    at[0] = k.covariance()[(2, 2)].sqrt();
                }
            }
            at[1] = k.covariance()[(2, 2)].sqrt();
            at
        };
        let standard = heading_sigma(FilterKind::Standard);
        let fading = heading_sigma(FilterKind::Fading);
        assert!(
            (fading[0] / standard[0] - 1.0).abs() < 0.05,
            "standing: standard {}, fading {}",
            standard[0],
            fading[0]
        );
        // the updates over: the fading filter discounts again, the standard does not
        assert!(
            fading[1] / fading[0] > 2.0 * (standard[1] / standard[0]),
            "after: standard {standard:?}, fading {fading:?}"
        );
    }

    /// A receiver that states nothing (no GST, no UERE) but is eight times better than the
    /// configured one: the filter learns its size from the innovations within a couple of
    /// minutes, and its mean NIS comes to about 3 (0.05 without learning).
    #[test]
    fn the_size_of_a_silent_receiver_is_learnt() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let run = |learn: bool| {
            let mut rng = rand::rngs::StdRng::seed_from_u64(7);
            let n = Normal::new(0.0, 1.0).unwrap();
            let mut st = parked();
            let mut k = Kf::new(
                FilterConfig {
                    kind: FilterKind::Standard,
                    learn_receiver_scale: learn,
                    ..FilterConfig::default()
                },
                st.lat,
            );
            let (rm, rn) = earth::radii(st.lat);
            let (lat0, lon0, h0) = (st.lat, st.lon, st.h);
            // the receiver: white 1.2 m per axis, 2 m in height (the configured 13.4 / 21.5)
            let (mut nis, mut count) = (0.0, 0);
            for i in 0..600 {
                k.propagate(&st, &Vector3::new(0.0, 0.0, 9.79), 1.0);
                let lat = lat0 + 1.2 * n.sample(&mut rng) / rm;
                let lon = lon0 + 1.2 * n.sample(&mut rng) / (rn * lat0.cos());
                let h = h0 + 2.0 * n.sample(&mut rng);
                k.update(&mut st, lat, lon, h, &StatedAccuracy::default());
                if i >= 300 {
                    nis += k.last_nis().unwrap_or(f64::NAN);
                    count += 1;
                }
            }
            (k.stats(), nis / f64::from(count))
        };
        let (learnt, nis) = run(true);
        let (fixed, nis_fixed) = run(false);
        eprintln!(
            "learnt scale {:?}, mean NIS {nis:.2}; without learning {nis_fixed:.3}",
            learnt.learned_scale
        );
        assert!((2.0..4.5).contains(&nis), "{nis}");
        assert!(nis_fixed < 0.3, "{nis_fixed}");
        assert!(
            learnt.learned_scale[0] < 0.3 && learnt.learned_scale[0] > 0.03,
            "{:?}",
            learnt.learned_scale
        );
        assert_eq!(fixed.learned_scale, [1.0; 2]);
    }
}
