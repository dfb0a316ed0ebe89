//! `hil`: the bench command line.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use hil::report;
use hil::run::{RunOptions, run_here, sibling_binary};
use hil::scenario::Scenario;
use std::path::{Path, PathBuf};
use vcan_setup::{CanSupport, GUEST_ENV, VmOptions};

#[derive(Parser)]
#[command(
    version,
    about = "Hardware-in-the-loop bench for the RLG strapdown INS",
    long_about = "Hardware-in-the-loop bench \
for the RLG strapdown INS. Emulators drive a real Linux vcan interface; the production nav binary reads it as it \
would read can0 on a vehicle. Where this kernel has no CAN, runs go through a QEMU guest automatically."
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run a scenario on vcan: emulators + nav, then checks, a result card and a report.
    Run(RunArgs),
    /// The main job: a four-position north-finding drill at the paper's start point with a random
    /// true heading, then a short GPS-aided drive (one 1 km lap with the NMEA receiver on a pty),
    /// each with its result card and report, and a summary of both.
    Demo {
        /// Speed factor (1 = real time: about 4.5 minutes of drill and 2 of driving).
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
        /// Dwell per position, s.
        #[arg(long, default_value_t = 60.0)]
        dwell: f64,
        /// Output folder (default runs/drill-north-finding-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Replay a nav recording through nav's pipeline in process and compare what it sends with
    /// what nav sent (bit for bit on a bench recording). Exit status 1 when they differ.
    Replay {
        /// A run folder (with nav.mcap and nav.toml) or an MCAP recording of nav.
        recording: PathBuf,
        /// nav's config for the recording (default: nav.toml beside it).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print the result as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Print the bus-load table of the wire contract.
    Busload {
        /// Bit rate, bit/s.
        #[arg(long, default_value_t = 1_000_000.0)]
        bitrate: f64,
    },
    /// Print the DBC file of the wire contract.
    Dbc,
    /// Validation suites against a device on a CAN interface (the emulator or real hardware).
    #[command(subcommand)]
    Validate(Validate),
    /// Operator drills on vcan (emulators + the production nav binary).
    #[command(subcommand)]
    Drill(Drill),
    /// Reproduce a paper's tables in process (same emulator and nav code as the bench).
    #[command(subcommand)]
    Experiment(Experiment),
    /// Benchmark nav's IMU front end (decode, dither filter, coning, attitude) and each
    /// scenario's emulators (truth, sensor model, encoding) on one core, in process.
    Bench {
        /// Seconds of 2 kHz IMU data per pass.
        #[arg(long, default_value_t = 120.0)]
        seconds: f64,
        /// Passes (the best is reported).
        #[arg(long, default_value_t = 3)]
        passes: u32,
        /// Scenario files whose emulators to time (default: the shipped ones under scenarios/).
        #[arg(long)]
        scenario: Vec<PathBuf>,
    },
}

#[derive(Subcommand)]
enum Validate {
    /// The indexing mechanism: index accuracy and settle time at each detent, lock engagement,
    /// zero return, rate-mode accuracy and stability, rejection of invalid commands, heartbeat
    /// timeout stop, emergency stop. Prints a pass/fail table and writes validation.json.
    Turntable(ValidateArgs),
}

/// Faults the emulated mechanism can be given for validation.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum TtFault {
    /// The motor stalls on the first move.
    Stall,
    /// The lock pin never engages.
    Lock,
    /// The encoder reports glitched angles now and then.
    EncoderGlitch,
    /// The enable command is lost.
    LostCommands,
    /// Every command takes 0.2 s to act and be acknowledged.
    DelayedCommands,
}

/// What every bench command on vcan takes: where, where to write, how to print.
#[derive(clap::Args, Clone)]
struct BusArgs {
    /// CAN interface (on the bench created when missing).
    #[arg(long, default_value = "vcan0")]
    iface: String,
    /// Output folder (default runs/<name>-<unix time>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the report as JSON on stdout instead of the result card or table.
    #[arg(long)]
    json: bool,
    /// Always use the QEMU guest, even where this kernel has CAN.
    #[arg(long)]
    vm: bool,
}

