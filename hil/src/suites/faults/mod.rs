//! The fault matrix (`hil faults`): each fault injected into the emulated devices (from a
//! scenario's fault fields, or by the bench taking the CAN interface down), run through vcan and
//! the pty against the unmodified nav binary, and judged against what nav must do: a counter in
//! its summary, a health bit in NAV_TIME, a mode, an abort reason, and by when.
//!
//! Every case is a short scenario of its own (a static IMU, a parked vehicle navigating with its
//! receiver, or a north-finding drill) with one fault; the whole matrix runs in one guest boot.
//! Detection latency is measured on the bus: the first NAV_TIME carrying the health bit (or the
//! mode) after the injection, in IMU time.

mod bus;
mod gps;
mod imu;
mod physical;
mod turntable;

use crate::report::RunReport;
use crate::run::{RunOptions, run_here};
use crate::scenario::Scenario;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The scenario a fault is injected into.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Base {
    /// The IMU alone, static, 6 s.
    Imu,
    /// A parked vehicle navigating with its receiver (surveyed heading), 16 s.
    Gps,
    /// A north-finding drill with 6 s dwells, cut at 45 s.
    Drill,
}

/// One row of the matrix: the fault and what nav must do.
pub struct FaultCase {
    /// Short name (`--only` takes it).
    pub name: &'static str,
    /// The scenario it goes into.
    pub base: Base,
    /// What is injected, in words.
    pub injected: &'static str,
    /// What nav must do, in words.
    pub expected: &'static str,
    /// IMU time of the injection, s.
    pub at_s: f64,
    /// Put the fault into the scenario (and the bench's actions into the options).
    inject: fn(&mut Scenario, &mut RunOptions),
    /// Judge the run.
    judge: fn(&RunReport, f64) -> Verdict,
}

/// What was seen of one case.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Verdict {
    /// Met the expectation.
    pub pass: bool,
    /// What was observed, in words (the counters and bits the judgement used).
    pub observed: String,
    /// Detection latency (IMU time from the injection to the first NAV_TIME showing it), s.
    pub latency_s: Option<f64>,
}

/// One row of the table.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FaultRow {
    /// Fault name.
    pub fault: String,
    /// Scenario base.
    pub base: Base,
    /// What was injected.
    pub injected: String,
    /// What nav must do.
    pub expected: String,
    /// What was seen.
    pub verdict: Verdict,
    /// nav's exit status.
    pub nav_exit: Option<i32>,
    /// Wall seconds of the run.
    pub wall_seconds: f64,
    /// The run's folder.
    pub run_dir: String,
}

/// The matrix's result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FaultMatrix {
    /// `native` or `vm`.
    pub backend: String,
    /// Rows, in matrix order.
    pub rows: Vec<FaultRow>,
    /// Every row passed.
    pub pass: bool,
}

/// IMU time of NAV_TIME sample count `k` in run `r`, s.
fn imu_time(r: &RunReport, k: u64) -> f64 {
    let first = r.nav.first_sample.unwrap_or(0);
    (k.saturating_sub(first) as f64 + 1.0) / r.scenario.imu.rate_hz
}

/// Latency of health bit `bit` after `at_s`, s.
fn bit_latency(r: &RunReport, bit: &str, at_s: f64) -> Option<f64> {
    r.solution.health_on_at(bit).map(|k| imu_time(r, k) - at_s)
}

/// Latency of mode `mode` after `at_s`, s.
fn mode_latency(r: &RunReport, mode: &str, at_s: f64) -> Option<f64> {
    let first = r.nav.first_sample.unwrap_or(0);
    let from = first + (at_s * r.scenario.imu.rate_hz) as u64;
    r.solution
        .mode_at(mode, from)
        .map(|k| imu_time(r, k) - at_s)
}

fn verdict(pass: bool, observed: String, latency_s: Option<f64>) -> Verdict {
    Verdict {
        pass,
        observed,
        latency_s,
    }
}

/// nav survived: it exited 0 and wrote its summary.
fn survived(r: &RunReport) -> bool {
    r.nav_exit == Some(0)
}

/// nav took IMU data to the run's last half second (navigation went on after the fault).
fn ran_to_end(r: &RunReport) -> bool {
    r.nav
        .last_sample
        .is_some_and(|k| imu_time(r, k) > r.scenario.duration_s - 0.5)
}

fn lat_text(l: Option<f64>) -> String {
    l.map_or("never".into(), |l| format!("{l:.3} s"))
}

/// The counter jump of `imu-counter-jump`, samples.
const COUNTER_JUMP: u64 = 30_000;

