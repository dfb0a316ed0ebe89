//! Turntable validation: a suite of checks run against the mechanism on a CAN interface, the
//! emulator or a real one, as a CAN client (TT_CMD out, TT_ACK and TT_STATUS in). Each check
//! reports the measured value against its limit; the suite prints a table and writes JSON.

use anyhow::{Context, Result, bail};
use serde::Serialize;
use socketcan::{CanSocket, Socket, SocketOptions};
use std::time::{Duration, Instant};
use wire::{Message, TtAck, TtCmd, TtCommand, TtResult, TtState, TtStatus};

/// Limits of the suite (defaults: the vehicle azimuth indexer).
#[derive(Debug, Clone, Serialize)]
pub struct Limits {
    /// Index accuracy at a detent, arcsec.
    pub index_arcsec: f64,
    /// Settle time of a 90 deg index (command to idle), s.
    pub settle_s: f64,
    /// Lock engagement time, s.
    pub lock_s: f64,
    /// Zero return accuracy, arcsec.
    pub zero_arcsec: f64,
    /// Rate-mode accuracy, fraction of the commanded rate.
    pub rate_accuracy: f64,
    /// Rate-mode stability: std of 0.1 s rates, deg/s.
    pub rate_stability_dps: f64,
    /// Acknowledgement latency, s.
    pub ack_s: f64,
    /// Stop from the heartbeat watchdog within this after the timeout, s.
    pub heartbeat_stop_s: f64,
    /// Largest jump of the idle encoder angle between two frames, deg.
    pub encoder_jump_deg: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            index_arcsec: 10.0,
            settle_s: 5.0,
            lock_s: 1.0,
            zero_arcsec: 10.0,
            rate_accuracy: 0.001,
            rate_stability_dps: 0.05,
            ack_s: 0.05,
            heartbeat_stop_s: 2.5,
            encoder_jump_deg: 0.01,
        }
    }
}

/// One check.
#[derive(Debug, Clone, Serialize)]
pub struct VCheck {
    /// Name.
    pub name: String,
    /// Passed?
    pub pass: bool,
    /// Measured, in words with units.
    pub measured: String,
    /// Limit, in words with units.
    pub limit: String,
    /// Why it failed (empty when it passed).
    pub reason: String,
}

/// The suite's result.
#[derive(Debug, Clone, Serialize)]
pub struct Validation {
    /// Interface.
    pub interface: String,
    /// Axis tested.
    pub axis: u8,
    /// Checks in order.
    pub checks: Vec<VCheck>,
    /// All passed.
    pub pass: bool,
    /// Commands sent.
    pub commands: u64,
    /// Acks received.
    pub acks: u64,
    /// Status frames received.
    pub status_frames: u64,
}

/// Whose time the suite runs on.
#[derive(Debug, Clone)]
pub enum SuiteTime {
    /// A mechanism the bench does not run (real hardware, or another emulator): the wall
    /// clock's, times `speed` (1 for real hardware).
    Wall {
        /// Mechanism seconds per wall second.
        speed: f64,
    },
    /// The bench's emulator, in lockstep: the mechanism's time is what the suite asks for, so the
    /// result is the same at any pace and on a loaded host. `pace`: mechanism seconds per wall
    /// second at most (how fast an operator watching wants it), infinite for as fast as it goes.
    Lockstep {
        /// The emulator's side of the lockstep.
        ls: std::sync::Arc<emulators::adapters::transport::TtLockstep>,
        /// Mechanism seconds per wall second at most.
        pace: f64,
    },
}

/// The suite's steps in lockstep, mechanism seconds (a command is taken at the start of the
/// step after it was written, so this is also the resolution of the measured latencies).
const STEP_S: f64 = 0.001;

/// How long the suite waits for the emulator to answer a step (liveness only: no result
/// depends on it).
const ANSWER_WAIT: Duration = Duration::from_secs(30);

