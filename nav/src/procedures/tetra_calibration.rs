//! Kalman calibration of a redundant MEMS gyro unit on a three-axis table (paper 001),
//! commanded over the bus, and its parity monitor on the calibrated outputs.
//!
//! Sequence: enable the table's three axes (unlock any that are locked); run the paper's
//! profile (rest; the body's x, y and z axes in turn at the set rate; rest) in rate mode, the
//! 16-state filter ([`TetraKf`]) taking every sample of the four gyros against the rate the
//! table's encoders say the body turns at ([`table_rate`]); when asked, run the profile again
//! with the parity monitor ([`ParityMonitor`]) on the outputs corrected by the estimates, the
//! table's rate as its reference; then return the axes to zero and lock them.
//!
//! **The table did what was commanded.** Every second of the profile in which a rate is held
//! (a second's margin at each change), each axis's encoder rate over that second must be the
//! commanded one within [`TetraCalibrationConfig::rate_tolerance_dps`]; the first second that
//! is not aborts the procedure, and its data are never taken as a result.
//!
//! The unit's frames (MEMS_GYRO) ride on the IMU's strobe: each one is tied to the IMU sample
//! whose counter's low byte it carries (the last one nav has), and a frame that does not match
//! is counted and not used. Angles and rates of the axes come from the status frames as in
//! [`crate::procedures::self_calibration`] (each frame stamped with the IMU time it arrived at, interpolated to the
//! samples' ends). A sample's reference rate is the encoders' angle change over the sample
//! widened by [`TetraCalibrationConfig::reference_half_window_s`] on each side where the rate
//! holds (the sample's own where it changes): the encoder's 0.5 arcsec of noise over 0.11 s instead of 0.01 s
//! (0.002 deg/s instead of 0.02: with the plain per-sample difference, the filter's scale
//! factors came out 1e-4 off at the paper's profile, against 9e-6 without encoder noise).

use crate::procedures::common::{Core, OnMechanism, Phases, Procedure, Reporting};
use crate::procedures::mission::Mission;
use crate::procedures::redundant_rates::{ParityMonitor, Status};
use crate::procedures::rotating_estimator::{GyroCoefficients, TETRA_GYROS, TetraKf, table_rate};
use crate::procedures::turntable_link::{AxisTrack, LinkTiming, SettingError, TtLink};
use crate::procedures::unit_parameters::ParameterFile;
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::collections::VecDeque;
use std::path::PathBuf;
use wire::{MemsGyro, NavMode, TtCmd, TtCommand, TtState, TtStatus};

/// Calibration settings (the `[tetra_calibration]` table of nav's config).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct TetraCalibrationConfig {
    /// Run the procedure at start.
    pub enabled: bool,
    /// Latitude of the table, deg.
    pub latitude_deg: f64,
    /// Heading of the table's base (its x axis at zero, clockwise from north), deg; the base
    /// is level.
    pub base_heading_deg: f64,
    /// What the table's axes 0, 1 and 2 turn about, outermost first: a permutation of "xyz".
    pub gimbal: String,
    /// Rate of each turn, deg/s (the paper: 20).
    pub rate_dps: f64,
    /// Rest before the turns, s.
    pub rest_s: f64,
    /// Each turn, s (the paper: 75).
    pub turn_s: f64,
    /// Rest after the turns, s.
    pub end_rest_s: f64,
    /// The unit's pulse weight, deg.
    pub pulse_deg: f64,
    /// The filter's initial covariance `P0 = p0 I`.
    pub p0: f64,
    /// The filter's measurement noise `R = r I`, (deg/s)^2.
    pub r: f64,
    /// The table's rate must be the commanded one within this, deg/s.
    pub rate_tolerance_dps: f64,
    /// The reference rate of a sample is the encoders' over the sample widened by this on both
    /// sides, s (exact for constant accelerations; the encoder's noise divided by the span).
    pub reference_half_window_s: f64,
    /// Run the profile again with the parity monitor on the calibrated outputs.
    pub monitor: bool,
    /// The unit's serial number (what its parameter files name).
    pub imu: String,
    /// Start from this parameter file (relative to the config's folder): no calibration, the
    /// profile with the parity monitor on the outputs the file corrects.
    pub parameters: Option<std::path::PathBuf>,
    /// Where the shell writes the parameter file of the estimates (none: not written).
    pub parameters_out: Option<std::path::PathBuf>,
    /// The coefficients of `parameters`, as the config's loader read and checked them.
    #[serde(skip)]
    pub coefficients: Option<[GyroCoefficients; TETRA_GYROS]>,
    /// The gyros' white noise per sample, deg/s (the monitor's threshold; the output's
    /// quantization is added).
    pub gyro_noise_dps: f64,
    /// The monitor alarms at this many sigmas of the parity's mean...
    pub monitor_k: f64,
    /// ... over this many samples.
    pub monitor_window: usize,
    /// Heartbeat period, s.
    pub heartbeat_s: f64,
    /// Acknowledgement timeout, s.
    pub ack_timeout_s: f64,
    /// Resends before giving up.
    pub ack_retries: u32,
    /// A stop, return or lock must finish within this, s.
    pub move_timeout_s: f64,
    /// Status silence that aborts, s.
    pub status_timeout_s: f64,
}

