//! The bench's bus scheduler: every emulated device on one simulated clock, in one thread, so
//! that what nav receives, and in what order, depends on the scenario and its seed only.
//!
//! For each IMU sample the scheduler writes what [`crate::step::Stepper`] says, in its order:
//! the frames over on the bus model by the next sample's end (the sample's IMU frames, the
//! turntable's acknowledgements and status frames, a babbling node's; the error frames of nav's
//! controller between them); then the GPS receiver's sentences due by then on its pty. The frames of one sample therefore always reach
//! nav in the same order, whatever the machine's speed or the way its processes are scheduled.
//!
//! **The receiver's bytes** go to the pty once the frames before them are on vcan, when nav has
//! the device open (after a port drop, the scheduler waits for nav to open it again), and the
//! IMU stream goes on only once nav has read them: nav takes the frames it received before the
//! bytes first, so they enter nav's pipeline right after the frames of their sample, on any
//! host and at any pace. nav confirms them on the bus (NAV_TIME's `GpsRxBytes`), and the
//! scheduler never runs [`Lockstep::window`] samples past an epoch it wrote before it has
//! that confirmation.
//!
//! **Lockstep.** Like a flight simulator that advances its physics only when the autopilot has
//! consumed the last step, the scheduler reads nav's own NAV_TIME frames (sent at 50 Hz of IMU
//! time, carrying the last IMU sample nav has processed) and never runs more than
//! [`Lockstep::window`] samples ahead of them. A turntable command nav sends while processing
//! the samples up to one NAV_TIME (the commands on the bus before that NAV_TIME) takes effect
//! [`Lockstep::latency`] samples after that NAV_TIME's sample: a fixed, realistic controller
//! latency, and a time that does not depend on when the frame happened to be read. nav is not
//! changed for this: it only relies on nav doing what the wire contract says.
//!
//! When nav stops confirming (it exited, or it is not the program on the other end), the
//! scheduler waits [`Lockstep::stall`] of wall time, then counts a stall and runs on at its
//! pace: the run goes on, and its report says it was not reproducible.

use crate::adapters::clock::SimClock;
use crate::adapters::pty::{GpsDevice, GpsTxStats, PtyError};
use crate::adapters::transport::{
    CanTxError, Progress, SentLog, TurntableTxStats, TxStats, write_all,
};
use crate::step::{FromNav, Step, Stepper};
pub use crate::turntable::ttbus::{TT_TRUTH_HZ, TtBus, TtTruth};
use serde::{Deserialize, Serialize};
use socketcan::{CanSocket, Socket, SocketOptions};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use thiserror::Error;
use wire::RawFrame;

/// How the scheduler follows nav.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Lockstep {
    /// Largest lead of the IMU stream over the last sample nav confirmed, samples.
    pub window: u64,
    /// A command takes effect this many samples after the NAV_TIME it preceded (at least
    /// `window`, so it never changes the past the IMU has already sent).
    pub latency: u64,
    /// Wall time without a confirmation before the scheduler gives up waiting.
    pub stall: Duration,
}

impl Default for Lockstep {
    fn default() -> Self {
        Self::at_rate(2000.0)
    }
}

impl Lockstep {
    /// The lockstep of an IMU at `imu_rate_hz`: 60 ms of IMU time (three of nav's 50 Hz output
    /// periods in flight; 120 samples at 2 kHz, 6 at 100 Hz), a command taking effect that long
    /// after its NAV_TIME whatever the IMU's rate.
    pub fn at_rate(imu_rate_hz: f64) -> Self {
        let n = (0.06 * imu_rate_hz).round().max(4.0) as u64;
        Self {
            window: n,
            latency: n,
            stall: Duration::from_secs(20),
        }
    }
}

