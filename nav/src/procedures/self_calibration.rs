//! Self-calibration of a dual-axis rotating IMU on a static base (paper 004), commanded over
//! the bus: nav's calibration mode.
//!
//! Sequence: enable both axes of the mechanism; **level** at rest (coarse alignment from the
//! mean specific force and rate, turned into the base's axes through the axes' angles); unlock;
//! **rotate** both axes at the set rate, each reversing after every full turn (the inner axis
//! starting a set time after the outer one); then stop, return both axes to zero and lock. The
//! gyro biases and scale-factor errors are the estimates at the end of the rotation, by two
//! methods side by side:
//! - the paper's decoupled recursive least squares ([`GyroRls`]), each gyro its own two-state
//!   problem against the rate the mechanism's angles and the earth's rate say it should see;
//! - the 14-state static-base alignment Kalman filter ([`AlignKf`]) on the strapdown velocity.
//!
//! **The mechanism's angles on the IMU clock.** Each status frame is stamped with the end time
//! of the last IMU sample nav had when the frame arrived (on the bench a status frame follows
//! the sample it was taken at, so the stamp is exact); the angles at any sample's ends are
//! interpolated between the stamped frames. Samples wait until a status frame at or after their
//! end has come. A status frame stamped one sample late moves that sample's angle increment to
//! its neighbour: the two errors cancel in the integrated measurement below, so an occasional
//! late frame costs nothing that accumulates; a stream steadily late by `d` s is a constant
//! angle lag of `rate * d`, which the reversals average out. Samples with no status frame
//! within [`SelfCalibrationConfig::max_status_gap_s`] on either side are not used (counted).
//!
//! **Why integrated.** The encoder measures angles, not rates: a rate taken from the difference
//! of two encoder angles 10 ms apart is 0.5 arcsec / 10 ms = 50 deg/h of noise, 5000 times the
//! bias sought. The RLS is therefore fed the same model integrated from the start of the
//! rotation, `theta_meas - E = eps T + dK E`, with `E` the expected angle (the earth's rate
//! through the mechanism plus the encoder's angle increments): the encoder's noise enters once,
//! at the ends, instead of once per sample.

use crate::frontend::imu_frames::ImuSample;
use crate::navigation::earth;
use crate::procedures::common::{Core, OnMechanism, Phases, Procedure, Reporting};
use crate::procedures::mission::Mission;
use crate::procedures::rotating_estimator::{
    AlignKf, AlignKfConfig, GyroRls, c_p_b, expected_rate,
};
use crate::procedures::turntable_link::{AxisTrack, LinkTiming, SettingError, TtLink};
use crate::procedures::unit_parameters::ParameterFile;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::collections::VecDeque;
use std::path::PathBuf;
use wire::{NavMode, TtCmd, TtCommand, TtState, TtStatus};

const DPH: f64 = earth::DEG_PER_HOUR_PER_RAD_S;
const G0: f64 = 9.80665;

/// Calibration-mode settings (the `[self_calibration]` table of nav's config).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SelfCalibrationConfig {
    /// Run the procedure at start.
    pub enabled: bool,
    /// Latitude of the site, deg.
    pub latitude_deg: f64,
    /// The mechanism's axis that turns the IMU about the vehicle's z (the outer axis).
    pub outer_axis: u8,
    /// The mechanism's axis that turns the IMU about its own x (the inner axis).
    pub inner_axis: u8,
    /// Rotation rate of both axes, deg/s (the paper: 5).
    pub rate_dps: f64,
    /// Each axis reverses after turning this far, deg (the paper: a full turn).
    pub turn_deg: f64,
    /// The inner axis starts this long after the outer one, s. The paper turns them in step
    /// (0); a quarter turn apart (18 s at 5 deg/s) the coarse attitude's tilt error averages
    /// out of the z gyro's bias (docs/calibration.md).
    pub inner_delay_s: f64,
    /// Coarse alignment at rest, s.
    pub level_s: f64,
    /// Rotation, s (the paper: 900).
    pub rotate_s: f64,
    /// Nominal gyro bias (the estimators' initial sigma), deg/h.
    pub gyro_bias_dph: f64,
    /// Nominal gyro scale-factor error, ppm.
    pub gyro_scale_factor_ppm: f64,
    /// Nominal accelerometer bias, g.
    pub accel_bias_g: f64,
    /// Gyro white noise per sample, deg/h.
    pub gyro_noise_dph: f64,
    /// Accelerometer white noise per sample, g.
    pub accel_noise_g: f64,
    /// The encoder's angle noise (1 sigma), arcsec: the integrated RLS's measurement noise.
    pub encoder_noise_arcsec: f64,
    /// Integrated measurements this often, s.
    pub measure_every_s: f64,
    /// Samples farther than this from a status frame are not used, s.
    pub max_status_gap_s: f64,
    /// The unit calibrated (written in the parameter file).
    pub imu: String,
    /// Where the shell writes the parameter file of the RLS estimates (none: not written).
    pub parameters_out: Option<std::path::PathBuf>,
    /// Heartbeat period, s.
    pub heartbeat_s: f64,
    /// Acknowledgement timeout, s.
    pub ack_timeout_s: f64,
    /// Resends before giving up.
    pub ack_retries: u32,
    /// A move, stop or lock must finish within this, s.
    pub move_timeout_s: f64,
    /// Status silence that aborts, s.
    pub status_timeout_s: f64,
}

