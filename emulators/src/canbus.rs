//! The physical CAN bus on the simulated clock, without I/O: each node's transmit queue, the
//! frames' durations from their bits (stuff bits included), arbitration by identifier among the
//! frames pending when the bus goes idle, and what each frame waited.
//!
//! vcan is an ideal bus: a frame is there the moment it is written. This model decides, for the
//! frames the bench's devices and nav queue at simulated times, when each one starts and
//! completes on a real bus of the scenario's bit rate, and so the order in which they reach the
//! other nodes. The scheduler ([`crate::step::Stepper`]) writes the devices' frames to vcan in
//! that order, and hands a turntable command to the mechanism when it completes. Pure: the same
//! frames queued at the same times give the same bus, on any host and at any pace.
//!
//! A node's queue is first in, first out (a controller with one transmit buffer behind a
//! driver's queue, as Linux SocketCAN drivers are): only the head of each queue takes part in
//! arbitration. A frame queued on a full queue is lost and counted, as the kernel's
//! `ENOBUFS` would be.

use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, VecDeque};
use wire::RawFrame;

/// How the bus is modelled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BusTiming {
    /// Bit rate, bit/s.
    pub bitrate_bps: f64,
    /// An ideal bus (vcan's): every frame completes the moment it is queued, in the order queued.
    pub ideal: bool,
    /// Depth of each node's transmit queue, frames.
    pub tx_queue: usize,
}

impl Default for BusTiming {
    fn default() -> Self {
        Self {
            bitrate_bps: wire::busload::NOMINAL_BITRATE,
            ideal: false,
            tx_queue: DEFAULT_TX_QUEUE,
        }
    }
}

/// Default depth of a node's transmit queue, frames (Linux's `txqueuelen` for CAN devices is
/// 10; a controller's buffers add a few).
pub const DEFAULT_TX_QUEUE: usize = 16;

/// Simulated time in nanoseconds, the model's unit.
pub fn ns(t_s: f64) -> u64 {
    (t_s * 1e9).round().max(0.0) as u64
}

/// A frame on the bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnBus {
    /// The frame.
    pub frame: RawFrame,
    /// The node that sent it ([`CanBus::node_name`]).
    pub node: usize,
    /// When it was queued, ns.
    pub queued_ns: u64,
    /// When it won arbitration (start of frame), ns.
    pub start_ns: u64,
    /// When its last bit (end of intermission) was on the bus, ns: when the other nodes have it.
    pub end_ns: u64,
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    frame: RawFrame,
    queued_ns: u64,
    seq: u64,
}

#[derive(Debug, Default)]
struct Node {
    name: &'static str,
    queue: VecDeque<Pending>,
    overflow: u64,
    sent: u64,
    deepest: usize,
}

/// What the bus did, per identifier.
#[derive(Debug, Clone, Default)]
struct IdStats {
    frames: u64,
    bits: u64,
    /// Queueing delay (queued to start of frame), ns -> frames.
    delay: BTreeMap<u64, u64>,
}

/// The bus.
#[derive(Debug)]
pub struct CanBus {
    timing: BusTiming,
    nodes: Vec<Node>,
    /// The bus is idle from then on, ns.
    free_ns: u64,
    seq: u64,
    ids: BTreeMap<u16, IdStats>,
    busy_ns: u64,
    first_ns: Option<u64>,
    last_ns: u64,
}

/// Name of the node of frames whose identifier the contract does not know (a foreign node on
/// the harness, the fault injector).
pub const FOREIGN: &str = "OTHER";

impl CanBus {
    /// An idle bus.
    pub fn new(timing: BusTiming) -> Self {
        Self {
            timing,
            nodes: Vec::new(),
            free_ns: 0,
            seq: 0,
            ids: BTreeMap::new(),
            busy_ns: 0,
            first_ns: None,
            last_ns: 0,
        }
    }

    /// How the bus is modelled.
    pub fn timing(&self) -> BusTiming {
        self.timing
    }

