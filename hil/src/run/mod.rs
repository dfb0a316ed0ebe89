//! One bench run: bring up vcan, start `nav` as its own process (unmodified: only its config
//! file differs from a vehicle's), run the emulators for the scenario's simulated duration,
//! stop `nav` with SIGTERM, check and report.

mod judge;
pub mod offload;

pub use crate::engine::faultlog::NavStall;
use crate::engine::truthrec::RunTruth;
use crate::procedures::observe::{DrillWatch, solution_socket, watch_solution};
use crate::report::{self, RunReport};
use crate::report::{KillOutcome, NavMemory, cpu_seconds};
use crate::scenario::Scenario;
use anyhow::{Context, Result, bail};
use emulators::adapters::pty::{GpsDevice, GpsPty, relink};
use judge::{Ended, judge, write_evidence};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tracing::info;

/// Options of a run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// CAN interface to use (created when missing).
    pub iface: String,
    /// Output folder.
    pub out: PathBuf,
    /// The `nav` binary.
    pub nav_bin: PathBuf,
    /// Print progress.
    pub progress: bool,
    /// After the run, also check nav against the in-process reference run, replay nav's
    /// recording through the pipeline and score navigation from it (off for benchmarks, which
    /// want the pace only).
    pub reference_checks: bool,
    /// Write `report.html` (plots read from nav's recording) beside `report.md`.
    pub html: bool,
    /// Take the interface down during the run: [down at, up at], simulated s, switched by the
    /// scheduler between two samples (the fault matrix's "CAN interface down and up").
    pub link_downs: Vec<[f64; 2]>,
    /// Kill nav outright (SIGKILL) at this simulated time, s; its recording is then read back
    /// and its summary rebuilt from it.
    pub kill_nav_at_s: Option<f64>,
    /// Stop nav (SIGSTOP) at this simulated time for this many seconds of wall time, then let it
    /// go on (SIGCONT): a host that deschedules it. Run free (no lockstep), the devices write on
    /// and nav's socket overflows (the fault matrix's `bus-overload`).
    pub stall_nav: Option<NavStall>,
    /// Run nav as this user and group id (see [`nav_account`]); none: as the bench's user.
    pub nav_account: Option<(u32, u32)>,
    /// Put gpsd between the GPS emulator's pty and nav (nav's `[gps] source = "gpsd"`), as a
    /// vehicle shares one receiver; gpsd's own log goes to `gpsd.log` in the run folder.
    pub gps_via_gpsd: bool,
    /// The live view the run is shown on, when there is one.
    pub live: Option<std::sync::Arc<crate::live::View>>,
}

/// The account nav runs as. nav needs no privilege (a raw CAN socket, and the serial port it
/// is given), so a bench running as root (in the VM, or natively under sudo) proves it by
/// running nav as `nobody` (65534); `HIL_NAV_UID` names another user id (0 keeps root).
/// Not root: nav runs as the bench's user.
pub fn nav_account() -> Option<(u32, u32)> {
    // SAFETY: geteuid(2) cannot fail.
    if unsafe { libc::geteuid() } != 0 {
        return None;
    }
    match std::env::var("HIL_NAV_UID")
        .ok()
        .map(|v| v.trim().parse::<u32>())
    {
        Some(Ok(0)) => None,
        Some(Ok(uid)) => Some((uid, uid)),
        Some(Err(_)) => {
            tracing::warn!("HIL_NAV_UID is not a user id: nav runs as nobody (65534)");
            Some((NOBODY, NOBODY))
        }
        None => Some((NOBODY, NOBODY)),
    }
}

/// `nobody`'s user and group id.
pub const NOBODY: u32 = 65534;

/// A folder nav (run as another user) may write in: its files are moved into the run folder
/// when nav is done, or when the run ends however it ends. The run folder (perhaps behind a
/// private parent) stays the bench user's.
pub(crate) struct NavFolder {
    pub(crate) dir: PathBuf,
    out: PathBuf,
    staged: bool,
}

