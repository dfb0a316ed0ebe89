//! Recorded traffic put back on the bus: a sequence of CAN frames, GPS bytes and silences (as a
//! recording of the other end saw them) written onto vcan and a pty in their order, paced on the
//! IMU clock the frames carry, and in lockstep with nav's NAV_TIME frames as the bus scheduler
//! ([`crate::bus`]) runs the emulators. It knows nothing of where the sequence came from: the
//! bench reads it out of nav's recording (`hil replay --bus`).
//!
//! **Pacing.** Each IMU_GYRO frame is one IMU sample: simulated time advances by one sample
//! period per IMU_GYRO frame (not by its counter, which a firmware fault may make jump), at the
//! speed factor asked. Everything between two IMU_GYRO frames goes out with the first.
//!
//! **GPS bytes** are written to the pty at their place in the sequence, after the frames before
//! them have gone out: nav sees them at the same point of the IMU stream as when it was
//! recorded (nav ties a fix to its PPS edge and applies it at a time set by the IMU stream, so
//! the exact moment within that window does not change the solution).
//!
//! **Silences** mark where nav's liveness watchdog fired in the recording: the player stops
//! there until nav's watchdog has fired again (a NAV_TIME with the imu_timeout bit), at most
//! `silence` of wall time, so that it fires at the same place in the stream.

use crate::adapters::clock::SimClock;
use crate::adapters::pty::{GpsPty, PtyError};
use crate::adapters::scheduler::{BusError, Lockstep, LockstepStats, WatchdogReports};
use crate::adapters::transport::{Progress, write_all};
use serde::{Deserialize, Serialize};
use socketcan::CanSocket;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use wire::{Message, RawFrame};

/// One recorded thing to put back.
#[derive(Debug, Clone, PartialEq)]
pub enum Recorded {
    /// A CAN frame.
    Frame(RawFrame),
    /// Bytes from the GPS receiver's port.
    Gps(Vec<u8>),
    /// The other end's liveness watchdog fired here: stop for a while.
    Silence,
}

/// How to play.
#[derive(Debug, Clone, Copy)]
pub struct PlayOptions {
    /// Speed factor over real time (1.0: as the IMU sent it).
    pub speed: f64,
    /// IMU sample rate, Hz.
    pub imu_rate_hz: f64,
    /// Wall time the player waits at most at a [`Recorded::Silence`] for nav's watchdog.
    pub silence: Duration,
    /// Follow nav's NAV_TIME frames (none: paced by the clock alone).
    pub lockstep: Option<Lockstep>,
}

/// What the player did.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct PlayStats {
    /// CAN frames written.
    pub frames: u64,
    /// IMU samples (IMU_GYRO frames) among them.
    pub samples: u64,
    /// Frames lost while the interface was down.
    pub lost_iface_down: u64,
    /// Retries while the transmit queue was full.
    pub enobufs_retries: u64,
    /// GPS bytes written.
    pub gps_bytes: u64,
    /// GPS writes.
    pub gps_writes: u64,
    /// GPS writes lost because nobody read the port.
    pub gps_unread: u64,
    /// GPS writes the reader had not taken within [`crate::adapters::pty::TAKE_WAIT`].
    pub gps_slow_reads: u64,
    /// Silences kept.
    pub silences: u64,
    /// Largest lag of the stream behind its paced time, ms.
    pub max_lag_ms: u64,
    /// Lockstep.
    pub lockstep: LockstepStats,
}

/// The frames nav confirmed, as the player follows them.
struct Follow {
    /// (sample index, 16-bit counter) of the IMU_GYRO frames sent, newest last.
    sent: VecDeque<(u64, u16)>,
    confirmed: Option<u64>,
    /// nav's watchdog reports, owed by the recording's silences (one per silence) or not.
    watchdog: WatchdogReports,
    /// In lockstep: a watchdog report no silence called for is counted as starvation.
    following: bool,
}

impl Follow {
    /// Nothing sent, nothing confirmed yet; `following` nav in lockstep.
    fn new(following: bool) -> Self {
        Self {
            sent: VecDeque::with_capacity(4096),
            confirmed: None,
            watchdog: WatchdogReports::default(),
            following,
        }
    }

    /// The sample a NAV_TIME names: the newest sent whose counter its count matches. Its
    /// imu_timeout bit where no silence called for it (in lockstep) is counted as
    /// [`LockstepStats::starved`].
    fn on_nav_time(
        &mut self,
        iface: &str,
        sample_count: u32,
        imu_timeout: bool,
        ls: &mut LockstepStats,
    ) {
        ls.nav_times += 1;
        if imu_timeout && self.watchdog.report(self.following, ls) {
            tracing::warn!(
                interface = iface,
                "nav's watchdog reported an IMU stop where the recording has none: the player was starved of CPU for longer than the watchdog, and the replay is no longer reproducible"
            );
        }
        let c = sample_count as u16;
        if let Some(&(k, _)) = self.sent.iter().rev().find(|s| s.1 == c)
            && self.confirmed.is_none_or(|p| k > p)
        {
            self.confirmed = Some(k);
            ls.last_confirmed = Some(k);
        }
    }
}

