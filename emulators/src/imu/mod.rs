//! RLG / quartz-accelerometer IMU: sensor errors, pulse quantization, and the frames it sends.
//!
//! Layers: the truth motion gives exact increments; the error model below turns them into what
//! the sensors would count; the counters quantize with carried remainder; the frames encode the
//! 16-bit wrapping counters.
//!
//! Gyro, per axis: scale-factor error and asymmetry (different for positive and negative
//! input), mounting misalignment (small angles onto the other two axes), constant bias (a random
//! sign per axis from the seed), bias instability (first-order Gauss-Markov), angle random walk,
//! mechanical dither (a sinusoidal angle at a distinct frequency per gyro in 300-430 Hz with a
//! random phase: the readout sees the dither, the navigation filter must remove it), range
//! limit (saturation is flagged on the wire).
//!
//! Accelerometer, per axis: scale factor, misalignment, cross-coupling (error proportional to
//! the product of the input and the next axis' acceleration), bias, velocity random walk, range.
//!
//! Defaults follow paper 003's sensor table: gyro bias 0.1 deg/h (its bias stability), random
//! drift 0.05 deg/h (the Gauss-Markov sigma), white noise 0.1 deg/h (taken as the 1 s averaged
//! rate noise, i.e. an angle random walk of 0.1/60 deg/sqrt(h)); accelerometer bias 5e-3 g,
//! white noise 0.001 m/s^2 (1 s averaged: a velocity random walk of 0.001 m/s/sqrt(s)).
//!
//! Quantization carries its remainder from sample to sample, so rounding never becomes drift:
//! the pulse count after N samples differs from the true accumulated angle by less than one
//! pulse, whatever N.

pub mod mapped;
pub mod mems;
pub mod oscillator;
pub mod pulse;
pub mod stream;

pub use crate::imu::oscillator::{ImuTimescale, Oscillator};
pub use crate::imu::pulse::PulseCounter;
use crate::truth::Motion;
use nalgebra::{Matrix3, Vector3};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use wire::{BitFlags, ImuAccel, ImuGyro, ImuHk, Message, RawFrame};

const ARCSEC: f64 = PI / 180.0 / 3600.0;
const DEG_H: f64 = PI / 180.0 / 3600.0;
const G0: f64 = 9.80665;

/// The most the IMU's oscillator may be off its nominal rate, offset and wander together, ppm
/// (a crystal is off by tens; a mis-set rate by more).
pub const MAX_CLOCK_ERROR_PPM: f64 = 5000.0;

/// IMU parameters (every one settable in a scenario file).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ImuParams {
    /// Nominal sample rate, Hz.
    pub rate_hz: f64,
    /// The sample clock's oscillator off its nominal rate, ppm (positive: fast, more samples
    /// per second than `rate_hz`), as a real unit's crystal is by tens of ppm.
    pub clock_offset_ppm: f64,
    /// The oscillator's wander about its offset, ppm (amplitude of a sinusoid over
    /// `clock_wander_period_s`, as with the unit's temperature cycle).
    pub clock_wander_ppm: f64,
    /// The wander's cycle, s.
    pub clock_wander_period_s: f64,
    /// Gyro pulse weight, arcsec/pulse, per axis.
    pub gyro_pulse_arcsec: [f64; 3],
    /// Accelerometer pulse weight, m/s per pulse, per axis.
    pub accel_pulse_mps: [f64; 3],
    /// Gyro constant bias, deg/h, per axis (drawn at +-this with random sign when `random_bias_sign`).
    pub gyro_bias_dph: [f64; 3],
    /// Gyro bias instability (random drift): Gauss-Markov sigma, deg/h.
    pub gyro_bias_instability_dph: f64,
    /// Correlation time of the bias instability, s.
    pub gyro_bias_tau_s: f64,
    /// Gyro angle random walk, deg/sqrt(h).
    pub gyro_arw_dpsh: f64,
    /// Gyro scale-factor error, ppm, per axis.
    pub gyro_scale_factor_ppm: [f64; 3],
    /// Gyro scale-factor asymmetry (positive minus negative input), ppm, per axis.
    pub gyro_sf_asymmetry_ppm: [f64; 3],
    /// Gyro mounting misalignment, arcsec: row i, column j (i != j) is the sensitivity of gyro i
    /// to rate about axis j. The diagonal is ignored.
    pub gyro_misalignment_arcsec: [[f64; 3]; 3],
    /// Dither frequencies, Hz, per gyro (distinct, 300-430 Hz for the type-90 RLG).
    pub dither_hz: [f64; 3],
    /// Dither amplitude (peak angle), arcsec, per gyro. 0 turns dither off.
    pub dither_arcsec: [f64; 3],
    /// Gyro range, deg/s (true input, without dither).
    pub gyro_range_dps: f64,
    /// Accelerometer constant bias, m/s^2, per axis.
    pub accel_bias_mps2: [f64; 3],
    /// Accelerometer velocity random walk, m/s/sqrt(s).
    pub accel_vrw_mpss: f64,
    /// Accelerometer scale-factor error, ppm, per axis.
    pub accel_scale_factor_ppm: [f64; 3],
    /// Accelerometer misalignment, arcsec (as for the gyros).
    pub accel_misalignment_arcsec: [[f64; 3]; 3],
    /// Accelerometer cross-coupling, 1/g: axis i errs by `k_i a_i a_(i+1) / g`.
    pub accel_cross_coupling_per_g: [f64; 3],
    /// Accelerometer range, g.
    pub accel_range_g: f64,
    /// Draw the sign of each bias at random from the seed.
    pub random_bias_sign: bool,
    /// Random seed: the same seed gives the same run.
    pub seed: u64,
    /// Offset of the GPS PPS edge after each whole second of simulated time, s.
    pub pps_phase_s: f64,
    /// Gyro block temperature, degC.
    pub temp_c: f64,
    /// Simulated time from which the built-in test reports a failure (none by default).
    pub bit_fail_from_s: Option<f64>,
    /// Periods [start, end] s in which the IMU flags saturation (a shock beyond its range).
    pub saturated_s: Vec<[f64; 2]>,
    /// Periods [start, end] s in which the PPS input is missing (no edge latched).
    pub pps_missing_s: Vec<[f64; 2]>,
    /// Jitter of the PPS edge latch, s (one sigma, Gaussian, drawn per second from the seed:
    /// a pure function of time, independent of the sensor noise's draws).
    pub pps_jitter_s: f64,
    /// Spurious PPS edges (a glitch on the PPS line) latched at these simulated times, s.
    pub pps_spurious_at_s: Vec<f64>,
    /// Firmware counter jumps: [sample index, jump]: from that sample on, the sample counter
    /// on the wire runs `jump` ahead (the samples themselves are not lost).
    pub counter_jumps: Vec<[u64; 2]>,
    /// A redundant MEMS gyro unit riding with this IMU (paper 001), sampled on its strobe.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tetra: Option<crate::imu::mems::TetraUnit>,
}

