//! The self-calibration procedure (paper 004's rotating IMU) as an operator command: the
//! scenario, its run in process (the same pipeline the bench's nav runs), and its scoring
//! against the emulated unit's true errors, on the bus or in process alike.

use crate::check::Check;
use crate::scenario::Scenario;
use crate::scenario::fogunit::{CalibOptions, fog_params};
use anyhow::{Result, bail};
use nav::procedures::common::Procedure;
use nav::procedures::self_calibration::{SelfCalibrationConfig, SelfCalibrationResult};
use serde::{Deserialize, Serialize};

/// The procedure's settings an operator chooses.
#[derive(Debug, Clone, Serialize)]
pub struct CalibrateOptions {
    /// Latitude of the site, deg.
    pub lat_deg: f64,
    /// The base's true heading, deg.
    pub heading_deg: f64,
    /// The base's true pitch and roll, deg.
    pub tilt_deg: f64,
    /// Coarse alignment at rest, s.
    pub level_s: f64,
    /// Rotation, s.
    pub rotate_s: f64,
    /// Rotation rate, deg/s.
    pub rate_dps: f64,
    /// The inner axis' delay, s.
    pub inner_delay_s: f64,
    /// Seed of the emulated unit and mechanism.
    pub seed: u64,
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        let c = SelfCalibrationConfig::default();
        let e = CalibOptions::default();
        Self {
            lat_deg: e.lat_deg,
            heading_deg: e.heading_deg,
            tilt_deg: e.tilt_deg,
            level_s: c.level_s,
            rotate_s: c.rotate_s,
            rate_dps: c.rate_dps,
            inner_delay_s: c.inner_delay_s,
            seed: 1,
        }
    }
}

/// A calibration bench: paper 004's fibre-optic IMU (the experiment's model, [`fog_params`],
/// 100 Hz) parked at the site (its pitch and roll both `tilt_deg`), the processing chain at the
/// IMU's rate (no dither to strip: it only has to pass the motion, as in
/// scenarios/rotating-fog.toml).
pub(super) fn fog_bench(
    name: &str,
    lat_deg: f64,
    heading_deg: f64,
    tilt_deg: f64,
    seed: u64,
) -> Scenario {
    let mut s = Scenario::builtin_static();
    s.name = name.into();
    s.site.lat_deg = lat_deg;
    s.site.heading_deg = heading_deg;
    s.site.pitch_deg = tilt_deg;
    s.site.roll_deg = tilt_deg;
    let e = CalibOptions {
        lat_deg,
        ..CalibOptions::default()
    };
    s.imu = fog_params(&e, seed);
    s.processing.fir = nav::frontend::dither_filter::FirSpec {
        fs_hz: s.imu.rate_hz,
        passband_hz: 20.0,
        stopband_hz: 45.0,
        order: 16,
        ..Default::default()
    };
    s
}

/// The procedure as a scenario: paper 004's fibre-optic IMU (the experiment's model,
/// [`fog_params`]) on a two-axis mechanism, parked at the site, nav in calibration mode; the
/// scenario lasts long enough for the procedure and its return to zero.
pub fn scenario(o: &CalibrateOptions) -> Scenario {
    let mut s = fog_bench(
        "calibrate-rotating-imu",
        o.lat_deg,
        o.heading_deg,
        o.tilt_deg,
        o.seed,
    );
    let e = CalibOptions {
        lat_deg: o.lat_deg,
        ..CalibOptions::default()
    };
    s.turntable = Some(emulators::turntable::TurntableParams {
        axes: 2,
        seed: o.seed,
        ..Default::default()
    });
    s.self_calibration = Some(SelfCalibrationConfig {
        enabled: true,
        latitude_deg: o.lat_deg,
        rate_dps: o.rate_dps,
        inner_delay_s: o.inner_delay_s,
        level_s: o.level_s,
        rotate_s: o.rotate_s,
        gyro_bias_dph: e.gyro_bias_dph,
        gyro_scale_factor_ppm: e.gyro_sf_ppm,
        accel_bias_g: e.accel_bias_g,
        gyro_noise_dph: e.gyro_noise_dph,
        accel_noise_g: e.accel_noise_g,
        ..SelfCalibrationConfig::default()
    });
    // enabling, the alignment, the rotation, then stopping, returning (up to half a turn at
    // the mechanism's rate) and locking, with a margin
    s.duration_s = o.level_s + o.rotate_s + 60.0;
    s
}

