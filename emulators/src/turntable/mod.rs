//! The indexing mechanism ("turntable"): command handling, dynamics, lock pin, heartbeat
//! watchdog and injected faults, as a pure model of simulated time.
//!
//! Each axis' true angle is an [`AngleProfile`]: analytic segments (constant acceleration, or an
//! exponential settle) appended when a move is planned. The IMU's truth reads the same profile,
//! so the gyros see every move exactly. Commands take effect at the later of their own time and
//! the last time the IMU has read, so the past the IMU has already integrated never changes.
//!
//! Moves are trapezoidal (rate and acceleration limits), end with an exponential settle onto the
//! final angle, and the final angle carries the mechanism's errors: backlash (half of it, with the
//! sign of the approach direction) and repeatability (random, a few arcsec). The lock pin engages
//! only within `lock_window_deg` of a detent and takes `lock_time_s`.

pub mod ttbus;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex};
use wire::{TtAck, TtCmd, TtCommand, TtFaults, TtResult, TtState, TtStatus};

/// One piece of an angle history.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Piece {
    /// `angle = a0 + w0 tau + alpha tau^2 / 2`.
    Poly { a0: f64, w0: f64, alpha: f64 },
    /// `angle = target + e0 exp(-tau / tau_s)`.
    Settle { target: f64, e0: f64, tau_s: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Seg {
    t0: f64,
    piece: Piece,
}

impl Seg {
    fn eval(&self, t: f64) -> (f64, f64, f64) {
        let tau = t - self.t0;
        match self.piece {
            Piece::Poly { a0, w0, alpha } => (
                a0 + w0 * tau + 0.5 * alpha * tau * tau,
                w0 + alpha * tau,
                alpha,
            ),
            Piece::Settle { target, e0, tau_s } => {
                let e = e0 * (-tau / tau_s).exp();
                (target + e, -e / tau_s, e / (tau_s * tau_s))
            }
        }
    }
}

/// The true angle history of one axis (rad, unwrapped), shared between the mechanism and the
/// IMU's truth.
#[derive(Debug, Clone)]
pub struct AngleProfile {
    segs: Vec<Seg>,
    horizon: f64,
}

impl AngleProfile {
    /// At rest at `angle` (rad) from t = 0.
    pub fn at_rest(angle: f64) -> Self {
        Self {
            segs: vec![Seg {
                t0: 0.0,
                piece: Piece::Poly {
                    a0: angle,
                    w0: 0.0,
                    alpha: 0.0,
                },
            }],
            horizon: 0.0,
        }
    }

    fn seg_at(&self, t: f64) -> &Seg {
        let i = self.segs.partition_point(|s| s.t0 <= t).saturating_sub(1);
        &self.segs[i]
    }

    /// The angle does not change over `[t0, t1]` (to within [`crate::truth::STILL_RAD`]): one
    /// piece covers it, at rest or settled.
    pub fn still(&self, t0: f64, t1: f64) -> bool {
        let i = self.segs.partition_point(|s| s.t0 <= t0).saturating_sub(1);
        if self.segs.get(i + 1).is_some_and(|n| n.t0 <= t1) {
            return false;
        }
        match self.segs[i].piece {
            Piece::Poly { w0, alpha, .. } => w0 == 0.0 && alpha == 0.0,
            Piece::Settle { e0, tau_s, .. } => {
                e0.abs() * (-(t0 - self.segs[i].t0).max(0.0) / tau_s).exp()
                    < crate::truth::STILL_RAD
            }
        }
    }

    /// Angle (rad), rate (rad/s) and acceleration at `t`.
    pub fn eval(&self, t: f64) -> (f64, f64, f64) {
        self.seg_at(t).eval(t)
    }

    /// Record that the IMU has integrated up to `t`: the history before it is final.
    pub fn read_to(&mut self, t: f64) {
        self.horizon = self.horizon.max(t);
    }

    /// The earliest time a change may take effect at, given it was asked for at `t`.
    pub fn effective(&self, t: f64) -> f64 {
        t.max(self.horizon)
    }

    /// Replace everything from `t` on with `pieces` (start times absolute).
    fn replace_from(&mut self, t: f64, pieces: Vec<Seg>) {
        self.segs.retain(|s| s.t0 < t);
        if self.segs.is_empty() {
            // keep the state at t as a starting point
            self.segs.push(Seg {
                t0: 0.0,
                piece: Piece::Poly {
                    a0: 0.0,
                    w0: 0.0,
                    alpha: 0.0,
                },
            });
        }
        self.segs.extend(pieces);
    }
}

/// A shared profile handle.
pub type SharedProfile = Arc<Mutex<AngleProfile>>;

/// Lock a shared profile, recovering from a poisoned lock (a panicked holder cannot leave the
/// profile half-written: every change is a single `replace_from`).
pub fn lock(p: &SharedProfile) -> std::sync::MutexGuard<'_, AngleProfile> {
    p.lock().unwrap_or_else(|e| e.into_inner())
}