/// What the lockstep saw.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct LockstepStats {
    /// Lockstep was asked for.
    pub enabled: bool,
    /// NAV_TIME frames read.
    pub nav_times: u64,
    /// Times the stream waited for nav.
    pub waits: u64,
    /// Wall time spent waiting for nav, ms.
    pub wait_ms: u64,
    /// Of that, held for nav's watchdog to report an IMU stop or the stream's end (its wall
    /// time, by design), ms: not the bench's pace.
    #[serde(default)]
    pub watchdog_wait_ms: u64,
    /// Times nav did not confirm within the stall limit (the run went on without lockstep).
    pub stalls: u64,
    /// NAV_TIMEs with the imu_timeout bit where the stream had not stopped: nav's watchdog
    /// fired because no frame reached it for its timeout of wall time while the bench was
    /// sending (the bench or the kernel starved of CPU, not an IMU stop). The liveness event
    /// takes a NAV_TIME of its own, so the run went on but no longer as its scenario alone
    /// decides.
    #[serde(default)]
    pub starved: u64,
    /// Turntable commands placed in time by a NAV_TIME.
    pub placed_commands: u64,
    /// Turntable commands that arrived while lockstep was off (applied at the next sample).
    pub unplaced_commands: u64,
    /// The last IMU sample (0-based) nav confirmed.
    pub last_confirmed: Option<u64>,
    /// Frame-in to solution-out on the bus: wall time from writing a sample's frames to reading
    /// nav's NAV_TIME that names it (as the scheduler sees it: it reads nav's frames once per
    /// batch of 16 samples, so this includes up to one batch of its own polling), median, ms.
    pub latency_p50_ms: f64,
    /// Its 99th percentile, ms.
    pub latency_p99_ms: f64,
    /// NAV_TIMEs the latency was measured on.
    pub latency_samples: u64,
    /// Times the stream waited for nav to open the receiver's device, to read the receiver's
    /// bytes, or to confirm them on the bus.
    #[serde(default)]
    pub receiver_waits: u64,
    /// Of which nav did none within the stall limit (the run went on: a fix may have been
    /// late, bytes lost).
    #[serde(default)]
    pub receiver_stalls: u64,
}

/// When each batch of samples went out, and how long nav took to confirm them.
#[derive(Default)]
struct Latency {
    sent: VecDeque<(u64, Instant)>,
    ms: Vec<f32>,
}

impl Latency {
    /// Samples up to `last` were just written.
    fn flushed(&mut self, last: Option<u64>) {
        if let Some(k) = last {
            self.sent.push_back((k, Instant::now()));
        }
    }

    /// nav confirmed sample `k`.
    fn confirmed(&mut self, k: u64) {
        while self.sent.front().is_some_and(|s| s.0 < k) {
            self.sent.pop_front();
        }
        if let Some(&(_, t)) = self.sent.front() {
            self.ms.push(t.elapsed().as_secs_f32() * 1e3);
        }
    }

    /// Median and 99th percentile, ms, and the count.
    fn percentiles(&mut self) -> (f64, f64, u64) {
        if self.ms.is_empty() {
            return (0.0, 0.0, 0);
        }
        self.ms.sort_by(f32::total_cmp);
        let at = |q: f64| f64::from(self.ms[((self.ms.len() - 1) as f64 * q).round() as usize]);
        (at(0.5), at(0.99), self.ms.len() as u64)
    }
}

/// Everything the scheduler drives in one run.
pub struct Devices {
    /// The scenario's devices on the IMU clock (IMU, turntable, the receiver's epochs).
    pub step: Stepper,
    /// The receiver's pty, when the scenario has a receiver.
    pub gps: Option<GpsDevice>,
    /// Where every frame put on the bus is logged, when given.
    pub sent_log: Option<SentLog>,
    /// Where the bus model's log goes, when given: every frame on the model (nav's too) and
    /// the error frames of nav's controller, at their simulated times.
    pub bus_log: Option<SentLog>,
    /// The interface taken down and brought up at points of the stream, when given.
    pub link: Option<LinkOutages>,
    /// Called after every sample with what it put on the bus model and the devices (a live
    /// view's watcher): it must return at once (it runs on the scheduler's thread) and it
    /// changes nothing.
    pub watch: Option<Watch>,
    /// A pause a viewer may ask for, when given ([`Hold`]).
    pub hold: Option<Hold>,
}

/// A watcher of the stream ([`Devices::watch`]).
pub type Watch = Box<dyn FnMut(&Step, &Stepper) + Send>;

/// A pause of the stream between two batches, asked for from outside (a viewer's pause
/// button). While `paused` is set the scheduler stands before its next batch: it writes what
/// it has, then calls `notify(true)`; once `paused` clears, it writes the next sample's frames
/// first and then calls `notify(false)`. Whoever pauses nav in `notify` (the bench stops its
/// process) has nav take what was written before or after the stop, in order, and finds the
/// stream's next frames waiting for it when it goes on (nav's watchdog does not count a
/// stopped process's time while an IMU frame waits in its socket): nothing of the pause
/// reaches a result.
pub struct Hold {
    /// The pause is asked for.
    pub paused: std::sync::Arc<AtomicBool>,
    /// The stream stands (`true`), the stream goes on (`false`).
    pub notify: Box<dyn FnMut(bool) + Send>,
}

