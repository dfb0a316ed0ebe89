//! Paper 003's vehicle test in process (`hil experiment navigation`): the campus loop with
//! north-finding first, then pure inertial, standard, fading-memory and adaptive filters
//! (Table 4), the filters with a mis-specified GPS noise, 60 s outages every 180 s, output
//! correction, and a receiver with what the filters do not model (the paper's surroundings:
//! satellites changing, multipath bursts, HDOP along the route). Every run is
//! `navrun::navigate`: the emulators and nav's own code, as on the bench, without the bus.

use crate::engine::navigate::{NavRun, NavSample, navigate};
use crate::report::plot::{LogChart, Series};
use crate::scenario::Scenario;
use crate::table::Table;
use anyhow::{Context, Result, bail};
use emulators::gps::ReceiverParams;
use emulators::gps::errors::{Environment, EnvironmentPreset};
use nav::navigation::filter::{FilterConfig, FilterKind};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Paper 003, Table 4 (at 1342 s): end position error (m) and velocity error (m/s) of pure
/// INS, the standard filter and the fading-memory filter.
pub const PAPER_TABLE4: [(&str, f64, f64); 3] = [
    ("pure INS", 20_473.0, 75.40),
    ("standard KF", 20.7, 0.42),
    ("fading-memory KF", 9.7, 0.24),
];

/// Settings of the experiment.
#[derive(Debug, Clone)]
pub struct NavExpOptions {
    /// The scenario (a drive with a receiver; north-finding first when it has one).
    pub scenario: Scenario,
    /// Repetitions with other IMU and GPS seeds (results are averaged).
    pub runs: usize,
    /// The GPS noise the mis-specified filters assume, m (the receiver's is about 19 m).
    pub misspecified_sigma_m: Vec<f64>,
    /// Outage length and period, s.
    pub outage_s: (f64, f64),
    /// The surroundings of the mis-modelled receiver.
    pub environment: Environment,
    /// Threads.
    pub threads: usize,
}

/// The filter kinds every comparison runs, with their names.
pub const KINDS: [(FilterKind, &str); 3] = [
    (FilterKind::Standard, "standard"),
    (FilterKind::Fading, "fading"),
    (FilterKind::Adaptive, "adaptive"),
];

/// Paper 003's margin: its fading filter ended at 9.7 / 20.7 of the standard one's error.
pub const PAPER_MARGIN: f64 = 9.7 / 20.7;

/// One case: a filter (or none) against a receiver, over the runs.
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    /// Name.
    pub name: String,
    /// Mean over the runs of the end position error, m.
    pub end_position_error_m: f64,
    /// Mean end velocity error, m/s.
    pub end_velocity_error_mps: f64,
    /// Mean RMS position error over the run, m.
    pub rms_position_error_m: f64,
    /// Mean RMS velocity error, m/s.
    pub rms_velocity_error_mps: f64,
    /// Mean NEES per degree of freedom (position, velocity).
    pub mean_nees_per_dof: Option<[f64; 2]>,
    /// RMS and largest error at the ends of the outages, over all runs, m.
    pub outage_drift_m: Option<(f64, f64)>,
    /// Integrity alarms raised, over all runs.
    pub integrity_alarms: u64,
    /// Mean of the receiver's slow error at the end (its 60 s mean), m: what a filter that
    /// removed the white noise and the bursts perfectly would still carry.
    pub end_receiver_wander_m: Option<f64>,
    /// The runs.
    pub runs: Vec<NavRun>,
}

/// The experiment's result.
#[derive(Debug, Clone, Serialize)]
pub struct NavExperiment {
    /// Scenario name.
    pub scenario: String,
    /// Seconds navigated (end of the run minus the start of navigation).
    pub navigated_s: f64,
    /// North-finding's heading error in the first run, deg.
    pub north_finding_error_deg: Option<f64>,
    /// Table 4: pure INS, then the filters of [`KINDS`].
    pub table4: Vec<CaseResult>,
    /// Mis-specified noise: for each assumed sigma, the filters of [`KINDS`].
    pub misspecified: Vec<(f64, Vec<CaseResult>)>,
    /// Outages: the filters of [`KINDS`].
    pub outages: Vec<CaseResult>,
    /// Paper 003's output correction (the INS runs free, its output is corrected): the
    /// filters of [`KINDS`].
    pub output_correction: Vec<CaseResult>,
    /// The receiver in the paper's surroundings (not in any filter's model): the filters of
    /// [`KINDS`], then the same scaling their white noise with the reported HDOP.
    pub mis_modelled: Vec<CaseResult>,
    /// The surroundings of the mis-modelled receiver.
    pub environment: Environment,
    /// With the mis-modelled receiver, the fading or the adaptive filter ends at or below
    /// [`PAPER_MARGIN`] of the standard filter's error (the paper's margin).
    pub beats_standard_by_paper_margin: bool,
    /// Outage periods used, s.
    pub outage_periods: Vec<[f64; 2]>,
    /// Pure INS ends in the kilometre class (over 1 km).
    pub pure_km_class: bool,
    /// Every filter ends at or below the paper's standard-filter figure (20.7 m).
    pub filters_within_paper: bool,
    /// Where the filter overstates the receiver's noise (the standard filter then trusts its
    /// own prediction too long, the case fading memory is for), the fading filter's RMS error
    /// is no worse than the standard one's (within 5 %).
    pub fading_no_worse_overstated: bool,
    /// The same where the filter understates it (both follow the receiver; fading weights it
    /// more): reported, not a target.
    pub fading_no_worse_understated: bool,
    /// The drive's truth against the reference integration of its own increments (a drive
    /// whose truth disagrees with itself is refused before it is driven).
    pub truth: crate::experiments::truth::TruthRow,
}

