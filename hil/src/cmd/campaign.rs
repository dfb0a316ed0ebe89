//! `hil campaign`: several builds through the same cases, one verdict per build and case
//! against the baseline.

use crate::cmd::guest::absolute;
use anyhow::{Context, Result};
use hil::campaign::plan::{Build, Cell, cell_at, cells, pending};
use hil::campaign::report;
use hil::campaign::run::{Runner, results};
use hil::campaign::spec::Campaign;
use hil::run::sibling_binary;
use std::path::PathBuf;

#[derive(clap::Args, Clone)]
pub(crate) struct CampaignArgs {
    /// The campaign file (TOML: devices, the baseline, cases; docs/campaigns.md).
    pub(crate) file: PathBuf,
    /// Output folder: a folder per cell (`cells/<key>/`) and the merged report. Run again
    /// with the same folder, a campaign resumes: a cell with a result from the same build is
    /// not run again.
    #[arg(long, default_value = "runs/campaign")]
    pub(crate) out: PathBuf,
    /// Print the plan (every cell: its number, device, case, seed, key, and whether it has a
    /// result) and exit.
    #[arg(long)]
    pub(crate) plan: bool,
    /// Run only cell K of the plan (0-based), as a cluster's array task does; no merge.
    #[arg(long, value_name = "K")]
    pub(crate) cell: Option<usize>,
    /// Cells run side by side, each on a CAN interface of its own.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=16))]
    pub(crate) jobs: u16,
    /// Merge the results there are, without running any cell.
    #[arg(long)]
    pub(crate) merge: bool,
    /// The CAN interfaces' prefix: cell K runs on `<prefix><K mod 64>`.
    #[arg(long, default_value = "vcan-cmp")]
    pub(crate) iface_prefix: String,
    /// Print the merged report (with `--plan`: the plan's cells) as JSON on stdout.
    #[arg(long)]
    pub(crate) json: bool,
}

/// The campaign's plan: its cases and cells.
fn planned(a: &CampaignArgs) -> Result<(Campaign, Vec<hil::campaign::spec::Case>, Vec<Cell>)> {
    let c = Campaign::load(&a.file)?;
    let nav = sibling_binary("nav")?;
    let builds = c
        .devices
        .iter()
        .map(|d| Build::of(d, &nav))
        .collect::<Result<Vec<_>>>()?;
    let cases = c.cases()?;
    let cells = cells(&c, &cases, &builds)?;
    Ok((c, cases, cells))
}

pub(crate) fn campaign(a: CampaignArgs) -> Result<i32> {
    // a campaign that cannot be planned is not a regression: its own exit status
    let (c, cases, cells) = match planned(&a) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("hil: error: {e:#}");
            return Ok(3);
        }
    };
    let out = absolute(&a.out)?;
    if a.plan && a.json {
        let plan: Vec<serde_json::Value> = cells
            .iter()
            .map(|k| {
                serde_json::json!({
                    "cell": k.number, "device": k.device, "build": k.build, "case": k.case,
                    "seed": k.seed, "key": k.key, "done": k.done(&out),
                })
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&plan)?);
        return Ok(0);
    }
    if a.plan {
        println!(
            "{:>4}  {:<16} {:<32} {:>6}  {:<4} key",
            "cell", "device", "case", "seed", "done"
        );
        for k in &cells {
            println!(
                "{:>4}  {:<16} {:<32} {:>6}  {:<4} {}",
                k.number,
                k.device,
                k.case,
                k.seed,
                if k.done(&out) { "yes" } else { "no" },
                k.key
            );
        }
        return Ok(0);
    }
    let runner = Runner {
        exe: std::env::current_exe().context("this program's path")?,
        nav_default: sibling_binary("nav")?,
        out: out.clone(),
        iface_prefix: a.iface_prefix.clone(),
    };
    if let Some(k) = a.cell {
        let cell = cell_at(&cells, k)?;
        if cell.done(&out) {
            eprintln!(
                "hil: cell {k} has its result already ({})",
                cell.folder(&out).display()
            );
            return Ok(0);
        }
        runner.run(&c, &cases, cell)?;
        return Ok(0);
    }
    if !a.merge {
        let todo = pending(&cells, &out);
        eprintln!(
            "hil: {} of {} cells to run ({} have results), {} at a time",
            todo.len(),
            cells.len(),
            cells.len() - todo.len(),
            a.jobs
        );
        let failed = hil::par::map(
            &todo,
            usize::from(a.jobs),
            |cell| match runner.run(&c, &cases, cell) {
                Ok(_) => {
                    eprintln!(
                        "hil: cell {} done: {} on {}",
                        cell.number, cell.case, cell.device
                    );
                    None
                }
                Err(e) => Some(format!("{e:#}")),
            },
            || Some("the cell's run panicked".to_string()),
        );
        for f in failed.iter().flatten() {
            eprintln!("hil: {f}");
        }
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let merged = report::merge(&c, &cases, &cells, &results(&cells, &out)?);
    report::write(&out, &merged, &cells)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&merged)?);
    } else {
        print!("{}", report::markdown(&merged, &cells));
        eprintln!("hil: the report is in {}", out.join("report.md").display());
    }
    Ok(merged.exit_status())
}
