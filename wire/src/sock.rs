//! Conversion between [`RawFrame`] and `socketcan::CanFrame`.

use crate::RawFrame;
use socketcan::{CanFrame, EmbeddedFrame, Id, StandardId};
use thiserror::Error;

/// A socketcan frame that is not a classic standard-id data frame.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum FrameConvError {
    /// Extended identifier.
    #[error("extended-id frame 0x{0:08X}: the contract uses 11-bit ids only")]
    Extended(u32),
    /// Remote request.
    #[error("remote frame 0x{0:03X}: the contract has no remote frames")]
    Remote(u32),
    /// Error frame from the controller.
    #[error("CAN error frame (class 0x{:08X}: {})", .0.class, .0.describe())]
    Error(crate::errframe::ErrorFrame),
    /// Id out of range for a standard frame.
    #[error("id 0x{0:X} does not fit an 11-bit identifier")]
    BadId(u16),
}

/// Convert a received socketcan frame.
pub fn from_can_frame(f: &CanFrame) -> Result<RawFrame, FrameConvError> {
    match f {
        CanFrame::Data(d) => match d.id() {
            Id::Standard(id) => {
                let mut data = [0u8; 8];
                let p = d.data();
                data[..p.len()].copy_from_slice(p);
                Ok(RawFrame {
                    id: id.as_raw(),
                    len: p.len() as u8,
                    data,
                })
            }
            Id::Extended(id) => Err(FrameConvError::Extended(id.as_raw())),
        },
        CanFrame::Remote(r) => Err(FrameConvError::Remote(match r.id() {
            Id::Standard(id) => u32::from(id.as_raw()),
            Id::Extended(id) => id.as_raw(),
        })),
        CanFrame::Error(e) => {
            let mut data = [0u8; 8];
            let p = e.data();
            data[..p.len().min(8)].copy_from_slice(&p[..p.len().min(8)]);
            Err(FrameConvError::Error(crate::errframe::ErrorFrame {
                class: e.error_bits(),
                data,
            }))
        }
    }
}

/// Convert a frame for sending.
pub fn to_can_frame(f: &RawFrame) -> Result<CanFrame, FrameConvError> {
    let id = StandardId::new(f.id).ok_or(FrameConvError::BadId(f.id))?;
    CanFrame::new(id, f.payload()).ok_or(FrameConvError::BadId(f.id))
}

/// The kernel's `struct can_frame` (classic CAN) as `sendmmsg`/`recvmmsg` move it.
#[repr(C)]
#[derive(Clone, Copy, Default)]
struct KernelFrame {
    can_id: u32,
    len: u8,
    pad: u8,
    res0: u8,
    len8_dlc: u8,
    data: [u8; 8],
}

const CAN_EFF_FLAG: u32 = 0x8000_0000;
const CAN_RTR_FLAG: u32 = 0x4000_0000;
const CAN_ERR_FLAG: u32 = 0x2000_0000;

/// Most frames moved by one system call.
pub const BATCH: usize = 64;

/// Control-message room per received frame: one `SCM_TIMESTAMPNS` (a timespec) with its
/// header, aligned (`CMSG_SPACE(16)` is 32 on 64-bit Linux), with margin.
const CONTROL_BYTES: usize = 64;

/// A control buffer, aligned for `cmsghdr`.
#[repr(C, align(8))]
#[derive(Clone, Copy)]
struct Control([u8; CONTROL_BYTES]);

