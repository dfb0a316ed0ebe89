//! Real vcan inside a QEMU guest (software emulation) running the host's stock Debian kernel.

use crate::cpio::Archive;
use crate::{Backend, Error, GUEST_ENV, Result, RunOutcome, io_ctx};
use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Kernel modules the guest loads, dependencies resolved from `modules.dep`.
const MODULES: &[&str] = &[
    "can",
    "can-raw",
    "can-dev",
    "vcan",
    "9p",
    "9pnet_virtio",
    "virtio_pci",
];

/// Kernel modules the guest loads when it has a network card ([`VmOptions::forward_tcp`]).
const NET_MODULES: &[&str] = &["virtio_net"];

/// The guest's address on QEMU's user-mode network (its default).
pub const GUEST_IP: &str = "10.0.2.15";

/// Debian packages the guest needs.
pub const APT_PACKAGES: &[&str] = &[
    "qemu-system-x86",
    "linux-image-amd64",
    "busybox-static",
    "can-utils",
];

/// can-utils programs the guest carries (at their host paths), so that tests and people can
/// watch and play the bus with the field's own tools.
pub const CAN_UTILS: &[&str] = &["candump", "canplayer", "cansend", "cangen", "canbusload"];

/// Programs the guest carries when the host has them (at their host paths): gpsd, so that a
/// bench run in the guest can put gpsd between the GPS emulator's pty and nav, as a vehicle
/// shares one receiver; socat, which puts a recorded receiver's log on a pty of its own (a real
/// receiver's stand-in). `./run-tests` installs both on the host.
pub const OPTIONAL_TOOLS: &[&str] = &["gpsd", "socat"];

/// Environment variables passed from the host into the guest when set.
const PASS_ENV: &[&str] = &["RUST_LOG", "RUST_BACKTRACE", "NO_COLOR", "TERM"];

/// Marker line the guest prints when the command starts.
const READY: &str = "vcan-setup-guest: ready";

/// How to run the guest.
#[derive(Debug, Clone)]
pub struct VmOptions {
    /// Host folders mounted in the guest at the same paths (read-write).
    pub shares: Vec<PathBuf>,
    /// Host folders mounted in the guest at the same paths read-only, their files cached in
    /// the guest (9p `cache=loose`): what does not change while the command runs, such as an
    /// interpreter and its packages, which it then opens without a round trip to this machine
    /// for every file.
    pub shares_ro: Vec<PathBuf>,
    /// Working directory of the command (must be inside a share); default the first share.
    pub cwd: Option<PathBuf>,
    /// Extra environment for the command.
    pub env: Vec<(String, String)>,
    /// Guest memory, MiB.
    pub memory_mb: u32,
    /// Guest CPUs.
    pub cpus: u32,
    /// Kill the guest after this long.
    pub timeout: Duration,
    /// Echo the output live to stderr.
    pub echo: bool,
    /// More executables whose shared libraries the guest needs (the command's own are found).
    pub libs_for: Vec<PathBuf>,
    /// TCP ports of the guest reachable from the host: (host address, guest port). The guest
    /// then gets a network card on QEMU's user-mode network (address `GUEST_IP`, no route
    /// out) and QEMU forwards each host address to the guest's port (a live view's server
    /// inside the guest, watched from the host).
    pub forward_tcp: Vec<(std::net::SocketAddr, u16)>,
}

impl Default for VmOptions {
    fn default() -> Self {
        Self {
            shares: Vec::new(),
            shares_ro: Vec::new(),
            cwd: None,
            env: Vec::new(),
            memory_mb: 2048,
            cpus: 2,
            timeout: Duration::from_secs(40 * 60),
            echo: true,
            libs_for: Vec::new(),
            forward_tcp: Vec::new(),
        }
    }
}

/// What the guest needs from the host, as found.
#[derive(Debug, Clone)]
pub struct VmPrereqs {
    /// `qemu-system-x86_64`.
    pub qemu: PathBuf,
    /// Kernel image.
    pub kernel: PathBuf,
    /// Kernel version (`/lib/modules/<version>`).
    pub kernel_version: String,
    /// Busybox binary.
    pub busybox: PathBuf,
    /// The can-utils programs (`CAN_UTILS`).
    pub can_utils: Vec<PathBuf>,
    /// The `OPTIONAL_TOOLS` the host has.
    pub optional: Vec<PathBuf>,
}

