//! `hil`: the bench command line.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use hil::report;
use hil::run::{RunOptions, run_here, sibling_binary};
use hil::scenario::Scenario;
use std::path::{Path, PathBuf};
use vcan_setup::{CanSupport, GUEST_ENV, VmOptions};

mod cmd;
use cmd::bench::bench;
use cmd::busload::busload;
use cmd::calibrate::{calibrate_rotating_imu, calibrate_tetrahedral};
use cmd::demo::demo;
use cmd::drill::drill_north_finding;
use cmd::experiment::experiment;
use cmd::faults::faults;
use cmd::fuzz::fuzz;
use cmd::guest::{
    absolute, default_out, junit_back, junit_through_guest, rerun_in_guest, run_in_guest,
};
use cmd::replay::{candump, replay, replay_bus, replay_live};
use cmd::run::run;
use cmd::validate::validate_turntable;

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
    /// when a scenario does not fit a bit rate.
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
}

#[derive(clap::Args, Clone)]
struct FaultsArgs {
    /// Only these faults (comma-separated names, as in the table).
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Speed factor of every run.
    #[arg(long, value_parser = hil::values::speed, default_value_t = 10.0)]
    speed: f64,
    /// List the faults and exit.
    #[arg(long)]
    list: bool,
    /// Faults run side by side, each on an interface of its own (--iface, then IFACE-1,
    /// IFACE-2, ...). Each run is in lockstep with its nav: the results are the same at any
    /// number.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..=16))]
    jobs: u16,
    /// Also write the result as JUnit XML to FILE, for a CI server (GitLab, Jenkins, GitHub):
    /// a test case per fault, failing with what was expected and observed.
    #[arg(long, value_name = "FILE")]
    junit: Option<PathBuf>,
    #[command(flatten)]
    bus: BusArgs,
}

#[derive(clap::Args, Clone)]
struct BenchArgs {
    /// Seconds of 2 kHz IMU data per pass of the in-process figures.
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 120.0)]
    seconds: f64,
    /// Passes of nav's front end (the best is reported).
    #[arg(long, default_value_t = 3)]
    passes: u32,
    /// Scenario files (default: the shipped ones under scenarios/; the bus part adds the drill).
    #[arg(long)]
    scenario: Vec<PathBuf>,
    /// Simulated seconds of each scenario through the bus (its first seconds).
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 30.0)]
    bus_seconds: f64,
    /// Frames per raw vcan measurement.
    #[arg(long, default_value_t = 200_000)]
    raw_frames: u64,
    /// In-process figures only: no bus, no guest.
    #[arg(long)]
    no_bus: bool,
    #[command(flatten)]
    bus: BusArgs,
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

/// The live view a run can be watched on.
#[derive(clap::Args, Clone, Default)]
struct LiveArgs {
    /// Serve a live view of the run over Foxglove's WebSocket protocol on ADDR (default
    /// 127.0.0.1:8765) for the command's whole length: open it in Foxglove or Lichtblick
    /// ("Open connection", "Foxglove WebSocket", ws://ADDR) with docs/foxglove-layout.json.
    /// Times are simulated time; the viewer's pause holds the run (its result does not change).
    /// Through the QEMU guest the port is forwarded to this host.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = hil::live::DEFAULT_ADDR)]
    live: Option<std::net::SocketAddr>,
    /// With --live: before the run starts, wait until N viewers have subscribed to every
    /// channel (at most 5 minutes), so that they see it from its first sample.
    #[arg(long, value_name = "N", default_value_t = 0, requires = "live")]
    live_wait: usize,
    /// The view, once started (a demo's parts share one).
    #[arg(skip)]
    view: Option<std::sync::Arc<hil::live::View>>,
}

impl LiveArgs {
    /// The arguments that ask for this view again (a command run again in the guest).
    fn to_args(&self) -> Vec<String> {
        match self.live {
            Some(a) => vec![
                "--live".into(),
                a.to_string(),
                "--live-wait".into(),
                self.live_wait.to_string(),
            ],
            None => Vec::new(),
        }
    }

