//! Paper 001 in process: Kalman calibration of a redundant MEMS IMU (four gyros in a
//! tetrahedral layout) on a three-axis table in rate mode, against the six-position method; part
//! of `hil experiment calibration`.
//!
//! The table (the scenario's three-axis mechanism: outer z, then x, then y) runs the paper's
//! profile on a level base at latitude 45 deg: rest, x at 20 deg/s for 75 s, then y, then z,
//! then rest, 360 s at 100 Hz; the emulated gyros ([`emulators::imu::mems`]) read the true body rate.
//! Before the data is used, the table's rates are checked against the commanded profile. nav's
//! 16-state filter ([`nav::procedures::rotating_estimator::TetraKf`], the paper's `P0 = I`, `R = 1e-3 I`) takes each
//! sample's outputs and the rate the table's encoders give ([`nav::procedures::rotating_estimator::table_rate`]). The
//! six-position method ([`nav::procedures::rotating_estimator::six_position`]) gets its own 360 s: plus and minus 20 deg/s
//! about x, y and z, 60 s each.

pub use crate::procedures::tetrahedral::{TetraErrors, errors};
use crate::stats::median;
use crate::table::Table;
use anyhow::{Result, bail};
use emulators::imu::mems::{TetraGyros, TetraParams};
use emulators::truth::{AxisAngle, Composed, Indexer, Motion, RateWindows, Static};
use nalgebra::{UnitQuaternion, Vector3};
use nav::procedures::rotating_estimator::{
    GyroCoefficients, TETRA_GYROS, TetraKf, six_position, table_rate,
};
use serde::Serialize;

/// The paper's bias error bound, deg/s.
pub const PAPER_BIAS_DPS: f64 = 0.0025;
/// The paper's mounting-angle error bound, deg.
pub const PAPER_ANGLE_DEG: f64 = 0.0025;
/// The paper's scale-factor error bound.
pub const PAPER_SF: f64 = 1.5e-5;
/// The paper's bound on the mean relative error.
pub const PAPER_RELATIVE: f64 = 0.009;
/// The paper's improvement over the six-position method.
pub const PAPER_GAIN: f64 = 0.1137;

const RATE_DPS: f64 = 20.0;

/// The paper's profile, `[from s, to s, deg/s]` per axis (z, x, y): 60 s at rest, x, y and z at
/// 20 deg/s for 75 s each, 75 s at rest.
const PAPER_PROFILE: [[f64; 3]; 3] = [
    [210.0, 285.0, RATE_DPS],
    [60.0, 135.0, RATE_DPS],
    [135.0, 210.0, RATE_DPS],
];
const HZ: f64 = 100.0;

/// One run of both methods.
#[derive(Debug, Clone, Serialize)]
pub struct TetraRun {
    /// Gyro noise, deg/s per sample.
    pub noise_dps: f64,
    /// The Kalman filter's errors at the end.
    pub kf: TetraErrors,
    /// The six-position method's.
    pub six: TetraErrors,
    /// When every coefficient of the filter was within 1 % of its final error band for good, s.
    pub converged_s: f64,
    /// 1 - KF / six-position mean relative error.
    pub gain: f64,
}

/// The table: outer z, then x, then y, each axis's rate schedule; the base level at `lat_deg`.
fn table(lat_deg: f64, z: RateWindows, x: RateWindows, y: RateWindows) -> Composed {
    Composed {
        base: Box::new(Static::level(lat_deg).site()),
        relative: vec![
            Box::new(Indexer::azimuth(z)),
            Box::new(Indexer {
                about: Vector3::x_axis(),
                axis: x,
            }),
            Box::new(Indexer {
                about: Vector3::y_axis(),
                axis: y,
            }),
        ],
        linear: None,
    }
}

fn windows(w: &[[f64; 3]]) -> RateWindows {
    RateWindows {
        windows: w.iter().map(|&[a, b, r]| [a, b, r.to_radians()]).collect(),
        accel: 40f64.to_radians(),
    }
}

