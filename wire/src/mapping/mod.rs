//! A lab's mapping: which messages and signals of the DBC it brings carry what the bench's
//! emulated devices produce (the IMU's samples, its status), which of its messages carry an
//! alive counter and a checksum and how, and the bus's bit rates. Read from a TOML file beside
//! the DBC and checked against the contract ([`crate::dbc::Contract`]) before anything runs: a
//! mapping that does not fit (a message or a signal the DBC lacks, a signal too narrow for the
//! range it must carry, a counter that is not a whole number, a checksum of the wrong width or
//! over its own bytes, a rate the bus cannot hold) is refused, naming the message and the
//! signal. Every key: docs/your-dbc.md.

mod solution;
mod table;

pub use solution::{
    PositionMapping, SolutionMapping, SolutionPart, SolutionReader, VelocityMapping,
};
pub use table::{CommandRefused, FAULT_NAMES, TableMapping, TableSide};

use crate::crc::Crc;
use crate::dbc::{Contract, EncodeError, FrameId, Kind, MessageLayout, SignalLayout};
use serde::Deserialize;
use thiserror::Error;

/// The mapping file as written.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MappingFile {
    /// The DBC it maps, relative to the mapping file.
    pub dbc: String,
    /// The bus's bit rates.
    pub bus: BusRates,
    /// The IMU's frames, when the lab's contract has them.
    #[serde(default)]
    pub imu: Option<ImuMapping>,
    /// The turntable's commands and reports, when the lab's contract has them.
    #[serde(default)]
    pub turntable: Option<TableMapping>,
    /// Where the device under test puts its solution, when the bench is to judge it.
    #[serde(default)]
    pub solution: Option<SolutionMapping>,
    /// The messages protected by an alive counter and a checksum.
    #[serde(default)]
    pub protect: Vec<Protection>,
    /// The bus's other periodic messages (the device's own frames, the table's reports), for
    /// the bus's load and every message's worst-case response time.
    #[serde(default)]
    pub traffic: Vec<Traffic>,
}

/// A periodic message besides the IMU's.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Traffic {
    /// The message, by its DBC name.
    pub message: String,
    /// Its period, ms.
    pub period_ms: f64,
    /// How late after its period's start it may be queued, ms (default 0).
    #[serde(default)]
    pub jitter_ms: f64,
}

/// The bus's bit rates.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BusRates {
    /// Arbitration phase (classic CAN: the only one), bit/s.
    pub bitrate: f64,
    /// CAN FD's data phase with the bit-rate switch, bit/s (default: `bitrate`).
    #[serde(default)]
    pub data_bitrate: Option<f64>,
}

/// The IMU's samples and status.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuMapping {
    /// Samples per second.
    pub rate_hz: f64,
    /// Samples a frame packs (`{k}` in the signals' names: 0 to this less one).
    #[serde(default = "one")]
    pub samples_per_frame: usize,
    /// The three gyros.
    pub gyro: Channel,
    /// The three accelerometers.
    pub accel: Channel,
    /// The unit's status frame.
    #[serde(default)]
    pub status: Option<StatusMapping>,
}

fn one() -> usize {
    1
}

/// What a channel's signals carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Quantity {
    /// A rate (deg/s) or a specific force (m/s^2), in the signal's unit.
    Rate,
    /// The increment over one sample (deg, m/s).
    Increment,
    /// Pulse counts, wrapping at the signal's width.
    Pulses,
}

/// Three axes of one sensor in one message.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Channel {
    /// The message.
    pub message: String,
    /// What its signals carry.
    pub quantity: Quantity,
    /// The x, y and z signals (with `{k}`, the sample's place in the frame, when a frame packs
    /// several).
    pub signals: [String; 3],
    /// The largest magnitude the unit puts out, in the signals' unit (pulses: per sample).
    pub full_scale: f64,
    /// The sample counter's signal (the frame's first sample), wrapping at its width.
    #[serde(default)]
    pub counter: Option<String>,
}

/// The unit's status frame.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StatusMapping {
    /// The message.
    pub message: String,
    /// One frame per this many samples.
    pub every: u32,
    /// The temperature's signal (degC).
    #[serde(default)]
    pub temperature: Option<String>,
    /// The built-in test word's signal.
    #[serde(default)]
    pub bit: Option<String>,
    /// The PPS latch's offset into the sample (ms).
    #[serde(default)]
    pub pps_offset: Option<String>,
    /// The PPS latch's valid flag.
    #[serde(default)]
    pub pps_valid: Option<String>,
}

/// An alive counter and a checksum on every frame of a message.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Protection {
    /// The message.
    pub message: String,
    /// The alive counter's signal: one more every frame, wrapping at its width.
    #[serde(default)]
    pub alive: Option<String>,
    /// The checksum's signal.
    #[serde(default)]
    pub crc: Option<String>,
    /// The checksum's algorithm, by its catalogue name ([`Crc::named`]).
    #[serde(default)]
    pub algorithm: Option<String>,
    /// The payload bytes it covers, first and last (default: those after its own when it
    /// leads the payload, else those before it).
    #[serde(default)]
    pub bytes: Option<[usize; 2]>,
}