fn which(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .chain(
            ["/usr/sbin", "/sbin", "/usr/bin", "/bin"]
                .iter()
                .map(PathBuf::from),
        )
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

fn hint() -> String {
    format!(
        "run `vcan-setup install` as root (apt-get install {})",
        APT_PACKAGES.join(" ")
    )
}

/// Find the guest's prerequisites on the host.
pub fn prereqs() -> Result<VmPrereqs> {
    let qemu = which("qemu-system-x86_64").ok_or_else(|| Error::MissingPrereq {
        what: "qemu-system-x86_64".into(),
        hint: hint(),
    })?;
    let busybox = ["/bin/busybox", "/usr/bin/busybox"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.is_file())
        .ok_or_else(|| Error::MissingPrereq {
            what: "busybox".into(),
            hint: hint(),
        })?;
    let mut kernels: Vec<(Vec<u64>, String)> = std::fs::read_dir("/boot")
        .map_err(io_ctx("listing /boot"))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            e.file_name()
                .to_str()
                .and_then(|n| n.strip_prefix("vmlinuz-"))
                .map(String::from)
        })
        .filter(|v| {
            Path::new("/lib/modules")
                .join(v)
                .join("modules.dep")
                .is_file()
        })
        .map(|v| {
            let key = v
                .split(|c: char| !c.is_ascii_digit())
                .filter_map(|p| p.parse().ok())
                .collect();
            (key, v)
        })
        .collect();
    kernels.sort();
    let (_, kernel_version) = kernels.pop().ok_or_else(|| Error::MissingPrereq {
        what: "a Debian kernel with its modules (/boot/vmlinuz-* and /lib/modules/*/modules.dep)"
            .into(),
        hint: hint(),
    })?;
    let can_utils = CAN_UTILS
        .iter()
        .map(|t| {
            which(t).ok_or_else(|| Error::MissingPrereq {
                what: format!("{t} (can-utils)"),
                hint: hint(),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let kernel = PathBuf::from(format!("/boot/vmlinuz-{kernel_version}"));
    if let Err(e) = std::fs::File::open(&kernel) {
        return Err(Error::MissingPrereq {
            what: format!("read access to {}", kernel.display()),
            hint: format!("{e}; run as root or make the kernel image readable"),
        });
    }
    Ok(VmPrereqs {
        qemu,
        kernel,
        kernel_version,
        busybox,
        can_utils,
        optional: OPTIONAL_TOOLS.iter().filter_map(|t| which(t)).collect(),
    })
}

/// Install the guest's prerequisites with apt-get (needs root).
pub fn install_prereqs() -> Result<VmPrereqs> {
    if prereqs().is_ok() {
        return prereqs();
    }
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return Err(Error::MissingPrereq {
            what: "root to install packages".into(),
            hint: format!("run `sudo apt-get install {}`", APT_PACKAGES.join(" ")),
        });
    }
    eprintln!(
        "vcan-setup: installing {} (about 1-2 minutes)",
        APT_PACKAGES.join(" ")
    );
    let apt = |args: &[&str]| -> Result<()> {
        let st = Command::new("apt-get")
            .args(args)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .stdout(Stdio::null())
            .status()
            .map_err(io_ctx("running apt-get"))?;
        if st.success() {
            Ok(())
        } else {
            Err(Error::MissingPrereq {
                what: APT_PACKAGES.join(" "),
                hint: format!("apt-get {} failed ({st})", args.join(" ")),
            })
        }
    };
    apt(&["update", "-qq"])?;
    let mut args = vec!["install", "-y", "-qq", "--no-install-recommends"];
    args.extend_from_slice(APT_PACKAGES);
    apt(&args)?;
    prereqs()
}

/// Module files in load order (dependencies first), from `modules.dep`.
fn module_files(kver: &str, wanted: &[&str]) -> Result<Vec<PathBuf>> {
    let base = Path::new("/lib/modules").join(kver);
    let dep = std::fs::read_to_string(base.join("modules.dep"))
        .map_err(io_ctx(format!("reading {}/modules.dep", base.display())))?;
    let norm = |p: &str| {
        Path::new(p)
            .file_name()
            .and_then(|n| n.to_str())
            .map(|n| n.split(".ko").next().unwrap_or(n).replace('-', "_"))
            .unwrap_or_default()
    };
    let mut table: BTreeMap<String, (String, Vec<String>)> = BTreeMap::new();
    for line in dep.lines() {
        if let Some((m, deps)) = line.split_once(':') {
            table.insert(
                norm(m),
                (
                    m.to_string(),
                    deps.split_whitespace().map(String::from).collect(),
                ),
            );
        }
    }
    let builtin = std::fs::read_to_string(base.join("modules.builtin")).unwrap_or_default();
    let builtin: BTreeSet<String> = builtin.lines().map(norm).collect();
    let mut order: Vec<String> = Vec::new();
    fn visit(
        path: &str,
        table: &BTreeMap<String, (String, Vec<String>)>,
        order: &mut Vec<String>,
        norm: &dyn Fn(&str) -> String,
    ) {
        if order.iter().any(|p| p == path) {
            return;
        }
        if let Some((_, deps)) = table.get(&norm(path)) {
            // modules.dep lists deps so that the last one loads first
            for d in deps.iter().rev() {
                visit(d, table, order, norm);
            }
        }
        order.push(path.to_string());
    }
    for m in wanted {
        let key = m.replace('-', "_");
        match table.get(&key) {
            Some((path, _)) => visit(&path.clone(), &table, &mut order, &norm),
            None if builtin.contains(&key) => {}
            None => {
                return Err(Error::MissingPrereq {
                    what: format!("kernel module {m} for kernel {kver}"),
                    hint: "install the stock Debian kernel (linux-image-amd64)".into(),
                });
            }
        }
    }
    Ok(order.into_iter().map(|p| base.join(p)).collect())
}

/// Shared libraries (and the dynamic loader) of `exe`, by `ldd`; empty for static binaries.
fn shared_libs(exe: &Path) -> Vec<PathBuf> {
    let Ok(out) = Command::new("ldd").arg(exe).output() else {
        return Vec::new();
    };
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| {
            let l = l.trim();
            let path = match l.split_once("=>") {
                Some((_, rhs)) => rhs.split_whitespace().next()?,
                None => l.split_whitespace().next()?,
            };
            path.starts_with('/').then(|| PathBuf::from(path))
        })
        .collect()
}

/// Executables beside `prog` and one folder up (cargo's `target/<profile>/deps/..` layout): the
/// programs a test binary starts need their libraries in the guest too.
fn sibling_executables(prog: &Path) -> Vec<PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let Some(dir) = prog.parent() else {
        return Vec::new();
    };
    let is_elf = |p: &Path| {
        let mut magic = [0u8; 4];
        std::fs::File::open(p)
            .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic))
            .is_ok()
            && magic == *b"\x7fELF"
    };
    let mut out = Vec::new();
    for d in [Some(dir), dir.parent()].into_iter().flatten() {
        let Ok(rd) = std::fs::read_dir(d) else {
            continue;
        };
        for e in rd.filter_map(|e| e.ok()) {
            let p = e.path();
            let exec = e
                .metadata()
                .map(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
                .unwrap_or(false);
            if exec && p.extension().is_none() && is_elf(&p) {
                out.push(p);
            }
        }
    }
    out
}

