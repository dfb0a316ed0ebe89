//! `hil experiment calibration`: paper 004's online gyro self-calibration of a dual-axis rotating
//! IMU, in process. The emulated IMU (the paper's fibre-optic gyros: no dither, 100 Hz) sits in
//! a two-axis mechanism on a static base, both axes turning at 5 deg/s and reversing after every
//! revolution; its frames are decoded by nav's IMU front end, and nav's two estimators
//! ([`nav::procedures::rotating_estimator`]) run on the samples: the paper's decoupled recursive least squares and the
//! 14-state alignment Kalman filter with the gyro biases and scale factors in its state. The
//! mean absolute errors over 450-900 s are compared, as the median over many seeds, with the
//! paper's ratios (52.41 % for the biases, 46.68 % for the scale factors), and the heading error
//! that the east drift would cause a parameter-identification alignment (`eps_E / (W_ie cos L)`)
//! is given without and with each estimate removed (the paper: 47.99 % remains with its RLS).
//!
//! The paper's conditions: latitude 30 deg, true heading 30.06 deg and pitch and roll 0.06 deg
//! against the coarse attitude (30 deg, level) the estimators are given; gyro biases 0.01 deg/h,
//! scale-factor errors 10 ppm, gyro noise 0.005 deg/h (1 sigma per sample), accelerometer biases
//! 1e-4 g and noise 0.5e-4 g; 900 s. The mechanism's angles and rates are the axes' true ones at
//! each sample's middle (the angle and rate sensors taken as perfect).
//!
//! Not yet here (issue 15): the run through vcan with nav commanding the mechanism, and nav's
//! calibration mode and parameter file.

use anyhow::{Context, Result};
use emulators::imu::ImuEmulator;
use emulators::truth::{Composed, Indexer, Reversing, Static};
use nalgebra::{UnitQuaternion, Vector3};
use nav::procedures::rotating_estimator::{AlignKf, AlignKfConfig, GyroRls, expected_rate};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

pub use crate::scenario::fogunit::{CalibOptions, drift_heading_deg, fog_params};
use crate::stats::median;

/// Experiment name (for its report).
pub const CALIBRATION: &str = "calibration";
/// The paper's RLS-to-KF ratio of mean absolute bias errors.
pub const PAPER_BIAS_RATIO: f64 = 0.5241;
/// The paper's ratio for the scale-factor errors.
pub const PAPER_SF_RATIO: f64 = 0.4668;
/// The paper's heading error from drift left after the RLS compensation, against none.
pub const PAPER_HEADING_RATIO: f64 = 0.4799;

const DEG_H: f64 = std::f64::consts::PI / 180.0 / 3600.0;
use crate::scenario::fogunit::G0;

/// One method's figures in one run.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct MethodErrors {
    /// Mean absolute bias error over the scored span, averaged over the three gyros, deg/h.
    pub bias_dph: f64,
    /// The same for the scale-factor errors, ppm.
    pub sf_ppm: f64,
    /// Heading error the east drift left after this method's bias estimate would cause, deg.
    pub heading_deg: f64,
}

/// One run.
#[derive(Debug, Clone, Serialize)]
pub struct CalibRun {
    /// Seed.
    pub seed: u64,
    /// The decoupled RLS.
    pub rls: MethodErrors,
    /// The 14-state Kalman filter.
    pub kf: MethodErrors,
    /// Heading error the east drift causes without calibration, deg.
    pub heading_uncalibrated_deg: f64,
    /// The RLS's estimates at the end: the gyros' biases, deg/h.
    pub rls_bias_dph: [f64; 3],
    /// And their scale-factor errors, ppm.
    pub rls_sf_ppm: [f64; 3],
}

/// The experiment's result.
#[derive(Debug, Clone, Serialize)]
pub struct CalibReport {
    /// Settings.
    pub options: CalibOptions,
    /// Every run.
    pub runs: Vec<CalibRun>,
    /// Medians over the runs: RLS / KF mean absolute bias error.
    pub bias_ratio: f64,
    /// The same for the scale-factor errors.
    pub sf_ratio: f64,
    /// Median heading error left with the RLS's drift estimate against none.
    pub heading_ratio_rls: f64,
    /// The same with the Kalman filter's.
    pub heading_ratio_kf: f64,
    /// Both ratios at or below the paper's.
    pub meets_paper: bool,
    /// Paper 001 at the paper's noise and at realistic MEMS noise.
    pub tetra: Vec<crate::experiments::redundant_imu::TetraSummary>,
    /// One failed gyro of the four, each kind, with and without a reference rate.
    pub failures: Vec<crate::experiments::redundant_imu::FailureRow>,
}

