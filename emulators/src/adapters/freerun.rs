//! Free-running devices: one emulated device on its own, paced by the host's clock with
//! absolute deadlines, as hardware runs: it waits for nobody.
//!
//! This is the other mode beside the lockstep of [`crate::bus`]. A device under test the bench
//! does not pace (another build, another team's box, a board on `can0`) meets emulators that
//! behave like the hardware they stand in for: the IMU sends every sample at its time, the
//! turntable's controller answers commands and reports its status at its rate, the receiver
//! writes its epochs at their PPS edges. Nothing here reads what the device under test says.
//!
//! What the bench can promise in this mode is measured, not assumed: every sample, tick and
//! epoch has a due instant on the host's clock (`origin + t / speed`) and the instant its write
//! returned, and their difference is the bench's own **lateness** ([`Lateness`]), kept apart
//! from anything the device under test does. When the host cannot keep real time (a sample
//! later than the limit), the device stops and says so ([`FreeStats::behind`]) rather than
//! feed a device under test a stream whose timing is the host's fault.
//!
//! The models are the same pure ones the lockstep bench steps ([`crate::imu::stream::BusStream`],
//! [`crate::turntable::ttbus::TtBus`], [`crate::gps::GpsReceiver`]); only the pacing and the transport are
//! here. An IMU on a table the bench does not model follows the table's reports
//! ([`crate::reported`]).

use crate::adapters::clock::SimClock;
use crate::adapters::pty::{GpsPty, PtyError};
use crate::adapters::scheduler::{bench_socket, drain, drain_stamped};
use crate::adapters::transport::{CanTxError, Progress, write_all};
use crate::gps::GpsReceiver;
use crate::imu::stream::{BusStream, TxStats};
use crate::reported::{ReportStats, SharedTrack};
use crate::turntable::ttbus::{TtBus, TurntableTxStats};
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use thiserror::Error;
use wire::{Message, RawFrame};

/// How a free-running device is paced.
#[derive(Debug, Clone, Copy)]
pub struct Pacing {
    /// The host instant of simulated time 0 (devices started apart share it to share a clock).
    pub origin: Instant,
    /// Simulated seconds per second of the host's clock (1: real time).
    pub speed: f64,
    /// Simulated time to run to, s (infinite: until stopped).
    pub until_s: f64,
    /// The bench's lateness beyond which it stops: it cannot keep real time.
    pub max_late: Duration,
    /// The IMU's frames go out in one write per this period, each sample's at most this much
    /// after its time (zero: each sample's at its own time). See [`IMU_WRITE_PERIOD`].
    pub imu_write_period: Duration,
}

/// The IMU's write period of a free-running bench: 1 ms, two samples of a 2 kHz IMU per write.
/// In a software-emulated guest each write, and each wake-up of every reader it causes, costs
/// tens of microseconds: at one write per sample the stream alone took most of a CPU, and a
/// device under test as much again. A sample goes out at most 1 ms after its time, which the
/// bench's lateness figures include.
pub const IMU_WRITE_PERIOD: Duration = Duration::from_millis(1);

impl Pacing {
    pub(crate) fn clock(&self) -> SimClock {
        SimClock::starting_at(self.origin, self.speed)
    }
}

/// The kernel's receive stamps (ns of the UNIX clock) on a pacing's simulated clock: a frame
/// enters the model at the time it reached the bench, not at the time the bench's thread got
/// round to reading it (under load a thread woken 30 ms late reads three 100 Hz reports at once;
/// taken at one instant they made the table turn 20 times its rate, beyond the gyros' range).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Stamps {
    /// The UNIX clock at simulated time 0, ns.
    unix_at_origin_ns: i128,
    speed: f64,
}

impl Stamps {
    /// Tie the UNIX clock to `p`'s origin, now.
    pub(crate) fn new(p: &Pacing) -> Self {
        let unix = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        let now = Instant::now();
        let since = if now >= p.origin {
            now.duration_since(p.origin).as_nanos() as i128
        } else {
            -(p.origin.duration_since(now).as_nanos() as i128)
        };
        Self {
            unix_at_origin_ns: unix - since,
            speed: p.speed,
        }
    }

