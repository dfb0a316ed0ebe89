//! The north-finding drill and the self-calibration in process (no bus: the path of the Monte Carlo runs and the
//! experiments) gives exactly the result the same drill gave through vcan. The vcan run is the
//! end-to-end test `north_finding_drill_lands_within_3_sigma_and_is_the_same_at_any_pace`,
//! which keeps its report; this runs on the host after it (`./run-tests`), where the in-process
//! drill takes a second. The guest computes what the host computes (`-cpu max`, docs/pace.md),
//! so the two agree to the last bit.

use e2e::{bin, reports_dir};
use serde_json::Value;
use std::process::Command;

#[test]
#[ignore = "needs the e2e tests' reports: run ./run-tests"]
fn the_in_process_drill_gives_the_result_of_the_drill_through_vcan() {
    let kept = reports_dir().join("drill-x3/report.json");
    let bench: Value = serde_json::from_slice(
        &std::fs::read(&kept).unwrap_or_else(|e| panic!("{}: {e}", kept.display())),
    )
    .expect("the kept report is JSON");
    let dir = tempfile::tempdir().unwrap();
    // the drill of tests/tests/vcan.rs (`drill_in`), in process
    let o = Command::new(bin("hil"))
        .args(e2e::DRILL)
        .args(["--in-process", "--json", "--out"])
        .arg(dir.path())
        .output()
        .expect("hil runs");
    let ip: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "hil drill --in-process printed no JSON ({e}): {}",
            String::from_utf8_lossy(&o.stderr)
        )
    });
    let a = &bench["nav"]["north_finding"]["result"];
    assert!(
        a["positions"].as_array().is_some_and(|p| p.len() == 4),
        "{a}"
    );
    assert_eq!(
        &ip["drill"]["result"], a,
        "the in-process drill must give the bench's result"
    );
}

/// The self-calibration in process gives exactly the result nav gave through vcan in
/// `the_rotating_imu_calibrates_itself_through_vcan` (its report kept).
#[test]
#[ignore = "needs the e2e tests' reports: run ./run-tests"]
fn the_in_process_calibration_gives_the_result_of_the_one_through_vcan() {
    let kept = reports_dir().join("calibrate/report.json");
    let bench: Value = serde_json::from_slice(
        &std::fs::read(&kept).unwrap_or_else(|e| panic!("{}: {e}", kept.display())),
    )
    .expect("the kept report is JSON");
    let dir = tempfile::tempdir().unwrap();
    // the procedure of tests/tests/vcan.rs (`CALIBRATE_ARGS`), in process
    let o = Command::new(bin("hil"))
        .args([
            "calibrate",
            "rotating-imu",
            "--level",
            "10",
            "--rotate",
            "150",
        ])
        .args(["--seed", "3", "--json", "--in-process", "--out"])
        .arg(dir.path())
        .output()
        .expect("hil runs");
    let ip: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "hil calibrate --in-process printed no JSON ({e}): {}",
            String::from_utf8_lossy(&o.stderr)
        )
    });
    let a = &bench["nav"]["self_calibration"]["result"];
    assert!(a["rls"]["gyro_bias_dph"].is_array(), "{a}");
    assert_eq!(
        &ip["calibration"]["result"], a,
        "the in-process calibration must give the bench's result"
    );
}

/// The redundant unit's calibration in process gives exactly what nav gave through vcan in
/// `the_redundant_unit_calibrates_and_each_failed_gyro_is_isolated_through_vcan` (its bias-jump
/// run's report kept).
#[test]
#[ignore = "needs the e2e tests' reports: run ./run-tests"]
fn the_in_process_tetra_calibration_gives_the_result_of_the_one_through_vcan() {
    let kept = reports_dir().join("calibrate-tetrahedral/report.json");
    let bench: Value = serde_json::from_slice(
        &std::fs::read(&kept).unwrap_or_else(|e| panic!("{}: {e}", kept.display())),
    )
    .expect("the kept report is JSON");
    let dir = tempfile::tempdir().unwrap();
    // the procedure of tests/tests/vcan.rs (`TETRA_ARGS`, bias-jump), in process
    let o = Command::new(bin("hil"))
        .args(["calibrate", "tetrahedral", "--rest", "5", "--turn", "20"])
        .args([
            "--end-rest",
            "5",
            "--seed",
            "2",
            "--json",
            "--fail",
            "bias-jump:3:0.5",
        ])
        .args(["--in-process", "--out"])
        .arg(dir.path())
        .output()
        .expect("hil runs");
    let ip: Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "hil calibrate tetrahedral --in-process printed no JSON ({e}): {}",
            String::from_utf8_lossy(&o.stderr)
        )
    });
    let a = &bench["nav"]["tetra_calibration"]["result"];
    assert!(a["coefficients"].is_array(), "{a}");
    assert_eq!(
        &ip["tetra_calibration"]["result"], a,
        "the in-process calibration must give the bench's result"
    );
}
