//! `hil run`: one scenario through the bench.

use crate::cmd::args::{BusArgs, FreeArgs, LiveArgs, finish_view};
use crate::cmd::guest::{absolute, as_command, default_out, run_in_guest_with_junit};
use anyhow::{Context, Result};
use hil::report;
use hil::run::{RunOptions, run_here, sibling_binary};
use hil::scenario::Scenario;
use std::path::{Path, PathBuf};
use vcan_setup::GUEST_ENV;

#[derive(clap::Args, Clone)]
pub(crate) struct RunArgs {
    /// Scenario file (TOML); default: the built-in static scenario.
    #[arg(long)]
    pub(crate) scenario: Option<PathBuf>,
    /// Override the simulated duration, s.
    #[arg(long, value_parser = hil::values::duration_s)]
    pub(crate) duration: Option<f64>,
    /// Override the speed factor (1 = real time).
    #[arg(long, value_parser = hil::values::speed)]
    pub(crate) speed: Option<f64>,
    /// The nav binary (default: next to hil).
    #[arg(long)]
    pub(crate) nav: Option<PathBuf>,
    /// Skip the checks that re-run the scenario in process and read nav's recording back (the
    /// reference run, the replay, the navigation scoring): for soaks, whose recording is too
    /// large to read back in the guest. Frame accounting, nav's exit and memory stay.
    #[arg(long)]
    pub(crate) no_reference: bool,
    /// Put gpsd between the GPS emulator's port and nav (nav's `[gps] source = "gpsd"`), as a
    /// vehicle shares one receiver; needs gpsd (./run-tests installs it).
    #[arg(long)]
    pub(crate) gpsd: bool,
    /// Also write the result as JUnit XML to FILE, for a CI server (GitLab, Jenkins, GitHub):
    /// a test case per check of the result card, failing with its detail.
    #[arg(long, value_name = "FILE")]
    pub(crate) junit: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) live: LiveArgs,
    #[command(flatten)]
    pub(crate) bus: BusArgs,
    #[command(flatten)]
    pub(crate) free: FreeArgs,
}

pub(crate) fn run(a: RunArgs) -> Result<i32> {
    let mut s = match &a.scenario {
        Some(p) => Scenario::load(p)?,
        None => Scenario::builtin_static(),
    };
    if let Some(d) = a.duration {
        s.duration_s = d;
    }
    if let Some(x) = a.speed {
        s.speed = x;
    }
    s.check()?;
    let out = absolute(&match &a.bus.out {
        Some(o) => o.clone(),
        None => default_out(&s.name),
    })?;
    let in_guest = std::env::var_os(GUEST_ENV).is_some();
    if a.free.free && a.bus.here() {
        return run_free_here(&s, &a, &out);
    }
    if a.bus.here() {
        return run_lockstep_here(&s, &a, &out, in_guest);
    }
    // No CAN here: the run inside the QEMU guest, as `hil run` with the options this command
    // was given (a drill or a calibration hands its scenario to this run: the scenario it
    // wrote), the output folder and the nav binary resolved here (another build of nav may
    // live outside the folders the guest is given: its folder is shared)
    let nav = match &a.nav {
        Some(n) => absolute(n)?,
        None => sibling_binary("nav")?,
    };
    let mut set = vec![
        ("out", out.to_string_lossy().into_owned()),
        ("nav", nav.to_string_lossy().into_owned()),
    ];
    let scenario = a.scenario.as_deref().map(absolute).transpose()?;
    if let Some(p) = &scenario {
        set.push(("scenario", p.to_string_lossy().into_owned()));
    }
    let (args, mut extra) = as_command(Some(&["run"]), &set, &["junit"])?;
    extra.extend(nav.parent().map(Path::to_path_buf));
    extra.extend(
        scenario
            .as_deref()
            .and_then(Path::parent)
            .map(Path::to_path_buf),
    );
    let code = run_in_guest_with_junit(
        args,
        &out,
        extra,
        vec![nav],
        a.bus.json.then_some("report.json"),
        a.junit.as_deref(),
    )?;
    Ok(code)
}

