//! Regression campaigns: several builds of a navigation computer through the same cases (fault
//! matrix rows, scenarios, drills, experiments), one verdict per build and case against a
//! baseline build.
//!
//! - [`spec`]: the campaign file (TOML): the devices under test, the baseline, the cases and
//!   their repeats;
//! - [`cells`]: the cells (device x case x repeat), each keyed by the build (a hash of the nav
//!   binary and its config), the case and the seed, so that a campaign resumes where it stopped
//!   and a build's cells already run are not run again; a cluster's task takes its cell by
//!   number;
//! - [`against_baseline`]: a case's figures per build against the baseline's: the same (every repeat's
//!   frames bit for bit), better, worse or not distinguishable, decided by the figures' own
//!   scatter (Welch's interval on the difference of the means), and flaky where a build's
//!   repeats disagree on pass or fail;
//! - [`run`]: running a cell (a bench run through vcan, a fault row, or an experiment's run in
//!   process) and keeping its result;
//! - [`report`]: the merged verdicts as Markdown, SVG, JSON and JUnit XML;
//! - [`cost`]: what the cells took, and what a campaign of many would take on a cluster.

pub mod against_baseline;
pub mod cells;
pub mod cost;
pub mod report;
pub mod run;
pub mod spec;
