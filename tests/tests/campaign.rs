//! `hil campaign` as a lab drives it by hand or from a cluster: the plan of cells with their
//! keys, a cluster's results merged into one report (the regression first, JUnit for the CI
//! server, the exit status failing on it), and a bad campaign refused with what is wrong. The
//! cells' runs through vcan are the end-to-end tests' (they need the guest).

use e2e::bin;
use std::path::Path;
use std::process::Command;

const CAMPAIGN: &str = r#"
name = "nightly"
baseline = "release"
repeats = 3

[[device]]
name = "release"

[[device]]
name = "overconfident"
[device.config.navigation.filter]
use_gst = false
gps_sigma_m = 0.3

[[case]]
scenario = "SCENARIO"
duration_s = 40.0
"#;

fn hil(args: &[&str], dir: &Path) -> std::process::Output {
    Command::new(bin("hil"))
        .arg("campaign")
        .arg(dir.join("campaign.toml"))
        .arg("--out")
        .arg(dir.join("out"))
        .args(args)
        .output()
        .expect("hil runs")
}

/// The plan's cell lines: (number, device, seed, key, done).
fn plan(dir: &Path) -> Vec<(usize, String, u64, String, bool)> {
    let o = hil(&["--plan"], dir);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (
                f[0].parse().expect("number"),
                f[1].to_string(),
                f[3].parse().expect("seed"),
                f[5].to_string(),
                f[4] == "yes",
            )
        })
        .collect()
}

#[test]
fn a_clusters_results_merge_into_one_verdict_per_build() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/drive-gps.toml");
    std::fs::write(
        dir.path().join("campaign.toml"),
        CAMPAIGN.replace("SCENARIO", &scenario.display().to_string()),
    )
    .unwrap();
    let cells = plan(dir.path());
    assert_eq!(cells.len(), 6, "{cells:?}");
    assert!(cells.iter().all(|c| !c.4));
    // what each cluster task left: the overconfident build's errors 40 % larger, seed by seed
    for (_, device, seed, key, _) in &cells {
        let x = 15.0 + *seed as f64;
        let k = if device == "overconfident" { 1.4 } else { 1.0 };
        let folder = dir.path().join("out/cells").join(key);
        std::fs::create_dir_all(&folder).unwrap();
        let result = serde_json::json!({
            "device": device, "case": "scenario:drive-gps", "seed": seed, "pass": true,
            "figures": {"rms_position_error_m": k * x, "end_position_error_m": k * x + 1.0},
            "sent_hash": format!("{device}{seed}"),
        });
        std::fs::write(folder.join("result.json"), result.to_string()).unwrap();
    }
    assert!(
        plan(dir.path()).iter().all(|c| c.4),
        "every cell has its result"
    );
    // the plan for a cluster's submitter: as many array tasks as cells
    let o = hil(&["--plan", "--json"], dir.path());
    let p: serde_json::Value = serde_json::from_slice(&o.stdout).expect("the plan as JSON");
    let p = p.as_array().expect("cells");
    assert_eq!(p.len(), 6);
    assert!(
        p.iter()
            .enumerate()
            .all(|(i, c)| c["cell"] == i && c["done"] == true)
    );
    assert_eq!(p[5]["key"], cells[5].3.as_str());
    let o = hil(&["--merge"], dir.path());
    let md = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "a regression fails: {md}");
    assert!(
        md.contains("**WORSE** overconfident on scenario:drive-gps"),
        "{md}"
    );
    assert!(
        md.contains("rms_position_error_m: 23.8000 against 17.0000"),
        "{md}"
    );
    let out = dir.path().join("out");
    for f in ["report.md", "report.svg", "report.json"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let xml = std::fs::read_to_string(out.join("junit.xml")).unwrap();
    let j = hil::junit::foreign(&xml, "junit.xml").unwrap();
    assert_eq!((j.tests, j.failures), (1, 1), "{xml}");
    // a task of the array for a cell that has its result: nothing to run
    let o = hil(&["--cell", "2"], dir.path());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("cell 2 has its result already"));
    let o = hil(&["--cell", "6"], dir.path());
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("the plan has 6 cells"));
}

#[test]
fn a_bad_campaign_is_refused_with_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("campaign.toml"),
        CAMPAIGN
            .replace("SCENARIO", "x.toml")
            .replace("baseline = \"release\"", "baseline = \"tuesday\""),
    )
    .unwrap();
    let o = hil(&["--plan"], dir.path());
    assert_eq!(o.status.code(), Some(3));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("the baseline \"tuesday\" is not a device"),
        "{e}"
    );
}

/// The regression campaign `./run-tests` runs twice: on its Slurm cluster, by parts with a
/// cell killed and resubmitted alone (`tests/slurm.sh`, `target/slurm-reports/campaign/`),
/// and through vcan with a local pool (`tests/tests/vcan.rs`,
/// `target/e2e-reports/campaign-local/`). The two reports are the same bytes: report.md,
/// report.json, and the JUnit XML but for when and on which host it was written.
#[test]
#[ignore = "reads the reports ./run-tests' Slurm stage and end-to-end tests leave: run ./run-tests"]
fn the_clusters_campaign_report_equals_the_local_pools() {
    let target = e2e::reports_dir()
        .parent()
        .expect("the target folder")
        .to_path_buf();
    let cluster = target.join("slurm-reports/campaign");
    let local = e2e::reports_dir().join("campaign-local");
    for d in [&cluster, &local] {
        if !d.join("report.json").is_file() {
            eprintln!(
                "SKIPPED: no campaign report in {} (./run-tests leaves it)",
                d.display()
            );
            return;
        }
    }
    // the attributes that say when and on which host a file was written, left out
    let unstamped = |p: &Path| -> String {
        let mut text =
            std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        for attribute in [" timestamp=\"", " hostname=\""] {
            let mut out = String::new();
            for (i, part) in text.split(attribute).enumerate() {
                // each part after the first starts with the value and its closing quote
                out.push_str(if i == 0 {
                    part
                } else {
                    part.split_once('"').map_or(part, |x| x.1)
                });
            }
            text = out;
        }
        text
    };
    for f in ["report.md", "report.json", "junit.xml"] {
        let (a, b) = (unstamped(&cluster.join(f)), unstamped(&local.join(f)));
        assert!(a == b, "{f}: the cluster's\n{a}\nthe local pool's\n{b}");
    }
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(cluster.join("report.json")).unwrap()).unwrap();
    assert!(
        m["verdicts"].as_array().is_some_and(|v| !v.is_empty()),
        "{m}"
    );
}
