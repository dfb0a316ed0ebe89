//! What the `nav` binary's thin shell needs around the pipeline: the receiver's port read in its
//! event loop, the order of arrival of frames and bytes, start-up.

pub mod arrival;
pub mod cli;
pub mod gps_port;
