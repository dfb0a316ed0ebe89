//! `hil drill north-finding`: the operator drill, on the bus or in process.

use crate::*;
use cmd::run::{procedure_folder, run_procedure};

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
    if let Some(p) = cmd::plan::positions(a.positions.as_deref(), a.out_and_back) {
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
        // random, reproducible from the seed (the same generator as the Monte Carlo)
        None => {
            use rand::{Rng, SeedableRng};
            rand::rngs::StdRng::seed_from_u64(a.seed).random::<f64>() * 360.0
        }
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