/// The CAN client.
struct Client {
    sock: CanSocket,
    iface: String,
    axis: u8,
    seq: u8,
    time: SuiteTime,
    /// When the suite started (wall).
    wall0: Instant,
    /// Mechanism time reached in lockstep, s.
    t: f64,
    /// Frames read in lockstep.
    frames_read: u64,
    /// Frames read in lockstep and not yet taken.
    pending: std::collections::VecDeque<socketcan::CanFrame>,
    last: Option<TtStatus>,
    /// Status frames with the mechanism time they arrived at.
    statuses: Vec<(f64, TtStatus)>,
    commands: u64,
    acks: u64,
    status_frames: u64,
    /// When the last command went out, mechanism s.
    last_sent: f64,
    /// Keep the heartbeat going while waiting.
    heartbeat: bool,
    /// Commands never acknowledged: (seq, code).
    unanswered: Vec<(u8, u8)>,
}

/// What came back for a command.
#[derive(Debug, Clone, Copy)]
struct Answer {
    ack: Option<TtAck>,
    latency_s: f64,
}

impl Client {
    fn open(iface: &str, axis: u8, time: SuiteTime) -> Result<Self> {
        let sock = CanSocket::open(iface).with_context(|| format!("CAN interface {iface}"))?;
        let _ = sock.set_filters(&[
            socketcan::CanFilter::new(0x101, 0x7FF),
            socketcan::CanFilter::new(0x102, 0x7FF),
        ]);
        Ok(Self {
            sock,
            iface: iface.into(),
            axis,
            seq: 0,
            time,
            wall0: Instant::now(),
            t: 0.0,
            frames_read: 0,
            pending: Default::default(),
            last: None,
            statuses: Vec::new(),
            commands: 0,
            acks: 0,
            status_frames: 0,
            last_sent: 0.0,
            heartbeat: true,
            unanswered: Vec::new(),
        })
    }

    /// The mechanism's time, s.
    fn now(&self) -> f64 {
        match self.time {
            SuiteTime::Wall { speed } => self.wall0.elapsed().as_secs_f64() * speed,
            SuiteTime::Lockstep { .. } => self.t,
        }
    }

    fn send_raw(&mut self, command: u8, arg: f64) -> Result<u8> {
        self.seq = self.seq.wrapping_add(1);
        let c = TtCmd {
            seq: self.seq,
            command,
            axis: self.axis,
            arg,
        };
        let raw = Message::TtCmd(c)
            .encode()
            .map_err(|e| anyhow::anyhow!("TT_CMD: {e}"))?;
        let f = wire::to_can_frame(&raw).map_err(|e| anyhow::anyhow!("TT_CMD: {e}"))?;
        self.sock
            .write_frame(&f)
            .with_context(|| format!("CAN interface {}: sending TT_CMD", self.iface))?;
        self.commands += 1;
        self.last_sent = self.now();
        Ok(self.seq)
    }

    /// Take one frame: the ack of `want_seq` when it is that.
    fn take(&mut self, f: &socketcan::CanFrame, want_seq: Option<u8>) -> Option<TtAck> {
        let raw = wire::from_can_frame(f).ok()?;
        match Message::decode(&raw) {
            Ok(Message::TtAck(a)) if a.axis == self.axis => {
                self.acks += 1;
                (Some(a.seq) == want_seq).then_some(a)
            }
            Ok(Message::TtStatus(s)) if s.axis == self.axis => {
                self.status_frames += 1;
                self.last = Some(s);
                let t = self.now();
                self.statuses.push((t, s));
                None
            }
            _ => None,
        }
    }

