//! The IMU on a lab's own contract (`wire::mapping`): what the unit measured over each sample
//! as the quantity the lab's DBC carries: rates (deg/s, m/s^2), increments (deg, m/s) or whole
//! pulses counted up and wrapping at their signal's width. Pure: a function of the samples.
//!
//! Rates and increments are put out as a unit that counts its angle does: each sample's value
//! is the step of the angle put out so far, in whole steps of the signal (its factor), the
//! remainder carried into the next sample. Rounded sample by sample instead, a dithered gyro
//! whose dither frequency divides evenly into the sample rate (331 Hz at 1 kHz: the same 1000
//! phases every second) rounds the same way every second, and its mean rate is off by up to a
//! deg/h: 0.5 deg of a four-position heading, seen before the carry.

use super::Measured;
use wire::dbc::{Contract, Kind};
use wire::mapping::{Channel, ImuMapping, MappedSample, Quantity};

/// One channel's conversion (the three gyros, or the three accelerometers).
#[derive(Debug, Clone)]
struct Conversion {
    quantity: Quantity,
    /// One pulse, in the measured unit (rad, m/s).
    pulse: [f64; 3],
    /// Pulses counted so far, with their fractions.
    total: [f64; 3],
    /// A pulse count's range: its signal's raw values (the low end, the count of values).
    range: (f64, f64),
    /// The signal's step (its factor), in the mapping's unit; 0: a float, not stepped.
    step: f64,
    /// What the steps put out so far fell short of the measured values, in the unit.
    carry: [f64; 3],
}

impl Conversion {
    fn new(c: &Channel, contract: &Contract, pulse: [f64; 3]) -> Self {
        let sig = contract
            .message(&c.message)
            .and_then(|m| m.signal(&c.signals[0].replace("{k}", "0")));
        let range = sig.map_or((0.0, 2f64.powi(32)), |s| {
            let n = 2f64.powi(i32::from(s.len));
            match s.kind {
                Kind::Signed => (-n / 2.0, n),
                _ => (0.0, n),
            }
        });
        let step = sig
            .filter(|s| matches!(s.kind, Kind::Signed | Kind::Unsigned))
            .map_or(0.0, |s| s.factor.abs());
        Self {
            quantity: c.quantity,
            pulse,
            total: [0.0; 3],
            range,
            step,
            carry: [0.0; 3],
        }
    }

    /// The sample's values of increments `d` (rad or m/s) over `dt`; `to_unit`: the mapping's
    /// unit per SI unit (deg per rad for the gyros, 1 for the accelerometers).
    fn values(&mut self, d: &[f64; 3], dt: f64, to_unit: f64) -> [f64; 3] {
        std::array::from_fn(|i| match self.quantity {
            Quantity::Rate => self.stepped(i, d[i] * to_unit / dt),
            Quantity::Increment => self.stepped(i, d[i] * to_unit),
            Quantity::Pulses => {
                self.total[i] += d[i] / self.pulse[i];
                let (low, n) = self.range;
                (self.total[i].floor() - low).rem_euclid(n) + low
            }
        })
    }
}

impl Conversion {
    /// Axis `i`'s value `v` in whole steps of its signal, what the step leaves carried into
    /// the next sample.
    fn stepped(&mut self, i: usize, v: f64) -> f64 {
        if self.step <= 0.0 {
            return v;
        }
        let want = v + self.carry[i];
        let out = (want / self.step).round() * self.step;
        self.carry[i] = want - out;
        out
    }
}

/// The unit's samples as the mapping's quantities.
#[derive(Debug, Clone)]
pub struct MappedImu {
    gyro: Conversion,
    accel: Conversion,
}

impl MappedImu {
    /// The IMU of `mapping` (checked against `contract`); its pulses, where it counts them:
    /// `gyro_pulse_rad` and `accel_pulse_mps` per axis.
    pub fn new(
        mapping: &ImuMapping,
        contract: &Contract,
        gyro_pulse_rad: [f64; 3],
        accel_pulse_mps: [f64; 3],
    ) -> Self {
        Self {
            gyro: Conversion::new(&mapping.gyro, contract, gyro_pulse_rad),
            accel: Conversion::new(&mapping.accel, contract, accel_pulse_mps),
        }
    }

