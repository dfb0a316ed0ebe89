//! Generic little-endian (DBC `@1`) bit packing driven by [`SignalSpec`] tables.

use thiserror::Error;

/// One signal of a frame, as in a DBC `SG_` line with Intel byte order (`@1`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalSpec {
    /// Signal name, exactly as in the DBC.
    pub name: &'static str,
    /// Start bit (LSB position, DBC numbering).
    pub start: u8,
    /// Length in bits (1..=32).
    pub len: u8,
    /// Two's-complement signed (`-`) or unsigned (`+`).
    pub signed: bool,
    /// Physical value = raw * factor + offset.
    pub factor: f64,
    /// Physical value = raw * factor + offset.
    pub offset: f64,
}

impl SignalSpec {
    /// Unsigned signal with factor 1.
    pub const fn uint(name: &'static str, start: u8, len: u8) -> Self {
        Self {
            name,
            start,
            len,
            signed: false,
            factor: 1.0,
            offset: 0.0,
        }
    }

    /// Scaled signal.
    pub const fn scaled(name: &'static str, start: u8, len: u8, signed: bool, factor: f64) -> Self {
        Self {
            name,
            start,
            len,
            signed,
            factor,
            offset: 0.0,
        }
    }

    /// Smallest raw value.
    pub fn raw_min(&self) -> i64 {
        if self.signed {
            -(1i64 << (self.len - 1))
        } else {
            0
        }
    }

    /// Largest raw value.
    pub fn raw_max(&self) -> i64 {
        if self.signed {
            (1i64 << (self.len - 1)) - 1
        } else {
            (1i64 << self.len) - 1
        }
    }

    /// Read the raw value (sign-extended for signed signals).
    pub fn get(&self, data: &[u8; 8]) -> i64 {
        let word = u64::from_le_bytes(*data);
        let mask = if self.len == 64 {
            u64::MAX
        } else {
            (1u64 << self.len) - 1
        };
        let v = (word >> self.start) & mask;
        if self.signed && v >> (self.len - 1) & 1 == 1 {
            (v | !mask) as i64
        } else {
            v as i64
        }
    }

    /// Read a one-bit flag.
    pub fn flag(&self, data: &[u8; 8]) -> bool {
        self.get(data) != 0
    }

    /// Read the physical value.
    pub fn phys(&self, data: &[u8; 8]) -> f64 {
        self.get(data) as f64 * self.factor + self.offset
    }

    /// Write a raw value, wrapping it to the signal's width (for free-running counters).
    pub fn put_wrapping(&self, data: &mut [u8; 8], raw: i64) {
        let mask = if self.len == 64 {
            u64::MAX
        } else {
            (1u64 << self.len) - 1
        };
        let mut word = u64::from_le_bytes(*data);
        word &= !(mask << self.start);
        word |= ((raw as u64) & mask) << self.start;
        *data = word.to_le_bytes();
    }

    /// Write a raw value, refusing one that does not fit.
    pub fn put(&self, data: &mut [u8; 8], raw: i64) -> Result<(), EncodeError> {
        if raw < self.raw_min() || raw > self.raw_max() {
            return Err(EncodeError::OutOfRange {
                signal: self.name,
                value: raw as f64,
                min: self.raw_min() as f64 * self.factor + self.offset,
                max: self.raw_max() as f64 * self.factor + self.offset,
            });
        }
        self.put_wrapping(data, raw);
        Ok(())
    }

    /// Write a flag.
    pub fn put_flag(&self, data: &mut [u8; 8], on: bool) {
        self.put_wrapping(data, i64::from(on));
    }

    /// Write a physical value, rounded to the nearest raw step; out of range is an error.
    pub fn put_phys(&self, data: &mut [u8; 8], value: f64) -> Result<(), EncodeError> {
        let raw = ((value - self.offset) / self.factor).round();
        if !raw.is_finite() || raw < self.raw_min() as f64 || raw > self.raw_max() as f64 {
            return Err(EncodeError::OutOfRange {
                signal: self.name,
                value,
                min: self.raw_min() as f64 * self.factor + self.offset,
                max: self.raw_max() as f64 * self.factor + self.offset,
            });
        }
        self.put_wrapping(data, raw as i64);
        Ok(())
    }

    /// Put an angle in degrees on a circle of `[0, 360)`: wrapped before and after quantization,
    /// so that 359.99999 deg, which rounds to a whole turn, goes out as 0 and never as 360.
    pub fn put_angle_deg(&self, data: &mut [u8; 8], deg: f64) -> Result<(), EncodeError> {
        let turn = (360.0 / self.factor).round();
        let raw = (deg.rem_euclid(360.0) / self.factor).round();
        if !raw.is_finite() {
            return Err(EncodeError::OutOfRange {
                signal: self.name,
                value: deg,
                min: 0.0,
                max: 360.0,
            });
        }
        let raw = if raw >= turn { raw - turn } else { raw };
        self.put_phys(data, raw * self.factor)
    }
}

