//! A north-finding drill planned before it starts (`hil plan north-finding`, and the check
//! `hil drill` makes before it runs): the heading sigma the drill will give on the scenario's
//! IMU and mechanism at its latitude, its terms, the dwell that meets a tolerance at a
//! confidence, and the latitude beyond which none does. The figures come from
//! [`nav::procedures::drill_plan`], the same code nav uses at start-up; `hil experiment north-finding`
//! checks them against drills.

use super::northfinding::drill_plan;
use crate::scenario::Scenario;
use crate::scenario::navconfig::gyro_noise;
use nav::procedures::drill_plan::{self, DrillPlan, DwellAnswer, GyroNoise, Prediction};
use nav::procedures::north_finding::NorthFindingConfig;
use serde::Serialize;
use std::fmt::Write as _;

/// What to plan.
#[derive(Debug, Clone)]
pub struct PlanRequest {
    /// The drill's scenario: its IMU, its mechanism, its site.
    pub scenario: Scenario,
    /// The drill's north-finding settings (positions, dwell).
    pub north_finding: NorthFindingConfig,
    /// Where the IMU's figures come from (for the reader).
    pub source: String,
    /// The tolerance on the heading error, deg.
    pub tolerance_deg: f64,
    /// Sigmas the tolerance must hold at (3: 99.7 % of drills for a Gaussian error).
    pub confidence: f64,
    /// Shortest and longest dwell per position considered, s.
    pub dwell_range_s: (f64, f64),
}

/// A dwell's row of the plan.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Dwell per position, s.
    pub dwell_s: f64,
    /// The drill's expected length (enable to locked at zero), s.
    pub drill_s: f64,
    /// The prediction.
    #[serde(flatten)]
    pub prediction: Prediction,
}

/// The plan.
#[derive(Debug, Clone, Serialize)]
pub struct PlanReport {
    /// Latitude, deg.
    pub latitude_deg: f64,
    /// Table positions in order, deg.
    pub positions_deg: Vec<f64>,
    /// Where the IMU's figures come from.
    pub source: String,
    /// The gyros' and the table's figures used.
    pub noise: GyroNoise,
    /// Tolerance, deg.
    pub tolerance_deg: f64,
    /// Confidence, sigmas.
    pub confidence: f64,
    /// The drill's own dwell and what it gives.
    pub asked: Row,
    /// It meets the tolerance at the confidence.
    pub asked_meets: bool,
    /// The dwell that meets the tolerance, or the best there is.
    pub answer: DwellAnswer,
    /// The highest latitude where some dwell in range meets the tolerance (none: not even at
    /// the equator).
    pub latitude_limit_deg: Option<f64>,
    /// Dwells from 10 s to 300 s and what each gives.
    pub table: Vec<Row>,
}

/// The drill's expected length for a plan: its dwells and moves, the first move and the
/// return to zero.
fn drill_s(p: &DrillPlan, pr: &Prediction) -> f64 {
    pr.span_s + 2.0 * p.index_time_s
}

fn row(base: &DrillPlan, dwell_s: f64) -> Row {
    let p = DrillPlan {
        dwell_s,
        ..base.clone()
    };
    let prediction = drill_plan::predict(&p);
    Row {
        dwell_s,
        drill_s: drill_s(&p, &prediction),
        prediction,
    }
}

/// Plan the drill.
pub fn plan(r: &PlanRequest) -> PlanReport {
    let base = drill_plan(&r.scenario, &r.north_finding);
    let asked = row(&base, r.north_finding.dwell_s);
    let (lo, hi) = r.dwell_range_s;
    PlanReport {
        latitude_deg: base.latitude_deg,
        positions_deg: base.positions_deg.clone(),
        source: r.source.clone(),
        noise: gyro_noise(&r.scenario),
        tolerance_deg: r.tolerance_deg,
        confidence: r.confidence,
        asked_meets: r.confidence * asked.prediction.sigma_deg <= r.tolerance_deg,
        asked,
        answer: drill_plan::dwell_for(&base, r.tolerance_deg, r.confidence, lo, hi),
        latitude_limit_deg: drill_plan::latitude_limit(
            &base,
            r.tolerance_deg,
            r.confidence,
            lo,
            hi,
        ),
        table: [10.0, 15.0, 30.0, 60.0, 120.0, 300.0]
            .into_iter()
            .map(|d| row(&base, d))
            .collect(),
    }
}