/// The CAN interface going down and coming back up at points of the simulated stream (a
/// controller switched off, a connector pulled): the scheduler switches the link between two
/// samples, so nav has every frame before the outage, the frames due inside it are lost to the
/// downed interface (counted), and the stream goes on after it, at any pace.
pub struct LinkOutages {
    /// Each outage: [down at, up at] simulated time, s.
    pub windows: Vec<[f64; 2]>,
    /// Takes the interface down (`false`) or brings it up (`true`).
    pub switch: Box<dyn FnMut(bool) -> std::io::Result<()> + Send>,
    /// An outage is under way.
    down: bool,
}

impl LinkOutages {
    /// Outages `windows` ([down at, up at], s), the link switched by `switch`.
    pub fn new(
        windows: Vec<[f64; 2]>,
        switch: Box<dyn FnMut(bool) -> std::io::Result<()> + Send>,
    ) -> Self {
        Self {
            windows,
            switch,
            down: false,
        }
    }

    /// Before the sample at `t`: the link switch due, if any (everything written before it went
    /// out first).
    fn before(&mut self, t: f64, port: &mut Port, nav: &mut NavSide) -> Result<(), CanTxError> {
        let due = if self.down {
            self.windows.first().is_some_and(|w| t >= w[1])
        } else {
            self.windows.first().is_some_and(|w| t >= w[0])
        };
        if !due {
            return Ok(());
        }
        port.flush(nav)?;
        let up = self.down;
        (self.switch)(up).map_err(|source| CanTxError::Link {
            iface: port.iface.into(),
            up,
            source,
        })?;
        tracing::info!(
            interface = port.iface,
            "the interface {} at {t:.4} s",
            if up { "is back up" } else { "went down" }
        );
        self.down = !up;
        if up {
            self.windows.remove(0);
        }
        Ok(())
    }
}

/// What the scheduler did.
pub struct BusOutcome {
    /// The IMU's frames.
    pub imu: TxStats,
    /// The turntable's frames.
    pub turntable: Option<TurntableTxStats>,
    /// The turntable's truth ([`TT_TRUTH_HZ`]).
    pub turntable_truth: Vec<TtTruth>,
    /// The receiver's output, and its pty (kept open until nav has stopped).
    pub gps: Option<(GpsTxStats, crate::adapters::pty::GpsPty)>,
    /// Lockstep.
    pub lockstep: LockstepStats,
    /// Lines in the log of sent frames ([`Devices::sent_log`]).
    pub sent_logged: Option<u64>,
    /// Lines in the bus model's log ([`Devices::bus_log`]).
    pub bus_logged: Option<u64>,
    /// The bus model: load, each identifier's delays, the command round trip.
    pub bus: crate::bus::model::BusStats,
    /// Error frames of nav's controller written to the bus.
    pub error_frames: u64,
}

