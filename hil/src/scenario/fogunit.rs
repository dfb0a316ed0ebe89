//! Paper 004's dual-axis rotating fibre-optic IMU as the bench emulates it: the unit's settings
//! (`CalibOptions`, shared by the operator procedure `hil calibrate rotating-imu` and the
//! calibration experiment), its IMU parameters, and the heading error its gyro biases make.

use emulators::imu::ImuParams;
use emulators::truth::Static;
use nalgebra::Vector3;
use serde::Serialize;

/// Standard gravity, m/s^2 (the unit's g).
pub const G0: f64 = 9.80665;

/// The experiment's settings.
#[derive(Debug, Clone, Serialize)]
pub struct CalibOptions {
    /// Seeds (one run each).
    pub runs: usize,
    /// First seed.
    pub seed: u64,
    /// Run length, s (the paper: 900).
    pub duration_s: f64,
    /// Errors are averaged from this time on, s (the paper: 450).
    pub score_from_s: f64,
    /// Latitude, deg.
    pub lat_deg: f64,
    /// True heading, deg.
    pub heading_deg: f64,
    /// True pitch and roll, deg (the coarse attitude takes them for 0).
    pub tilt_deg: f64,
    /// The coarse heading the estimators are given, deg.
    pub coarse_heading_deg: f64,
    /// Gyro bias magnitude, deg/h (random sign per gyro).
    pub gyro_bias_dph: f64,
    /// Gyro scale-factor error, ppm.
    pub gyro_sf_ppm: f64,
    /// Gyro noise, deg/h, 1 sigma per sample.
    pub gyro_noise_dph: f64,
    /// Accelerometer bias magnitude, g.
    pub accel_bias_g: f64,
    /// Accelerometer noise, g, 1 sigma per sample.
    pub accel_noise_g: f64,
    /// Rate of each axis, deg/s.
    pub axis_rate_dps: f64,
    /// The inner axis starts this long after the outer, s (0: the axes turn in step; the paper
    /// does not say how its axes are phased).
    pub inner_delay_s: f64,
    /// Sample rate, Hz.
    pub rate_hz: f64,
}

impl Default for CalibOptions {
    fn default() -> Self {
        Self {
            runs: 20,
            seed: 1,
            duration_s: 900.0,
            score_from_s: 450.0,
            lat_deg: 30.0,
            heading_deg: 30.06,
            tilt_deg: 0.06,
            coarse_heading_deg: 30.0,
            gyro_bias_dph: 0.01,
            gyro_sf_ppm: 10.0,
            gyro_noise_dph: 0.005,
            accel_bias_g: 1e-4,
            accel_noise_g: 0.5e-4,
            axis_rate_dps: 5.0,
            inner_delay_s: 18.0,
            rate_hz: 100.0,
        }
    }
}

/// The paper's fibre-optic IMU.
pub fn fog_params(o: &CalibOptions, seed: u64) -> ImuParams {
    let dt = 1.0 / o.rate_hz;
    ImuParams {
        rate_hz: o.rate_hz,
        // fine enough that the output's quantization stays far below the noise studied
        gyro_pulse_arcsec: [0.01; 3],
        accel_pulse_mps: [1e-5; 3],
        // what 16-bit counters of those quanta carry at 100 Hz (9.1 deg/s, 3.3 g)
        gyro_range_dps: 9.0,
        accel_range_g: 3.0,
        gyro_bias_dph: [o.gyro_bias_dph; 3],
        gyro_bias_instability_dph: 0.0,
        // a white rate noise of sigma per sample is an angle random walk of sigma sqrt(dt)
        gyro_arw_dpsh: o.gyro_noise_dph * (dt / 3600.0).sqrt(),
        gyro_scale_factor_ppm: [o.gyro_sf_ppm; 3],
        accel_bias_mps2: [o.accel_bias_g * G0; 3],
        accel_vrw_mpss: o.accel_noise_g * G0 * dt.sqrt(),
        random_bias_sign: true,
        seed,
        ..ImuParams::ideal()
    }
}

/// The heading error (deg) a static alignment makes of gyro biases `b` (rad/s, IMU axes with
/// the IMU at its reference position) on `site`'s true attitude: their east drift over the
/// horizontal earth rate.
pub fn drift_heading_deg(site: &Static, b: &Vector3<f64>) -> f64 {
    let c_nb = emulators::truth::c_b_n(
        site.heading_deg.to_radians(),
        site.pitch_deg.to_radians(),
        site.roll_deg.to_radians(),
    );
    let east = (c_nb * b).x;
    (east / (emulators::geodesy::OMEGA * site.lat_deg.to_radians().cos())).to_degrees()
}
