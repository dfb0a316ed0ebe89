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
    /// curves); with --csv, its profile for a plot. Exit status 1 when the scenario ends before
    /// the drive does.
    Route(RouteArgs),
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
}

fn route_cmd(a: RouteArgs) -> Result<i32> {
    let s = Scenario::load(&a.scenario)?;
    let r = hil::scenario::route::summary(&s)?;
    if let Some(f) = &a.csv {
        hil::scenario::route::csv(&s, a.csv_hz, f)?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", hil::scenario::route::text(&r));
        if let Some(f) = &a.csv {
            println!("  profile: {}", f.display());
        }
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
        Some(nav::northplan::out_and_back(n))
    } else if n != 4 {
        Some(nav::northplan::equally_spaced(n))
    } else {
        None
    }
}

pub(crate) fn plan_cmd(p: Plan) -> Result<i32> {
    let a = match p {
        Plan::NorthFinding(a) => a,
        Plan::Route(r) => return route_cmd(r),
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
        nav::northplan::DwellAnswer::Cannot { .. }
    )))
}
