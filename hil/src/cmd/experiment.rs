//! `hil experiment`: the papers' tables in process.

use crate::*;
use hil::experiments::Experiment as Exp;
use hil::experiments::coning::ConingTables;
use hil::experiments::navigation::Navigation;
use hil::experiments::northfinding::NorthFindingMc;
use hil::experiments::routes::Routes;

pub(crate) fn experiment(e: Experiment) -> Result<i32> {
    match e {
        Experiment::Merge { parts, out } => {
            let kind = hil::experiments::shard::experiment_of(&parts[0])?;
            let out = out.unwrap_or_else(|| default_out(&format!("experiment-{kind}")));
            match kind.as_str() {
                NorthFindingMc::NAME => merged::<NorthFindingMc>(&parts, &out),
                Navigation::NAME => merged::<Navigation>(&parts, &out),
                Routes::NAME => merged::<Routes>(&parts, &out),
                ConingTables::NAME => merged::<ConingTables>(&parts, &out),
                other => bail!(
                    "{}: parts of a `{other}` experiment cannot be merged",
                    parts[0].display()
                ),
            }
        }
        Experiment::NorthFinding {
            runs,
            dwell,
            lat,
            seed,
            shard,
            out,
        } => {
            if runs == 0 || dwell.is_nan() || dwell < 2.0 {
                bail!("--runs must be positive and --dwell at least 2 s");
            }
            let out = out.unwrap_or_else(|| default_out("experiment-north-finding"));
            let o = hil::experiments::northfinding::McOptions {
                runs,
                dwell_s: dwell,
                latitude_deg: lat,
                seed,
                ..Default::default()
            };
            run_or_part::<NorthFindingMc>(&o, shard, &out)
        }
        Experiment::Navigation {
            scenario,
            runs,
            misspecified,
            environment,
            shard,
            out,
        } => {
            let s = Scenario::load(&scenario)?;
            let preset: emulators::gps::errors::EnvironmentPreset = serde_json::from_value(
                serde_json::Value::String(environment.clone()),
            )
            .map_err(|_| {
                anyhow::anyhow!(
                    "--environment: `{environment}` is not a preset (paper-003, urban, open-sky)"
                )
            })?;
            if runs == 0 || misspecified.iter().any(|x| x.is_nan() || *x <= 0.0) {
                bail!("--runs must be positive and every --misspecified sigma positive");
            }
            let out = out.unwrap_or_else(|| default_out("experiment-navigation"));
            let o = hil::experiments::navigation::NavExpOptions {
                scenario: s,
                runs,
                misspecified_sigma_m: misspecified,
                outage_s: (60.0, 180.0),
                environment: emulators::gps::errors::Environment::preset(preset),
                threads: hil::par::threads(),
            };
            run_or_part::<Navigation>(&o, shard, &out)
        }
        Experiment::Routes {
            scenario,
            runs,
            filters,
            shard,
            out,
        } => {
            let o = routes_options(scenario, runs, &filters)?;
            let out = out.unwrap_or_else(|| default_out("experiment-routes"));
            run_or_part::<Routes>(&o, shard, &out)
        }
        Experiment::Calibration {
            runs,
            seed,
            duration,
            lat,
            heading,
            inner_delay,
            out,
        } => calibration(runs, seed, duration, lat, heading, inner_delay, out),
        Experiment::Coning {
            out,
            duration,
            sweep_step,
            seed,
            shard,
        } => {
            if !(duration > 1.0 && sweep_step > 0.0) {
                bail!("--duration must exceed 1 s and --sweep-step be positive");
            }
            let out = out.unwrap_or_else(|| default_out("experiment-coning"));
            let mut opts = hil::experiments::coning::ConingOptions {
                duration_s: duration,
                sweep_step_hz: sweep_step,
                ..Default::default()
            };
            opts.imu.seed = seed;
            run_or_part::<ConingTables>(&opts, shard, &out)
        }
    }
}