impl NavFolder {
    pub(crate) fn new(out: &Path, account: Option<(u32, u32)>) -> Result<Self> {
        let Some((uid, gid)) = account else {
            return Ok(Self {
                dir: out.to_path_buf(),
                out: out.to_path_buf(),
                staged: false,
            });
        };
        // beside the run folder when nav can reach it (moving is then a rename, however large
        // the recording), else in the temporary folder
        let name = format!(
            ".hil-nav-{}-{}",
            std::process::id(),
            NAV_FOLDERS.fetch_add(1, Ordering::Relaxed)
        );
        let dir = if reachable_by_others(out) {
            out.join(name)
        } else {
            std::env::temp_dir().join(name)
        };
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        std::os::unix::fs::chown(&dir, Some(uid), Some(gid))
            .with_context(|| format!("giving {} to uid {uid}", dir.display()))?;
        Ok(Self {
            dir,
            out: out.to_path_buf(),
            staged: true,
        })
    }

    /// Move nav's files into the run folder.
    pub(crate) fn finish(&mut self) -> Result<()> {
        if !self.staged {
            return Ok(());
        }
        self.staged = false;
        for e in std::fs::read_dir(&self.dir)
            .with_context(|| format!("listing {}", self.dir.display()))?
        {
            let from = e?.path();
            let Some(name) = from.file_name() else {
                continue;
            };
            let to = self.out.join(name);
            if std::fs::rename(&from, &to).is_err() {
                std::fs::copy(&from, &to)
                    .with_context(|| format!("moving {} to {}", from.display(), to.display()))?;
                std::fs::remove_file(&from)?;
            }
            // the run folder's files are the bench user's, as if nav had never been someone else
            // SAFETY: getuid(2) and getgid(2) cannot fail.
            let (uid, gid) = unsafe { (libc::getuid(), libc::getgid()) };
            if let Err(e) = std::os::unix::fs::chown(&to, Some(uid), Some(gid)) {
                // the file is there and readable: a warning, not a failed run
                tracing::warn!("cannot give {} back to uid {uid}: {e}", to.display());
            }
        }
        std::fs::remove_dir(&self.dir).with_context(|| format!("removing {}", self.dir.display()))
    }
}

impl Drop for NavFolder {
    fn drop(&mut self) {
        if let Err(e) = self.finish() {
            tracing::warn!("nav's files: {e:#}");
        }
    }
}

/// Every folder from the root down to `dir` may be entered by any user.
fn reachable_by_others(dir: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    let Ok(dir) = dir.canonicalize() else {
        return false;
    };
    dir.ancestors().all(|d| {
        std::fs::metadata(d).is_ok_and(|m| m.is_dir() && m.permissions().mode() & 0o001 != 0)
    })
}