fn sh_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', "'\\''"))
}

fn build_initramfs(
    pre: &VmPrereqs,
    mods: &[PathBuf],
    execs: &[PathBuf],
    shares: &[Share],
    net: bool,
) -> Result<Vec<u8>> {
    let mut a = Archive::default();
    for d in [
        "proc",
        "sys",
        "dev",
        "tmp",
        "root",
        "run/vcan-setup",
        "etc",
        "sbin",
        "usr/bin",
        "usr/sbin",
    ] {
        a.dir(d);
    }
    let read = |p: &Path| std::fs::read(p).map_err(io_ctx(format!("reading {}", p.display())));
    a.file("bin/busybox", 0o755, &read(&pre.busybox)?);
    // glibc and friends, so ordinary dynamically linked binaries run unchanged
    let mut libs: BTreeSet<PathBuf> = BTreeSet::new();
    for e in execs
        .iter()
        .chain(std::iter::once(&pre.busybox))
        .chain(&pre.can_utils)
        .chain(&pre.optional)
    {
        libs.extend(shared_libs(e));
    }
    for t in pre.can_utils.iter().chain(&pre.optional) {
        // at its host path (PATH in the guest has /usr/bin and /bin)
        a.file(
            t.to_string_lossy().trim_start_matches('/'),
            0o755,
            &read(t)?,
        );
    }
    for l in &libs {
        let data = read(l)?; // follows symlinks
        a.file(&l.to_string_lossy(), 0o755, &data);
    }
    let mut names = Vec::new();
    for m in mods {
        let name = m
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("mod.ko")
            .to_string();
        a.file(&format!("lib/modules/{name}"), 0o644, &read(m)?);
        names.push(name);
    }
    let mut mounts = String::new();
    for (i, s) in shares.iter().enumerate() {
        let p = sh_quote(&s.path.to_string_lossy());
        let how = if s.ro { "ro,cache=loose" } else { "cache=none" };
        mounts.push_str(&format!(
            "mkdir -p {p} && mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000,{how} share{i} {p} || echo 'vcan-setup-guest: cannot mount share {i}'\n"
        ));
    }
    let init = format!(
        r#"#!/bin/busybox sh
/bin/busybox --install -s /bin
export PATH=/bin:/sbin:/usr/bin:/usr/sbin
mount -t proc proc /proc; mount -t sysfs sys /sys; mount -t devtmpfs dev /dev
mkdir -p /dev/pts /dev/shm; mount -t devpts devpts /dev/pts; mount -t tmpfs tmp /tmp; mount -t tmpfs shm /dev/shm
for m in {mods}; do insmod /lib/modules/$m || echo "vcan-setup-guest: insmod $m failed"; done
ip link set lo up
{net}# nav runs unprivileged: the socket buffer it asks for is capped by rmem_max (set-up's job, as
# on a vehicle's image)
echo 16777216 > /proc/sys/net/core/rmem_max
# the field's tools (candump, canbusload) take the default buffer: 8 MiB holds some 2 s of a
# 4,000-frame/s bus, so a reader an emulated CPU leaves unscheduled for a moment loses nothing
# (212,992 bytes, the kernel's default, is some 50 ms: canbusload lost 27 of 20,297 frames so)
echo 8388608 > /proc/sys/net/core/rmem_default
mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 ctl /run/vcan-setup
{mounts}echo "{READY} $(cut -d' ' -f1 /proc/uptime) s"
sh /run/vcan-setup/cmd.sh
echo $? > /run/vcan-setup/rc
sync
poweroff -f
"#,
        mods = names.join(" "),
        net = if net {
            format!(
                "ip link set eth0 up && ip addr add {GUEST_IP}/24 dev eth0 || echo 'vcan-setup-guest: no network card'\n"
            )
        } else {
            String::new()
        }
    );
    a.file("init", 0o755, init.as_bytes());
    Ok(a.finish())
}