/// A lockstep run here, where vcan is: the card or the JSON, and the exit status.
fn run_lockstep_here(s: &Scenario, a: &RunArgs, out: &Path, in_guest: bool) -> Result<i32> {
    let nav_bin = match &a.nav {
        Some(n) => n.clone(),
        None => sibling_binary("nav")?,
    };
    let (view, own_view) = a.live.view(s.duration_s)?;
    let opts = RunOptions {
        progress: true,
        reference_checks: !a.no_reference,
        gps_via_gpsd: a.gpsd,
        live: view.clone(),
        ..RunOptions::new(&a.bus.iface, out.to_path_buf(), nav_bin)
    };
    let backend = if in_guest { "vm" } else { "native" };
    let r = run_here(s, &opts, backend);
    drop(opts);
    if let (Some(v), true) = (view, own_view) {
        finish_view(v);
    }
    let r = r?;
    if let Some(j) = &a.junit {
        write_junit(j, &format!("hil run {}", s.name), r.wall_seconds, &r.checks)?;
    }
    if a.bus.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", report::card(&r));
        println!(
            " report: {} (and report.md beside it)",
            out.join("report.html").display()
        );
    }
    Ok(if r.pass { 0 } else { 1 })
}

/// `--junit`: the run's checks, a test case each.
fn write_junit(j: &Path, name: &str, wall_s: f64, checks: &[hil::check::Check]) -> Result<()> {
    let suite = hil::junit::of_checks(
        name,
        name,
        wall_s,
        checks
            .iter()
            .map(|c| (c.name.as_str(), c.pass, c.detail.as_str())),
    );
    hil::junit::write(j, "hil run", &[suite])
}

/// A free-running run here, where vcan is: the card or the JSON, and the exit status (3: the
/// bench could not keep real time, no verdict).
fn run_free_here(s: &Scenario, a: &RunArgs, out: &Path) -> Result<i32> {
    let nav_bin = match &a.nav {
        Some(n) => n.clone(),
        None => sibling_binary("nav")?,
    };
    let r = hil::free::run_free(
        s,
        &a.free
            .options(s, &a.bus.iface, out.to_path_buf(), nav_bin)?,
    )?;
    if let Some(j) = &a.junit {
        write_junit(
            j,
            &format!("hil run --free {}", s.name),
            r.wall_s,
            &r.checks,
        )?;
    }
    if a.bus.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", hil::free::card(&r));
        println!(" report: {}", out.join("report.json").display());
    }
    Ok(match (&r.bench_behind, r.pass) {
        (Some(_), _) => 3,
        (None, true) => 0,
        (None, false) => 1,
    })
}

/// An operator procedure's run folder (`out`, or `runs/<name>-<time>`), with the scenario
/// written in it as `file` (what the run is repeated from).
pub(crate) fn procedure_folder(
    s: &Scenario,
    out: Option<&Path>,
    name: &str,
    file: &str,
) -> Result<(PathBuf, PathBuf)> {
    let out = absolute(&out.map_or_else(|| default_out(name), Path::to_path_buf))?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let scen = out.join(file);
    std::fs::write(&scen, toml::to_string_pretty(s)?)?;
    Ok((out, scen))
}

/// An operator procedure on the bench: the scenario file `scen` through `hil run` into `out`.
pub(crate) fn run_procedure(
    scen: PathBuf,
    out: PathBuf,
    bus: BusArgs,
    live: LiveArgs,
    free: FreeArgs,
) -> Result<i32> {
    run(RunArgs {
        free,
        scenario: Some(scen),
        duration: None,
        speed: None,
        nav: None,
        no_reference: false,
        gpsd: false,
        junit: None,
        live,
        bus: BusArgs {
            out: Some(out),
            ..bus
        },
    })
}

/// An operator procedure in process: its outcome under `key` in `out/report.json`, and as JSON
/// (`json`) or its card on stdout.
pub(crate) fn report_in_process<T: serde::Serialize>(
    out: &Path,
    key: &str,
    outcome: &T,
    json: bool,
    card: impl FnOnce(&T) -> String,
) -> Result<()> {
    let j = serde_json::json!({ "in_process": true, key: outcome });
    std::fs::write(out.join("report.json"), serde_json::to_string_pretty(&j)?)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&j)?);
    } else {
        print!("{}", card(outcome));
    }
    Ok(())
}
