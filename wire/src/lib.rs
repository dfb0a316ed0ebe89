//! The bench's one CAN wire contract.
//!
//! `bench.dbc` (beside this crate's `Cargo.toml`) describes every frame on the bus. This crate
//! is the one codec for those frames: the emulators encode with it, `nav` decodes with it, and
//! a test parses the DBC and checks that every [`SignalSpec`] here agrees with it, bit for bit.
//! Frame layouts are written nowhere else.
//!
//! The crate does no I/O. [`RawFrame`] is a plain classic CAN frame; the optional `socketcan`
//! feature converts it to and from `socketcan::CanFrame`. The optional `dbc` feature is the
//! generic codec of any DBC ([`dbc`]: a lab's own contract), equal to this one on `bench.dbc`.

pub mod busload;
pub mod candump;
mod codec;
pub mod crc;
#[cfg(feature = "dbc")]
pub mod dbc;
pub mod errframe;
#[cfg(feature = "dbc")]
pub mod mapping;
mod messages;
#[cfg(feature = "socketcan")]
mod sock;

pub use codec::{DecodeError, EncodeError, MessageSpec, RawFrame, SignalSpec};
pub use messages::*;
#[cfg(feature = "socketcan")]
pub use sock::{
    BATCH, CpuPick, FrameConvError, from_can_frame, pin_to_one_cpu, recv_batch, recv_batch_stamped,
    send_batch, send_error_frame, set_error_filter, set_rcvbuf, socket_drops, to_can_frame,
    wait_readable,
};

/// The DBC file text, embedded so tools can print or ship it.
pub const DBC: &str = include_str!("../bench.dbc");