/// Run `call` over one message header per frame (at most [`BATCH`]), each with its control
/// buffer when `control` is given (whose lengths, as the kernel set them, go to its second
/// slice); returns how many messages it moved. Everything stays on the stack: this is on nav's
/// receive path, once per wake-up.
fn mmsg_call(
    frames: &mut [KernelFrame],
    mut control: Option<(&mut [Control], &mut [usize])>,
    call: impl FnOnce(*mut libc::mmsghdr, u32) -> libc::c_int,
) -> std::io::Result<usize> {
    let n = frames.len().min(BATCH);
    // SAFETY: all-zero iovecs and message headers are valid (no buffers, no name, no control).
    let mut iov: [libc::iovec; BATCH] = unsafe { std::mem::zeroed() };
    // SAFETY: as above.
    let mut hdrs: [libc::mmsghdr; BATCH] = unsafe { std::mem::zeroed() };
    for (i, ((f, v), h)) in frames
        .iter_mut()
        .zip(&mut iov)
        .zip(&mut hdrs)
        .enumerate()
        .take(n)
    {
        v.iov_base = (f as *mut KernelFrame).cast();
        v.iov_len = std::mem::size_of::<KernelFrame>();
        h.msg_hdr.msg_iov = v;
        h.msg_hdr.msg_iovlen = 1;
        if let Some(c) = control.as_mut().and_then(|(c, _)| c.get_mut(i)) {
            h.msg_hdr.msg_control = c.0.as_mut_ptr().cast();
            h.msg_hdr.msg_controllen = CONTROL_BYTES as _;
        }
    }
    let r = call(hdrs.as_mut_ptr(), n as u32);
    if r < 0 {
        return Err(std::io::Error::last_os_error());
    }
    if let Some((_, lens)) = control {
        for (len, h) in lens.iter_mut().zip(&hdrs).take(r as usize) {
            // msg_controllen is a size_t on glibc, a socklen_t on musl
            #[allow(clippy::unnecessary_cast)]
            let l = h.msg_hdr.msg_controllen as usize;
            *len = l;
        }
    }
    Ok(r as usize)
}

/// The `SCM_TIMESTAMPNS` time in a received message's control data, ns since the epoch.
fn timestamp_ns(c: &Control, len: usize) -> Option<u64> {
    // SAFETY: a msghdr over the buffer as the kernel filled it (`len` bytes of control data);
    // the CMSG_* functions only walk within msg_control..msg_control + msg_controllen, and the
    // timespec is read unaligned.
    unsafe {
        let mut h: libc::msghdr = std::mem::zeroed();
        h.msg_control = c.0.as_ptr() as *mut libc::c_void;
        h.msg_controllen = len.min(CONTROL_BYTES) as _;
        let mut m = libc::CMSG_FIRSTHDR(&h);
        while !m.is_null() {
            if (*m).cmsg_level == libc::SOL_SOCKET && (*m).cmsg_type == libc::SCM_TIMESTAMPNS {
                let ts: libc::timespec = std::ptr::read_unaligned(libc::CMSG_DATA(m).cast());
                return Some((ts.tv_sec as u64) * 1_000_000_000 + ts.tv_nsec as u64);
            }
            m = libc::CMSG_NXTHDR(&h, m);
        }
    }
    None
}

