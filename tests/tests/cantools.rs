//! The field's DBC tool against our wire contract: `cantools` (Python) reads a `candump -l` log
//! written by our formatter, decodes every frame with `bench.dbc`, and every signal agrees with
//! our codec. `./run-tests` installs cantools (pip) before the tests run.

use std::process::Command;

/// Decodes each line of a candump log with cantools and prints one JSON object per frame.
const DECODE: &str = r#"
import json, sys
import cantools
from cantools import logreader
db = cantools.database.load_file(sys.argv[1], database_format="dbc")
with open(sys.argv[2]) as f:
    for fr in logreader.Parser(f):
        m = db.get_message_by_frame_id(fr.frame_id)
        s = m.decode(bytes(fr.data), decode_choices=False, scaling=True)
        print(json.dumps({"id": fr.frame_id, "signals": {k: float(v) for k, v in s.items()}}))
"#;

/// A deterministic byte stream (xorshift).
fn bytes(n: usize, mut x: u64) -> Vec<u8> {
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

#[test]
fn cantools_decodes_our_candump_logs_with_our_dbc_and_agrees_with_our_codec() {
    let have = Command::new("python3")
        .args(["-c", "import cantools"])
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        have,
        "cantools is missing: ./run-tests installs it (python3 -m pip install cantools)"
    );
    let dir = tempfile::tempdir().unwrap();
    let dbc = dir.path().join("bench.dbc");
    std::fs::write(&dbc, wire::DBC).unwrap();
    // every message of the contract, 40 times, with random payloads: every bit of every field
    let mut frames = Vec::new();
    let mut log = String::new();
    for (i, spec) in wire::ALL_MESSAGES.iter().enumerate() {
        for k in 0..40u64 {
            let b = bytes(8, 0x9E37_79B9_7F4A_7C15 ^ ((i as u64) << 32 | k) | 1);
            let mut data = [0u8; 8];
            data[..usize::from(spec.dlc)].copy_from_slice(&b[..usize::from(spec.dlc)]);
            let f = wire::RawFrame {
                id: spec.id,
                len: spec.dlc,
                data,
            };
            log += &wire::candump::format_line(1_795_435_864_000_000 + k * 500, "can0", &f);
            log.push('\n');
            frames.push((spec, f));
        }
    }
    let log_path = dir.path().join("bus.log");
    std::fs::write(&log_path, &log).unwrap();
    let out = e2e::python(DECODE, &[dbc.as_os_str(), log_path.as_os_str()], "cantools");
    let decoded: Vec<serde_json::Value> = String::from_utf8(out)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(decoded.len(), frames.len(), "cantools read every line");
    let mut compared = 0;
    for ((spec, f), d) in frames.iter().zip(&decoded) {
        assert_eq!(d["id"].as_u64(), Some(u64::from(spec.id)));
        for s in spec.signals {
            let theirs = d["signals"][s.name]
                .as_f64()
                .unwrap_or_else(|| panic!("cantools has no {}.{}: {d}", spec.name, s.name));
            let ours = s.phys(&f.data);
            assert!(
                (theirs - ours).abs() <= 1e-9 * ours.abs().max(1.0),
                "{}.{} of {:02X?}: cantools {theirs}, ours {ours}",
                spec.name,
                s.name,
                f.payload()
            );
            compared += 1;
        }
    }
    eprintln!("{compared} signal values of {} frames agree", frames.len());
}
