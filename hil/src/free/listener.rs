//! The bench's ear on the bus in a free-running run: every frame but the IMU's stream, decoded
//! by the DBC only. The device under test's solution epochs (NAV_TIME and the frames of its
//! Seq), each NAV_TIME tied to the IMU sample it names and the instant that sample went on the
//! bus (or, for a sample not sent yet, the instant it is due); its turntable commands counted;
//! every frame outside the DBC counted and named.
//!
//! Frames are taken in the order of their kernel receive stamps, not of their reads: vcan hands
//! a sender's frames to the receive queue of the CPU it is on, so a device that moves between
//! CPUs on a loaded host can be heard out of order; the stamp is taken as the frame is queued,
//! in the order it was sent. Frames wait [`REORDER_WINDOW`] for a later-read, earlier-stamped
//! one. Where the adapter stamps in hardware the card says so; vcan's are the kernel's.

use crate::free::score::Epoch;
use anyhow::{Context, Result};
use emulators::adapters::freerun::SentSamples;
use emulators::imu::Oscillator;
use socketcan::{CanAnyFrame, CanFdSocket, CanFrame, Socket, SocketOptions};
use std::collections::{BTreeMap, BinaryHeap};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};
use wire::{Message, NavHealth};

/// How long a frame waits for one stamped before it and read after it, s.
pub const REORDER_WINDOW: f64 = 0.2;

/// What the bench has heard so far.
#[derive(Debug, Default)]
pub struct Observed {
    /// The device's solution epochs, in the order they came.
    pub epochs: Vec<Epoch>,
    /// Frames outside the DBC: an identifier it does not define, a length or a value its
    /// layout refuses, an extended or remote frame; by what they were.
    pub outside_dbc: BTreeMap<String, u64>,
    /// TT_CMD frames on the bus (the device under test commanding the table).
    pub commands: u64,
    /// Bytes the device says it took from the receiver (NAV_TIME's GpsRxBytes, 12 bits,
    /// accumulated), and the last value seen.
    pub receiver_bytes: u64,
    last_rx_bytes: Option<u16>,
    /// Where the frames' times came from (the card says it).
    pub stamps: Stamps,
    /// Frames heard in another order than their stamps' (put back in order).
    pub reordered: u64,
    /// On a lab's contract: the device's protected frames checked (alive counter, checksum).
    pub protected_checked: u64,
    /// Their faults, by message and kind, with the first of each in words.
    pub protection_faults: BTreeMap<String, (u64, String)>,
    /// On a lab's contract: the last time tag, unwrapped to a sample count.
    last_tag: Option<u64>,
    /// On a lab's contract: the device's alive counters as last heard.
    guard: wire::mapping::Guard,
}

/// Where the times of the frames the bench hears come from.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Stamps {
    /// Nothing heard yet.
    #[default]
    None,
    /// The kernel's software receive stamps (SO_TIMESTAMPNS): vcan, or an adapter without
    /// hardware stamps.
    Kernel,
    /// The adapter's hardware stamps were present (not used: the order and the times are the
    /// kernel's, on the host's clock).
    Hardware,
    /// The socket gave no stamps: the times are those of the reads.
    Read,
}

impl Stamps {
    /// In words, for the card.
    pub fn words(self) -> &'static str {
        match self {
            Stamps::None => "no frames heard",
            Stamps::Kernel => "the kernel's software receive stamps (vcan has no hardware stamps)",
            Stamps::Hardware => {
                "the kernel's receive stamps (the adapter's hardware stamps are present, on its own clock: not used)"
            }
            Stamps::Read => "the bench's reads (the socket gave no receive stamps)",
        }
    }
}

impl Observed {
    /// Frames outside the DBC, in all.
    pub fn outside_count(&self) -> u64 {
        self.outside_dbc.values().sum()
    }
}

/// The names of the health bits set.
fn health_names(h: &NavHealth) -> Vec<String> {
    [
        (h.imu_timeout, "imu_timeout"),
        (h.imu_gaps, "imu_gaps"),
        (h.imu_bit, "imu_bit"),
        (h.gps_stale, "gps_stale"),
        (h.turntable, "turntable"),
        (h.filter, "filter"),
        (h.gps_data, "gps_data"),
        (h.can_bus, "can_bus"),
    ]
    .into_iter()
    .filter(|(on, _)| *on)
    .map(|(_, n)| n.to_string())
    .collect()
}

