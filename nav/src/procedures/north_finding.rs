//! Four-position north-finding on the azimuth indexing mechanism (paper 003).
//!
//! Sequence: enable the mechanism; for each position (0, 90, 180, 270 deg by default) unlock,
//! index, lock at the detent, wait for the base to settle, dwell; then return to zero and lock,
//! and hand over. During each dwell the gyro angle and the velocity increments (dither-filtered,
//! coning/sculling compensated, from [`crate::frontend::processing`]) are accumulated.
//!
//! Per position: the IMU is levelled from its own mean specific force (the base may tilt
//! differently under each position), the body rate is rotated into that level frame, and the
//! rate is the difference of the mean accumulated angle over short windows at both ends of the
//! dwell (the windows average out what the dither filter leaves of the dither angle, which a
//! plain end-point difference would turn into a rate error of 0.06 deg/h over a minute).
//!
//! With `phi_k` the measured table angle (counter-clockwise), the IMU heading is
//! `psi_0 - phi_k`, and the level horizontal gyros read
//! `g_x = -s cos phi_k + c sin phi_k + b_x`, `g_y = s sin phi_k + c cos phi_k + b_y`
//! with `s = W_N sin psi_0`, `c = W_N cos psi_0`, `W_N = W_ie cos L`: a weighted linear
//! least-squares problem in `(s, c, b_x, b_y)`. Constant biases cancel between opposite
//! positions; the heading is `atan2(s, c)` and its sigma follows from the noise measured within
//! each dwell (the scatter of block rates), so it is the data's own figure, not a datasheet's.
//!
//! Disturbances (a door slam, someone climbing in, wind) show as blocks whose rate or specific
//! force departs from the dwell's first block; the dwell is then repeated once the base is quiet.
//! Every turntable fault, rejected command, missing acknowledgement or timeout aborts with a
//! reason naming the position and the command.

use crate::navigation::earth;
use crate::procedures::common::{Core, OnMechanism, Phases, Procedure, Reporting};
use crate::procedures::mission::Mission;
use crate::procedures::turntable_link::{LinkTiming, SettingError, TtLink};
use nalgebra::{Matrix4, Rotation3, Vector3, Vector4};
use serde::{Deserialize, Serialize};
use std::any::Any;
use wire::{NavMode, TtCmd, TtCommand, TtState, TtStatus};

/// North-finding settings (the `[north_finding]` table of nav's config).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct NorthFindingConfig {
    /// Run north-finding at start-up.
    pub enabled: bool,
    /// Latitude of the site, deg (from the last fix or the operator).
    pub latitude_deg: f64,
    /// Table positions, deg.
    pub positions_deg: Vec<f64>,
    /// Dwell per position, s of IMU time.
    pub dwell_s: f64,
    /// Wait after the lock engages before the dwell starts, s.
    pub settle_s: f64,
    /// Averaging window at each end of a dwell, s.
    pub end_window_s: f64,
    /// Blocks per dwell (noise estimate and disturbance detection).
    pub blocks: usize,
    /// A block whose horizontal rate departs from the first block's by more than this is
    /// disturbed, deg/h.
    pub disturbance_rate_dph: f64,
    /// ... or whose specific force departs by more than this, m/s^2.
    pub disturbance_accel_mps2: f64,
    /// The base must be quiet this long before a repeated dwell, s.
    pub quiet_s: f64,
    /// Repeats allowed per position before giving up.
    pub max_repeats: u32,
    /// Turntable axis used.
    pub axis: u8,
    /// Heartbeat interval to the turntable, s.
    pub heartbeat_s: f64,
    /// Time allowed for an acknowledgement, s (IMU time).
    pub ack_timeout_s: f64,
    /// Retries of an unacknowledged command.
    pub ack_retries: u32,
    /// Time allowed for a move to finish, s.
    pub move_timeout_s: f64,
    /// Longest silence of the mechanism's status frames (its heartbeat, 100 Hz) before the
    /// drill gives up, s of IMU time.
    pub status_timeout_s: f64,
    /// Time allowed for the lock pin, s.
    pub lock_timeout_s: f64,
    /// What the drill is expected to give, and must ([`crate::procedures::drill_plan`]).
    pub plan: crate::procedures::drill_plan::PlanConfig,
    /// When the mechanism is lost mid-drill (its status frames stop, or it stalls), find north
    /// by a static gyrocompass where the table stands: a dwell there, solved with the positions
    /// measured before, the unknown gyro biases bounded by `plan.gyro.bias_dph`. The table's
    /// angle is followed from its last status frame by the IMU's own vertical gyro. false:
    /// abort, as on any other fault.
    pub fallback: bool,
}

impl Default for NorthFindingConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            latitude_deg: 28.218157,
            positions_deg: vec![0.0, 90.0, 180.0, 270.0],
            dwell_s: 60.0,
            settle_s: 1.0,
            end_window_s: 0.1,
            blocks: 10,
            disturbance_rate_dph: 20.0,
            disturbance_accel_mps2: 0.02,
            quiet_s: 3.0,
            max_repeats: 3,
            axis: 0,
            heartbeat_s: 0.25,
            ack_timeout_s: 0.5,
            ack_retries: 2,
            move_timeout_s: 30.0,
            status_timeout_s: 0.5,
            lock_timeout_s: 3.0,
            plan: crate::procedures::drill_plan::PlanConfig::default(),
            fallback: true,
        }
    }
}

/// A setting of `[north_finding]` out of its range.
pub type NorthFindingConfigError = crate::procedures::turntable_link::SettingError;

impl NorthFindingConfig {
    /// The turntable link's timing.
    pub fn timing(&self) -> LinkTiming {
        LinkTiming {
            heartbeat_s: self.heartbeat_s,
            ack_timeout_s: self.ack_timeout_s,
            ack_retries: self.ack_retries,
            status_timeout_s: self.status_timeout_s,
        }
    }

    /// Check the settings; the error names the setting.
    pub fn check(&self) -> Result<(), NorthFindingConfigError> {
        let bad = |setting, requirement| {
            Err(crate::procedures::turntable_link::SettingError::new(
                "north_finding",
                setting,
                requirement,
            ))
        };
        crate::procedures::turntable_link::check_site_and_link(
            "north_finding",
            self.latitude_deg,
            &self.timing(),
            self.move_timeout_s,
        )?;
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if self.positions_deg.len() < 2
            || self.positions_deg.iter().any(|p| !(0.0..360.0).contains(p))
        {
            return bad("positions_deg", "needs two or more angles in [0, 360)");
        }
        if !(pos(self.dwell_s) && pos(self.end_window_s) && self.end_window_s * 4.0 < self.dwell_s)
        {
            return bad(
                "dwell_s",
                "must be positive and exceed 4 end windows (end_window_s)",
            );
        }
        if self.blocks < 2 {
            return bad("blocks", "must be 2 or more");
        }
        self.plan.check()
    }