/// The IMU's view of an axis: reads the shared profile.
#[derive(Clone)]
pub struct ProfileAxis(pub SharedProfile);

impl crate::truth::AxisAngle for ProfileAxis {
    fn angle(&self, t: f64) -> f64 {
        let mut p = lock(&self.0);
        p.read_to(t);
        p.eval(t).0
    }
    fn rate(&self, t: f64) -> f64 {
        let mut p = lock(&self.0);
        p.read_to(t);
        p.eval(t).1
    }
    fn angle_and_rate(&self, t: f64) -> (f64, f64) {
        let mut p = lock(&self.0);
        p.read_to(t);
        let (a, r, _) = p.eval(t);
        (a, r)
    }
    fn still(&self, t0: f64, t1: f64) -> bool {
        let mut p = lock(&self.0);
        p.read_to(t1);
        p.still(t0, t1)
    }
}

/// Faults the mechanism can be told to have.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct TurntableFaults {
    /// From this time on the motor stalls on the next move (stops dead, stall fault).
    pub stall_from_s: Option<f64>,
    /// The lock pin never engages (lock fault after the lock time).
    pub lock_fails: bool,
    /// Times at which one status frame carries a glitched encoder angle (and the encoder bit).
    pub encoder_glitch_at_s: Vec<f64>,
    /// Command sequence numbers that are lost (never executed, never acknowledged).
    pub lost_command_seqs: Vec<u8>,
    /// Extra delay before a command takes effect and is acknowledged, s.
    pub command_delay_s: f64,
    /// Periods [start, end] s in which the controller sends no status frames (its heartbeat
    /// is lost; the mechanism itself goes on).
    pub status_silent_s: Vec<[f64; 2]>,
}

/// Mechanism parameters (the `[turntable]` table of a scenario).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct TurntableParams {
    /// Axes: 1 (vehicle azimuth indexer), 2 (dual-axis rotating IMU), 3 (lab table).
    pub axes: u8,
    /// Rate limit, deg/s.
    pub max_rate_dps: f64,
    /// Acceleration limit, deg/s^2.
    pub max_accel_dps2: f64,
    /// Settling time constant after a move, s.
    pub settle_tau_s: f64,
    /// The move reports `Settling` until the remaining error is below this, deg.
    pub settle_tolerance_deg: f64,
    /// Backlash, arcsec (half of it appears with the sign of the approach).
    pub backlash_arcsec: f64,
    /// Repeatability of the final angle (1 sigma), arcsec.
    pub repeatability_arcsec: f64,
    /// Encoder noise on the status angle (1 sigma), arcsec.
    pub encoder_noise_arcsec: f64,
    /// Lock detents, deg.
    pub detents_deg: Vec<f64>,
    /// Lock engages only this close to a detent, deg.
    pub lock_window_deg: f64,
    /// Time for the lock pin to engage or withdraw, s.
    pub lock_time_s: f64,
    /// Without any command for this long an enabled axis stops and faults, s.
    pub heartbeat_timeout_s: f64,
    /// Status frames per second per axis.
    pub status_hz: f64,
    /// Largest relative move, deg.
    pub max_move_deg: f64,
    /// Seed.
    pub seed: u64,
    /// Injected faults.
    pub faults: TurntableFaults,
}

impl Default for TurntableParams {
    fn default() -> Self {
        Self {
            axes: 1,
            max_rate_dps: 30.0,
            max_accel_dps2: 60.0,
            settle_tau_s: 0.08,
            settle_tolerance_deg: 0.0005,
            backlash_arcsec: 6.0,
            repeatability_arcsec: 2.0,
            encoder_noise_arcsec: 0.5,
            detents_deg: vec![0.0, 90.0, 180.0, 270.0],
            lock_window_deg: 0.02,
            lock_time_s: 0.4,
            heartbeat_timeout_s: 1.0,
            status_hz: 100.0,
            max_move_deg: 720.0,
            seed: 1,
            faults: TurntableFaults::default(),
        }
    }
}

impl TurntableParams {
    /// Check ranges; the message names the parameter.
    pub fn check(&self) -> Result<(), crate::ParamError> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if !(1..=3).contains(&self.axes) {
            return Err(crate::ParamError::new(
                "turntable",
                format!("axes must be 1, 2 or 3, not {}", self.axes),
            ));
        }
        if !(pos(self.max_rate_dps) && pos(self.max_accel_dps2) && pos(self.settle_tau_s)) {
            return Err(crate::ParamError::new(
                "turntable",
                "rate, acceleration and settle time must be positive",
            ));
        }
        if !(pos(self.status_hz) && self.status_hz <= 1000.0) {
            return Err(crate::ParamError::new(
                "turntable",
                "status_hz must be in (0, 1000]",
            ));
        }
        if !pos(self.heartbeat_timeout_s) {
            return Err(crate::ParamError::new(
                "turntable",
                "heartbeat_timeout_s must be positive",
            ));
        }
        Ok(())
    }
}

/// Why a lock is pending.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Pin {
    Out,
    Engaging { done_at: f64 },
    In,
    Withdrawing { done_at: f64 },
}

