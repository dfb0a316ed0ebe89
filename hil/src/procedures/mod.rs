//! The procedures nav runs on the indexing mechanism, one file each: four-position
//! north-finding ([`northfinding`]), the rotating IMU's self-calibration ([`rotating`]) and the
//! tetrahedral unit's calibration ([`tetrahedral`]): each one's scenario, its in-process run,
//! its outcome scored against truth, its progress line and its result card, and its
//! [`BenchProcedure`] in [`ALL`]. [`observe`] follows them on nav's lines and frames.
//!
//! A new procedure: its file here (its [`BenchProcedure`]), a line in [`ALL`], its field in
//! [`Outcomes`] and its section in the scenario ([`crate::scenario::Scenario`]). The run, the
//! checks, the result card and the Markdown and HTML reports go through [`ALL`].

pub mod northfinding;
pub mod observe;
pub mod plan;
pub mod rotating;
pub mod tetrahedral;

use crate::check::Check;
use crate::scenario::Scenario;
use nav::summary::Summary;
use northfinding::DrillOutcome;
use rotating::CalibrateOutcome;
use serde::{Deserialize, Serialize};
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
    fn score(&self, s: &Scenario, nav: &Summary, sim_reached: f64, o: &mut Outcomes);
    /// Its checks, on its outcome in `o` and nav's summary `nav`, into `out` (none when it
    /// did not run).
    fn checks(&self, s: &Scenario, o: &Outcomes, nav: &Summary, out: &mut Vec<Check>);
    /// Its part of the run's result card, lines without indent (none when it did not run).
    fn card(&self, s: &Scenario, o: &Outcomes) -> Option<String>;
    /// Its heading in the reports.
    fn title(&self) -> &'static str;
    /// Its section of the run's Markdown report, ending in a blank line (none when it did not
    /// run): its card, unless it says more.
    fn markdown(&self, s: &Scenario, o: &Outcomes) -> Option<String> {
        let c = self.card(s, o)?;
        Some(format!("## {}\n\n```\n{c}```\n\n", self.title()))
    }
    /// Its section of the run's HTML report (none when it did not run): its card, unless it
    /// says more.
    fn html(&self, s: &Scenario, o: &Outcomes, _nav: &Summary) -> Option<Section> {
        Some(Section {
            title: self.title(),
            text: Some(self.card(s, o)?),
            ..Default::default()
        })
    }
}

/// A procedure's section of a run's HTML report.
#[derive(Debug, Clone, Default)]
pub struct Section {
    /// Its heading.
    pub title: &'static str,
    /// Its figures, as (name, value) rows.
    pub figures: Vec<(&'static str, String)>,
    /// Text shown as it is (a result card).
    pub text: Option<String>,
    /// A table of JSON objects (the keys of the first as columns), with its caption.
    pub detail: Option<(&'static str, Vec<serde_json::Value>)>,
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

/// Every procedure the bench knows, in the order of nav's registry (`nav::procedures::mission`).
pub const ALL: [&dyn BenchProcedure; 3] = [
    &northfinding::NorthFinding,
    &rotating::RotatingImu,
    &tetrahedral::Tetrahedral,
];

/// The outcomes of the procedures a scenario runs, each scored from nav's summary against the
/// scenario's truth (none where the scenario does not run it). In a run's `report.json` they
/// are the fields `drill`, `calibration` and `tetra_calibration`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Outcomes {
    /// Four-position north-finding.
    #[serde(rename = "drill")]
    pub north_finding: Option<DrillOutcome>,
    /// The rotating IMU's self-calibration.
    #[serde(
        rename = "calibration",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub rotating_imu: Option<CalibrateOutcome>,
    /// The tetrahedral unit's calibration.
    #[serde(
        rename = "tetra_calibration",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub tetrahedral: Option<TetraOutcome>,
}

impl Outcomes {
    /// The outcomes of scenario `s`'s procedures from nav's summary `nav`, the stream having
    /// reached `sim_reached` s.
    pub fn of(s: &Scenario, nav: &Summary, sim_reached: f64) -> Self {
        let mut o = Self::default();
        for p in ALL {
            if p.runs_in(s) {
                p.score(s, nav, sim_reached, &mut o);
            }
        }
        o
    }
}

/// A procedure's checks that its parameter file was written and loads for its unit: `file` as
/// nav's summary names it, `load` reading it back and describing what it holds.
fn parameter_file_check<P>(
    name: &str,
    file: Option<&std::path::Path>,
    load: impl FnOnce(&std::path::Path) -> Result<P, nav::procedures::unit_parameters::ParamsError>,
    describe: impl FnOnce(&P) -> String,
) -> Check {
    let loaded = file.map(load);
    Check {
        name: name.into(),
        pass: matches!(loaded, Some(Ok(_))),
        detail: match (file, loaded) {
            (Some(f), Some(Ok(p))) => format!("{}: {}", f.display(), describe(&p)),
            (Some(f), Some(Err(e))) => format!("{}: {e}", f.display()),
            _ => "nav wrote no parameter file".into(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The outcomes keep the field names `report.json` has always had: `drill` (null when the
    /// run had none), `calibration` and `tetra_calibration` (absent when it had none).
    #[test]
    fn outcomes_keep_their_report_fields() {
        let none = serde_json::to_value(Outcomes::default()).expect("serializes");
        assert_eq!(none, serde_json::json!({ "drill": null }));
        let drill = northfinding::outcome(10.0, None, Some("stopped"), 5.0);
        let o = Outcomes {
            north_finding: Some(drill),
            ..Default::default()
        };
        let v = serde_json::to_value(&o).expect("serializes");
        assert_eq!(v["drill"]["abort"], "stopped");
        let back: Outcomes = serde_json::from_value(v).expect("reads back");
        assert_eq!(
            back.north_finding.and_then(|d| d.abort).as_deref(),
            Some("stopped")
        );
    }
}
