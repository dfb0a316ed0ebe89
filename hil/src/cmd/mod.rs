//! The commands of `hil`, one module each with its arguments and its run function (`main.rs`
//! only dispatches; the work is in the `hil` library); [`args`] holds the arguments several
//! commands share.

pub(crate) mod args;
pub(crate) mod bench;
pub(crate) mod busload;
pub(crate) mod calibrate;
pub(crate) mod campaign;
pub(crate) mod demo;
pub(crate) mod drill;
pub(crate) mod emulate;
pub(crate) mod experiment;
pub(crate) mod faults;
pub(crate) mod fuzz;
pub(crate) mod guest;
pub(crate) mod judge;
pub(crate) mod plan;
pub(crate) mod replay;
pub(crate) mod run;
pub(crate) mod validate;