impl Default for ImuParams {
    fn default() -> Self {
        Self {
            rate_hz: wire::IMU_RATE_HZ,
            clock_offset_ppm: 0.0,
            clock_wander_ppm: 0.0,
            clock_wander_period_s: 3600.0,
            gyro_pulse_arcsec: [1.0; 3],
            accel_pulse_mps: [1e-4; 3],
            gyro_bias_dph: [0.1; 3],
            gyro_bias_instability_dph: 0.05,
            gyro_bias_tau_s: 600.0,
            gyro_arw_dpsh: 0.1 / 60.0,
            gyro_scale_factor_ppm: [5.0, -3.0, 4.0],
            gyro_sf_asymmetry_ppm: [1.0; 3],
            gyro_misalignment_arcsec: [[0.0, 5.0, -4.0], [3.0, 0.0, 6.0], [-5.0, 2.0, 0.0]],
            dither_hz: [331.0, 373.0, 412.0],
            dither_arcsec: [400.0; 3],
            gyro_range_dps: 400.0,
            accel_bias_mps2: [5e-3 * G0; 3],
            accel_vrw_mpss: 0.001,
            accel_scale_factor_ppm: [50.0, -40.0, 30.0],
            accel_misalignment_arcsec: [[0.0, 10.0, -8.0], [6.0, 0.0, 12.0], [-10.0, 4.0, 0.0]],
            accel_cross_coupling_per_g: [1.5e-5; 3],
            accel_range_g: 10.0,
            random_bias_sign: true,
            seed: 1,
            pps_phase_s: 0.000_123,
            temp_c: 42.0,
            bit_fail_from_s: None,
            saturated_s: Vec::new(),
            pps_missing_s: Vec::new(),
            pps_jitter_s: 0.0,
            pps_spurious_at_s: Vec::new(),
            counter_jumps: Vec::new(),
            tetra: None,
        }
    }
}

impl ImuParams {
    /// An ideal IMU: no errors, no dither; pulses and their quantization only.
    pub fn ideal() -> Self {
        Self {
            gyro_bias_dph: [0.0; 3],
            gyro_bias_instability_dph: 0.0,
            gyro_arw_dpsh: 0.0,
            gyro_scale_factor_ppm: [0.0; 3],
            gyro_sf_asymmetry_ppm: [0.0; 3],
            gyro_misalignment_arcsec: [[0.0; 3]; 3],
            dither_arcsec: [0.0; 3],
            accel_bias_mps2: [0.0; 3],
            accel_vrw_mpss: 0.0,
            accel_scale_factor_ppm: [0.0; 3],
            accel_misalignment_arcsec: [[0.0; 3]; 3],
            accel_cross_coupling_per_g: [0.0; 3],
            ..Self::default()
        }
    }

    /// The sample clock: nominal rate, offset and wander.
    pub fn oscillator(&self) -> Oscillator {
        Oscillator::new(
            self.rate_hz,
            self.clock_offset_ppm,
            self.clock_wander_ppm,
            self.clock_wander_period_s,
        )
    }

    /// Check ranges; the message names the parameter.
    pub fn check(&self) -> Result<(), crate::ParamError> {
        self.check_clock()?;
        self.check_sensors()
    }

    /// The oscillator's offset, wander and cycle.
    fn check_clock(&self) -> Result<(), crate::ParamError> {
        let off = self.clock_offset_ppm.abs() + self.clock_wander_ppm.abs();
        if !(off.is_finite() && off <= MAX_CLOCK_ERROR_PPM) {
            return Err(crate::ParamError::new(
                "imu",
                format!(
                    "clock_offset_ppm ({}) and clock_wander_ppm ({}) must together stay within {MAX_CLOCK_ERROR_PPM} ppm",
                    self.clock_offset_ppm, self.clock_wander_ppm
                ),
            ));
        }
        if !(self.clock_wander_period_s.is_finite() && self.clock_wander_period_s >= 1.0) {
            return Err(crate::ParamError::new(
                "imu",
                format!(
                    "clock_wander_period_s ({}) must be at least 1 s",
                    self.clock_wander_period_s
                ),
            ));
        }
        Ok(())
    }

