//! nav's side of the link to the turntable (the indexing mechanism), shared by every procedure
//! that commands it (north-finding, self-calibration): one command in flight at a time, each
//! answered by TT_ACK with its sequence number; a command without an answer within the ack
//! timeout is sent again under a new number, up to the retry count; a heartbeat when nothing
//! else went out for the heartbeat period (the mechanism's watchdog stops it otherwise); the
//! status frames' silence beyond the status timeout means the mechanism is lost.
//!
//! The link only carries commands: what they mean, and what a status says about the procedure,
//! is the procedure's. It stamps each status frame with the IMU time it was given.

use std::collections::VecDeque;
use wire::{TtAck, TtCmd, TtCommand, TtResult, TtState, TtStatus};

/// The link's timing (from the procedure's settings).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkTiming {
    /// Heartbeat period when no other command goes out, s.
    pub heartbeat_s: f64,
    /// Resend a command without an acknowledgement after this long, s.
    pub ack_timeout_s: f64,
    /// Give up after this many resends.
    pub ack_retries: u32,
    /// The mechanism is lost after this long without a status frame, s.
    pub status_timeout_s: f64,
}

/// Why the link failed: what the procedure aborts with (see [`LinkFailure::describe`]).
#[derive(Debug, Clone, PartialEq)]
pub enum LinkFailure {
    /// No status frame for `silent_s`.
    StatusLost {
        /// Time since the last status frame, s.
        silent_s: f64,
    },
    /// A command went unanswered through every retry.
    NoAck {
        /// The command.
        command: u8,
        /// The last sequence number it was sent under.
        seq: u8,
        /// How often it was sent.
        tries: u32,
    },
    /// The mechanism rejected a command.
    Rejected {
        /// The command.
        command: u8,
        /// Why.
        result: TtResult,
    },
}

/// A command code's name (`Enable`, `Rate`, ...), or its number when unknown.
pub fn command_name(code: u8) -> String {
    TtCommand::from_raw(i64::from(code))
        .map_or_else(|| format!("command {code}"), |c| format!("{c:?}"))
}

impl LinkFailure {
    /// The reason, saying where the procedure was (`at`, e.g. "position 2 of 4 (90 deg)").
    pub fn describe(&self, at: &str) -> String {
        match self {
            Self::StatusLost { silent_s } => format!(
                "no turntable status for {silent_s:.2} s at {at}: the mechanism's heartbeat is lost"
            ),
            Self::NoAck {
                command,
                seq,
                tries,
            } => {
                let name = TtCommand::from_raw(i64::from(*command))
                    .map_or_else(|| "command".to_string(), |c| format!("{c:?}"));
                format!("no acknowledgement of {name} (seq {seq}) at {at} after {tries} tries")
            }
            Self::Rejected { command, result } => format!(
                "turntable rejected {} at {at}: {result:?}",
                command_name(*command)
            ),
        }
    }
}

/// What [`TtLink::poll`] says.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkPoll {
    /// Send this (a command sent again for want of an answer).
    Send(TtCmd),
    /// A command is in flight: nothing to send.
    Waiting,
    /// Nothing in flight: the procedure may queue its next commands, then call
    /// [`TtLink::next`].
    Idle,
    /// The link failed.
    Failed(LinkFailure),
}

/// What waits for an acknowledgement.
#[derive(Debug, Clone, Copy)]
struct Outstanding {
    cmd: TtCmd,
    sent_at: f64,
    tries: u32,
}

/// The link to the axes a procedure commands.
#[derive(Debug, Clone)]
pub struct TtLink {
    timing: LinkTiming,
    axes: Vec<u8>,
    seq: u8,
    outstanding: Option<Outstanding>,
    queue: VecDeque<(TtCommand, u8, f64)>,
    last_sent: f64,
    status: Vec<Option<TtStatus>>,
    last_status_t: Option<f64>,
    retries: u64,
    stale_acks: u64,
}

impl TtLink {
    /// A link to `axes` (the first one carries the heartbeat).
    pub fn new(timing: LinkTiming, axes: &[u8]) -> Self {
        let n = axes.iter().map(|a| usize::from(*a) + 1).max().unwrap_or(1);
        Self {
            timing,
            axes: axes.to_vec(),
            seq: 0,
            outstanding: None,
            queue: VecDeque::new(),
            last_sent: f64::NEG_INFINITY,
            status: vec![None; n],
            last_status_t: None,
            retries: 0,
            stale_acks: 0,
        }
    }