impl Default for TetraCalibrationConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            latitude_deg: 45.0,
            base_heading_deg: 0.0,
            gimbal: "zxy".into(),
            rate_dps: 20.0,
            rest_s: 60.0,
            turn_s: 75.0,
            end_rest_s: 75.0,
            pulse_deg: 1e-4,
            p0: 1.0,
            r: 1e-3,
            rate_tolerance_dps: 0.01,
            reference_half_window_s: 0.05,
            monitor: false,
            imu: "unnamed".into(),
            parameters: None,
            parameters_out: None,
            coefficients: None,
            gyro_noise_dps: 0.005,
            monitor_k: 5.0,
            monitor_window: 50,
            heartbeat_s: 0.1,
            ack_timeout_s: 0.25,
            ack_retries: 3,
            move_timeout_s: 60.0,
            status_timeout_s: 0.5,
        }
    }
}

/// A setting of `[tetra_calibration]` out of its range.
pub type TetraCalibrationConfigError = crate::procedures::turntable_link::SettingError;

impl TetraCalibrationConfig {
    /// Check the settings; the error names the setting.
    pub fn check(&self) -> Result<(), TetraCalibrationConfigError> {
        let bad = |setting, requirement| {
            Err(crate::procedures::turntable_link::SettingError::new(
                "tetra_calibration",
                setting,
                requirement,
            ))
        };
        crate::procedures::turntable_link::check_site_and_link(
            "tetra_calibration",
            self.latitude_deg,
            &self.timing(),
            self.move_timeout_s,
        )?;
        let pos = |x: f64| x.is_finite() && x > 0.0;
        let mut g: Vec<char> = self.gimbal.chars().collect();
        g.sort_unstable();
        if g != ['x', 'y', 'z'] {
            return bad("gimbal", "must be a permutation of \"xyz\" (axes 0, 1, 2)");
        }
        if ![
            self.rate_dps,
            self.turn_s,
            self.pulse_deg,
            self.p0,
            self.r,
            self.rate_tolerance_dps,
            self.gyro_noise_dps,
            self.monitor_k,
        ]
        .into_iter()
        .all(pos)
        {
            return bad(
                "rate_dps/turn_s/pulse_deg/p0/r/rate_tolerance_dps/gyro_noise_dps/monitor_k",
                "must be positive",
            );
        }
        if !(self.rest_s >= 2.0 && self.end_rest_s >= 2.0 && self.turn_s >= 4.0) {
            return bad(
                "rest_s/end_rest_s/turn_s",
                "rests of 2 s or more, turns of 4 s or more",
            );
        }
        if !(0.0..=0.5).contains(&self.reference_half_window_s) {
            return bad("reference_half_window_s", "must lie in [0, 0.5] s");
        }
        if self.monitor_window < 3 {
            return bad("monitor_window", "must be 3 or more");
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

    /// The profile's length, s.
    pub fn profile_s(&self) -> f64 {
        self.rest_s + 3.0 * self.turn_s + self.end_rest_s
    }

    /// The table axis (0, 1, 2) that turns about body axis `body` (0 x, 1 y, 2 z).
    fn table_axis(&self, body: usize) -> u8 {
        let c = ['x', 'y', 'z'][body];
        self.gimbal.chars().position(|g| g == c).unwrap_or(body) as u8
    }

    /// The turn under way at profile time `t`: (body axis, table axis, from, to).
    fn turn_at(&self, t: f64) -> Option<(usize, u8, f64, f64)> {
        (0..3).find_map(|b| {
            let from = self.rest_s + b as f64 * self.turn_s;
            (t >= from && t < from + self.turn_s)
                .then(|| (b, self.table_axis(b), from, from + self.turn_s))
        })
    }
}

/// Where the procedure is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TetraPhase {
    /// Enabling the three axes.
    Enabling,
    /// Withdrawing lock pins.
    Unlocking,
    /// The profile, calibrating.
    Calibrating,
    /// The profile again, the parity monitor watching.
    Monitoring,
    /// Stopping the axes.
    Stopping,
    /// Returning the axes to zero.
    Returning,
    /// Locking at zero.
    Locking,
    /// Finished.
    Done,
    /// Gave up.
    Aborted,
}

/// What the parity monitor saw.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MonitorOutcome {
    /// The monitor's final state.
    pub status: Status,
    /// Profile time of the alarm, s.
    pub detected_at_s: Option<f64>,
    /// Profile time of the isolation, s.
    pub isolated_at_s: Option<f64>,
    /// Largest error of the rate from the gyros in use against the table's, after the
    /// isolation (or over the whole pass without one), deg/s.
    pub worst_rate_error_dps: f64,
}