impl BusArgs {
    /// Defaults (vcan0, no JSON, the guest only where needed) writing to `out`.
    fn to(out: PathBuf) -> Self {
        Self {
            iface: "vcan0".into(),
            out: Some(out),
            json: false,
            vm: false,
        }
    }
}

#[derive(clap::Args, Clone)]
struct ValidateArgs {
    /// Axis to test.
    #[arg(long, default_value_t = 0)]
    axis: u8,
    /// Test real hardware on --iface: do not start the emulator.
    #[arg(long)]
    real: bool,
    /// Inject a fault into the emulated mechanism (the suite must catch it).
    #[arg(long, value_enum)]
    fault: Option<TtFault>,
    /// Speed factor of the emulated mechanism.
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    #[command(flatten)]
    bus: BusArgs,
}

#[derive(Subcommand)]
enum Drill {
    /// Four-position north-finding: the vehicle is parked at a given or random heading; nav
    /// indexes the IMU through 0/90/180/270 deg on the turntable, finds north, returns to zero
    /// and locks. Live progress, then a result card; the run is saved with its report.
    NorthFinding(NorthFindingArgs),
}

#[derive(clap::Args, Clone)]
struct NorthFindingArgs {
    /// True heading of the vehicle, deg (default: random).
    #[arg(long)]
    heading: Option<f64>,
    /// Latitude, deg.
    #[arg(long, default_value_t = 28.218157)]
    lat: f64,
    /// Dwell per position, s.
    #[arg(long, default_value_t = 60.0)]
    dwell: f64,
    /// Speed factor (1 = real time, as on the vehicle).
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Disturbance script: TOML file with [[disturbance]] entries (door_slam, climb_in, wind).
    #[arg(long)]
    disturbances: Option<PathBuf>,
    /// Pass when the heading error is within this, deg.
    #[arg(long, default_value_t = 0.1)]
    tolerance: f64,
    /// Random seed (sensor errors, random heading).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Run the same drill in process (no bus, no nav process: the same emulators and nav code,
    /// stepped in the order the bench delivers the frames); its result equals the bench's.
    #[arg(long)]
    in_process: bool,
    #[command(flatten)]
    bus: BusArgs,
}