/// Scheduler (and player) failures.
#[derive(Debug, Error)]
pub enum BusError {
    /// CAN trouble.
    #[error(transparent)]
    Can(#[from] CanTxError),
    /// pty trouble.
    #[error("GPS receiver: {0}")]
    Gps(#[from] PtyError),
    /// GPS bytes to put back but no port to write them to (the player).
    #[error("the recording has GPS bytes but no GPS port was given")]
    NoGpsPort,
}

/// The bench's socket on `iface`: receiving only the ids in `ids` (what nav sends that the
/// writer follows), non-blocking, and its thread kept on one CPU ([`pin_to_this_cpu`]).
pub(crate) fn bench_socket(iface: &str, ids: &[u16]) -> Result<CanSocket, CanTxError> {
    let open_err = |source| CanTxError::Open {
        iface: iface.into(),
        source,
    };
    let sock = CanSocket::open(iface).map_err(open_err)?;
    pin_to_this_cpu(iface);
    let filters: Vec<_> = ids
        .iter()
        .map(|&id| socketcan::CanFilter::new(u32::from(id), 0x7FF))
        .collect();
    sock.set_filters(&filters).map_err(open_err)?;
    sock.set_nonblocking(true).map_err(open_err)?;
    Ok(sock)
}

/// Everything nav has sent so far on `sock`, without blocking, each frame to `f` (none: not a
/// data frame). A downed interface has nothing to read.
pub(crate) fn drain(
    sock: &CanSocket,
    iface: &str,
    mut f: impl FnMut(Option<RawFrame>),
) -> Result<(), CanTxError> {
    let mut got = Vec::with_capacity(wire::BATCH);
    drain_into(sock, iface, &mut got, wire::recv_batch, |r| f(r.ok()))
}

/// As [`drain`], each frame with its kernel receive time (ns since the UNIX epoch) where the
/// socket has `SO_TIMESTAMPNS` on (none otherwise).
pub(crate) fn drain_stamped(
    sock: &CanSocket,
    iface: &str,
    mut f: impl FnMut(Option<RawFrame>, Option<u64>),
) -> Result<(), CanTxError> {
    let mut got = Vec::with_capacity(wire::BATCH);
    drain_into(
        sock,
        iface,
        &mut got,
        wire::recv_batch_stamped,
        |(r, at)| f(r.ok(), at),
    )
}

/// Batches from `recv` until one comes short, each frame to `f`.
fn drain_into<T>(
    sock: &CanSocket,
    iface: &str,
    got: &mut Vec<T>,
    recv: impl Fn(std::os::fd::RawFd, &mut Vec<T>, usize) -> std::io::Result<usize>,
    mut f: impl FnMut(T),
) -> Result<(), CanTxError> {
    use std::os::fd::AsRawFd;
    loop {
        got.clear();
        let n = match recv(sock.as_raw_fd(), got, wire::BATCH) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            // the interface went down: the socket reports it once; nothing to read meanwhile
            Err(e) if e.raw_os_error() == Some(libc::ENETDOWN) => return Ok(()),
            Err(source) => {
                return Err(CanTxError::Read {
                    iface: iface.into(),
                    source,
                });
            }
        };
        for r in got.drain(..) {
            f(r);
        }
        if n < wire::BATCH {
            return Ok(());
        }
    }
}

/// Frames waiting to go on the bus, and what their writes did.
struct Outbox {
    frames: Vec<RawFrame>,
    /// The last sample whose frames are waiting.
    last: Option<u64>,
    written: u64,
    retries: u64,
    lost_down: u64,
    log: Option<SentLog>,
}

impl Outbox {
    /// Write the waiting frames (to the log of sent frames too). Frames lost to a downed
    /// interface never reach nav, so the lockstep takes their samples as confirmed (nav cannot
    /// confirm what it never received).
    fn flush(
        &mut self,
        sock: &CanSocket,
        iface: &str,
        confirmed: &mut Option<u64>,
        latency: &mut Latency,
    ) -> Result<(), CanTxError> {
        let w = write_all(sock, iface, &self.frames)?;
        self.retries += w.retries;
        let went = self.frames.len() - w.lost_down as usize;
        if w.lost_down > 0 {
            self.lost_down += w.lost_down;
            if let Some(k) = self.last {
                *confirmed = Some(confirmed.map_or(k, |c| c.max(k)));
            }
        }
        if let Some(log) = self.log.as_mut() {
            log.frames(&self.frames[..went])?;
        }
        self.written += went as u64;
        self.frames.clear();
        latency.flushed(self.last.take());
        Ok(())
    }
}

/// Keep the calling thread on the first CPU it may run on ([`wire::pin_to_one_cpu`]: vcan keeps
/// a writer's order only while the writer stays on one CPU; nav, started by the bench, takes
/// the last).
pub(crate) fn pin_to_this_cpu(iface: &str) {
    if let Err(e) = wire::pin_to_one_cpu(wire::CpuPick::First) {
        tracing::warn!(
            interface = iface,
            "cannot pin the bus thread to its CPU ({e}): frames may reach readers out of order"
        );
    }
}

/// nav's watchdog reports (NAV_TIMEs with the imu_timeout bit) as a sender of the IMU stream
/// counts them: each stop of the stream it holds for owes one; a report beyond those, in
/// lockstep, means nav saw no frame for its watchdog's wall time while the stream went on (the
/// sender starved of CPU), counted as [`LockstepStats::starved`]. The bus scheduler and the
/// replay's player both keep one.
#[derive(Debug, Default)]
pub(crate) struct WatchdogReports {
    /// Reports the holds so far call for and nav has not yet sent.
    owed: u64,
    /// A report came since the last hold began.
    seen: bool,
}

impl WatchdogReports {
    /// The stream stops here and holds until nav's watchdog has reported it: one report more
    /// is owed, and none has come for this hold yet.
    pub(crate) fn hold(&mut self) {
        self.owed += 1;
        self.seen = false;
    }

    /// Whether a report came since the last [`hold`](Self::hold) began.
    pub(crate) fn seen(&self) -> bool {
        self.seen
    }

