//! North-finding drills: in process (for Monte Carlo and tests) with the same emulators and
//! nav code as on the bench, and the drill's scoring.

use crate::check::Check;
use crate::scenario::Scenario;
use crate::stats::wrap180;
use anyhow::{Result, bail};
use nav::procedures::common::Procedure;
use nav::procedures::drill_plan::{self, DrillPlan, Prediction};
use nav::procedures::north_finding::{NorthFinder, NorthFindingConfig, NorthResult, Progress};
use serde::{Deserialize, Serialize};

/// The outcome of one drill.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DrillOutcome {
    /// True heading of the vehicle (and the IMU at table zero), deg.
    pub truth_deg: f64,
    /// Found heading, deg (none when aborted).
    pub heading_deg: Option<f64>,
    /// Error, deg, wrapped to (-180, 180].
    pub error_deg: Option<f64>,
    /// Estimated sigma, deg.
    pub sigma_deg: Option<f64>,
    /// Time to locked at zero, s.
    pub duration_s: f64,
    /// Dwells repeated after disturbances.
    pub repeats: u32,
    /// Why it was aborted, if it was.
    pub abort: Option<String>,
    /// Set when the mechanism was lost and nav found north by a static gyrocompass: why.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degraded: Option<String>,
    /// The sigma predicted before the drill from the IMU's and the table's figures
    /// ([`nav::procedures::drill_plan`]), deg.
    #[serde(default)]
    pub predicted_sigma_deg: Option<f64>,
    /// The full result.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub result: Option<serde_json::Value>,
}

/// One live progress line from a progress object (nav's JSON or [`Progress`]).
pub fn progress_line(p: &serde_json::Value) -> String {
    let num = |k: &str| p[k].as_f64();
    let est = match (num("heading_deg"), num("sigma_deg")) {
        (Some(h), Some(s)) => format!("heading {h:8.3} deg +- {s:.3}"),
        _ => "heading   --".into(),
    };
    format!(
        "drill: {:<11} position {}/{}  dwell left {:5.1} s  {est}  t = {:6.1} s{}",
        p["phase"].as_str().unwrap_or("?"),
        p["position"].as_u64().unwrap_or(0),
        p["positions"].as_u64().unwrap_or(0),
        num("dwell_left_s").unwrap_or(0.0),
        num("elapsed_s").unwrap_or(0.0),
        match p["repeats"].as_u64() {
            Some(0) | None => String::new(),
            Some(n) => format!("  ({n} dwell(s) repeated)"),
        }
    )
}

/// The drill's true heading drawn from its seed, deg in [0, 360) (`hil drill north-finding`
/// without `--heading`, a campaign's drill cell): reproducible from the seed, the same
/// generator as the Monte Carlo.
pub fn heading_of_seed(seed: u64) -> f64 {
    use rand::{Rng, SeedableRng};
    rand::rngs::StdRng::seed_from_u64(seed).random::<f64>() * 360.0
}

/// The operator drill as a scenario: the vehicle parked at `heading_deg` at latitude `lat_deg`,
/// four-position north-finding with `dwell_s` per position, IMU and mechanism seeded by `seed`,
/// and enough simulated time for the four dwells, the moves and a few repeats.
pub fn scenario(heading_deg: f64, lat_deg: f64, dwell_s: f64, seed: u64) -> Scenario {
    let mut s = Scenario::builtin_static();
    s.name = "drill-north-finding".into();
    s.site.heading_deg = heading_deg;
    s.site.lat_deg = lat_deg;
    s.imu.seed = seed;
    s.turntable = Some(emulators::turntable::TurntableParams {
        seed,
        ..Default::default()
    });
    s.north_finding = Some(nav::procedures::north_finding::NorthFindingConfig {
        dwell_s,
        ..Default::default()
    });
    s.duration_s = 4.0 * dwell_s + 120.0 + 2.0 * dwell_s;
    s
}

/// The drill `nf` on the scenario's IMU and mechanism at its site, as the prediction sees it:
/// what nav's config says of it ([`crate::scenario::navconfig::nf_config`]).
pub fn drill_plan(s: &Scenario, nf: &NorthFindingConfig) -> DrillPlan {
    crate::scenario::navconfig::nf_config(s, nf).drill_plan()
}

/// The heading sigma the scenario's drill `nf` is predicted to give.
pub fn predict(s: &Scenario, nf: &NorthFindingConfig) -> Prediction {
    drill_plan::predict(&drill_plan(s, nf))
}

