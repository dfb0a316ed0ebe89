//! The generic codec: any DBC's messages and signals, read at run time, as a lab brings its own
//! contract. Standard and extended identifiers, classic and CAN FD payloads (up to 64 bytes),
//! Intel (`@1`) and Motorola (`@0`) byte orders, signed, unsigned and IEEE float signals, and
//! simple multiplexing. Bit by bit: slower than [`crate::codec`]'s hand-written layouts of
//! `bench.dbc`, and equal to them on it, to the byte (`wire/tests/generic_codec.rs`), so our own
//! contract is the fast special case of this one and not a second copy of the rules.

use can_dbc::{ByteOrder, Dbc, MessageId, MultiplexIndicator, SignalExtendedValueType, ValueType};
use thiserror::Error;

/// A frame's identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FrameId {
    /// 11 bits.
    Standard(u16),
    /// 29 bits.
    Extended(u32),
}

impl std::fmt::Display for FrameId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Standard(id) => write!(f, "0x{id:03X}"),
            Self::Extended(id) => write!(f, "0x{id:08X} (extended)"),
        }
    }
}

/// How a signal's raw bits read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Two's complement.
    Signed,
    /// Unsigned.
    Unsigned,
    /// IEEE 754 single precision (32 bits).
    Float32,
    /// IEEE 754 double precision (64 bits).
    Float64,
}

/// Which frames a signal is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mux {
    /// Every frame of its message.
    Always,
    /// It is the multiplexor: its value says which multiplexed signals a frame carries.
    Multiplexor,
    /// Only frames whose multiplexor has this value.
    When(u64),
}

/// One signal's layout.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalLayout {
    /// Its name in the DBC.
    pub name: String,
    /// The DBC's start bit: the least significant bit's position for Intel order, the most
    /// significant bit's (in the DBC's sawtooth numbering) for Motorola order.
    pub start: u16,
    /// Length, bits (1 to 64).
    pub len: u16,
    /// Motorola (big-endian, `@0`) rather than Intel (`@1`).
    pub big_endian: bool,
    /// How its bits read.
    pub kind: Kind,
    /// Physical = raw x factor + offset.
    pub factor: f64,
    /// See [`SignalLayout::factor`].
    pub offset: f64,
    /// The DBC's physical range (both 0: none given).
    pub min: f64,
    /// See [`SignalLayout::min`].
    pub max: f64,
    /// Its unit.
    pub unit: String,
    /// Which frames carry it.
    pub mux: Mux,
    /// Its bits' payload positions, least significant first (worked out once, when read).
    at: Vec<u16>,
}

/// One message's layout.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageLayout {
    /// Its name in the DBC.
    pub name: String,
    /// Its identifier.
    pub id: FrameId,
    /// Payload bytes (up to 8 on classic CAN, 64 on CAN FD).
    pub size: usize,
    /// The node that sends it (empty: none named).
    pub sender: String,
    /// Its signals, in the DBC's order.
    pub signals: Vec<SignalLayout>,
}

/// A contract read from a DBC.
#[derive(Debug, Clone, PartialEq)]
pub struct Contract {
    /// Every message, in the DBC's order.
    pub messages: Vec<MessageLayout>,
}

/// Why a DBC is not a contract the bench can speak.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ContractError {
    /// The text does not parse.
    #[error("the DBC does not parse: {0}")]
    Parse(String),
    /// A message longer than a CAN FD frame.
    #[error("message {message} ({id}): {size} bytes, more than a CAN FD frame's 64")]
    TooLong {
        /// The message.
        message: String,
        /// Its identifier.
        id: FrameId,
        /// Its size.
        size: u64,
    },
    /// A signal that does not fit its message, or of a length the codec cannot carry.
    #[error("message {message}, signal {signal}: {why}")]
    BadSignal {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
        /// What is wrong.
        why: String,
    },
}

/// Why values could not be put into a frame.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum EncodeError {
    /// The contract has no such message or signal.
    #[error("{0}")]
    Unknown(String),
    /// A value outside what the signal can carry.
    #[error("message {message}, signal {signal}: {value} outside [{min}, {max}]")]
    OutOfRange {
        /// The message.
        message: String,
        /// The signal.
        signal: String,
        /// The value asked for.
        value: f64,
        /// The smallest it can carry.
        min: f64,
        /// The largest.
        max: f64,
    },
}

