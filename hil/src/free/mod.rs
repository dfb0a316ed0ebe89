//! A free-running run: the bench's emulators on the host's clock at x1, waiting for nobody,
//! and a device under test that the bench does not pace (our nav like any other, another
//! team's implementation of the DBC, a box already on the interface), judged by what it sends
//! on the bus, by the DBC only ([`score`]), against truth at the IMU sample each of its
//! NAV_TIMEs names, with its latency from that sample on the bus.
//!
//! Devices may be real instead of emulated: a turntable on the interface (the IMU then rides
//! it: its truth turns as the table's TT_STATUS reports, `emulators::reported`, and so does the
//! truth the heading is scored against), a receiver on a serial port (given to the device under
//! test; not scored here). What the bench cannot know is said on the card.
//!
//! The bench measures its own lateness apart from the device's; when it cannot keep real time
//! it stops and says so, and gives no verdict on the device.

pub mod clock;
pub mod listener;
pub mod probe;
pub mod score;
mod verdict;

use crate::check::Check;
use crate::scenario::Scenario;
use anyhow::{Context, Result, bail};
use emulators::adapters::freerun::{FreeStats, Pacing, SentSamples};
use emulators::adapters::pty::GpsPty;
use emulators::adapters::transport::{BusStream, Progress};
use emulators::gps::GpsReceiver;
use emulators::imu::ImuEmulator;
use emulators::reported::SharedTrack;
use emulators::turntable::ttbus::TtBus;
use listener::Observed;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The device under test.
#[derive(Debug, Clone, PartialEq)]
pub enum Dut {
    /// Our nav binary, on the config the bench writes for the scenario.
    Nav(PathBuf),
    /// A command the bench starts (through `sh -c`), with `{iface}`, `{gps}` (the receiver's
    /// port), `{config}` (the nav.toml the bench wrote for the scenario), `{out}` (its folder),
    /// `{nav}` (our nav binary), and on a lab's contract `{mapping}` and `{dbc}` (its files)
    /// replaced.
    Command(String, PathBuf),
    /// Nothing to start: the device is already on the interface.
    Nothing,
}

/// How a free-running run goes.
#[derive(Debug, Clone)]
pub struct FreeOptions {
    /// The CAN interface.
    pub iface: String,
    /// The run folder.
    pub out: PathBuf,
    /// The device under test.
    pub dut: Dut,
    /// The turntable on the interface is real: the bench does not emulate it.
    pub real_turntable: bool,
    /// The receiver is real, on this port: the bench does not emulate it.
    pub real_gps: Option<PathBuf>,
    /// The device's latency budget: the 99th percentile of IMU sample on the bus to the
    /// NAV_TIME naming it, ms.
    pub latency_budget_ms: f64,
    /// The device must send its first NAV_TIME within this long of the stream's start, s.
    pub answer_within_s: f64,
    /// The bench's own lateness beyond which it stops, ms.
    pub max_late_ms: f64,
    /// How far ahead of the stream a NAV_TIME may name a sample (a device that states its
    /// solution as a prediction), ms; none: one of its output periods.
    pub lead_allowance_ms: Option<f64>,
    /// Progress on the terminal.
    pub progress: bool,
    /// The bus speaks a lab's own contract (its DBC and mapping), not ours.
    pub lab: Option<Arc<listener::LabEar>>,
}

/// The bench's ear on the lab's contract of the mapping file at `path` (and the DBC it names).
pub fn lab_ear(path: &Path) -> Result<listener::LabEar> {
    let (c, m) = crate::scenario::lab_contract::load(path)?;
    if m.file.solution.is_none() {
        bail!(
            "the mapping {}: no [solution]: the bench cannot read the device's solution",
            path.display()
        );
    }
    // absolute: the device under test runs in its own folder, given {mapping} and {dbc}
    let path =
        std::fs::canonicalize(path).with_context(|| format!("the mapping {}", path.display()))?;
    Ok(listener::LabEar::new(c, m, path))
}