    /// The view to run on: the one already started, or a new one (`true`: this caller owns it
    /// and finishes it), or none.
    fn view(&self, duration_s: f64) -> Result<(Option<std::sync::Arc<hil::live::View>>, bool)> {
        Ok(match (&self.view, self.live) {
            (Some(v), _) => (Some(v.clone()), false),
            (None, Some(addr)) => (
                Some(hil::live::View::start(addr, self.live_wait, duration_s)?),
                true,
            ),
            _ => (None, false),
        })
    }
}

/// Stop a live view this command started and say what its viewers got.
fn finish_view(v: std::sync::Arc<hil::live::View>) {
    let st = v.finish();
    for c in &st.clients {
        eprintln!(
            "hil: live view: client {}: {} messages sent, {} dropped (fell behind), {} subscriptions",
            c.peer, c.sent, c.dropped, c.subscriptions
        );
    }
    if st.clients.is_empty() {
        eprintln!(
            "hil: live view: nobody watched ({} messages published)",
            st.published
        );
    }
}

impl BusArgs {
    /// Whether the run goes here: this kernel has CAN and the guest was not asked for (or this
    /// is the guest). Otherwise the command runs again inside the QEMU guest.
    fn here(&self) -> bool {
        let in_guest = std::env::var_os(GUEST_ENV).is_some();
        (!self.vm || in_guest) && matches!(vcan_setup::can_support(), CanSupport::Available)
    }

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
    /// Pace of the emulated mechanism: its seconds per wall second at most. The suite runs in
    /// lockstep with the emulator, so the result is the same at any pace and on a loaded host;
    /// the pace only sets how fast an operator sees it (with --real, the mechanism's own time).
    #[arg(long, value_parser = hil::values::speed, default_value_t = 1.0)]
    speed: f64,
    /// Also write the result as JUnit XML to FILE, for a CI server (GitLab, Jenkins, GitHub):
    /// a test case per check, failing with the measured value, the limit and why.
    #[arg(long, value_name = "FILE")]
    junit: Option<PathBuf>,
    #[command(flatten)]
    bus: BusArgs,
}

#[derive(Subcommand)]
enum Calibrate {
    /// Self-calibration of a dual-axis rotating IMU on a static base (paper 004): nav levels
    /// and finds a coarse heading at rest, turns both axes of the mechanism at the set rate,
    /// reversing each after every turn, estimates the gyro biases and scale-factor errors by the
    /// paper's decoupled RLS (and a 14-state Kalman filter beside it), returns the axes to zero,
    /// locks them and writes the IMU parameter file (gyro-parameters.toml in the run folder).
    /// Live progress, then a result card scored against the emulated unit's true errors.
    RotatingImu(CalibrateArgs),
    /// Kalman calibration of a redundant MEMS gyro unit (four gyros in a tetrahedron) on a
    /// three-axis table (paper 001): nav turns the table about x, y and z in turn at the set
    /// rate, checks every held second that the table did what was commanded, and estimates
    /// each gyro's bias, scale factor and two mounting angles with the paper's 16-state filter.
    /// With --monitor (or --fail) the profile runs again with the parity monitor on the
    /// calibrated outputs; --fail injects one gyro's failure over the bus. Live progress, then
    /// a result card scored against the emulated unit's truth.
    Tetrahedral(TetraArgs),
}