/// One run of both estimators.
pub fn run_one(o: &CalibOptions, seed: u64) -> Result<CalibRun> {
    let lat = o.lat_deg.to_radians();
    let (site, axis, inner, motion) = rig(o);
    let p = fog_params(o, seed);
    let mut imu = ImuEmulator::new(Box::new(motion), p.clone());
    let true_bias = Vector3::from(imu.gyro_bias_dph()) * DEG_H;
    let true_sf = Vector3::from(p.gyro_scale_factor_ppm) * 1e-6;
    let mut front =
        nav::frontend::imu_frames::ImuFrontEnd::new(nav::frontend::imu_frames::ImuCalibration {
            gyro_pulse_arcsec: p.gyro_pulse_arcsec,
            accel_pulse_mps: p.accel_pulse_mps,
            gyro_range_dps: p.gyro_range_dps,
            accel_range_mps2: p.accel_range_g * G0,
            rate_hz: p.rate_hz,
            ..Default::default()
        });
    let dt = 1.0 / o.rate_hz;
    let noise = o.gyro_noise_dph * DEG_H;
    let mut rls = GyroRls::new(o.gyro_bias_dph * DEG_H, o.gyro_sf_ppm * 1e-6, noise);
    // the coarse attitude: heading known roughly, levelled
    let q_nb =
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -o.coarse_heading_deg.to_radians());
    let kf_cfg = align_config(o);
    // the filter starts with the first sample nav's front end gives (the second on the wire:
    // the first only sets the counters), at the mechanism's angles then
    let mut kf: Option<AlignKf> = None;
    let n = (o.duration_s * o.rate_hz).round() as u64;
    let (mut samples, mut events) = (Vec::new(), Vec::new());
    let (mut i, mut scored) = (0u64, 0u64);
    let (mut rls_err, mut kf_err) = ([0.0f64; 2], [0.0f64; 2]);
    use emulators::truth::AxisAngle;
    while i < n {
        let s = imu.next_sample();
        for f in &s.frames {
            let m = wire::Message::decode(f)
                .with_context(|| format!("sample {}: frame 0x{:03X}", s.k, f.id))?;
            front.on_message(&m, &mut samples, &mut events);
        }
        for smp in samples.drain(..) {
            // the sample of the frames just decoded: sample s.k, over (k dt, (k + 1) dt]
            let t = (s.k as f64 + 0.5) * dt;
            let (ax, wx) = inner.angle_and_rate(t);
            let (az, wz) = axis.angle_and_rate(t);
            let w_exp = expected_rate(lat, &q_nb, [ax, az], [wx, wz]);
            let dth = Vector3::from(smp.dtheta) / f64::from(smp.span);
            rls.update(&(dth / dt), &w_exp);
            let kf = kf.get_or_insert_with(|| {
                let t0 = s.k as f64 * dt;
                let q0 = q_nb
                    * nav::procedures::rotating_estimator::c_p_b(inner.angle(t0), axis.angle(t0));
                AlignKf::new(kf_cfg, q0, lat, 0.0, 0.0)
            });
            kf.propagate(&Vector3::from(smp.dtheta), &Vector3::from(smp.dv), dt);
            i += u64::from(smp.span);
            if i.is_multiple_of(10) {
                kf.update();
                if t >= o.score_from_s {
                    scored += 1;
                    let add = |acc: &mut [f64; 2], b: Vector3<f64>, k: Vector3<f64>| {
                        acc[0] += (b - true_bias).abs().sum() / 3.0;
                        acc[1] += (k - true_sf).abs().sum() / 3.0;
                    };
                    add(&mut rls_err, rls.bias(), rls.scale_factor());
                    add(&mut kf_err, kf.bias(), kf.scale_factor());
                }
            }
        }
    }
    let scored = scored.max(1) as f64;
    let heading = |residual: Vector3<f64>| drift_heading_deg(&site, &residual);
    let kf = kf.context("no IMU sample")?;
    let method = |acc: [f64; 2], b: Vector3<f64>| MethodErrors {
        bias_dph: acc[0] / scored / DEG_H,
        sf_ppm: acc[1] / scored * 1e6,
        heading_deg: heading(true_bias - b),
    };
    Ok(CalibRun {
        seed,
        rls: method(rls_err, rls.bias()),
        kf: method(kf_err, kf.bias()),
        heading_uncalibrated_deg: heading(true_bias),
        rls_bias_dph: (rls.bias() / DEG_H).into(),
        rls_sf_ppm: (rls.scale_factor() * 1e6).into(),
    })
}

