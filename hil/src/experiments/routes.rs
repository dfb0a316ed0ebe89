//! The filters over a set of routes (`hil experiment routes`): every shipped drive with a
//! receiver, each filter kind, in process with the bench's devices and nav's pipeline. One table:
//! end and RMS position and velocity error, NEES per degree of freedom, NIS, rejected fixes and
//! integrity alarms; plots of each route's errors against the filter's own sigma.
//!
//! The promise checked: on every route every filter's NEES per degree of freedom lies in
//! [0.5, 2] for position and velocity (the sigmas nav sends are honest) over the drive, in each
//! ten-minute window, inside each outage and in the minute after it ([`Windowed`]); no good fix
//! (its error within 3 of the receiver's own sigma) is refused; and no run ends with a
//! velocity error above 1 m/s without nav's integrity monitor having flagged it.

use crate::engine::navigate::{NavRun, NavSample};
use crate::experiments::navigation::filter;
use crate::experiments::windows::{Stretch, Windowed};
use crate::report::plot::{BandChart, Panel};
use crate::scenario::Scenario;
use anyhow::{Context, Result, bail};
use nav::navigation::filter::{Correction, FilterKind};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::Path;

/// A filter as nav offers it: its kind and how its estimate is applied (closed-loop feedback,
/// nav's default, or paper 003's output correction). Written `standard` (feedback) or
/// `standard/output`, in the report's JSON as on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Mode {
    /// The filter kind.
    pub kind: FilterKind,
    /// How its estimate is applied.
    pub correction: Correction,
}

impl Mode {
    /// Every mode nav offers: each filter kind with feedback, then each with output correction.
    pub fn all() -> Vec<Mode> {
        let kinds = [
            FilterKind::Standard,
            FilterKind::Fading,
            FilterKind::Adaptive,
        ];
        [Correction::Feedback, Correction::Output]
            .iter()
            .flat_map(|&correction| kinds.iter().map(move |&kind| Mode { kind, correction }))
            .collect()
    }
}

impl From<FilterKind> for Mode {
    fn from(kind: FilterKind) -> Mode {
        Mode {
            kind,
            correction: Correction::Feedback,
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.correction {
            Correction::Feedback => write!(f, "{}", self.kind),
            Correction::Output => write!(f, "{}/output", self.kind),
        }
    }
}

impl std::str::FromStr for Mode {
    type Err = anyhow::Error;
    /// `standard`, `fading/output`, `adaptive/feedback`.
    fn from_str(s: &str) -> Result<Mode> {
        let (kind, correction) = s.trim().split_once('/').unwrap_or((s.trim(), "feedback"));
        let word = |v: &str| serde_json::Value::String(v.trim().to_string());
        let kind = serde_json::from_value::<FilterKind>(word(kind)).map_err(|_| {
            anyhow::anyhow!("`{s}`: `{kind}` is not a filter kind (standard, fading, adaptive)")
        })?;
        let correction = serde_json::from_value::<Correction>(word(correction)).map_err(|_| {
            anyhow::anyhow!("`{s}`: `{correction}` is not a correction (feedback, output)")
        })?;
        Ok(Mode { kind, correction })
    }
}

impl TryFrom<String> for Mode {
    type Error = anyhow::Error;
    fn try_from(s: String) -> Result<Mode> {
        s.parse()
    }
}

impl From<Mode> for String {
    fn from(m: Mode) -> String {
        m.to_string()
    }
}

/// NEES per degree of freedom a consistent filter stays within.
pub const NEES_BOUNDS: [f64; 2] = [0.5, 2.0];

/// A velocity error nav must have flagged, m/s.
pub const VELOCITY_FLAG_MPS: f64 = 1.0;

/// Settings of the experiment.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RoutesOptions {
    /// The routes (drives with a `[gps]`).
    pub scenarios: Vec<Scenario>,
    /// Runs per route and filter with other IMU and receiver seeds.
    pub runs: usize,
    /// The filters compared (kind and correction); an earlier part's plan named them `kinds`
    /// (feedback alone).
    #[serde(alias = "kinds")]
    pub modes: Vec<Mode>,
    /// Threads (not part of the plan).
    #[serde(skip)]
    pub threads: usize,
}

