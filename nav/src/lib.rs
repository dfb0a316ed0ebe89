//! Navigation library of the RLG strapdown INS. The `nav` binary is the production program; it
//! opens the devices named in its config file and knows nothing of emulators.
//!
//! Its parts, each a folder, each importing only from those before it:
//! - [`frontend`]: the devices' data as nav takes it in: IMU frames to increments, the dither
//!   filter, coning and sculling, the attitude update, the receiver's NMEA, the IMU's clock;
//! - [`navigation`]: the earth model, strapdown navigation, the SINS/GPS filter, its integrity
//!   and the solution frames;
//! - [`procedures`]: what nav runs on the indexing mechanism at start (north-finding and its
//!   plan, the rotating IMU's self-calibration, the redundant unit's calibration), the link to
//!   the mechanism, the units' parameter files;
//! - [`record`]: the MCAP recording, its raw and JSON channels and Foxglove's views;
//! - then [`config`], [`summary`] and [`pipeline`] (the mission logic as one pipeline without
//!   I/O, which every in-process run drives too);
//! - [`shell`]: what the binary's thin shell needs around the pipeline (the receiver's port,
//!   the order of arrival of frames and bytes, start-up).

pub mod frontend;
pub mod navigation;
pub mod procedures;
pub mod record;

pub mod config;
pub mod pipeline;
pub mod summary;

pub mod shell;
