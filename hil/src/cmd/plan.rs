//! `hil plan north-finding`: what a drill will give before it starts, and the dwell that meets
//! a tolerance (the work is in [`hil::procedures::plan`]).

use anyhow::{Context, Result};
use hil::procedures::plan::{PlanRequest, plan, text};
use hil::scenario::Scenario;
use std::path::PathBuf;

/// What to plan.
#[derive(clap::Subcommand)]
pub(crate) enum Plan {
    /// The heading sigma a north-finding drill will give (the paper's IMU, or a scenario's or
    /// an IMU parameter file's) at a latitude, made of its terms (angle random walk, the
    /// gyro drift during the drill, the dwells' end windows, the table's angle); the dwell per
    /// position that meets a tolerance at a confidence; and the latitude beyond which no dwell
    /// does. Exit status 1 when no dwell meets the tolerance.
    NorthFinding(PlanArgs),
    /// What the bench will drive on a scenario's route: its length and duration, heights,
    /// speeds, accelerations (along and across the road), the body's pitch and roll, where it
    /// stands, and what the plan had to do (legs driven slower than asked, short vertical
    /// curves); with --csv, its profile for a plot; with --check, the truth's self-check. Exit
    /// status 1 when the scenario ends before the drive does, 3 when the truth disagrees with
    /// itself.
    Route(RouteArgs),
    /// Check a recorded track (GPX 1.0/1.1, an NMEA log of GGA/RMC, or a CSV reference
    /// trajectory) and show what the bench will drive from it: the points it dropped and why,
    /// what it assumed, the stops it found, how far the road it drives is from the track's
    /// points and times, and the route's summary; with --svg, a picture of the track against
    /// the road; with --check, the truth's self-check. A track the bench cannot drive is
    /// refused with the file, the line or point, and what is wrong (exit status 2); exit status
    /// 3 when the drive's truth disagrees with itself.
    Track(TrackArgs),
}

/// `hil plan track`'s arguments.
#[derive(clap::Args)]
pub(crate) struct TrackArgs {
    /// The track file.
    file: PathBuf,
    /// A scenario whose [drive] limits (acceleration, braking, jerk, lateral acceleration,
    /// turn rate, the body's pitch and roll, start_wait_s, track_jitter_m,
    /// track_max_speed_mps) to drive the track with (default: a driver's: 2 m/s^2 of
    /// acceleration, 3 of braking and lateral, 2 m/s^3 of jerk, 40 deg/s of turn rate).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Write a picture of the track against the road the bench drives (SVG).
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Also write the drive's profile (time, distance, latitude, longitude, height, speed,
    /// heading, pitch, roll) to this CSV file.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
    /// Also check the truth: integrate the drive's own ideal increments (at the scenario's IMU
    /// rate, else 2 kHz) and compare with its position, velocity and attitude, against the
    /// bound every in-process run is held to; exit status 3 when it departs beyond it.
    #[arg(long)]
    check: bool,
}

/// The truth's self-check of `d` at `rate_hz` over `run_s`, into `r`; exit status 3 when it
/// fails.
fn check_truth(
    r: &mut hil::scenario::route::RouteSummary,
    d: &emulators::drive::Drive,
    rate_hz: f64,
    run_s: f64,
) -> i32 {
    let c = emulators::road::reference::self_check(d, rate_hz, run_s);
    let code = if c.holds() { 0 } else { 3 };
    r.truth_check = Some(c);
    code
}