/// One route and filter over its runs.
#[derive(Debug, Clone, Serialize)]
pub struct RouteRow {
    /// Route (scenario name).
    pub route: String,
    /// Filter kind and correction.
    pub filter: Mode,
    /// Runs.
    pub runs: usize,
    /// Seconds navigated (first run).
    pub navigated_s: f64,
    /// Mean end horizontal position error, m.
    pub end_position_error_m: f64,
    /// Mean RMS horizontal position error, m.
    pub rms_position_error_m: f64,
    /// Mean end velocity error, m/s.
    pub end_velocity_error_mps: f64,
    /// Mean RMS velocity error, m/s.
    pub rms_velocity_error_mps: f64,
    /// Mean NEES per degree of freedom, position and velocity.
    pub nees_per_dof: [f64; 2],
    /// Mean NIS of the fixes (3 for a consistent filter).
    pub mean_nis: f64,
    /// Fixes rejected by the innovation gate, over the runs.
    pub rejected: u64,
    /// Of those, in the filter's first minute (none may be: a start that fits the receiver).
    pub rejected_first_minute: u64,
    /// Integrity alarms raised, over the runs.
    pub integrity_alarms: u64,
    /// Runs whose navigation was aligned in motion (the vehicle moving when nav could first
    /// start), and the latest start over the runs, s.
    pub started_in_motion: usize,
    /// See [`RouteRow::started_in_motion`].
    pub latest_start_s: f64,
    /// Zero-velocity updates applied at stops, over the runs.
    pub zero_velocity_updates: u64,
    /// NEES per dof in each ten-minute window, inside each outage and in the minute after
    /// it, pooled over the runs.
    pub windowed: Windowed,
    /// Fixes refused by the gate although their error was within 3 of the receiver's own
    /// sigma, over the runs (none may be).
    pub good_fixes_refused: u64,
    /// NEES within [`NEES_BOUNDS`] for position and velocity over the whole drive, in every
    /// window and in and after every outage.
    pub consistent: bool,
    /// Runs ending with a velocity error above [`VELOCITY_FLAG_MPS`] that nav did not flag.
    pub unflagged_velocity_errors: usize,
}

/// The experiment's result.
#[derive(Debug, Clone, Serialize)]
pub struct RoutesReport {
    /// One row per route and filter.
    pub rows: Vec<RouteRow>,
    /// Each route's truth against the reference integration of its own increments (a route
    /// whose truth disagrees with itself is refused before it is driven).
    pub truth: Vec<crate::experiments::truth::TruthRow>,
    /// Every row consistent.
    pub all_consistent: bool,
    /// No run ended with an unflagged velocity error.
    pub no_unflagged_velocity_errors: bool,
}

/// One run of a part: its errors and its series (for the plots).
pub type PartRun = crate::experiments::navigation::PartRun;

/// Part `k` of `n` of the experiment (see [`crate::experiments::shard`]).
pub type RoutesPart = crate::experiments::shard::Part<PartRun>;

/// The experiment's name in its parts.
pub const EXPERIMENT: &str = "routes";

struct Job {
    route: usize,
    kind: Mode,
    seed: u64,
}

fn jobs(o: &RoutesOptions) -> Vec<Job> {
    let mut v = Vec::new();
    for route in 0..o.scenarios.len() {
        for &kind in &o.modes {
            for seed in 0..o.runs as u64 {
                v.push(Job { route, kind, seed });
            }
        }
    }
    v
}

fn check(o: &RoutesOptions) -> Result<()> {
    if o.runs == 0 || o.modes.is_empty() || o.scenarios.is_empty() {
        bail!("at least one route, one filter kind and one run");
    }
    for s in &o.scenarios {
        if s.drive.is_none() || s.gps.is_none() {
            bail!("{}: a route needs a [drive] and a [gps]", s.name);
        }
    }
    Ok(())
}

