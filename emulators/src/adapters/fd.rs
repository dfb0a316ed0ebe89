//! A lab's own contract on a CAN interface: the frames its mapping builds (`wire::mapping`),
//! with 29-bit identifiers where its DBC has them and CAN FD frames (the bit-rate switch on)
//! where a message is longer than 8 bytes; the interface must carry CAN FD (MTU 72:
//! `vcan_setup::ensure_vcan_fd`).

use crate::reported::SharedTrack;
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
    /// The table's report could not be put in the lab's form.
    #[error("the turntable's report at {t:.3} s in the lab's frames")]
    Report {
        /// Its time, s.
        t: f64,
        /// What the encoder said.
        source: wire::dbc::EncodeError,
    },
    /// A read failed.
    #[error("CAN interface {iface}: read failed")]
    Read {
        /// Interface.
        iface: String,
        /// Cause.
        source: std::io::Error,
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

    /// Hear only the frames of `ids` on this socket (with the kernel's receive stamps), read
    /// by [`FdWriter::drain`] without waiting.
    pub fn listen(&mut self, ids: &[FrameId]) -> Result<(), FdError> {
        use socketcan::SocketOptions;
        const EFF: u32 = 0x8000_0000;
        let filters: Vec<socketcan::CanFilter> = ids
            .iter()
            .map(|id| match *id {
                FrameId::Standard(x) => socketcan::CanFilter::new(u32::from(x), 0x7FF | EFF),
                FrameId::Extended(x) => socketcan::CanFilter::new(x | EFF, 0x1FFF_FFFF | EFF),
            })
            .collect();
        let io = |source| FdError::Read {
            iface: self.iface.clone(),
            source,
        };
        self.sock.set_filters(&filters).map_err(io)?;
        self.sock.set_nonblocking(true).map_err(io)?;
        // a socket without stamps gives its frames their read times
        let _ = self.sock.set_recv_timestamp(true);
        Ok(())
    }

    /// Every frame waiting on the socket, each to `f` with its identifier, its data and its
    /// kernel receive stamp (ns of the UNIX clock), until none is left.
    pub fn drain(&mut self, mut f: impl FnMut(FrameId, &[u8], Option<u64>)) -> Result<(), FdError> {
        use socketcan::CanAnyFrame;
        loop {
            let (frame, ts) = match self.sock.read_frame_with_timestamps() {
                Ok(x) => x,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Ok(()),
                // the interface went down: nothing to read meanwhile
                Err(e) if e.raw_os_error() == Some(libc::ENETDOWN) => return Ok(()),
                Err(source) => {
                    return Err(FdError::Read {
                        iface: self.iface.clone(),
                        source,
                    });
                }
            };
            let stamp = ts.socket.or(ts.sw).and_then(|w| {
                w.duration_since(std::time::UNIX_EPOCH)
                    .ok()
                    .map(|d| d.as_nanos() as u64)
            });
            let (id, data) = match &frame {
                CanAnyFrame::Normal(d) => (d.id(), d.data().to_vec()),
                CanAnyFrame::Fd(d) => (d.id(), d.data().to_vec()),
                _ => continue,
            };
            let id = match id {
                socketcan::Id::Standard(x) => FrameId::Standard(x.as_raw()),
                socketcan::Id::Extended(x) => FrameId::Extended(x.as_raw()),
            };
            f(id, &data, stamp);
        }
    }
}

/// The emulated IMU on a lab's contract, ready to run: its model, its quantities, its framer,
/// and, where it rides the table, the table's reports it follows and the samples' record for
/// the judge.
pub struct MappedImuRun<'a> {
    /// The unit's model (truth and errors).
    pub imu: crate::imu::ImuEmulator,
    /// Its samples as the mapping's quantities.
    pub mapped: crate::imu::mapped::MappedImu,
    /// Its frames.
    pub framer: wire::mapping::Framer<'a>,
    /// Its samples per second.
    pub rate_hz: f64,
    /// The table's reports in the lab's form, and the axes they move (the IMU's truth turns
    /// as they say); none: the unit stands still.
    pub table: Option<(wire::mapping::TableSide<'a>, Vec<SharedTrack>)>,
    /// Where each sample's write is recorded (the judge's latency and time tags).
    pub sent: Option<std::sync::Arc<super::freerun::SentSamples>>,
}