    /// The drill these settings make, for [`crate::procedures::drill_plan`].
    pub fn drill_plan(&self) -> crate::procedures::drill_plan::DrillPlan {
        crate::procedures::drill_plan::DrillPlan {
            latitude_deg: self.latitude_deg,
            positions_deg: self.positions_deg.clone(),
            dwell_s: self.dwell_s,
            index_time_s: self.plan.index_time_s,
            noise: self.plan.gyro,
        }
    }

    /// The drill's predicted sigma and, when it cannot meet `[north_finding.plan]`'s
    /// tolerance, what nav says before it starts.
    pub fn check_plan(&self) -> (crate::procedures::drill_plan::Prediction, Option<String>) {
        crate::procedures::drill_plan::check_drill(&self.drill_plan(), &self.plan)
    }
}

/// Where the sequence is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Enabling the mechanism.
    Enabling,
    /// Withdrawing the lock pin.
    Unlocking,
    /// Indexing to the position.
    Indexing,
    /// Engaging the lock pin.
    Locking,
    /// Waiting for the base to settle.
    Settling,
    /// Measuring.
    Dwell,
    /// A disturbance: waiting for quiet before repeating the dwell.
    Disturbed,
    /// Returning to zero.
    Returning,
    /// Locking at zero.
    LockingZero,
    /// The mechanism lost: waiting for the table to come to rest, for a static gyrocompass
    /// where it stands.
    TableLost,
    /// Finished: result available.
    Done,
    /// Given up: reason available.
    Aborted,
}

/// Live progress.
#[derive(Debug, Clone, Serialize)]
pub struct Progress {
    /// Phase.
    pub phase: Phase,
    /// Position index (1-based) and count.
    pub position: usize,
    /// Positions in all.
    pub positions: usize,
    /// Dwell time left at this position, s.
    pub dwell_left_s: f64,
    /// Heading estimate so far (from the positions done), deg.
    pub heading_deg: Option<f64>,
    /// Its sigma, deg.
    pub sigma_deg: Option<f64>,
    /// Elapsed IMU time, s.
    pub elapsed_s: f64,
    /// Dwells repeated after disturbances.
    pub repeats: u32,
}

/// One position's measurement.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct PositionResult {
    /// Commanded angle, deg.
    pub commanded_deg: f64,
    /// Measured table angle (encoder mean over the dwell), deg.
    pub table_deg: f64,
    /// Level-frame rate x, y, z, deg/h.
    pub rate_dph: [f64; 3],
    /// Sigma of each horizontal rate from the block scatter, deg/h.
    pub sigma_dph: f64,
    /// Pitch and roll of the IMU at this position, deg.
    pub tilt_deg: [f64; 2],
    /// Dwell repeats here.
    pub repeats: u32,
}

/// The least-squares solution of the positions measured so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingSolution {
    /// Heading of the IMU at table zero (clockwise from true north), deg, [0, 360).
    pub heading_deg: f64,
    /// Its sigma from the dwells' scatter, deg.
    pub sigma_deg: f64,
    /// Horizontal gyro biases x, y (level frame at table zero), deg/h.
    pub gyro_bias_dph: [f64; 2],
    /// Horizontal earth rate found, deg/h.
    pub horizontal_earth_rate_dph: f64,
}

/// The answer.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct NorthResult {
    /// Heading of the IMU at table zero (clockwise from true north), deg, [0, 360).
    pub heading_deg: f64,
    /// Its sigma, deg: the two below, root sum square.
    pub sigma_deg: f64,
    /// The part the dwells' own scatter measures (the gyros' white noise), deg.
    #[serde(default)]
    pub noise_sigma_deg: f64,
    /// The part of the gyro drift between dwells, which no dwell's scatter shows, predicted
    /// from the unit's figures ([`crate::procedures::drill_plan`]), deg.
    #[serde(default)]
    pub drift_sigma_deg: f64,
    /// Horizontal gyro biases x, y (level frame at table zero), deg/h.
    pub gyro_bias_dph: [f64; 2],
    /// Horizontal earth rate found, deg/h (expected `15.041 cos L`).
    pub horizontal_earth_rate_dph: f64,
    /// Expected horizontal earth rate, deg/h.
    pub expected_earth_rate_dph: f64,
    /// Pitch and roll at table zero, deg.
    pub tilt_deg: [f64; 2],
    /// Total dwell time used, s.
    pub dwell_total_s: f64,
    /// Time from start to locked at zero, s (IMU time).
    pub duration_s: f64,
    /// Dwells repeated after disturbances.
    pub repeats: u32,
    /// Per position.
    pub positions: Vec<PositionResult>,
    /// Set when the mechanism was lost and the heading comes from a static gyrocompass where
    /// the table stood: why.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degraded: Option<String>,
    /// The table's angle at the end, deg (0: returned to zero; else where it stood when lost).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub final_table_deg: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// The mechanism lost mid-drill.
#[derive(Debug, Clone)]
struct Lost {
    /// Why.
    why: String,
    /// The table's angle, followed by the IMU's vertical gyro, deg.
    angle_deg: f64,
    /// Its uncertainty: the table's rate at its last status frame times the frame's age
    /// uncertainty, deg.
    angle_sigma_deg: f64,
    /// When it was lost, s (IMU time).
    at: f64,
    /// The table's rotation over the current rest window: (start time, angle at its start).
    window: (f64, f64),
    /// Since when the table has been at rest, s.
    rest_since: Option<f64>,
}

/// A table turning slower than this is at rest, deg/s (the dither filter's residue is a few
/// arcsec: over a rest window, a thousandth of a degree per second).
const REST_RATE_DPS: f64 = 0.02;
/// The window the table's rate is measured over for rest, s.
const REST_WINDOW_S: f64 = 0.5;
/// ... for this long before the gyrocompass dwell starts, s.
const REST_S: f64 = 1.0;
/// The uncertainty of a status frame's time against the IMU's updates (two samples at 2 kHz),
/// s: the table's angle is carried on from it by the vertical gyro.
const STATUS_AGE_S: f64 = 0.001;

/// Accumulation of one dwell.
#[derive(Debug, Clone, Default)]
struct Dwell {
    t0: f64,
    theta: Vector3<f64>,
    vel: Vector3<f64>,
    /// Block boundaries: window means at each boundary (time, theta, v).
    bounds: Vec<(f64, Vector3<f64>, Vector3<f64>)>,
    cur_win: (f64, Vector3<f64>, Vector3<f64>, u32),
    enc_sum: f64,
    enc_n: u32,
    disturbed: bool,
    /// Current 0.1 s micro-window: sums of time, theta, v and the count.
    micro: (f64, Vector3<f64>, Vector3<f64>, u32),
    micro_t0: f64,
    last_micro: Option<(f64, Vector3<f64>, Vector3<f64>)>,
}