/// Why a mapping does not fit its DBC.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MappingError {
    /// The text is not a mapping.
    #[error("the mapping does not read: {0}")]
    Parse(String),
    /// A message the DBC does not have.
    #[error("[{section}]: message {message} is not in the DBC")]
    NoMessage {
        /// Where in the mapping.
        section: String,
        /// The message.
        message: String,
    },
    /// A signal its message does not have.
    #[error("[{section}]: message {message} has no signal {signal}")]
    NoSignal {
        /// Where in the mapping.
        section: String,
        /// The message.
        message: String,
        /// The signal.
        signal: String,
    },
    /// A signal that cannot carry what it must.
    #[error("[{section}]: message {message}, signal {signal}: {why}")]
    BadSignal {
        /// Where in the mapping.
        section: String,
        /// The message.
        message: String,
        /// The signal.
        signal: String,
        /// What is wrong.
        why: String,
    },
    /// A value out of its range.
    #[error("[{section}]: {why}")]
    Bad {
        /// Where in the mapping.
        section: String,
        /// What is wrong.
        why: String,
    },
    /// More traffic than the bus carries.
    #[error("the bus cannot hold the traffic: {0}")]
    Overload(String),
}

/// A mapping checked against its DBC.
#[derive(Debug, Clone, PartialEq)]
pub struct Mapping {
    /// What the file says.
    pub file: MappingFile,
    /// The devices' frames per second, by message.
    pub frames_per_s: Vec<(String, f64)>,
    /// The bus's load from those frames at their longest (every stuff bit), 0 to 1.
    pub worst_load: f64,
}

impl Mapping {
    /// Read the mapping `text` and check it against `contract`.
    pub fn parse(text: &str, contract: &Contract) -> Result<Self, MappingError> {
        let file: MappingFile =
            toml::from_str(text).map_err(|e| MappingError::Parse(e.to_string()))?;
        Self::check(file, contract)
    }

    /// Check `file` against `contract`.
    pub fn check(file: MappingFile, contract: &Contract) -> Result<Self, MappingError> {
        let rates = file.bus;
        let data_bps = rates.data_bitrate.unwrap_or(rates.bitrate);
        if !(rates.bitrate >= 1000.0 && data_bps >= rates.bitrate && data_bps <= 1.2e7) {
            return Err(MappingError::Bad {
                section: "bus".into(),
                why: format!(
                    "bitrate {} and data_bitrate {data_bps}: a bit rate from 1 kbit/s, the data phase's at least that and at most 12 Mbit/s",
                    rates.bitrate
                ),
            });
        }
        let mut frames: Vec<(String, f64)> = Vec::new();
        if let Some(imu) = &file.imu {
            check_imu(imu, contract, &mut frames)?;
        }
        if let Some(t) = &file.turntable {
            table::check(t, contract)?;
        }
        if let Some(s) = &file.solution {
            solution::check(s, contract)?;
        }
        for (i, p) in file.protect.iter().enumerate() {
            check_protection(&format!("protect {}", i + 1), p, contract)?;
        }
        for (i, t) in file.traffic.iter().enumerate() {
            let section = format!("traffic {}", i + 1);
            message(contract, &section, &t.message)?;
            if !(t.period_ms > 0.0 && t.jitter_ms >= 0.0 && t.jitter_ms.is_finite()) {
                return Err(MappingError::Bad {
                    section,
                    why: format!(
                        "{}: period_ms {} and jitter_ms {}: a period above 0, a jitter from 0",
                        t.message, t.period_ms, t.jitter_ms
                    ),
                });
            }
            frames.push((t.message.clone(), 1000.0 / t.period_ms));
        }
        let mut worst_load = 0.0;
        for (name, per_s) in &frames {
            let m = message(contract, "imu", name)?;
            let t = crate::busload::frame_time_worst_s(
                matches!(m.id, FrameId::Extended(_)),
                m.size,
                m.size > 8,
                rates.bitrate,
                data_bps,
            );
            worst_load += per_s * t;
        }
        if worst_load > 1.0 {
            let list: Vec<String> = frames
                .iter()
                .map(|(m, f)| format!("{m} {f:.0}/s"))
                .collect();
            return Err(MappingError::Overload(format!(
                "{} at {} bit/s (data phase {data_bps}) is {:.0} % of the bus at its longest frames",
                list.join(", "),
                rates.bitrate,
                100.0 * worst_load
            )));
        }
        Ok(Self {
            file,
            frames_per_s: frames,
            worst_load,
        })
    }
}

impl Mapping {
    /// Every periodic message the mapping names (the IMU's at their rates, then the
    /// `[[traffic]]`), for [`crate::busload::response_times`].
    pub fn periodic(&self, contract: &Contract) -> Vec<crate::busload::Periodic> {
        let jitter = |name: &str| {
            self.file
                .traffic
                .iter()
                .find(|t| t.message == name)
                .map_or(0.0, |t| t.jitter_ms / 1000.0)
        };
        self.frames_per_s
            .iter()
            .filter_map(|(name, per_s)| {
                let m = contract.message(name)?;
                let (id, extended) = match m.id {
                    FrameId::Extended(x) => (x, true),
                    FrameId::Standard(x) => (u32::from(x), false),
                };
                Some(crate::busload::Periodic {
                    name: name.clone(),
                    id,
                    extended,
                    payload: m.size,
                    fd: m.size > 8,
                    period_s: 1.0 / per_s,
                    jitter_s: jitter(name),
                })
            })
            .collect()
    }
}

