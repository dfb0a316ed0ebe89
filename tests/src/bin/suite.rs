//! `suite`: the test runner of `./run-tests`. Runs every test of Rust test binaries in a process
//! of its own, several at a time, and measures each one: its wall time and the CPU time of its
//! process tree (what it spent running; the rest it spent waiting on a guest, a clock, a peer or a CPU).
//! Then one report of everything `./run-tests` did: a table slowest first, and JUnit XML
//! (`target/junit.xml`) with every test, every stage and every fault-matrix row as a test case.
//!
//! - `suite discover OUT [-- CARGO-TEST-ARGS]`: the test binaries `cargo test --no-run` builds
//!   (each with the folder cargo would run it in), as a JSON list in OUT.
//! - `suite run --binaries LIST --name NAME --results FILE`: every test of those binaries, `--jobs`
//!   at a time, each `BINARY --exact NAME --nocapture` with its output in its own log; a line
//!   per test as it ends, and a failed test's output at once. Tests whose previous run (the
//!   results file, when it is there) took longest start first. Exit status 1 when one failed.
//! - `suite report --results FILE... --stages FILE --junit OUT`: the table and the XML. A test
//!   can add its own cases (a fault matrix's rows): JUnit files it writes into the folder its
//!   `SUITE_JUNIT_DIR` names go into the report as suites of their own.
//!
//! It is what cargo-nextest does for one machine, kept to what the bench needs: the end-to-end
//! tests run inside the QEMU guest, where no cargo is.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use hil::junit::{Case, Foreign, Outcome, Suite};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, VecDeque};
use std::io::Write as _;
use std::os::unix::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[derive(Parser)]
#[command(about = "Runs Rust test binaries a test per process, measures each, reports JUnit XML")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Write the test binaries `cargo test --no-run ARGS` builds to OUT (JSON).
    Discover {
        /// The list to write.
        out: PathBuf,
        /// Arguments of `cargo test` (after `--`), e.g. --workspace.
        #[arg(last = true)]
        cargo: Vec<String>,
    },
    /// Run every test of the binaries in LIST, each in a process of its own.
    Run(RunArgs),
    /// The table of every test and stage, slowest first, and the JUnit XML.
    Report(ReportArgs),
}

#[derive(clap::Args)]
struct RunArgs {
    /// The binaries (a list `suite discover` wrote, or `NAME=PATH[@DIR]`, repeated).
    #[arg(long, required = true)]
    binaries: Vec<String>,
    /// The suite's name (the test cases' group in the report).
    #[arg(long)]
    name: String,
    /// Only the binaries of these names (comma-separated; default all).
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Run the tests marked #[ignore] (and only those), as `cargo test -- --ignored`.
    #[arg(long)]
    ignored: bool,
    /// Tests at a time (default: the CPUs here).
    #[arg(long)]
    jobs: Option<usize>,
    /// Run the tests at this nice value (0-19): tests whose results do not depend on the
    /// machine's load (lockstep) then take only the CPU that tests with deadlines leave.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(i32).range(0..=19))]
    nice: i32,
    /// A test still running after this many seconds is killed and failed.
    #[arg(long, default_value_t = 1800)]
    timeout_s: u64,
    /// Where the results go (JSON).
    #[arg(long)]
    results: PathBuf,
    /// A previous run's results, to start the tests that took longest first (default: the
    /// results file, when it is there).
    #[arg(long)]
    history: Option<PathBuf>,
    /// Tests known to be slow, one name per line (`#` comments): started first, in that order,
    /// when no previous run says how long they took (a fresh clone).
    #[arg(long)]
    slow_first: Option<PathBuf>,
    /// Tests that run with nothing else of this run beside them (a test whose verdict compares
    /// two of its runs' latencies): first, one after another, before the others start
    /// (comma-separated names, as listed: `module::test`).
    #[arg(long, value_delimiter = ',')]
    alone: Vec<String>,
    /// Folder for each test's output (default: beside the results, `<name>-logs`).
    #[arg(long)]
    logs: Option<PathBuf>,
}