/// `hil experiment calibration`: papers 004 and 001 in process.
fn calibration(
    runs: usize,
    seed: u64,
    duration: f64,
    lat: f64,
    heading: f64,
    inner_delay: f64,
    out: Option<PathBuf>,
) -> Result<i32> {
    let ok = |x: f64, lo: f64, hi: f64| (lo..=hi).contains(&x);
    if runs == 0 || !ok(duration, 20.0, 1e6) || !ok(lat, -89.0, 89.0) || !ok(inner_delay, 0.0, 1e6)
    {
        bail!(
            "--runs must be positive, --duration at least 20 s, |--lat| at most 89 deg and --inner-delay not negative"
        );
    }
    let out = out.unwrap_or_else(|| default_out("experiment-calibration"));
    let defaults = hil::experiments::calibration::CalibOptions::default();
    let o = hil::experiments::calibration::CalibOptions {
        runs,
        seed,
        duration_s: duration,
        score_from_s: duration / 2.0,
        lat_deg: lat,
        heading_deg: heading,
        inner_delay_s: inner_delay,
        coarse_heading_deg: heading - (defaults.heading_deg - defaults.coarse_heading_deg),
        ..defaults
    };
    let r = hil::experiments::calibration::calibration(&o, Some(&out), true)?;
    print!("{}", hil::experiments::calibration::markdown(&r));
    println!(" files: {}", out.display());
    let tetra_ok = r.tetra.first().is_some_and(|t| t.meets_paper);
    Ok(if r.meets_paper && tetra_ok { 0 } else { 1 })
}

/// The routes experiment's options from its arguments: the scenarios (every shipped route when
/// none is given) and the filter kinds.
fn routes_options(
    scenario: Vec<PathBuf>,
    runs: usize,
    filters: &[String],
) -> Result<hil::experiments::routes::RoutesOptions> {
    let files = if scenario.is_empty() {
        shipped_routes()?
    } else {
        scenario
    };
    let scenarios = files
        .iter()
        .map(|f| Scenario::load(f))
        .collect::<Result<Vec<_>>>()?;
    let kinds = filters
        .iter()
        .map(|f| {
            serde_json::from_value::<nav::kf::FilterKind>(serde_json::Value::String(
                f.trim().to_string(),
            ))
            .map_err(|_| {
                anyhow::anyhow!(
                    "--filters: `{f}` is not a filter kind (standard, fading, adaptive)"
                )
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(hil::experiments::routes::RoutesOptions {
        scenarios,
        runs,
        kinds,
        threads: hil::par::threads(),
    })
}

/// Runs experiment `E` whole (its report printed; exit status 0 when it meets its targets), or
/// only part `shard` of it.
fn run_or_part<E: Exp>(o: &E::Options, shard: Option<(usize, usize)>, out: &Path) -> Result<i32> {
    if let Some((k, n)) = shard {
        return written(&E::part(o, k, n, true)?, out);
    }
    let r = E::run(o, out, true)?;
    printed::<E>(&r, out)
}

/// Merges the parts of experiment `E` into its report.
fn merged<E: Exp>(parts: &[PathBuf], out: &Path) -> Result<i32> {
    let r = E::merge(&hil::experiments::shard::read(parts)?, out, true)?;
    printed::<E>(&r, out)
}

/// Prints experiment `E`'s report and where its files are; its exit status.
fn printed<E: Exp>(r: &E::Report, out: &Path) -> Result<i32> {
    print!("{}", E::text(r));
    println!(" files: {}", out.display());
    Ok(if E::met(r) { 0 } else { 1 })
}

/// Writes one part of an experiment and says how to merge the parts.
fn written<T: serde::Serialize>(
    part: &hil::experiments::shard::Part<T>,
    out: &Path,
) -> Result<i32> {
    let f = hil::experiments::shard::write(part, out)?;
    println!(
        "part {} of {}: {} runs; merge all parts with `hil experiment merge`: {}",
        part.shard,
        part.shards,
        part.outcomes.len(),
        f.display()
    );
    Ok(0)
}

/// The shipped scenarios that are routes: a drive with a receiver.
fn shipped_routes() -> Result<Vec<PathBuf>> {
    let mut v = Vec::new();
    for p in Scenario::shipped_files()? {
        let s = Scenario::load(&p)?;
        if s.drive.is_some() && s.gps.is_some() {
            v.push(p);
        }
    }
    Ok(v)
}