    /// The simulated time of a frame stamped `stamp_ns` and read at `now` (s): the stamp's,
    /// unless there is none or it is not within a second before the read (the UNIX clock was
    /// stepped): then the read's.
    pub(crate) fn at(&self, stamp_ns: Option<u64>, now: f64) -> f64 {
        let Some(ns) = stamp_ns else { return now };
        let t = (i128::from(ns) - self.unix_at_origin_ns) as f64 * 1e-9 * self.speed;
        if t <= now && now - t < self.speed {
            t
        } else {
            now
        }
    }
}

/// Free-running failures.
#[derive(Debug, Error)]
pub enum FreeError {
    /// CAN trouble.
    #[error(transparent)]
    Can(#[from] CanTxError),
    /// The receiver's pty.
    #[error("GPS receiver: {0}")]
    Gps(#[from] PtyError),
}

/// When each IMU sample went on the bus: its index, its 16-bit counter (what a device under
/// test names in NAV_TIME), and the host's instant its write began. The newest `capacity`
/// samples are kept (a device's latency is measured against them).
#[derive(Debug)]
pub struct SentSamples {
    ring: std::sync::Mutex<std::collections::VecDeque<(u64, u16, Instant)>>,
    capacity: usize,
}

impl SentSamples {
    /// Keep the newest `capacity` samples.
    pub fn new(capacity: usize) -> Self {
        Self {
            ring: std::sync::Mutex::new(std::collections::VecDeque::with_capacity(capacity)),
            capacity: capacity.max(1),
        }
    }

    /// Sample `k`, its counter `counter`, went on the bus at `at` (the oldest kept is dropped
    /// when the ring is full).
    pub fn push(&self, k: u64, counter: u16, at: Instant) {
        let mut r = self.ring.lock().unwrap_or_else(|e| e.into_inner());
        if r.len() == self.capacity {
            r.pop_front();
        }
        r.push_back((k, counter, at));
    }

    /// The newest sample sent whose counter is `counter` (the low 16 bits of a NAV_TIME's
    /// SampleCount): its index and when it went on the bus. None when no such sample is kept.
    pub fn find(&self, counter: u16) -> Option<(u64, Instant)> {
        let r = self.ring.lock().unwrap_or_else(|e| e.into_inner());
        let &(_, newest, _) = r.back()?;
        let back = usize::from(newest.wrapping_sub(counter));
        let i = r.len().checked_sub(1 + back)?;
        let (k, c, at) = r[i];
        (c == counter).then_some((k, at))
    }

    /// Where the sample whose counter is `counter` stands: `(index, Some(instant it went on
    /// the bus))` for one sent and kept, `(index, None)` for one not sent yet (ahead of the
    /// newest by less than half the counter's period). A counter is read as the nearer of the
    /// two: behind the newest by less than half the period (32,768 samples), else ahead of it.
    /// None before any sample, or for one behind by more than is kept.
    pub fn place(&self, counter: u16) -> Option<(u64, Option<Instant>)> {
        self.place_bits(u64::from(counter), 16)
    }

    /// [`SentSamples::place`] for a counter of `bits` bits (a lab's time tag: its low 16 bits
    /// where it is wider, the half period 2^(bits - 1) where it is narrower).
    pub fn place_bits(&self, counter: u64, bits: u16) -> Option<(u64, Option<Instant>)> {
        let bits = bits.clamp(1, 16);
        let mask = (1u64 << bits) - 1;
        let counter = counter & mask;
        let r = self.ring.lock().unwrap_or_else(|e| e.into_inner());
        let &(newest_k, newest, _) = r.back()?;
        let back = u64::from(newest).wrapping_sub(counter) & mask;
        if back > mask / 2 {
            let ahead = counter.wrapping_sub(u64::from(newest)) & mask;
            return Some((newest_k + ahead, None));
        }
        let i = r.len().checked_sub(1 + usize::try_from(back).ok()?)?;
        let (k, c, at) = r[i];
        (u64::from(c) & mask == counter).then_some((k, Some(at)))
    }

    /// The newest sample sent: its index and counter.
    pub fn newest(&self) -> Option<(u64, u16)> {
        let r = self.ring.lock().unwrap_or_else(|e| e.into_inner());
        r.back().map(|&(k, c, _)| (k, c))
    }
}

/// Width of a bin of [`Lateness`], µs.
const BIN_US: f64 = 10.0;
/// Bins: lateness up to 100 ms is binned, beyond it counted in the last bin (its maximum exact).
const BINS: usize = 10_000;

/// The bench's own lateness: for each write, the host's instant its write returned minus the
/// instant it was due. A histogram of 10 µs bins (bounded memory for runs of hours) and the
/// exact worst.
#[derive(Debug, Clone)]
pub struct Lateness {
    bins: Vec<u64>,
    count: u64,
    max_ms: f64,
    over_1ms: u64,
}

impl Default for Lateness {
    fn default() -> Self {
        Self {
            bins: vec![0; BINS],
            count: 0,
            max_ms: 0.0,
            over_1ms: 0,
        }
    }
}

/// Lateness in figures.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct LatenessSummary {
    /// Writes measured.
    pub count: u64,
    /// Median, ms (to the 10 µs bin's upper edge).
    pub p50_ms: f64,
    /// 99th percentile, ms.
    pub p99_ms: f64,
    /// Worst, ms (exact).
    pub max_ms: f64,
    /// Writes more than 1 ms late.
    pub over_1ms: u64,
}

impl Lateness {
    /// A write `late` after its due instant.
    pub fn add(&mut self, late: Duration) {
        let us = late.as_secs_f64() * 1e6;
        let i = ((us / BIN_US) as usize).min(BINS - 1);
        self.bins[i] += 1;
        self.count += 1;
        self.max_ms = self.max_ms.max(us * 1e-3);
        self.over_1ms += u64::from(us > 1000.0);
    }