/// A socket on `iface` that hears classic and CAN FD frames, with the kernel's receive stamps
/// (and the adapter's, where it has them): on our contract everything but the IMU's stream
/// (0x080-0x09F); on a lab's, everything (its IMU's frames are dropped as they are read).
pub fn open(iface: &str, lab: bool) -> Result<CanFdSocket> {
    use socketcan::timestamp as ts;
    let sock = CanFdSocket::open(iface).with_context(|| format!("listening on {iface}"))?;
    if !lab {
        sock.set_filters(&[socketcan::CanFilter::new_inverted(0x080, 0x7E0)])
            .with_context(|| format!("filters on {iface}"))?;
    }
    // a socket without stamps is still heard (by the reads' times, said on the card)
    let _ = sock.set_recv_timestamp(true);
    let _ = sock.set_timestamping(
        ts::SOF_TIMESTAMPING_RX_HARDWARE
            | ts::SOF_TIMESTAMPING_RAW_HARDWARE
            | ts::SOF_TIMESTAMPING_OPT_CMSG,
    );
    sock.set_read_timeout(Duration::from_millis(20))
        .with_context(|| format!("read timeout on {iface}"))?;
    Ok(sock)
}

/// Frames held until no earlier-stamped one can still come: ordered by stamp (ns), then by
/// the order they were read.
#[derive(Debug, Default)]
pub struct Reorder {
    held: BinaryHeap<Waiting>,
    reads: u64,
    newest: Option<i128>,
    /// Frames read after one stamped later than them.
    pub reordered: u64,
}

/// A frame in [`Reorder`], first out the earliest stamp (then the earliest read).
#[derive(Debug)]
struct Waiting {
    stamp: i128,
    read: u64,
    held: Held,
}

impl PartialEq for Waiting {
    fn eq(&self, o: &Self) -> bool {
        (self.stamp, self.read) == (o.stamp, o.read)
    }
}
impl Eq for Waiting {}
impl PartialOrd for Waiting {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Waiting {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        // the heap's top is its greatest: the earliest
        (o.stamp, o.read).cmp(&(self.stamp, self.read))
    }
}

/// A frame waiting in [`Reorder`]: its time and what it was.
#[derive(Debug, Clone, PartialEq)]
pub struct Held {
    /// The frame's time, ns since the origin.
    pub at_ns: i128,
    /// The frame.
    pub frame: HeldFrame,
}

/// A frame as read: in the DBC's form, or what it was when it is none.
#[derive(Debug, Clone, PartialEq)]
pub enum HeldFrame {
    /// A data frame in the DBC's form.
    Raw(wire::RawFrame),
    /// A data frame of a lab's contract: its identifier and its data.
    Mapped(wire::dbc::FrameId, Vec<u8>),
    /// A frame outside the DBC, in words.
    Outside(String),
}

impl Reorder {
    /// A frame stamped `stamp_ns` (ns since the run's origin, on the host's clock).
    pub fn push(&mut self, stamp_ns: i128, frame: Held) {
        if self.newest.is_some_and(|n| stamp_ns < n) {
            self.reordered += 1;
        }
        self.newest = Some(self.newest.map_or(stamp_ns, |n| n.max(stamp_ns)));
        self.reads += 1;
        self.held.push(Waiting {
            stamp: stamp_ns,
            read: self.reads,
            held: frame,
        });
    }

    /// Frames held.
    pub fn len(&self) -> usize {
        self.held.len()
    }

    /// Nothing held.
    pub fn is_empty(&self) -> bool {
        self.held.is_empty()
    }

    /// The next frame stamped at or before `until_ns` (no frame stamped before it can still
    /// come: the window has passed), or the next of any (`all`: the end).
    pub fn pop(&mut self, until_ns: i128, all: bool) -> Option<Held> {
        if !all && self.held.peek()?.stamp > until_ns {
            return None;
        }
        self.held.pop().map(|w| w.held)
    }
}