    /// The sensors' and the PPS's parameters.
    fn check_sensors(&self) -> Result<(), crate::ParamError> {
        for (i, f) in self.dither_hz.iter().enumerate() {
            if self.dither_arcsec[i] != 0.0 && !(*f > 0.0 && *f < self.rate_hz / 2.0) {
                return Err(crate::ParamError::new(
                    "imu",
                    format!(
                        "dither_hz[{i}] = {f} must lie in (0, {}) Hz",
                        self.rate_hz / 2.0
                    ),
                ));
            }
        }
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if !positive(self.gyro_bias_tau_s) {
            return Err(crate::ParamError::new(
                "imu",
                "gyro_bias_tau_s must be positive",
            ));
        }
        if self.gyro_pulse_arcsec.iter().any(|w| !positive(*w))
            || self.accel_pulse_mps.iter().any(|w| !positive(*w))
        {
            return Err(crate::ParamError::new(
                "imu",
                "pulse weights must be positive",
            ));
        }
        if !(positive(self.gyro_range_dps) && positive(self.accel_range_g)) {
            return Err(crate::ParamError::new("imu", "ranges must be positive"));
        }
        // a receiver differences consecutive 16-bit counters: a sample's pulses at full range
        // must stay below half the counter's span to be unambiguous
        let per_sample = |range: f64, pulse: f64| range / self.rate_hz / pulse;
        for (i, w) in self.gyro_pulse_arcsec.iter().enumerate() {
            let n = per_sample(self.gyro_range_dps * 3600.0, *w);
            if n > 32767.0 {
                return Err(crate::ParamError::new(
                    "imu",
                    format!(
                        "gyro_range_dps = {} at rate_hz = {} is {n:.0} pulses of {w} arcsec (axis {i}) a sample: more than the 16-bit counters carry unambiguously (32767); lower the range or coarsen the pulse",
                        self.gyro_range_dps, self.rate_hz
                    ),
                ));
            }
        }
        for (i, w) in self.accel_pulse_mps.iter().enumerate() {
            let n = per_sample(self.accel_range_g * G0, *w);
            if n > 32767.0 {
                return Err(crate::ParamError::new(
                    "imu",
                    format!(
                        "accel_range_g = {} at rate_hz = {} is {n:.0} pulses of {w} m/s (axis {i}) a sample: more than the 16-bit counters carry unambiguously (32767); lower the range or coarsen the pulse",
                        self.accel_range_g, self.rate_hz
                    ),
                ));
            }
        }
        if let Some(t) = &self.tetra {
            if !positive(t.pulse_deg) {
                return Err(crate::ParamError::new(
                    "imu.tetra",
                    "pulse_deg must be positive",
                ));
            }
            if let Some(f) = &t.failure {
                let g = match *f {
                    crate::imu::mems::GyroFailure::Stuck { gyro, .. }
                    | crate::imu::mems::GyroFailure::BiasJump { gyro, .. }
                    | crate::imu::mems::GyroFailure::NoiseBurst { gyro, .. } => gyro,
                };
                if g >= crate::imu::mems::GYROS {
                    return Err(crate::ParamError::new(
                        "imu.tetra.failure",
                        format!("gyro {g} does not exist: gyros are 0 to 3"),
                    ));
                }
            }
        }
        if !(self.pps_jitter_s.is_finite() && (0.0..=0.1).contains(&self.pps_jitter_s)) {
            return Err(crate::ParamError::new(
                "imu",
                format!(
                    "pps_jitter_s = {} must lie in [0, 0.1] s",
                    self.pps_jitter_s
                ),
            ));
        }
        Ok(())
    }
}

/// The deterministic part of the sensor error model (what a calibration would find).
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorModel {
    /// Gyro: `w_out = M_g (w + asym) + bias` with `M_g = I + SF + misalignment`.
    pub gyro_matrix: Matrix3<f64>,
    /// Gyro scale-factor asymmetry, per axis (fraction, half applied with the sign of the input).
    pub gyro_asymmetry: Vector3<f64>,
    /// Gyro constant bias, rad/s.
    pub gyro_bias: Vector3<f64>,
    /// Accelerometer matrix.
    pub accel_matrix: Matrix3<f64>,
    /// Accelerometer cross-coupling, per (m/s^2).
    pub accel_cross: Vector3<f64>,
    /// Accelerometer bias, m/s^2.
    pub accel_bias: Vector3<f64>,
}

impl ErrorModel {
    /// Gyro output rate for a true rate (without noise, drift and dither).
    pub fn gyro(&self, w: &Vector3<f64>) -> Vector3<f64> {
        let asym = Vector3::from_fn(|i, _| 0.5 * self.gyro_asymmetry[i] * w[i].abs());
        self.gyro_matrix * w + asym + self.gyro_bias
    }

    /// Accelerometer output for a true specific force (without noise).
    pub fn accel(&self, f: &Vector3<f64>) -> Vector3<f64> {
        let cross = Vector3::from_fn(|i, _| self.accel_cross[i] * f[i] * f[(i + 1) % 3]);
        self.accel_matrix * f + cross + self.accel_bias
    }
}