    /// A report came: true (and counted in `ls.starved`) when no hold called for it and the
    /// sender is `following` nav in lockstep (off lockstep the clock paces the stream, and a
    /// late sender is not counted).
    pub(crate) fn report(&mut self, following: bool, ls: &mut LockstepStats) -> bool {
        self.seen = true;
        if self.owed > 0 {
            self.owed -= 1;
            return false;
        }
        if !following {
            return false;
        }
        ls.starved += 1;
        true
    }
}

/// What nav has said, as the scheduler follows it.
struct NavSide {
    follow: Option<Lockstep>,
    confirmed: Option<u64>,
    /// NAV_TIME's latest `GpsRxBytes`.
    gps_rx: Option<u16>,
    /// nav's watchdog reports, owed by the stream's stops (one per hold) or not.
    watchdog: WatchdogReports,
    /// The receiver's bytes written so far, and the sample of the last epoch, until nav has
    /// confirmed them on the bus.
    owed: Option<(u64, u64)>,
    ls: LockstepStats,
    bad: u64,
    latency: Latency,
}

impl NavSide {
    /// nav's side before the first sample, following nav's NAV_TIME when `lockstep` is given.
    fn following(lockstep: Option<Lockstep>) -> Self {
        Self {
            follow: lockstep,
            confirmed: None,
            gps_rx: None,
            watchdog: WatchdogReports::default(),
            owed: None,
            ls: LockstepStats {
                enabled: lockstep.is_some(),
                ..Default::default()
            },
            bad: 0,
            latency: Latency::default(),
        }
    }

    /// Sample `k` (at `t`) as nav cannot confirm it: its frames lost on the bus model, or not
    /// sent on purpose (a silence starts then, and lasts its paced wall time).
    fn unconfirmable(
        &mut self,
        st: &Step,
        k: u64,
        t: f64,
        clock: &mut SimClock,
        silent: &mut bool,
    ) {
        if st.lost {
            // frames lost on the bus model (a full queue, a bus-off): nav cannot confirm
            // their samples
            self.confirmed = Some(self.confirmed.map_or(k, |c| c.max(k)));
        }
        if st.dropped {
            // a sample deliberately not sent (a fault): nav cannot confirm it, so the lockstep
            // does not wait for it (an IMU that stops for seconds is then paced by the clock)
            self.confirmed = Some(self.confirmed.map_or(k, |c| c.max(k)));
            if !*silent {
                // a silence starts: it lasts its paced wall time even when the stream ran
                // behind the clock (else a stop of seconds would pass in no time at all and
                // nav's watchdog would never see it)
                clock.catch_up(t);
                *silent = true;
            }
        } else {
            *silent = false;
        }
    }
    /// Read what nav sent so far, without blocking.
    fn read(
        &mut self,
        sock: &CanSocket,
        iface: &str,
        step: &mut Stepper,
    ) -> Result<(), CanTxError> {
        let lockstep = self.follow.is_some();
        drain(sock, iface, |f| {
            let Some(f) = f else {
                self.bad += 1;
                return;
            };
            let nav_time = f.id == wire::nav_time::SPEC.id;
            match step.from_nav(f, lockstep) {
                FromNav::Confirmed {
                    sample,
                    imu_timeout,
                    gps_rx_bytes,
                    placed,
                } => {
                    self.ls.nav_times += 1;
                    if imu_timeout && self.watchdog.report(self.follow.is_some(), &mut self.ls) {
                        tracing::warn!(
                            interface = iface,
                            "nav's watchdog reported an IMU stop after sample {sample}, where the stream had not stopped: the bench was starved of CPU for longer than the watchdog, and the run is no longer reproducible"
                        );
                    }
                    self.gps_rx = Some(gps_rx_bytes);
                    self.ls.placed_commands += placed;
                    if self.confirmed.is_none_or(|c| sample > c) {
                        self.confirmed = Some(sample);
                        self.ls.last_confirmed = Some(sample);
                        self.latency.confirmed(sample);
                    }
                }
                FromNav::Unplaced => self.ls.nav_times += u64::from(nav_time),
                FromNav::Command if !lockstep => self.ls.unplaced_commands += 1,
                FromNav::Command | FromNav::Other => {}
                FromNav::Unexpected => self.bad += 1,
            }
        })
    }

    /// nav has confirmed the receiver's bytes up to `written` (12 bits, as NAV_TIME carries
    /// them).
    fn has_bytes(&self, written: u64) -> bool {
        self.gps_rx == Some((written & 0xFFF) as u16)
    }

    /// In lockstep, what sample `k` must wait for: nav is more than a window behind; an epoch
    /// written more than a window ago is not confirmed on the bus.
    fn must_wait(&self, k: u64) -> Option<(bool, bool)> {
        let l = self.follow?;
        let behind = self.confirmed.map_or(l.window, |c| c + l.window) < k;
        let unconfirmed = self
            .owed
            .is_some_and(|(bytes, at)| at + l.window < k && !self.has_bytes(bytes));
        Some((behind, unconfirmed))
    }
}

/// The scheduler's socket and the frames waiting to go out on it.
struct Port<'a> {
    sock: &'a CanSocket,
    iface: &'a str,
    outbox: Outbox,
    /// Error frames written.
    error_frames: u64,
}