/// The procedure's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TetraCalibrationResult {
    /// Per gyro: bias (deg/s), scale-factor error, mounting angles (rad).
    pub coefficients: [GyroCoefficients; TETRA_GYROS],
    /// Their sigmas (the filter's own; its initial ones when the coefficients came from a
    /// file).
    pub sigmas: [GyroCoefficients; TETRA_GYROS],
    /// The coefficients came from a parameter file (no calibration ran).
    #[serde(default)]
    pub from_file: bool,
    /// Samples the filter took.
    pub samples: u64,
    /// Seconds of the profile checked against the commanded rates (all passed).
    pub checked_s: u64,
    /// MEMS frames that matched no IMU sample.
    pub unmatched_frames: u64,
    /// Samples not used for want of a status frame near them.
    pub samples_without_status: u64,
    /// The monitor's pass, when run.
    pub monitor: Option<MonitorOutcome>,
    /// Start to locked at zero, s.
    pub duration_s: f64,
}

/// Progress, for the operator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TetraProgress {
    /// Phase.
    pub phase: TetraPhase,
    /// Time since the start, s.
    pub elapsed_s: f64,
    /// Time left in this phase's profile, s.
    pub phase_left_s: f64,
    /// The body axis turning now (x, y, z), if any.
    pub turning: Option<char>,
    /// The filter's biases so far, deg/s.
    pub bias_dps: [f64; TETRA_GYROS],
}

/// A sample of the unit waiting for the table's angles at its end.
#[derive(Debug, Clone, Copy)]
struct Pending {
    t0: f64,
    t1: f64,
    out: [f64; TETRA_GYROS],
}

/// The procedure.
#[derive(Debug)]
pub struct TetraCalibrator {
    core: Core<TetraPhase>,
    cfg: TetraCalibrationConfig,
    lat: f64,
    q_nb: UnitQuaternion<f64>,
    axes: [AxisTrack; 3],
    last_counts: Option<[u16; TETRA_GYROS]>,
    pending: VecDeque<Pending>,
    kf: TetraKf,
    /// Coefficients from a parameter file: the monitor corrects with these, and the profile
    /// runs once, monitoring.
    loaded: Option<[GyroCoefficients; TETRA_GYROS]>,
    monitor: Option<ParityMonitor>,
    outcome: Option<MonitorOutcome>,
    /// The turn commanded last (body axis), so that each is commanded once.
    commanded: Option<usize>,
    /// The current second of the rate check: its start (profile time) and each axis's
    /// (stamp, angle) then.
    block: Option<(f64, [(f64, f64); 3])>,
    checked_s: u64,
    samples: u64,
    unmatched: u64,
    skipped: u64,
    result: Option<TetraCalibrationResult>,
}

