//! The procedures the pipeline can run on the mechanism at start, as the pipeline sees them: the
//! inputs each takes beyond the mechanism's frames, the IMU time it runs on, nav's mode while it
//! runs and what it hands on when done (a heading, a parameter file).
//! Each procedure's file implements it; [`crate::pipeline::REGISTRY`] lists them; the pipeline
//! knows none of them by name.
//!
//! A new procedure: its file (settings, phases, steps on [`crate::procedures::common::Core`], its
//! [`Mission`] and its section of the summary), a line in [`crate::pipeline::REGISTRY`], its
//! section in nav's config ([`crate::config::NavConfig`]) and its field in the summary
//! ([`crate::summary::Summary`], with its line in `put_section`).

use crate::frontend::imu_frames::ImuSample;
use crate::procedures::common::Procedure;
use crate::procedures::unit_parameters::ParameterFile;
use std::any::Any;
use std::path::PathBuf;
use wire::{MemsGyro, NavMode};

/// A procedure on the mechanism as the pipeline runs it.
pub(crate) trait Mission: std::fmt::Debug {
    /// The procedure itself.
    fn procedure(&mut self) -> &mut dyn Procedure;
    /// The procedure itself, to read.
    fn procedure_ref(&self) -> &dyn Procedure;
    /// It runs on the processing chain's valid sample (its inputs are the chain's updates);
    /// else on the end of the last sample nav has.
    fn on_valid_sample(&self) -> bool {
        false
    }
    /// One IMU sample over `(t1 - dt, t1]`, IMU time, s.
    fn on_sample(&mut self, _t1: f64, _dt: f64, _s: &ImuSample) {}
    /// One update of the processing chain at IMU time `t`.
    fn on_update(&mut self, _t: f64, _phi: [f64; 3], _dv: [f64; 3]) {}
    /// A MEMS gyro frame after sample `k` (ending at `t`, samples `dt` long); true when it
    /// takes them.
    fn on_mems(&mut self, _k: u64, _t: f64, _dt: f64, _g: &MemsGyro) -> bool {
        false
    }
    /// nav's mode while it runs.
    fn mode(&self) -> NavMode;
    /// The heading it found, for navigation.
    fn heading_deg(&self) -> Option<f64> {
        None
    }
    /// Its sigma, deg.
    fn heading_sigma_deg(&self) -> Option<f64> {
        None
    }
    /// It goes on without the mechanism, which it lost.
    fn mechanism_lost(&self) -> bool {
        false
    }
    /// It has just finished: the parameter file it made, and where its settings want it
    /// written (none: kept in the summary only).
    fn made(&mut self) -> Option<(Option<PathBuf>, ParameterFile)> {
        None
    }
    /// For the pipeline's typed accessors.
    fn as_any(&self) -> &dyn Any;
}
