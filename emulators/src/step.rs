//! The order in which the bench's devices act, written once: each IMU sample's frames and the
//! turntable's frames due after that sample, through the bus model ([`crate::bus::model`]: on the
//! ideal bus in that order, on the modelled bus in the order they complete, nav's frames taking
//! bus time among them), then the GPS receiver's epochs due by the sample's end; and what the
//! devices make of nav's frames (NAV_TIME places the frames nav sent before it on the bus; a
//! turntable command reaches the mechanism when it is over). Pure: no I/O, no wall time.
//!
//! The bus scheduler ([`crate::adapters::scheduler::run`]) puts each [`Step`] on vcan and the pty; the
//! in-process runs feed it to nav's pipeline directly. Both call [`Stepper::step`] and
//! [`Stepper::from_nav`], so the order nav meets its inputs in is the same on both, by
//! construction.
//!
//! **The receiver's bytes enter after the frames of the sample they are due at, and before
//! any later frame.** On the bus the scheduler writes them once that sample's frames are on
//! vcan, and holds the IMU stream until nav has read them; nav takes every frame already
//! received before bytes it has read (`nav`'s event loop). In process they go into the
//! pipeline right after the sample's frames.

use crate::bus::model::{BusStats, CanBus, Delivered, RoundTrip, ns};
use crate::gps::{Epoch, GpsReceiver};
use crate::imu::stream::BusStream;
use crate::turntable::ttbus::TtBus;
use std::collections::{BTreeMap, VecDeque};
use wire::{Message, RawFrame};

/// What one IMU sample brings, in the order nav meets it.
#[derive(Debug, Default)]
pub struct Step {
    /// The sample's index (0-based).
    pub k: u64,
    /// Simulated time at its end, s.
    pub t: f64,
    /// The devices' frames that go on the bus from the sample's end until the next one's, in
    /// the order the bus model puts them there: the IMU's (with any injected), the turntable's.
    pub frames: Vec<RawFrame>,
    /// How many of `frames` are the turntable's.
    pub turntable_frames: usize,
    /// Error frames nav's controller raises in this step: before which of `frames` each goes
    /// (its index; `frames.len()`: after them), when (ns), the frame.
    pub errors: Vec<(usize, u64, wire::errframe::ErrorFrame)>,
    /// Everything on the bus model in this step, nav's frames and the error frames of nav's
    /// controller included, at its time (ns): the bus's own log on the simulated clock.
    pub trace: Vec<(u64, Traced)>,
    /// Frames of the devices were lost on the bus in this step (a full queue, a node bus-off,
    /// nav's controller bus-off): nav cannot confirm their samples.
    pub lost: bool,
    /// The sample was deliberately not sent (a fault): nav cannot confirm it.
    pub dropped: bool,
    /// The IMU stops sending at this sample (a `stop_s` fault begins): before anything more
    /// reaches nav, its watchdog reports the stop. On the bus the scheduler holds the stream
    /// until nav's NAV_TIME says so; in process the watchdog's change goes into the pipeline
    /// here. Either way nav's watchdog fires once per stop, right after the last sample before
    /// it, whatever the host's pace.
    pub stop_begins: bool,
    /// The receiver's epochs due by the sample's end, after its frames.
    pub epochs: Vec<Epoch>,
}

/// An entry of the bus's log ([`Step::trace`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Traced {
    /// A frame over on the bus.
    Frame(RawFrame),
    /// An error frame of nav's controller.
    Error(wire::errframe::ErrorFrame),
}

/// What a frame from nav meant to the devices.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FromNav {
    /// A NAV_TIME: nav has processed this sample; it confirms this many bytes from the
    /// receiver (12 bits), and placed this many turntable commands.
    Confirmed {
        /// The sample.
        sample: u64,
        /// Its imu_timeout health bit (nav's watchdog has fired).
        imu_timeout: bool,
        /// NAV_TIME's `GpsRxBytes`.
        gps_rx_bytes: u16,
        /// Commands placed in time by it.
        placed: u64,
    },
    /// A NAV_TIME that names no sample sent.
    Unplaced,
    /// A turntable command (waiting for the next NAV_TIME, or at the next sample).
    Command,
    /// A frame no device takes (a TT_CMD without a turntable, an undecodable frame).
    Unexpected,
    /// Anything else nav sends (its solution's other frames).
    Other,
}

