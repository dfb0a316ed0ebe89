//! vcan on the host's own kernel.

use crate::{Backend, Error, Result, RunOutcome, VmOptions, io_ctx};
use socketcan::nl::CanInterface;
use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

/// Whether the running kernel can carry CAN sockets.
#[derive(Debug)]
pub enum CanSupport {
    /// `socket(AF_CAN, SOCK_RAW, CAN_RAW)` works.
    Available,
    /// It does not, and `modprobe` did not help.
    Missing(std::io::Error),
}

fn try_can_socket() -> std::io::Result<()> {
    // SAFETY: plain socket(2) call; the fd is closed right away.
    let fd = unsafe { libc::socket(libc::AF_CAN, libc::SOCK_RAW, libc::CAN_RAW) };
    if fd < 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: fd is a valid descriptor we own.
    unsafe { libc::close(fd) };
    Ok(())
}

fn modprobe(modules: &[&str]) {
    if Path::new("/proc/modules").exists() {
        let _ = Command::new("modprobe")
            .arg("-a")
            .args(modules)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
    }
}

/// Check (and where possible load) kernel CAN support.
pub fn can_support() -> CanSupport {
    match try_can_socket() {
        Ok(()) => CanSupport::Available,
        Err(_) => {
            modprobe(&["can_raw", "vcan"]);
            match try_can_socket() {
                Ok(()) => CanSupport::Available,
                Err(e) => CanSupport::Missing(e),
            }
        }
    }
}

/// Make sure a vcan interface called `name` exists and is up, creating it over netlink when
/// missing. An existing interface of another type is refused, never reconfigured.
pub fn ensure_vcan(name: &str) -> Result<()> {
    if let CanSupport::Missing(e) = can_support() {
        return Err(Error::NoKernelCan(e));
    }
    let sys = Path::new("/sys/class/net").join(name);
    if sys.exists() {
        let link_type = std::fs::read_to_string(sys.join("type")).unwrap_or_default();
        // ARPHRD_CAN = 280
        if link_type.trim() != "280" {
            return Err(Error::NotCan {
                name: name.into(),
                link_type: link_type.trim().into(),
            });
        }
        let flags = std::fs::read_to_string(sys.join("flags")).unwrap_or_default();
        let up =
            u32::from_str_radix(flags.trim().trim_start_matches("0x"), 16).unwrap_or(0) & 1 == 1;
        if up {
            return Ok(());
        }
    } else if let Err(e) = CanInterface::create_vcan(name, None) {
        let detail = e.to_string();
        let low = detail.to_lowercase();
        if low.contains("permission") || low.contains("not permitted") {
            return Err(Error::Permission { name: name.into() });
        }
        if low.contains("not supported") || low.contains("unknown") {
            modprobe(&["vcan"]);
            if CanInterface::create_vcan(name, None).is_err() {
                return Err(Error::NoVcanModule {
                    name: name.into(),
                    detail,
                });
            }
        } else if !sys.exists() {
            // (another process creating the same interface at the same moment wins the race:
            // then it exists, and is brought up below like any other)
            return Err(Error::Netlink {
                name: name.into(),
                action: "create",
                detail,
            });
        }
    }
    let iface = CanInterface::open(name).map_err(|e| Error::Netlink {
        name: name.into(),
        action: "open",
        detail: e.to_string(),
    })?;
    iface.bring_up().map_err(|e| {
        let detail = e.to_string();
        if detail.to_lowercase().contains("permi") {
            Error::Permission { name: name.into() }
        } else {
            Error::Netlink {
                name: name.into(),
                action: "bring up",
                detail,
            }
        }
    })
}

/// [`ensure_vcan`], able to carry CAN FD frames (MTU 72): a vcan interface of the classic MTU
/// is taken down, given FD's and brought up again (vcan changes its MTU only while down).
pub fn ensure_vcan_fd(name: &str) -> Result<()> {
    ensure_vcan(name)?;
    let mtu = std::fs::read_to_string(Path::new("/sys/class/net").join(name).join("mtu"))
        .ok()
        .and_then(|m| m.trim().parse::<u32>().ok());
    if mtu == Some(socketcan::nl::Mtu::Fd as u32) {
        return Ok(());
    }
    let iface = CanInterface::open(name).map_err(|e| Error::Netlink {
        name: name.into(),
        action: "open",
        detail: e.to_string(),
    })?;
    let fail = |action: &'static str| {
        move |e: socketcan::Error| Error::Netlink {
            name: name.into(),
            action,
            detail: e.to_string(),
        }
    };
    iface.bring_down().map_err(fail("take down"))?;
    iface
        .set_mtu(socketcan::nl::Mtu::Fd)
        .map_err(fail("set the CAN FD MTU (72) of"))?;
    iface.bring_up().map_err(fail("bring up"))
}

/// Take interface `name` down (`up = false`) or bring it back up, as `ip link set NAME down|up`
/// does (a CAN controller switched off and on, a cable pulled and put back).
pub fn set_link(name: &str, up: bool) -> Result<()> {
    let action = if up { "bring up" } else { "take down" };
    let iface = CanInterface::open(name).map_err(|e| Error::Netlink {
        name: name.into(),
        action: "open",
        detail: e.to_string(),
    })?;
    let r = if up {
        iface.bring_up()
    } else {
        iface.bring_down()
    };
    r.map_err(|e| Error::Netlink {
        name: name.into(),
        action,
        detail: e.to_string(),
    })
}

/// Run the command on the host, streaming its output.
pub(crate) fn run_native(cmd: &[String], opts: &VmOptions) -> Result<RunOutcome> {
    let start = Instant::now();
    let (prog, args) = cmd.split_first().ok_or_else(|| Error::Io {
        context: "run".into(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "empty command"),
    })?;
    let mut child = Command::new(prog)
        .args(args)
        .envs(opts.env.iter().map(|(k, v)| (k, v)))
        .current_dir(opts.cwd.clone().unwrap_or_else(|| ".".into()))
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(io_ctx(format!("starting {prog}")))?;
    let mut output = String::new();
    if let Some(out) = child.stdout.take() {
        for line in BufReader::new(out).lines() {
            let line = line.map_err(io_ctx(format!("reading output of {prog}")))?;
            if opts.echo {
                let _ = writeln!(std::io::stderr(), "{line}");
            }
            output.push_str(&line);
            output.push('\n');
        }
    }
    let st = child
        .wait()
        .map_err(io_ctx(format!("waiting for {prog}")))?;
    use std::os::unix::process::ExitStatusExt;
    let status = st.code().unwrap_or_else(|| 128 + st.signal().unwrap_or(0));
    Ok(RunOutcome {
        status,
        output,
        backend: Backend::Native,
        boot_secs: 0.0,
        total_secs: start.elapsed().as_secs_f64(),
    })
}
