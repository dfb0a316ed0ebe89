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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BusTiming {
    /// Bit rate, bit/s.
    pub bitrate_bps: f64,
    /// CAN FD's data phase after the bit-rate switch, bit/s (none: `bitrate_bps`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_bitrate_bps: Option<f64>,
    /// An ideal bus (vcan's): every frame completes the moment it is queued, in the order queued.
    pub ideal: bool,
    /// Depth of each node's transmit queue, frames.
    pub tx_queue: usize,
    /// Faults of the physical layer (none on the ideal bus).
    pub faults: PhysicalFaults,
}

impl Default for BusTiming {
    fn default() -> Self {
        Self {
            bitrate_bps: wire::busload::NOMINAL_BITRATE,
            data_bitrate_bps: None,
            ideal: false,
            tx_queue: DEFAULT_TX_QUEUE,
            faults: PhysicalFaults::default(),
        }
    }
}

/// Faults of the physical layer, on the simulated clock (ISO 11898-1's fault confinement).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicalFaults {
    /// The harness disturbed: `[from s, to s, frames corrupted per second]`. Each corruption
    /// hits the next frame to start: it is cut by an error frame and sent again; its sender's
    /// transmit error counter rises by 8, every other node's receive counter by 1.
    #[serde(default)]
    pub disturbed_s: Vec<[f64; 3]>,
    /// The bus stuck dominant: `[from s, to s]`. Nothing gets through; the node about to send
    /// goes bus-off, every other node error-passive.
    #[serde(default)]
    pub stuck_dominant_s: Vec<[f64; 2]>,
    /// A babbling node: `[from s, to s, identifier]`: a node on the harness sending that
    /// identifier back to back (8 bytes each).
    #[serde(default)]
    pub babbling_s: Vec<[f64; 3]>,
    /// A node's transmitter faulty (a wiring fault on its TX line): every frame it sends from
    /// `from_s` to `to_s` fails, until it goes bus-off; it recovers after 128 x 11 recessive
    /// bits and fails again while the fault lasts.
    #[serde(default)]
    pub tx_faults: Vec<TxFault>,
}

/// A node's faulty transmitter ([`PhysicalFaults::tx_faults`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TxFault {
    /// The node: the contract's transmitter (`IMU`, `TT`, `NAV`, `MEMS`).
    pub node: String,
    /// From, s.
    pub from_s: f64,
    /// To, s.
    pub to_s: f64,
}

impl PhysicalFaults {
    /// No fault is set.
    pub fn is_empty(&self) -> bool {
        self.disturbed_s.is_empty()
            && self.stuck_dominant_s.is_empty()
            && self.babbling_s.is_empty()
            && self.tx_faults.is_empty()
    }
}

/// Bits of an error frame and the intermission after it (error flag, its echo, delimiter,
/// intermission).
const ERROR_FRAME_BITS: u32 = 20;
/// Bits of recessive bus a bus-off node waits before it takes part again (128 x 11).
const BUS_OFF_RECOVERY_BITS: u32 = 128 * 11;
/// The node that babbles ([`PhysicalFaults::babbling_s`]).
pub const BABBLER: &str = "BABBLER";

/// Default depth of a node's transmit queue, frames (Linux's `txqueuelen` for CAN devices is
/// 10; a controller's buffers add a few).
pub const DEFAULT_TX_QUEUE: usize = 16;

/// Simulated time in nanoseconds, the model's unit.
pub fn ns(t_s: f64) -> u64 {
    (t_s * 1e9).round().max(0.0) as u64
}

/// A frame the bus model carries: our contract's classic frames ([`RawFrame`]), or a lab's
/// ([`crate::bus::lab::LabFrame`]: 29-bit identifiers, CAN FD's data phase at its own rate).
pub trait BusFrame: Copy + std::fmt::Debug {
    /// Its identifier.
    fn id(&self) -> u32;
    /// A 29-bit identifier.
    fn extended(&self) -> bool;
    /// Its place in arbitration: the lower wins.
    fn arbitration(&self) -> u64;
    /// Its bits on the wire: at the nominal rate, and in CAN FD's data phase (0: classic).
    fn bits(&self) -> (u32, u32);
    /// The node that sends it.
    fn sender(&self) -> &'static str;
    /// Its message's name (else its identifier).
    fn name(&self) -> String;
    /// A babbling node's frame ([`PhysicalFaults::babbling_s`]'s identifier).
    fn babble(id: f64) -> Self;
}