impl Default for SelfCalibrationConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            latitude_deg: 30.0,
            outer_axis: 0,
            inner_axis: 1,
            rate_dps: 5.0,
            turn_deg: 360.0,
            inner_delay_s: 18.0,
            level_s: 60.0,
            rotate_s: 900.0,
            gyro_bias_dph: 0.01,
            gyro_scale_factor_ppm: 10.0,
            accel_bias_g: 1e-4,
            gyro_noise_dph: 0.005,
            accel_noise_g: 0.5e-4,
            encoder_noise_arcsec: 0.5,
            measure_every_s: 0.1,
            max_status_gap_s: 0.05,
            imu: "unnamed".into(),
            parameters_out: None,
            heartbeat_s: 0.1,
            ack_timeout_s: 0.25,
            ack_retries: 3,
            move_timeout_s: 30.0,
            status_timeout_s: 0.5,
        }
    }
}

/// A setting of `[self_calibration]` out of its range.
pub type SelfCalibrationConfigError = crate::procedures::turntable_link::SettingError;

impl SelfCalibrationConfig {
    /// Check the settings; the error names the setting.
    pub fn check(&self) -> Result<(), SelfCalibrationConfigError> {
        let bad = |setting, requirement| {
            Err(crate::procedures::turntable_link::SettingError::new(
                "self_calibration",
                setting,
                requirement,
            ))
        };
        crate::procedures::turntable_link::check_site_and_link(
            "self_calibration",
            self.latitude_deg,
            &self.timing(),
            self.move_timeout_s,
        )?;
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if self.outer_axis > 2 || self.inner_axis > 2 || self.outer_axis == self.inner_axis {
            return bad("outer_axis/inner_axis", "two different axes of 0, 1 and 2");
        }
        if !(pos(self.rate_dps) && pos(self.turn_deg)) {
            return bad("rate_dps/turn_deg", "must be positive");
        }
        if !(self.inner_delay_s.is_finite() && self.inner_delay_s >= 0.0) {
            return bad("inner_delay_s", "must be zero or positive");
        }
        if !(pos(self.level_s) && pos(self.rotate_s) && self.rotate_s > self.inner_delay_s) {
            return bad(
                "level_s/rotate_s",
                "must be positive, the rotation longer than the inner axis' delay",
            );
        }
        if ![
            self.gyro_bias_dph,
            self.gyro_scale_factor_ppm,
            self.accel_bias_g,
            self.gyro_noise_dph,
            self.accel_noise_g,
            self.encoder_noise_arcsec,
        ]
        .into_iter()
        .all(pos)
        {
            return bad(
                "gyro_bias_dph/gyro_scale_factor_ppm/accel_bias_g/gyro_noise_dph/accel_noise_g/encoder_noise_arcsec",
                "nominal errors and noises must be positive",
            );
        }
        if !(pos(self.measure_every_s) && pos(self.max_status_gap_s)) {
            return bad("measure_every_s/max_status_gap_s", "must be positive");
        }
        Ok(())
    }

    fn timing(&self) -> LinkTiming {
        LinkTiming {
            heartbeat_s: self.heartbeat_s,
            ack_timeout_s: self.ack_timeout_s,
            ack_retries: self.ack_retries,
            status_timeout_s: self.status_timeout_s,
        }
    }
}

/// Where the procedure is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CalPhase {
    /// Enabling both axes.
    Enabling,
    /// Coarse alignment at rest.
    Levelling,
    /// Withdrawing the lock pins.
    Unlocking,
    /// Rotating and estimating.
    Rotating,
    /// Stopping both axes.
    Stopping,
    /// Returning both axes to zero.
    Returning,
    /// Locking at zero.
    Locking,
    /// Finished with a result.
    Done,
    /// Gave up (see the reason).
    Aborted,
}

/// One method's estimates and their sigmas (the filter's own).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GyroEstimate {
    /// Gyro biases, deg/h.
    pub gyro_bias_dph: [f64; 3],
    /// Gyro scale-factor errors, ppm.
    pub gyro_scale_factor_ppm: [f64; 3],
    /// Sigmas of the biases, deg/h.
    pub bias_sigma_dph: [f64; 3],
    /// Sigmas of the scale-factor errors, ppm.
    pub scale_factor_sigma_ppm: [f64; 3],
    /// The heading error the estimated biases' east drift would cause with the IMU at the
    /// mechanism's zero (what the estimate removes), deg.
    pub heading_from_drift_deg: f64,
}

