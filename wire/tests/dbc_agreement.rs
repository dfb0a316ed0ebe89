//! Parses `bench.dbc` and checks that every codec layout agrees with it.

use can_dbc::{AttributeValue, ByteOrder, Dbc, MessageId, ValueType};
use wire::{ALL_MESSAGES, DBC};

fn attr(dbc: &Dbc, name: &str, id: u16) -> Option<f64> {
    dbc.attribute_values_message
        .iter()
        .find(|a| a.name == name && a.message_id == MessageId::Standard(id))
        .map(|a| match &a.value {
            AttributeValue::Uint(v) => *v as f64,
            AttributeValue::Int(v) => *v as f64,
            AttributeValue::Double(v) => *v,
            AttributeValue::String(s) => panic!("attribute {name} of 0x{id:X} is a string: {s}"),
        })
}

#[test]
fn every_codec_layout_agrees_with_the_dbc() {
    let dbc = Dbc::try_from(DBC).expect("bench.dbc parses");
    assert_eq!(
        dbc.messages.len(),
        ALL_MESSAGES.len(),
        "same number of messages in DBC and codec"
    );
    for spec in ALL_MESSAGES {
        let m = dbc
            .messages
            .iter()
            .find(|m| m.id == MessageId::Standard(spec.id))
            .unwrap_or_else(|| panic!("{} 0x{:03X} missing from DBC", spec.name, spec.id));
        assert_eq!(m.name, spec.name, "name of 0x{:03X}", spec.id);
        assert_eq!(m.size, u64::from(spec.dlc), "DLC of {}", spec.name);
        assert_eq!(
            format!("{:?}", m.transmitter),
            format!("NodeName({:?})", spec.sender),
            "sender of {}",
            spec.name
        );
        assert_eq!(
            m.signals.len(),
            spec.signals.len(),
            "signal count of {}",
            spec.name
        );
        for s in spec.signals {
            let d = m
                .signals
                .iter()
                .find(|d| d.name == s.name)
                .unwrap_or_else(|| panic!("{}.{} missing from DBC", spec.name, s.name));
            let what = format!("{}.{}", spec.name, s.name);
            assert_eq!(d.start_bit, u64::from(s.start), "start bit of {what}");
            assert_eq!(d.size, u64::from(s.len), "length of {what}");
            assert_eq!(
                d.byte_order,
                ByteOrder::LittleEndian,
                "byte order of {what}"
            );
            let signed = d.value_type == ValueType::Signed;
            assert_eq!(signed, s.signed, "signedness of {what}");
            assert!(
                (d.factor - s.factor).abs() <= 1e-12 * s.factor.abs(),
                "factor of {what}"
            );
            assert_eq!(d.offset, s.offset, "offset of {what}");
            // the DBC range must be encodable
            let lo = s.raw_min() as f64 * s.factor + s.offset;
            let hi = s.raw_max() as f64 * s.factor + s.offset;
            assert!(
                d.min >= lo - 1e-9 && d.max <= hi + 1e-9,
                "range of {what} [{}, {}] not in [{lo}, {hi}]",
                d.min,
                d.max
            );
        }
        // no two signals overlap, all inside the frame
        let mut used = 0u64;
        for s in spec.signals {
            assert!(
                u32::from(s.start) + u32::from(s.len) <= 8 * u32::from(spec.dlc),
                "{}.{} outside the frame",
                spec.name,
                s.name
            );
            let mask = ((1u128 << s.len) - 1) as u64;
            assert_eq!(
                used & (mask << s.start),
                0,
                "{}.{} overlaps another signal",
                spec.name,
                s.name
            );
            used |= mask << s.start;
        }
        // the codec's rate budget equals the DBC attributes
        let fps = match (
            attr(&dbc, "CycleTimeUs", spec.id),
            attr(&dbc, "BudgetFramesPerSecond", spec.id),
        ) {
            (Some(us), _) if us > 0.0 => {
                1e6 / us * attr(&dbc, "FramesPerCycle", spec.id).unwrap_or(1.0)
            }
            (_, Some(b)) => b,
            _ => panic!(
                "{} has neither a cycle time nor a frame budget in the DBC",
                spec.name
            ),
        };
        assert!(
            (fps - spec.frames_per_second).abs() < 1e-9,
            "{}: DBC rate {fps}/s, codec {}/s",
            spec.name,
            spec.frames_per_second
        );
    }
}

#[test]
fn dbc_value_tables_match_the_codec_enums() {
    let dbc = Dbc::try_from(DBC).expect("bench.dbc parses");
    let names = |id: u16, sig: &str| -> Vec<(i64, String)> {
        let v = dbc
            .value_descriptions_for_signal(MessageId::Standard(id), sig)
            .unwrap_or_else(|| panic!("no VAL_ for 0x{id:X} {sig}"));
        v.iter().map(|d| (d.id, d.description.clone())).collect()
    };
    let check = |got: Vec<(i64, String)>, want: Vec<(i64, &str)>| {
        let want: Vec<(i64, String)> = want.into_iter().map(|(i, s)| (i, s.to_string())).collect();
        assert_eq!(got, want);
    };
    check(
        names(0x100, "Command"),
        wire::TtCommand::ALL
            .iter()
            .map(|c| (*c as i64, c.name()))
            .collect(),
    );
    check(
        names(0x101, "Result"),
        wire::TtResult::ALL
            .iter()
            .map(|c| (*c as i64, c.name()))
            .collect(),
    );
    check(
        names(0x102, "State"),
        wire::TtState::ALL
            .iter()
            .map(|c| (*c as i64, c.name()))
            .collect(),
    );
    check(
        names(0x200, "Mode"),
        wire::NavMode::ALL
            .iter()
            .map(|c| (*c as i64, c.name()))
            .collect(),
    );
}