/// Give the scenario's drill these table positions in order (the emulated mechanism gets a
/// detent at each, as the mechanism for such a drill has), and the simulated time their dwells
/// and moves need.
pub fn set_positions(s: &mut Scenario, positions_deg: Vec<f64>) {
    let Some(nf) = s.north_finding.as_mut() else {
        return;
    };
    if let Some(tt) = s.turntable.as_mut() {
        for p in &positions_deg {
            if !tt.detents_deg.iter().any(|d| (d - p).abs() < 1e-9) {
                tt.detents_deg.push(*p);
            }
        }
        tt.detents_deg.sort_by(f64::total_cmp);
    }
    let dwells = positions_deg.len() as f64;
    s.duration_s = dwells * (nf.dwell_s + 10.0) + 80.0 + 2.0 * nf.dwell_s;
    nf.positions_deg = positions_deg;
}

/// Score a result against truth.
pub fn outcome(
    truth_deg: f64,
    r: Option<&NorthResult>,
    abort: Option<&str>,
    t: f64,
) -> DrillOutcome {
    DrillOutcome {
        predicted_sigma_deg: None,
        degraded: r.and_then(|r| r.degraded.clone()),
        truth_deg,
        heading_deg: r.map(|r| r.heading_deg),
        error_deg: r.map(|r| wrap180(r.heading_deg - truth_deg)),
        sigma_deg: r.map(|r| r.sigma_deg),
        duration_s: r.map_or(t, |r| r.duration_s),
        repeats: r.map_or(0, |r| r.repeats),
        abort: abort.map(str::to_string),
        result: r.and_then(|r| serde_json::to_value(r).ok()),
    }
}

/// A drill in process (no bus): the scenario's devices driving nav's pipeline, stepped sample
/// by sample in the bench's bus order ([`crate::engine::inproc::InProcessBench`]); the result is the
/// bench's, bit for bit. `progress` gets nav's progress at every stage change and every second.
pub fn run_in_process(
    s: &Scenario,
    nf: &NorthFindingConfig,
    mut progress: impl FnMut(&Progress),
) -> Result<DrillOutcome> {
    let (motion, tt) = s.build();
    let Some(tt) = tt else {
        bail!(
            "scenario {} has no [turntable]: north-finding needs one",
            s.name
        );
    };
    let mut cfg = crate::scenario::navconfig::nav_config(s, None, None);
    cfg.north_finding = crate::scenario::navconfig::nf_config(s, nf);
    let mut bench = crate::engine::inproc::InProcessBench::new(s, &cfg, motion, Some(tt), None)?;
    let mut last_phase = None;
    let (mut k, mut t) = (0u64, 0.0);
    while bench.running()
        && !bench
            .pipeline()
            .finder()
            .is_none_or(NorthFinder::is_finished)
    {
        t = bench.step();
        if let Some(f) = bench.pipeline().finder() {
            let stage = f.stage();
            if last_phase != Some(stage) || k.is_multiple_of(2000) {
                last_phase = Some(stage);
                progress(&f.progress());
            }
        }
        k += 1;
    }
    let finder = bench
        .pipeline()
        .finder()
        .ok_or_else(|| anyhow::anyhow!("north-finding is not enabled"))?;
    if !finder.is_finished() {
        return Ok(outcome(
            s.truth_heading_deg(),
            None,
            Some(&format!(
                "not finished within the scenario's {} s (phase {:?})",
                s.duration_s,
                finder.phase()
            )),
            t,
        ));
    }
    Ok(DrillOutcome {
        predicted_sigma_deg: Some(predict(s, nf).sigma_deg),
        ..outcome(s.truth_heading_deg(), finder.result(), finder.abort(), t)
    })
}

/// The drill's verdict: finished, within tolerance, error against the estimated sigma.
fn checks(out: &mut Vec<Check>, s: &Scenario, o: &DrillOutcome) {
    out.push(Check {
        name: "north-finding finished".into(),
        pass: o.abort.is_none() && o.heading_deg.is_some(),
        detail: match (&o.abort, o.heading_deg) {
            (Some(why), _) => format!("aborted: {why}"),
            (None, Some(h)) => format!(
                "heading {h:.4} deg in {:.1} s, {} dwell(s) repeated",
                o.duration_s, o.repeats
            ),
            (None, None) => "no result reported".into(),
        },
    });
    if let (Some(e), Some(sig)) = (o.error_deg, o.sigma_deg) {
        out.push(Check {
            name: "heading within the drill's tolerance".into(),
            pass: e.abs() <= s.heading_tolerance_deg,
            detail: format!(
                "error {e:+.4} deg (truth {:.4}), tolerance {} deg; estimated sigma {sig:.4} deg, error = {:.2} sigma",
                o.truth_deg,
                s.heading_tolerance_deg,
                e.abs() / sig.max(1e-12)
            ),
        });
        out.push(consistency(e, sig, o.predicted_sigma_deg));
    }
}