/// A frame in the DBC's form, or what it was: none for a controller's error frame or a frame
/// `lab` ignores (its IMU's stream).
fn held_frame(f: &CanAnyFrame, lab: Option<&LabEar>) -> Option<HeldFrame> {
    use socketcan::EmbeddedFrame;
    let classic = match f {
        CanAnyFrame::Normal(d) => CanFrame::Data(*d),
        CanAnyFrame::Remote(r) => CanFrame::Remote(*r),
        CanAnyFrame::Error(e) => CanFrame::Error(*e),
        CanAnyFrame::Fd(d) => {
            return match lab {
                Some(lab) => lab.held(d.id(), d.data()),
                None => Some(HeldFrame::Outside(format!(
                    "a CAN FD frame ({} bytes)",
                    d.data().len()
                ))),
            };
        }
    };
    if let (Some(lab), CanFrame::Data(d)) = (lab, &classic) {
        return lab.held(d.id(), d.data());
    }
    match wire::from_can_frame(&classic) {
        Ok(r) => Some(HeldFrame::Raw(r)),
        // a controller's error frame is no device's message
        Err(wire::FrameConvError::Error(_)) => None,
        Err(e) => Some(HeldFrame::Outside(format!("{e}"))),
    }
}

/// The bench's ear on a lab's contract: its DBC, the mapping's solution and protection, the
/// IMU's messages it does not listen to, the table's command message it counts.
pub struct LabEar {
    /// The lab's DBC.
    pub contract: wire::dbc::Contract,
    /// Its mapping.
    pub mapping: wire::mapping::Mapping,
    /// The DBC's file name, for the card.
    pub dbc_name: String,
    /// The mapping file.
    pub path: std::path::PathBuf,
    ignored: Vec<wire::dbc::FrameId>,
    device_sends: Vec<String>,
    /// The IMU's sample counter's width, bits: a time tag is placed at no more (a device that
    /// joined the stream late knows the sample no better than the counter tells it).
    counter_bits: Option<u16>,
}

impl std::fmt::Debug for LabEar {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "LabEar({})", self.dbc_name)
    }
}

impl LabEar {
    /// The ear of `contract` through `mapping`, read from the file at `path`.
    pub fn new(
        contract: wire::dbc::Contract,
        mapping: wire::mapping::Mapping,
        path: std::path::PathBuf,
    ) -> Self {
        let dbc_name = mapping.file.dbc.clone();
        let f = &mapping.file;
        let mut ignored = Vec::new();
        if let Some(imu) = &f.imu {
            for n in [Some(&imu.gyro.message), Some(&imu.accel.message)]
                .into_iter()
                .chain([imu.status.as_ref().map(|s| &s.message)])
                .flatten()
            {
                ignored.extend(contract.message(n).map(|m| m.id));
            }
        }
        let counter_bits = f.imu.as_ref().and_then(|imu| {
            let n = imu.gyro.counter.as_deref()?;
            Some(contract.message(&imu.gyro.message)?.signal(n)?.len)
        });
        let mut device_sends: Vec<String> = Vec::new();
        if let Some(t) = &f.turntable {
            device_sends.push(t.command.clone());
        }
        if let Some(s) = &f.solution {
            device_sends.push(s.message.clone());
            device_sends.extend(s.position.as_ref().map(|p| p.message.clone()));
            device_sends.extend(s.velocity.as_ref().map(|v| v.message.clone()));
        }
        Self {
            contract,
            mapping,
            dbc_name,
            path,
            ignored,
            device_sends,
            counter_bits,
        }
    }

    /// A data frame heard: none for the IMU's stream.
    fn held(&self, id: socketcan::Id, data: &[u8]) -> Option<HeldFrame> {
        let id = match id {
            socketcan::Id::Standard(x) => wire::dbc::FrameId::Standard(x.as_raw()),
            socketcan::Id::Extended(x) => wire::dbc::FrameId::Extended(x.as_raw()),
        };
        (!self.ignored.contains(&id)).then(|| HeldFrame::Mapped(id, data.to_vec()))
    }