#[derive(clap::Args, Clone)]
struct TetraArgs {
    /// Latitude of the table, deg.
    #[arg(long, value_parser = hil::values::latitude_deg, default_value_t = 45.0, allow_negative_numbers = true)]
    lat: f64,
    /// Heading of the table's base, deg.
    #[arg(long, value_parser = hil::values::heading_deg, default_value_t = 0.0, allow_negative_numbers = true)]
    heading: f64,
    /// Rate of each turn, deg/s (the paper: 20).
    #[arg(long, value_parser = hil::values::rate_dps, default_value_t = 20.0)]
    rate: f64,
    /// Rest before the turns, s.
    #[arg(long, value_parser = hil::values::pause_s, default_value_t = 60.0)]
    rest: f64,
    /// Each turn, s (the paper: 75).
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 75.0)]
    turn: f64,
    /// Rest after the turns, s.
    #[arg(long, value_parser = hil::values::pause_s, default_value_t = 75.0)]
    end_rest: f64,
    /// The unit's gyro noise, deg/s per sample (the paper's is 2.8e-7; MEMS: 0.005 to 0.05).
    #[arg(long, value_parser = hil::values::noise_dps, default_value_t = 0.005)]
    noise: f64,
    /// Run the profile again with the parity monitor on the calibrated outputs.
    #[arg(long)]
    monitor: bool,
    /// Fail one gyro (1-4) halfway through the monitor's pass: stuck:G, bias-jump:G:DPS or
    /// noise:G:DPS (implies --monitor).
    #[arg(long)]
    fail: Option<String>,
    /// Start from the unit's parameter file (an earlier run's tetra-parameters.toml): no
    /// calibration, the profile once with the parity monitor.
    #[arg(long)]
    parameters: Option<PathBuf>,
    /// Speed factor (1 = real time).
    #[arg(long, value_parser = hil::values::speed, default_value_t = 20.0)]
    speed: f64,
    /// Seed of the unit and the table.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Run the same procedure in process (no bus, no nav process).
    #[arg(long)]
    in_process: bool,
    #[command(flatten)]
    live: LiveArgs,
    #[command(flatten)]
    bus: BusArgs,
}

#[derive(clap::Args, Clone)]
struct CalibrateArgs {
    /// Latitude of the site, deg.
    #[arg(long, value_parser = hil::values::latitude_deg, default_value_t = 30.0, allow_negative_numbers = true)]
    lat: f64,
    /// True heading of the base, deg.
    #[arg(long, value_parser = hil::values::heading_deg, default_value_t = 30.06, allow_negative_numbers = true)]
    heading: f64,
    /// True pitch and roll of the base, deg.
    #[arg(long, value_parser = hil::values::tilt_deg, default_value_t = 0.06, allow_negative_numbers = true)]
    tilt: f64,
    /// Coarse alignment at rest, s.
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 60.0)]
    level: f64,
    /// Rotation, s (the paper: 900).
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 900.0)]
    rotate: f64,
    /// Rotation rate of both axes, deg/s (the paper: 5).
    #[arg(long, value_parser = hil::values::rate_dps, default_value_t = 5.0)]
    rate: f64,
    /// The inner axis starts this long after the outer one, s (0: in step; the paper does not
    /// say).
    #[arg(long, value_parser = hil::values::pause_s, default_value_t = 18.0)]
    inner_delay: f64,
    /// Speed factor (1 = real time).
    #[arg(long, value_parser = hil::values::speed, default_value_t = 20.0)]
    speed: f64,
    /// Seed of the emulated unit and mechanism.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// An IMU parameter file for nav to load at start (e.g. an earlier run's
    /// gyro-parameters.toml): the procedure then refines it, and its static alignment starts
    /// from calibrated gyros.
    #[arg(long)]
    parameters: Option<PathBuf>,
    /// Run the same procedure in process (no bus, no nav process: the same emulators and nav
    /// code, stepped in the order the bench delivers the frames).
    #[arg(long)]
    in_process: bool,
    #[command(flatten)]
    live: LiveArgs,
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
    #[arg(long, value_parser = hil::values::heading_deg, allow_negative_numbers = true)]
    heading: Option<f64>,
    /// Latitude, deg.
    #[arg(long, value_parser = hil::values::latitude_deg, allow_negative_numbers = true, default_value_t = 28.218157)]
    lat: f64,
    /// Longitude, deg (the site's surveyed position, with --lat: where a real receiver is).
    #[arg(long, value_parser = hil::values::longitude_deg, allow_negative_numbers = true, default_value_t = 112.989583)]
    lon: f64,
    /// Dwell per position, s, or `auto`: the shortest that meets --tolerance at 3 sigma by the
    /// drill's prediction (`hil plan north-finding`), else the one that comes closest.
    #[arg(long, value_parser = cmd::drill::dwell, default_value = "60")]
    dwell: cmd::drill::Dwell,
    /// Positions: 2, 4 or 8, equally spaced (4: 0, 90, 180, 270, the paper's).
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(["2", "4", "8"]))]
    positions: Option<String>,
    /// Visit the positions out and back (0, 90, 180, 270, 270, 180, 90, 0): a linear gyro
    /// drift cancels; each visit is a dwell.
    #[arg(long)]
    out_and_back: bool,
    /// Speed factor (1 = real time, as on the vehicle).
    #[arg(long, value_parser = hil::values::speed, default_value_t = 1.0)]
    speed: f64,
    /// Disturbance script: TOML file with [[disturbance]] entries (door_slam, climb_in, wind).
    #[arg(long)]
    disturbances: Option<PathBuf>,
    /// Pass when the heading error is within this, deg.
    #[arg(long, value_parser = hil::values::tolerance_deg, default_value_t = 0.1)]
    tolerance: f64,
    /// Random seed (sensor errors, random heading).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Run the same drill in process (no bus, no nav process: the same emulators and nav code,
    /// stepped in the order the bench delivers the frames); its result equals the bench's.
    #[arg(long)]
    in_process: bool,
    #[command(flatten)]
    live: LiveArgs,
    #[command(flatten)]
    bus: BusArgs,
    #[command(flatten)]
    free: FreeArgs,
}

