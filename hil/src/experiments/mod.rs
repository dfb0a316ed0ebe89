//! The papers' tables, reproduced in process with the same emulators and nav code as the bench:
//! coning ([`coning`]), north-finding Monte Carlo ([`north_finding_mc`]), navigation ([`navigation`])
//! and its routes ([`routes`], judged window by window: [`windows`]), calibration ([`calibration`], [`redundant_imu`]); each can run in
//! parts ([`shard`]).

pub mod calibration;
pub mod coning;
pub mod navigation;
pub mod north_finding_mc;
pub mod redundant_imu;
pub mod routes;
pub mod shard;
pub mod truth;
pub mod windows;

use anyhow::Result;
use serde::{Serialize, de::DeserializeOwned};
use shard::Part;
use std::path::Path;

/// An experiment that runs in parts: each part runs its share of the experiment's plan, and the
/// merge of all parts gives the single run's report, table for table. The command line, Slurm
/// array tasks and Kubernetes indexed Jobs all go through this.
pub trait Experiment {
    /// The name its parts carry (`hil experiment merge` tells them apart by it).
    const NAME: &'static str;
    /// What it is asked to do.
    type Options;
    /// One run's outcome, as a part keeps it.
    type Run: Serialize + DeserializeOwned;
    /// The report of all parts.
    type Report;
    /// Part `k` of `n` (0-based); `progress`: a line per run on stderr.
    fn part(o: &Self::Options, k: usize, n: usize, progress: bool) -> Result<Part<Self::Run>>;
    /// The report of `parts`, its files written to `out`.
    fn merge(parts: &[Part<Self::Run>], out: &Path, progress: bool) -> Result<Self::Report>;
    /// The report as the terminal shows it.
    fn text(r: &Self::Report) -> String;
    /// Whether the report meets the experiment's targets (the command's exit status 0).
    fn met(r: &Self::Report) -> bool;
    /// The whole experiment as one part, merged.
    fn run(o: &Self::Options, out: &Path, progress: bool) -> Result<Self::Report> {
        let part = Self::part(o, 0, 1, progress)?;
        Self::merge(&[part], out, progress)
    }
}