/// The north-finding sequence.
#[derive(Debug)]
pub struct NorthFinder {
    core: Core<Phase>,
    cfg: NorthFindingConfig,
    k: usize,
    returning: bool,
    seen_moving: bool,
    dwell: Dwell,
    quiet_since: f64,
    repeats_here: u32,
    repeats: u32,
    results: Vec<PositionResult>,
    result: Option<NorthResult>,
    /// The IMU's rotation about its vertical since the last status frame, deg, and the IMU time
    /// that frame came at (updates valid before it are in its angle already).
    z_since_status: (f64, f64),
    /// The IMU time of the last update, s.
    last_update: Option<f64>,
    /// The earth's rate about the vertical at the site, rad/s.
    earth_up: f64,
    lost: Option<Lost>,
}

const DPH: f64 = earth::DEG_PER_HOUR_PER_RAD_S;
/// Micro-window length for disturbance detection, s.
const MICRO_S: f64 = 0.1;
/// Micro-window rates are noisier than block rates: their threshold is this many times the
/// block threshold.
const MICRO_RATE_FACTOR: f64 = 2.5;

impl NorthFinder {
    /// A sequence with these settings (checked).
    pub fn new(cfg: NorthFindingConfig) -> Result<Self, NorthFindingConfigError> {
        cfg.check()?;
        let earth_up = earth::OMEGA_IE * cfg.latitude_deg.to_radians().sin();
        let mut link = TtLink::new(cfg.timing(), &[cfg.axis]);
        link.push(TtCommand::Enable, cfg.axis, 0.0);
        Ok(Self {
            cfg,
            k: 0,
            core: Core::new(Phase::Enabling, link),
            returning: false,
            seen_moving: false,
            dwell: Dwell::default(),
            quiet_since: 0.0,
            repeats_here: 0,
            repeats: 0,
            results: Vec::new(),
            result: None,
            z_since_status: (0.0, 0.0),
            last_update: None,
            earth_up,
            lost: None,
        })
    }

    /// Why the mechanism was lost, when it was and north-finding goes on without it.
    pub fn lost(&self) -> Option<&str> {
        self.lost.as_ref().map(|l| l.why.as_str())
    }

    /// The mechanism is lost for `why`: a static gyrocompass where the table stands, or (not
    /// allowed, or never heard) give up.
    fn lose(&mut self, why: String) {
        if self.core.finished() || self.lost.is_some() {
            return;
        }
        let Some(st) = self.core.link.status(self.cfg.axis).copied() else {
            self.core.fail(why);
            return;
        };
        if !self.cfg.fallback {
            self.core.fail(why);
            return;
        }
        let (z, since) = self.z_since_status;
        let age = (self.last_update.unwrap_or(since) - since).max(1e-3);
        let angle = st.angle_deg + z;
        tracing::warn!(
            "{why}: north-finding goes on by a static gyrocompass where the table stands (last reported at {:.4} deg, {:.4} deg now by the IMU)",
            st.angle_deg,
            angle
        );
        self.lost = Some(Lost {
            why,
            angle_deg: angle,
            angle_sigma_deg: (z / age).abs() * STATUS_AGE_S,
            at: self.core.t,
            window: (self.core.t, angle),
            rest_since: None,
        });
        // nothing more to the mechanism: no command, no heartbeat
        self.core.link.clear();
        self.dwell = Dwell::default();
        self.enter(Phase::TableLost);
    }

    /// Phase.
    pub fn phase(&self) -> Phase {
        self.core.phase
    }

    /// The result, once done.
    pub fn result(&self) -> Option<&NorthResult> {
        self.result.as_ref()
    }

    fn enter(&mut self, p: Phase) {
        self.core.enter(p);
        self.seen_moving = false;
    }

    fn where_(&self) -> String {
        if let Some(l) = &self.lost {
            format!("a static gyrocompass at {:.3} deg", l.angle_deg)
        } else if self.returning {
            "returning to zero".into()
        } else {
            format!(
                "position {} of {} ({} deg)",
                self.k + 1,
                self.cfg.positions_deg.len(),
                self.cfg.positions_deg.get(self.k).copied().unwrap_or(0.0)
            )
        }
    }

    /// A turntable status frame arrived at IMU time `t` (the end of the last sample nav has).
    pub fn on_status_at(&mut self, t: f64, st: &TtStatus) {
        if st.axis == self.cfg.axis && self.lost.is_none() {
            self.z_since_status = (0.0, t);
        }
        self.on_status(st);
    }

    /// A turntable status frame arrived.
    pub fn on_status(&mut self, st: &TtStatus) {
        if st.axis != self.cfg.axis || self.core.finished() || self.lost.is_some() {
            return;
        }
        if let Some(names) = crate::procedures::common::faults_of(st) {
            let w = self.where_();
            let why = format!("turntable fault at {w}: {names}");
            // a stalled table stands where it stopped, its encoder still read: only the
            // indexing is lost
            if st.faults.stall && !st.faults.encoder {
                self.core.link.on_status(self.core.t, st);
                self.lose(why);
            } else {
                self.core.fail(why);
            }
            return;
        }
        if st.state == TtState::Moving {
            self.seen_moving = true;
        }
        if self.core.phase == Phase::Dwell {
            // average the offset from the commanded angle: the encoder wraps at 360 deg, and at
            // the zero detent its noise straddles the wrap
            let d = (st.angle_deg - self.target()).rem_euclid(360.0);
            self.dwell.enc_sum += if d > 180.0 { d - 360.0 } else { d };
            self.dwell.enc_n += 1;
        }
        self.core.link.on_status(self.core.t, st);
    }

    /// The next command to send at IMU time `t` (s), if any. Call after feeding the inputs.
    pub fn poll(&mut self, t: f64) -> Option<TtCmd> {
        self.core.t = t;
        self.core.t_start.get_or_insert(t);
        if self.lost.is_some() {
            return None;
        }
        crate::procedures::common::poll(self, t)
    }

    fn state(&self) -> Option<TtState> {
        self.core.link.state(self.cfg.axis)
    }