/// The procedure's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelfCalibrationResult {
    /// The base's heading from the coarse alignment, deg.
    pub base_heading_deg: f64,
    /// The base's pitch and roll from the coarse alignment, deg.
    pub base_tilt_deg: [f64; 2],
    /// The paper's decoupled RLS.
    pub rls: GyroEstimate,
    /// The alignment Kalman filter.
    pub kf: GyroEstimate,
    /// Rotation time the estimates are from, s.
    pub rotation_s: f64,
    /// Reversals of the outer and inner axis.
    pub reversals: [u32; 2],
    /// Integrated measurements the RLS took.
    pub measurements: u64,
    /// IMU samples not used for want of a status frame near them.
    pub samples_without_status: u64,
    /// Start to locked at zero, s.
    pub duration_s: f64,
}

/// Progress, for the operator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalProgress {
    /// Phase.
    pub phase: CalPhase,
    /// Time since the start, s.
    pub elapsed_s: f64,
    /// Time left in this phase (levelling, rotating), s.
    pub phase_left_s: f64,
    /// The RLS's biases so far, deg/h.
    pub rls_bias_dph: Option<[f64; 3]>,
    /// The RLS's scale-factor errors so far, ppm.
    pub rls_scale_factor_ppm: Option<[f64; 3]>,
}

/// An IMU sample waiting for the mechanism's angles at its end.
#[derive(Debug, Clone, Copy)]
struct Pending {
    t0: f64,
    t1: f64,
    dtheta: Vector3<f64>,
    dv: Vector3<f64>,
}

/// Running sums of the rotation (the integrated measurement).
#[derive(Debug, Clone)]
struct Estimation {
    t0: f64,
    rls: GyroRls,
    kf: AlignKf,
    kf_acc: (Vector3<f64>, Vector3<f64>, f64),
    kf_steps: u64,
    measured: Vector3<f64>,
    expected: Vector3<f64>,
    next_measure: f64,
    measurements: u64,
    /// The coarse attitude turned by one sigma of its error about east, north and up, and the
    /// same RLS on each: how much the estimate owes to the attitude it was given.
    q_pert: [UnitQuaternion<f64>; 3],
    expected_pert: [Vector3<f64>; 3],
    rls_pert: [GyroRls; 3],
}

/// The calibration procedure.
#[derive(Debug)]
pub struct SelfCalibrator {
    core: Core<CalPhase>,
    cfg: SelfCalibrationConfig,
    lat: f64,
    axes: [AxisTrack; 2],
    pending: VecDeque<Pending>,
    level: (Vector3<f64>, Vector3<f64>, f64),
    q_nb: Option<UnitQuaternion<f64>>,
    est: Option<Estimation>,
    inner_started: bool,
    rotation_s: f64,
    skipped: u64,
    result: Option<SelfCalibrationResult>,
}

impl SelfCalibrator {
    /// The procedure with these settings (checked).
    pub fn new(cfg: SelfCalibrationConfig) -> Result<Self, SelfCalibrationConfigError> {
        cfg.check()?;
        let mut link = TtLink::new(cfg.timing(), &[cfg.outer_axis, cfg.inner_axis]);
        link.push(TtCommand::Enable, cfg.outer_axis, 0.0);
        link.push(TtCommand::Enable, cfg.inner_axis, 0.0);
        Ok(Self {
            lat: cfg.latitude_deg.to_radians(),
            cfg,
            core: Core::new(CalPhase::Enabling, link),
            axes: [AxisTrack::default(), AxisTrack::default()],
            pending: VecDeque::new(),
            level: (Vector3::zeros(), Vector3::zeros(), 0.0),
            q_nb: None,
            est: None,
            inner_started: false,
            rotation_s: 0.0,
            skipped: 0,
            result: None,
        })
    }

    /// The settings.
    pub fn config(&self) -> &SelfCalibrationConfig {
        &self.cfg
    }

    /// Phase.
    pub fn phase(&self) -> CalPhase {
        self.core.phase
    }

    /// The result, once done.
    pub fn result(&self) -> Option<&SelfCalibrationResult> {
        self.result.as_ref()
    }

    fn where_(&self) -> String {
        format!("{:?}", self.core.phase).to_lowercase()
    }

    fn slot(&self, axis: u8) -> Option<usize> {
        if axis == self.cfg.outer_axis {
            Some(0)
        } else if axis == self.cfg.inner_axis {
            Some(1)
        } else {
            None
        }
    }

    /// A status frame arrived; `t` is the end time of the last IMU sample nav had then.
    pub fn on_status(&mut self, t: f64, st: &TtStatus) {
        let Some(slot) = self.slot(st.axis) else {
            return;
        };
        if self.core.finished() {
            return;
        }
        if let Some(names) = crate::procedures::common::faults_of(st) {
            let w = self.where_();
            self.core.fail(format!(
                "turntable fault on axis {} while {w}: {names}",
                st.axis
            ));
            return;
        }
        self.core.link.on_status(t, st);
        let a = &mut self.axes[slot];
        a.push(t, st.angle_deg);
        if matches!(self.core.phase, CalPhase::Levelling | CalPhase::Unlocking)
            && let Some((_, now)) = a.latest()
        {
            // the mean at rest; restarted should the axis have crept
            if a.rest.1 > 0 && (now - a.rest.0 / f64::from(a.rest.1)).abs() > 0.01 {
                a.rest = (0.0, 0);
            }
            a.rest.0 += now;
            a.rest.1 += 1;
        }
        self.drain();
    }

