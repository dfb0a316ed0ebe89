//! A run's bus in the logs the CAN world opens: `hil candump` writes Vector ASC and BLF through
//! python-can's writers; python-can reads each back and finds every frame of the candump log,
//! in order, with its identifier, length, data and time stamp (to the microsecond), and cantools
//! decodes every frame of the ASC with our DBC. The recording is the drill the end-to-end tests
//! ran at x3 (`target/e2e-reports/drill-x3/nav.mcap`), so this runs after them (`./run-tests`).

use e2e::{bin, reports_dir};
use serde_json::Value;
use std::process::Command;

const READ_BACK: &str = r#"
import json, sys
import can, cantools
d = sys.argv[1]
ref = list(can.LogReader(d + "/bus.log"))
out = {"frames": len(ref)}
for f in ("asc", "blf"):
    got = list(can.LogReader(d + "/bus." + f))
    r0, g0 = ref[0].timestamp, got[0].timestamp
    out[f] = {
        "frames": len(got),
        "mismatched": sum(
            1
            for a, b in zip(ref, got)
            if (a.arbitration_id, a.dlc, bytes(a.data)) != (b.arbitration_id, b.dlc, bytes(b.data))
        ),
        "worst_time_error_s": max(
            abs((a.timestamp - r0) - (b.timestamp - g0)) for a, b in zip(ref, got)
        ),
        "error_frames": sum(1 for m in got if m.is_error_frame),
    }
db = cantools.database.load_file(d + "/bench.dbc")
ids = {m.frame_id for m in db.messages}
decoded, failed, foreign = 0, [], 0
for m in can.LogReader(d + "/bus.asc"):
    if m.arbitration_id not in ids:
        foreign += 1
        continue
    try:
        db.decode_message(m.arbitration_id, bytes(m.data))
        decoded += 1
    except Exception as e:
        failed.append("0x%03X: %s" % (m.arbitration_id, e))
out["cantools"] = {"decoded": decoded, "failed": failed[:5], "failures": len(failed), "foreign": foreign}
print(json.dumps(out))
"#;

