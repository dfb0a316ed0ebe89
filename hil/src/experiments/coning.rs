//! Experiments that reproduce the papers' tables in process (same model and nav code as the
//! bench, no bus): `hil experiment coning` is paper 000's Tables 1-3.

use crate::engine::reference::run_in_process;
use crate::report::plot::{LogChart, Series};
use crate::scenario::Scenario;
use anyhow::{Context, Result};
use emulators::imu::ImuParams;
use emulators::truth::{Coning, Motion};
use nav::frontend::coning::{self, ConingCoefficients, ConingMethod};
use nav::frontend::dither_filter::Fir;
use nav::frontend::processing::ImuProcessor;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::Path;

/// The attitude algorithms of paper 000's Table 2, plus ours.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Alg {
    /// 1: ideal (unfiltered) data, classical coefficients.
    Ideal,
    /// 2: filtered data, classical coefficients.
    FilteredClassical,
    /// 3: filtered data, Taylor-tuned coefficients (the paper's method, our filter).
    FilteredTaylor,
    /// Ours: filtered data, coefficients fitted over the passband (nav's default).
    Ours,
}

impl Alg {
    /// All four, in table order.
    pub const ALL: [Alg; 4] = [
        Alg::Ideal,
        Alg::FilteredClassical,
        Alg::FilteredTaylor,
        Alg::Ours,
    ];

    /// Column name.
    pub fn name(self) -> &'static str {
        match self {
            Alg::Ideal => "alg 1",
            Alg::FilteredClassical => "alg 2",
            Alg::FilteredTaylor => "alg 3",
            Alg::Ours => "ours",
        }
    }

    fn method(self) -> ConingMethod {
        match self {
            Alg::Ideal | Alg::FilteredClassical => ConingMethod::Classical,
            Alg::FilteredTaylor => ConingMethod::Taylor,
            Alg::Ours => ConingMethod::Fitted,
        }
    }

    fn filtered(self) -> bool {
        self != Alg::Ideal
    }

    /// Paper 000's Table 2 value (deg per 60 s) at 1, 10, 50, 80 Hz, where it has one.
    pub fn paper_table2(self, f_hz: f64) -> Option<f64> {
        let i = TABLE_F.iter().position(|f| *f == f_hz)?;
        match self {
            Alg::Ideal => Some([-4.36e-10, 6.53e-10, 3.92e-6, 7.14e-5][i]),
            Alg::FilteredClassical => Some([-6.66e-5, -6.57e-2, -5.96, -10.78][i]),
            Alg::FilteredTaylor => Some([2.07e-7, 2.75e-6, 4.62e-2, 2.51][i]),
            Alg::Ours => None,
        }
    }

    /// Paper 000's Table 3 value (recorded dither and noise added), algorithms 2 and 3.
    pub fn paper_table3(self, f_hz: f64) -> Option<f64> {
        let i = TABLE_F.iter().position(|f| *f == f_hz)?;
        match self {
            Alg::FilteredClassical => Some([-2.85e-2, -1.09e-1, -5.99, -10.8][i]),
            Alg::FilteredTaylor => Some([-3.01e-2, -3.24e-2, 2.35e-2, 2.62][i]),
            _ => None,
        }
    }
}

/// The coning frequencies of the paper's tables, Hz.
pub const TABLE_F: [f64; 4] = [1.0, 10.0, 50.0, 80.0];
/// Half-cone angle of the paper's tables, deg.
pub const HALF_ANGLE_DEG: f64 = 1.0;
/// Sub-samples of the paper's tables.
pub const N: usize = 4;

/// The chain for `alg` (the filter is nav's default dither filter).
pub fn processor(alg: Alg, fir: &Fir) -> Result<ImuProcessor> {
    let f = alg.filtered().then_some(fir);
    Ok(ImuProcessor::with(
        f,
        ConingCoefficients::for_method(alg.method(), N, f)?,
    ))
}