/// The matrix, in table order.
pub fn matrix() -> Vec<FaultCase> {
    let groups: [fn() -> Vec<FaultCase>; 9] = [
        imu::frames,
        imu::sensor,
        bus::interface,
        bus::traffic,
        physical::cases,
        bus::nav_process,
        gps::stream,
        gps::device,
        turntable::cases,
    ];
    groups.into_iter().flat_map(|g| g()).collect()
}

fn tt_faults(s: &mut Scenario, f: impl FnOnce(&mut emulators::turntable::TurntableFaults)) {
    if let Some(t) = s.turntable.as_mut() {
        f(&mut t.faults);
    }
}

/// The end position error of a navigating run (nav's final output against the truth), m.
fn end_error(r: &RunReport) -> Option<f64> {
    let drive = emulators::drive::Drive::plan(r.scenario.drive.as_ref()?).ok()?;
    let imu = r.scenario.imu.oscillator().from_first_sample();
    crate::engine::scoring::score_summary(&drive, &r.nav, &imu).map(|n| n.position_error_m)
}

/// What nav must do with a frame overtaken on the bus.
const LATE_FRAME: &str = "the late frame counted and dropped, the gap it left counted and differenced across (cumulative counters: no angle lost, attitude valid), imu_gaps health bit within 0.1 s";

/// A frame overtaken on the bus: dropped and counted, the gap differenced across, no
/// re-synchronisation, the attitude valid, `imu_gaps` within 0.1 s.
fn late_frame(r: &RunReport, at: f64) -> Verdict {
    let i = &r.nav.imu;
    let l = bit_latency(r, "imu_gaps", at);
    let pass = survived(r)
        && i.gaps >= 1
        && i.late_frames == 1
        && i.backwards == 0
        && r.nav.attitude.valid
        && l.is_some_and(|l| (0.0..=0.1).contains(&l));
    verdict(
        pass,
        format!(
            "late frames {}, gaps {}, missing {}, re-synchronisations {}, attitude valid {}, imu_gaps after {}",
            i.late_frames,
            i.gaps,
            i.missing_samples,
            i.backwards,
            r.nav.attitude.valid,
            lat_text(l)
        ),
        l,
    )
}

/// A GPS outage from `at` to `end`: Coasting within 3.5 s of its start, GpsAided again after
/// its end.
fn gps_outage(r: &RunReport, at: f64, end: f64, void: bool) -> Verdict {
    let l = mode_latency(r, "Coasting", at);
    let stale = bit_latency(r, "gps_stale", at);
    let back = mode_latency(r, "GpsAided", end);
    let no_fix = r.nav.gps.as_ref().map_or(0, |g| g.stats.no_fix);
    let pass = survived(r)
        && l.is_some_and(|l| (0.0..=3.5).contains(&l))
        && stale.is_some()
        && back.is_some()
        && (!void || no_fix >= 5);
    verdict(
        pass,
        format!(
            "Coasting after {}, gps_stale seen {}, GpsAided again {}, void fixes {no_fix}",
            lat_text(l),
            if stale.is_some() { "yes" } else { "no" },
            if back.is_some() { "yes" } else { "no" }
        ),
        l,
    )
}

/// North-finding aborted with `word` in its reason and the turntable health bit set; latency
/// from `at` to the bit.
fn nf_abort(r: &RunReport, at: f64, word: &str) -> Verdict {
    let abort = r.nav.north_finding.as_ref().and_then(|n| n.abort.clone());
    let l = bit_latency(r, "turntable", at);
    let pass = survived(r)
        && abort
            .as_deref()
            .is_some_and(|a| a.to_lowercase().contains(word))
        && l.is_some();
    verdict(
        pass,
        format!(
            "aborted: {}; turntable bit after {}",
            abort.as_deref().unwrap_or("no"),
            lat_text(l)
        ),
        l,
    )
}

/// The mechanism lost mid-drill: north-finding went on by a static gyrocompass (`word` in its
/// reason), NAV_TIME said so (mode Gyrocompass), its heading within 3 of its own (larger)
/// sigmas of the truth, the turntable health bit set; latency from `at` to the mode.
fn nf_degraded(r: &RunReport, at: f64, word: &str) -> Verdict {
    let nf = r.procedures.north_finding.as_ref();
    let why = nf.and_then(|o| o.degraded.clone());
    let (err, sigma) = nf.map_or((None, None), |o| (o.error_deg, o.sigma_deg));
    let within = matches!((err, sigma), (Some(e), Some(s)) if e.abs() <= 3.0 * s);
    let mode = mode_latency(r, "Gyrocompass", at);
    let bit = bit_latency(r, "turntable", at);
    let pass = survived(r)
        && why
            .as_deref()
            .is_some_and(|a| a.to_lowercase().contains(word))
        && within
        && mode.is_some()
        && bit.is_some();
    let f = |x: Option<f64>| x.map_or("--".to_string(), |v| format!("{v:+.4}"));
    verdict(
        pass,
        format!(
            "degraded: {}; heading error {} deg, sigma {} deg ({} sigma); NAV_TIME Gyrocompass after {}; turntable bit after {}",
            why.as_deref().unwrap_or("no"),
            f(err),
            sigma.map_or("--".into(), |s| format!("{s:.4}")),
            match (err, sigma) {
                (Some(e), Some(s)) => format!("{:.2}", e.abs() / s.max(1e-12)),
                _ => "--".into(),
            },
            lat_text(mode),
            lat_text(bit)
        ),
        mode,
    )
}

