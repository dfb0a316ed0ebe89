//! The tetrahedral calibration (paper 001's redundant MEMS unit on a three-axis table) as an
//! operator command: the scenario, its run in process (the same pipeline the bench's nav
//! runs), and its scoring against the emulated unit's truth, on the bus or in process alike.

use super::rotating::{fog_bench, until_finished};
use crate::check::Check;
use crate::scenario::Scenario;
use anyhow::{Result, bail};
use emulators::imu::mems::TetraParams;
use nav::procedures::common::Procedure;
use nav::procedures::rotating_estimator::{GyroCoefficients, TETRA_GYROS};
use serde::{Deserialize, Serialize};

/// Largest errors over the four gyros, per coefficient.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct TetraErrors {
    /// Bias, deg/s.
    pub bias_dps: f64,
    /// Scale factor.
    pub scale_factor: f64,
    /// Mounting angles (both), deg.
    pub angle_deg: f64,
    /// Mean relative error over the 16 coefficients.
    pub relative: f64,
}

/// The largest errors over the four gyros of the estimates `est` against the truth `t`, and
/// the mean relative error over the 16 coefficients.
pub fn errors(est: &[GyroCoefficients; TETRA_GYROS], t: &TetraParams) -> TetraErrors {
    let mut e = TetraErrors::default();
    let mut rel = 0.0;
    for (i, c) in est.iter().enumerate() {
        let pairs = [
            (c.bias_dps, t.bias_dps[i]),
            (c.scale_factor, t.scale_factor[i]),
            (c.sigma_j, t.sigma_j_deg[i].to_radians()),
            (c.sigma_k, t.sigma_k_deg[i].to_radians()),
        ];
        e.bias_dps = e.bias_dps.max((pairs[0].0 - pairs[0].1).abs());
        e.scale_factor = e.scale_factor.max((pairs[1].0 - pairs[1].1).abs());
        for (x, y) in &pairs[2..] {
            e.angle_deg = e.angle_deg.max((x - y).abs().to_degrees());
        }
        rel += pairs.iter().map(|(x, y)| ((x - y) / y).abs()).sum::<f64>();
    }
    e.relative = rel / (4 * TETRA_GYROS) as f64;
    e
}

/// Paper 001's procedure as an operator command: its settings.
#[derive(Debug, Clone, Serialize)]
pub struct TetraOptions {
    /// Latitude of the table, deg.
    pub lat_deg: f64,
    /// Heading of the table's base, deg.
    pub heading_deg: f64,
    /// Rate of each turn, deg/s.
    pub rate_dps: f64,
    /// Rest before the turns, s.
    pub rest_s: f64,
    /// Each turn, s.
    pub turn_s: f64,
    /// Rest after the turns, s.
    pub end_rest_s: f64,
    /// The unit's gyro noise, deg/s per sample.
    pub noise_dps: f64,
    /// Run the profile again with the parity monitor.
    pub monitor: bool,
    /// A failure of one gyro (times from the start of the run).
    pub failure: Option<emulators::imu::mems::GyroFailure>,
    /// Start from this parameter file of the unit (an earlier run's): no calibration, the
    /// profile once with the parity monitor.
    pub parameters: Option<std::path::PathBuf>,
    /// Seed.
    pub seed: u64,
}

impl Default for TetraOptions {
    fn default() -> Self {
        let c = nav::procedures::tetra_calibration::TetraCalibrationConfig::default();
        Self {
            lat_deg: c.latitude_deg,
            heading_deg: 0.0,
            rate_dps: c.rate_dps,
            rest_s: c.rest_s,
            turn_s: c.turn_s,
            end_rest_s: c.end_rest_s,
            noise_dps: 0.005,
            monitor: false,
            failure: None,
            parameters: None,
            seed: 1,
        }
    }
}