/// The emulated IMU speaking a lab's contract on `iface`, free-running on the host's clock
/// (`p`): each sample measured by the model, as the mapping's quantities, framed (counters,
/// alive counters and checksums), written when its frame is complete and due, until
/// `p.until_s` or `stop`. Before each write, the table's reports since the last one enter the
/// truth at their kernel receive stamps.
pub fn run_mapped_imu(
    iface: &str,
    mut run: MappedImuRun,
    p: &super::freerun::Pacing,
    stop: &std::sync::atomic::AtomicBool,
    progress: &super::transport::Progress,
) -> Result<super::freerun::FreeStats, FdError> {
    use std::sync::atomic::Ordering;
    let mut out = FdWriter::open(iface)?;
    if let Some((side, _)) = &run.table {
        out.listen(&[side.report_id()])?;
    }
    let stamps = super::freerun::Stamps::new(p);
    let clock = p.clock();
    let mut late = super::freerun::Lateness::default();
    let mut behind = None;
    let started = std::time::Instant::now();
    let mut reached = 0.0;
    let mut block: Vec<u64> = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        let s = run.imu.next_sample();
        let t = (s.k + 1) as f64 / run.rate_hz;
        if t > p.until_s {
            break;
        }
        let frames = run
            .framer
            .push(run.mapped.sample(s.k, &s.measured))
            .map_err(|source| FdError::Encode {
                sample: s.k,
                source,
            })?;
        reached = t;
        block.push(s.k);
        if frames.is_empty() {
            continue;
        }
        let due = p.origin + std::time::Duration::from_secs_f64(t / p.speed);
        let now = std::time::Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        if let Some((side, tracks)) = &run.table {
            let now = clock.now();
            out.drain(|_, data, stamp| {
                if let Ok((axis, angle, encoder)) = side.read_report(data)
                    && let Some(tr) = tracks.get(axis)
                {
                    tr.lock().unwrap_or_else(|e| e.into_inner()).report(
                        stamps.at(stamp, now),
                        angle.rem_euclid(360.0),
                        encoder,
                    );
                }
            })?;
        }
        // kept before the write: a device may answer before the write returns
        if let Some(sent) = &run.sent {
            let at = std::time::Instant::now();
            for k in block.drain(..) {
                sent.push(k, k as u16, at);
            }
        }
        block.clear();
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
    let followed = run.table.as_ref().map_or_else(Vec::new, |(_, tracks)| {
        tracks
            .iter()
            .map(|t| t.lock().unwrap_or_else(|e| e.into_inner()).stats)
            .collect()
    });
    Ok(super::freerun::FreeStats {
        device: "imu".into(),
        port: iface.into(),
        speed: p.speed,
        reached_s: reached,
        wall_s: started.elapsed().as_secs_f64(),
        written: out.written,
        lateness: late.summary(),
        behind,
        followed,
        ..Default::default()
    })
}

/// The turntable's controller on a lab's contract, free-running on `iface` with its loop at
/// `tick_hz`: the lab's command frames since the last tick taken as ours (`side`), the
/// mechanism moved to the tick's time, its status reports sent in the lab's form (alive
/// counter and checksum by `protector`; the acknowledged sequence rides in them). A command
/// frame that does not decode is counted in the table's bad frames.
#[allow(clippy::too_many_arguments)]
pub fn run_mapped_turntable(
    iface: &str,
    tt: &mut crate::turntable::ttbus::TtBus,
    side: &wire::mapping::TableSide,
    protector: &mut wire::mapping::Protector,
    tick_hz: f64,
    p: &super::freerun::Pacing,
    stop: &std::sync::atomic::AtomicBool,
    progress: &super::transport::Progress,
) -> Result<super::freerun::FreeStats, FdError> {
    use std::sync::atomic::Ordering;
    let mut out = FdWriter::open(iface)?;
    out.listen(&[side.command_id()])?;
    let clock = p.clock();
    let started = std::time::Instant::now();
    let mut late = super::freerun::Lateness::default();
    let (mut msgs, mut due) = (Vec::new(), Vec::new());
    let (mut behind, mut k, mut bad) = (None, 0u64, 0u64);
    loop {
        let t = (k + 1) as f64 / tick_hz;
        if behind.is_some() || t > p.until_s || !super::freerun::sleep_until(&clock, t, stop) {
            break;
        }
        due.clear();
        out.drain(|_, data, _| match side.command(data) {
            Ok(c) => {
                msgs.clear();
                tt.receive(t, c, &mut msgs);
                due.append(&mut msgs);
            }
            Err(_) => bad += 1,
        })?;
        tt.after_sample(k, t, &mut due);
        let mut wrote = false;
        for m in &due {
            if let wire::Message::TtStatus(st) = m {
                let f = side
                    .report(st, protector)
                    .map_err(|source| FdError::Report { t, source })?;
                out.write(&f)?;
                wrote = true;
            }
            tt.sent(m);
        }
        if wrote {
            behind = super::freerun::measure(&mut late, &clock, t, p, || {
                format!("the turntable's tick at {t:.3} s")
            });
        }
        progress.sim_us.store((t * 1e6) as u64, Ordering::Relaxed);
        k += 1;
    }
    tt.stats.bad_frames += bad;
    Ok(super::freerun::FreeStats {
        device: "turntable".into(),
        port: iface.into(),
        speed: p.speed,
        reached_s: k as f64 / tick_hz,
        wall_s: started.elapsed().as_secs_f64(),
        written: out.written,
        lateness: late.summary(),
        behind,
        turntable: Some(tt.stats),
        ..Default::default()
    })
}