    /// Is `axis` one of the link's?
    pub fn has_axis(&self, axis: u8) -> bool {
        self.axes.contains(&axis)
    }

    /// A status frame arrived at IMU time `t`; false (and ignored) when its axis is not the
    /// link's.
    pub fn on_status(&mut self, t: f64, st: &TtStatus) -> bool {
        if !self.has_axis(st.axis) {
            return false;
        }
        self.status[usize::from(st.axis)] = Some(*st);
        self.last_status_t = Some(t);
        true
    }

    /// The latest status of `axis`.
    pub fn status(&self, axis: u8) -> Option<&TtStatus> {
        self.status.get(usize::from(axis)).and_then(Option::as_ref)
    }

    /// The latest state of `axis`.
    pub fn state(&self, axis: u8) -> Option<TtState> {
        self.status(axis).map(|s| s.state)
    }

    /// An acknowledgement arrived: an error when it rejects the command in flight. One of
    /// another axis is ignored; one that matches nothing in flight is counted as stale.
    pub fn on_ack(&mut self, a: &TtAck) -> Result<(), LinkFailure> {
        if !self.has_axis(a.axis) {
            return Ok(());
        }
        let Some(o) = self
            .outstanding
            .filter(|o| o.cmd.seq == a.seq && o.cmd.axis == a.axis)
        else {
            // an acknowledgement of a command already given up on (it came late) or never sent
            self.stale_acks += 1;
            return Ok(());
        };
        self.outstanding = None;
        if a.result != TtResult::Accepted {
            return Err(LinkFailure::Rejected {
                command: o.cmd.command,
                result: a.result,
            });
        }
        Ok(())
    }

    /// Queue a command.
    pub fn push(&mut self, c: TtCommand, axis: u8, arg: f64) {
        self.queue.push_back((c, axis, arg));
    }

    /// Commands queued and not sent yet?
    pub fn queued(&self) -> bool {
        !self.queue.is_empty()
    }

    /// Drop what is queued and in flight (the procedure ended).
    pub fn clear(&mut self) {
        self.outstanding = None;
        self.queue.clear();
    }

    /// At IMU time `t`: the status timeout, then the command in flight (sent again, or given
    /// up on).
    pub fn poll(&mut self, t: f64) -> LinkPoll {
        if let Some(ls) = self.last_status_t
            && t - ls > self.timing.status_timeout_s
        {
            return LinkPoll::Failed(LinkFailure::StatusLost { silent_s: t - ls });
        }
        let Some(o) = self.outstanding else {
            return LinkPoll::Idle;
        };
        if t - o.sent_at <= self.timing.ack_timeout_s {
            return LinkPoll::Waiting;
        }
        if o.tries >= self.timing.ack_retries {
            return LinkPoll::Failed(LinkFailure::NoAck {
                command: o.cmd.command,
                seq: o.cmd.seq,
                tries: o.tries + 1,
            });
        }
        // resend under a new sequence number
        self.retries += 1;
        self.seq = self.seq.wrapping_add(1);
        let cmd = TtCmd {
            seq: self.seq,
            ..o.cmd
        };
        self.outstanding = Some(Outstanding {
            cmd,
            sent_at: t,
            tries: o.tries + 1,
        });
        self.last_sent = t;
        LinkPoll::Send(cmd)
    }

    /// With nothing in flight: the next queued command, or a heartbeat when due.
    pub fn next(&mut self, t: f64) -> Option<TtCmd> {
        if self.outstanding.is_some() {
            return None;
        }
        if let Some((c, axis, arg)) = self.queue.pop_front() {
            return Some(self.send(t, c, axis, arg));
        }
        if t - self.last_sent >= self.timing.heartbeat_s {
            let axis = self.axes.first().copied().unwrap_or(0);
            return Some(self.send(t, TtCommand::Heartbeat, axis, 0.0));
        }
        None
    }

    fn send(&mut self, t: f64, c: TtCommand, axis: u8, arg: f64) -> TtCmd {
        self.seq = self.seq.wrapping_add(1);
        let cmd = TtCmd {
            seq: self.seq,
            command: c as u8,
            axis,
            arg,
        };
        self.outstanding = Some(Outstanding {
            cmd,
            sent_at: t,
            tries: 0,
        });
        self.last_sent = t;
        cmd
    }

    /// Commands sent again for want of an acknowledgement, and acknowledgements that came too
    /// late (or matched nothing).
    pub fn ack_counters(&self) -> (u64, u64) {
        (self.retries, self.stale_acks)
    }