impl TetraCalibrator {
    /// The procedure with these settings (checked).
    pub fn new(cfg: TetraCalibrationConfig) -> Result<Self, TetraCalibrationConfigError> {
        let loaded = cfg.coefficients;
        Self::with_coefficients(cfg, loaded)
    }

    /// The procedure starting from a unit's known coefficients (its parameter file, which the
    /// shell loaded and checked): no calibration, the profile once with the parity monitor.
    pub fn with_coefficients(
        cfg: TetraCalibrationConfig,
        loaded: Option<[GyroCoefficients; TETRA_GYROS]>,
    ) -> Result<Self, TetraCalibrationConfigError> {
        cfg.check()?;
        let mut link = TtLink::new(cfg.timing(), &[0, 1, 2]);
        for a in 0..3 {
            link.push(TtCommand::Enable, a, 0.0);
        }
        Ok(Self {
            lat: cfg.latitude_deg.to_radians(),
            // the base level, its x axis at the heading: body to ENU
            q_nb: UnitQuaternion::from_axis_angle(
                &Vector3::z_axis(),
                -cfg.base_heading_deg.to_radians(),
            ),
            kf: TetraKf::new(cfg.p0, cfg.r),
            loaded,
            cfg,
            core: Core::new(TetraPhase::Enabling, link),
            axes: Default::default(),
            last_counts: None,
            pending: VecDeque::new(),
            monitor: None,
            outcome: None,
            commanded: None,
            block: None,
            checked_s: 0,
            samples: 0,
            unmatched: 0,
            skipped: 0,
            result: None,
        })
    }

    /// The settings.
    pub fn config(&self) -> &TetraCalibrationConfig {
        &self.cfg
    }

    /// The parameter file of the estimates (undated: the shell stamps it), once a calibration
    /// finished; none when the coefficients came from a file.
    pub fn parameters(&self) -> Option<crate::procedures::unit_parameters::RedundantParameters> {
        let r = self.result.as_ref().filter(|r| !r.from_file)?;
        let c = &self.cfg;
        Some(crate::procedures::unit_parameters::RedundantParameters {
            format: crate::procedures::unit_parameters::REDUNDANT_FORMAT.into(),
            imu: c.imu.clone(),
            procedure: format!(
                "nav tetra-calibration (paper 001 16-state Kalman filter): three-axis table, x y z at {} deg/s for {} s each, {} s of profile, latitude {} deg",
                c.rate_dps,
                c.turn_s,
                c.profile_s(),
                c.latitude_deg
            ),
            date: String::new(),
            gyro: r
                .coefficients
                .iter()
                .map(crate::procedures::unit_parameters::RedundantGyro::of)
                .collect(),
        })
    }

    /// Phase.
    pub fn phase(&self) -> TetraPhase {
        self.core.phase
    }

    /// The result, once done.
    pub fn result(&self) -> Option<&TetraCalibrationResult> {
        self.result.as_ref()
    }

    fn enter(&mut self, p: TetraPhase) {
        self.core.enter(p);
        self.commanded = None;
        self.block = None;
    }

    fn where_(&self) -> String {
        format!("{:?}", self.core.phase).to_lowercase()
    }

    fn profiling(&self) -> bool {
        matches!(
            self.core.phase,
            TetraPhase::Calibrating | TetraPhase::Monitoring
        )
    }

    /// A status frame arrived; `t` is the end time of the last IMU sample nav had then.
    pub fn on_status(&mut self, t: f64, st: &TtStatus) {
        if st.axis > 2 || self.core.finished() {
            return;
        }
        if let Some(names) = crate::procedures::common::faults_of(st) {
            let w = self.where_();
            self.core.fail(format!(
                "table fault on axis {} while {w}: {names}",
                st.axis
            ));
            return;
        }
        self.core.link.on_status(t, st);
        self.axes[usize::from(st.axis)].push(t, st.angle_deg);
        self.drain();
    }