#[derive(Subcommand)]
enum Experiment {
    /// Monte Carlo of four-position north-finding in process: heading error RMS against the
    /// bound ARW / (W_ie cos L sqrt(T)), gyro bias effect, other latitudes, drill time against
    /// accuracy. Writes runs.csv, report.json and report.md.
    NorthFinding {
        /// Runs of the main cases (the other cases run a third as many).
        #[arg(long, default_value_t = 100)]
        runs: usize,
        /// Dwell per position of the main cases, s.
        #[arg(long, default_value_t = 60.0)]
        dwell: f64,
        /// Main latitude, deg.
        #[arg(long, default_value_t = 28.2)]
        lat: f64,
        /// Base seed.
        #[arg(long, default_value_t = 1000)]
        seed: u64,
        /// Run only part K of N (0-based, `K/N`): the drills whose place in the plan is K modulo
        /// N. Writes part-K-of-N.json to the output folder; `hil experiment merge` makes the
        /// report of all parts (e.g. the tasks of a Slurm array or a Kubernetes indexed Job).
        #[arg(long, value_parser = parse_shard)]
        shard: Option<(usize, usize)>,
        /// Output folder (default runs/experiment-north-finding-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Merge the parts of a sharded north-finding Monte Carlo (`--shard K/N`) into its report:
    /// the same tables a single run gives.
    Merge {
        /// The part files (part-K-of-N.json), every K once.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Output folder (default runs/experiment-north-finding-<unix time>).
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
        #[arg(long, default_value_t = 1)]
        runs: usize,
        /// GPS noise the mis-specified filters assume, m (comma-separated).
        #[arg(long, value_delimiter = ',', default_value = "5,100")]
        misspecified: Vec<f64>,
        /// Output folder (default runs/experiment-navigation-<unix time>).
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
        #[arg(long, default_value_t = 60.0)]
        duration: f64,
        /// Step of the simulated frequency sweep, Hz.
        #[arg(long, default_value_t = 2.0)]
        sweep_step: f64,
        /// Seed of the emulated IMU (Table 3 analogue).
        #[arg(long, default_value_t = 7)]
        seed: u64,
    },
}

#[derive(clap::Args, Clone)]
struct RunArgs {
    /// Scenario file (TOML); default: the built-in static scenario.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Override the simulated duration, s.
    #[arg(long)]
    duration: Option<f64>,
    /// Override the speed factor (1 = real time).
    #[arg(long)]
    speed: Option<f64>,
    /// The nav binary (default: next to hil).
    #[arg(long)]
    nav: Option<PathBuf>,
    #[command(flatten)]
    bus: BusArgs,
}

fn main() {
    nav::cli::init_tracing();
    // exit 0: pass, 1: a check failed or the run could not go on
    std::process::exit(nav::cli::exit_code("hil", real_main(), |code| code));
}

fn real_main() -> Result<i32> {
    match Cli::parse().cmd {
        Cmd::Run(a) => run(a),
        Cmd::Demo { speed, dwell, out } => demo(speed, dwell, out),
        Cmd::Drill(Drill::NorthFinding(a)) => drill_north_finding(a),
        Cmd::Validate(Validate::Turntable(a)) => validate_turntable(a),
        Cmd::Busload { bitrate } => {
            print!("{}", wire::busload::report(bitrate));
            Ok(0)
        }
        Cmd::Replay {
            recording,
            config,
            json,
        } => replay(&recording, config.as_deref(), json),
        Cmd::Dbc => {
            print!("{}", wire::DBC);
            Ok(0)
        }
        Cmd::Experiment(Experiment::Merge { parts, out }) => {
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
        Cmd::Experiment(Experiment::NorthFinding {
            runs,
            dwell,
            lat,
            seed,
            shard,
            out,
        }) => {
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
        Cmd::Experiment(Experiment::Navigation {
            scenario,
            runs,
            misspecified,
            out,
        }) => {
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
        Cmd::Experiment(Experiment::Coning {
            out,
            duration,
            sweep_step,
            seed,
        }) => {
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
        Cmd::Bench {
            seconds,
            passes,
            scenario,
        } => {
            if seconds.is_nan() || seconds <= 0.1 {
                bail!("--seconds must exceed 0.1");
            }
            let files = if scenario.is_empty() {
                let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
                let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
                    .with_context(|| format!("listing {}", dir.display()))?
                    .filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| p.extension().is_some_and(|x| x == "toml"))
                    .collect();
                v.sort();
                v
            } else {
                scenario
            };
            println!("emulators (truth + sensor model + encoding), one core, in process:");
            for f in &files {
                let s = Scenario::load(f)?;
                let secs = seconds.min(s.duration_s);
                let r = hil::bench::emulators(&s, secs);
                println!(
                    "  {:<24} {:7.1} s simulated: x{:7.1} real time, {:.3e} frames/s",
                    r.scenario, r.seconds, r.speed_factor, r.frames_per_second
                );
            }
            let r = hil::bench::frontend(seconds, passes)?;
            println!(
                "nav front end (decode + counters + dither FIR + coning/sculling + attitude), one core, {} build:\n  {} samples ({} frames) per pass, best of {}: {:.3e} samples/s, {:.3e} frames/s",
                r.profile, r.samples, r.frames, r.passes, r.samples_per_second, r.frames_per_second
            );
            if r.profile == "debug" {
                println!(
                    "  (debug build: run `cargo run --release -p hil -- bench` for the product's figure)"
                );
            }
            Ok(0)
        }
    }
}

fn validate_turntable(a: ValidateArgs) -> Result<i32> {
    use emulators::turntable::{Turntable, TurntableFaults, TurntableParams};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    if a.speed.is_nan() || a.speed <= 0.0 || a.speed > 100.0 {
        bail!("--speed must be in (0, 100]");
    }
    let out = absolute(
        &a.bus
            .out
            .clone()
            .unwrap_or_else(|| default_out("validate-turntable")),
    )?;
    let in_guest = std::env::var_os(GUEST_ENV).is_some();
    let here = a.real
        || ((!a.bus.vm || in_guest) && matches!(vcan_setup::can_support(), CanSupport::Available));
    if !here {
        let mut args: Vec<String> = vec![
            "validate".into(),
            "turntable".into(),
            "--iface".into(),
            a.bus.iface.clone(),
            "--axis".into(),
            a.axis.to_string(),
            "--speed".into(),
            a.speed.to_string(),
            "--out".into(),
            out.to_string_lossy().into_owned(),
        ];
        if let Some(f) = a.fault {
            args.extend([
                "--fault".into(),
                clap::ValueEnum::to_possible_value(&f)
                    .map(|v| v.get_name().to_string())
                    .unwrap_or_default(),
            ]);
        }
        if a.bus.json {
            args.push("--json".into());
        }
        return run_in_guest(
            args,
            &out,
            vec![],
            vec![],
            a.bus.json.then_some("validation.json"),
        );
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let stop = Arc::new(AtomicBool::new(false));
    let emulator = if a.real {
        None
    } else {
        vcan_setup::ensure_vcan(&a.bus.iface)?;
        let mut faults = TurntableFaults::default();
        match a.fault {
            Some(TtFault::Stall) => faults.stall_from_s = Some(0.0),
            Some(TtFault::Lock) => faults.lock_fails = true,
            Some(TtFault::EncoderGlitch) => {
                faults.encoder_glitch_at_s = (0..400).map(|i| 0.5 + 0.25 * f64::from(i)).collect();
            }
            Some(TtFault::LostCommands) => faults.lost_command_seqs = vec![4],
            Some(TtFault::DelayedCommands) => faults.command_delay_s = 0.2,
            None => {}
        }
        let p = TurntableParams {
            axes: a.axis + 1,
            faults,
            ..TurntableParams::default()
        };
        p.check()?;
        let tt = Turntable::new(p);
        let progress = Arc::new(emulators::can::Progress::default());
        let clock = emulators::clock::SimClock::start(a.speed);
        // the mechanism's time: the simulated clock (no IMU here to follow)
        let ticker = {
            let (progress, stop) = (progress.clone(), stop.clone());
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    progress
                        .sim_us
                        .store((clock.now() * 1e6) as u64, Ordering::Release);
                    std::thread::sleep(std::time::Duration::from_millis(1));
                }
            })
        };
        let (iface, stop2) = (a.bus.iface.clone(), stop.clone());
        let h = std::thread::spawn(move || {
            emulators::can::run_turntable(&iface, tt, &progress, f64::INFINITY, &stop2)
        });
        std::thread::sleep(std::time::Duration::from_millis(50));
        Some((h, ticker))
    };
    let result = hil::validate::run_suite(
        &a.bus.iface,
        a.axis,
        if a.real { 1.0 } else { a.speed },
        &Default::default(),
    );
    stop.store(true, Ordering::Relaxed);
    if let Some((h, ticker)) = emulator {
        let _ = ticker.join();
        match h.join() {
            Ok(r) => {
                r.context("turntable emulator")?;
            }
            Err(_) => bail!("turntable emulator thread panicked"),
        }
    }
    let v = result?;
    std::fs::write(
        out.join("validation.json"),
        serde_json::to_string_pretty(&v)?,
    )?;
    if a.bus.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print!("{}", hil::validate::table(&v));
        println!(" report: {}", out.join("validation.json").display());
    }
    Ok(if v.pass { 0 } else { 1 })
}

/// Disturbance script file: `[[disturbance]]` entries.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct DisturbanceScript {
    #[serde(default)]
    disturbance: Vec<emulators::truth::Disturbance>,
}