    /// In lockstep: the mechanism to `t1`, its frames up to then read into `pending`.
    fn step_to(&mut self, t1: f64) -> Result<()> {
        let SuiteTime::Lockstep { ls, pace } = &self.time else {
            return Ok(());
        };
        // pacing decides only how fast the run goes, never what it does
        if pace.is_finite() {
            let due = Duration::from_secs_f64(t1 / pace);
            if let Some(ahead) = due.checked_sub(self.wall0.elapsed()) {
                std::thread::sleep(ahead);
            }
        }
        ls.ask(t1, self.commands);
        let Some(written) = ls.wait_reached(ANSWER_WAIT) else {
            bail!(
                "the turntable emulator on {} did not reach {t1:.3} s within {} s of wall time",
                self.iface,
                ANSWER_WAIT.as_secs()
            );
        };
        let since = Instant::now();
        while self.frames_read < written {
            match self.sock.read_frame_timeout(Duration::from_millis(20)) {
                Ok(f) => {
                    self.frames_read += 1;
                    self.pending.push_back(f);
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
                    ) && since.elapsed() < ANSWER_WAIT => {}
                Err(e) => {
                    return Err(e).with_context(|| {
                        format!(
                            "CAN interface {}: reading the turntable's frame {} of {written}",
                            self.iface,
                            self.frames_read + 1
                        )
                    });
                }
            }
        }
        self.t = t1;
        Ok(())
    }

    /// Read frames for `dur` s of the mechanism's time; returns the ack of `want_seq` as soon as
    /// it arrives when one is wanted.
    fn pump(&mut self, dur: f64, want_seq: Option<u8>) -> Result<Option<TtAck>> {
        let end = self.now() + dur;
        loop {
            while let Some(f) = self.pending.pop_front() {
                if let Some(a) = self.take(&f, want_seq) {
                    return Ok(Some(a));
                }
            }
            if self.heartbeat && self.now() - self.last_sent > 0.2 && want_seq.is_none() {
                self.send_raw(TtCommand::Heartbeat as u8, 0.0)?;
            }
            let now = self.now();
            if now >= end - 1e-9 {
                return Ok(None);
            }
            if let SuiteTime::Wall { speed } = self.time {
                let left = Duration::from_secs_f64((end - now) / speed);
                match self
                    .sock
                    .read_frame_timeout(left.min(Duration::from_millis(20)))
                {
                    Ok(f) => self.pending.push_back(f),
                    Err(e)
                        if matches!(
                            e.kind(),
                            std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
                        ) => {}
                    Err(e) => {
                        return Err(e)
                            .with_context(|| format!("CAN interface {}: reading", self.iface));
                    }
                }
            } else {
                self.step_to((now + STEP_S).min(end))?;
            }
        }
    }

    /// Send a command and wait for its ack (up to 0.5 s of mechanism time).
    fn cmd(&mut self, c: TtCommand, arg: f64) -> Result<Answer> {
        self.cmd_raw(c as u8, arg)
    }

    fn cmd_raw(&mut self, code: u8, arg: f64) -> Result<Answer> {
        let t0 = self.now();
        let seq = self.send_raw(code, arg)?;
        let ack = self.pump(0.5, Some(seq))?;
        if ack.is_none() {
            self.unanswered.push((seq, code));
        }
        Ok(Answer {
            ack,
            latency_s: self.now() - t0,
        })
    }

    /// Wait until the state is `want` (true) or `within` mechanism seconds pass (false).
    fn wait_state(&mut self, want: TtState, within: f64) -> Result<(bool, f64)> {
        let t0 = self.now();
        while self.now() - t0 < within {
            self.pump(0.01, None)?;
            if self.last.is_some_and(|s| s.state == want) {
                return Ok((true, self.now() - t0));
            }
            if self.last.is_some_and(|s| s.state == TtState::Fault) && want != TtState::Fault {
                return Ok((false, self.now() - t0));
            }
        }
        Ok((false, within))
    }