/// The message `name` of `contract`, or the error naming it under `section`.
fn message<'a>(
    contract: &'a Contract,
    section: &str,
    name: &str,
) -> Result<&'a MessageLayout, MappingError> {
    contract
        .message(name)
        .ok_or_else(|| MappingError::NoMessage {
            section: section.into(),
            message: name.into(),
        })
}

/// The signal `name` of message `m`, or the error naming both under `section`.
fn signal<'a>(
    m: &'a MessageLayout,
    section: &str,
    name: &str,
) -> Result<&'a SignalLayout, MappingError> {
    m.signal(name).ok_or_else(|| MappingError::NoSignal {
        section: section.into(),
        message: m.name.clone(),
        signal: name.into(),
    })
}

fn bad_signal(section: &str, m: &MessageLayout, s: &SignalLayout, why: String) -> MappingError {
    MappingError::BadSignal {
        section: section.into(),
        message: m.name.clone(),
        signal: s.name.clone(),
        why,
    }
}

/// A counter's signal: a whole number from 0 (unsigned, factor 1, offset 0).
fn check_counter(section: &str, m: &MessageLayout, s: &SignalLayout) -> Result<(), MappingError> {
    if s.kind != Kind::Unsigned || s.factor != 1.0 || s.offset != 0.0 {
        return Err(bad_signal(
            section,
            m,
            s,
            "a counter must be an unsigned whole number (factor 1, offset 0)".into(),
        ));
    }
    Ok(())
}

fn check_imu(
    imu: &ImuMapping,
    contract: &Contract,
    frames: &mut Vec<(String, f64)>,
) -> Result<(), MappingError> {
    let spf = imu.samples_per_frame;
    if !(imu.rate_hz > 0.0 && imu.rate_hz <= 100_000.0) || spf == 0 || spf > 64 {
        return Err(MappingError::Bad {
            section: "imu".into(),
            why: format!(
                "rate_hz {} and samples_per_frame {spf}: a rate up to 100 kHz, 1 to 64 samples a frame",
                imu.rate_hz
            ),
        });
    }
    for (section, c) in [("imu.gyro", &imu.gyro), ("imu.accel", &imu.accel)] {
        let m = message(contract, section, &c.message)?;
        for name in &c.signals {
            if spf > 1 && !name.contains("{k}") {
                return Err(MappingError::Bad {
                    section: section.into(),
                    why: format!(
                        "signal {name}: a frame packs {spf} samples, so each signal's name needs {{k}} (the sample's place, 0 to {})",
                        spf - 1
                    ),
                });
            }
            for k in 0..spf {
                let s = signal(m, section, &name.replace("{k}", &k.to_string()))?;
                check_range(section, m, s, c)?;
            }
        }
        if let Some(n) = &c.counter {
            check_counter(section, m, signal(m, section, n)?)?;
        }
        if !frames.iter().any(|(f, _)| *f == c.message) {
            frames.push((c.message.clone(), imu.rate_hz / spf as f64));
        }
    }
    if let Some(st) = &imu.status {
        let m = message(contract, "imu.status", &st.message)?;
        for n in [&st.temperature, &st.bit, &st.pps_offset, &st.pps_valid]
            .into_iter()
            .flatten()
        {
            signal(m, "imu.status", n)?;
        }
        if st.every == 0 {
            return Err(MappingError::Bad {
                section: "imu.status".into(),
                why: "every: at least 1 sample".into(),
            });
        }
        frames.push((st.message.clone(), imu.rate_hz / f64::from(st.every)));
    }
    Ok(())
}

/// A sensor's signal carries its full scale both ways (pulses: a whole number wide enough for
/// one sample's pulses to be told from a wrap).
fn check_range(
    section: &str,
    m: &MessageLayout,
    s: &SignalLayout,
    c: &Channel,
) -> Result<(), MappingError> {
    if !(c.full_scale > 0.0 && c.full_scale.is_finite()) {
        return Err(MappingError::Bad {
            section: section.into(),
            why: format!("full_scale {}: a positive number", c.full_scale),
        });
    }
    let Some((lo, hi)) = s.raw_range() else {
        // a float carries any value
        return Ok(());
    };
    if c.quantity == Quantity::Pulses {
        if s.factor != 1.0 || s.offset != 0.0 {
            return Err(bad_signal(
                section,
                m,
                s,
                "pulses are whole counts (factor 1, offset 0)".into(),
            ));
        }
        // a counter of n bits tells a step of less than half its span from a wrap
        let span = (hi - lo) as f64 + 1.0;
        if 2.0 * c.full_scale >= span {
            return Err(bad_signal(
                section,
                m,
                s,
                format!(
                    "{} bits wrap after {span} pulses: a sample's {} pulses cannot be told from a wrap",
                    s.len, c.full_scale
                ),
            ));
        }
        return Ok(());
    }
    let (a, b) = (
        lo as f64 * s.factor + s.offset,
        hi as f64 * s.factor + s.offset,
    );
    let (lo_phys, hi_phys) = (a.min(b), a.max(b));
    if lo_phys > -c.full_scale || hi_phys < c.full_scale {
        return Err(bad_signal(
            section,
            m,
            s,
            format!(
                "carries {lo_phys} to {hi_phys} {}, the unit puts out up to {} either way",
                s.unit, c.full_scale
            ),
        ));
    }
    Ok(())
}