/// The scenario of base `b` for fault `name`.
pub fn base_scenario(b: Base, name: &str) -> Result<Scenario> {
    let mut s = match b {
        Base::Imu => {
            let mut s = Scenario::builtin_static();
            s.duration_s = 6.0;
            s
        }
        Base::Gps => {
            let mut s = Scenario::from_text(include_str!("../../../../scenarios/drive-gps.toml"))
                .context("the drive-gps scenario")?;
            s.duration_s = 16.0;
            if let Some(d) = s.drive.as_mut() {
                // parked the whole run: the faults, not the drive, are what is looked at
                d.start_wait_s = 1000.0;
            }
            s
        }
        Base::Drill => {
            let mut s = crate::procedures::northfinding::scenario(30.0, 45.0, 6.0, 7);
            s.duration_s = 45.0;
            s
        }
    };
    s.name = format!("fault-{name}");
    s.speed = 10.0;
    Ok(s)
}

/// Settings of a matrix run.
pub struct FaultOptions {
    /// CAN interface.
    pub iface: String,
    /// Output folder (one sub-folder per case).
    pub out: std::path::PathBuf,
    /// The nav binary.
    pub nav_bin: std::path::PathBuf,
    /// Only these faults (all when empty).
    pub only: Vec<String>,
    /// Speed factor.
    pub speed: f64,
    /// Print a line per case.
    pub progress: bool,
    /// Cases run side by side, each on an interface of its own (`iface`, then `iface-1`,
    /// `iface-2`, ...). Every case is in lockstep with its nav, so its result does not depend
    /// on what runs beside it.
    pub jobs: usize,
}

/// One case of the matrix on `iface`: its row (a failed row when the run could not be made).
fn run_case(c: &FaultCase, o: &FaultOptions, iface: &str, backend: &str) -> FaultRow {
    let dir = o.out.join(c.name);
    let t0 = std::time::Instant::now();
    let row = |verdict: Verdict, nav_exit: Option<i32>, wall_seconds: f64| FaultRow {
        fault: c.name.into(),
        base: c.base,
        injected: c.injected.into(),
        expected: c.expected.into(),
        verdict,
        nav_exit,
        wall_seconds,
        run_dir: dir.display().to_string(),
    };
    let run = || -> Result<RunReport> {
        let mut s = base_scenario(c.base, c.name)?;
        s.speed = o.speed;
        let mut opts = RunOptions {
            // the matrix's own table (faults.md) is the report of its runs
            html: false,
            ..RunOptions::new(iface, dir.clone(), o.nav_bin.clone())
        };
        (c.inject)(&mut s, &mut opts);
        s.check()
            .with_context(|| format!("the scenario of fault {}", c.name))?;
        run_here(&s, &opts, backend)
    };
    match run() {
        Ok(r) => row((c.judge)(&r, c.at_s), r.nav_exit, r.wall_seconds),
        Err(e) => row(
            verdict(false, format!("the run failed: {e:#}"), None),
            None,
            t0.elapsed().as_secs_f64(),
        ),
    }
}