/// Whatever the tolerance says, an error beyond 3 of nav's own sigmas means nav promised more
/// than it found: its sigma cannot be trusted.
fn consistency(e: f64, sig: f64, predicted: Option<f64>) -> Check {
    let k = e.abs() / sig.max(1e-12);
    let pred = predicted.map_or(String::new(), |p| format!("; predicted sigma {p:.4} deg"));
    Check {
        name: "heading within 3 of nav's sigmas".into(),
        pass: k <= 3.0,
        detail: if k <= 3.0 {
            format!("error {e:+.4} deg = {k:.2} of nav's sigma {sig:.4} deg{pred}")
        } else {
            format!("inconsistent: error {e:+.4} deg = {k:.2} of nav's sigma {sig:.4} deg{pred}")
        },
    }
}

/// The drill's lines of a run's result card.
fn card(s: &Scenario, d: &DrillOutcome) -> String {
    use std::fmt::Write;
    let f = |x: Option<f64>, p: usize| x.map_or("--".to_string(), |v| format!("{v:.p$}"));
    let mut c = String::from("NORTH-FINDING DRILL\n");
    let _ = writeln!(
        c,
        "  found heading {:>10} deg    truth {:.4} deg    error {:>9} deg",
        f(d.heading_deg, 4),
        d.truth_deg,
        f(d.error_deg, 4)
    );
    let _ = writeln!(
        c,
        "  sigma         {:>10} deg    predicted {} deg    error in nav's sigmas {}{}",
        f(d.sigma_deg, 4),
        f(d.predicted_sigma_deg, 4),
        match (d.error_deg, d.sigma_deg) {
            (Some(e), Some(sg)) => format!("{:.2}", e.abs() / sg.max(1e-12)),
            _ => "--".into(),
        },
        match (d.error_deg, d.sigma_deg) {
            (Some(e), Some(sg)) if e.abs() > 3.0 * sg => "  INCONSISTENT (beyond 3)",
            _ => "",
        }
    );
    let _ = writeln!(
        c,
        "  duration {:.1} s    dwells repeated {}    tolerance {} deg",
        d.duration_s, d.repeats, s.heading_tolerance_deg
    );
    if let Some(why) = &d.degraded {
        let _ = writeln!(
            c,
            "  DEGRADED: the mechanism lost, heading from a {why} (sigma above is its own)"
        );
    }
    if let Some(why) = &d.abort {
        let _ = writeln!(c, "  ABORTED: {why}");
    }
    c
}

/// The drill's section of a run's Markdown report.
fn markdown(d: &DrillOutcome) -> String {
    let f = |x: Option<f64>| x.map_or("--".to_string(), |v| format!("{v:.4}"));
    let mut t = crate::table::Table::left(&[
        "found heading",
        "truth",
        "error",
        "nav's sigma",
        "predicted sigma",
        "duration",
        "repeats",
    ]);
    t.row([
        format!("{} deg", f(d.heading_deg)),
        format!("{:.4} deg", d.truth_deg),
        format!("{} deg", f(d.error_deg)),
        format!("{} deg", f(d.sigma_deg)),
        format!("{} deg", f(d.predicted_sigma_deg)),
        format!("{:.1} s", d.duration_s),
        d.repeats.to_string(),
    ]);
    let mut m = format!("## North-finding drill\n\n{}\n", t.finish());
    if let Some(why) = &d.degraded {
        m += &format!("**Degraded:** the mechanism lost, heading from a {why}\n\n");
    }
    if let Some(why) = &d.abort {
        m += &format!("**Aborted:** {why}\n\n");
    }
    m
}

/// The drill's section of a run's HTML report: its figures and the dwells as nav measured them.
fn html(d: &DrillOutcome, nav: &nav::summary::Summary) -> super::Section {
    let f = |x: Option<f64>| x.map_or("--".to_string(), |v| format!("{v:.4}"));
    let nf = serde_json::to_value(&nav.north_finding).unwrap_or_default();
    super::Section {
        title: super::BenchProcedure::title(&NorthFinding),
        figures: vec![
            ("found heading, deg", f(d.heading_deg)),
            ("truth, deg", format!("{:.4}", d.truth_deg)),
            ("error, deg", f(d.error_deg)),
            ("nav's sigma, deg", f(d.sigma_deg)),
            ("predicted sigma, deg", f(d.predicted_sigma_deg)),
            ("duration, s", format!("{:.1}", d.duration_s)),
            ("dwells repeated", d.repeats.to_string()),
            (
                "degraded",
                d.degraded.clone().unwrap_or_else(|| "no".into()),
            ),
            ("aborted", d.abort.clone().unwrap_or_else(|| "no".into())),
        ],
        text: None,
        detail: nf["result"]["positions"]
            .as_array()
            .map(|p| ("The dwells (positions) as nav measured them:", p.clone())),
    }
}