static NAV_FOLDERS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Receiver links made by this process so far (each run's link has a name of its own).
static GPS_LINKS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

impl RunOptions {
    /// A run of `nav_bin` on `iface` writing to `out`: quiet, no reference checks, no bench
    /// actions.
    pub fn new(iface: &str, out: PathBuf, nav_bin: PathBuf) -> Self {
        Self {
            iface: iface.into(),
            out,
            nav_bin,
            progress: false,
            reference_checks: false,
            html: true,
            link_downs: Vec::new(),
            kill_nav_at_s: None,
            stall_nav: None,
            nav_account: nav_account(),
            gps_via_gpsd: false,
            live: None,
        }
    }
}

/// The `nav` binary next to the running executable (cargo puts all workspace binaries together).
pub fn sibling_binary(name: &str) -> Result<PathBuf> {
    let exe = std::env::current_exe().context("locating the running executable")?;
    let dir = exe.parent().context("executable has no folder")?;
    for d in [dir, dir.parent().unwrap_or(dir)] {
        let p = d.join(name);
        if p.is_file() {
            return Ok(p);
        }
    }
    bail!(
        "cannot find the {name} binary next to {} (build it with `cargo build --workspace`)",
        exe.display()
    )
}

pub(crate) struct NavProcess {
    child: Child,
    lines: std::sync::mpsc::Receiver<String>,
}

pub(crate) fn start_nav(
    bin: &Path,
    config: &Path,
    account: Option<(u32, u32)>,
) -> Result<NavProcess> {
    use std::os::unix::process::CommandExt;
    let mut cmd = Command::new(bin);
    cmd.arg("--config")
        .arg(config)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    if let Some((uid, gid)) = account {
        // std drops the supplementary groups too when root changes the user
        cmd.uid(uid).gid(gid);
    }
    // nav on one CPU, the last it may run on, as the bench's bus thread is on the first: on vcan a writer that moves between CPUs can
    // have its frames delivered out of order (seen with two CPU hogs: a NAV_TIME after the
    // one that followed it, so the frames it placed went on the bus model late, and the
    // model's figures differed between two paces of one drill); a real controller keeps
    // a sender's order. Failing to pin changes nothing else (the run reports any reordering).
    // SAFETY: pin_to_one_cpu makes two async-signal-safe system calls between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            let _ = wire::pin_to_one_cpu(wire::CpuPick::Last);
            Ok(())
        });
    }
    let mut child = cmd.spawn().with_context(|| {
        format!(
            "starting {}{}",
            bin.display(),
            account.map_or(String::new(), |(u, _)| format!(" as uid {u}"))
        )
    })?;
    let out = child.stdout.take().context("nav stdout")?;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for l in BufReader::new(out).lines().map_while(|l| l.ok()) {
            let _ = tx.send(l);
        }
    });
    let started = Instant::now();
    let stat = format!("/proc/{}/stat", child.id());
    loop {
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(l) if l.starts_with("nav: receiving") => break,
            Ok(l) => crate::status::line(&l),
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                if let Some(st) = child.try_wait()? {
                    bail!("nav exited before it was ready ({st}); see its messages above");
                }
                // liveness, not pace: a nav the machine starves (two CPU hogs beside a loaded
                // guest) is waited for; one that spent its CPU without getting ready is not
                let cpu = cpu_seconds(&stat).unwrap_or(0.0);
                let waited = started.elapsed().as_secs_f64();
                if (waited > READY_WAIT_S && cpu > READY_CPU_S) || waited > READY_STARVED_S {
                    let _ = child.kill();
                    bail!(
                        "nav did not report ready within {waited:.0} s, having had {cpu:.1} s of CPU{}",
                        if cpu > READY_CPU_S {
                            ""
                        } else {
                            ": the machine starved it"
                        }
                    );
                }
            }
            Err(_) => {
                let st = child.wait()?;
                bail!("nav exited before it was ready ({st}); see its messages above");
            }
        }
    }
    Ok(NavProcess { child, lines: rx })
}

/// Wall time after which nav must be ready if it has had [`READY_CPU_S`] of CPU, s.
const READY_WAIT_S: f64 = 60.0;
/// CPU time within which nav gets ready (it needs well under a second), s.
const READY_CPU_S: f64 = 20.0;
/// Wall time after which a nav not ready is given up on however little CPU it had, s.
const READY_STARVED_S: f64 = 600.0;

pub(crate) fn stop_nav(mut nav: NavProcess) -> Result<(Option<i32>, Vec<String>)> {
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(nav.child.id() as libc::pid_t, libc::SIGTERM) };
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(st) = nav.child.try_wait()? {
            break st.code();
        }
        if Instant::now() > deadline {
            let _ = nav.child.kill();
            let _ = nav.child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Ok((status, nav.lines.try_iter().collect()))
}

