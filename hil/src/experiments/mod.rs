//! The papers' tables, reproduced in process with the same emulators and nav code as the bench:
//! coning ([`coning`]), north-finding Monte Carlo ([`northfinding`]), navigation ([`navigation`])
//! and its routes ([`routes`]), calibration ([`calibration`], [`tetrahedral`]); each can run in
//! parts ([`shard`]).

pub mod calibration;
pub mod coning;
pub mod navigation;
pub mod northfinding;
pub mod routes;
pub mod shard;
pub mod tetrahedral;