#[derive(Debug)]
struct Axis {
    profile: SharedProfile,
    state: TtState,
    faults: TtFaults,
    pin: Pin,
    /// When the current move (planned) reaches its settle tolerance.
    move_done_at: Option<f64>,
    /// When the current move starts settling.
    settle_from: Option<f64>,
    /// The commanded final angle of the current move, rad (unwrapped).
    target: Option<f64>,
    rate_mode: bool,
    last_dir: f64,
}

/// Commands the mechanism has received but not executed yet (delay fault).
#[derive(Debug, Clone, Copy)]
struct Pending {
    at: f64,
    cmd: TtCmd,
}

/// The mechanism.
#[derive(Debug)]
pub struct Turntable {
    p: TurntableParams,
    axes: Vec<Axis>,
    last_cmd_at: f64,
    ack_seq: u8,
    counter: u8,
    rng: StdRng,
    pending: Vec<Pending>,
    glitches: Vec<f64>,
    stall_armed: bool,
    stall_at: Option<(usize, f64)>,
}

const DEG: f64 = std::f64::consts::PI / 180.0;

fn wrap360(deg: f64) -> f64 {
    let w = deg.rem_euclid(360.0);
    if w >= 360.0 { 0.0 } else { w }
}

/// A move's acceleration, cruise (when there is one) and deceleration from angle `a0` (rad)
/// at `t` (s) in direction `dir`: the profile's pieces, and the angle and time it ends at.
fn trapezoid(
    t: f64,
    a0: f64,
    dir: f64,
    amax: f64,
    v: f64,
    t_acc: f64,
    t_cruise: f64,
) -> (Vec<Seg>, f64, f64) {
    let mut pieces = Vec::new();
    let mut tt = t;
    let mut a = a0;
    pieces.push(Seg {
        t0: tt,
        piece: Piece::Poly {
            a0: a,
            w0: 0.0,
            alpha: dir * amax,
        },
    });
    a += dir * 0.5 * amax * t_acc * t_acc;
    tt += t_acc;
    if t_cruise > 0.0 {
        pieces.push(Seg {
            t0: tt,
            piece: Piece::Poly {
                a0: a,
                w0: dir * v,
                alpha: 0.0,
            },
        });
        a += dir * v * t_cruise;
        tt += t_cruise;
    }
    pieces.push(Seg {
        t0: tt,
        piece: Piece::Poly {
            a0: a,
            w0: dir * v,
            alpha: -dir * amax,
        },
    });
    a += dir * 0.5 * amax * t_acc * t_acc;
    tt += t_acc;
    (pieces, a, tt)
}

impl Turntable {
    /// A mechanism at rest at zero, drive off.
    pub fn new(p: TurntableParams) -> Self {
        let axes = (0..p.axes)
            .map(|_| Axis {
                profile: Arc::new(Mutex::new(AngleProfile::at_rest(0.0))),
                state: TtState::Disabled,
                faults: TtFaults::default(),
                pin: Pin::Out,
                move_done_at: None,
                settle_from: None,
                target: None,
                rate_mode: false,
                last_dir: 1.0,
            })
            .collect();
        Self {
            rng: StdRng::seed_from_u64(p.seed),
            glitches: p.faults.encoder_glitch_at_s.clone(),
            stall_armed: p.faults.stall_from_s.is_some(),
            stall_at: None,
            p,
            axes,
            last_cmd_at: 0.0,
            ack_seq: 0,
            counter: 0,
            pending: Vec::new(),
        }
    }

    /// The parameters.
    pub fn params(&self) -> &TurntableParams {
        &self.p
    }

    /// The shared true-angle profile of `axis` (for the IMU's truth).
    pub fn profile(&self, axis: usize) -> SharedProfile {
        self.axes[axis].profile.clone()
    }

    /// True angle (deg, unwrapped) and rate (deg/s) of `axis` at `t`.
    pub fn true_angle(&self, axis: usize, t: f64) -> (f64, f64) {
        let (a, w, _) = lock(&self.axes[axis].profile).eval(t);
        (a / DEG, w / DEG)
    }

    /// Number of axes.
    pub fn axis_count(&self) -> usize {
        self.axes.len()
    }

    /// State of `axis`.
    pub fn state(&self, axis: usize) -> TtState {
        self.axes[axis].state
    }

    /// A command arrives at simulated time `t`. Returns the acknowledgement to send now (none
    /// when the command is lost, or delayed: delayed ones are answered by [`Turntable::advance`]).
    pub fn command(&mut self, t: f64, cmd: TtCmd) -> Option<TtAck> {
        if self.p.faults.lost_command_seqs.contains(&cmd.seq) {
            return None;
        }
        if self.p.faults.command_delay_s > 0.0 {
            self.pending.push(Pending {
                at: t + self.p.faults.command_delay_s,
                cmd,
            });
            return None;
        }
        Some(self.execute(t, cmd))
    }

