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

pub(crate) fn drill_north_finding(a: NorthFindingArgs) -> Result<i32> {
    let heading = match a.heading {
        Some(h) => h.rem_euclid(360.0),
        // random, reproducible from the seed (the same generator as the Monte Carlo)
        None => {
            use rand::{Rng, SeedableRng};
            rand::rngs::StdRng::seed_from_u64(a.seed).random::<f64>() * 360.0
        }
    };
    let mut s = hil::procedures::northfinding::scenario(heading, a.lat, a.dwell, a.seed);
    s.speed = a.speed;
    s.site.lon_deg = a.lon;
    s.heading_tolerance_deg = a.tolerance;
    if let Some(p) = &a.disturbances {
        let text = std::fs::read_to_string(p)
            .with_context(|| format!("cannot read disturbance script {}", p.display()))?;
        let d: DisturbanceScript =
            toml::from_str(&text).with_context(|| format!("disturbance script {}", p.display()))?;
        s.disturbance = d.disturbance;
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
        heading, a.lat, a.dwell, a.speed
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