/// Boot the guest, run `cmd` in it as root and return its status and output.
pub fn run_in_vm(cmd: &[String], opts: &VmOptions) -> Result<RunOutcome> {
    let start = Instant::now();
    let pre = prereqs()?;
    let (prog, _) = cmd.split_first().ok_or_else(|| Error::Io {
        context: "run".into(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidInput, "empty command"),
    })?;
    let mut wanted: Vec<&str> = MODULES.to_vec();
    if !opts.forward_tcp.is_empty() {
        wanted.extend(NET_MODULES);
    }
    let mods = module_files(&pre.kernel_version, &wanted)?;
    let shares = guest_shares(opts)?;
    let execs = guest_executables(cmd, prog, opts);

    let ctl = tempfile::Builder::new()
        .prefix("vcan-setup-")
        .tempdir()
        .map_err(io_ctx("creating the guest's control folder"))?;
    let initrd = ctl.path().join("initrd.cpio");
    let net = !opts.forward_tcp.is_empty();
    std::fs::write(&initrd, build_initramfs(&pre, &mods, &execs, &shares, net)?)
        .map_err(io_ctx("writing the initramfs"))?;
    let script = guest_script(cmd, opts, &shares);
    std::fs::write(ctl.path().join("cmd.sh"), script)
        .map_err(io_ctx("writing the guest command"))?;

    let launch = |kvm: bool, boot_limit: Option<Duration>| {
        launch(&Launch {
            pre: &pre,
            ctl: ctl.path(),
            initrd: &initrd,
            shares: &shares,
            opts,
            kvm,
            boot_limit,
            start,
            prog,
        })
    };
    let launched = on_an_accelerator(&launch)?;
    let (mut output, preboot, boot_secs) = match launched {
        Launched::Done {
            output,
            preboot,
            boot_secs,
        } => (output, preboot, boot_secs),
        Launched::NoBoot(why) => {
            return Err(Error::NoStatus(format!("the guest did not boot: {why}")));
        }
    };
    let rc = std::fs::read_to_string(ctl.path().join("rc"))
        .ok()
        .and_then(|s| s.trim().parse::<i32>().ok());
    let Some(status) = rc else {
        if boot_secs.is_none() {
            output = preboot;
        }
        let tail: Vec<&str> = output.lines().rev().take(30).collect();
        return Err(Error::NoStatus(
            tail.into_iter().rev().collect::<Vec<_>>().join("\n"),
        ));
    };
    Ok(RunOutcome {
        status,
        output,
        backend: Backend::Vm,
        boot_secs: boot_secs.unwrap_or(0.0),
        total_secs: start.elapsed().as_secs_f64(),
    })
}