impl BusFrame for RawFrame {
    fn id(&self) -> u32 {
        u32::from(self.id)
    }
    fn extended(&self) -> bool {
        false
    }
    fn arbitration(&self) -> u64 {
        u64::from(self.id)
    }
    fn bits(&self) -> (u32, u32) {
        (wire::busload::frame_bits_exact(self), 0)
    }
    fn sender(&self) -> &'static str {
        wire::spec_for_id(self.id).map_or(FOREIGN, |s| s.sender)
    }
    fn name(&self) -> String {
        wire::spec_for_id(self.id)
            .map_or_else(|| format!("0x{:03X}", self.id), |s| s.name.to_string())
    }
    fn babble(id: f64) -> Self {
        RawFrame {
            id: (id.max(0.0) as u16) & 0x7FF,
            len: 8,
            data: [0xBA; 8],
        }
    }
}

/// What the bus hands on: a frame over, or an error frame nav's controller raises.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Delivered<F = RawFrame> {
    /// A frame is over on the bus.
    Frame(OnBus<F>),
    /// nav's controller reports an error (a bus error, a change of its error state, bus-off, a
    /// restart), at `t_ns`.
    Error {
        /// When, ns.
        t_ns: u64,
        /// The error frame as a Linux CAN driver writes it.
        frame: wire::errframe::ErrorFrame,
    },
}

/// A frame on the bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnBus<F = RawFrame> {
    /// The frame.
    pub frame: F,
    /// The node that sent it ([`CanBus::node_name`]).
    pub node: usize,
    /// When it was queued, ns.
    pub queued_ns: u64,
    /// When it won arbitration (start of frame), ns.
    pub start_ns: u64,
    /// When its last bit (end of intermission) was on the bus, ns: when the other nodes have it.
    pub end_ns: u64,
    /// nav's controller took it (it was not bus-off).
    pub nav_receives: bool,
}

#[derive(Debug, Clone, Copy)]
struct Pending<F> {
    frame: F,
    queued_ns: u64,
    seq: u64,
    /// Its length on the wire with its stuff bits, at the nominal rate and in CAN FD's data
    /// phase (counted once, as it is queued: a frame waits through many calls of
    /// [`CanBus::run`]).
    bits: (u32, u32),
}

#[derive(Debug)]
struct Node<F> {
    name: &'static str,
    queue: VecDeque<Pending<F>>,
    overflow: u64,
    sent: u64,
    deepest: usize,
    /// Its error counters.
    tec: u16,
    rec: u16,
    /// Bus-off until then, ns.
    off_until: Option<u64>,
    failed: u64,
    bus_offs: u64,
    lost_off: u64,
    max_tec: u16,
}

impl<F> Node<F> {
    fn named(name: &'static str) -> Self {
        Self {
            name,
            queue: VecDeque::new(),
            overflow: 0,
            sent: 0,
            deepest: 0,
            tec: 0,
            rec: 0,
            off_until: None,
            failed: 0,
            bus_offs: 0,
            lost_off: 0,
            max_tec: 0,
        }
    }

    fn state(&self) -> wire::errframe::ErrorState {
        if self.off_until.is_some() {
            wire::errframe::ErrorState::BusOff
        } else {
            wire::errframe::ErrorState::of(self.tec, self.rec)
        }
    }
}

/// What the bus did, per identifier.
#[derive(Debug, Clone, Default)]
struct IdStats {
    id: u32,
    extended: bool,
    name: String,
    sender: &'static str,
    frames: u64,
    bits: u64,
    /// Bits in CAN FD's data phase.
    data_bits: u64,
    /// Queueing delay (queued to start of frame), ns -> frames.
    delay: BTreeMap<u64, u64>,
}

/// The bus.
#[derive(Debug)]
pub struct CanBus<F = RawFrame> {
    timing: BusTiming,
    nodes: Vec<Node<F>>,
    /// The node of each identifier met so far (an index into `nodes`, which only grows): the
    /// contract's lookup and the name's search once per identifier, not per frame.
    node_of_id: BTreeMap<u64, usize>,
    /// A bit's time, ns, where it is a whole number (500 kbit/s: 2,000; any rate that divides
    /// 1 GHz): a frame's time is then the product, exactly what the rounded quotient gives.
    ns_per_bit: Option<u64>,
    /// Per disturbance window, the next corruption, ns.
    next_corruption: Vec<u64>,
    /// Stuck windows already applied.
    stuck_done: usize,
    corrupted: u64,
    stuck_ns: u64,
    nav_errors: u64,
    /// nav's controller's view, kept even before nav has sent anything.
    nav: usize,
    /// Error frames of nav's controller not handed on yet (time, frame).
    events: Vec<(u64, wire::errframe::ErrorFrame)>,
    /// The bus is idle from then on, ns.
    free_ns: u64,
    seq: u64,
    /// By arbitration order.
    ids: BTreeMap<u64, IdStats>,
    busy_ns: u64,
    first_ns: Option<u64>,
    last_ns: u64,
}