/// One method's errors against the unit's truth.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct MethodScore {
    /// Estimated minus true gyro bias, deg/h.
    pub bias_error_dph: [f64; 3],
    /// Estimated minus true scale-factor error, ppm.
    pub sf_error_ppm: [f64; 3],
    /// Mean absolute bias error, deg/h.
    pub bias_mae_dph: f64,
    /// Mean absolute scale-factor error, ppm.
    pub sf_mae_ppm: f64,
    /// Largest |error| / sigma over the six estimates (the filter's promise kept when small).
    pub worst_sigma_ratio: f64,
    /// The heading error left by the bias residual's east drift, deg.
    pub heading_left_deg: f64,
}

/// The outcome of one procedure.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CalibrateOutcome {
    /// The unit's true gyro biases, deg/h.
    pub true_bias_dph: [f64; 3],
    /// The unit's true scale-factor errors, ppm.
    pub true_sf_ppm: [f64; 3],
    /// The base's true heading, deg.
    pub true_heading_deg: f64,
    /// The heading error the true biases' east drift would cause uncalibrated, deg.
    pub heading_uncalibrated_deg: f64,
    /// The parameters nav started with (a file loaded with `[calibration]`), when any.
    #[serde(default)]
    pub loaded: Option<nav::procedures::unit_parameters::GyroParameters>,
    /// The coarse alignment's heading error, deg: the east gyro bias over the horizontal
    /// earth rate, what a calibrated unit's static alignment gains.
    #[serde(default)]
    pub coarse_heading_error_deg: Option<f64>,
    /// nav's result (none when aborted or unfinished); its estimates are residuals on top of
    /// `loaded`, and the errors below are of the two composed (what nav's parameter file says).
    pub result: Option<SelfCalibrationResult>,
    /// The RLS's errors.
    pub rls: Option<MethodScore>,
    /// The Kalman filter's errors.
    pub kf: Option<MethodScore>,
    /// Why it did not finish, if it did not.
    pub abort: Option<String>,
    /// Simulated time at the end, s.
    pub duration_s: f64,
    /// The parameter file nav made of its result (undated in process).
    #[serde(default)]
    pub parameters: Option<nav::procedures::unit_parameters::ImuParameters>,
}

/// The unit's true biases (deg/h) and scale factors (ppm) of scenario `s`.
pub fn truth(s: &Scenario) -> ([f64; 3], [f64; 3]) {
    let imu = emulators::imu::ImuEmulator::new(s.motion(), s.imu.clone());
    (imu.gyro_bias_dph(), s.imu.gyro_scale_factor_ppm)
}

/// Score nav's result (or its abort) against the truth of scenario `s`.
pub fn outcome(
    s: &Scenario,
    result: Option<&SelfCalibrationResult>,
    abort: Option<&str>,
    duration_s: f64,
) -> CalibrateOutcome {
    let (tb, tk) = truth(s);
    // the east drift of a bias vector (deg/h) with the IMU at the mechanism's zero
    let heading = |b: [f64; 3]| {
        let rad_s = nalgebra::Vector3::from(b).map(|x| (x / 3600.0).to_radians());
        crate::scenario::fogunit::drift_heading_deg(&s.site, &rad_s)
    };
    // what nav started with; its estimates are residuals on top (composed as nav's front end
    // applies them: `(raw - b0) / (1 + k0)` reads `(1 + k') w + b'`)
    let loaded = s.nav_parameters.as_ref().and_then(|p| {
        nav::procedures::unit_parameters::ImuParameters::load(p, &s.unit_id())
            .ok()
            .map(|p| p.gyro)
    });
    let (b0, k0) = loaded.map_or(([0.0; 3], [0.0; 3]), |g| (g.bias_dph, g.scale_factor_ppm));
    let score = |g: &nav::procedures::self_calibration::GyroEstimate| {
        let be: [f64; 3] =
            std::array::from_fn(|j| b0[j] + g.gyro_bias_dph[j] * (1.0 + k0[j] * 1e-6) - tb[j]);
        let ke: [f64; 3] = std::array::from_fn(|j| {
            ((1.0 + g.gyro_scale_factor_ppm[j] * 1e-6) * (1.0 + k0[j] * 1e-6) - 1.0) * 1e6 - tk[j]
        });
        let ratio = (0..3)
            .flat_map(|j| {
                [
                    be[j].abs() / g.bias_sigma_dph[j].max(1e-300),
                    ke[j].abs() / g.scale_factor_sigma_ppm[j].max(1e-300),
                ]
            })
            .fold(0.0, f64::max);
        MethodScore {
            bias_error_dph: be,
            sf_error_ppm: ke,
            bias_mae_dph: be.iter().map(|x| x.abs()).sum::<f64>() / 3.0,
            sf_mae_ppm: ke.iter().map(|x| x.abs()).sum::<f64>() / 3.0,
            worst_sigma_ratio: ratio,
            heading_left_deg: heading(be.map(|x| -x)),
        }
    };
    CalibrateOutcome {
        loaded,
        coarse_heading_error_deg: result
            .map(|r| crate::stats::wrap180(r.base_heading_deg - s.site.heading_deg)),
        true_bias_dph: tb,
        true_sf_ppm: tk,
        true_heading_deg: s.site.heading_deg,
        heading_uncalibrated_deg: heading(tb),
        result: result.cloned(),
        rls: result.map(|r| score(&r.rls)),
        kf: result.map(|r| score(&r.kf)),
        abort: abort.map(str::to_string),
        duration_s,
        parameters: None,
    }
}