/// Why a frame could not be read.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DecodeError {
    /// Not a message of the contract.
    #[error("identifier {0} is not in the DBC")]
    UnknownId(FrameId),
    /// Shorter than the message.
    #[error("message {message} ({id}): {got} bytes, the DBC says {want}")]
    Length {
        /// The message.
        message: String,
        /// Its identifier.
        id: FrameId,
        /// Bytes received.
        got: usize,
        /// Bytes the DBC gives it.
        want: usize,
    },
}

impl Contract {
    /// Read a DBC's text.
    pub fn parse(text: &str) -> Result<Self, ContractError> {
        let dbc = Dbc::try_from(text).map_err(|e| ContractError::Parse(format!("{e:?}")))?;
        let mut messages = Vec::with_capacity(dbc.messages.len());
        for m in &dbc.messages {
            let id = match m.id {
                MessageId::Standard(id) => FrameId::Standard(id),
                MessageId::Extended(id) => FrameId::Extended(id),
            };
            if m.size > 64 {
                return Err(ContractError::TooLong {
                    message: m.name.clone(),
                    id,
                    size: m.size,
                });
            }
            let mut signals = Vec::with_capacity(m.signals.len());
            for s in &m.signals {
                let extended = dbc.extended_value_type_for_signal(m.id, &s.name);
                signals.push(signal_layout(
                    &m.name,
                    m.size as usize,
                    s,
                    extended.copied(),
                )?);
            }
            no_overlap(&m.name, &signals)?;
            messages.push(MessageLayout {
                name: m.name.clone(),
                id,
                size: m.size as usize,
                sender: match &m.transmitter {
                    can_dbc::Transmitter::NodeName(n) => n.clone(),
                    can_dbc::Transmitter::VectorXXX => String::new(),
                },
                signals,
            });
        }
        Ok(Self { messages })
    }

    /// The message named `name`.
    pub fn message(&self, name: &str) -> Option<&MessageLayout> {
        self.messages.iter().find(|m| m.name == name)
    }

    /// The message of identifier `id`.
    pub fn by_id(&self, id: FrameId) -> Option<&MessageLayout> {
        self.messages.iter().find(|m| m.id == id)
    }

    /// A frame's signals by name, with their physical values (the multiplexed ones its
    /// multiplexor selects).
    pub fn decode(&self, id: FrameId, data: &[u8]) -> Result<Vec<(&str, f64)>, DecodeError> {
        self.by_id(id)
            .ok_or(DecodeError::UnknownId(id))?
            .decode(data)
    }
}

/// No bit of `message` carried by two signals that go into the same frame (a multiplexed
/// signal shares its bits only with those of other multiplexor values).
fn no_overlap(message: &str, signals: &[SignalLayout]) -> Result<(), ContractError> {
    // each signal's bits as a mask of the 512 a CAN FD payload has
    let masks: Vec<[u64; 8]> = signals
        .iter()
        .map(|s| {
            let mut m = [0u64; 8];
            for p in s.positions().filter(|p| *p < 512) {
                m[p / 64] |= 1 << (p % 64);
            }
            m
        })
        .collect();
    for (i, a) in signals.iter().enumerate() {
        for (j, b) in signals[..i].iter().enumerate() {
            let together = !matches!((a.mux, b.mux), (Mux::When(x), Mux::When(y)) if x != y);
            if together && masks[i].iter().zip(&masks[j]).any(|(x, y)| x & y != 0) {
                return Err(ContractError::BadSignal {
                    message: message.to_string(),
                    signal: a.name.clone(),
                    why: format!("its bits overlap signal {}'s", b.name),
                });
            }
        }
    }
    Ok(())
}

/// The payload positions of a signal's bits from the DBC's start bit, least significant first.
fn bit_positions(start: u16, len: u16, big_endian: bool) -> Vec<u16> {
    if !big_endian {
        return (0..len).map(|i| start.saturating_add(i)).collect();
    }
    // the start bit is the most significant; walk down within a byte, then on to the next
    // byte's most significant bit (the DBC's sawtooth numbering)
    let mut at = Vec::with_capacity(usize::from(len));
    let mut p = start;
    for _ in 0..len {
        at.push(p);
        p = if p.is_multiple_of(8) {
            p.saturating_add(15)
        } else {
            p - 1
        };
    }
    at.reverse();
    at
}