fn check_protection(
    section: &str,
    p: &Protection,
    contract: &Contract,
) -> Result<(), MappingError> {
    let m = message(contract, section, &p.message)?;
    if let Some(a) = &p.alive {
        check_counter(section, m, signal(m, section, a)?)?;
    }
    let Some(c) = &p.crc else {
        if p.algorithm.is_some() || p.bytes.is_some() {
            return Err(MappingError::Bad {
                section: section.into(),
                why: format!(
                    "message {}: an algorithm or bytes without a crc signal",
                    m.name
                ),
            });
        }
        return Ok(());
    };
    let s = signal(m, section, c)?;
    let name = p.algorithm.as_deref().unwrap_or("(none)");
    let Some(crc) = Crc::named(name) else {
        return Err(bad_signal(
            section,
            m,
            s,
            format!(
                "algorithm {name}: not one the bench knows (CRC-8/SAE-J1850, CRC-8/AUTOSAR, CRC-8/SMBUS, CRC-16/IBM-3740, CRC-16/ARC)"
            ),
        ));
    };
    if s.kind != Kind::Unsigned || u32::from(s.len) != u32::from(crc.width) {
        return Err(bad_signal(
            section,
            m,
            s,
            format!(
                "{name} is {} bits; the signal is {} bits{}",
                crc.width,
                s.len,
                if s.kind == Kind::Unsigned {
                    ""
                } else {
                    ", and not unsigned"
                }
            ),
        ));
    }
    let [first, last] = p.bytes.unwrap_or([0, m.size.saturating_sub(1)]);
    if first > last || last >= m.size {
        return Err(MappingError::Bad {
            section: section.into(),
            why: format!(
                "message {}: bytes {first} to {last}, not within its {} bytes",
                m.name, m.size
            ),
        });
    }
    let own: Vec<usize> = s.positions().map(|b| b / 8).collect();
    if p.bytes.is_some() && own.iter().any(|b| (first..=last).contains(b)) {
        return Err(bad_signal(
            section,
            m,
            s,
            format!("the checksum covers bytes {first} to {last}, its own among them"),
        ));
    }
    Ok(())
}

/// One IMU sample as the mapping's signals carry it (the quantity its channels name, in their
/// units), with the unit's sample counter.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MappedSample {
    /// The unit's sample counter (the mapping's counter signal takes it modulo its width).
    pub counter: u64,
    /// Gyros x, y, z.
    pub gyro: [f64; 3],
    /// Accelerometers x, y, z.
    pub accel: [f64; 3],
    /// The unit's temperature, degC (its status frame's).
    pub temperature_c: f64,
    /// Its built-in test word (0: healthy).
    pub bit: u32,
    /// A PPS edge latched in this sample: its time after the sample's start, ms.
    pub pps_ms: Option<f64>,
}

/// A frame of a mapped contract.
#[derive(Debug, Clone, PartialEq)]
pub struct MappedFrame {
    /// Its identifier.
    pub id: FrameId,
    /// Its payload (more than 8 bytes: a CAN FD frame).
    pub data: Vec<u8>,
}

/// The IMU's frames of a mapped contract: samples packed as many to a frame as the mapping
/// says, each protected message's alive counter and checksum filled in (the devices' side of
/// [`Guard`]).
#[derive(Debug, Clone)]
pub struct Framer<'a> {
    contract: &'a Contract,
    mapping: &'a Mapping,
    pending: Vec<MappedSample>,
    protector: Protector<'a>,
    /// Samples taken, for the status frame's period.
    seen: u64,
    /// The PPS latched since the last status frame (ms into its sample).
    pps: Option<f64>,
}

impl<'a> Framer<'a> {
    /// The framer of `mapping` (checked against `contract`).
    pub fn new(contract: &'a Contract, mapping: &'a Mapping) -> Self {
        Self {
            contract,
            mapping,
            pending: Vec::new(),
            protector: Protector::new(mapping),
            seen: 0,
            pps: None,
        }
    }

    /// One sample: the frames it completes (none until a frame's samples are all there).
    pub fn push(&mut self, s: MappedSample) -> Result<Vec<MappedFrame>, EncodeError> {
        let mapping = self.mapping;
        let Some(imu) = &mapping.file.imu else {
            return Ok(Vec::new());
        };
        let status = self.status(imu, &s)?;
        self.pending.push(s);
        let mut out = if self.pending.len() < imu.samples_per_frame {
            Vec::new()
        } else {
            self.blocks(imu)?
        };
        out.extend(status);
        Ok(out)
    }

