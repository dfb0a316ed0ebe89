//! The bus's physical model on the simulated clock ([`model`]: frame lengths with their stuff
//! bits, arbitration, a queue per node, errors and bus-off). Pure: the scheduler that puts every
//! device's frames on vcan in lockstep with nav and the socket transport are adapters
//! ([`crate::adapters::scheduler`], [`crate::adapters::transport`]).

pub mod bounds;
pub mod lab;
pub mod model;
