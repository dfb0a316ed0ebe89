//! `hil emulate imu|turntable|gps`: one emulated device on its own, free-running on the host's
//! clock (`emulators::adapters::freerun`), until stopped: a stand-in for the hardware for anybody's
//! device under test.

use anyhow::{Context, Result, bail};
use emulators::adapters::freerun::{FreeStats, Pacing};
use emulators::adapters::pty::{GpsPty, relink};
use emulators::adapters::transport::{BusStream, Progress};
use emulators::gps::GpsReceiver;
use emulators::imu::ImuEmulator;
use emulators::reported::SharedTrack;
use emulators::turntable::ttbus::TtBus;
use hil::scenario::Scenario;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// The device to emulate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Device {
    /// The RLG/accelerometer unit: IMU_GYRO/IMU_ACCEL frames at the scenario's rate on --iface.
    Imu,
    /// The indexing mechanism's controller: answers TT_CMD with TT_ACK and reports TT_STATUS
    /// at its status rate on --iface.
    Turntable,
    /// The NMEA receiver: its sentences at each epoch on a pty, behind the link --link.
    Gps,
}

/// `hil emulate`'s arguments.
#[derive(clap::Args)]
pub(crate) struct EmulateArgs {
    /// The device.
    #[arg(value_enum)]
    device: Device,
    /// Scenario whose models the device takes (its [imu], [turntable], [gps] and [drive], its
    /// site and seed). Default for imu and turntable: the main job's drill (28.218157 N,
    /// heading 30 deg, seed 1); the receiver needs a scenario with [drive] and [gps]
    /// (scenarios/drive-gps.toml).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// CAN interface (imu, turntable): a vcan interface is created when missing; a real one
    /// (can0) must be up.
    #[arg(long, default_value = "vcan0")]
    iface: String,
    /// The receiver's device (gps): a link made to its pty, as a USB receiver sits behind
    /// /dev/serial/by-id; removed when it stops.
    #[arg(long, default_value = "/tmp/hil-gps")]
    link: PathBuf,
    /// The IMU sits on a table the bench does not model (a real one, or `hil emulate turntable`
    /// in another process): its gyros turn as the table's TT_STATUS on --iface reports.
    #[arg(long)]
    follow_turntable: bool,
    /// With --follow-turntable: how far the IMU's truth follows behind the table's reports,
    /// s (two status periods by default: each move is felt whole, this much later).
    #[arg(long, value_parser = hil::values::pause_s, default_value_t = 0.02)]
    follow_delay: f64,
    /// Simulated time to run, s (default: until SIGINT or SIGTERM).
    #[arg(long, value_parser = hil::values::duration_s)]
    duration: Option<f64>,
    /// Speed over real time (free-running devices run at 1, as hardware does).
    #[arg(long, value_parser = hil::values::speed, default_value_t = 1.0)]
    speed: f64,
    /// Simulated time 0 at this UNIX time, s: devices started apart (an IMU and a receiver
    /// riding the same drive) share one clock. Default: now.
    #[arg(long)]
    t0: Option<f64>,
    /// The bench's own lateness beyond which the device stops (the host cannot keep real
    /// time), ms.
    #[arg(long, default_value_t = 200.0)]
    max_late_ms: f64,
    /// The IMU's frames go out in one write per this period, ms (two samples of a 2 kHz IMU at
    /// 1 ms); 0: each sample's at its own time. Each write and each wake-up of a reader costs
    /// tens of microseconds in an emulated guest.
    #[arg(long, default_value_t = 1.0)]
    imu_write_ms: f64,
    /// Write what the device did as JSON here when it stops.
    #[arg(long)]
    report: Option<PathBuf>,
    /// imu, turntable: speak a lab's own contract instead of ours: its mapping file, with the
    /// DBC it names beside it (docs/your-dbc.md): the mapped frames (29-bit identifiers, CAN
    /// FD where the DBC says so, counters, alive counters and checksums; the IMU at the
    /// mapping's rate, the table by the lab's opcodes and states); the interface is given CAN
    /// FD's MTU.
    #[arg(long)]
    mapping: Option<PathBuf>,
    /// Also write the nav.toml our nav takes with this scenario's devices on --iface (and the
    /// receiver at --link), with the parameter files it loads beside it.
    #[arg(long)]
    nav_config: Option<PathBuf>,
}

