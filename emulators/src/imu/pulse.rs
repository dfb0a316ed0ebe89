//! The sensors' pulse outputs on the wire: whole pulses with the remainder carried to the next
//! sample, counted in 16 bits (the RLGs', the accelerometers' and the MEMS gyros' counters).

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
