//! The HIL bench: scenarios, runs on vcan, checks and reports.

pub mod replay;
pub mod report;
pub mod run;
pub mod scenario;