fn sensor_matrix(sf_ppm: &[f64; 3], mis_arcsec: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| {
        if i == j {
            1.0 + sf_ppm[i] * 1e-6
        } else {
            mis_arcsec[i][j] * ARCSEC
        }
    })
}

/// The IMU: truth -> errors -> pulses -> frames, one sample at a time.
pub struct ImuEmulator {
    motion: Box<dyn Motion>,
    p: ImuParams,
    dt: f64,
    clock: Oscillator,
    k: u64,
    counter0: u16,
    gyro: [PulseCounter; 3],
    accel: [PulseCounter; 3],
    model: ErrorModel,
    drift: [f64; 3],
    drift_sum: [f64; 3],
    drift_phi: f64,
    drift_drive: f64,
    dither_phase: [f64; 3],
    /// The dither angle at the end of the last sample (the start of the next), and that time.
    dither_last: Option<(f64, [f64; 3])>,
    rng: StdRng,
    arw_sigma: f64,
    vrw_sigma: f64,
    tetra: Option<crate::imu::mems::TetraStream>,
}

/// Frames of one sample.
#[derive(Debug, Clone)]
pub struct SampleFrames {
    /// Sample index since the start (0-based).
    pub k: u64,
    /// IMU_GYRO, IMU_ACCEL and, at 10 Hz, IMU_HK.
    pub frames: Vec<RawFrame>,
    /// The true input went beyond the gyros' or accelerometers' range in this sample (clamped
    /// and flagged; a `saturated_s` window alone does not count).
    pub over_range: bool,
    /// What the unit measured over the sample before its pulse counters (every error of the
    /// model, the dither included): for a contract that carries rates or increments instead
    /// of pulses (`mapped`).
    pub measured: Measured,
}

/// A sample's measured increments, in SI units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measured {
    /// Angle increments x, y, z, rad.
    pub dtheta: [f64; 3],
    /// Velocity increments x, y, z, m/s.
    pub dv: [f64; 3],
    /// The sample's length, s.
    pub dt: f64,
    /// A PPS edge latched in the sample: its time after the sample's start, s.
    pub pps_s: Option<f64>,
    /// The built-in test reports a failure.
    pub bit_fail: bool,
    /// The gyro block's temperature, degC.
    pub temp_c: f64,
}

impl ImuEmulator {
    /// An IMU undergoing `motion`.
    pub fn new(motion: Box<dyn Motion>, p: ImuParams) -> Self {
        let mut rng = StdRng::seed_from_u64(p.seed);
        let mut sign = |b: f64| {
            if p.random_bias_sign && rand::Rng::random_bool(&mut rng, 0.5) {
                -b
            } else {
                b
            }
        };
        let gyro_bias = Vector3::from(p.gyro_bias_dph.map(|b| sign(b) * DEG_H));
        let accel_bias = Vector3::from(p.accel_bias_mps2.map(&mut sign));
        let dt = 1.0 / p.rate_hz;
        // random counter origins so every run exercises the 16-bit wrap
        let counter0 = rand::Rng::random::<u16>(&mut rng);
        let mut gyro = [PulseCounter::default(); 3];
        let mut accel = [PulseCounter::default(); 3];
        for c in gyro.iter_mut().chain(accel.iter_mut()) {
            c.total = i64::from(rand::Rng::random::<u16>(&mut rng));
        }
        let dither_phase = std::array::from_fn(|_| rand::Rng::random::<f64>(&mut rng) * 2.0 * PI);
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let sigma = p.gyro_bias_instability_dph * DEG_H;
        let drift = std::array::from_fn(|_| sigma * n.sample(&mut rng));
        let drift_phi = (-dt / p.gyro_bias_tau_s).exp();
        let model = ErrorModel {
            gyro_matrix: sensor_matrix(&p.gyro_scale_factor_ppm, &p.gyro_misalignment_arcsec),
            gyro_asymmetry: Vector3::from(p.gyro_sf_asymmetry_ppm.map(|x| x * 1e-6)),
            gyro_bias,
            accel_matrix: sensor_matrix(&p.accel_scale_factor_ppm, &p.accel_misalignment_arcsec),
            accel_cross: Vector3::from(p.accel_cross_coupling_per_g.map(|k| k / G0)),
            accel_bias,
        };
        Self {
            motion,
            tetra: p.tetra.clone().map(crate::imu::mems::TetraStream::new),
            arw_sigma: p.gyro_arw_dpsh.to_radians() / 60.0 * dt.sqrt(),
            vrw_sigma: p.accel_vrw_mpss * dt.sqrt(),
            drift_drive: sigma * (1.0 - drift_phi * drift_phi).sqrt(),
            drift_phi,
            drift,
            drift_sum: [0.0; 3],
            dither_phase,
            dither_last: None,
            clock: p.oscillator(),
            p,
            dt,
            k: 0,
            counter0,
            gyro,
            accel,
            model,
            rng,
        }
    }

    /// The gyro constant biases actually applied, deg/h.
    pub fn gyro_bias_dph(&self) -> [f64; 3] {
        std::array::from_fn(|i| self.model.gyro_bias[i] / DEG_H)
    }

    /// The accelerometer biases actually applied, m/s^2.
    pub fn accel_bias_mps2(&self) -> [f64; 3] {
        self.model.accel_bias.into()
    }