fn drill_north_finding(a: NorthFindingArgs) -> Result<i32> {
    let mut s = Scenario::builtin_static();
    let heading = match a.heading {
        Some(h) => h.rem_euclid(360.0),
        // random, reproducible from the seed (the same generator as the Monte Carlo)
        None => {
            use rand::{Rng, SeedableRng};
            rand::rngs::StdRng::seed_from_u64(a.seed).random::<f64>() * 360.0
        }
    };
    s.name = "drill-north-finding".into();
    s.site.heading_deg = heading;
    s.site.lat_deg = a.lat;
    s.speed = a.speed;
    s.imu.seed = a.seed;
    s.turntable = Some(emulators::turntable::TurntableParams {
        seed: a.seed,
        ..Default::default()
    });
    s.north_finding = Some(nav::northfind::NorthFindingConfig {
        dwell_s: a.dwell,
        ..Default::default()
    });
    s.heading_tolerance_deg = a.tolerance;
    // enough simulated time for four dwells, the moves and a few repeats
    s.duration_s = 4.0 * a.dwell + 120.0 + 2.0 * a.dwell;
    if let Some(p) = &a.disturbances {
        let text = std::fs::read_to_string(p)
            .with_context(|| format!("cannot read disturbance script {}", p.display()))?;
        let d: DisturbanceScript =
            toml::from_str(&text).with_context(|| format!("disturbance script {}", p.display()))?;
        s.disturbance = d.disturbance;
    }
    s.check()?;
    let out = absolute(
        &a.bus
            .out
            .clone()
            .unwrap_or_else(|| default_out("drill-north-finding")),
    )?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let scen = out.join("drill.toml");
    std::fs::write(&scen, toml::to_string_pretty(&s)?)?;
    eprintln!(
        "hil: north-finding drill at {:.4} deg heading, latitude {} deg, {} s dwell, x{}",
        heading, a.lat, a.dwell, a.speed
    );
    if a.in_process {
        let nf = s.north_finding.clone().unwrap_or_default();
        let o = hil::drill::run_in_process(&s, &nf, |_| {})?;
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
    run(RunArgs {
        scenario: Some(scen),
        duration: None,
        speed: None,
        nav: None,
        bus: BusArgs {
            out: Some(out),
            ..a.bus
        },
    })
}

/// The built-in GPS-aided drive of the demo.
const DRIVE_GPS: &str = include_str!("../../scenarios/drive-gps.toml");

fn demo(speed: f64, dwell: f64, out: Option<PathBuf>) -> Result<i32> {
    let out = absolute(&out.unwrap_or_else(|| default_out("demo")))?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let in_guest = std::env::var_os(GUEST_ENV).is_some();
    if !in_guest && !matches!(vcan_setup::can_support(), CanSupport::Available) {
        // one guest boot for both parts
        let args = vec![
            "demo".into(),
            "--speed".into(),
            speed.to_string(),
            "--dwell".into(),
            dwell.to_string(),
            "--out".into(),
            out.to_string_lossy().into_owned(),
        ];
        let status = run_in_guest(args, &out, vec![], vec![sibling_binary("nav")?], None)?;
        return Ok(status);
    }
    let seed = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(1);
    eprintln!("hil: demo part 1 of 2: four-position north-finding drill");
    let drill = drill_north_finding(NorthFindingArgs {
        heading: None,
        lat: 28.218157,
        dwell,
        speed,
        disturbances: None,
        tolerance: 0.1,
        seed,
        in_process: false,
        bus: BusArgs::to(out.join("drill")),
    })?;
    eprintln!("hil: demo part 2 of 2: GPS-aided drive (one 1 km lap, NMEA receiver on a pty)");
    let mut s: Scenario = toml::from_str(DRIVE_GPS).context("built-in drive scenario")?;
    s.speed = speed;
    let scen = out.join("drive-gps.toml");
    std::fs::write(&scen, toml::to_string_pretty(&s)?)?;
    let drive = run(RunArgs {
        scenario: Some(scen),
        duration: None,
        speed: None,
        nav: None,
        bus: BusArgs::to(out.join("drive")),
    })?;
    let verdict = |c: i32| if c == 0 { "PASS" } else { "FAIL" };
    let summary = format!(
        "# Demo\n\n| part | result | report |\n|---|---|---|\n| north-finding drill | {} | [drill/report.md](drill/report.md) |\n| GPS-aided drive | {} | [drive/report.md](drive/report.md) |\n",
        verdict(drill),
        verdict(drive)
    );
    std::fs::write(out.join("report.md"), &summary)?;
    println!("==============================================================================");
    println!(
        " DEMO  north-finding drill: {}   GPS-aided drive: {}",
        verdict(drill),
        verdict(drive)
    );
    println!(
        " reports: {}/drill/report.md, {}/drive/report.md",
        out.display(),
        out.display()
    );
    println!("==============================================================================");
    Ok(if drill == 0 && drive == 0 { 0 } else { 1 })
}

fn default_out(name: &str) -> PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    PathBuf::from("runs").join(format!("{name}-{secs}"))
}

