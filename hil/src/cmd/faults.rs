//! `hil faults`: the fault matrix, where vcan is (natively, or all of it in the guest).

use crate::cmd::args::BusArgs;
use crate::cmd::guest::{absolute, default_out, run_in_guest_with_junit, same_command};
use anyhow::{Result, bail};
use hil::run::sibling_binary;
use hil::suites::faults::{FaultOptions, matrix, run_matrix};
use std::path::PathBuf;
use vcan_setup::GUEST_ENV;

#[derive(clap::Args, Clone)]
pub(crate) struct FaultsArgs {
    /// Only these faults (comma-separated names, as in the table).
    #[arg(long, value_delimiter = ',')]
    pub(crate) only: Vec<String>,
    /// Speed factor of every run.
    #[arg(long, value_parser = hil::values::speed, default_value_t = 10.0)]
    pub(crate) speed: f64,
    /// List the faults and exit.
    #[arg(long)]
    pub(crate) list: bool,
    /// Faults run side by side, each on an interface of its own (--iface, then IFACE-1,
    /// IFACE-2, ...). Each run is in lockstep with its nav: the results are the same at any
    /// number.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..=16))]
    pub(crate) jobs: u16,
    /// Also write the result as JUnit XML to FILE, for a CI server (GitLab, Jenkins, GitHub):
    /// a test case per fault, failing with what was expected and observed.
    #[arg(long, value_name = "FILE")]
    pub(crate) junit: Option<PathBuf>,
    /// The nav binary (default: next to hil): another build of nav through the matrix.
    #[arg(long)]
    pub(crate) nav: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) bus: BusArgs,
}

pub(crate) fn faults(a: FaultsArgs) -> Result<i32> {
    if a.list {
        // into a pager or `head`: a closed pipe ends the list, not the program
        use std::io::Write as _;
        let mut o = std::io::stdout().lock();
        for c in matrix() {
            if writeln!(o, "{:<28} {}", c.name, c.injected).is_err() {
                break;
            }
        }
        return Ok(0);
    }
    if !(a.speed.is_finite() && a.speed > 0.0 && a.speed <= 100.0) {
        bail!("--speed must be in (0, 100]");
    }
    let known: Vec<&str> = matrix().iter().map(|c| c.name).collect();
    if let Some(bad) = a.only.iter().find(|n| !known.contains(&n.as_str())) {
        bail!("--only: `{bad}` is not a fault of the matrix (see `hil faults --list`)");
    }
    let out = absolute(&a.bus.out.clone().unwrap_or_else(|| default_out("faults")))?;
    let nav = match &a.nav {
        Some(n) => absolute(n)?,
        None => sibling_binary("nav")?,
    };
    if !a.bus.here() {
        let (args, mut shares) = same_command(
            &[
                ("out", out.to_string_lossy().into_owned()),
                ("nav", nav.to_string_lossy().into_owned()),
            ],
            &["junit"],
        )?;
        shares.extend(nav.parent().map(std::path::Path::to_path_buf));
        let code = run_in_guest_with_junit(
            args,
            &out,
            shares,
            vec![nav],
            a.bus.json.then_some("faults.json"),
            a.junit.as_deref(),
        )?;
        return Ok(code);
    }
    let in_guest = std::env::var_os(GUEST_ENV).is_some();
    let o = FaultOptions {
        iface: a.bus.iface.clone(),
        out: out.clone(),
        nav_bin: nav,
        only: a.only.clone(),
        speed: a.speed,
        progress: !a.bus.json,
        jobs: usize::from(a.jobs),
    };
    let m = run_matrix(&o, if in_guest { "vm" } else { "native" })?;
    if let Some(j) = &a.junit {
        hil::junit::write(j, "hil faults", &[hil::suites::faults::junit(&m)])?;
    }
    if a.bus.json {
        println!("{}", serde_json::to_string_pretty(&m)?);
    } else {
        print!("{}", hil::suites::faults::markdown(&m));
        println!("\n files: {}", out.display());
    }
    Ok(if m.pass { 0 } else { 1 })
}
