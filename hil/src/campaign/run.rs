//! Running a campaign's cells and reading what they gave.
//!
//! A cell is one run of the bench by this program (`hil run`), in a folder of its own under the
//! campaign's output folder (`cells/<key>/`): the scenario as the cell runs it (the case's,
//! re-seeded for the cell's seed, with the device's nav settings merged in: the bench's nav and
//! its in-process twin read the same), the run's folder, its JSON report, and `result.json`,
//! the figures the verdicts are taken from. A cell is done when `result.json` is there; a cell
//! that could not run (no report) leaves none, so running the campaign again runs it again.

use super::against_baseline::CellResult;
use super::cells::Cell;
use super::spec::{Campaign, Case, CaseKind, Device, Experiment};
use crate::scenario::Scenario;
use anyhow::{Context, Result, bail};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// How this machine runs cells.
#[derive(Debug, Clone)]
pub struct Runner {
    /// This program (`hil`).
    pub exe: PathBuf,
    /// The nav binary of a device that names none.
    pub nav_default: PathBuf,
    /// The campaign's output folder.
    pub out: PathBuf,
    /// The CAN interfaces' prefix: cell `k` runs on `<prefix><k mod 64>`.
    pub iface_prefix: String,
    /// Cells run side by side (kept with each cell's time).
    pub jobs: usize,
}

/// The figures of a bench run's JSON report that the verdicts read (absolute values of signed
/// errors): the end of the drive, the drive second by second, a drill's heading.
pub fn figures_of_report(r: &Value) -> BTreeMap<String, f64> {
    let mut f = BTreeMap::new();
    let mut put = |name: &str, v: &Value| {
        if let Some(x) = v.as_f64().filter(|x| x.is_finite()) {
            f.insert(name.to_string(), x.abs());
        }
    };
    let n = &r["navigation"];
    put("end_position_error_m", &n["position_error_m"]);
    put("end_velocity_error_mps", &n["velocity_error_mps"]);
    put("end_heading_error_deg", &n["heading_error_deg"]);
    put("end_position_sigma_m", &n["position_sigma_m"]);
    let s = &r["navigation_series"];
    put("rms_position_error_m", &s["rms_position_error_m"]);
    put("max_position_error_m", &s["max_position_error_m"]);
    put("nees_position", &s["mean_nees_per_dof"][0]);
    put("nees_velocity", &s["mean_nees_per_dof"][1]);
    let d = &r["drill"];
    put("drill_heading_error_deg", &d["error_deg"]);
    put("drill_heading_sigma_deg", &d["sigma_deg"]);
    f
}

/// A cell's result from the bench run's JSON report `r`.
pub fn result_of_report(cell: &Cell, r: &Value) -> CellResult {
    CellResult {
        device: cell.device.clone(),
        case: cell.case.clone(),
        seed: cell.seed,
        pass: r["pass"].as_bool(),
        figures: figures_of_report(r),
        sent_hash: r["nav"]["solution"]["sent_hash"]
            .as_str()
            .filter(|h| !h.is_empty())
            .map(str::to_string),
    }
}

/// The scenario cell `cell` of case `case` runs for `device`: the case's, its length as the
/// case says, re-seeded for the cell's seed, with the device's nav settings.
pub fn cell_scenario(case: &Case, device: &Device, cell: &Cell) -> Result<Scenario> {
    let CaseKind::Scenario(path) = &case.kind else {
        bail!("case {} is not a scenario", case.id);
    };
    let mut s = Scenario::load(path)?;
    if let Some(d) = case.duration_s {
        s.duration_s = d;
    }
    s.name = format!("{}-{}-s{}", s.name, device.name, cell.seed);
    let s = s.reseeded(cell.seed);
    match &device.config {
        Some(over) => s
            .with_nav_settings(over)
            .with_context(|| format!("device {:?}", device.name)),
        None => Ok(s),
    }
}

/// The north-finding drill cell `cell` runs for `device`, as `hil drill north-finding --seed`
/// makes it: at the paper's start point, its heading drawn from the seed, `dwell_s` at each of
/// four positions (60 s by default), at up to x25 (lockstep: its result is the same at any
/// pace), with the device's nav settings.
pub fn drill_scenario(case: &Case, device: &Device, cell: &Cell) -> Result<Scenario> {
    let heading = crate::procedures::northfinding::heading_of_seed(cell.seed);
    let mut s = crate::procedures::northfinding::scenario(
        heading,
        28.218157,
        case.dwell_s.unwrap_or(60.0),
        cell.seed,
    );
    s.site.lon_deg = 112.989583;
    s.speed = 25.0;
    s.name = format!("drill-{}-s{}", device.name, cell.seed);
    match &device.config {
        Some(over) => s
            .with_nav_settings(over)
            .with_context(|| format!("device {:?}", device.name)),
        None => Ok(s),
    }
}