fn absolute(p: &Path) -> Result<PathBuf> {
    Ok(if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir()?.join(p)
    })
}

fn run(a: RunArgs) -> Result<i32> {
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
    let native = !a.bus.vm || in_guest;
    if native && matches!(vcan_setup::can_support(), CanSupport::Available) {
        let opts = RunOptions {
            iface: a.bus.iface.clone(),
            out: out.clone(),
            nav_bin: match &a.nav {
                Some(n) => n.clone(),
                None => sibling_binary("nav")?,
            },
            progress: true,
        };
        let backend = if in_guest { "vm" } else { "native" };
        let r = run_here(&s, &opts, backend)?;
        if a.bus.json {
            println!("{}", serde_json::to_string_pretty(&r)?);
        } else {
            print!("{}", report::card(&r));
            println!(" report: {}", out.join("report.md").display());
        }
        return Ok(if r.pass { 0 } else { 1 });
    }
    // No CAN here: run this same command inside the QEMU guest.
    let mut args: Vec<String> = vec!["run".into()];
    let mut extra = vec![out.clone()];
    if let Some(p) = &a.scenario {
        let p = absolute(p)?;
        extra.push(p.parent().map(Path::to_path_buf).unwrap_or_default());
        args.extend(["--scenario".into(), p.to_string_lossy().into_owned()]);
    }
    args.extend([
        "--duration".into(),
        s.duration_s.to_string(),
        "--speed".into(),
        s.speed.to_string(),
    ]);
    args.extend([
        "--iface".into(),
        a.bus.iface.clone(),
        "--out".into(),
        out.to_string_lossy().into_owned(),
    ]);
    let nav = match &a.nav {
        Some(n) => absolute(n)?,
        None => sibling_binary("nav")?,
    };
    args.extend(["--nav".into(), nav.to_string_lossy().into_owned()]);
    if a.bus.json {
        args.push("--json".into());
    }
    run_in_guest(
        args,
        &out,
        extra,
        vec![nav],
        a.bus.json.then_some("report.json"),
    )
}