/// Which table a case belongs to.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Group {
    Table4,
    Misspecified(usize),
    Outages,
    OutputCorrection,
    MisModelled,
}

/// The filter of kind `kind` as the experiments run it; `sigma`: the total receiver noise it
/// assumes, m (none: the default receiver model).
pub(crate) fn filter(kind: FilterKind, sigma: Option<f64>) -> FilterConfig {
    let mut f = FilterConfig {
        kind,
        ..FilterConfig::default()
    };
    if let Some(s) = sigma {
        // the filter assumes a receiver of `s` per axis in all, split as the real one is
        // (Gauss-Markov 12 m and white 6 m: 0.894 and 0.447 of the total)
        let total = f.gps_gm_sigma_m.hypot(f.gps_sigma_m);
        let k = s / total;
        f.gps_sigma_m *= k;
        f.gps_sigma_h_m *= k;
        f.gps_gm_sigma_m *= k;
        f.gps_gm_sigma_h_m *= k;
    }
    f
}

/// Outages of `len` s every `period` s once the vehicle drives off, to the end of the drive.
pub fn outage_periods(s: &Scenario, len: f64, period: f64) -> Vec<[f64; 2]> {
    let Some(d) = &s.drive else {
        return Vec::new();
    };
    let end = emulators::drive::Drive::plan(d).map_or(s.duration_s, |p| p.duration());
    let mut out = Vec::new();
    let mut t = d.start_wait_s + period - len;
    while t + len <= end.min(s.duration_s) {
        out.push([t, t + len]);
        t += period;
    }
    out
}

/// The surroundings of the mis-modelled cases (older parts carry none: the paper's).
fn paper_environment() -> Environment {
    Environment::preset(EnvironmentPreset::Paper003)
}

struct Job {
    case: usize,
    filter: Option<FilterConfig>,
    rx: ReceiverParams,
    seed: u64,
}

/// What every part of the experiment shares.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct NavPlan {
    scenario: Scenario,
    runs: usize,
    misspecified_sigma_m: Vec<f64>,
    outage_s: (f64, f64),
    #[serde(default = "paper_environment")]
    environment: Environment,
}

/// One run of a part: its errors and its second-by-second series (for the plots).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PartRun {
    /// The run's errors.
    pub run: NavRun,
    /// Second by second.
    pub series: Vec<NavSample>,
}

/// One run of an experiment: the scenario's IMU and mechanism and the receiver re-seeded for
/// run `seed`, navigated with `filter`, its series split off for the part file.
pub(crate) fn seeded_run(
    s: &Scenario,
    filter: Option<&FilterConfig>,
    rx: &ReceiverParams,
    seed: u64,
) -> Result<PartRun> {
    // the scenario's own receiver is not the one navigated with: `rx` (its seed changed alike)
    let sc = s.reseeded(seed);
    let mut rx = rx.clone();
    rx.errors.seed += 1000 * seed;
    let mut run = navigate(&sc, filter, &rx, 0.0)?;
    let series = std::mem::take(&mut run.series);
    Ok(PartRun { run, series })
}

/// Progress of a part's runs, one line per finished run.
pub(crate) struct Tally {
    done: std::sync::atomic::AtomicUsize,
    total: usize,
    t0: std::time::Instant,
    on: bool,
}

impl Drop for Tally {
    fn drop(&mut self) {
        crate::status::finish();
    }
}

impl Tally {
    pub(crate) fn new(total: usize, on: bool) -> Self {
        Self {
            done: Default::default(),
            total,
            t0: std::time::Instant::now(),
            on,
        }
    }