    /// Name of node `i`.
    pub fn node_name(&self, i: usize) -> &'static str {
        self.nodes.get(i).map_or(FOREIGN, |n| n.name)
    }

    /// The node that sends `frame`: the contract's transmitter of its identifier, else
    /// [`FOREIGN`].
    fn node_of(&mut self, frame: &RawFrame) -> usize {
        let name = wire::spec_for_id(frame.id).map_or(FOREIGN, |s| s.sender);
        match self.nodes.iter().position(|n| n.name == name) {
            Some(i) => i,
            None => {
                self.nodes.push(Node {
                    name,
                    ..Default::default()
                });
                self.nodes.len() - 1
            }
        }
    }

    /// Duration of `frame` on the bus, ns (zero on the ideal bus).
    pub fn duration_ns(&self, frame: &RawFrame) -> u64 {
        self.bits_ns(wire::busload::frame_bits_exact(frame))
    }

    /// Duration of `bits` on the bus, ns (zero on the ideal bus).
    fn bits_ns(&self, bits: u32) -> u64 {
        if self.timing.ideal {
            return 0;
        }
        (f64::from(bits) * 1e9 / self.timing.bitrate_bps).round() as u64
    }

    /// `frame` is handed to its node's controller at `t_ns`. False when the node's queue was
    /// full: the frame is lost (counted).
    pub fn queue(&mut self, t_ns: u64, frame: RawFrame) -> bool {
        let i = self.node_of(&frame);
        let depth = self.timing.tx_queue.max(1);
        let node = &mut self.nodes[i];
        if node.queue.len() >= depth {
            node.overflow += 1;
            return false;
        }
        node.queue.push_back(Pending {
            frame,
            queued_ns: t_ns,
            seq: self.seq,
        });
        self.seq += 1;
        node.deepest = node.deepest.max(node.queue.len());
        true
    }

    /// Frames are waiting in some node's queue.
    pub fn pending(&self) -> bool {
        self.nodes.iter().any(|n| !n.queue.is_empty())
    }

    /// The frame that goes next, and when it starts: the bus idle, the lowest identifier among
    /// the queues' heads pending then (on the ideal bus: the first queued).
    fn next(&self) -> Option<(usize, u64)> {
        let heads = self
            .nodes
            .iter()
            .enumerate()
            .filter_map(|(i, n)| n.queue.front().map(|p| (i, p)));
        if self.timing.ideal {
            return heads
                .min_by_key(|(_, p)| (p.queued_ns, p.seq))
                .map(|(i, p)| (i, p.queued_ns));
        }
        let earliest = heads.clone().map(|(_, p)| p.queued_ns).min()?;
        let at = self.free_ns.max(earliest);
        heads
            .filter(|(_, p)| p.queued_ns <= at)
            .min_by_key(|(i, p)| (p.frame.id, *i))
            .map(|(i, _)| (i, at))
    }

    /// Put on the bus every frame that starts before `limit_ns` (`complete_by`: that is over by
    /// then), in bus order, each to `out` as it completes. Frames `out` queues on the bus it is
    /// given (a node answering the frame) take part in the arbitrations after it. Stopping at a
    /// limit changes nothing on the bus: a frame left pending starts at the same time in the
    /// next call, and frames queued later than that do not contend with it.
    pub fn run(&mut self, limit_ns: u64, complete_by: bool, mut out: impl FnMut(&mut Self, OnBus)) {
        while let Some((i, start)) = self.next() {
            let Some(p) = self.nodes[i].queue.front().copied() else {
                break;
            };
            let bits = wire::busload::frame_bits_exact(&p.frame);
            let end = start + self.bits_ns(bits);
            if (complete_by && end > limit_ns) || (!complete_by && start >= limit_ns) {
                break;
            }
            self.nodes[i].queue.pop_front();
            self.nodes[i].sent += 1;
            self.free_ns = end;
            self.first_ns.get_or_insert(start);
            self.last_ns = self.last_ns.max(end);
            self.busy_ns += end - start;
            let s = self.ids.entry(p.frame.id).or_default();
            s.frames += 1;
            s.bits += u64::from(bits);
            *s.delay.entry(start - p.queued_ns).or_default() += 1;
            out(
                self,
                OnBus {
                    frame: p.frame,
                    node: i,
                    queued_ns: p.queued_ns,
                    start_ns: start,
                    end_ns: end,
                },
            );
        }
    }

    /// What the bus did so far.
    pub fn stats(&self) -> BusStats {
        let span = self.last_ns.saturating_sub(self.first_ns.unwrap_or(0));
        let ids = self
            .ids
            .iter()
            .map(|(&id, s)| {
                let spec = wire::spec_for_id(id);
                IdTiming {
                    id,
                    name: spec.map_or_else(|| format!("0x{id:03X}"), |s| s.name.to_string()),
                    sender: spec.map_or(FOREIGN, |s| s.sender).to_string(),
                    frames: s.frames,
                    load: if span > 0 {
                        s.bits as f64 / self.timing.bitrate_bps / (span as f64 * 1e-9)
                    } else {
                        0.0
                    },
                    delay_p50_us: percentile(&s.delay, 0.5) as f64 * 1e-3,
                    delay_p99_us: percentile(&s.delay, 0.99) as f64 * 1e-3,
                    delay_max_us: s.delay.keys().next_back().copied().unwrap_or(0) as f64 * 1e-3,
                }
            })
            .collect();
        BusStats {
            bitrate_bps: self.timing.bitrate_bps,
            ideal: self.timing.ideal,
            span_s: span as f64 * 1e-9,
            load: if span > 0 && !self.timing.ideal {
                self.busy_ns as f64 / span as f64
            } else {
                0.0
            },
            ids,
            nodes: self
                .nodes
                .iter()
                .map(|n| NodeTiming {
                    name: n.name.to_string(),
                    sent: n.sent,
                    overflow: n.overflow,
                    deepest: n.deepest as u64,
                })
                .collect(),
            round_trip: RoundTrip::default(),
        }
    }
}