#[derive(Subcommand)]
enum Experiment {
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
    /// position and velocity error, NEES per degree of freedom (target [0.5, 2]), NIS, rejected
    /// fixes (none may be in a filter's first minute) and integrity alarms per route and filter
    /// kind; plots of the errors against the filters' 3-sigma bounds. Writes report.md/json and
    /// SVGs; exit status 1 when a target is missed. Use a release build (the 11 shipped routes,
    /// 8 runs each: about 4.5 minutes on 2 cores).
    Routes {
        /// Route scenarios (drives with a [gps]); default: every shipped one under scenarios/.
        #[arg(long)]
        scenario: Vec<PathBuf>,
        /// Runs per route and filter with other IMU and receiver seeds (results are averaged).
        #[arg(long, value_parser = hil::values::count, default_value_t = 1)]
        runs: usize,
        /// Filter kinds (comma-separated).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "standard,fading,adaptive"
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

#[derive(clap::Args, Clone)]
struct RunArgs {
    /// Scenario file (TOML); default: the built-in static scenario.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Override the simulated duration, s.
    #[arg(long, value_parser = hil::values::duration_s)]
    duration: Option<f64>,
    /// Override the speed factor (1 = real time).
    #[arg(long, value_parser = hil::values::speed)]
    speed: Option<f64>,
    /// The nav binary (default: next to hil).
    #[arg(long)]
    nav: Option<PathBuf>,
    /// Skip the checks that re-run the scenario in process and read nav's recording back (the
    /// reference run, the replay, the navigation scoring): for soaks, whose recording is too
    /// large to read back in the guest. Frame accounting, nav's exit and memory stay.
    #[arg(long)]
    no_reference: bool,
    /// Put gpsd between the GPS emulator's port and nav (nav's `[gps] source = "gpsd"`), as a
    /// vehicle shares one receiver; needs gpsd (./run-tests installs it).
    #[arg(long)]
    gpsd: bool,
    /// Also write the result as JUnit XML to FILE, for a CI server (GitLab, Jenkins, GitHub):
    /// a test case per check of the result card, failing with its detail.
    #[arg(long, value_name = "FILE")]
    junit: Option<PathBuf>,
    #[command(flatten)]
    live: LiveArgs,
    #[command(flatten)]
    bus: BusArgs,
    #[command(flatten)]
    free: FreeArgs,
}

/// A free-running run: the device under test as it runs in the vehicle.
#[derive(clap::Args, Clone, Default)]
struct FreeArgs {
    /// Free-running, as in the vehicle: the emulators run on the host's clock at x1 and wait
    /// for nobody; the device under test (our nav by default, or --dut) is judged by what it
    /// sends on the bus, by the DBC only: its heading against truth at the sample its NAV_TIME
    /// names, its latency from that sample on the bus, its output rate, its time tags, frames
    /// outside the DBC. The bench's own lateness is measured apart; when the host cannot keep
    /// real time the run stops with no verdict (exit status 3). Results are measured, not
    /// bit-identical (docs/your-device.md).
    #[arg(long)]
    free: bool,
    /// With --free: the device under test, a command run through `sh -c` with {iface}, {gps}
    /// (the receiver's port), {config} (the nav.toml the bench wrote for the scenario), {out}
    /// (its folder) and {nav} (our nav binary) replaced; `none`: nothing to start, the device
    /// is already on the interface. Default: our nav (--nav).
    #[arg(long, requires = "free")]
    dut: Option<String>,
    /// With --free: a device that is real, not emulated: `turntable=IFACE` (a table on the
    /// bench's interface; the IMU rides it as its TT_STATUS reports), `gps=PORT` (a receiver on
    /// a serial port, handed to the device under test). Repeatable.
    #[arg(long, value_name = "DEVICE=PORT", requires = "free")]
    real: Vec<String>,
    /// With --free: the device's latency budget, ms: the 99th percentile of IMU sample on
    /// the bus to the NAV_TIME naming it (default: the scenario's `[bus] latency_budget_ms`,
    /// else 50).
    #[arg(long, value_parser = hil::values::latency_budget_ms, requires = "free")]
    latency_budget_ms: Option<f64>,
    /// With --free: the device must send its first NAV_TIME within this long, s.
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 15.0, requires = "free")]
    answer_within: f64,
    /// With --free: the bench's own lateness beyond which it stops, ms.
    #[arg(long, default_value_t = 200.0, requires = "free")]
    max_late_ms: f64,
}

