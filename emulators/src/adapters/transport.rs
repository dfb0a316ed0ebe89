//! Transport: puts emulator frames on a CAN interface (vcan on the bench), paced by the
//! simulated clock. The pure pieces it writes (the IMU's stream with its faults, the
//! turntable on the bus) are in `stream` and `ttbus`.

use socketcan::{CanSocket, Socket, SocketOptions};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};
use thiserror::Error;
use wire::RawFrame;

pub use crate::imu::stream::{BusFaults, BusStream, TxStats};
pub use crate::turntable::ttbus::TurntableTxStats;

/// Transport failures.
#[derive(Debug, Error)]
pub enum CanTxError {
    /// The interface could not be opened.
    #[error("CAN interface {iface}: cannot open")]
    Open {
        /// Interface.
        iface: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A write failed.
    #[error("CAN interface {iface}: write of frame 0x{id:03X} failed")]
    Write {
        /// Interface.
        iface: String,
        /// Frame id.
        id: u16,
        /// Cause.
        source: std::io::Error,
    },
    /// The log of sent frames could not be written.
    #[error("log of the frames sent, {path}")]
    Log {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A read failed (the turntable reading its commands).
    #[error("CAN interface {iface}: reading turntable commands failed")]
    Read {
        /// Interface.
        iface: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The client said it wrote commands the turntable never received.
    #[error(
        "CAN interface {iface}: the client wrote {written} turntable commands, {taken} arrived"
    )]
    CommandsMissing {
        /// Interface.
        iface: String,
        /// Commands the client wrote.
        written: u64,
        /// Commands that arrived.
        taken: u64,
    },
    /// A scheduled link outage could not switch the interface.
    #[error("CAN interface {iface}: could not {} the link", if *up { "bring up" } else { "take down" })]
    Link {
        /// Interface.
        iface: String,
        /// It was to come up (else to go down).
        up: bool,
        /// Cause.
        source: std::io::Error,
    },
}

/// A `candump -l` log of the frames the bench put on the bus: what its emulators sent, each
/// line stamped with the wall time of its write (µs, as `candump` stamps the time it received a
/// frame), so that the real tools (`canplayer`, `cantools`) and `hil replay` read it. Frames
/// lost to a downed interface are not in it: they never reached the bus.
///
/// While the bus runs, each frame costs a 19-byte binary record in a buffered file beside the
/// log (formatting text lines at 40,000 frames a second took CPU from nav on a 2-core guest);
/// [`SentLog::finish`] writes the text after the run.
pub struct SentLog {
    out: std::io::BufWriter<std::fs::File>,
    path: std::path::PathBuf,
    raw: std::path::PathBuf,
    iface: String,
    lines: u64,
}

/// Bytes of one binary record: time µs (8), the kernel's identifier (4: `CAN_ERR_FLAG` for an
/// error frame), length (1), data (8).
const SENT_RECORD: usize = 21;

impl SentLog {
    /// Create the log file `path` for frames written on `iface`.
    pub fn create(path: &std::path::Path, iface: &str) -> Result<Self, CanTxError> {
        let raw = path.with_extension("log.partial");
        let file = std::fs::File::create(&raw).map_err(|source| CanTxError::Log {
            path: raw.display().to_string(),
            source,
        })?;
        Ok(Self {
            out: std::io::BufWriter::with_capacity(1 << 16, file),
            path: path.into(),
            raw,
            iface: iface.into(),
            lines: 0,
        })
    }

    fn err(&self, source: std::io::Error) -> CanTxError {
        CanTxError::Log {
            path: self.path.display().to_string(),
            source,
        }
    }

    /// Frames just written to the bus.
    pub(crate) fn frames(&mut self, frames: &[RawFrame]) -> Result<(), CanTxError> {
        let t_us = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_micros() as u64);
        for f in frames {
            self.record(t_us, u32::from(f.id), f.len, &f.data)?;
        }
        Ok(())
    }

    /// A frame over on the bus model at `t_ns` of simulated time.
    pub fn frame_at(&mut self, t_ns: u64, f: &RawFrame) -> Result<(), CanTxError> {
        self.record(t_ns / 1000, u32::from(f.id), f.len, &f.data)
    }