    /// One IMU sample over `(t1 - dt, t1]` (s, IMU time): its angle and velocity increments
    /// (rad, m/s), as nav's front end corrected them.
    pub fn on_sample(&mut self, t1: f64, dt: f64, dtheta: [f64; 3], dv: [f64; 3], saturated: bool) {
        self.core.t = self.core.t.max(t1);
        if saturated && matches!(self.core.phase, CalPhase::Levelling | CalPhase::Rotating) {
            let w = self.where_();
            self.core.fail(format!(
                "the IMU saturated while {w} (at {} deg/s): the mechanism's rate is beyond the unit's range",
                self.cfg.rate_dps
            ));
            return;
        }
        let (dtheta, dv) = (Vector3::from(dtheta), Vector3::from(dv));
        match self.core.phase {
            CalPhase::Levelling => {
                self.level.0 += dtheta;
                self.level.1 += dv;
                self.level.2 += dt;
            }
            CalPhase::Rotating => {
                self.pending.push_back(Pending {
                    t0: t1 - dt,
                    t1,
                    dtheta,
                    dv,
                });
                self.drain();
            }
            _ => {}
        }
    }

    /// The samples whose angles are known now, into the estimators.
    fn drain(&mut self) {
        let gap = self.cfg.max_status_gap_s;
        while let Some(p) = self.pending.front().copied() {
            let known = self
                .axes
                .iter()
                .all(|a| a.latest().is_some_and(|l| l.0 >= p.t1));
            if !known {
                // no status frame at or after its end yet; one that will never come (the
                // stream stopped) is judged by the status timeout
                return;
            }
            self.pending.pop_front();
            let ends = |a: &AxisTrack| Some((a.start(p.t0, gap)?, a.at(p.t1, gap)?));
            let (Some(z), Some(x), Some(q_nb), Some(e)) = (
                ends(&self.axes[0]),
                ends(&self.axes[1]),
                self.q_nb,
                self.est.as_mut(),
            ) else {
                self.skipped += 1;
                continue;
            };
            self.axes[0].chain = Some((p.t1, z.1));
            self.axes[1].chain = Some((p.t1, x.1));
            let dt = p.t1 - p.t0;
            let r = |d: f64| d.to_radians();
            let mid = [r(0.5 * (x.0 + x.1)), r(0.5 * (z.0 + z.1))];
            let rates = [r(x.1 - x.0) / dt, r(z.1 - z.0) / dt];
            e.expected += expected_rate(self.lat, &q_nb, mid, rates) * dt;
            for (acc, q) in e.expected_pert.iter_mut().zip(&e.q_pert) {
                *acc += expected_rate(self.lat, q, mid, rates) * dt;
            }
            e.measured += p.dtheta;
            // the filter at about 100 Hz whatever the IMU's rate
            e.kf_acc.0 += p.dtheta;
            e.kf_acc.1 += p.dv;
            e.kf_acc.2 += dt;
            if e.kf_acc.2 >= 0.01 - 1e-9 {
                let (th, v, d) =
                    std::mem::replace(&mut e.kf_acc, (Vector3::zeros(), Vector3::zeros(), 0.0));
                e.kf.propagate(&th, &v, d);
                e.kf_steps += 1;
                if e.kf_steps.is_multiple_of(10) {
                    e.kf.update();
                }
            }
            if p.t1 >= e.next_measure {
                e.next_measure += self.cfg.measure_every_s;
                e.measurements += 1;
                let resid = e.measured - e.expected;
                e.rls.observe_integrated(p.t1 - e.t0, &e.expected, &resid);
                for (rls, exp) in e.rls_pert.iter_mut().zip(&e.expected_pert) {
                    rls.observe_integrated(p.t1 - e.t0, exp, &(e.measured - exp));
                }
            }
        }
    }

    /// The next command to send at IMU time `t` (s), if any. Call after feeding the inputs.
    pub fn poll(&mut self, t: f64) -> Option<TtCmd> {
        self.core.t = self.core.t.max(t);
        self.core.t_start.get_or_insert(t);
        crate::procedures::common::poll(self, t)
    }

    fn states(&self) -> [Option<TtState>; 2] {
        [
            self.core.link.state(self.cfg.outer_axis),
            self.core.link.state(self.cfg.inner_axis),
        ]
    }

    fn both(&self, f: impl Fn(TtState) -> bool) -> bool {
        self.states().iter().all(|s| s.is_some_and(&f))
    }