/// The time of a bit at `bitrate_bps`, ns, when it is a whole number.
fn whole_ns_per_bit(bitrate_bps: f64) -> Option<u64> {
    ((1.0..=1e9).contains(&bitrate_bps) && 1e9 % bitrate_bps == 0.0)
        .then(|| (1e9 / bitrate_bps) as u64)
}

/// Name of the node of frames whose identifier the contract does not know (a foreign node on
/// the harness, the fault injector).
pub const FOREIGN: &str = "OTHER";

impl<F: BusFrame> CanBus<F> {
    /// An idle bus.
    pub fn new(timing: BusTiming) -> Self {
        let next_corruption = timing.faults.disturbed_s.iter().map(|w| ns(w[0])).collect();
        let ns_per_bit = whole_ns_per_bit(timing.bitrate_bps);
        Self {
            timing,
            nodes: vec![Node::named("NAV")],
            node_of_id: BTreeMap::new(),
            ns_per_bit,
            next_corruption,
            stuck_done: 0,
            corrupted: 0,
            stuck_ns: 0,
            nav_errors: 0,
            nav: 0,
            events: Vec::new(),
            free_ns: 0,
            seq: 0,
            ids: BTreeMap::new(),
            busy_ns: 0,
            first_ns: None,
            last_ns: 0,
        }
    }

    /// How the bus is modelled.
    pub fn timing(&self) -> &BusTiming {
        &self.timing
    }

