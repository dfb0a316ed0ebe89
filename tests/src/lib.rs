//! Helpers for the end-to-end tests: locating the workspace binaries and reading MCAP files.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A binary of the workspace, from the same target folder as the running test.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> -> target/<profile>/<name>
    let dir = exe.parent().and_then(Path::parent).expect("target folder");
    let p = dir.join(name);
    assert!(
        p.is_file(),
        "{} is missing: build the workspace binaries first (cargo build --workspace)",
        p.display()
    );
    p
}

/// Messages per topic in a recording (every part of it: `nav::record::writer::parts`), reading until
/// the end or the first error.
pub fn mcap_topic_counts(path: &Path) -> anyhow::Result<BTreeMap<String, u64>> {
    let mut counts = BTreeMap::new();
    for part in nav::record::writer::parts(path) {
        let buf = std::fs::read(&part)?;
        for m in mcap::MessageStream::new(&buf)? {
            let m = m?;
            *counts.entry(m.channel.topic.clone()).or_insert(0) += 1;
        }
    }
    if counts.is_empty() && !path.is_file() {
        anyhow::bail!("{}: no such recording", path.display());
    }
    Ok(counts)
}

/// Where the end-to-end tests leave the HTML reports of their runs (`target/e2e-reports/`,
/// beside the profile folders): `./run-tests` then opens each in a headless browser on the
/// host (`tests/tests/browser.rs`).
pub fn reports_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> -> target/e2e-reports
    exe.ancestors()
        .nth(3)
        .expect("target folder")
        .join("e2e-reports")
}

/// Keep the HTML report of the run in `run_dir` as `reports_dir()/name/report.html`.
pub fn keep_report(run_dir: &Path, name: &str) {
    keep_file(run_dir, name, "report.html");
}

/// Keep `file` of the run in `run_dir` as `reports_dir()/name/file`.
pub fn keep_file(run_dir: &Path, name: &str, file: &str) {
    let to = reports_dir().join(name);
    std::fs::create_dir_all(&to).expect("creating the reports folder");
    std::fs::copy(run_dir.join(file), to.join(file))
        .unwrap_or_else(|e| panic!("{}: no {file}: {e}", run_dir.display()));
}

