//! `hil experiment`: the papers' tables in process.

use crate::cmd::guest::default_out;
use anyhow::{Context, Result, bail};
use clap::Subcommand;
use hil::experiments::Experiment as Exp;
use hil::experiments::coning::ConingTables;
use hil::experiments::navigation::Navigation;
use hil::experiments::north_finding_mc::NorthFindingMc;
use hil::experiments::routes::Routes;
use hil::scenario::Scenario;
use std::path::{Path, PathBuf};

#[derive(Subcommand)]
pub(crate) enum Experiment {
    /// Monte Carlo of four-position north-finding in process: heading error RMS against the
    /// bound ARW / (W_ie cos L sqrt(T)), gyro bias effect, other latitudes, drill time against
    /// accuracy. Writes runs.csv, report.json and report.md.
    NorthFinding {
        /// Runs of the main cases (the other cases run a third as many).
        #[arg(long, value_parser = hil::values::count, default_value_t = 100)]
        runs: usize,
        /// Dwell per position of the main cases, s.
        #[arg(long, value_parser = hil::values::duration_s, default_value_t = 60.0)]
        dwell: f64,
        /// Main latitude, deg.
        #[arg(long, value_parser = hil::values::latitude_deg, allow_negative_numbers = true, default_value_t = 28.2)]
        lat: f64,
        /// Base seed.
        #[arg(long, default_value_t = 1000)]
        seed: u64,
        /// Run only part K of N (0-based, `K/N`): the drills whose place in the plan is K modulo
        /// N. Writes part-K-of-N.json to the output folder; `hil experiment merge` makes the
        /// report of all parts (e.g. the tasks of a Slurm array or a Kubernetes indexed Job).
        #[arg(long, value_parser = hil::experiments::shard::parse)]
        shard: Option<(usize, usize)>,
        /// Output folder (default runs/experiment-north-finding-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Merge the parts of an experiment run in parts (`--shard K/N`) into its report: the same
    /// tables a single run gives.
    Merge {
        /// The part files (part-K-of-N.json), every K once.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Output folder (default runs/experiment-<name>-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Paper 003, Table 4 in process: the campus loop (north-finding first, then six laps of
    /// about 1 km, 1342 s) with pure INS, the standard and the fading-memory filter; the filters
    /// with a mis-specified GPS noise; 60 s outages every 180 s with the drift at the end of each;
    /// NEES. Writes report.md/json, series.csv and SVG plots. Use a release build (about a
    /// minute per run and core).
    Navigation {
        /// Scenario (a drive with a [gps]).
        #[arg(long, default_value = "scenarios/campus-loop.toml")]
        scenario: PathBuf,
        /// Runs per case with other IMU and GPS seeds (results are averaged).
        #[arg(long, value_parser = hil::values::count, default_value_t = 1)]
        runs: usize,
        /// GPS noise the mis-specified filters assume, m (comma-separated).
        #[arg(long, value_parser = hil::values::sigma_m, value_delimiter = ',', default_value = "5,100")]
        misspecified: Vec<f64>,
        /// Surroundings of the mis-modelled receiver: `paper-003` (paper 003's campus: the
        /// satellites used change, multipath bursts), `urban` or `open-sky`.
        #[arg(long, default_value = "paper-003")]
        environment: String,
        /// Run only part K of N (0-based, `K/N`): the runs whose place in the plan is K modulo
        /// N. Writes part-K-of-N.json to the output folder; `hil experiment merge` makes the
        /// report of all parts.
        #[arg(long, value_parser = hil::experiments::shard::parse)]
        shard: Option<(usize, usize)>,
        /// Output folder (default runs/experiment-navigation-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// The filters over a set of routes in process, with nav's default config: end and RMS
    /// position and velocity error, NEES per degree of freedom over the drive and in each ten
    /// minutes (target [0.5, 2]) and inside and after each outage (at most 2), NIS, rejected
    /// fixes (none in a filter's first minute, no good fix ever) and integrity alarms per route
    /// and filter mode (feedback and output correction); plots of the errors against the
    /// filters' 3-sigma bounds. Writes report.md/json and SVGs; exit status 1 when a target is
    /// missed. Use a release build (the 14 level routes, three of them an hour long, `--runs 16`
    /// as docs/navigation-results.md takes its verdict on: 29 minutes on 2 cores for the three
    /// feedback filters, twice that with the output-corrected three; the roads of
    /// docs/routes.md besides, one of them a highway of 2.3 hours).
    Routes {
        /// Route scenarios (drives with a [gps]); default: every shipped one under scenarios/.
        #[arg(long)]
        scenario: Vec<PathBuf>,
        /// Runs per route and filter with other IMU and receiver seeds (results are averaged).
        #[arg(long, value_parser = hil::values::count, default_value_t = 1)]
        runs: usize,
        /// Filters (comma-separated): a kind (standard, fading, adaptive) with feedback, nav's
        /// default, or KIND/output for paper 003's output correction; default: every mode nav
        /// offers.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "standard,fading,adaptive,standard/output,fading/output,adaptive/output"
        )]
        filters: Vec<String>,
        /// Run only part K of N (0-based, `K/N`); `hil experiment merge` makes the report.
        #[arg(long, value_parser = hil::experiments::shard::parse)]
        shard: Option<(usize, usize)>,
        /// Output folder (default runs/experiment-routes-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Paper 004 in process: online self-calibration of the gyros of a dual-axis rotating IMU
    /// (fibre-optic gyros, 100 Hz, both axes at 5 deg/s reversing every turn) by the paper's
    /// decoupled recursive least squares against a 14-state alignment Kalman filter: mean
    /// absolute bias and scale-factor errors over the second half, the ratio of the two methods
    /// beside the paper's, median over the runs. Then paper 001: a redundant MEMS IMU (four gyros,
    /// tetrahedral) on a three-axis table, its 16-state Kalman calibration against the
    /// six-position method, at the paper's and at realistic noise. Writes report.md/json/html
    /// and gyro-parameters.toml. Exit status 0 when both papers' targets are met. Use a release
    /// build.
    Calibration {
        /// Runs (seeds).
        #[arg(long, value_parser = hil::values::count, default_value_t = 20)]
        runs: usize,
        /// First seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Run length, s (errors are averaged over its second half).
        #[arg(long, value_parser = hil::values::duration_s, default_value_t = 900.0)]
        duration: f64,
        /// Latitude, deg.
        #[arg(long, value_parser = hil::values::latitude_deg, default_value_t = 30.0, allow_negative_numbers = true)]
        lat: f64,
        /// True heading, deg (the estimators are given it less 0.06 deg).
        #[arg(long, value_parser = hil::values::heading_deg, default_value_t = 30.06, allow_negative_numbers = true)]
        heading: f64,
        /// Start the inner axis this long after the outer, s. The paper does not say how its
        /// axes are phased: a quarter turn (18 s at 5 deg/s, the default) averages the coarse
        /// tilt out of the z gyro's bias; 0 turns them in step.
        #[arg(long, value_parser = hil::values::pause_s, default_value_t = 18.0)]
        inner_delay: f64,
        /// Output folder (default runs/experiment-calibration-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Paper 000, Tables 1-3: coning drift of the classical, Taylor-tuned and fitted
    /// algorithms on filtered data; writes CSV, JSON, Markdown and an SVG plot.
    Coning {
        /// Output folder (default runs/experiment-coning-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Run length for the tables, s.
        #[arg(long, value_parser = hil::values::duration_s, default_value_t = 60.0)]
        duration: f64,
        /// Step of the simulated frequency sweep, Hz.
        #[arg(long, value_parser = hil::values::step_hz, default_value_t = 2.0)]
        sweep_step: f64,
        /// Seed of the emulated IMU (Table 3 analogue).
        #[arg(long, default_value_t = 7)]
        seed: u64,
        /// Run only part K of N (0-based, `K/N`): the table rows whose place in the plan is K
        /// modulo N. Writes part-K-of-N.json to the output folder; `hil experiment merge`
        /// makes the report of all parts.
        #[arg(long, value_parser = hil::experiments::shard::parse)]
        shard: Option<(usize, usize)>,
    },
}

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
            let o = hil::experiments::north_finding_mc::McOptions {
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
        } => navigation(&scenario, runs, misspecified, &environment, shard, out),
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

/// `hil experiment navigation`: paper 003's vehicle test in process.
fn navigation(
    scenario: &Path,
    runs: usize,
    misspecified: Vec<f64>,
    environment: &str,
    shard: Option<(usize, usize)>,
    out: Option<PathBuf>,
) -> Result<i32> {
    let s = Scenario::load(scenario)?;
    let preset: emulators::gps::errors::EnvironmentPreset = serde_json::from_value(
        serde_json::Value::String(environment.to_string()),
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
    let modes = filters
        .iter()
        .map(|f| f.parse().context("--filters"))
        .collect::<Result<Vec<hil::experiments::routes::Mode>>>()?;
    Ok(hil::experiments::routes::RoutesOptions {
        scenarios,
        runs,
        modes,
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
