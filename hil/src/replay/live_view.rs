//! `hil replay RUN --live`: nav's recording through nav's pipeline in process, shown on the live
//! view as it goes, paced at `--speed` on the recording's IMU time, with the viewer's playback
//! controls: pause, play, a speed, and seek. A seek back starts the pipeline again from the
//! recording's start and runs it unseen to the seek time; a seek forward runs it unseen to
//! there. Every pass is the same pipeline on the same inputs (a replay is deterministic), so
//! what is shown after a seek is what a straight replay shows there. The frames, nav's lines
//! and the truth (from the run's scenario, when the folder has it) go through the same watcher
//! and publisher as a bench run's ([`super::bench_run`]).

use crate::engine::recording::{Input, Playback, Replayer, each_message, input_of, text};
use crate::live::View;
use crate::live::bench_run::BenchRun;
use crate::live::server::{Control, Playback as Status};
use crate::scenario::Scenario;
use anyhow::Result;
use nav::config::NavConfig;
use nav::pipeline::Output;
use serde_json::json;
use std::path::Path;
use std::sync::Arc;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// Where the viewer wants the replay.
struct Wanted {
    playing: bool,
    speed: f64,
    /// A seek asked for (ns of the recording's IMU time).
    seek: Option<u64>,
}

/// Replay `mcap` (config `cfg`, the run's scenario `scenario` when known) on a live view at
/// `addr` (waiting for `wait` viewers first) at `speed` until its end; then, while a viewer is
/// connected, wait for a seek back. The replay's comparison with what nav sent (the last full
/// pass's) and what the viewers got.
pub fn replay_live(
    mcap: &Path,
    cfg: &NavConfig,
    scenario: Option<&Scenario>,
    addr: std::net::SocketAddr,
    wait: usize,
    speed: f64,
) -> Result<(Playback, crate::live::server::ServerStats)> {
    let mut inputs = Vec::new();
    each_message(mcap, "replaying", |m| {
        if let Some(i) = input_of(m) {
            inputs.push(i);
        }
    })?;
    let samples = inputs.iter().filter(|i| is_gyro(i)).count() as u64;
    let end_ns = (samples as f64 / cfg.imu.rate_hz * 1e9) as u64;
    let view = View::start(addr, wait, end_ns as f64 * 1e-9)?;
    let pb = play(&inputs, cfg, scenario, &view, speed, end_ns, mcap);
    let stats = view.finish();
    Ok((pb?, stats))
}

/// An IMU_GYRO frame: one IMU sample (the recording's clock).
fn is_gyro(i: &Input) -> bool {
    matches!(i, Input::Frame(f) if f.id == wire::imu_gyro::SPEC.id)
}

