//! `hil replay --bus`: a recording's traffic back onto vcan and a pty, with the `nav` binary
//! (this build, or another given with `--nav`) running on it as on a vehicle, and its new
//! solution compared with the recorded one.
//!
//! What goes back is what nav received, in the order its loop took it: the frames of `/can/raw`
//! (IMU and turntable), the bytes of `/gps/raw` (the receiver's port), and a silence wherever
//! nav's liveness watchdog fired (`/nav/event` `imu_timeout`), so it fires at the same place.
//! The player ([`emulators::adapters::player`]) paces them on the IMU clock at the speed asked and in
//! lockstep with nav's NAV_TIME frames, as the bench runs its emulators; the turntable's
//! answers come from the recording (nav's commands go on the bus and are not answered again).
//! nav's frames of the new run (`/can/tx`) are compared with the recorded ones: identical bit
//! for bit for the same build. For another build, the solutions are compared at the same IMU
//! times.

use crate::run::{NavFolder, RemoveOnDrop, start_nav, stop_nav};
use anyhow::{Context, Result, bail};
use emulators::adapters::player::{PlayOptions, PlayStats, Recorded};
use emulators::adapters::pty::{GpsPty, relink};
use nav::config::{GpsSource, NavConfig};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use wire::RawFrame;

/// Options of a replay onto the bus.
#[derive(Debug, Clone)]
pub struct BusReplayOptions {
    /// CAN interface (created when missing).
    pub iface: String,
    /// Output folder of the new run.
    pub out: PathBuf,
    /// The `nav` binary.
    pub nav_bin: PathBuf,
    /// Speed factor over real time.
    pub speed: f64,
    /// Print progress.
    pub progress: bool,
}

/// What a recording holds for a replay onto the bus.
pub struct Recording {
    /// What nav received, in its order.
    pub items: Vec<Recorded>,
    /// What nav sent.
    pub sent: Vec<RawFrame>,
    /// nav's solutions (`/nav/solution`): IMU time ns -> the JSON.
    pub solutions: Vec<(u64, serde_json::Value)>,
    /// Decoded fixes recorded (`/gps/fix`).
    pub fixes: u64,
    /// Records that could not be read.
    pub bad_records: u64,
    /// The recording was cut short (nav killed).
    pub cut: bool,
}

impl Recording {
    /// Read nav's recording `mcap` (all its parts), what nav received in the order it arrived
    /// ([`in_arrival_order`]).
    pub fn read(mcap: &Path) -> Result<Self> {
        let (mut r, times) = Self::read_timed(mcap)?;
        r.items = in_arrival_order(std::mem::take(&mut r.items), &times);
        Ok(r)
    }

    /// Read nav's recording `mcap` (all its parts), everything where nav's loop took it, with
    /// each item's log time (none for a silence).
    fn read_timed(mcap: &Path) -> Result<(Self, Vec<Option<u64>>)> {
        let mut times = Vec::new();
        let mut r = Recording {
            items: Vec::new(),
            sent: Vec::new(),
            solutions: Vec::new(),
            fixes: 0,
            bad_records: 0,
            cut: false,
        };
        r.cut = crate::engine::recording::each_message(mcap, "replaying", |m| {
            let frame = || nav::record::raw::frame_of(m);
            match m.channel.topic.as_str() {
                "/can/raw" => match frame() {
                    Some(f) => {
                        r.items.push(Recorded::Frame(f));
                        times.push(Some(m.log_time));
                    }
                    None => r.bad_records += 1,
                },
                "/can/tx" => match frame() {
                    Some(f) => r.sent.push(f),
                    None => r.bad_records += 1,
                },
                "/gps/raw" => match nav::record::raw::serial_of(m) {
                    Some(b) => {
                        r.items.push(Recorded::Gps(b.to_vec()));
                        times.push(Some(m.log_time));
                    }
                    None => r.bad_records += 1,
                },
                "/gps/fix" => r.fixes += 1,
                "/nav/event" => match serde_json::from_slice::<serde_json::Value>(&m.data) {
                    Ok(e) if e["kind"] == "imu_timeout" => {
                        r.items.push(Recorded::Silence);
                        times.push(None);
                    }
                    Ok(_) => {}
                    Err(_) => r.bad_records += 1,
                },
                "/nav/solution" => match serde_json::from_slice(&m.data) {
                    Ok(v) => r.solutions.push((m.publish_time, v)),
                    Err(_) => r.bad_records += 1,
                },
                _ => {}
            }
        })?;
        Ok((r, times))
    }