/// Cone-axis drift (deg per 60 s) of `alg` on exact (noise-free, unquantized) increments of
/// classical coning at `f_hz`, over `duration_s`.
pub fn ideal_drift(alg: Alg, fir: &Fir, f_hz: f64, duration_s: f64) -> Result<f64> {
    let motion = Coning {
        half_angle_deg: HALF_ANGLE_DEG,
        frequency_hz: f_hz,
    };
    let dt = 1.0 / fir.spec().fs_hz;
    let mut p = processor(alg, fir)?;
    let mut upd = Vec::new();
    let n = (duration_s / dt).round() as u64;
    for k in 0..n {
        let inc = motion.increments(k as f64 * dt, (k + 1) as f64 * dt);
        p.push_increment(inc.dtheta.into(), [0.0; 3], &mut upd);
        upd.clear();
    }
    let (t0, t1) = (
        p.origin().unwrap_or(0) as f64 * dt,
        p.valid_sample() as f64 * dt,
    );
    let e = crate::engine::reference::attitude_error(&motion, t0, t1, &p.attitude());
    Ok(e[0].to_degrees() * 60.0 / (t1 - t0))
}

/// Cone-axis drift (deg per 60 s) of `alg` on the emulated IMU (dither, noise, drift,
/// quantization, scale factor and misalignment: the default sensor model) under classical
/// coning, through frames and nav's front end.
pub fn emulated_drift(alg: Alg, f_hz: f64, duration_s: f64, imu: &ImuParams) -> Result<f64> {
    let mut s = Scenario::builtin_static();
    s.name = "coning".into();
    s.duration_s = duration_s;
    s.coning = Some(Coning {
        half_angle_deg: HALF_ANGLE_DEG,
        frequency_hz: f_hz,
    });
    s.imu = imu.clone();
    s.processing.dither_filter = alg.filtered();
    s.processing.coning = alg.method();
    s.processing.coning_samples = N;
    let r = run_in_process(&s)?;
    let span = (r.valid_sample - r.origin_sample.unwrap_or(0)) as f64 / s.imu.rate_hz;
    Ok(r.error_deg[0] * 60.0 / span)
}

/// Options of the coning experiment.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ConingOptions {
    /// Run length for the tables, s (the paper's 60 s).
    pub duration_s: f64,
    /// Step of the simulated frequency sweep, Hz.
    pub sweep_step_hz: f64,
    /// Run length of each sweep point, s (scaled to 60 s).
    pub sweep_duration_s: f64,
    /// IMU model for the Table 3 analogue.
    pub imu: ImuParams,
}

impl Default for ConingOptions {
    fn default() -> Self {
        Self {
            duration_s: 60.0,
            sweep_step_hz: 2.0,
            sweep_duration_s: 10.0,
            imu: ImuParams {
                seed: 7,
                // 1 deg coning at 80 Hz peaks at 502 deg/s, beyond the RLG's 400 deg/s range
                // (the paper added recorded sensor data to ideal coning, without a range limit)
                gyro_range_dps: 1000.0,
                ..ImuParams::default()
            },
        }
    }
}

/// Table 1: the coefficient sets for one `n`.
#[derive(Debug, Clone, Serialize)]
pub struct CoefficientRow {
    /// Sub-samples.
    pub n: usize,
    /// Classical (exact rationals).
    pub classical: Vec<f64>,
    /// Paper 000's filter-tuned row (for its filter).
    pub paper_tuned: Vec<f64>,
    /// Our Taylor-tuned set (for our filter).
    pub taylor: Vec<f64>,
    /// Our fitted set (nav's default).
    pub fitted: Vec<f64>,
}

/// One row of a table.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Row {
    /// Coning frequency, Hz.
    pub f_hz: f64,
    /// Drift per algorithm (deg per 60 s), in `Alg::ALL` order; `None` where not run.
    pub drift: Vec<Option<f64>>,
}

/// Everything the experiment measured.
#[derive(Debug, Clone, Serialize)]
pub struct ConingReport {
    /// Coefficient sets for n = 2..5.
    pub coefficients: Vec<CoefficientRow>,
    /// Filter response.
    pub fir: nav::frontend::dither_filter::FirResponse,
    /// Table 2 analogue (exact data).
    pub table2: Vec<Row>,
    /// Table 3 analogue (emulated sensor).
    pub table3: Vec<Row>,
    /// Simulated sweep on exact data.
    pub sweep: Vec<Row>,
    /// Ours at least 10x below the paper's algorithm 3 at 50 and 80 Hz.
    pub ours_10x_below_paper_alg3: bool,
    /// Sweep points where ours drifted more than algorithm 2.
    pub ours_worse_than_alg2_at: Vec<f64>,
}