    /// The figures.
    pub fn summary(&self) -> LatenessSummary {
        let at = |q: f64| {
            if self.count == 0 {
                return 0.0;
            }
            let want = ((self.count as f64) * q).ceil().max(1.0) as u64;
            let mut seen = 0;
            for (i, n) in self.bins.iter().enumerate() {
                seen += n;
                if seen >= want {
                    return ((i + 1) as f64 * BIN_US * 1e-3).min(self.max_ms);
                }
            }
            self.max_ms
        };
        LatenessSummary {
            count: self.count,
            p50_ms: at(0.5),
            p99_ms: at(0.99),
            max_ms: self.max_ms,
            over_1ms: self.over_1ms,
        }
    }
}

/// What a free-running device did.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FreeStats {
    /// `imu`, `turntable`, `gps`.
    pub device: String,
    /// The interface or the device path it wrote to.
    pub port: String,
    /// Speed over real time.
    pub speed: f64,
    /// Simulated time reached, s.
    pub reached_s: f64,
    /// Wall time it ran, s.
    pub wall_s: f64,
    /// Frames (or NMEA bytes, for the receiver) written.
    pub written: u64,
    /// The bench's own lateness.
    pub lateness: LatenessSummary,
    /// It stopped because the host could not keep real time: what was late, and by how much.
    pub behind: Option<String>,
    /// The IMU's stream.
    pub imu: Option<TxStats>,
    /// The turntable's frames.
    pub turntable: Option<TurntableTxStats>,
    /// The table reports an IMU followed, one per axis.
    pub followed: Vec<ReportStats>,
    /// The receiver's epochs.
    pub gps: Option<FreeGpsStats>,
}

/// What a free-running receiver wrote.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FreeGpsStats {
    /// Epochs written.
    pub epochs: u64,
    /// Epochs not written because nobody had the device open (a serial line loses them too).
    pub no_reader: u64,
    /// Epochs not written because the reader had left more than a few epochs unread.
    pub reader_behind: u64,
    /// Epochs the receiver puts out nothing (an outage, a port drop in the scenario).
    pub silent: u64,
}

/// Sleep until `t` is due on `clock`, in slices short enough to see `stop` (false: stopped).
pub(crate) fn sleep_until(clock: &SimClock, t: f64, stop: &AtomicBool) -> bool {
    let due = clock.wall_at(t);
    loop {
        if stop.load(Ordering::Relaxed) {
            return false;
        }
        let now = Instant::now();
        if now >= due {
            return true;
        }
        std::thread::sleep((due - now).min(Duration::from_millis(50)));
    }
}

/// Measure a write due at `t` that has just returned; the reason to stop when it is beyond the
/// limit.
pub(crate) fn measure(
    late: &mut Lateness,
    clock: &SimClock,
    t: f64,
    p: &Pacing,
    what: impl FnOnce() -> String,
) -> Option<String> {
    let l = Instant::now().saturating_duration_since(clock.wall_at(t));
    late.add(l);
    (l > p.max_late).then(|| {
        format!(
            "the host cannot keep real time at x{}: {} went out {:.1} ms after its time (limit {:.0} ms); stopped rather than feed a device under test a late stream",
            p.speed,
            what(),
            l.as_secs_f64() * 1e3,
            p.max_late.as_secs_f64() * 1e3
        )
    })
}

