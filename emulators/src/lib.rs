//! Device models and their bus adapters.
//!
//! Layers: truth ([`truth`]: exact motion, pure functions of time) -> sensor error model
//! ([`imu`]: biases, noise, pulse quantization) -> wire encoding (the `wire` crate) ->
//! transport ([`can`]: vcan or a real CAN interface). Everything but the transport is pure and
//! tested without I/O. All emulators share one simulated clock ([`clock::SimClock`]).

pub mod bus;
pub mod can;
pub mod clock;
pub mod drive;
pub mod geodesy;
pub mod gps;
pub mod imu;
pub mod truth;
pub mod turntable;