/// Run the Python program `script` with `args` (a tool of the field: cantools, python-can,
/// mcap), returning what it printed; a failure panics with `what` and Python's error.
pub fn python<S: AsRef<std::ffi::OsStr>>(script: &str, args: &[S], what: &str) -> Vec<u8> {
    let o = std::process::Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .expect("python3 runs: ./run-tests installs the Python tools");
    assert!(
        o.status.success(),
        "{what} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o.stdout
}

/// The drill every drill test runs (4 s dwells, truth 287.5 deg, seed 7, tolerance 0.5 deg):
/// through vcan (`tests/tests/vcan.rs`), in process (`tests/tests/in_process.rs`) and watched
/// live (`tests/tests/live_view.rs`), so their results can be compared.
pub const DRILL: [&str; 10] = [
    "drill",
    "north-finding",
    "--dwell",
    "4",
    "--heading",
    "287.5",
    "--seed",
    "7",
    "--tolerance",
    "0.5",
];

/// Hand a JUnit file a test's run wrote (`hil faults --junit`) to the runner of `./run-tests`
/// (`suite`), whose report takes its suites in: copied into the folder `SUITE_JUNIT_DIR` names.
/// Nothing when the test runs without that runner (a plain `cargo test`).
pub fn junit_for_ci(file: &Path) {
    if let Some(dir) = std::env::var_os("SUITE_JUNIT_DIR") {
        let name = file.file_name().expect("a JUnit file's name");
        let to = Path::new(&dir).join(name);
        std::fs::copy(file, &to)
            .unwrap_or_else(|e| panic!("copying {} to {}: {e}", file.display(), to.display()));
    }
}

/// Run `hil` with `args` and then `paths` (its log shown); its JSON on stdout (which it must
/// print) and its exit status. A lockstep run that failed with the bench starved of CPU past
/// nav's watchdog ([`starved`]) runs again, its output folder (the first of `paths`) emptied,
/// up to [`STARVED_RERUNS`] times: identity is asserted of a run the scenario alone decided,
/// never waived. A free-running run the bench stopped because the machine did not keep real
/// time (exit 3) runs once more: a verdict is given of a run the machine could carry, not
/// waived for a stall.
pub fn hil_json(args: &[&str], paths: &[&std::path::Path]) -> (serde_json::Value, i32) {
    let (mut v, mut code) = hil_json_once(args, paths);
    let (mut starved_again, mut free_again) = (0, 0);
    loop {
        let why = if code == 3 && free_again == 0 {
            // a free-running run the bench stopped rather than feed the device a late stream
            // (an IMU sample past its lateness limit): the machine stalled, mostly for a
            // moment at the start; once more, and a second such run gives no verdict as it
            // stands
            free_again += 1;
            format!("the bench stopped: {}; {FREE_RERUN}", v["bench_behind"])
        } else if let Some(why) =
            starved_rerun(&v, code != 0).filter(|_| starved_again < STARVED_RERUNS)
        {
            // nav's watchdog fired where the stream had not stopped: the bench was starved of
            // CPU past it (a loaded host), and the run says nothing of the scenario; again,
            // and a run starved every time fails as it stands
            starved_again += 1;
            why
        } else {
            return (v, code);
        };
        eprintln!("{why}: {args:?}");
        // from an empty output folder
        if let Some(out) = paths.first() {
            empty_run_folder(out);
        }
        (v, code) = hil_json_once(args, paths);
    }
}

/// How many times a lockstep run starved of CPU past nav's watchdog runs again: twice, since
/// a run can starve while the free-running tests take the guest's CPUs at normal priority on
/// a host loaded beside the suite, and the next again for as long as they run.
pub const STARVED_RERUNS: u32 = 2;

/// Why a lockstep run is to run once more, if it is: it `failed` and its JSON (the run's
/// output or its report.json) counts watchdog reports no stop of the stream called for
/// ([`starved`]): the bench was starved of CPU past nav's watchdog, and the run says nothing
/// of the scenario. The text ends with [`STARVED_RERUN`], which `./run-tests`'s table counts.
pub fn starved_rerun(v: &serde_json::Value, failed: bool) -> Option<String> {
    let n = starved(v);
    (failed && n > 0).then(|| {
        format!("{n} watchdog report(s) no stop of the stream called for; {STARVED_RERUN}")
    })
}

/// Empty a run's output folder (where it is one) for the run's next go.
pub fn empty_run_folder(out: &Path) {
    if out.is_dir() {
        std::fs::remove_dir_all(out)
            .unwrap_or_else(|e| panic!("emptying the run folder {}: {e}", out.display()));
        std::fs::create_dir_all(out)
            .unwrap_or_else(|e| panic!("the run folder {} again: {e}", out.display()));
    }
}

/// What a test prints when it runs a lockstep run once more because the bench was starved
/// (`./run-tests`'s table counts it).
pub const STARVED_RERUN: &str = "run once more: the bench was starved of CPU";

/// What a test prints when it runs a free-running run once more because the bench stopped it,
/// the machine not keeping real time (`./run-tests`'s table counts it).
pub const FREE_RERUN: &str = "run once more: the machine did not keep real time";

/// The watchdog reports no stop of the stream called for, anywhere in a run's JSON (every
/// `starved` of its lockstep statistics: the bench's, a replay's player's).
pub fn starved(v: &serde_json::Value) -> u64 {
    match v {
        serde_json::Value::Object(m) => m
            .iter()
            .map(|(k, x)| match (k.as_str(), x.as_u64()) {
                ("starved", Some(n)) => n,
                _ => starved(x),
            })
            .sum(),
        serde_json::Value::Array(a) => a.iter().map(starved).sum(),
        _ => 0,
    }
}

fn hil_json_once(args: &[&str], paths: &[&std::path::Path]) -> (serde_json::Value, i32) {
    let o = std::process::Command::new(bin("hil"))
        .args(args)
        .args(paths)
        .output()
        .expect("hil runs");
    eprintln!("{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "hil {args:?} printed no JSON ({e}); stdout: {}",
            String::from_utf8_lossy(&o.stdout)
        )
    });
    (v, o.status.code().unwrap_or(-1))
}

