//! In-process reference runs: the scenario's devices (faults included) driving nav's own
//! pipeline with no bus in between ([`crate::engine::inproc`]). The bench compares nav's result on vcan
//! against this; experiments use it directly. Same code, no copies.

use crate::scenario::Scenario;
use anyhow::{Context, Result};
use emulators::truth::Motion;
use nalgebra::UnitQuaternion;
use nav::frontend::imu_frames::ImuStats;
use nav::frontend::processing::{ProcessingStats, quaternion_to_rotation_vector};
use serde::{Deserialize, Serialize};

/// Result of an in-process run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct InProcess {
    /// Front-end counters.
    pub imu: ImuStats,
    /// Processing-chain counters.
    pub processing: ProcessingStats,
    /// Sample the attitude is counted from.
    pub origin_sample: Option<i64>,
    /// Sample the attitude is valid at.
    pub valid_sample: i64,
    /// Simulated time of the origin sample, s.
    pub origin_time_s: f64,
    /// Integrated attitude (inertial, from the origin), rotation vector, deg.
    pub rotation_vector_deg: [f64; 3],
    /// Its error against truth, body axes, deg.
    pub error_deg: [f64; 3],
    /// Mean filtered rate over the attitude's span, deg/h.
    pub mean_rate_dph: [f64; 3],
    /// Mean filtered specific force, m/s^2.
    pub mean_specific_force_mps2: [f64; 3],
    /// Static scenarios: what the mean rate should be (truth through the sensor error model,
    /// plus the random drift the emulator applied), deg/h.
    pub expected_rate_dph: Option<[f64; 3]>,
    /// Static scenarios: the expected mean specific force, m/s^2.
    pub expected_specific_force_mps2: Option<[f64; 3]>,
    /// Constant gyro biases applied, deg/h.
    pub gyro_bias_dph: [f64; 3],
    /// Accelerometer biases applied, m/s^2.
    pub accel_bias_mps2: [f64; 3],
    /// Largest dither-filter gain over the dither band (the residual of the dither angle).
    pub dither_residual_gain: f64,
    /// The hash over every frame the pipeline sent, with the sample each went at
    /// (`nav::pipeline::Pipeline::sent_hash`).
    #[serde(default)]
    pub sent_hash: String,
    /// The bus model: load, each identifier's delays, the command round trip.
    #[serde(default)]
    pub bus: emulators::bus::model::BusStats,
}

/// Error of an integrated attitude `q` (body at `t1` relative to body at `t0`, inertial)
/// against the truth motion, as a rotation vector in body axes, rad.
pub fn attitude_error(motion: &dyn Motion, t0: f64, t1: f64, q: &UnitQuaternion<f64>) -> [f64; 3] {
    let truth = motion.inertial_attitude(t0).inverse() * motion.inertial_attitude(t1);
    quaternion_to_rotation_vector(&(truth.inverse() * q))
}