    /// GPS bytes in the recording.
    pub fn has_gps_bytes(&self) -> bool {
        self.items.iter().any(|i| matches!(i, Recorded::Gps(_)))
    }
}

/// `items` (as nav's loop took them, with their log times: a frame's kernel receive time, the
/// time nav's reader read the GPS bytes, none for a silence) in the order they arrived. nav's
/// loop takes GPS bytes when it gets to them, later than they came by however far it was behind
/// on the bus; replayed where the loop took them, a fix came later on every replay of a replay,
/// until past the time nav applies it. So each GPS read goes back among the frames by its time:
/// after every frame that arrived before it, ties included. The frames keep their order, a
/// silence stays after the frame it followed, and the GPS reads keep theirs.
pub fn in_arrival_order(items: Vec<Recorded>, times: &[Option<u64>]) -> Vec<Recorded> {
    let (mut gps, mut rest) = (Vec::new(), Vec::with_capacity(items.len()));
    let (mut last_gps, mut last) = (0u64, 0u64);
    for (item, t) in items.into_iter().zip(times.iter().copied()) {
        if matches!(item, Recorded::Gps(_)) {
            last_gps = last_gps.max(t.unwrap_or(last_gps));
            gps.push((last_gps, item));
        } else {
            last = t.unwrap_or(last);
            rest.push((last, item));
        }
    }
    let mut out = Vec::with_capacity(rest.len() + gps.len());
    let mut gps = gps.into_iter().peekable();
    for (t, item) in rest {
        while let Some(g) = gps.next_if(|g| g.0 < t) {
            out.push(g.1);
        }
        out.push(item);
    }
    out.extend(gps.map(|g| g.1));
    out
}

/// How far two solutions at the same IMU times lie apart.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct SolutionDifference {
    /// Solutions at the same IMU time in both.
    pub compared: u64,
    /// Largest horizontal position difference, m.
    pub max_horizontal_m: f64,
    /// Largest heading difference, deg.
    pub max_heading_deg: f64,
    /// Largest velocity difference (norm), m/s.
    pub max_velocity_mps: f64,
}

/// Compare two runs' `/nav/solution` records at the same IMU times.
pub fn compare_solutions(
    a: &[(u64, serde_json::Value)],
    b: &[(u64, serde_json::Value)],
) -> SolutionDifference {
    let by_time: std::collections::HashMap<u64, &serde_json::Value> =
        b.iter().map(|(t, v)| (*t, v)).collect();
    let mut d = SolutionDifference::default();
    let num = |v: &serde_json::Value, k: &str| v[k].as_f64();
    for (t, x) in a {
        let Some(y) = by_time.get(t) else { continue };
        d.compared += 1;
        if let (Some(la), Some(oa), Some(lb), Some(ob)) = (
            num(x, "lat_deg"),
            num(x, "lon_deg"),
            num(y, "lat_deg"),
            num(y, "lon_deg"),
        ) {
            // a local plane is plenty for differences of metres
            let (rm, rn) = emulators::geodesy::radii(la.to_radians());
            let dn = (lb - la).to_radians() * rm;
            let de = (ob - oa).to_radians() * rn * la.to_radians().cos();
            d.max_horizontal_m = d.max_horizontal_m.max(dn.hypot(de));
        }
        let heading = |v: &serde_json::Value| v["hpr_deg"][0].as_f64();
        if let (Some(ha), Some(hb)) = (heading(x), heading(y)) {
            let dh = (hb - ha + 540.0).rem_euclid(360.0) - 180.0;
            d.max_heading_deg = d.max_heading_deg.max(dh.abs());
        }
        if let (Some(va), Some(vb)) = (x["vel_enu_mps"].as_array(), y["vel_enu_mps"].as_array()) {
            let dv: f64 = va
                .iter()
                .zip(vb)
                .filter_map(|(p, q)| Some((q.as_f64()? - p.as_f64()?).powi(2)))
                .sum();
            d.max_velocity_mps = d.max_velocity_mps.max(dv.sqrt());
        }
    }
    d
}