/// Run a scenario here (the kernel must have CAN). Returns the report; files go to `opts.out`.
/// The stages: `prepare` the devices' pty and nav's config, start nav and the devices,
/// `supervise` them to the stream's end, stop them, `read_summary`, `judge` nav against the
/// run's truth (planned once, before nav starts) and the reference runs, `write_evidence` and
/// `write_report`.
pub fn run_here(s: &Scenario, opts: &RunOptions, backend: &str) -> Result<RunReport> {
    let mut setup = prepare(s, opts)?;
    let truth = RunTruth::of(s, &opts.link_downs, opts.kill_nav_at_s, opts.stall_nav)?;
    let account = opts
        .nav_account
        .map_or_else(|| "this user".into(), |(u, g)| format!("uid {u}, gid {g}"));
    info!(interface = %opts.iface, account = %account, "starting nav");
    let mut phases = Phases::starting_now();
    let nav = start_nav(&opts.nav_bin, &setup.cfg_path, opts.nav_account)?;
    phases.end("nav start");
    let live = match &opts.live {
        Some(v) => {
            let l = crate::live::bench_run::BenchRun::begin(v, &s.name, Some(&truth), true)?;
            l.set_nav_pid(nav.child.id());
            Some(l)
        }
        None => None,
    };

    let watch_stop = Arc::new(AtomicBool::new(false));
    let watch = {
        // opened before the IMU starts, so the first epoch is not missed
        let sock = solution_socket(&opts.iface)?;
        let (iface, stop) = (opts.iface.clone(), watch_stop.clone());
        std::thread::spawn(move || watch_solution(sock, &iface, &stop))
    };
    let gps_device = receiver_device(s, opts, setup.gps.take())?;
    let t0 = Instant::now();
    let devices = crate::engine::devices::start_scenario(
        s,
        &opts.iface,
        gps_device,
        Some(&opts.out.join("bench-can.log")),
        &opts.link_downs,
        live.as_ref().map(|l| l.watcher(s)),
        live.as_ref().map(|l| l.hold()),
    )?;
    let Supervised {
        mut drill,
        killed_at,
        mut memory,
    } = supervise(s, opts, &nav, &devices, live.as_ref());
    let wall = t0.elapsed().as_secs_f64();
    phases.end("devices");
    let sim_reached = devices.sim_time();
    let bus = devices.join();
    // in lockstep nav has confirmed the last sample and reported the stream's end; else a
    // moment for nav to take the last frames (it also drains its socket when told to stop)
    if !s.bus.lockstep {
        std::thread::sleep(Duration::from_millis(100));
    }
    if killed_at.is_none() {
        memory.read(nav.child.id(), sim_reached);
    }
    let (bus, nav_out) = match bus {
        Ok(b) => (b, stop_nav(nav)?),
        Err(e) => {
            let _ = stop_nav(nav);
            return Err(e);
        }
    };
    memory.finish();
    phases.end("nav stop");
    let (nav_exit, nav_lines) = nav_out;
    setup.nav_folder.finish()?;
    watch_stop.store(true, Ordering::Relaxed);
    let solution = watch
        .join()
        .map_err(|_| anyhow::anyhow!("solution watcher panicked"))??;
    for l in &nav_lines {
        // nav's own words (its summary, warnings), unless the caller wants the figures only
        if !drill.line(l, false) && opts.progress {
            crate::status::line(l);
        }
    }
    let kill = killed_at.map(|at| (at, solution.last_sample));
    let (nav_json, killed) = read_summary(s, opts, &setup.nav_cfg, kill, nav_exit)?;
    phases.end("summary");
    let ended = Ended {
        bus,
        sim_reached,
        wall,
        nav_exit,
        nav: nav_json,
        killed,
        memory,
        solution,
    };
    let (mut r, evidence) = judge(s, opts, &truth, &setup.nav_cfg, backend, ended, &mut phases)?;
    write_evidence(s, opts, &truth, &evidence)?;
    phases.end("files");
    phases.log(r.nav_memory.as_ref().and_then(|m| m.cpu_s));
    if let Some(l) = live {
        let j = serde_json::to_value(&r)?;
        r.live = Some(l.end(j, crate::report::card(&r)));
    }
    write_report(&r, opts)?;
    Ok(r)
}

