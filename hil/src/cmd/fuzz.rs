//! `hil fuzz`: hostile input for nav's decoders and the bench's parsers.

use crate::cmd::guest::{absolute, default_out};
use anyhow::{Context, Result, bail};
use hil::suites::fuzz::Target;
use std::path::PathBuf;

pub(crate) fn fuzz(
    targets: Vec<Target>,
    inputs: u64,
    seed: u64,
    out: Option<PathBuf>,
    rerun: Vec<PathBuf>,
) -> Result<i32> {
    if !rerun.is_empty() {
        let [t] = targets[..] else {
            bail!("--rerun needs exactly one --target (the target the inputs were kept from)");
        };
        let rs = hil::suites::fuzz::rerun(t, &rerun, seed)?;
        for r in &rs {
            match &r.panic {
                Some(p) => println!(
                    "{}: PANIC after {:.2} ms CPU: {p}",
                    r.file.display(),
                    r.cpu_ms
                ),
                None => println!(
                    "{}: ok, {:.2} ms CPU{}{}",
                    r.file.display(),
                    r.cpu_ms,
                    if r.accepted { ", accepted" } else { "" },
                    if r.cpu_ms > hil::suites::fuzz::HANG.as_secs_f64() * 1e3 {
                        " (HANG)"
                    } else {
                        ""
                    }
                ),
            }
        }
        let bad = rs
            .iter()
            .any(|r| r.panic.is_some() || r.cpu_ms > hil::suites::fuzz::HANG.as_secs_f64() * 1e3);
        return Ok(if bad { 1 } else { 0 });
    }
    if inputs == 0 {
        bail!("--inputs must be positive");
    }
    let targets = if targets.is_empty() {
        vec![Target::Can, Target::Nmea, Target::Config, Target::Scenario]
    } else {
        targets
    };
    let out = absolute(&out.unwrap_or_else(|| default_out("fuzz")))?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let mut reports = Vec::new();
    for t in targets {
        let t0 = std::time::Instant::now();
        let r = hil::suites::fuzz::run(t, inputs, seed, &out, |i| {
            if i > 0 {
                hil::status::count(
                    i as usize,
                    inputs as usize,
                    t0.elapsed().as_secs_f64(),
                    &format!("{t:?} inputs"),
                );
            }
        })?;
        hil::status::line(&format!(
            "hil fuzz: {t:?}: {} inputs, {} panics, {} hangs, slowest {:.2} ms",
            r.inputs, r.panics, r.hangs, r.slowest_ms
        ));
        reports.push(r);
    }
    let md = hil::suites::fuzz::markdown(&reports);
    std::fs::write(out.join("fuzz.md"), &md)?;
    std::fs::write(
        out.join("fuzz.json"),
        serde_json::to_string_pretty(&reports)?,
    )?;
    hil::report::page::folder_page(&out, "Hostile input (hil fuzz)", &md)?;
    print!("{md}");
    for r in &reports {
        for c in &r.crashes {
            println!(" input kept: {}", c.display());
        }
    }
    println!(" files: {}", out.display());
    Ok(if reports.iter().all(|r| r.panics == 0 && r.hangs == 0) {
        0
    } else {
        1
    })
}
