//! Gives a run a real Linux vcan interface.
//!
//! Where the host kernel has CAN (most desktops and CI images), [`ensure_vcan`] creates the
//! interface over netlink and the run goes on natively. Where it has none (our build machines:
//! `CONFIG_CAN` unset), [`run_in_vm`] boots a stock Debian kernel under QEMU (software emulation),
//! loads `can`, `can-raw`, `vcan` and 9p, mounts the host folders the run needs at the *same*
//! paths, and runs the command there as root. The host's glibc is copied into the guest's
//! initramfs, so ordinary (dynamically linked) cargo binaries run unchanged; no static build.
//! The command's console output streams back live and its exit status is returned.
//!
//! [`run`] picks the way: natively when the kernel can do vcan, otherwise in the guest.

mod cpio;
mod native;
mod vm;

pub use native::{CanSupport, can_support, ensure_vcan, ensure_vcan_fd, set_link};
pub use vm::{VmOptions, VmPrereqs, install_prereqs, prereqs, run_in_vm};

use std::path::PathBuf;
use thiserror::Error;

/// Environment variable set to `1` inside the guest.
pub const GUEST_ENV: &str = "VCAN_SETUP_GUEST";

/// What went wrong setting up vcan or the guest.
#[derive(Debug, Error)]
pub enum Error {
    /// The kernel has no CAN support and it could not be loaded.
    #[error(
        "the kernel has no CAN support (socket(AF_CAN) failed: {0}); load it with `modprobe can_raw vcan`, or run through the QEMU guest (vcan-setup run)"
    )]
    NoKernelCan(std::io::Error),
    /// Creating the interface needs CAP_NET_ADMIN.
    #[error(
        "no permission to create vcan interface {name}: it needs CAP_NET_ADMIN. Run as root, or have an administrator run `ip link add dev {name} type vcan && ip link set {name} up`"
    )]
    Permission {
        /// Interface name.
        name: String,
    },
    /// The vcan module is missing.
    #[error(
        "cannot create vcan interface {name}: the kernel's vcan module is missing ({detail}); try `modprobe vcan`"
    )]
    NoVcanModule {
        /// Interface name.
        name: String,
        /// What netlink said.
        detail: String,
    },
    /// A name exists but is not a CAN interface.
    #[error(
        "interface {name} exists but is not a CAN interface (link type {link_type}); choose another name"
    )]
    NotCan {
        /// Interface name.
        name: String,
        /// ARPHRD type found.
        link_type: String,
    },
    /// Netlink failed otherwise.
    #[error("vcan interface {name}: {action} failed: {detail}")]
    Netlink {
        /// Interface name.
        name: String,
        /// What was tried.
        action: &'static str,
        /// Error text.
        detail: String,
    },
    /// A prerequisite of the guest is missing.
    #[error("the QEMU guest needs {what}, which is missing: {hint}")]
    MissingPrereq {
        /// What is missing.
        what: String,
        /// How to get it.
        hint: String,
    },
    /// An I/O step failed.
    #[error("{context}")]
    Io {
        /// What was being done.
        context: String,
        /// The error.
        source: std::io::Error,
    },
    /// The guest did not finish in time.
    #[error(
        "the QEMU guest did not finish within {0} s; it was killed (hil: set HIL_GUEST_TIMEOUT_S for longer runs)"
    )]
    Timeout(u64),
    /// The guest ended without reporting the command's exit status.
    #[error(
        "the QEMU guest ended without reporting an exit status (kernel panic or crash?); last output:\n{0}"
    )]
    NoStatus(String),
}

/// Result alias.
pub type Result<T, E = Error> = std::result::Result<T, E>;

pub(crate) fn io_ctx(context: impl Into<String>) -> impl FnOnce(std::io::Error) -> Error {
    let context = context.into();
    move |source| Error::Io { context, source }
}

/// How a command ran.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// Exit status of the command (128 + signal when killed by one).
    pub status: i32,
    /// Its console output (stdout and stderr merged in the guest), `\r` removed.
    pub output: String,
    /// Where it ran.
    pub backend: Backend,
    /// Seconds from start until the command began (guest boot), 0 natively.
    pub boot_secs: f64,
    /// Seconds in all.
    pub total_secs: f64,
}

/// Where a command ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// On the host, whose kernel has vcan.
    Native,
    /// In the QEMU guest.
    Vm,
}

/// Run `cmd` where vcan is available: natively when the host kernel has CAN (the command
/// then creates its interfaces itself, see [`ensure_vcan`]), otherwise in the QEMU guest.
/// Output is streamed to stderr as it comes and also returned.
pub fn run(cmd: &[String], opts: &VmOptions) -> Result<RunOutcome> {
    if matches!(can_support(), CanSupport::Available) {
        native::run_native(cmd, opts)
    } else {
        run_in_vm(cmd, opts)
    }
}

/// Folders a bench run needs in the guest: the cargo workspace root that holds `exe`
/// (binaries and sources), `../shared` beside it when present, and `extra`.
pub fn default_shares(exe: &std::path::Path, extra: &[PathBuf]) -> Vec<PathBuf> {
    let mut shares = Vec::new();
    let mut dir = exe.parent();
    while let Some(d) = dir {
        if d.join("Cargo.toml").is_file() && d.join("Cargo.lock").is_file() {
            shares.push(d.to_path_buf());
            if let Some(parent) = d.parent() {
                let shared = parent.join("shared");
                if shared.is_dir() {
                    shares.push(shared);
                }
            }
            break;
        }
        dir = d.parent();
    }
    if let (true, Some(p)) = (shares.is_empty(), exe.parent()) {
        shares.push(p.to_path_buf());
    }
    shares.extend(extra.iter().cloned());
    shares
}
