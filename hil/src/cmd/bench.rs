//! `hil bench`: the benchmark suite, where vcan is (natively, or all of it in the guest).

use crate::cmd::args::BusArgs;
use crate::cmd::guest::{absolute, default_out, run_in_guest, same_command};
use anyhow::{Context, Result, bail};
use hil::run::{run_here, sibling_binary};
use hil::scenario::Scenario;
use hil::suites::benchmarks::{BusPace, Suite};
use std::path::{Path, PathBuf};
use vcan_setup::GUEST_ENV;

#[derive(clap::Args, Clone)]
pub(crate) struct BenchArgs {
    /// Seconds of 2 kHz IMU data per pass of the in-process figures.
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 120.0)]
    pub(crate) seconds: f64,
    /// Passes of nav's front end (the best is reported).
    #[arg(long, default_value_t = 3)]
    pub(crate) passes: u32,
    /// Scenario files (default: the shipped ones under scenarios/; the bus part adds the drill).
    #[arg(long)]
    pub(crate) scenario: Vec<PathBuf>,
    /// Simulated seconds of each scenario through the bus (its first seconds).
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 30.0)]
    pub(crate) bus_seconds: f64,
    /// Frames per raw vcan measurement.
    #[arg(long, default_value_t = 200_000)]
    pub(crate) raw_frames: u64,
    /// In-process figures only: no bus, no guest.
    #[arg(long)]
    pub(crate) no_bus: bool,
    #[command(flatten)]
    pub(crate) bus: BusArgs,
}

pub(crate) fn bench(a: BenchArgs) -> Result<i32> {
    if a.seconds.is_nan() || a.seconds <= 0.1 || a.bus_seconds.is_nan() || a.bus_seconds < 1.0 {
        bail!("--seconds must exceed 0.1 and --bus-seconds be at least 1");
    }
    let out = absolute(&a.bus.out.clone().unwrap_or_else(|| default_out("bench")))?;
    let files = scenario_files(&a.scenario)?;
    let in_guest = std::env::var_os(GUEST_ENV).is_some();
    let here = a.no_bus || a.bus.here();
    if !here {
        return bench_in_guest(&a, &out);
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let scenarios = files
        .iter()
        .map(|f| Scenario::load(f))
        .collect::<Result<Vec<_>>>()?;
    let say = |line: String| {
        if !a.bus.json {
            eprintln!("{line}");
        }
    };
    let mut suite = Suite::new(if in_guest { "vm" } else { "native" });
    for s in &scenarios {
        let r = hil::suites::benchmarks::emulators(s, a.seconds.min(s.duration_s));
        say(format!(
            "hil bench: emulators of {}: x{:.1}",
            r.scenario, r.speed_factor
        ));
        suite.emulators.push(r);
    }
    suite.front_end = Some(hil::suites::benchmarks::frontend(a.seconds, a.passes)?);
    say("hil bench: nav's front end timed".into());
    if let Some(s) = scenarios
        .iter()
        .find(|s| s.gps.is_some() && s.drive.is_some() && s.turntable.is_none())
    {
        let r = hil::suites::benchmarks::pipeline_drive(s, a.seconds)?;
        say(format!(
            "hil bench: nav's pipeline on {}: x{:.1}",
            r.scenario, r.speed_factor
        ));
        suite.pipeline = Some(r);
    }
    if !a.no_bus {
        vcan_setup::ensure_vcan(&a.bus.iface)?;
        for per_write in [1, wire::BATCH] {
            let r = hil::suites::benchmarks::raw_vcan(&a.bus.iface, a.raw_frames, per_write)?;
            say(format!(
                "hil bench: raw vcan, {per_write} frame(s) per write: {:.0} frames/s",
                r.frames_per_second
            ));
            suite.raw_vcan.push(r);
        }
        let nav_bin = sibling_binary("nav")?;
        let mut bus_scenarios: Vec<Scenario> = scenarios.clone();
        if a.scenario.is_empty() {
            bus_scenarios.push(hil::procedures::northfinding::scenario(
                359.97, -33.92, 10.0, 7,
            ));
        }
        for mut s in bus_scenarios {
            s.duration_s = s.duration_s.min(a.bus_seconds);
            s.speed = 100.0;
            let opts = hil::run::RunOptions::new(
                &a.bus.iface,
                out.join(format!("bus-{}", s.name)),
                nav_bin.clone(),
            );
            let r = run_here(&s, &opts, if in_guest { "vm" } else { "native" })
                .with_context(|| format!("{} through the bus", s.name))?;
            let p = BusPace::of(&r, suite.raw_limit());
            say(format!(
                "hil bench: {} through the bus: x{:.1}, {} lost",
                p.scenario, p.pace_reached, p.lost
            ));
            suite.bus.push(p);
        }
    }
    let md = hil::suites::benchmarks::markdown(&suite);
    std::fs::write(
        out.join("bench.json"),
        serde_json::to_string_pretty(&suite)?,
    )?;
    std::fs::write(out.join("bench.md"), &md)?;
    hil::report::page::folder_page(&out, "Pace benchmark (hil bench)", &md)?;
    if a.bus.json {
        println!("{}", serde_json::to_string_pretty(&suite)?);
    } else {
        print!("{md}");
        println!(" files: {}", out.join("bench.md").display());
    }
    Ok(0)
}

/// The whole benchmark again inside the QEMU guest, with the same arguments.
fn bench_in_guest(a: &BenchArgs, out: &Path) -> Result<i32> {
    let (args, extra) = same_command(&[("out", out.to_string_lossy().into_owned())], &[])?;
    run_in_guest(
        args,
        out,
        extra,
        vec![hil::run::sibling_binary("nav")?],
        a.bus.json.then_some("bench.json"),
    )
}

/// The scenario files given, or the shipped ones under scenarios/.
fn scenario_files(given: &[PathBuf]) -> Result<Vec<PathBuf>> {
    if given.is_empty() {
        Scenario::shipped_files()
    } else {
        Ok(given.to_vec())
    }
}