/// What the plan advises before a drill: `None` when the drill's own dwell meets the tolerance,
/// else a sentence saying so with the dwell that would (or that none would, and the best).
pub fn advice(p: &PlanReport) -> Option<String> {
    if p.asked_meets {
        return None;
    }
    let k = p.confidence;
    let head = format!(
        "a {:.0} s dwell cannot meet {} deg at {k} sigma here: predicted sigma {:.4} deg ({k} sigma {:.3} deg)",
        p.asked.dwell_s,
        p.tolerance_deg,
        p.asked.prediction.sigma_deg,
        k * p.asked.prediction.sigma_deg
    );
    Some(match p.answer {
        DwellAnswer::Meets {
            dwell_s,
            prediction,
        } => format!(
            "{head}; a {dwell_s:.0} s dwell would (sigma {:.4} deg; --dwell auto picks it)",
            prediction.sigma_deg
        ),
        DwellAnswer::Cannot {
            best_dwell_s,
            prediction,
        } => format!(
            "{head}; no dwell would: the best, {best_dwell_s:.0} s, gives sigma {:.4} deg ({k} sigma {:.3} deg)",
            prediction.sigma_deg,
            k * prediction.sigma_deg
        ),
    })
}

/// The dwell `--dwell auto` picks: the shortest that meets the tolerance, else the best.
pub fn auto_dwell(p: &PlanReport) -> f64 {
    match p.answer {
        DwellAnswer::Meets { dwell_s, .. } => dwell_s,
        DwellAnswer::Cannot { best_dwell_s, .. } => best_dwell_s,
    }
}

/// The plan's table of dwells from 10 s to 300 s: what each gives and whether it meets the
/// tolerance.
fn dwell_table(p: &PlanReport) -> String {
    let k = p.confidence;
    let mut t = crate::table::Table::left(&[
        "dwell s",
        "drill s",
        "sigma deg",
        "k sigma",
        "ARW",
        "drift",
        "end",
        "meets",
    ]);
    for r in &p.table {
        let pr = &r.prediction;
        t.row([
            format!("{:.0}", r.dwell_s),
            format!("{:.0}", r.drill_s),
            format!("{:.4}", pr.sigma_deg),
            format!("{:.3}", k * pr.sigma_deg),
            format!("{:.4}", pr.arw_deg),
            format!("{:.4}", pr.drift_deg),
            format!("{:.4}", pr.end_angle_deg),
            if k * pr.sigma_deg <= p.tolerance_deg {
                "yes".into()
            } else {
                "no".into()
            },
        ]);
    }
    t.finish()
}