    /// A MEMS_GYRO frame arrived after the IMU sample `sample` (its extended counter), which
    /// ends at `t1` and lasts `dt` (s).
    pub fn on_mems(&mut self, sample: u64, t1: f64, dt: f64, m: &MemsGyro) {
        self.core.t = self.core.t.max(t1);
        if u64::from(m.sample_counter_low) != sample & 0xFF {
            self.unmatched += 1;
            self.last_counts = None;
            return;
        }
        let prev = self.last_counts.replace(m.counts);
        let Some(prev) = prev else { return };
        if !self.profiling() {
            return;
        }
        let out: [f64; TETRA_GYROS] = std::array::from_fn(|i| {
            let d = (i32::from(m.counts[i]) - i32::from(prev[i])).rem_euclid(1 << 14);
            let d = if d >= 1 << 13 { d - (1 << 14) } else { d };
            f64::from(d) * self.cfg.pulse_deg / dt
        });
        self.pending.push_back(Pending {
            t0: t1 - dt,
            t1,
            out,
        });
        self.drain();
    }

    fn drain(&mut self) {
        let gap = 0.05;
        let h = self.cfg.reference_half_window_s;
        while let Some(p) = self.pending.front().copied() {
            if !self
                .axes
                .iter()
                .all(|a| a.latest().is_some_and(|l| l.0 >= p.t1 + h - 1e-9))
            {
                return;
            }
            self.pending.pop_front();
            let mut gimbal = Vec::with_capacity(3);
            let mut ok = true;
            for (i, c) in self.cfg.gimbal.chars().enumerate() {
                let a = &self.axes[i];
                // the rate over the sample widened by h on both sides: exact for a constant
                // acceleration, the encoder's noise divided by the span
                let (Some(w0), Some(w1), Some(a0), Some(a1)) = (
                    a.at(p.t0 - h, gap),
                    a.at(p.t1 + h, gap),
                    a.at(p.t0, gap),
                    a.at(p.t1, gap),
                ) else {
                    ok = false;
                    break;
                };
                let axis = match c {
                    'x' => Vector3::x_axis(),
                    'y' => Vector3::y_axis(),
                    _ => Vector3::z_axis(),
                };
                // where the rate changes (the corners of an acceleration) the widened
                // difference smears: there the sample's own difference
                let steady = h > 0.0 && ((a0 - w0) / h - (w1 - a1) / h).abs() < 0.05;
                let rate = if steady {
                    (w1 - w0).to_radians() / (p.t1 - p.t0 + 2.0 * h)
                } else {
                    (a1 - a0).to_radians() / (p.t1 - p.t0)
                };
                gimbal.push((axis, (0.5 * (a0 + a1)).to_radians(), rate));
            }
            if !ok {
                self.skipped += 1;
                continue;
            }
            let known = table_rate(self.lat, &self.q_nb, &gimbal).map(f64::to_degrees);
            self.samples += 1;
            match self.core.phase {
                TetraPhase::Calibrating => self.kf.update(&p.out, &known),
                TetraPhase::Monitoring => self.watch(p.t1, p.t1 - p.t0, &p.out, &known),
                _ => {}
            }
        }
    }