impl FreeArgs {
    /// The arguments that ask for this again (a command run again in the guest).
    fn to_args(&self) -> Vec<String> {
        if !self.free {
            return Vec::new();
        }
        let mut a = vec![
            "--free".into(),
            "--answer-within".into(),
            self.answer_within.to_string(),
            "--max-late-ms".into(),
            self.max_late_ms.to_string(),
        ];
        if let Some(d) = &self.dut {
            a.extend(["--dut".into(), d.clone()]);
        }
        if let Some(b) = self.latency_budget_ms {
            a.extend(["--latency-budget-ms".into(), b.to_string()]);
        }
        for r in &self.real {
            a.extend(["--real".into(), r.clone()]);
        }
        a
    }

    /// The run's options for scenario `s`, on `iface` into `out`, our nav being `nav`.
    fn options(
        &self,
        s: &Scenario,
        iface: &str,
        out: PathBuf,
        nav: PathBuf,
    ) -> Result<hil::free::FreeOptions> {
        let mut o = hil::free::FreeOptions {
            iface: iface.into(),
            out,
            dut: match self.dut.as_deref() {
                None => hil::free::Dut::Nav(nav),
                Some("none") => hil::free::Dut::Nothing,
                Some(c) => hil::free::Dut::Command(c.into(), nav),
            },
            real_turntable: false,
            real_gps: None,
            latency_budget_ms: self
                .latency_budget_ms
                .or(s.bus.latency_budget_ms)
                .unwrap_or(50.0),
            answer_within_s: self.answer_within,
            max_late_ms: self.max_late_ms,
            progress: true,
        };
        for r in &self.real {
            match r.split_once('=') {
                Some(("turntable", i)) if i == iface => o.real_turntable = true,
                Some(("turntable", _)) => bail!(
                    "--real {r}: the bench has one bus, --iface {iface}: the real turntable must be on it"
                ),
                Some(("gps", p)) => o.real_gps = Some(PathBuf::from(p)),
                _ => bail!("--real {r}: turntable=IFACE or gps=PORT"),
            }
        }
        if !(0.0..=10_000.0).contains(&self.max_late_ms) {
            bail!("--max-late-ms {}: between 0 and 10000", self.max_late_ms);
        }
        Ok(o)
    }
}

fn main() {
    let cli = Cli::parse();
    // nav's pipeline runs in process here (drills, experiments, replays): its progress goes in
    // the results, not in a log line per run; under the fuzzer its warnings about the hostile
    // input are the expected answer, counted by the fuzzer, not logged a million times
    // log lines clear the status line a terminal may be showing (hil::status)
    nav::cli::init_tracing_on(
        if matches!(cli.cmd, Cmd::Fuzz { .. }) {
            "info,nav=off"
        } else {
            "info,nav=warn"
        },
        hil::status::LogWriter,
    );
    // exit 0: pass, 1: a check failed or the run could not go on
    std::process::exit(nav::cli::exit_code("hil", real_main(cli), |code| code));
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
            bitrate,
            scenario,
            measure,
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
    }
}