/// The outcome of a replay onto the bus.
#[derive(Debug, Clone, Serialize)]
pub struct BusReplay {
    /// The recording replayed.
    pub recording: String,
    /// The new run's folder.
    pub out: String,
    /// What the player put on the bus and the port.
    pub play: PlayStats,
    /// Frames nav sent in the recording.
    pub recorded_tx: u64,
    /// Frames nav sent on the replay.
    pub replayed_tx: u64,
    /// The first frame at which the two differ (index, recorded, replayed), if any.
    pub first_difference: crate::engine::recording::Difference,
    /// The solutions compared at the same IMU times.
    pub solutions: SolutionDifference,
    /// Records of the recording that could not be read.
    pub bad_records: u64,
    /// nav's exit status.
    pub nav_exit: Option<i32>,
    /// Wall time of the replay, s.
    pub wall_s: f64,
    /// The new run's summary.
    pub summary: nav::summary::Summary,
}

impl BusReplay {
    /// nav sent exactly what it sent in the recording.
    pub fn identical(&self) -> bool {
        self.first_difference.is_none() && self.recorded_tx == self.replayed_tx
    }

    /// For people.
    pub fn text(&self) -> String {
        let p = &self.play;
        let mut s = format!(
            "put back {} frames ({} IMU samples) and {} GPS bytes in {} writes, {} silences, in {:.1} s (lockstep: {} waits, {} stalls{})\n",
            p.frames,
            p.samples,
            p.gps_bytes,
            p.gps_writes,
            p.silences,
            self.wall_s,
            p.lockstep.waits,
            p.lockstep.stalls,
            crate::report::starved_text(p.lockstep.starved)
        );
        s += &format!(
            "nav sent {} frames in the recording, {} on the replay: {}\n",
            self.recorded_tx,
            self.replayed_tx,
            crate::engine::recording::verdict(&self.first_difference)
        );
        let d = &self.solutions;
        s += &format!(
            "solutions at the same IMU time: {} compared; largest differences {:.3} m, {:.4} deg heading, {:.3} m/s\n",
            d.compared, d.max_horizontal_m, d.max_heading_deg, d.max_velocity_mps
        );
        s += &format!("the new run: {}\n", self.out);
        s
    }
}