/// Run this program with `args` inside the QEMU guest (this kernel has no CAN): shares the
/// workspace, `out` and `extra` folders; returns the guest command's exit status.
fn run_in_guest(
    args: Vec<String>,
    out: &Path,
    mut extra: Vec<PathBuf>,
    libs_for: Vec<PathBuf>,
    json: Option<&str>,
) -> Result<i32> {
    if std::env::var_os(GUEST_ENV).is_some() {
        bail!(
            "inside the QEMU guest and still no CAN support: the guest kernel lacks the can/vcan modules"
        );
    }
    eprintln!("hil: this kernel has no CAN support; running on real vcan inside a QEMU guest");
    vcan_setup::install_prereqs()?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    extra.push(out.to_path_buf());
    let exe = std::env::current_exe()?;
    let mut full = vec![exe.to_string_lossy().into_owned()];
    full.extend(args);
    let shares = dedupe_nested(vcan_setup::default_shares(&exe, &extra));
    let mut opts = VmOptions {
        shares,
        libs_for,
        ..VmOptions::default()
    };
    // long runs (the full campus loop) may need more than the default 40 minutes
    if let Some(v) = std::env::var_os("HIL_GUEST_TIMEOUT_S") {
        let s: u64 = v
            .to_str()
            .and_then(|v| v.parse().ok())
            .context("HIL_GUEST_TIMEOUT_S must be a whole number of seconds")?;
        opts.timeout = std::time::Duration::from_secs(s);
    }
    let o = vcan_setup::run_in_vm(&full, &opts)?;
    if let Some(name) = json {
        // the guest's console mixes its stdout and stderr: the JSON comes from the file the run
        // wrote in the shared output folder, so stdout carries the JSON alone
        let p = out.join(name);
        match std::fs::read_to_string(&p) {
            Ok(j) => println!("{}", j.trim_end()),
            Err(e) => eprintln!("hil: the run in the guest wrote no {}: {e}", p.display()),
        }
    }
    eprintln!(
        "hil: guest boot {:.1} s, run {:.1} s",
        o.boot_secs,
        o.total_secs - o.boot_secs
    );
    Ok(o.status)
}