    /// One sample for the parity monitor: the outputs corrected by the estimates.
    fn watch(&mut self, t: f64, dt: f64, out: &[f64; TETRA_GYROS], known: &Vector3<f64>) {
        let est = self.loaded.unwrap_or_else(|| self.kf.coefficients());
        // the rate from the calibrated model first (least squares over the four), for the
        // mounting angles' small cross terms
        let axes = std::array::from_fn(|i| est[i].sensing_axis(i));
        let biased: [f64; TETRA_GYROS] = std::array::from_fn(|i| out[i] + est[i].bias_dps);
        let w =
            crate::procedures::redundant_rates::rate_through(&axes, &biased, [true; TETRA_GYROS])
                .unwrap_or(*known);
        let corrected: [f64; TETRA_GYROS] = std::array::from_fn(|i| est[i].correct(i, out[i], &w));
        let t_rel = t - self.core.phase_since;
        let (window, k) = (self.cfg.monitor_window, self.cfg.monitor_k);
        // the output's quantization adds to the noise: the difference of two uniform errors of
        // one pulse over the sample
        let q = self.cfg.pulse_deg / dt;
        let sigma = (self.cfg.gyro_noise_dps.powi(2) + q * q / 6.0).sqrt();
        let mon = self
            .monitor
            .get_or_insert_with(|| ParityMonitor::new(sigma, k, window));
        let rate = mon.update(&corrected, Some(known));
        let st = mon.status();
        let o = self.outcome.get_or_insert(MonitorOutcome {
            status: Status::Healthy,
            detected_at_s: None,
            isolated_at_s: None,
            worst_rate_error_dps: 0.0,
        });
        if st != Status::Healthy && o.detected_at_s.is_none() {
            o.detected_at_s = Some(t_rel);
        }
        if matches!(st, Status::Isolated { .. }) && o.isolated_at_s.is_none() {
            o.isolated_at_s = Some(t_rel);
            // from the isolation on: the error of the rate from the other three
            o.worst_rate_error_dps = 0.0;
        }
        o.status = st;
        if let Some(r) = rate {
            o.worst_rate_error_dps = o.worst_rate_error_dps.max((r - known).norm());
        }
    }

    /// The next command to send at IMU time `t` (s), if any. Call after feeding the inputs.
    pub fn poll(&mut self, t: f64) -> Option<TtCmd> {
        self.core.t = self.core.t.max(t);
        self.core.t_start.get_or_insert(t);
        crate::procedures::common::poll(self, t)
    }

    fn all(&self, f: impl Fn(TtState) -> bool) -> bool {
        (0..3).all(|a| self.core.link.state(a).is_some_and(&f))
    }

    fn step(&mut self) {
        let since = self.core.t - self.core.phase_since;
        let timeout = self.cfg.move_timeout_s;
        match self.core.phase {
            TetraPhase::Enabling => {
                if self.all(|s| s != TtState::Disabled) {
                    self.enter(TetraPhase::Unlocking);
                    for a in 0..3 {
                        if self.core.link.state(a) == Some(TtState::Locked) {
                            self.core.link.push(TtCommand::Unlock, a, 0.0);
                        }
                    }
                } else if since > timeout {
                    self.core
                        .fail("the table's three axes did not come up after Enable".into());
                }
            }
            TetraPhase::Unlocking => {
                if self.all(|s| s == TtState::Idle) {
                    self.enter(if self.loaded.is_some() {
                        TetraPhase::Monitoring
                    } else {
                        TetraPhase::Calibrating
                    });
                } else if since > timeout {
                    self.core.fail("the lock pins did not withdraw".into());
                }
            }
            TetraPhase::Calibrating | TetraPhase::Monitoring => self.profile(since),
            TetraPhase::Stopping => {
                if self.all(|s| s == TtState::Idle) {
                    self.enter(TetraPhase::Returning);
                    for a in 0..3 {
                        self.core.link.push(TtCommand::Home, a, 0.0);
                    }
                } else if since > timeout {
                    self.core
                        .fail(format!("the axes did not stop within {timeout} s"));
                }
            }
            TetraPhase::Returning => {
                if since > 1.0 && self.all(|s| s == TtState::Idle) {
                    self.enter(TetraPhase::Locking);
                    for a in 0..3 {
                        self.core.link.push(TtCommand::Lock, a, 0.0);
                    }
                } else if since > timeout {
                    self.core.fail(format!(
                        "the axes did not return to zero within {timeout} s"
                    ));
                }
            }
            TetraPhase::Locking => {
                if self.all(|s| s == TtState::Locked) {
                    self.core.phase = TetraPhase::Done;
                    let d = self.core.elapsed();
                    if let Some(r) = self.result.as_mut() {
                        r.duration_s = d;
                    }
                } else if since > timeout {
                    self.core
                        .fail(format!("the lock pins did not engage within {timeout} s"));
                }
            }
            TetraPhase::Done | TetraPhase::Aborted => {}
        }
    }