    /// Run `label` has finished with `r`.
    pub(crate) fn done(&self, label: &str, r: &Result<PartRun>) {
        let n = self.done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if self.on {
            crate::status::count(
                n,
                self.total,
                self.t0.elapsed().as_secs_f64(),
                &format!(
                    "{label}{}",
                    r.as_ref().map_or(String::new(), |r| format!(
                        ", end error {:.1} m",
                        r.run.end_position_error_m
                    ))
                ),
            );
        }
    }
}

/// Part `k` of `n` of the experiment (see [`crate::experiments::shard`]).
pub type NavPart = crate::experiments::shard::Part<PartRun>;

/// The experiment's name in its parts.
pub const EXPERIMENT: &str = "navigation";

/// The cases of the experiment, in table order.
struct Plan {
    names: Vec<String>,
    groups: Vec<Group>,
    outages: Vec<[f64; 2]>,
    rx0: ReceiverParams,
    jobs: Vec<Job>,
}

fn plan(o: &NavExpOptions) -> Result<Plan> {
    let s = &o.scenario;
    let Some(rx0) = s.gps.clone() else {
        bail!("scenario {} has no [gps]", s.name);
    };
    if o.runs == 0 {
        bail!("runs must be at least 1");
    }
    let outages = outage_periods(s, o.outage_s.0, o.outage_s.1);
    let mut names: Vec<String> = vec!["pure INS".into()];
    let mut groups = vec![Group::Table4];
    let mut cases: Vec<(Option<FilterConfig>, ReceiverParams)> = vec![(None, rx0.clone())];
    let mut add = |name: String, g: Group, f: FilterConfig, rx: &ReceiverParams| {
        names.push(name);
        groups.push(g);
        cases.push((Some(f), rx.clone()));
    };
    for (k, n) in KINDS {
        add(format!("{n} KF"), Group::Table4, filter(k, None), &rx0);
    }
    for (i, &sig) in o.misspecified_sigma_m.iter().enumerate() {
        for (k, n) in KINDS {
            add(
                format!("{n}, assumes {sig} m"),
                Group::Misspecified(i),
                filter(k, Some(sig)),
                &rx0,
            );
        }
    }
    let with_outages = ReceiverParams {
        outages: outages.clone(),
        ..rx0.clone()
    };
    for (k, n) in KINDS {
        add(
            format!("{n}, 60 s outages"),
            Group::Outages,
            filter(k, None),
            &with_outages,
        );
    }
    for (k, n) in KINDS {
        let mut f = filter(k, None);
        f.correction = nav::navigation::filter::Correction::Output;
        add(
            format!("{n}, output correction"),
            Group::OutputCorrection,
            f,
            &rx0,
        );
    }
    let mut mis_modelled = rx0.clone();
    mis_modelled.errors.environment = o.environment.clone();
    // the HDOP the receiver reports at its nominal geometry: where the assumed white noise holds
    let hdop_ref = mis_modelled.errors.nominal_hdop();
    for hdop in [false, true] {
        for (k, n) in KINDS {
            let mut f = filter(k, None);
            if hdop {
                f.hdop_ref = hdop_ref;
            }
            let tag = if hdop { ", HDOP-scaled" } else { "" };
            add(
                format!("{n}{tag}, mis-modelled receiver"),
                Group::MisModelled,
                f,
                &mis_modelled,
            );
        }
    }
    let jobs: Vec<Job> = (0..o.runs)
        .flat_map(|r| {
            cases.iter().enumerate().map(move |(i, (f, rx))| Job {
                case: i,
                filter: f.clone(),
                rx: rx.clone(),
                seed: r as u64,
            })
        })
        .collect();
    Ok(Plan {
        names,
        groups,
        outages,
        rx0,
        jobs,
    })
}

/// Run the experiment; files go to `out` when given.
pub fn run(o: &NavExpOptions, out: Option<&Path>, progress: bool) -> Result<NavExperiment> {
    let part = run_part(o, 0, 1, progress)?;
    merge(&[part], out)
}