fn track_cmd(a: TrackArgs) -> Result<i32> {
    use emulators::drive::{Drive, DriveSpec};
    let (mut spec, run_s, rate_hz) = match &a.scenario {
        Some(p) => {
            let s = Scenario::load(p)?;
            let d = s
                .drive
                .clone()
                .with_context(|| format!("scenario {} has no [drive]", p.display()))?;
            (d, Some(s.duration_s), s.imu.rate_hz)
        }
        // a driver's limits, not the level route's gentle ones: a track is driven as it was
        None => (DriveSpec::driver(), None, 2000.0),
    };
    spec.track = Some(a.file.display().to_string());
    let track = match emulators::road::track::read(&a.file) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return Ok(2);
        }
    };
    let d = match Drive::plan(&spec) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("error: {}", e.problem);
            return Ok(2);
        }
    };
    let name = a.file.display().to_string();
    let run_s = run_s.unwrap_or(d.duration());
    let mut r = hil::scenario::route::summary_of(&name, run_s, &d);
    let code = if a.check {
        check_truth(&mut r, &d, rate_hz, run_s)
    } else {
        0
    };
    if let Some(f) = &a.csv {
        hil::scenario::route::csv_of(&d, 1.0, f)?;
    }
    if let (Some(f), Some(n)) = (&a.svg, &r.track) {
        let pic = hil::scenario::trackview::svg(&track, &d, n, &name);
        std::fs::write(f, pic).with_context(|| format!("cannot write {}", f.display()))?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", hil::scenario::route::text(&r));
        for (what, f) in [("picture", &a.svg), ("profile", &a.csv)] {
            if let Some(f) = f {
                println!("  {what}: {}", f.display());
            }
        }
    }
    Ok(code)
}

/// `hil plan route`'s arguments.
#[derive(clap::Args)]
pub(crate) struct RouteArgs {
    /// The scenario whose [drive] to show.
    #[arg(long)]
    scenario: PathBuf,
    /// Also write the profile (time, distance, latitude, longitude, height, speed, heading,
    /// pitch, roll) to this CSV file.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// The CSV's rate, Hz.
    #[arg(long, default_value_t = 1.0, value_parser = hil::values::step_hz)]
    csv_hz: f64,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
    /// Also write the drive as a recorded track, as a logger would record it, to this file:
    /// .gpx (GPX 1.1; --track-format gpx10 for 1.0), .nmea (GGA and RMC) or .csv (a reference
    /// trajectory: exact, with attitude and velocity). The bench drives such a file with
    /// `[drive] track`.
    #[arg(long)]
    track: Option<PathBuf>,
    /// The track's format (default: from the file's extension).
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(["gpx", "gpx10", "nmea", "csv"]))]
    track_format: Option<String>,
    /// The logger's step between points, s (a reference trajectory's: its step).
    #[arg(long, default_value_t = 1.0, value_parser = hil::values::duration_s)]
    track_step: f64,
    /// The logger's spread of its step, +- s (uniform).
    #[arg(long, default_value_t = 0.0, value_parser = hil::values::pause_s)]
    track_step_spread: f64,
    /// The logger's horizontal jitter, m (1 sigma, wandering with a 30 s time constant; its
    /// heights jitter twice as much).
    #[arg(long, default_value_t = 0.0, value_parser = jitter_m)]
    track_jitter: f64,
    /// The chance of a glitch (a point 450 m off) and of a point without elevation.
    #[arg(long, default_value_t = 0.0, value_parser = probability)]
    track_glitch: f64,
    /// See --track-glitch.
    #[arg(long, default_value_t = 0.0, value_parser = probability)]
    track_no_elevation: f64,
    /// The logger's seed.
    #[arg(long, default_value_t = 1)]
    track_seed: u64,
    /// When the logger is switched on, s into the drive (its track then starts in motion, as
    /// a logger's switched on while driving does).
    #[arg(long, default_value_t = 0.0, value_parser = hil::values::pause_s)]
    track_start: f64,
    /// Also check the truth: integrate the drive's own ideal increments at the scenario's IMU
    /// rate and compare with its position, velocity and attitude over the scenario, against
    /// the bound every in-process run is held to; exit status 3 when it departs beyond it.
    #[arg(long)]
    check: bool,
}

fn jitter_m(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..=100.0).contains(&v) => Ok(v),
        _ => Err(format!("a jitter is from 0 to 100 m, got {s:?}")),
    }
}