/// Paper 001's procedure as a scenario: the redundant MEMS unit riding on a quiet 100 Hz IMU
/// (the bench's clock) on a level three-axis table (axes 0, 1, 2 about z, x, y), nav
/// calibrating it.
pub fn tetra_scenario(o: &TetraOptions) -> Scenario {
    let mut s = fog_bench(
        "calibrate-tetrahedral",
        o.lat_deg,
        o.heading_deg,
        0.0,
        o.seed,
    );
    // the rate's range for the table's 20 deg/s: 16-bit counters of 0.1 arcsec at 100 Hz
    s.imu.gyro_pulse_arcsec = [0.1; 3];
    s.imu.gyro_range_dps = 90.0;
    s.imu.tetra = Some(emulators::imu::mems::TetraUnit {
        gyros: emulators::imu::mems::TetraParams {
            noise_dps: o.noise_dps,
            seed: o.seed,
            ..Default::default()
        },
        failure: o.failure,
        ..Default::default()
    });
    s.turntable = Some(emulators::turntable::TurntableParams {
        axes: 3,
        seed: o.seed,
        // a lab table: turns of 20 deg/s and more
        max_rate_dps: 60.0,
        ..Default::default()
    });
    let c = nav::procedures::tetra_calibration::TetraCalibrationConfig {
        enabled: true,
        latitude_deg: o.lat_deg,
        base_heading_deg: o.heading_deg,
        rate_dps: o.rate_dps,
        rest_s: o.rest_s,
        turn_s: o.turn_s,
        end_rest_s: o.end_rest_s,
        monitor: o.monitor,
        gyro_noise_dps: o.noise_dps.max(1e-6),
        // the paper's R, or the unit's noise where that is larger (with the output's
        // quantization and the reference rate's noise, about 0.004 deg/s): the filter's
        // sigmas then keep their promise at MEMS noise too
        r: (o.noise_dps.powi(2) + 0.004f64.powi(2)).max(1e-3),
        parameters: o.parameters.clone(),
        ..Default::default()
    };
    let passes = if o.monitor && o.parameters.is_none() {
        2.0
    } else {
        1.0
    };
    s.duration_s = passes * c.profile_s() + 90.0;
    s.tetra_calibration = Some(c);
    s
}

/// The outcome of paper 001's procedure.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TetraOutcome {
    /// The unit's true coefficients.
    pub truth: emulators::imu::mems::TetraParams,
    /// nav's result.
    pub result: Option<nav::procedures::tetra_calibration::TetraCalibrationResult>,
    /// Largest errors and the mean relative error.
    pub errors: Option<TetraErrors>,
    /// Largest |error| / sigma over the 16 coefficients.
    pub worst_sigma_ratio: Option<f64>,
    /// The failure injected, if any.
    pub failure: Option<emulators::imu::mems::GyroFailure>,
    /// Why it did not finish.
    pub abort: Option<String>,
    /// Simulated time at the end, s.
    pub duration_s: f64,
    /// The unit's parameter file nav made of its estimates (undated in process).
    #[serde(default)]
    pub parameters: Option<nav::procedures::unit_parameters::RedundantParameters>,
}

/// Score nav's result against the unit of scenario `s`.
pub fn tetra_outcome(
    s: &Scenario,
    result: Option<&nav::procedures::tetra_calibration::TetraCalibrationResult>,
    abort: Option<&str>,
    duration_s: f64,
) -> TetraOutcome {
    let unit = s.imu.tetra.clone().unwrap_or_default();
    let t = &unit.gyros;
    let ratio = result.map(|r| {
        (0..4)
            .flat_map(|i| {
                let (c, sg) = (&r.coefficients[i], &r.sigmas[i]);
                [
                    (c.bias_dps - t.bias_dps[i]) / sg.bias_dps,
                    (c.scale_factor - t.scale_factor[i]) / sg.scale_factor,
                    (c.sigma_j - t.sigma_j_deg[i].to_radians()) / sg.sigma_j,
                    (c.sigma_k - t.sigma_k_deg[i].to_radians()) / sg.sigma_k,
                ]
            })
            .map(f64::abs)
            .fold(0.0, f64::max)
    });
    TetraOutcome {
        truth: t.clone(),
        errors: result.map(|r| errors(&r.coefficients, t)),
        worst_sigma_ratio: ratio,
        result: result.cloned(),
        failure: unit.failure,
        abort: abort.map(str::to_string),
        duration_s,
        parameters: None,
    }
}

/// Paper 001's procedure in process, as [`super::rotating::run_in_process`].
pub fn tetra_in_process(
    s: &Scenario,
    progress: impl FnMut(&serde_json::Value),
) -> Result<TetraOutcome> {
    let (bench, t, unfinished) = until_finished(
        s,
        |p| p.tetra_calibrator().map(|c| c as &dyn Procedure),
        progress,
    )?;
    let Some(c) = bench.pipeline().tetra_calibrator() else {
        bail!("tetra_calibration is not enabled in nav's config");
    };
    let mut o = tetra_outcome(s, c.result(), unfinished.as_deref().or(c.abort()), t);
    o.parameters = c.parameters();
    Ok(o)
}