    /// The unit's status frame when sample `s` completes its period: its temperature and
    /// built-in test word, and the PPS latched since the last one (offset and valid flag; none:
    /// not valid).
    fn status(
        &mut self,
        imu: &ImuMapping,
        s: &MappedSample,
    ) -> Result<Option<MappedFrame>, EncodeError> {
        self.seen += 1;
        if s.pps_ms.is_some() {
            self.pps = s.pps_ms;
        }
        let Some(st) = &imu.status else {
            return Ok(None);
        };
        if !self.seen.is_multiple_of(u64::from(st.every.max(1))) {
            return Ok(None);
        }
        let pps = self.pps.take();
        let v: Vec<(&str, f64)> = [
            (&st.temperature, s.temperature_c),
            (&st.bit, f64::from(s.bit)),
            (&st.pps_offset, pps.unwrap_or(0.0)),
            (&st.pps_valid, f64::from(u8::from(pps.is_some()))),
        ]
        .into_iter()
        .filter_map(|(name, x)| name.as_deref().map(|n| (n, x)))
        .collect();
        let m = self.contract.message(&st.message).ok_or_else(|| {
            EncodeError::Unknown(format!("the DBC has no message {}", st.message))
        })?;
        let mut data = m.encode(&v)?;
        self.protect(m, &mut data)?;
        Ok(Some(MappedFrame { id: m.id, data }))
    }

    /// The sample blocks of the samples pending (a frame's worth): each message's frame.
    fn blocks(&mut self, imu: &ImuMapping) -> Result<Vec<MappedFrame>, EncodeError> {
        let samples = std::mem::take(&mut self.pending);
        let mut out: Vec<MappedFrame> = Vec::new();
        // each message's values, gyro's first (one message when both share it)
        let mut values: Vec<(&str, Vec<(String, f64)>)> = Vec::new();
        for (c, pick) in [(&imu.gyro, 0), (&imu.accel, 1)] {
            let i = match values.iter().position(|(m, _)| *m == c.message) {
                Some(i) => i,
                None => {
                    values.push((c.message.as_str(), Vec::new()));
                    values.len() - 1
                }
            };
            let v = &mut values[i].1;
            for (k, s) in samples.iter().enumerate() {
                let axes = if pick == 0 { s.gyro } else { s.accel };
                for (name, x) in c.signals.iter().zip(axes) {
                    v.push((name.replace("{k}", &k.to_string()), x));
                }
            }
            if let Some(n) = &c.counter {
                let sig = self.contract.message(&c.message).and_then(|m| m.signal(n));
                let wrap = sig.map_or(u64::MAX, |s| wrap_of(s.len));
                v.push((n.clone(), (samples[0].counter % wrap) as f64));
            }
        }
        for (message, v) in values {
            let m = self
                .contract
                .message(message)
                .ok_or_else(|| EncodeError::Unknown(format!("the DBC has no message {message}")))?;
            let named: Vec<(&str, f64)> = v.iter().map(|(n, x)| (n.as_str(), *x)).collect();
            let mut data = m.encode(&named)?;
            self.protect(m, &mut data)?;
            out.push(MappedFrame { id: m.id, data });
        }
        Ok(out)
    }

    /// Fill in message `m`'s alive counter and checksum ([`Protector::protect`]).
    pub fn protect(&mut self, m: &MessageLayout, data: &mut [u8]) -> Result<(), EncodeError> {
        self.protector.protect(m, data)
    }
}

/// A sender's alive counters: each protected message's frames numbered one up from 0 and
/// their checksums filled in (the senders' side of [`Guard`]).
#[derive(Debug, Clone)]
pub struct Protector<'a> {
    mapping: &'a Mapping,
    alive: std::collections::BTreeMap<String, u64>,
}

impl<'a> Protector<'a> {
    /// The protector of `mapping`'s messages.
    pub fn new(mapping: &'a Mapping) -> Self {
        Self {
            mapping,
            alive: Default::default(),
        }
    }

    /// Fill in message `m`'s alive counter (one more than its last frame's) and checksum,
    /// where the mapping protects it.
    pub fn protect(&mut self, m: &MessageLayout, data: &mut [u8]) -> Result<(), EncodeError> {
        let Some(p) = self
            .mapping
            .file
            .protect
            .iter()
            .find(|p| p.message == m.name)
        else {
            return Ok(());
        };
        if let Some(s) = p.alive.as_deref().and_then(|a| m.signal(a)) {
            let n = self.alive.entry(m.name.clone()).or_insert(0);
            s.put_raw(&m.name, data, (*n % wrap_of(s.len)) as i64)?;
            *n += 1;
        }
        if let Some((s, crc, [first, last])) = checksum(m, p) {
            let v = crc.compute(&data[first..=last]);
            s.put_raw(&m.name, data, i64::from(v))?;
        }
        Ok(())
    }
}

/// A counter of `bits` wraps after this many values.
fn wrap_of(bits: u16) -> u64 {
    if bits >= 64 { u64::MAX } else { 1u64 << bits }
}