/// One row of the experiment's tables: which table, at which coning frequency.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
enum RowJob {
    /// Table 2 (ideal coning through the filter) at f Hz.
    Table2(f64),
    /// The Table 3 analogue (the emulated IMU) at f Hz.
    Table3(f64),
    /// A point of the frequency sweep at f Hz.
    Sweep(f64),
}

fn row_jobs(opts: &ConingOptions) -> Vec<RowJob> {
    let mut v: Vec<RowJob> = TABLE_F.iter().map(|&f| RowJob::Table2(f)).collect();
    v.extend(TABLE_F.iter().map(|&f| RowJob::Table3(f)));
    let mut f = opts.sweep_step_hz;
    while f <= 100.0 + 1e-9 {
        v.push(RowJob::Sweep(f));
        f += opts.sweep_step_hz;
    }
    v
}

fn run_row(job: RowJob, opts: &ConingOptions, fir: &Fir) -> Result<Row> {
    Ok(match job {
        RowJob::Table2(f) => Row {
            f_hz: f,
            drift: Alg::ALL
                .iter()
                .map(|a| ideal_drift(*a, fir, f, opts.duration_s).map(Some))
                .collect::<Result<_>>()?,
        },
        RowJob::Table3(f) => {
            let mut drift = vec![None];
            for a in &Alg::ALL[1..] {
                drift.push(Some(emulated_drift(*a, f, opts.duration_s, &opts.imu)?));
            }
            Row { f_hz: f, drift }
        }
        RowJob::Sweep(f) => Row {
            f_hz: f,
            drift: Alg::ALL
                .iter()
                .map(|a| ideal_drift(*a, fir, f, opts.sweep_duration_s).map(Some))
                .collect::<Result<_>>()?,
        },
    })
}

/// Part `k` of `n` of the coning experiment: its rows (see [`crate::experiments::shard`]).
pub type ConingPart = crate::experiments::shard::Part<Row>;

/// The coning experiment's name in its parts.
pub const CONING: &str = "coning";

/// Run part `shard` of `shards` of the coning experiment: the table rows whose place in the
/// plan is `shard` modulo `shards`, on the machine's cores.
pub fn coning_part(
    opts: &ConingOptions,
    shard: usize,
    shards: usize,
    progress: bool,
) -> Result<ConingPart> {
    let fir = Fir::default_dither_filter();
    let all = row_jobs(opts);
    let total = all.len();
    let mine = crate::experiments::shard::select(all, shard, shards)?;
    if progress {
        eprintln!(
            "experiment: {} of {total} rows (Tables 2 and 3 at {} frequencies, the sweep in {} Hz steps)",
            mine.len(),
            TABLE_F.len(),
            opts.sweep_step_hz
        );
    }
    let rows = crate::par::map(
        &mine,
        crate::par::threads(),
        |(g, j)| run_row(*j, opts, &fir).map(|r| (*g, r)),
        || Err(anyhow::anyhow!("worker panicked")),
    );
    Ok(ConingPart {
        experiment: CONING.into(),
        plan: serde_json::to_value(opts)?,
        shard,
        shards,
        total,
        outcomes: rows.into_iter().collect::<Result<_>>()?,
    })
}

/// Run the coning experiment (one part of one, merged) and write its files to `out`.
pub fn coning(opts: &ConingOptions, out: &Path, progress: bool) -> Result<ConingReport> {
    let part = coning_part(opts, 0, 1, progress)?;
    coning_merge(&[part], out)
}