    /// Mean bias instability (random drift) applied over the samples so far, deg/h.
    pub fn mean_drift_dph(&self) -> [f64; 3] {
        let n = self.k.max(1) as f64;
        self.drift_sum.map(|x| x / n / DEG_H)
    }

    /// The deterministic error model in use.
    pub fn error_model(&self) -> &ErrorModel {
        &self.model
    }

    /// The parameters in use.
    pub fn params(&self) -> &ImuParams {
        &self.p
    }

    /// The truth motion.
    pub fn motion(&self) -> &dyn Motion {
        self.motion.as_ref()
    }

    /// Index (0-based) of the next sample.
    pub fn next_index(&self) -> u64 {
        self.k
    }

    /// The 16-bit sample counter the frames of sample `k` (0-based) carry.
    pub fn sample_counter(&self, k: u64) -> u16 {
        let jumps: u64 = self
            .p
            .counter_jumps
            .iter()
            .filter(|j| k >= j[0])
            .map(|j| j[1])
            .sum();
        (u64::from(self.counter0) + k + 1 + jumps) as u16
    }

    /// Simulated time at the end of the next sample, s.
    pub fn next_time(&self) -> f64 {
        self.clock.tick_time(self.k + 1)
    }

    /// Simulated time at the end of the last sample produced (0 before any), s.
    pub fn last_time(&self) -> f64 {
        self.clock.tick_time(self.k)
    }

    /// The sample clock.
    pub fn oscillator(&self) -> &Oscillator {
        &self.clock
    }

