//! What the bench observes of nav during a run: its solution frames on the bus and its
//! north-finding lines on stdout. `run` records it; `report` checks it.

use anyhow::{Context, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// What the bench saw of nav's solution output on the bus.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct SolutionWatch {
    /// NAV_* frames received.
    pub frames: u64,
    /// NAV_TIME frames (epochs).
    pub epochs: u64,
    /// Frames that did not decode.
    pub bad_frames: u64,
    /// Epoch sequence numbers skipped (and not come later).
    pub seq_gaps: u64,
    /// Epochs that came after a later one (vcan on a machine of several CPUs may deliver a
    /// sender's frames out of order when the sender moves between CPUs: its frames go through
    /// each CPU's own receive queue); each filled the gap it had left.
    #[serde(default)]
    pub reordered: u64,
    /// The last NAV_POS, deg.
    pub last_position_deg: Option<[f64; 2]>,
    /// The last mode.
    pub last_mode: Option<String>,
    /// Reads that found the interface down.
    #[serde(default)]
    pub link_down_errors: u64,
    /// Each health bit's first NAV_TIME with it set: (bit, IMU sample count).
    #[serde(default)]
    pub health_first: Vec<(String, u64)>,
    /// Every change of mode: (mode, IMU sample count of the first NAV_TIME in it).
    #[serde(default)]
    pub modes: Vec<(String, u64)>,
    /// The IMU sample count of the latest NAV_TIME (as sent: the low 32 bits): how far nav
    /// had got when its output stopped.
    #[serde(default)]
    pub last_sample: Option<u64>,
    /// NAV_TIMEs, in nav's order (their Seq), that named a sample before the one before them
    /// (the bus's reordering, which Seq shows, aside).
    #[serde(default)]
    pub backwards: u64,
    /// The first of them: the sample before, and the one named.
    #[serde(default)]
    pub first_backwards: Option<(u64, u64)>,
}

impl SolutionWatch {
    /// The IMU sample count at which health bit `bit` was first set, if it was.
    pub fn health_on_at(&self, bit: &str) -> Option<u64> {
        self.health_first
            .iter()
            .find(|(b, _)| b == bit)
            .map(|(_, k)| *k)
    }

    /// The IMU sample count at which nav first reported `mode` at or after sample `from`.
    pub fn mode_at(&self, mode: &str, from: u64) -> Option<u64> {
        self.modes
            .iter()
            .find(|(m, k)| m == mode && *k >= from)
            .map(|(_, k)| *k)
    }
}

/// How often the solution watcher takes the frames queued for it.
pub const WATCH_EVERY: Duration = Duration::from_millis(10);

/// A socket on `iface` that receives nav's NAV_* frames only.
pub fn solution_socket(iface: &str) -> Result<socketcan::CanSocket> {
    use socketcan::{CanSocket, Socket, SocketOptions};
    let sock = CanSocket::open(iface)
        .with_context(|| format!("opening {iface} to watch nav's solution"))?;
    sock.set_filters(&[socketcan::CanFilter::new(0x200, 0x7F8)])
        .with_context(|| format!("filtering NAV frames on {iface}"))?;
    Ok(sock)
}

/// Listen to nav's NAV_* frames on `sock` until `stop`. Nothing here needs a frame the moment
/// it comes (every figure is on nav's sample count): the watcher takes what has queued every
/// [`WATCH_EVERY`] in `recvmmsg` batches, from a socket buffer of 8 MiB (seconds of frames).
pub fn watch_solution(
    sock: socketcan::CanSocket,
    iface: &str,
    stop: &AtomicBool,
) -> Result<SolutionWatch> {
    use std::os::fd::AsRawFd;
    let mut w = SolutionWatch::default();
    let mut last_seq: Option<u8> = None;
    let fd = sock.as_raw_fd();
    if let Err(e) = wire::set_rcvbuf(fd, 8 << 20) {
        tracing::warn!(
            interface = iface,
            "the solution watcher's receive buffer: {e}"
        );
    }
    let mut got = Vec::with_capacity(wire::BATCH);
    // (a last reading once told to stop: what nav sent before it stopped)
    let mut last = false;
    while !last {
        last = stop.load(Ordering::Relaxed);
        wire::wait_readable(fd, Duration::from_millis(50));
        loop {
            got.clear();
            let n = match wire::recv_batch(fd, &mut got, wire::BATCH) {
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                // the interface was taken down (a fault of the matrix): reported once, go on
                Err(e) if e.raw_os_error() == Some(libc::ENETDOWN) => {
                    w.link_down_errors += 1;
                    0
                }
                Err(e) => return Err(e).with_context(|| format!("reading NAV frames on {iface}")),
            };
            for f in got.drain(..) {
                w.frames += 1;
                watch_frame(&mut w, &mut last_seq, f.ok());
            }
            if n < wire::BATCH {
                break;
            }
        }
        std::thread::sleep(WATCH_EVERY);
    }
    Ok(w)
}

