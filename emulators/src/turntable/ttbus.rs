//! The turntable on the bus, without I/O: commands in (when they completed on the bus, which
//! [`crate::step`] decides), its acknowledgements and status frames out after each IMU sample, and its truth kept for the
//! bench's recording. The scheduler (`bus`) and the in-process runs step it alike (`step`).

use crate::turntable::Turntable;
use serde::{Deserialize, Serialize};
use wire::{Message, TtAck, TtCmd};

/// What the turntable adapter did.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
pub struct TurntableTxStats {
    /// TT_CMD frames received.
    pub commands: u64,
    /// TT_ACK frames sent.
    pub acks: u64,
    /// TT_STATUS frames sent.
    pub status_frames: u64,
    /// Frames received that were not a valid TT_CMD.
    pub bad_frames: u64,
    /// Commands lost on purpose (fault injection: no ack).
    pub lost_commands: u64,
    /// Status frames withheld on purpose (fault injection: heartbeat loss).
    #[serde(default)]
    pub silenced_status: u64,
}

/// The turntable's truth at one instant: what the mechanism really did (never on the wire), for
/// the bench's recording.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TtTruth {
    /// Simulated time, s.
    pub t_s: f64,
    /// True angle of each axis, deg (unwrapped).
    pub angle_deg: Vec<f64>,
    /// True rate of each axis, deg/s.
    pub rate_dps: Vec<f64>,
    /// State of each axis (its controller's).
    pub state: Vec<String>,
}

/// Rate at which the turntable's truth is kept, Hz.
pub const TT_TRUTH_HZ: f64 = 10.0;

/// The turntable on the bus, without I/O: commands in, frames out after each IMU sample.
pub struct TtBus {
    tt: Turntable,
    status_every: u64,
    truth_every: u64,
    /// The mechanism's truth at [`TT_TRUTH_HZ`].
    pub truth: Vec<TtTruth>,
    /// Every command the controller received, and when (simulated s).
    pub received: Vec<(f64, TtCmd)>,
    acks: Vec<TtAck>,
    /// What went out.
    pub stats: TurntableTxStats,
}

impl TtBus {
    /// The mechanism `tt` beside an IMU at `imu_rate_hz`.
    pub fn new(tt: Turntable, imu_rate_hz: f64) -> Self {
        Self {
            status_every: (imu_rate_hz / tt.params().status_hz).round().max(1.0) as u64,
            truth_every: (imu_rate_hz / TT_TRUTH_HZ).round().max(1.0) as u64,
            truth: Vec::new(),
            received: Vec::new(),
            tt,
            acks: Vec::new(),
            stats: TurntableTxStats::default(),
        }
    }

    /// A command reached the mechanism's controller at `t` (simulated s: when it completed on
    /// the bus); it acts on it at once, its acknowledgement (if it answers) to `out`. Calls come
    /// in time order, between the [`TtBus::after_sample`] calls of the samples around `t`.
    pub fn receive(&mut self, t: f64, cmd: TtCmd, out: &mut Vec<Message>) {
        self.stats.commands += 1;
        self.received.push((t, cmd));
        match self.tt.command(t, cmd) {
            Some(a) => out.push(Message::TtAck(a)),
            None if self.tt.params().faults.lost_command_seqs.contains(&cmd.seq) => {
                self.stats.lost_commands += 1
            }
            None => {}
        }
    }

    /// The frames due right after IMU sample `k` (which ends at `t`), in bus order.
    pub fn after_sample(&mut self, k: u64, t: f64, out: &mut Vec<Message>) {
        self.acks.clear();
        self.tt.advance(t, &mut self.acks);
        if k.is_multiple_of(self.truth_every) {
            let n = self.tt.axis_count();
            let (angle_deg, rate_dps) = (0..n).map(|a| self.tt.true_angle(a, t)).unzip();
            self.truth.push(TtTruth {
                t_s: t,
                angle_deg,
                rate_dps,
                state: (0..n).map(|a| format!("{:?}", self.tt.state(a))).collect(),
            });
        }
        out.extend(self.acks.drain(..).map(Message::TtAck));
        if (k + 1).is_multiple_of(self.status_every) {
            let status = self.tt.status(t);
            let silent = self.tt.params().faults.status_silent_s.iter();
            if silent.clone().any(|w| t >= w[0] && t < w[1]) {
                // the mechanism's controller hangs: no heartbeat
                self.stats.silenced_status += status.len() as u64;
            } else {
                out.extend(status.into_iter().map(Message::TtStatus));
            }
        }
    }

    /// Count frames that went out.
    pub(crate) fn sent(&mut self, m: &Message) {
        match m {
            Message::TtAck(_) => self.stats.acks += 1,
            _ => self.stats.status_frames += 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::turntable::TurntableParams;
    use wire::{TtCommand, TtResult};

    fn cmd(seq: u8, command: TtCommand) -> TtCmd {
        TtCmd {
            seq,
            command: command as u8,
            axis: 0,
            arg: 0.0,
        }
    }

    #[test]
    fn a_command_is_answered_when_it_reaches_the_controller() {
        let mut b = TtBus::new(Turntable::new(TurntableParams::default()), 2000.0);
        let mut out = Vec::new();
        for k in 0..640 {
            b.after_sample(k, (k + 1) as f64 / 2000.0, &mut out);
        }
        assert!(!out.iter().any(|m| matches!(m, Message::TtAck(_))));
        out.clear();
        // on the bus until 0.3202 s, between the ends of samples 639 and 640
        b.receive(0.3202, cmd(1, TtCommand::Enable), &mut out);
        match out.as_slice() {
            [Message::TtAck(a)] => assert_eq!((a.seq, a.result), (1, TtResult::Accepted)),
            other => panic!("{other:?}"),
        }
        assert_eq!(b.stats.commands, 1);
        out.clear();
        b.after_sample(640, 641.0 / 2000.0, &mut out);
        // the status frames at 100 Hz (every 20th sample)
        assert!(out.iter().all(|m| matches!(m, Message::TtStatus(_))));
        assert_eq!(out.len(), usize::from((641 % 20) == 0));
    }

    #[test]
    fn status_frames_come_at_the_mechanism_rate() {
        let mut b = TtBus::new(Turntable::new(TurntableParams::default()), 2000.0);
        let mut out = Vec::new();
        for k in 0..2000 {
            b.after_sample(k, (k + 1) as f64 / 2000.0, &mut out);
        }
        assert_eq!(out.len(), 100);
    }

    /// The mechanism's truth is kept at 10 Hz of IMU time, each axis's angle, rate and state,
    /// following what the commands made it do.
    #[test]
    fn the_turntables_truth_is_kept_at_ten_hertz() {
        let mut b = TtBus::new(Turntable::new(TurntableParams::default()), 2000.0);
        let mut out = Vec::new();
        b.receive(0.0, cmd(1, TtCommand::Enable), &mut out);
        out.clear();
        for k in 0..2000 {
            b.after_sample(k, (k + 1) as f64 / 2000.0, &mut out);
        }
        assert_eq!(b.truth.len(), 10);
        let first = &b.truth[0];
        assert_eq!((first.t_s, first.angle_deg.len()), (1.0 / 2000.0, 1));
        assert!(
            b.truth
                .windows(2)
                .all(|w| (w[1].t_s - w[0].t_s - 0.1).abs() < 1e-9)
        );
        assert!(
            b.truth
                .iter()
                .all(|t| t.state.len() == 1 && t.rate_dps[0] == 0.0)
        );
        assert_ne!(b.truth[9].state[0], "Disabled", "{:?}", b.truth[9]);
    }
}