fn probability(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!("a chance is from 0 to 1, got {s:?}")),
    }
}

/// The scenario's drive recorded as a track file.
fn record_track(s: &Scenario, a: &RouteArgs, out: &std::path::Path) -> Result<()> {
    use emulators::road::track::{Format, logger};
    let spec = s.drive.as_ref().context("the scenario has no [drive]")?;
    let d = emulators::drive::Drive::plan(spec)
        .map_err(|e| anyhow::anyhow!("[{}] {}", e.table, e.problem))?;
    let ext = out.extension().and_then(|e| e.to_str()).unwrap_or("");
    let fmt = a.track_format.as_deref().unwrap_or(ext);
    let (format, v10) = match fmt {
        "gpx" => (Format::Gpx, false),
        "gpx10" => (Format::Gpx, true),
        "nmea" | "nma" | "log" => (Format::Nmea, false),
        "csv" => (Format::Csv, false),
        _ => anyhow::bail!(
            "--track {}: say the format with --track-format (gpx, gpx10, nmea, csv)",
            out.display()
        ),
    };
    // the scenario's UTC start, else 2026-05-01T08:00:00Z
    let t0 = 1_777_622_400.0;
    let points = if format == Format::Csv {
        logger::reference(&d, a.track_step, t0)
    } else {
        let log = logger::Logger {
            step_s: a.track_step,
            step_spread_s: a.track_step_spread.min(0.9 * a.track_step),
            standing_step_s: a.track_step.max(5.0),
            jitter_m: a.track_jitter,
            jitter_h_m: 2.0 * a.track_jitter,
            no_elevation: a.track_no_elevation,
            glitch: a.track_glitch,
            seed: a.track_seed,
            start_s: a.track_start,
        };
        logger::record(&d, &log, t0)
    };
    std::fs::write(out, logger::write(&points, format, v10))
        .with_context(|| format!("cannot write {}", out.display()))
}

fn route_cmd(a: RouteArgs) -> Result<i32> {
    let s = Scenario::load(&a.scenario)?;
    let mut r = hil::scenario::route::summary(&s)?;
    let checked = if a.check {
        let spec = s.drive.as_ref().context("the scenario has no [drive]")?;
        let d = emulators::drive::Drive::plan(spec)
            .map_err(|e| anyhow::anyhow!("[{}] {}", e.table, e.problem))?;
        check_truth(&mut r, &d, s.imu.rate_hz, s.duration_s)
    } else {
        0
    };
    if let Some(f) = &a.csv {
        hil::scenario::route::csv(&s, a.csv_hz, f)?;
    }
    if let Some(f) = &a.track {
        record_track(&s, &a, f)?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", hil::scenario::route::text(&r));
        if let Some(f) = &a.csv {
            println!("  profile: {}", f.display());
        }
        if let Some(f) = &a.track {
            println!("  track: {}", f.display());
        }
    }
    if checked != 0 {
        return Ok(checked);
    }
    Ok(i32::from(r.duration_s > r.scenario_s))
}