    /// Mean encoder angle over `secs` of status frames (unwrapped around the first).
    fn mean_angle(&mut self, secs: f64) -> Result<Option<f64>> {
        let from = self.statuses.len();
        self.pump(secs, None)?;
        let s = &self.statuses[from..];
        if s.is_empty() {
            return Ok(None);
        }
        let a0 = s[0].1.angle_deg;
        let mean = s
            .iter()
            .map(|(_, x)| a0 + wrap180(x.angle_deg - a0))
            .sum::<f64>()
            / s.len() as f64;
        Ok(Some(mean.rem_euclid(360.0)))
    }

    fn faults_text(&self) -> String {
        match self.last {
            None => "no status frames".into(),
            Some(s) if s.faults.any() => format!("fault: {}", s.faults.names()),
            Some(s) => format!("state {:?}", s.state),
        }
    }
}

use crate::stats::wrap180;

fn check(
    out: &mut Vec<VCheck>,
    name: &str,
    pass: bool,
    measured: String,
    limit: String,
    reason: String,
) {
    out.push(VCheck {
        name: name.into(),
        pass,
        measured,
        limit,
        reason: if pass { String::new() } else { reason },
    });
}

fn expect(out: &mut Vec<VCheck>, name: &str, a: &Answer, want: TtResult) {
    let got = a.ack.map(|a| a.result);
    check(
        out,
        name,
        got == Some(want),
        got.map_or("no acknowledgement".into(), |r| format!("{r:?}")),
        format!("{want:?}"),
        match got {
            None => "the command was never acknowledged".into(),
            Some(r) => format!("answered {r:?} instead of {want:?}"),
        },
    );
}

/// Run the suite against the mechanism on `iface` (axis `axis`). `speed` is the emulator's speed
/// factor (1 for real hardware).
pub fn run_suite(iface: &str, axis: u8, time: SuiteTime, lim: &Limits) -> Result<Validation> {
    let mut c = Client::open(iface, axis, time)?;
    let mut out = Vec::new();
    first_status(&mut c, iface, axis)?;
    command_checks(&mut c, &mut out, lim)?;
    detent_checks(&mut c, &mut out, lim)?;
    // a lock away from a detent is refused
    let fresh = c.last.is_some_and(|s| s.state == TtState::Idle);
    if fresh {
        zero_and_rate_checks(&mut c, &mut out, lim)?;
        stop_checks(&mut c, &mut out, lim)?;
    } else {
        check(
            &mut out,
            "remaining checks",
            false,
            "not run".into(),
            "-".into(),
            format!(
                "the axis is not idle after the detent checks: {}",
                c.faults_text()
            ),
        );
    }
    acknowledged_check(&c, &mut out);
    let pass = out.iter().all(|x| x.pass);
    Ok(Validation {
        interface: iface.into(),
        axis,
        checks: out,
        pass,
        commands: c.commands,
        acks: c.acks,
        status_frames: c.status_frames,
    })
}

/// Wait for the mechanism's first status: it must be talking.
fn first_status(c: &mut Client, iface: &str, axis: u8) -> Result<()> {
    // the mechanism must be talking: its first status within 0.3 s of its time (on the wall
    // clock, 2 s: a mechanism we do not run may start late)
    let wait = match c.time {
        SuiteTime::Wall { speed } => (0.3f64).max(2.0 * speed),
        SuiteTime::Lockstep { .. } => 0.3,
    };
    let t0 = c.now();
    while c.last.is_none() && c.now() - t0 < wait {
        c.pump(0.02, None)?;
    }
    if c.last.is_none() {
        bail!(
            "no TT_STATUS frames from axis {axis} on {iface} within {wait:.1} s: is the mechanism powered and on the bus?"
        );
    }
    Ok(())
}

