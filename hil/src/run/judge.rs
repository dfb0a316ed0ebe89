//! Judging a run once its devices and nav have stopped: the in-process reference run, nav's
//! recording replayed through its pipeline and scored against the truth, the procedures'
//! outcomes and every check of the result card. Judging writes no file: [`write_evidence`]
//! writes what it found (nav's error second by second, the fixes, the truth recording) beside
//! the report.

use super::offload::{self, Recomputed};
use super::{Phases, RunOptions};
use crate::engine::scoring::{FixFate, NavScore, ScoredRecording, SeriesStats};
use crate::engine::truthrec::RunTruth;
use crate::report::{self, KillOutcome, NavMemory, RunReport};
use crate::scenario::Scenario;
use anyhow::Result;
use emulators::adapters::scheduler::TtTruth;
use emulators::drive::Drive;
use std::path::Path;

/// A run whose devices and nav have stopped: what the bus, nav and the bench's watchers said.
pub(super) struct Ended {
    pub(super) bus: emulators::adapters::scheduler::BusOutcome,
    pub(super) sim_reached: f64,
    pub(super) wall: f64,
    pub(super) nav_exit: Option<i32>,
    pub(super) nav: nav::summary::Summary,
    pub(super) killed: Option<KillOutcome>,
    pub(super) memory: NavMemory,
    pub(super) solution: crate::procedures::observe::SolutionWatch,
}

/// What the judging read and the report does not hold, for the files beside it.
#[derive(Default)]
pub(super) struct Evidence {
    /// nav's error second by second, from its recording.
    scores: Vec<NavScore>,
    /// The receiver's fixes nav took (east, north of the drive's start, m) and their fate,
    /// when nav's recording could be read for them.
    fixes: Option<Vec<(f64, [f64; 2], FixFate)>>,
    /// Simulated time -> the wall time nav logged it at, for the truth recording.
    clock: Vec<(f64, u64)>,
    /// The turntable's true state through the run.
    turntable: Vec<TtTruth>,
    /// The simulated time the run reached (at most its duration), s.
    end_s: f64,
}

/// The checks that recompute things, side by side: the in-process reference run, and the
/// replay of nav's recording through its pipeline with the scoring of that recording against
/// truth (one reading of the recording for both); by a judge server when the environment names
/// one ([`offload::ENV`]) and it takes the work, otherwise here.
fn recompute(
    s: &Scenario,
    opts: &RunOptions,
    nav_cfg: &nav::config::NavConfig,
    drive: Option<&Drive>,
) -> Result<Recomputed> {
    let mcap = opts.out.join("nav.mcap");
    let w = offload::Work {
        scenario: s,
        nav_cfg,
        // (through gpsd, nav gets only the sentences gpsd keeps: not the receiver's bytes)
        reference: s.turntable.is_none() && opts.reference_checks && !opts.gps_via_gpsd,
        replay: opts.reference_checks,
        drive: drive.filter(|_| opts.reference_checks),
        mcap: &mcap,
    };
    if !w.reference && !w.replay {
        return Ok(Recomputed {
            reference: None,
            replayed: None,
            scored: None,
            by_server: false,
        });
    }
    if let Some(dir) = std::env::var_os(offload::ENV).filter(|d| !d.is_empty()) {
        match offload::ask(Path::new(&dir), &w) {
            Ok(Some(r)) => return Ok(r),
            Ok(None) => {}
            Err(e) => tracing::warn!("the judge server ({}): {e:#}; judging here", offload::ENV),
        }
    }
    offload::compute(&w, &mcap.display().to_string())
}