    fn execute(&mut self, t: f64, cmd: TtCmd) -> TtAck {
        self.last_cmd_at = t;
        let result = self.decide(t, &cmd);
        self.ack_seq = cmd.seq;
        TtAck {
            seq: cmd.seq,
            command: cmd.command,
            axis: cmd.axis,
            result,
        }
    }

    fn decide(&mut self, t: f64, cmd: &TtCmd) -> TtResult {
        let Some(code) = TtCommand::from_raw(i64::from(cmd.command)) else {
            return TtResult::UnknownCommand;
        };
        if usize::from(cmd.axis) >= self.axes.len() {
            return TtResult::BadAxis;
        }
        let i = usize::from(cmd.axis);
        self.update_axis(i, t);
        let st = self.axes[i].state;
        use TtCommand as C;
        match code {
            C::Heartbeat => TtResult::Accepted,
            C::EStop => {
                self.halt(i, t, true);
                let a = &mut self.axes[i];
                a.faults.estop = true;
                a.state = TtState::Fault;
                TtResult::Accepted
            }
            C::Disable => {
                self.halt(i, t, true);
                let a = &mut self.axes[i];
                a.state = TtState::Disabled;
                a.faults = TtFaults::default();
                a.rate_mode = false;
                TtResult::Accepted
            }
            _ if st == TtState::Fault => TtResult::Faulted,
            C::Enable => {
                if st == TtState::Disabled {
                    let a = &mut self.axes[i];
                    a.state = if a.pin == Pin::In {
                        TtState::Locked
                    } else {
                        TtState::Idle
                    };
                }
                TtResult::Accepted
            }
            _ if st == TtState::Disabled => TtResult::NotEnabled,
            C::Stop => {
                self.halt(i, t, false);
                TtResult::Accepted
            }
            C::Lock => {
                if st == TtState::Locked {
                    return TtResult::Accepted;
                }
                if matches!(st, TtState::Moving | TtState::Settling) {
                    return TtResult::Busy;
                }
                let (ang, _) = self.true_angle(i, t);
                if !self.near_detent(ang) {
                    return TtResult::NotAtDetent;
                }
                self.axes[i].pin = Pin::Engaging {
                    done_at: t + self.p.lock_time_s,
                };
                TtResult::Accepted
            }
            C::Unlock => {
                let a = &mut self.axes[i];
                match a.pin {
                    Pin::In | Pin::Engaging { .. } => {
                        a.pin = Pin::Withdrawing {
                            done_at: t + self.p.lock_time_s,
                        };
                    }
                    _ => {}
                }
                TtResult::Accepted
            }
            C::Home | C::IndexAbs | C::MoveRel | C::Rate => self.decide_motion(i, t, code, cmd, st),
        }
    }

    /// A motion command (home, index, move, rate) on axis `i` in state `st`: refused while
    /// locked, busy or out of range, else planned.
    fn decide_motion(
        &mut self,
        i: usize,
        t: f64,
        code: TtCommand,
        cmd: &TtCmd,
        st: TtState,
    ) -> TtResult {
        use TtCommand as C;
        if st == TtState::Locked || self.axes[i].pin != Pin::Out {
            return TtResult::Locked;
        }
        let rate_change = code == C::Rate && self.axes[i].rate_mode;
        if matches!(st, TtState::Moving | TtState::Settling) && !rate_change {
            return TtResult::Busy;
        }
        match code {
            C::Rate => {
                if cmd.arg.is_nan() || cmd.arg.abs() > self.p.max_rate_dps {
                    return TtResult::OutOfRange;
                }
                self.plan_rate(i, t, cmd.arg);
            }
            C::Home => self.plan_abs(i, t, 0.0),
            C::IndexAbs => {
                if !(0.0..360.0).contains(&cmd.arg) {
                    return TtResult::OutOfRange;
                }
                self.plan_abs(i, t, cmd.arg);
            }
            _ => {
                if cmd.arg.is_nan() || cmd.arg.abs() > self.p.max_move_deg || cmd.arg == 0.0 {
                    return TtResult::OutOfRange;
                }
                let (ang, _) = self.true_angle(i, t);
                let base = self.axes[i].target.map_or(ang, |x| x / DEG);
                self.plan_move(i, t, base + cmd.arg);
            }
        }
        TtResult::Accepted
    }

    fn near_detent(&self, angle_deg: f64) -> bool {
        let a = wrap360(angle_deg);
        self.p.detents_deg.iter().any(|d| {
            let diff = (a - d).rem_euclid(360.0);
            diff.min(360.0 - diff) <= self.p.lock_window_deg
        })
    }

    /// Plan a move to the absolute angle `deg` by the shorter way round.
    fn plan_abs(&mut self, i: usize, t: f64, deg: f64) {
        let (ang, _) = self.true_angle(i, t);
        let cur = self.axes[i].target.map_or(ang, |x| x / DEG);
        let mut d = (deg - wrap360(cur)).rem_euclid(360.0);
        if d > 180.0 {
            d -= 360.0;
        }
        self.plan_move(i, t, cur + d);
    }