/// Step scenario `s` in process (its devices driving nav's pipeline in the bench's bus order)
/// until the procedure `pick` finds in the pipeline has finished, or the scenario ends.
/// `progress` gets the procedure's progress at each stage change and every 10 s of IMU time.
/// Returns the bench, the simulated time reached, and why the procedure did not finish.
pub fn until_finished(
    s: &Scenario,
    pick: fn(&nav::pipeline::Pipeline) -> Option<&dyn Procedure>,
    mut progress: impl FnMut(&serde_json::Value),
) -> Result<(crate::engine::inproc::InProcessBench, f64, Option<String>)> {
    let mut bench = crate::engine::inproc::InProcessBench::of(s)?;
    let Some(name) = pick(bench.pipeline()).map(|p| p.name()) else {
        bail!(
            "scenario {}: the procedure is not enabled in nav's config",
            s.name
        );
    };
    let every = (10.0 * s.imu.rate_hz) as u64;
    let (mut k, mut t, mut last) = (0u64, 0.0, None);
    while bench.running() && pick(bench.pipeline()).is_some_and(|p| !p.is_finished()) {
        t = bench.step();
        if let Some(p) = pick(bench.pipeline()) {
            let stage = p.stage_key();
            if last != Some(stage) || k.is_multiple_of(every) {
                if let Some(j) = p
                    .progress_json()
                    .and_then(|j| serde_json::from_str(&j).ok())
                {
                    progress(&j);
                }
                last = Some(stage);
            }
        }
        k += 1;
    }
    let unfinished = pick(bench.pipeline())
        .filter(|p| !p.is_finished())
        .map(|p| {
            format!(
                "{name} not finished within the scenario's {} s (stage {})",
                s.duration_s,
                p.stage_name()
            )
        });
    Ok((bench, t, unfinished))
}

/// The procedure in process (no bus): the scenario's devices driving nav's pipeline in the
/// bench's bus order; the result is the bench's, bit for bit.
pub fn run_in_process(
    s: &Scenario,
    progress: impl FnMut(&serde_json::Value),
) -> Result<CalibrateOutcome> {
    let (bench, t, unfinished) =
        until_finished(s, |p| p.calibrator().map(|c| c as &dyn Procedure), progress)?;
    let Some(c) = bench.pipeline().calibrator() else {
        bail!("self-calibration is not enabled in nav's config");
    };
    let mut o = outcome(s, c.result(), unfinished.as_deref().or(c.abort()), t);
    o.parameters = bench
        .pipeline()
        .summary()
        .self_calibration
        .and_then(|c| c.parameters);
    Ok(o)
}