/// One of nav's frames (none: not a data frame) into what the bench saw.
fn watch_frame(w: &mut SolutionWatch, last_seq: &mut Option<u8>, f: Option<wire::RawFrame>) {
    match f.and_then(|r| wire::Message::decode(&r).ok()) {
        Some(wire::Message::NavTime(t)) => {
            w.epochs += 1;
            let step = last_seq.map_or(1, |p| t.seq.wrapping_sub(p) as i8);
            if step <= 0 {
                // an epoch after a later one: it fills the gap that one left
                w.reordered += 1;
                w.seq_gaps = w.seq_gaps.saturating_sub(1);
                return;
            }
            w.seq_gaps += u64::from(step as u8 - 1);
            *last_seq = Some(t.seq);
            let mode = format!("{:?}", t.mode);
            let k = u64::from(t.sample_count);
            if let Some(before) = w.last_sample
                && k < before
                && before - k < 1 << 31
            {
                w.backwards += 1;
                w.first_backwards.get_or_insert((before, k));
            }
            w.last_sample = Some(k);
            if w.last_mode.as_deref() != Some(mode.as_str()) {
                w.modes.push((mode.clone(), k));
            }
            w.last_mode = Some(mode);
            let h = t.health;
            for (bit, on) in [
                ("imu_timeout", h.imu_timeout),
                ("imu_gaps", h.imu_gaps),
                ("imu_bit", h.imu_bit),
                ("gps_stale", h.gps_stale),
                ("turntable", h.turntable),
                ("filter", h.filter),
                ("gps_data", h.gps_data),
                ("can_bus", h.can_bus),
            ] {
                if on && !w.health_first.iter().any(|(b, _)| b == bit) {
                    w.health_first.push((bit.to_string(), k));
                }
            }
        }
        Some(wire::Message::NavPos(p)) => w.last_position_deg = Some([p.lat_deg, p.lon_deg]),
        Some(_) => {}
        None => w.bad_frames += 1,
    }
}

/// Follows the lines of nav's start-up procedure (north-finding, self-calibration) during a
/// run.
#[derive(Default)]
pub struct DrillWatch {
    /// The procedure's final word has come.
    pub done: bool,
}

impl DrillWatch {
    /// Handle one nav stdout line; true when it is the procedure's final word.
    pub fn line(&mut self, l: &str, show: bool) -> bool {
        for p in super::ALL {
            let name = p.name();
            let Some(rest) = l.strip_prefix("nav: ").and_then(|r| r.strip_prefix(name)) else {
                continue;
            };
            if let Some(j) = rest.strip_prefix(" progress ") {
                if show && let Ok(v) = serde_json::from_str::<serde_json::Value>(j) {
                    crate::status::show(&p.progress_line(&v));
                }
                return false;
            }
            if rest.starts_with(" result") || rest.starts_with(" aborted") {
                if show {
                    crate::status::line(l);
                }
                let first = !self.done;
                self.done = true;
                return first;
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nav_time(seq: u8, sample_count: u32) -> Option<wire::RawFrame> {
        wire::Message::NavTime(wire::NavTime {
            sample_count,
            seq,
            mode: wire::NavMode::Navigation,
            health: wire::NavHealth::default(),
            gps_rx_bytes: 0,
        })
        .encode()
        .ok()
    }

    /// Epochs heard out of order on the bus are put back by Seq, not taken for time going
    /// back; a NAV_TIME that names an earlier sample in nav's own order is.
    #[test]
    fn time_going_back_is_told_from_the_bus_reordering() {
        let mut w = SolutionWatch::default();
        let mut last = None;
        for (seq, k) in [(0, 40), (2, 120), (1, 80), (3, 160), (4, 80), (5, 240)] {
            watch_frame(&mut w, &mut last, nav_time(seq, k));
        }
        assert_eq!((w.epochs, w.reordered, w.seq_gaps), (6, 1, 0));
        assert_eq!((w.backwards, w.first_backwards), (1, Some((160, 80))));
    }
}