    /// A step's entries of the bus model's log ([`crate::step::Step::trace`]).
    pub fn trace(&mut self, entries: &[(u64, crate::step::Traced)]) -> Result<(), CanTxError> {
        for (t_ns, x) in entries {
            match x {
                crate::step::Traced::Frame(f) => self.frame_at(*t_ns, f)?,
                crate::step::Traced::Error(e) => self.error_at(*t_ns, e)?,
            }
        }
        Ok(())
    }

    /// An error frame raised at `t_ns` of simulated time.
    pub fn error_at(
        &mut self,
        t_ns: u64,
        e: &wire::errframe::ErrorFrame,
    ) -> Result<(), CanTxError> {
        self.record(t_ns / 1000, e.can_id(), 8, &e.data)
    }

    fn record(
        &mut self,
        t_us: u64,
        can_id: u32,
        len: u8,
        data: &[u8; 8],
    ) -> Result<(), CanTxError> {
        use std::io::Write;
        let mut rec = [0u8; SENT_RECORD];
        rec[..8].copy_from_slice(&t_us.to_le_bytes());
        rec[8..12].copy_from_slice(&can_id.to_le_bytes());
        rec[12] = len;
        rec[13..].copy_from_slice(data);
        self.out.write_all(&rec).map_err(|e| self.err(e))?;
        self.lines += 1;
        Ok(())
    }

    /// Write the text log from the records; the lines written.
    pub fn finish(mut self) -> Result<u64, CanTxError> {
        use std::io::{Read, Write};
        self.out.flush().map_err(|e| self.err(e))?;
        let mut raw =
            std::io::BufReader::new(std::fs::File::open(&self.raw).map_err(|e| self.err(e))?);
        let text = std::fs::File::create(&self.path).map_err(|e| self.err(e))?;
        let mut text = std::io::BufWriter::with_capacity(1 << 16, text);
        let mut rec = [0u8; SENT_RECORD];
        let mut line = String::with_capacity(64);
        for _ in 0..self.lines {
            raw.read_exact(&mut rec).map_err(|e| self.err(e))?;
            let mut data = [0u8; 8];
            data.copy_from_slice(&rec[13..]);
            let can_id = u32::from_le_bytes([rec[8], rec[9], rec[10], rec[11]]);
            let t_us = u64::from_le_bytes(rec[..8].try_into().unwrap_or([0; 8]));
            line.clear();
            if can_id & wire::errframe::CAN_ERR_FLAG != 0 {
                let e = wire::errframe::ErrorFrame {
                    class: can_id & wire::errframe::CAN_ERR_MASK,
                    data,
                };
                line.push_str(&wire::candump::format_error_line(t_us, &self.iface, &e));
            } else {
                let f = RawFrame {
                    id: (can_id & 0x7FF) as u16,
                    len: rec[12],
                    data,
                };
                wire::candump::push_line(&mut line, t_us, &self.iface, &f);
            }
            line.push('\n');
            text.write_all(line.as_bytes()).map_err(|e| self.err(e))?;
        }
        text.flush().map_err(|e| self.err(e))?;
        let _ = std::fs::remove_file(&self.raw);
        Ok(self.lines)
    }
}

#[cfg(test)]
mod sent_log_tests {
    use super::*;

    /// What goes in comes out as `candump -l` lines, in order, and the binary file is gone.
    #[test]
    fn the_sent_log_reads_as_candump_lines() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("bench-can.log");
        let mut log = SentLog::create(&p, "vcan0").unwrap();
        let f = |id: u16, len: u8| RawFrame {
            id,
            len,
            data: [1, 2, 3, 4, 5, 6, 7, 8],
        };
        log.frames(&[f(0x080, 8), f(0x102, 3)]).unwrap();
        log.frames(&[f(0x7FF, 0)]).unwrap();
        assert_eq!(log.finish().unwrap(), 3);
        let text = std::fs::read_to_string(&p).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3);
        assert!(
            lines[0].ends_with(" vcan0 080#0102030405060708"),
            "{}",
            lines[0]
        );
        assert!(lines[1].ends_with(" vcan0 102#010203"), "{}", lines[1]);
        assert!(lines[2].ends_with(" vcan0 7FF#"), "{}", lines[2]);
        assert!(!d.path().join("bench-can.log.partial").exists());
    }
}

/// Write one frame, retrying while the transmit queue is full; returns the retries.
pub(crate) fn write(sock: &CanSocket, iface: &str, f: &RawFrame) -> Result<u64, CanTxError> {
    write_all(sock, iface, std::slice::from_ref(f)).map(|w| w.retries)
}