    /// The PPS edge of second `n`: `n` + phase + that second's jitter, s.
    fn pps_edge(&self, n: f64) -> f64 {
        let mut e = n + self.p.pps_phase_s;
        if self.p.pps_jitter_s > 0.0 {
            // two uniforms from a hash of (seed, second): Box-Muller
            let h = |salt: u64| {
                let mut z = self
                    .p
                    .seed
                    .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                    .wrapping_add((n as i64 as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9))
                    .wrapping_add(salt);
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                z ^= z >> 31;
                ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (u1, u2) = (h(0x5050_5331), h(0x5050_5332));
            e += self.p.pps_jitter_s
                * (-2.0 * u1.ln()).sqrt()
                * (2.0 * std::f64::consts::PI * u2).cos();
        }
        e
    }

    /// The PPS edge latched in (t0, t1], if any.
    fn pps_edge_in(&self, t0: f64, t1: f64) -> Option<f64> {
        let n = (t1 - self.p.pps_phase_s).floor();
        // jitter can move an edge across a whole-second boundary's neighbour samples
        let reach = if self.p.pps_jitter_s > 0.0 { 1.0 } else { 0.0 };
        [n - reach, n, n + reach]
            .into_iter()
            .map(|m| self.pps_edge(m))
            .find(|e| *e > t0 && *e <= t1)
    }

    fn dither(&self, i: usize, t: f64) -> f64 {
        self.p.dither_arcsec[i]
            * ARCSEC
            * (2.0 * PI * self.p.dither_hz[i] * t + self.dither_phase[i]).sin()
    }

    /// Where a PPS edge falls inside the sample (t0, t1], in 1/256 of the sample before its end:
    /// the edge of whole seconds plus phase and jitter unless it is missing, or a spurious one.
    fn pps_offset(&self, t0: f64, t1: f64, edge: Option<f64>) -> Option<u8> {
        let dt = self.sample_length(t0, t1);
        edge.map(|edge| (((t1 - edge) / dt) * 256.0).floor().clamp(0.0, 255.0) as u8)
    }

    /// The PPS edge the unit latches in the sample (t0, t1], if any: a true one outside the
    /// missing windows, else a spurious one.
    fn pps_latched(&self, t0: f64, t1: f64) -> Option<f64> {
        let within = |w: &[[f64; 2]], t: f64| w.iter().any(|p| t >= p[0] && t < p[1]);
        self.pps_edge_in(t0, t1)
            .filter(|e| !within(&self.p.pps_missing_s, *e))
            .or_else(|| {
                self.p
                    .pps_spurious_at_s
                    .iter()
                    .copied()
                    .find(|e| *e > t0 && *e <= t1)
            })
    }

    /// The housekeeping frame, at 10 Hz of samples (none between).
    fn housekeeping(&self, sample_counter: u16, bit_fail: bool) -> Option<wire::RawFrame> {
        if !self
            .k
            .is_multiple_of((self.p.rate_hz / 10.0).round().max(1.0) as u64)
        {
            return None;
        }
        let hk = ImuHk {
            sample_counter,
            temp_gyro_c: self.p.temp_c,
            temp_accel_c: self.p.temp_c - 1.5,
            bit: BitFlags {
                gyro: [bit_fail; 3],
                ..BitFlags::default()
            },
        };
        Message::ImuHk(hk).encode().ok()
    }

    /// The length of the sample (t0, t1], s: the nominal period on a nominal clock (bit for
    /// bit), else the oscillator's.
    fn sample_length(&self, t0: f64, t1: f64) -> f64 {
        if self.clock.is_nominal() {
            self.dt
        } else {
            t1 - t0
        }
    }

    /// Produce the next sample's frames.
    pub fn next_sample(&mut self) -> SampleFrames {
        let (t0, t1) = (
            self.clock.tick_time(self.k),
            self.clock.tick_time(self.k + 1),
        );
        let dt = self.sample_length(t0, t1);
        let inc = self.motion.increments(t0, t1);
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let mut saturated = false;
        // range limits act on the true input
        let glim = self.p.gyro_range_dps.to_radians() * dt;
        let alim = self.p.accel_range_g * G0 * dt;
        let dth = inc.dtheta.map(|x| {
            saturated |= x.abs() > glim;
            x.clamp(-glim, glim)
        });
        let dvt = inc.dv.map(|x| {
            saturated |= x.abs() > alim;
            x.clamp(-alim, alim)
        });
        // the error models are linear in the rate, so applying them to the increment is exact
        let g = self.model.gyro(&(dth / dt)) * dt;
        let a = self.model.accel(&(dvt / dt)) * dt;
        // the dither angle at t0 is the one computed at the end of the last sample
        let d0 = match self.dither_last {
            Some((t, d)) if t == t0 => d,
            _ => std::array::from_fn(|i| self.dither(i, t0)),
        };
        let d1: [f64; 3] = std::array::from_fn(|i| self.dither(i, t1));
        self.dither_last = Some((t1, d1));
        let mut measured = Measured {
            dt,
            ..Measured::default()
        };
        for i in 0..3 {
            let d = g[i] + self.drift[i] * dt + self.arw_sigma * n.sample(&mut self.rng) + d1[i]
                - d0[i];
            measured.dtheta[i] = d;
            self.gyro[i].add(d / (self.p.gyro_pulse_arcsec[i] * ARCSEC));
            self.drift_sum[i] += self.drift[i];
            self.drift[i] =
                self.drift_phi * self.drift[i] + self.drift_drive * n.sample(&mut self.rng);
            let dv = a[i] + self.vrw_sigma * n.sample(&mut self.rng);
            measured.dv[i] = dv;
            self.accel[i].add(dv / self.p.accel_pulse_mps[i]);
        }
        let bit_fail = self.p.bit_fail_from_s.is_some_and(|t| t1 >= t);
        let sample_counter = self.sample_counter(self.k);
        // PPS: an edge (whole seconds + phase + jitter, or a spurious one) inside (t0, t1]?
        let within = |w: &[[f64; 2]], t: f64| w.iter().any(|p| t >= p[0] && t < p[1]);
        let over_range = saturated;
        saturated |= within(&self.p.saturated_s, t1);
        let edge = self.pps_latched(t0, t1);
        let pps_offset = self.pps_offset(t0, t1, edge);
        measured.pps_s = edge.map(|e| e - t0);
        measured.bit_fail = bit_fail;
        measured.temp_c = self.p.temp_c;
        let gf = ImuGyro {
            counts: [
                self.gyro[0].wire(),
                self.gyro[1].wire(),
                self.gyro[2].wire(),
            ],
            sample_counter,
        };
        let af = ImuAccel {
            counts: [
                self.accel[0].wire(),
                self.accel[1].wire(),
                self.accel[2].wire(),
            ],
            sample_counter_low: (sample_counter & 0xF) as u8,
            pps_offset,
            bit_fail,
            saturated,
        };
        let mut frames = Vec::with_capacity(4);
        for m in [Message::ImuGyro(gf), Message::ImuAccel(af)] {
            frames.push(m.encode().expect("IMU frames always encode"));
        }
        let tetra = self
            .tetra
            .as_mut()
            .map(|u| u.frame(t1, dt, &inc.dtheta, sample_counter));
        frames.extend(self.housekeeping(sample_counter, bit_fail));
        if let Some(m) = tetra
            && let Ok(f) = Message::MemsGyro(m).encode()
        {
            frames.push(f);
        }
        let k = self.k;
        self.k += 1;
        SampleFrames {
            k,
            frames,
            over_range,
            measured,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::truth::Static;

    #[test]
    fn quantization_carries_the_remainder() {
        let mut c = PulseCounter::default();
        let mut emitted = 0;
        for _ in 0..1_000_000 {
            emitted += c.add(0.3337);
        }
        assert!((emitted as f64 - 333_700.0).abs() <= 1.0, "{emitted}");
    }

    #[test]
    fn noiseless_static_imu_integrates_to_truth_within_one_pulse() {
        let s = Static {
            lat_deg: 28.2,
            lon_deg: 0.0,
            height_m: 0.0,
            heading_deg: 30.0,
            pitch_deg: 1.0,
            roll_deg: -2.0,
        };
        let p = ImuParams::ideal();
        let mut imu = ImuEmulator::new(Box::new(s), p);
        let start = imu.gyro.map(|c| c.total);
        let n = 20_000;
        for _ in 0..n {
            imu.next_sample();
        }
        let t = n as f64 / 2000.0;
        let w = s.rate();
        let arcsec = std::f64::consts::PI / 180.0 / 3600.0;
        for i in 0..3 {
            let pulses = (imu.gyro[i].total - start[i]) as f64;
            assert!((pulses - w[i] * t / arcsec).abs() <= 1.0, "axis {i}");
        }
    }

    #[test]
    fn an_oscillator_off_nominal_samples_the_truth_on_its_own_ticks() {
        let s = Static::level(45.0);
        let p = ImuParams {
            clock_offset_ppm: 2000.0,
            pps_phase_s: 0.25,
            ..ImuParams::ideal()
        };
        let mut imu = ImuEmulator::new(Box::new(s), p);
        let start = imu.accel[2].total;
        let (n, mut edges) = (20_000u64, Vec::new());
        for _ in 0..n {
            let sf = imu.next_sample();
            for f in sf.frames {
                if let Ok(Message::ImuAccel(a)) = Message::decode(&f)
                    && a.pps_offset.is_some()
                {
                    edges.push(sf.k);
                }
            }
        }
        // 20,000 samples of a clock 0.2 % fast end before 10 s: the up accelerometer counted
        // gravity over those true seconds, not over ten
        let t = imu.last_time();
        assert!((t - 10.0 / 1.002).abs() < 1e-9, "{t}");
        let g = (imu.accel[2].total - start) as f64 * 1e-4 / t;
        assert!((g - s.force()[2]).abs() < 2e-4, "{g}");
        // the receiver's pulses (whole simulated seconds) come 2,004 samples apart
        assert_eq!(edges.len(), 10, "{edges:?}");
        for w in edges.windows(2) {
            assert!((w[1] - w[0]).abs_diff(2004) <= 1, "{edges:?}");
        }
    }

    #[test]
    fn frames_carry_wrapping_counters_pps_and_housekeeping() {
        let s = Static::level(45.0);
        let mut imu = ImuEmulator::new(Box::new(s), ImuParams::default());
        let (mut pps, mut hk, mut last_sc) = (0, 0, None::<u16>);
        for _ in 0..4000 {
            let f = imu.next_sample();
            for fr in &f.frames {
                match Message::decode(fr).expect("decodes") {
                    Message::ImuGyro(g) => {
                        if let Some(l) = last_sc {
                            assert_eq!(g.sample_counter, l.wrapping_add(1));
                        }
                        last_sc = Some(g.sample_counter);
                    }
                    Message::ImuAccel(a) => pps += usize::from(a.pps_offset.is_some()),
                    Message::ImuHk(_) => hk += 1,
                    m => panic!("unexpected {m:?}"),
                }
            }
        }
        assert_eq!(pps, 2, "one PPS edge per simulated second");
        assert_eq!(hk, 20, "housekeeping at 10 Hz");
    }

    /// PPS edges as latched: IMU time of each edge (sample end less the offset), s.
    fn pps_edges(p: ImuParams, samples: usize) -> Vec<f64> {
        let site = Static {
            lat_deg: -33.9,
            lon_deg: 18.4,
            height_m: 0.0,
            heading_deg: 10.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
        };
        let mut imu = ImuEmulator::new(Box::new(site), p);
        let dt = 1.0 / imu.p.rate_hz;
        let mut out = Vec::new();
        for _ in 0..samples {
            let t1 = imu.next_time();
            for f in imu.next_sample().frames {
                if let Ok(Message::ImuAccel(a)) = Message::decode(&f)
                    && let Some(o) = a.pps_offset
                {
                    out.push(t1 - f64::from(o) / 256.0 * dt);
                }
            }
        }
        out
    }

    #[test]
    fn pps_jitter_moves_edges_by_its_sigma_and_spurious_edges_come_where_asked() {
        let base = ImuParams {
            pps_phase_s: 0.25,
            ..ImuParams::default()
        };
        let n = 2000 * 40;
        let clean = pps_edges(base.clone(), n);
        assert_eq!(clean.len(), 40);
        let jittered = pps_edges(
            ImuParams {
                pps_jitter_s: 0.001,
                pps_spurious_at_s: vec![7.6],
                ..base
            },
            n,
        );
        assert_eq!(jittered.len(), 41, "{jittered:?}");
        let spurious: Vec<_> = jittered
            .iter()
            .filter(|e| (*e - 7.6).abs() < 0.001)
            .collect();
        assert_eq!(spurious.len(), 1);
        let dev: Vec<f64> = jittered
            .iter()
            .filter(|e| (*e - 7.6).abs() >= 0.001)
            .zip(&clean)
            .map(|(j, c)| j - c)
            .collect();
        let rms = (dev.iter().map(|d| d * d).sum::<f64>() / dev.len() as f64).sqrt();
        // 40 draws of sigma 1 ms (quantised to 1/256 of a sample)
        assert!((0.0006..0.0015).contains(&rms), "{rms} {dev:?}");
        assert!(dev.iter().all(|d| d.abs() < 0.005));
    }

    #[test]
    fn the_same_seed_gives_the_same_frames() {
        let s = Static::level(10.0);
        let mut a = ImuEmulator::new(Box::new(s), ImuParams::default());
        let mut b = ImuEmulator::new(Box::new(s), ImuParams::default());
        for _ in 0..100 {
            assert_eq!(a.next_sample().frames, b.next_sample().frames);
        }
    }

    fn gyro_pulses(imu: &mut ImuEmulator, n: usize) -> Vec<[i64; 3]> {
        (0..n)
            .map(|_| {
                let before = imu.gyro.map(|c| c.total);
                imu.next_sample();
                std::array::from_fn(|i| imu.gyro[i].total - before[i])
            })
            .collect()
    }

    fn level(lat_deg: f64) -> Static {
        Static::level(lat_deg)
    }

    #[test]
    fn dither_shows_at_its_own_frequency_and_carries_no_net_angle() {
        let p = ImuParams {
            dither_arcsec: [400.0, 300.0, 200.0],
            ..ImuParams::ideal()
        };
        let mut imu = ImuEmulator::new(Box::new(level(0.0)), p.clone());
        let pulses = gyro_pulses(&mut imu, 20_000);
        for i in 0..3 {
            // amplitude of the increments ~ A * 2 sin(pi f dt)
            let peak = pulses.iter().map(|x| x[i].abs()).max().unwrap() as f64;
            let expect = p.dither_arcsec[i] * 2.0 * (PI * p.dither_hz[i] / 2000.0).sin();
            assert!((peak - expect).abs() <= 2.0, "axis {i}: {peak} vs {expect}");
            // the dither is an oscillating angle: the sum stays within its amplitude
            let sum: i64 = pulses.iter().map(|x| x[i]).sum();
            assert!(sum.abs() as f64 <= 2.0 * p.dither_arcsec[i] + 1.0, "{sum}");
            // correlation with its own frequency is strong, with another gyro's weak
            let corr = |f: f64| {
                let (mut c, mut s) = (0.0, 0.0);
                for (k, x) in pulses.iter().enumerate() {
                    let ph = 2.0 * PI * f * k as f64 / 2000.0;
                    c += x[i] as f64 * ph.cos();
                    s += x[i] as f64 * ph.sin();
                }
                (c * c + s * s).sqrt() / pulses.len() as f64
            };
            let own = corr(p.dither_hz[i]);
            let other = corr(p.dither_hz[(i + 1) % 3]);
            assert!(own > 50.0 * other, "axis {i}: {own} vs {other}");
        }
    }

    #[test]
    fn scale_factor_and_misalignment_act_on_the_true_rate() {
        let p = ImuParams {
            gyro_scale_factor_ppm: [1000.0, 0.0, 0.0],
            gyro_misalignment_arcsec: [[0.0; 3], [0.0, 0.0, 0.0], [3600.0, 0.0, 0.0]],
            ..ImuParams::ideal()
        };
        // spin about x at 100 deg/s on a lab table
        let m = crate::truth::Composed {
            base: Box::new(crate::truth::Coning {
                half_angle_deg: 0.0,
                frequency_hz: 1.0,
            }),
            relative: vec![Box::new(RotX(100f64.to_radians()))],
            linear: None,
        };
        let mut imu = ImuEmulator::new(Box::new(m), p);
        let pulses = gyro_pulses(&mut imu, 2000);
        let sum = |i: usize| pulses.iter().map(|x| x[i]).sum::<i64>() as f64;
        // 1 s at 100 deg/s = 360000 arcsec; +1000 ppm; 1 deg misalignment puts sin(1 deg) on z
        assert!((sum(0) - 360_000.0 * 1.001).abs() <= 1.0, "{}", sum(0));
        assert!(
            (sum(2) - 360_000.0 * 3600.0 * ARCSEC).abs() <= 1.0,
            "{}",
            sum(2)
        );
        assert!(sum(1).abs() <= 1.0);
    }

    struct RotX(f64);
    impl crate::truth::RelativeRotation for RotX {
        fn rotation(&self, t: f64) -> nalgebra::UnitQuaternion<f64> {
            nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.0 * t)
        }
        fn rate(&self, _t: f64) -> Vector3<f64> {
            Vector3::new(self.0, 0.0, 0.0)
        }
    }

    #[test]
    fn over_range_input_is_clamped_and_flagged() {
        let m = crate::truth::Composed {
            base: Box::new(level(0.0)),
            relative: vec![Box::new(RotX(500f64.to_radians()))],
            linear: None,
        };
        let mut imu = ImuEmulator::new(Box::new(m), ImuParams::ideal());
        let f = imu.next_sample();
        let sat = f
            .frames
            .iter()
            .any(|fr| matches!(Message::decode(fr), Ok(Message::ImuAccel(a)) if a.saturated));
        assert!(sat, "saturation flagged");
        assert!(f.over_range, "and counted as the motion's, not a window's");
        // a saturated_s window flags without counting
        let p = ImuParams {
            saturated_s: vec![[0.0, 1.0]],
            ..ImuParams::ideal()
        };
        let f = ImuEmulator::new(Box::new(level(0.0)), p).next_sample();
        assert!(!f.over_range);
    }

    #[test]
    fn bias_instability_wanders_with_the_configured_sigma() {
        let p = ImuParams {
            gyro_bias_instability_dph: 0.05,
            gyro_bias_tau_s: 1.0,
            ..ImuParams::ideal()
        };
        let mut imu = ImuEmulator::new(Box::new(level(0.0)), p);
        let mut sq = 0.0;
        let n = 200_000;
        for _ in 0..n {
            imu.next_sample();
            sq += imu.drift[0].powi(2) + imu.drift[1].powi(2) + imu.drift[2].powi(2);
        }
        let rms = (sq / (3 * n) as f64).sqrt() / DEG_H;
        // 100 correlation times x 3 axes: about 4 % sampling error
        assert!((rms - 0.05).abs() < 0.015, "{rms}");
    }

    #[test]
    fn bit_failure_is_reported_from_the_configured_time() {
        let p = ImuParams {
            bit_fail_from_s: Some(0.01),
            ..ImuParams::ideal()
        };
        let mut imu = ImuEmulator::new(Box::new(level(0.0)), p);
        let mut first = None;
        for _ in 0..100 {
            let f = imu.next_sample();
            for fr in &f.frames {
                if let Ok(Message::ImuAccel(a)) = Message::decode(fr)
                    && a.bit_fail
                    && first.is_none()
                {
                    first = Some(f.k);
                }
            }
        }
        assert_eq!(first, Some(19), "t1 = 20 / 2000 s = 0.01 s");
    }
}
