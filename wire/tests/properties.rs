//! Property tests of the codec over every field's whole range: every message's signals hold any
//! raw value of their range without touching each other, and a frame built from such values
//! decodes to a message that encodes back to the very same bytes.

use proptest::prelude::*;
use wire::*;

/// A message spec and one raw value per signal, each anywhere in the signal's range.
fn spec_and_raws() -> impl Strategy<Value = (&'static MessageSpec, Vec<i64>)> {
    (0..ALL_MESSAGES.len()).prop_flat_map(|i| {
        let spec = ALL_MESSAGES[i];
        let raws: Vec<_> = spec
            .signals
            .iter()
            .map(|s| s.raw_min()..=s.raw_max())
            .collect();
        (Just(spec), raws)
    })
}

fn frame_of(spec: &MessageSpec, raws: &[i64]) -> RawFrame {
    let mut data = [0u8; 8];
    for (s, r) in spec.signals.iter().zip(raws) {
        s.put(&mut data, *r).expect("in range");
    }
    RawFrame {
        id: spec.id,
        len: spec.dlc,
        data,
    }
}

/// The same, as a sender following the DBC's comments builds it: a field the DBC declares
/// meaningless in some frames is sent as 0 there ("PpsOffset ... valid when PpsLatched"; a
/// decoder cannot give back what carries no meaning).
fn sent_frame(spec: &MessageSpec, raws: &[i64]) -> RawFrame {
    let mut f = frame_of(spec, raws);
    if spec.id == imu_accel::SPEC.id && !imu_accel::PPS_LATCHED.flag(&f.data) {
        imu_accel::PPS_OFFSET.put_wrapping(&mut f.data, 0);
    }
    f
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]

    /// Every signal reads back what was put, whatever the others hold.
    #[test]
    fn signals_hold_every_value_of_their_range_independently((spec, raws) in spec_and_raws()) {
        let f = frame_of(spec, &raws);
        for (s, r) in spec.signals.iter().zip(&raws) {
            prop_assert_eq!(s.get(&f.data), *r, "{}.{}", spec.name, s.name);
        }
    }

    /// decode then encode gives the frame back, byte for byte, wherever decode accepts it; where
    /// it refuses, it says why (a value the message does not define) and does not panic.
    #[test]
    fn decode_then_encode_is_the_identity((spec, raws) in spec_and_raws()) {
        let f = sent_frame(spec, &raws);
        match Message::decode(&f) {
            Ok(m) => {
                let back = m.encode().expect("a decoded message encodes");
                prop_assert_eq!(back, f, "{}", spec.name);
            }
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }

    /// Any bytes under any id: decode answers (a message or an error), never panics.
    #[test]
    fn any_frame_decodes_or_is_refused(id in 0u16..0x800, len in 0u8..=8, data in any::<[u8; 8]>()) {
        let f = RawFrame { id, len, data };
        if let Ok(m) = Message::decode(&f) {
            prop_assert_eq!(m.spec().id, id);
        }
    }
}