/// One run at `noise_dps` with the gyros of `seed`.
pub fn run(noise_dps: f64, seed: u64) -> Result<TetraRun> {
    let lat = 45.0;
    let truth = TetraParams {
        noise_dps,
        seed,
        ..TetraParams::default()
    };
    let [zs, xs, ys] = PAPER_PROFILE.map(|w| [w]);
    let (az, ax, ay) = (windows(&zs), windows(&xs), windows(&ys));
    let m = table(lat, az.clone(), ax.clone(), ay.clone());
    let mut gyros = TetraGyros::new(truth.clone());
    let mut kf = TetraKf::new(1.0, 1e-3);
    let q_nb = UnitQuaternion::identity();
    let n = (360.0 * HZ) as usize;
    let mut history = Vec::with_capacity(n / 100);
    for k in 0..n {
        let t = k as f64 / HZ;
        let w = m.omega_ib_b(t).map(f64::to_degrees);
        let out = gyros.sample(&w);
        // the encoders' angles and rates
        let enc = |a: &RateWindows| a.angle_and_rate(t);
        let (z, x, y) = (enc(&az), enc(&ax), enc(&ay));
        // the table did what was commanded: the rate of each axis within 0.001 deg/s of the
        // profile's wherever it holds a rate
        for (axis, (_, rate), sched) in [("z", z, &zs), ("x", x, &xs), ("y", y, &ys)] {
            for &[from, to, r] in sched.iter() {
                if t > from + 1.0 && t < to - 1.0 && (rate.to_degrees() - r).abs() > 1e-3 {
                    bail!(
                        "the table's {axis} axis turned at {:.4} deg/s at {t:.2} s, commanded {r}: calibration data refused",
                        rate.to_degrees()
                    );
                }
            }
        }
        let known = table_rate(
            lat.to_radians(),
            &q_nb,
            &[
                (Vector3::z_axis(), z.0, z.1),
                (Vector3::x_axis(), x.0, x.1),
                (Vector3::y_axis(), y.0, y.1),
            ],
        )
        .map(f64::to_degrees);
        kf.update(&out, &known);
        if k % 100 == 0 {
            history.push((t, kf.coefficients()));
        }
    }
    let est = kf.coefficients();
    // converged: from when on every coefficient stays within 1 % of its true value's size (or
    // of the final error, if larger) of the final estimate
    let truth_c = |i: usize| {
        [
            truth.bias_dps[i],
            truth.scale_factor[i],
            truth.sigma_j_deg[i].to_radians(),
            truth.sigma_k_deg[i].to_radians(),
        ]
    };
    let vals = |c: &GyroCoefficients| [c.bias_dps, c.scale_factor, c.sigma_j, c.sigma_k];
    let settled = |c: &[GyroCoefficients; TETRA_GYROS]| {
        (0..TETRA_GYROS).all(|i| {
            let (now, end, tr) = (vals(&c[i]), vals(&est[i]), truth_c(i));
            (0..4).all(|j| (now[j] - end[j]).abs() <= 0.01 * tr[j].abs())
        })
    };
    let converged_s = history
        .iter()
        .rev()
        .take_while(|(_, c)| settled(c))
        .last()
        .map_or(f64::NAN, |(t, _)| *t);
    let six = six_position_method(&truth, lat)?;
    let (kf_e, six_e) = (errors(&est, &truth), errors(&six, &truth));
    Ok(TetraRun {
        noise_dps,
        kf: kf_e,
        six: six_e,
        converged_s,
        gain: 1.0 - kf_e.relative / six_e.relative,
    })
}