/// What a free-running run found.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FreeReport {
    /// The scenario.
    pub scenario: String,
    /// The interface.
    pub interface: String,
    /// The contract the bus spoke: our DBC, or a lab's through its mapping.
    #[serde(default)]
    pub contract: String,
    /// The device under test, as started.
    pub device: String,
    /// How it ended (exit status, or still running when stopped).
    pub device_exit: String,
    /// Why the run ended.
    pub ended: String,
    /// Wall time from the stream's start, s.
    pub wall_s: f64,
    /// The bench's emulated devices: what each sent and its own lateness.
    pub bench: Vec<FreeStats>,
    /// The bench could not keep real time: why (no verdict on the device then).
    pub bench_behind: Option<String>,
    /// Devices that were real, and where.
    pub real: Vec<String>,
    /// The device's solution epochs.
    pub epochs: u64,
    /// Its stated latency: IMU sample on the bus to the NAV_TIME naming it (negative for a
    /// sample named before it went out).
    pub latency: score::Spread,
    /// The same less what the host held a thread beside the device of each ([`probe`]).
    pub latency_own: score::Spread,
    /// NAV_TIMEs naming no sample the bench could place (older than it keeps).
    pub unnamed_samples: u64,
    /// NAV_TIMEs naming samples ahead of the stream.
    pub lead: clock::Lead,
    /// The device's clock against the IMU's.
    pub clock: Option<clock::ClockFit>,
    /// The host's scheduling delays beside the device, as the probe saw them.
    pub host: emulators::adapters::freerun::LatenessSummary,
    /// Where the frames' times come from, in words.
    pub stamps: String,
    /// Frames heard out of their stamps' order, put back in it.
    pub reordered: u64,
    /// Its output rate.
    pub rate: score::Rate,
    /// The heading at the drill's end, against truth.
    pub heading: Option<score::HeadingScore>,
    /// Navigation along the drive, against truth.
    pub navigation: Option<score::DriveScore>,
    /// How old its data are against its tags, turn by turn; none when the data cannot tell.
    pub data_offset: Option<clock::DataOffset>,
    /// NAV_TIMEs whose sample count went back.
    pub backwards: u64,
    /// Frames outside the DBC, by what they were.
    pub outside_dbc: std::collections::BTreeMap<String, u64>,
    /// Turntable commands the device sent.
    pub commands: u64,
    /// Bytes the device says it took from the receiver (NAV_TIME's GpsRxBytes).
    pub receiver_bytes: u64,
    /// The device's position at the drill's end against the site's surveyed position: the
    /// horizontal distance, m, and its PosSigma, m.
    pub site_error: Option<(f64, Option<f64>)>,
    /// What the bench could not judge, and why.
    pub not_judged: Vec<String>,
    /// The checks.
    pub checks: Vec<Check>,
    /// All checks passed (and the bench kept real time).
    pub pass: bool,
}

/// A drill's vehicle parked with its receiver on, as our nav needs to say its heading on the
/// bus (it navigates after north-finding, from the first fix): a drive that stands still at
/// the site, facing the site's heading, for the whole run, and the scenario's receiver (the
/// default one when it has none). A scenario with a drive already is returned as it is.
pub fn parked_with_receiver(s: &Scenario) -> Result<Scenario> {
    let mut s = s.clone();
    if s.drive.is_some() {
        return Ok(s);
    }
    let h = s.site.heading_deg.to_radians();
    let text = format!(
        "lat_deg = {}\nlon_deg = {}\nheight_m = {}\nwaypoints = [[{}, {}]]\nspeed_mps = 1.0\nstart_wait_s = {}\n",
        s.site.lat_deg,
        s.site.lon_deg,
        s.site.height_m,
        1000.0 * h.sin(),
        1000.0 * h.cos(),
        s.duration_s + 60.0
    );
    s.drive = Some(toml::from_str(&text).context("the parked vehicle's drive")?);
    s.gps.get_or_insert_with(Default::default);
    s.navigation.get_or_insert_with(Default::default);
    Ok(s)
}

/// The scenario is a drill: north-finding with the vehicle standing still throughout (the run
/// ends when the device has said its heading).
pub(crate) fn is_drill(s: &Scenario) -> bool {
    s.north_finding.is_some()
        && s.drive
            .as_ref()
            .is_none_or(|d| d.start_wait_s >= s.duration_s)
}