/// One live progress line from nav's progress JSON.
pub fn progress_line(p: &serde_json::Value) -> String {
    let arr = |k: &str| {
        p[k].as_array().map(|a| {
            a.iter()
                .map(|x| format!("{:+.4}", x.as_f64().unwrap_or(f64::NAN)))
                .collect::<Vec<_>>()
                .join(" ")
        })
    };
    let est = match (arr("rls_bias_dph"), arr("rls_scale_factor_ppm")) {
        (Some(b), Some(k)) => format!("bias [{b}] deg/h  sf [{k}] ppm"),
        _ => String::new(),
    };
    format!(
        "calibrate: {:<10} left {:6.1} s  t = {:6.1} s  {est}",
        p["phase"].as_str().unwrap_or("?"),
        p["phase_left_s"].as_f64().unwrap_or(0.0),
        p["elapsed_s"].as_f64().unwrap_or(0.0),
    )
}

/// The result card.
pub fn card(o: &CalibrateOutcome) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(s, "== self-calibration of the rotating IMU (paper 004) ==");
    let Some(r) = &o.result else {
        let _ = writeln!(
            s,
            "ABORTED after {:.1} s: {}",
            o.duration_s,
            o.abort.as_deref().unwrap_or("no result")
        );
        return s;
    };
    let v3 = |a: [f64; 3], p: usize| {
        a.iter()
            .map(|x| format!("{x:+.p$}"))
            .collect::<Vec<_>>()
            .join("  ")
    };
    if let Some(g) = &o.loaded {
        let _ = writeln!(
            s,
            "started with      gyro bias {} deg/h, scale factor {} ppm (a parameter file; estimates below are on top of it)",
            v3(g.bias_dph, 5),
            v3(g.scale_factor_ppm, 2)
        );
    }
    let _ = writeln!(
        s,
        "coarse alignment  heading {:.4} deg (true {:.4}, error {:+.4}), pitch {:+.4}, roll {:+.4} deg",
        r.base_heading_deg,
        o.true_heading_deg,
        o.coarse_heading_error_deg.unwrap_or(f64::NAN),
        r.base_tilt_deg[0],
        r.base_tilt_deg[1]
    );
    let _ = writeln!(
        s,
        "rotation          {:.0} s, reversals outer {} inner {}, {} measurements, {} samples without status",
        r.rotation_s, r.reversals[0], r.reversals[1], r.measurements, r.samples_without_status
    );
    let _ = writeln!(
        s,
        "                   gyro bias x y z (deg/h)          scale factor x y z (ppm)"
    );
    let _ = writeln!(
        s,
        "truth             {}    {}",
        v3(o.true_bias_dph, 5),
        v3(o.true_sf_ppm, 2)
    );
    for (name, g, sc) in [("RLS", &r.rls, &o.rls), ("KF", &r.kf, &o.kf)] {
        let _ = writeln!(
            s,
            "{name:<17} {}    {}",
            v3(g.gyro_bias_dph, 5),
            v3(g.gyro_scale_factor_ppm, 2)
        );
        if let Some(sc) = sc {
            let _ = writeln!(
                s,
                "  error{}     {}    {}   (mean |e| {:.5} deg/h, {:.2} ppm; worst |e|/sigma {:.1})",
                if o.loaded.is_some() {
                    " (file)"
                } else {
                    "       "
                },
                v3(sc.bias_error_dph, 5),
                v3(sc.sf_error_ppm, 2),
                sc.bias_mae_dph,
                sc.sf_mae_ppm,
                sc.worst_sigma_ratio
            );
        }
    }
    if let (Some(a), Some(b)) = (&o.rls, &o.kf) {
        let _ = writeln!(
            s,
            "RLS / KF          bias {:.1} %, scale factor {:.1} % (paper: 52.41 %, 46.68 %)",
            100.0 * a.bias_mae_dph / b.bias_mae_dph.max(1e-300),
            100.0 * a.sf_mae_ppm / b.sf_mae_ppm.max(1e-300)
        );
        let _ = writeln!(
            s,
            "heading error from east drift: {:+.4} deg uncalibrated, {:+.4} left by the RLS, {:+.4} by the KF",
            o.heading_uncalibrated_deg, a.heading_left_deg, b.heading_left_deg
        );
    }
    let _ = writeln!(s, "duration {:.1} s", r.duration_s);
    s
}