    fn step(&mut self) {
        let since = self.core.t - self.core.phase_since;
        let timeout = self.cfg.move_timeout_s;
        match self.core.phase {
            CalPhase::Enabling => {
                if self.both(|s| s != TtState::Disabled) {
                    self.core.enter(CalPhase::Levelling);
                    self.level = (Vector3::zeros(), Vector3::zeros(), 0.0);
                } else if since > timeout {
                    self.core.fail(
                        "the mechanism's axes did not come up after Enable: are both on the bus?"
                            .into(),
                    );
                }
            }
            CalPhase::Levelling => {
                if !self.both(|s| matches!(s, TtState::Idle | TtState::Locked)) {
                    self.core
                        .fail("an axis moved during the coarse alignment".into());
                } else if since >= self.cfg.level_s {
                    match self.coarse_alignment() {
                        Ok(q) => {
                            self.q_nb = Some(q);
                            self.core.enter(CalPhase::Unlocking);
                            for (axis, s) in [self.cfg.outer_axis, self.cfg.inner_axis]
                                .into_iter()
                                .zip(self.states())
                            {
                                if s == Some(TtState::Locked) {
                                    self.core.link.push(TtCommand::Unlock, axis, 0.0);
                                }
                            }
                        }
                        Err(why) => self.core.fail(why),
                    }
                }
            }
            CalPhase::Unlocking => {
                if self.both(|s| s == TtState::Idle) {
                    self.start_rotation();
                } else if since > timeout {
                    self.core.fail(format!(
                        "the lock pins did not withdraw while {w}",
                        w = self.where_()
                    ));
                }
            }
            CalPhase::Rotating => self.rotate(since),
            CalPhase::Stopping => {
                if self.both(|s| s == TtState::Idle) {
                    self.core.enter(CalPhase::Returning);
                    self.core
                        .link
                        .push(TtCommand::Home, self.cfg.outer_axis, 0.0);
                    self.core
                        .link
                        .push(TtCommand::Home, self.cfg.inner_axis, 0.0);
                } else if since > timeout {
                    self.core
                        .fail(format!("the axes did not stop within {timeout} s"));
                }
            }
            CalPhase::Returning => {
                // both back at zero and at rest (a second after the commands, so that the
                // state read is the move's, not the rest before it)
                if since > 1.0 && self.both(|s| s == TtState::Idle) {
                    self.core.enter(CalPhase::Locking);
                    self.core
                        .link
                        .push(TtCommand::Lock, self.cfg.outer_axis, 0.0);
                    self.core
                        .link
                        .push(TtCommand::Lock, self.cfg.inner_axis, 0.0);
                } else if since > timeout {
                    self.core.fail(format!(
                        "the axes did not return to zero within {timeout} s"
                    ));
                }
            }
            CalPhase::Locking => {
                if self.both(|s| s == TtState::Locked) {
                    self.core.phase = CalPhase::Done;
                    let d = self.core.elapsed();
                    if let Some(r) = self.result.as_mut() {
                        r.duration_s = d;
                    }
                } else if since > timeout {
                    self.core
                        .fail(format!("the lock pins did not engage within {timeout} s"));
                }
            }
            CalPhase::Done | CalPhase::Aborted => {}
        }
    }

    /// The base's attitude from the mean rate and specific force at rest, turned into the base's
    /// axes through the axes' angles.
    fn coarse_alignment(&self) -> Result<UnitQuaternion<f64>, String> {
        let (th, v, t) = self.level;
        let (Some(z), Some(x)) = (self.axes[0].latest(), self.axes[1].latest()) else {
            return Err("no axis angles for the coarse alignment".into());
        };
        if t <= 0.0 {
            return Err("no IMU samples during the coarse alignment".into());
        }
        let c = c_p_b(x.1.to_radians(), z.1.to_radians());
        let (w_b, f_b) = (c * (th / t), c * (v / t));
        let g = earth::gravity(self.lat, 0.0);
        if (f_b.norm() - g).abs() > 0.05 * g {
            return Err(format!(
                "specific force {:.3} m/s^2 at rest, not the gravity's {g:.3}: is the base static?",
                f_b.norm()
            ));
        }
        let up = f_b.normalize();
        let east = w_b.cross(&up);
        let horiz = earth::OMEGA_IE * self.lat.cos();
        if east.norm() < 0.5 * horiz {
            return Err(format!(
                "horizontal earth rate {:.3} deg/h at rest, not {:.3}: a gyro fault or a moving base",
                east.norm() * DPH,
                horiz * DPH
            ));
        }
        let east = east.normalize();
        let north = up.cross(&east);
        let c_bn = Matrix3::from_rows(&[east.transpose(), north.transpose(), up.transpose()]);
        Ok(UnitQuaternion::from_rotation_matrix(
            &Rotation3::from_matrix_unchecked(c_bn),
        ))
    }