/// One live progress line from nav's tetra-calibration progress JSON.
pub fn tetra_progress_line(p: &serde_json::Value) -> String {
    let b = p["bias_dps"].as_array().map_or(String::new(), |a| {
        a.iter()
            .map(|x| format!("{:+.4}", x.as_f64().unwrap_or(f64::NAN)))
            .collect::<Vec<_>>()
            .join(" ")
    });
    format!(
        "calibrate: {:<11} turning {}  left {:6.1} s  t = {:6.1} s  bias [{b}] deg/s",
        p["phase"].as_str().unwrap_or("?"),
        p["turning"].as_str().unwrap_or("-"),
        p["phase_left_s"].as_f64().unwrap_or(0.0),
        p["elapsed_s"].as_f64().unwrap_or(0.0),
    )
}

/// The result card of paper 001's procedure.
pub fn tetra_card(o: &TetraOutcome) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "== Kalman calibration of the redundant MEMS unit on the three-axis table (paper 001) =="
    );
    let Some(r) = &o.result else {
        let _ = writeln!(
            s,
            "ABORTED after {:.1} s: {}",
            o.duration_s,
            o.abort.as_deref().unwrap_or("no result")
        );
        return s;
    };
    let _ = writeln!(
        s,
        "{} samples, {} s of the profile checked against the commanded rates, {} unmatched frames, {} samples without status",
        r.samples, r.checked_s, r.unmatched_frames, r.samples_without_status
    );
    let _ = writeln!(
        s,
        "gyro  bias deg/s (true)        scale factor (true)       sigma_j deg (true)   sigma_k deg (true)"
    );
    let t = &o.truth;
    for (i, c) in r.coefficients.iter().enumerate() {
        let _ = writeln!(
            s,
            "{}     {:+.5} ({:+.5})   {:+.6} ({:+.6})   {:+.4} ({:+.4})    {:+.4} ({:+.4})",
            i + 1,
            c.bias_dps,
            t.bias_dps[i],
            c.scale_factor,
            t.scale_factor[i],
            c.sigma_j.to_degrees(),
            t.sigma_j_deg[i],
            c.sigma_k.to_degrees(),
            t.sigma_k_deg[i]
        );
    }
    if let (Some(e), Some(q)) = (&o.errors, o.worst_sigma_ratio) {
        let _ = writeln!(
            s,
            "largest errors: bias {:.2e} deg/s (paper < 0.0025), angle {:.2e} deg (< 0.0025), scale factor {:.2e} (< 1.5e-5); mean relative error {:.3} % (< 0.9 %); worst |e|/sigma {q:.1}",
            e.bias_dps,
            e.angle_deg,
            e.scale_factor,
            100.0 * e.relative
        );
    }
    if let Some(m) = &r.monitor {
        let f = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.2} s"));
        let _ = writeln!(
            s,
            "parity monitor: {} (failure injected: {}); alarm at {}, isolated at {} into the monitored pass; worst rate error {:.4} deg/s",
            serde_json::to_string(&m.status).unwrap_or_default(),
            o.failure
                .map_or("none".to_string(), |f| serde_json::to_string(&f)
                    .unwrap_or_default()),
            f(m.detected_at_s),
            f(m.isolated_at_s),
            m.worst_rate_error_dps
        );
    }
    let _ = writeln!(s, "duration {:.1} s", r.duration_s);
    s
}

/// The redundant unit's calibration: finished (the table having done what was commanded
/// throughout), every estimate within 3 of its sigmas of the truth, and with a failure
/// injected, the monitor isolating that gyro.
fn checks(out: &mut Vec<Check>, o: &TetraOutcome, nav: &nav::summary::Summary) {
    out.push(Check {
        name: "tetra-calibration finished, the table's rates checked".into(),
        pass: o.result.as_ref().is_some_and(|r| r.checked_s > 0),
        detail: match (&o.result, &o.abort) {
            (Some(r), _) => format!(
                "{} samples, {} s of the profile checked against the commanded rates, locked at zero after {:.1} s",
                r.samples, r.checked_s, r.duration_s
            ),
            (None, Some(why)) => format!("aborted: {why}"),
            (None, None) => "no result reported".into(),
        },
    });
    let from_file = o.result.as_ref().is_some_and(|r| r.from_file);
    if let (Some(e), Some(q), false) = (&o.errors, o.worst_sigma_ratio, from_file) {
        out.push(Check {
            name: "estimates within 3 sigma of the unit's truth".into(),
            pass: q <= 3.0,
            detail: format!(
                "largest errors: bias {:.2e} deg/s, angle {:.2e} deg, scale factor {:.2e}; mean relative error {:.3} %; worst {q:.2} sigma",
                e.bias_dps,
                e.angle_deg,
                e.scale_factor,
                100.0 * e.relative
            ),
        });
    }
    if o.result.is_some() && !from_file {
        let tc = nav.tetra_calibration.as_ref();
        let unit = tc
            .and_then(|c| c.parameters.as_ref())
            .map(|p| p.imu.clone())
            .unwrap_or_default();
        out.push(super::parameter_file_check(
            "the unit's parameter file written, and loadable for it",
            tc.and_then(|c| c.parameters_file.as_deref()),
            |f| nav::procedures::unit_parameters::RedundantParameters::load(f, &unit),
            |p| format!("unit {}, {} gyros", p.imu, p.gyro.len()),
        ));
    }
    if let (Some(f), Some(r)) = (&o.failure, &o.result) {
        let gyro = match *f {
            emulators::imu::mems::GyroFailure::Stuck { gyro, .. }
            | emulators::imu::mems::GyroFailure::BiasJump { gyro, .. }
            | emulators::imu::mems::GyroFailure::NoiseBurst { gyro, .. } => gyro,
        };
        let m = r.monitor;
        out.push(Check {
            name: "the failed gyro isolated by the parity monitor".into(),
            pass: m.is_some_and(|m| {
                matches!(m.status, nav::procedures::redundant_rates::Status::Isolated { gyro: g, .. } if g == gyro)
            }),
            detail: format!(
                "injected {}; monitor {}",
                serde_json::to_string(f).unwrap_or_default(),
                m.map_or("did not run".to_string(), |m| serde_json::to_string(&m)
                    .unwrap_or_default())
            ),
        });
    }
}

