//! A lab's contract on the bus model: its frames (29-bit identifiers, CAN FD payloads whose
//! data phase runs at its own bit rate) and the periodic traffic its mapping describes (the
//! IMU's blocks and status, the table's reports, the box's commands and solution, each queued
//! with its jitter), with the table answering each command at its controller's next tick by a
//! report of its own. What each message waits and the command's round trip, to set against the
//! analysis (`wire::busload::response_times`). Pure: the same messages and seed give the same
//! bus.

use super::model::{BABBLER, BusFrame, BusStats, BusTiming, CanBus, Delivered, RoundTrip, ns};
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;
use wire::busload::Periodic;

/// A frame of a lab's contract on the bus model. Its length is its longest (every stuff bit the
/// rules allow): the model's figures then sit on the analysis' own assumption.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabFrame {
    /// Its identifier.
    pub id: u32,
    /// A 29-bit identifier.
    pub extended: bool,
    /// Payload bytes.
    pub len: u8,
    /// A CAN FD frame with the bit-rate switch.
    pub fd: bool,
    /// Its message's name.
    pub name: &'static str,
    /// Its sender.
    pub sender: &'static str,
}

impl BusFrame for LabFrame {
    fn id(&self) -> u32 {
        self.id
    }
    fn extended(&self) -> bool {
        self.extended
    }
    fn arbitration(&self) -> u64 {
        wire::busload::arbitration_key(self.id, self.extended)
    }
    fn bits(&self) -> (u32, u32) {
        wire::busload::frame_bits_worst_phases(self.extended, usize::from(self.len), self.fd)
    }
    fn sender(&self) -> &'static str {
        self.sender
    }
    fn name(&self) -> String {
        self.name.to_string()
    }
    fn babble(id: f64) -> Self {
        LabFrame {
            id: (id.max(0.0) as u32) & 0x7FF,
            extended: false,
            len: 8,
            fd: false,
            name: "babble",
            sender: BABBLER,
        }
    }
}

/// One of the contract's periodic messages, with its sender.
#[derive(Debug, Clone, PartialEq)]
pub struct LabMessage {
    /// Its period, jitter and frame.
    pub periodic: Periodic,
    /// The node that sends it.
    pub sender: String,
}

/// The table's round trip: the command message and the report that answers it (by index in
/// the messages), the controller's tick, s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableLoop {
    /// The box's command message.
    pub command: usize,
    /// The table's report message.
    pub report: usize,
    /// The controller's loop period, s: a command completed on the bus is taken at its next
    /// tick and answered by a report queued then.
    pub tick_s: f64,
}

