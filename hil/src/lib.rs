//! The HIL bench: scenarios, runs on vcan, checks and reports.
//!
//! Folders from the bottom up; each imports only from those above it in this list (and the
//! small helpers at the top level, which import nothing of the crate):
//! - [`scenario`]: the scenario file, its checks, and what it means for nav's configuration;
//! - [`engine`]: the scenario's devices stepped in process or put behind the bus scheduler, the
//!   in-process reference and navigation runs, nav's recording read back, the fault schedule and
//!   the truth recording;
//! - [`procedures`]: the procedures on the mechanism (north-finding, the rotating-IMU and the
//!   tetrahedral calibrations): their scenarios, outcomes, progress lines and result cards;
//! - [`report`]: a run's checks and its report (Markdown, HTML, SVG plots);
//! - [`run`]: the bench run on vcan with the nav binary, and recorded traffic put back on the bus;
//! - [`experiments`]: the papers' tables in process, in parts when asked;
//! - [`suites`]: the fault matrix, the validation suite, fuzzing, the benchmarks.
//!
//! The commands (`src/cmd`, `src/main.rs`) parse arguments and call into these.

pub mod campaign;
pub mod check;
pub mod engine;
pub mod experiments;
pub mod free;
pub mod junit;
pub mod live;
pub mod par;
pub mod procedures;
pub mod replay;
pub mod report;
pub mod run;
pub mod scenario;
pub mod stats;
pub mod status;
pub mod suites;
pub mod table;
pub mod values;