    fn start_rotation(&mut self) {
        let Some(q_nb) = self.q_nb else {
            self.core.fail("rotation without a coarse alignment".into());
            return;
        };
        self.core.enter(CalPhase::Rotating);
        let c = &self.cfg;
        let (Some(z), Some(x)) = (self.axes[0].latest(), self.axes[1].latest()) else {
            self.core
                .fail("no axis angles at the start of the rotation".into());
            return;
        };
        let q_np = q_nb * c_p_b(x.1.to_radians(), z.1.to_radians());
        let dph = |x: f64| x / DPH;
        let kf = AlignKf::new(
            AlignKfConfig {
                attitude0: [0.1f64.to_radians(), 1f64.to_radians()],
                velocity0: 0.1,
                accel_bias0: c.accel_bias_g * G0,
                gyro_bias0: dph(c.gyro_bias_dph),
                gyro_sf0: c.gyro_scale_factor_ppm * 1e-6,
                gyro_noise: dph(c.gyro_noise_dph),
                accel_noise: c.accel_noise_g * G0,
                velocity_noise: 1e-4,
            },
            q_np,
            self.lat,
            0.0,
            0.0,
        );
        // the integrated measurement's noise: the encoder at the interval's end (its start is
        // the mean at rest)
        let enc = (c.encoder_noise_arcsec / 3600.0).to_radians();
        let rls = GyroRls::new(dph(c.gyro_bias_dph), c.gyro_scale_factor_ppm * 1e-6, enc);
        // the coarse alignment's sigmas: tilt from the accelerometer bias, heading from the
        // gyro bias against the horizontal earth rate (and the tilt through the latitude)
        let tilt = c.accel_bias_g;
        let heading =
            dph(c.gyro_bias_dph) / (earth::OMEGA_IE * self.lat.cos()) + tilt * self.lat.tan().abs();
        let turn = |axis: Vector3<f64>, a: f64| UnitQuaternion::from_scaled_axis(axis * a) * q_nb;
        let q_pert = [
            turn(Vector3::x(), tilt),
            turn(Vector3::y(), tilt),
            turn(Vector3::z(), heading),
        ];
        // the rotation's reference: each axis's mean angle at rest
        for (slot, now) in [(0, z), (1, x)] {
            let a = &mut self.axes[slot];
            let rest = if a.rest.1 > 0 {
                a.rest.0 / f64::from(a.rest.1)
            } else {
                now.1
            };
            a.chain = Some((self.core.t, rest));
        }
        self.est = Some(Estimation {
            t0: self.core.t,
            rls,
            q_pert,
            expected_pert: [Vector3::zeros(); 3],
            rls_pert: [rls; 3],
            kf,
            kf_acc: (Vector3::zeros(), Vector3::zeros(), 0.0),
            kf_steps: 0,
            measured: Vector3::zeros(),
            expected: Vector3::zeros(),
            next_measure: self.core.t + c.measure_every_s,
            measurements: 0,
        });
        self.axes[0].dir = 1.0;
        self.axes[0].turn_from = z.1;
        self.core
            .link
            .push(TtCommand::Rate, self.cfg.outer_axis, self.cfg.rate_dps);
        self.inner_started = false;
    }

    fn rotate(&mut self, since: f64) {
        let c = self.cfg.clone();
        if since >= c.rotate_s {
            self.rotation_s = since;
            self.finish_estimates();
            self.core.enter(CalPhase::Stopping);
            self.core.link.push(TtCommand::Stop, c.outer_axis, 0.0);
            self.core.link.push(TtCommand::Stop, c.inner_axis, 0.0);
            return;
        }
        if !self.inner_started && since >= c.inner_delay_s {
            self.inner_started = true;
            if let Some(x) = self.axes[1].latest() {
                self.axes[1].dir = 1.0;
                self.axes[1].turn_from = x.1;
            }
            self.core
                .link
                .push(TtCommand::Rate, c.inner_axis, c.rate_dps);
            return;
        }
        for (slot, axis) in [(0, c.outer_axis), (1, c.inner_axis)] {
            let a = &mut self.axes[slot];
            let Some((_, now)) = a.latest() else { continue };
            if a.dir != 0.0 && (now - a.turn_from) * a.dir >= c.turn_deg {
                a.dir = -a.dir;
                a.turn_from = now;
                a.reversals += 1;
                let rate = a.dir * c.rate_dps;
                self.core.link.push(TtCommand::Rate, axis, rate);
            }
        }
    }