/// The layout of signal `s` of message `message` (`size` bytes), checked.
fn signal_layout(
    message: &str,
    size: usize,
    s: &can_dbc::Signal,
    extended: Option<SignalExtendedValueType>,
) -> Result<SignalLayout, ContractError> {
    let bad = |why: String| ContractError::BadSignal {
        message: message.to_string(),
        signal: s.name.clone(),
        why,
    };
    let kind = match (extended, s.value_type) {
        (Some(SignalExtendedValueType::IEEEfloat32Bit), _) => Kind::Float32,
        (Some(SignalExtendedValueType::IEEEdouble64bit), _) => Kind::Float64,
        (_, ValueType::Signed) => Kind::Signed,
        (_, ValueType::Unsigned) => Kind::Unsigned,
    };
    let want = match kind {
        Kind::Float32 => Some(32),
        Kind::Float64 => Some(64),
        _ => None,
    };
    if s.size == 0 || s.size > 64 || want.is_some_and(|w| w != s.size) {
        return Err(bad(format!(
            "{} bits: a signal of this kind has {}",
            s.size,
            want.map_or("1 to 64".into(), |w| w.to_string())
        )));
    }
    if s.factor == 0.0 || !s.factor.is_finite() {
        return Err(bad(format!("factor {}", s.factor)));
    }
    let layout = SignalLayout {
        name: s.name.clone(),
        start: s.start_bit as u16,
        len: s.size as u16,
        big_endian: matches!(s.byte_order, ByteOrder::BigEndian),
        kind,
        factor: s.factor,
        offset: s.offset,
        min: s.min,
        max: s.max,
        unit: s.unit.clone(),
        mux: match s.multiplexer_indicator {
            MultiplexIndicator::Plain => Mux::Always,
            MultiplexIndicator::Multiplexor => Mux::Multiplexor,
            MultiplexIndicator::MultiplexedSignal(v)
            | MultiplexIndicator::MultiplexorAndMultiplexedSignal(v) => Mux::When(v),
        },
        at: bit_positions(
            s.start_bit as u16,
            s.size as u16,
            matches!(s.byte_order, ByteOrder::BigEndian),
        ),
    };
    if s.start_bit >= (size * 8) as u64 {
        return Err(bad(format!(
            "start bit {} past the message's {} bytes",
            s.start_bit, size
        )));
    }
    if let Some(p) = layout.positions().find(|p| *p >= size * 8) {
        return Err(bad(format!(
            "{} bits from bit {} run past the message's {size} bytes (to bit {p})",
            s.size, s.start_bit
        )));
    }
    Ok(layout)
}

impl SignalLayout {
    /// The payload bit positions (byte x 8 + bit, bit 0 the byte's least significant) of the
    /// raw value's bits, least significant first.
    pub fn positions(&self) -> impl Iterator<Item = usize> + '_ {
        self.at.iter().map(|p| usize::from(*p))
    }

    /// The raw bits, least significant first in a word.
    pub fn bits(&self, data: &[u8]) -> u64 {
        let mut v = 0u64;
        for (i, p) in self.positions().enumerate() {
            if data.get(p / 8).is_some_and(|b| b >> (p % 8) & 1 == 1) {
                v |= 1 << i;
            }
        }
        v
    }

    /// Put the raw bits (`len` of them) into `data`.
    pub fn put_bits(&self, data: &mut [u8], v: u64) {
        for (i, p) in self.positions().enumerate() {
            if let Some(b) = data.get_mut(p / 8) {
                if v >> i & 1 == 1 {
                    *b |= 1 << (p % 8);
                } else {
                    *b &= !(1 << (p % 8));
                }
            }
        }
    }

    /// The raw value as an integer (sign-extended for a signed signal).
    pub fn raw(&self, data: &[u8]) -> i64 {
        let v = self.bits(data);
        match self.kind {
            Kind::Signed if self.len < 64 && v >> (self.len - 1) & 1 == 1 => {
                (v | !((1u64 << self.len) - 1)) as i64
            }
            _ => v as i64,
        }
    }

    /// The physical value.
    pub fn phys(&self, data: &[u8]) -> f64 {
        let raw = match self.kind {
            Kind::Float32 => f64::from(f32::from_bits(self.bits(data) as u32)),
            Kind::Float64 => f64::from_bits(self.bits(data)),
            Kind::Unsigned => self.bits(data) as f64,
            Kind::Signed => self.raw(data) as f64,
        };
        raw * self.factor + self.offset
    }

    /// The integer raw values it can carry (floats: none).
    pub fn raw_range(&self) -> Option<(i64, i64)> {
        let n = u32::from(self.len);
        match self.kind {
            Kind::Signed => Some((-(1i64 << (n - 1)), ((1u64 << (n - 1)) - 1) as i64)),
            Kind::Unsigned if n < 64 => Some((0, ((1u64 << n) - 1) as i64)),
            Kind::Unsigned => Some((0, i64::MAX)),
            Kind::Float32 | Kind::Float64 => None,
        }
    }

    /// Put a raw integer, refusing one it cannot carry.
    pub fn put_raw(&self, message: &str, data: &mut [u8], raw: i64) -> Result<(), EncodeError> {
        let Some((lo, hi)) = self.raw_range() else {
            return Err(EncodeError::Unknown(format!(
                "message {message}, signal {}: a float signal takes a physical value",
                self.name
            )));
        };
        if raw < lo || raw > hi {
            return Err(self.out_of_range(message, raw as f64 * self.factor + self.offset));
        }
        self.put_bits(data, raw as u64);
        Ok(())
    }

    /// Put a physical value (rounded to the nearest raw step), refusing one it cannot carry.
    pub fn put_phys(&self, message: &str, data: &mut [u8], value: f64) -> Result<(), EncodeError> {
        let raw = (value - self.offset) / self.factor;
        match self.kind {
            Kind::Float32 => self.put_bits(data, u64::from((raw as f32).to_bits())),
            Kind::Float64 => self.put_bits(data, raw.to_bits()),
            Kind::Signed | Kind::Unsigned => {
                let r = raw.round();
                let (lo, hi) = self.raw_range().unwrap_or((0, 0));
                if !r.is_finite() || r < lo as f64 || r > hi as f64 {
                    return Err(self.out_of_range(message, value));
                }
                self.put_bits(data, r as i64 as u64);
            }
        }
        Ok(())
    }

    fn out_of_range(&self, message: &str, value: f64) -> EncodeError {
        let (lo, hi) = self.raw_range().unwrap_or((0, 0));
        let (a, b) = (
            lo as f64 * self.factor + self.offset,
            hi as f64 * self.factor + self.offset,
        );
        EncodeError::OutOfRange {
            message: message.to_string(),
            signal: self.name.clone(),
            value,
            min: a.min(b),
            max: a.max(b),
        }
    }
}