/// Run the scenario in process: its devices driving nav's pipeline
/// ([`crate::engine::inproc::InProcessBench`]), the integrated attitude scored against the truth.
pub fn run_in_process(s: &Scenario) -> Result<InProcess> {
    let mut bench = crate::engine::inproc::InProcessBench::of(s)?;
    while bench.running() {
        bench.step();
    }
    bench.finish();
    let p = bench.pipeline();
    let sum = p.summary();
    let proc = p.processor();
    let base = proc.baseline().unwrap_or(0) as i64;
    let origin_time_s = bench.time_of(proc.origin().unwrap_or(base));
    let q = proc.attitude();
    let imu = bench.imu();
    let err = attitude_error(
        imu.motion(),
        origin_time_s,
        bench.time_of(proc.valid_sample()),
        &q,
    );
    let dph = nav::navigation::earth::DEG_PER_HOUR_PER_RAD_S;
    let (expected_rate_dph, expected_specific_force_mps2) = if s.is_static() {
        let m = imu.error_model();
        let drift = imu.mean_drift_dph();
        let w = m.gyro(&s.site.rate()) * dph;
        let f = m.accel(&s.site.force());
        (
            Some(std::array::from_fn(|i| w[i] + drift[i])),
            Some(f.into()),
        )
    } else {
        (None, None)
    };
    let fir = s
        .processing
        .dither_filter
        .then(|| nav::frontend::dither_filter::Fir::design(s.processing.fir))
        .transpose()
        .context("dither filter")?;
    let dither_residual_gain = fir.map_or(1.0, |f| {
        (300..=430)
            .map(|hz| f.amplitude(f64::from(hz)).abs())
            .fold(0.0, f64::max)
    });
    Ok(InProcess {
        mean_rate_dph: sum.mean_rate_dph,
        mean_specific_force_mps2: sum.mean_specific_force_mps2,
        expected_rate_dph,
        expected_specific_force_mps2,
        gyro_bias_dph: imu.gyro_bias_dph(),
        accel_bias_mps2: imu.accel_bias_mps2(),
        dither_residual_gain,
        imu: sum.imu,
        processing: sum.processing,
        origin_sample: proc.origin(),
        valid_sample: proc.valid_sample(),
        origin_time_s,
        rotation_vector_deg: sum.attitude.rotation_vector_deg,
        error_deg: err.map(f64::to_degrees),
        sent_hash: sum.solution.sent_hash,
        bus: bench.bus_stats(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use emulators::imu::ImuParams;
    use emulators::truth::Coning;

    #[test]
    fn static_run_in_process_matches_truth_through_the_error_model() {
        let mut s = Scenario::builtin_static();
        s.duration_s = 20.0;
        let r = run_in_process(&s).unwrap();
        let t = (r.valid_sample - r.origin_sample.unwrap()) as f64 / 2000.0;
        assert!(t > 19.9, "{t}");
        let want = r.expected_rate_dph.unwrap();
        let lim = 5.0 * s.imu.gyro_arw_dpsh * 60.0 / t.sqrt()
            + (2.0 + 2.0 * 400.0 * r.dither_residual_gain) / t;
        for (i, (got, want)) in r.mean_rate_dph.iter().zip(want).enumerate() {
            assert!(
                (got - want).abs() <= lim,
                "axis {i}: {got} vs {want} (limit {lim})"
            );
        }
        let f = r.expected_specific_force_mps2.unwrap();
        for (i, (got, want)) in r.mean_specific_force_mps2.iter().zip(f).enumerate() {
            let e = (got - want).abs();
            assert!(e <= 5.0 * 0.001 / t.sqrt() + 2e-4 / t, "axis {i}: {e}");
        }
    }

    #[test]
    fn coning_on_an_ideal_imu_tracks_truth_through_frames_and_filter() {
        let mut s = Scenario::builtin_static();
        s.duration_s = 10.0;
        s.coning = Some(Coning {
            half_angle_deg: 1.0,
            frequency_hz: 10.0,
        });
        s.imu = ImuParams::ideal();
        let r = run_in_process(&s).unwrap();
        // the cone axis (x) does not drift beyond quantization (1 arcsec pulses); across it the
        // filter's passband gain scales the coning's oscillation: |1 - F(10 Hz)| a
        let fir = nav::frontend::dither_filter::Fir::default_dither_filter();
        let across = (1.0 - fir.amplitude(10.0)).abs() * 3600.0 + 3.0;
        let e = r.error_deg.map(|x| x * 3600.0);
        assert!(e[0].abs() < 3.0, "cone-axis error {e:?} arcsec");
        assert!(
            e[1].hypot(e[2]) < across,
            "error across {e:?} arcsec, limit {across}"
        );
        assert_eq!(r.imu.missing_samples, 0);
    }

    #[test]
    fn a_drive_on_an_ideal_imu_tracks_the_inertial_attitude() {
        let mut s = Scenario::builtin_static();
        s.duration_s = 60.0;
        s.drive = Some(emulators::drive::DriveSpec {
            lat_deg: 28.218157,
            lon_deg: 112.989583,
            height_m: 0.0,
            waypoints: vec![[0.0, 200.0], [150.0, 200.0], [150.0, 0.0], [0.0, 0.0]],
            speed_mps: 12.0,
            accel_mps2: 1.5,
            turn_rate_dps: 15.0,
            lateral_accel_mps2: 2.5,
            laps: 1,
            start_wait_s: 2.0,
            ..Default::default()
        });
        s.imu = ImuParams::ideal();
        s.check().unwrap();
        let r = run_in_process(&s).unwrap();
        // four 90 deg turns later the attitude is still right to pulse level
        let e = r.error_deg.map(|x| x * 3600.0);
        assert!(e.iter().all(|x| x.abs() < 5.0), "error {e:?} arcsec");
    }
}