    /// Trapezoidal move from rest to `goal_deg` (unwrapped), then a settle onto the final angle
    /// with backlash and repeatability.
    fn plan_move(&mut self, i: usize, t: f64, goal_deg: f64) {
        let mut prof = lock(&self.axes[i].profile);
        let t = prof.effective(t);
        let (a0, _, _) = prof.eval(t);
        let dist = goal_deg * DEG - a0;
        let dir = if dist >= 0.0 { 1.0 } else { -1.0 };
        let (vmax, amax) = (self.p.max_rate_dps * DEG, self.p.max_accel_dps2 * DEG);
        let d = dist.abs();
        let (t_acc, t_cruise, v) = if d >= vmax * vmax / amax {
            (vmax / amax, (d - vmax * vmax / amax) / vmax, vmax)
        } else {
            let v = (d * amax).sqrt();
            (v / amax, 0.0, v)
        };
        // errors of the final angle: backlash with the sign of the approach, repeatability
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let err = (0.5 * self.p.backlash_arcsec * dir
            + self.p.repeatability_arcsec * n.sample(&mut self.rng))
            / 3600.0
            * DEG;
        let final_angle = goal_deg * DEG + err;
        let (mut pieces, a, tt) = trapezoid(t, a0, dir, amax, v, t_acc, t_cruise);
        // settle from where the profile ends (the commanded goal) onto the final angle
        let e0 = a - final_angle;
        let tau = self.p.settle_tau_s;
        pieces.push(Seg {
            t0: tt,
            piece: Piece::Settle {
                target: final_angle,
                e0,
                tau_s: tau,
            },
        });
        let tol = self.p.settle_tolerance_deg * DEG;
        let t_settle = if e0.abs() > tol {
            tau * (e0.abs() / tol).ln()
        } else {
            0.0
        };
        prof.replace_from(t, pieces);
        drop(prof);
        let ax = &mut self.axes[i];
        ax.move_done_at = Some(tt + t_settle);
        ax.settle_from = Some(tt);
        ax.target = Some(goal_deg * DEG);
        ax.state = TtState::Moving;
        ax.rate_mode = false;
        ax.last_dir = dir;
        if self.stall_armed && self.p.faults.stall_from_s.is_some_and(|s| t >= s) {
            // the motor stalls a third of the way into the acceleration
            self.stall_armed = false;
            let ts = t + t_acc / 3.0;
            let mut prof = lock(&self.axes[i].profile);
            let (a_s, _, _) = prof.eval(ts);
            prof.replace_from(
                ts,
                vec![Seg {
                    t0: ts,
                    piece: Piece::Poly {
                        a0: a_s,
                        w0: 0.0,
                        alpha: 0.0,
                    },
                }],
            );
            drop(prof);
            let ax = &mut self.axes[i];
            ax.move_done_at = Some(f64::INFINITY);
            ax.settle_from = None;
            ax.target = None;
            self.stall_at = Some((i, ts));
        }
    }

    /// Ramp to a constant rate (deg/s) and hold it.
    fn plan_rate(&mut self, i: usize, t: f64, rate_dps: f64) {
        let mut prof = lock(&self.axes[i].profile);
        let t = prof.effective(t);
        let (a0, w0, _) = prof.eval(t);
        let w1 = rate_dps * DEG;
        let amax = self.p.max_accel_dps2 * DEG;
        let dt = (w1 - w0).abs() / amax;
        let alpha = (w1 - w0).signum() * amax;
        let mut pieces = vec![Seg {
            t0: t,
            piece: Piece::Poly { a0, w0, alpha },
        }];
        let a1 = a0 + w0 * dt + 0.5 * alpha * dt * dt;
        pieces.push(Seg {
            t0: t + dt,
            piece: Piece::Poly {
                a0: a1,
                w0: w1,
                alpha: 0.0,
            },
        });
        prof.replace_from(t, pieces);
        drop(prof);
        let ax = &mut self.axes[i];
        ax.state = if rate_dps == 0.0 {
            TtState::Idle
        } else {
            TtState::Moving
        };
        ax.rate_mode = rate_dps != 0.0;
        ax.move_done_at = None;
        ax.settle_from = None;
        ax.target = None;
    }

    /// Stop: decelerate to rest (or at once, `hard`, for a drive cut).
    fn halt(&mut self, i: usize, t: f64, hard: bool) {
        let mut prof = lock(&self.axes[i].profile);
        let t = prof.effective(t);
        let (a0, w0, _) = prof.eval(t);
        let pieces = if hard || w0 == 0.0 {
            vec![Seg {
                t0: t,
                piece: Piece::Poly {
                    a0,
                    w0: 0.0,
                    alpha: 0.0,
                },
            }]
        } else {
            let amax = self.p.max_accel_dps2 * DEG;
            let dt = w0.abs() / amax;
            let alpha = -w0.signum() * amax;
            vec![
                Seg {
                    t0: t,
                    piece: Piece::Poly { a0, w0, alpha },
                },
                Seg {
                    t0: t + dt,
                    piece: Piece::Poly {
                        a0: a0 + w0 * dt + 0.5 * alpha * dt * dt,
                        w0: 0.0,
                        alpha: 0.0,
                    },
                },
            ]
        };
        let moving = w0 != 0.0;
        let stop_at = pieces.last().map_or(t, |s| s.t0);
        prof.replace_from(t, pieces);
        drop(prof);
        let ax = &mut self.axes[i];
        ax.rate_mode = false;
        ax.target = None;
        ax.settle_from = None;
        if matches!(ax.state, TtState::Moving | TtState::Settling) {
            ax.move_done_at = Some(stop_at);
            ax.state = if moving {
                TtState::Moving
            } else {
                TtState::Idle
            };
        }
    }