    /// A frame of the lab's contract into what was heard: outside its DBC counted; the
    /// device's protected frames checked; its table commands counted; its solution's parts
    /// into epochs.
    fn take(
        &self,
        o: &mut Observed,
        id: wire::dbc::FrameId,
        data: &[u8],
        rx_s: f64,
        place: &Place,
    ) {
        use wire::mapping::SolutionPart;
        let Some(m) = self.contract.by_id(id) else {
            *o.outside_dbc
                .entry(format!("{id}: not in {}", self.dbc_name))
                .or_default() += 1;
            return;
        };
        if self.device_sends.contains(&m.name) {
            o.guard.check(&self.mapping, m, data);
            o.protected_checked = o.guard.checked;
            let faults: Vec<_> = o.guard.faults.drain(..).collect();
            for f in faults {
                let kind = match &f {
                    wire::mapping::ProtectionFault::Checksum { .. } => "checksum wrong",
                    wire::mapping::ProtectionFault::Skipped { .. } => "alive counter skipped",
                };
                let e = o
                    .protection_faults
                    .entry(format!("{} {id}: {kind}", m.name))
                    .or_insert_with(|| (0, f.to_string()));
                e.0 += 1;
            }
        }
        if self
            .mapping
            .file
            .turntable
            .as_ref()
            .is_some_and(|t| t.command == m.name)
        {
            o.commands += 1;
        }
        let Some(sol) = &self.mapping.file.solution else {
            return;
        };
        let part = match wire::mapping::SolutionReader::new(sol).read(m, data) {
            Ok(Some(p)) => p,
            Ok(None) => return,
            Err(e) => {
                *o.outside_dbc
                    .entry(format!("{} {id}: {e}", m.name))
                    .or_default() += 1;
                return;
            }
        };
        let last = o.epochs.len().checked_sub(1);
        match part {
            SolutionPart::Epoch {
                tag,
                tag_bits,
                mode,
                att,
                heading_sigma,
            } => {
                let count = unwrap_tag(o.last_tag, tag, tag_bits);
                o.last_tag = Some(count);
                let bits = self.counter_bits.map_or(tag_bits, |c| c.min(tag_bits));
                let named = place.named_bits(tag, bits);
                o.epochs.push(Epoch {
                    sample_count: count as u32,
                    seq: o.epochs.len() as u8,
                    mode,
                    health: Vec::new(),
                    rx_s,
                    sample: named.map(|(k, at, _)| (k, at)),
                    scheduled: named.is_some_and(|n| n.2),
                    att,
                    vel: None,
                    pos: None,
                    hgt: heading_sigma.map(|s| [0.0, 0.0, s]),
                });
            }
            SolutionPart::Position {
                lat_lon,
                height,
                sigma,
            } => {
                if let Some(e) = last.map(|i| &mut o.epochs[i]) {
                    e.pos = Some(lat_lon);
                    let h = e.hgt.get_or_insert([0.0, 0.0, f64::NAN]);
                    h[0] = height.unwrap_or(0.0);
                    h[1] = sigma.unwrap_or(0.0);
                }
            }
            SolutionPart::Velocity(v) => {
                if let Some(e) = last.map(|i| &mut o.epochs[i]) {
                    e.vel = Some(v);
                }
            }
        }
    }
}

/// A time tag of `bits` bits as a sample count, unwrapped against the last (the nearer way
/// round).
fn unwrap_tag(last: Option<u64>, tag: u64, bits: u16) -> u64 {
    let Some(last) = last else { return tag };
    if bits >= 63 {
        return tag;
    }
    let span = 1u64 << bits;
    let d = tag.wrapping_sub(last) & (span - 1);
    if d < span / 2 {
        last + d
    } else {
        last.saturating_sub(span - d)
    }
}

/// The clocks the bench times a run with: the host's monotonic `origin` and the wall clock the
/// kernel stamps with, tied at one instant.
#[derive(Debug, Clone, Copy)]
struct Clocks {
    wall_at_origin_ns: i128,
}

impl Clocks {
    fn new(origin: Instant) -> Self {
        let wall = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        let now = Instant::now();
        let since = if now >= origin {
            now.duration_since(origin).as_nanos() as i128
        } else {
            -(origin.duration_since(now).as_nanos() as i128)
        };
        Self {
            wall_at_origin_ns: wall - since,
        }
    }

    /// A wall-clock stamp in ns since the origin.
    fn since_origin_ns(&self, wall: SystemTime) -> i128 {
        wall.duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128)
            - self.wall_at_origin_ns
    }
}