/// Run one device until it is stopped (exit 0), or until the host cannot keep real time
/// (exit 3).
pub(crate) fn emulate(a: EmulateArgs) -> Result<i32> {
    let s = match &a.scenario {
        Some(p) => Scenario::load(p)?,
        None if a.device == Device::Gps => bail!(
            "hil emulate gps needs --scenario with [drive] and [gps] (e.g. scenarios/drive-gps.toml)"
        ),
        None => hil::procedures::northfinding::scenario(30.0, 28.218157, 60.0, 1),
    };
    if !(0.0..=100.0).contains(&a.imu_write_ms) {
        bail!("--imu-write-ms {}: between 0 and 100", a.imu_write_ms);
    }
    if !(0.0..=10_000.0).contains(&a.max_late_ms) {
        bail!("--max-late-ms {}: between 0 and 10000", a.max_late_ms);
    }
    if let Some(p) = &a.nav_config {
        let gps = (a.device == Device::Gps || s.gps.is_some()).then_some(a.link.as_path());
        hil::scenario::navconfig::write_nav_config(&s, Some(&a.iface), gps, p)?;
        eprintln!("emulate: nav's config for {} in {}", s.name, p.display());
    }
    let pacing = Pacing {
        origin: origin(a.t0)?,
        speed: a.speed,
        until_s: a.duration.unwrap_or(f64::INFINITY),
        max_late: Duration::from_secs_f64(a.max_late_ms * 1e-3),
        imu_write_period: Duration::from_secs_f64(a.imu_write_ms * 1e-3),
    };
    let stop = Arc::new(AtomicBool::new(false));
    stop_on_signals(stop.clone())?;
    let progress = Arc::new(Progress::default());
    let device = a.device;
    let label = match device {
        Device::Gps => format!("gps on {}", a.link.display()),
        d => format!("{d:?} on {}", a.iface).to_lowercase(),
    };
    let t0_given = a.t0.is_some();
    let lab = match (&a.mapping, device) {
        (Some(m), Device::Imu | Device::Turntable) => Some(hil::scenario::lab_contract::load(m)?),
        (Some(_), d) => {
            bail!("--mapping: the imu and the turntable speak a lab's contract, not {d:?}")
        }
        (None, _) => None,
    };
    let runner = {
        let (stop, progress) = (stop.clone(), progress.clone());
        let s = s.clone();
        let (iface, link) = (a.iface.clone(), a.link.clone());
        let follow = a.follow_turntable.then_some(a.follow_delay);
        std::thread::Builder::new()
            .name("device".into())
            .spawn(move || -> Result<FreeStats> {
                match device {
                    Device::Imu if lab.is_some() => {
                        let (c, m) = lab.as_ref().context("the lab's contract")?;
                        mapped_imu(&s, &iface, (c, m), (&pacing, t0_given), &stop, &progress)
                    }
                    Device::Imu => imu(&s, &iface, follow, &pacing, &stop, &progress),
                    Device::Turntable if lab.is_some() => {
                        let (c, m) = lab.as_ref().context("the lab's contract")?;
                        mapped_turntable(&s, &iface, (c, m), &pacing, &stop, &progress)
                    }
                    Device::Turntable => turntable(&s, &iface, &pacing, &stop, &progress),
                    Device::Gps => gps(&s, &link, &pacing, &stop, &progress),
                }
            })
            .context("starting the device's thread")?
    };
    eprintln!(
        "emulate: {label}, free-running at x{} from {} ({}); stop with Ctrl-C or SIGTERM",
        a.speed,
        s.name,
        a.duration
            .map_or("until stopped".into(), |d| format!("for {d} s")),
    );
    let mut shown = Instant::now();
    while !runner.is_finished() {
        std::thread::sleep(Duration::from_millis(100));
        if shown.elapsed() >= Duration::from_secs(10) {
            hil::status::show(&format!("emulate: {label}: {:.1} s", progress.now()));
            shown = Instant::now();
        }
    }
    let st = runner
        .join()
        .map_err(|_| anyhow::anyhow!("the device's thread panicked"))??;
    println!("{}", card(&st));
    if let Some(p) = &a.report {
        std::fs::write(p, serde_json::to_string_pretty(&st)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(if st.behind.is_some() { 3 } else { 0 })
}

/// The host instant of simulated time 0: UNIX time `t0`, or now.
fn origin(t0: Option<f64>) -> Result<Instant> {
    let now = Instant::now();
    let Some(t0) = t0 else { return Ok(now) };
    if !t0.is_finite() || t0 < 0.0 {
        bail!("--t0 {t0}: a UNIX time, s");
    }
    let unix_now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .context("the host's clock is before 1970")?
        .as_secs_f64();
    let ahead = t0 - unix_now;
    if ahead.abs() > 3600.0 {
        bail!("--t0 {t0}: {ahead:.0} s from now; give a time within the hour");
    }
    let d = Duration::from_secs_f64(ahead.abs());
    Ok(if ahead >= 0.0 {
        now + d
    } else {
        now.checked_sub(d)
            .context("--t0: too far back for this host's clock")?
    })
}

/// Set `stop` on SIGINT or SIGTERM.
pub(crate) fn stop_on_signals(stop: Arc<AtomicBool>) -> Result<()> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("the signal handler's runtime")?;
    let (ready_tx, ready) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        rt.block_on(async move {
            use tokio::signal::unix::{SignalKind, signal};
            let (Ok(mut int), Ok(mut term)) = (
                signal(SignalKind::interrupt()),
                signal(SignalKind::terminate()),
            ) else {
                let _ = ready_tx.send(false);
                return;
            };
            let _ = ready_tx.send(true);
            tokio::select! {
                _ = int.recv() => {}
                _ = term.recv() => {}
            }
            stop.store(true, Ordering::Relaxed);
        })
    });
    if !ready.recv().unwrap_or(false) {
        bail!("cannot install the SIGINT/SIGTERM handlers");
    }
    Ok(())
}