/// What a write did.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Written {
    /// Retries while the transmit queue was full.
    pub retries: u64,
    /// Frames lost because the interface was down (`ip link set ... down`).
    pub lost_down: u64,
}

/// Write `frames` in order with as few system calls as the kernel allows (`sendmmsg`), retrying
/// while the transmit queue is full. While the interface is down the frames are lost, as on a
/// bus whose controller is off: counted, not an error.
pub(crate) fn write_all(
    sock: &CanSocket,
    iface: &str,
    frames: &[RawFrame],
) -> Result<Written, CanTxError> {
    use std::os::fd::AsRawFd;
    let (mut done, mut retries) = (0, 0u64);
    let mut deadline = Instant::now() + Duration::from_secs(2);
    while done < frames.len() {
        match wire::send_batch(sock.as_raw_fd(), &frames[done..]) {
            Ok(n) if n > 0 => {
                done += n;
                deadline = Instant::now() + Duration::from_secs(2);
            }
            Ok(_) => retries += 1,
            Err(e) if e.raw_os_error() == Some(libc::ENETDOWN) => {
                tracing::debug!(interface = iface, "interface down: frames lost");
                return Ok(Written {
                    retries,
                    lost_down: (frames.len() - done) as u64,
                });
            }
            Err(e)
                if (e.raw_os_error() == Some(libc::ENOBUFS)
                    || e.kind() == std::io::ErrorKind::WouldBlock
                    || e.kind() == std::io::ErrorKind::Interrupted)
                    && Instant::now() < deadline =>
            {
                retries += 1;
                std::thread::sleep(Duration::from_micros(200));
            }
            Err(source) => {
                return Err(CanTxError::Write {
                    iface: iface.into(),
                    id: frames[done].id,
                    source,
                });
            }
        }
    }
    Ok(Written {
        retries,
        lost_down: 0,
    })
}

/// Live progress shared with the caller and the other emulators: the simulated time the IMU
/// stream has reached. It is the bench's "now": when the IMU falls behind the wall clock (a slow
/// machine at a high speed factor) the other emulators wait for it rather than run ahead.
#[derive(Debug, Default)]
pub struct Progress {
    /// Simulated time reached, microseconds.
    pub sim_us: AtomicU64,
}

impl Progress {
    /// Simulated time reached, s.
    pub fn now(&self) -> f64 {
        self.sim_us.load(Ordering::Acquire) as f64 * 1e-6
    }

    pub(crate) fn set(&self, t: f64) {
        self.sim_us.store((t * 1e6) as u64, Ordering::Release);
    }
}

/// The lockstep of a turntable alone on the bus with the client that commands it (the
/// validation suite): the client asks for a time, saying how many commands it has written; the
/// mechanism takes exactly those commands, writes its frames up to that time and says how many.
/// Both sides wait on these counts, never on the wall clock, so a run is the same at any pace and
/// on a loaded host; the wall clock only bounds how long a side waits for the other to answer.
#[derive(Debug, Default)]
pub struct TtLockstep {
    state: std::sync::Mutex<LockstepState>,
    changed: std::sync::Condvar,
}

#[derive(Debug, Default, Clone, Copy)]
struct LockstepState {
    /// The time the client asks for, µs.
    target_us: u64,
    /// TT_CMD frames the client has written.
    commands_written: u64,
    /// The time the mechanism has reached, µs.
    reached_us: u64,
    /// Frames (TT_ACK, TT_STATUS) the mechanism has written.
    frames_written: u64,
}

impl TtLockstep {
    fn state(&self) -> std::sync::MutexGuard<'_, LockstepState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The client: reach `t_s`, the client having written `commands` TT_CMD frames in all.
    pub fn ask(&self, t_s: f64, commands: u64) {
        let mut s = self.state();
        s.target_us = (t_s * 1e6).round() as u64;
        s.commands_written = commands;
        self.changed.notify_all();
    }

    /// The client: wait up to `within` of wall time for the mechanism to reach what was asked;
    /// the frames it has written in all, or none when it did not answer in time.
    pub fn wait_reached(&self, within: Duration) -> Option<u64> {
        let s = self.state();
        let (s, _) = self
            .changed
            .wait_timeout_while(s, within, |s| s.reached_us < s.target_us)
            .unwrap_or_else(|e| e.into_inner());
        (s.reached_us >= s.target_us).then_some(s.frames_written)
    }