/// Listen on `sock` until `stop`, into `seen`; times in s since `origin`. `clock`: the IMU's
/// oscillator (when a sample not sent yet is due).
pub fn listen(
    sock: CanFdSocket,
    origin: Instant,
    clock: Oscillator,
    sent: &SentSamples,
    seen: &Mutex<Observed>,
    stop: &AtomicBool,
    lab: Option<&LabEar>,
) -> Result<()> {
    let clocks = Clocks::new(origin);
    let mut order = Reorder::default();
    let window_ns = (REORDER_WINDOW * 1e9) as i128;
    let place = Place {
        origin,
        clock,
        sent,
    };
    let mut stamps = Stamps::None;
    loop {
        let stopping = stop.load(Ordering::Relaxed);
        if !stopping {
            match sock.read_frame_with_timestamps() {
                Ok((f, ts)) => {
                    let read_ns = origin.elapsed().as_nanos() as i128;
                    let at_ns = ts
                        .socket
                        .or(ts.sw)
                        .map_or(read_ns, |w| clocks.since_origin_ns(w));
                    stamps = match (ts.hw, ts.socket.or(ts.sw)) {
                        (Some(_), _) => Stamps::Hardware,
                        (None, Some(_)) => Stamps::Kernel,
                        (None, None) => Stamps::Read,
                    };
                    if let Some(frame) = held_frame(&f, lab) {
                        order.push(at_ns, Held { at_ns, frame });
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::Interrupted
                    ) => {}
                Err(e) => return Err(e).context("reading the bus"),
            }
        }
        // a frame waits for the window on the host's clock (its stamps' clock): a quiet bus
        // releases what it holds
        let now_ns = origin.elapsed().as_nanos() as i128;
        let mut o = seen.lock().unwrap_or_else(|e| e.into_inner());
        o.stamps = stamps;
        o.reordered = order.reordered;
        while let Some(h) = order.pop(now_ns - window_ns, stopping) {
            take_held(&mut o, h, &place, lab);
        }
        if stopping {
            return Ok(());
        }
    }
}

/// How a NAV_TIME's named sample is placed.
struct Place<'a> {
    origin: Instant,
    clock: Oscillator,
    sent: &'a SentSamples,
}

impl Place<'_> {
    /// The sample whose counter is `counter`: its index, the instant it went on the bus (or is
    /// due, s since the origin) and whether it had not gone out when placed.
    fn named(&self, counter: u16) -> Option<(u64, f64, bool)> {
        self.named_bits(u64::from(counter), 16)
    }

    /// [`Place::named`] for a counter of `bits` bits.
    fn named_bits(&self, counter: u64, bits: u16) -> Option<(u64, f64, bool)> {
        let (k, at) = self.sent.place_bits(counter, bits)?;
        Some(match at {
            Some(at) => (
                k,
                at.saturating_duration_since(self.origin).as_secs_f64(),
                false,
            ),
            // due at its sample time on the origin's clock (the IMU's sample k ends at tick k + 1)
            None => (k, self.clock.tick_time(k + 1), true),
        })
    }
}

/// A held frame into what was heard.
fn take_held(o: &mut Observed, h: Held, place: &Place, lab: Option<&LabEar>) {
    let rx_s = h.at_ns as f64 * 1e-9;
    let raw = match h.frame {
        HeldFrame::Outside(what) => {
            *o.outside_dbc.entry(what).or_default() += 1;
            return;
        }
        HeldFrame::Mapped(id, data) => {
            if let Some(lab) = lab {
                lab.take(o, id, &data, rx_s, place);
            }
            return;
        }
        HeldFrame::Raw(r) => r,
    };
    let m = match Message::decode(&raw) {
        Ok(m) => m,
        Err(e) => {
            let what = match wire::spec_for_id(raw.id) {
                Some(s) => format!("{} (0x{:03X}): {e}", s.name, raw.id),
                None => format!("0x{:03X}: not in the DBC", raw.id),
            };
            *o.outside_dbc.entry(what).or_default() += 1;
            return;
        }
    };
    take(o, m, rx_s, place);
}