    /// Sample `counter` with what the unit measured over it.
    pub fn sample(&mut self, counter: u64, m: &Measured) -> MappedSample {
        MappedSample {
            counter,
            gyro: self
                .gyro
                .values(&m.dtheta, m.dt, 180.0 / std::f64::consts::PI),
            accel: self.accel.values(&m.dv, m.dt, 1.0),
            temperature_c: m.temp_c,
            bit: u32::from(m.bit_fail),
            pps_ms: m.pps_s.map(|s| s * 1e3),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lab() -> (Contract, wire::mapping::Mapping) {
        let here = concat!(env!("CARGO_MANIFEST_DIR"), "/../wire/contracts/");
        let dbc = std::fs::read_to_string(format!("{here}lab-imu.dbc")).expect("the lab's DBC");
        let c = Contract::parse(&dbc).expect("reads");
        let toml = std::fs::read_to_string(format!("{here}lab-imu.toml")).expect("its mapping");
        let m = wire::mapping::Mapping::parse(&toml, &c).expect("fits");
        (c, m)
    }

    /// Rates from increments over the sample, pulses counted up with their fractions kept and
    /// wrapping at their signal's width.
    #[test]
    fn the_unit_measures_as_the_mapping_says() {
        let (c, m) = lab();
        let imu = m.file.imu.as_ref().expect("the lab maps an IMU");
        let mut x = MappedImu::new(imu, &c, [1e-5; 3], [1e-3; 3]);
        let dt = 1e-3;
        let meas = Measured {
            dtheta: [1e-4, -2e-4, 0.0],
            dv: [9.8e-3, 0.0, -1e-3],
            dt,
            pps_s: Some(2e-4),
            bit_fail: false,
            temp_c: 41.5,
        };
        let s = x.sample(7, &meas);
        // the lab's gyros and accelerometers are rates
        assert_eq!(s.counter, 7);
        // in whole steps of 0.01 deg/s, the remainder carried
        let true_rate = 1e-4 / dt * 180.0 / std::f64::consts::PI;
        assert!((s.gyro[0] - 5.73).abs() < 1e-9 && (true_rate - 5.7296).abs() < 1e-4);
        assert!((s.accel[0] - 9.8).abs() < 1e-12 && (s.accel[2] + 1.0).abs() < 1e-12);
        assert_eq!((s.temperature_c, s.bit, s.pps_ms), (41.5, 0, Some(0.2)));
        // as pulses on a 16-bit unsigned signal: 10.5 then 21 pulses, wrapping past 65535
        let mut p = Conversion {
            quantity: Quantity::Pulses,
            pulse: [1e-5; 3],
            total: [65530.0, 0.0, 0.0],
            range: (0.0, 65536.0),
            step: 1.0,
            carry: [0.0; 3],
        };
        let v = p.values(&[1.05e-4, 0.0, -1e-5], dt, 1.0);
        assert_eq!(v, [4.0, 0.0, 65535.0]);
    }

    /// A dithered rate whose dither divides evenly into the sample rate: stepped with the
    /// remainder carried, its mean over whole seconds is the true rate to a step over the span;
    /// rounded sample by sample it would be off by a fixed amount (0.5 deg/h here).
    #[test]
    fn rates_carry_their_remainder_so_a_dither_leaves_no_bias() {
        let (c, m) = lab();
        let imu = m.file.imu.as_ref().expect("the lab maps an IMU");
        let mut x = MappedImu::new(imu, &c, [1e-5; 3], [1e-3; 3]);
        let (dt, true_dps) = (1e-3, 0.0036f64);
        let amp = (400.0f64 / 3600.0).to_radians();
        let dither = |t: f64| amp * (2.0 * std::f64::consts::PI * 331.0 * t + 0.3).sin();
        let n = 5000;
        let (mut sum, mut rounded) = (0.0, 0.0);
        for k in 0..n {
            let (t0, t1) = (k as f64 * dt, (k + 1) as f64 * dt);
            let d = true_dps.to_radians() * dt + dither(t1) - dither(t0);
            let meas = Measured {
                dtheta: [d, 0.0, 0.0],
                dt,
                ..Measured::default()
            };
            sum += x.sample(k, &meas).gyro[0];
            rounded += (d.to_degrees() / dt / 0.01).round() * 0.01;
        }
        let exact = (true_dps.to_radians() * dt * n as f64 + dither(n as f64 * dt) - dither(0.0))
            .to_degrees()
            / dt
            / n as f64;
        let dph = |x: f64| x * 3600.0;
        // the carried steps: within one step over the span
        assert!(dph((sum / n as f64 - exact).abs()) <= dph(0.01 / n as f64) + 1e-9);
        // rounding each sample alone: a fixed error far beyond it
        assert!(dph((rounded / n as f64 - exact).abs()) > 0.3);
    }
}