impl Runner {
    /// Run `cell` (of `campaign`, whose cases are `cases`) and keep its result; the result.
    pub fn run(&self, campaign: &Campaign, cases: &[Case], cell: &Cell) -> Result<CellResult> {
        let case = cases
            .iter()
            .find(|c| c.id == cell.case)
            .with_context(|| format!("cell {}: no case {}", cell.number, cell.case))?;
        let device = campaign
            .devices
            .iter()
            .find(|d| d.name == cell.device)
            .with_context(|| format!("cell {}: no device {}", cell.number, cell.device))?;
        let dir = cell.folder(&self.out);
        if dir.exists() && !cell.done(&self.out) {
            // what a run stopped part way left (a killed task): the cell starts afresh
            std::fs::remove_dir_all(&dir)
                .with_context(|| format!("clearing {} (a run that did not end)", dir.display()))?;
        }
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let started = std::time::Instant::now();
        let result = match &case.kind {
            CaseKind::Scenario(_) => {
                let s = cell_scenario(case, device, cell)?;
                result_of_report(cell, &self.run_scenario(&s, device, cell, &dir)?)
            }
            CaseKind::Fault(name) => self.run_fault(name, device, cell, &dir)?,
            CaseKind::Drill(_) => {
                let s = drill_scenario(case, device, cell)?;
                result_of_report(cell, &self.run_scenario(&s, device, cell, &dir)?)
            }
            CaseKind::Experiment(e) => in_process(e, case, device, cell)?,
        };
        super::cost::CellTime {
            wall_s: started.elapsed().as_secs_f64(),
            jobs: self.jobs,
            guest: std::env::var_os(vcan_setup::GUEST_ENV).is_some(),
        }
        .write(&dir)?;
        let text = serde_json::to_string_pretty(&result)?;
        std::fs::write(dir.join("result.json"), text)
            .with_context(|| format!("writing {}", dir.join("result.json").display()))?;
        Ok(result)
    }

    /// A fault row for `device`: `hil faults --only` with its nav binary (the matrix's own
    /// settings: a device's nav settings apply to scenario cases), the row's pass, its
    /// detection latency and what nav sent.
    fn run_fault(
        &self,
        name: &str,
        device: &Device,
        cell: &Cell,
        dir: &Path,
    ) -> Result<CellResult> {
        if device.dut.is_some() {
            bail!(
                "cell {} ({}): the fault matrix runs builds of nav; {:?} is a free-running device",
                cell.number,
                cell.case,
                device.name
            );
        }
        let mut c = Command::new(&self.exe);
        c.args(["faults", "--only", name, "--jobs", "1", "--json"])
            .arg("--out")
            .arg(dir.join("run"))
            .args([
                "--iface",
                &format!("{}{}", self.iface_prefix, cell.number % 64),
            ])
            .arg("--nav")
            .arg(device.nav.as_deref().unwrap_or(&self.nav_default));
        let m = self.report_of(c, cell, dir)?;
        let row = &m["rows"][0];
        if row["fault"].as_str() != Some(name) {
            bail!(
                "cell {} ({}): the matrix gave no row {name}",
                cell.number,
                cell.case
            );
        }
        let mut figures = BTreeMap::new();
        if let Some(l) = row["verdict"]["latency_s"]
            .as_f64()
            .filter(|x| x.is_finite())
        {
            figures.insert("detection_latency_s".to_string(), l.abs());
        }
        // what nav sent in the row's run, for "the same frames"
        let run: Value = row["run_dir"]
            .as_str()
            .and_then(|d| std::fs::read(Path::new(d).join("report.json")).ok())
            .and_then(|b| serde_json::from_slice(&b).ok())
            .unwrap_or(Value::Null);
        Ok(CellResult {
            device: cell.device.clone(),
            case: cell.case.clone(),
            seed: cell.seed,
            pass: row["verdict"]["pass"].as_bool(),
            figures,
            sent_hash: run["nav"]["solution"]["sent_hash"]
                .as_str()
                .filter(|h| !h.is_empty())
                .map(str::to_string),
        })
    }

    /// Run `c` (a hil command printing its JSON report), its log kept in the cell's folder;
    /// the report (a run whose checks fail still reports, with exit status 1).
    fn report_of(&self, mut c: Command, cell: &Cell, dir: &Path) -> Result<Value> {
        let o = c
            .output()
            .with_context(|| format!("starting {}", self.exe.display()))?;
        std::fs::write(dir.join("run.log"), &o.stderr)
            .with_context(|| format!("writing {}", dir.join("run.log").display()))?;
        serde_json::from_slice(&o.stdout).with_context(|| {
            format!(
                "cell {} ({} on {}): the run gave no report (exit status {:?}; its log: {})",
                cell.number,
                cell.case,
                cell.device,
                o.status.code(),
                dir.join("run.log").display()
            )
        })
    }

