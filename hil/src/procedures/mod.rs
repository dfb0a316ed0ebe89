//! The procedures nav runs on the indexing mechanism, one file each: four-position
//! north-finding ([`northfinding`]), the rotating IMU's self-calibration ([`rotating`]) and the
//! tetrahedral unit's calibration ([`tetrahedral`]): each one's scenario, its in-process run,
//! its outcome scored against truth, its progress line and its result card, and its
//! [`BenchProcedure`] in [`ALL`]. [`observe`] follows them on nav's lines and frames.
//!
//! A new procedure: its file here, a line in [`ALL`] and its field in [`Outcomes`].

pub mod northfinding;
pub mod observe;
pub mod rotating;
pub mod tetrahedral;

use crate::scenario::Scenario;
use northfinding::DrillOutcome;
use rotating::CalibrateOutcome;
use tetrahedral::TetraOutcome;

/// A procedure nav runs on the mechanism, as the bench knows it: which scenarios run it, how
/// its progress reads to an operator, and its outcome scored against the scenario's truth.
/// Its file also holds its scenario, its in-process run and its result card.
pub trait BenchProcedure: Sync {
    /// nav's name for it: nav says `nav: <name> progress {...}`, then `nav: <name> result ...`
    /// or `nav: <name> aborted: ...`.
    fn name(&self) -> &'static str;
    /// Scenario `s` runs it.
    fn runs_in(&self, s: &Scenario) -> bool;
    /// The operator's progress line, from nav's progress JSON.
    fn progress_line(&self, p: &serde_json::Value) -> String;
    /// Its outcome from nav's summary `nav` (the stream having reached `sim_reached` s), into
    /// `o`.
    fn score(&self, s: &Scenario, nav: &nav::summary::Summary, sim_reached: f64, o: &mut Outcomes);
}

/// What nav's summary says of procedure `name` (its section's result and abort reason): the
/// result, and why there is none; a summary without the section says it was not enabled.
fn said<'a, R>(
    name: &str,
    section: Option<(Option<&'a R>, Option<&'a str>)>,
) -> (Option<&'a R>, Option<String>) {
    match section {
        Some((result, abort)) => (result, abort.map(str::to_string)),
        None => (None, Some(format!("{name} was not enabled in nav"))),
    }
}

/// Every procedure the bench knows, in the order of nav's registry (`nav::mission`).
pub const ALL: [&dyn BenchProcedure; 3] = [
    &northfinding::NorthFinding,
    &rotating::RotatingImu,
    &tetrahedral::Tetrahedral,
];

/// The outcomes of the procedures a scenario runs, each scored from nav's summary against the
/// scenario's truth (none where the scenario does not run it).
#[derive(Debug, Clone, Default)]
pub struct Outcomes {
    /// Four-position north-finding.
    pub north_finding: Option<DrillOutcome>,
    /// The rotating IMU's self-calibration.
    pub rotating_imu: Option<CalibrateOutcome>,
    /// The tetrahedral unit's calibration.
    pub tetrahedral: Option<TetraOutcome>,
}

impl Outcomes {
    /// The outcomes of scenario `s`'s procedures from nav's summary `nav`, the stream having
    /// reached `sim_reached` s.
    pub fn of(s: &Scenario, nav: &nav::summary::Summary, sim_reached: f64) -> Self {
        let mut o = Self::default();
        for p in ALL {
            if p.runs_in(s) {
                p.score(s, nav, sim_reached, &mut o);
            }
        }
        o
    }
}