/// The tetrahedral unit's calibration, as the bench knows it.
pub struct Tetrahedral;

impl super::BenchProcedure for Tetrahedral {
    fn name(&self) -> &'static str {
        "tetra-calibration"
    }
    fn runs_in(&self, s: &Scenario) -> bool {
        s.tetra_calibration.is_some()
    }
    fn progress_line(&self, p: &serde_json::Value) -> String {
        tetra_progress_line(p)
    }
    fn score(
        &self,
        s: &Scenario,
        nav: &nav::summary::Summary,
        sim_reached: f64,
        o: &mut super::Outcomes,
    ) {
        let (result, why) = super::said(
            self.name(),
            nav.tetra_calibration
                .as_ref()
                .map(|c| (c.result.as_ref(), c.abort.as_deref())),
        );
        o.tetrahedral = Some(tetra_outcome(s, result, why.as_deref(), sim_reached));
    }
    fn checks(
        &self,
        _s: &Scenario,
        o: &super::Outcomes,
        nav: &nav::summary::Summary,
        out: &mut Vec<Check>,
    ) {
        if let Some(o) = &o.tetrahedral {
            checks(out, o, nav);
        }
    }
    fn card(&self, _s: &Scenario, o: &super::Outcomes) -> Option<String> {
        o.tetrahedral.as_ref().map(tetra_card)
    }
    fn title(&self) -> &'static str {
        "Redundant unit's calibration"
    }
}

#[cfg(test)]
mod tetra_tests {
    use super::*;

    /// A short profile in process: nav commands the table's three axes over the bus's
    /// protocol, checks their rates, calibrates the four gyros, and with a bias jump injected
    /// in the second pass its parity monitor isolates the failed gyro against the table's rate.
    #[test]
    fn a_short_profile_calibrates_the_unit_and_the_monitor_isolates_a_failure() {
        let mut o = TetraOptions {
            rest_s: 5.0,
            turn_s: 20.0,
            end_rest_s: 5.0,
            monitor: true,
            ..TetraOptions::default()
        };
        let s = tetra_scenario(&o);
        let pass = s.tetra_calibration.as_ref().expect("set").profile_s();
        // a jump of gyro 3 halfway through the second pass (the run's start is a few tenths
        // of a second before the profile's)
        o.failure = Some(emulators::imu::mems::GyroFailure::BiasJump {
            gyro: 2,
            at_s: 1.5 * pass,
            jump_dps: 0.5,
        });
        let s = tetra_scenario(&o);
        s.check().expect("scenario");
        let out = tetra_in_process(&s, |_| {}).expect("runs");
        println!("{}", tetra_card(&out));
        let r = out
            .result
            .as_ref()
            .unwrap_or_else(|| panic!("{}", out.abort.as_deref().unwrap_or("no result")));
        let e = out.errors.expect("scored");
        assert!(e.bias_dps < 0.0025 && e.angle_deg < 0.0025, "{e:?}");
        assert!(r.checked_s > 40, "{}", r.checked_s);
        let m = r.monitor.expect("the monitor ran");
        assert!(
            matches!(
                m.status,
                nav::procedures::redundant_rates::Status::Isolated { gyro: 2, .. }
            ),
            "{m:?}"
        );
    }
}