    /// Bring the axis' state up to time `t` (move completion, lock pin, watchdog, stall).
    fn update_axis(&mut self, i: usize, t: f64) {
        if let Some((ax, ts)) = self.stall_at
            && ax == i
            && t >= ts
        {
            self.stall_at = None;
            let a = &mut self.axes[i];
            a.faults.stall = true;
            a.state = TtState::Fault;
            a.move_done_at = None;
        }
        let hb = self.p.heartbeat_timeout_s;
        let last = self.last_cmd_at;
        let needs_halt = {
            let a = &self.axes[i];
            !matches!(a.state, TtState::Disabled | TtState::Fault) && t - last > hb
        };
        if needs_halt {
            self.halt(i, last + hb, false);
            let a = &mut self.axes[i];
            a.faults.heartbeat = true;
            a.state = TtState::Fault;
        }
        let a = &mut self.axes[i];
        if let Some(done) = a.move_done_at
            && matches!(a.state, TtState::Moving | TtState::Settling)
        {
            if t >= done {
                a.state = TtState::Idle;
                a.move_done_at = None;
                a.settle_from = None;
            } else if a.settle_from.is_some_and(|s| t >= s) {
                a.state = TtState::Settling;
            }
        }
        match a.pin {
            Pin::Engaging { done_at } if t >= done_at => {
                if self.p.faults.lock_fails {
                    a.pin = Pin::Out;
                    a.faults.lock = true;
                    a.state = TtState::Fault;
                } else {
                    a.pin = Pin::In;
                    if a.state == TtState::Idle {
                        a.state = TtState::Locked;
                    }
                }
            }
            Pin::Withdrawing { done_at } if t >= done_at => {
                a.pin = Pin::Out;
                if a.state == TtState::Locked {
                    a.state = TtState::Idle;
                }
            }
            _ => {}
        }
    }

    /// Advance to `t`: execute delayed commands (their acks go to `acks`) and update states.
    pub fn advance(&mut self, t: f64, acks: &mut Vec<TtAck>) {
        self.pending.sort_by(|a, b| a.at.total_cmp(&b.at));
        while let Some(p) = self.pending.first().copied() {
            if p.at > t {
                break;
            }
            self.pending.remove(0);
            acks.push(self.execute(p.at, p.cmd));
        }
        for i in 0..self.axes.len() {
            self.update_axis(i, t);
        }
    }