/// The calibration rig: the unit at the site on an azimuth axis reversing at the options' rate
/// and an inner (x) axis doing the same after its delay.
fn rig(o: &CalibOptions) -> (Static, Reversing, Delayed, Composed) {
    let site = Static {
        lat_deg: o.lat_deg,
        lon_deg: 0.0,
        height_m: 0.0,
        heading_deg: o.heading_deg,
        pitch_deg: o.tilt_deg,
        roll_deg: o.tilt_deg,
    };
    let axis = Reversing {
        rate: o.axis_rate_dps.to_radians(),
        accel: o.axis_rate_dps.to_radians(), // a second to reverse
    };
    let inner = Delayed {
        axis,
        delay_s: o.inner_delay_s,
    };
    let motion = Composed {
        base: Box::new(site.site()),
        relative: vec![
            Box::new(Indexer::azimuth(axis)),
            Box::new(Indexer {
                about: Vector3::x_axis(),
                axis: inner,
            }),
        ],
        linear: None,
    };
    (site, axis, inner, motion)
}

/// The alignment filter's start: its uncertainties and noises from the options.
fn align_config(o: &CalibOptions) -> AlignKfConfig {
    AlignKfConfig {
        attitude0: [0.1f64.to_radians(), 1f64.to_radians()],
        velocity0: 0.1,
        accel_bias0: o.accel_bias_g * G0,
        gyro_bias0: o.gyro_bias_dph * DEG_H,
        gyro_sf0: o.gyro_sf_ppm * 1e-6,
        gyro_noise: o.gyro_noise_dph * DEG_H,
        accel_noise: o.accel_noise_g * G0,
        velocity_noise: 1e-4,
    }
}

/// An axis that starts later.
#[derive(Debug, Clone, Copy)]
struct Delayed {
    axis: Reversing,
    delay_s: f64,
}

impl emulators::truth::AxisAngle for Delayed {
    fn angle(&self, t: f64) -> f64 {
        self.axis.angle(t - self.delay_s)
    }
    fn rate(&self, t: f64) -> f64 {
        self.axis.rate(t - self.delay_s)
    }
}

/// The parameter file the first run's RLS estimates make, in the run folder.
pub const PARAMETER_FILE: &str = "gyro-parameters.toml";

/// The IMU parameter file of a run's RLS estimates (what nav loads at start with
/// `[calibration]`), for the emulated IMU of its seed.
pub fn parameters(
    o: &CalibOptions,
    r: &CalibRun,
) -> nav::procedures::unit_parameters::ImuParameters {
    nav::procedures::unit_parameters::ImuParameters {
        format: nav::procedures::unit_parameters::FORMAT.into(),
        imu: format!("emulated-fog-seed-{}", r.seed),
        procedure: format!(
            "paper 004 decoupled RLS, dual-axis rotation at {} deg/s reversing every turn, {} s, static base at {} deg",
            o.axis_rate_dps, o.duration_s, o.lat_deg
        ),
        date: nav::procedures::unit_parameters::now_rfc3339(),
        gyro: nav::procedures::unit_parameters::GyroParameters {
            bias_dph: r.rls_bias_dph,
            scale_factor_ppm: r.rls_sf_ppm,
        },
    }
}