/// Run part `shard` of `shards` of the experiment: the runs whose place in the plan is `shard`
/// modulo `shards`.
pub fn run_part(o: &NavExpOptions, shard: usize, shards: usize, progress: bool) -> Result<NavPart> {
    let s = &o.scenario;
    let Plan {
        names,
        groups,
        jobs,
        ..
    } = plan(o)?;
    let total = jobs.len();
    let mine = crate::experiments::shard::select(jobs, shard, shards)?;
    // the truth each run is scored against, checked before any is driven
    crate::experiments::truth::check_all(std::slice::from_ref(s), 1)?;
    if progress {
        eprintln!(
            "hil: {} of {} runs of {} ({} cases x {} seeds, {} s each) on {} threads",
            mine.len(),
            total,
            s.name,
            groups.len(),
            o.runs,
            s.duration_s,
            o.threads
        );
    }
    let tally = Tally::new(mine.len(), progress);
    let results = crate::par::map(
        &mine,
        o.threads,
        |(g, j)| {
            let r = seeded_run(s, j.filter.as_ref(), &j.rx, j.seed)
                .with_context(|| format!("{} (seed {})", names[j.case], j.seed));
            tally.done(&names[j.case], &r);
            r.map(|r| (*g, r))
        },
        || Err(anyhow::anyhow!("worker panicked")),
    );
    Ok(NavPart {
        experiment: EXPERIMENT.into(),
        plan: serde_json::to_value(NavPlan {
            scenario: s.clone(),
            runs: o.runs,
            misspecified_sigma_m: o.misspecified_sigma_m.clone(),
            outage_s: o.outage_s,
            environment: o.environment.clone(),
        })?,
        shard,
        shards,
        total,
        outcomes: results.into_iter().collect::<Result<_>>()?,
    })
}

/// Merge the parts of one experiment (every part once) into its report; files go to `out`
/// when given.
pub fn merge(parts: &[NavPart], out: Option<&Path>) -> Result<NavExperiment> {
    let all = crate::experiments::shard::assemble(parts)?;
    let p: NavPlan = serde_json::from_value(parts[0].plan.clone())
        .context("the parts' plan is not a navigation experiment's")?;
    let o = NavExpOptions {
        scenario: p.scenario,
        runs: p.runs,
        misspecified_sigma_m: p.misspecified_sigma_m,
        outage_s: p.outage_s,
        environment: p.environment,
        threads: 1,
    };
    let s = &o.scenario;
    let Plan {
        names,
        groups,
        outages,
        rx0,
        jobs,
    } = plan(&o)?;
    if jobs.len() != all.len() {
        bail!(
            "the parts hold {} runs, their plan {}",
            all.len(),
            jobs.len()
        );
    }
    let results = all.into_iter().map(|r| {
        let mut run = r.run;
        run.series = r.series;
        Ok::<_, anyhow::Error>(run)
    });
    let mut per_case: Vec<Vec<NavRun>> = vec![Vec::new(); groups.len()];
    for (j, r) in jobs.iter().zip(results) {
        per_case[j.case].push(r?);
    }
    let summarize = |i: usize| CaseResult::of(names[i].clone(), per_case[i].clone());
    let group = |g: Group| -> Vec<CaseResult> {
        (0..groups.len())
            .filter(|&i| groups[i] == g)
            .map(summarize)
            .collect()
    };
    let table4 = group(Group::Table4);
    let misspecified: Vec<(f64, Vec<CaseResult>)> = o
        .misspecified_sigma_m
        .iter()
        .enumerate()
        .map(|(k, &sig)| (sig, group(Group::Misspecified(k))))
        .collect();
    let outage_cases = group(Group::Outages);
    let output_correction = group(Group::OutputCorrection);
    let mis_modelled = group(Group::MisModelled);
    let standard_end = mis_modelled[0].end_position_error_m;
    let beats_standard_by_paper_margin = mis_modelled[1..3]
        .iter()
        .any(|c| c.end_position_error_m <= PAPER_MARGIN * standard_end);
    let first = &table4[1].runs[0];
    // the receiver's horizontal error per axis (Gauss-Markov and white parts)
    let rx_sigma = rx0.errors.gm_sigma_m.hypot(rx0.errors.white_sigma_m);
    let truth = crate::experiments::truth::check_all(std::slice::from_ref(s), 1)?;
    let r = NavExperiment {
        truth: truth.into_iter().next().context("no truth checked")?,
        scenario: s.name.clone(),
        navigated_s: first.duration_s - first.started_at_s.unwrap_or(0.0),
        north_finding_error_deg: first
            .north_finding
            .as_ref()
            .map(|n| crate::stats::wrap180(n.heading_deg - s.truth_heading_deg())),
        pure_km_class: table4[0].end_position_error_m > 1000.0,
        filters_within_paper: table4[1..]
            .iter()
            .all(|c| c.end_position_error_m <= PAPER_TABLE4[1].1),
        fading_no_worse_overstated: misspecified
            .iter()
            .filter(|(sig, _)| *sig > rx_sigma)
            .all(|(_, c)| c[1].rms_position_error_m <= 1.05 * c[0].rms_position_error_m),
        fading_no_worse_understated: misspecified
            .iter()
            .filter(|(sig, _)| *sig <= rx_sigma)
            .all(|(_, c)| c[1].rms_position_error_m <= 1.05 * c[0].rms_position_error_m),
        mis_modelled,
        environment: o.environment.clone(),
        beats_standard_by_paper_margin,
        table4,
        misspecified,
        outages: outage_cases,
        output_correction,
        outage_periods: outages,
    };
    if let Some(dir) = out {
        write_files(&r, dir)?;
    }
    Ok(r)
}