/// The IMU free-running on `iface`: each sample's frames at the sample's time (samples that
/// fell due together in one write). With `tracks` (one per table axis), it follows the table's
/// TT_STATUS reports on the bus (its truth turns as the table reported, [`crate::reported`]).
pub fn run_imu(
    iface: &str,
    mut stream: BusStream,
    tracks: &[SharedTrack],
    sent: Option<&SentSamples>,
    p: &Pacing,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<FreeStats, FreeError> {
    let ids: Vec<u16> = if tracks.is_empty() {
        Vec::new()
    } else {
        vec![wire::tt_status::SPEC.id]
    };
    let sock = bench_socket(iface, &ids)?;
    // a socket that cannot stamp gives the reports their read times
    if !tracks.is_empty()
        && let Err(e) = socketcan::SocketOptions::set_recv_timestamp(&sock, true)
    {
        tracing::warn!(
            "{iface}: no kernel receive times (SO_TIMESTAMPNS: {e}): the table's reports enter the IMU's truth when read"
        );
    }
    let stamps = Stamps::new(p);
    let clock = p.clock();
    let start = Instant::now();
    let mut late = Lateness::default();
    let mut frames: Vec<RawFrame> = Vec::with_capacity(wire::BATCH);
    let mut due: Vec<(u64, f64)> = Vec::new();
    let (mut written, mut behind) = (0u64, None);
    // the last sample of a write period is due when the write goes (never past the end)
    let hold =
        (p.imu_write_period.as_secs_f64() * p.speed - 1.0 / stream.imu().params().rate_hz).max(0.0);
    while behind.is_none() && stream.next_time() <= p.until_s {
        let wake = (stream.next_time() + hold).min(p.until_s);
        if !sleep_until(&clock, wake, stop) {
            break;
        }
        if !tracks.is_empty() {
            let now = clock.now();
            drain_stamped(&sock, iface, |f, stamp| {
                if let Some(Ok(Message::TtStatus(s))) = f.map(|f| Message::decode(&f))
                    && let Some(tr) = tracks.get(usize::from(s.axis))
                {
                    tr.lock().unwrap_or_else(|e| e.into_inner()).report(
                        stamps.at(stamp, now),
                        s.angle_deg,
                        s.faults.encoder,
                    );
                }
            })?;
        }
        // every sample due by now, in one write
        let now = clock.now();
        frames.clear();
        due.clear();
        loop {
            due.push((stream.imu().next_index(), stream.next_time()));
            stream.next_frames(&mut frames);
            if stream.next_time() > now.min(p.until_s) || frames.len() + 8 > wire::BATCH {
                break;
            }
        }
        // kept before the write: a device may answer before the write returns
        if let Some(s) = sent {
            let at = Instant::now();
            for &(k, _) in &due {
                s.push(k, stream.imu().sample_counter(k), at);
            }
        }
        let w = write_all(&sock, iface, &frames)?;
        written += frames.len() as u64 - w.lost_down;
        for &(k, t) in &due {
            behind = behind.or(measure(&mut late, &clock, t, p, || {
                format!("IMU sample {k}")
            }));
        }
        progress.set(stream.next_time());
    }
    Ok(FreeStats {
        device: "imu".into(),
        port: iface.into(),
        speed: p.speed,
        reached_s: stream.imu().last_time(),
        wall_s: start.elapsed().as_secs_f64(),
        written,
        lateness: late.summary(),
        behind,
        imu: Some(TxStats {
            frames: written,
            ..stream.stats
        }),
        followed: tracks
            .iter()
            .map(|t| t.lock().unwrap_or_else(|e| e.into_inner()).stats)
            .collect(),
        ..FreeStats::default()
    })
}

/// The turntable's controller free-running on `iface`, its loop at `tick_hz`: at each tick the
/// commands received since the last one (each acknowledged at once), then the mechanism moved
/// to the tick's time and its frames due (status at its rate). Its truth stays in `tt`.
pub fn run_turntable(
    iface: &str,
    tt: &mut TtBus,
    tick_hz: f64,
    p: &Pacing,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<FreeStats, FreeError> {
    let sock = bench_socket(iface, &[wire::tt_cmd::SPEC.id])?;
    let clock = p.clock();
    let start = Instant::now();
    let mut late = Lateness::default();
    let (mut msgs, mut out) = (Vec::new(), Vec::new());
    let (mut written, mut behind, mut k) = (0u64, None, 0u64);
    let mut bad = 0u64;
    loop {
        let t = (k + 1) as f64 / tick_hz;
        if behind.is_some() || t > p.until_s || !sleep_until(&clock, t, stop) {
            break;
        }
        // the commands since the last tick, taken at this tick (the controller's loop)
        out.clear();
        drain(&sock, iface, |f| match f.map(|f| Message::decode(&f)) {
            Some(Ok(Message::TtCmd(c))) => {
                msgs.clear();
                tt.receive(t, c, &mut msgs);
                out.append(&mut msgs);
            }
            _ => bad += 1,
        })?;
        tt.after_sample(k, t, &mut out);
        if !out.is_empty() {
            let frames: Vec<RawFrame> = out.iter().filter_map(|m| m.encode().ok()).collect();
            let w = write_all(&sock, iface, &frames)?;
            written += frames.len() as u64 - w.lost_down;
            for m in &out {
                tt.sent(m);
            }
            behind = measure(&mut late, &clock, t, p, || {
                format!("the turntable's tick at {t:.3} s")
            });
        }
        progress.set(t);
        k += 1;
    }
    tt.stats.bad_frames += bad;
    Ok(FreeStats {
        device: "turntable".into(),
        port: iface.into(),
        speed: p.speed,
        reached_s: k as f64 / tick_hz,
        wall_s: start.elapsed().as_secs_f64(),
        written,
        lateness: late.summary(),
        behind,
        turntable: Some(tt.stats),
        ..FreeStats::default()
    })
}

/// Bytes a reader may leave unread before epochs are no longer written (a few epochs' worth).
const UNREAD_LIMIT: usize = 2048;

/// The receiver free-running on `pty`: each epoch's sentences at its time, whoever reads them.
/// An epoch nobody has the device open for, or that a reader far behind would not take, is
/// counted and not written, as a serial line loses it.
pub fn run_gps(
    pty: &mut GpsPty,
    rx: &mut GpsReceiver,
    p: &Pacing,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<FreeStats, FreeError> {
    let clock = p.clock();
    let start = Instant::now();
    let mut late = Lateness::default();
    let mut st = FreeGpsStats::default();
    let (mut written, mut behind) = (0u64, None);
    while behind.is_none() {
        let t = rx.next_write_time();
        if t > p.until_s || !sleep_until(&clock, t, stop) {
            break;
        }
        while let Some(e) = rx.poll(t, p.until_s) {
            if e.port_drop.is_some() || e.text.is_empty() {
                st.silent += 1;
            } else if !pty.reader_attached() {
                st.no_reader += 1;
            } else if pty.unread().is_some_and(|n| n > UNREAD_LIMIT) {
                st.reader_behind += 1;
            } else {
                pty.write(e.text.as_bytes())?;
                written += e.text.len() as u64;
                st.epochs += 1;
                behind = behind.or(measure(&mut late, &clock, t, p, || {
                    format!("the epoch of {:.1} s", e.edge)
                }));
            }
        }
        progress.set(t);
    }
    Ok(FreeStats {
        device: "gps".into(),
        port: pty.path().into(),
        speed: p.speed,
        reached_s: clock.now().min(p.until_s),
        wall_s: start.elapsed().as_secs_f64(),
        written,
        lateness: late.summary(),
        behind,
        gps: Some(st),
        ..FreeStats::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_enters_at_its_kernel_stamp_not_at_its_read() {
        let p = Pacing {
            origin: Instant::now(),
            speed: 1.0,
            until_s: f64::INFINITY,
            max_late: Duration::from_millis(200),
            imu_write_period: IMU_WRITE_PERIOD,
        };
        let st = Stamps::new(&p);
        let unix_ns = |t: f64| (st.unix_at_origin_ns + (t * 1e9) as i128) as u64;
        // three reports 10 ms apart, read together 30 ms after the first
        for (i, t) in [5.000, 5.010, 5.020].into_iter().enumerate() {
            let at = st.at(Some(unix_ns(t)), 5.030);
            assert!((at - t).abs() < 1e-6, "report {i}: {at} for {t}");
        }
        // no stamp, a stamp from the future, one from long before the read: the read's time
        assert_eq!(st.at(None, 5.03), 5.03);
        assert_eq!(st.at(Some(unix_ns(5.2)), 5.03), 5.03);
        assert_eq!(st.at(Some(unix_ns(3.0)), 5.03), 5.03);
        // at x10 a stamp's wall seconds are ten simulated ones
        let fast = Stamps { speed: 10.0, ..st };
        let at = fast.at(Some(unix_ns(0.5)), 5.03);
        assert!((at - 5.0).abs() < 1e-6, "{at}");
    }

    #[test]
    fn a_sample_is_found_by_its_counter_across_the_wrap() {
        let s = SentSamples::new(100);
        let t = Instant::now();
        for k in 0..80u64 {
            s.push(k, (65_500 + k) as u16, t + Duration::from_micros(500 * k));
        }
        // the counter wraps between samples 35 (65,535) and 36 (0)
        assert_eq!(s.newest(), Some((79, 43)));
        assert_eq!(s.find(65_535).map(|x| x.0), Some(35));
        assert_eq!(s.find(0).map(|x| x.0), Some(36));
        assert_eq!(s.find(43).map(|x| x.0), Some(79));
        for k in 80..300u64 {
            s.push(k, (65_500 + k) as u16, t);
        }
        assert_eq!(s.find(200).map(|x| x.0), Some(236));
        // older than what is kept
        assert_eq!(s.find(100), None);
        // placed: kept, not sent yet (ahead of the newest), or behind what is kept
        assert_eq!(s.place(200).map(|x| x.0), Some(236));
        assert!(s.place(200).is_some_and(|x| x.1.is_some()));
        assert_eq!(s.place(263 + 5), Some((304, None)));
        assert_eq!(
            s.place(263u16.wrapping_add(0x7FFF)),
            Some((299 + 0x7FFF, None))
        );
        assert_eq!(s.place(100), None);
    }

    #[test]
    fn lateness_percentiles_come_from_the_histogram_and_the_worst_is_exact() {
        let mut l = Lateness::default();
        for us in 0..1000u64 {
            l.add(Duration::from_micros(us));
        }
        l.add(Duration::from_millis(250));
        let s = l.summary();
        assert_eq!(s.count, 1001);
        assert!((s.p50_ms - 0.5).abs() <= 0.011, "{s:?}");
        assert!((s.p99_ms - 0.99).abs() <= 0.011, "{s:?}");
        assert_eq!(s.max_ms, 250.0);
        assert_eq!(s.over_1ms, 1);
        assert_eq!(Lateness::default().summary(), LatenessSummary::default());
    }

    #[test]
    fn a_write_beyond_the_limit_says_the_host_cannot_keep_real_time() {
        let p = Pacing {
            origin: Instant::now() - Duration::from_millis(500),
            speed: 1.0,
            until_s: f64::INFINITY,
            max_late: Duration::from_millis(100),
            imu_write_period: Duration::ZERO,
        };
        let clock = p.clock();
        let mut l = Lateness::default();
        // due at 0.45 s of a clock started 0.5 s ago: 50 ms late, within the limit
        assert!(measure(&mut l, &clock, 0.45, &p, || "a".into()).is_none());
        // due at 0.1 s: 400 ms late
        let why = measure(&mut l, &clock, 0.1, &p, || "IMU sample 200".into());
        let why = why.expect("beyond the limit");
        assert!(
            why.contains("IMU sample 200") && why.contains("cannot keep real time"),
            "{why}"
        );
    }

    /// A 12-bit counter (a lab's time tag) places its sample the nearer way round, its low 16
    /// bits where it is wider.
    #[test]
    fn counters_of_other_widths_place_their_samples() {
        let s = SentSamples::new(100);
        let t0 = Instant::now();
        for k in 4050..4150u64 {
            s.push(k, k as u16, t0);
        }
        // 4149 is 53 mod 4096: 4100 is 4 mod 4096, 49 back
        assert_eq!(
            s.place_bits(4, 12).map(|(k, at)| (k, at.is_some())),
            Some((4100, true))
        );
        assert_eq!(
            s.place_bits(60, 12).map(|(k, at)| (k, at.is_some())),
            Some((4156, false))
        );
        assert_eq!(
            s.place_bits((1 << 20) + 4149, 24).map(|(k, _)| k),
            Some(4149)
        );
        // 4000 is 149 behind the newest, older than the 100 kept
        assert_eq!(s.place_bits(4000, 12), None);
    }
}
