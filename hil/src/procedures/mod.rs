//! The procedures nav runs on the indexing mechanism: four-position north-finding
//! ([`northfinding`]), the rotating-IMU and tetrahedral calibrations ([`calibrate`]): each one's
//! scenario, outcome scored against truth, progress line and result card; [`observe`] follows
//! them on nav's log lines.

pub mod calibrate;
pub mod northfinding;
pub mod observe;