/// The `q` quantile of a histogram (value -> count), by nearest rank.
pub fn percentile(h: &BTreeMap<u64, u64>, q: f64) -> u64 {
    let n: u64 = h.values().sum();
    if n == 0 {
        return 0;
    }
    let rank = ((n as f64 * q).ceil() as u64).clamp(1, n);
    let mut seen = 0;
    for (&v, &c) in h {
        seen += c;
        if seen >= rank {
            return v;
        }
    }
    0
}

/// One identifier's traffic on the modelled bus.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IdTiming {
    /// Identifier.
    pub id: u16,
    /// Message name in the contract (else the identifier).
    pub name: String,
    /// The node that sends it.
    pub sender: String,
    /// Frames sent.
    pub frames: u64,
    /// Its share of the bus (its bits over the bit rate and the run's span).
    pub load: f64,
    /// Queueing delay (queued to start of frame), median, µs.
    pub delay_p50_us: f64,
    /// Its 99th percentile, µs.
    pub delay_p99_us: f64,
    /// Its worst, µs.
    pub delay_max_us: f64,
}

/// One node's transmit queue.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NodeTiming {
    /// The node (the contract's transmitter, or [`FOREIGN`]).
    pub name: String,
    /// Frames it sent.
    pub sent: u64,
    /// Frames lost to its full queue.
    pub overflow: u64,
    /// Most frames its queue held at once.
    pub deepest: u64,
}

/// Turntable command to acknowledgement on the modelled bus: from nav queueing the TT_CMD to
/// the TT_ACK that answers it being on the bus.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RoundTrip {
    /// Commands answered.
    pub commands: u64,
    /// Median, µs.
    pub p50_us: f64,
    /// 99th percentile, µs.
    pub p99_us: f64,
    /// Worst, µs.
    pub max_us: f64,
}

impl RoundTrip {
    /// From a histogram of round trips, ns.
    pub fn of(h: &BTreeMap<u64, u64>) -> Self {
        Self {
            commands: h.values().sum(),
            p50_us: percentile(h, 0.5) as f64 * 1e-3,
            p99_us: percentile(h, 0.99) as f64 * 1e-3,
            max_us: h.keys().next_back().copied().unwrap_or(0) as f64 * 1e-3,
        }
    }
}