/// The self-calibration's verdict: finished, each RLS estimate within three of its sigmas of
/// the unit's truth (the sigma a promise kept), and the parameter file written and loadable
/// for the unit.
fn checks(out: &mut Vec<Check>, o: &CalibrateOutcome, nav: &nav::summary::Summary) {
    out.push(Check {
        name: "self-calibration finished".into(),
        pass: o.result.is_some(),
        detail: match (&o.result, &o.abort) {
            (Some(r), _) => format!(
                "{:.0} s of rotation, reversals {:?}, locked at zero after {:.1} s",
                r.rotation_s, r.reversals, r.duration_s
            ),
            (None, Some(why)) => format!("aborted: {why}"),
            (None, None) => "no result reported".into(),
        },
    });
    if let (Some(r), Some(sc)) = (&o.result, &o.rls) {
        let ratios: Vec<f64> = (0..3)
            .flat_map(|j| {
                [
                    sc.bias_error_dph[j].abs() / r.rls.bias_sigma_dph[j].max(1e-300),
                    sc.sf_error_ppm[j].abs() / r.rls.scale_factor_sigma_ppm[j].max(1e-300),
                ]
            })
            .collect();
        out.push(Check {
            name: "RLS estimates within 3 sigma of the truth".into(),
            pass: ratios.iter().all(|x| *x <= 3.0),
            detail: format!(
                "bias errors {:.5?} deg/h (sigma {:.5?}), scale-factor errors {:.3?} ppm (sigma {:.3?}); worst {:.2} sigma",
                sc.bias_error_dph,
                r.rls.bias_sigma_dph,
                sc.sf_error_ppm,
                r.rls.scale_factor_sigma_ppm,
                sc.worst_sigma_ratio
            ),
        });
    }
    if o.result.is_some() {
        let sc = nav.self_calibration.as_ref();
        let imu = sc
            .and_then(|c| c.parameters.as_ref())
            .map(|p| p.imu.clone())
            .unwrap_or_default();
        out.push(super::parameter_file_check(
            "parameter file written, and loadable for the unit",
            sc.and_then(|c| c.parameters_file.as_deref()),
            |f| nav::procedures::unit_parameters::ImuParameters::load(f, &imu),
            |p| {
                format!(
                    "unit {}, gyro bias {:.5?} deg/h, scale factor {:.3?} ppm",
                    p.imu, p.gyro.bias_dph, p.gyro.scale_factor_ppm
                )
            },
        ));
    }
}

/// The rotating IMU's self-calibration, as the bench knows it.
pub struct RotatingImu;

impl super::BenchProcedure for RotatingImu {
    fn name(&self) -> &'static str {
        "self-calibration"
    }
    fn runs_in(&self, s: &Scenario) -> bool {
        s.self_calibration.is_some()
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
        let c = nav.self_calibration.as_ref();
        let (result, why) = super::said(
            self.name(),
            c.map(|c| (c.result.as_ref(), c.abort.as_deref())),
        );
        let mut r = outcome(s, result, why.as_deref(), sim_reached);
        r.parameters = c.and_then(|c| c.parameters.clone());
        o.rotating_imu = Some(r);
    }
    fn checks(
        &self,
        _s: &Scenario,
        o: &super::Outcomes,
        nav: &nav::summary::Summary,
        out: &mut Vec<Check>,
    ) {
        if let Some(o) = &o.rotating_imu {
            checks(out, o, nav);
        }
    }
    fn card(&self, _s: &Scenario, o: &super::Outcomes) -> Option<String> {
        o.rotating_imu.as_ref().map(card)
    }
    fn title(&self) -> &'static str {
        "Self-calibration"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A short procedure in process: nav's calibration mode commands the two axes through
    /// their turns and reversals and estimates the unit's biases and scale factors.
    #[test]
    fn a_short_procedure_estimates_the_gyro_errors() {
        let o = CalibrateOptions {
            level_s: 20.0,
            rotate_s: 300.0,
            ..CalibrateOptions::default()
        };
        let s = scenario(&o);
        s.check().expect("scenario");
        let out = run_in_process(&s, |_| {}).expect("runs");
        println!("{}", card(&out));
        let r = out
            .result
            .as_ref()
            .unwrap_or_else(|| panic!("{}", out.abort.as_deref().unwrap_or("no result")));
        assert!(
            r.reversals[0] >= 3 && r.reversals[1] >= 3,
            "{:?}",
            r.reversals
        );
        let rls = out.rls.expect("scored");
        assert!(rls.bias_mae_dph < 0.003, "{rls:?}");
        assert!(rls.sf_mae_ppm < 1.0, "{rls:?}");
    }
}