/// A decoded frame into what was heard.
fn take(o: &mut Observed, m: Message, rx_s: f64, place: &Place) {
    let same = |o: &mut Observed, seq: Option<u8>| -> Option<usize> {
        let i = o.epochs.len().checked_sub(1)?;
        seq.is_none_or(|s| o.epochs[i].seq == s).then_some(i)
    };
    match m {
        Message::NavTime(t) => {
            if let Some(prev) = o.last_rx_bytes {
                o.receiver_bytes += u64::from(t.gps_rx_bytes.wrapping_sub(prev) & 0xFFF);
            }
            o.last_rx_bytes = Some(t.gps_rx_bytes);
            let named = place.named(t.sample_count as u16);
            o.epochs.push(Epoch {
                sample_count: t.sample_count,
                seq: t.seq,
                mode: t.mode,
                health: health_names(&t.health),
                rx_s,
                sample: named.map(|(k, at, _)| (k, at)),
                scheduled: named.is_some_and(|n| n.2),
                att: None,
                vel: None,
                pos: None,
                hgt: None,
            });
        }
        Message::NavAtt(a) => {
            if let Some(i) = same(o, Some(a.seq)) {
                o.epochs[i].att = Some([a.heading_deg, a.pitch_deg, a.roll_deg]);
            }
        }
        Message::NavVel(v) => {
            if let Some(i) = same(o, Some(v.seq)) {
                o.epochs[i].vel = Some(v.enu_mps);
            }
        }
        // NAV_POS has no Seq: it belongs to the epoch whose NAV_VEL came last
        Message::NavPos(p) => {
            if let Some(i) = same(o, None).filter(|i| o.epochs[*i].vel.is_some()) {
                o.epochs[i].pos = Some([p.lat_deg, p.lon_deg]);
            }
        }
        Message::NavHgt(h) => {
            if let Some(i) = same(o, Some(h.seq)) {
                o.epochs[i].hgt = Some([h.height_m, h.pos_sigma_m, h.heading_sigma_deg]);
            }
        }
        Message::TtCmd(_) => o.commands += 1,
        _ => {}
    }
}