    /// Advance the sequence on the turntable's state (no command outstanding).
    fn step(&mut self) {
        let since = self.core.t - self.core.phase_since;
        match self.core.phase {
            Phase::Enabling => {
                if let Some(s) = self.state() {
                    if s == TtState::Disabled {
                        if since > self.cfg.move_timeout_s {
                            self.core
                                .fail("turntable stays disabled after Enable".into());
                        }
                        return;
                    }
                    self.k = 0;
                    self.begin_position();
                } else if since > self.cfg.move_timeout_s {
                    self.core
                        .fail("no turntable status frames: is the mechanism on the bus?".into());
                }
            }
            Phase::Unlocking => match self.state() {
                Some(TtState::Idle) => {
                    if self.returning {
                        self.enter(Phase::Returning);
                        self.core.link.push(TtCommand::Home, self.cfg.axis, 0.0);
                    } else {
                        let target = self.target();
                        self.enter(Phase::Indexing);
                        self.core
                            .link
                            .push(TtCommand::IndexAbs, self.cfg.axis, target);
                    }
                }
                _ if since > self.cfg.lock_timeout_s => self.core.fail(format!(
                    "lock pin did not withdraw at {w}",
                    w = self.where_()
                )),
                _ => {}
            },
            Phase::Indexing | Phase::Returning => {
                if self.state() == Some(TtState::Idle) && (self.seen_moving || since > 1.0) {
                    // check we are where we asked to be
                    let want = if self.core.phase == Phase::Returning {
                        0.0
                    } else {
                        self.target()
                    };
                    if let Some(st) = self.core.link.status(self.cfg.axis).copied() {
                        let d = (st.angle_deg - want).rem_euclid(360.0);
                        if d.min(360.0 - d) > 0.05 {
                            self.core.fail(format!(
                                "turntable at {:.4} deg, not at {want} deg, after the move ({w})",
                                st.angle_deg,
                                w = self.where_()
                            ));
                            return;
                        }
                    }
                    let next = if self.core.phase == Phase::Returning {
                        Phase::LockingZero
                    } else {
                        Phase::Locking
                    };
                    self.enter(next);
                    self.core.link.push(TtCommand::Lock, self.cfg.axis, 0.0);
                } else if since > self.cfg.move_timeout_s {
                    self.core.fail(format!(
                        "move did not finish within {} s at {w}",
                        self.cfg.move_timeout_s,
                        w = self.where_()
                    ));
                }
            }
            Phase::Locking | Phase::LockingZero => {
                if self.state() == Some(TtState::Locked) {
                    if self.core.phase == Phase::LockingZero {
                        self.finish();
                    } else {
                        self.enter(Phase::Settling);
                    }
                } else if since > self.cfg.lock_timeout_s {
                    self.core.fail(format!(
                        "lock pin did not engage within {} s at {w}",
                        self.cfg.lock_timeout_s,
                        w = self.where_()
                    ));
                }
            }
            Phase::Settling => {
                if since >= self.cfg.settle_s {
                    self.start_dwell();
                }
            }
            Phase::Dwell | Phase::Disturbed | Phase::TableLost => {}
            Phase::Done | Phase::Aborted => {}
        }
    }

    fn target(&self) -> f64 {
        self.cfg.positions_deg.get(self.k).copied().unwrap_or(0.0)
    }

    fn begin_position(&mut self) {
        self.repeats_here = 0;
        self.enter(Phase::Unlocking);
        if self.state() == Some(TtState::Locked) {
            self.core.link.push(TtCommand::Unlock, self.cfg.axis, 0.0);
        }
    }

    fn start_dwell(&mut self) {
        self.enter(Phase::Dwell);
        self.dwell = Dwell {
            t0: self.core.t,
            ..Dwell::default()
        };
    }

    /// An attitude/velocity update from the processing chain, valid at IMU time `t` (s):
    /// rotation vector `phi` and velocity increment `dv` over the update interval.
    pub fn on_update(&mut self, t: f64, phi: [f64; 3], dv: [f64; 3]) {
        self.core.t = t;
        // the table turns the IMU about its vertical (counter-clockwise positive, as the
        // table's angle), the earth too: the table's turn followed between status frames (the
        // updates valid after the last one's time), and after the mechanism is lost
        let dt = self.last_update.map_or(0.0, |p| (t - p).max(0.0));
        self.last_update = Some(t);
        let dz = (phi[2] - self.earth_up * dt).to_degrees();
        match self.lost.as_mut() {
            Some(l) => l.angle_deg += dz,
            None if t > self.z_since_status.1 => self.z_since_status.0 += dz,
            None => {}
        }
        if self.core.phase == Phase::TableLost {
            self.wait_for_rest(t);
            return;
        }
        match self.core.phase {
            Phase::Dwell => self.dwell_update(t, phi, dv),
            Phase::Disturbed => {
                // watch for quiet: a block of the quiet length with no departure
                self.dwell_update(t, phi, dv);
                if t - self.quiet_since >= self.cfg.quiet_s {
                    if self.dwell.disturbed {
                        // still moving: keep waiting
                        self.quiet_since = t;
                        self.dwell = Dwell {
                            t0: t,
                            ..Dwell::default()
                        };
                    } else {
                        self.start_dwell();
                    }
                }
            }
            _ => {}
        }
    }

    fn dwell_update(&mut self, t: f64, phi: [f64; 3], dv: [f64; 3]) {
        let d = &mut self.dwell;
        d.theta += Vector3::from(phi);
        d.vel += Vector3::from(dv);
        let w = self.cfg.end_window_s;
        let tau = t - d.t0;
        let dur = if self.core.phase == Phase::Dwell {
            self.cfg.dwell_s
        } else {
            self.cfg.quiet_s
        };
        let block = dur / self.cfg.blocks as f64;
        // window means at each block boundary: the window [b - w/2, b + w/2], clipped to the dwell
        let next_b = d.bounds.len() as f64 * block;
        let (lo, hi) = ((next_b - w / 2.0).max(0.0), (next_b + w / 2.0).min(dur));
        if tau >= lo && tau <= hi {
            d.cur_win.0 += t;
            d.cur_win.1 += d.theta;
            d.cur_win.2 += d.vel;
            d.cur_win.3 += 1;
        }
        if tau > hi && d.cur_win.3 > 0 {
            let n = f64::from(d.cur_win.3);
            d.bounds
                .push((d.cur_win.0 / n, d.cur_win.1 / n, d.cur_win.2 / n));
            d.cur_win = (0.0, Vector3::zeros(), Vector3::zeros(), 0);
            // disturbance check on the block just closed against the first block
            let nb = d.bounds.len();
            if nb >= 3 {
                let rate = |i: usize| {
                    let (t0, a0, v0) = d.bounds[i - 1];
                    let (t1, a1, v1) = d.bounds[i];
                    ((a1 - a0) / (t1 - t0), (v1 - v0) / (t1 - t0))
                };
                let (w1, f1) = rate(1);
                let (wn, fn_) = rate(nb - 1);
                let dw = (wn - w1).xy().norm() * DPH;
                let df = (fn_ - f1).norm();
                if dw > self.cfg.disturbance_rate_dph || df > self.cfg.disturbance_accel_mps2 {
                    d.disturbed = true;
                }
            }
        }
        // micro-windows: the mean angle over each 0.1 s (which averages the dither residue);
        // the rate between consecutive ones catches oscillations a block average would hide
        if d.micro.3 == 0 {
            d.micro_t0 = t;
        }
        d.micro.0 += t;
        d.micro.1 += d.theta;
        d.micro.2 += d.vel;
        d.micro.3 += 1;
        if t - d.micro_t0 >= MICRO_S {
            let n = f64::from(d.micro.3);
            let m = (d.micro.0 / n, d.micro.1 / n, d.micro.2 / n);
            d.micro = (0.0, Vector3::zeros(), Vector3::zeros(), 0);
            if let (Some(last), true) = (d.last_micro, d.bounds.len() >= 2) {
                let dt = m.0 - last.0;
                let (w, f) = ((m.1 - last.1) / dt, (m.2 - last.2) / dt);
                let (t0, a0, v0) = d.bounds[0];
                let (t1, a1, v1) = d.bounds[1];
                let (wr, fr) = ((a1 - a0) / (t1 - t0), (v1 - v0) / (t1 - t0));
                if (w - wr).xy().norm() * DPH > MICRO_RATE_FACTOR * self.cfg.disturbance_rate_dph
                    || (f - fr).norm() > self.cfg.disturbance_accel_mps2
                {
                    d.disturbed = true;
                }
            }
            d.last_micro = Some(m);
        }
        if self.core.phase == Phase::Dwell {
            if self.dwell.disturbed {
                self.repeats_here += 1;
                self.repeats += 1;
                if self.repeats_here > self.cfg.max_repeats {
                    let w = self.where_();
                    self.core.fail(format!(
                        "base disturbed during {} dwells in a row at {w}",
                        self.repeats_here
                    ));
                    return;
                }
                self.enter(Phase::Disturbed);
                self.quiet_since = t;
                self.dwell = Dwell {
                    t0: t,
                    ..Dwell::default()
                };
                return;
            }
            if self.dwell.bounds.len() > self.cfg.blocks {
                self.finish_position();
            }
        }
    }