/// The six-position method on the same unit: +-20 deg/s about x, y, z, 60 s each, the gyros'
/// means over the held rate.
fn six_position_method(truth: &TetraParams, lat: f64) -> Result<[GyroCoefficients; TETRA_GYROS]> {
    let mut gyros = TetraGyros::new(truth.clone());
    let plan: [(usize, f64); 6] = [
        (0, RATE_DPS),
        (0, -RATE_DPS),
        (1, RATE_DPS),
        (1, -RATE_DPS),
        (2, RATE_DPS),
        (2, -RATE_DPS),
    ];
    let mut per_axis: [Vec<[f64; 3]>; 3] = Default::default();
    for (slot, (axis, r)) in plan.iter().enumerate() {
        let from = 60.0 * slot as f64;
        per_axis[*axis].push([from, from + 60.0, *r]);
    }
    let m6 = table(
        lat,
        windows(&per_axis[2]),
        windows(&per_axis[0]),
        windows(&per_axis[1]),
    );
    let mut means = [[[0.0; TETRA_GYROS]; 2]; 3];
    for (slot, (axis, r)) in plan.iter().enumerate() {
        let from = 60.0 * slot as f64;
        let (mut sum, mut count) = ([0.0; TETRA_GYROS], 0.0);
        for k in 0..(60.0 * HZ) as usize {
            let t = from + k as f64 / HZ;
            let w = m6.omega_ib_b(t).map(f64::to_degrees);
            let out = gyros.sample(&w);
            if t > from + 2.0 && t < from + 58.0 {
                for i in 0..TETRA_GYROS {
                    sum[i] += out[i];
                }
                count += 1.0;
            }
        }
        means[*axis][usize::from(*r < 0.0)] = sum.map(|s| s / count);
    }
    let Some(six) = six_position(&means, RATE_DPS) else {
        bail!("the six-position system is singular");
    };
    Ok(six)
}

/// One failure injected on the table run, and what nav's parity monitor made of it.
#[derive(Debug, Clone, Serialize)]
pub struct FailureRow {
    /// The failure.
    pub failure: emulators::imu::mems::GyroFailure,
    /// With the table's rate as the reference.
    pub with_reference: bool,
    /// The monitor's state at the end.
    pub status: nav::procedures::redundant_rates::Status,
    /// Seconds from the failure to its detection.
    pub detected_after_s: Option<f64>,
    /// Seconds from the failure to its isolation.
    pub isolated_after_s: Option<f64>,
    /// Largest error of the rate it gave from the isolation on (from the detection where none),
    /// deg/s.
    pub rate_error_dps: f64,
}

/// Each failure at 150 s on the paper's table profile with MEMS noise 0.005 deg/s, calibrated
/// gyros, with and without the table's rate as the reference.
pub fn failures(seed: u64) -> Vec<FailureRow> {
    use emulators::imu::mems::{FailureInjector, GyroFailure};
    let at_s = 150.0;
    let cases = [
        GyroFailure::Stuck { gyro: 1, at_s },
        GyroFailure::BiasJump {
            gyro: 2,
            at_s,
            jump_dps: 0.5,
        },
        GyroFailure::NoiseBurst {
            gyro: 3,
            at_s,
            sigma_dps: 0.2,
        },
    ];
    let noise = 0.005;
    let mut rows = Vec::new();
    for failure in cases {
        for with_reference in [false, true] {
            // the gyros as calibrated: errors-free but for their noise
            let truth = TetraParams {
                bias_dps: [0.0; 4],
                scale_factor: [0.0; 4],
                sigma_j_deg: [0.0; 4],
                sigma_k_deg: [0.0; 4],
                noise_dps: noise,
                seed,
            };
            let [az, ax, ay] = PAPER_PROFILE.map(|w| windows(&[w]));
            let m = table(45.0, az, ax, ay);
            let mut gyros = TetraGyros::new(truth);
            let mut inject = FailureInjector::new(failure, seed);
            let mut mon = nav::procedures::redundant_rates::ParityMonitor::new(noise, 5.0, 50);
            let (mut detected, mut isolated) = (None, None);
            let (mut worst_detected, mut worst_isolated) = (0.0f64, 0.0f64);
            for k in 0..(360.0 * HZ) as usize {
                let t = k as f64 / HZ;
                let w = m.omega_ib_b(t).map(f64::to_degrees);
                let mut out = gyros.sample(&w);
                inject.apply(t, &mut out);
                let r = mon.update(&out, with_reference.then_some(&w));
                let st = mon.status();
                if detected.is_none() && st != nav::procedures::redundant_rates::Status::Healthy {
                    detected = Some(t - at_s);
                }
                if isolated.is_none()
                    && matches!(
                        st,
                        nav::procedures::redundant_rates::Status::Isolated { .. }
                    )
                {
                    isolated = Some(t - at_s);
                }
                if let Some(r) = r {
                    let e = (r - w).norm();
                    if detected.is_some() {
                        worst_detected = worst_detected.max(e);
                    }
                    if isolated.is_some() {
                        worst_isolated = worst_isolated.max(e);
                    }
                }
            }
            rows.push(FailureRow {
                failure,
                with_reference,
                status: mon.status(),
                detected_after_s: detected,
                isolated_after_s: isolated,
                rate_error_dps: if isolated.is_some() {
                    worst_isolated
                } else {
                    worst_detected
                },
            });
        }
    }
    rows
}