/// The IMU of `s` on `iface`; following the table's reports `follow` s behind, when given.
fn imu(
    s: &Scenario,
    iface: &str,
    follow: Option<f64>,
    p: &Pacing,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<FreeStats> {
    vcan_setup::ensure_vcan(iface)?;
    let axes = s.turntable.as_ref().map_or(1, |t| usize::from(t.axes));
    let tracks: Vec<SharedTrack> = match follow {
        Some(delay) => (0..axes).map(|_| s.reported_track(delay)).collect(),
        None => Vec::new(),
    };
    let motion = if follow.is_some() {
        // a scenario without [turntable] still has one azimuth axis to follow
        let mut on_table = s.clone();
        on_table.turntable.get_or_insert_with(Default::default);
        on_table.following(&tracks)
    } else {
        if s.turntable.is_some() {
            tracing::warn!(
                "the scenario has a turntable but nothing turns it here: the IMU stays at the table's zero (--follow-turntable to turn with a table on {iface})"
            );
        }
        s.motion()
    };
    let stream = BusStream::new(ImuEmulator::new(motion, s.imu.clone()), &s.faults);
    Ok(emulators::adapters::freerun::run_imu(
        iface, stream, &tracks, None, p, stop, progress,
    )?)
}

/// The IMU of `s` speaking the lab's contract `c` through its mapping `m` on `iface` (at the
/// mapping's rate; the table, if any, stays at its zero).
/// Without `--t0` (`t0_given` false), time 0 is when the interface and the unit are ready.
fn mapped_imu(
    s: &Scenario,
    iface: &str,
    (c, m): (&wire::dbc::Contract, &wire::mapping::Mapping),
    (p, t0_given): (&Pacing, bool),
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<FreeStats> {
    vcan_setup::ensure_vcan_fd(iface)?;
    let run = hil::scenario::lab_contract::imu_run(s, (c, m), Vec::new(), None)?;
    let p = &Pacing {
        origin: if t0_given { p.origin } else { Instant::now() },
        ..*p
    };
    Ok(emulators::adapters::fd::run_mapped_imu(
        iface, run, p, stop, progress,
    )?)
}

/// The turntable of `s` on the lab's contract `c` through its mapping `m` on `iface`, its
/// controller's loop at 1 kHz.
fn mapped_turntable(
    s: &Scenario,
    iface: &str,
    (c, m): (&wire::dbc::Contract, &wire::mapping::Mapping),
    p: &Pacing,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<FreeStats> {
    vcan_setup::ensure_vcan_fd(iface)?;
    let Some(tp) = &s.turntable else {
        bail!("scenario {} has no [turntable]", s.name);
    };
    let (side, mut protector) = hil::scenario::lab_contract::table_side(c, m)?;
    let tick_hz = 1000.0;
    let mut tt = TtBus::new(emulators::turntable::Turntable::new(tp.clone()), tick_hz);
    Ok(emulators::adapters::fd::run_mapped_turntable(
        iface,
        &mut tt,
        &side,
        &mut protector,
        tick_hz,
        p,
        stop,
        progress,
    )?)
}

/// The turntable of `s` on `iface`, its controller's loop at 1 kHz.
fn turntable(
    s: &Scenario,
    iface: &str,
    p: &Pacing,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<FreeStats> {
    vcan_setup::ensure_vcan(iface)?;
    let Some(tp) = &s.turntable else {
        bail!("scenario {} has no [turntable]", s.name);
    };
    let tick_hz = 1000.0;
    let mut tt = TtBus::new(emulators::turntable::Turntable::new(tp.clone()), tick_hz);
    Ok(emulators::adapters::freerun::run_turntable(
        iface, &mut tt, tick_hz, p, stop, progress,
    )?)
}

/// The receiver of `s` on a pty behind `link`.
fn gps(
    s: &Scenario,
    link: &std::path::Path,
    p: &Pacing,
    stop: &AtomicBool,
    progress: &Progress,
) -> Result<FreeStats> {
    let Some(rx) = &s.gps else {
        bail!("scenario {} has no [gps] receiver", s.name);
    };
    let Some(run) = hil::engine::inproc::gps_run(s, rx)? else {
        bail!(
            "scenario {} has no [drive]: the receiver needs the trajectory its antenna rides",
            s.name
        );
    };
    let mut pty = GpsPty::open().context("GPS emulator")?;
    relink(link, pty.path()).context("GPS emulator")?;
    let mut receiver = GpsReceiver::new(run);
    let r = emulators::adapters::freerun::run_gps(&mut pty, &mut receiver, p, stop, progress);
    let _ = std::fs::remove_file(link);
    Ok(r?)
}

/// What the device did, for people.
fn card(st: &FreeStats) -> String {
    let l = &st.lateness;
    let mut out = format!(
        " EMULATED {} on {}  {:.1} s simulated in {:.1} s wall (x{} asked), {} {} written\n the bench's lateness: median {:.2} ms, p99 {:.2} ms, worst {:.2} ms; {} of {} writes more than 1 ms late",
        st.device,
        st.port,
        st.reached_s.max(0.0),
        st.wall_s,
        st.speed,
        st.written,
        if st.device == "gps" {
            "bytes"
        } else {
            "frames"
        },
        l.p50_ms,
        l.p99_ms,
        l.max_ms,
        l.over_1ms,
        l.count,
    );
    if let Some(t) = &st.turntable {
        out += &format!(
            "\n commands {}, acknowledged {}, status frames {}, frames not a command {}",
            t.commands, t.acks, t.status_frames, t.bad_frames
        );
    }
    for (axis, f) in st.followed.iter().enumerate() {
        out += &format!(
            "\n followed the table's axis {axis}: {} reports taken, {} later than the delay, {} closer together than the table turns (spread at its fastest), {} with the encoder fault left out",
            f.reports, f.late, f.bunched, f.encoder_faults
        );
    }
    if let Some(g) = &st.gps {
        out += &format!(
            "\n epochs written {}, nobody reading {}, reader behind {}, silent (outages) {}",
            g.epochs, g.no_reader, g.reader_behind, g.silent
        );
    }
    match &st.behind {
        Some(why) => out += &format!("\n STOPPED: {why}"),
        None => out += "\n kept real time",
    }
    out
}