impl CaseResult {
    /// The case `name` from its runs: their means, NEES, drift in outages and alarms.
    fn of(name: String, runs: Vec<NavRun>) -> Self {
        let m = |f: &dyn Fn(&NavRun) -> f64| runs.iter().map(f).sum::<f64>() / runs.len() as f64;
        let nees: Vec<[f64; 2]> = runs.iter().filter_map(|r| r.mean_nees_per_dof).collect();
        let drift: Vec<f64> = runs
            .iter()
            .flat_map(|r| r.outage_end_errors_m.iter().copied())
            .collect();
        CaseResult {
            name,
            end_position_error_m: m(&|r| r.end_position_error_m),
            end_velocity_error_mps: m(&|r| r.end_velocity_error_mps),
            rms_position_error_m: m(&|r| r.rms_position_error_m),
            rms_velocity_error_mps: m(&|r| r.rms_velocity_error_mps),
            mean_nees_per_dof: (!nees.is_empty()).then(|| {
                let k = nees.len() as f64;
                [
                    nees.iter().map(|x| x[0]).sum::<f64>() / k,
                    nees.iter().map(|x| x[1]).sum::<f64>() / k,
                ]
            }),
            outage_drift_m: (!drift.is_empty()).then(|| {
                let rms = (drift.iter().map(|x| x * x).sum::<f64>() / drift.len() as f64).sqrt();
                (rms, drift.iter().copied().fold(0.0, f64::max))
            }),
            integrity_alarms: runs.iter().map(|r| r.integrity.alarms).sum(),
            end_receiver_wander_m: runs
                .iter()
                .map(|r| r.end_receiver_wander_m)
                .sum::<Option<f64>>()
                .map(|x| x / runs.len() as f64),
            runs,
        }
    }
}

fn write_files(r: &NavExperiment, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let w = |name: &str, text: String| {
        std::fs::write(dir.join(name), text).with_context(|| format!("writing {name}"))
    };
    w("report.json", serde_json::to_string_pretty(r)?)?;
    w("report.md", markdown(r))?;
    // the first run of each Table 4 case and of the outage cases, second by second
    let mut csv = String::from(
        "case,t_s,position_error_m,velocity_error_e_mps,velocity_error_n_mps,velocity_error_u_mps,heading_error_deg,nees_position,nees_velocity\n",
    );
    let all: Vec<&CaseResult> = r.table4.iter().chain(r.outages.iter()).collect();
    for c in &all {
        for x in &c.runs[0].series {
            let o = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
            csv += &format!(
                "{},{:.1},{:.3},{:.4},{:.4},{:.4},{:.5},{},{}\n",
                c.name,
                x.t_s,
                x.position_error_m,
                x.velocity_error_mps[0],
                x.velocity_error_mps[1],
                x.velocity_error_mps[2],
                x.heading_error_deg,
                o(x.nees_position),
                o(x.nees_velocity)
            );
        }
    }
    w("series.csv", csv)?;
    let colors = ["#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e"];
    let chart = |title: &str,
                 y: &str,
                 cases: &[&CaseResult],
                 f: &dyn Fn(&crate::engine::navigate::NavSample) -> f64| {
        LogChart {
            title: title.into(),
            x_label: "time, s".into(),
            y_label: y.into(),
            series: cases
                .iter()
                .zip(colors)
                .map(|(c, color)| Series {
                    name: c.name.clone(),
                    color,
                    points: c.runs[0].series.iter().map(|x| (x.t_s, f(x))).collect(),
                    markers: false,
                })
                .collect(),
        }
        .svg()
    };
    let t4: Vec<&CaseResult> = r.table4.iter().collect();
    w(
        "position-error.svg",
        chart(
            &format!("{}: horizontal position error", r.scenario),
            "m",
            &t4,
            &|x| x.position_error_m,
        ),
    )?;
    w(
        "velocity-error.svg",
        chart(
            &format!("{}: velocity error", r.scenario),
            "m/s",
            &t4,
            &|x| nalgebra::Vector3::from(x.velocity_error_mps).norm(),
        ),
    )?;
    let oc: Vec<&CaseResult> = r.outages.iter().collect();
    w(
        "outages.svg",
        chart(
            &format!("{}: 60 s GPS outages every 180 s", r.scenario),
            "m",
            &oc,
            &|x| x.position_error_m,
        ),
    )?;
    crate::report::page::folder_page(dir, "Navigation experiment (paper 003)", &markdown(r))?;
    Ok(())
}