/// The checksum of protection `p` on message `m`: its signal, its algorithm and the bytes it
/// covers.
fn checksum<'m>(
    m: &'m MessageLayout,
    p: &Protection,
) -> Option<(&'m SignalLayout, Crc, [usize; 2])> {
    let s = m.signal(p.crc.as_deref()?)?;
    let crc = Crc::named(p.algorithm.as_deref()?)?;
    let bytes = p.bytes.unwrap_or_else(|| {
        // every byte but the checksum's own, which the default takes as the first or the last
        let own: Vec<usize> = s.positions().map(|b| b / 8).collect();
        if own.contains(&0) {
            [own.iter().max().map_or(0, |b| b + 1), m.size - 1]
        } else {
            [0, own.iter().min().map_or(m.size, |b| *b) - 1]
        }
    });
    Some((s, crc, bytes))
}

/// What was wrong with a protected frame a device sent.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ProtectionFault {
    /// The checksum does not match the bytes.
    #[error("message {message}: checksum {got:#X}, the bytes give {want:#X}")]
    Checksum {
        /// The message.
        message: String,
        /// The checksum in the frame.
        got: u64,
        /// The checksum of its bytes.
        want: u64,
    },
    /// The alive counter did not go one up.
    #[error("message {message}: alive counter {got} after {last} (expected {want})")]
    Skipped {
        /// The message.
        message: String,
        /// The counter in the frame.
        got: u64,
        /// The one before it.
        last: u64,
        /// The one expected.
        want: u64,
    },
}

/// The fault of a frame of message `m` whose checksum (where `mapping` protects it) does not
/// match its bytes.
pub fn checksum_fault(
    mapping: &Mapping,
    m: &MessageLayout,
    data: &[u8],
) -> Option<ProtectionFault> {
    let p = mapping.file.protect.iter().find(|p| p.message == m.name)?;
    let (s, crc, [first, last]) = checksum(m, p)?;
    let want = u64::from(crc.compute(data.get(first..=last)?));
    let got = s.bits(data);
    (got != want).then(|| ProtectionFault::Checksum {
        message: m.name.clone(),
        got,
        want,
    })
}

/// The judge's side of [`Framer::protect`]: every protected frame a device sends checked for
/// its checksum and its alive counter, each fault counted by message.
#[derive(Debug, Clone, Default)]
pub struct Guard {
    last: std::collections::BTreeMap<String, u64>,
    /// Frames checked.
    pub checked: u64,
    /// The faults found, in order.
    pub faults: Vec<ProtectionFault>,
}