impl<'a> Port<'a> {
    /// The bench's port on `sock` (interface `iface`), every frame it writes logged to `log`.
    fn on(sock: &'a CanSocket, iface: &'a str, log: Option<SentLog>) -> Self {
        Self {
            sock,
            iface,
            error_frames: 0,
            outbox: Outbox {
                frames: Vec::with_capacity(wire::BATCH),
                last: None,
                written: 0,
                retries: 0,
                lost_down: 0,
                log,
            },
        }
    }
}

impl Port<'_> {
    fn flush(&mut self, nav: &mut NavSide) -> Result<(), CanTxError> {
        self.outbox
            .flush(self.sock, self.iface, &mut nav.confirmed, &mut nav.latency)
    }

    /// A step's frames into the outbox, with nav's controller's error frames written where
    /// the bus raised them (between the frames around them).
    fn take(&mut self, st: &Step, nav: &mut NavSide) -> Result<(), CanTxError> {
        let mut from = 0;
        for (at, _, e) in &st.errors {
            self.outbox.frames.extend_from_slice(&st.frames[from..*at]);
            from = *at;
            self.flush(nav)?;
            self.error_frame(e)?;
        }
        self.outbox.frames.extend_from_slice(&st.frames[from..]);
        Ok(())
    }

    /// An error frame of nav's controller on the bus (after everything before it).
    fn error_frame(&mut self, e: &wire::errframe::ErrorFrame) -> Result<(), CanTxError> {
        use std::os::fd::AsRawFd;
        match wire::send_error_frame(self.sock.as_raw_fd(), e) {
            Ok(()) => {
                self.error_frames += 1;
                Ok(())
            }
            // a downed interface loses it, like any frame
            Err(e) if e.raw_os_error() == Some(libc::ENETDOWN) => Ok(()),
            Err(source) => Err(CanTxError::Write {
                iface: self.iface.into(),
                // the error frame's class: its identifier without CAN_ERR_FLAG
                id: (e.class & 0xFFFF) as u16,
                source,
            }),
        }
    }
}

/// Before sample `k`: read what nav said (once a batch, or when it must have said more) and,
/// in lockstep, wait until nav is close enough behind and has confirmed the receiver's bytes.
fn wait_for_nav(
    port: &mut Port,
    nav: &mut NavSide,
    step: &mut Stepper,
    k: u64,
    read_anyway: bool,
    stop: &AtomicBool,
) -> Result<(), CanTxError> {
    let mut waited: Option<Instant> = None;
    loop {
        let wait = nav.must_wait(k);
        if read_anyway || wait.is_some_and(|(b, u)| b || u) {
            nav.read(port.sock, port.iface, step)?;
        }
        let Some((behind, unconfirmed)) = nav.must_wait(k) else {
            break;
        };
        if !behind && !unconfirmed {
            if nav.owed.is_some_and(|(bytes, _)| nav.has_bytes(bytes)) {
                nav.owed = None;
            }
            break;
        }
        // nav cannot confirm what it has not received
        if !port.outbox.frames.is_empty() {
            port.flush(nav)?;
            continue;
        }
        let since = *waited.get_or_insert_with(|| {
            nav.ls.waits += 1;
            nav.ls.receiver_waits += u64::from(unconfirmed);
            Instant::now()
        });
        if stop.load(Ordering::Relaxed) {
            // told to stop (nav killed, a drill over, a signal): no more waiting for nav
            break;
        }
        let stall = nav.follow.map_or(Duration::ZERO, |l| l.stall);
        if since.elapsed() > stall {
            nav.ls.stalls += 1;
            nav.follow = None;
            tracing::warn!(
                interface = port.iface,
                "nav confirmed no IMU sample past {:?} (receiver bytes {:?} of {:?}) for {} s: lockstep off, the run is no longer reproducible",
                nav.confirmed,
                nav.gps_rx,
                nav.owed.map(|o| o.0 & 0xFFF),
                stall.as_secs()
            );
            break;
        }
        wait_readable(port.sock, Duration::from_millis(2));
    }
    if let Some(w) = waited {
        nav.ls.wait_ms += w.elapsed().as_millis() as u64;
    }
    Ok(())
}

