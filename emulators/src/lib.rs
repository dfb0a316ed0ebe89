//! Device models and their bus adapters.
//!
//! Layers: truth ([`truth`]: exact motion, pure functions of time) -> sensor error model
//! ([`imu`]: biases, noise, pulse quantization) -> wire encoding (the `wire` crate) ->
//! transport ([`adapters::transport`]: vcan or a real CAN interface). Everything outside
//! [`adapters`] is pure (no I/O, no wall time) and tested without I/O; the adapters put it on
//! vcan and a pty, paced by one clock ([`adapters::clock::SimClock`]).
//!
//! Rooms: [`truth`], [`drive`] and [`road`] (the motion), [`imu`] (the unit, its pulse
//! counters, its stream of frames, the MEMS units), [`turntable`] (the mechanism and its
//! traffic), [`gps`] (the receiver), [`bus`] (the physical bus model), [`step`] (the one order in
//! which the devices act), [`reported`]; then [`adapters`] (the scheduler that drives every
//! device on vcan in lockstep with nav, the socket transport, the pty, the player, the
//! free-running devices).

pub mod adapters;
pub mod bus;
pub mod drive;
pub mod geodesy;
pub mod gps;
pub mod imu;
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
