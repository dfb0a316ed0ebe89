//! One codec, two speeds: `bench.dbc` read by the generic codec (`wire::dbc`, any lab's DBC)
//! puts every signal of every message where the hand-written layouts put it, to the byte, and
//! reads back what they read, for any raw values the signals can carry.

use proptest::prelude::*;
use wire::dbc::{Contract, FrameId};
use wire::{ALL_MESSAGES, DBC};

fn contract() -> Contract {
    Contract::parse(DBC).expect("bench.dbc is a contract")
}

#[test]
fn every_message_of_ours_is_in_the_generic_contract_as_we_lay_it_out() {
    let c = contract();
    assert_eq!(c.messages.len(), ALL_MESSAGES.len());
    for spec in ALL_MESSAGES {
        let m = c
            .by_id(FrameId::Standard(spec.id))
            .unwrap_or_else(|| panic!("{} missing", spec.name));
        assert_eq!(
            (m.name.as_str(), m.size, m.sender.as_str()),
            (spec.name, usize::from(spec.dlc), spec.sender)
        );
        assert_eq!(m.signals.len(), spec.signals.len(), "{}", spec.name);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Random raw values, each within its signal's range, through both codecs.
    #[test]
    fn both_codecs_give_the_same_bytes_and_values(seed in any::<u64>()) {
        let c = contract();
        let mut x = seed | 1;
        let mut next = || {
            // xorshift: a stream of raw values from the case's seed
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for spec in ALL_MESSAGES {
            let m = c.by_id(FrameId::Standard(spec.id)).expect("message");
            let mut ours = [0u8; 8];
            let mut generic = vec![0u8; m.size];
            for s in spec.signals {
                let span = (s.raw_max() - s.raw_min()) as u64 + 1;
                let raw = s.raw_min() + (next() % span) as i64;
                s.put(&mut ours, raw).expect("in range");
                let g = m.signal(s.name).expect("signal");
                g.put_raw(&m.name, &mut generic, raw).expect("in range");
                prop_assert_eq!(g.raw(&generic), raw, "{} {}", spec.name, s.name);
                prop_assert_eq!(g.phys(&generic), s.phys(&ours), "{} {}", spec.name, s.name);
            }
            prop_assert_eq!(&ours[..m.size], &generic[..], "{}", spec.name);
        }
    }
}