/// The bus of `msgs` for `duration_s`, every message's first frame at 0 (the critical
/// instant) and each later one queued within its jitter (drawn from `seed`); with `table`, each
/// command answered by a report at the controller's next tick, the round trip from the
/// command's queueing to the answer's end in the statistics.
pub fn simulate(
    msgs: &[LabMessage],
    table: Option<TableLoop>,
    timing: BusTiming,
    duration_s: f64,
    seed: u64,
) -> BusStats {
    // a DBC's few names, once per call: the model's nodes and messages are named statically
    let frames: Vec<LabFrame> = msgs
        .iter()
        .map(|m| LabFrame {
            id: m.periodic.id,
            extended: m.periodic.extended,
            len: m.periodic.payload.min(64) as u8,
            fd: m.periodic.fd,
            name: Box::leak(m.periodic.name.clone().into_boxed_str()),
            sender: Box::leak(m.sender.clone().into_boxed_str()),
        })
        .collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    // every frame's queueing time, in time order
    let mut queued: Vec<(u64, usize)> = Vec::new();
    for (i, m) in msgs.iter().enumerate() {
        let p = &m.periodic;
        let n = (duration_s / p.period_s).floor() as u64;
        for k in 0..n {
            let jitter = if k == 0 || p.jitter_s <= 0.0 {
                0.0
            } else {
                rng.random_range(0.0..p.jitter_s)
            };
            queued.push((ns(k as f64 * p.period_s + jitter), i));
        }
    }
    queued.sort();
    let mut bus: CanBus<LabFrame> = CanBus::new(timing);
    let mut trips: BTreeMap<u64, u64> = BTreeMap::new();
    // commands waiting for their answer (queued at, answered at), answers not queued yet
    let mut waiting: Vec<(u64, u64)> = Vec::new();
    let mut answers: Vec<u64> = Vec::new();
    // the bus runs to every frame's queueing and, with a table, every tick of its controller
    // (an answer is queued at a tick, never before the bus has got there)
    let tick = table.map(|t| ns(t.tick_s).max(1));
    let mut events: Vec<(u64, Option<usize>)> =
        queued.into_iter().map(|(t, i)| (t, Some(i))).collect();
    if let Some(tick) = tick {
        events.extend((0..=ns(duration_s) / tick).map(|k| (k * tick, None)));
        events.sort();
    }
    for (t, frame) in events {
        bus.run(t, false, |_, d| {
            let (Delivered::Frame(f), Some(tl), Some(tick)) = (d, table, tick) else {
                return;
            };
            if f.frame == frames[tl.command] {
                let at = f.end_ns.div_ceil(tick) * tick;
                answers.push(at);
                waiting.push((f.queued_ns, at));
            } else if f.frame == frames[tl.report]
                && let Some(w) = waiting.iter().position(|(_, at)| *at == f.queued_ns)
            {
                let (cmd_at, _) = waiting.swap_remove(w);
                *trips.entry(f.end_ns - cmd_at).or_default() += 1;
            }
        });
        if let Some(tl) = table {
            answers.retain(|at| {
                let due = *at <= t;
                if due {
                    bus.queue(*at, frames[tl.report]);
                }
                !due
            });
        }
        if let Some(i) = frame {
            bus.queue(t, frames[i]);
        }
    }
    bus.run(u64::MAX, false, |_, _| {});
    let mut stats = bus.stats();
    stats.round_trip = RoundTrip::of(&trips);
    stats
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(name: &str, id: u32, extended: bool, payload: usize, period_ms: f64) -> LabMessage {
        LabMessage {
            periodic: Periodic {
                name: name.into(),
                id,
                extended,
                payload,
                fd: payload > 8,
                period_s: period_ms * 1e-3,
                jitter_s: 0.0,
            },
            sender: name.into(),
        }
    }

    /// CAN FD's data phase runs at its own rate: a 64-byte block takes its arbitration bits at
    /// the nominal rate and its data bits at the data rate; the lower identifier wins (a
    /// standard one over an extended one of the same base bits); every frame is sent, and the
    /// table's answer comes a tick after the command.
    #[test]
    fn a_labs_frames_share_the_bus_by_their_identifiers_and_phases() {
        let msgs = vec![
            msg("BLOCK", 0x1900_0000, true, 64, 10.0),
            msg("CMD", 0x100, false, 8, 100.0),
            msg("REPORT", 0x101, false, 8, 10.0),
        ];
        let timing = BusTiming {
            bitrate_bps: 500_000.0,
            data_bitrate_bps: Some(2_000_000.0),
            ..BusTiming::default()
        };
        let table = TableLoop {
            command: 1,
            report: 2,
            tick_s: 1e-3,
        };
        let b = simulate(&msgs, Some(table), timing, 1.0, 7);
        let frames = |n: &str| b.ids.iter().find(|i| i.name == n).map_or(0, |i| i.frames);
        // the reports: 100 periodic and one answering each of the 10 commands
        assert_eq!(
            (frames("BLOCK"), frames("CMD"), frames("REPORT")),
            (100, 10, 110)
        );
        // at the critical instant CMD (0x100) goes first, REPORT next, the block last: it
        // waits for both
        let (arb, data) = wire::busload::frame_bits_worst_phases(true, 64, true);
        let block_ns = f64::from(arb) * 2000.0 + f64::from(data) * 500.0;
        let classic_ns = f64::from(wire::busload::frame_bits_worst(8)) * 2000.0;
        let block = b
            .ids
            .iter()
            .find(|i| i.name == "BLOCK")
            .map(|i| i.delay_max_us);
        assert!(
            block.is_some_and(|d| (d * 1e3 - 2.0 * classic_ns).abs() < 1.0),
            "{block:?}"
        );
        let expected_load = (100.0 * block_ns + 120.0 * classic_ns) * 1e-9;
        assert!(
            (b.load * b.span_s - expected_load).abs() < 1e-6,
            "{} x {}",
            b.load,
            b.span_s
        );
        assert_eq!(b.round_trip.commands, 10);
        // command sent, the tick, the report sent: a little over a millisecond
        assert!(
            b.round_trip.max_us > 1000.0 && b.round_trip.max_us < 1500.0,
            "{:?}",
            b.round_trip
        );
    }
}