/// `hil candump INPUT --out OUT`, which must succeed.
fn hil_candump(input: &std::path::Path, out: &std::path::Path) {
    let o = Command::new(bin("hil"))
        .arg("candump")
        .arg(input)
        .arg("--out")
        .arg(out)
        .output()
        .expect("hil runs");
    assert!(
        o.status.success(),
        "hil candump {} --out {}: {}",
        input.display(),
        out.display(),
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
#[ignore = "needs the e2e tests' recordings: run ./run-tests"]
fn a_runs_bus_reads_back_from_vector_asc_and_blf() {
    let mcap = reports_dir().join("drill-x3").join("nav.mcap");
    assert!(mcap.is_file(), "{}: run ./run-tests", mcap.display());
    let dir = tempfile::tempdir().unwrap();
    for name in ["bus.log", "bus.asc", "bus.blf"] {
        hil_candump(&mcap, &dir.path().join(name));
    }
    let dbc = Command::new(bin("hil"))
        .arg("dbc")
        .output()
        .expect("hil runs");
    std::fs::write(dir.path().join("bench.dbc"), &dbc.stdout).unwrap();
    let out = e2e::python(READ_BACK, &[dir.path()], "python-can's read-back");
    let r: Value = serde_json::from_slice(&out).expect("the read-back prints JSON");
    println!("{r}");
    let frames = r["frames"].as_u64().unwrap();
    assert!(frames > 100_000, "the drill's bus: {r}");
    for f in ["asc", "blf"] {
        assert_eq!(
            r[f]["frames"].as_u64(),
            Some(frames),
            "{f}: every frame: {r}"
        );
        assert_eq!(
            r[f]["mismatched"].as_u64(),
            Some(0),
            "{f}: ids and data: {r}"
        );
        assert!(
            r[f]["worst_time_error_s"].as_f64().unwrap() < 1e-6,
            "{f}: time stamps to the microsecond: {r}"
        );
        // the drill had no physical fault: no error frame may appear from nowhere
        assert_eq!(r[f]["error_frames"].as_u64(), Some(0), "{f}: {r}");
    }
    let c = &r["cantools"];
    assert_eq!(c["failures"].as_u64(), Some(0), "cantools: {r}");
    assert_eq!(
        c["foreign"].as_u64(),
        Some(0),
        "only the contract's frames: {r}"
    );
    assert_eq!(
        c["decoded"].as_u64(),
        Some(frames),
        "cantools decodes them all: {r}"
    );
}

const READ_BACK_ERRORS: &str = r##"
import json, sys
import can
d = sys.argv[1]
# the candump log itself, read here line by line: time, id, data, error frame or not
ref = []
for line in open(d + "/bus.log"):
    t, _, frame = line.split()
    cid, data = frame.split("#")
    cid = int(cid, 16)
    ref.append((float(t[1:-1]), bool(cid & 0x20000000), cid & 0x1FFFFFFF, bytes.fromhex(data)))
out = {"frames": len(ref), "error_frames": sum(1 for r in ref if r[1]), "last_s": ref[-1][0]}
for f in ("asc", "blf"):
    got = list(can.LogReader(d + "/bus." + f))
    g0 = got[0].timestamp
    out[f] = {
        "frames": len(got),
        "error_frames": sum(1 for m in got if m.is_error_frame),
        "errors_in_place": sum(1 for a, b in zip(ref, got) if a[1] == b.is_error_frame),
        "mismatched": sum(
            1
            for a, b in zip(ref, got)
            if not a[1] and (a[2], a[3]) != (b.arbitration_id, bytes(b.data))
        ),
        "worst_time_error_s": max(abs((a[0] - ref[0][0]) - (b.timestamp - g0)) for a, b in zip(ref, got)),
    }
print(json.dumps(out))
"##;

/// The bus model's own log (`bus.log`, `[bus] log = true`) of the fault matrix's
/// `can-error-frames` row: every frame on the modelled bus (nav's too) and the 200 error frames
/// of nav's controller, stamped with simulated time. As Vector ASC and BLF through python-can,
/// every frame and every error frame comes back in place, with its simulated time stamp.
#[test]
#[ignore = "needs the e2e tests' recordings: run ./run-tests"]
fn the_bus_models_log_reads_back_with_its_error_frames_on_the_simulated_clock() {
    let log = reports_dir().join("fault-can-error-frames").join("bus.log");
    assert!(log.is_file(), "{}: run ./run-tests", log.display());
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(&log, dir.path().join("bus.log")).unwrap();
    for name in ["bus.asc", "bus.blf"] {
        hil_candump(&dir.path().join("bus.log"), &dir.path().join(name));
    }
    let out = e2e::python(READ_BACK_ERRORS, &[dir.path()], "python-can's read-back");
    let r: Value = serde_json::from_slice(&out).expect("the read-back prints JSON");
    println!("{r}");
    let frames = r["frames"].as_u64().unwrap();
    // the row's 6 s of a 2 kHz IMU: more than 24,000 frames; its 200 bus errors
    assert!(frames > 24_000, "{r}");
    assert_eq!(r["error_frames"].as_u64(), Some(200), "{r}");
    // simulated time: the log ends at the run's 6 s, whatever the wall clock said
    let last = r["last_s"].as_f64().unwrap();
    assert!((5.0..=6.1).contains(&last), "{r}");
    for f in ["asc", "blf"] {
        assert_eq!(r[f]["frames"].as_u64(), Some(frames), "{f}: {r}");
        assert_eq!(r[f]["error_frames"].as_u64(), Some(200), "{f}: {r}");
        assert_eq!(r[f]["errors_in_place"].as_u64(), Some(frames), "{f}: {r}");
        assert_eq!(r[f]["mismatched"].as_u64(), Some(0), "{f}: {r}");
        assert!(
            r[f]["worst_time_error_s"].as_f64().unwrap() < 1e-6,
            "{f}: {r}"
        );
    }
}

/// The lab's contract as the emulated IMU and table put it on vcan
/// (`the_imu_and_table_speak_a_labs_own_contract_on_vcan`, its candump capture in
/// `target/e2e-reports/lab-contract/`): python-can reads every line of it, the IMU's blocks as
/// extended CAN FD frames with the bit-rate switch, cantools decodes each with the lab's DBC,
/// every CRC-8/SAE-J1850 of the bench's frames right and every alive counter one up on its
/// message's last, the sample counter ten up a frame (wrapping at 12 bits); the table disabled
/// (the lab's 0) until it took the Enable of sequence 7, then idle (the lab's 1) with 7 in
/// AckSequence until a second without a heartbeat faults it (the lab's 14, its heartbeat bit);
/// the Enable of sequence 9, its CRC wrong, never acknowledged.
#[test]
#[ignore = "reads the end-to-end tests' capture: run ./run-tests"]
fn cantools_decodes_the_lab_contract_the_emulated_imu_and_table_sent_on_vcan() {
    let log = reports_dir().join("lab-contract/candump.log");
    if !log.is_file() {
        panic!(
            "{} is missing: the end-to-end tests run first (./run-tests)",
            log.display()
        );
    }
    let dbc =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../wire/contracts/lab-imu.dbc");
    let out = e2e::python(
        &format!("{}{LAB_READ_BACK}", e2e::PY_CRC8_SAE_J1850),
        &[log.as_os_str(), dbc.as_os_str()],
        "python-can and cantools on the lab's capture",
    );
    let r: Value = serde_json::from_slice(&out).expect("the read-back's JSON");
    let frames = r["frames"].as_u64().unwrap();
    assert_eq!(r["fd_brs_extended"], 400, "{r}");
    assert_eq!(r["decoded"], frames, "{r}");
    // the table's reports: disabled, then idle acknowledging 7 once it took it; 9 never
    assert!(r["reports"].as_u64().unwrap() >= 200, "{r}");
    assert_eq!(r["commands"], 2, "{r}");
    assert_eq!(r["commands_bad_crc"], 1, "{r}");
    assert!(r["disabled_before"].as_u64().unwrap() > 0, "{r}");
    assert!(r["idle_acking_7"].as_u64().unwrap() > 0, "{r}");
    assert_eq!(r["acking_9"], 0, "{r}");
    assert_eq!(r["after_enable_not_idle"], 0, "{r}");
    // the unit's status: its temperature, healthy, and the PPS latched every second
    assert_eq!(r["status"], 20, "{r}");
    assert_eq!(r["status_ok"], 20, "{r}");
    assert!(r["pps_valid"].as_u64().unwrap() >= 1, "{r}");
    assert_eq!(r["bad_crc"], 0, "{r}");
    assert_eq!(r["bad_alive"], 0, "{r}");
    assert_eq!(r["bad_counter"], 0, "{r}");
}

const LAB_READ_BACK: &str = r#"
import json, sys
import can, cantools
db = cantools.database.load_file(sys.argv[2], database_format="dbc")
out = {"frames": 0, "fd_brs_extended": 0, "decoded": 0, "bad_crc": 0, "bad_alive": 0, "bad_counter": 0,
       "status": 0, "status_ok": 0, "pps_valid": 0, "reports": 0, "commands": 0,
       "commands_bad_crc": 0, "disabled_before": 0, "idle_acking_7": 0, "acking_9": 0,
       "after_enable_not_idle": 0}
alive, counter = {}, {}
enabled = False
for m in can.LogReader(sys.argv[1]):
    out["frames"] += 1
    out["fd_brs_extended"] += int(m.is_fd and m.bitrate_switch and m.is_extended_id)
    msg = db.get_message_by_frame_id(m.arbitration_id)
    data = bytes(m.data)
    s = msg.decode(data, decode_choices=False, scaling=False)
    out["decoded"] += 1
    crc_ok = s["Crc8"] == crc8_sae_j1850(data[1:])
    if msg.name == "TABLE_CMD":
        # the test's own commands, one spoiled on purpose
        out["commands"] += 1
        out["commands_bad_crc"] += int(not crc_ok)
        continue
    out["bad_crc"] += int(not crc_ok)
    if msg.name == "TABLE_REPORT":
        out["reports"] += 1
        out["acking_9"] += int(s["AckSequence"] == 9)
        if s["AckSequence"] == 7:
            enabled = True
            out["idle_acking_7"] += int(s["State"] == 1)
        elif not enabled:
            out["disabled_before"] += int(s["State"] == 0)
        # idle, until a second without a heartbeat faults it (the lab's 14, Faults bit 3)
        idle_or_timed_out = s["State"] == 1 or (s["State"] == 14 and s["Faults"] & 8)
        out["after_enable_not_idle"] += int(enabled and not idle_or_timed_out)
    elif msg.name == "IMU_STATUS":
        t = msg.decode(data, decode_choices=False)
        out["status"] += 1
        out["status_ok"] += int(abs(t["Temperature"] - 45.0) < 30 and t["BitWord"] == 0)
        out["pps_valid"] += int(t["PpsValid"] == 1)
    elif msg.name in counter:
        out["bad_counter"] += int(s["SampleCtr"] != (counter[msg.name] + 10) % 4096)
    if msg.name in alive:
        out["bad_alive"] += int(s["AliveCtr"] != (alive[msg.name] + 1) % 16)
    alive[msg.name] = s["AliveCtr"]
    if "SampleCtr" in s:
        counter[msg.name] = s["SampleCtr"]
print(json.dumps(out))
"#;