/// Run part `shard` of `shards`: the runs whose place in the plan is `shard` modulo `shards`.
pub fn run_part(
    o: &RoutesOptions,
    shard: usize,
    shards: usize,
    progress: bool,
) -> Result<RoutesPart> {
    check(o)?;
    let all = jobs(o);
    let total = all.len();
    let mine = crate::experiments::shard::select(all, shard, shards)?;
    // the truth each run is scored against, checked before any is driven
    crate::experiments::truth::check_all(&o.scenarios, o.threads)?;
    if progress {
        eprintln!(
            "hil: {} of {total} runs ({} routes x {} filters x {} seeds) on {} threads",
            mine.len(),
            o.scenarios.len(),
            o.modes.len(),
            o.runs,
            o.threads
        );
    }
    let tally = crate::experiments::navigation::Tally::new(mine.len(), progress);
    let results = crate::par::map(
        &mine,
        o.threads,
        |(g, j)| {
            let s = &o.scenarios[j.route];
            let Some(rx) = &s.gps else {
                bail!("{}: no [gps]", s.name);
            };
            let label = format!("{} {}", s.name, j.kind);
            let f = nav::navigation::filter::FilterConfig {
                correction: j.kind.correction,
                ..filter(j.kind.kind, None)
            };
            let r = crate::experiments::navigation::seeded_run(s, Some(&f), rx, j.seed)
                .with_context(|| format!("{label}, seed {}", j.seed));
            tally.done(&label, &r);
            r.map(|r| (*g, r))
        },
        || Err(anyhow::anyhow!("worker panicked")),
    );
    Ok(RoutesPart {
        experiment: EXPERIMENT.into(),
        plan: serde_json::to_value(o)?,
        shard,
        shards,
        total,
        outcomes: results.into_iter().collect::<Result<_>>()?,
    })
}

/// Run the whole experiment here; files go to `out` when given.
pub fn run(o: &RoutesOptions, out: Option<&Path>, progress: bool) -> Result<RoutesReport> {
    let part = run_part(o, 0, 1, progress)?;
    merge(&[part], out)
}

/// Merge the parts (every part once) into the report; files go to `out` when given.
pub fn merge(parts: &[RoutesPart], out: Option<&Path>) -> Result<RoutesReport> {
    let all = crate::experiments::shard::assemble(parts)?;
    let o: RoutesOptions = serde_json::from_value(parts[0].plan.clone())
        .context("the parts' plan is not a routes experiment's")?;
    let jobs = jobs(&o);
    if jobs.len() != all.len() {
        bail!(
            "the parts hold {} runs, their plan {}",
            all.len(),
            jobs.len()
        );
    }
    let mut rows = Vec::new();
    let mut firsts: Vec<(usize, Mode, Vec<NavSample>)> = Vec::new();
    for (route, s) in o.scenarios.iter().enumerate() {
        for &kind in &o.modes {
            let runs: Vec<&PartRun> = jobs
                .iter()
                .zip(&all)
                .filter(|(j, _)| j.route == route && j.kind == kind)
                .map(|(_, r)| r)
                .collect();
            if let Some(first) = runs.first() {
                firsts.push((route, kind, first.series.clone()));
            }
            rows.push(row(s, kind, &runs));
        }
    }
    let r = RoutesReport {
        truth: crate::experiments::truth::check_all(&o.scenarios, crate::par::threads())?,
        all_consistent: rows.iter().all(|r| r.consistent),
        no_unflagged_velocity_errors: rows.iter().all(|r| r.unflagged_velocity_errors == 0),
        rows,
    };
    if let Some(dir) = out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let w = |name: &str, text: String| {
            std::fs::write(dir.join(name), text).with_context(|| format!("writing {name}"))
        };
        w("report.json", serde_json::to_string_pretty(&r)?)?;
        w("report.md", markdown(&r))?;
        for (route, s) in o.scenarios.iter().enumerate() {
            let mine: Vec<&(usize, Mode, Vec<NavSample>)> =
                firsts.iter().filter(|f| f.0 == route).collect();
            w(&format!("{}-series.csv", s.name), series_csv(&mine))?;
            w(
                &format!("{}-position.svg", s.name),
                sigma_chart(s, &mine, true),
            )?;
            w(
                &format!("{}-velocity.svg", s.name),
                sigma_chart(s, &mine, false),
            )?;
        }
        crate::report::page::folder_page(dir, "The filters over the routes", &markdown(&r))?;
    }
    Ok(r)
}