#[derive(clap::Args)]
struct ReportArgs {
    /// Results of `suite run` (one file per suite); missing files are named and skipped.
    #[arg(long, required = true)]
    results: Vec<PathBuf>,
    /// The stages of `./run-tests`: lines `seconds<TAB>status<TAB>name`.
    #[arg(long)]
    stages: Option<PathBuf>,
    /// The JUnit XML to write.
    #[arg(long)]
    junit: PathBuf,
    /// The whole table, as Markdown (the printed one leaves out tests under a second).
    #[arg(long)]
    table: Option<PathBuf>,
    /// Wall time of the whole command, s (for the table's last line).
    #[arg(long)]
    total_s: Option<f64>,
}

/// A test binary and where cargo would run it.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Binary {
    /// Its name in the report: the crate's target, `crate` or `crate::target`.
    name: String,
    /// The executable.
    exe: PathBuf,
    /// Its working folder: its package's folder, as under `cargo test`.
    cwd: PathBuf,
}

/// One test's result.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct TestResult {
    /// The suite it ran in.
    suite: String,
    /// Its binary's name.
    binary: String,
    /// The test's name.
    name: String,
    /// "passed", "failed" or "skipped".
    outcome: String,
    /// Wall time, s.
    time_s: f64,
    /// When it started (s since the Unix epoch, by the clock of the machine it ran on): the
    /// suite's timeline, which tests ran beside which.
    #[serde(default)]
    started_unix_s: f64,
    /// CPU time of its process and every child it waited for, s.
    cpu_s: f64,
    /// Its output.
    log: PathBuf,
    /// Why it failed, in a line (empty when it passed).
    message: String,
    /// Its JUnit folder (files a test writes there become suites of the report).
    junit_dir: PathBuf,
}

fn main() {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Discover { out, cargo } => discover(&out, &cargo).map(|()| 0),
        Cmd::Run(a) => run(&a),
        Cmd::Report(a) => report(&a).map(|()| 0),
    };
    match r {
        Ok(code) => std::process::exit(code),
        Err(e) => {
            eprintln!("suite: {e:#}");
            std::process::exit(2);
        }
    }
}

fn discover(out: &Path, cargo_args: &[String]) -> Result<()> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let o = std::process::Command::new(cargo)
        .arg("test")
        .args(cargo_args)
        .args(["--no-run", "--message-format=json"])
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("running cargo test --no-run")?;
    if !o.status.success() {
        bail!("cargo test --no-run failed ({})", o.status);
    }
    let mut bins = Vec::new();
    for line in String::from_utf8_lossy(&o.stdout).lines() {
        let Ok(m) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let (Some(exe), Some(manifest)) = (m["executable"].as_str(), m["manifest_path"].as_str())
        else {
            continue;
        };
        if m["profile"]["test"] != true {
            continue;
        }
        let package = m["package_id"].as_str().unwrap_or_default();
        let krate = package_name(package);
        let target = m["target"]["name"].as_str().unwrap_or_default();
        let kind = m["target"]["kind"][0].as_str().unwrap_or_default();
        let name = match kind {
            "lib" => krate.clone(),
            "bin" => format!("{krate}::bin::{target}"),
            _ => format!("{krate}::{target}"),
        };
        let cwd = Path::new(manifest).parent().unwrap_or(Path::new("."));
        bins.push(Binary {
            name,
            exe: exe.into(),
            cwd: cwd.into(),
        });
    }
    bins.sort_by(|a, b| a.name.cmp(&b.name));
    std::fs::write(out, serde_json::to_string_pretty(&bins)?)
        .with_context(|| format!("writing {}", out.display()))?;
    eprintln!("suite: {} test binaries in {}", bins.len(), out.display());
    Ok(())
}

/// The package's name in a package id (`path+file:///x/nav#0.1.0`, `registry+...#name@1.0`).
fn package_name(id: &str) -> String {
    let tail = id.rsplit('#').next().unwrap_or(id);
    match tail.split_once('@') {
        Some((name, _)) => name.to_string(),
        None => {
            // `.../nav#0.1.0`: the name is the path's last part
            let head = id.split('#').next().unwrap_or(id);
            head.rsplit('/').next().unwrap_or(head).to_string()
        }
    }
}

