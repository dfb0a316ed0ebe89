//! A run's report: what it holds ([`RunReport`]), its checks ([`checks`]), what the bench measured
//! of the nav process ([`nav_process`]), and its renderings: the card and the Markdown
//! ([`card`]), the HTML page ([`html`], [`page`], [`plot`]) and the bus's figures
//! ([`bus_figures`]).

pub mod bus_figures;
pub mod card;
pub mod checks;
pub mod html;
pub mod nav_process;
pub mod page;
pub mod plot;

use crate::engine::reference::InProcess;
use crate::scenario::Scenario;
use emulators::adapters::transport::TxStats;
use nav::summary::Summary;
use serde::{Deserialize, Serialize};

pub use crate::check::Check;

/// The full report of a run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunReport {
    /// Scenario as run.
    pub scenario: Scenario,
    /// `native` or `vm`.
    pub backend: String,
    /// CAN interface.
    pub interface: String,
    /// Wall seconds of the emulation.
    pub wall_seconds: f64,
    /// Frames per second of wall time through the interface.
    pub frames_per_wall_second: f64,
    /// The speed factor reached (simulated seconds per wall second, the time held for nav's
    /// watchdog to report an IMU stop or the stream's end left out).
    pub pace_reached: f64,
    /// How the emulators followed nav (lockstep).
    pub lockstep: emulators::adapters::scheduler::LockstepStats,
    /// The bus model: load, each identifier's queueing delays, the turntable command round
    /// trip, each node's queue.
    #[serde(default)]
    pub bus: emulators::bus::model::BusStats,
    /// What the emulator sent.
    pub tx: TxStats,
    /// The same scenario run in process (no bus): the reference nav must reproduce (none for
    /// runs with a turntable, which moves on nav's own commands).
    pub in_process: Option<InProcess>,
    /// What the turntable emulator did (runs with a turntable).
    pub turntable: Option<emulators::adapters::transport::TurntableTxStats>,
    /// The outcomes of the procedures the scenario ran, scored against its truth (in the JSON:
    /// `drill`, `calibration`, `tetra_calibration`).
    #[serde(flatten)]
    pub procedures: crate::procedures::Outcomes,
    /// What the GPS emulator wrote (runs with a receiver).
    pub gps: Option<emulators::adapters::pty::GpsTxStats>,
    /// nav's solution frames as the bench received them.
    pub solution: crate::procedures::observe::SolutionWatch,
    /// nav's navigation scored against truth (runs that navigate).
    pub navigation: Option<crate::engine::scoring::NavScore>,
    /// The same second by second, from nav's recording.
    pub navigation_series: Option<crate::engine::scoring::SeriesStats>,
    /// nav's exit status.
    pub nav_exit: Option<i32>,
    /// nav's summary (as nav wrote it; rebuilt from its recording when it was killed).
    pub nav: Summary,
    /// nav was killed outright during the run: what its recording kept.
    #[serde(default)]
    pub killed: Option<KillOutcome>,
    /// nav's memory over the run (read from /proc).
    #[serde(default)]
    pub nav_memory: Option<NavMemory>,
    /// IMU frames lost on the bus (sent but not received).
    pub bus_lost_frames: i64,
    /// Checks.
    pub checks: Vec<Check>,
    /// All checks passed.
    pub pass: bool,
    /// The live view, when the run had one: what its clients got and lost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub live: Option<crate::live::bench_run::RunViewStats>,
}

pub use card::{card, markdown};
pub use checks::*;
pub use nav_process::{KillOutcome, NavMemory, cpu_seconds};