/// `K/N` (0-based part K of N).
fn parse_shard(s: &str) -> std::result::Result<(usize, usize), String> {
    let (k, n) = s
        .split_once('/')
        .ok_or_else(|| format!("`{s}`: a shard is K/N, e.g. 0/4"))?;
    let (k, n): (usize, usize) = (
        k.trim()
            .parse()
            .map_err(|_| format!("`{k}` is not a part number"))?,
        n.trim()
            .parse()
            .map_err(|_| format!("`{n}` is not a part count"))?,
    );
    if n == 0 || k >= n {
        return Err(format!("`{s}`: parts are numbered 0 to N-1"));
    }
    Ok((k, n))
}

/// Drop shares that lie inside another share.
fn dedupe_nested(mut shares: Vec<PathBuf>) -> Vec<PathBuf> {
    shares.retain(|p| !p.as_os_str().is_empty());
    let all = shares.clone();
    shares.retain(|p| !all.iter().any(|q| q != p && p.starts_with(q)));
    shares.dedup();
    shares
}

fn replay(recording: &Path, config: Option<&Path>, json: bool) -> Result<i32> {
    let (mcap, cfg) = if recording.is_dir() {
        (recording.join("nav.mcap"), recording.join("nav.toml"))
    } else {
        let beside = recording
            .parent()
            .unwrap_or(Path::new("."))
            .join("nav.toml");
        (recording.to_path_buf(), beside)
    };
    let cfg = config.map_or(cfg, Path::to_path_buf);
    if !cfg.is_file() {
        bail!(
            "no nav config for {} (looked for {}; give one with --config)",
            recording.display(),
            cfg.display()
        );
    }
    let cfg = nav::config::NavConfig::load(&cfg)?;
    let r = hil::playback::replay(&mcap, &cfg)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", hil::playback::text(&r));
    }
    Ok(i32::from(!r.identical()))
}
