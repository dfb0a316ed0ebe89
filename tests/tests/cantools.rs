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

/// Checks the lab contract's frames with cantools: each decoded by `lab-imu.dbc`, its CRC-8/
/// SAE-J1850 over bytes 1 to 63 recomputed (the catalogue's parameters, written here again in
/// Python) and its alive counter one up per message; prints one JSON object per frame.
const CHECK_LAB: &str = r#"
import json, sys
import cantools
db = cantools.database.load_file(sys.argv[1], database_format="dbc")
last = {}
for line in open(sys.argv[2]):
    fid, hexdata = line.split()
    fid, data = int(fid, 16), bytes.fromhex(hexdata)
    m = db.get_message_by_frame_id(fid)
    s = m.decode(data, decode_choices=False, scaling=True)
    alive_ok = m.name not in last or s["AliveCtr"] == (last[m.name] + 1) % 16
    last[m.name] = s["AliveCtr"]
    print(json.dumps({"name": m.name, "fd": m.is_fd, "extended": m.is_extended_frame,
                      "crc_ok": s["Crc8"] == crc8_sae_j1850(data[1:64]), "alive_ok": alive_ok,
                      "signals": {k: float(v) for k, v in s.items()}}))
"#;

/// The second contract of issue 64 (`wire/contracts/lab-imu.dbc`: 29-bit identifiers, Motorola
/// signals, scaled rates, ten samples to a CAN FD frame, a CRC byte and an alive counter on
/// every frame): the frames the bench's framer builds from the lab's mapping are decoded by
/// cantools to the values put in, as extended CAN FD frames, with their checksums right and
/// their alive counters one up a frame.
#[test]
fn cantools_reads_the_lab_contracts_frames_with_their_checksums_right() {
    let dir = tempfile::tempdir().unwrap();
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../wire/contracts");
    let dbc = std::fs::read_to_string(here.join("lab-imu.dbc")).unwrap();
    let contract = wire::dbc::Contract::parse(&dbc).unwrap();
    let toml = std::fs::read_to_string(here.join("lab-imu.toml")).unwrap();
    let mapping = wire::mapping::Mapping::parse(&toml, &contract).unwrap();
    let mut framer = wire::mapping::Framer::new(&contract, &mapping);
    let mut lines = String::new();
    let (mut n, mut status) = (0, 0);
    for k in 0..200u64 {
        let x = (k as f64 * 0.37).sin();
        for f in framer
            .push(wire::mapping::MappedSample {
                counter: 4000 + k,
                gyro: [120.0 * x, -0.01 * k as f64, 299.99],
                accel: [9.0 * x, 0.0, -9.80665],
                temperature_c: 41.5,
                ..Default::default()
            })
            .unwrap()
        {
            let wire::dbc::FrameId::Extended(id) = f.id else {
                panic!("{:?}: not extended", f.id)
            };
            // the unit's status frame, one per 100 samples (read back from the bus by the
            // end-to-end capture's test, tests/tests/can_logs.rs)
            if f.data.len() == 8 {
                status += 1;
                continue;
            }
            let hex: String = f.data.iter().map(|b| format!("{b:02X}")).collect();
            lines += &format!("{id:08X} {hex}\n");
            n += 1;
        }
    }
    assert_eq!(n, 40, "ten samples to a frame, two blocks");
    assert_eq!(status, 2, "a status frame per 100 samples");
    std::fs::write(dir.path().join("lab-imu.dbc"), &dbc).unwrap();
    std::fs::write(dir.path().join("frames.txt"), &lines).unwrap();
    let o = Command::new("python3")
        .args(["-c", &format!("{}{CHECK_LAB}", e2e::PY_CRC8_SAE_J1850)])
        .arg(dir.path().join("lab-imu.dbc"))
        .arg(dir.path().join("frames.txt"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: Vec<serde_json::Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rows.len(), 40);
    for (i, r) in rows.iter().enumerate() {
        assert!(r["fd"] == true && r["extended"] == true, "{r}");
        assert!(
            r["crc_ok"] == true && r["alive_ok"] == true,
            "frame {i}: {r}"
        );
        let s = &r["signals"];
        // the block's first sample: its counter (wrapping at 12 bits) and values
        let k = (i / 2 * 10) as u64;
        assert_eq!(
            s["SampleCtr"].as_f64(),
            Some(((4000 + k) % 4096) as f64),
            "{r}"
        );
        let x = (k as f64 * 0.37).sin();
        if r["name"] == "IMU_GYRO_BLOCK" {
            assert!(
                (s["GyroX_0"].as_f64().unwrap() - 120.0 * x).abs() <= 0.005,
                "{r}"
            );
            assert_eq!(s["GyroZ_9"].as_f64(), Some(299.99), "{r}");
        } else {
            assert!(
                (s["AccelX_0"].as_f64().unwrap() - 9.0 * x).abs() <= 0.001,
                "{r}"
            );
            assert!(
                (s["AccelZ_9"].as_f64().unwrap() + 9.80665).abs() <= 0.001,
                "{r}"
            );
        }
    }
}

/// `hil busload --mapping` on the lab's contract: every mapped message with its rate, its
/// share of the bus and its worst-case response time (extended identifiers, CAN FD where the
/// DBC's frame is longer than 8 bytes), the total, exit 0; a mapping whose traffic names a
/// message its DBC lacks is refused, naming it.
#[test]
fn hil_busload_analyses_the_lab_contracts_bus() {
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../wire/contracts");
    let o = Command::new(e2e::bin("hil"))
        .args(["busload", "--mapping"])
        .arg(here.join("lab-imu.toml"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for row in [
        "IMU_GYRO_BLOCK   0x18FF1021    64  yes       100",
        "TABLE_REPORT     0x18EF1020     8   no       100",
        "TABLE_CMD        0x18EF2010     8   no        10",
    ] {
        assert!(text.contains(row), "no row {row:?} in\n{text}");
    }
    // the highest priority waits for one 64-byte FD frame at most, then is sent: 452 + 320 us
    assert!(text.contains("3.20      0.0        0.772"), "{text}");
    assert!(text.contains("total: 14.7 % of the bus"), "{text}");
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(here.join("lab-imu.dbc"), dir.path().join("lab-imu.dbc")).unwrap();
    let toml = std::fs::read_to_string(here.join("lab-imu.toml")).unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, toml.replace("\"INS_POSITION\"", "\"INS_SPEED\"")).unwrap();
    let o = Command::new(e2e::bin("hil"))
        .args(["busload", "--mapping"])
        .arg(&bad)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("INS_SPEED is not in the DBC"),
        "{err}"
    );
}
