//! `hil`: the bench command line.

use anyhow::{Result, bail};
use clap::{Parser, Subcommand};
use std::path::PathBuf;

mod cmd;
use cmd::args::{BusArgs, LiveArgs};
use cmd::bench::{BenchArgs, bench};
use cmd::busload::busload;
use cmd::calibrate::{Calibrate, calibrate_rotating_imu, calibrate_tetrahedral};
use cmd::campaign::{CampaignArgs, campaign};
use cmd::demo::demo;
use cmd::drill::{Drill, drill_north_finding};
use cmd::experiment::{Experiment, experiment};
use cmd::faults::{FaultsArgs, faults};
use cmd::fuzz::fuzz;
use cmd::replay::{candump, replay, replay_bus, replay_live};
use cmd::run::{RunArgs, run};
use cmd::validate::{Validate, validate_turntable};

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
    /// One emulated device on its own, free-running on the host's clock as hardware runs, until
    /// stopped: the IMU or the turntable on a CAN interface, the GPS receiver on a pty. A
    /// stand-in for the hardware for any device under test (ours, another team's, a board on
    /// can0); the IMU can ride a table on the bus it does not model (--follow-turntable). On
    /// stop it prints what it sent and its own lateness; exit status 3 when the host could not
    /// keep real time.
    Emulate(cmd::emulate::EmulateArgs),
    /// The main job: a four-position north-finding drill at the paper's start point with a random
    /// true heading, then a short GPS-aided drive (one 1 km lap with the NMEA receiver on a pty),
    /// each with its result card and report, and a summary of both.
    Demo {
        /// Speed factor (1 = real time: about 4.5 minutes of drill and 2 of driving).
        #[arg(long, value_parser = hil::values::speed, default_value_t = 1.0)]
        speed: f64,
        /// Dwell per position, s.
        #[arg(long, value_parser = hil::values::duration_s, default_value_t = 60.0)]
        dwell: f64,
        /// Output folder (default runs/drill-north-finding-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
        #[command(flatten)]
        live: LiveArgs,
    },
    /// Replay a nav recording and compare what nav sends with what it sent (bit for bit for the
    /// same build). By default through nav's pipeline in process; with `--bus`, the recorded
    /// IMU, turntable and GPS traffic goes back onto vcan and a pty at `--speed`, and the nav
    /// binary runs on it as on a vehicle (a new run folder in `--out`). Exit status 1 when they
    /// differ.
    Replay {
        /// A run folder (with nav.mcap and nav.toml), an MCAP recording of nav, or a
        /// `candump -l` log of the bus (the frames nav sends, by the DBC, are what it sent;
        /// in process only).
        recording: PathBuf,
        /// nav's config for the recording (default: nav.toml beside it).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Put the traffic back onto vcan and a pty and run the nav binary on it.
        #[arg(long)]
        bus: bool,
        /// With --bus or --live: speed factor over real time (1 = as the IMU sent it).
        #[arg(long, value_parser = hil::values::speed, default_value_t = 1.0)]
        speed: f64,
        /// With --bus: the nav binary to run (default: the one beside hil), e.g. a newer build.
        #[arg(long)]
        nav: Option<PathBuf>,
        /// Without --bus: watch the replay on a live view (`--live [ADDR]`, as on `hil run`),
        /// paced at --speed, with the viewer's pause, play and seek.
        #[command(flatten)]
        live: LiveArgs,
        #[command(flatten)]
        bus_args: BusArgs,
    },
    /// Export a nav recording's CAN frames (received and sent) as a `candump -l` log, which
    /// can-utils' `canplayer` plays back, `cantools` decodes with `hil dbc`, and `hil replay`
    /// replays; or, by the output's extension, as Vector ASC (`.asc`) or BLF (`.blf`), written by
    /// python-can (`pip install python-can`; cantools brings it).
    Candump {
        /// A run folder (with nav.mcap) or an MCAP recording of nav.
        recording: PathBuf,
        /// Output file (default: stdout, candump); `.asc` or `.blf`: Vector's formats.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Interface name written in the log (canplayer maps it: `vcan0=can0`).
        #[arg(long, default_value = "can0")]
        iface: String,
    },
    /// Hostile input: a seeded mutation fuzzer over nav's CAN pipeline, its NMEA framer and
    /// decoder, its config parser and the scenario parser (stable toolchain). Counts inputs,
    /// panics (each input saved), hangs and the slowest input; writes fuzz.md and fuzz.json.
    /// Exit status 1 on any panic or hang. Use a release build for long runs.
    Fuzz {
        /// Targets (default: all).
        #[arg(long, value_enum)]
        target: Vec<hil::suites::fuzz::Target>,
        /// Inputs per target.
        #[arg(long, default_value_t = 1_000_000)]
        inputs: u64,
        /// Seed (the run is reproducible from it).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output folder (default runs/fuzz-<unix time>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Run these kept inputs (crash-*.bin, hang-*.bin) once more against the one --target
        /// instead of fuzzing: prints each one's panic message or CPU time.
        #[arg(long, value_name = "FILE", num_args = 1..)]
        rerun: Vec<PathBuf>,
    },
    /// Print the bus-load table of the wire contract at its nominal rates, or of a scenario's
    /// traffic (its IMU rate, turntable, redundant unit) and whether it fits its bit rate. With
    /// `--measure`, run the scenario (by default the main job's drill and GPS drive) in process
    /// on the bus model and print what it measured: the load, each identifier's worst and p99
    /// queueing delay, the TT_CMD -> TT_ACK round trip and each node's queue. Exit status 1
    /// when a scenario does not fit a bit rate. With `--mapping`, a lab's own contract: its
    /// mapped messages' load and worst-case response times (CAN FD and 29-bit identifiers as its
    /// DBC says).
    Busload {
        /// Bit rate, bit/s; repeat or separate by commas for several (default: 1 Mbit/s, or
        /// the scenario's `bus.bitrate_bps`).
        #[arg(long, value_parser = hil::values::bitrate, value_delimiter = ',')]
        bitrate: Vec<f64>,
        /// A scenario file: its traffic rather than the contract's nominal rates.
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Run the scenario in process on the bus model and print the measured figures.
        #[arg(long)]
        measure: bool,
        /// A lab's mapping file (its DBC beside it, docs/your-dbc.md): the load and every
        /// message's worst-case response time at the mapping's bit rates; with --measure, its
        /// traffic on the bus model beside them (and the table's round trip).
        #[arg(long, conflicts_with_all = ["scenario", "bitrate"])]
        mapping: Option<PathBuf>,
    },
    /// Print the DBC file of the wire contract.
    Dbc,
    /// Validation suites against a device on a CAN interface (the emulator or real hardware).
    #[command(subcommand)]
    Validate(Validate),
    /// Operator drills on vcan (emulators + the production nav binary).
    #[command(subcommand)]
    Drill(Drill),
    /// Plan a drill before it starts: what it will give, and how long it must last.
    #[command(subcommand)]
    Plan(cmd::plan::Plan),
    /// Calibration procedures on vcan (emulators + the production nav binary in its calibration
    /// mode).
    #[command(subcommand)]
    Calibrate(Calibrate),
    /// Reproduce a paper's tables in process (same emulator and nav code as the bench).
    #[command(subcommand)]
    Experiment(Experiment),
    /// The benchmark suite: the raw vcan limit (a trivial writer and reader), each scenario's
    /// pace through the bench on vcan (speed factor, fraction of the limit, loss, frame-in to
    /// NAV_TIME-out latency), each scenario's emulators and nav's pipeline in process. Runs where
    /// vcan is: natively, or all of it inside the QEMU guest. Writes bench.json and bench.md.
    Bench(BenchArgs),
    /// The fault matrix: 34 faults (IMU frames dropped, duplicated, reordered, delayed, counter
    /// jump, BIT failure, saturation, accelerometer frames missing, IMU stream stopping, CAN
    /// interface down and up, a flood of foreign frames, an overloaded bus, bad frames; on the
    /// physical layer error frames, a stuck-dominant bus, a babbling node, the IMU's, nav's and
    /// the turntable's controllers bus-off; nav
    /// killed outright; GPS outages void and silent, position jump, time going backwards,
    /// garbage, receiver unplugged, PPS missing and jittered; turntable
    /// stall, lock failure, encoder glitch, lost and late acknowledgements, heartbeat loss), each
    /// injected into the emulators or by the bench, run through vcan and the pty against the
    /// unmodified nav, and judged against what nav must do and by when. Writes faults.md and
    /// faults.json (fault, expected, observed, detection latency, pass/fail) and one run folder
    /// per fault. Exit status 1 when a row fails.
    Faults(FaultsArgs),
    /// Judge the runs of a bench on another machine: where the devices run on a slow computer
    /// (a software-emulated guest, a small box beside the CAN hardware), its runs hand their
    /// in-process reference run, the replay of nav's recording and its scoring to this
    /// command through a folder both share (`HIL_JUDGE_SERVER=FOLDER` on the runs' side).
    /// Only for the same build of hil on a CPU of the same floating-point features (otherwise
    /// it declines and the run judges itself); a result does not depend on where it was
    /// computed. Runs until SIGINT or SIGTERM.
    JudgeServer(cmd::judge::JudgeServerArgs),
    /// A regression campaign: several devices under test (builds of nav with their config
    /// overrides, or free-running devices) through the same cases, each case run with each
    /// seed for each device (a cell), the cells kept by build, case and seed so that a
    /// campaign resumes and an unchanged build is not run again; then one verdict per build and
    /// case against the baseline: the same bit for bit, better, worse or not distinguishable
    /// by the figures' scatter, or flaky. Writes report.md, report.svg, report.json and
    /// junit.xml. Exit status 1 on a regression or a flaky case, 2 while cells lack results, 3 when the campaign cannot be planned (a bad file, a missing binary).
    /// This version runs scenarios, fault rows and drills (experiments are planned and judged,
    /// not yet run).
    Campaign(CampaignArgs),
}

