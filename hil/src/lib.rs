//! The HIL bench: scenarios, runs on vcan, checks and reports.

pub mod bench;
pub mod busreplay;
pub mod devices;
pub mod drill;
pub mod experiment;
pub mod faultlog;
pub mod faults;
pub mod fuzz;
pub mod html;
pub mod inproc;
pub mod montecarlo;
pub mod navexp;
pub mod navrun;
pub mod observe;
pub mod par;
pub mod playback;
pub mod plot;
pub mod replay;
pub mod report;
pub mod routes;
pub mod run;
pub mod scenario;
pub mod shard;
pub mod status;
pub mod truthrec;
pub mod validate;