/// Run the matrix here (the kernel must have CAN).
pub fn run_matrix(o: &FaultOptions, backend: &str) -> Result<FaultMatrix> {
    let cases: Vec<FaultCase> = matrix()
        .into_iter()
        .filter(|c| o.only.is_empty() || o.only.iter().any(|n| n == c.name))
        .collect();
    if cases.is_empty() {
        bail!(
            "--only names no fault of the matrix ({})",
            matrix()
                .iter()
                .map(|c| c.name)
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    std::fs::create_dir_all(&o.out).with_context(|| format!("creating {}", o.out.display()))?;
    let jobs = o.jobs.clamp(1, cases.len());
    let next = std::sync::atomic::AtomicUsize::new(0);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let slots: Vec<std::sync::Mutex<Option<FaultRow>>> =
        cases.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for job in 0..jobs {
            let iface = if job == 0 {
                o.iface.clone()
            } else {
                format!("{}-{job}", o.iface)
            };
            let (cases, next, done, slots) = (&cases, &next, &done, &slots);
            scope.spawn(move || {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(c) = cases.get(i) else { break };
                    let t0 = std::time::Instant::now();
                    let row = run_case(c, o, &iface, backend);
                    if o.progress {
                        let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                        eprintln!(
                            "hil faults: {n}/{} {} {} ({:.1} s): {}",
                            cases.len(),
                            if row.verdict.pass { "PASS" } else { "FAIL" },
                            row.fault,
                            t0.elapsed().as_secs_f64(),
                            row.verdict.observed
                        );
                    }
                    if let Ok(mut slot) = slots[i].lock() {
                        *slot = Some(row);
                    }
                }
            });
        }
    });
    let rows: Vec<FaultRow> = slots
        .into_iter()
        .zip(&cases)
        .map(|(slot, c)| {
            slot.into_inner()
                .ok()
                .flatten()
                .unwrap_or_else(|| FaultRow {
                    fault: c.name.into(),
                    base: c.base,
                    injected: c.injected.into(),
                    expected: c.expected.into(),
                    verdict: verdict(false, "the case's worker stopped before it".into(), None),
                    nav_exit: None,
                    wall_seconds: 0.0,
                    run_dir: o.out.join(c.name).display().to_string(),
                })
        })
        .collect();
    let m = FaultMatrix {
        backend: backend.into(),
        pass: rows.iter().all(|r| r.verdict.pass),
        rows,
    };
    write(&m, &o.out)?;
    Ok(m)
}

/// Write `faults.json` and `faults.md`.
pub fn write(m: &FaultMatrix, out: &Path) -> Result<()> {
    std::fs::write(out.join("faults.json"), serde_json::to_string_pretty(m)?)
        .context("writing faults.json")?;
    std::fs::write(out.join("faults.md"), markdown(m)).context("writing faults.md")?;
    crate::report::page::folder_page(out, "Fault matrix", &markdown(m))?;
    Ok(())
}

/// The table as Markdown.
pub fn markdown(m: &FaultMatrix) -> String {
    let mut t = crate::table::Table::left(&[
        "fault",
        "injected",
        "expected",
        "observed",
        "detection latency",
        "result",
    ]);
    for r in &m.rows {
        t.row([
            r.fault.to_string(),
            r.injected.to_string(),
            r.expected.to_string(),
            r.verdict.observed.clone(),
            r.verdict
                .latency_s
                .map_or("--".into(), |l| format!("{l:.3} s")),
            (if r.verdict.pass { "pass" } else { "**FAIL**" }).to_string(),
        ]);
    }
    format!(
        "# Fault matrix ({})\n\n{} of {} faults handled as expected.\n\n{}",
        m.backend,
        m.rows.iter().filter(|r| r.verdict.pass).count(),
        m.rows.len(),
        t.finish()
    )
}

/// The matrix as a JUnit suite (`hil faults --junit`): a case per row with its run's wall
/// time, failing with what was expected and what was observed.
pub fn junit(m: &FaultMatrix) -> crate::junit::Suite {
    let cases = m
        .rows
        .iter()
        .map(|r| {
            let latency = r
                .verdict
                .latency_s
                .map_or("--".into(), |l| format!("{l:.3} s"));
            crate::junit::Case::judged(
                "hil faults",
                &r.fault,
                r.wall_seconds,
                r.verdict.pass,
                format!("expected: {}; observed: {}", r.expected, r.verdict.observed),
                format!(
                    "injected: {}\nexpected: {}\nobserved: {}\ndetection latency: {latency}\nnav's exit status: {}\nrun folder: {}",
                    r.injected,
                    r.expected,
                    r.verdict.observed,
                    crate::check::exit_words(r.nav_exit),
                    r.run_dir
                ),
            )
        })
        .collect();
    let time = m.rows.iter().map(|r| r.wall_seconds).sum();
    crate::junit::Suite::new(&format!("fault matrix ({})", m.backend), time, cases)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The matrix covers at least 16 faults, each name once, and every case's scenario passes
    /// its checks with the fault in it.
    #[test]
    fn every_case_builds_a_valid_scenario() {
        let m = matrix();
        assert!(m.len() >= 16, "{} faults", m.len());
        let mut names: Vec<&str> = m.iter().map(|c| c.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), m.len(), "a name is used twice");
        for c in &m {
            let mut s = base_scenario(c.base, c.name).unwrap();
            let mut o = RunOptions::new("vcan0", "/tmp".into(), "nav".into());
            (c.inject)(&mut s, &mut o);
            s.check().unwrap_or_else(|e| panic!("{}: {e:#}", c.name));
            assert!(c.at_s < s.duration_s, "{}", c.name);
        }
    }
}