fn nees_text(n: Option<[f64; 2]>) -> String {
    n.map_or("--".into(), |n| format!("{:.2} / {:.2}", n[0], n[1]))
}

/// The report as Markdown.
pub fn markdown(r: &NavExperiment) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let runs = r.table4[0].runs.len();
    let _ = writeln!(
        s,
        "# Paper 003 vehicle test in process: {}\n\n{runs} run(s) per case (means shown); {:.0} s navigated after north-finding (error {}).\n",
        r.scenario,
        r.navigated_s,
        r.north_finding_error_deg
            .map_or("--".into(), |e| format!("{e:+.4} deg"))
    );
    let mut t = Table::left(&[
        "",
        "paper: position",
        "ours: position",
        "paper: velocity",
        "ours: velocity",
        "ours: RMS position",
        "ours: RMS velocity",
        "NEES/dof pos / vel",
        "integrity alarms",
    ]);
    for (i, c) in r.table4.iter().enumerate() {
        let p = PAPER_TABLE4.get(i);
        t.row([
            c.name.clone(),
            p.map_or("--".into(), |p| format!("{} m", p.1)),
            format!("{:.1} m", c.end_position_error_m),
            p.map_or("--".into(), |p| format!("{} m/s", p.2)),
            format!("{:.2} m/s", c.end_velocity_error_mps),
            format!("{:.1} m", c.rms_position_error_m),
            format!("{:.2} m/s", c.rms_velocity_error_mps),
            nees_text(c.mean_nees_per_dof),
            c.integrity_alarms.to_string(),
        ]);
    }
    s += "## Table 4 (end of the run)\n\n";
    s += &t.finish();
    let _ = writeln!(
        s,
        "\nTargets: pure INS in the kilometre class: **{}**; every filter at or below 20.7 m: **{}**.\n",
        yes(r.pure_km_class),
        yes(r.filters_within_paper)
    );
    let headings: Vec<String> = std::iter::once("filter assumes (per axis)".to_string())
        .chain(KINDS.map(|(_, n)| format!("{n}: end / RMS, NEES/dof pos")))
        .collect();
    let mut t = Table::left(&headings.iter().map(String::as_str).collect::<Vec<_>>());
    for (sig, cases) in &r.misspecified {
        t.row(
            std::iter::once(format!("{sig} m")).chain(cases.iter().map(|c| {
                format!(
                    "{:.1} / {:.1} m, {:.2}",
                    c.end_position_error_m,
                    c.rms_position_error_m,
                    c.mean_nees_per_dof.map_or(f64::NAN, |n| n[0])
                )
            })),
        );
    }
    s += "## Mis-specified GPS noise (the receiver's error is about 13 m per axis, 19 m horizontal)\n\n";
    s += &t.finish();
    let _ = writeln!(
        s,
        "\nFading no worse than standard (RMS, 5 % margin) where the filter overstates the noise (the target): **{}**; where it understates it: {}. With the noise understated both filters already follow the receiver too closely and fading weights it more still, so it cannot win there.\n",
        yes(r.fading_no_worse_overstated),
        yes(r.fading_no_worse_understated)
    );
    s += &outages_markdown(r);
    s += &mis_modelled_markdown(r);
    s += "\n";
    s += &crate::experiments::truth::markdown(std::slice::from_ref(&r.truth));
    s
}

/// The sections on outages, and on feedback against output correction.
fn outages_markdown(r: &NavExperiment) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## 60 s outages every 180 s ({} outages per run)\n",
        r.outage_periods.len()
    );
    let mut t = Table::left(&[
        "filter",
        "drift at the end of an outage: RMS",
        "max",
        "end error",
        "RMS error",
    ]);
    for c in &r.outages {
        let (rms, max) = c.outage_drift_m.unwrap_or((f64::NAN, f64::NAN));
        t.row([
            c.name.clone(),
            format!("{rms:.1} m"),
            format!("{max:.1} m"),
            format!("{:.1} m", c.end_position_error_m),
            format!("{:.1} m", c.rms_position_error_m),
        ]);
    }
    s += &t.finish();
    s += "\n## Feedback (the default) against paper 003's output correction\n\n";
    let mut t = Table::left(&[
        "filter",
        "feedback: end / RMS",
        "output correction: end / RMS",
    ]);
    for (fb, oc) in r.table4[1..].iter().zip(&r.output_correction) {
        t.row([
            fb.name.clone(),
            format!(
                "{:.1} / {:.1} m",
                fb.end_position_error_m, fb.rms_position_error_m
            ),
            format!(
                "{:.1} / {:.1} m",
                oc.end_position_error_m, oc.rms_position_error_m
            ),
        ]);
    }
    s += &t.finish();
    let _ = writeln!(
        s,
        "\nWith output correction the INS runs free (kilometres off after 20 minutes, like the pure INS) and the filter's linear error model has to describe that whole error.\n"
    );
    s
}

