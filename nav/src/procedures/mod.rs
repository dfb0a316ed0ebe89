//! The procedures nav runs on the indexing mechanism at start, what they share, the link to the
//! mechanism, and the calibration parameters bound to a unit.

pub mod common;
pub mod drill_plan;
pub(crate) mod mission;
pub mod north_finding;
pub mod redundant_rates;
pub mod rotating_estimator;
pub mod self_calibration;
pub mod tetra_calibration;
pub mod turntable_link;
pub mod unit_parameters;