/// The guest launched (`launch(kvm, boot_limit)`) on the accelerator [`Accel::choose`] says:
/// KVM, software emulation, or KVM probed with a fall-back to software emulation. A
/// software-emulated guest that is not up within [`TCG_BOOT_LIMIT`] (its kernel stalled at
/// boot: seen once in a fresh clone, the guest silent for the whole 2400 s) starts again, once,
/// rather than hold the run until its timeout.
fn on_an_accelerator(
    launch: &dyn Fn(bool, Option<Duration>) -> Result<Launched>,
) -> Result<Launched> {
    let tcg = || -> Result<Launched> {
        match launch(false, Some(TCG_BOOT_LIMIT))? {
            Launched::NoBoot(why) => {
                eprintln!("vcan-setup: the guest did not come up ({why}); starting it again");
                launch(false, Some(TCG_BOOT_LIMIT))
            }
            done => Ok(done),
        }
    };
    Ok(match Accel::choose() {
        Accel::Tcg => tcg()?,
        Accel::Kvm => launch(true, None)?,
        Accel::Probe(cache) => match launch(true, Some(KVM_BOOT_LIMIT))? {
            Launched::NoBoot(why) => {
                eprintln!(
                    "vcan-setup: KVM did not start the guest ({why}); using software emulation (TCG){}",
                    cache.as_ref().map_or(String::new(), |c| format!(
                        " from now on (remembered in {}; delete it to probe again)",
                        c.display()
                    ))
                );
                remember_kvm(cache.as_deref(), false);
                tcg()?
            }
            done => {
                remember_kvm(cache.as_deref(), true);
                done
            }
        },
    })
}

/// A host folder the guest mounts.
struct Share {
    path: PathBuf,
    /// Read-only, its files cached in the guest ([`VmOptions::shares_ro`]).
    ro: bool,
}

/// The host folders the guest mounts, each once (read-write where it is given both ways),
/// parents before children (nested shares mount on top).
fn guest_shares(opts: &VmOptions) -> Result<Vec<Share>> {
    let mut shares: Vec<Share> = Vec::new();
    for (s, ro) in opts
        .shares
        .iter()
        .map(|s| (s, false))
        .chain(opts.shares_ro.iter().map(|s| (s, true)))
    {
        let c = s
            .canonicalize()
            .map_err(io_ctx(format!("share {}", s.display())))?;
        if !shares.iter().any(|x| x.path == c) {
            shares.push(Share { path: c, ro });
        }
    }
    shares.sort_by_key(|s| s.path.components().count());
    Ok(shares)
}

/// The executables the guest needs with their libraries: the command's program, its siblings,
/// the programs a wrapper names among its arguments, and `opts.libs_for`.
fn guest_executables(cmd: &[String], prog: &str, opts: &VmOptions) -> Vec<PathBuf> {
    let mut execs = opts.libs_for.clone();
    let prog_path = PathBuf::from(prog);
    let prog_path = if prog_path.is_file() {
        prog_path
    } else {
        which(prog).unwrap_or(prog_path)
    };
    execs.extend(sibling_executables(&prog_path));
    execs.push(prog_path);
    // a wrapper (a shell script) names the programs it runs among its arguments: theirs too
    for a in cmd.iter().skip(1).map(Path::new).filter(|p| p.is_file()) {
        execs.extend(sibling_executables(a));
        execs.push(a.to_path_buf());
    }
    execs.sort();
    execs.dedup();
    execs
}