    fn finish_position(&mut self) {
        let d = &self.dwell;
        let nb = d.bounds.len();
        let (t0, a0, v0) = d.bounds[0];
        let (t1, a1, v1) = d.bounds[nb - 1];
        let w_b = (a1 - a0) / (t1 - t0);
        let f_b = (v1 - v0) / (t1 - t0);
        // level this position from its own specific force
        let roll = (-f_b.x).atan2(f_b.z);
        let pitch = f_b.y.atan2((f_b.x * f_b.x + f_b.z * f_b.z).sqrt());
        let level = Rotation3::from_axis_angle(&Vector3::x_axis(), pitch)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), roll);
        let w_l = level * w_b;
        // noise: scatter of the block rates (horizontal), scaled to the whole dwell
        let rates: Vec<Vector3<f64>> = (1..nb)
            .map(|i| {
                level * ((d.bounds[i].1 - d.bounds[i - 1].1) / (d.bounds[i].0 - d.bounds[i - 1].0))
            })
            .collect();
        let m = rates.len() as f64;
        let mean = rates.iter().fold(Vector3::zeros(), |a, r| a + r) / m;
        let var: f64 = rates
            .iter()
            .map(|r| (r - mean).xy().norm_squared() / 2.0)
            .sum::<f64>()
            / (m - 1.0).max(1.0);
        let sigma = (var / m).sqrt();
        let (commanded, table) = match &self.lost {
            Some(l) => (l.angle_deg, l.angle_deg),
            None => (
                self.target(),
                self.target()
                    + if d.enc_n > 0 {
                        d.enc_sum / f64::from(d.enc_n)
                    } else {
                        0.0
                    },
            ),
        };
        self.results.push(PositionResult {
            commanded_deg: commanded,
            table_deg: table,
            rate_dph: [w_l.x * DPH, w_l.y * DPH, w_l.z * DPH],
            sigma_dph: sigma * DPH,
            tilt_deg: [pitch.to_degrees(), roll.to_degrees()],
            repeats: self.repeats_here,
        });
        if self.lost.is_some() {
            self.finish_fallback();
            return;
        }
        self.k += 1;
        if self.k < self.cfg.positions_deg.len() {
            if self.target() == self.results[self.results.len() - 1].commanded_deg {
                // the same position again (out and back): the next dwell at once, still locked
                self.repeats_here = 0;
                self.start_dwell();
            } else {
                self.begin_position();
            }
        } else {
            // back to zero and lock
            self.returning = true;
            self.begin_position();
        }
    }

    /// Solve for heading and biases from the positions measured so far (two or more; none
    /// when they do not determine the heading).
    pub fn solve(results: &[PositionResult]) -> Option<HeadingSolution> {
        if results.len() < 2 {
            return None;
        }
        Self::solve_with(results, None)
    }

    /// Solve as [`Self::solve`], the horizontal biases bounded by a prior of `bias_dph` (1
    /// sigma, deg/h) when given: then one position suffices (a static gyrocompass), its
    /// sigma set by the prior.
    pub fn solve_with(
        results: &[PositionResult],
        bias_dph: Option<f64>,
    ) -> Option<HeadingSolution> {
        if results.is_empty() {
            return None;
        }
        let mut ata = Matrix4::<f64>::zeros();
        let mut atb = Vector4::<f64>::zeros();
        if let Some(b) = bias_dph {
            let w = 1.0 / b.max(1e-6).powi(2);
            ata[(2, 2)] += w;
            ata[(3, 3)] += w;
        }
        for r in results {
            let phi = r.table_deg.to_radians();
            let wgt = 1.0 / r.sigma_dph.max(1e-6).powi(2);
            for (row, g) in [
                (Vector4::new(-phi.cos(), phi.sin(), 1.0, 0.0), r.rate_dph[0]),
                (Vector4::new(phi.sin(), phi.cos(), 0.0, 1.0), r.rate_dph[1]),
            ] {
                ata += row * row.transpose() * wgt;
                atb += row * g * wgt;
            }
        }
        let cov = ata.try_inverse()?;
        let x = cov * atb;
        let (s, c) = (x[0], x[1]);
        let heading = s.atan2(c).to_degrees().rem_euclid(360.0);
        let n2 = s * s + c * c;
        let var =
            (c * c * cov[(0, 0)] + s * s * cov[(1, 1)] - 2.0 * s * c * cov[(0, 1)]) / (n2 * n2);
        Some(HeadingSolution {
            heading_deg: heading,
            sigma_deg: var.max(0.0).sqrt().to_degrees(),
            gyro_bias_dph: [x[2], x[3]],
            horizontal_earth_rate_dph: n2.sqrt(),
        })
    }

    /// The mechanism lost: wait until the table is at rest (its rate by the IMU's vertical gyro
    /// over [`REST_WINDOW_S`] windows below [`REST_RATE_DPS`] for [`REST_S`]), then dwell there.
    fn wait_for_rest(&mut self, t: f64) {
        let timeout = self.cfg.move_timeout_s;
        let Some(l) = self.lost.as_mut() else {
            return;
        };
        let (t0, a0) = l.window;
        if t - t0 < REST_WINDOW_S {
            return;
        }
        let rate = (l.angle_deg - a0) / (t - t0);
        l.window = (t, l.angle_deg);
        if rate.abs() > REST_RATE_DPS {
            l.rest_since = None;
        } else if l.rest_since.is_none() {
            l.rest_since = Some(t0);
        }
        let (rested, at) = (l.rest_since.is_some_and(|r| t - r >= REST_S), l.at);
        if rested {
            self.repeats_here = 0;
            self.start_dwell();
        } else if t - at > timeout {
            let why = format!(
                "{}; the table did not come to rest within {timeout} s for a static gyrocompass",
                l.why
            );
            self.core.fail(why);
        }
    }

    /// The static gyrocompass's dwell done: the heading from it and the positions measured
    /// before the loss, the biases bounded by the unit's figure.
    fn finish_fallback(&mut self) {
        let Some(l) = self.lost.clone() else {
            return;
        };
        let Some(sol) = Self::solve_with(&self.results, Some(self.cfg.plan.gyro.bias_dph)) else {
            self.core
                .fail(format!("{}; the static gyrocompass found nothing", l.why));
            return;
        };
        let sigma = sol.sigma_deg.hypot(l.angle_sigma_deg);
        tracing::warn!(
            "north-finding degraded ({}): heading {:.4} deg, sigma {sigma:.4} deg from a static gyrocompass at {:.3} deg and {} position(s) before",
            l.why,
            sol.heading_deg,
            l.angle_deg,
            self.results.len() - 1
        );
        self.conclude(
            &sol,
            (sigma, 0.0),
            Some(format!("static gyrocompass: {}", l.why)),
            l.angle_deg,
        );
    }

    /// The result of solution `sol` with its sigma's parts (the scatter's or the fit's, the
    /// drift's), done.
    fn conclude(
        &mut self,
        sol: &HeadingSolution,
        (noise, drift): (f64, f64),
        degraded: Option<String>,
        final_table_deg: f64,
    ) {
        let expected = earth::OMEGA_IE * self.cfg.latitude_deg.to_radians().cos() * DPH;
        self.result = Some(NorthResult {
            heading_deg: sol.heading_deg,
            sigma_deg: noise.hypot(drift),
            noise_sigma_deg: noise,
            drift_sigma_deg: drift,
            gyro_bias_dph: sol.gyro_bias_dph,
            horizontal_earth_rate_dph: sol.horizontal_earth_rate_dph,
            expected_earth_rate_dph: expected,
            tilt_deg: self.results[0].tilt_deg,
            dwell_total_s: self.cfg.dwell_s * self.results.len() as f64,
            duration_s: self.core.elapsed(),
            repeats: self.repeats,
            positions: self.results.clone(),
            degraded,
            final_table_deg,
        });
        self.enter(Phase::Done);
    }

    fn finish(&mut self) {
        let Some(sol) = Self::solve(&self.results) else {
            self.core.fail("too few positions measured to solve".into());
            return;
        };
        // the dwells' scatter measures the white noise; what the bias does between dwells it
        // cannot see: that part comes from the unit's figures ([north_finding.plan.gyro])
        let drift = crate::procedures::drill_plan::predict(&self.cfg.drill_plan()).drift_deg;
        self.conclude(&sol, (sol.sigma_deg, drift), None, 0.0);
    }

    /// Phase and position (1-based): cheap, for deciding when to report progress.
    pub fn stage(&self) -> (Phase, usize) {
        (
            self.core.phase,
            (self.k + 1).min(self.cfg.positions_deg.len()),
        )
    }

    /// Live progress (solves for the estimate so far: call it when reporting, not per sample).
    pub fn progress(&self) -> Progress {
        let est = Self::solve(&self.results);
        let dwell_left = match self.core.phase {
            Phase::Dwell => (self.cfg.dwell_s - (self.core.t - self.dwell.t0)).max(0.0),
            Phase::Done | Phase::Aborted | Phase::Returning | Phase::LockingZero => 0.0,
            _ => self.cfg.dwell_s,
        };
        Progress {
            phase: self.core.phase,
            position: self.stage().1,
            positions: self.cfg.positions_deg.len(),
            dwell_left_s: dwell_left,
            heading_deg: self
                .result
                .as_ref()
                .map(|r| r.heading_deg)
                .or(est.map(|e| e.heading_deg)),
            sigma_deg: self
                .result
                .as_ref()
                .map(|r| r.sigma_deg)
                .or(est.map(|e| e.sigma_deg)),
            elapsed_s: self.core.elapsed(),
            repeats: self.repeats,
        }
    }
}