/// What a run needs before nav starts, and what must live as long as the run: the receiver's
/// pty (behind a link, removed when the run ends), nav's folder and config, gpsd when asked.
struct Setup {
    gps: Option<(GpsPty, PathBuf)>,
    _link_guard: Option<RemoveOnDrop>,
    nav_folder: NavFolder,
    cfg_path: PathBuf,
    nav_cfg: nav::config::NavConfig,
    _gpsd: Option<Gpsd>,
}

/// The run folder, the receiver's pty, nav's folder and its config file (with the parameter
/// files it loads beside it), gpsd when the run puts it between the receiver and nav.
fn prepare(s: &Scenario, opts: &RunOptions) -> Result<Setup> {
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("creating {}", opts.out.display()))?;
    vcan_setup::ensure_vcan(&opts.iface)?;
    std::fs::write(opts.out.join("scenario.toml"), toml::to_string_pretty(s)?)?;
    // the receiver's pty, behind a link as a USB receiver sits behind /dev/serial/by-id
    let gps = match &s.gps {
        Some(_) => {
            let pty = GpsPty::open().context("GPS emulator")?;
            // one per run: runs of one process side by side (`hil faults --jobs`) each have one
            let link = std::env::temp_dir().join(format!(
                "hil-gps-{}-{}",
                std::process::id(),
                GPS_LINKS.fetch_add(1, Ordering::Relaxed)
            ));
            relink(&link, pty.path()).context("GPS emulator")?;
            Some((pty, link))
        }
        None => None,
    };
    // the link goes when the run ends, however it ends
    let _link_guard = gps.as_ref().map(|g| RemoveOnDrop(g.1.clone()));
    let nav_folder = NavFolder::new(&opts.out, opts.nav_account)?;
    if let (Some((uid, gid)), Some((pty, _))) = (opts.nav_account, &gps) {
        // the receiver's port is nav's to open, as udev gives a vehicle's serial port to nav's
        // group
        pty.give_to(uid, gid)?;
    }
    let cfg_path = nav_folder.dir.join("nav.toml");
    let mut nav_cfg = crate::scenario::navconfig::nav_config(
        s,
        Some(&opts.iface),
        gps.as_ref().map(|g| g.1.as_path()),
    );
    // gpsd between the receiver and nav: started on the port before nav, stopped after the run
    let _gpsd = match (&gps, opts.gps_via_gpsd, nav_cfg.gps.as_mut()) {
        (Some((_, link)), true, Some(g)) => {
            let d = Gpsd::start(link, &opts.out.join("gpsd.log"))?;
            g.source = nav::config::GpsSource::Gpsd;
            g.gpsd = d.addr.clone();
            g.gpsd_device = Some(link.to_string_lossy().into_owned());
            Some(d)
        }
        (_, true, _) => bail!("--gpsd: the scenario has no GPS receiver"),
        _ => None,
    };
    // the parameter file nav loads goes beside its config, where nav (perhaps another user)
    // can read it, and into the run's record
    crate::scenario::navconfig::copy_inputs_beside(&mut nav_cfg, &nav_folder.dir)?;
    std::fs::write(&cfg_path, nav_cfg.to_toml())?;
    Ok(Setup {
        gps,
        _link_guard,
        nav_folder,
        cfg_path,
        nav_cfg,
        _gpsd,
    })
}

/// The receiver on its pty (and what it sent, logged), when the scenario has one.
fn receiver_device(
    s: &Scenario,
    opts: &RunOptions,
    gps: Option<(GpsPty, PathBuf)>,
) -> Result<Option<(emulators::gps::GpsRun, GpsDevice)>> {
    Ok(match (gps, &s.gps) {
        (Some((pty, link)), Some(rx)) => match crate::engine::inproc::gps_run(s, rx)? {
            // what the receiver sent, kept beside nav's recording (gpsd's .log form)
            Some(run) => {
                let dev = GpsDevice::new(pty, Some(link))
                    .with_owner(opts.nav_account)
                    .with_log(&opts.out.join("gps-sent.log"))?;
                // gpsd reads the device and passes nav only the sentences it keeps
                let dev = if opts.gps_via_gpsd {
                    dev.without_bus_confirmation()
                } else {
                    dev
                };
                Some((run, dev))
            }
            None => None,
        },
        _ => None,
    })
}