/// Merge the parts of a coning experiment (every part once) into its report, written to `out`.
pub fn coning_merge(parts: &[ConingPart], out: &Path) -> Result<ConingReport> {
    let rows = crate::experiments::shard::assemble(parts)?;
    let opts: ConingOptions = serde_json::from_value(parts[0].plan.clone())
        .context("the parts' plan is not a coning experiment's")?;
    let jobs = row_jobs(&opts);
    if jobs.len() != rows.len() {
        anyhow::bail!(
            "the parts hold {} rows, their plan {}",
            rows.len(),
            jobs.len()
        );
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let fir = Fir::default_dither_filter();
    let coefficients = (2..=5)
        .map(|n| CoefficientRow {
            n,
            classical: coning::classical(n).k,
            paper_tuned: coning::paper_000_tuned(n),
            taylor: ConingCoefficients::taylor(n, &fir).k,
            fitted: ConingCoefficients::fitted(n, &fir, fir.spec().passband_hz)
                .map(|c| c.k)
                .unwrap_or_default(),
        })
        .collect();
    let (mut table2, mut table3, mut sweep) = (Vec::new(), Vec::new(), Vec::new());
    for (j, r) in jobs.iter().zip(rows) {
        match j {
            RowJob::Table2(_) => table2.push(r),
            RowJob::Table3(_) => table3.push(r),
            RowJob::Sweep(_) => sweep.push(r),
        }
    }
    let at = |rows: &[Row], f: f64, a: usize| {
        rows.iter()
            .find(|r| r.f_hz == f)
            .and_then(|r| r.drift[a])
            .unwrap_or(f64::NAN)
    };
    let ours_10x_below_paper_alg3 = [50.0, 80.0].iter().all(|&f| {
        let paper = Alg::FilteredTaylor.paper_table2(f).unwrap_or(0.0).abs();
        at(&table2, f, 3).abs() * 10.0 <= paper
    });
    let ours_worse_than_alg2_at = sweep
        .iter()
        .chain(&table2)
        .filter(|r| {
            let (a2, o) = (r.drift[1].unwrap_or(0.0), r.drift[3].unwrap_or(0.0));
            o.abs() > a2.abs()
        })
        .map(|r| r.f_hz)
        .collect();
    let report = ConingReport {
        coefficients,
        fir: fir.response(),
        table2,
        table3,
        sweep,
        ours_10x_below_paper_alg3,
        ours_worse_than_alg2_at,
    };
    write_files(&report, &fir, out)?;
    Ok(report)
}

fn csv(rows: &[Row], paper: impl Fn(Alg, f64) -> Option<f64>) -> String {
    let mut s = String::from("f_hz");
    for a in Alg::ALL {
        let _ = write!(
            s,
            ",{}_deg_per_60s,{}_paper",
            a.name().replace(' ', ""),
            a.name().replace(' ', "")
        );
    }
    s.push('\n');
    for r in rows {
        let _ = write!(s, "{}", r.f_hz);
        for (i, a) in Alg::ALL.iter().enumerate() {
            let v = r.drift[i].map(|x| format!("{x:e}")).unwrap_or_default();
            let p = paper(*a, r.f_hz)
                .map(|x| format!("{x:e}"))
                .unwrap_or_default();
            let _ = write!(s, ",{v},{p}");
        }
        s.push('\n');
    }
    s
}

fn write_files(r: &ConingReport, fir: &Fir, out: &Path) -> Result<()> {
    let w = |name: &str, text: String| {
        std::fs::write(out.join(name), text).with_context(|| format!("writing {name}"))
    };
    w("table2.csv", csv(&r.table2, Alg::paper_table2))?;
    w("table3.csv", csv(&r.table3, Alg::paper_table3))?;
    w("sweep.csv", csv(&r.sweep, |_, _| None))?;
    let mut pred = String::from("f_hz,alg1,alg2,alg3,ours\n");
    let a = HALF_ANGLE_DEG.to_radians();
    let sets: Vec<(Option<&Fir>, ConingCoefficients)> = Alg::ALL
        .iter()
        .map(|al| {
            let f = al.filtered().then_some(fir);
            Ok((f, ConingCoefficients::for_method(al.method(), N, f)?))
        })
        .collect::<Result<_>>()?;
    let mut predicted: Vec<Vec<(f64, f64)>> = vec![Vec::new(); 4];
    for i in 1..=200 {
        let f = 0.5 * f64::from(i);
        let _ = write!(pred, "{f}");
        for (j, (fl, c)) in sets.iter().enumerate() {
            let d = c.predicted_drift(*fl, a, f, fir.spec().fs_hz).to_degrees() * 60.0;
            let _ = write!(pred, ",{d:e}");
            predicted[j].push((f, d.abs()));
        }
        pred.push('\n');
    }
    w("predicted.csv", pred)?;
    w("report.json", serde_json::to_string_pretty(r)?)?;
    let colors = ["#555555", "#d62728", "#1f77b4", "#2ca02c"];
    let mut series = Vec::new();
    for (j, al) in Alg::ALL.iter().enumerate() {
        series.push(Series {
            name: format!("{} predicted", al.name()),
            color: colors[j],
            points: predicted[j].clone(),
            markers: false,
        });
        series.push(Series {
            name: format!("{} simulated", al.name()),
            color: colors[j],
            points: r
                .sweep
                .iter()
                .chain(&r.table2)
                .filter_map(|row| row.drift[j].map(|d| (row.f_hz, d.abs())))
                .collect(),
            markers: true,
        });
    }
    series.push(Series {
        name: "paper alg 2 / 3".into(),
        color: "#ff7f0e",
        points: TABLE_F
            .iter()
            .flat_map(|&f| {
                [Alg::FilteredClassical, Alg::FilteredTaylor]
                    .into_iter()
                    .filter_map(move |al| al.paper_table2(f).map(|p| (f, p.abs())))
            })
            .collect(),
        markers: true,
    });
    let chart = LogChart {
        title: format!("Coning drift, half-angle {HALF_ANGLE_DEG} deg, fs 2 kHz, n = {N}"),
        x_label: "coning frequency, Hz".into(),
        y_label: "|cone-axis drift|, deg per 60 s".into(),
        series,
    };
    w("coning-drift.svg", chart.svg())?;
    w("report.md", markdown(r))?;
    crate::report::page::folder_page(out, "Coning experiment (paper 000)", &markdown(r))?;
    Ok(())
}

fn fmt_opt(x: Option<f64>) -> String {
    x.map(|v| format!("{v:10.3e}"))
        .unwrap_or_else(|| format!("{:>10}", "-"))
}

/// The printed tables.
pub fn text(r: &ConingReport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Dither filter: order {}, passband deviation {:.3} dB to 100 Hz, {:.1} dB from 300 Hz, delay {} samples\n",
        r.fir.delay_samples * 2,
        r.fir.passband_deviation_db,
        r.fir.stopband_attenuation_db,
        r.fir.delay_samples
    );
    let _ = writeln!(s, "Table 1: coning coefficients k_1..k_(n-1)");
    for CoefficientRow {
        n,
        classical: c,
        paper_tuned: p,
        taylor: t,
        fitted: f,
    } in &r.coefficients
    {
        let show = |v: &Vec<f64>| {
            v.iter()
                .map(|x| format!("{x:.4}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let _ = writeln!(s, "  n={n} classical     {}", show(c));
        let _ = writeln!(s, "      paper tuned   {}", show(p));
        let _ = writeln!(s, "      our Taylor    {}", show(t));
        let _ = writeln!(s, "      our fit       {}", show(f));
    }
    for (title, rows, paper) in [
        (
            "Table 2: cone-axis drift, deg per 60 s (exact data)",
            &r.table2,
            Alg::paper_table2 as fn(Alg, f64) -> Option<f64>,
        ),
        (
            "Table 3 analogue: emulated sensor (dither, bias, drift, noise, scale factor, misalignment, quantization; range opened to 1000 deg/s)",
            &r.table3,
            Alg::paper_table3,
        ),
    ] {
        let _ = writeln!(s, "\n{title}");
        let _ = writeln!(
            s,
            "  {:>5} | {:>10} {:>10} | {:>10} {:>10} | {:>10} {:>10} | {:>10}",
            "f Hz", "alg 1", "paper", "alg 2", "paper", "alg 3", "paper", "ours"
        );
        for row in rows.iter() {
            let _ = writeln!(
                s,
                "  {:>5} | {} {} | {} {} | {} {} | {}",
                row.f_hz,
                fmt_opt(row.drift[0]),
                fmt_opt(paper(Alg::Ideal, row.f_hz)),
                fmt_opt(row.drift[1]),
                fmt_opt(paper(Alg::FilteredClassical, row.f_hz)),
                fmt_opt(row.drift[2]),
                fmt_opt(paper(Alg::FilteredTaylor, row.f_hz)),
                fmt_opt(row.drift[3]),
            );
        }
    }
    let _ = writeln!(
        s,
        "\nTargets:\n  ours >= 10x below the paper's alg 3 at 50 and 80 Hz: {}\n  ours never worse than alg 2 ({} sweep points, {}..100 Hz, plus the table): {}",
        if r.ours_10x_below_paper_alg3 {
            "MET"
        } else {
            "MISSED"
        },
        r.sweep.len(),
        r.sweep.first().map_or(0.0, |x| x.f_hz),
        if r.ours_worse_than_alg2_at.is_empty() {
            "MET".to_string()
        } else {
            format!("MISSED at {:?} Hz", r.ours_worse_than_alg2_at)
        }
    );
    s
}

fn markdown(r: &ConingReport) -> String {
    format!(
        "# Coning experiment (paper 000, Tables 1-3)\n\n```\n{}```\n\nFiles: `table2.csv`, `table3.csv`, `sweep.csv` (simulated), `predicted.csv` (analytic, 0.5 Hz steps), `coning-drift.svg`, `report.json`.\n\nSee `docs/coning.md` for the derivation and how our figures compare with the paper's.\n",
        text(r)
    )
}

/// Paper 000's coning tables as an [`Experiment`](crate::experiments::Experiment).
pub struct ConingTables;

impl crate::experiments::Experiment for ConingTables {
    const NAME: &'static str = CONING;
    type Options = ConingOptions;
    type Run = Row;
    type Report = ConingReport;
    fn part(o: &ConingOptions, k: usize, n: usize, progress: bool) -> Result<ConingPart> {
        coning_part(o, k, n, progress)
    }
    fn merge(parts: &[ConingPart], out: &Path, _progress: bool) -> Result<ConingReport> {
        coning_merge(parts, out)
    }
    fn text(r: &ConingReport) -> String {
        text(r)
    }
    fn met(r: &ConingReport) -> bool {
        r.ours_10x_below_paper_alg3 && r.ours_worse_than_alg2_at.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simulated_drift_agrees_with_the_analytic_prediction() {
        let fir = Fir::default_dither_filter();
        let a = HALF_ANGLE_DEG.to_radians();
        for (alg, f) in [
            (Alg::FilteredClassical, 10.0),
            (Alg::FilteredClassical, 80.0),
            (Alg::FilteredTaylor, 80.0),
        ] {
            let sim = ideal_drift(alg, &fir, f, 5.0).unwrap();
            let fl = alg.filtered().then_some(&fir);
            let pred = ConingCoefficients::for_method(alg.method(), N, fl)
                .unwrap()
                .predicted_drift(fl, a, f, 2000.0)
                .to_degrees()
                * 60.0;
            // the prediction is of order a^2 only: 10 % agreement where the drift is large (for
            // our set the a^4 terms the prediction leaves out are of the same size as its drift)
            assert!(
                (sim - pred).abs() <= 0.1 * pred.abs() + 2e-4,
                "{alg:?} {f} Hz: simulated {sim:e}, predicted {pred:e}"
            );
        }
    }

    #[test]
    fn ours_beats_algorithm_2_and_3_at_high_frequency() {
        let fir = Fir::default_dither_filter();
        let d = |alg| ideal_drift(alg, &fir, 80.0, 5.0).unwrap().abs();
        let (a2, a3, ours) = (
            d(Alg::FilteredClassical),
            d(Alg::FilteredTaylor),
            d(Alg::Ours),
        );
        assert!(ours * 100.0 < a2, "ours {ours:e} alg2 {a2:e}");
        assert!(ours * 3.0 < a3, "ours {ours:e} alg3 {a3:e}");
        // and the ideal algorithm drifts least of all
        assert!(d(Alg::Ideal) < ours);
    }

    /// The coning tables run whole and in three parts (through their JSON) are the same.
    #[test]
    fn coning_in_three_parts_merged_is_the_single_run() {
        let o = ConingOptions {
            duration_s: 2.0,
            sweep_step_hz: 40.0,
            sweep_duration_s: 1.0,
            ..ConingOptions::default()
        };
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let one = coning(&o, a.path(), false).unwrap();
        let parts: Vec<ConingPart> = (0..3)
            .map(|k| {
                let p = coning_part(&o, k, 3, false).unwrap();
                serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap()
            })
            .collect();
        let three = coning_merge(&parts, b.path()).unwrap();
        assert_eq!(
            serde_json::to_string(&one).unwrap(),
            serde_json::to_string(&three).unwrap()
        );
        assert_eq!(one.sweep.len(), 2);
    }
}