/// A report's checks: (name, passed, detail).
pub fn checks(r: &serde_json::Value) -> Vec<(String, bool, String)> {
    r["checks"]
        .as_array()
        .expect("checks")
        .iter()
        .map(|c| {
            (
                c["name"].as_str().unwrap_or("").to_string(),
                c["pass"].as_bool().unwrap_or(false),
                c["detail"].as_str().unwrap_or("").to_string(),
            )
        })
        .collect()
}

/// Run `c` at nice 0, whatever the test's own priority: for the field's tools that read or
/// write a bus in real time (canbusload, canplayer) in tests `./run-tests` runs at nice 19
/// (tests/guest-e2e.sh). Raising a priority takes root, which the end-to-end tests have in the
/// guest; without it the child keeps the test's priority.
pub fn normal_priority(c: &mut std::process::Command) {
    // SAFETY: setpriority on the child itself, between fork and exec (async-signal-safe)
    unsafe {
        std::os::unix::process::CommandExt::pre_exec(c, || {
            libc::setpriority(libc::PRIO_PROCESS, 0, 0);
            Ok(())
        });
    }
}

/// Run `c`, a tool that only reads a bus, at a real-time priority (SCHED_FIFO 10) and nice 0:
/// the kernel queues a vcan frame in each reader's socket as the sender sends it, and a
/// reader not scheduled while a 4,000-frame/s log plays (four tests at once on an emulated
/// guest's two CPUs) finds its receive buffer overflowed and frames lost (canbusload lost 33
/// of 20,297 so, once). A reader blocks between frames, so it takes no CPU from the others
/// but what it needs. Without root, nice 0 only.
pub fn realtime_reader(c: &mut std::process::Command) {
    // SAFETY: sched_setscheduler and setpriority on the child itself, between fork and exec
    // (async-signal-safe system calls)
    unsafe {
        std::os::unix::process::CommandExt::pre_exec(c, || {
            libc::setpriority(libc::PRIO_PROCESS, 0, 0);
            let p = libc::sched_param { sched_priority: 10 };
            libc::sched_setscheduler(0, libc::SCHED_FIFO, &p);
            Ok(())
        });
    }
}

/// gpsd's receiver captures in `../shared/testdata/gpsd-nmea` (next to the workspace, or next
/// to its parent for a clone elsewhere), when present.
pub fn gpsd_testdata() -> Option<PathBuf> {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    [
        "../../shared/testdata/gpsd-nmea",
        "../../../shared/testdata/gpsd-nmea",
    ]
    .into_iter()
    .map(|p| here.join(p))
    .find(|p| p.is_dir())
}

/// CRC-8/SAE-J1850 in Python (polynomial 0x1D, start and final XOR 0xFF), for the scripts
/// that check a lab contract's frames with the field's tools: written from the catalogue, not
/// from our code.
pub const PY_CRC8_SAE_J1850: &str = r#"
def crc8_sae_j1850(data):
    crc = 0xFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF
"#;

#[cfg(test)]
mod tests {
    /// The watchdog reports counted starved are found wherever the run's JSON holds them.
    #[test]
    fn starved_reports_are_summed_from_every_lockstep_statistic() {
        let v = serde_json::json!({
            "lockstep": {"starved": 1, "stalls": 0},
            "play": {"lockstep": {"starved": 2}},
            "rows": [{"run": {"lockstep": {"starved": 3}}}, {"starved": "x"}],
        });
        assert_eq!(super::starved(&v), 6);
        assert_eq!(
            super::starved(&serde_json::json!({"lockstep": {"stalls": 4}})),
            0
        );
        // once more only for a failed run that counts some
        let why = super::starved_rerun(&v, true).expect("a failed starved run runs again");
        assert!(
            why.starts_with("6 ") && why.ends_with(super::STARVED_RERUN),
            "{why}"
        );
        assert_eq!(super::starved_rerun(&v, false), None);
        let fed = serde_json::json!({"lockstep": {"starved": 0}});
        assert_eq!(super::starved_rerun(&fed, true), None);
        assert_eq!(super::starved_rerun(&serde_json::Value::Null, true), None);
    }
}