/// Replay nav's recording `mcap` (made with config `cfg`) onto the bus with the nav binary of
/// `opts`. The kernel must have CAN.
pub fn replay_on_bus(mcap: &Path, cfg: &NavConfig, opts: &BusReplayOptions) -> Result<BusReplay> {
    let start = Instant::now();
    let rec = Recording::read(mcap)?;
    if rec.items.is_empty() {
        bail!("{}: nothing nav received is recorded", mcap.display());
    }
    let gps = cfg.gps.is_some() && rec.has_gps_bytes();
    if cfg.gps.is_some() && !gps && rec.fixes > 0 {
        tracing::warn!(
            "{}: {} fixes but no /gps/raw (recorded before nav kept its GPS bytes): the GPS is not replayed and the solutions will differ",
            mcap.display(),
            rec.fixes
        );
    }
    if rec.cut {
        tracing::warn!(
            "{}: the recording is cut short (nav killed): replaying what it has",
            mcap.display()
        );
    }
    std::fs::create_dir_all(&opts.out)
        .with_context(|| format!("creating {}", opts.out.display()))?;
    vcan_setup::ensure_vcan(&opts.iface)?;
    let account = crate::run::nav_account();
    let mut pty = if gps {
        let pty = GpsPty::open().context("the GPS port for the replay")?;
        if let Some((uid, gid)) = account {
            pty.give_to(uid, gid)?;
        }
        Some(pty)
    } else {
        None
    };
    let link = std::env::temp_dir().join(format!("hil-replay-gps-{}", std::process::id()));
    if let Some(p) = &pty {
        relink(&link, p.path())?;
    }
    let _link_guard = RemoveOnDrop(link.clone());
    let mut folder = NavFolder::new(&opts.out, account)?;
    let c = replay_config(cfg, opts, gps, &link)?;
    let cfg_path = folder.dir.join("nav.toml");
    std::fs::write(&cfg_path, c.to_toml())
        .with_context(|| format!("writing {}", cfg_path.display()))?;
    let nav = start_nav(&opts.nav_bin, &cfg_path, account)?;
    let items = rec.items.len();
    let play_opts = PlayOptions {
        speed: opts.speed,
        imu_rate_hz: cfg.imu.rate_hz,
        // well past nav's watchdog, so that it fires where it fired
        silence: Duration::from_millis(cfg.watchdog.imu_timeout_ms * 3 + 100),
        lockstep: Some(emulators::adapters::scheduler::Lockstep::at_rate(
            cfg.imu.rate_hz,
        )),
    };
    let played = play_showing_progress(&rec.items, pty.as_mut(), opts, &play_opts, cfg.imu.rate_hz);
    crate::status::finish();
    // nav takes what is still in its socket when told to stop
    let (nav_exit, lines) = stop_nav(nav)?;
    folder.finish()?;
    let play = match played {
        Ok(r) => r.with_context(|| format!("replaying {items} records onto {}", opts.iface))?,
        Err(_) => bail!("the player panicked"),
    };
    for l in &lines {
        if opts.progress {
            crate::status::line(l);
        }
    }
    let summary =
        nav::summary::Summary::read(&opts.out.join("nav-summary.json")).with_context(|| {
            format!(
                "nav wrote no summary; exit status {}",
                crate::check::exit_words(nav_exit)
            )
        })?;
    let (new, _) = Recording::read_timed(&opts.out.join("nav.mcap"))?;
    Ok(BusReplay {
        recording: mcap.display().to_string(),
        out: opts.out.display().to_string(),
        play,
        recorded_tx: rec.sent.len() as u64,
        replayed_tx: new.sent.len() as u64,
        first_difference: crate::engine::recording::first_difference(&rec.sent, &new.sent),
        solutions: compare_solutions(&rec.solutions, &new.solutions),
        bad_records: rec.bad_records,
        nav_exit,
        wall_s: start.elapsed().as_secs_f64(),
        summary,
    })
}

/// nav's config for the replay: the recording's, on the replay's interface, the receiver (when
/// replayed) on the port behind `link`, recording into its own folder.
fn replay_config(
    cfg: &NavConfig,
    opts: &BusReplayOptions,
    gps: bool,
    link: &Path,
) -> Result<NavConfig> {
    let mut c = cfg.clone();
    if let Some(can) = c.can.as_mut() {
        can.interface = opts.iface.clone();
    } else {
        bail!("the recording's config has no [can] table: nav did not listen to a bus");
    }
    c.gps = if gps {
        cfg.gps.clone().map(|mut g| {
            g.source = GpsSource::Serial;
            g.port = link.to_path_buf();
            g.fixes_jsonl = g.fixes_jsonl.as_ref().map(|_| "gps-fixes.jsonl".into());
            g
        })
    } else {
        None
    };
    c.record.mcap = Some("nav.mcap".into());
    c.record.summary = Some("nav-summary.json".into());
    Ok(c)
}

