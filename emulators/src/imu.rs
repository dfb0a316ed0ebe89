//! RLG / quartz-accelerometer IMU: sensor errors, pulse quantization, and the frames it sends.
//!
//! Defaults follow paper 003's sensor table: gyro bias stability 0.1 deg/h and white noise
//! 0.1 deg/h (taken as the 1 s averaged rate noise, i.e. an angle random walk of
//! 0.1/60 deg/sqrt(h)); accelerometer white noise 0.001 m/s^2 (1 s averaged, i.e. a velocity
//! random walk of 0.001 m/s/sqrt(s)). The accelerometer bias default is 5e-5 g per axis, a
//! good quartz unit after calibration; the paper's 5e-3 g is its bias *stability* spec over the
//! range and can be set in the scenario.
//!
//! Quantization carries its remainder from sample to sample, so rounding never becomes drift:
//! the pulse count after N samples differs from the true accumulated angle by less than one
//! pulse, whatever N.

use crate::truth::Motion;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use wire::{BitFlags, ImuAccel, ImuGyro, ImuHk, Message, RawFrame};

/// IMU parameters (every one settable in a scenario file).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ImuParams {
    /// Sample rate, Hz.
    pub rate_hz: f64,
    /// Gyro pulse weight, arcsec/pulse, per axis.
    pub gyro_pulse_arcsec: [f64; 3],
    /// Accelerometer pulse weight, m/s per pulse, per axis.
    pub accel_pulse_mps: [f64; 3],
    /// Gyro constant bias, deg/h, per axis (drawn at +-this with random sign when `random_bias_sign`).
    pub gyro_bias_dph: [f64; 3],
    /// Gyro angle random walk, deg/sqrt(h).
    pub gyro_arw_dpsh: f64,
    /// Accelerometer constant bias, m/s^2, per axis.
    pub accel_bias_mps2: [f64; 3],
    /// Accelerometer velocity random walk, m/s/sqrt(s).
    pub accel_vrw_mpss: f64,
    /// Draw the sign of each bias at random from the seed.
    pub random_bias_sign: bool,
    /// Random seed: the same seed gives the same run.
    pub seed: u64,
    /// Offset of the GPS PPS edge after each whole second of simulated time, s.
    pub pps_phase_s: f64,
    /// Gyro block temperature, degC.
    pub temp_c: f64,
}

impl Default for ImuParams {
    fn default() -> Self {
        Self {
            rate_hz: wire::IMU_RATE_HZ,
            gyro_pulse_arcsec: [1.0; 3],
            accel_pulse_mps: [1e-4; 3],
            gyro_bias_dph: [0.1; 3],
            gyro_arw_dpsh: 0.1 / 60.0,
            accel_bias_mps2: [5e-5 * 9.80665; 3],
            accel_vrw_mpss: 0.001,
            random_bias_sign: true,
            seed: 1,
            pps_phase_s: 0.000_123,
            temp_c: 42.0,
        }
    }
}

/// A pulse counter that quantizes with carried remainder and wraps at 16 bits.
#[derive(Debug, Clone, Copy, Default)]
pub struct PulseCounter {
    remainder: f64,
    /// Accumulated pulses (never wraps; the wire value is its low 16 bits).
    pub total: i64,
}

impl PulseCounter {
    /// Add `pulses` (fractional); returns the whole pulses emitted this step.
    pub fn add(&mut self, pulses: f64) -> i64 {
        let acc = self.remainder + pulses;
        let n = acc.round();
        self.remainder = acc - n;
        self.total += n as i64;
        n as i64
    }

    /// The 16-bit wire value.
    pub fn wire(&self) -> u16 {
        self.total.rem_euclid(65536) as u16
    }
}

/// The IMU: truth -> errors -> pulses -> frames, one sample at a time.
pub struct ImuEmulator {
    motion: Box<dyn Motion>,
    p: ImuParams,
    dt: f64,
    k: u64,
    counter0: u16,
    gyro: [PulseCounter; 3],
    accel: [PulseCounter; 3],
    gyro_bias: [f64; 3],
    accel_bias: [f64; 3],
    rng: StdRng,
    arw_sigma: f64,
    vrw_sigma: f64,
}