/// Listen in a thread of its own.
pub fn spawn(
    sock: CanFdSocket,
    origin: Instant,
    clock: Oscillator,
    sent: Arc<SentSamples>,
    seen: Arc<Mutex<Observed>>,
    stop: Arc<AtomicBool>,
    lab: Option<Arc<LabEar>>,
) -> Result<std::thread::JoinHandle<Result<()>>> {
    std::thread::Builder::new()
        .name("observer".into())
        .spawn(move || listen(sock, origin, clock, &sent, &seen, &stop, lab.as_deref()))
        .context("starting the bus observer")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn held(at_ns: i128, what: &str) -> Held {
        Held {
            at_ns,
            frame: HeldFrame::Outside(what.into()),
        }
    }

    fn name(h: Held) -> String {
        match h.frame {
            HeldFrame::Outside(w) => w,
            HeldFrame::Raw(r) => format!("{:03X}", r.id),
            HeldFrame::Mapped(id, _) => id.to_string(),
        }
    }

    /// The judge's ear on the example lab contract, without a bus: the device's heading frame
    /// opens an epoch placed at the sample its tag names (at the IMU counter's 12 bits), its
    /// position frame fills it; a frame with its CRC spoiled and one whose alive counter skips
    /// are named by message and kind; an identifier outside the lab's DBC is counted; the
    /// bench's own IMU frames are not heard at all.
    #[test]
    fn the_ear_on_a_labs_contract_reads_the_solution_and_names_protection_faults() {
        let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let path = here.join("../wire/contracts/lab-imu.toml");
        let (c, m) = crate::scenario::lab_contract::load(&path).expect("the example");
        let ear = LabEar::new(c.clone(), m.clone(), path);
        let sent = SentSamples::new(10_000);
        let place = Place {
            origin: Instant::now(),
            clock: Oscillator::nominal(1000.0),
            sent: &sent,
        };
        let mut protector = wire::mapping::Protector::new(&m);
        let heading = c.message("INS_HEADING").expect("heading");
        let position = c.message("INS_POSITION").expect("position");
        let enc = |p: &mut wire::mapping::Protector,
                   msg: &wire::dbc::MessageLayout,
                   v: &[(&str, f64)]| {
            let mut d = msg.encode(v).expect("encodes");
            p.protect(msg, &mut d).expect("protects");
            d
        };
        let hd = |tag: f64| {
            [
                ("Mode", 5.0),
                ("Heading", 90.5),
                ("HeadingSigma", 0.2),
                ("TimeTag", tag),
            ]
        };
        let mut o = Observed::default();
        let take = |o: &mut Observed, id, data: Vec<u8>| {
            if let Some(h) = ear.held(id, &data) {
                take_held(o, Held { at_ns: 0, frame: h }, &place, Some(&ear));
            }
        };
        let ext = |id: wire::dbc::FrameId| match id {
            wire::dbc::FrameId::Extended(x) => {
                socketcan::Id::Extended(socketcan::ExtendedId::new(x).expect("29 bits"))
            }
            wire::dbc::FrameId::Standard(x) => {
                socketcan::Id::Standard(socketcan::StandardId::new(x).expect("11 bits"))
            }
        };
        // samples 0 to 5000 on the bus; the device names 4100 (its 16-bit tag)
        for k in 0..=5000u64 {
            sent.push(k, k as u16, Instant::now());
        }
        let p = &mut protector;
        take(&mut o, ext(heading.id), enc(p, heading, &hd(4100.0)));
        let at = [
            ("Latitude", 28.2),
            ("Longitude", 112.9),
            ("PositionSigma", 3.5),
        ];
        take(&mut o, ext(position.id), enc(p, position, &at));
        assert_eq!(o.epochs.len(), 1);
        let e = &o.epochs[0];
        assert_eq!(
            (e.sample.map(|s| s.0), e.mode),
            (Some(4100), wire::NavMode::Navigation)
        );
        assert!(e.att.is_some_and(|a| (a[0] - 90.5).abs() < 0.01));
        assert!(
            e.hgt
                .is_some_and(|h| (h[1] - 3.5).abs() < 1e-9 && (h[2] - 0.2).abs() < 1e-4)
        );
        assert!(e.pos.is_some_and(|p| (p[0] - 28.2).abs() < 1e-6));
        // a spoiled CRC, then a frame whose alive counter skips one
        let mut bad = enc(p, heading, &hd(4120.0));
        bad[3] ^= 1;
        take(&mut o, ext(heading.id), bad);
        let _ = enc(p, heading, &hd(4140.0));
        take(&mut o, ext(heading.id), enc(p, heading, &hd(4160.0)));
        let kinds: Vec<&String> = o.protection_faults.keys().collect();
        assert_eq!(
            kinds,
            [
                "INS_HEADING 0x18FE3001 (extended): alive counter skipped",
                "INS_HEADING 0x18FE3001 (extended): checksum wrong"
            ],
            "{:?}",
            o.protection_faults
        );
        assert_eq!(o.protected_checked, 4);
        // outside the DBC, and the bench's own IMU block (not heard)
        take(
            &mut o,
            ext(wire::dbc::FrameId::Extended(0x1234_5678)),
            vec![0; 8],
        );
        let gyro = c.message("IMU_GYRO_BLOCK").expect("gyro");
        assert!(ear.held(ext(gyro.id), &[0; 64]).is_none());
        assert_eq!(o.outside_count(), 1, "{:?}", o.outside_dbc);
        assert_eq!(o.epochs.len(), 3);
    }

    /// A lab's time tag of any width unwraps to a sample count the nearer way round.
    #[test]
    fn a_labs_time_tag_unwraps_to_a_sample_count() {
        assert_eq!(unwrap_tag(None, 4000, 12), 4000);
        assert_eq!(unwrap_tag(Some(4090), 5, 12), 4101);
        assert_eq!(unwrap_tag(Some(4101), 4090, 12), 4090);
        assert_eq!(unwrap_tag(Some(65_530), 20, 16), 65_556);
        assert_eq!(unwrap_tag(Some(7), 1u64 << 40, 63), 1u64 << 40);
    }

    /// Frames read out of their stamps' order come out in it, once no earlier one can come.
    #[test]
    fn frames_come_out_in_their_stamps_order() {
        let mut r = Reorder::default();
        r.push(100, held(100, "a"));
        r.push(300, held(300, "c"));
        // read after c, stamped before it: heard out of order
        r.push(200, held(200, "b"));
        r.push(300, held(300, "d"));
        assert_eq!(r.reordered, 1);
        assert_eq!(r.len(), 4);
        // the window has passed the first two only
        assert_eq!(r.pop(250, false).map(name).as_deref(), Some("a"));
        assert_eq!(r.pop(250, false).map(name).as_deref(), Some("b"));
        assert!(r.pop(250, false).is_none());
        // at the end everything, same stamps in the order they were read
        assert_eq!(r.pop(0, true).map(name).as_deref(), Some("c"));
        assert_eq!(r.pop(0, true).map(name).as_deref(), Some("d"));
        assert!(r.pop(0, true).is_none() && r.is_empty());
    }
}
