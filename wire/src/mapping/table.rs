//! The turntable on a lab's contract: which of its messages carries the commands and which the
//! table's reports, which signals carry the opcode, the sequence, the target, the state, the
//! acknowledged sequence, the angle and the fault bits, and the lab's value for each of our
//! commands and states (by their names in `bench.dbc`'s value tables: `IndexAbs`, `Locked`).
//! [`TableSide`] is the emulated table's translator: a command frame in the lab's form into
//! our [`TtCmd`], our [`TtStatus`] into the lab's report frame.

use super::{
    MappedFrame, Mapping, MappingError, ProtectionFault, Protector, bad_signal, check_counter,
    message, signal,
};
use crate::dbc::{Contract, DecodeError, EncodeError, FrameId, MessageLayout};
use crate::{TtCmd, TtCommand, TtState, TtStatus};
use serde::Deserialize;
use std::collections::BTreeMap;

/// The turntable's frames on a lab's contract.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableMapping {
    /// The message carrying the device's commands to the table.
    pub command: String,
    /// Its opcode signal (a whole number; values in `opcodes`).
    pub opcode: String,
    /// Its sequence signal, echoed in the report (none: the table acknowledges nothing).
    #[serde(default)]
    pub sequence: Option<String>,
    /// Its argument signal: the target angle, deg (or the rate, deg/s, for `Rate`).
    #[serde(default)]
    pub argument: Option<String>,
    /// Its axis signal (none: one axis, 0).
    #[serde(default)]
    pub axis: Option<String>,
    /// The message carrying the table's reports.
    pub report: String,
    /// Its state signal (values in `states`).
    pub state: String,
    /// Its axis signal: which axis the report is of (none: one axis, 0).
    #[serde(default)]
    pub report_axis: Option<String>,
    /// Its signal echoing the sequence of the last command acknowledged.
    #[serde(default)]
    pub ack: Option<String>,
    /// Its angle signal, deg.
    pub angle: String,
    /// Its fault bits signal: bit i set for fault i of `fault_bits` (default: stall, lock,
    /// encoder, heartbeat, estop, drive, limit in bits 0 to 6).
    #[serde(default)]
    pub faults: Option<String>,
    /// The bit of each fault in `faults`, by our name (stall, lock, encoder, heartbeat,
    /// estop, drive, limit).
    #[serde(default)]
    pub fault_bits: BTreeMap<String, u32>,
    /// The lab's opcode for each of our commands it has, by our name (`Heartbeat`, `Enable`,
    /// `Disable`, `Home`, `IndexAbs`, `MoveRel`, `Rate`, `Stop`, `EStop`, `Lock`, `Unlock`).
    pub opcodes: BTreeMap<String, i64>,
    /// The lab's value for each of the table's states, by our name (`Disabled`, `Idle`,
    /// `Moving`, `Settling`, `Locked`, `Fault`: every one).
    pub states: BTreeMap<String, i64>,
}

/// Our fault bits' names, in [`crate::TtFaults`]' order.
pub const FAULT_NAMES: [&str; 7] = [
    "stall",
    "lock",
    "encoder",
    "heartbeat",
    "estop",
    "drive",
    "limit",
];

