//! The campaign file:
//!
//! ```toml
//! name = "nightly"
//! baseline = "release"
//! repeats = 3                      # statistical cases' repeats (default 3)
//!
//! [[device]]
//! name = "release"
//! nav = "builds/nav-1.4"           # a nav binary (default: the nav beside hil)
//!
//! [[device]]
//! name = "new-filter"
//! nav = "builds/nav-1.5"
//! [device.config.navigation.filter]   # nav settings for this device
//! kind = "adaptive"
//!
//! [[device]]
//! name = "their-box"
//! dut = "python3 their_nav.py {iface}"   # a free-running device command
//!
//! [[case]]
//! faults = ["imu-frames-dropped", "gps-void-outage"]   # or ["all"]
//!
//! [[case]]
//! scenario = "scenarios/drive-gps.toml"
//! duration_s = 60.0
//!
//! [[case]]
//! drill = "north-finding"
//! seeds = [1, 2, 3]
//!
//! [[case]]
//! experiment = "north-finding"     # drills in process, a run per seed
//! runs = 8
//!
//! [[case]]
//! experiment = "navigation"        # the scenario's drive navigated in process, a run per seed
//! scenario = "scenarios/drive-gps.toml"
//! runs = 8
//! ```

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A campaign: devices, a baseline among them, cases.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Campaign {
    /// The campaign's name (its report's title).
    pub name: String,
    /// The device every other is compared with.
    pub baseline: String,
    /// Repeats of a statistical case (a scenario, a drill or an experiment without seeds or
    /// runs), each with another seed.
    #[serde(default = "three")]
    pub repeats: u32,
    /// The devices under test.
    #[serde(rename = "device")]
    pub devices: Vec<Device>,
    /// The cases.
    #[serde(rename = "case")]
    pub cases: Vec<CaseSpec>,
}

fn three() -> u32 {
    3
}

/// A device under test: a build of nav with its config, or a free-running device's command.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Device {
    /// Its name in the report.
    pub name: String,
    /// A nav binary (relative to the campaign file's folder); none: the nav beside hil.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nav: Option<PathBuf>,
    /// nav config overrides (tables and keys of nav's config file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub config: Option<toml::Table>,
    /// A free-running device's command (`{iface}`, `{tty}` replaced), instead of nav.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dut: Option<String>,
}

/// A case as the file says it: exactly one of its kinds.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct CaseSpec {
    /// Fault-matrix rows by name, or `["all"]`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<String>,
    /// A scenario file (relative to the campaign file's folder).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario: Option<PathBuf>,
    /// A drill (`north-finding`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drill: Option<String>,
    /// An experiment (`north-finding`, `navigation`, `routes`, ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub experiment: Option<String>,
    /// A scenario's length, s (default: the scenario's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
    /// The seeds of a drill or a scenario (default: 1 to the campaign's `repeats`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub seeds: Vec<u64>,
    /// An experiment's runs (seeds 1 to `runs`; default the campaign's `repeats`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub runs: Option<u32>,
    /// A north-finding drill's dwell at each position, s (default 60).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dwell_s: Option<f64>,
}

/// What a case runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum CaseKind {
    /// One fault-matrix row (lockstep: one run says it all).
    Fault(String),
    /// A scenario through the bench.
    Scenario(PathBuf),
    /// A drill.
    Drill(String),
    /// An experiment in process (nav's library, no bus), one run per seed: `north-finding`
    /// (the drill) or `navigation` (the scenario's drive).
    Experiment(Experiment),
}

/// The experiments a campaign runs, in process (nav's library with the device's settings).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Experiment {
    /// North-finding drills, one per seed (the drill of `hil drill north-finding --seed`).
    NorthFinding,
    /// The scenario's drive navigated with its receiver, one run per seed.
    Navigation(PathBuf),
}

/// The experiments a campaign knows, by name.
pub const EXPERIMENTS: [&str; 2] = ["north-finding", "navigation"];

/// One case of a campaign, with its seeds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Case {
    /// Its name in the report and in its cells' keys (`fault:imu-frames-dropped`,
    /// `scenario:drive-gps`, ...).
    pub id: String,
    /// What it runs.
    pub kind: CaseKind,
    /// A scenario's length, s.
    pub duration_s: Option<f64>,
    /// A drill's dwell at each position, s.
    pub dwell_s: Option<f64>,
    /// One cell per seed and device.
    pub seeds: Vec<u64>,
}