/// The plan as an operator reads it.
pub fn text(p: &PlanReport) -> String {
    let mut s = String::new();
    let n = &p.noise;
    let k = p.confidence;
    let positions: Vec<String> = p.positions_deg.iter().map(|x| format!("{x}")).collect();
    let _ = writeln!(
        s,
        "NORTH-FINDING PLAN   latitude {:.4} deg   {} dwells at {} deg",
        p.latitude_deg,
        p.positions_deg.len(),
        positions.join(", ")
    );
    let _ = writeln!(
        s,
        "  {}: gyro white noise {:.5} deg/sqrt(h), drift {} deg/h over {} s, end windows {:.3} arcsec, table {:.3} arcsec",
        p.source, n.arw_dpsh, n.drift_dph, n.drift_tau_s, n.end_angle_arcsec, n.index_arcsec
    );
    let _ = writeln!(
        s,
        "  horizontal earth rate {:.3} deg/h",
        p.asked.prediction.earth_rate_dph
    );
    let a = &p.asked;
    let _ = writeln!(
        s,
        "\n  at {:.0} s per position (a drill of about {:.0} s): sigma {:.4} deg, {k} sigma {:.3} deg: {} {} deg",
        a.dwell_s,
        a.drill_s,
        a.prediction.sigma_deg,
        k * a.prediction.sigma_deg,
        if p.asked_meets {
            "meets"
        } else {
            "does NOT meet"
        },
        p.tolerance_deg
    );
    let _ = writeln!(
        s,
        "    made of: angle random walk {:.4}, drift during the drill {:.4}, end windows {:.4}, indexing {:.5} (deg, root sum square)",
        a.prediction.arw_deg,
        a.prediction.drift_deg,
        a.prediction.end_angle_deg,
        a.prediction.index_deg
    );
    let _ = match p.answer {
        DwellAnswer::Meets {
            dwell_s,
            prediction,
        } => writeln!(
            s,
            "  to meet {} deg at {k} sigma: {dwell_s:.0} s per position (sigma {:.4} deg)",
            p.tolerance_deg, prediction.sigma_deg
        ),
        DwellAnswer::Cannot {
            best_dwell_s,
            prediction,
        } => writeln!(
            s,
            "  to meet {} deg at {k} sigma: no dwell up to the longest considered will; the best, {best_dwell_s:.0} s per position, gives sigma {:.4} deg ({k} sigma {:.3} deg)",
            p.tolerance_deg,
            prediction.sigma_deg,
            k * prediction.sigma_deg
        ),
    };
    let _ = match p.latitude_limit_deg {
        Some(l) if l >= 89.99 => writeln!(s, "  met at every latitude by some dwell"),
        Some(l) => writeln!(
            s,
            "  beyond {l:.1} deg of latitude (north or south) no dwell meets {} deg at {k} sigma",
            p.tolerance_deg
        ),
        None => writeln!(
            s,
            "  not met at any latitude by any dwell with these gyros: the drift during the drill sets the floor"
        ),
    };
    let _ = write!(s, "\n{}", dwell_table(p));
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(lat: f64, dwell: f64, tol: f64) -> PlanRequest {
        let s = super::super::northfinding::scenario(0.0, lat, dwell, 1);
        PlanRequest {
            north_finding: s.north_finding.clone().unwrap(),
            scenario: s,
            source: "the paper's IMU".into(),
            tolerance_deg: tol,
            confidence: 3.0,
            dwell_range_s: (5.0, 600.0),
        }
    }

    #[test]
    fn a_short_dwell_at_a_high_latitude_is_told_before_it_starts() {
        let p = plan(&request(70.0, 10.0, 0.5));
        assert!(!p.asked_meets);
        let a = advice(&p).unwrap();
        assert!(
            a.contains("cannot meet 0.5 deg") && a.contains("--dwell auto"),
            "{a}"
        );
        let d = auto_dwell(&p);
        assert!(d > 10.0, "{d}");
        // the dwell it picks meets it
        let again = plan(&request(70.0, d, 0.5));
        assert!(again.asked_meets && advice(&again).is_none());
        assert!(text(&p).contains("does NOT meet 0.5 deg"), "{}", text(&p));
        // the same in the south
        assert_eq!(auto_dwell(&plan(&request(-70.0, 10.0, 0.5))), d);
    }

    #[test]
    fn beyond_the_limit_no_dwell_suffices_and_it_is_said() {
        let p = plan(&request(28.2, 60.0, 0.1));
        assert!(matches!(p.answer, DwellAnswer::Cannot { .. }));
        assert!(advice(&p).unwrap().contains("no dwell would"));
        assert_eq!(p.latitude_limit_deg, None);
        let loose = plan(&request(28.2, 60.0, 0.3));
        let lim = loose.latitude_limit_deg.unwrap();
        assert!(text(&loose).contains(&format!("beyond {lim:.1} deg")));
    }
}
