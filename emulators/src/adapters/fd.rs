//! A lab's own contract on a CAN interface: the frames its mapping builds (`wire::mapping`),
//! with 29-bit identifiers where its DBC has them and CAN FD frames (the bit-rate switch on)
//! where a message is longer than 8 bytes; the interface must carry CAN FD (MTU 72:
//! `vcan_setup::ensure_vcan_fd`).

use socketcan::{
    CanDataFrame, CanFdFrame, CanFdSocket, EmbeddedFrame, ExtendedId, Socket, StandardId,
};
use thiserror::Error;
use wire::dbc::FrameId;
use wire::mapping::MappedFrame;

/// What went wrong putting a lab's frames on the bus.
#[derive(Debug, Error)]
pub enum FdError {
    /// The interface could not be opened for CAN FD.
    #[error("CAN interface {iface}: cannot open it for CAN FD frames")]
    Open {
        /// Interface.
        iface: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A frame the bus cannot carry (an identifier out of range, more than 64 bytes).
    #[error("CAN interface {iface}: frame {id} of {len} bytes is not a CAN frame")]
    Frame {
        /// Interface.
        iface: String,
        /// Identifier.
        id: String,
        /// Its length.
        len: usize,
    },
    /// A sample the mapping could not encode (a value its signal cannot carry).
    #[error("the IMU's sample {sample} in the lab's frames")]
    Encode {
        /// The sample.
        sample: u64,
        /// What the encoder said.
        source: wire::dbc::EncodeError,
    },
    /// A write failed.
    #[error("CAN interface {iface}: write of frame {id} failed")]
    Write {
        /// Interface.
        iface: String,
        /// Identifier.
        id: String,
        /// Cause.
        source: std::io::Error,
    },
}

/// The socket a lab's frames go out on.
pub struct FdWriter {
    sock: CanFdSocket,
    iface: String,
    /// Frames written.
    pub written: u64,
}

impl FdWriter {
    /// Open `iface` for CAN FD frames.
    pub fn open(iface: &str) -> Result<Self, FdError> {
        let sock = CanFdSocket::open(iface).map_err(|source| FdError::Open {
            iface: iface.into(),
            source,
        })?;
        Ok(Self {
            sock,
            iface: iface.into(),
            written: 0,
        })
    }

    /// Write frame `f`: CAN FD with the bit-rate switch when longer than 8 bytes, else classic.
    pub fn write(&mut self, f: &MappedFrame) -> Result<(), FdError> {
        let bad = || FdError::Frame {
            iface: self.iface.clone(),
            id: f.id.to_string(),
            len: f.data.len(),
        };
        let id: socketcan::Id = match f.id {
            FrameId::Standard(x) => StandardId::new(x).ok_or_else(bad)?.into(),
            FrameId::Extended(x) => ExtendedId::new(x).ok_or_else(bad)?.into(),
        };
        let r = if f.data.len() > 8 {
            let mut fd = CanFdFrame::new(id, &f.data).ok_or_else(bad)?;
            fd.set_brs(true);
            self.sock.write_frame(&fd)
        } else {
            let classic = CanDataFrame::new(id, &f.data).ok_or_else(bad)?;
            self.sock.write_frame(&classic)
        };
        r.map_err(|source| FdError::Write {
            iface: self.iface.clone(),
            id: f.id.to_string(),
            source,
        })?;
        self.written += 1;
        Ok(())
    }
}

/// The emulated IMU speaking a lab's contract on `iface`, free-running on the host's clock
/// (`p`): each sample measured by `imu`, as the mapping's quantities (`mapped`), framed by
/// `framer` (counters, alive counters and checksums), written when its frame is complete and
/// due, until `p.until_s` or `stop`. `rate_hz`: the unit's samples per second.
#[allow(clippy::too_many_arguments)]
pub fn run_mapped_imu(
    iface: &str,
    mut imu: crate::imu::ImuEmulator,
    mut mapped: crate::imu::mapped::MappedImu,
    framer: &mut wire::mapping::Framer,
    rate_hz: f64,
    p: &super::freerun::Pacing,
    stop: &std::sync::atomic::AtomicBool,
    progress: &super::transport::Progress,
) -> Result<super::freerun::FreeStats, FdError> {
    use std::sync::atomic::Ordering;
    let mut out = FdWriter::open(iface)?;
    let mut late = super::freerun::Lateness::default();
    let mut behind = None;
    let started = std::time::Instant::now();
    let mut reached = 0.0;
    while !stop.load(Ordering::Relaxed) {
        let s = imu.next_sample();
        let t = (s.k + 1) as f64 / rate_hz;
        if t > p.until_s {
            break;
        }
        let frames = framer
            .push(mapped.sample(s.k, &s.measured))
            .map_err(|source| FdError::Encode {
                sample: s.k,
                source,
            })?;
        reached = t;
        if frames.is_empty() {
            continue;
        }
        let due = p.origin + std::time::Duration::from_secs_f64(t / p.speed);
        let now = std::time::Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        for f in &frames {
            out.write(f)?;
        }
        let l = std::time::Instant::now().saturating_duration_since(due);
        late.add(l);
        progress.sim_us.store((t * 1e6) as u64, Ordering::Relaxed);
        if l > p.max_late {
            behind = Some(format!(
                "{:.1} ms late at {t:.3} s: the host could not keep real time",
                l.as_secs_f64() * 1e3
            ));
            break;
        }
    }
    Ok(super::freerun::FreeStats {
        device: "imu".into(),
        port: iface.into(),
        speed: p.speed,
        reached_s: reached,
        wall_s: started.elapsed().as_secs_f64(),
        written: out.written,
        lateness: late.summary(),
        behind,
        ..Default::default()
    })
}
