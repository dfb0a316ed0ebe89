//! The IMU's oscillator: its sample clock off the nominal rate by a constant offset and a slow
//! wander (a crystal's with its temperature cycle), a pure function of simulated time.
//!
//! The oscillator's fractional frequency error at simulated time `t` is
//! `y(t) = offset + wander sin(2 pi t / period)`: a positive `y` is a fast oscillator, more
//! samples per simulated second than nominal. Its ticks counted from `t = 0` are
//! `N(t) = (t (1 + offset) + wander period / (2 pi) (1 - cos(2 pi t / period))) / P`, with `P`
//! the nominal sample period; sample `k` (0-based) runs from tick `k` to tick `k + 1`. With no
//! offset and no wander, tick `n` is `n P` exactly (the bench's IMU of before, bit for bit).
//!
//! Whatever reads an IMU sample's number as a time (nav, which counts its seconds in samples at
//! the nominal rate, and the bench, which scores nav's solution at the simulated time of the
//! sample it names) goes through [`Oscillator::tick_time`] or an [`ImuTimescale`] on the truth's
//! side: a nominal `k / rate` there would score nav against the truth of another instant.

use std::f64::consts::PI;

/// The IMU's sample clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oscillator {
    /// Nominal sample period, s.
    period_s: f64,
    /// Constant fractional frequency offset.
    offset: f64,
    /// Amplitude of the wander (fractional).
    wander: f64,
    /// Angular frequency of the wander, rad/s.
    omega: f64,
}

impl Oscillator {
    /// An oscillator at exactly its nominal rate `rate_hz`.
    pub fn nominal(rate_hz: f64) -> Self {
        Self::new(rate_hz, 0.0, 0.0, 3600.0)
    }

    /// An oscillator of nominal rate `rate_hz`, off it by `offset_ppm` (positive: fast) and
    /// wandering by `wander_ppm` (amplitude) over a cycle of `wander_period_s`.
    pub fn new(rate_hz: f64, offset_ppm: f64, wander_ppm: f64, wander_period_s: f64) -> Self {
        Self {
            period_s: 1.0 / rate_hz,
            offset: offset_ppm * 1e-6,
            wander: wander_ppm * 1e-6,
            omega: 2.0 * PI / wander_period_s.max(1e-3),
        }
    }

    /// Whether the oscillator runs at exactly its nominal rate.
    pub fn is_nominal(&self) -> bool {
        self.offset == 0.0 && self.wander == 0.0
    }

    /// The nominal sample period, s.
    pub fn nominal_period_s(&self) -> f64 {
        self.period_s
    }

    /// The fractional frequency error at simulated time `t`, ppm (positive: fast).
    pub fn error_ppm(&self, t: f64) -> f64 {
        (self.offset + self.wander * (self.omega * t).sin()) * 1e6
    }

    /// The mean fractional frequency error over `[t0, t1]`, ppm.
    pub fn mean_error_ppm(&self, t0: f64, t1: f64) -> f64 {
        if t1 <= t0 {
            return self.error_ppm(t0);
        }
        ((self.ticks_at(t1) - self.ticks_at(t0)) * self.period_s / (t1 - t0) - 1.0) * 1e6
    }

    /// Ticks counted by simulated time `t` (continuous).
    pub fn ticks_at(&self, t: f64) -> f64 {
        if self.is_nominal() {
            return t / self.period_s;
        }
        let w = self.wander / self.omega * (1.0 - (self.omega * t).cos());
        (t * (1.0 + self.offset) + w) / self.period_s
    }

    /// Simulated time of tick `n`: the end of sample `n - 1`, the start of sample `n`, s.
    pub fn tick_time(&self, n: u64) -> f64 {
        if self.is_nominal() {
            // as the IMU always computed it: bit for bit the nominal clock's
            return n as f64 * self.period_s;
        }
        self.time_of_ticks(n as f64)
    }