/// The failures' table (Markdown).
pub fn failures_markdown(rows: &[FailureRow]) -> String {
    let s = String::from(
        "\n### One failed gyro of four (nav::procedures::redundant_rates's parity monitor)\n\n\
         The table profile above, gyro noise 0.005 deg/s, a failure at 150 s; alarm at 5 sigmas \
         of the parity's mean over 50 samples. A stuck output is right for as long as the rate \
         it froze at holds: it shows when the table's motion next changes (at 210 s).\n\n",
    );
    let mut t = Table::left(&[
        "failure",
        "reference rate",
        "outcome",
        "detected after, s",
        "isolated after, s",
        "largest rate error from then on, deg/s",
    ]);
    for r in rows {
        let outcome = match r.status {
            nav::procedures::redundant_rates::Status::Healthy => "not detected".to_string(),
            nav::procedures::redundant_rates::Status::DetectedNotIsolated { .. } => {
                "detected, not isolable: all four kept".to_string()
            }
            nav::procedures::redundant_rates::Status::Isolated { gyro, by, .. } => {
                format!(
                    "gyro {} isolated ({by:?}), rates from the other three",
                    gyro + 1
                )
            }
        };
        let secs = |a: Option<f64>| a.map_or("-".into(), |a| format!("{a:.2}"));
        t.row([
            serde_json::to_string(&r.failure).unwrap_or_default(),
            (if r.with_reference { "table's" } else { "none" }).to_string(),
            outcome,
            secs(r.detected_after_s),
            secs(r.isolated_after_s),
            format!("{:.3}", r.rate_error_dps),
        ]);
    }
    s + &t.finish()
}

/// Medians over the seeds at one noise level.
#[derive(Debug, Clone, Serialize)]
pub struct TetraSummary {
    /// Gyro noise, deg/s per sample.
    pub noise_dps: f64,
    /// Runs.
    pub runs: usize,
    /// The filter's errors (medians).
    pub kf: TetraErrors,
    /// The six-position method's (medians).
    pub six: TetraErrors,
    /// Convergence time (median), s.
    pub converged_s: f64,
    /// Gain over the six-position method (median).
    pub gain: f64,
    /// Every bound of the paper met by the medians.
    pub meets_paper: bool,
}

/// The experiment at each noise level in `noises` over seeds `seed..seed + runs`.
pub fn experiment(noises: &[f64], runs: usize, seed: u64) -> Result<Vec<TetraSummary>> {
    let jobs: Vec<(f64, u64)> = noises
        .iter()
        .flat_map(|&n| (0..runs as u64).map(move |k| (n, seed + k)))
        .collect();
    let all = crate::par::map(
        &jobs,
        crate::par::threads(),
        |&(n, s)| run(n, s),
        || bail!("a run panicked"),
    )
    .into_iter()
    .collect::<Result<Vec<_>>>()?;
    Ok(noises
        .iter()
        .map(|&n| {
            let rs: Vec<&TetraRun> = all.iter().filter(|r| r.noise_dps == n).collect();
            let med = |f: &dyn Fn(&TetraRun) -> f64| median(rs.iter().map(|r| f(r)).collect());
            let errs = |f: &dyn Fn(&TetraRun) -> TetraErrors| TetraErrors {
                bias_dps: med(&|r| f(r).bias_dps),
                scale_factor: med(&|r| f(r).scale_factor),
                angle_deg: med(&|r| f(r).angle_deg),
                relative: med(&|r| f(r).relative),
            };
            let (kf, six) = (errs(&|r| r.kf), errs(&|r| r.six));
            let (converged_s, gain) = (med(&|r| r.converged_s), med(&|r| r.gain));
            TetraSummary {
                noise_dps: n,
                runs: rs.len(),
                meets_paper: kf.bias_dps < PAPER_BIAS_DPS
                    && kf.angle_deg < PAPER_ANGLE_DEG
                    && kf.scale_factor < PAPER_SF
                    && kf.relative < PAPER_RELATIVE
                    && gain >= PAPER_GAIN
                    && converged_s <= 250.0,
                kf,
                six,
                converged_s,
                gain,
            }
        })
        .collect())
}

