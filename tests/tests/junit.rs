//! The JUnit XML the bench writes, read by a CI server's kind of reader: a fault matrix with a
//! failing row (`hil faults --junit` writes it with `hil::suites::faults::junit`) checked
//! against Jenkins' junit-10.xsd and read by Python's junitparser (tests/junit-check.py), not
//! by us. The failing row must come out as a failed test case whose message and text carry the
//! expected and the observed behaviour.

use serde_json::{Value, json};
use std::path::PathBuf;

/// The schema `./run-tests` fetched (pytest's copy of the xUnit plug-in's junit-10.xsd).
fn schema() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable");
    // target/debug/deps/<test> -> target/junit-10.xsd
    let target = exe
        .parent()
        .and_then(|p| p.parent())
        .and_then(|p| p.parent())
        .expect("target folder");
    target.join("junit-10.xsd")
}

/// tests/junit-check.py on `xml`: the schema's verdict and what junitparser read.
fn junit_check(xml: &std::path::Path) -> std::process::Output {
    std::process::Command::new("python3")
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/junit-check.py"))
        .arg(xml)
        .arg(schema())
        .output()
        .expect("python3 runs")
}

#[test]
#[ignore = "needs Python's junitparser and xmlschema and the schema: run ./run-tests"]
fn a_failing_fault_row_is_a_failed_case_that_junitparser_reads_with_its_figures() {
    let row = |fault: &str, pass: bool, observed: &str| {
        json!({
            "fault": fault,
            "base": "imu",
            "injected": "the IMU stops at 3 s",
            "expected": "imu_timeout within 2.5 s",
            "verdict": { "pass": pass, "observed": observed, "latency_s": 2.001 },
            "nav_exit": 0,
            "wall_seconds": 4.25,
            "run_dir": "/tmp/x/imu-stop",
        })
    };
    let m: hil::suites::faults::FaultMatrix = serde_json::from_value(json!({
        "backend": "vm",
        "rows": [
            row("imu-stop", true, "imu_timeout after 2.001 s"),
            row("imu-stop-late", false, "no imu_timeout in 13 s <& \"quoted\">"),
        ],
        "pass": false,
    }))
    .expect("a matrix");
    let dir = tempfile::tempdir().unwrap();
    let xml = dir.path().join("faults.xml");
    hil::junit::write(&xml, "hil faults", &[hil::suites::faults::junit(&m)]).unwrap();
    let o = junit_check(&xml);
    assert!(
        o.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&o.stderr),
        std::fs::read_to_string(&xml).unwrap()
    );
    let read: Value = serde_json::from_slice(&o.stdout).expect("the checker's JSON");
    assert_eq!(read["tests"], 2, "{read}");
    assert_eq!(read["failures"], 1, "{read}");
    let f = &read["failed"][0];
    assert_eq!(f["case"], "imu-stop-late");
    assert_eq!(f["classname"], "hil faults");
    assert_eq!(f["time"], 4.25);
    let message = f["message"].as_str().unwrap();
    assert!(
        message.contains("expected: imu_timeout within 2.5 s")
            && message.contains("observed: no imu_timeout in 13 s <& \"quoted\">"),
        "{message}"
    );
    let text = f["text"].as_str().unwrap();
    assert!(
        text.contains("injected: the IMU stops at 3 s")
            && text.contains("detection latency: 2.001 s"),
        "{text}"
    );
}

/// A document the schema refuses is refused by the checker: the check can fail.
#[test]
#[ignore = "needs Python's junitparser and xmlschema and the schema: run ./run-tests"]
fn the_checker_refuses_what_the_schema_refuses() {
    let dir = tempfile::tempdir().unwrap();
    let xml = dir.path().join("bad.xml");
    std::fs::write(
        &xml,
        "<testsuites tests=\"1\"><testsuite name=\"s\"><testcase name=\"c\"/></testsuite></testsuites>",
    )
    .unwrap();
    let o = junit_check(&xml);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("not valid"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}