/// The scenario's devices on the IMU clock.
pub struct Stepper {
    imu: BusStream,
    tt: Option<TtBus>,
    gps: Option<GpsReceiver>,
    duration_s: f64,
    msgs: Vec<Message>,
    scratch: Vec<RawFrame>,
    in_stop: bool,
    procedure_end: Option<ProcedureEnd>,
    bus: CanBus,
    nav: NavFrames,
    /// Devices' frames on the bus that nav's controller did not take (it was bus-off).
    unseen: u64,
    /// Error frames nav's controller raised.
    error_frames: u64,
}

/// nav's frames on their way to the bus model: sent, placed by a NAV_TIME, queued.
struct NavFrames {
    /// Samples after a NAV_TIME's sample that the frames before it go on the bus.
    latency: u64,
    /// Frames nav sent since its last NAV_TIME (which places them).
    waiting: Vec<RawFrame>,
    /// Frames placed, and the sample at whose end they go on the bus.
    placed: VecDeque<(u64, RawFrame)>,
    /// Turntable commands on the bus and not yet answered: sequence number, when queued (ns).
    unanswered: Vec<(u8, u64)>,
    /// Command to acknowledgement, ns -> commands.
    round_trip: BTreeMap<u64, u64>,
}

/// The stream's end when nav's procedure is over ([`Stepper::end_with_procedure`]).
#[derive(Debug, Clone, Copy)]
struct ProcedureEnd {
    /// Samples after the NAV_TIME that says so.
    margin: u64,
    /// A NAV_TIME has shown a procedure running.
    seen: bool,
    /// The last sample to send.
    last: Option<u64>,
}

impl Stepper {
    /// The IMU stream `imu`, the turntable `tt` and the receiver `gps` for `duration_s` of
    /// simulated time, on `bus`. In lockstep, the frames nav sends before a NAV_TIME go on the
    /// bus `latency` samples after that NAV_TIME's sample (at least the lockstep's window, so
    /// that they never change what was already sent).
    pub fn new(
        imu: BusStream,
        tt: Option<TtBus>,
        gps: Option<GpsReceiver>,
        duration_s: f64,
        bus: CanBus,
        latency: u64,
    ) -> Self {
        Self {
            imu,
            tt,
            gps,
            duration_s,
            msgs: Vec::new(),
            scratch: Vec::new(),
            in_stop: false,
            procedure_end: None,
            bus,
            unseen: 0,
            error_frames: 0,
            nav: NavFrames {
                latency,
                waiting: Vec::new(),
                placed: VecDeque::new(),
                unanswered: Vec::new(),
                round_trip: BTreeMap::new(),
            },
        }
    }

    /// End the stream when nav's procedure on the mechanism (north-finding, a calibration) is
    /// over, as nav's NAV_TIME says it (its mode leaves north-finding, the gyrocompass, levelling and
    /// calibrating after it has shown one), `margin` samples after the sample that NAV_TIME
    /// names. The end is then a point of the data, not of the moment somebody read nav's
    /// report: with `margin` at least the lockstep's window the scheduler has never sent past
    /// it when it learns of it, at any pace, and the in-process run ends at the same sample.
    pub fn end_with_procedure(mut self, margin: u64) -> Self {
        self.procedure_end = Some(ProcedureEnd {
            margin,
            seen: false,
            last: None,
        });
        self
    }

    /// The scenario's time is not over yet, nor nav's procedure (when the stream ends with it).
    pub fn running(&self) -> bool {
        self.imu.next_time() <= self.duration_s + 1e-9
            && self
                .procedure_end
                .and_then(|p| p.last)
                .is_none_or(|last| self.next_index() <= last)
    }

    /// Simulated time at the end of the next sample, s.
    pub fn next_time(&self) -> f64 {
        self.imu.next_time()
    }

    /// The next sample's index.
    pub fn next_index(&self) -> u64 {
        self.imu.imu().next_index()
    }

    /// The IMU's stream.
    pub fn imu(&self) -> &BusStream {
        &self.imu
    }

    /// The turntable, when there is one.
    pub fn turntable(&self) -> Option<&TtBus> {
        self.tt.as_ref()
    }