/// Send the error frame `e` on the CAN raw socket `fd` (as a controller's driver would raise
/// it; on vcan every socket with an error filter receives it).
pub fn send_error_frame(
    fd: std::os::fd::RawFd,
    e: &crate::errframe::ErrorFrame,
) -> std::io::Result<()> {
    let k = KernelFrame {
        can_id: e.can_id(),
        len: 8,
        data: e.data,
        ..Default::default()
    };
    // SAFETY: one live, initialised KernelFrame of its own size.
    let n = unsafe {
        libc::write(
            fd,
            (&k as *const KernelFrame).cast(),
            std::mem::size_of::<KernelFrame>(),
        )
    };
    if n < 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Sets the error classes socket `fd` receives as error frames (`CAN_RAW_ERR_FILTER`; 0: none,
/// the kernel's default; [`crate::errframe::CAN_ERR_MASK`]: all).
pub fn set_error_filter(fd: std::os::fd::RawFd, mask: u32) -> std::io::Result<()> {
    // SAFETY: a u32 option value of its own size for a CAN raw socket option.
    let r = unsafe {
        libc::setsockopt(
            fd,
            libc::SOL_CAN_RAW,
            libc::CAN_RAW_ERR_FILTER,
            (&mask as *const u32).cast(),
            std::mem::size_of::<u32>() as libc::socklen_t,
        )
    };
    if r != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Send `frames` on the CAN raw socket `fd`, up to [`BATCH`] per system call (`sendmmsg`).
/// Returns how many went out: fewer than given when the socket would block or the transmit queue
/// is full after the first ones (the caller retries the rest); an error only when none did.
pub fn send_batch(fd: std::os::fd::RawFd, frames: &[RawFrame]) -> std::io::Result<usize> {
    let mut k = [KernelFrame::default(); BATCH];
    for (d, f) in k.iter_mut().zip(frames) {
        *d = KernelFrame {
            can_id: u32::from(f.id),
            len: f.len.min(8),
            data: f.data,
            ..Default::default()
        };
    }
    let k = &mut k[..frames.len().min(BATCH)];
    // SAFETY: every header points at one live iovec over one live KernelFrame.
    mmsg_call(k, None, |h, n| unsafe { libc::sendmmsg(fd, h, n, 0) })
}

/// Wait until the socket `fd` has something to read, or `timeout` passes (a signal ends the
/// wait early too): one `poll`, so a reader takes what came in one [`recv_batch`] rather than
/// a system call per frame.
pub fn wait_readable(fd: std::os::fd::RawFd, timeout: std::time::Duration) {
    let mut p = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let ms = libc::c_int::try_from(timeout.as_millis()).unwrap_or(libc::c_int::MAX);
    // SAFETY: one valid pollfd for the duration of the call.
    unsafe { libc::poll(&mut p, 1, ms) };
}

/// Receive up to `max` (at most [`BATCH`]) waiting frames from the CAN raw socket `fd` without
/// blocking (`recvmmsg`), each as a data frame or the reason it is not one. Returns how many were
/// appended to `out`: 0 when none was waiting.
pub fn recv_batch(
    fd: std::os::fd::RawFd,
    out: &mut Vec<Result<RawFrame, FrameConvError>>,
    max: usize,
) -> std::io::Result<usize> {
    let mut k = [KernelFrame::default(); BATCH];
    let k = &mut k[..max.clamp(1, BATCH)];
    // SAFETY: every header points at one live iovec over one live KernelFrame.
    let n = match mmsg_call(k, None, |h, n| unsafe {
        libc::recvmmsg(fd, h, n, libc::MSG_DONTWAIT, std::ptr::null_mut())
    }) {
        Ok(n) => n,
        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => 0,
        Err(e) => return Err(e),
    };
    out.extend(k[..n].iter().map(convert));
    Ok(n)
}

/// As [`recv_batch`], with each frame's kernel receive time (ns since the epoch) where the
/// socket has `SO_TIMESTAMPNS` on (none otherwise): `candump`'s time stamps.
pub fn recv_batch_stamped(
    fd: std::os::fd::RawFd,
    out: &mut Vec<(Result<RawFrame, FrameConvError>, Option<u64>)>,
    max: usize,
) -> std::io::Result<usize> {
    let mut k = [KernelFrame::default(); BATCH];
    let k = &mut k[..max.clamp(1, BATCH)];
    let mut control = [Control([0; CONTROL_BYTES]); BATCH];
    let mut lens = [0usize; BATCH];
    // SAFETY: every header points at one live iovec over one live KernelFrame and one live
    // control buffer of CONTROL_BYTES.
    let n = match mmsg_call(k, Some((&mut control, &mut lens)), |h, n| unsafe {
        libc::recvmmsg(fd, h, n, libc::MSG_DONTWAIT, std::ptr::null_mut())
    }) {
        Ok(n) => n,
        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => 0,
        Err(e) => return Err(e),
    };
    out.extend(
        k[..n]
            .iter()
            .zip(control.iter().zip(lens))
            .map(|(f, (c, len))| (convert(f), timestamp_ns(c, len))),
    );
    Ok(n)
}

/// A frame as the kernel gave it: a data frame, or why it is not one.
fn convert(f: &KernelFrame) -> Result<RawFrame, FrameConvError> {
    {
        let id = f.can_id;
        if id & CAN_ERR_FLAG != 0 {
            Err(FrameConvError::Error(crate::errframe::ErrorFrame {
                class: id & 0x1FFF_FFFF,
                data: f.data,
            }))
        } else if id & CAN_EFF_FLAG != 0 {
            Err(FrameConvError::Extended(id & 0x1FFF_FFFF))
        } else if id & CAN_RTR_FLAG != 0 {
            Err(FrameConvError::Remote(id & 0x7FF))
        } else {
            Ok(RawFrame {
                id: (id & 0x7FF) as u16,
                len: f.len.min(8),
                data: f.data,
            })
        }
    }
}

/// Sets the receive buffer of socket `fd` to `bytes`: past the system's cap where allowed
/// (`SO_RCVBUFFORCE`, CAP_NET_ADMIN), else up to the cap (`SO_RCVBUF`, `net.core.rmem_max`).
/// Returns the size the socket got, bytes of payload (the kernel reports twice that, its
/// bookkeeping included): less than asked when the cap applied.
pub fn set_rcvbuf(fd: i32, bytes: usize) -> std::io::Result<usize> {
    let v = bytes.min(i32::MAX as usize / 2) as libc::c_int;
    let len = std::mem::size_of::<libc::c_int>() as libc::socklen_t;
    let p = &v as *const libc::c_int as *const libc::c_void;
    // SAFETY: fd is an open socket, p points to a c_int of the given length.
    let mut r = unsafe { libc::setsockopt(fd, libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, p, len) };
    if r != 0 {
        // SAFETY: as above; without CAP_NET_ADMIN fall back to the capped SO_RCVBUF.
        r = unsafe { libc::setsockopt(fd, libc::SOL_SOCKET, libc::SO_RCVBUF, p, len) };
    }
    if r != 0 {
        return Err(std::io::Error::last_os_error());
    }
    let mut got: libc::c_int = 0;
    let mut glen = len;
    // SAFETY: `got` is a live c_int of `glen` bytes.
    let r = unsafe {
        libc::getsockopt(
            fd,
            libc::SOL_SOCKET,
            libc::SO_RCVBUF,
            (&mut got as *mut libc::c_int).cast(),
            &mut glen,
        )
    };
    if r != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(got.max(0) as usize / 2)
}

/// Frames the kernel has dropped on socket `fd` because its receive buffer was full: the
/// socket's drop counter (`sk_drops`, the count `SO_RXQ_OVFL` reports with each message), read
/// with `SO_MEMINFO`.
pub fn socket_drops(fd: std::os::fd::RawFd) -> std::io::Result<u64> {
    /// `SO_MEMINFO` (asm-generic/socket.h; not in the libc crate).
    const SO_MEMINFO: libc::c_int = 55;
    let mut info = [0u32; 9];
    let mut len = std::mem::size_of_val(&info) as libc::socklen_t;
    // SAFETY: `info` is a live buffer of `len` bytes; the kernel writes at most `len`.
    let r = unsafe {
        libc::getsockopt(
            fd,
            libc::SOL_SOCKET,
            SO_MEMINFO,
            info.as_mut_ptr().cast(),
            &mut len,
        )
    };
    if r != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(u64::from(info[libc::SK_MEMINFO_DROPS as usize]))
}

/// Which of the CPUs a thread may run on [`pin_to_one_cpu`] keeps it on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CpuPick {
    /// The lowest-numbered CPU allowed.
    First,
    /// The highest-numbered CPU allowed.
    Last,
}

/// Keep the calling thread (between `fork` and `exec`: the process to be) on one of the CPUs
/// it may run on, and return that CPU. vcan hands each frame written to the receive backlog of
/// the CPU its writer runs on, so a writer that moves between CPUs can have its frames
/// delivered out of order (IMU frames reordered by up to 41 samples in an hour's soak under
/// load; nav's NAV_TIME and TT_CMD frames reordered with two CPU hogs beside a drill). A real
/// controller keeps a sender's order. Two writers that talk to each other (the bench's bus
/// thread and nav) take different ends, so that on two CPUs or more they do not share one.
/// Async-signal-safe: two system calls.
pub fn pin_to_one_cpu(pick: CpuPick) -> std::io::Result<usize> {
    // SAFETY: the cpu_set_t are zeroed plain data, read and written by the kernel with their
    // size, for the calling thread (pid 0); CPU_ISSET/CPU_SET index within CPU_SETSIZE.
    unsafe {
        let mut allowed: libc::cpu_set_t = std::mem::zeroed();
        let size = std::mem::size_of::<libc::cpu_set_t>();
        if libc::sched_getaffinity(0, size, &mut allowed) != 0 {
            return Err(std::io::Error::last_os_error());
        }
        let n = libc::CPU_SETSIZE as usize;
        let mut cpus = (0..n).filter(|&c| libc::CPU_ISSET(c, &allowed));
        let cpu = match pick {
            CpuPick::First => cpus.next(),
            CpuPick::Last => cpus.next_back(),
        };
        let Some(cpu) = cpu else {
            return Err(std::io::Error::from_raw_os_error(libc::EINVAL));
        };
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        if libc::sched_setaffinity(0, size, &set) != 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(cpu)
    }
}