/// What the bench saw while the devices ran.
struct Supervised {
    drill: DrillWatch,
    killed_at: Option<f64>,
    memory: NavMemory,
}

/// Watch nav and the devices until the stream ends: nav's progress lines, its memory each
/// second, the kill the fault matrix asks for, the pace on the terminal.
fn supervise(
    s: &Scenario,
    opts: &RunOptions,
    nav: &NavProcess,
    devices: &crate::engine::devices::Running<emulators::adapters::scheduler::BusOutcome>,
    live: Option<&crate::live::bench_run::BenchRun>,
) -> Supervised {
    let mut drill = DrillWatch::default();
    let mut next_report = Instant::now() + Duration::from_secs(5);
    let mut last_report = (Instant::now(), 0.0);
    let mut killed_at: Option<f64> = None;
    let mut memory = NavMemory::new(s.duration_s);
    let mut next_memory = Instant::now();
    let mut stall = Stall::new(opts.stall_nav, nav.child.id());
    // a stall is held to its end even if the stream ends meanwhile (a stopped nav takes no
    // signal to finish)
    while !devices.is_finished() || stall.holding() {
        // a pending stall is started within 2 ms of its simulated time
        let poll = if stall.pending() { 2 } else { 50 };
        std::thread::sleep(Duration::from_millis(poll));
        stall.poll(devices.sim_time());
        if killed_at.is_none() && Instant::now() >= next_memory {
            memory.read(nav.child.id(), devices.sim_time());
            next_memory += Duration::from_secs(1);
        }
        if let Some(k) = opts.kill_nav_at_s
            && killed_at.is_none()
            && devices.sim_time() >= k
        {
            let t = devices.sim_time();
            info!("killing nav (SIGKILL) at {t:.2} s");
            // SAFETY: kill(2) on our own child's pid.
            unsafe { libc::kill(nav.child.id() as libc::pid_t, libc::SIGKILL) };
            killed_at = Some(t);
            // nothing more can reach a dead nav: the devices stop rather than wait for it
            devices.stop();
        }
        // (a procedure with no drive after it ends the stream itself, when nav's NAV_TIME says
        // it is over: `inproc::stepper`)
        for l in nav.lines.try_iter() {
            drill.line(&l, opts.progress);
            if let Some(v) = live {
                v.line(&l);
            }
        }
        if opts.progress && (!s.has_procedure() || drill.done) && Instant::now() >= next_report {
            let t = devices.sim_time();
            let reached = (t - last_report.1) / last_report.0.elapsed().as_secs_f64().max(1e-9);
            // nothing to say while the devices stand (a finished drill being stopped)
            if t <= last_report.1 {
                next_report += Duration::from_secs(5);
                continue;
            }
            let text = format!(
                "{t:.1} / {:.1} s simulated (x{} asked, x{reached:.1} reached)",
                s.duration_s, s.speed
            );
            // a bar redrawn each second on a terminal, a line every 5 s in a log
            let every = if crate::status::interactive() {
                crate::status::show(&format!(
                    "{} {text}",
                    crate::status::bar_of(t / s.duration_s.max(1e-9), 30)
                ));
                1
            } else {
                crate::status::show(&format!("hil: {text}"));
                5
            };
            last_report = (Instant::now(), t);
            next_report += Duration::from_secs(every);
        }
    }
    crate::status::finish();
    Supervised {
        drill,
        killed_at,
        memory,
    }
}

/// The bench's stop of nav ([`RunOptions::stall_nav`]): SIGSTOP at its simulated time, SIGCONT
/// its wall time later.
struct Stall {
    plan: Option<NavStall>,
    pid: libc::pid_t,
    stopped: Option<Instant>,
    done: bool,
}