/// The guest's command script: into the working folder (one under a share), the environment
/// passed through, then the command.
fn guest_script(cmd: &[String], opts: &VmOptions, shares: &[Share]) -> String {
    let cwd = opts
        .cwd
        .clone()
        .or_else(|| {
            std::env::current_dir()
                .ok()
                .filter(|d| shares.iter().any(|s| d.starts_with(&s.path)))
        })
        .or_else(|| shares.first().map(|s| s.path.clone()))
        .unwrap_or_else(|| "/".into());
    let mut script = format!(
        "cd {} || exit 126\nexport HOME=/root TMPDIR=/tmp {GUEST_ENV}=1\n",
        sh_quote(&cwd.to_string_lossy())
    );
    for k in PASS_ENV {
        if let Ok(v) = std::env::var(k) {
            script.push_str(&format!("export {k}={}\n", sh_quote(&v)));
        }
    }
    if std::env::var_os("NO_COLOR").is_none()
        && !std::io::IsTerminal::is_terminal(&std::io::stderr())
    {
        // the guest's console is a terminal, the host's log is not (a file, a pipe, CI): no
        // colour codes in it
        script.push_str("export NO_COLOR=1\n");
    }
    for (k, v) in &opts.env {
        script.push_str(&format!("export {k}={}\n", sh_quote(v)));
    }
    script.push_str("exec");
    for a in cmd {
        script.push(' ');
        script.push_str(&sh_quote(a));
    }
    script.push_str(" 2>&1\n");
    script
}

/// How long a KVM guest may take to come up before the probe gives up on KVM (a KVM guest is
/// up in about a second; where nested virtualisation does not work it hangs at boot).
const KVM_BOOT_LIMIT: Duration = Duration::from_secs(15);

/// How long a software-emulated guest may take to come up before it is started again (it is up
/// in 12-40 s, idle or beside two busy loops).
const TCG_BOOT_LIMIT: Duration = Duration::from_secs(240);

/// The accelerator the guest runs on.
enum Accel {
    /// Software emulation.
    Tcg,
    /// KVM, asked for: no fall-back.
    Kvm,
    /// KVM if it starts the guest, else software emulation; the answer is remembered here.
    Probe(Option<PathBuf>),
}

impl Accel {
    /// `VCAN_SETUP_ACCEL` = `tcg`, `kvm` or `auto` (the default: KVM where `/dev/kvm` opens
    /// and a guest has come up on it before or has not been tried).
    fn choose() -> Self {
        match std::env::var("VCAN_SETUP_ACCEL").as_deref() {
            Ok("tcg") => return Self::Tcg,
            Ok("kvm") => return Self::Kvm,
            _ => {}
        }
        let usable = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open("/dev/kvm")
            .is_ok();
        if !usable {
            return Self::Tcg;
        }
        let cache = kvm_cache();
        match cache
            .as_deref()
            .and_then(|c| std::fs::read_to_string(c).ok())
        {
            Some(s) if s.trim() == "no" => Self::Tcg,
            _ => Self::Probe(cache),
        }
    }
}

/// Where the KVM probe's answer is kept: `$XDG_CACHE_HOME/vcan-setup/kvm` (or under
/// `$HOME/.cache`), one file per host kernel.
fn kvm_cache() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    let release = std::fs::read_to_string("/proc/sys/kernel/osrelease").ok()?;
    Some(
        base.join("vcan-setup")
            .join(format!("kvm-{}", release.trim())),
    )
}

/// Keeps the probe's answer (best effort: without it the next run probes again).
fn remember_kvm(cache: Option<&Path>, works: bool) {
    if let Some(c) = cache {
        if let Some(d) = c.parent() {
            let _ = std::fs::create_dir_all(d);
        }
        let _ = std::fs::write(c, if works { "yes\n" } else { "no\n" });
    }
}