impl OnMechanism for NorthFinder {
    type Phase = Phase;
    fn core(&mut self) -> &mut Core<Phase> {
        &mut self.core
    }
    fn link_failed(&mut self, f: crate::procedures::turntable_link::LinkFailure) {
        let why = f.describe(&self.where_());
        match f {
            // the mechanism's status frames stopped (its controller, its bus): only the
            // indexing is lost
            crate::procedures::turntable_link::LinkFailure::StatusLost { .. } => self.lose(why),
            _ => self.core.fail(why),
        }
    }
    fn at(&self) -> String {
        self.where_()
    }
    fn advance(&mut self) {
        self.step()
    }
}

impl Phases for Phase {
    const DONE: Self = Phase::Done;
    const ABORTED: Self = Phase::Aborted;
}

// north-finding stamps status frames with its own update time
crate::procedures::common::procedure!(NorthFinder, "north-finding", |s, t, st| s
    .on_status_at(t, st));

/// North-finding at exit.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NorthFindingSummary {
    /// Last phase.
    pub phase: Phase,
    /// The result, when it finished.
    pub result: Option<NorthResult>,
    /// Why it gave up, when it did.
    pub abort: Option<String>,
    /// Turntable commands sent.
    pub commands_sent: u64,
    /// Turntable frames received (status, acks).
    pub turntable_frames: u64,
    /// Commands sent again for want of an acknowledgement.
    #[serde(default)]
    pub command_retries: u64,
    /// Acknowledgements that came too late (or matched no command).
    #[serde(default)]
    pub stale_acks: u64,
}

/// North-finding as the pipeline runs it (its [`Mission`]).
#[derive(Debug)]
pub(crate) struct NorthFinding {
    pub(crate) finder: NorthFinder,
}

impl NorthFinding {
    /// The procedure of config section `c` (none when it is not enabled).
    pub(crate) fn make(c: &NorthFindingConfig) -> Result<Option<Box<dyn Mission>>, SettingError> {
        if !c.enabled {
            return Ok(None);
        }
        Ok(Some(Box::new(Self {
            finder: NorthFinder::new(c.clone())?,
        })))
    }

    /// Its section of nav's summary (`rep`: what the pipeline counted for it).
    pub(crate) fn section(&self, rep: &Reporting) -> NorthFindingSummary {
        let f = &self.finder;
        NorthFindingSummary {
            phase: f.phase(),
            result: f.result().cloned(),
            abort: f.abort().map(str::to_string),
            commands_sent: rep.commands_sent,
            turntable_frames: rep.frames,
            command_retries: f.ack_counters().0,
            stale_acks: f.ack_counters().1,
        }
    }
}