impl Stall {
    fn new(plan: Option<NavStall>, pid: u32) -> Self {
        Self {
            plan,
            pid: pid as libc::pid_t,
            stopped: None,
            done: false,
        }
    }

    /// Planned and not yet started.
    fn pending(&self) -> bool {
        self.plan.is_some() && self.stopped.is_none() && !self.done
    }

    /// nav is stopped now.
    fn holding(&self) -> bool {
        self.stopped.is_some() && !self.done
    }

    /// Stop nav when the stream reaches the stall's time, let it go on when the stall is over.
    fn poll(&mut self, sim_time: f64) {
        let Some(plan) = self.plan else { return };
        match self.stopped {
            None if sim_time >= plan.at_s => {
                info!(
                    "stopping nav (SIGSTOP) at {sim_time:.3} s for {} s of wall time",
                    plan.wall_s
                );
                // SAFETY: kill(2) on our own child's pid.
                unsafe { libc::kill(self.pid, libc::SIGSTOP) };
                self.stopped = Some(Instant::now());
            }
            Some(t) if !self.done && t.elapsed().as_secs_f64() >= plan.wall_s => {
                info!("nav goes on (SIGCONT) at {sim_time:.3} s");
                // SAFETY: kill(2) on our own child's pid.
                unsafe { libc::kill(self.pid, libc::SIGCONT) };
                self.done = true;
            }
            _ => {}
        }
    }
}

/// nav's summary file; for a nav killed outright (`kill`: the stream's time at the kill and
/// the IMU sample count of nav's last NAV_TIME the bench saw), rebuilt by nav's pipeline from
/// its recording, and what the kill cost. Paths nav wrote in its own folder point into the run
/// folder.
fn read_summary(
    s: &Scenario,
    opts: &RunOptions,
    nav_cfg: &nav::config::NavConfig,
    kill: Option<(f64, Option<u64>)>,
    nav_exit: Option<i32>,
) -> Result<(nav::summary::Summary, Option<KillOutcome>)> {
    let summary_path = opts.out.join("nav-summary.json");
    let mut killed = None;
    let mut nav_json = match nav::summary::Summary::read(&summary_path) {
        Ok(s) => s,
        Err(nav::summary::SummaryError::Read { .. }) if kill.is_some() => {
            // killed outright: what it recorded is all there is; nav's pipeline rebuilds the
            // summary from it
            let p = crate::engine::recording::replay(&opts.out.join("nav.mcap"), nav_cfg)
                .context("reading back the recording of the killed nav")?;
            let (at_s, nav_last) = kill.unwrap_or((0.0, None));
            let sm = &p.summary;
            let recorded_until_s = match (sm.first_sample, sm.last_sample) {
                (Some(a), Some(b)) => (b.saturating_sub(a) + 1) as f64 / s.imu.rate_hz,
                _ => 0.0,
            };
            // NAV_TIME carries the count's low 32 bits: measured from the recording's first
            // sample the same way
            let nav_reached_s = match (sm.first_sample, nav_last) {
                (Some(a), Some(k)) => {
                    Some((f64::from((k as u32).wrapping_sub(a as u32)) + 1.0) / s.imu.rate_hz)
                }
                (None, Some(k)) => Some((k + 1) as f64 / s.imu.rate_hz),
                (_, None) => None,
            };
            killed = Some(KillOutcome {
                at_s,
                recorded_frames: p.frames_in,
                recorded_until_s,
                lost_s: at_s - recorded_until_s,
                nav_reached_s,
                unrecorded_s: nav_reached_s.map(|n| n - recorded_until_s),
                bad_records: p.bad_records,
            });
            p.summary
        }
        Err(e @ nav::summary::SummaryError::Read { .. }) => {
            return Err(anyhow::Error::new(e).context(format!(
                "nav wrote no summary; exit status {}",
                crate::check::exit_words(nav_exit)
            )));
        }
        Err(e) => return Err(e.into()),
    };
    // nav wrote its files in its own folder, now moved into the run folder
    for f in nav_json.written_files_mut() {
        if let Some(name) = f.file_name() {
            *f = opts.out.join(name);
        }
    }
    Ok((nav_json, killed))
}