/// What the modelled bus did in a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BusStats {
    /// Bit rate, bit/s.
    pub bitrate_bps: f64,
    /// The bus was ideal (vcan's timing, no model).
    pub ideal: bool,
    /// From the first frame's start to the last one's end, s.
    pub span_s: f64,
    /// Fraction of that time the bus was busy.
    pub load: f64,
    /// Per identifier, in identifier order.
    pub ids: Vec<IdTiming>,
    /// Per node.
    pub nodes: Vec<NodeTiming>,
    /// TT_CMD to TT_ACK.
    pub round_trip: RoundTrip,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u16) -> RawFrame {
        RawFrame {
            id,
            len: 8,
            data: [0x55; 8],
        }
    }

    fn drain(bus: &mut CanBus, limit: u64) -> Vec<OnBus> {
        let mut got = Vec::new();
        bus.run(limit, false, |_, f| got.push(f));
        got
    }

    #[test]
    fn frames_pending_together_go_in_identifier_order_one_after_the_other() {
        let mut bus = CanBus::new(BusTiming::default());
        // nav's command first, then the IMU's two frames, all at the same instant
        assert!(bus.queue(1_000_000, frame(0x100)));
        assert!(bus.queue(1_000_000, frame(0x080)));
        assert!(bus.queue(1_000_000, frame(0x081)));
        let got = drain(&mut bus, u64::MAX);
        let ids: Vec<_> = got.iter().map(|f| f.frame.id).collect();
        // the IMU's queue is first in, first out: 0x080 then 0x081 beat 0x100
        assert_eq!(ids, [0x080, 0x081, 0x100]);
        assert_eq!(got[0].start_ns, 1_000_000);
        for w in got.windows(2) {
            assert_eq!(w[1].start_ns, w[0].end_ns, "back to back");
        }
        let d = |id| bus.duration_ns(&frame(id));
        assert_eq!(
            d(0x080),
            1000 * u64::from(wire::busload::frame_bits_exact(&frame(0x080)))
        );
        // nav's command waited for both of the IMU's
        assert_eq!(got[2].start_ns - got[2].queued_ns, d(0x080) + d(0x081));
    }

    #[test]
    fn a_frame_on_the_bus_is_not_interrupted_by_a_higher_priority_one() {
        let mut bus = CanBus::new(BusTiming::default());
        bus.queue(0, frame(0x200));
        bus.queue(10_000, frame(0x080));
        let got = drain(&mut bus, u64::MAX);
        assert_eq!(got[0].frame.id, 0x200);
        assert_eq!(got[1].start_ns, got[0].end_ns);
        // the IMU's frame waited for the rest of nav's frame
        assert_eq!(got[1].start_ns - got[1].queued_ns, got[0].end_ns - 10_000);
    }

    #[test]
    fn half_the_bit_rate_doubles_the_frames_durations() {
        let fast = CanBus::new(BusTiming::default());
        let slow = CanBus::new(BusTiming {
            bitrate_bps: 500_000.0,
            ..BusTiming::default()
        });
        let f = frame(0x102);
        assert_eq!(slow.duration_ns(&f), 2 * fast.duration_ns(&f));
    }

    #[test]
    fn a_full_queue_loses_the_frame_and_counts_it() {
        let mut bus = CanBus::new(BusTiming {
            tx_queue: 2,
            ..BusTiming::default()
        });
        assert!(bus.queue(0, frame(0x080)));
        assert!(bus.queue(0, frame(0x081)));
        assert!(!bus.queue(0, frame(0x082)));
        // another node's queue is its own
        assert!(bus.queue(0, frame(0x200)));
        drain(&mut bus, u64::MAX);
        let s = bus.stats();
        let imu = s.nodes.iter().find(|n| n.name == "IMU").unwrap();
        assert_eq!((imu.sent, imu.overflow, imu.deepest), (2, 1, 2));
    }

    #[test]
    fn the_window_stops_at_frames_that_start_later_and_keeps_them() {
        let mut bus = CanBus::new(BusTiming::default());
        for _ in 0..10 {
            bus.queue(0, frame(0x200));
        }
        let d = bus.duration_ns(&frame(0x200));
        let first = drain(&mut bus, 3 * d);
        assert_eq!(first.len(), 3);
        assert!(bus.pending());
        let mut over = Vec::new();
        bus.run(5 * d, true, |_, f| over.push(f));
        // complete_by: only the frames whose end is in time
        assert_eq!(over.len(), 2);
        assert_eq!(over[1].end_ns, 5 * d);
    }

    #[test]
    fn the_ideal_bus_takes_no_time_and_keeps_the_order_queued() {
        let mut bus = CanBus::new(BusTiming {
            ideal: true,
            ..BusTiming::default()
        });
        bus.queue(7, frame(0x200));
        bus.queue(7, frame(0x080));
        let got = drain(&mut bus, 8);
        assert_eq!(got[0].frame.id, 0x200);
        assert!(got.iter().all(|f| f.start_ns == 7 && f.end_ns == 7));
    }

    #[test]
    fn load_and_delays_are_measured_per_identifier() {
        let mut bus = CanBus::new(BusTiming::default());
        // 2 kHz of two 8-byte frames for one second, and a 100 Hz status
        for k in 0..2000u64 {
            let t = k * 500_000;
            bus.queue(t, frame(0x080));
            bus.queue(t, frame(0x081));
            if k % 20 == 0 {
                bus.queue(t, frame(0x102));
            }
            drain(&mut bus, t + 500_000);
        }
        let s = bus.stats();
        let bits = |id| f64::from(wire::busload::frame_bits_exact(&frame(id)));
        // over the span from the first frame's start to the last one's end
        let busy = 2000.0 * (bits(0x080) + bits(0x081)) + 100.0 * bits(0x102);
        assert!((s.load - busy / 1e6 / s.span_s).abs() < 1e-9, "{s:?}");
        let status = s.ids.iter().find(|i| i.id == 0x102).unwrap();
        // the status waits for both IMU frames
        let waited = bits(0x080) + bits(0x081);
        assert!((status.delay_max_us - waited).abs() < 1e-6, "{status:?}");
        let gyro = s.ids.iter().find(|i| i.id == 0x080).unwrap();
        assert_eq!(gyro.delay_max_us, 0.0);
        let mut h = BTreeMap::new();
        for v in 1..=100 {
            h.insert(v, 1);
        }
        assert_eq!((percentile(&h, 0.5), percentile(&h, 0.99)), (50, 99));
    }
}