/// Put `items` on `iface` (and the GPS bytes on `pty`), paced and followed as `opts` says.
/// Stops early when `stop` is set; `progress` follows the simulated time reached.
pub fn play(
    iface: &str,
    items: impl IntoIterator<Item = Recorded>,
    mut pty: Option<&mut GpsPty>,
    opts: &PlayOptions,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<PlayStats, BusError> {
    // what nav says: its solution header (NAV_TIME) only; its turntable commands go unanswered
    // (the recording holds the turntable's answers)
    let sock = crate::adapters::scheduler::bench_socket(iface, &[wire::nav_time::SPEC.id])?;
    let mut st = PlayStats::default();
    st.lockstep.enabled = opts.lockstep.is_some();
    let period = 1.0 / opts.imu_rate_hz.max(1e-9);
    let mut clock = SimClock::start(opts.speed);
    let mut follow = Follow::new(opts.lockstep.is_some());
    let mut lockstep = opts.lockstep;
    let mut outbox: Vec<RawFrame> = Vec::with_capacity(wire::BATCH);
    let flush = |outbox: &mut Vec<RawFrame>, st: &mut PlayStats| -> Result<(), BusError> {
        let w = write_all(&sock, iface, outbox)?;
        st.enobufs_retries += w.retries;
        st.lost_iface_down += w.lost_down;
        st.frames += outbox.len() as u64 - w.lost_down;
        outbox.clear();
        Ok(())
    };
    // the next sample's index (the count of IMU_GYRO frames met)
    let mut k = 0u64;
    for item in items {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        match item {
            Recorded::Frame(f) => {
                // only the IMU_GYRO frames are decoded (for their counter): the rest go out as
                // they are
                let gyro = (f.id == wire::imu_gyro::SPEC.id)
                    .then(|| Message::decode(&f).ok())
                    .flatten();
                if let Some(Message::ImuGyro(g)) = gyro {
                    let t = k as f64 * period;
                    if k.is_multiple_of(16) {
                        flush(&mut outbox, &mut st)?;
                        // lockstep: never more than a window ahead of what nav confirmed
                        if let Some(l) = lockstep {
                            let ok = wait_for_nav(&sock, iface, &mut follow, k, &l, stop, &mut st)?;
                            if !ok {
                                st.lockstep.stalls += 1;
                                lockstep = None;
                                follow.following = false;
                                tracing::warn!(
                                    interface = iface,
                                    "nav confirmed no IMU sample past {:?} for {} s: lockstep off, the replay is no longer reproducible",
                                    follow.confirmed,
                                    l.stall.as_secs()
                                );
                            }
                        } else {
                            read_nav(&sock, iface, &mut follow, &mut st.lockstep)?;
                        }
                        clock.sleep_until(t);
                        let lag = Instant::now().saturating_duration_since(clock.wall_at(t));
                        st.max_lag_ms = st.max_lag_ms.max(lag.as_millis() as u64);
                        progress.set(t);
                    }
                    if follow.sent.len() == follow.sent.capacity() {
                        follow.sent.pop_front();
                    }
                    follow.sent.push_back((k, g.sample_counter));
                    k += 1;
                    st.samples += 1;
                }
                outbox.push(f);
                if outbox.len() >= wire::BATCH {
                    flush(&mut outbox, &mut st)?;
                }
            }
            Recorded::Gps(bytes) => {
                flush(&mut outbox, &mut st)?;
                let p = pty.as_deref_mut().ok_or(BusError::NoGpsPort)?;
                put_gps(p, &bytes, lockstep, stop, &mut st)?;
            }
            Recorded::Silence => {
                flush(&mut outbox, &mut st)?;
                hold_silence(&sock, iface, &mut follow, opts.silence, stop, &mut st)?;
                // what follows is paced from here, not caught up at once
                clock.catch_up(k as f64 * period);
            }
        }
    }
    flush(&mut outbox, &mut st)?;
    read_nav(&sock, iface, &mut follow, &mut st.lockstep)?;
    progress.set(k as f64 * period);
    Ok(st)
}

/// The receiver's recorded bytes onto its pty, once nav's reader is there; nav takes them
/// before the IMU stream goes on.
fn put_gps(
    p: &mut GpsPty,
    bytes: &[u8],
    lockstep: Option<Lockstep>,
    stop: &AtomicBool,
    st: &mut PlayStats,
) -> Result<(), BusError> {
    // in lockstep nav's reader has as long as nav has to confirm a sample
    let limit = lockstep.map_or(crate::adapters::pty::TAKE_WAIT, |l| l.stall);
    // nav re-opening the device after a drop: the bytes wait for it
    if !p.reader_attached() && !p.wait_reader_until(limit, stop) {
        st.gps_slow_reads += 1;
    }
    match p.write(bytes) {
        Ok(()) => {
            st.gps_bytes += bytes.len() as u64;
            st.gps_writes += 1;
            // nav reads them (and takes the frames before them first) before the
            // IMU stream goes on
            if !p.wait_taken_until(limit, stop) {
                st.gps_slow_reads += 1;
            }
        }
        Err(PtyError::Write { source, .. }) if source.kind() == std::io::ErrorKind::TimedOut => {
            st.gps_unread += 1;
            p.clear();
        }
        Err(e) => return Err(e.into()),
    }
    Ok(())
}

/// A recorded silence of the IMU: nothing goes out until nav's watchdog has fired again (at
/// most `silence`).
fn hold_silence(
    sock: &CanSocket,
    iface: &str,
    follow: &mut Follow,
    silence: Duration,
    stop: &AtomicBool,
    st: &mut PlayStats,
) -> Result<(), BusError> {
    st.silences += 1;
    // nav's watchdog fires again here: nothing more goes out until it has
    follow.watchdog.hold();
    let since = Instant::now();
    while !follow.watchdog.seen() && since.elapsed() < silence && !stop.load(Ordering::Relaxed) {
        crate::adapters::scheduler::wait_readable(sock, Duration::from_millis(2));
        read_nav(sock, iface, follow, &mut st.lockstep)?;
    }
    Ok(())
}

/// Read nav's NAV_TIME frames until it has confirmed within the window of sample `k`; false
/// when it did not within the stall limit.
fn wait_for_nav(
    sock: &CanSocket,
    iface: &str,
    follow: &mut Follow,
    k: u64,
    l: &Lockstep,
    stop: &AtomicBool,
    st: &mut PlayStats,
) -> Result<bool, BusError> {
    let mut waited: Option<Instant> = None;
    loop {
        read_nav(sock, iface, follow, &mut st.lockstep)?;
        // before nav has named any sample, the first window goes out unconfirmed
        if follow.confirmed.map_or(l.window, |c| c + l.window) >= k || stop.load(Ordering::Relaxed)
        {
            break;
        }
        let since = *waited.get_or_insert_with(|| {
            st.lockstep.waits += 1;
            Instant::now()
        });
        if since.elapsed() > l.stall {
            st.lockstep.wait_ms += since.elapsed().as_millis() as u64;
            return Ok(false);
        }
        crate::adapters::scheduler::wait_readable(sock, Duration::from_millis(2));
    }
    if let Some(w) = waited {
        st.lockstep.wait_ms += w.elapsed().as_millis() as u64;
    }
    Ok(true)
}

/// Take what nav said so far, without blocking.
fn read_nav(
    sock: &CanSocket,
    iface: &str,
    follow: &mut Follow,
    ls: &mut LockstepStats,
) -> Result<(), BusError> {
    crate::adapters::scheduler::drain(sock, iface, |f| {
        if let Some(Ok(Message::NavTime(nt))) = f.map(|f| Message::decode(&f)) {
            follow.on_nav_time(iface, nt.sample_count, nt.health.imu_timeout, ls);
        }
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A NAV_TIME names the newest sample sent with its counter, across the 16-bit wrap; an
    /// older or unknown count changes nothing.
    #[test]
    fn nav_time_confirms_the_newest_sample_with_its_counter() {
        let mut f = Follow::new(true);
        let mut ls = LockstepStats::default();
        for (k, c) in [(0u64, 65534u16), (1, 65535), (2, 0), (3, 1)] {
            f.sent.push_back((k, c));
        }
        f.on_nav_time("vcan0", 0x0001_0000, false, &mut ls);
        assert_eq!(f.confirmed, Some(2));
        f.on_nav_time("vcan0", 65535, false, &mut ls);
        assert_eq!(f.confirmed, Some(2), "an older sample does not go back");
        f.on_nav_time("vcan0", 7, false, &mut ls);
        assert_eq!(f.confirmed, Some(2), "a count never sent is ignored");
        f.on_nav_time("vcan0", 0x0001_0001, false, &mut ls);
        assert_eq!((f.confirmed, ls.nav_times), (Some(3), 4));
    }

    /// nav's watchdog report where the recording has a silence is the one owed; one where it
    /// has none, in lockstep, is starvation; without lockstep the pace is the clock's and
    /// nothing is counted.
    #[test]
    fn a_watchdog_report_no_silence_called_for_counts_as_starvation() {
        let mut f = Follow::new(true);
        let mut ls = LockstepStats::default();
        f.watchdog.hold();
        f.on_nav_time("vcan0", 5, true, &mut ls);
        assert_eq!(ls.starved, 0, "the silence's own report");
        assert!(f.watchdog.seen());
        f.on_nav_time("vcan0", 6, false, &mut ls);
        f.on_nav_time("vcan0", 7, true, &mut ls);
        assert_eq!(ls.starved, 1, "a report no silence owed");
        let mut free = Follow::new(false);
        free.on_nav_time("vcan0", 7, true, &mut ls);
        assert_eq!(ls.starved, 1, "not counted without lockstep");
    }
}