/// The section on a receiver the filters do not model.
fn mis_modelled_markdown(r: &NavExperiment) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let e = &r.environment;
    let _ = writeln!(
        s,
        "## A receiver the filters do not model ({} surroundings)\n\nThe same 25 m class receiver, plus: the satellites used change every {:.0} s on average (the solution steps by {:.0} m per axis, 1 sigma, and the HDOP follows the number used: nominal {:.1}), and multipath bursts of {:.0}-{:.0} s add a {:.0} m error (correlated over {:.0} s) every {:.0} s on average. HDOP-scaled: the filter scales its white noise by the fix's HDOP over the nominal.\n",
        e.preset,
        e.constellation_change_every_s,
        e.constellation_step_sigma_m,
        e.hdop,
        e.multipath_duration_s[0],
        e.multipath_duration_s[1],
        e.multipath_sigma_m,
        e.multipath_tau_s,
        e.multipath_every_s
    );
    let mut t = Table::left(&[
        "filter",
        "end position (per run)",
        "receiver's slow error at the end",
        "RMS position",
        "end velocity",
        "RMS velocity",
        "NEES/dof pos / vel",
        "gate rejections",
        "integrity alarms",
    ]);
    for c in &r.mis_modelled {
        let rejected: u64 = c
            .runs
            .iter()
            .filter_map(|r| r.filter.as_ref().map(|f| f.rejected))
            .sum();
        let per_run: Vec<String> = c
            .runs
            .iter()
            .map(|r| format!("{:.1}", r.end_position_error_m))
            .collect();
        t.row([
            c.name.clone(),
            format!("{:.1} m ({})", c.end_position_error_m, per_run.join(", ")),
            c.end_receiver_wander_m
                .map_or("--".into(), |w| format!("{w:.1} m")),
            format!("{:.1} m", c.rms_position_error_m),
            format!("{:.2} m/s", c.end_velocity_error_mps),
            format!("{:.2} m/s", c.rms_velocity_error_mps),
            nees_text(c.mean_nees_per_dof),
            rejected.to_string(),
            c.integrity_alarms.to_string(),
        ]);
    }
    s += &t.finish();
    let _ = writeln!(
        s,
        "\nFading or adaptive at or below {:.0} % of the standard filter's end error (paper 003's margin, 9.7 against 20.7 m): **{}**. The receiver's slow error at the end (its mean over the last 60 s of fixes: the white noise and the bursts average out, the wander of minutes does not) is what even a filter that removed every fast error would carry; a single run's ratio scatters widely (see the per-run figures).\n",
        PAPER_MARGIN * 100.0,
        yes(r.beats_standard_by_paper_margin)
    );
    let _ = writeln!(
        s,
        "\nNEES per degree of freedom is 1 for a consistent filter (0.5 to 2 is the target). The filter models the receiver's slow Gauss-Markov wander (12 m, 300 s) as three states of its own; a filter that assumes the wrong receiver (the mis-specified cases) cannot be consistent.\n\nFiles: `report.json`, `series.csv` (first run of each case, 1 Hz), `position-error.svg`, `velocity-error.svg`, `outages.svg`."
    );
    s
}

fn yes(b: bool) -> &'static str {
    if b { "yes" } else { "NO" }
}