    /// The mechanism: the next time asked for past `reached_us` and the commands written by
    /// then, waiting up to `within` of wall time (none: nothing new yet).
    fn wait_asked(&self, reached_us: u64, within: Duration) -> Option<(u64, u64)> {
        let s = self.state();
        let (s, _) = self
            .changed
            .wait_timeout_while(s, within, |s| s.target_us <= reached_us)
            .unwrap_or_else(|e| e.into_inner());
        (s.target_us > reached_us).then_some((s.target_us, s.commands_written))
    }

    /// The mechanism: it has reached `t_us`, having written `frames` frames in all.
    fn reached(&self, t_us: u64, frames: u64) {
        let mut s = self.state();
        s.reached_us = t_us;
        s.frames_written = frames;
        self.changed.notify_all();
    }
}

/// Run the turntable on `iface` in lockstep with its client (`ls`) until `stop` is set: the
/// commands the client wrote before asking for a time are taken at the time reached before it
/// (TT_ACK out at once), then TT_STATUS at the mechanism's status rate up to the time asked for.
/// `progress` shows the time reached.
pub fn run_turntable(
    iface: &str,
    mut tt: crate::turntable::Turntable,
    ls: &TtLockstep,
    progress: &Progress,
    stop: &AtomicBool,
) -> Result<TurntableTxStats, CanTxError> {
    // how long the client may leave a command it said it wrote unread: liveness only
    const COMMAND_WAIT: Duration = Duration::from_secs(30);
    let sock = CanSocket::open(iface).map_err(|source| CanTxError::Open {
        iface: iface.into(),
        source,
    })?;
    // only commands: the IMU's 4,000 frames/s are not ours to read
    let _ = sock.set_filters(&[socketcan::CanFilter::new(0x100, 0x7FF)]);
    let mut st = TurntableTxStats::default();
    let period = 1.0 / tt.params().status_hz;
    let mut next_status = 0.0;
    let (mut reached_us, mut taken) = (0u64, 0u64);
    let mut acks = Vec::new();
    let send = |m: wire::Message, st: &mut TurntableTxStats| -> Result<(), CanTxError> {
        if let Ok(f) = m.encode() {
            write(&sock, iface, &f)?;
            match m {
                wire::Message::TtAck(_) => st.acks += 1,
                _ => st.status_frames += 1,
            }
        }
        Ok(())
    };
    while !stop.load(Ordering::Relaxed) {
        let Some((target_us, written)) = ls.wait_asked(reached_us, Duration::from_millis(50))
        else {
            continue;
        };
        let t = reached_us as f64 * 1e-6;
        let since = Instant::now();
        while taken < written && !stop.load(Ordering::Relaxed) {
            match sock.read_frame_timeout(Duration::from_millis(20)) {
                Ok(f) => {
                    taken += 1;
                    match wire::from_can_frame(&f)
                        .ok()
                        .and_then(|r| wire::Message::decode(&r).ok())
                    {
                        Some(wire::Message::TtCmd(c)) => {
                            st.commands += 1;
                            match tt.command(t, c) {
                                Some(a) => send(wire::Message::TtAck(a), &mut st)?,
                                None if tt.params().faults.lost_command_seqs.contains(&c.seq) => {
                                    st.lost_commands += 1
                                }
                                None => {}
                            }
                        }
                        _ => st.bad_frames += 1,
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
                    ) =>
                {
                    if since.elapsed() > COMMAND_WAIT {
                        return Err(CanTxError::CommandsMissing {
                            iface: iface.into(),
                            written,
                            taken,
                        });
                    }
                }
                Err(source) => {
                    return Err(CanTxError::Read {
                        iface: iface.into(),
                        source,
                    });
                }
            }
        }
        let t1 = target_us as f64 * 1e-6;
        while next_status <= t1 {
            acks.clear();
            tt.advance(next_status, &mut acks);
            for a in acks.drain(..) {
                send(wire::Message::TtAck(a), &mut st)?;
            }
            for s in tt.status(next_status) {
                send(wire::Message::TtStatus(s), &mut st)?;
            }
            next_status += period;
        }
        reached_us = target_us;
        progress.set(t1);
        ls.reached(reached_us, st.acks + st.status_frames);
    }
    Ok(st)
}