/// Commands refused or accepted from a known state: unknown, a move while disabled, enable
/// (and how soon it is acknowledged), an angle out of range.
fn command_checks(c: &mut Client, out: &mut Vec<VCheck>, lim: &Limits) -> Result<()> {
    // start from a known state
    c.cmd(TtCommand::Disable, 0.0)?;
    let a = c.cmd_raw(99, 0.0)?;
    expect(
        out,
        "rejects an unknown command",
        &a,
        TtResult::UnknownCommand,
    );
    let a = c.cmd(TtCommand::IndexAbs, 90.0)?;
    expect(
        out,
        "rejects a move while disabled",
        &a,
        TtResult::NotEnabled,
    );
    let a = c.cmd(TtCommand::Enable, 0.0)?;
    expect(out, "accepts enable", &a, TtResult::Accepted);
    check(
        out,
        "acknowledges promptly",
        a.ack.is_some() && a.latency_s <= lim.ack_s,
        format!("{:.1} ms", a.latency_s * 1e3),
        format!("<= {:.0} ms", lim.ack_s * 1e3),
        if a.ack.is_none() {
            "no acknowledgement".into()
        } else {
            format!("acknowledged after {:.1} ms", a.latency_s * 1e3)
        },
    );
    let a = c.cmd(TtCommand::IndexAbs, 400.0)?;
    expect(
        out,
        "rejects an out-of-range angle",
        &a,
        TtResult::OutOfRange,
    );
    Ok(())
}

/// The turntable indexed through its detents and locked at each: the worst figures met.
struct DetentTour {
    worst_err: f64,
    worst_settle: f64,
    worst_lock: f64,
    idx_fail: String,
    lock_fail: String,
    jump: f64,
}

/// Index through the four detents: accuracy, settle time, the lock at each, the encoder while
/// idle, a move refused while locked.
fn detent_checks(c: &mut Client, out: &mut Vec<VCheck>, lim: &Limits) -> Result<()> {
    let tour = tour_detents(c, out, lim)?;
    detent_verdicts(out, lim, &tour);
    Ok(())
}

/// Index to each detent, lock, try to move while locked, unlock.
fn tour_detents(c: &mut Client, out: &mut Vec<VCheck>, lim: &Limits) -> Result<DetentTour> {
    // unlock if a pin is in, then index through the detents
    c.cmd(TtCommand::Unlock, 0.0)?;
    c.wait_state(TtState::Idle, 2.0)?;
    let mut worst_err: f64 = 0.0;
    let mut worst_settle: f64 = 0.0;
    let mut worst_lock: f64 = 0.0;
    let mut idx_fail = String::new();
    let mut lock_fail = String::new();
    let mut jump: f64 = 0.0;
    for target in [90.0, 180.0, 270.0, 0.0] {
        let a = c.cmd(TtCommand::IndexAbs, target)?;
        if a.ack.map(|a| a.result) != Some(TtResult::Accepted) {
            idx_fail = format!(
                "index to {target} deg: {}",
                a.ack
                    .map_or("no acknowledgement".into(), |a| format!("{:?}", a.result))
            );
            break;
        }
        // moving, then idle
        c.wait_state(TtState::Moving, 1.0)?;
        let (ok, t) = c.wait_state(TtState::Idle, lim.settle_s * 2.0)?;
        worst_settle = worst_settle.max(t);
        if !ok {
            idx_fail = format!("index to {target} deg did not settle: {}", c.faults_text());
            break;
        }
        let from = c.statuses.len();
        let Some(m) = c.mean_angle(0.3)? else {
            idx_fail = "no status while idle".into();
            break;
        };
        for w in c.statuses[from..].windows(2) {
            jump = jump.max(wrap180(w[1].1.angle_deg - w[0].1.angle_deg).abs());
        }
        worst_err = worst_err.max(wrap180(m - target).abs() * 3600.0);
        let a = c.cmd(TtCommand::Lock, 0.0)?;
        let (ok, t) = if a.ack.map(|a| a.result) == Some(TtResult::Accepted) {
            c.wait_state(TtState::Locked, lim.lock_s * 3.0)?
        } else {
            (false, 0.0)
        };
        worst_lock = worst_lock.max(t);
        if !ok {
            lock_fail = format!(
                "at {target} deg: {}",
                a.ack.map_or("no acknowledgement".to_string(), |a| {
                    if a.result == TtResult::Accepted {
                        c.faults_text()
                    } else {
                        format!("{:?}", a.result)
                    }
                })
            );
            break;
        }
        let a = c.cmd(TtCommand::IndexAbs, target + 10.0)?;
        if target == 90.0 {
            expect(out, "rejects a move while locked", &a, TtResult::Locked);
        }
        c.cmd(TtCommand::Unlock, 0.0)?;
        c.wait_state(TtState::Idle, lim.lock_s * 3.0)?;
    }
    Ok(DetentTour {
        worst_err,
        worst_settle,
        worst_lock,
        idx_fail,
        lock_fail,
        jump,
    })
}