/// `hil plan north-finding`'s arguments.
#[derive(clap::Args)]
pub(crate) struct PlanArgs {
    /// Latitude, deg (default: the scenario's site, else the paper's start point).
    #[arg(long, value_parser = hil::values::latitude_deg, allow_negative_numbers = true)]
    lat: Option<f64>,
    /// The tolerance on the heading error, deg.
    #[arg(long, value_parser = hil::values::tolerance_deg, default_value_t = 0.1)]
    tolerance: f64,
    /// Sigmas the tolerance must hold at (3: all but 0.3 % of drills).
    #[arg(long, default_value_t = 3.0, value_parser = confidence)]
    confidence: f64,
    /// Dwell per position to predict, s (default: the scenario's, else 60).
    #[arg(long, value_parser = hil::values::duration_s)]
    dwell: Option<f64>,
    /// Positions: 2, 4 or 8, equally spaced (4: 0, 90, 180, 270, the paper's; default: the
    /// scenario's).
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(["2", "4", "8"]))]
    positions: Option<String>,
    /// Visit the positions out and back (0, 90, 180, 270, 270, 180, 90, 0): a linear gyro drift
    /// cancels; each visit is a dwell.
    #[arg(long)]
    out_and_back: bool,
    /// The scenario whose IMU ([imu]), mechanism ([turntable]), site and drill
    /// ([north_finding]) to plan for.
    #[arg(long, conflicts_with = "imu")]
    scenario: Option<PathBuf>,
    /// A TOML file of the IMU's parameters (the keys of a scenario's [imu], at top level or
    /// under [imu]), on the paper's mechanism.
    #[arg(long)]
    imu: Option<PathBuf>,
    /// Longest dwell per position considered, s.
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 600.0)]
    max_dwell: f64,
    /// Print the plan as JSON.
    #[arg(long)]
    json: bool,
}

fn confidence(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (0.5..=10.0).contains(&v) => Ok(v),
        _ => Err(format!(
            "a confidence is a number of sigmas from 0.5 to 10, got {s:?}"
        )),
    }
}

/// An IMU parameter file: the keys of `[imu]`, bare or under `[imu]`.
fn imu_file(p: &std::path::Path) -> Result<emulators::imu::ImuParams> {
    let text =
        std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
    let v: toml::Table = toml::from_str(&text).with_context(|| format!("{}", p.display()))?;
    let t = match v.get("imu") {
        Some(toml::Value::Table(t)) => t.clone(),
        _ => v,
    };
    let imu: emulators::imu::ImuParams = t
        .try_into()
        .with_context(|| format!("{}: not an IMU's parameters", p.display()))?;
    imu.check()
        .map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
    Ok(imu)
}

/// The table positions `--positions N [--out-and-back]` ask for.
pub(crate) fn positions(n: Option<&str>, out_and_back: bool) -> Option<Vec<f64>> {
    let n: usize = n.map_or(4, |n| n.parse().unwrap_or(4));
    if out_and_back {
        Some(nav::procedures::drill_plan::out_and_back(n))
    } else if n != 4 {
        Some(nav::procedures::drill_plan::equally_spaced(n))
    } else {
        None
    }
}

pub(crate) fn plan_cmd(p: Plan) -> Result<i32> {
    let a = match p {
        Plan::NorthFinding(a) => a,
        Plan::Route(r) => return route_cmd(r),
        Plan::Track(t) => return track_cmd(t),
    };
    let (mut s, source) = match (&a.scenario, &a.imu) {
        (Some(f), _) => (Scenario::load(f)?, format!("scenario {}", f.display())),
        (None, Some(f)) => {
            let mut s = hil::procedures::northfinding::scenario(0.0, 28.218157, 60.0, 1);
            s.imu = imu_file(f)?;
            (s, format!("IMU of {}", f.display()))
        }
        (None, None) => (
            hil::procedures::northfinding::scenario(0.0, 28.218157, 60.0, 1),
            "the paper's IMU".into(),
        ),
    };
    if let Some(l) = a.lat {
        s.site.lat_deg = l;
    }
    let mut nf = s.north_finding.clone().unwrap_or_default();
    if let Some(d) = a.dwell {
        nf.dwell_s = d;
    }
    if let Some(p) = positions(a.positions.as_deref(), a.out_and_back) {
        nf.positions_deg = p;
    }
    let r = plan(&PlanRequest {
        scenario: s,
        north_finding: nf,
        source,
        tolerance_deg: a.tolerance,
        confidence: a.confidence,
        dwell_range_s: (5.0, a.max_dwell.max(5.0)),
    });
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", text(&r));
    }
    Ok(i32::from(matches!(
        r.answer,
        nav::procedures::drill_plan::DwellAnswer::Cannot { .. }
    )))
}
