//! The bus: its physical model on the simulated clock ([`model`]: frame lengths with their
//! stuff bits, arbitration, a queue per node, errors and bus-off), the scheduler that puts every
//! device's frames on it in lockstep with nav ([`scheduler`]), and the socket transport that
//! writes them to vcan or a real CAN interface ([`transport`]).

pub mod model;
pub mod scheduler;
pub mod transport;