    /// The turntable, when there is one.
    pub fn turntable_mut(&mut self) -> Option<&mut TtBus> {
        self.tt.as_mut()
    }

    /// The scenario's duration, s.
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// Simulated time the receiver puts out its next epoch (none without a receiver).
    pub fn next_epoch_time(&self) -> Option<f64> {
        self.gps.as_ref().map(GpsReceiver::next_write_time)
    }

    /// One IMU sample: its frames, the turntable's after it, the epochs due by its end.
    ///
    /// At the sample's end the IMU queues its frames on the bus, and nav's frames placed there
    /// are queued too; what is over on the bus by then reaches the other nodes (on the ideal
    /// bus: everything queued, at once); the turntable's controller queues its frames due then;
    /// the bus runs to the next sample's end, and every frame over by then is on the bus in
    /// this step, in the bus's order. A turntable command reaches the mechanism when it is
    /// over, and its acknowledgement is queued then.
    pub fn step(&mut self, out: &mut Step) {
        out.k = self.imu.imu().next_index();
        out.t = self.imu.next_time();
        out.frames.clear();
        out.epochs.clear();
        out.errors.clear();
        out.trace.clear();
        out.turntable_frames = 0;
        let lost_before = self.bus.lost_device_frames() + self.unseen;
        let now = ns(out.t);
        while self.nav.placed.front().is_some_and(|p| p.0 <= out.k) {
            let Some((_, f)) = self.nav.placed.pop_front() else {
                break;
            };
            // a frame lost to nav's full queue is counted by the bus
            if self.bus.queue(now, f)
                && let Ok(Message::TtCmd(c)) = Message::decode(&f)
            {
                self.nav.unanswered.push((c.seq, now));
            }
        }
        let dropped = self.imu.stats.dropped_samples;
        self.scratch.clear();
        self.imu.next_frames(&mut self.scratch);
        for f in &self.scratch {
            // a frame lost to the IMU's full queue is counted by the bus
            self.bus.queue(now, *f);
        }
        out.dropped = self.imu.stats.dropped_samples > dropped;
        let stopped = out.dropped && self.imu.stopped_at(out.t);
        out.stop_begins = stopped && !self.in_stop;
        self.in_stop = stopped;
        self.run_bus((now, out.t), out);
        if let Some(tt) = self.tt.as_mut() {
            self.msgs.clear();
            tt.after_sample(out.k, out.t, &mut self.msgs);
            for m in &self.msgs {
                if let Ok(f) = m.encode()
                    && self.bus.queue(now, f)
                {
                    tt.sent(m);
                }
            }
        }
        let next = self.imu.next_time();
        self.run_bus((ns(next), next), out);
        out.lost = self.bus.lost_device_frames() + self.unseen > lost_before;
        if let Some(g) = self.gps.as_mut() {
            while let Some(e) = g.poll(out.t, self.duration_s) {
                out.epochs.push(e);
            }
        }
    }

    /// The bus until `limit` (ns, and the same in s): every frame over by then, the devices'
    /// into `out`, nav's commands to the mechanism (whose answers go on the bus at once).
    fn run_bus(&mut self, limit: (u64, f64), out: &mut Step) {
        let Self {
            bus,
            tt,
            nav,
            msgs,
            unseen,
            error_frames,
            ..
        } = self;
        bus.run(limit.0, true, |b, d| {
            let f = match d {
                Delivered::Frame(f) => f,
                Delivered::Error { t_ns, frame } => {
                    *error_frames += 1;
                    out.trace.push((t_ns, Traced::Error(frame)));
                    out.errors.push((out.frames.len(), t_ns, frame));
                    return;
                }
            };
            out.trace.push((f.end_ns, Traced::Frame(f.frame)));
            let m = Message::decode(&f.frame);
            if b.node_name(f.node) == "NAV" {
                if let (Ok(Message::TtCmd(c)), Some(tt)) = (m, tt.as_mut()) {
                    // the sample's own time on the ideal bus (no rounding through ns)
                    let t = if f.end_ns == limit.0 {
                        limit.1
                    } else {
                        f.end_ns as f64 * 1e-9
                    };
                    msgs.clear();
                    tt.receive(t, c, msgs);
                    for m in msgs.iter() {
                        if let Ok(a) = m.encode()
                            && b.queue(f.end_ns, a)
                        {
                            tt.sent(m);
                        }
                    }
                }
                return;
            }
            if !f.nav_receives {
                // nav's controller is bus-off: the frame is on the bus, not in nav's socket
                *unseen += 1;
                return;
            }
            out.frames.push(f.frame);
            if wire::spec_for_id(f.frame.id).is_some_and(|s| s.sender == "TT") {
                out.turntable_frames += 1;
            }
            if let Ok(Message::TtAck(a)) = m
                && let Some(i) = nav.unanswered.iter().position(|u| u.0 == a.seq)
            {
                let (_, queued) = nav.unanswered.remove(i);
                *nav.round_trip.entry(f.end_ns - queued).or_default() += 1;
            }
        });
    }