fn row(s: &Scenario, kind: Mode, parts: &[&PartRun]) -> RouteRow {
    let runs: Vec<&NavRun> = parts.iter().map(|r| &r.run).collect();
    let series: Vec<&[NavSample]> = parts.iter().map(|r| r.series.as_slice()).collect();
    let outages = s.gps.as_ref().map_or(&[][..], |g| g.outages.as_slice());
    let windowed = Windowed::of(&series, outages);
    let n = runs.len().max(1) as f64;
    let mean = |f: &dyn Fn(&NavRun) -> f64| runs.iter().map(|r| f(r)).sum::<f64>() / n;
    let nees = [
        mean(&|r| r.mean_nees_per_dof.map_or(f64::NAN, |x| x[0])),
        mean(&|r| r.mean_nees_per_dof.map_or(f64::NAN, |x| x[1])),
    ];
    let within = |x: f64| (NEES_BOUNDS[0]..=NEES_BOUNDS[1]).contains(&x);
    RouteRow {
        route: s.name.clone(),
        filter: kind,
        runs: runs.len(),
        navigated_s: runs
            .first()
            .map_or(0.0, |r| r.duration_s - r.started_at_s.unwrap_or(0.0)),
        end_position_error_m: mean(&|r| r.end_position_error_m),
        rms_position_error_m: mean(&|r| r.rms_position_error_m),
        end_velocity_error_mps: mean(&|r| r.end_velocity_error_mps),
        rms_velocity_error_mps: mean(&|r| r.rms_velocity_error_mps),
        nees_per_dof: nees,
        mean_nis: mean(&|r| r.filter.map_or(f64::NAN, |f| f.mean_nis)),
        rejected: runs
            .iter()
            .map(|r| r.filter.map_or(0, |f| f.rejected))
            .sum(),
        rejected_first_minute: runs
            .iter()
            .map(|r| r.filter.map_or(0, |f| f.rejected_first_minute))
            .sum(),
        integrity_alarms: runs.iter().map(|r| r.integrity.alarms).sum(),
        started_in_motion: runs
            .iter()
            .filter(|r| r.start.0 == Some(nav::navigation::navigator::StartKind::InMotion))
            .count(),
        latest_start_s: runs
            .iter()
            .filter_map(|r| r.started_at_s)
            .fold(0.0, f64::max),
        zero_velocity_updates: runs
            .iter()
            .map(|r| r.filter.map_or(0, |f| f.zero_velocity_updates))
            .sum(),
        good_fixes_refused: runs.iter().map(|r| r.good_fixes_refused).sum(),
        consistent: within(nees[0]) && within(nees[1]) && windowed.within(NEES_BOUNDS),
        windowed,
        unflagged_velocity_errors: runs
            .iter()
            .filter(|r| r.end_velocity_error_mps > VELOCITY_FLAG_MPS && r.integrity.alarms == 0)
            .count(),
    }
}