    /// Name of node `i`.
    pub fn node_name(&self, i: usize) -> &'static str {
        self.nodes.get(i).map_or(FOREIGN, |n| n.name)
    }

    /// The node that sends `frame`: the contract's transmitter of its identifier, else
    /// [`FOREIGN`].
    fn node_of(&mut self, frame: &F) -> usize {
        let key = frame.arbitration();
        if let Some(&i) = self.node_of_id.get(&key) {
            return i;
        }
        let i = self.node_named(frame.sender());
        self.node_of_id.insert(key, i);
        i
    }

    /// The node called `name`, added when new.
    fn node_named(&mut self, name: &'static str) -> usize {
        match self.nodes.iter().position(|n| n.name == name) {
            Some(i) => i,
            None => {
                self.nodes.push(Node::named(name));
                self.nodes.len() - 1
            }
        }
    }

    /// Duration of `frame` on the bus, ns (zero on the ideal bus).
    pub fn duration_ns(&self, frame: &F) -> u64 {
        self.phases_ns(frame.bits())
    }

    /// Duration of bits at the nominal rate and in the data phase, ns (zero on the ideal bus).
    fn phases_ns(&self, (bits, data): (u32, u32)) -> u64 {
        self.bits_ns(bits) + self.data_ns(data)
    }

    /// Duration of `bits` in CAN FD's data phase, ns (zero on the ideal bus).
    fn data_ns(&self, bits: u32) -> u64 {
        if bits == 0 || self.timing.ideal {
            return 0;
        }
        let rate = self
            .timing
            .data_bitrate_bps
            .unwrap_or(self.timing.bitrate_bps);
        (f64::from(bits) * 1e9 / rate).round() as u64
    }

    /// Duration of `bits` on the bus, ns (zero on the ideal bus).
    fn bits_ns(&self, bits: u32) -> u64 {
        if self.timing.ideal {
            return 0;
        }
        match self.ns_per_bit {
            Some(k) => u64::from(bits) * k,
            None => (f64::from(bits) * 1e9 / self.timing.bitrate_bps).round() as u64,
        }
    }

    /// `frame` is handed to its node's controller at `t_ns`. False when the node's queue was
    /// full: the frame is lost (counted).
    pub fn queue(&mut self, t_ns: u64, frame: F) -> bool {
        let i = self.node_of(&frame);
        self.queue_on(i, t_ns, frame)
    }

    fn queue_on(&mut self, i: usize, t_ns: u64, frame: F) -> bool {
        let mut events = std::mem::take(&mut self.events);
        self.recover(t_ns, &mut events);
        self.events = events;
        let depth = self.timing.tx_queue.max(1);
        let node = &mut self.nodes[i];
        if node.off_until.is_some() {
            // a bus-off controller takes nothing (its driver's queue is stopped)
            node.lost_off += 1;
            return false;
        }
        if node.queue.len() >= depth {
            node.overflow += 1;
            return false;
        }
        node.queue.push_back(Pending {
            frame,
            queued_ns: t_ns,
            seq: self.seq,
            bits: frame.bits(),
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
            .filter(|(_, n)| n.off_until.is_none())
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
            .min_by_key(|(i, p)| (p.frame.arbitration(), *i))
            .map(|(i, _)| (i, at))
    }

    /// Put on the bus every frame that starts before `limit_ns` (`complete_by`: that is over by
    /// then), in bus order, each to `out` as it completes, with the error frames nav's
    /// controller raises on the way. Frames `out` queues on the bus it is given (a node
    /// answering the frame) take part in the arbitrations after it. Stopping at a limit changes
    /// nothing on the bus: a frame left pending starts at the same time in the next call, and
    /// frames queued later than that do not contend with it.
    pub fn run(
        &mut self,
        limit_ns: u64,
        complete_by: bool,
        mut out: impl FnMut(&mut Self, Delivered<F>),
    ) {
        let mut events = std::mem::take(&mut self.events);
        loop {
            self.recover(self.free_ns, &mut events);
            self.babble(limit_ns);
            let Some((i, start)) = self.next() else {
                self.recover(limit_ns, &mut events);
                flush_events(self, &mut events, limit_ns, &mut out);
                break;
            };
            let Some(p) = self.nodes[i].queue.front().copied() else {
                break;
            };
            let bits = p.bits;
            let end = start + self.phases_ns(bits);
            if (complete_by && end > limit_ns) || (!complete_by && start >= limit_ns) {
                self.recover(limit_ns.min(start), &mut events);
                flush_events(self, &mut events, limit_ns, &mut out);
                break;
            }
            if !self.timing.ideal && self.stuck(i, start, &mut events) {
                continue;
            }
            if !self.timing.ideal && self.corrupts(i, start) {
                self.fail(i, start, bits, &mut events);
                continue;
            }
            flush_events(self, &mut events, start, &mut out);
            self.nodes[i].queue.pop_front();
            self.nodes[i].sent += 1;
            self.free_ns = end;
            self.first_ns.get_or_insert(start);
            self.last_ns = self.last_ns.max(end);
            self.busy_ns += end - start;
            let s = self
                .ids
                .entry(p.frame.arbitration())
                .or_insert_with(|| IdStats {
                    id: p.frame.id(),
                    extended: p.frame.extended(),
                    name: p.frame.name(),
                    sender: p.frame.sender(),
                    ..IdStats::default()
                });
            s.frames += 1;
            s.bits += u64::from(bits.0);
            s.data_bits += u64::from(bits.1);
            *s.delay.entry(start - p.queued_ns).or_default() += 1;
            self.succeeded(i, end, &mut events);
            let nav_receives = self.nodes[self.nav].off_until.is_none();
            out(
                self,
                Delivered::Frame(OnBus {
                    frame: p.frame,
                    node: i,
                    queued_ns: p.queued_ns,
                    start_ns: start,
                    end_ns: end,
                    nav_receives,
                }),
            );
        }
        self.events = events;
    }

    /// Bus-off nodes whose 128 x 11 recessive bits are over by `now_ns` take part again.
    fn recover(&mut self, now_ns: u64, events: &mut Vec<(u64, wire::errframe::ErrorFrame)>) {
        for i in 0..self.nodes.len() {
            let n = &mut self.nodes[i];
            if let Some(t) = n.off_until
                && t <= now_ns
            {
                n.off_until = None;
                n.tec = 0;
                n.rec = 0;
                if i == self.nav {
                    events.push((t, wire::errframe::ErrorFrame::restarted()));
                }
            }
        }
    }

    /// A babbling node keeps one frame queued while its window lasts.
    fn babble(&mut self, limit_ns: u64) {
        if self.timing.ideal || self.timing.faults.babbling_s.is_empty() {
            return;
        }
        let i = self.node_named(BABBLER);
        if !self.nodes[i].queue.is_empty() {
            return;
        }
        for w in self.timing.faults.babbling_s.clone() {
            let (from, to) = (ns(w[0]), ns(w[1]));
            let at = from.max(self.free_ns);
            if at < to && at <= limit_ns {
                self.queue_on(i, at, F::babble(w[2]));
                return;
            }
        }
    }

    /// A stuck-dominant window begins before `start`: nothing gets through until its end; the
    /// node about to send goes bus-off, every other error-passive. Returns whether it applied.
    fn stuck(
        &mut self,
        sender: usize,
        start: u64,
        events: &mut Vec<(u64, wire::errframe::ErrorFrame)>,
    ) -> bool {
        use wire::errframe::{ErrorFrame, prot};
        let Some(w) = self
            .timing
            .faults
            .stuck_dominant_s
            .get(self.stuck_done)
            .copied()
        else {
            return false;
        };
        let (from, to) = (ns(w[0]), ns(w[1]));
        if start < from {
            return false;
        }
        self.stuck_done += 1;
        let at = start.max(from);
        if to <= at {
            return true;
        }
        self.stuck_ns += to - at;
        let bit = self.bits_ns(1).max(1);
        // every 8 dominant bits after the error flag: +8 on every counter
        let rise = ((to - at) / bit / 8 * 8).min(512) as u16;
        for i in 0..self.nodes.len() {
            let before = self.nodes[i].state();
            if self.nodes[i].off_until.is_some() {
                continue;
            }
            if i == self.nav {
                let (tec, rec) = (self.nodes[i].tec, self.nodes[i].rec);
                events.push((
                    at,
                    ErrorFrame::bus_error(prot::BIT0, prot::LOC_SOF, tec, rec),
                ));
                self.nav_errors += 1;
            }
            if i == sender {
                self.nodes[i].tec = self.nodes[i].tec.saturating_add(rise.max(256));
                self.nodes[i].failed += 1;
            } else {
                self.nodes[i].rec = (self.nodes[i].rec + rise).min(255);
            }
            let n = &mut self.nodes[i];
            n.max_tec = n.max_tec.max(n.tec);
            if n.tec > 255 {
                self.bus_off(i, at + 256 * bit, to, events);
            } else if n.state() != before && i == self.nav {
                let (tec, rec) = (n.tec, n.rec);
                let when = at + 128 * bit;
                events.push((when, ErrorFrame::state_change(n.state(), tec, rec)));
            }
        }
        self.free_ns = self.free_ns.max(to);
        true
    }

    /// Node `i` goes bus-off at `at`: its queue is lost; it takes part again 128 x 11 bits after
    /// `quiet_from` (the bus is recessive again).
    fn bus_off(
        &mut self,
        i: usize,
        at: u64,
        quiet_from: u64,
        events: &mut Vec<(u64, wire::errframe::ErrorFrame)>,
    ) {
        let recovery = self.bits_ns(BUS_OFF_RECOVERY_BITS);
        let n = &mut self.nodes[i];
        n.lost_off += n.queue.len() as u64;
        n.queue.clear();
        n.bus_offs += 1;
        n.off_until = Some(quiet_from.max(at) + recovery);
        if i == self.nav {
            let (tec, rec) = (n.tec, n.rec);
            events.push((
                at,
                wire::errframe::ErrorFrame::state_change(
                    wire::errframe::ErrorState::BusOff,
                    tec,
                    rec,
                ),
            ));
        }
    }

    /// A disturbance or a faulty transmitter corrupts node `i`'s frame starting at `start`.
    fn corrupts(&mut self, i: usize, start: u64) -> bool {
        let name = self.nodes[i].name;
        let t = start as f64 * 1e-9;
        if self
            .timing
            .faults
            .tx_faults
            .iter()
            .any(|f| f.node == name && t >= f.from_s && t < f.to_s)
        {
            return true;
        }
        for (w, next) in self
            .timing
            .faults
            .disturbed_s
            .iter()
            .zip(self.next_corruption.iter_mut())
        {
            let to = ns(w[1]);
            if *next < to && start >= *next {
                let every = (1e9 / w[2].max(1e-3)).round().max(1.0) as u64;
                while *next <= start {
                    *next += every;
                }
                return true;
            }
        }
        false
    }

    /// Node `i`'s frame starting at `start` (`bits` long) is cut by an error frame: the sender's
    /// transmit counter +8, every other node's receive counter +1; the frame stays first in
    /// its queue to be sent again, unless its sender went bus-off.
    fn fail(
        &mut self,
        i: usize,
        start: u64,
        (bits, data): (u32, u32),
        events: &mut Vec<(u64, wire::errframe::ErrorFrame)>,
    ) {
        use wire::errframe::prot;
        self.corrupted += 1;
        let end = start + self.bits_ns(bits / 2 + ERROR_FRAME_BITS) + self.data_ns(data / 2);
        self.free_ns = end;
        self.first_ns.get_or_insert(start);
        self.last_ns = self.last_ns.max(end);
        self.busy_ns += end - start;
        let at = start + self.bits_ns(bits / 2) + self.data_ns(data / 2);
        // nav's controller reports the error it sent (a bit error) or saw (a stuff error)
        let kind = if i == self.nav {
            prot::BIT | prot::TX
        } else {
            prot::STUFF
        };
        self.confine(i, at, end, Some(kind), events, |n, sender| {
            if sender {
                n.tec += 8;
                n.failed += 1;
                n.max_tec = n.max_tec.max(n.tec);
            } else {
                n.rec = (n.rec + 1).min(255);
            }
        });
    }

    /// Fault confinement after a frame of `sender`'s: `update` changes each node's counters
    /// (told whether it is the sender); a node past 255 goes bus-off at `off_at`; nav's
    /// controller reports the bus error `bus_error` (a protocol error type) and any change of
    /// its state, at `at`.
    fn confine(
        &mut self,
        sender: usize,
        at: u64,
        off_at: u64,
        bus_error: Option<u8>,
        events: &mut Vec<(u64, wire::errframe::ErrorFrame)>,
        update: impl Fn(&mut Node<F>, bool),
    ) {
        use wire::errframe::{ErrorFrame, prot};
        for j in 0..self.nodes.len() {
            if self.nodes[j].off_until.is_some() {
                continue;
            }
            let before = self.nodes[j].state();
            update(&mut self.nodes[j], j == sender);
            let n = &self.nodes[j];
            let (tec, rec, now) = (n.tec, n.rec, n.state());
            if j == self.nav
                && let Some(kind) = bus_error
            {
                events.push((at, ErrorFrame::bus_error(kind, prot::LOC_DATA, tec, rec)));
                self.nav_errors += 1;
            }
            if tec > 255 {
                self.bus_off(j, off_at, off_at, events);
            } else if now != before && j == self.nav {
                events.push((at, ErrorFrame::state_change(now, tec, rec)));
            }
        }
    }

    /// Node `i`'s frame was over at `end` without error: its transmit counter -1, every other
    /// node's receive counter -1 (from error-passive: back to 119..127, here 120).
    fn succeeded(
        &mut self,
        i: usize,
        end: u64,
        events: &mut Vec<(u64, wire::errframe::ErrorFrame)>,
    ) {
        if self.timing.faults.is_empty() {
            return;
        }
        self.confine(i, end, end, None, events, |n, sender| {
            if sender {
                n.tec = n.tec.saturating_sub(1);
            } else if n.rec > 127 {
                n.rec = 120;
            } else {
                n.rec = n.rec.saturating_sub(1);
            }
        });
    }

    /// Frames of the devices (every node but nav's) lost so far: to a full queue, to a bus-off.
    pub fn lost_device_frames(&self) -> u64 {
        self.nodes
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != self.nav)
            .map(|(_, n)| n.overflow + n.lost_off)
            .sum()
    }

    /// What the bus did so far.
    pub fn stats(&self) -> BusStats {
        let span = self.last_ns.saturating_sub(self.first_ns.unwrap_or(0));
        let ids = self
            .ids
            .values()
            .map(|s| {
                let data_rate = self
                    .timing
                    .data_bitrate_bps
                    .unwrap_or(self.timing.bitrate_bps);
                IdTiming {
                    id: s.id,
                    extended: s.extended,
                    name: s.name.clone(),
                    sender: s.sender.to_string(),
                    frames: s.frames,
                    load: if span > 0 {
                        let nominal =
                            s.bits as f64 / self.timing.bitrate_bps / (span as f64 * 1e-9);
                        if s.data_bits == 0 {
                            nominal
                        } else {
                            nominal + s.data_bits as f64 / data_rate / (span as f64 * 1e-9)
                        }
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
                .filter(|n| n.sent + n.overflow + n.lost_off + n.failed > 0)
                .map(|n| NodeTiming {
                    name: n.name.to_string(),
                    sent: n.sent,
                    overflow: n.overflow,
                    deepest: n.deepest as u64,
                    failed: n.failed,
                    bus_offs: n.bus_offs,
                    lost_bus_off: n.lost_off,
                    max_tx_errors: n.max_tec,
                    state: format!("{:?}", n.state()),
                })
                .collect(),
            round_trip: RoundTrip::default(),
            corrupted: self.corrupted,
            stuck_ms: self.stuck_ns as f64 * 1e-6,
            nav_error_frames: self.nav_errors,
            unseen_by_nav: 0,
        }
    }
}

/// Hand on the error frames raised by `until_ns`, in time order.
fn flush_events<F: BusFrame>(
    bus: &mut CanBus<F>,
    events: &mut Vec<(u64, wire::errframe::ErrorFrame)>,
    until_ns: u64,
    out: &mut impl FnMut(&mut CanBus<F>, Delivered<F>),
) {
    if events.is_empty() {
        return;
    }
    events.sort_by_key(|e| e.0);
    let n = events.iter().take_while(|e| e.0 <= until_ns).count();
    for (t_ns, frame) in events.drain(..n) {
        out(bus, Delivered::Error { t_ns, frame });
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
    pub id: u32,
    /// A 29-bit identifier.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub extended: bool,
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
    /// Its transmissions cut by an error frame.
    #[serde(default)]
    pub failed: u64,
    /// Times it went bus-off.
    #[serde(default)]
    pub bus_offs: u64,
    /// Frames lost to its bus-off (its queue, and what it was given meanwhile).
    #[serde(default)]
    pub lost_bus_off: u64,
    /// Its largest transmit error counter.
    #[serde(default)]
    pub max_tx_errors: u16,
    /// Its error state at the end.
    #[serde(default)]
    pub state: String,
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
    /// Transmissions cut by an error frame (disturbance, faulty transmitter).
    #[serde(default)]
    pub corrupted: u64,
    /// Time the bus was stuck dominant, ms.
    #[serde(default)]
    pub stuck_ms: f64,
    /// Error frames nav's controller raised (bus errors, state changes, bus-off, restarts).
    #[serde(default)]
    pub nav_error_frames: u64,
    /// Devices' frames nav's controller did not take (it was bus-off).
    #[serde(default)]
    pub unseen_by_nav: u64,
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
        everything(bus, limit, false).0
    }

    /// The frames and nav's error frames up to `limit`.
    fn everything(
        bus: &mut CanBus,
        limit: u64,
        complete_by: bool,
    ) -> (Vec<OnBus>, Vec<(u64, wire::errframe::ErrorFrame)>) {
        let (mut got, mut errors) = (Vec::new(), Vec::new());
        bus.run(limit, complete_by, |_, d| match d {
            Delivered::Frame(f) => got.push(f),
            Delivered::Error { t_ns, frame } => errors.push((t_ns, frame)),
        });
        (got, errors)
    }

    fn faulty(faults: PhysicalFaults) -> CanBus {
        CanBus::new(BusTiming {
            faults,
            ..BusTiming::default()
        })
    }

    /// Two IMU frames every 0.5 ms and a NAV_TIME every 20 ms for `seconds`.
    fn traffic(
        bus: &mut CanBus,
        seconds: f64,
    ) -> (Vec<OnBus>, Vec<(u64, wire::errframe::ErrorFrame)>) {
        let (mut frames, mut errors) = (Vec::new(), Vec::new());
        for k in 0..(seconds * 2000.0) as u64 {
            let t = k * 500_000;
            bus.queue(t, frame(0x080));
            bus.queue(t, frame(0x081));
            if k % 40 == 0 {
                bus.queue(t, frame(0x200));
            }
            let (f, e) = everything(bus, t + 500_000, true);
            frames.extend(f);
            errors.extend(e);
        }
        (frames, errors)
    }

    fn node<'a>(s: &'a BusStats, name: &str) -> &'a NodeTiming {
        s.nodes.iter().find(|n| n.name == name).unwrap()
    }

    #[test]
    fn a_disturbed_harness_cuts_frames_that_are_sent_again_and_nav_reports_each_error() {
        let mut bus = faulty(PhysicalFaults {
            disturbed_s: vec![[0.1, 0.2, 100.0]],
            ..Default::default()
        });
        let (frames, errors) = traffic(&mut bus, 0.3);
        let s = bus.stats();
        // ten corruptions, each frame sent again: nothing lost
        assert_eq!(s.corrupted, 10);
        assert_eq!(frames.iter().filter(|f| f.frame.id == 0x080).count(), 600);
        assert_eq!(bus.lost_device_frames(), 0);
        // nav (a receiver) saw ten bus errors, its receive counter up by one each, down again
        let bus_errors: Vec<_> = errors
            .iter()
            .filter(|e| e.1.class & wire::errframe::class::BUSERROR != 0)
            .collect();
        assert_eq!(bus_errors.len(), 10);
        assert!(bus_errors.iter().all(|e| e.1.counters() == Some((0, 1))));
        assert!(errors.windows(2).all(|w| w[0].0 <= w[1].0));
        assert!(node(&s, "IMU").failed + node(&s, "NAV").failed == 10);
    }

    #[test]
    fn a_faulty_transmitter_goes_error_passive_then_bus_off_and_recovers_after_128_by_11_bits() {
        let mut bus = faulty(PhysicalFaults {
            tx_faults: vec![TxFault {
                node: "NAV".into(),
                from_s: 0.06,
                to_s: 0.065,
            }],
            ..Default::default()
        });
        let (frames, errors) = traffic(&mut bus, 0.1);
        let states: Vec<_> = errors.iter().filter_map(|e| e.1.state()).collect();
        use wire::errframe::ErrorState as E;
        // 16 failures: warning at 96 was passed on the way (12), passive at 128, bus-off
        // past 255 (32), then the restart
        assert_eq!(
            states,
            [E::Warning, E::Passive, E::BusOff, E::Active],
            "{errors:?}"
        );
        let off = errors
            .iter()
            .find(|e| e.1.state() == Some(E::BusOff))
            .unwrap()
            .0;
        let back = errors
            .iter()
            .find(|e| e.1.class & wire::errframe::class::RESTARTED != 0)
            .unwrap()
            .0;
        assert_eq!(back - off, 1408 * 1000, "128 x 11 bits at 1 Mbit/s");
        // while nav's controller was off the bus it took no frame
        assert!(frames.iter().any(|f| !f.nav_receives));
        assert!(
            frames
                .iter()
                .filter(|f| !f.nav_receives)
                .all(|f| f.end_ns > off && f.end_ns <= back + 300_000)
        );
        let s = bus.stats();
        assert_eq!((node(&s, "NAV").bus_offs, node(&s, "NAV").failed), (1, 32));
    }

    #[test]
    fn a_stuck_dominant_bus_passes_nothing_and_puts_the_sender_bus_off() {
        let mut bus = faulty(PhysicalFaults {
            stuck_dominant_s: vec![[0.02, 0.03]],
            ..Default::default()
        });
        let (frames, errors) = traffic(&mut bus, 0.05);
        assert!(
            !frames
                .iter()
                .any(|f| f.start_ns > 20_000_000 && f.start_ns < 30_000_000)
        );
        let s = bus.stats();
        assert!((s.stuck_ms - 10.0).abs() < 0.2, "{s:?}");
        // the IMU was about to send: bus-off, its queue lost, the queue full meanwhile
        assert_eq!(node(&s, "IMU").bus_offs, 1);
        assert!(bus.lost_device_frames() > 0);
        // nav, a receiver: a bus error, error-passive, and back to active on the frames after
        use wire::errframe::ErrorState as E;
        let states: Vec<_> = errors.iter().filter_map(|e| e.1.state()).collect();
        assert_eq!(states.first(), Some(&E::Passive), "{errors:?}");
        assert_eq!(states.last(), Some(&E::Active), "{errors:?}");
    }

    #[test]
    fn a_babbling_node_takes_the_bus_and_the_others_queues_overflow() {
        let mut bus = faulty(PhysicalFaults {
            babbling_s: vec![[0.01, 0.02, 1.0]],
            ..Default::default()
        });
        let (frames, _) = traffic(&mut bus, 0.03);
        let babble = frames.iter().filter(|f| f.frame.id == 0x001).count();
        // back to back for 10 ms: about 80 frames of 8 bytes at 1 Mbit/s
        assert!((70..=95).contains(&babble), "{babble}");
        let s = bus.stats();
        assert!(node(&s, "IMU").overflow > 0, "{s:?}");
        // the IMU goes on after it
        assert!(
            frames
                .iter()
                .any(|f| f.frame.id == 0x080 && f.start_ns > 21_000_000)
        );
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
        let over = everything(&mut bus, 5 * d, true).0;
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