fn binaries(specs: &[String], only: &[String]) -> Result<Vec<Binary>> {
    let mut out = Vec::new();
    for s in specs {
        if let Some((name, rest)) = s.split_once('=') {
            let (exe, cwd) = rest.split_once('@').unwrap_or((rest, "."));
            out.push(Binary {
                name: name.into(),
                exe: exe.into(),
                cwd: cwd.into(),
            });
        } else {
            let text = std::fs::read_to_string(s).with_context(|| format!("reading {s}"))?;
            let list: Vec<Binary> =
                serde_json::from_str(&text).with_context(|| format!("{s}: not a binaries list"))?;
            out.extend(list);
        }
    }
    if !only.is_empty() {
        for o in only {
            if !out.iter().any(|b| &b.name == o) {
                bail!("--only {o}: no such test binary");
            }
        }
        out.retain(|b| only.contains(&b.name));
    }
    Ok(out)
}

/// The tests of `b` (only the #[ignore] ones when `ignored`).
fn list(b: &Binary, ignored: bool) -> Result<Vec<String>> {
    let mut c = std::process::Command::new(&b.exe);
    c.args(["--list", "--format", "terse"]).current_dir(&b.cwd);
    if ignored {
        c.arg("--ignored");
    }
    let o = c
        .output()
        .with_context(|| format!("{}: listing its tests ({})", b.name, b.exe.display()))?;
    if !o.status.success() {
        bail!(
            "{}: --list failed: {}",
            b.name,
            String::from_utf8_lossy(&o.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| l.strip_suffix(": test"))
        .map(str::to_string)
        .collect())
}

/// Every test of `bins` to run, slowest first: by the last run's times, else by the
/// `--slow-first` list, else in the binaries' order.
fn ordered(a: &RunArgs, bins: &[Binary]) -> Result<Vec<(Binary, String)>> {
    // the previous run's times, to start the longest first
    let before: BTreeMap<(String, String), f64> =
        std::fs::read_to_string(a.history.as_ref().unwrap_or(&a.results))
            .ok()
            .and_then(|t| serde_json::from_str::<Vec<TestResult>>(&t).ok())
            .unwrap_or_default()
            .into_iter()
            .map(|r| ((r.binary, r.name), r.time_s))
            .collect();
    let slow: Vec<String> = match &a.slow_first {
        Some(p) => std::fs::read_to_string(p)
            .with_context(|| format!("reading {}", p.display()))?
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
            .map(str::to_string)
            .collect(),
        None => Vec::new(),
    };
    let mut queue = Vec::new();
    for b in bins {
        let ignored_ones = list(b, true)?;
        let tests = if a.ignored {
            ignored_ones
        } else {
            list(b, false)?
                .into_iter()
                .filter(|t| !ignored_ones.contains(t))
                .collect()
        };
        for t in tests {
            // the last run's time; else the list's rank; else first of all but the listed
            let prior = before
                .get(&(b.name.clone(), t.clone()))
                .copied()
                .or_else(|| slow.iter().position(|n| n == &t).map(|k| 2e9 - k as f64))
                .unwrap_or(1e9);
            queue.push((prior, b.clone(), t));
        }
    }
    // slowest first, else in the binaries' order
    queue.sort_by(|x, y| y.0.total_cmp(&x.0));
    Ok(queue.into_iter().map(|(_, b, t)| (b, t)).collect())
}

fn run(a: &RunArgs) -> Result<i32> {
    let bins = binaries(&a.binaries, &a.only)?;
    let logs = a.logs.clone().unwrap_or_else(|| {
        let stem = a.results.with_extension("");
        PathBuf::from(format!("{}-logs", stem.display()))
    });
    std::fs::create_dir_all(&logs).with_context(|| format!("creating {}", logs.display()))?;
    let queue = ordered(a, &bins)?;
    let jobs = a.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(2, std::num::NonZeroUsize::get)
    });
    let total = queue.len();
    eprintln!(
        "suite {}: {total} tests of {} binaries, {jobs} at a time",
        a.name,
        bins.len()
    );
    let started = Instant::now();
    let (alone, queue): (Vec<_>, Vec<_>) = queue
        .into_iter()
        .partition(|(_, t)| a.alone.iter().any(|n| n == t));
    let mut done = Vec::new();
    for (b, t) in alone {
        eprintln!("suite {}: {t} runs alone", a.name);
        let r = run_one(
            &a.name,
            &b,
            &t,
            &logs,
            (a.ignored, a.nice),
            Duration::from_secs(a.timeout_s),
        );
        announce(&r);
        done.push(r);
    }
    let queue = Arc::new(Mutex::new(queue.into_iter().collect::<VecDeque<_>>()));
    let results = Arc::new(Mutex::new(done));
    let workers: Vec<_> = (0..jobs.max(1))
        .map(|_| {
            let (queue, results) = (queue.clone(), results.clone());
            let (name, logs, ignored, timeout) = (
                a.name.clone(),
                logs.clone(),
                a.ignored,
                Duration::from_secs(a.timeout_s),
            );
            let nice = a.nice;
            std::thread::spawn(move || {
                loop {
                    let next = queue.lock().map(|mut q| q.pop_front());
                    let Ok(Some((b, t))) = next else { break };
                    let r = run_one(&name, &b, &t, &logs, (ignored, nice), timeout);
                    announce(&r);
                    if let Ok(mut rs) = results.lock() {
                        rs.push(r);
                    }
                }
            })
        })
        .collect();
    for w in workers {
        let _ = w.join();
    }
    let mut results = results.lock().map(|r| r.clone()).unwrap_or_default();
    results.sort_by(|x, y| (&x.binary, &x.name).cmp(&(&y.binary, &y.name)));
    std::fs::write(&a.results, serde_json::to_string_pretty(&results)?)
        .with_context(|| format!("writing {}", a.results.display()))?;
    let failed: Vec<&TestResult> = results.iter().filter(|r| r.outcome == "failed").collect();
    eprintln!(
        "suite {}: {} passed, {} failed of {total} in {:.1} s",
        a.name,
        results.iter().filter(|r| r.outcome == "passed").count(),
        failed.len(),
        started.elapsed().as_secs_f64()
    );
    for f in &failed {
        eprintln!("  FAILED {}::{}: {}", f.binary, f.name, f.message);
    }
    Ok(if failed.is_empty() && results.len() == total {
        0
    } else {
        1
    })
}

