//! Device models and their bus adapters.
//!
//! Layers: truth ([`truth`]: exact motion, pure functions of time) -> sensor error model
//! ([`imu`]: biases, noise, pulse quantization) -> wire encoding (the `wire` crate) ->
//! transport ([`bus::transport`]: vcan or a real CAN interface). Everything but the transport is
//! pure and tested without I/O. All emulators share one simulated clock ([`clock::SimClock`]).
//!
//! Rooms: [`imu`] (the unit, its pulse counters, its stream of frames, the MEMS units),
//! [`turntable`] (the mechanism and its traffic), [`gps`] (the receiver), [`bus`] (the
//! physical bus model, the scheduler that drives every device on it in lockstep with nav, the
//! socket transport), [`step`] (the one order in which the devices act).

pub mod bus;
pub mod clock;
pub mod drive;
pub mod freerun;
pub mod geodesy;
pub mod gps;
pub mod imu;
pub mod player;
pub mod reported;
pub mod road;
pub mod step;
pub mod truth;
pub mod turntable;

/// A scenario parameter out of its range: which table, and what is wrong (naming the parameter).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("[{table}] {problem}")]
pub struct ParamError {
    /// The scenario table (`imu`, `turntable`, `drive`).
    pub table: &'static str,
    /// What is wrong, naming the parameter.
    pub problem: String,
}

impl ParamError {
    /// `problem` with a parameter of table `table`.
    pub fn new(table: &'static str, problem: impl Into<String>) -> Self {
        Self {
            table,
            problem: problem.into(),
        }
    }
}