    fn run_scenario(
        &self,
        s: &Scenario,
        device: &Device,
        cell: &Cell,
        dir: &Path,
    ) -> Result<Value> {
        let file = dir.join("scenario.toml");
        std::fs::write(&file, toml::to_string(&s)?)
            .with_context(|| format!("writing {}", file.display()))?;
        let iface = format!("{}{}", self.iface_prefix, cell.number % 64);
        let mut c = Command::new(&self.exe);
        c.arg("run")
            .arg("--scenario")
            .arg(&file)
            .arg("--json")
            .arg("--out")
            .arg(dir.join("run"))
            .args(["--iface", &iface]);
        match &device.dut {
            Some(cmd) => {
                c.args(["--free", "--dut", cmd]);
            }
            None => {
                c.arg("--nav")
                    .arg(device.nav.as_deref().unwrap_or(&self.nav_default));
            }
        }
        self.report_of(c, cell, dir)
    }
}

/// An experiment's cell: one run in process (nav's library, the bench's devices, no bus) with
/// the device's nav settings, for the cell's seed. What nav computed is hashed to the bit for
/// "the same" (there are no frames on a bus to compare).
pub fn in_process(e: &Experiment, case: &Case, device: &Device, cell: &Cell) -> Result<CellResult> {
    if device.dut.is_some() {
        bail!(
            "cell {} ({}): an experiment runs nav's library in process; {:?} is a free-running device",
            cell.number,
            cell.case,
            device.name
        );
    }
    let (pass, figures, bits) = match e {
        Experiment::NorthFinding => {
            let s = drill_scenario(case, device, cell)?;
            let nf = s
                .north_finding
                .clone()
                .context("the drill's scenario has no [north_finding]")?;
            let o = crate::procedures::northfinding::run_in_process(&s, &nf, |_| {})
                .with_context(|| format!("cell {} ({})", cell.number, cell.case))?;
            let mut f = BTreeMap::new();
            let mut put = |name: &str, v: Option<f64>| {
                if let Some(x) = v.filter(|x| x.is_finite()) {
                    f.insert(name.to_string(), x.abs());
                }
            };
            put("drill_heading_error_deg", o.error_deg);
            put("drill_heading_sigma_deg", o.sigma_deg);
            let pass = o.abort.is_none()
                && matches!((o.error_deg, o.sigma_deg), (Some(e), Some(s)) if e.abs() <= 3.0 * s);
            (pass, f, serde_json::to_vec(&o)?)
        }
        Experiment::Navigation(path) => {
            let mut s = Scenario::load(path)?;
            if let Some(d) = case.duration_s {
                s.duration_s = d;
            }
            let s = match &device.config {
                Some(over) => s
                    .reseeded(cell.seed)
                    .with_nav_settings(over)
                    .with_context(|| format!("device {:?}", device.name))?,
                None => s.reseeded(cell.seed),
            };
            let rx = s
                .gps
                .clone()
                .with_context(|| format!("{}: no [gps] to navigate with", path.display()))?;
            let filter = s
                .navigation
                .as_ref()
                .map(|n| n.filter.clone())
                .unwrap_or_default();
            let r = crate::engine::navigate::navigate(&s, Some(&filter), &rx, 0.0)
                .with_context(|| format!("cell {} ({})", cell.number, cell.case))?;
            let mut f = BTreeMap::new();
            let mut put = |name: &str, x: f64| {
                if x.is_finite() {
                    f.insert(name.to_string(), x.abs());
                }
            };
            put("end_position_error_m", r.end_position_error_m);
            put("end_velocity_error_mps", r.end_velocity_error_mps);
            put("end_heading_error_deg", r.end_heading_error_deg);
            put("rms_position_error_m", r.rms_position_error_m);
            put(
                "max_position_error_m",
                r.series
                    .iter()
                    .map(|x| x.position_error_m)
                    .fold(0.0, f64::max),
            );
            if let Some([p, v]) = r.mean_nees_per_dof {
                put("nees_position", p);
                put("nees_velocity", v);
            }
            // as a bench run's checks judge it: the end error, no good fix refused, the sigmas
            let consistent = r
                .mean_nees_per_dof
                .is_none_or(|n| n.iter().all(|x| *x <= crate::report::NEES_PER_DOF_LIMIT));
            let pass = r.end_position_error_m <= s.position_tolerance_m
                && r.good_fixes_refused == 0
                && consistent;
            (pass, f, serde_json::to_vec(&r)?)
        }
    };
    Ok(CellResult {
        device: cell.device.clone(),
        case: cell.case.clone(),
        seed: cell.seed,
        pass: Some(pass),
        figures,
        sent_hash: Some(format!(
            "in-process:{:016x}",
            super::cells::hash_bytes(&bits)
        )),
    })
}

/// Every cell's result kept in `out` (the cells without one left out).
pub fn results(cells: &[Cell], out: &Path) -> Result<Vec<CellResult>> {
    let mut v = Vec::new();
    for c in cells.iter().filter(|c| c.done(out)) {
        let p = c.folder(out).join("result.json");
        let text =
            std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
        v.push(serde_json::from_str(&text).with_context(|| format!("{}", p.display()))?);
    }
    Ok(v)
}