/// The detent checks from the tour's figures.
fn detent_verdicts(out: &mut Vec<VCheck>, lim: &Limits, tour: &DetentTour) {
    let DetentTour {
        worst_err,
        worst_settle,
        worst_lock,
        idx_fail,
        lock_fail,
        jump,
    } = tour;
    let (worst_err, worst_settle, worst_lock, jump) =
        (*worst_err, *worst_settle, *worst_lock, *jump);
    check(
        out,
        "index accuracy at the detents",
        idx_fail.is_empty() && worst_err <= lim.index_arcsec,
        format!("{worst_err:.2} arcsec worst"),
        format!("<= {} arcsec", lim.index_arcsec),
        if idx_fail.is_empty() {
            format!("off by {worst_err:.2} arcsec")
        } else {
            idx_fail.clone()
        },
    );
    check(
        out,
        "settle time of a 90 deg index",
        idx_fail.is_empty() && worst_settle <= lim.settle_s,
        format!("{worst_settle:.2} s worst"),
        format!("<= {} s", lim.settle_s),
        if idx_fail.is_empty() {
            format!("took {worst_settle:.2} s")
        } else {
            idx_fail.clone()
        },
    );
    check(
        out,
        "lock engages at each detent",
        lock_fail.is_empty() && idx_fail.is_empty() && worst_lock <= lim.lock_s,
        format!("{worst_lock:.2} s worst"),
        format!("<= {} s", lim.lock_s),
        if !lock_fail.is_empty() {
            format!("lock failed {lock_fail}")
        } else if !idx_fail.is_empty() {
            "not reached: indexing failed".into()
        } else {
            format!("took {worst_lock:.2} s")
        },
    );
    check(
        out,
        "encoder steady while idle",
        jump <= lim.encoder_jump_deg,
        format!("{jump:.4} deg largest step"),
        format!("<= {} deg", lim.encoder_jump_deg),
        format!("the idle angle jumped {jump:.4} deg between two frames (encoder glitch)"),
    );
}