/// Run the experiment (its runs spread over the cores); writes report.json and report.md to
/// `out` when given.
pub fn calibration(o: &CalibOptions, out: Option<&Path>, progress: bool) -> Result<CalibReport> {
    let seeds: Vec<u64> = (0..o.runs as u64).map(|k| o.seed + k).collect();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let runs = crate::par::map(
        &seeds,
        crate::par::threads(),
        |&s| {
            let r = run_one(o, s);
            let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if progress {
                eprintln!("calibration: run {k} of {} done (seed {s})", seeds.len());
            }
            r
        },
        || Err(anyhow::anyhow!("a run panicked")),
    )
    .into_iter()
    .collect::<Result<Vec<_>>>()?;
    let ratio = |f: &dyn Fn(&CalibRun) -> f64| median(runs.iter().map(f).collect());
    let bias_ratio = ratio(&|r| r.rls.bias_dph / r.kf.bias_dph);
    let sf_ratio = ratio(&|r| r.rls.sf_ppm / r.kf.sf_ppm);
    // the heading errors as a ratio of means: with random bias signs the east drift of one run
    // can be next to nothing, and a ratio per run then means nothing
    let mean_abs = |f: &dyn Fn(&CalibRun) -> f64| {
        runs.iter().map(|r| f(r).abs()).sum::<f64>() / runs.len().max(1) as f64
    };
    let uncal = mean_abs(&|r| r.heading_uncalibrated_deg);
    let heading_ratio_rls = mean_abs(&|r| r.rls.heading_deg) / uncal;
    let heading_ratio_kf = mean_abs(&|r| r.kf.heading_deg) / uncal;
    let tetra = crate::experiments::redundant_imu::experiment(
        &crate::experiments::redundant_imu::NOISES,
        o.runs,
        o.seed,
    )?;
    let report = CalibReport {
        tetra,
        failures: crate::experiments::redundant_imu::failures(o.seed),
        options: o.clone(),
        meets_paper: bias_ratio <= PAPER_BIAS_RATIO && sf_ratio <= PAPER_SF_RATIO,
        runs,
        bias_ratio,
        sf_ratio,
        heading_ratio_rls,
        heading_ratio_kf,
    };
    if let Some(out) = out {
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        std::fs::write(
            out.join("report.json"),
            serde_json::to_string_pretty(&report)?,
        )?;
        std::fs::write(out.join("report.md"), markdown(&report))?;
        if let Some(first) = report.runs.first() {
            let f = out.join(PARAMETER_FILE);
            std::fs::write(&f, parameters(o, first).to_toml())
                .with_context(|| format!("writing {}", f.display()))?;
        }
        crate::report::page::folder_page(
            out,
            "Experiment: calibration (paper 004)",
            &markdown(&report),
        )?;
    }
    Ok(report)
}