/// Check `t` against `contract`: its messages and signals there, every opcode and state one
/// of ours with a value its signal carries, no value twice, every state given.
pub(super) fn check(t: &TableMapping, contract: &Contract) -> Result<(), MappingError> {
    let sec = "turntable";
    let cmd = message(contract, sec, &t.command)?;
    let rep = message(contract, sec, &t.report)?;
    codes(sec, cmd, signal(cmd, sec, &t.opcode)?, &t.opcodes, |n| {
        TtCommand::ALL.iter().any(|c| c.name() == n)
    })?;
    codes(sec, rep, signal(rep, sec, &t.state)?, &t.states, |n| {
        TtState::ALL.iter().any(|c| c.name() == n)
    })?;
    if let Some(missing) = TtState::ALL
        .iter()
        .find(|s| !t.states.contains_key(s.name()))
    {
        return Err(MappingError::Bad {
            section: "turntable.states".into(),
            why: format!(
                "state {} has no value: every state needs one",
                missing.name()
            ),
        });
    }
    for n in [&t.sequence, &t.argument, &t.axis].into_iter().flatten() {
        signal(cmd, sec, n)?;
    }
    if let Some(s) = &t.sequence {
        check_counter(sec, cmd, signal(cmd, sec, s)?)?;
    }
    for n in [&t.ack, &t.faults, &t.report_axis].into_iter().flatten() {
        check_counter(sec, rep, signal(rep, sec, n)?)?;
    }
    signal(rep, sec, &t.angle)?;
    if let Some(f) = &t.faults {
        let s = signal(rep, sec, f)?;
        for (name, bit) in &t.fault_bits {
            if !FAULT_NAMES.contains(&name.as_str()) || *bit >= u32::from(s.len) {
                return Err(bad_signal(
                    "turntable.fault_bits",
                    rep,
                    s,
                    format!(
                        "{name} = {bit}: a fault of {} at a bit below {}",
                        FAULT_NAMES.join(", "),
                        s.len
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Every name one `known` accepts, every value one the signal carries, no value twice.
pub(super) fn codes(
    section: &str,
    m: &MessageLayout,
    s: &crate::dbc::SignalLayout,
    values: &BTreeMap<String, i64>,
    known: impl Fn(&str) -> bool,
) -> Result<(), MappingError> {
    let range = s.raw_range();
    let mut seen: BTreeMap<i64, &str> = BTreeMap::new();
    for (name, v) in values {
        if !known(name) {
            return Err(bad_signal(
                section,
                m,
                s,
                format!("{name}: not a name of ours (bench.dbc's value tables)"),
            ));
        }
        if range.is_some_and(|(lo, hi)| *v < lo || *v > hi) {
            return Err(bad_signal(
                section,
                m,
                s,
                format!("{name} = {v}: beyond what the signal carries"),
            ));
        }
        if let Some(other) = seen.insert(*v, name) {
            return Err(bad_signal(
                section,
                m,
                s,
                format!("{name} and {other} both {v}"),
            ));
        }
    }
    Ok(())
}

/// Why the table did not take a command frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandRefused {
    /// The frame does not decode by the lab's DBC.
    #[error(transparent)]
    Decode(#[from] DecodeError),
    /// Its checksum is wrong: the table drops it, as a real one does.
    #[error(transparent)]
    Checksum(ProtectionFault),
}

/// The emulated table's side of a lab's contract: its commands read, its reports written.
#[derive(Debug)]
pub struct TableSide<'a> {
    mapping: &'a Mapping,
    table: &'a TableMapping,
    cmd: &'a MessageLayout,
    rep: &'a MessageLayout,
}

/// An opcode the table does not know: sent on as a command code no table has, to be refused.
const UNKNOWN_COMMAND: u8 = 0xFF;

impl<'a> TableSide<'a> {
    /// The table's side of `mapping` (checked against `contract`); none when it has no
    /// `[turntable]` or a message is missing.
    pub fn new(contract: &'a Contract, mapping: &'a Mapping) -> Option<Self> {
        let table = mapping.file.turntable.as_ref()?;
        Some(Self {
            mapping,
            table,
            cmd: contract.message(&table.command)?,
            rep: contract.message(&table.report)?,
        })
    }

    /// The command message's identifier (what the table listens for).
    pub fn command_id(&self) -> FrameId {
        self.cmd.id
    }

    /// The report message's layout.
    pub fn report_layout(&self) -> &'a MessageLayout {
        self.rep
    }

    /// A command frame in the lab's form as ours: its opcode by the lab's table (an opcode it
    /// lacks becomes a code the table refuses), sequence, axis and argument. A frame whose
    /// checksum is wrong is refused (its alive counter is the judge's to check).
    pub fn command(&self, data: &[u8]) -> Result<TtCmd, CommandRefused> {
        if let Some(f) = super::checksum_fault(self.mapping, self.cmd, data) {
            return Err(CommandRefused::Checksum(f));
        }
        let v = self.cmd.decode(data)?;
        let get = |n: &Option<String>| {
            n.as_deref()
                .and_then(|n| v.iter().find(|(s, _)| *s == n).map(|(_, x)| *x))
        };
        let op = v
            .iter()
            .find(|(s, _)| *s == self.table.opcode)
            .map_or(-1, |(_, x)| *x as i64);
        let command = self
            .table
            .opcodes
            .iter()
            .find(|(_, code)| **code == op)
            .and_then(|(name, _)| TtCommand::ALL.iter().find(|c| c.name() == name))
            .map_or(UNKNOWN_COMMAND, |c| *c as u8);
        Ok(TtCmd {
            seq: get(&self.table.sequence).unwrap_or(0.0) as u8,
            command,
            axis: get(&self.table.axis).unwrap_or(0.0) as u8,
            arg: get(&self.table.argument).unwrap_or(0.0),
        })
    }

    /// The report message's identifier.
    pub fn report_id(&self) -> FrameId {
        self.rep.id
    }

    /// A report frame as the IMU's side reads it: its axis, the axis' angle, deg, and whether
    /// the encoder's fault bit is set.
    pub fn read_report(&self, data: &[u8]) -> Result<(usize, f64, bool), DecodeError> {
        let t = self.table;
        let v = self.rep.decode(data)?;
        let get = |n: &str| v.iter().find(|(x, _)| *x == n).map(|(_, x)| *x);
        let bit = t.fault_bits.get("encoder").copied().unwrap_or(2);
        let faults = t.faults.as_deref().and_then(get).unwrap_or(0.0) as u64;
        let axis = t.report_axis.as_deref().and_then(get).unwrap_or(0.0) as usize;
        Ok((
            axis,
            get(&t.angle).unwrap_or(f64::NAN),
            faults >> bit & 1 == 1,
        ))
    }

    /// Our status report in the lab's form: state by its table, the acknowledged sequence,
    /// the angle, the fault bits; alive counter and checksum by `protector`.
    pub fn report(
        &self,
        st: &TtStatus,
        protector: &mut Protector,
    ) -> Result<MappedFrame, EncodeError> {
        let t = self.table;
        let state = t.states.get(st.state.name()).copied().ok_or_else(|| {
            EncodeError::Unknown(format!("state {} has no value", st.state.name()))
        })?;
        let bits = st
            .faults
            .to_array()
            .iter()
            .zip(FAULT_NAMES)
            .enumerate()
            .filter(|(_, (on, _))| **on)
            .map(|(i, (_, name))| 1u64 << t.fault_bits.get(name).copied().unwrap_or(i as u32))
            .sum::<u64>();
        let mut v: Vec<(&str, f64)> = vec![(&t.state, state as f64), (&t.angle, st.angle_deg)];
        if let Some(a) = &t.ack {
            v.push((a, f64::from(st.ack_seq)));
        }
        if let Some(a) = &t.report_axis {
            v.push((a, f64::from(st.axis)));
        }
        if let Some(f) = &t.faults {
            v.push((f, bits as f64));
        }
        let mut data = self.rep.encode(&v)?;
        protector.protect(self.rep, &mut data)?;
        Ok(MappedFrame {
            id: self.rep.id,
            data,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mapping::Mapping;
    use crate::{TtFaults, TtState};

    fn lab() -> (Contract, Mapping) {
        let c = Contract::parse(include_str!("../../contracts/lab-imu.dbc")).expect("DBC");
        let m = Mapping::parse(include_str!("../../contracts/lab-imu.toml"), &c).expect("mapping");
        (c, m)
    }

    /// A command in the lab's form is ours by its opcode table; an opcode it lacks becomes a
    /// code the table refuses; our status goes out as the lab's report, its state by the lab's
    /// value, its fault bits where the lab puts them, protected.
    #[test]
    fn the_table_speaks_the_labs_commands_and_reports() {
        let (c, m) = lab();
        let side = TableSide::new(&c, &m).expect("its messages");
        let cmd = side.cmd;
        let mut data = cmd
            .encode(&[("Opcode", 5.0), ("Sequence", 42.0), ("TargetAngle", 180.0)])
            .expect("encodes");
        Protector::new(&m)
            .protect(cmd, &mut data)
            .expect("protects");
        let got = side.command(&data).expect("decodes");
        assert_eq!(
            (got.seq, got.command, got.axis),
            (42, TtCommand::IndexAbs as u8, 0)
        );
        assert!((got.arg - 180.0).abs() < 1e-3);
        let mut data = cmd.encode(&[("Opcode", 9.0)]).expect("encodes");
        Protector::new(&m)
            .protect(cmd, &mut data)
            .expect("protects");
        assert_eq!(
            side.command(&data).expect("decodes").command,
            UNKNOWN_COMMAND
        );
        data[3] ^= 1;
        assert!(matches!(
            side.command(&data),
            Err(CommandRefused::Checksum(ProtectionFault::Checksum { .. }))
        ));
        let st = TtStatus {
            angle_deg: 90.0,
            rate_dps: 0.0,
            state: TtState::Locked,
            axis: 0,
            faults: TtFaults {
                encoder: true,
                ..TtFaults::default()
            },
            ack_seq: 42,
            counter: 0,
        };
        let mut p = Protector::new(&m);
        let mut guard = crate::mapping::Guard::default();
        for alive in 0..3 {
            let f = side.report(&st, &mut p).expect("reports");
            assert_eq!(f.id, side.rep.id);
            let v = side.rep.decode(&f.data).expect("decodes");
            let get = |n: &str| v.iter().find(|(x, _)| *x == n).map(|(_, x)| *x);
            assert_eq!(get("State"), Some(6.0));
            assert_eq!(get("AckSequence"), Some(42.0));
            assert_eq!(get("Faults"), Some(4.0));
            assert_eq!(get("AliveCtr"), Some(f64::from(alive)));
            assert!((get("Angle").unwrap_or(0.0) - 90.0).abs() < 1e-3);
            guard.check(&m, side.rep, &f.data);
            let (axis, angle, encoder) = side.read_report(&f.data).expect("reads");
            assert!(axis == 0 && (angle - 90.0).abs() < 1e-3 && encoder);
        }
        assert_eq!((guard.checked, guard.faults.len()), (3, 0));
    }

    /// A turntable section that does not fit is refused, naming what is wrong.
    #[test]
    fn a_table_mapping_that_does_not_fit_is_refused() {
        let (c, _) = lab();
        let text = include_str!("../../contracts/lab-imu.toml");
        let refused = |from: &str, to: &str| {
            let e = Mapping::parse(&text.replacen(from, to, 1), &c)
                .expect_err("refused")
                .to_string();
            assert!(e.contains("turntable"), "{e}");
            e
        };
        let e = refused("IndexAbs = 5", "IndexAbsolute = 5");
        assert!(e.contains("IndexAbsolute: not a name of ours"), "{e}");
        let e = refused("IndexAbs = 5", "IndexAbs = 16");
        assert!(e.contains("IndexAbs = 16: beyond"), "{e}");
        let e = refused("IndexAbs = 5", "IndexAbs = 2");
        assert!(e.contains("both 2"), "{e}");
        let e = refused("Settling = 4\n", "");
        assert!(e.contains("state Settling has no value"), "{e}");
        let e = refused("angle = \"Angle\"", "angle = \"Azimuth\"");
        assert!(e.contains("TABLE_REPORT has no signal Azimuth"), "{e}");
    }
}