/// Play the recorded `items` onto the bus (and the receiver's bytes onto `pty`), showing the
/// IMU time reached while it plays.
fn play_showing_progress(
    items: &[Recorded],
    pty: Option<&mut GpsPty>,
    opts: &BusReplayOptions,
    play_opts: &PlayOptions,
    imu_rate_hz: f64,
) -> std::thread::Result<Result<PlayStats, emulators::adapters::scheduler::BusError>> {
    let progress = emulators::adapters::transport::Progress::default();
    let stop = AtomicBool::new(false);
    let duration_s = items
        .iter()
        .filter(|i| matches!(i, Recorded::Frame(f) if f.id == wire::imu_gyro::SPEC.id))
        .count() as f64
        / imu_rate_hz;
    std::thread::scope(|sc| {
        let (done_tx, done) = std::sync::mpsc::channel::<()>();
        let player = sc.spawn(|| {
            let r = emulators::adapters::player::play(
                &opts.iface,
                items.iter().cloned(),
                pty,
                play_opts,
                &stop,
                &progress,
            );
            drop(done_tx);
            r
        });
        // nav is told to stop as soon as the last frame is out: a pause longer than its
        // watchdog would add a timeout the recording does not have
        while let Err(std::sync::mpsc::RecvTimeoutError::Timeout) =
            done.recv_timeout(Duration::from_millis(200))
        {
            if opts.progress {
                let t = progress.now();
                crate::status::show(&format!(
                    "{} replay {t:.1} / {duration_s:.1} s of IMU time",
                    crate::status::bar_of(t / duration_s.max(1e-9), 30)
                ));
            }
        }
        player.join()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u16) -> Recorded {
        Recorded::Frame(RawFrame {
            id,
            len: 1,
            data: [0; 8],
        })
    }

    fn gps(b: &str) -> Recorded {
        Recorded::Gps(b.as_bytes().to_vec())
    }

    /// GPS reads that nav's loop took late go back among the frames by their read time (after
    /// frames that arrived at the same time); one taken early stays behind frames that arrived
    /// before it; frames keep their order and a silence stays after the frame it followed.
    #[test]
    fn gps_reads_go_back_among_the_frames_by_their_arrival() {
        let items = vec![
            frame(1),
            frame(2),
            frame(3),
            gps("a"),
            Recorded::Silence,
            frame(4),
            gps("b"),
            frame(5),
            frame(6),
        ];
        let times = [
            Some(10),
            Some(20),
            Some(30),
            Some(15),
            None,
            Some(40),
            Some(40),
            Some(50),
            Some(60),
        ];
        let out = in_arrival_order(items, &times);
        assert_eq!(
            out,
            vec![
                frame(1),
                gps("a"),
                frame(2),
                frame(3),
                Recorded::Silence,
                frame(4),
                gps("b"),
                frame(5),
                frame(6),
            ]
        );
        // read after everything: at the end, in their order
        let late = in_arrival_order(
            vec![gps("x"), frame(1), gps("y")],
            &[Some(99), Some(1), Some(99)],
        );
        assert_eq!(late, vec![frame(1), gps("x"), gps("y")]);
    }

    /// Two solutions apart by a known amount at one shared IMU time; others unmatched.
    #[test]
    fn solutions_compare_at_the_same_imu_time() {
        let s = |lat: f64, h: f64| {
            serde_json::json!({"lat_deg": lat, "lon_deg": 10.0, "hpr_deg": [h, 0.0, 0.0],
                "vel_enu_mps": [1.0, 0.0, 0.0]})
        };
        let a = vec![(1, s(45.0, 359.9)), (2, s(45.0, 1.0))];
        let b = vec![(2, s(45.0 + 1e-5, 0.9)), (3, s(0.0, 0.0))];
        let d = compare_solutions(&a, &b);
        assert_eq!(d.compared, 1);
        assert!((d.max_horizontal_m - 1.111).abs() < 0.01, "{d:?}");
        assert!((d.max_heading_deg - 0.1).abs() < 1e-9, "{d:?}");
        assert_eq!(d.max_velocity_mps, 0.0);
    }
}
