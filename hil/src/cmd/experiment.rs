//! `hil experiment`: the papers' tables in process.

use crate::*;

pub(crate) fn experiment(e: Experiment) -> Result<i32> {
    match e {
        Experiment::Merge { parts, out } => {
            let parts = parts
                .iter()
                .map(|p| {
                    let t = std::fs::read_to_string(p)
                        .with_context(|| format!("reading {}", p.display()))?;
                    serde_json::from_str::<hil::montecarlo::McPart>(&t)
                        .with_context(|| format!("{} is not a Monte Carlo part", p.display()))
                })
                .collect::<Result<Vec<_>>>()?;
            let out = out.unwrap_or_else(|| default_out("experiment-north-finding"));
            let r = hil::montecarlo::merge(&parts, &out, true)?;
            print!("{}", hil::montecarlo::text(&r));
            println!(" files: {}", out.display());
            Ok(if r.within_1_2 { 0 } else { 1 })
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
            let o = hil::montecarlo::McOptions {
                runs,
                dwell_s: dwell,
                latitude_deg: lat,
                seed,
                ..Default::default()
            };
            if let Some((k, n)) = shard {
                let part = hil::montecarlo::run_part(&o, k, n)?;
                std::fs::create_dir_all(&out)
                    .with_context(|| format!("creating {}", out.display()))?;
                let f = out.join(format!("part-{k}-of-{n}.json"));
                std::fs::write(&f, serde_json::to_string(&part)?)
                    .with_context(|| format!("writing {}", f.display()))?;
                println!(
                    "part {k} of {n}: {} drills; merge all parts with `hil experiment merge`: {}",
                    part.outcomes.len(),
                    f.display()
                );
                return Ok(0);
            }
            let r = hil::montecarlo::north_finding(&o, &out, true)?;
            print!("{}", hil::montecarlo::text(&r));
            println!(" files: {}", out.display());
            Ok(if r.within_1_2 { 0 } else { 1 })
        }
        Experiment::Navigation {
            scenario,
            runs,
            misspecified,
            out,
        } => {
            let s = Scenario::load(&scenario)?;
            if runs == 0 || misspecified.iter().any(|x| x.is_nan() || *x <= 0.0) {
                bail!("--runs must be positive and every --misspecified sigma positive");
            }
            let out = out.unwrap_or_else(|| default_out("experiment-navigation"));
            let o = hil::navexp::NavExpOptions {
                scenario: s,
                runs,
                misspecified_sigma_m: misspecified,
                outage_s: (60.0, 180.0),
                threads: hil::par::threads(),
            };
            let r = hil::navexp::run(&o, Some(&out), true)?;
            print!("{}", hil::navexp::text(&r));
            println!(" files: {}", out.display());
            Ok(
                if r.pure_km_class && r.filters_within_paper && r.fading_no_worse_overstated {
                    0
                } else {
                    1
                },
            )
        }
        Experiment::Coning {
            out,
            duration,
            sweep_step,
            seed,
        } => {
            if !(duration > 1.0 && sweep_step > 0.0) {
                bail!("--duration must exceed 1 s and --sweep-step be positive");
            }
            let out = out.unwrap_or_else(|| default_out("experiment-coning"));
            let mut opts = hil::experiment::ConingOptions {
                duration_s: duration,
                sweep_step_hz: sweep_step,
                ..Default::default()
            };
            opts.imu.seed = seed;
            let r = hil::experiment::coning(&opts, &out, true)?;
            print!("{}", hil::experiment::text(&r));
            println!(" files: {}", out.display());
            Ok(
                if r.ours_10x_below_paper_alg3 && r.ours_worse_than_alg2_at.is_empty() {
                    0
                } else {
                    1
                },
            )
        }
    }
}
