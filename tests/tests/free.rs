//! End-to-end tests of the bench free-running on the host's clock at x1 (`--free`, `hil
//! emulate`), judging a device under test the bench does not pace. Their verdicts need a guest
//! that keeps real time, so `./run-tests` starts them once the host's own stages are done, at
//! normal priority beside the lockstep tests (`vcan.rs`, at nice 19: a loaded guest cannot move
//! their results), the Python device's three tests alone (`tests/guest-e2e.sh`).
//! Like `vcan.rs` they need a kernel with CAN and are ignored by a plain `cargo test`.

use e2e::{bin, checks, hil_json};
use serde_json::Value;
use std::process::Command;

/// The free drill both drill tests run: our nav at the paper's site, 6 s dwells (about 50 s at
/// x1: the time the table stands and turns is what is judged, not the heading's accuracy).
const FREE_DRILL: [&str; 9] = [
    "drill",
    "north-finding",
    "--free",
    "--heading",
    "137.5",
    "--dwell",
    "6",
    "--seed",
    "7",
];

/// A process of the test's, killed (SIGTERM, then SIGKILL after 10 s) if the test ends first.
struct Child(std::process::Child);

impl Child {
    /// SIGTERM, then its exit status (SIGKILL when it has not exited within 30 s).
    fn stop(&mut self) -> Option<i32> {
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(self.0.id() as libc::pid_t, libc::SIGTERM) };
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
        while std::time::Instant::now() < deadline {
            if let Ok(Some(st)) = self.0.try_wait() {
                return st.code();
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        let _ = self.0.kill();
        None
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// A real turntable's stand-in: `hil emulate turntable` in a process of its own on the
/// interface, free-running, that the bench does not control; the bench runs a free drill with
/// `--real turntable=IFACE`: it emulates only the IMU (whose gyros turn as the table's
/// TT_STATUS reports) and the receiver, and our nav drives the real table through its four
/// positions. nav's heading lands within 3 of its sigmas; the table answered every command.
/// Should the host not keep real time, the bench says so and the test does not judge nav.
#[test]
#[ignore = "needs vcan: run ./run-tests"]
fn a_real_turntable_stand_in_turns_the_emulated_imu_in_a_free_drill() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let iface = "vcan-free";
    let mut tt = Command::new(bin("hil"));
    tt.args([
        "emulate",
        "turntable",
        "--iface",
        iface,
        "--duration",
        "400",
        // a guest under load stalls for tenths of a second: the stand-in allows a second
        "--max-late-ms",
        "1000",
    ])
    .arg("--report")
    .arg(d.join("turntable.json"))
    .stdout(std::process::Stdio::null());
    let mut tt = Child(tt.spawn().expect("hil emulate starts"));
    std::thread::sleep(std::time::Duration::from_millis(500));
    let real = format!("turntable={iface}");
    let mut args = FREE_DRILL.to_vec();
    args.extend([
        "--max-late-ms",
        "1000",
        // the budget is not what this run is about (a loaded guest is slow, not nav): as
        // generous as in the free drill's test, where latency is judged
        "--latency-budget-ms",
        "1000",
        "--real",
        &real,
        "--iface",
        iface,
        "--json",
        "--out",
    ]);
    let (r, code) = hil_json(&args, &[&d.join("run")]);
    let tt_exit = tt.stop();
    let t: Value =
        serde_json::from_slice(&std::fs::read(d.join("turntable.json")).unwrap()).unwrap();
    eprintln!("hil emulate turntable: {t}");
    if !t["behind"].is_null() {
        eprintln!(
            "the turntable's stand-in could not keep real time: {}; no verdict on nav",
            t["behind"]
        );
        return;
    }
    if !judged(&r, code) {
        return;
    }
    assert_eq!((code, tt_exit), (0, Some(0)), "{r}");
    assert_eq!(r["real"][0].as_str(), Some("turntable on vcan-free"));
    let bench: Vec<&str> = r["bench"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["device"].as_str().unwrap())
        .collect();
    assert_eq!(bench, ["imu", "gps"]);
    let followed = &r["bench"][0]["followed"][0];
    // the table's status at 100 Hz over the drill's 50 s
    assert!(followed["reports"].as_u64().unwrap() > 3000, "{followed}");
    let h = &r["heading"];
    let (err, sigma) = (
        h["error_deg"].as_f64().unwrap(),
        h["sigma_deg"].as_f64().unwrap(),
    );
    assert!(err.abs() <= 3.0 * sigma && sigma > 0.0, "{h}");
    let t = &t["turntable"];
    let commands = t["commands"].as_u64().unwrap();
    assert!(commands >= 8, "{t}");
    assert_eq!(t["acks"].as_u64(), Some(commands), "{t}");
    assert_eq!(t["bad_frames"].as_u64(), Some(0), "{t}");
}

/// A free-running run's report: false (and why, said) when the host could not keep real time:
/// the bench gave no verdict (exit 3), or the device fell behind on a machine late itself
/// ([`machine_could_not`]); else its checks are shown and true.
fn judged(r: &Value, code: i32) -> bool {
    if code == 3 {
        eprintln!(
            "the host could not keep real time: {}; no verdict on the device",
            r["bench_behind"]
        );
        return false;
    }
    for (name, pass, detail) in checks(r) {
        eprintln!("[{}] {name}: {detail}", if pass { "PASS" } else { "FAIL" });
    }
    eprintln!(
        "the device's latency {:.1} ms (p99); the bench's own lateness {:.1} ms (p99); the host beside it {}",
        r["latency"]["p99_ms"].as_f64().unwrap_or(0.0),
        bench_lateness_p99_ms(r),
        r["host"]
    );
    eprintln!("its clock: {}", r["clock"]);
    for n in r["not_judged"].as_array().into_iter().flatten() {
        eprintln!("[NOT JUDGED] {}", n.as_str().unwrap_or_default());
    }
    if let Some(why) = machine_could_not(r) {
        eprintln!("{why}; no verdict on the device");
        return false;
    }
    // a drill whose device never finished north-finding while the bench's own devices were
    // late (seen beside a loaded host: the real table's stand-in 96 ms late, nav still
    // indexing at the scenario's end)
    let late = bench_lateness_p99_ms(r);
    if r["heading"].is_null() && r["epochs"].as_u64().unwrap_or(0) > 0 && late >= BENCH_LATE_MS {
        eprintln!(
            "the device did not finish north-finding while the bench's own devices were {late:.0} ms late (p99): this machine could not run it at real time; no verdict on the device"
        );
        return false;
    }
    true
}

/// Why a device started on this machine was not judged, if so: its solutions' tail fell
/// behind (p99 past [`MACHINE_LAG_MS`]) while the bench's own devices were [`BENCH_LATE_MS`]
/// or more late (p99): the machine could not run it at real time, so its latency is the
/// machine's. Seen with two CPU hogs, the guest at x0.8-1.1: the Python device's NAV_TIMEs
/// p99 2.8-10 s late with the bench's emulators 60-100 ms late (p99); in an idle guest its p99
/// is 14-24 ms. On a machine that keeps its times, a device that falls behind is judged.
fn machine_could_not(r: &Value) -> Option<String> {
    let lag = r["latency"]["p99_ms"].as_f64().unwrap_or(0.0);
    let late = bench_lateness_p99_ms(r);
    (lag > MACHINE_LAG_MS && late >= BENCH_LATE_MS).then(|| {
        format!(
            "the device's solutions {lag:.0} ms behind its data (p99) while the bench's own devices were {late:.0} ms late (p99): this machine could not run it at real time"
        )
    })
}

/// A device's latency scatter about its clock line (RMS, ms) up to which the drift's sigma is
/// held to 200 ppm: the Python device's in an idle guest is a few ms.
const DRIFT_SCATTER_MS: f64 = 20.0;

/// A device's p99 latency past which, on a machine late itself, it has fallen behind real
/// time, ms (the Python device's honest budget).
const MACHINE_LAG_MS: f64 = 200.0;
/// The bench's own lateness (p99 over its devices) from which the machine, not only the
/// device, misses real time, ms.
const BENCH_LATE_MS: f64 = 50.0;

/// The largest p99 lateness of the bench's own devices in a free-running report, ms.
fn bench_lateness_p99_ms(r: &Value) -> f64 {
    r["bench"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|b| b["lateness"]["p99_ms"].as_f64())
        .fold(0.0, f64::max)
}

/// The machine-lag rule of [`judged`] on the figures of the two red two-hog runs (the guest
/// at x0.8-1.1) and of runs where the bench or the device kept its times.
#[test]
fn a_device_run_late_on_a_late_machine_is_not_judged() {
    let report = |lag: f64, late: f64| {
        serde_json::json!({
            "latency": {"p99_ms": lag},
            "bench": [{"lateness": {"p99_ms": 29.6}}, {"lateness": {"p99_ms": late}}],
        })
    };
    assert!(machine_could_not(&report(10117.7, 100.0)).is_some());
    assert!(machine_could_not(&report(2778.3, 59.8)).is_some());
    assert!(
        machine_could_not(&report(2778.3, 4.0)).is_none(),
        "the bench kept its times"
    );
    assert!(
        machine_could_not(&report(14.5, 100.0)).is_none(),
        "the device kept up"
    );
    assert_eq!(bench_lateness_p99_ms(&report(0.0, 100.0)), 100.0);
}

/// The report's NOT JUDGED entry that starts with `prefix` (a check's name and a colon).
fn not_judged(r: &Value, prefix: &str) -> String {
    r["not_judged"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|n| n.as_str())
        .find(|n| n.starts_with(prefix))
        .unwrap_or_else(|| panic!("no check and nothing not judged for {prefix:?} in {r}"))
        .to_string()
}

/// The latency check of a report: (pass, detail); none when the bench did not judge it
/// because the host could explain the device's latency (said, and checked to be said so).
fn latency_verdict(r: &Value) -> Option<(bool, String)> {
    match checks(r)
        .into_iter()
        .find(|c| c.0 == "latency within the budget")
    {
        Some((_, pass, detail)) => Some((pass, detail)),
        None => {
            let why = not_judged(r, "latency within the budget: ");
            assert!(why.contains("the host could explain it"), "{why}");
            eprintln!("NOT JUDGED: {why}");
            None
        }
    }
}

/// A figure with its uncertainty in a report, `[value, sigma]`.
fn estimate(v: &Value) -> (f64, f64) {
    (
        v["value"]
            .as_f64()
            .unwrap_or_else(|| panic!("no value in {v}")),
        v["sigma"]
            .as_f64()
            .unwrap_or_else(|| panic!("no sigma in {v}")),
    )
}

/// The check named `name` of a report: (pass, detail).
fn check_named(r: &Value, name: &str) -> (bool, String) {
    checks(r)
        .into_iter()
        .find(|c| c.0 == name)
        .map(|c| (c.1, c.2))
        .unwrap_or_else(|| panic!("no check {name:?} in {r}"))
}

/// A free drill of our nav on `iface` with `extra` arguments: the bench's report and exit status.
fn free_drill(iface: &str, out: &std::path::Path, extra: &[&str]) -> (Value, i32) {
    let mut args = FREE_DRILL.to_vec();
    args.extend(["--iface", iface, "--json"]);
    args.extend_from_slice(extra);
    args.push("--out");
    hil_json(&args, &[out])
}

/// `hil drill north-finding --free`: the bench free-running at x1, judging the device under
/// test by what it sends on the bus, by the DBC only. Our nav (the default device) lands within
/// 3 of the sigma it sends (NAV_HGT) at the sample its NAV_TIME names, its latency from that
/// sample on the bus is measured, every frame is within the DBC, its tags go forward. Should
/// the host not keep real time, the bench says so (exit 3) and the test does not judge the
/// device.
#[test]
#[ignore = "needs vcan: run ./run-tests"]
fn a_free_running_drill_judges_the_device_by_the_dbc() {
    let dir = tempfile::tempdir().unwrap();
    // the budget is not what this run is about (a loaded guest is slow, not nav): generous
    let (r, code) = free_drill(
        "vcan-free2",
        &dir.path().join("ours"),
        &["--latency-budget-ms", "1000"],
    );
    if judged(&r, code) {
        assert_eq!(code, 0, "{r}");
        let h = &r["heading"];
        let (err, sigma) = (
            h["error_deg"].as_f64().unwrap(),
            h["sigma_deg"].as_f64().unwrap(),
        );
        assert!(err.abs() <= 3.0 * sigma && sigma > 0.0, "{h}");
        assert!(
            r["latency"]["count"].as_u64().unwrap() > 1000,
            "{}",
            r["latency"]
        );
        let hz = r["rate"]["hz"].as_f64().unwrap();
        assert!((hz - 50.0).abs() < 2.0, "{}", r["rate"]);
        assert_eq!(r["rate"]["step_samples"].as_u64(), Some(40));
        let bench: Vec<&str> = r["bench"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b["device"].as_str().unwrap())
            .collect();
        assert_eq!(bench, ["turntable", "imu", "gps"]);
        assert!(r["commands"].as_u64().unwrap() >= 8);
    }
}

/// `hil run --free`: a drive free-running at x1, our nav scored against truth at the samples
/// its NAV_TIMEs name, and its time tags against its headings through the lap's turns. Should
/// the host not keep real time, the bench says so (exit 3) and the test does not judge the
/// device.
#[test]
#[ignore = "needs vcan: run ./run-tests"]
fn a_free_running_drive_is_scored_against_truth_at_the_samples_nav_names() {
    let dir = tempfile::tempdir().unwrap();
    let (r, code) = hil_json(
        &[
            "run",
            "--scenario",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/drive-gps.toml"),
            "--duration",
            "40",
            "--free",
            "--latency-budget-ms",
            "1000",
            "--iface",
            "vcan-free4",
            "--json",
            "--out",
        ],
        &[&dir.path().join("drive")],
    );
    if judged(&r, code) {
        assert_eq!(code, 0, "{r}");
        let n = &r["navigation"];
        assert!(n["epochs"].as_u64().unwrap() > 1000, "{n}");
        assert!(n["last_m"].as_f64().unwrap() < 25.0, "{n}");
        assert!(check_named(&r, "time tags agree with the data").0);
    }
}

/// Devices that fail get verdicts with figures, never a hang: nothing on the bus (it never
/// answers), and our nav killed after 10 s under a budget it cannot meet (it dies in the
/// middle, it is too late). Should the host not keep real time, the bench says so (exit 3) and
/// the test does not judge the device.
#[test]
#[ignore = "needs vcan: run ./run-tests"]
fn a_free_running_device_that_fails_gets_a_verdict_not_a_hang() {
    let dir = tempfile::tempdir().unwrap();
    let drill = |out: &str, extra: &[&str]| free_drill("vcan-free3", &dir.path().join(out), extra);
    // nothing on the bus: a verdict within the answer time, not a hang
    let (r, code) = drill("silent", &["--dut", "none", "--answer-within", "3"]);
    // (a host that cannot keep real time even for the bench's own devices gives no verdict:
    // seen with two CPU hogs beside the guest)
    if judged(&r, code) {
        assert_eq!(code, 1, "{r}");
        let (pass, detail) = check_named(&r, "the device answered");
        assert!(!pass && detail.contains("no NAV_TIME"), "{detail}");
    }
    // our nav killed after 10 s, under a budget of 50 us
    let (r, code) = drill(
        "dies",
        &[
            "--dut",
            "timeout -s KILL 10 {nav} --config {config}",
            "--latency-budget-ms",
            "0.05",
        ],
    );
    if judged(&r, code) {
        assert_eq!(code, 1, "{r}");
        let (pass, detail) = check_named(&r, "the device ran to the end");
        assert!(
            !pass
                && detail.contains("exited")
                && (detail.contains("137") || detail.contains("signal 9")),
            "{detail}"
        );
        // too late for the budget, unless the host's own delays beside it explain it
        if let Some((pass, detail)) = latency_verdict(&r) {
            assert!(!pass && detail.contains("budget p99 0.05 ms"), "{detail}")
        }
        assert!(check_named(&r, "the device answered").0);
    }
}

/// The Python the guest was given for the independent device under test (`./run-tests` writes
/// its path beside the binaries, shares its prefix and its extension modules' libraries).
fn guest_python() -> Option<std::path::PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let f = exe.parent()?.parent()?.join("e2e-python");
    let p = std::path::PathBuf::from(std::fs::read_to_string(f).ok()?.trim());
    p.is_file().then_some(p)
}

/// A drill of the independent device under test, `tests/dut/northfinder.py` (5 s dwells, the
/// device's and the drill's: about 50 s at x1) with `extra` on its command line, free-running on
/// `iface` under a latency budget of `budget_ms`: the bench's report and exit status, or none
/// (said on stderr) where the guest has no Python.
fn python_drill(iface: &str, extra: &str, budget_ms: f64) -> Option<(Value, i32)> {
    python_drill_on(iface, extra, budget_ms, None).map(|(r, code, _)| (r, code))
}

/// [`python_drill`] on a lab's contract where `mapping` is given (the bench and the device
/// both speak it): also what the device printed.
fn python_drill_on(
    iface: &str,
    extra: &str,
    budget_ms: f64,
    mapping: Option<&std::path::Path>,
) -> Option<(Value, i32, String)> {
    let dwell_s = 5;
    let Some(py) = guest_python() else {
        eprintln!(
            "SKIPPED: no Python for the guest (target/debug/e2e-python, written by ./run-tests)"
        );
        return None;
    };
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let contract = match mapping {
        Some(_) => "{dbc} --mapping {mapping}".to_string(),
        None => here.join("../wire/bench.dbc").display().to_string(),
    };
    let dut = format!(
        "{} {} --iface {{iface}} --dbc {contract} --config {{config}} --dwell {dwell_s} {extra}",
        py.display(),
        here.join("dut/northfinder.py").display(),
    );
    let dir = tempfile::tempdir().unwrap();
    let budget = format!("{budget_ms:.0}");
    let mut lab: Vec<&str> = Vec::new();
    let mapping_arg = mapping.map(|m| m.display().to_string());
    if let Some(m) = &mapping_arg {
        lab.extend(["--mapping", m.as_str()]);
    }
    let (r, code) = hil_json(
        &[
            "drill",
            "north-finding",
            "--free",
            "--heading",
            "251.25",
            "--dwell",
            &dwell_s.to_string(),
            "--seed",
            "5",
            "--iface",
            iface,
            // Python's imports over the guest's shared folder: up to a minute under load
            "--answer-within",
            "120",
            "--latency-budget-ms",
            &budget,
            "--json",
            "--dut",
            &dut,
        ]
        .into_iter()
        .chain(lab)
        .chain(["--out"])
        .collect::<Vec<_>>(),
        &[&dir.path().join("run")],
    );
    let printed =
        std::fs::read_to_string(dir.path().join("run/device/device.out")).unwrap_or_default();
    Some((r, code, printed))
}

/// An independent device under test: `tests/dut/northfinder.py`, a minimal four-position
/// north-finder in Python with python-can and cantools reading our DBC (no code of ours), that
/// commands the table over CAN and sends NAV_TIME, NAV_ATT and NAV_HGT. The bench judges it by
/// the same checks as our nav: it lands within 3 of its own sigmas and within 1 deg (its simple
/// method's honest tolerance), and its time tags agree with its data while the table turns.
/// The same program with 50 ms added to its output fails a latency budget set 25 ms above what
/// it showed honest, naming the figures. (`./run-tests` runs this test alone: the budget comes
/// from its first run, which a neighbour's load would move.)
#[test]
#[ignore = "needs vcan and the guest's Python: run ./run-tests"]
fn an_independent_python_device_is_judged_by_the_same_checks() {
    let Some((r, code)) = python_drill("vcan-py", "", 200.0) else {
        return;
    };
    if !judged(&r, code) {
        return;
    }
    let h = &r["heading"];
    let (err, sigma) = (
        h["error_deg"].as_f64().unwrap(),
        h["sigma_deg"].as_f64().unwrap(),
    );
    assert!(err.abs() <= 3.0 * sigma && err.abs() < 1.0, "{h}");
    let (pass, detail) = check_named(&r, "time tags agree with the data");
    assert!(pass, "{detail}");
    let p99 = r["latency"]["p99_ms"].as_f64().unwrap();
    let p50 = r["latency"]["p50_ms"].as_f64().unwrap();
    // the honest run's own latency tail is the guest's pace as much as the device's (a Python
    // device's p99 234 ms against its 200 in a guest slowed beside other work; 14-24 ms
    // idle): the honest device missing its budget with a tail wider than 50 ms over its median
    // is the machine's, no verdict on the latency; every other check must still pass
    if code == 1
        && p99 - p50 > 50.0
        && let Some((false, detail)) = latency_verdict(&r)
    {
        let failed: Vec<String> = checks(&r)
            .into_iter()
            .filter(|(name, pass, _)| !pass && name != "latency within the budget")
            .map(|(name, _, detail)| format!("{name}: {detail}"))
            .collect();
        assert!(failed.is_empty(), "{failed:?}");
        eprintln!(
            "the honest run missed its latency budget with a tail wider than 50 ms ({detail}): the guest's pace; no verdict on the latency budget"
        );
        return;
    }
    assert_eq!(code, 0, "{r}");
    // the budget half judges 50 ms more on every solution: where the honest run's own tail is
    // wider than that (a slow or loaded host: p50 3.5 ms, p99 170 ms seen in the guest at x1.6),
    // its p99 measures the machine, not the device, and a second run's can land 50 ms lower
    if p99 - p50 > 50.0 {
        eprintln!(
            "the honest run's latency tail is wider than the 50 ms to detect (p50 {p50:.1} ms, p99 {p99:.1} ms); no verdict on the latency budget"
        );
        return;
    }
    // 50 ms more on every solution, against a budget 25 ms above the honest p99
    let budget = (p99 + 25.0).max(30.0);
    let Some((r, code)) = python_drill("vcan-py", "--delay 0.05", budget) else {
        return;
    };
    if judged(&r, code) {
        let Some((pass, detail)) = latency_verdict(&r) else {
            return;
        };
        assert_eq!(code, 1, "{r}");
        assert!(!pass && detail.contains("budget p99"), "{detail}");
        assert!(
            r["latency"]["p50_ms"].as_f64().unwrap() >= 50.0,
            "{}",
            r["latency"]
        );
        assert!(check_named(&r, "time tags agree with the data").0);
    }
}

/// The same independent Python device lying about time: its data 30 ms older than its tags
/// (it names the newest sample, not the one its solution is of) and 20 ms late on top, a stray
/// frame every 5 s, one NAV_TIME 30 s in naming an older sample. The bench's estimate from the
/// data recovers the 30 ms within its stated uncertainty (not the 50 ms of its latency), its
/// tags fail against its data by more than an output period, its clock shows no drift and it
/// names no sample ahead; its checks name the frame outside the DBC and the tag that went back.
#[test]
#[ignore = "needs vcan and the guest's Python: run ./run-tests"]
fn an_independent_python_device_that_lies_about_time_is_caught() {
    let Some((r, code)) = python_drill(
        "vcan-py2",
        "--stale 0.03 --delay 0.02 --stray 5 --backwards",
        1000.0,
    ) else {
        return;
    };
    if judged(&r, code) {
        assert_eq!(code, 1, "{r}");
        let (pass, detail) = check_named(&r, "time tags agree with the data");
        assert!(
            !pass && detail.contains("limit one output period, 20 ms"),
            "{detail}"
        );
        let (tau, sigma) = estimate(&r["data_offset"]["offset_ms"]);
        assert!(
            (tau - 30.0).abs() <= 3.0 * sigma + 2.0 && sigma < 5.0,
            "{tau} ± {sigma} ms: {}",
            r["data_offset"]
        );
        // (its clock's drift is not asserted: a Python device's latency moves with its phase,
        // dwelling or indexing, by more than its line's sigma says: seen 141 ± 30 ppm)
        assert!(
            r["latency"]["p50_ms"].as_f64().unwrap() >= 20.0,
            "{}",
            r["latency"]
        );
        assert!(
            check_named(
                &r,
                "no sample named ahead of the stream beyond the allowance"
            )
            .0
        );
        let (pass, detail) = check_named(&r, "frames within the DBC");
        assert!(
            !pass && detail.contains("0x3FF: not in the DBC"),
            "{detail}"
        );
        let (pass, detail) = check_named(&r, "time tags never go backwards");
        assert!(!pass && detail.starts_with("1 of"), "{detail}");
    }
}

/// The independent Python device on a lab's own contract (`wire/contracts/lab-imu.dbc` and its
/// mapping: 29-bit identifiers, the IMU's rates ten samples to a CAN FD frame, the table by the
/// lab's opcodes and states, a CRC-8 and an alive counter on every frame, its solution in
/// INS_HEADING), with a clock 1000 ppm fast against the IMU's (its own crystal, or a mis-set
/// sample rate; 5 s dwells), a wrong checksum on every 50th frame it sends and an alive counter
/// that skips on every 70th. Every frame it took from the bench's IMU and table (decoded by
/// cantools from the lab's DBC) had its checksum and alive counter right. The bench, reading
/// its solution through the mapping, estimates its drift from its time tags within the
/// uncertainty it states, counts the samples it names before they went on the bus and fails it
/// for leading the stream by more than one output period, with the figures; names its bad
/// checksums and skipped counters by message; still judges its heading where north-finding is
/// over, against the truth at the sample it names (right: the table stands still then).
#[test]
#[ignore = "needs vcan and the guest's Python: run ./run-tests"]
fn an_independent_python_device_on_a_labs_contract_whose_clock_drifts_is_caught() {
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mapping = here.join("../wire/contracts/lab-imu.toml");
    let Some((r, code, printed)) = python_drill_on(
        "vcan-py3",
        "--drift-ppm 1000 --bad-crc 50 --skip-alive 70",
        1000.0,
        Some(&mapping),
    ) else {
        return;
    };
    if !judged(&r, code) {
        return;
    }
    assert_eq!(code, 1, "{r}");
    // what the device took from the bench, checked by its own decoder
    for m in ["IMU_GYRO_BLOCK", "TABLE_REPORT"] {
        let line = printed
            .lines()
            .find(|l| l.contains(&format!(" {m}: ")))
            .unwrap_or_else(|| panic!("the device printed nothing of {m}:\n{printed}"));
        eprintln!("{line}");
        assert!(
            line.ends_with(": 0 bad checksums, 0 alive counter skips"),
            "{line}"
        );
    }
    let (pass, detail) = check_named(&r, "the device's checksums and alive counters hold");
    assert!(
        !pass
            && detail.contains("INS_HEADING 0x18FE3001 (extended): checksum wrong")
            && detail.contains("INS_HEADING 0x18FE3001 (extended): alive counter skipped"),
        "{detail}"
    );
    let (pass, detail) = check_named(&r, "frames within the DBC");
    assert!(pass && detail.contains("lab-imu.dbc"), "{detail}");
    let (drift, sigma) = estimate(&r["clock"]["drift_ppm"]);
    // the drift is told through the device's latency, whose scatter about its line is the
    // guest's pace as much as the device's: a Python device in a guest slowed beside other
    // work scattered by 58 and 329 ms RMS (1210 ± 466, 3094 ± 8516 ppm): no verdict on the
    // drift there; everything else below still judged
    let scatter = r["clock"]["residual_rms_ms"].as_f64().unwrap_or(0.0);
    if scatter <= DRIFT_SCATTER_MS {
        assert!(
            (drift - 1000.0).abs() <= 3.0 * sigma + 30.0 && sigma < 200.0,
            "{drift} ± {sigma} ppm: {}",
            r["clock"]
        );
    } else {
        eprintln!(
            "the device's latency scattered by {scatter:.0} ms RMS about its clock line (the guest's pace beside it): no verdict on its drift ({drift:.0} ± {sigma:.0} ppm)"
        );
    }
    let (pass, detail) = check_named(
        &r,
        "no sample named ahead of the stream beyond the allowance",
    );
    assert!(!pass && detail.contains("allowance 20.0 ms"), "{detail}");
    let lead = &r["lead"];
    assert!(
        lead["epochs"].as_u64().unwrap() > lead["of"].as_u64().unwrap() / 2
            && lead["max_ms"].as_f64().unwrap() > 20.0,
        "{lead}"
    );
    let (pass, detail) = check_named(
        &r,
        "heading at the drill's end within 3 of the device's sigmas",
    );
    assert!(
        pass && detail.contains("the first after north-finding"),
        "{detail}"
    );
}

/// A real receiver's stand-in: a recorded receiver (gpsd's capture of a Telit HE910 in
/// ../shared/testdata/gpsd-nmea: half a minute of searching, then fixes of a receiver standing
/// still) played at its own rate onto a pty by socat, given to the bench with `--real gps=PTY`.
/// The drill's site is the receiver's surveyed position. Our nav finds north on the emulated IMU
/// and table, then navigates from the real receiver's fixes: its heading is scored against
/// truth, its position against the site, and the card says what it could not judge (the
/// receiver's fixes themselves).
#[test]
#[ignore = "needs vcan, socat and ../shared: run ./run-tests"]
fn a_recorded_receiver_on_a_pty_stands_in_for_a_real_one() {
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let log = here.join("../../shared/testdata/gpsd-nmea/telit-he910.log");
    if !log.is_file() {
        eprintln!("SKIPPED: {} is absent", log.display());
        return;
    }
    if Command::new("socat").arg("-V").output().is_err() {
        eprintln!("SKIPPED: no socat here (./run-tests installs it)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("receiver");
    let mut socat = Command::new("socat");
    socat
        .arg(format!("PTY,link={},raw,echo=0", pty.display()))
        .arg(format!(
            "EXEC:sh {} {}",
            here.join("dut/pace-nmea.sh").display(),
            log.display()
        ));
    let _socat = Child(socat.spawn().expect("socat starts"));
    let t0 = std::time::Instant::now();
    while !pty.exists() {
        assert!(t0.elapsed().as_secs() < 30, "socat made no pty");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // the capture's position: 50 50.4126 N, 4 20.8228 E
    let real = format!("gps={}", pty.display());
    let (r, code) = hil_json(
        &[
            "drill",
            "north-finding",
            "--free",
            "--real",
            &real,
            "--lat",
            "50.84021",
            "--lon",
            "4.347047",
            "--heading",
            "33",
            "--dwell",
            "15",
            "--seed",
            "3",
            "--iface",
            "vcan-rx",
            "--latency-budget-ms",
            "1000",
            "--json",
            "--out",
        ],
        &[&dir.path().join("run")],
    );
    if !judged(&r, code) {
        return;
    }
    assert_eq!(code, 0, "{r}");
    assert!(
        r["receiver_bytes"].as_u64().unwrap() > 5000,
        "{}",
        r["receiver_bytes"]
    );
    let bench: Vec<&str> = r["bench"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["device"].as_str().unwrap())
        .collect();
    assert_eq!(bench, ["turntable", "imu"]);
    let (pass, detail) = check_named(
        &r,
        "position at the drill's end within 3 of its sigmas of the site",
    );
    assert!(pass, "{detail}");
    assert!(
        r["not_judged"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n.as_str().unwrap().contains("real receiver's fixes")),
        "{}",
        r["not_judged"]
    );
}