    /// The profile at profile time `since`: each turn commanded once, stopped at its end; the
    /// table's rates checked second by second.
    fn profile(&mut self, since: f64) {
        let c = self.cfg.clone();
        if since >= c.profile_s() {
            if self.core.phase == TetraPhase::Calibrating && c.monitor {
                self.enter(TetraPhase::Monitoring);
                return;
            }
            self.finish_result();
            self.enter(TetraPhase::Stopping);
            for a in 0..3 {
                self.core.link.push(TtCommand::Stop, a, 0.0);
            }
            return;
        }
        let turn = c.turn_at(since);
        if let Some((body, axis, ..)) = turn
            && self.commanded != Some(body)
        {
            if let Some(prev) = self.commanded {
                self.core
                    .link
                    .push(TtCommand::Stop, c.table_axis(prev), 0.0);
            }
            self.commanded = Some(body);
            self.core.link.push(TtCommand::Rate, axis, c.rate_dps);
            return;
        }
        if turn.is_none()
            && let Some(prev) = self.commanded.take()
        {
            self.core
                .link
                .push(TtCommand::Stop, c.table_axis(prev), 0.0);
            return;
        }
        self.check_rates(since, turn);
    }

    /// The rate check, one second at a time away from the profile's changes.
    fn check_rates(&mut self, since: f64, turn: Option<(usize, u8, f64, f64)>) {
        let c = &self.cfg;
        // the changes: the turns' starts and ends
        let near_change = (0..=3).any(|b| {
            let edge = c.rest_s + b as f64 * c.turn_s;
            (since - edge).abs() < 1.0
        });
        // each axis's latest angle, and the time it was stamped with
        let latest: Option<Vec<(f64, f64)>> = self.axes.iter().map(AxisTrack::latest).collect();
        let Some(latest) = latest else { return };
        let now = [latest[0], latest[1], latest[2]];
        match self.block {
            Some((from, a0)) if since - from >= 1.0 => {
                self.block = None;
                if near_change {
                    return;
                }
                for axis in 0..3u8 {
                    let want = match turn {
                        Some((_, ax, ..)) if ax == axis => c.rate_dps,
                        _ => 0.0,
                    };
                    // each axis on its own stamps (their frames come one after another)
                    let (n, b) = (now[usize::from(axis)], a0[usize::from(axis)]);
                    let got = (n.1 - b.1) / (n.0 - b.0).max(1e-9);
                    if (got - want).abs() > c.rate_tolerance_dps {
                        let w = self.where_();
                        self.core.fail(format!(
                            "the table's axis {axis} turned at {got:.4} deg/s at {since:.1} s of the profile while {w}, commanded {want}: calibration data refused"
                        ));
                        return;
                    }
                }
                self.checked_s += 1;
            }
            Some(_) => {}
            // a block starts at the time of the angles it starts from
            None if !near_change => self.block = Some((since, now)),
            None => {}
        }
    }

    fn finish_result(&mut self) {
        if self.result.is_some() {
            return;
        }
        self.result = Some(TetraCalibrationResult {
            coefficients: self.loaded.unwrap_or_else(|| self.kf.coefficients()),
            sigmas: self.kf.sigmas(),
            from_file: self.loaded.is_some(),
            samples: self.samples,
            checked_s: self.checked_s,
            unmatched_frames: self.unmatched,
            samples_without_status: self.skipped,
            monitor: self.outcome,
            duration_s: 0.0,
        });
    }

    /// The phase (a progress line at each change).
    pub fn stage(&self) -> TetraPhase {
        self.core.phase
    }