/// One frame type of the contract.
#[derive(Debug, Clone, Copy)]
pub struct MessageSpec {
    /// Message name, exactly as in the DBC.
    pub name: &'static str,
    /// 11-bit standard identifier.
    pub id: u16,
    /// Data length code (bytes).
    pub dlc: u8,
    /// Every signal of the frame.
    pub signals: &'static [&'static SignalSpec],
    /// Nominal frames per second on the bus (cycle rate times instances, or the event budget).
    pub frames_per_second: f64,
    /// The node that sends it (the DBC's transmitter: `IMU`, `TT` or `NAV`).
    pub sender: &'static str,
}

/// A classic CAN data frame with an 11-bit identifier, independent of any I/O library.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawFrame {
    /// Standard identifier.
    pub id: u16,
    /// Number of data bytes (0..=8).
    pub len: u8,
    /// Payload; bytes past `len` are zero.
    pub data: [u8; 8],
}

impl RawFrame {
    /// The payload bytes actually carried.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len.min(8))]
    }
}

/// Why a frame could not be decoded.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DecodeError {
    /// The identifier is not in the DBC.
    #[error("unknown CAN id 0x{id:03X} (not in bench.dbc)")]
    UnknownId {
        /// The identifier seen.
        id: u32,
    },
    /// The frame is an extended-id, remote or error frame; the contract has none.
    #[error("CAN id 0x{id:X}: {what} frames are not part of the contract")]
    UnsupportedKind {
        /// The identifier seen.
        id: u32,
        /// Which kind of frame.
        what: &'static str,
    },
    /// The data length does not match the DBC.
    #[error("{name} (0x{id:03X}): {got} data bytes, the DBC says {expected}")]
    WrongLength {
        /// Message name.
        name: &'static str,
        /// Identifier.
        id: u16,
        /// DLC in the DBC.
        expected: u8,
        /// DLC received.
        got: u8,
    },
    /// A signal holds a value the contract does not define (an enum out of range).
    #[error("{message}.{signal}: raw value {raw} is not defined")]
    InvalidValue {
        /// Message name.
        message: &'static str,
        /// Signal name.
        signal: &'static str,
        /// Raw value.
        raw: i64,
    },
}

/// Why a value could not be encoded.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum EncodeError {
    /// The physical value does not fit the signal.
    #[error("signal {signal}: value {value} outside the encodable range [{min}, {max}]")]
    OutOfRange {
        /// Signal name.
        signal: &'static str,
        /// Value asked for.
        value: f64,
        /// Smallest encodable value.
        min: f64,
        /// Largest encodable value.
        max: f64,
    },
}

/// Check id and length of `frame` against `spec`, returning the padded payload.
pub(crate) fn check(spec: &MessageSpec, frame: &RawFrame) -> Result<[u8; 8], DecodeError> {
    if frame.len != spec.dlc {
        return Err(DecodeError::WrongLength {
            name: spec.name,
            id: spec.id,
            expected: spec.dlc,
            got: frame.len,
        });
    }
    Ok(frame.data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_fields_sign_extend_and_round_trip() {
        let s = SignalSpec::scaled("X", 22, 16, true, 0.01);
        let mut d = [0u8; 8];
        s.put_phys(&mut d, -12.34).unwrap();
        assert_eq!(s.get(&d), -1234);
        assert!((s.phys(&d) + 12.34).abs() < 1e-9);
        // neighbours untouched
        assert_eq!(u64::from_le_bytes(d) & ((1 << 22) - 1), 0);
        assert_eq!(u64::from_le_bytes(d) >> 38, 0);
    }

    #[test]
    fn out_of_range_is_an_error_not_a_wrap() {
        let s = SignalSpec::scaled("Rate", 0, 16, true, 0.01);
        let mut d = [0u8; 8];
        assert!(s.put_phys(&mut d, 400.0).is_err());
        assert!(s.put_phys(&mut d, f64::NAN).is_err());
        assert!(s.put(&mut d, 40000).is_err());
    }

    #[test]
    fn wrapping_put_wraps() {
        let s = SignalSpec::uint("C", 48, 16);
        let mut d = [0xFFu8; 8];
        s.put_wrapping(&mut d, 65536 + 7);
        assert_eq!(s.get(&d), 7);
        assert_eq!(&d[..6], &[0xFF; 6]);
    }
}