/// One start of QEMU.
struct Launch<'a> {
    pre: &'a VmPrereqs,
    ctl: &'a Path,
    initrd: &'a Path,
    shares: &'a [Share],
    opts: &'a VmOptions,
    kvm: bool,
    /// Give up (kill QEMU, `Launched::NoBoot`) when the guest is not up by then.
    boot_limit: Option<Duration>,
    start: Instant,
    prog: &'a str,
}

/// What a start of QEMU gave.
enum Launched {
    /// The guest ran (the command's status is in the control folder, if it got one).
    Done {
        output: String,
        preboot: String,
        boot_secs: Option<f64>,
    },
    /// The guest did not come up within the boot limit.
    NoBoot(String),
}

/// QEMU's command line for launch `l`: the accelerator and CPU, the serial console, the
/// guest's size, the kernel and initrd, the control folder and the shares over 9p.
fn qemu_command(l: &Launch<'_>) -> Command {
    // the guest's CPU model: `max` unless VCAN_SETUP_CPU names another (for measuring, e.g. a
    // model without FMA/AVX, whose libm paths TCG emulates more cheaply or not)
    let Launch {
        pre,
        ctl,
        initrd,
        shares,
        opts,
        kvm,
        ..
    } = *l;
    let cpu =
        std::env::var("VCAN_SETUP_CPU").unwrap_or_else(|_| if kvm { "host" } else { "max" }.into());
    let mut q = Command::new(&pre.qemu);
    q.args([
        "-accel",
        if kvm { "kvm" } else { "tcg,thread=multi" },
        "-cpu",
        cpu.as_str(),
        "-nodefaults",
        "-display",
        "none",
    ])
    .args(["-serial", "stdio", "-no-reboot"])
    // QEMU's human monitor on a Unix socket when VCAN_SETUP_MONITOR names one, for measuring
    // (`echo "info jit" | socat - unix:PATH`: the translator's code buffer and its flushes)
    .args(
        std::env::var("VCAN_SETUP_MONITOR")
            .map(|m| vec!["-monitor".to_string(), format!("unix:{m},server,nowait")])
            .unwrap_or_default(),
    )
    .args([
        "-smp",
        &opts.cpus.to_string(),
        "-m",
        &opts.memory_mb.to_string(),
    ])
    .arg("-kernel")
    .arg(&pre.kernel)
    .arg("-initrd")
    .arg(initrd)
    // VCAN_SETUP_APPEND: more kernel arguments, for measuring (docs/pace.md: `mitigations=off`
    // measured no faster).
    // norandmaps: every start of a program maps its code at the same addresses. QEMU's
    // translator keys its translations by virtual address, so with address-space
    // randomisation each start of nav or hil translated its code afresh (the translations of
    // seven short end-to-end tests: 408 MB of the 1 GiB code buffer, 127 MB without; 45-48 s
    // against 42-43 s). A throwaway test guest loses nothing by it.
    .args([
        "-append".to_string(),
        format!(
            "console=ttyS0 quiet loglevel=3 panic=-1 clocksource=tsc tsc=reliable norandmaps {}",
            std::env::var("VCAN_SETUP_APPEND").unwrap_or_default()
        ),
    ])
    .arg("-virtfs")
    .arg(format!(
        "local,path={},mount_tag=ctl,security_model=none",
        ctl.display()
    ));
    for (i, s) in shares.iter().enumerate() {
        q.arg("-virtfs").arg(format!(
            "local,path={},mount_tag=share{i},security_model=none{}",
            s.path.display(),
            if s.ro { ",readonly=on" } else { "" }
        ));
    }
    if !opts.forward_tcp.is_empty() {
        // user-mode networking: no privilege, nothing on the host's network but the forwards
        let mut nic = String::from("user,model=virtio-net-pci,restrict=on");
        for (host, port) in &opts.forward_tcp {
            nic.push_str(&format!(
                ",hostfwd=tcp:{}:{}-{GUEST_IP}:{port}",
                host.ip(),
                host.port()
            ));
        }
        q.arg("-nic").arg(nic);
    }
    q
}