/// Check and score a run against `truth`: the recomputations, the procedures' outcomes, the
/// checks; the report, and the evidence for the files beside it.
pub(super) fn judge(
    s: &Scenario,
    opts: &RunOptions,
    truth: &RunTruth,
    nav_cfg: &nav::config::NavConfig,
    backend: &str,
    e: Ended,
    phases: &mut Phases,
) -> Result<(RunReport, Evidence)> {
    let Ended {
        bus,
        sim_reached,
        wall,
        nav_exit,
        nav: nav_json,
        killed,
        memory,
        solution,
    } = e;
    let (tx, tt_stats, lockstep_stats, bus_stats) = (bus.imu, bus.turntable, bus.lockstep, bus.bus);
    // the receiver's device stayed until nav had stopped
    let gps_stats = bus.gps.map(|(st, _pty)| st);
    // nav is scored second by second on a drive it navigates, when the run checks it
    let drive = match (&s.navigation, &truth.drive) {
        (Some(_), Some(d)) if opts.reference_checks => Some(d),
        _ => None,
    };
    let mut rc = recompute(s, opts, nav_cfg, drive)?;
    let reference = rc.reference.take().transpose()?;
    phases.end(if rc.by_server {
        "reference, replay and scoring (by the judge server)"
    } else {
        "reference, replay and scoring"
    });
    let bench = report::BenchSide {
        tx: &tx,
        lockstep: &lockstep_stats,
        bus: &bus_stats,
        turntable: tt_stats.as_ref(),
        gps_via_gpsd: opts.gps_via_gpsd,
    };
    let (mut checks, lost) = report::checks(s, bench, reference.as_ref(), &nav_json, nav_exit);
    let procedures = crate::procedures::Outcomes::of(s, &nav_json, sim_reached);
    report::procedure_checks(&mut checks, s, &procedures, &nav_json);
    report::solution_checks(&mut checks, &solution, &nav_json);
    // nav's binary is a shell around its pipeline: from its own recording, the pipeline in
    // process must send exactly what nav sent
    if let Some(replayed) = rc.replayed {
        checks.push(report::replay_check(replayed.as_ref()));
    }
    let mut evidence = Evidence {
        turntable: bus.turntable_truth,
        end_s: sim_reached.min(s.duration_s),
        ..Evidence::default()
    };
    let (navigation, navigation_series) = score_navigation(
        s,
        drive,
        rc.scored,
        &nav_json,
        gps_stats.as_ref(),
        &mut checks,
        &mut evidence,
    );
    phases.end("checks");
    let pass = checks.iter().all(|c| c.pass);
    let r = RunReport {
        scenario: s.clone(),
        backend: backend.into(),
        interface: opts.iface.clone(),
        wall_seconds: wall,
        frames_per_wall_second: tx.frames as f64 / wall.max(1e-9),
        pace_reached: sim_reached
            / (wall - lockstep_stats.watchdog_wait_ms as f64 * 1e-3).max(1e-9),
        lockstep: lockstep_stats,
        bus: bus_stats,
        tx,
        in_process: reference,
        turntable: tt_stats,
        procedures,
        gps: gps_stats,
        navigation,
        navigation_series,
        solution,
        nav_exit,
        nav: nav_json,
        killed,
        nav_memory: Some(memory),
        bus_lost_frames: lost,
        checks,
        pass,
        live: None,
    };
    Ok((r, evidence))
}

/// Navigation scored against truth: from nav's summary, and second by second from its
/// recording (statistics, and the series and fixes for the files); the navigation checks.
fn score_navigation(
    s: &Scenario,
    drive: Option<&Drive>,
    scored: Option<Result<ScoredRecording>>,
    nav_json: &nav::summary::Summary,
    gps_stats: Option<&emulators::adapters::pty::GpsTxStats>,
    checks: &mut Vec<report::Check>,
    evidence: &mut Evidence,
) -> (Option<NavScore>, Option<SeriesStats>) {
    let (Some(drive), Some(scored)) = (drive, scored) else {
        return (None, None);
    };
    let imu = s.imu.oscillator().from_first_sample();
    let o = crate::engine::scoring::score_summary(drive, nav_json, &imu);
    let mut navigation_series = None;
    match scored {
        Ok(sc) if !sc.scores.is_empty() => {
            navigation_series = Some(SeriesStats::of(&sc.scores, sc.bad));
            // sim time -> the wall time nav logged it at, for the truth recording
            evidence.clock = sc
                .scores
                .iter()
                .filter_map(|x| Some((x.t_s, x.logged_wall_ns?)))
                .collect();
            // the receiver's fixes nav took, for the track
            evidence.fixes = Some(sc.fixes);
            evidence.scores = sc.scores;
        }
        Ok(_) => {}
        Err(e) => tracing::warn!("nav's recording: {e:#}"),
    }
    report::navigation_checks(checks, s, o.as_ref(), nav_json, gps_stats);
    if let Some(c) = navigation_series.as_ref().and_then(report::sigma_check) {
        checks.push(c);
    }
    (o, navigation_series)
}

