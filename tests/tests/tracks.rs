//! Recorded tracks as a new user brings them: `hil plan track` checks each shipped track (a
//! handheld logger's GPX, a receiver's NMEA log, a reference system's CSV), says how close the
//! road it drives is, draws it, and refuses a bad track with the file, the line and why; `hil
//! plan route --track` writes a drive as a track that `hil plan track` reads back.

use e2e::bin;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

fn tracks() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/tracks")
}

fn plan_track(file: &Path, extra: &[&str]) -> (Value, std::process::Output) {
    let o = Command::new(bin("hil"))
        .args(["plan", "track"])
        .arg(file)
        .args(extra)
        .arg("--json")
        .output()
        .expect("hil runs");
    let v = serde_json::from_slice(&o.stdout).unwrap_or(Value::Null);
    (v, o)
}

/// Each shipped track is driven within a few metres of its points and seconds of its times,
/// and its picture is an SVG with the road and the points.
#[test]
fn every_shipped_track_is_checked_and_drawn() {
    let dir = tempfile::tempdir().unwrap();
    for (file, glitches) in [
        ("lisbon-handheld.gpx", 4),
        ("lisbon-receiver.nmea", 0),
        ("lisbon-reference.csv", 0),
    ] {
        let svg = dir.path().join(format!("{file}.svg"));
        let (v, o) = plan_track(&tracks().join(file), &["--svg", svg.to_str().unwrap()]);
        assert!(
            o.status.success(),
            "{file}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let t = &v["track"];
        let f = |k: &str| t[k].as_f64().unwrap_or(f64::NAN);
        assert!(
            f("distance_rms_m") < 2.0 && f("distance_max_m") < 6.0,
            "{file}: {t}"
        );
        assert!(
            f("time_rms_s") < 3.0 && f("time_max_s") < 6.0,
            "{file}: {t}"
        );
        assert_eq!(
            t["dropped_points"].as_array().map(Vec::len),
            Some(glitches),
            "{file}: {t}"
        );
        assert!(
            t["stops"].as_array().is_some_and(|s| s.len() >= 3),
            "{file}: {t}"
        );
        let pic = std::fs::read_to_string(&svg).expect("the picture");
        assert!(
            pic.starts_with("<svg") && pic.trim_end().ends_with("</svg>"),
            "{file}"
        );
        assert!(pic.matches("<circle").count() > 200, "{file}: the points");
        assert!(pic.contains("stroke=\"#1f5fbf\""), "{file}: the road");
    }
}

/// A track the bench cannot drive is refused with exit status 2, the file, the line and why.
#[test]
fn a_bad_track_is_refused_with_where_and_why() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("back.csv");
    std::fs::write(
        &f,
        "time,lat,lon\n0,46.0,7.0\n10,46.001,7.0\n5,46.002,7.0\n",
    )
    .unwrap();
    let (_, o) = plan_track(&f, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("back.csv") && err.contains("line 4") && err.contains("time goes back"),
        "{err}"
    );
}

/// A scenario's drive written as a track by `hil plan route --track` (GPX 1.0, jittery) is
/// read back and driven where the scenario drove.
#[test]
fn a_drive_written_as_a_track_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let gpx = dir.path().join("lisbon.gpx");
    let scenario =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/route-lisbon-hills.toml");
    let o = Command::new(bin("hil"))
        .args(["plan", "route", "--scenario"])
        .arg(&scenario)
        .arg("--track")
        .arg(&gpx)
        .args([
            "--track-format",
            "gpx10",
            "--track-jitter",
            "2",
            "--track-step",
            "2",
        ])
        .output()
        .expect("hil runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&gpx).unwrap();
    assert!(text.contains("version=\"1.0\""));
    let (v, o) = plan_track(&gpx, &["--scenario", scenario.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // the route is 1,741 m long
    let len = v["length_m"].as_f64().unwrap();
    assert!((len - 1741.0).abs() < 60.0, "{len}");
}

/// Real receivers' logs (gpsd's captures, in `../shared`): each is driven or refused with a
/// reason (exit status 0 or 2, never a crash); most stand still and are refused as too few
/// points to drive, and the one of a moving vessel (a u-blox ZED-F9P at 3 m/s) is driven within
/// a few metres of its fixes.
#[test]
fn real_receivers_logs_are_driven_or_refused_with_a_reason() {
    let Some(dir) = e2e::gpsd_testdata() else {
        eprintln!("SKIPPED: ../shared/testdata/gpsd-nmea is absent");
        return;
    };
    let entries = std::fs::read_dir(&dir).expect("the captures' folder reads");
    let mut logs: Vec<_> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "log"))
        .collect();
    logs.sort();
    assert!(logs.len() > 20, "{}", dir.display());
    let mut driven = 0;
    for log in &logs {
        let (v, o) = plan_track(log, &[]);
        let err = String::from_utf8_lossy(&o.stderr);
        match o.status.code() {
            Some(0) => driven += 1,
            Some(2) => assert!(
                err.contains("error: track") && err.contains(&*log.to_string_lossy()),
                "{err}"
            ),
            c => panic!("{}: exit {c:?}: {err}", log.display()),
        }
        if log.ends_with("bundg_zeus_9.log") {
            let t = &v["track"];
            assert!(t["distance_rms_m"].as_f64().is_some_and(|d| d < 3.0), "{t}");
            assert!(v["length_m"].as_f64().is_some_and(|l| l > 300.0), "{v}");
        }
    }
    assert!(driven >= 3, "{driven} of {} driven", logs.len());
}