/// Starts QEMU, echoes and collects the guest's output until it powers off.
fn launch(l: &Launch<'_>) -> Result<Launched> {
    let Launch {
        pre,
        opts,
        kvm,
        boot_limit,
        start,
        prog,
        ..
    } = *l;
    let launched = Instant::now();
    let mut q = qemu_command(l);
    let mut child = q
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(io_ctx(format!("starting {}", pre.qemu.display())))?;
    let (rx, readers) = read_lines(&mut child);
    let mut output = String::new();
    let mut preboot: Vec<String> = Vec::new();
    let mut boot_secs = None;
    let deadline = start + opts.timeout;
    loop {
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(line) => {
                if boot_secs.is_none() && line.contains(READY) {
                    boot_secs = Some(start.elapsed().as_secs_f64());
                    if opts.echo {
                        eprintln!(
                            "vcan-setup: guest up after {:.1} s (kernel {}, {}), running {prog}",
                            start.elapsed().as_secs_f64(),
                            pre.kernel_version,
                            if kvm { "KVM" } else { "software emulation" }
                        );
                    }
                    continue;
                }
                if boot_secs.is_none() {
                    // firmware and kernel chatter before the command starts: kept for errors only
                    preboot.push(line);
                    continue;
                }
                if line.contains("] reboot: Power down") {
                    continue;
                }
                if opts.echo {
                    let _ = writeln!(std::io::stderr(), "{line}");
                }
                output.push_str(&line);
                output.push('\n');
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                if boot_secs.is_none() && boot_limit.is_some() {
                    let _ = child.wait();
                    let last = preboot.iter().rev().find(|l| !l.trim().is_empty());
                    return Ok(Launched::NoBoot(format!(
                        "QEMU ended before the guest was up: {}",
                        last.map_or("no output", |l| l.as_str())
                    )));
                }
                break;
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if let Some(limit) = boot_limit
                    && boot_secs.is_none()
                    && launched.elapsed() > limit
                {
                    let _ = child.kill();
                    let _ = child.wait();
                    return Ok(Launched::NoBoot(format!(
                        "not up within {} s",
                        limit.as_secs()
                    )));
                }
                if Instant::now() > deadline {
                    let _ = child.kill();
                    let _ = child.wait();
                    return Err(Error::Timeout(opts.timeout.as_secs()));
                }
            }
        }
    }
    for r in readers {
        let _ = r.join();
    }
    let _ = child.wait();
    Ok(Launched::Done {
        output,
        preboot: preboot.join("\n"),
        boot_secs,
    })
}

/// QEMU's output as lines on one channel: its standard output (the guest's console) as it is,
/// its standard error prefixed `qemu: `; with the threads reading them.
fn read_lines(
    child: &mut std::process::Child,
) -> (mpsc::Receiver<String>, [std::thread::JoinHandle<()>; 2]) {
    let (tx, rx) = mpsc::channel::<String>();
    let out = child.stdout.take();
    let err = child.stderr.take();
    let tx2 = tx.clone();
    let t1 = std::thread::spawn(move || {
        if let Some(o) = out {
            for line in BufReader::new(o).split(b'\n').map_while(|l| l.ok()) {
                let _ = tx.send(
                    String::from_utf8_lossy(&line)
                        .trim_end_matches('\r')
                        .to_string(),
                );
            }
        }
    });
    let t2 = std::thread::spawn(move || {
        if let Some(e) = err {
            for line in BufReader::new(e).lines().map_while(|l| l.ok()) {
                let _ = tx2.send(format!("qemu: {line}"));
            }
        }
    });
    (rx, [t1, t2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoting_survives_single_quotes() {
        assert_eq!(sh_quote("a'b"), r#"'a'\''b'"#);
    }

    #[test]
    fn modules_resolve_in_dependency_order_when_a_kernel_is_installed() {
        let Ok(pre) = prereqs() else {
            eprintln!("skipped: no Debian kernel installed (vcan-setup install)");
            return;
        };
        let files = module_files(&pre.kernel_version, MODULES).expect("modules resolve");
        let pos = |n: &str| {
            files
                .iter()
                .position(|p| p.file_name().and_then(|f| f.to_str()) == Some(n))
        };
        let (can, raw, vcan, dev) = (
            pos("can.ko"),
            pos("can-raw.ko"),
            pos("vcan.ko"),
            pos("can-dev.ko"),
        );
        assert!(
            can.is_some() && raw.is_some() && vcan.is_some() && dev.is_some(),
            "{files:?}"
        );
        assert!(can < raw && dev < vcan);
    }
}