    /// The status frames of every axis at `t` (call at `status_hz`).
    pub fn status(&mut self, t: f64) -> Vec<TtStatus> {
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let glitch = if let Some(pos) = self.glitches.iter().position(|g| *g <= t) {
            self.glitches.swap_remove(pos);
            true
        } else {
            false
        };
        self.counter = (self.counter + 1) & 0xF;
        let mut out = Vec::with_capacity(self.axes.len());
        for i in 0..self.axes.len() {
            self.update_axis(i, t);
            let (ang, rate) = self.true_angle(i, t);
            let noise = self.p.encoder_noise_arcsec / 3600.0 * n.sample(&mut self.rng);
            let a = &self.axes[i];
            let mut faults = a.faults;
            let mut angle = ang + noise;
            if glitch && i == 0 {
                angle += 7.3;
                faults.encoder = true;
            }
            out.push(TtStatus {
                angle_deg: wrap360(angle),
                rate_dps: rate,
                state: a.state,
                axis: i as u8,
                faults,
                ack_seq: self.ack_seq,
                counter: self.counter,
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cmd(seq: u8, c: TtCommand, arg: f64) -> TtCmd {
        TtCmd {
            seq,
            command: c as u8,
            axis: 0,
            arg,
        }
    }

    /// Run the mechanism from `t0` to `t1` with heartbeats every 0.2 s, returning the states seen.
    fn run(tt: &mut Turntable, t0: f64, t1: f64, seq: &mut u8) -> Vec<TtState> {
        let mut seen = Vec::new();
        let mut t = t0;
        let mut next_hb = t0;
        while t < t1 {
            if t >= next_hb {
                *seq = seq.wrapping_add(1);
                tt.command(t, cmd(*seq, TtCommand::Heartbeat, 0.0));
                next_hb += 0.2;
            }
            tt.advance(t, &mut Vec::new());
            let s = tt.status(t)[0].state;
            if seen.last() != Some(&s) {
                seen.push(s);
            }
            t += 0.01;
        }
        seen
    }

    #[test]
    fn index_settle_and_lock_at_a_detent() {
        let p = TurntableParams::default();
        let mut tt = Turntable::new(p.clone());
        let mut seq = 0;
        assert_eq!(
            tt.command(0.0, cmd(1, TtCommand::Enable, 0.0))
                .unwrap()
                .result,
            TtResult::Accepted
        );
        let ack = tt.command(0.1, cmd(2, TtCommand::IndexAbs, 90.0)).unwrap();
        assert_eq!(ack.result, TtResult::Accepted);
        assert_eq!(ack.seq, 2);
        let states = run(&mut tt, 0.1, 6.0, &mut seq);
        assert_eq!(
            states,
            vec![TtState::Moving, TtState::Settling, TtState::Idle],
            "{states:?}"
        );
        let (a, w) = tt.true_angle(0, 6.0);
        let err_arcsec = (a - 90.0) * 3600.0;
        let lim = p.backlash_arcsec / 2.0 + 4.0 * p.repeatability_arcsec;
        assert!(err_arcsec.abs() <= lim, "{err_arcsec} arcsec");
        assert!(w.abs() < 1e-9);
        // the encoder reports it within its noise and resolution
        let st = tt.status(6.0)[0];
        assert!((st.angle_deg - a).abs() < 5.0 * p.encoder_noise_arcsec / 3600.0 + 1e-4);
        // a 90 deg move at 30 deg/s, 60 deg/s^2: 3.5 s plus the settle
        assert_eq!(
            tt.command(6.0, cmd(3, TtCommand::Lock, 0.0))
                .unwrap()
                .result,
            TtResult::Accepted
        );
        let states = run(&mut tt, 6.0, 7.0, &mut seq);
        assert_eq!(states.last(), Some(&TtState::Locked), "{states:?}");
        assert_eq!(
            tt.command(7.0, cmd(4, TtCommand::IndexAbs, 180.0))
                .unwrap()
                .result,
            TtResult::Locked
        );
        tt.command(7.0, cmd(5, TtCommand::Unlock, 0.0));
        run(&mut tt, 7.0, 7.6, &mut seq);
        assert_eq!(tt.state(0), TtState::Idle);
        // home: back to zero the short way
        assert_eq!(
            tt.command(7.6, cmd(6, TtCommand::Home, 0.0))
                .unwrap()
                .result,
            TtResult::Accepted
        );
        run(&mut tt, 7.6, 13.0, &mut seq);
        let (a, _) = tt.true_angle(0, 13.0);
        assert!(a.abs() * 3600.0 <= lim, "home at {a} deg");
    }

    #[test]
    fn invalid_commands_are_rejected_with_the_reason() {
        let mut tt = Turntable::new(TurntableParams::default());
        let r = |tt: &mut Turntable, t: f64, c: TtCmd| tt.command(t, c).unwrap().result;
        assert_eq!(
            r(&mut tt, 0.0, cmd(1, TtCommand::IndexAbs, 90.0)),
            TtResult::NotEnabled
        );
        assert_eq!(
            r(
                &mut tt,
                0.0,
                TtCmd {
                    seq: 2,
                    command: 99,
                    axis: 0,
                    arg: 0.0
                }
            ),
            TtResult::UnknownCommand
        );
        assert_eq!(
            r(
                &mut tt,
                0.0,
                TtCmd {
                    seq: 3,
                    command: 1,
                    axis: 2,
                    arg: 0.0
                }
            ),
            TtResult::BadAxis
        );
        r(&mut tt, 0.0, cmd(4, TtCommand::Enable, 0.0));
        assert_eq!(
            r(&mut tt, 0.0, cmd(5, TtCommand::IndexAbs, 400.0)),
            TtResult::OutOfRange
        );
        assert_eq!(
            r(&mut tt, 0.0, cmd(6, TtCommand::Rate, 99.0)),
            TtResult::OutOfRange
        );
        assert_eq!(
            r(&mut tt, 0.0, cmd(7, TtCommand::MoveRel, 45.0)),
            TtResult::Accepted
        );
        assert_eq!(
            r(&mut tt, 0.1, cmd(8, TtCommand::IndexAbs, 10.0)),
            TtResult::Busy
        );
        // 45 deg is not a detent
        let mut seq = 10;
        run(&mut tt, 0.1, 4.0, &mut seq);
        assert_eq!(
            r(&mut tt, 4.0, cmd(20, TtCommand::Lock, 0.0)),
            TtResult::NotAtDetent
        );
        assert_eq!(
            r(&mut tt, 4.0, cmd(21, TtCommand::EStop, 0.0)),
            TtResult::Accepted
        );
        assert_eq!(tt.state(0), TtState::Fault);
        assert_eq!(
            r(&mut tt, 4.1, cmd(22, TtCommand::Home, 0.0)),
            TtResult::Faulted
        );
        // disable clears the fault
        assert_eq!(
            r(&mut tt, 4.2, cmd(23, TtCommand::Disable, 0.0)),
            TtResult::Accepted
        );
        assert_eq!(tt.state(0), TtState::Disabled);
        assert!(!tt.status(4.2)[0].faults.any());
    }

    #[test]
    fn without_commands_the_watchdog_stops_the_axis_safely() {
        let mut tt = Turntable::new(TurntableParams::default());
        tt.command(0.0, cmd(1, TtCommand::Enable, 0.0));
        tt.command(0.0, cmd(2, TtCommand::Rate, 20.0));
        // no heartbeat: after 1 s the axis decelerates to rest and faults
        let mut t = 0.0;
        while t < 3.0 {
            tt.advance(t, &mut Vec::new());
            t += 0.01;
        }
        let st = tt.status(3.0)[0];
        assert_eq!(st.state, TtState::Fault);
        assert!(st.faults.heartbeat);
        assert!(st.rate_dps.abs() < 1e-9, "{}", st.rate_dps);
    }

    #[test]
    fn emergency_stop_cuts_the_drive_at_once() {
        let mut tt = Turntable::new(TurntableParams::default());
        let mut seq = 0;
        tt.command(0.0, cmd(1, TtCommand::Enable, 0.0));
        tt.command(0.0, cmd(2, TtCommand::Rate, 20.0));
        run(&mut tt, 0.0, 1.0, &mut seq);
        assert!((tt.true_angle(0, 1.0).1 - 20.0).abs() < 1e-9);
        tt.command(1.0, cmd(50, TtCommand::EStop, 0.0));
        assert_eq!(tt.true_angle(0, 1.001).1, 0.0);
        assert!(tt.status(1.01)[0].faults.estop);
    }

    #[test]
    fn injected_faults_show_up() {
        let p = TurntableParams {
            faults: TurntableFaults {
                stall_from_s: Some(0.0),
                lost_command_seqs: vec![9],
                encoder_glitch_at_s: vec![0.5],
                ..TurntableFaults::default()
            },
            ..TurntableParams::default()
        };
        let mut tt = Turntable::new(p);
        let mut seq = 0;
        tt.command(0.0, cmd(1, TtCommand::Enable, 0.0));
        assert!(
            tt.command(0.0, cmd(9, TtCommand::Heartbeat, 0.0)).is_none(),
            "lost"
        );
        tt.command(0.0, cmd(2, TtCommand::IndexAbs, 90.0));
        let mut glitch = false;
        let mut t = 0.0;
        while t < 2.0 {
            seq += 1;
            tt.command(t, cmd(100 + (seq % 100) as u8, TtCommand::Heartbeat, 0.0));
            glitch |= tt.status(t)[0].faults.encoder;
            t += 0.01;
        }
        assert!(glitch, "one glitched status frame");
        let st = tt.status(2.0)[0];
        assert!(st.faults.stall && st.state == TtState::Fault, "{st:?}");
        assert!(tt.true_angle(0, 2.0).0 < 5.0, "stalled early in the move");

        let p = TurntableParams {
            faults: TurntableFaults {
                lock_fails: true,
                command_delay_s: 0.05,
                ..TurntableFaults::default()
            },
            ..TurntableParams::default()
        };
        let mut tt = Turntable::new(p);
        assert!(
            tt.command(0.0, cmd(1, TtCommand::Enable, 0.0)).is_none(),
            "delayed"
        );
        let mut acks = Vec::new();
        tt.advance(0.04, &mut acks);
        assert!(acks.is_empty());
        tt.advance(0.06, &mut acks);
        assert_eq!(acks.len(), 1);
        tt.command(0.1, cmd(2, TtCommand::Lock, 0.0));
        let mut seq = 10;
        run(&mut tt, 0.1, 1.0, &mut seq);
        let st = tt.status(1.0)[0];
        assert!(st.faults.lock && st.state == TtState::Fault, "{st:?}");
    }

    #[test]
    fn the_imu_sees_every_move_through_the_shared_profile() {
        use crate::truth::AxisAngle;
        let mut tt = Turntable::new(TurntableParams::default());
        let axis = ProfileAxis(tt.profile(0));
        tt.command(0.0, cmd(1, TtCommand::Enable, 0.0));
        tt.command(0.0, cmd(2, TtCommand::IndexAbs, 270.0));
        // integrate the rate the IMU reads: it must add up to the angle moved (-90 deg)
        let (mut sum, dt) = (0.0, 1e-4);
        let mut t = 0.0;
        while t < 5.0 {
            sum += axis.rate(t + dt / 2.0) * dt;
            t += dt;
        }
        let moved = tt.true_angle(0, 5.0).0;
        assert!(
            (sum.to_degrees() - moved).abs() < 1e-6,
            "{} vs {moved}",
            sum.to_degrees()
        );
        assert!((moved + 90.0).abs() < 0.01, "the short way round: {moved}");
        // a command after the IMU has read ahead takes effect from then, never in its past
        tt.command(2.0, cmd(3, TtCommand::Heartbeat, 0.0));
        let before = axis.angle(4.0);
        tt.command(3.0, cmd(4, TtCommand::Stop, 0.0));
        assert_eq!(axis.angle(4.0), before);
    }
}