    /// IMU time of the last status frame.
    pub fn last_status_time(&self) -> Option<f64> {
        self.last_status_t
    }
}

/// A procedure's setting out of its range: `<table>.<setting>: <requirement>`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{table}.{setting}: {requirement}")]
pub struct SettingError {
    /// The config table (`north_finding`, `self_calibration`, ...).
    pub table: &'static str,
    /// The setting (as in the table).
    pub setting: &'static str,
    /// What it must be.
    pub requirement: &'static str,
}

impl SettingError {
    /// The setting of `table` must be what `requirement` says.
    pub fn new(table: &'static str, setting: &'static str, requirement: &'static str) -> Self {
        Self {
            table,
            setting,
            requirement,
        }
    }
}

/// What every procedure on the link checks: a latitude within 89 deg of the equator, and
/// positive heartbeat, acknowledgement, move and status timeouts.
pub(crate) fn check_site_and_link(
    table: &'static str,
    latitude_deg: f64,
    timing: &LinkTiming,
    move_timeout_s: f64,
) -> Result<(), SettingError> {
    let pos = |x: f64| x.is_finite() && x > 0.0;
    if !(-89.0..=89.0).contains(&latitude_deg) {
        return Err(SettingError::new(
            table,
            "latitude_deg",
            "must be within 89 deg of the equator",
        ));
    }
    if !(pos(timing.heartbeat_s)
        && pos(timing.ack_timeout_s)
        && pos(move_timeout_s)
        && pos(timing.status_timeout_s))
    {
        return Err(SettingError::new(
            table,
            "heartbeat_s/ack_timeout_s/move_timeout_s/status_timeout_s",
            "timeouts must be positive",
        ));
    }
    Ok(())
}

/// One axis's encoder angles on the IMU clock (status frames stamped with the IMU time they
/// arrived at), unwrapped, with what a procedure keeps of its rotation.
#[derive(Debug, Clone, Default)]
pub(crate) struct AxisTrack {
    /// (IMU time, unwrapped angle deg) of recent status frames.
    pub(crate) hist: VecDeque<(f64, f64)>,
    /// Direction of the current turn (+1, -1), 0 before it starts.
    pub(crate) dir: f64,
    /// Angle where the current turn started, deg (unwrapped).
    pub(crate) turn_from: f64,
    pub(crate) reversals: u32,
    /// Mean of the encoder at rest before the rotation: (sum, count).
    pub(crate) rest: (f64, u32),
    /// The angle at the end of the last sample used (deg): the next sample starts there, so
    /// that the encoder's increments telescope and its noise enters at the ends only.
    pub(crate) chain: Option<(f64, f64)>,
}

impl AxisTrack {
    pub(crate) fn push(&mut self, t: f64, angle_deg: f64) {
        let a = match self.hist.back() {
            Some(&(_, prev)) => {
                let d = (angle_deg - prev).rem_euclid(360.0);
                prev + if d > 180.0 { d - 360.0 } else { d }
            }
            None => angle_deg,
        };
        // two frames stamped alike (they came before the next sample did): the later reading
        // stands for that time, and no interval is of zero length
        if let Some(last) = self.hist.back_mut()
            && last.0 == t
        {
            last.1 = a;
            return;
        }
        self.hist.push_back((t, a));
        while self.hist.len() > 2 && self.hist.back().map_or(0.0, |b| b.0) - self.hist[1].0 > 2.0 {
            self.hist.pop_front();
        }
    }

    /// The angle at the start of a sample beginning at `t0`: where the previous one ended when
    /// it ended there, else interpolated.
    pub(crate) fn start(&self, t0: f64, gap: f64) -> Option<f64> {
        match self.chain {
            Some((t, a)) if (t - t0).abs() < 1e-9 => Some(a),
            _ => self.at(t0, gap),
        }
    }

    pub(crate) fn latest(&self) -> Option<(f64, f64)> {
        self.hist.back().copied()
    }