impl MessageLayout {
    /// The signal named `name`.
    pub fn signal(&self, name: &str) -> Option<&SignalLayout> {
        self.signals.iter().find(|s| s.name == name)
    }

    /// A payload of the message's size with `values` (physical, by signal name); the signals
    /// not named are 0. A multiplexed signal goes in only where the multiplexor's value (given
    /// among `values`, else 0) selects it.
    pub fn encode(&self, values: &[(&str, f64)]) -> Result<Vec<u8>, EncodeError> {
        let mut data = vec![0u8; self.size];
        let selected = self.selected(values);
        for (name, v) in values {
            let s = self.signal(name).ok_or_else(|| {
                EncodeError::Unknown(format!("message {} has no signal {name}", self.name))
            })?;
            if let Mux::When(k) = s.mux
                && Some(k) != selected
            {
                continue;
            }
            s.put_phys(&self.name, &mut data, *v)?;
        }
        Ok(data)
    }

    /// The multiplexor's value among `values`.
    fn selected(&self, values: &[(&str, f64)]) -> Option<u64> {
        let m = self.signals.iter().find(|s| s.mux == Mux::Multiplexor)?;
        let v = values
            .iter()
            .find(|(n, _)| *n == m.name)
            .map_or(0.0, |(_, v)| *v);
        Some(((v - m.offset) / m.factor).round() as u64)
    }

