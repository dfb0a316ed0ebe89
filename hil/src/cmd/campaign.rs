//! `hil campaign`: several builds through the same cases, one verdict per build and case
//! against the baseline.

use crate::cmd::guest::{absolute, run_in_guest, same_command};
use anyhow::{Context, Result};
use hil::campaign::cells::{Build, Cell, cell_at, cells, check_in_process, shard};
use hil::campaign::report;
use hil::campaign::run::{Runner, results};
use hil::campaign::spec::{Campaign, Case, CaseKind};
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
    #[arg(long, value_name = "K", conflicts_with = "shard")]
    pub(crate) cell: Option<usize>,
    /// Run only part K of N (0-based): the cells whose number is K modulo N that have no result
    /// yet, as a cluster's array task of N does (in one guest where this kernel has no CAN);
    /// no merge.
    #[arg(long, value_name = "K/N", value_parser = hil::experiments::shard::parse)]
    pub(crate) shard: Option<(usize, usize)>,
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
    check_in_process(&c, &cases, &nav)?;
    let cells = cells(&c, &cases, &builds)?;
    Ok((c, cases, cells))
}

/// Whether a cell of `case` needs the bus (every case but an experiment, which runs in
/// process).
fn on_the_bus(cases: &[Case], cell: &Cell) -> bool {
    cases
        .iter()
        .find(|k| k.id == cell.case)
        .is_none_or(|k| !matches!(k.kind, CaseKind::Experiment(_)))
}

/// The plan's cells (their number, device, case, seed, whether done, key) on stdout, as a
/// table or as JSON for a cluster's submitter.
fn print_plan(cells: &[Cell], out: &std::path::Path, json: bool) -> Result<()> {
    if json {
        let plan: Vec<serde_json::Value> = cells
            .iter()
            .map(|k| {
                serde_json::json!({
                    "cell": k.number, "device": k.device, "build": k.build, "case": k.case,
                    "seed": k.seed, "key": k.key, "done": k.done(out),
                })
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&plan)?);
        return Ok(());
    }
    println!(
        "{:>4}  {:<16} {:<32} {:>6}  {:<4} key",
        "cell", "device", "case", "seed", "done"
    );
    for k in cells {
        println!(
            "{:>4}  {:<16} {:<32} {:>6}  {:<4} {}",
            k.number,
            k.device,
            k.case,
            k.seed,
            if k.done(out) { "yes" } else { "no" },
            k.key
        );
    }
    Ok(())
}

/// Run `todo`, `jobs` at a time, each cell's end said; how many could not run (said with why).
fn run_cells(runner: &Runner, c: &Campaign, cases: &[Case], todo: &[&Cell], jobs: usize) -> usize {
    let failed = hil::par::map(
        todo,
        jobs,
        |cell| match runner.run(c, cases, cell) {
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
    failed.iter().flatten().count()
}

/// This command again inside the QEMU guest (this kernel has no CAN), from its parsed
/// arguments: the campaign's file, its nav binaries and scenarios and the output folder shared;
/// the guest runs the cells (and the merge, unless a cell or a part was asked for).
fn in_guest(a: &CampaignArgs, c: &Campaign, cases: &[Case], out: &std::path::Path) -> Result<i32> {
    let (args, mut shares) = same_command(&[("out", out.to_string_lossy().into_owned())], &[])?;
    let mut navs = vec![sibling_binary("nav")?];
    for d in &c.devices {
        if let Some(n) = &d.nav {
            let n = absolute(n)?;
            shares.extend(n.parent().map(std::path::Path::to_path_buf));
            navs.push(n);
        }
    }
    for k in cases {
        let path = match &k.kind {
            CaseKind::Scenario(p) => Some(p),
            CaseKind::Experiment(hil::campaign::spec::Experiment::Navigation(p)) => Some(p),
            _ => None,
        };
        if let Some(p) = path {
            shares.extend(absolute(p)?.parent().map(std::path::Path::to_path_buf));
        }
    }
    shares.sort();
    shares.dedup();
    let json = (a.json && a.cell.is_none() && a.shard.is_none()).then_some("report.json");
    run_in_guest(args, out, shares, navs, json)
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
    if a.plan {
        print_plan(&cells, &out, a.json)?;
        return Ok(0);
    }
    let selected: Vec<&Cell> = match (a.cell, a.shard) {
        (Some(k), _) => vec![cell_at(&cells, k)?],
        (None, Some((k, n))) => shard(&cells, k, n)?,
        (None, None) if a.merge => Vec::new(),
        (None, None) => cells.iter().collect(),
    };
    let todo: Vec<&Cell> = selected.into_iter().filter(|k| !k.done(&out)).collect();
    let here = std::env::var_os(vcan_setup::GUEST_ENV).is_some()
        || matches!(vcan_setup::can_support(), vcan_setup::CanSupport::Available);
    let runner = Runner {
        exe: std::env::current_exe().context("this program's path")?,
        nav_default: sibling_binary("nav")?,
        out: out.clone(),
        iface_prefix: a.iface_prefix.clone(),
        jobs: usize::from(a.jobs),
    };
    if !here && todo.iter().any(|k| on_the_bus(&cases, k)) {
        // the experiments' runs in process here, on this machine's CPU rather than the guest's
        // emulated one (the same results: hil::run::offload's judge does the same), then the
        // cells on the bus in the guest
        let local: Vec<&Cell> = todo
            .iter()
            .copied()
            .filter(|k| !on_the_bus(&cases, k))
            .collect();
        let failed = run_cells(&runner, &c, &cases, &local, usize::from(a.jobs));
        let code = in_guest(&a, &c, &cases, &out)?;
        return Ok(if failed > 0 && code == 0 { 2 } else { code });
    }
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
        let of = match a.shard {
            Some((k, n)) => format!("part {k}/{n}'s {}", shard(&cells, k, n)?.len()),
            None => cells.len().to_string(),
        };
        eprintln!(
            "hil: {} of {of} cells to run, {} at a time",
            todo.len(),
            a.jobs
        );
        let failed = run_cells(&runner, &c, &cases, &todo, usize::from(a.jobs));
        if a.shard.is_some() {
            // a part is one task of a cluster's array: the merge is a job of its own; a part
            // with a cell that could not run fails, so that the cluster says which to run again
            if failed > 0 {
                eprintln!(
                    "hil: {failed} of the part's cells could not run (no result): run the part again"
                );
                return Ok(2);
            }
            return Ok(0);
        }
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let merged = report::merge(&c, &cases, &cells, &results(&cells, &out)?);
    report::write(&out, &merged, &cells)?;
    let cost = hil::campaign::cost::Cost::of(&cells, &out);
    std::fs::write(out.join("cost.md"), cost.markdown())
        .with_context(|| format!("writing {}", out.join("cost.md").display()))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&merged)?);
    } else {
        print!("{}", report::markdown(&merged, &cells));
        eprintln!(
            "hil: the report is in {} (what the cells cost: {})",
            out.join("report.md").display(),
            out.join("cost.md").display()
        );
    }
    Ok(merged.exit_status())
}