    /// The angle at `t` (deg), interpolated between the status frames around it, when both are
    /// within `gap` s.
    pub(crate) fn at(&self, t: f64, gap: f64) -> Option<f64> {
        // times computed two ways (a sample's end plus a window, a frame's stamp) differ in
        // their last bits: within a nanosecond is the same time
        const SAME: f64 = 1e-9;
        // the first frame at or after `t`, looked for from the newest: the times asked are
        // recent, the history two seconds long
        let i = self
            .hist
            .iter()
            .rposition(|&(ti, _)| ti < t - SAME)
            .map_or(0, |j| j + 1);
        let (t1, a1) = *self.hist.get(i)?;
        if (t1 - t).abs() <= SAME {
            return Some(a1);
        }
        let (t0, a0) = *self.hist.get(i.checked_sub(1)?)?;
        if t - t0 > gap || t1 - t > gap || t1 <= t0 {
            return None;
        }
        Some(a0 + (a1 - a0) * (t - t0) / (t1 - t0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wire::TtFaults;

    fn timing() -> LinkTiming {
        LinkTiming {
            heartbeat_s: 0.1,
            ack_timeout_s: 0.2,
            ack_retries: 2,
            status_timeout_s: 0.5,
        }
    }

    fn status(axis: u8) -> TtStatus {
        TtStatus {
            angle_deg: 0.0,
            rate_dps: 0.0,
            state: TtState::Idle,
            axis,
            faults: TtFaults::default(),
            ack_seq: 0,
            counter: 0,
        }
    }

    fn ack(c: &TtCmd, result: TtResult) -> TtAck {
        TtAck {
            seq: c.seq,
            command: c.command,
            axis: c.axis,
            result,
        }
    }

    #[test]
    fn commands_go_one_at_a_time_and_heartbeats_fill_the_silence() {
        let mut l = TtLink::new(timing(), &[0, 1]);
        l.push(TtCommand::Enable, 0, 0.0);
        l.push(TtCommand::Enable, 1, 0.0);
        assert_eq!(l.poll(0.0), LinkPoll::Idle);
        let a = l.next(0.0).expect("first");
        assert_eq!((a.command, a.axis), (TtCommand::Enable as u8, 0));
        assert_eq!(l.poll(0.05), LinkPoll::Waiting);
        assert_eq!(l.next(0.05), None, "one in flight at a time");
        // an answer for the other axis with the same number is not this one's
        l.on_ack(&TtAck {
            axis: 1,
            ..ack(&a, TtResult::Accepted)
        })
        .expect("ignored");
        assert_eq!(l.ack_counters(), (0, 1));
        l.on_ack(&ack(&a, TtResult::Accepted)).expect("accepted");
        let b = l.next(0.06).expect("second");
        assert_eq!((b.axis, b.seq), (1, a.seq + 1));
        l.on_ack(&ack(&b, TtResult::Accepted)).expect("accepted");
        assert_eq!(l.next(0.1), None, "heartbeat not due");
        let hb = l.next(0.17).expect("heartbeat");
        assert_eq!((hb.command, hb.axis), (TtCommand::Heartbeat as u8, 0));
    }

    #[test]
    fn an_unanswered_command_is_resent_then_given_up_and_a_rejection_is_an_error() {
        let mut l = TtLink::new(timing(), &[2]);
        l.push(TtCommand::Rate, 2, 5.0);
        let c = l.next(0.0).expect("sent");
        let LinkPoll::Send(r1) = l.poll(0.25) else {
            panic!("resent")
        };
        assert_eq!((r1.seq, r1.arg), (c.seq + 1, 5.0));
        let LinkPoll::Send(_) = l.poll(0.5) else {
            panic!("resent again")
        };
        let LinkPoll::Failed(f) = l.poll(0.75) else {
            panic!("given up")
        };
        assert_eq!(
            f.describe("rotation"),
            format!(
                "no acknowledgement of Rate (seq {}) at rotation after 3 tries",
                c.seq + 2
            )
        );
        let mut l = TtLink::new(timing(), &[0]);
        l.push(TtCommand::Unlock, 0, 0.0);
        let c = l.next(0.0).expect("sent");
        let e = l.on_ack(&ack(&c, TtResult::Faulted)).expect_err("rejected");
        assert_eq!(
            e.describe("here"),
            "turntable rejected Unlock at here: Faulted"
        );
    }

    #[test]
    fn silence_of_the_status_frames_fails_the_link() {
        let mut l = TtLink::new(timing(), &[0]);
        assert_eq!(
            l.poll(10.0),
            LinkPoll::Idle,
            "no status yet: nothing to time"
        );
        assert!(!l.on_status(1.0, &status(1)), "not the link's axis");
        assert!(l.on_status(1.0, &status(0)));
        assert_eq!(l.state(0), Some(TtState::Idle));
        assert_eq!(l.poll(1.4), LinkPoll::Idle);
        assert!(matches!(
            l.poll(1.6),
            LinkPoll::Failed(LinkFailure::StatusLost { .. })
        ));
    }
}