    /// Simulated time at which the oscillator has counted `x` ticks (continuous), s.
    pub fn time_of_ticks(&self, x: f64) -> f64 {
        if self.is_nominal() {
            return x * self.period_s;
        }
        // Newton on N(t) = x: N is smooth and its slope (1 + y) / P within 1 % of 1 / P
        let mut t = x * self.period_s / (1.0 + self.offset);
        for _ in 0..8 {
            let slope = (1.0 + self.offset + self.wander * (self.omega * t).sin()) / self.period_s;
            let step = (self.ticks_at(t) - x) / slope;
            t -= step;
            if step.abs() < 1e-13 * t.abs().max(1.0) {
                break;
            }
        }
        t
    }

    /// The simulated time `imu_s` seconds of the IMU's own clock (its samples counted at the
    /// nominal rate) after simulated time `t0`, s.
    pub fn after(&self, t0: f64, imu_s: f64) -> f64 {
        if self.is_nominal() {
            return t0 + imu_s;
        }
        self.time_of_ticks(self.ticks_at(t0) + imu_s / self.period_s)
    }

    /// The IMU's time scale counted from its first sample, whose end is tick 1.
    pub fn from_first_sample(&self) -> ImuTimescale {
        self.timescale(self.tick_time(1))
    }

    /// The IMU's time scale counted from the sample that ended at simulated time `first_s`.
    pub fn timescale(&self, first_s: f64) -> ImuTimescale {
        ImuTimescale {
            oscillator: *self,
            first_s,
        }
    }
}

/// The IMU's own seconds (what nav counts: samples since its first one, at the nominal rate)
/// mapped to simulated time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuTimescale {
    oscillator: Oscillator,
    first_s: f64,
}

impl ImuTimescale {
    /// Simulated time of IMU time `imu_s` (0 at the end of the first sample), s.
    pub fn sim_time(&self, imu_s: f64) -> f64 {
        self.oscillator.after(self.first_s, imu_s)
    }

    /// Simulated time at the end of the first sample, s.
    pub fn first_s(&self) -> f64 {
        self.first_s
    }

    /// The oscillator.
    pub fn oscillator(&self) -> &Oscillator {
        &self.oscillator
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_nominal_oscillator_is_the_nominal_clock_bit_for_bit() {
        let o = Oscillator::nominal(2000.0);
        let dt = 1.0 / 2000.0;
        for n in [0u64, 1, 7, 2_000, 7_200_001] {
            assert_eq!(o.tick_time(n), n as f64 * dt);
        }
        let ts = o.from_first_sample();
        assert_eq!(ts.sim_time(12.5), 12.5 + dt);
    }

    #[test]
    fn a_fast_oscillator_counts_more_samples_per_second() {
        let o = Oscillator::new(2000.0, 100.0, 0.0, 3600.0);
        // an hour holds 720 more samples than 7.2 million
        let n = o.ticks_at(3600.0);
        assert!((n - 7_200_720.0).abs() < 1e-6, "{n}");
        // and sample 7,200,720 ends at the hour
        assert!((o.tick_time(7_200_720) - 3600.0).abs() < 1e-9);
        // an IMU second is shorter than a simulated one
        let ts = o.from_first_sample();
        let d = ts.sim_time(1000.0) - ts.sim_time(0.0);
        assert!((d - 1000.0 / 1.0001).abs() < 1e-9, "{d}");
    }

    #[test]
    fn the_wander_integrates_and_inverts() {
        let o = Oscillator::new(100.0, -60.0, 40.0, 1800.0);
        for t in [0.0, 0.01, 3.3, 450.0, 900.0, 1799.9, 5432.1, 36_000.0] {
            let back = o.time_of_ticks(o.ticks_at(t));
            assert!((back - t).abs() < 1e-9, "{t}: {back}");
        }
        // over a whole cycle the wander averages out: the offset alone
        assert!((o.mean_error_ppm(0.0, 1800.0) + 60.0).abs() < 1e-6);
        // over its first quarter it adds 2/pi of its amplitude
        let q = o.mean_error_ppm(0.0, 450.0);
        assert!((q - (-60.0 + 40.0 * 2.0 / PI)).abs() < 1e-6, "{q}");
        assert!((o.error_ppm(450.0) - (-20.0)).abs() < 1e-9);
        // the ticks only grow
        let mut last = -1.0;
        for i in 0..10_000 {
            let t = o.tick_time(i);
            assert!(t > last);
            last = t;
        }
    }
}