/// Frames of one sample.
#[derive(Debug, Clone)]
pub struct SampleFrames {
    /// Sample index since the start (0-based).
    pub k: u64,
    /// IMU_GYRO, IMU_ACCEL and, at 10 Hz, IMU_HK.
    pub frames: Vec<RawFrame>,
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
        let deg_h = std::f64::consts::PI / 180.0 / 3600.0;
        let gyro_bias = p.gyro_bias_dph.map(|b| sign(b) * deg_h);
        let accel_bias = p.accel_bias_mps2.map(&mut sign);
        let dt = 1.0 / p.rate_hz;
        // random counter origins so every run exercises the 16-bit wrap
        let counter0 = rand::Rng::random::<u16>(&mut rng);
        let mut gyro = [PulseCounter::default(); 3];
        let mut accel = [PulseCounter::default(); 3];
        for c in gyro.iter_mut().chain(accel.iter_mut()) {
            c.total = i64::from(rand::Rng::random::<u16>(&mut rng));
        }
        Self {
            motion,
            arw_sigma: p.gyro_arw_dpsh.to_radians() / 60.0 * dt.sqrt(),
            vrw_sigma: p.accel_vrw_mpss * dt.sqrt(),
            p,
            dt,
            k: 0,
            counter0,
            gyro,
            accel,
            gyro_bias,
            accel_bias,
            rng,
        }
    }

    /// The gyro biases actually applied, deg/h.
    pub fn gyro_bias_dph(&self) -> [f64; 3] {
        self.gyro_bias.map(|b| b.to_degrees() * 3600.0)
    }

    /// The accelerometer biases actually applied, m/s^2.
    pub fn accel_bias_mps2(&self) -> [f64; 3] {
        self.accel_bias
    }

    /// Simulated time at the end of the next sample, s.
    pub fn next_time(&self) -> f64 {
        (self.k + 1) as f64 * self.dt
    }

    /// Produce the next sample's frames.
    pub fn next_sample(&mut self) -> SampleFrames {
        let (t0, t1) = (self.k as f64 * self.dt, (self.k + 1) as f64 * self.dt);
        let inc = self.motion.increments(t0, t1);
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let arcsec = std::f64::consts::PI / 180.0 / 3600.0;
        for i in 0..3 {
            let dth = inc.dtheta[i]
                + self.gyro_bias[i] * self.dt
                + self.arw_sigma * n.sample(&mut self.rng);
            self.gyro[i].add(dth / (self.p.gyro_pulse_arcsec[i] * arcsec));
            let dv =
                inc.dv[i] + self.accel_bias[i] * self.dt + self.vrw_sigma * n.sample(&mut self.rng);
            self.accel[i].add(dv / self.p.accel_pulse_mps[i]);
        }
        let sample_counter = (u64::from(self.counter0) + self.k + 1) as u16;
        // PPS: an edge at whole seconds + phase inside (t0, t1]?
        let edge = (t1 - self.p.pps_phase_s).floor() + self.p.pps_phase_s;
        let pps_offset = (edge > t0 && edge <= t1)
            .then(|| (((t1 - edge) / self.dt) * 256.0).floor().clamp(0.0, 255.0) as u8);
        let g = ImuGyro {
            counts: [
                self.gyro[0].wire(),
                self.gyro[1].wire(),
                self.gyro[2].wire(),
            ],
            sample_counter,
        };
        let a = ImuAccel {
            counts: [
                self.accel[0].wire(),
                self.accel[1].wire(),
                self.accel[2].wire(),
            ],
            sample_counter_low: (sample_counter & 0xF) as u8,
            pps_offset,
            bit_fail: false,
            saturated: false,
        };
        let mut frames = Vec::with_capacity(3);
        for m in [Message::ImuGyro(g), Message::ImuAccel(a)] {
            frames.push(m.encode().expect("IMU frames always encode"));
        }
        if self
            .k
            .is_multiple_of((self.p.rate_hz / 10.0).round().max(1.0) as u64)
        {
            let hk = ImuHk {
                sample_counter,
                temp_gyro_c: self.p.temp_c,
                temp_accel_c: self.p.temp_c - 1.5,
                bit: BitFlags::default(),
            };
            if let Ok(f) = Message::ImuHk(hk).encode() {
                frames.push(f);
            }
        }
        let k = self.k;
        self.k += 1;
        SampleFrames { k, frames }
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
        let p = ImuParams {
            gyro_bias_dph: [0.0; 3],
            gyro_arw_dpsh: 0.0,
            accel_bias_mps2: [0.0; 3],
            accel_vrw_mpss: 0.0,
            ..Default::default()
        };
        let mut imu = ImuEmulator::new(Box::new(s), p);
        let start = imu.gyro.map(|c| c.total);
        let n = 20_000;
        for _ in 0..n {
            imu.next_sample();
        }
        let t = n as f64 / 2000.0;
        let w = s.omega_ib_b();
        let arcsec = std::f64::consts::PI / 180.0 / 3600.0;
        for i in 0..3 {
            let pulses = (imu.gyro[i].total - start[i]) as f64;
            assert!((pulses - w[i] * t / arcsec).abs() <= 1.0, "axis {i}");
        }
    }

    #[test]
    fn frames_carry_wrapping_counters_pps_and_housekeeping() {
        let s = Static {
            lat_deg: 45.0,
            lon_deg: 0.0,
            height_m: 0.0,
            heading_deg: 0.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
        };
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

    #[test]
    fn the_same_seed_gives_the_same_frames() {
        let s = Static {
            lat_deg: 10.0,
            lon_deg: 0.0,
            height_m: 0.0,
            heading_deg: 0.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
        };
        let mut a = ImuEmulator::new(Box::new(s), ImuParams::default());
        let mut b = ImuEmulator::new(Box::new(s), ImuParams::default());
        for _ in 0..100 {
            assert_eq!(a.next_sample().frames, b.next_sample().frames);
        }
    }
}