/// A lock refused away from a detent, the return to zero, rate mode's accuracy and stability.
fn zero_and_rate_checks(c: &mut Client, out: &mut Vec<VCheck>, lim: &Limits) -> Result<()> {
    c.cmd(TtCommand::IndexAbs, 45.0)?;
    c.wait_state(TtState::Moving, 1.0)?;
    c.wait_state(TtState::Idle, lim.settle_s * 2.0)?;
    let a = c.cmd(TtCommand::Lock, 0.0)?;
    expect(
        out,
        "refuses to lock away from a detent",
        &a,
        TtResult::NotAtDetent,
    );
    // zero return
    c.cmd(TtCommand::Home, 0.0)?;
    c.wait_state(TtState::Moving, 1.0)?;
    let (ok, _) = c.wait_state(TtState::Idle, lim.settle_s * 2.0)?;
    let m = c.mean_angle(0.3)?.unwrap_or(f64::NAN);
    let e = wrap180(m).abs() * 3600.0;
    check(
        out,
        "returns to zero",
        ok && e <= lim.zero_arcsec,
        format!("{e:.2} arcsec"),
        format!("<= {} arcsec", lim.zero_arcsec),
        if ok {
            format!("off by {e:.2} arcsec")
        } else {
            format!("did not settle: {}", c.faults_text())
        },
    );
    // rate mode
    let rate = 10.0;
    let a = c.cmd(TtCommand::Rate, rate)?;
    c.pump(1.0, None)?; // ramp
    let from = c.statuses.len();
    c.pump(3.0, None)?;
    let s = &c.statuses[from..];
    let (mut acc, mut rates) = (0.0, Vec::new());
    for w in s.windows(2) {
        let d = wrap180(w[1].1.angle_deg - w[0].1.angle_deg);
        acc += d;
        let dt = w[1].0 - w[0].0;
        if dt > 0.0 {
            rates.push(d / dt);
        }
    }
    let span = s.last().zip(s.first()).map_or(0.0, |(l, f)| l.0 - f.0);
    // mean rate from the reported rate (time stamps of frames are wall arrival times)
    let reported: Vec<f64> = s.iter().map(|x| x.1.rate_dps).collect();
    let mean = reported.iter().sum::<f64>() / reported.len().max(1) as f64;
    let sd = (reported.iter().map(|r| (r - mean).powi(2)).sum::<f64>()
        / reported.len().max(1) as f64)
        .sqrt();
    let from_angle = if span > 0.0 { acc / span } else { f64::NAN };
    let err = (mean - rate).abs() / rate;
    check(
        out,
        "rate-mode accuracy",
        a.ack.map(|a| a.result) == Some(TtResult::Accepted) && err <= lim.rate_accuracy,
        format!(
            "{mean:.5} deg/s ({:.3} % off; {from_angle:.3} deg/s from the angle)",
            err * 100.0
        ),
        format!("within {:.2} % of {rate} deg/s", lim.rate_accuracy * 100.0),
        format!("mean rate {mean:.5} deg/s: {}", c.faults_text()),
    );
    check(
        out,
        "rate-mode stability",
        sd <= lim.rate_stability_dps && !reported.is_empty(),
        format!("{sd:.5} deg/s std"),
        format!("<= {} deg/s", lim.rate_stability_dps),
        format!("rate scatter {sd:.5} deg/s"),
    );
    Ok(())
}

/// The emergency stop, moves refused while faulted, the heartbeat watchdog.
fn stop_checks(c: &mut Client, out: &mut Vec<VCheck>, lim: &Limits) -> Result<()> {
    // emergency stop
    let a = c.cmd(TtCommand::EStop, 0.0)?;
    c.pump(0.1, None)?;
    let st = c.last;
    check(
        out,
        "emergency stop",
        a.ack.is_some()
            && st.is_some_and(|s| {
                s.rate_dps.abs() < 1e-6 && s.faults.estop && s.state == TtState::Fault
            }),
        st.map_or("no status".into(), |s| {
            format!(
                "rate {:.4} deg/s, state {:?}, estop {}",
                s.rate_dps, s.state, s.faults.estop
            )
        }),
        "rate 0 at once, fault state, e-stop bit".into(),
        "the axis did not stop and latch the e-stop".into(),
    );
    let a = c.cmd(TtCommand::Home, 0.0)?;
    expect(out, "rejects moves while faulted", &a, TtResult::Faulted);
    c.cmd(TtCommand::Disable, 0.0)?;
    // heartbeat watchdog: enable, rate, then silence
    c.cmd(TtCommand::Enable, 0.0)?;
    c.cmd(TtCommand::Rate, 5.0)?;
    c.heartbeat = false;
    let t0 = c.now();
    let (stopped, _) = c.wait_state(TtState::Fault, lim.heartbeat_stop_s * 2.0)?;
    let t = c.now() - t0;
    c.pump(1.0, None)?;
    let st = c.last;
    c.heartbeat = true;
    check(
        out,
        "heartbeat timeout stops the axis",
        stopped
            && t <= lim.heartbeat_stop_s
            && st.is_some_and(|s| s.faults.heartbeat && s.rate_dps.abs() < 1e-6),
        format!(
            "fault after {t:.2} s of silence, then rate {:.4} deg/s",
            st.map_or(f64::NAN, |s| s.rate_dps)
        ),
        format!("<= {} s, then at rest", lim.heartbeat_stop_s),
        if stopped {
            "stopped too late or not at rest".into()
        } else {
            "no stop without heartbeat".into()
        },
    );
    c.cmd(TtCommand::Disable, 0.0)?;
    Ok(())
}