fn main() {
    let cmd = <Cli as clap::CommandFactory>::command();
    let matches = cmd.clone().get_matches();
    let cli = match <Cli as clap::FromArgMatches>::from_arg_matches(&matches) {
        Ok(c) => c,
        Err(e) => e.exit(),
    };
    // kept for running the same command again in the QEMU guest (cmd::guest::same_command)
    cmd::guest::remember(cmd, matches);
    // nav's pipeline runs in process here (drills, experiments, replays): its progress goes in
    // the results, not in a log line per run; under the fuzzer its warnings about the hostile
    // input are the expected answer, counted by the fuzzer, not logged a million times
    // log lines clear the status line a terminal may be showing (hil::status)
    nav::shell::cli::init_tracing_on(
        // (a judge server replays other runs' recordings: nav's warnings are theirs, and go in
        // their reports)
        if matches!(cli.cmd, Cmd::Fuzz { .. } | Cmd::JudgeServer(_)) {
            "info,nav=off"
        } else {
            "info,nav=warn"
        },
        hil::status::LogWriter,
    );
    // exit 0: pass, 1: a check failed or the run could not go on
    std::process::exit(nav::shell::cli::exit_code("hil", real_main(cli), |code| {
        code
    }));
}

fn real_main(cli: Cli) -> Result<i32> {
    match cli.cmd {
        Cmd::Run(a) => run(a),
        Cmd::Emulate(a) => cmd::emulate::emulate(a),
        Cmd::Demo {
            speed,
            dwell,
            out,
            live,
        } => demo(speed, dwell, out, live),
        Cmd::Drill(Drill::NorthFinding(a)) => drill_north_finding(a),
        Cmd::Plan(p) => cmd::plan::plan_cmd(p),
        Cmd::Calibrate(Calibrate::RotatingImu(a)) => calibrate_rotating_imu(a),
        Cmd::Calibrate(Calibrate::Tetrahedral(a)) => calibrate_tetrahedral(a),
        Cmd::Validate(Validate::Turntable(a)) => validate_turntable(a),
        Cmd::Busload {
            mapping: Some(m),
            measure,
            ..
        } => cmd::busload::mapped(&m, measure),
        Cmd::Busload {
            bitrate,
            scenario,
            measure,
            mapping: None,
        } => busload(&bitrate, scenario, measure),
        Cmd::Replay {
            recording,
            config,
            bus,
            speed,
            nav,
            live,
            bus_args,
        } => {
            if let Some(addr) = live.live {
                if bus {
                    bail!(
                        "--live with --bus: not yet; watch the replay in process (without --bus), or a bench run (hil run --live)"
                    );
                }
                replay_live(&recording, config.as_deref(), addr, live.live_wait, speed)
            } else if bus {
                replay_bus(
                    &recording,
                    config.as_deref(),
                    speed,
                    nav.as_deref(),
                    &bus_args,
                )
            } else {
                replay(&recording, config.as_deref(), bus_args.json)
            }
        }
        Cmd::Candump {
            recording,
            out,
            iface,
        } => candump(&recording, out.as_deref(), &iface),
        Cmd::Fuzz {
            target,
            inputs,
            seed,
            out,
            rerun,
        } => fuzz(target, inputs, seed, out, rerun),
        Cmd::Dbc => {
            print!("{}", wire::DBC);
            Ok(0)
        }
        Cmd::Experiment(e) => experiment(e),
        Cmd::Bench(a) => bench(a),
        Cmd::Faults(a) => faults(a),
        Cmd::JudgeServer(a) => cmd::judge::judge_server(a),
        Cmd::Campaign(a) => campaign(a),
    }
}