impl Mission for NorthFinding {
    fn procedure(&mut self) -> &mut dyn Procedure {
        &mut self.finder
    }
    fn procedure_ref(&self) -> &dyn Procedure {
        &self.finder
    }
    fn on_valid_sample(&self) -> bool {
        true
    }
    fn on_update(&mut self, t: f64, phi: [f64; 3], dv: [f64; 3]) {
        self.finder.on_update(t, phi, dv);
    }
    fn mode(&self) -> NavMode {
        if self.finder.lost().is_some() {
            NavMode::Gyrocompass
        } else {
            NavMode::NorthFinding
        }
    }
    fn heading_deg(&self) -> Option<f64> {
        // the IMU's own heading: where the table stands turns it from the heading at zero
        self.finder
            .result()
            .map(|r| (r.heading_deg - r.final_table_deg).rem_euclid(360.0))
    }
    fn heading_sigma_deg(&self) -> Option<f64> {
        self.finder.result().map(|r| r.sigma_deg)
    }
    fn mechanism_lost(&self) -> bool {
        self.finder.lost().is_some()
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedures::common::Procedure;
    use wire::{TtAck, TtFaults, TtResult};

    const G: f64 = 9.80665;

    fn cfg(lat: f64) -> NorthFindingConfig {
        NorthFindingConfig {
            enabled: true,
            latitude_deg: lat,
            dwell_s: 2.0,
            settle_s: 0.2,
            quiet_s: 0.5,
            ..NorthFindingConfig::default()
        }
    }

    /// A scripted indexing mechanism: acknowledges every command (or rejects one, or says
    /// nothing), moves in 0.5 s, engages and withdraws its pin at once.
    #[derive(Default)]
    struct Mech {
        state: Option<TtState>,
        angle: f64,
        moving: Option<(f64, f64)>,
        acks: Vec<TtAck>,
        reject: Option<TtCommand>,
        silent: bool,
        faults: TtFaults,
        sent: Vec<TtCmd>,
    }

    impl Mech {
        fn command(&mut self, t: f64, c: TtCmd) {
            self.sent.push(c);
            if self.silent {
                return;
            }
            let cmd = TtCommand::from_raw(i64::from(c.command));
            let result = if cmd.is_some() && cmd == self.reject {
                TtResult::Faulted
            } else {
                TtResult::Accepted
            };
            self.acks.push(TtAck {
                seq: c.seq,
                command: c.command,
                axis: c.axis,
                result,
            });
            if result != TtResult::Accepted {
                return;
            }
            match cmd {
                Some(TtCommand::Enable) => self.state = Some(TtState::Locked),
                Some(TtCommand::Unlock) => self.state = Some(TtState::Idle),
                Some(TtCommand::Lock) => self.state = Some(TtState::Locked),
                Some(TtCommand::IndexAbs) => {
                    self.state = Some(TtState::Moving);
                    self.moving = Some((t + 0.5, c.arg));
                }
                Some(TtCommand::Home) => {
                    self.state = Some(TtState::Moving);
                    self.moving = Some((t + 0.5, 0.0));
                }
                _ => {}
            }
        }

        fn status(&mut self, t: f64) -> TtStatus {
            if let Some((until, a)) = self.moving
                && t >= until
            {
                self.angle = a;
                self.state = Some(TtState::Idle);
                self.moving = None;
            }
            TtStatus {
                angle_deg: self.angle,
                rate_dps: 0.0,
                state: self.state.unwrap_or(TtState::Disabled),
                axis: 0,
                faults: self.faults,
                ack_seq: 0,
                counter: 0,
            }
        }
    }

    /// The level-frame rate the solve's model gives at table angle `phi` (deg) for heading `h`
    /// (deg), horizontal earth rate `w` and horizontal biases `b` (deg/h).
    fn model_rate(phi: f64, h: f64, w: f64, b: [f64; 2]) -> [f64; 2] {
        let (p, (s, c)) = (phi.to_radians(), h.to_radians().sin_cos());
        [
            -p.cos() * w * s + p.sin() * w * c + b[0],
            p.sin() * w * s + p.cos() * w * c + b[1],
        ]
    }

    /// Run the sequence against the mechanism with a noise-free IMU at rest, heading `h` deg, at
    /// latitude `lat`; `disturb(position, tau)` adds a rate (rad/s, body x) `tau` s after the
    /// first dwell at `position` began.
    fn run(
        f: &mut NorthFinder,
        m: &mut Mech,
        h: f64,
        lat: f64,
        disturb: impl Fn(usize, f64) -> f64,
    ) -> Vec<(Phase, usize)> {
        let b = [0.1, -0.2];
        let lat_r = lat.to_radians();
        let (w, wv) = (15.041_067 * lat_r.cos(), 15.041_067 * lat_r.sin());
        let dt = 0.002;
        let mut stages = vec![f.stage()];
        let (mut dwell_t0, mut dwells) = (0.0, 0);
        for i in 0..60_000 {
            let t = f64::from(i) * dt;
            let angle = m.angle;
            let r = model_rate(angle, h, w, b);
            let (phase, pos) = f.stage();
            let extra = if phase == Phase::Dwell || phase == Phase::Disturbed {
                disturb(pos, t - dwell_t0)
            } else {
                0.0
            };
            let wb = [r[0] / DPH + extra, r[1] / DPH, wv / DPH];
            f.on_update(t, wb.map(|x| x * dt), [0.0, 0.0, G * dt]);
            if i % 5 == 0 {
                for a in m.acks.drain(..) {
                    f.ack(&a);
                }
                let st = m.status(t);
                f.on_status(&st);
            }
            while let Some(c) = f.poll(t) {
                m.command(t, c);
            }
            if stages.last() != Some(&f.stage()) {
                stages.push(f.stage());
                // the first dwell at each position: a disturbance comes once, at a time of its own
                if f.stage().0 == Phase::Dwell && f.stage().1 > dwells {
                    dwells = f.stage().1;
                    dwell_t0 = t;
                }
            }
            if f.is_finished() {
                break;
            }
        }
        stages
    }

    #[test]
    fn the_solve_recovers_heading_biases_and_earth_rate_in_both_hemispheres() {
        for (h, lat) in [(359.9, -33.9), (0.1, 28.2), (123.4, 60.0), (250.0, -70.0)] {
            let w = 15.041_067 * f64::to_radians(lat).cos();
            let results: Vec<PositionResult> = [0.0, 90.0, 180.0, 270.0]
                .iter()
                .map(|&phi| {
                    let r = model_rate(phi, h, w, [0.1, -0.2]);
                    PositionResult {
                        commanded_deg: phi,
                        table_deg: phi,
                        rate_dph: [r[0], r[1], 0.0],
                        sigma_dph: 0.01,
                        tilt_deg: [0.0, 0.0],
                        repeats: 0,
                    }
                })
                .collect();
            let s = NorthFinder::solve(&results).unwrap();
            let e = (s.heading_deg - h + 180.0).rem_euclid(360.0) - 180.0;
            assert!(e.abs() < 1e-9, "{h} at {lat}: {s:?}");
            assert!((s.horizontal_earth_rate_dph - w).abs() < 1e-9, "{s:?}");
            assert!(
                (s.gyro_bias_dph[0] - 0.1).abs() < 1e-9 && (s.gyro_bias_dph[1] + 0.2).abs() < 1e-9
            );
            // each of W sin H, W cos H comes from two opposite positions on two axes: sigma / 2
            let want = (0.01 / w / 2.0).to_degrees();
            assert!(
                (s.sigma_deg / want - 1.0).abs() < 0.01,
                "{} vs {want}",
                s.sigma_deg
            );
            assert!(NorthFinder::solve(&results[..1]).is_none());
        }
    }

    #[test]
    fn four_positions_in_order_give_the_heading_of_a_noise_free_imu() {
        let (h, lat) = (359.9, -33.9);
        let mut f = NorthFinder::new(cfg(lat)).unwrap();
        let mut m = Mech::default();
        let stages = run(&mut f, &mut m, h, lat, |_, _| 0.0);
        let r = f
            .result()
            .unwrap_or_else(|| panic!("{:?} {stages:?}", f.abort()));
        let e = (r.heading_deg - h + 180.0).rem_euclid(360.0) - 180.0;
        assert!(e.abs() < 1e-6, "{r:?}");
        assert_eq!(r.repeats, 0);
        assert_eq!(r.positions.len(), 4);
        let phases: Vec<Phase> = stages.iter().map(|s| s.0).collect();
        use Phase::*;
        for want in [
            Enabling,
            Unlocking,
            Indexing,
            Locking,
            Settling,
            Dwell,
            Returning,
            LockingZero,
            Done,
        ] {
            assert!(phases.contains(&want), "{want:?} missing: {stages:?}");
        }
        assert_eq!(
            stages.iter().filter(|s| s.0 == Dwell).count(),
            4,
            "{stages:?}"
        );
        // sequence numbers go up by one per command sent, heartbeats included
        for w in m.sent.windows(2) {
            assert_eq!(w[1].seq, w[0].seq.wrapping_add(1));
        }
        let indexes: Vec<f64> = m
            .sent
            .iter()
            .filter(|c| c.command == TtCommand::IndexAbs as u8)
            .map(|c| c.arg)
            .collect();
        assert_eq!(indexes, [0.0, 90.0, 180.0, 270.0]);
        assert!(
            m.sent
                .iter()
                .any(|c| c.command == TtCommand::Heartbeat as u8)
        );
        assert_eq!(m.state, Some(TtState::Locked));
        assert_eq!(m.angle, 0.0);
    }

    #[test]
    fn a_disturbed_dwell_is_repeated_once_the_base_is_quiet() {
        let (h, lat) = (45.0, 28.2);
        let mut f = NorthFinder::new(cfg(lat)).unwrap();
        let mut m = Mech::default();
        // a door slam in the second dwell: 2 Hz, 0.01 deg about x, for 0.4 s
        let slam = |pos: usize, tau: f64| {
            if pos == 2 && (0.5..0.9).contains(&tau) {
                let w = 2.0 * std::f64::consts::PI * 2.0;
                0.01f64.to_radians() * w * (w * tau).cos()
            } else {
                0.0
            }
        };
        let stages = run(&mut f, &mut m, h, lat, slam);
        let r = f.result().unwrap_or_else(|| panic!("{:?}", f.abort()));
        assert_eq!(r.repeats, 1, "{stages:?}");
        assert_eq!(r.positions[1].repeats, 1);
        assert!(stages.contains(&(Phase::Disturbed, 2)), "{stages:?}");
        let e = (r.heading_deg - h + 180.0).rem_euclid(360.0) - 180.0;
        assert!(e.abs() < 1e-6, "{r:?}");
    }

    #[test]
    fn an_unacknowledged_command_is_resent_under_new_numbers_then_given_up() {
        let mut f = NorthFinder::new(cfg(28.2)).unwrap();
        let c1 = f.poll(0.0).unwrap();
        assert_eq!(c1.command, TtCommand::Enable as u8);
        assert!(
            f.poll(0.3).is_none(),
            "no heartbeat while a command is outstanding"
        );
        let c2 = f.poll(0.6).unwrap();
        assert_eq!((c2.command, c2.seq), (c1.command, c1.seq + 1));
        let c3 = f.poll(1.2).unwrap();
        assert_eq!(c3.seq, c1.seq + 2);
        assert!(f.poll(1.8).is_none());
        let why = f.abort().unwrap();
        assert!(
            why.contains("no acknowledgement of Enable") && why.contains("after 3 tries"),
            "{why}"
        );
        assert_eq!(f.phase(), Phase::Aborted);
    }

    #[test]
    fn a_rejected_command_or_a_fault_aborts_with_the_reason_and_the_place() {
        let mut f = NorthFinder::new(cfg(28.2)).unwrap();
        let mut m = Mech {
            reject: Some(TtCommand::Enable),
            ..Mech::default()
        };
        let c = f.poll(0.0).unwrap();
        m.command(0.0, c);
        for a in m.acks.drain(..) {
            f.ack(&a);
        }
        let why = f.abort().unwrap();
        assert!(why.contains("rejected Enable at position 1 of 4"), "{why}");

        let mut f = NorthFinder::new(cfg(28.2)).unwrap();
        let mut m = Mech {
            faults: TtFaults {
                lock: true,
                ..TtFaults::default()
            },
            ..Mech::default()
        };
        let c = f.poll(0.0).unwrap();
        m.command(0.0, c);
        let st = m.status(0.01);
        f.on_status(&st);
        let why = f.abort().unwrap();
        assert!(
            why.contains("turntable fault at position 1") && why.contains("lock"),
            "{why}"
        );
    }

    #[test]
    fn heartbeats_keep_the_link_alive_while_the_sequence_waits() {
        let mut f = NorthFinder::new(cfg(28.2)).unwrap();
        let c = f.poll(0.0).unwrap();
        f.ack(&TtAck {
            seq: c.seq,
            command: c.command,
            axis: 0,
            result: TtResult::Accepted,
        });
        // the mechanism stays disabled: the sequence waits and keeps the watchdog fed
        let disabled = TtStatus {
            angle_deg: 0.0,
            rate_dps: 0.0,
            state: TtState::Disabled,
            axis: 0,
            faults: TtFaults::default(),
            ack_seq: c.seq,
            counter: 0,
        };
        let mut beats = Vec::new();
        for i in 1..=20 {
            let t = f64::from(i) * 0.05;
            f.on_status(&disabled);
            if let Some(b) = f.poll(t) {
                assert_eq!(b.command, TtCommand::Heartbeat as u8);
                f.ack(&TtAck {
                    seq: b.seq,
                    command: b.command,
                    axis: 0,
                    result: TtResult::Accepted,
                });
                beats.push(t);
            }
        }
        assert_eq!(beats.len(), 4, "every 0.25 s: {beats:?}");
        assert!(!f.is_finished());
    }
}