    /// The payload's signals with their physical values (the multiplexed ones its multiplexor
    /// selects), in the DBC's order.
    pub fn decode(&self, data: &[u8]) -> Result<Vec<(&str, f64)>, DecodeError> {
        if data.len() < self.size {
            return Err(DecodeError::Length {
                message: self.name.clone(),
                id: self.id,
                got: data.len(),
                want: self.size,
            });
        }
        let selected = self
            .signals
            .iter()
            .find(|s| s.mux == Mux::Multiplexor)
            .map(|m| m.bits(data));
        Ok(self
            .signals
            .iter()
            .filter(|s| !matches!(s.mux, Mux::When(k) if Some(k) != selected))
            .map(|s| (s.name.as_str(), s.phys(data)))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LAB: &str = r#"VERSION ""

NS_ :

BS_:

BU_: IMU NAV

BO_ 2147484160 IMU_RATES: 64 IMU
 SG_ Counter : 7|12@0+ (1,0) [0|4095] "" NAV
 SG_ Crc : 23|8@0+ (1,0) [0|255] "" NAV
 SG_ RateX : 31|24@0- (1e-05,0) [-83.88608|83.88607] "deg/s" NAV
 SG_ Temp : 504|8@1- (0.5,-10) [-74|53.5] "degC" NAV

BO_ 300 MODE: 8 NAV
 SG_ Page M : 0|8@1+ (1,0) [0|255] "" IMU
 SG_ Heading m1 : 8|16@1+ (0.01,0) [0|655.35] "deg" IMU
 SG_ Speed m2 : 8|32@1+ (1,0) [0|0] "m/s" IMU

SIG_VALTYPE_ 300 Speed : 1;
"#;

    #[test]
    fn a_labs_contract_reads_with_extended_ids_can_fd_motorola_and_floats() {
        let c = Contract::parse(LAB).expect("parses");
        let m = c.message("IMU_RATES").expect("message");
        assert_eq!(
            (m.id, m.size, m.sender.as_str()),
            (FrameId::Extended(0x200), 64, "IMU")
        );
        // a 12-bit Motorola counter from bit 7: byte 0 all of it, then byte 1's top four bits
        let mut data = vec![0u8; 64];
        let counter = m.signal("Counter").expect("signal");
        counter
            .put_raw("IMU_RATES", &mut data, 0xABC)
            .expect("fits");
        assert_eq!(&data[..2], &[0xAB, 0xC0]);
        assert_eq!(counter.bits(&data), 0xABC);
        let data = m
            .encode(&[("Counter", 4095.0), ("RateX", -12.34567), ("Temp", 21.5)])
            .expect("encodes");
        let got = m.decode(&data).expect("decodes");
        let v = |n: &str| got.iter().find(|(s, _)| *s == n).expect("signal").1;
        assert_eq!(v("Counter"), 4095.0);
        assert!((v("RateX") + 12.34567).abs() < 1e-9, "{}", v("RateX"));
        assert_eq!(v("Temp"), 21.5);
        // the temperature in the CAN FD frame's last byte: (21.5 + 10) / 0.5 = 63; the bytes
        // are those cantools encodes from the same DBC text
        assert_eq!(data[63], 63);
        assert_eq!(&data[..6], &[0xFF, 0xF0, 0x00, 0xED, 0x29, 0x79]);
        let e = m.encode(&[("Temp", 60.0)]).expect_err("past 8 bits");
        assert!(
            e.to_string()
                .contains("message IMU_RATES, signal Temp: 60 outside [-74, 53.5]"),
            "{e}"
        );
        // multiplexed: the page selects the heading or the speed (an IEEE float)
        let mode = c.by_id(FrameId::Standard(300)).expect("MODE");
        assert_eq!(mode.signal("Speed").expect("speed").kind, Kind::Float32);
        // each page as cantools encodes it, and only its own signals read back
        let mut pages = Vec::new();
        for (page, speed, selected, bytes) in [
            (
                1.0,
                9.0,
                ("Heading", 123.45),
                [0x01, 0x39, 0x30, 0, 0, 0, 0, 0],
            ),
            (
                2.0,
                9.5,
                ("Speed", 9.5),
                [0x02, 0x00, 0x00, 0x18, 0x41, 0, 0, 0],
            ),
        ] {
            let d = mode
                .encode(&[("Page", page), ("Heading", 123.45), ("Speed", speed)])
                .expect("a page");
            assert_eq!(d, bytes, "page {page}");
            assert_eq!(
                mode.decode(&d).expect("decodes"),
                [("Page", page), selected]
            );
            pages.push(d);
        }
        let d2 = &pages[1];
        assert_eq!(
            c.decode(FrameId::Standard(0x7FF), d2),
            Err(DecodeError::UnknownId(FrameId::Standard(0x7FF)))
        );
        assert!(matches!(
            mode.decode(&d2[..4]),
            Err(DecodeError::Length {
                got: 4,
                want: 8,
                ..
            })
        ));
    }

    #[test]
    fn a_contract_that_does_not_fit_names_the_message_and_the_signal() {
        let bad = |from: &str, to: &str, want: &str| {
            let e = Contract::parse(&LAB.replacen(from, to, 1)).expect_err(want);
            assert!(e.to_string().contains(want), "{e} (expected {want})");
        };
        bad(
            "Temp : 504|8@1-",
            "Temp : 508|8@1-",
            "message IMU_RATES, signal Temp: 8 bits from bit 508 run past the message's 64 bytes",
        );
        bad(
            "IMU_RATES: 64",
            "IMU_RATES: 65",
            "message IMU_RATES (0x00000200 (extended)): 65 bytes",
        );
        bad(
            "Speed m2 : 8|32@1+",
            "Speed m2 : 8|16@1+",
            "message MODE, signal Speed: 16 bits: a signal of this kind has 32",
        );
        bad(
            "BO_ 300 MODE: 8 NAV",
            "BO_ 300 MODE 8 NAV",
            "does not parse",
        );
    }
}