fn play(
    inputs: &[Input],
    cfg: &NavConfig,
    scenario: Option<&Scenario>,
    view: &Arc<View>,
    speed: f64,
    end_ns: u64,
    mcap: &Path,
) -> Result<Playback> {
    let rate = cfg.imu.rate_hz;
    let (tx, rx) = mpsc::channel();
    view.controls_to(tx);
    let truth = scenario
        .map(|s| crate::engine::truthrec::RunTruth::of(s, &[], None, None))
        .transpose()?;
    let name = mcap.display().to_string();
    let mut wanted = Wanted {
        playing: true,
        speed,
        seek: None,
    };
    let mut first = true;
    loop {
        let show_from = wanted.seek.take().unwrap_or(0);
        let run = BenchRun::begin(view, &name, truth.as_ref(), first)?;
        first = false;
        let mut w = run.frame_watcher(cfg.imu.gyro_pulse_arcsec, cfg.imu.accel_pulse_mps, rate);
        let mut r = Replayer::with_records(cfg, true)?;
        r.tap = Some(Vec::new());
        let mut k = 0u64;
        // the wall clock's origin for the pace: (when, at which IMU time, s)
        let mut origin: Option<(Instant, f64)> = None;
        let mut restart = false;
        for i in inputs {
            let t = k as f64 / rate;
            let t_ns = (t * 1e9) as u64;
            let showing = t_ns >= show_from;
            if showing {
                // the viewer's requests, a pause, the pace
                if viewer_wants_back(view, &rx, &mut wanted, &mut origin, t_ns) {
                    restart = true;
                    break;
                }
                if let Some(s) = wanted.seek {
                    if s > t_ns {
                        // forward: on unseen to there, by this same pass
                        origin = None;
                    }
                } else if is_gyro(i) {
                    let (at, t0) = *origin.get_or_insert((Instant::now(), t));
                    let due = at + Duration::from_secs_f64(((t - t0) / wanted.speed).max(0.0));
                    let now = Instant::now();
                    if due > now {
                        std::thread::sleep(due - now);
                    }
                }
            }
            let visible = showing && wanted.seek.is_none_or(|s| t_ns >= s);
            if wanted.seek.is_some_and(|s| t_ns >= s) {
                wanted.seek = None;
            }
            if let (true, Input::Frame(f)) = (visible, i) {
                w.on_frame(t_ns, f);
            }
            r.feed(i.clone());
            for o in r.tap.as_mut().map(std::mem::take).unwrap_or_default() {
                match o {
                    Output::Command(f) | Output::Solution(f) if visible => w.on_frame(t_ns, &f),
                    Output::Line(l) if visible => run.line(&l),
                    _ => {}
                }
            }
            if is_gyro(i) {
                if visible {
                    w.after_sample(k, (k + 1) as f64 / rate);
                }
                k += 1;
            }
        }
        if restart {
            run.abandon();
            continue;
        }
        let pb = r.finish(&name);
        let identical = pb.identical();
        let report = json!({
            "pass": identical,
            "checks": [{"name": "the replay sends what nav sent", "pass": identical,
                        "detail": pb.verdict()}],
            "replay": &pb,
        });
        run.end(report, text(&pb));
        view.playback(Status::Ended, end_ns, wanted.speed, false, None);
        // at the end: a viewer may seek back; without one the replay is over
        match wait_for_seek(view, &rx, &mut wanted, end_ns) {
            true => continue,
            false => return Ok(pb),
        }
    }
}

/// Take the viewer's requests at IMU time `t_ns`, holding while it pauses: true when it seeks
/// back (the replay starts again from the start).
fn viewer_wants_back(
    view: &View,
    rx: &mpsc::Receiver<Control>,
    wanted: &mut Wanted,
    origin: &mut Option<(Instant, f64)>,
    t_ns: u64,
) -> bool {
    loop {
        while let Ok(c) = rx.try_recv() {
            answer(view, wanted, &c, t_ns);
        }
        if wanted.seek.is_some_and(|s| s < t_ns) {
            return true;
        }
        if wanted.seek.is_some() || wanted.playing {
            return false;
        }
        *origin = None;
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Take the viewer's request `c` at IMU time `t_ns` and answer it with the playback state.
fn answer(view: &View, wanted: &mut Wanted, c: &Control, t_ns: u64) {
    wanted.playing = c.play;
    if c.speed.is_finite() && c.speed > 0.0 {
        wanted.speed = f64::from(c.speed);
    }
    wanted.seek = c.seek_ns.map(|s| s.saturating_sub(view.offset()));
    let status = if c.play {
        Status::Playing
    } else {
        Status::Paused
    };
    let at = wanted.seek.unwrap_or(t_ns);
    view.playback(
        status,
        at,
        wanted.speed,
        wanted.seek.is_some(),
        Some(&c.request_id),
    );
}

/// After the end: while a viewer is connected, wait for one to seek (true); false once none is.
fn wait_for_seek(view: &View, rx: &Receiver<Control>, wanted: &mut Wanted, end_ns: u64) -> bool {
    loop {
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(c) => {
                answer(view, wanted, &c, end_ns);
                if wanted.seek.is_some() {
                    return true;
                }
            }
            Err(RecvTimeoutError::Timeout) => {
                if view.clients() == 0 {
                    return false;
                }
            }
            Err(RecvTimeoutError::Disconnected) => return false,
        }
    }
}