/// Every command the suite sent was acknowledged.
fn acknowledged_check(c: &Client, out: &mut Vec<VCheck>) {
    let lost: Vec<String> = c
        .unanswered
        .iter()
        .map(|(seq, code)| {
            let name = TtCommand::from_raw(i64::from(*code))
                .map_or_else(|| format!("code {code}"), |x| format!("{x:?}"));
            format!("{name} (seq {seq})")
        })
        .collect();
    check(
        out,
        "every command acknowledged",
        lost.is_empty(),
        format!("{} of {} unanswered", lost.len(), c.commands),
        "none unanswered within 0.5 s".into(),
        format!("no acknowledgement of {}", lost.join(", ")),
    );
}

/// The validation as a JUnit suite (`hil validate turntable --junit`): a case per check,
/// failing with what was measured against its limit and why.
pub fn junit(v: &Validation, time_s: f64) -> crate::junit::Suite {
    let classname = format!("hil validate turntable (axis {})", v.axis);
    let cases = v
        .checks
        .iter()
        .map(|c| {
            crate::junit::Case::judged(
                &classname,
                &c.name,
                0.0,
                c.pass,
                format!("measured {}; limit {}", c.measured, c.limit),
                format!(
                    "measured: {}\nlimit: {}\nwhy: {}",
                    c.measured, c.limit, c.reason
                ),
            )
        })
        .collect();
    crate::junit::Suite::new(
        &format!("turntable validation on {}", v.interface),
        time_s,
        cases,
    )
}

/// The table printed at the end.
pub fn table(v: &Validation) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let line = "=".repeat(100);
    let _ = writeln!(s, "{line}");
    let _ = writeln!(
        s,
        " TURNTABLE VALIDATION  axis {} on {}  ({} commands, {} acks, {} status frames)",
        v.axis, v.interface, v.commands, v.acks, v.status_frames
    );
    let _ = writeln!(s, "{line}");
    for c in &v.checks {
        let _ = writeln!(
            s,
            " [{}] {:<36} {:<44} limit {}",
            if c.pass { "PASS" } else { "FAIL" },
            c.name,
            c.measured,
            c.limit
        );
        if !c.pass {
            let _ = writeln!(s, "        reason: {}", c.reason);
        }
    }
    let _ = writeln!(s, "{line}");
    let _ = writeln!(s, " RESULT: {}", if v.pass { "PASS" } else { "FAIL" });
    s
}

/// The validation as Markdown (`validation.md`, and the HTML report made from it).
pub fn markdown(v: &Validation) -> String {
    let mut t = crate::table::Table::left(&["check", "result", "measured", "limit", "reason"]);
    for c in &v.checks {
        t.row([
            c.name.as_str(),
            if c.pass { "PASS" } else { "FAIL" },
            &c.measured,
            &c.limit,
            if c.pass { "" } else { &c.reason },
        ]);
    }
    format!(
        "# Turntable validation\n\nAxis {} on `{}`: {} commands, {} acknowledgements, {} status frames. **Result: {}**\n\n{}",
        v.axis,
        v.interface,
        v.commands,
        v.acks,
        v.status_frames,
        if v.pass { "PASS" } else { "FAIL" },
        t.finish()
    )
}
