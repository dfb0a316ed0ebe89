//! The procedures nav runs on the indexing mechanism: four-position north-finding
//! ([`northfinding`]), the rotating-IMU and tetrahedral calibrations ([`calibrate`]): each one's
//! scenario, outcome scored against truth, progress line and result card; [`observe`] follows
//! them on nav's log lines.

pub mod calibrate;
pub mod northfinding;
pub mod observe;

use crate::scenario::Scenario;
use calibrate::{CalibrateOutcome, TetraOutcome};
use northfinding::DrillOutcome;

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
        let north_finding = s.north_finding.as_ref().map(|_| {
            let nf = nav.north_finding.as_ref();
            northfinding::outcome(
                s.truth_heading_deg(),
                nf.and_then(|n| n.result.as_ref()),
                nf.map_or(Some("north-finding was not enabled in nav"), |n| {
                    n.abort.as_deref()
                }),
                sim_reached,
            )
        });
        let rotating_imu = s.self_calibration.as_ref().map(|_| {
            let c = nav.self_calibration.as_ref();
            let mut o = calibrate::outcome(
                s,
                c.and_then(|c| c.result.as_ref()),
                c.map_or(Some("self-calibration was not enabled in nav"), |c| {
                    c.abort.as_deref()
                }),
                sim_reached,
            );
            o.parameters = c.and_then(|c| c.parameters.clone());
            o
        });
        let tetrahedral = s.tetra_calibration.as_ref().map(|_| {
            let c = nav.tetra_calibration.as_ref();
            calibrate::tetra_outcome(
                s,
                c.and_then(|c| c.result.as_ref()),
                c.map_or(Some("tetra-calibration was not enabled in nav"), |c| {
                    c.abort.as_deref()
                }),
                sim_reached,
            )
        });
        Self {
            north_finding,
            rotating_imu,
            tetrahedral,
        }
    }
}