impl Campaign {
    /// Read and check a campaign file; its relative paths are made relative to its folder.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading the campaign {}", path.display()))?;
        let mut c: Self =
            toml::from_str(&text).with_context(|| format!("campaign {}", path.display()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        for d in &mut c.devices {
            if let Some(n) = &d.nav {
                d.nav = Some(dir.join(n));
            }
        }
        for k in &mut c.cases {
            if let Some(s) = &k.scenario {
                k.scenario = Some(dir.join(s));
            }
        }
        c.check()
            .with_context(|| format!("campaign {}", path.display()))?;
        Ok(c)
    }

    /// Devices named once each, the baseline among them, each device one thing, each case one
    /// kind, repeats at least one.
    pub fn check(&self) -> Result<()> {
        if self.devices.is_empty() || self.cases.is_empty() {
            bail!("a campaign needs at least one [[device]] and one [[case]]");
        }
        for (i, d) in self.devices.iter().enumerate() {
            if self.devices[..i].iter().any(|e| e.name == d.name) {
                bail!("device {:?} is named twice", d.name);
            }
            if d.dut.is_some() && (d.nav.is_some() || d.config.is_some()) {
                bail!(
                    "device {:?}: a free-running `dut` command has no `nav` or `config`",
                    d.name
                );
            }
        }
        if !self.devices.iter().any(|d| d.name == self.baseline) {
            bail!(
                "the baseline {:?} is not a device (devices: {})",
                self.baseline,
                self.devices
                    .iter()
                    .map(|d| d.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        if self.repeats == 0 {
            bail!("repeats must be at least 1");
        }
        self.cases()?;
        Ok(())
    }

    /// The cases, each fault row its own case, in the file's order.
    pub fn cases(&self) -> Result<Vec<Case>> {
        let mut out = Vec::new();
        let seeds = |k: &CaseSpec| -> Vec<u64> {
            if k.seeds.is_empty() {
                (1..=u64::from(self.repeats)).collect()
            } else {
                k.seeds.clone()
            }
        };
        for (i, k) in self.cases.iter().enumerate() {
            // an experiment's scenario is its drive, not a case of its own
            let kinds = usize::from(!k.faults.is_empty())
                + usize::from(k.scenario.is_some() && k.experiment.is_none())
                + usize::from(k.drill.is_some())
                + usize::from(k.experiment.is_some());
            if kinds != 1 {
                bail!(
                    "case {} must name exactly one of faults, scenario, drill, experiment",
                    i + 1
                );
            }
            if k.runs.is_some() && k.experiment.is_none() {
                bail!(
                    "case {}: runs are an experiment's (a scenario or a drill has seeds)",
                    i + 1
                );
            }
            if k.runs.is_some() && !k.seeds.is_empty() {
                bail!("case {}: give runs or seeds, not both", i + 1);
            }
            if k.runs == Some(0) {
                bail!("case {}: runs must be at least 1", i + 1);
            }
            let known: Vec<&str> = crate::suites::faults::matrix()
                .iter()
                .map(|c| c.name)
                .collect();
            let rows: Vec<String> = if k.faults.iter().any(|f| f == "all") {
                known.iter().map(|f| f.to_string()).collect()
            } else {
                k.faults.clone()
            };
            if let Some(bad) = rows.iter().find(|f| !known.contains(&f.as_str())) {
                bail!(
                    "case {}: {bad:?} is not a fault of the matrix (`hil faults --list`)",
                    i + 1
                );
            }
            for f in &rows {
                out.push(Case {
                    id: format!("fault:{f}"),
                    kind: CaseKind::Fault(f.clone()),
                    duration_s: None,
                    dwell_s: None,
                    seeds: vec![0],
                });
            }
            if let Some(s) = k.scenario.as_ref().filter(|_| k.experiment.is_none()) {
                let stem = stem_of(s);
                out.push(Case {
                    id: format!("scenario:{stem}"),
                    kind: CaseKind::Scenario(s.clone()),
                    duration_s: k.duration_s,
                    dwell_s: None,
                    seeds: seeds(k),
                });
            }
            if let Some(d) = k.drill.as_ref().filter(|d| d.as_str() != "north-finding") {
                bail!(
                    "case {}: drill {d:?}: the drill a campaign runs is \"north-finding\"",
                    i + 1
                );
            }
            if k.dwell_s.is_some_and(|d| !(5.0..=600.0).contains(&d)) {
                bail!("case {}: dwell_s from 5 to 600 s", i + 1);
            }
            if let Some(d) = &k.drill {
                out.push(Case {
                    id: format!("drill:{d}"),
                    kind: CaseKind::Drill(d.clone()),
                    duration_s: None,
                    dwell_s: k.dwell_s,
                    seeds: seeds(k),
                });
            }
            if let Some(e) = &k.experiment {
                let run_seeds = match k.runs {
                    Some(n) => (1..=u64::from(n)).collect(),
                    None => seeds(k),
                };
                out.push(experiment_case(i, e, k, run_seeds)?);
            }
        }
        for (i, c) in out.iter().enumerate() {
            if out[..i].iter().any(|d| d.id == c.id) {
                bail!("case {} is named twice", c.id);
            }
        }
        Ok(out)
    }
}

/// The experiment case `e` of the file's case `i` (`k`), with its runs' seeds.
fn experiment_case(i: usize, e: &str, k: &CaseSpec, seeds: Vec<u64>) -> Result<Case> {
    let (id, which) = match (e, &k.scenario) {
        ("north-finding", None) => (
            "experiment:north-finding".to_string(),
            Experiment::NorthFinding,
        ),
        ("north-finding", Some(_)) => bail!(
            "case {}: experiment \"north-finding\" runs the drill (dwell_s), not a scenario",
            i + 1
        ),
        ("navigation", Some(s)) => (
            format!("experiment:navigation:{}", stem_of(s)),
            Experiment::Navigation(s.clone()),
        ),
        ("navigation", None) => bail!(
            "case {}: experiment \"navigation\" needs the scenario whose drive it navigates",
            i + 1
        ),
        (other, _) => bail!(
            "case {}: experiment {other:?}: a campaign runs {}",
            i + 1,
            EXPERIMENTS.join(" or ")
        ),
    };
    Ok(Case {
        id,
        kind: CaseKind::Experiment(which),
        duration_s: k.duration_s,
        dwell_s: k.dwell_s,
        seeds,
    })
}

/// A scenario's name in a case's id: its file's stem.
fn stem_of(s: &Path) -> String {
    s.file_stem().map_or_else(
        || s.display().to_string(),
        |x| x.to_string_lossy().into_owned(),
    )
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) const EXAMPLE: &str = r#"
name = "nightly"
baseline = "release"
repeats = 2

[[device]]
name = "release"

[[device]]
name = "worse"
[device.config.filter]
gps_sigma_m = 0.5

[[case]]
faults = ["imu-frames-dropped", "gps-void-outage"]

[[case]]
scenario = "scenarios/drive-gps.toml"
duration_s = 60.0

[[case]]
drill = "north-finding"
seeds = [7, 8, 9]

[[case]]
experiment = "north-finding"
runs = 4

[[case]]
experiment = "navigation"
scenario = "scenarios/drive-gps.toml"
duration_s = 30.0
seeds = [3, 4]
"#;

    #[test]
    fn a_campaign_file_gives_its_cases_with_their_seeds() {
        let c: Campaign = toml::from_str(EXAMPLE).expect("parses");
        c.check().expect("valid");
        let cases = c.cases().expect("cases");
        let ids: Vec<&str> = cases.iter().map(|c| c.id.as_str()).collect();
        assert_eq!(
            ids,
            [
                "fault:imu-frames-dropped",
                "fault:gps-void-outage",
                "scenario:drive-gps",
                "drill:north-finding",
                "experiment:north-finding",
                "experiment:navigation:drive-gps",
            ]
        );
        assert_eq!(cases[0].seeds, [0]);
        assert_eq!(cases[2].seeds, [1, 2]);
        assert_eq!(cases[3].seeds, [7, 8, 9]);
        assert_eq!(
            cases[4].kind,
            CaseKind::Experiment(Experiment::NorthFinding)
        );
        assert_eq!(cases[4].seeds, [1, 2, 3, 4]);
        assert_eq!(
            cases[5].kind,
            CaseKind::Experiment(Experiment::Navigation("scenarios/drive-gps.toml".into()))
        );
        assert_eq!(
            (cases[5].seeds.as_slice(), cases[5].duration_s),
            ([3, 4].as_slice(), Some(30.0))
        );
        // every row of the matrix
        let all: Campaign = toml::from_str(&EXAMPLE.replace(
            "faults = [\"imu-frames-dropped\", \"gps-void-outage\"]",
            "faults = [\"all\"]",
        ))
        .expect("parses");
        let rows = crate::suites::faults::matrix().len();
        assert_eq!(all.cases().expect("cases").len(), rows + 4);
    }

    #[test]
    fn a_bad_campaign_says_what_is_wrong() {
        let bad = |from: &str, to: &str, want: &str| {
            let text = EXAMPLE.replacen(from, to, 1);
            let e = toml::from_str::<Campaign>(&text)
                .map_err(anyhow::Error::from)
                .and_then(|c| c.check())
                .expect_err(want);
            assert!(format!("{e:#}").contains(want), "{e:#} (expected {want})");
        };
        bad(
            "baseline = \"release\"",
            "baseline = \"nightly\"",
            "the baseline \"nightly\" is not a device",
        );
        bad("name = \"worse\"", "name = \"release\"", "named twice");
        bad(
            "drill = \"north-finding\"",
            "drill = \"north-finding\"\nexperiment = \"x\"",
            "exactly one",
        );
        bad("repeats = 2", "repeats = 0", "at least 1");
        bad(
            "runs = 4",
            "runs = 4\nseeds = [1]",
            "runs or seeds, not both",
        );
        bad("seeds = [7, 8, 9]", "runs = 3", "runs are an experiment's");
        bad(
            "experiment = \"north-finding\"",
            "experiment = \"routes\"",
            "a campaign runs north-finding or navigation",
        );
        bad(
            "experiment = \"navigation\"\nscenario = \"scenarios/drive-gps.toml\"",
            "experiment = \"navigation\"",
            "needs the scenario",
        );
        bad(
            "\"gps-void-outage\"",
            "\"gps-outage\"",
            "\"gps-outage\" is not a fault of the matrix",
        );
        bad("duration_s = 60.0", "duration = 60.0", "unknown field");
    }
}