/// The run's report.json, report.md and, when asked, report.html.
fn write_report(r: &RunReport, opts: &RunOptions) -> Result<()> {
    std::fs::write(
        opts.out.join("report.json"),
        serde_json::to_string_pretty(&r)?,
    )?;
    std::fs::write(opts.out.join("report.md"), report::markdown(r))?;
    if opts.html {
        std::fs::write(
            opts.out.join("report.html"),
            crate::report::html::run_report(r, &opts.out),
        )?;
    }
    Ok(())
}

/// Where a run's wall time went, phase by phase (logged at the end of every run: the e2e tests
/// have a time budget).
struct Phases {
    since: Instant,
    done: Vec<(&'static str, f64)>,
}

impl Phases {
    /// Log the phases, with the CPU time nav (`nav_cpu_s`) and the bench took.
    fn log(&self, nav_cpu_s: Option<f64>) {
        info!(
            "run phases: {self} CPU: nav {:.1} s, bench {:.1} s",
            nav_cpu_s.unwrap_or(f64::NAN),
            cpu_seconds("/proc/self/stat").unwrap_or(f64::NAN)
        );
    }

    /// The first phase begins now.
    fn starting_now() -> Self {
        Self {
            since: Instant::now(),
            done: Vec::new(),
        }
    }

    /// The phase `name` ends now (it began when the previous one ended).
    fn end(&mut self, name: &'static str) {
        let now = Instant::now();
        self.done.push((name, (now - self.since).as_secs_f64()));
        self.since = now;
    }
}

impl std::fmt::Display for Phases {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let total: f64 = self.done.iter().map(|p| p.1).sum();
        write!(f, "{total:.1} s:")?;
        for (n, s) in self.done.iter().filter(|p| p.1 >= 0.05) {
            write!(f, " {n} {s:.1} s,")?;
        }
        Ok(())
    }
}

/// Removes a file when dropped.
/// gpsd on the GPS emulator's port, stopped when dropped.
struct Gpsd {
    child: Child,
    /// Where it listens, `host:port`.
    addr: String,
}

impl Gpsd {
    /// Start gpsd in the foreground on `device`, read-only (`-b`: it must not write probes to the
    /// receiver's port), opening it at once (`-n`), on a free local port; its output to `log`.
    /// Returns once it accepts connections.
    fn start(device: &Path, log: &Path) -> Result<Self> {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .context("finding a free port for gpsd")?
            .port();
        let out =
            std::fs::File::create(log).with_context(|| format!("creating {}", log.display()))?;
        let err = out.try_clone().context("gpsd's log")?;
        let child = Command::new("gpsd")
            .args(["-N", "-n", "-b", "-S", &port.to_string()])
            .arg(device)
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .spawn()
            .context(
                "starting gpsd (./run-tests installs it; in the guest it comes from the host)",
            )?;
        let mut d = Self {
            child,
            addr: format!("127.0.0.1:{port}"),
        };
        let t0 = Instant::now();
        while std::net::TcpStream::connect(&d.addr).is_err() {
            if let Ok(Some(st)) = d.child.try_wait() {
                bail!("gpsd exited ({st}) before listening: see {}", log.display());
            }
            if t0.elapsed() > Duration::from_secs(10) {
                bail!(
                    "gpsd did not listen on {} within 10 s: see {}",
                    d.addr,
                    log.display()
                );
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        info!(address = %d.addr, device = %device.display(), "gpsd started");
        Ok(d)
    }
}

impl Drop for Gpsd {
    fn drop(&mut self) {
        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM) };
        let _ = self.child.wait();
    }
}

pub(crate) struct RemoveOnDrop(pub(crate) PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}