/// Short text for the terminal.
pub fn text(r: &NavExperiment) -> String {
    let mut s = String::new();
    s += &format!(
        " {}: {:.0} s navigated; north-finding error {}\n",
        r.scenario,
        r.navigated_s,
        r.north_finding_error_deg
            .map_or("--".into(), |e| format!("{e:+.4} deg"))
    );
    s += " Table 4            paper pos   ours pos    paper vel  ours vel   RMS pos\n";
    for (i, c) in r.table4.iter().enumerate() {
        let p = PAPER_TABLE4.get(i);
        s += &format!(
            " {:<18} {:>9} m {:>9.1} m {:>7} m/s {:>6.2} m/s {:>7.1} m\n",
            c.name,
            p.map_or("--".into(), |p| p.1.to_string()),
            c.end_position_error_m,
            p.map_or("--".into(), |p| p.2.to_string()),
            c.end_velocity_error_mps,
            c.rms_position_error_m
        );
    }
    for (sig, cases) in &r.misspecified {
        let cells: Vec<String> = cases
            .iter()
            .zip(KINDS)
            .map(|(c, (_, n))| format!("{n} {:.1} m", c.rms_position_error_m))
            .collect();
        s += &format!(" assumes {sig:>5} m   RMS {}\n", cells.join(", "));
    }
    for c in &r.mis_modelled {
        s += &format!(
            " {:<44} end {:.1} m, RMS {:.1} m\n",
            c.name, c.end_position_error_m, c.rms_position_error_m
        );
    }
    for c in &r.output_correction {
        s += &format!(
            " {:<28} end {:.1} m, RMS {:.1} m\n",
            c.name, c.end_position_error_m, c.rms_position_error_m
        );
    }
    for c in &r.outages {
        if let Some((rms, max)) = c.outage_drift_m {
            s += &format!(
                " {:<24} outage-end drift RMS {rms:.1} m, max {max:.1} m\n",
                c.name
            );
        }
    }
    s += &format!(
        " pure INS km class: {}; filters <= 20.7 m: {}; fading no worse with the noise overstated: {} (understated: {}); fading or adaptive beats standard by the paper's margin on the mis-modelled receiver: {}\n",
        yes(r.pure_km_class),
        yes(r.filters_within_paper),
        yes(r.fading_no_worse_overstated),
        yes(r.fading_no_worse_understated),
        yes(r.beats_standard_by_paper_margin)
    );
    s
}

/// Paper 003's Table 4 as an [`Experiment`](crate::experiments::Experiment).
pub struct Navigation;

impl crate::experiments::Experiment for Navigation {
    const NAME: &'static str = EXPERIMENT;
    type Options = NavExpOptions;
    type Run = PartRun;
    type Report = NavExperiment;
    fn part(o: &NavExpOptions, k: usize, n: usize, progress: bool) -> Result<NavPart> {
        run_part(o, k, n, progress)
    }
    fn merge(parts: &[NavPart], out: &Path, _progress: bool) -> Result<NavExperiment> {
        merge(parts, Some(out))
    }
    fn text(r: &NavExperiment) -> String {
        text(r)
    }
    fn met(r: &NavExperiment) -> bool {
        r.pure_km_class
            && r.filters_within_paper
            && r.fading_no_worse_overstated
            && r.beats_standard_by_paper_margin
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outages_start_after_drive_off_and_repeat() {
        let mut s = Scenario::builtin_static();
        s.drive = Some(emulators::drive::DriveSpec {
            lat_deg: 28.0,
            lon_deg: 113.0,
            height_m: 0.0,
            waypoints: vec![[0.0, 5000.0]],
            speed_mps: 10.0,
            accel_mps2: 1.0,
            turn_rate_dps: 10.0,
            lateral_accel_mps2: 2.0,
            laps: 1,
            start_wait_s: 10.0,
            ..Default::default()
        });
        s.duration_s = 1000.0;
        let o = outage_periods(&s, 60.0, 180.0);
        assert_eq!(o[0], [130.0, 190.0]);
        assert_eq!(o[1], [310.0, 370.0]);
        assert!(o.iter().all(|p| p[1] <= 515.0), "{o:?}");
    }

    /// A short drive run whole and in three parts (through their JSON, as separate processes
    /// would write them) gives the same report, plots included.
    #[test]
    fn three_parts_merged_give_the_single_run_report() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/drive-gps.toml");
        let mut scenario = Scenario::load(&path).unwrap();
        scenario.duration_s = 40.0;
        let o = NavExpOptions {
            scenario,
            runs: 1,
            misspecified_sigma_m: vec![5.0],
            outage_s: (10.0, 20.0),
            environment: paper_environment(),
            threads: 2,
        };
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let one = run(&o, Some(a.path()), false).unwrap();
        let parts: Vec<NavPart> = (0..3)
            .map(|k| {
                let p = run_part(&o, k, 3, false).unwrap();
                serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap()
            })
            .collect();
        let three = merge(&parts, Some(b.path())).unwrap();
        assert_eq!(
            serde_json::to_string(&one).unwrap(),
            serde_json::to_string(&three).unwrap()
        );
        for f in ["series.csv", "report.md"] {
            let read = |d: &tempfile::TempDir| std::fs::read_to_string(d.path().join(f)).unwrap();
            assert_eq!(read(&a), read(&b), "{f}");
        }
        assert!(
            merge(&parts[1..], None).is_err(),
            "a missing part is refused"
        );
    }
}