/// Each filter's first run on one route, second by second: errors, sigmas and NEES.
fn series_csv(runs: &[&(usize, Mode, Vec<NavSample>)]) -> String {
    let mut c = String::from(
        "filter,t_s,position_error_m,position_sigma_m,velocity_error_mps,velocity_sigma_mps,nees_position,nees_velocity\n",
    );
    let o = |x: Option<f64>| x.map_or(String::new(), |v| format!("{v:.4}"));
    for (_, kind, samples) in runs {
        for x in samples {
            let v = x.velocity_error_mps;
            let _ = writeln!(
                c,
                "{kind},{:.3},{:.3},{},{:.4},{},{},{}",
                x.t_s,
                x.position_error_m,
                o(x.position_sigma_m),
                (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(),
                o(x.velocity_sigma_mps),
                o(x.nees_position),
                o(x.nees_velocity)
            );
        }
    }
    c
}

/// Each filter's error on one route against its own 3-sigma bound (first run), a panel per
/// filter, the receiver's outages shaded.
fn sigma_chart(s: &Scenario, runs: &[&(usize, Mode, Vec<NavSample>)], position: bool) -> String {
    const COLORS: [&str; 4] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"];
    let panels = runs
        .iter()
        .enumerate()
        .map(|(i, (_, kind, samples))| {
            let (error, bound) = samples
                .iter()
                .map(|x| {
                    if position {
                        (
                            (x.t_s, x.position_error_m),
                            (x.t_s, 3.0 * x.position_sigma_m.unwrap_or(f64::NAN)),
                        )
                    } else {
                        let v = x.velocity_error_mps;
                        (
                            (x.t_s, (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()),
                            (x.t_s, 3.0 * x.velocity_sigma_mps.unwrap_or(f64::NAN)),
                        )
                    }
                })
                .unzip();
            Panel {
                name: kind.to_string(),
                color: COLORS[i % COLORS.len()],
                error,
                bound,
            }
        })
        .collect();
    BandChart {
        title: format!(
            "{}: {} error against each filter's 3-sigma bound",
            s.name,
            if position {
                "horizontal position"
            } else {
                "velocity"
            }
        ),
        x_label: "time, s".into(),
        y_label: if position { "m" } else { "m/s" }.into(),
        band_label: "3 sigma".into(),
        panels,
        spans: s.gps.as_ref().map_or_else(Vec::new, |g| g.outages.clone()),
        span_label: "receiver outage".into(),
    }
    .svg()
}

/// The table as Markdown.
pub fn markdown(r: &RoutesReport) -> String {
    use crate::table::{Align::*, Table};
    let mut t = Table::new(&[
        ("route", Left),
        ("filter", Left),
        ("runs", Right),
        ("navigated s", Right),
        ("end pos m", Right),
        ("RMS pos m", Right),
        ("end vel m/s", Right),
        ("RMS vel m/s", Right),
        ("NEES/dof pos", Right),
        ("NEES/dof vel", Right),
        ("worst 10 min pos/vel", Right),
        ("in/after outages, highest pos/vel", Right),
        ("mean NIS", Right),
        ("rejected (first minute)", Right),
        ("good fixes refused", Right),
        ("alarms", Right),
        ("start (in motion)", Right),
        ("stops' ZUPTs", Right),
        ("consistent", Left),
    ]);
    for x in &r.rows {
        t.row([
            x.route.clone(),
            x.filter.to_string(),
            x.runs.to_string(),
            format!("{:.0}", x.navigated_s),
            format!("{:.1}", x.end_position_error_m),
            format!("{:.1}", x.rms_position_error_m),
            format!("{:.3}", x.end_velocity_error_mps),
            format!("{:.3}", x.rms_velocity_error_mps),
            format!("{:.2}", x.nees_per_dof[0]),
            format!("{:.2}", x.nees_per_dof[1]),
            stretch_cell(x.windowed.worst_window(NEES_BOUNDS)),
            stretch_cell(x.windowed.worst_outage()),
            format!("{:.2}", x.mean_nis),
            format!("{} ({})", x.rejected, x.rejected_first_minute),
            x.good_fixes_refused.to_string(),
            x.integrity_alarms.to_string(),
            format!("{:.0} s ({})", x.latest_start_s, x.started_in_motion),
            x.zero_velocity_updates.to_string(),
            (if x.consistent { "yes" } else { "NO" }).to_string(),
        ]);
    }
    let mut m = format!("# The filters over the routes\n\n{}", t.finish());
    let _ = write!(
        m,
        "\nNEES per degree of freedom within [{}, {}] over each drive and in each {}-minute window, and at most the upper bound inside each outage and in the {} s after it (pooled over the runs): {}\n\nThe same, each stretch allowed its ± (the 95 % interval of its figure from the scatter between the runs, Student's t over their own figures): {}. A figure past its bound by less than its ± is within what these runs can tell apart; more runs decide it.\n\nNo fix rejected in any filter's first minute: {}\n\nNo good fix (its error within 3 of the receiver's own sigma) refused by any filter: {}\n\nNo run ends with a velocity error above {} m/s that nav did not flag: {}\n",
        NEES_BOUNDS[0],
        NEES_BOUNDS[1],
        crate::experiments::windows::WINDOW_S / 60.0,
        crate::experiments::windows::AFTER_OUTAGE_S,
        if r.all_consistent { "MET" } else { "NOT MET" },
        if r.rows
            .iter()
            .all(|x| x.windowed.within_scatter(NEES_BOUNDS))
        {
            "MET"
        } else {
            "NOT MET"
        },
        if r.rows.iter().all(|x| x.rejected_first_minute == 0) {
            "MET"
        } else {
            "NOT MET"
        },
        if r.rows.iter().all(|x| x.good_fixes_refused == 0) {
            "MET"
        } else {
            "NOT MET"
        },
        VELOCITY_FLAG_MPS,
        if r.no_unflagged_velocity_errors {
            "MET"
        } else {
            "NOT MET"
        }
    );
    let _ = write!(m, "\n{}", crate::experiments::truth::markdown(&r.truth));
    m
}

/// A stretch's two figures and where it lies ("1.12 / 0.95 at 1800-2400 s"; "-" for none).
fn stretch_cell(s: Option<&Stretch>) -> String {
    let f = |x: f64| {
        if x.is_finite() {
            format!("{x:.2}")
        } else {
            "-".into()
        }
    };
    // with the runs' scatter: "1.07±0.53 / 2.05±1.39"
    let pm = |i: usize| match s.and_then(|s| s.interval_per_dof) {
        Some(h) if h[i].is_finite() => format!("±{:.2}", h[i]),
        _ => String::new(),
    };
    s.map_or("-".into(), |s| {
        format!(
            "{}{} / {}{} at {:.0}-{:.0} s",
            f(s.nees_per_dof[0]),
            pm(0),
            f(s.nees_per_dof[1]),
            pm(1),
            s.from_s,
            s.to_s
        )
    })
}

/// The filters over the routes as an [`Experiment`](crate::experiments::Experiment).
pub struct Routes;

impl crate::experiments::Experiment for Routes {
    const NAME: &'static str = EXPERIMENT;
    type Options = RoutesOptions;
    type Run = PartRun;
    type Report = RoutesReport;
    fn part(o: &RoutesOptions, k: usize, n: usize, progress: bool) -> Result<RoutesPart> {
        run_part(o, k, n, progress)
    }
    fn merge(parts: &[RoutesPart], out: &Path, _progress: bool) -> Result<RoutesReport> {
        merge(parts, Some(out))
    }
    fn text(r: &RoutesReport) -> String {
        markdown(r)
    }
    /// Every filter consistent on every route (windowed), no velocity error unflagged, no fix
    /// rejected in a filter's first minute and no good fix refused.
    fn met(r: &RoutesReport) -> bool {
        let clean_starts = r.rows.iter().all(|x| x.rejected_first_minute == 0);
        let good_taken = r.rows.iter().all(|x| x.good_fixes_refused == 0);
        r.all_consistent && r.no_unflagged_velocity_errors && clean_starts && good_taken
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every mode is written as it is read, a kind alone means feedback, and a word that is
    /// neither a kind nor a correction is refused naming it.
    #[test]
    fn modes_are_read_as_written() {
        let all = Mode::all();
        assert_eq!(all.len(), 6);
        for m in &all {
            assert_eq!(m.to_string().parse::<Mode>().unwrap(), *m);
        }
        assert_eq!(
            " adaptive ".parse::<Mode>().unwrap(),
            Mode::from(FilterKind::Adaptive)
        );
        assert_eq!(
            "standard/output".parse::<Mode>().unwrap().correction,
            Correction::Output
        );
        let json = serde_json::to_string(&all).unwrap();
        assert!(json.contains("\"fading/output\""), "{json}");
        assert_eq!(serde_json::from_str::<Vec<Mode>>(&json).unwrap(), all);
        // an earlier part's plan: `kinds`, each a kind alone
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/drive-gps.toml");
        let o = RoutesOptions {
            scenarios: vec![Scenario::load(&path).unwrap()],
            runs: 2,
            modes: vec![FilterKind::Standard.into(), FilterKind::Adaptive.into()],
            threads: 1,
        };
        let old = serde_json::to_string(&o)
            .unwrap()
            .replace("\"modes\"", "\"kinds\"");
        assert!(
            old.contains("\"kinds\":[\"standard\",\"adaptive\"]"),
            "{old}"
        );
        let read: RoutesOptions = serde_json::from_str(&old).unwrap();
        assert_eq!(read.modes, o.modes);
        let e = "kalman/output".parse::<Mode>().unwrap_err().to_string();
        assert!(e.contains("`kalman` is not a filter kind"), "{e}");
        let e = "fading/both".parse::<Mode>().unwrap_err().to_string();
        assert!(e.contains("`both` is not a correction"), "{e}");
    }

    /// A short route run whole and in two parts (through their JSON) gives the same table, and
    /// the table carries what the promise is judged on.
    #[test]
    fn two_parts_merged_give_the_single_run_table() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/drive-gps.toml");
        let mut s = Scenario::load(&path).unwrap();
        s.duration_s = 40.0;
        let o = RoutesOptions {
            scenarios: vec![s],
            runs: 1,
            modes: vec![
                FilterKind::Standard.into(),
                "fading/output".parse().unwrap(),
            ],
            threads: 2,
        };
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let one = run(&o, Some(a.path()), false).unwrap();
        assert_eq!(one.rows.len(), 2);
        for r in &one.rows {
            assert!(
                r.nees_per_dof.iter().all(|x| x.is_finite() && *x > 0.0),
                "{r:?}"
            );
            assert!(r.mean_nis.is_finite() && r.navigated_s > 20.0, "{r:?}");
            let within = |x: f64| (NEES_BOUNDS[0]..=NEES_BOUNDS[1]).contains(&x);
            assert_eq!(
                r.consistent,
                within(r.nees_per_dof[0])
                    && within(r.nees_per_dof[1])
                    && r.windowed.within(NEES_BOUNDS)
            );
            assert_eq!(r.windowed.windows.len(), 1, "a 40 s drive is one window");
        }
        let parts: Vec<RoutesPart> = (0..2)
            .map(|k| {
                let p = run_part(&o, k, 2, false).unwrap();
                serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap()
            })
            .collect();
        let two = merge(&parts, Some(b.path())).unwrap();
        assert_eq!(
            serde_json::to_string(&one).unwrap(),
            serde_json::to_string(&two).unwrap()
        );
        for f in [
            "report.md",
            "drive-gps-position.svg",
            "drive-gps-velocity.svg",
        ] {
            let read = |d: &tempfile::TempDir| std::fs::read_to_string(d.path().join(f)).unwrap();
            assert_eq!(read(&a), read(&b), "{f}");
        }
        assert!(
            std::fs::read_to_string(a.path().join("drive-gps-position.svg"))
                .unwrap()
                .contains("3 sigma")
        );
    }
}
