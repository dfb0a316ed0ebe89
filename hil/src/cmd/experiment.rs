//! `hil experiment`: the papers' tables in process.

use crate::*;

pub(crate) fn experiment(e: Experiment) -> Result<i32> {
    match e {
        Experiment::Merge { parts, out } => {
            let kind = hil::experiments::shard::experiment_of(&parts[0])?;
            let out = out.unwrap_or_else(|| default_out(&format!("experiment-{kind}")));
            match kind.as_str() {
                hil::experiments::northfinding::EXPERIMENT => {
                    let r = hil::experiments::northfinding::merge(
                        &hil::experiments::shard::read(&parts)?,
                        &out,
                        true,
                    )?;
                    print!("{}", hil::experiments::northfinding::text(&r));
                    println!(" files: {}", out.display());
                    Ok(if r.within_1_2 { 0 } else { 1 })
                }
                hil::experiments::navigation::EXPERIMENT => {
                    let r = hil::experiments::navigation::merge(
                        &hil::experiments::shard::read(&parts)?,
                        Some(&out),
                    )?;
                    print!("{}", hil::experiments::navigation::text(&r));
                    println!(" files: {}", out.display());
                    Ok(navigation_status(&r))
                }
                hil::experiments::routes::EXPERIMENT => {
                    let r = hil::experiments::routes::merge(
                        &hil::experiments::shard::read(&parts)?,
                        Some(&out),
                    )?;
                    print!("{}", hil::experiments::routes::markdown(&r));
                    println!(" files: {}", out.display());
                    Ok(routes_status(&r))
                }
                hil::experiments::coning::CONING => {
                    let r = hil::experiments::coning::coning_merge(
                        &hil::experiments::shard::read(&parts)?,
                        &out,
                    )?;
                    print!("{}", hil::experiments::coning::text(&r));
                    println!(" files: {}", out.display());
                    Ok(coning_status(&r))
                }
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
            if let Some((k, n)) = shard {
                let part = hil::experiments::northfinding::run_part(&o, k, n)?;
                return written(&part, &out);
            }
            let r = hil::experiments::northfinding::north_finding(&o, &out, true)?;
            print!("{}", hil::experiments::northfinding::text(&r));
            println!(" files: {}", out.display());
            Ok(if r.within_1_2 { 0 } else { 1 })
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
            if let Some((k, n)) = shard {
                let part = hil::experiments::navigation::run_part(&o, k, n, true)?;
                return written(&part, &out);
            }
            let r = hil::experiments::navigation::run(&o, Some(&out), true)?;
            print!("{}", hil::experiments::navigation::text(&r));
            println!(" files: {}", out.display());
            Ok(navigation_status(&r))
        }
        Experiment::Routes {
            scenario,
            runs,
            filters,
            shard,
            out,
        } => {
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
            let o = hil::experiments::routes::RoutesOptions {
                scenarios,
                runs,
                kinds,
                threads: hil::par::threads(),
            };
            let out = out.unwrap_or_else(|| default_out("experiment-routes"));
            if let Some((k, n)) = shard {
                let part = hil::experiments::routes::run_part(&o, k, n, true)?;
                return written(&part, &out);
            }
            let r = hil::experiments::routes::run(&o, Some(&out), true)?;
            print!("{}", hil::experiments::routes::markdown(&r));
            println!(" files: {}", out.display());
            Ok(routes_status(&r))
        }
        Experiment::Calibration {
            runs,
            seed,
            duration,
            lat,
            heading,
            inner_delay,
            out,
        } => {
            let ok = |x: f64, lo: f64, hi: f64| (lo..=hi).contains(&x);
            if runs == 0
                || !ok(duration, 20.0, 1e6)
                || !ok(lat, -89.0, 89.0)
                || !ok(inner_delay, 0.0, 1e6)
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
            if let Some((k, n)) = shard {
                let part = hil::experiments::coning::coning_part(&opts, k, n, true)?;
                return written(&part, &out);
            }
            let r = hil::experiments::coning::coning(&opts, &out, true)?;
            print!("{}", hil::experiments::coning::text(&r));
            println!(" files: {}", out.display());
            Ok(coning_status(&r))
        }
    }
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

/// The navigation experiment's exit status: 0 when it meets its targets.
fn navigation_status(r: &hil::experiments::navigation::NavExperiment) -> i32 {
    if r.pure_km_class
        && r.filters_within_paper
        && r.fading_no_worse_overstated
        && r.beats_standard_by_paper_margin
    {
        0
    } else {
        1
    }
}

/// The coning experiment's exit status: 0 when it meets its targets.
fn coning_status(r: &hil::experiments::coning::ConingReport) -> i32 {
    if r.ours_10x_below_paper_alg3 && r.ours_worse_than_alg2_at.is_empty() {
        0
    } else {
        1
    }
}

/// The routes experiment's exit status: 0 when every filter is consistent on every route, no
/// velocity error went unflagged and no fix was rejected in a filter's first minute.
fn routes_status(r: &hil::experiments::routes::RoutesReport) -> i32 {
    let clean_starts = r.rows.iter().all(|x| x.rejected_first_minute == 0);
    if r.all_consistent && r.no_unflagged_velocity_errors && clean_starts {
        0
    } else {
        1
    }
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