    /// Progress, for the operator.
    pub fn progress(&self) -> TetraProgress {
        let since = self.core.t - self.core.phase_since;
        let profiling = self.profiling();
        TetraProgress {
            phase: self.core.phase,
            elapsed_s: self.core.elapsed(),
            phase_left_s: if profiling {
                (self.cfg.profile_s() - since).max(0.0)
            } else {
                0.0
            },
            turning: profiling
                .then(|| self.cfg.turn_at(since))
                .flatten()
                .map(|(b, ..)| ['x', 'y', 'z'][b]),
            bias_dps: self.kf.coefficients().map(|c| c.bias_dps),
        }
    }
}

impl OnMechanism for TetraCalibrator {
    type Phase = TetraPhase;
    fn core(&mut self) -> &mut Core<TetraPhase> {
        &mut self.core
    }
    fn at(&self) -> String {
        self.where_()
    }
    fn advance(&mut self) {
        self.step()
    }
}

impl Phases for TetraPhase {
    const DONE: Self = TetraPhase::Done;
    const ABORTED: Self = TetraPhase::Aborted;
}

crate::procedures::common::procedure!(TetraCalibrator, "tetra-calibration", |s, t, st| s
    .on_status(t, st));

/// The redundant unit's calibration at exit.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TetraCalibrationSummary {
    /// The parameter file's content, when it finished calibrating.
    pub parameters: Option<crate::procedures::unit_parameters::RedundantParameters>,
    /// Where the parameter file was written, when it was.
    #[serde(default)]
    pub parameters_file: Option<PathBuf>,
    /// Last phase.
    pub phase: crate::procedures::tetra_calibration::TetraPhase,
    /// The result, when it finished.
    pub result: Option<crate::procedures::tetra_calibration::TetraCalibrationResult>,
    /// Why it gave up, when it did.
    pub abort: Option<String>,
    /// Table commands sent.
    pub commands_sent: u64,
    /// Frames taken (table status and acks, the unit's MEMS_GYRO).
    pub frames: u64,
    /// Commands sent again for want of an acknowledgement.
    pub command_retries: u64,
    /// Acknowledgements that came too late (or matched no command).
    pub stale_acks: u64,
}

/// The redundant unit's calibration as the pipeline runs it (its [`Mission`]).
#[derive(Debug)]
pub(crate) struct TetraCalibration {
    pub(crate) cal: TetraCalibrator,
    parameters: Option<crate::procedures::unit_parameters::RedundantParameters>,
}

impl TetraCalibration {
    /// The procedure of config section `c` (none when it is not enabled).
    pub(crate) fn make(
        c: &TetraCalibrationConfig,
    ) -> Result<Option<Box<dyn Mission>>, SettingError> {
        if !c.enabled {
            return Ok(None);
        }
        Ok(Some(Box::new(Self {
            cal: TetraCalibrator::new(c.clone())?,
            parameters: None,
        })))
    }

    /// Its section of nav's summary (`rep`: what the pipeline counted for it).
    pub(crate) fn section(&self, rep: &Reporting) -> TetraCalibrationSummary {
        let c = &self.cal;
        TetraCalibrationSummary {
            parameters: self.parameters.clone(),
            parameters_file: None,
            phase: c.phase(),
            result: c.result().cloned(),
            abort: c.abort().map(str::to_string),
            commands_sent: rep.commands_sent,
            frames: rep.frames,
            command_retries: c.ack_counters().0,
            stale_acks: c.ack_counters().1,
        }
    }
}

impl Mission for TetraCalibration {
    fn procedure(&mut self) -> &mut dyn Procedure {
        &mut self.cal
    }
    fn procedure_ref(&self) -> &dyn Procedure {
        &self.cal
    }
    fn on_mems(&mut self, k: u64, t: f64, dt: f64, g: &MemsGyro) -> bool {
        self.cal.on_mems(k, t, dt, g);
        true
    }
    fn mode(&self) -> NavMode {
        match self.cal.phase() {
            TetraPhase::Enabling => NavMode::Init,
            _ => NavMode::Calibrating,
        }
    }
    fn made(&mut self) -> Option<(Option<PathBuf>, ParameterFile)> {
        let p = self.cal.parameters()?;
        self.parameters = Some(p.clone());
        Some((
            self.cal.config().parameters_out.clone(),
            ParameterFile::Redundant(p),
        ))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