    fn finish_estimates(&mut self) {
        let (Some(e), Some(q_nb)) = (&self.est, self.q_nb) else {
            self.core.fail("no rotation data".into());
            return;
        };
        let lat = self.lat;
        // the heading error an east drift of the IMU at the mechanism's zero causes
        let heading = |b: Vector3<f64>| ((q_nb * b).x / (earth::OMEGA_IE * lat.cos())).to_degrees();
        let est =
            |b: Vector3<f64>, k: Vector3<f64>, sb: Vector3<f64>, sk: Vector3<f64>| GyroEstimate {
                gyro_bias_dph: (b * DPH).into(),
                gyro_scale_factor_ppm: (k * 1e6).into(),
                bias_sigma_dph: (sb * DPH).into(),
                scale_factor_sigma_ppm: (sk * 1e6).into(),
                heading_from_drift_deg: heading(b),
            };
        let (mut rsb, mut rsk) = e.rls.sigmas();
        // the estimate's sensitivity to the coarse attitude, one sigma about each axis, added
        // to the filter's own sigma (the decoupled RLS takes the attitude as exact)
        for p in &e.rls_pert {
            let (db, dk) = (
                p.bias() - e.rls.bias(),
                p.scale_factor() - e.rls.scale_factor(),
            );
            rsb = rsb.zip_map(&db, |s, d| (s * s + d * d).sqrt());
            rsk = rsk.zip_map(&dk, |s, d| (s * s + d * d).sqrt());
        }
        let (ksb, ksk) = e.kf.sigmas();
        let r = est(e.rls.bias(), e.rls.scale_factor(), rsb, rsk);
        let k = est(e.kf.bias(), e.kf.scale_factor(), ksb, ksk);
        let (hd, pitch, roll) = crate::navigation::strapdown::NavState {
            q_nb,
            v: Vector3::zeros(),
            lat,
            lon: 0.0,
            h: 0.0,
        }
        .euler();
        self.result = Some(SelfCalibrationResult {
            base_heading_deg: hd.to_degrees().rem_euclid(360.0),
            base_tilt_deg: [pitch.to_degrees(), roll.to_degrees()],
            rls: r,
            kf: k,
            rotation_s: self.rotation_s,
            reversals: [self.axes[0].reversals, self.axes[1].reversals],
            measurements: e.measurements,
            samples_without_status: self.skipped,
            duration_s: 0.0,
        });
    }

    /// Progress, for the operator.
    pub fn progress(&self) -> CalProgress {
        let since = self.core.t - self.core.phase_since;
        let left = match self.core.phase {
            CalPhase::Levelling => (self.cfg.level_s - since).max(0.0),
            CalPhase::Rotating => (self.cfg.rotate_s - since).max(0.0),
            _ => 0.0,
        };
        let rls = self.est.as_ref().map(|e| &e.rls);
        CalProgress {
            phase: self.core.phase,
            elapsed_s: self.core.elapsed(),
            phase_left_s: left,
            rls_bias_dph: rls.map(|r| (r.bias() * DPH).into()),
            rls_scale_factor_ppm: rls.map(|r| (r.scale_factor() * 1e6).into()),
        }
    }

    /// The phase, and a coarse stage number within it, for reporting changes.
    pub fn stage(&self) -> CalPhase {
        self.core.phase
    }
}

impl OnMechanism for SelfCalibrator {
    type Phase = CalPhase;
    fn core(&mut self) -> &mut Core<CalPhase> {
        &mut self.core
    }
    fn at(&self) -> String {
        self.where_()
    }
    fn advance(&mut self) {
        self.step()
    }
}

impl Phases for CalPhase {
    const DONE: Self = CalPhase::Done;
    const ABORTED: Self = CalPhase::Aborted;
}

crate::procedures::common::procedure!(SelfCalibrator, "self-calibration", |s, t, st| s
    .on_status(t, st));

/// Self-calibration at exit.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SelfCalibrationSummary {
    /// Last phase.
    pub phase: crate::procedures::self_calibration::CalPhase,
    /// The result, when it finished.
    pub result: Option<crate::procedures::self_calibration::SelfCalibrationResult>,
    /// Why it gave up, when it did.
    pub abort: Option<String>,
    /// The parameter file's content (the RLS's estimates on top of the parameters nav started
    /// with), when it finished.
    pub parameters: Option<crate::procedures::unit_parameters::ImuParameters>,
    /// Where the parameter file was written, when it was.
    #[serde(default)]
    pub parameters_file: Option<PathBuf>,
    /// Turntable commands sent.
    pub commands_sent: u64,
    /// Turntable frames received (status, acks).
    pub turntable_frames: u64,
    /// Commands sent again for want of an acknowledgement.
    pub command_retries: u64,
    /// Acknowledgements that came too late (or matched no command).
    pub stale_acks: u64,
}

/// The rotating IMU's self-calibration as the pipeline runs it (its [`Mission`]).
#[derive(Debug)]
pub(crate) struct SelfCalibration {
    pub(crate) cal: SelfCalibrator,
    /// The gyro parameters nav started with (the estimates are residuals on top of them).
    start: crate::procedures::unit_parameters::GyroParameters,
    parameters: Option<crate::procedures::unit_parameters::ImuParameters>,
}

impl SelfCalibration {
    /// The procedure of config section `c` on a unit whose front end applies the gyro
    /// parameters `start` (none when it is not enabled).
    pub(crate) fn make(
        c: &SelfCalibrationConfig,
        start: crate::procedures::unit_parameters::GyroParameters,
    ) -> Result<Option<Box<dyn Mission>>, SettingError> {
        if !c.enabled {
            return Ok(None);
        }
        Ok(Some(Box::new(Self {
            cal: SelfCalibrator::new(c.clone())?,
            start,
            parameters: None,
        })))
    }