/// A test's line as it ends; a failure's output follows at once.
fn announce(r: &TestResult) {
    let cpu = if r.time_s > 0.0 {
        100.0 * r.cpu_s / r.time_s
    } else {
        0.0
    };
    let mut e = std::io::stderr().lock();
    let _ = writeln!(
        e,
        "{:<6} {:>7.1} s {:>5.0} % CPU  {}::{}",
        match r.outcome.as_str() {
            "passed" => "ok",
            "skipped" => "SKIP",
            _ => "FAILED",
        },
        r.time_s,
        cpu,
        r.binary,
        r.name
    );
    if r.outcome != "failed" && !r.message.is_empty() {
        let _ = writeln!(e, "       ({})", r.message);
    }
    if r.outcome == "failed" {
        let text = std::fs::read_to_string(&r.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        let from = lines.len().saturating_sub(80);
        let _ = writeln!(
            e,
            "------ {}::{}: the last {} lines of its output ({}) ------",
            r.binary,
            r.name,
            lines.len() - from,
            r.log.display()
        );
        for l in &lines[from..] {
            let _ = writeln!(e, "{l}");
        }
        let _ = writeln!(e, "------");
    }
}

/// A file name for a test's log.
fn file_name(binary: &str, test: &str) -> String {
    format!("{binary}--{test}")
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn run_one(
    suite: &str,
    b: &Binary,
    test: &str,
    logs: &Path,
    (ignored, nice): (bool, i32),
    timeout: Duration,
) -> TestResult {
    let base = file_name(&b.name, test);
    let log = logs.join(format!("{base}.log"));
    let junit_dir = logs.join(format!("{base}.junit"));
    let mut r = TestResult {
        suite: suite.into(),
        binary: b.name.clone(),
        name: test.into(),
        outcome: "failed".into(),
        time_s: 0.0,
        started_unix_s: 0.0,
        cpu_s: 0.0,
        log: log.clone(),
        message: String::new(),
        junit_dir: junit_dir.clone(),
    };
    let _ = std::fs::remove_dir_all(&junit_dir);
    if let Err(e) = std::fs::create_dir_all(&junit_dir) {
        r.message = format!("creating {}: {e}", junit_dir.display());
        return r;
    }
    let out = match std::fs::File::create(&log) {
        Ok(f) => f,
        Err(e) => {
            r.message = format!("creating {}: {e}", log.display());
            return r;
        }
    };
    let err = match out.try_clone() {
        Ok(f) => f,
        Err(e) => {
            r.message = format!("{}: {e}", log.display());
            return r;
        }
    };
    let mut c = std::process::Command::new(&b.exe);
    c.args([test, "--exact", "--nocapture", "--test-threads=1"])
        .current_dir(&b.cwd)
        .env("SUITE_JUNIT_DIR", &junit_dir)
        .stdin(std::process::Stdio::null())
        .stdout(out)
        .stderr(err)
        // its own process group: a test that outlives its time is killed with what it started
        .process_group(0);
    if ignored {
        c.arg("--ignored");
    }
    if nice > 0 {
        // SAFETY: setpriority on the child itself between fork and exec (async-signal-safe);
        // what it starts inherits it
        unsafe {
            c.pre_exec(move || {
                if libc::setpriority(libc::PRIO_PROCESS, 0, nice) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
    let start = Instant::now();
    r.started_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64());
    let child = match c.spawn() {
        Ok(c) => c,
        Err(e) => {
            r.message = format!("starting {}: {e}", b.exe.display());
            return r;
        }
    };
    let (status, cpu) = wait_with_usage(child.id(), timeout);
    r.time_s = start.elapsed().as_secs_f64();
    r.cpu_s = cpu;
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    classify(&mut r, status, &text, timeout);
    r
}

/// A test's outcome and its line of explanation from its exit `status` (none: killed after
/// `timeout`) and its output `text`.
fn classify(r: &mut TestResult, status: Option<i32>, text: &str, timeout: Duration) {
    let ran = text.contains("test result: ok. 1 passed");
    r.message.clear();
    match status {
        // a test that found what it needs absent (../shared's captures, the guest's Python)
        // returns early saying so: skipped, with its reason, not passed
        Some(0) if ran => match skip_reason(text) {
            Some(why) => {
                r.outcome = "skipped".into();
                r.message = why;
            }
            None => {
                let mut notes = Vec::new();
                // a lockstep run whose bench was starved past nav's watchdog, run again
                let again = text.matches(e2e::STARVED_RERUN).count();
                if again > 0 {
                    notes.push(format!(
                        "{again} of its runs ran once more: the bench was starved of CPU past nav's watchdog"
                    ));
                }
                // a free-running run the bench stopped (the machine behind real time), run again
                let again = text.matches(e2e::FREE_RERUN).count();
                if again > 0 {
                    notes.push(format!(
                        "{again} of its runs ran once more: the machine did not keep real time"
                    ));
                }
                // a free-running test whose host could not keep real time returns without
                // judging (tests/tests/free.rs): not all it claims was checked, so skipped,
                // with the reason, not passed
                let unjudged = text.matches("; no verdict on ").count();
                r.outcome = if unjudged > 0 {
                    notes.insert(
                        0,
                        format!(
                            "{unjudged} of its runs gave no verdict: the machine could not keep real time"
                        ),
                    );
                    "skipped"
                } else {
                    "passed"
                }
                .into();
                r.message = notes.join("; ");
            }
        },
        Some(0) if text.contains(" 1 ignored") => {
            r.outcome = "skipped".into();
            r.message = "ignored".into();
        }
        Some(0) => r.message = "the test binary ran no test of that name".into(),
        None => r.message = format!("still running after {} s: killed", timeout.as_secs()),
        Some(code) => r.message = failure_line(text, code),
    }
}

/// Why a test that passed skipped its work: the rest of its first line with `SKIPPED: `.
fn skip_reason(text: &str) -> Option<String> {
    text.lines().find_map(|l| {
        l.split_once("SKIPPED: ")
            .map(|(_, why)| why.trim().to_string())
    })
}

/// The line that says why a test failed: its panic's message, else its exit status.
fn failure_line(text: &str, code: i32) -> String {
    let mut lines = text.lines();
    while let Some(l) = lines.next() {
        if l.starts_with("thread '") && l.contains("panicked at") {
            let what = lines.next().unwrap_or_default();
            return format!("{} {}", l.trim(), what.trim())
                .chars()
                .take(400)
                .collect();
        }
    }
    if code >= 128 {
        format!("killed by signal {}", code - 128)
    } else {
        format!("exit status {code}")
    }
}

/// Wait for process `pid` (killing its group after `timeout`): its exit code (128 + signal when
/// a signal ended it; None when it timed out) and the CPU time of it and its waited-for children.
fn wait_with_usage(pid: u32, timeout: Duration) -> (Option<i32>, f64) {
    let start = Instant::now();
    let pid = pid as libc::pid_t;
    let mut killed = false;
    loop {
        let mut status: libc::c_int = 0;
        // SAFETY: rusage is plain data that wait4 fills; status is a valid out pointer
        let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
        let flags = if killed { 0 } else { libc::WNOHANG };
        let got = unsafe { libc::wait4(pid, &mut status, flags, &mut ru) };
        if got == pid {
            let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
            let cpu = secs(ru.ru_utime) + secs(ru.ru_stime);
            let code = if killed {
                None
            } else if libc::WIFEXITED(status) {
                Some(libc::WEXITSTATUS(status))
            } else {
                Some(128 + libc::WTERMSIG(status))
            };
            return (code, cpu);
        }
        if got < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::Interrupted {
                return (Some(255), 0.0);
            }
        }
        if !killed && start.elapsed() > timeout {
            // SAFETY: signalling the test's own process group
            unsafe { libc::kill(-pid, libc::SIGKILL) };
            killed = true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn report(a: &ReportArgs) -> Result<()> {
    let mut results: Vec<TestResult> = Vec::new();
    for p in &a.results {
        match std::fs::read_to_string(p) {
            Ok(t) => results.extend(
                serde_json::from_str::<Vec<TestResult>>(&t)
                    .with_context(|| format!("{}: not the results of suite run", p.display()))?,
            ),
            Err(e) => eprintln!("suite: no results in {} ({e}): left out", p.display()),
        }
    }
    let stages = match &a.stages {
        Some(p) => read_stages(p)?,
        None => Vec::new(),
    };
    let (suites, foreign) = junit_suites(&results, &stages)?;
    let xml = hil::junit::document("./run-tests", &suites, &foreign);
    if let Some(d) = a.junit.parent() {
        std::fs::create_dir_all(d)?;
    }
    std::fs::write(&a.junit, xml).with_context(|| format!("writing {}", a.junit.display()))?;
    let (full, short) = table(&results, &stages, a.total_s);
    if let Some(t) = &a.table {
        std::fs::write(t, &full).with_context(|| format!("writing {}", t.display()))?;
    }
    print!("{short}");
    // what was not checked, and why: a green run names its skipped tests
    let skipped: Vec<&TestResult> = results.iter().filter(|r| r.outcome == "skipped").collect();
    if !skipped.is_empty() {
        println!("skipped ({}):", skipped.len());
        for r in skipped {
            println!("  {}::{}: {}", r.binary, r.name, r.message);
        }
    }
    let cases: usize = suites.iter().map(|s| s.cases.len()).sum::<usize>()
        + foreign.iter().map(|f| f.tests).sum::<usize>();
    println!(
        "JUnit XML: {} ({cases} test cases in {} suites){}",
        a.junit.display(),
        suites.len() + foreign.len(),
        a.table
            .as_ref()
            .map(|t| format!("; the whole table: {}", t.display()))
            .unwrap_or_default()
    );
    Ok(())
}

/// A stage of `./run-tests`: (seconds, passed, name).
type Stage = (f64, bool, String);

fn read_stages(p: &Path) -> Result<Vec<Stage>> {
    let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
    let mut out = Vec::new();
    for (i, l) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let mut f = l.splitn(3, '\t');
        let (Some(s), Some(st), Some(name)) = (f.next(), f.next(), f.next()) else {
            bail!(
                "{} line {}: not seconds<TAB>status<TAB>name",
                p.display(),
                i + 1
            );
        };
        let secs: f64 = s
            .trim()
            .parse()
            .with_context(|| format!("{} line {}: seconds {s:?}", p.display(), i + 1))?;
        out.push((secs, st.trim() == "0", name.to_string()));
    }
    Ok(out)
}

fn junit_suites(results: &[TestResult], stages: &[Stage]) -> Result<(Vec<Suite>, Vec<Foreign>)> {
    let mut suites = Vec::new();
    if !stages.is_empty() {
        let cases = stages
            .iter()
            .map(|(s, pass, name)| {
                Case::judged(
                    "run-tests",
                    name,
                    *s,
                    *pass,
                    format!("the stage failed: {name}"),
                    "its output is in the log of ./run-tests".into(),
                )
            })
            .collect();
        suites.push(Suite::new("stages of ./run-tests", 0.0, cases));
    }
    let mut by_suite: BTreeMap<&str, Vec<&TestResult>> = BTreeMap::new();
    for r in results {
        by_suite.entry(&r.suite).or_default().push(r);
    }
    let mut foreign = Vec::new();
    for (name, rs) in by_suite {
        let mut cases = Vec::new();
        for r in &rs {
            let outcome = match r.outcome.as_str() {
                "passed" => Outcome::Passed,
                "skipped" => Outcome::Skipped {
                    message: r.message.clone(),
                },
                _ => {
                    let text = std::fs::read_to_string(&r.log).unwrap_or_default();
                    let lines: Vec<&str> = text.lines().collect();
                    let tail = lines[lines.len().saturating_sub(200)..].join("\n");
                    Outcome::Failed {
                        message: r.message.clone(),
                        text: format!("{}\n(the whole output: {})", tail, r.log.display()),
                    }
                }
            };
            cases.push(Case {
                name: r.name.clone(),
                classname: r.binary.clone(),
                time_s: r.time_s,
                outcome,
                // a pass with a remark (runs without a verdict) shows it beside the case
                output: if r.outcome == "passed" {
                    r.message.clone()
                } else {
                    String::new()
                },
            });
            foreign.extend(foreign_of(r)?);
        }
        let time = rs.iter().map(|r| r.time_s).sum();
        suites.push(Suite::new(name, time, cases));
    }
    Ok((suites, foreign))
}

/// The JUnit files a test wrote into its folder.
fn foreign_of(r: &TestResult) -> Result<Vec<Foreign>> {
    let Ok(dir) = std::fs::read_dir(&r.junit_dir) else {
        return Ok(Vec::new());
    };
    let mut files: Vec<PathBuf> = dir
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "xml"))
        .collect();
    files.sort();
    files
        .iter()
        .map(|p| {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            hil::junit::foreign(&text, &p.display().to_string())
        })
        .collect()
}

/// The whole table (Markdown) and the printed one (what took a second or more, the rest in a
/// line).
fn table(results: &[TestResult], stages: &[Stage], total_s: Option<f64>) -> (String, String) {
    struct Row {
        what: String,
        kind: String,
        time_s: f64,
        cpu: Option<f64>,
        outcome: String,
    }
    let mut rows: Vec<Row> = stages
        .iter()
        .map(|(s, pass, name)| Row {
            what: name.clone(),
            kind: "stage".into(),
            time_s: *s,
            cpu: None,
            outcome: if *pass { "ok" } else { "FAILED" }.into(),
        })
        .collect();
    rows.extend(results.iter().map(|r| Row {
        what: format!("{}::{}", r.binary, r.name),
        kind: r.suite.clone(),
        time_s: r.time_s,
        cpu: (r.time_s > 0.0).then(|| r.cpu_s / r.time_s),
        outcome: match r.outcome.as_str() {
            "passed" if r.message.is_empty() => "ok".into(),
            "passed" => format!("ok ({})", r.message),
            o => o.to_uppercase(),
        },
    }));
    rows.sort_by(|a, b| b.time_s.total_cmp(&a.time_s));
    let head = "| wall | running | waiting | result | suite | test or stage |\n|---:|---:|---:|---|---|---|\n";
    let line = |r: &Row| {
        let (run, wait) = match r.cpu {
            Some(c) => (
                format!("{:.0} %", 100.0 * c),
                format!("{:.0} %", 100.0 * (1.0 - c).max(0.0)),
            ),
            None => ("".into(), "".into()),
        };
        format!(
            "| {:.1} s | {run} | {wait} | {} | {} | {} |\n",
            r.time_s, r.outcome, r.kind, r.what
        )
    };
    let mut full = String::from(
        "Every test and stage of ./run-tests, slowest first. running: the CPU time of the test's \
         processes over its wall time (200 % = two CPUs busy); waiting: the rest of its wall time \
         (a guest, a clock, a peer, or a CPU busy with other tests).\n\n",
    );
    full.push_str(head);
    let mut short = String::from("\n== where the time went (slowest first)\n");
    short.push_str(head);
    let (mut rest, mut rest_s) = (0, 0.0);
    for r in &rows {
        full.push_str(&line(r));
        if r.time_s >= 1.0 || r.outcome != "ok" {
            short.push_str(&line(r));
        } else {
            rest += 1;
            rest_s += r.time_s;
        }
    }
    if rest > 0 {
        short.push_str(&format!(
            "\nand {rest} tests under a second each, {rest_s:.1} s in all\n"
        ));
    }
    if let Some(t) = total_s {
        let line = format!(
            "\n./run-tests took {} min {:02} s in all (stages overlap: their sum is more)\n",
            (t / 60.0) as u64,
            t as u64 % 60
        );
        full.push_str(&line);
        short.push_str(&line);
    }
    (full, short)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn package_names_from_ids() {
        assert_eq!(package_name("path+file:///work/main/nav#0.1.0"), "nav");
        assert_eq!(
            package_name("path+file:///work/main/tests#e2e@0.1.0"),
            "e2e"
        );
        assert_eq!(
            package_name("registry+https://github.com/rust-lang/crates.io-index#serde@1.0.0"),
            "serde"
        );
    }

    #[test]
    fn a_panic_is_the_failure_line() {
        let t =
            "running 1 test\nthread 'x' panicked at tests/a.rs:3:5:\nassertion failed: 1 == 2\n";
        assert_eq!(
            failure_line(t, 101),
            "thread 'x' panicked at tests/a.rs:3:5: assertion failed: 1 == 2"
        );
        assert_eq!(failure_line("", 137), "killed by signal 9");
        assert_eq!(failure_line("", 1), "exit status 1");
    }

    #[test]
    fn a_test_that_says_it_skipped_has_its_reason() {
        let t = "running 1 test\ntest free::x ... SKIPPED: ../shared/testdata is absent\nok\n\ntest result: ok. 1 passed; 0 failed\n";
        assert_eq!(
            skip_reason(t).as_deref(),
            Some("../shared/testdata is absent")
        );
        assert_eq!(skip_reason("test result: ok. 1 passed"), None);
        // and the runner reports it so, not as passed
        let mut r = TestResult {
            suite: "s".into(),
            binary: "b".into(),
            name: "x".into(),
            outcome: "failed".into(),
            time_s: 0.0,
            started_unix_s: 0.0,
            cpu_s: 0.0,
            log: PathBuf::new(),
            message: String::new(),
            junit_dir: PathBuf::new(),
        };
        classify(&mut r, Some(0), t, Duration::from_secs(1));
        assert_eq!(
            (r.outcome.as_str(), r.message.as_str()),
            ("skipped", "../shared/testdata is absent")
        );
        classify(
            &mut r,
            Some(0),
            "test result: ok. 1 passed",
            Duration::from_secs(1),
        );
        // and nothing of the earlier verdict stays
        assert_eq!((r.outcome.as_str(), r.message.as_str()), ("passed", ""));
        // a run done again because its bench was starved is said
        let again = format!(
            "1 watchdog report(s); {}: [..]\ntest result: ok. 1 passed",
            e2e::STARVED_RERUN
        );
        classify(&mut r, Some(0), &again, Duration::from_secs(1));
        assert_eq!(r.outcome, "passed");
        assert!(
            r.message.starts_with("1 of its runs ran once more"),
            "{}",
            r.message
        );
        // a free-running run the bench stopped, run again and judged: passed, and said
        let again = format!(
            "the bench stopped: \"late\"; {}: [..]\ntest result: ok. 1 passed",
            e2e::FREE_RERUN
        );
        classify(&mut r, Some(0), &again, Duration::from_secs(1));
        assert_eq!(
            (r.outcome.as_str(), r.message.as_str()),
            (
                "passed",
                "1 of its runs ran once more: the machine did not keep real time"
            )
        );
        // and again without a verdict: not passed, skipped with the reason
        let none = format!(
            "{again}\nthe host could not keep real time: \"late\"; no verdict on the device\ntest result: ok. 1 passed"
        );
        classify(&mut r, Some(0), &none, Duration::from_secs(1));
        assert_eq!(r.outcome, "skipped");
        assert!(
            r.message
                .starts_with("1 of its runs gave no verdict: the machine could not keep real time; 1 of its runs ran once more"),
            "{}",
            r.message
        );
    }
}