/// The devices the bench runs, each in its thread.
struct Bench {
    threads: Vec<(&'static str, JoinHandle<Result<FreeStats>>)>,
    progress: Arc<Progress>,
    tracks: Vec<SharedTrack>,
    sent: Arc<SentSamples>,
    origin: Instant,
}

/// Run `s` free-running with the device under test of `o`.
pub fn run_free(s: &Scenario, o: &FreeOptions) -> Result<FreeReport> {
    std::fs::create_dir_all(&o.out).with_context(|| format!("creating {}", o.out.display()))?;
    let lab_rate = o.lab.as_ref().and_then(|l| l.mapping.file.imu.as_ref());
    let s = &match lab_rate {
        // the lab's unit samples at its mapping's rate
        Some(imu) => {
            let mut s = s.clone();
            s.imu.rate_hz = imu.rate_hz;
            s
        }
        None => s.clone(),
    };
    if o.lab.is_some() {
        vcan_setup::ensure_vcan_fd(&o.iface)?;
    } else {
        vcan_setup::ensure_vcan(&o.iface)?;
    }
    std::fs::write(o.out.join("scenario.toml"), toml::to_string_pretty(s)?)?;
    // the receiver's port: the real one, or the emulator's pty behind a link
    let pty = match (&s.gps, &o.real_gps) {
        (Some(_), None) => Some(GpsPty::open().context("GPS emulator")?),
        _ => None,
    };
    let link = std::env::temp_dir().join(format!("hil-free-gps-{}", std::process::id()));
    let gps_port = match (&pty, &o.real_gps) {
        (_, Some(p)) => Some(p.clone()),
        (Some(p), None) => {
            emulators::adapters::pty::relink(&link, p.path())?;
            Some(link.clone())
        }
        _ => None,
    };
    let nav_dir = o.out.join("device");
    std::fs::create_dir_all(&nav_dir)?;
    let cfg = nav_dir.join("nav.toml");
    crate::scenario::navconfig::write_nav_config(s, Some(&o.iface), gps_port.as_deref(), &cfg)?;
    let stop = Arc::new(AtomicBool::new(false));
    let prepared = prepare_bench(s, o, pty, stop.clone())?;
    let (mut child, device) = start_dut(o, &cfg, gps_port.as_deref(), &nav_dir)?;
    // a moment for the device to open its devices, as a vehicle's computer boots first
    std::thread::sleep(Duration::from_secs(1));
    let seen = Arc::new(Mutex::new(Observed::default()));
    let sock = listener::open(&o.iface, o.lab.is_some())?;
    let bench = start_bench(s, o, prepared)?;
    let observer = listener::spawn(
        sock,
        bench.origin,
        s.imu.oscillator(),
        bench.sent.clone(),
        seen.clone(),
        stop.clone(),
        o.lab.clone(),
    )?;
    let probe = probe::Probe::start(bench.origin, stop.clone())?;
    let ended = supervise(s, o, &bench, &seen, child.as_mut());
    stop.store(true, Ordering::Relaxed);
    let host = probe.finish();
    let device_exit = stop_dut(child);
    let wall_s = bench.origin.elapsed().as_secs_f64();
    let tracks = bench.tracks.clone();
    let mut stats = Vec::new();
    for (name, t) in bench.threads {
        let r = t
            .join()
            .map_err(|_| anyhow::anyhow!("the {name} emulator panicked"))?;
        stats.push(r.with_context(|| format!("{name} emulator"))?);
    }
    observer
        .join()
        .map_err(|_| anyhow::anyhow!("the bus observer panicked"))??;
    let _ = std::fs::remove_file(&link);
    let seen = std::mem::take(&mut *seen.lock().unwrap_or_else(|e| e.into_inner()));
    let ctx = Judged {
        device,
        device_exit,
        ended,
        wall_s,
        stats,
        tracks,
        host,
    };
    let r = verdict::judge(s, o, ctx, seen);
    std::fs::write(o.out.join("report.json"), serde_json::to_string_pretty(&r)?)?;
    std::fs::write(o.out.join("report.md"), format!("```\n{}```\n", card(&r)))?;
    Ok(r)
}

/// Start the device under test; its description.
fn start_dut(
    o: &FreeOptions,
    cfg: &Path,
    gps: Option<&Path>,
    dir: &Path,
) -> Result<(Option<Child>, String)> {
    let log = |name: &str| -> Result<Stdio> {
        Ok(std::fs::File::create(dir.join(name))
            .with_context(|| format!("creating {}", dir.join(name).display()))?
            .into())
    };
    let (mut cmd, what) = match &o.dut {
        Dut::Nothing => {
            return Ok((
                None,
                "already on the interface (not started by the bench)".into(),
            ));
        }
        Dut::Nav(bin) => {
            let mut c = Command::new(bin);
            c.arg("--config").arg(cfg);
            (
                c,
                format!("{} --config {} (ours)", bin.display(), cfg.display()),
            )
        }
        Dut::Command(text, nav) => {
            let text = text
                .replace("{nav}", &nav.to_string_lossy())
                .replace("{iface}", &o.iface)
                .replace("{config}", &cfg.to_string_lossy())
                .replace("{out}", &dir.to_string_lossy())
                .replace(
                    "{mapping}",
                    &o.lab
                        .as_ref()
                        .map(|l| l.path.to_string_lossy().into_owned())
                        .unwrap_or_default(),
                )
                .replace(
                    "{dbc}",
                    &o.lab
                        .as_ref()
                        .map(|l| {
                            let p = l.path.parent().unwrap_or(Path::new("."));
                            p.join(&l.dbc_name).to_string_lossy().into_owned()
                        })
                        .unwrap_or_default(),
                )
                .replace(
                    "{gps}",
                    &gps.map(|g| g.to_string_lossy().into_owned())
                        .unwrap_or_default(),
                );
            let mut c = Command::new("sh");
            c.arg("-c").arg(&text);
            (c, text)
        }
    };
    cmd.current_dir(dir)
        .stdin(Stdio::null())
        .stdout(log("device.out")?)
        .stderr(log("device.err")?);
    let child = cmd
        .spawn()
        .with_context(|| format!("starting the device under test: {what}"))?;
    Ok((Some(child), what))
}

/// Stop the device under test (SIGTERM, then SIGKILL after 10 s): how it ended.
fn stop_dut(child: Option<Child>) -> String {
    let Some(mut c) = child else {
        return "not the bench's to stop".into();
    };
    if let Ok(Some(st)) = c.try_wait() {
        return format!("ended before the bench stopped it: {}", exit_words(st));
    }
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(c.id() as libc::pid_t, libc::SIGTERM) };
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if let Ok(Some(st)) = c.try_wait() {
            return format!("stopped by SIGTERM: {}", exit_words(st));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = c.kill();
    let _ = c.wait();
    "did not stop within 10 s of SIGTERM: killed".into()
}

/// An exit status in words.
fn exit_words(st: std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (st.code(), st.signal()) {
        (Some(c), _) => format!("exit status {c}"),
        (None, Some(s)) => format!("killed by signal {s}"),
        _ => "ended".into(),
    }
}

/// A device's run, waiting for its pacing.
type DeviceRun = Box<dyn FnOnce(Pacing) -> Result<FreeStats> + Send>;

/// The emulated devices, built and not yet started.
struct Prepared {
    devices: Vec<(&'static str, DeviceRun)>,
    progress: Arc<Progress>,
    tracks: Vec<SharedTrack>,
    sent: Arc<SentSamples>,
}

/// Build every device's model (the receiver's whole drive among them, which takes a while on a
/// slow machine) before the device under test starts, so that the clock starts when the
/// devices can keep it and the device does not wait for a stream that is still being made.
fn prepare_bench(
    s: &Scenario,
    o: &FreeOptions,
    pty: Option<GpsPty>,
    stop: Arc<AtomicBool>,
) -> Result<Prepared> {
    let progress = Arc::new(Progress::default());
    let sent = Arc::new(SentSamples::new((30.0 * s.imu.rate_hz) as usize));
    // the IMU rides the table, emulated or real, as its TT_STATUS reports it
    let axes = s.turntable.as_ref().map_or(0, |t| usize::from(t.axes));
    let tracks: Vec<SharedTrack> = (0..axes).map(|_| s.reported_track(0.02)).collect();
    let mut devices: Vec<(&'static str, DeviceRun)> = Vec::new();
    if let Some(lab) = &o.lab {
        lab_devices(s, o, lab, (&tracks, &sent, &progress), &stop, &mut devices)?;
    } else {
        our_devices(s, o, (&tracks, &sent, &progress), &stop, &mut devices);
    }
    if let (Some(mut pty), Some(rx)) = (pty, &s.gps) {
        let Some(run) = crate::engine::inproc::gps_run(s, rx)? else {
            bail!("scenario {}: a receiver needs a [drive]", s.name);
        };
        let mut rx = GpsReceiver::new(run);
        let (stop, progress) = (stop.clone(), Arc::new(Progress::default()));
        devices.push((
            "gps",
            Box::new(move |pacing: Pacing| {
                Ok(emulators::adapters::freerun::run_gps(
                    &mut pty, &mut rx, &pacing, &stop, &progress,
                )?)
            }),
        ));
    }
    Ok(Prepared {
        devices,
        progress,
        tracks,
        sent,
    })
}

/// The emulated table and IMU on our contract.
fn our_devices(
    s: &Scenario,
    o: &FreeOptions,
    (tracks, sent, progress): (&[SharedTrack], &Arc<SentSamples>, &Arc<Progress>),
    stop: &Arc<AtomicBool>,
    devices: &mut Vec<(&'static str, DeviceRun)>,
) {
    if let (Some(tp), false) = (&s.turntable, o.real_turntable) {
        let mut tt = TtBus::new(emulators::turntable::Turntable::new(tp.clone()), 1000.0);
        let (iface, stop, progress) =
            (o.iface.clone(), stop.clone(), Arc::new(Progress::default()));
        devices.push((
            "turntable",
            Box::new(move |pacing: Pacing| {
                Ok(emulators::adapters::freerun::run_turntable(
                    &iface, &mut tt, 1000.0, &pacing, &stop, &progress,
                )?)
            }),
        ));
    }
    let motion = s.following(tracks);
    let stream = BusStream::new(ImuEmulator::new(motion, s.imu.clone()), &s.faults);
    let (iface, stop, progress, sent, tracks) = (
        o.iface.clone(),
        stop.clone(),
        progress.clone(),
        sent.clone(),
        tracks.to_vec(),
    );
    devices.push((
        "imu",
        Box::new(move |pacing: Pacing| {
            Ok(emulators::adapters::freerun::run_imu(
                &iface,
                stream,
                &tracks,
                Some(&sent),
                &pacing,
                &stop,
                &progress,
            )?)
        }),
    ));
}

/// The emulated table and IMU on the lab's contract (`lab`): the table by its opcodes and
/// states, the IMU in its frames riding the table as the lab's reports say.
fn lab_devices(
    s: &Scenario,
    o: &FreeOptions,
    lab: &Arc<listener::LabEar>,
    (tracks, sent, progress): (&[SharedTrack], &Arc<SentSamples>, &Arc<Progress>),
    stop: &Arc<AtomicBool>,
    devices: &mut Vec<(&'static str, DeviceRun)>,
) -> Result<()> {
    if let (Some(tp), false) = (&s.turntable, o.real_turntable) {
        // checked here, before anything runs
        crate::scenario::lab_contract::table_side(&lab.contract, &lab.mapping)?;
        let mut tt = TtBus::new(emulators::turntable::Turntable::new(tp.clone()), 1000.0);
        let (iface, stop, lab) = (o.iface.clone(), stop.clone(), lab.clone());
        devices.push((
            "turntable",
            Box::new(move |pacing: Pacing| {
                let (side, mut protector) =
                    crate::scenario::lab_contract::table_side(&lab.contract, &lab.mapping)?;
                Ok(emulators::adapters::fd::run_mapped_turntable(
                    &iface,
                    &mut tt,
                    &side,
                    &mut protector,
                    1000.0,
                    &pacing,
                    &stop,
                    &Progress::default(),
                )?)
            }),
        ));
    }
    if lab.mapping.file.imu.is_none() {
        bail!(
            "the mapping {}: no [imu]: the bench's IMU cannot speak the lab's contract",
            lab.path.display()
        );
    }
    let (s, iface, stop, lab) = (s.clone(), o.iface.clone(), stop.clone(), lab.clone());
    let (tracks, sent, progress) = (tracks.to_vec(), sent.clone(), progress.clone());
    devices.push((
        "imu",
        Box::new(move |pacing: Pacing| {
            let run = crate::scenario::lab_contract::imu_run(
                &s,
                (&lab.contract, &lab.mapping),
                tracks,
                Some(sent),
            )?;
            Ok(emulators::adapters::fd::run_mapped_imu(
                &iface, run, &pacing, &stop, &progress,
            )?)
        }),
    ));
    Ok(())
}

/// Start the prepared devices, sharing one origin a little ahead.
fn start_bench(s: &Scenario, o: &FreeOptions, p: Prepared) -> Result<Bench> {
    let Prepared {
        devices,
        progress,
        tracks,
        sent,
    } = p;
    // the threads first, each waiting for its pacing: their start is not the stream's
    let mut threads: Vec<(&'static str, JoinHandle<Result<FreeStats>>)> = Vec::new();
    let mut go = Vec::new();
    for (name, run) in devices {
        let (tx, rx) = std::sync::mpsc::channel::<Pacing>();
        let t = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || match rx.recv() {
                Ok(pacing) => run(pacing),
                Err(_) => bail!("the {name} emulator was never started"),
            })
            .with_context(|| format!("starting the {name} emulator"))?;
        threads.push((name, t));
        go.push(tx);
    }
    // the devices open their sockets within this margin
    let origin = Instant::now() + Duration::from_millis(200);
    let pacing = Pacing {
        origin,
        speed: 1.0,
        until_s: s.duration_s,
        max_late: Duration::from_secs_f64(o.max_late_ms * 1e-3),
        imu_write_period: emulators::adapters::freerun::IMU_WRITE_PERIOD,
    };
    for tx in go {
        // a thread that has already ended says why when it is joined
        let _ = tx.send(pacing);
    }
    Ok(Bench {
        threads,
        progress,
        tracks,
        sent,
        origin,
    })
}

/// Watch the run until it is over: the scenario's time, the drill's end as the device says
/// it, the device's death or silence, an emulator stopping (the host behind real time). Why
/// it ended.
fn supervise(
    s: &Scenario,
    o: &FreeOptions,
    bench: &Bench,
    seen: &Mutex<Observed>,
    mut child: Option<&mut Child>,
) -> String {
    let drill = is_drill(s);
    let mut over_at: Option<Instant> = None;
    let mut shown = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(50));
        let t = bench.origin.elapsed().as_secs_f64();
        // the IMU's stream is the run; a receiver ends up to a period before it (its last
        // epoch), any other device earlier only when it failed or fell behind
        for (name, h) in &bench.threads {
            let early = if *name == "imu" { 0.0 } else { 2.0 };
            if h.is_finished() {
                if t < s.duration_s - early {
                    return format!("the {name} emulator stopped at {t:.1} s");
                }
                if *name == "imu" {
                    return format!("the scenario's {} s are over", s.duration_s);
                }
            }
        }
        if let Some(c) = child.as_deref_mut()
            && let Ok(Some(st)) = c.try_wait()
        {
            return format!(
                "the device under test exited at {t:.1} s ({})",
                exit_words(st)
            );
        }
        let (answered, done) = {
            let g = seen.lock().unwrap_or_else(|e| e.into_inner());
            (!g.epochs.is_empty(), drill && score::drill_over(&g.epochs))
        };
        if !answered && t > o.answer_within_s {
            return format!(
                "the device under test sent no {} within {} s of the stream's start",
                verdict::Words::of(o).epoch,
                o.answer_within_s
            );
        }
        // the drill is over when the device has said its heading; a second more of its output
        if done && over_at.get_or_insert_with(Instant::now).elapsed() > Duration::from_secs(1) {
            return format!(
                "the drill ended at {t:.1} s (the device's heading after north-finding)"
            );
        }
        if o.progress && shown.elapsed() >= Duration::from_secs(1) {
            shown = Instant::now();
            let n = seen.lock().map_or(0, |g| g.epochs.len());
            crate::status::show(&format!(
                "free-running: {:.1} s of {:.0}, {n} solution epochs from the device",
                bench.progress.now(),
                s.duration_s
            ));
        }
    }
}

/// What the run left for judging.
pub(crate) struct Judged {
    pub(crate) device: String,
    pub(crate) device_exit: String,
    pub(crate) ended: String,
    pub(crate) wall_s: f64,
    pub(crate) stats: Vec<FreeStats>,
    pub(crate) tracks: Vec<SharedTrack>,
    pub(crate) host: probe::HostDelays,
}

/// The result card.
pub fn card(r: &FreeReport) -> String {
    let mut out = format!(
        " FREE-RUNNING {} on {}  {:.1} s at x1 (the host's clock); device: {}\n contract: {}\n",
        r.scenario, r.interface, r.wall_s, r.device, r.contract
    );
    for b in &r.bench {
        let l = &b.lateness;
        out += &format!(
            " bench {:<9} {} {}, its own lateness median {:.2} ms, p99 {:.2} ms, worst {:.1} ms{}\n",
            b.device,
            b.written,
            if b.device == "gps" { "bytes" } else { "frames" },
            l.p50_ms,
            l.p99_ms,
            l.max_ms,
            if b.behind.is_some() {
                " (fell behind)"
            } else {
                ""
            }
        );
        out += &followed_words(b);
    }
    for x in &r.real {
        out += &format!(" real     {x}\n");
    }
    out += &timing_lines(r);
    out += &format!(
        " output   {} epochs, {:.1} Hz by the host's clock, every {} samples, jitter {:.2} ms rms, longest gap {:.1} ms; {} turntable commands; {} bytes taken from the receiver\n",
        r.epochs,
        r.rate.hz,
        r.rate.step_samples,
        r.rate.jitter_rms_ms,
        r.rate.max_interval_ms,
        r.commands,
        r.receiver_bytes
    );
    for c in &r.checks {
        out += &format!(
            " [{}] {:<58} {}\n",
            if c.pass { "PASS" } else { "FAIL" },
            c.name,
            c.detail
        );
    }
    for n in &r.not_judged {
        out += &format!(" [NOT JUDGED] {n}\n");
    }
    match &r.bench_behind {
        Some(why) => out += &format!(" RESULT: NO VERDICT: {why}\n"),
        None => out += &format!(" RESULT: {}\n", if r.pass { "PASS" } else { "FAIL" }),
    }
    out
}

/// What the bench's IMU made of the table it rides and whether the motion stayed within its
/// range: a line of the card, empty where there is nothing to say.
fn followed_words(b: &FreeStats) -> String {
    let mut out = String::new();
    for (axis, f) in b.followed.iter().enumerate() {
        out += &format!(
            "          its truth followed the table's axis {axis}: {} reports, {} later than the delay, {} closer together than the table turns (spread at its fastest), {} left out for the encoder fault\n",
            f.reports, f.late, f.bunched, f.encoder_faults
        );
    }
    if let Some(n) = b
        .imu
        .as_ref()
        .map(|i| i.over_range_samples)
        .filter(|n| *n > 0)
    {
        out += &format!(
            "          {n} samples went beyond the IMU's range (clamped, flagged saturated)\n"
        );
    }
    out
}

/// The card's lines on time: the host's delays, where the times come from, the device's clock,
/// its data's age.
fn timing_lines(r: &FreeReport) -> String {
    let mut out = String::new();
    out += &format!(
        " host     a thread beside the device woke late by median {:.2} ms, p99 {:.2} ms, worst {:.1} ms ({} wake-ups every {} ms)\n",
        r.host.p50_ms,
        r.host.p99_ms,
        r.host.max_ms,
        r.host.count,
        probe::PERIOD.as_millis()
    );
    out += &format!(
        " times    {}{}\n",
        r.stamps,
        if r.reordered > 0 {
            format!(
                "; {} frames heard out of their stamps' order, put back in it",
                r.reordered
            )
        } else {
            String::new()
        }
    );
    match &r.clock {
        Some(c) => {
            out += &format!(
                " clock    latency {} at the start, {} at the end ({:.0} s): the device's clock {} against the IMU's; line residual RMS {:.2} ms, worst {:.1} ms, over {} epochs\n",
                c.start_ms.words(2, "ms"),
                c.end_ms.words(2, "ms"),
                c.span_s,
                c.drift_ppm.words(1, "ppm"),
                c.residual_rms_ms,
                c.residual_max_ms,
                c.epochs
            )
        }
        None => {
            out += " clock    not estimated: fewer than 30 epochs named a sample the bench placed\n"
        }
    }
    if let Some(d) = &r.data_offset {
        out += &format!(
            " data     its headings are {} older than their tags over {} turns ({} epochs){}: {}\n",
            d.offset_ms.words(1, "ms"),
            d.turns.len(),
            d.epochs,
            d.drift_ppm.map_or(String::new(), |x| format!(
                ", drifting {}",
                x.words(0, "ppm")
            )),
            d.turns
                .iter()
                .map(|t| format!("{:.1} s {}", t.t_s, t.offset_ms.words(1, "ms")))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    out
}