    /// The parameter file of a result: the RLS's residual estimates composed with the
    /// parameters the front end applied (`(raw - b0) / (1 + k0)` read `(1 + k') w + b'`).
    fn parameters(
        &self,
        r: &SelfCalibrationResult,
    ) -> crate::procedures::unit_parameters::ImuParameters {
        let c = self.cal.config();
        let (b0, k0) = (self.start.bias_dph, self.start.scale_factor_ppm);
        let mut g = self.start;
        for j in 0..3 {
            let k0f = k0[j] * 1e-6;
            g.bias_dph[j] = b0[j] + r.rls.gyro_bias_dph[j] * (1.0 + k0f);
            g.scale_factor_ppm[j] =
                ((1.0 + r.rls.gyro_scale_factor_ppm[j] * 1e-6) * (1.0 + k0f) - 1.0) * 1e6;
        }
        crate::procedures::unit_parameters::ImuParameters {
            format: crate::procedures::unit_parameters::FORMAT.into(),
            imu: c.imu.clone(),
            procedure: format!(
                "nav self-calibration (paper 004 decoupled RLS, integrated): dual-axis rotation at {} deg/s reversing every {} deg, inner axis {} s behind, {:.0} s, static base at latitude {} deg",
                c.rate_dps, c.turn_deg, c.inner_delay_s, r.rotation_s, c.latitude_deg
            ),
            // the shell stamps the date: the pipeline's output depends on its input only
            date: String::new(),
            gyro: g,
        }
    }

    /// Its section of nav's summary (`rep`: what the pipeline counted for it).
    pub(crate) fn section(&self, rep: &Reporting) -> SelfCalibrationSummary {
        let c = &self.cal;
        SelfCalibrationSummary {
            phase: c.phase(),
            result: c.result().cloned(),
            abort: c.abort().map(str::to_string),
            parameters: self.parameters.clone(),
            parameters_file: None,
            commands_sent: rep.commands_sent,
            turntable_frames: rep.frames,
            command_retries: c.ack_counters().0,
            stale_acks: c.ack_counters().1,
        }
    }
}

impl Mission for SelfCalibration {
    fn procedure(&mut self) -> &mut dyn Procedure {
        &mut self.cal
    }
    fn procedure_ref(&self) -> &dyn Procedure {
        &self.cal
    }
    fn on_sample(&mut self, t1: f64, dt: f64, s: &ImuSample) {
        self.cal.on_sample(t1, dt, s.dtheta, s.dv, s.saturated);
    }
    fn mode(&self) -> NavMode {
        match self.cal.phase() {
            CalPhase::Enabling | CalPhase::Levelling => NavMode::Levelling,
            _ => NavMode::Calibrating,
        }
    }
    fn made(&mut self) -> Option<(Option<PathBuf>, ParameterFile)> {
        let r = self.cal.result().cloned()?;
        let p = self.parameters(&r);
        self.parameters = Some(p.clone());
        Some((
            self.cal.config().parameters_out.clone(),
            ParameterFile::Imu(p),
        ))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The encoder's angle unwraps across 360 deg, interpolates between frames, refuses a
    /// sample across a gap in the status stream, and a sample starts where the last one ended.
    #[test]
    fn axis_angles_unwrap_interpolate_and_chain() {
        let mut a = AxisTrack::default();
        for (i, ang) in [359.8, 359.9, 0.0, 0.1].into_iter().enumerate() {
            a.push(i as f64 * 0.01, ang);
        }
        let at = |t: f64| a.at(t, 0.05).expect("covered");
        assert!((at(0.025) - 360.05).abs() < 1e-9, "{}", at(0.025));
        assert!((at(0.03) - 360.1).abs() < 1e-9);
        assert_eq!(a.at(0.031, 0.05), None, "not yet covered");
        a.push(0.2, 2.0);
        assert_eq!(a.at(0.1, 0.05), None, "across a 0.17 s gap");
        a.chain = Some((0.02, 123.0));
        assert_eq!(a.start(0.02, 0.05), Some(123.0));
        assert!((a.start(0.015, 0.05).expect("interpolated") - 359.95).abs() < 1e-9);
    }

    /// Settings out of range are refused with their name.
    #[test]
    fn bad_settings_name_themselves() {
        let ok = SelfCalibrationConfig::default();
        ok.check().expect("defaults");
        let e = SelfCalibrationConfig {
            inner_axis: 0,
            ..ok.clone()
        }
        .check()
        .unwrap_err();
        assert_eq!(e.setting, "outer_axis/inner_axis");
        let e = SelfCalibrationConfig {
            rotate_s: 10.0,
            ..ok
        }
        .check()
        .unwrap_err();
        assert_eq!(e.setting, "level_s/rotate_s");
    }
}