/// The paper's noise (1e-3 deg/h), then a good and a common MEMS gyro's, deg/s per sample.
pub const NOISES: [f64; 3] = [1e-3 / 3600.0, 0.005, 0.05];

/// The Markdown section.
pub fn markdown(rows: &[TetraSummary]) -> String {
    let s = String::from(
        "## Paper 001: redundant MEMS IMU (four gyros, tetrahedral) on a three-axis table\n\n\
         The paper's profile (rest, x, y, z at 20 deg/s for 75 s each, rest; 360 s at 100 Hz, \
         latitude 45 deg), its 16-state filter (`P0 = I`, `R = 1e-3 I`), against the six-position \
         method (+-20 deg/s about each axis, 60 s each, the earth's rate neglected). Largest \
         error over the four gyros, medians over the seeds.\n\n",
    );
    let mut t = Table::left(&[
        "gyro noise, deg/s",
        "bias, deg/s (paper < 0.0025)",
        "mounting angle, deg (< 0.0025)",
        "scale factor (< 1.5e-5)",
        "mean relative error (< 0.9 %)",
        "six-position: mean relative error",
        "gain over six-position (paper 11.37 %)",
        "converged (paper 250 s)",
        "paper's bounds",
    ]);
    for r in rows {
        t.row([
            format!("{:.1e}", r.noise_dps),
            format!("{:.2e}", r.kf.bias_dps),
            format!("{:.2e}", r.kf.angle_deg),
            format!("{:.2e}", r.kf.scale_factor),
            format!("{:.3} %", 100.0 * r.kf.relative),
            format!("{:.3} %", 100.0 * r.six.relative),
            format!("{:.1} %", 100.0 * r.gain),
            format!("{:.0} s", r.converged_s),
            (if r.meets_paper { "met" } else { "not met" }).to_string(),
        ]);
    }
    s + &t.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With the paper's noise the filter meets every one of the paper's bounds and beats the
    /// six-position method, which neglects the earth's rate.
    /// Each failure injected on the table is caught; where the evidence allows it is isolated
    /// and the rate from the other three is good.
    #[test]
    fn every_injected_gyro_failure_is_caught() {
        use nav::procedures::redundant_rates::{Isolation, Status};
        let rows = failures(1);
        eprintln!("{}", failures_markdown(&rows));
        for r in &rows {
            // a stuck output shows when the motion next changes (210 s), the others at once
            let due = match r.failure {
                emulators::imu::mems::GyroFailure::Stuck { .. } => 60.0,
                _ => 0.0,
            };
            assert!(
                r.detected_after_s
                    .is_some_and(|a| (due..due + 5.0).contains(&a)),
                "{r:?}"
            );
            match (r.status, r.with_reference) {
                (Status::Isolated { .. }, _) => assert!(r.rate_error_dps < 0.1, "{r:?}"),
                (Status::DetectedNotIsolated { .. }, false) => {
                    assert!(matches!(
                        r.failure,
                        emulators::imu::mems::GyroFailure::BiasJump { .. }
                    ))
                }
                _ => panic!("{r:?}"),
            }
        }
        assert!(rows.iter().filter(|r| r.with_reference).all(|r| matches!(
            r.status,
            Status::Isolated {
                by: Isolation::Reference,
                ..
            }
        )));
    }

    #[test]
    fn the_redundant_imu_calibrates_to_the_papers_bounds() {
        let r = run(1e-3 / 3600.0, 1).unwrap();
        eprintln!("{r:?}");
        assert!(r.kf.bias_dps < PAPER_BIAS_DPS, "{r:?}");
        assert!(r.kf.angle_deg < PAPER_ANGLE_DEG, "{r:?}");
        assert!(r.kf.scale_factor < PAPER_SF, "{r:?}");
        assert!(r.kf.relative < PAPER_RELATIVE, "{r:?}");
        assert!(r.gain > PAPER_GAIN, "{r:?}");
        assert!(r.converged_s <= 300.0, "{r:?}");
    }
}