/// The files of what the judging found, beside the report: `navigation.csv` and its plot,
/// `fixes.csv`, and the bench's own side of the run, `truth.mcap` (the truth and the faults
/// injected, on nav's logged wall clock).
pub(super) fn write_evidence(
    s: &Scenario,
    opts: &RunOptions,
    truth: &RunTruth,
    ev: &Evidence,
) -> Result<()> {
    if !ev.scores.is_empty() {
        write_navigation_series(&opts.out, &s.name, &ev.scores)?;
    }
    if let Some(f) = &ev.fixes {
        write_fixes(&opts.out, f)?;
    }
    if let Err(e) = crate::engine::truthrec::write(
        &opts.out,
        truth.drive.as_ref(),
        &truth.site,
        ev.end_s,
        &ev.clock,
        &ev.turntable,
        &truth.faults,
    ) {
        tracing::warn!("truth.mcap: {e:#}");
    }
    Ok(())
}

/// The receiver's fixes nav took (east, north of the drive's start, m) and what became of them:
/// `fixes.csv` (fate: valid, void or rejected).
fn write_fixes(out: &Path, fixes: &[(f64, [f64; 2], FixFate)]) -> Result<()> {
    let mut csv = String::from("t_s,east_m,north_m,fate\n");
    for (t, [e, n], fate) in fixes {
        let fate = match fate {
            FixFate::Valid => "valid",
            FixFate::Void => "void",
            FixFate::Rejected => "rejected",
        };
        csv += &format!("{t:.3},{e:.3},{n:.3},{fate}\n");
    }
    std::fs::write(out.join("fixes.csv"), csv)?;
    Ok(())
}

/// nav's navigation error second by second: `navigation.csv` and `navigation-error.svg`.
fn write_navigation_series(out: &Path, name: &str, scores: &[NavScore]) -> Result<()> {
    let mut csv = String::from(
        "t_s,position_error_m,velocity_error_mps,heading_error_deg,position_sigma_m,heading_sigma_deg,\
         nav_east_m,nav_north_m,truth_east_m,truth_north_m,\
         vel_error_east_mps,vel_error_north_mps,vel_error_up_mps,\
         vel_sigma_east_mps,vel_sigma_north_mps,vel_sigma_up_mps,\
         pitch_error_deg,roll_error_deg,tilt_sigma_deg,nees_position,nees_velocity\n",
    );
    let opt = |v: Option<f64>, p: usize| v.map_or(String::new(), |v| format!("{v:.p$}"));
    for x in scores {
        let tr = x.track_en_m;
        let ve = x.velocity_error_enu_mps;
        let vs = x.velocity_sigma_enu_mps;
        let tilt = x.tilt_error_deg;
        csv += &format!(
            "{:.3},{:.3},{:.4},{:.5},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            x.t_s,
            x.position_error_m,
            x.velocity_error_mps,
            x.heading_error_deg,
            opt(x.position_sigma_m, 3),
            opt(x.heading_sigma_deg, 5),
            opt(tr.map(|t| t[0][0]), 3),
            opt(tr.map(|t| t[0][1]), 3),
            opt(tr.map(|t| t[1][0]), 3),
            opt(tr.map(|t| t[1][1]), 3),
            opt(ve.map(|v| v[0]), 4),
            opt(ve.map(|v| v[1]), 4),
            opt(ve.map(|v| v[2]), 4),
            opt(vs.map(|v| v[0]), 4),
            opt(vs.map(|v| v[1]), 4),
            opt(vs.map(|v| v[2]), 4),
            opt(tilt.map(|t| t[0]), 5),
            opt(tilt.map(|t| t[1]), 5),
            opt(x.tilt_sigma_deg, 5),
            opt(x.nees.map(|n| n[0]), 3),
            opt(x.nees.map(|n| n[1]), 3),
        );
    }
    std::fs::write(out.join("navigation.csv"), csv)?;
    let chart = crate::report::plot::LogChart {
        title: format!("{name}: nav's horizontal position error (from its recording)"),
        x_label: "time, s".into(),
        y_label: "m".into(),
        series: vec![crate::report::plot::Series {
            name: "nav".into(),
            color: "#1f77b4",
            points: scores.iter().map(|x| (x.t_s, x.position_error_m)).collect(),
            markers: false,
        }],
    };
    std::fs::write(out.join("navigation-error.svg"), chart.svg())?;
    Ok(())
}