/// Four-position north-finding, as the bench knows it.
pub struct NorthFinding;

impl super::BenchProcedure for NorthFinding {
    fn name(&self) -> &'static str {
        "north-finding"
    }
    fn runs_in(&self, s: &Scenario) -> bool {
        s.north_finding.is_some()
    }
    fn progress_line(&self, p: &serde_json::Value) -> String {
        progress_line(p)
    }
    fn score(
        &self,
        s: &Scenario,
        nav: &nav::summary::Summary,
        sim_reached: f64,
        o: &mut super::Outcomes,
    ) {
        let nf = nav.north_finding.as_ref();
        let (result, why) = super::said(
            self.name(),
            nf.map(|n| (n.result.as_ref(), n.abort.as_deref())),
        );
        o.north_finding = Some(DrillOutcome {
            predicted_sigma_deg: s.north_finding.as_ref().map(|nf| predict(s, nf).sigma_deg),
            ..outcome(s.truth_heading_deg(), result, why.as_deref(), sim_reached)
        });
    }
    fn checks(
        &self,
        s: &Scenario,
        o: &super::Outcomes,
        _nav: &nav::summary::Summary,
        out: &mut Vec<Check>,
    ) {
        if let Some(o) = &o.north_finding {
            checks(out, s, o);
        }
    }
    fn card(&self, s: &Scenario, o: &super::Outcomes) -> Option<String> {
        o.north_finding.as_ref().map(|d| card(s, d))
    }
    fn title(&self) -> &'static str {
        "North-finding drill"
    }
    fn markdown(&self, _s: &Scenario, o: &super::Outcomes) -> Option<String> {
        o.north_finding.as_ref().map(markdown)
    }
    fn html(
        &self,
        _s: &Scenario,
        o: &super::Outcomes,
        nav: &nav::summary::Summary,
    ) -> Option<super::Section> {
        o.north_finding.as_ref().map(|d| html(d, nav))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use emulators::truth::Disturbance;
    use emulators::turntable::{TurntableFaults, TurntableParams};

    fn drill(heading: f64, dwell: f64) -> (Scenario, NorthFindingConfig) {
        let mut s = Scenario::builtin_static();
        s.name = "drill".into();
        s.duration_s = 4.0 * dwell + 60.0;
        s.site.heading_deg = heading;
        s.turntable = Some(TurntableParams::default());
        let nf = NorthFindingConfig {
            dwell_s: dwell,
            ..NorthFindingConfig::default()
        };
        (s, nf)
    }

    #[test]
    fn four_positions_find_north_within_the_noise() {
        let (s, nf) = drill(123.4, 20.0);
        let o = run_in_process(&s, &nf, |_| {}).unwrap();
        assert!(o.abort.is_none(), "{:?}", o.abort);
        let (e, sig) = (o.error_deg.unwrap(), o.sigma_deg.unwrap());
        // bound: ARW / (W cos L sqrt(T)) with T = 80 s: 0.054 deg
        let bound = (s.imu.gyro_arw_dpsh * 60.0
            / (15.041 * s.site.lat_deg.to_radians().cos() * 80f64.sqrt()))
        .to_degrees();
        assert!(
            e.abs() < 4.0 * bound.max(sig),
            "error {e} deg, sigma {sig}, bound {bound}"
        );
        assert!(
            sig < 3.0 * bound && sig > bound / 3.0,
            "sigma {sig} vs bound {bound}"
        );
        assert!(o.duration_s < 4.0 * 20.0 + 40.0, "{}", o.duration_s);
        assert_eq!(o.repeats, 0, "a quiet base needs no repeats");
    }

    #[test]
    fn a_door_slam_during_a_dwell_repeats_it() {
        let (mut s, nf) = drill(10.0, 20.0);
        // positions start about every 25 s; slam in the second dwell
        s.disturbance = vec![Disturbance::DoorSlam {
            at_s: 40.0,
            amplitude_deg: 0.05,
            frequency_hz: 1.8,
            decay_s: 0.6,
        }];
        let o = run_in_process(&s, &nf, |_| {}).unwrap();
        assert!(o.abort.is_none(), "{:?}", o.abort);
        assert!(o.repeats >= 1, "the disturbed dwell was repeated");
        let e = o.error_deg.unwrap();
        assert!(e.abs() < 0.3, "{e}");
    }

    /// The fault matrix's drill (6 s dwells at 45 N): the mechanism's status frames stop at
    /// 12 s, mid-move to 90 deg, or its motor stalls on the move after 5 s. nav goes on by a
    /// static gyrocompass where the table comes to rest (followed by the IMU's vertical gyro),
    /// and its heading is within 3 of its own, larger sigmas; without the fallback it aborts.
    #[test]
    fn a_table_lost_mid_drill_gives_a_degraded_heading_within_3_sigma() {
        type Inject = fn(&mut TurntableFaults);
        let cases: [(&str, Inject); 2] = [
            ("heartbeat", |f| f.status_silent_s = vec![[12.0, 1e9]]),
            ("stall", |f| f.stall_from_s = Some(5.0)),
        ];
        for (word, inject) in cases {
            for seed in [7, 8, 9] {
                let mut s = scenario(30.0 + 40.0 * seed as f64, 45.0, 6.0, seed);
                s.duration_s = 45.0;
                if let Some(t) = s.turntable.as_mut() {
                    inject(&mut t.faults);
                }
                let nf = s.north_finding.clone().unwrap();
                let o = run_in_process(&s, &nf, |_| {}).unwrap();
                assert!(o.abort.is_none(), "{word}: {:?}", o.abort);
                let why = o.degraded.clone().unwrap();
                assert!(why.contains(word), "{why}");
                let (e, sig) = (o.error_deg.unwrap(), o.sigma_deg.unwrap());
                assert!(
                    e.abs() <= 3.0 * sig,
                    "{word} seed {seed}: error {e}, sigma {sig}"
                );
                assert!(sig > o.predicted_sigma_deg.unwrap(), "{sig}");
                let off = NorthFindingConfig {
                    fallback: false,
                    ..nf.clone()
                };
                let o = run_in_process(&s, &off, |_| {}).unwrap();
                assert!(o.abort.unwrap().contains(word));
            }
        }
    }

    /// Two and four positions visited out and back (0, 180, 180, 0; 0, 90, 180, 270, 270, 180,
    /// 90, 0) at the same total dwell as `hil drill` with 8 and 4 s: nav visits every position
    /// in order, dwelling twice where the sequence turns back, and lands within 3 of its sigmas.
    /// (Eight positions, the most moves, go through vcan: `tests/tests/vcan.rs`.)
    #[test]
    fn two_and_four_positions_out_and_back_land_within_3_sigma_in_order() {
        for (n, dwell) in [(2usize, 8.0), (4, 4.0)] {
            let mut s = scenario(123.4, 28.218157, dwell, 3);
            let out: Vec<f64> = (0..n).map(|k| k as f64 * 360.0 / n as f64).collect();
            let want: Vec<f64> = out.iter().chain(out.iter().rev()).copied().collect();
            set_positions(&mut s, nav::procedures::drill_plan::out_and_back(n));
            let nf = s.north_finding.clone().expect("a drill");
            assert_eq!(nf.positions_deg, want, "{n} positions");
            let o = run_in_process(&s, &nf, |_| {}).unwrap();
            assert!(o.abort.is_none(), "{n} positions: {:?}", o.abort);
            let (e, sig) = (o.error_deg.unwrap(), o.sigma_deg.unwrap());
            assert!(
                e.abs() <= 3.0 * sig,
                "{n} positions: error {e} deg, sigma {sig}"
            );
            let visited: Vec<f64> = o.result.as_ref().expect("nav's result")["positions"]
                .as_array()
                .expect("positions")
                .iter()
                .map(|p| p["commanded_deg"].as_f64().expect("commanded"))
                .collect();
            assert_eq!(visited, want, "{n} positions");
        }
    }

    #[test]
    fn a_turntable_fault_aborts_with_the_reason() {
        let (mut s, nf) = drill(10.0, 10.0);
        s.turntable = Some(TurntableParams {
            faults: TurntableFaults {
                lock_fails: true,
                ..TurntableFaults::default()
            },
            ..TurntableParams::default()
        });
        let o = run_in_process(&s, &nf, |_| {}).unwrap();
        let why = o.abort.unwrap();
        assert!(
            why.contains("lock pin") && why.contains("position 1"),
            "{why}"
        );
        assert!(o.heading_deg.is_none());
    }
}