/// The IMU stops: nothing more goes out until nav's watchdog has said so (a NAV_TIME with the
/// imu_timeout bit), so that it fires once, after the same sample, at any pace.
fn hold_for_watchdog(
    port: &mut Port,
    nav: &mut NavSide,
    step: &mut Stepper,
    stall: Duration,
    stop: &AtomicBool,
) -> Result<(), CanTxError> {
    port.flush(nav)?;
    nav.watchdog.hold();
    let since = Instant::now();
    while !nav.watchdog.seen() && !stop.load(Ordering::Relaxed) {
        if since.elapsed() > stall {
            nav.ls.stalls += 1;
            tracing::warn!(
                interface = port.iface,
                "nav's watchdog did not report the IMU's stop within {} s",
                stall.as_secs()
            );
            break;
        }
        wait_readable(port.sock, Duration::from_millis(2));
        nav.read(port.sock, port.iface, step)?;
    }
    let held = since.elapsed().as_millis() as u64;
    nav.ls.wait_ms += held;
    nav.ls.watchdog_wait_ms += held;
    Ok(())
}

/// Stand before sample `k` while `hold` is paused (see [`Hold`]): everything written goes out
/// before `notify(true)`.
fn hold_while_paused(
    port: &mut Port,
    nav: &mut NavSide,
    hold: &mut Hold,
    k: u64,
    stop: &AtomicBool,
) -> Result<(), CanTxError> {
    port.flush(nav)?;
    tracing::info!(interface = port.iface, "paused before sample {k}");
    (hold.notify)(true);
    while hold.paused.load(Ordering::Relaxed) && !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(20));
    }
    tracing::info!(interface = port.iface, "resumed at sample {k}");
    Ok(())
}

/// The receiver's epochs due after sample `k` to its device; what nav owes on the bus.
fn deliver_epochs(
    g: &mut GpsDevice,
    epochs: &mut Vec<crate::gps::Epoch>,
    k: u64,
    nav: &mut NavSide,
    stop: &AtomicBool,
) -> Result<(), PtyError> {
    let limit = nav
        .follow
        .map_or(crate::adapters::pty::TAKE_WAIT, |l| l.stall);
    for e in epochs.drain(..) {
        if let Some(d) = g.deliver(&e, limit, stop)? {
            nav.ls.receiver_waits += u64::from(d.waited);
            nav.ls.receiver_stalls += u64::from(d.stalled);
            if g.confirms_on_bus() {
                nav.owed = Some((g.stats.bytes, k));
            }
        }
    }
    Ok(())
}