    /// A frame nav sent, to the devices and the bus model. `lockstep`: it waits for the next
    /// NAV_TIME, which places it (and the frames before it) the lockstep's latency after its
    /// sample; otherwise it goes on the bus at the next sample.
    pub fn from_nav(&mut self, f: RawFrame, lockstep: bool) -> FromNav {
        let m = Message::decode(&f);
        let next = self.imu.imu().next_index();
        if lockstep {
            self.nav.waiting.push(f);
        } else {
            self.nav.placed.push_back((next, f));
        }
        match m {
            Ok(Message::NavTime(nt)) => {
                let Some(k) = nav_time_sample(self.imu.imu(), nt.sample_count) else {
                    return FromNav::Unplaced;
                };
                let mut placed = 0;
                if lockstep {
                    let at = k + self.nav.latency;
                    for f in self.nav.waiting.drain(..) {
                        placed += u64::from(f.id == wire::tt_cmd::SPEC.id);
                        self.nav.placed.push_back((at, f));
                    }
                }
                if self.tt.is_none() {
                    placed = 0;
                }
                if let Some(p) = self.procedure_end.as_mut() {
                    use wire::NavMode as M;
                    let running = matches!(
                        nt.mode,
                        M::NorthFinding | M::Gyrocompass | M::Levelling | M::Calibrating
                    );
                    p.seen |= running;
                    if p.seen && !running && p.last.is_none() {
                        p.last = Some(k + p.margin);
                    }
                }
                FromNav::Confirmed {
                    sample: k,
                    imu_timeout: nt.health.imu_timeout,
                    gps_rx_bytes: nt.gps_rx_bytes,
                    placed,
                }
            }
            Ok(Message::TtCmd(_)) if self.tt.is_none() => FromNav::Unexpected,
            Ok(Message::TtCmd(_)) => FromNav::Command,
            Ok(_) => FromNav::Other,
            Err(_) => FromNav::Unexpected,
        }
    }

    /// What the bus model did so far.
    pub fn bus_stats(&self) -> BusStats {
        let mut s = self.bus.stats();
        s.unseen_by_nav = self.unseen;
        s.nav_error_frames = self.error_frames;
        s.round_trip = RoundTrip::of(&self.nav.round_trip);
        s
    }

    /// The stream is over: whether nav's watchdog is still to report it. The end of the stream
    /// is an IMU stop like any other, so nav's watchdog fires once after the last sample on the
    /// bus and in process alike, before nav is stopped, whatever the host's pace (else the time
    /// from the last sample to nav's SIGTERM, wall time, would decide whether it fires). No:
    /// when the stream already ends in a stop (reported where it began), or when no gyro frame
    /// ever went out (nav's watchdog watches a stream that has begun).
    pub fn end_awaits_watchdog(&self) -> bool {
        !self.in_stop && self.imu.stats.gyro_frames > 0
    }

    /// The devices back, at the end: the IMU stream and the turntable.
    pub fn into_parts(self) -> (BusStream, Option<TtBus>) {
        (self.imu, self.tt)
    }
}

/// The IMU sample (0-based index) a NAV_TIME's `sample_count` names: the latest sample already
/// sent whose 16-bit counter it matches. None before any sample went out.
pub fn nav_time_sample(imu: &crate::imu::ImuEmulator, sample_count: u32) -> Option<u64> {
    let newest = imu.next_index().checked_sub(1)?;
    let back = u64::from(imu.sample_counter(newest).wrapping_sub(sample_count as u16));
    newest.checked_sub(back)
}