/// The report as Markdown.
pub fn markdown(r: &CalibReport) -> String {
    let o = &r.options;
    let med = |f: &dyn Fn(&CalibRun) -> f64| median(r.runs.iter().map(f).collect());
    let mut s = format!(
        "# Paper 004: online gyro self-calibration of a rotating IMU\n\n\
         {} runs (seeds {}-{}), {} s at {} Hz, latitude {} deg, heading {} deg and tilt {} deg against \
         the coarse attitude ({} deg, level); both axes at {} deg/s, reversing every turn. Gyro \
         bias {} deg/h, scale factor {} ppm, noise {} deg/h; accelerometer bias {} g, noise {} g. \
         Mean absolute errors over {}-{} s, averaged over the three gyros; medians over the runs.\n\n",
        r.runs.len(),
        o.seed,
        o.seed + r.runs.len() as u64 - 1,
        o.duration_s,
        o.rate_hz,
        o.lat_deg,
        o.heading_deg,
        o.tilt_deg,
        o.coarse_heading_deg,
        o.axis_rate_dps,
        o.gyro_bias_dph,
        o.gyro_sf_ppm,
        o.gyro_noise_dph,
        o.accel_bias_g,
        o.accel_noise_g,
        o.score_from_s,
        o.duration_s
    );
    let mut t =
        crate::table::Table::left(&["", "decoupled RLS", "14-state KF", "RLS / KF", "paper"]);
    t.row([
        "gyro bias error, deg/h".to_string(),
        format!("{:.2e}", med(&|x| x.rls.bias_dph)),
        format!("{:.2e}", med(&|x| x.kf.bias_dph)),
        format!("{:.1} %", 100.0 * r.bias_ratio),
        format!("{:.2} %", 100.0 * PAPER_BIAS_RATIO),
    ])
    .row([
        "scale-factor error, ppm".to_string(),
        format!("{:.3}", med(&|x| x.rls.sf_ppm)),
        format!("{:.3}", med(&|x| x.kf.sf_ppm)),
        format!("{:.1} %", 100.0 * r.sf_ratio),
        format!("{:.2} %", 100.0 * PAPER_SF_RATIO),
    ]);
    s += &t.finish();
    let mean = |f: &dyn Fn(&CalibRun) -> f64| {
        r.runs.iter().map(|x| f(x).abs()).sum::<f64>() / r.runs.len().max(1) as f64
    };
    let _ = writeln!(
        s,
        "\nHeading error from the east drift (`eps_E / (W_ie cos L)`), mean of its size over the \
         runs: uncalibrated {:.4} deg; left with the RLS's estimate {:.4} deg ({:.1} %; paper \
         {:.2} %), with the KF's {:.4} deg ({:.1} %).\n",
        mean(&|x| x.heading_uncalibrated_deg),
        mean(&|x| x.rls.heading_deg),
        100.0 * r.heading_ratio_rls,
        100.0 * PAPER_HEADING_RATIO,
        mean(&|x| x.kf.heading_deg),
        100.0 * r.heading_ratio_kf
    );
    let _ = writeln!(
        s,
        "Target (ratios at or below the paper's): {}\n",
        if r.meets_paper { "met" } else { "NOT met" }
    );
    s += &crate::experiments::redundant_imu::markdown(&r.tetra);
    s += &crate::experiments::redundant_imu::failures_markdown(&r.failures);
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With the coarse attitude exact, both estimators find the gyros' biases and the RLS their
    /// scale factors; the paper's conditions (the coarse attitude 0.06 deg off) cost the RLS's
    /// bias estimates but not its scale factors, which the Kalman filter hardly sees.
    #[test]
    fn both_estimators_calibrate_the_rotating_imu() {
        let exact = CalibOptions {
            duration_s: 300.0,
            score_from_s: 150.0,
            tilt_deg: 0.0,
            heading_deg: 30.0,
            inner_delay_s: 0.0,
            ..Default::default()
        };
        let r = run_one(&exact, 3).unwrap();
        eprintln!("{r:?}");
        // mean absolute errors over 150-300 s, of a 0.01 deg/h bias and a 10 ppm scale factor
        assert!(r.rls.bias_dph < 5e-4, "{r:?}");
        assert!(r.rls.sf_ppm < 0.2, "{r:?}");
        assert!(r.kf.bias_dph < 5e-3, "{r:?}");
        // the east drift left is a fraction of what it was
        assert!(
            r.rls.heading_deg.abs() < 0.1 * r.heading_uncalibrated_deg.abs(),
            "{r:?}"
        );
        // the axes in step
        let paper = CalibOptions {
            duration_s: 300.0,
            score_from_s: 150.0,
            inner_delay_s: 0.0,
            ..Default::default()
        };
        let p = run_one(&paper, 3).unwrap();
        eprintln!("{p:?}");
        assert!(p.rls.bias_dph > r.rls.bias_dph, "{p:?}");
        assert!(p.rls.sf_ppm < 0.5 && p.kf.sf_ppm > 3.0, "{p:?}");
        // with the inner axis a quarter turn behind, the attitude errors average out better;
        // the parameter file of its estimates is one nav loads, for this unit only
        let delayed = CalibOptions {
            inner_delay_s: 18.0,
            ..paper
        };
        let d = run_one(&delayed, 3).unwrap();
        eprintln!("{d:?}");
        assert!(d.rls.bias_dph < p.rls.bias_dph, "{d:?}");
        let f = parameters(&delayed, &d);
        assert_eq!(f.check("emulated-fog-seed-3"), Ok(()));
        assert!(f.check("emulated-fog-seed-4").is_err());
        for j in 0..3 {
            assert!((f.gyro.scale_factor_ppm[j] - 10.0).abs() < 1.0, "{f:?}");
            assert!((f.gyro.bias_dph[j].abs() - 0.01).abs() < 0.004, "{f:?}");
        }
    }
}