/// Run every device on `iface` (and the receiver's pty) for the scenario's simulated time,
/// paced by `clock`, following nav when `lockstep` is given. Stops early when `stop` is set.
pub fn run(
    iface: &str,
    mut dev: Devices,
    mut clock: SimClock,
    lockstep: Option<Lockstep>,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<BusOutcome, BusError> {
    // what nav sends: turntable commands, its solution (NAV_TIME places them in time), all on
    // the bus model
    let from_nav: Vec<u16> = wire::ALL_MESSAGES
        .iter()
        .filter(|m| m.sender == "NAV")
        .map(|m| m.id)
        .collect();
    let sock = bench_socket(iface, &from_nav)?;
    let mut nav = NavSide::following(lockstep);
    let mut st = Step::default();
    // frames go out in batches of a few samples: one system call instead of one per frame
    let mut port = Port::on(&sock, iface, dev.sent_log.take());
    let batch_samples = 16u64;
    let mut max_lag_ms = 0u64;
    let mut silent = false;
    let mut resumed = false;
    while dev.step.running() && !stop.load(Ordering::Relaxed) {
        let k = dev.step.next_index();
        let t = dev.step.next_time();
        let batch_start = k.is_multiple_of(batch_samples);
        wait_for_nav(&mut port, &mut nav, &mut dev.step, k, batch_start, stop)?;
        if let Some(l) = dev.link.as_mut() {
            l.before(t, &mut port, &mut nav)?;
        }
        if batch_start
            && let Some(h) = dev.hold.as_mut()
            && h.paused.load(Ordering::Relaxed)
        {
            hold_while_paused(&mut port, &mut nav, h, k, stop)?;
            clock.catch_up(t);
            resumed = true;
        }
        if batch_start {
            clock.sleep_until(t);
            let lag = Instant::now().saturating_duration_since(clock.wall_at(t));
            max_lag_ms = max_lag_ms.max(lag.as_millis() as u64);
        }
        dev.step.step(&mut st);
        if st.stop_begins
            && let Some(l) = nav.follow
        {
            clock.catch_up(t);
            hold_for_watchdog(&mut port, &mut nav, &mut dev.step, l.stall, stop)?;
            silent = true;
        }
        nav.unconfirmable(&st, k, t, &mut clock, &mut silent);
        port.outbox.last = Some(k);
        port.take(&st, &mut nav)?;
        if let Some(w) = dev.watch.as_mut() {
            w(&st, &dev.step);
        }
        if resumed && let Some(h) = dev.hold.as_mut() {
            // the stream's next frames wait for nav before it goes on
            port.flush(&mut nav)?;
            (h.notify)(false);
            resumed = false;
        }
        if !st.epochs.is_empty()
            || (k + 1).is_multiple_of(batch_samples)
            || port.outbox.frames.len() + 8 > wire::BATCH
        {
            port.flush(&mut nav)?;
        }
        if let Some(log) = dev.bus_log.as_mut() {
            log.trace(&st.trace)?;
        }
        if let Some(g) = dev.gps.as_mut() {
            deliver_epochs(g, &mut st.epochs, k, &mut nav, stop)?;
        }
        progress.set(t);
    }
    port.flush(&mut nav)?;
    if resumed && let Some(h) = dev.hold.as_mut() {
        // stopped while paused: whoever paused nav lets it go on
        (h.notify)(false);
    }
    if let Some(l) = nav.follow
        && !stop.load(Ordering::Relaxed)
        && dev.step.end_awaits_watchdog()
    {
        // the end of the stream is a stop: nav's watchdog reports it before nav is told to stop
        hold_for_watchdog(&mut port, &mut nav, &mut dev.step, l.stall, stop)?;
    }
    progress.set(dev.step.next_time());
    let error_frames = port.error_frames;
    outcome(dev, port.outbox, nav, max_lag_ms, error_frames)
}

/// What the scheduler did, from the devices, the outbox and nav's side at the end.
fn outcome(
    dev: Devices,
    outbox: Outbox,
    mut nav: NavSide,
    max_lag_ms: u64,
    error_frames: u64,
) -> Result<BusOutcome, BusError> {
    let mut ls = nav.ls;
    (ls.latency_p50_ms, ls.latency_p99_ms, ls.latency_samples) = nav.latency.percentiles();
    let bus = dev.step.bus_stats();
    let (imu, mut turntable) = dev.step.into_parts();
    if let Some(tt) = turntable.as_mut() {
        tt.stats.bad_frames += nav.bad;
    }
    let imu_frames = outbox.written
        - turntable
            .as_ref()
            .map_or(0, |t| t.stats.acks + t.stats.status_frames);
    Ok(BusOutcome {
        imu: TxStats {
            frames: imu_frames,
            enobufs_retries: outbox.retries,
            lost_iface_down: outbox.lost_down,
            max_lag_ms,
            ..imu.stats
        },
        turntable_truth: turntable
            .as_mut()
            .map(|t| std::mem::take(&mut t.truth))
            .unwrap_or_default(),
        turntable: turntable.map(|t| t.stats),
        gps: dev.gps.map(|g| (g.stats, g.into_pty())),
        lockstep: ls,
        sent_logged: outbox.log.map(SentLog::finish).transpose()?,
        bus_logged: dev.bus_log.map(SentLog::finish).transpose()?,
        bus,
        error_frames,
    })
}

/// Wait until `sock` has a frame to read, or `timeout`.
pub(crate) fn wait_readable(sock: &CanSocket, timeout: Duration) {
    use std::os::fd::AsRawFd;
    wire::wait_readable(sock.as_raw_fd(), timeout);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each hold for nav's watchdog owes one report with the imu_timeout bit; a report beyond
    /// those, in lockstep, is starvation (nav's watchdog saw no frame for its wall time while
    /// the stream went on); without lockstep the clock paces the stream and nothing is counted.
    #[test]
    fn a_watchdog_report_no_stop_called_for_counts_as_starvation() {
        let mut ls = LockstepStats::default();
        let mut w = WatchdogReports::default();
        w.hold();
        assert!(!w.seen());
        assert!(!w.report(true, &mut ls), "the stop's own report");
        assert!(w.seen());
        assert!(w.report(true, &mut ls), "one more");
        assert_eq!((ls.starved, w.owed), (1, 0));
        w.hold();
        assert!(!w.seen(), "a new hold waits for a report of its own");
        assert!(!w.report(true, &mut ls), "owed by the second hold");
        assert_eq!(ls.starved, 1);
        assert!(!w.report(false, &mut ls), "lockstep off: not counted");
        assert!(w.seen());
        assert_eq!(ls.starved, 1, "not counted without lockstep");
    }
}