impl Guard {
    /// Check a frame of message `m` (of `mapping`'s contract); a message the mapping does not
    /// protect passes unchecked.
    pub fn check(&mut self, mapping: &Mapping, m: &MessageLayout, data: &[u8]) {
        let Some(p) = mapping.file.protect.iter().find(|p| p.message == m.name) else {
            return;
        };
        self.checked += 1;
        if let Some(f) = checksum_fault(mapping, m, data) {
            self.faults.push(f);
        }
        if let Some(s) = p.alive.as_deref().and_then(|a| m.signal(a)) {
            let got = s.bits(data);
            if let Some(&last) = self.last.get(&m.name) {
                let want = (last + 1) % wrap_of(s.len);
                if got != want {
                    self.faults.push(ProtectionFault::Skipped {
                        message: m.name.clone(),
                        got,
                        last,
                        want,
                    });
                }
            }
            self.last.insert(m.name.clone(), got);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lab() -> Contract {
        Contract::parse(include_str!("../../contracts/lab-imu.dbc")).expect("the lab's DBC reads")
    }

    const MAPPING: &str = include_str!("../../contracts/lab-imu.toml");

    /// The second contract's mapping fits its DBC: ten samples a CAN FD frame at 1 kHz, two
    /// blocks and a status frame, the table's reports, the box's commands and solution: a small
    /// share of a 500 kbit/s bus with a 2 Mbit/s data phase, every message with a bound.
    #[test]
    fn the_lab_contracts_mapping_fits_its_dbc() {
        let c = lab();
        let m = Mapping::parse(MAPPING, &c).expect("fits");
        let per_s = |n: &str, f: f64| (n.to_string(), f);
        assert_eq!(
            m.frames_per_s,
            vec![
                per_s("IMU_GYRO_BLOCK", 100.0),
                per_s("IMU_ACCEL_BLOCK", 100.0),
                per_s("IMU_STATUS", 10.0),
                per_s("TABLE_REPORT", 100.0),
                per_s("TABLE_CMD", 10.0),
                per_s("INS_HEADING", 50.0),
                per_s("INS_POSITION", 10.0),
            ]
        );
        let p = m.periodic(&c);
        assert!(p.iter().all(|x| x.extended) && p[0].fd && !p[2].fd && p[6].fd);
        assert_eq!(p[4].jitter_s, 0.005);
        let r = crate::busload::response_times(&p, 500e3, 2e6);
        // each message waits at most for one lower frame, every higher one once (the bus is
        // lightly loaded) and itself: below the sum of all frames' longest times, above its own
        let all: f64 = p
            .iter()
            .map(|x| crate::busload::frame_time_worst_s(true, x.payload, x.fd, 500e3, 2e6))
            .sum();
        for (x, r) in p.iter().zip(&r) {
            let own = crate::busload::frame_time_worst_s(true, x.payload, x.fd, 500e3, 2e6);
            let r = r.unwrap_or_else(|| panic!("{} has no bound", x.name));
            assert!(r >= own && r <= all + x.jitter_s + 1e-12, "{}: {r}", x.name);
        }
        // a 64-byte FD frame with an extended identifier at its longest: 56 bits at the
        // arbitration rate (36 and their stuff bits, then ACK, end of frame and intermission)
        // and 679 in the data phase (ESI, DLC and 512 data bits with theirs, the stuff count
        // and 21-bit CRC with their fixed stuff bits, the CRC delimiter)
        let fd = crate::busload::frame_time_worst_s(true, 64, true, 500e3, 2e6);
        assert!((fd - (56.0 / 500e3 + 679.0 / 2e6)).abs() < 1e-12, "{fd}");
        assert!(
            m.worst_load > 0.14 && m.worst_load < 0.16,
            "{}",
            m.worst_load
        );
    }

    /// What does not fit is refused, naming the message and the signal.
    #[test]
    fn a_mapping_that_does_not_fit_is_refused_naming_message_and_signal() {
        let c = lab();
        let refused = |from: &str, to: &str| {
            assert!(MAPPING.contains(from), "{from}");
            Mapping::parse(&MAPPING.replacen(from, to, 1), &c)
                .expect_err("refused")
                .to_string()
        };
        let e = refused("message = \"IMU_GYRO_BLOCK\"", "message = \"IMU_RATES\"");
        assert!(
            e.contains("[imu.gyro]") && e.contains("IMU_RATES is not in the DBC"),
            "{e}"
        );
        let e = refused(
            "message = \"INS_POSITION\"\nperiod_ms",
            "message = \"INS_SPEED\"\nperiod_ms",
        );
        assert!(
            e.contains("[traffic 4]") && e.contains("INS_SPEED is not in the DBC"),
            "{e}"
        );
        let e = refused("period_ms = 10.0", "period_ms = 0.0");
        assert!(e.contains("traffic 1") && e.contains("period_ms 0"), "{e}");
        let e = refused("samples_per_frame = 10", "samples_per_frame = 11");
        assert!(e.contains("IMU_GYRO_BLOCK has no signal GyroX_10"), "{e}");
        let e = refused("full_scale = 300.0", "full_scale = 400.0");
        assert!(
            e.contains("IMU_GYRO_BLOCK, signal GyroX_0: carries -327.68 to 327.67 deg/s"),
            "{e}"
        );
        let e = refused("counter = \"SampleCtr\"", "counter = \"GyroX_0\"");
        assert!(e.contains("signal GyroX_0: a counter must be"), "{e}");
        let e = refused(
            "algorithm = \"CRC-8/SAE-J1850\"",
            "algorithm = \"CRC-16/ARC\"",
        );
        assert!(
            e.contains("[protect 1]")
                && e.contains("signal Crc8: CRC-16/ARC is 16 bits; the signal is 8 bits"),
            "{e}"
        );
        let e = refused("bytes = [1, 63]", "bytes = [0, 63]");
        assert!(
            e.contains("signal Crc8: the checksum covers bytes 0 to 63, its own among them"),
            "{e}"
        );
        let e = refused(
            "algorithm = \"CRC-8/SAE-J1850\"",
            "algorithm = \"CRC-9/NONE\"",
        );
        assert!(
            e.contains("algorithm CRC-9/NONE: not one the bench knows"),
            "{e}"
        );
        let e = refused("rate_hz = 1000.0", "rate_hz = 20000.0");
        assert!(
            e.starts_with("the bus cannot hold the traffic: IMU_GYRO_BLOCK 2000/s"),
            "{e}"
        );
        let e = refused("data_bitrate = 2000000", "data_bitrate = 200000");
        assert!(e.contains("[bus]"), "{e}");
        let e = refused("dbc = ", "dbx = ");
        assert!(e.starts_with("the mapping does not read"), "{e}");
    }

    /// Pulse counts need a whole-number signal wide enough that a sample's pulses are told
    /// from a wrap.
    #[test]
    fn pulses_need_a_counter_wider_than_a_samples_pulses() {
        let c = lab();
        let pulses = MAPPING
            .replacen("quantity = \"rate\"", "quantity = \"pulses\"", 1)
            .replacen("full_scale = 300.0", "full_scale = 100.0", 1);
        let e = Mapping::parse(&pulses, &c)
            .expect_err("a scaled signal")
            .to_string();
        assert!(e.contains("signal GyroX_0: pulses are whole counts"), "{e}");
        // the counters: 12 bits, whole numbers
        let on_counter = pulses.replacen(
            "signals = [\"GyroX_{k}\", \"GyroY_{k}\", \"GyroZ_{k}\"]",
            "signals = [\"SampleCtr\", \"SampleCtr\", \"SampleCtr\"]",
            1,
        );
        let one_sample = on_counter.replacen("samples_per_frame = 10", "samples_per_frame = 1", 1);
        Mapping::parse(&one_sample, &c).expect("100 pulses on 12 bits");
        let e = Mapping::parse(
            &one_sample.replacen("full_scale = 100.0", "full_scale = 2048.0", 1),
            &c,
        )
        .expect_err("wraps")
        .to_string();
        assert!(e.contains("12 bits wrap after 4096 pulses"), "{e}");
    }

    /// The unit's status frame every 100 samples (the lab's `every`): its temperature and BIT
    /// word, the PPS latched since the last status with its offset (valid 0 when none was).
    #[test]
    fn the_units_status_goes_every_hundred_samples_with_the_pps_latched_since_the_last() {
        let c = lab();
        let m = Mapping::parse(MAPPING, &c).expect("fits");
        let mut framer = Framer::new(&c, &m);
        let status = c.message("IMU_STATUS").expect("in the DBC");
        let mut seen = Vec::new();
        for k in 0..200u64 {
            let s = MappedSample {
                counter: k,
                temperature_c: 41.5,
                bit: u32::from(k >= 150),
                pps_ms: (k == 120).then_some(0.25),
                ..Default::default()
            };
            for f in framer.push(s).expect("encodes") {
                if f.id == status.id {
                    seen.push((k, status.decode(&f.data).expect("reads")));
                }
            }
        }
        let get = |d: &[(&str, f64)], n: &str| d.iter().find(|(k, _)| *k == n).map(|x| x.1);
        assert_eq!(seen.len(), 2);
        let (first, second) = (&seen[0].1, &seen[1].1);
        assert_eq!((seen[0].0, seen[1].0), (99, 199));
        assert_eq!(get(first, "PpsValid"), Some(0.0));
        assert_eq!(get(first, "BitWord"), Some(0.0));
        assert_eq!(get(second, "PpsValid"), Some(1.0));
        assert!((get(second, "PpsOffset").unwrap() - 0.25).abs() < 1e-9);
        assert_eq!(get(second, "BitWord"), Some(1.0));
        assert!((get(second, "Temperature").unwrap() - 41.5).abs() < 0.05);
        // protected as the mapping says: one more alive count a frame
        assert_eq!(
            get(second, "AliveCtr").unwrap(),
            (get(first, "AliveCtr").unwrap() + 1.0) % 16.0
        );
    }

    /// The IMU's samples, ten to a CAN FD frame of the lab's contract: each value, the first
    /// sample's counter, the alive counter one up a frame and the checksum right, as the judge's
    /// guard reads them; a byte changed, or a frame left out, is named.
    #[test]
    fn samples_framed_by_the_mapping_read_back_and_their_protection_holds() {
        let c = lab();
        let m = Mapping::parse(MAPPING, &c).expect("fits");
        let mut framer = Framer::new(&c, &m);
        let mut frames = Vec::new();
        for k in 0..30u64 {
            let x = k as f64;
            frames.extend(
                framer
                    .push(MappedSample {
                        counter: 4090 + k,
                        gyro: [0.01 * x, -1.5, 300.0],
                        accel: [0.002 * x, 0.0, -9.806],
                        ..Default::default()
                    })
                    .expect("encodes"),
            );
        }
        assert_eq!(frames.len(), 6, "three of each block");
        let gyro = c.message("IMU_GYRO_BLOCK").expect("in the DBC");
        let d = gyro.decode(&frames[2].data).expect("reads");
        let get = |d: &[(&str, f64)], n: &str| d.iter().find(|(k, _)| *k == n).map(|x| x.1);
        assert_eq!(frames[2].id, FrameId::Extended(0x18FF1021));
        assert_eq!(frames[2].data.len(), 64);
        assert_eq!(
            get(&d, "SampleCtr"),
            Some(((4090 + 10) % 4096) as f64),
            "wrapped at 12 bits"
        );
        assert_eq!(get(&d, "AliveCtr"), Some(1.0));
        assert!((get(&d, "GyroX_3").expect("a signal") - 0.13).abs() < 1e-9);
        assert_eq!(get(&d, "GyroZ_9"), Some(300.0));
        let mut guard = Guard::default();
        for f in &frames {
            let msg = c.by_id(f.id).expect("a message of the DBC");
            guard.check(&m, msg, &f.data);
        }
        assert_eq!(
            (guard.checked, guard.faults.len()),
            (6, 0),
            "{:?}",
            guard.faults
        );
        // a corrupted byte and a lost frame, as a device's faults
        let mut bad = frames[4].data.clone();
        bad[20] ^= 0x01;
        let mut guard = Guard::default();
        guard.check(&m, gyro, &frames[2].data);
        guard.check(&m, gyro, &bad);
        assert!(
            matches!(&guard.faults[..], [ProtectionFault::Checksum { message, .. }] if message == "IMU_GYRO_BLOCK"),
            "{:?}",
            guard.faults
        );
        let mut guard = Guard::default();
        guard.check(&m, gyro, &frames[0].data);
        guard.check(&m, gyro, &frames[4].data);
        assert_eq!(
            guard
                .faults
                .iter()
                .map(|f| f.to_string())
                .collect::<Vec<_>>(),
            vec!["message IMU_GYRO_BLOCK: alive counter 2 after 0 (expected 1)".to_string()]
        );
    }
}
