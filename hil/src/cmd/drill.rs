//! `hil drill north-finding`: the operator drill, on the bus or in process.

use crate::cmd::args::{BusArgs, FreeArgs, LiveArgs};
use crate::cmd::run::{procedure_folder, run_procedure};
use anyhow::{Context, Result};
use clap::Subcommand;
use std::path::PathBuf;

#[derive(Subcommand)]
pub(crate) enum Drill {
    /// Four-position north-finding: the vehicle is parked at a given or random heading; nav
    /// indexes the IMU through 0/90/180/270 deg on the turntable, finds north, returns to zero
    /// and locks. Live progress, then a result card; the run is saved with its report.
    NorthFinding(NorthFindingArgs),
}

#[derive(clap::Args, Clone)]
pub(crate) struct NorthFindingArgs {
    /// True heading of the vehicle, deg (default: random).
    #[arg(long, value_parser = hil::values::heading_deg, allow_negative_numbers = true)]
    pub(crate) heading: Option<f64>,
    /// Latitude, deg.
    #[arg(long, value_parser = hil::values::latitude_deg, allow_negative_numbers = true, default_value_t = 28.218157)]
    pub(crate) lat: f64,
    /// Longitude, deg (the site's surveyed position, with --lat: where a real receiver is).
    #[arg(long, value_parser = hil::values::longitude_deg, allow_negative_numbers = true, default_value_t = 112.989583)]
    pub(crate) lon: f64,
    /// Dwell per position, s, or `auto`: the shortest that meets --tolerance at 3 sigma by the
    /// drill's prediction (`hil plan north-finding`), else the one that comes closest.
    #[arg(long, value_parser = crate::cmd::drill::dwell, default_value = "60")]
    pub(crate) dwell: crate::cmd::drill::Dwell,
    /// Positions: 2, 4 or 8, equally spaced (4: 0, 90, 180, 270, the paper's).
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(["2", "4", "8"]))]
    pub(crate) positions: Option<String>,
    /// Visit the positions out and back (0, 90, 180, 270, 270, 180, 90, 0): a linear gyro
    /// drift cancels; each visit is a dwell.
    #[arg(long)]
    pub(crate) out_and_back: bool,
    /// Speed factor (1 = real time, as on the vehicle).
    #[arg(long, value_parser = hil::values::speed, default_value_t = 1.0)]
    pub(crate) speed: f64,
    /// Disturbance script: TOML file with [[disturbance]] entries (door_slam, climb_in, wind).
    #[arg(long)]
    pub(crate) disturbances: Option<PathBuf>,
    /// Pass when the heading error is within this, deg.
    #[arg(long, value_parser = hil::values::tolerance_deg, default_value_t = 0.1)]
    pub(crate) tolerance: f64,
    /// Random seed (sensor errors, random heading).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Run the same drill in process (no bus, no nav process: the same emulators and nav code,
    /// stepped in the order the bench delivers the frames); its result equals the bench's.
    #[arg(long)]
    pub(crate) in_process: bool,
    #[command(flatten)]
    pub(crate) live: LiveArgs,
    #[command(flatten)]
    pub(crate) bus: BusArgs,
    #[command(flatten)]
    pub(crate) free: FreeArgs,
}

/// Disturbance script file: `[[disturbance]]` entries.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct DisturbanceScript {
    #[serde(default)]
    disturbance: Vec<emulators::truth::Disturbance>,
}

/// `--dwell`: seconds, or `auto`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Dwell {
    /// The shortest dwell that meets the tolerance by the prediction.
    Auto,
    /// Seconds per position.
    Seconds(f64),
}

/// Parse `--dwell`.
pub(crate) fn dwell(s: &str) -> std::result::Result<Dwell, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(Dwell::Auto);
    }
    hil::values::duration_s(s)
        .map(Dwell::Seconds)
        .map_err(|e| format!("{e} (or `auto`)"))
}

/// The drill's scenario for these arguments at `dwell_s` per position.
fn drill_scenario(
    a: &NorthFindingArgs,
    heading: f64,
    dwell_s: f64,
) -> Result<hil::scenario::Scenario> {
    let mut s = hil::procedures::northfinding::scenario(heading, a.lat, dwell_s, a.seed);
    s.speed = a.speed;
    s.site.lon_deg = a.lon;
    s.heading_tolerance_deg = a.tolerance;
    if let Some(p) = crate::cmd::plan::positions(a.positions.as_deref(), a.out_and_back) {
        hil::procedures::northfinding::set_positions(&mut s, p);
    }
    if let Some(p) = &a.disturbances {
        let text = std::fs::read_to_string(p)
            .with_context(|| format!("cannot read disturbance script {}", p.display()))?;
        let d: DisturbanceScript =
            toml::from_str(&text).with_context(|| format!("disturbance script {}", p.display()))?;
        s.disturbance = d.disturbance;
    }
    Ok(s)
}

/// The drill's plan on its scenario: what it will give, against the tolerance at 3 sigma.
fn drill_plan(s: &hil::scenario::Scenario) -> hil::procedures::plan::PlanReport {
    hil::procedures::plan::plan(&hil::procedures::plan::PlanRequest {
        north_finding: s.north_finding.clone().unwrap_or_default(),
        scenario: s.clone(),
        source: "the bench's IMU".into(),
        tolerance_deg: s.heading_tolerance_deg,
        confidence: 3.0,
        dwell_range_s: (5.0, 600.0),
    })
}

pub(crate) fn drill_north_finding(a: NorthFindingArgs) -> Result<i32> {
    let heading = match a.heading {
        Some(h) => h.rem_euclid(360.0),
        // random, reproducible from the seed
        None => hil::procedures::northfinding::heading_of_seed(a.seed),
    };
    let dwell_s = match a.dwell {
        Dwell::Seconds(d) => d,
        Dwell::Auto => {
            let p = drill_plan(&drill_scenario(&a, heading, 60.0)?);
            let d = hil::procedures::plan::auto_dwell(&p);
            eprintln!("hil: --dwell auto: {d:.0} s per position");
            d
        }
    };
    let mut s = drill_scenario(&a, heading, dwell_s)?;
    let plan = drill_plan(&s);
    eprintln!(
        "hil: predicted heading sigma {:.4} deg (3 sigma {:.3} deg, tolerance {} deg; `hil plan north-finding` for its terms)",
        plan.asked.prediction.sigma_deg,
        3.0 * plan.asked.prediction.sigma_deg,
        a.tolerance
    );
    if let Some(why) = hil::procedures::plan::advice(&plan) {
        eprintln!("hil: WARNING: {why}");
    }
    if a.free.free {
        // free-running, the device is judged by what it sends: our nav says its heading on the
        // bus (NAV_ATT, NAV_HGT's sigma) once it navigates after north-finding
        s = hil::free::parked_with_receiver(&s)?;
    }
    s.check()?;
    let (out, scen) = procedure_folder(
        &s,
        a.bus.out.as_deref(),
        "drill-north-finding",
        "drill.toml",
    )?;
    eprintln!(
        "hil: north-finding drill at {:.4} deg heading, latitude {} deg, {} s dwell, x{}",
        heading, a.lat, dwell_s, a.speed
    );
    if a.in_process {
        let nf = s.north_finding.clone().unwrap_or_default();
        let o = hil::procedures::northfinding::run_in_process(&s, &nf, |_| {})?;
        let j = serde_json::json!({ "in_process": true, "drill": o });
        std::fs::write(out.join("report.json"), serde_json::to_string_pretty(&j)?)?;
        if a.bus.json {
            println!("{}", serde_json::to_string_pretty(&j)?);
        } else {
            match (o.heading_deg, o.error_deg, o.sigma_deg) {
                (Some(h), Some(e), Some(sg)) => println!(
                    "in process: found {h:.4} deg, truth {:.4}, error {e:+.4} deg, sigma {sg:.4} deg, {:.1} s",
                    o.truth_deg, o.duration_s
                ),
                _ => println!("in process: aborted: {}", o.abort.as_deref().unwrap_or("?")),
            }
        }
        return Ok(i32::from(o.error_deg.is_none_or(|e| e.abs() > a.tolerance)));
    }
    run_procedure(scen, out, a.bus, a.live, a.free)
}
