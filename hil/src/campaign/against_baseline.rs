//! A case's verdict for one build against the baseline, from their cells' results.
//!
//! - **same**: every seed of both ran, and each sent the same frames (the hash of everything
//!   nav sent) as the baseline with that seed: lockstep runs repeat bit for bit, so the build
//!   behaves identically on this case;
//! - **flaky**: the build's repeats disagree on pass or fail (said, never averaged away);
//! - **worse** / **better**: the case failed where the baseline passed (or the reverse), or a
//!   figure's difference from the baseline's is beyond its 95 % interval: with the same seeds on
//!   both sides, Student's t over the per-seed differences (the seed's own luck cancels); with
//!   unmatched seeds, Welch's interval on the difference of the means. A figure is worse when
//!   larger (an error, a sigma, a latency) or, for a NEES or NIS, when further from 1 (as
//!   `|ln x|`);
//! - **not distinguishable**: no difference beyond the scatter (or one run a side: no scatter
//!   to judge by).

use crate::stats::t_975;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// What one cell gave.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellResult {
    /// The device.
    pub device: String,
    /// The case's id.
    pub case: String,
    /// The seed.
    pub seed: u64,
    /// The case's own pass or fail (none where it has none).
    pub pass: Option<bool>,
    /// The figures, by name (`end_position_error_m`, `nees_position`, `latency_ms`, ...).
    pub figures: BTreeMap<String, f64>,
    /// The hash of what nav sent (lockstep runs), for "the same bit for bit".
    pub sent_hash: Option<String>,
}

/// A case's verdict for a build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// Worse than the baseline.
    Worse,
    /// Its repeats disagree on pass or fail.
    Flaky,
    /// No result to compare (a cell did not run).
    Missing,
    /// Better than the baseline.
    Better,
    /// No difference beyond the scatter.
    NotDistinguishable,
    /// Bit for bit the baseline's frames.
    Same,
}

impl std::fmt::Display for Verdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Worse => "worse",
            Self::Flaky => "flaky",
            Self::Missing => "missing",
            Self::Better => "better",
            Self::NotDistinguishable => "not distinguishable",
            Self::Same => "same",
        })
    }
}

/// Which way a figure is better.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sense {
    /// Smaller is better (errors, sigmas, latencies, counts of faults).
    Lower,
    /// Nearer 1 is better (NEES, NIS per degree of freedom), compared as `|ln x|`.
    NearOne,
}

impl Sense {
    /// A figure's sense from its name: NEES and NIS are best at 1, all else when smaller.
    pub fn of(name: &str) -> Self {
        let n = name.to_ascii_lowercase();
        if n.contains("nees") || n.contains("nis") {
            Self::NearOne
        } else {
            Self::Lower
        }
    }

    /// How bad `x` is, larger worse.
    fn badness(self, x: f64) -> f64 {
        match self {
            Self::Lower => x,
            Self::NearOne => x.max(1e-300).ln().abs(),
        }
    }
}

/// One figure of a case, the build against the baseline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FigureVerdict {
    /// The figure's name.
    pub name: String,
    /// The baseline's mean over its seeds.
    pub baseline: f64,
    /// The build's.
    pub build: f64,
    /// The difference of their badness (build less baseline: positive is worse) and the
    /// half-width of its 95 % interval (none with one run a side).
    pub difference: f64,
    /// See [`FigureVerdict::difference`].
    pub interval: Option<f64>,
    /// Whether the seeds were paired (the same seeds on both sides).
    pub paired: bool,
    /// The figure's verdict.
    pub verdict: Verdict,
}

/// A case's verdict for a build, with its figures'.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseVerdict {
    /// The case's id.
    pub case: String,
    /// The build's device name.
    pub device: String,
    /// The verdict.
    pub verdict: Verdict,
    /// Why, in a line.
    pub why: String,
    /// Each figure both sides have.
    pub figures: Vec<FigureVerdict>,
}

/// Mean and sample variance.
fn mean_var(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = if x.len() > 1 {
        x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (m, v)
}

/// Compare one figure: `base` and `build` by seed.
fn figure(name: &str, base: &[(u64, f64)], build: &[(u64, f64)]) -> FigureVerdict {
    let sense = Sense::of(name);
    let bad = |v: &[(u64, f64)]| -> Vec<f64> { v.iter().map(|x| sense.badness(x.1)).collect() };
    let mean = |v: &[(u64, f64)]| v.iter().map(|x| x.1).sum::<f64>() / v.len() as f64;
    let mut seeds_b: Vec<u64> = base.iter().map(|x| x.0).collect();
    let mut seeds_d: Vec<u64> = build.iter().map(|x| x.0).collect();
    seeds_b.sort_unstable();
    seeds_d.sort_unstable();
    let paired = seeds_b == seeds_d;
    let (difference, interval) = if paired {
        let d: Vec<f64> = seeds_b
            .iter()
            .map(|s| {
                let at = |v: &[(u64, f64)]| v.iter().find(|x| x.0 == *s).map_or(f64::NAN, |x| x.1);
                sense.badness(at(build)) - sense.badness(at(base))
            })
            .collect();
        let (m, v) = mean_var(&d);
        let hw = (d.len() > 1).then(|| t_975(d.len() - 1) * (v / d.len() as f64).sqrt());
        (m, hw)
    } else {
        let (bb, bd) = (bad(base), bad(build));
        let ((mb, vb), (md, vd)) = (mean_var(&bb), mean_var(&bd));
        let (nb, nd) = (bb.len() as f64, bd.len() as f64);
        let hw = (bb.len() > 1 && bd.len() > 1).then(|| {
            let (qb, qd) = (vb / nb, vd / nd);
            let se2 = qb + qd;
            // Welch-Satterthwaite degrees of freedom
            let df = if se2 > 0.0 {
                se2 * se2 / (qb * qb / (nb - 1.0) + qd * qd / (nd - 1.0))
            } else {
                nb + nd - 2.0
            };
            t_975(df.floor().max(1.0) as usize) * se2.sqrt()
        });
        (md - mb, hw)
    };
    let verdict = match interval {
        Some(hw) if difference - hw > 0.0 => Verdict::Worse,
        Some(hw) if difference + hw < 0.0 => Verdict::Better,
        _ => Verdict::NotDistinguishable,
    };
    FigureVerdict {
        name: name.to_string(),
        baseline: mean(base),
        build: mean(build),
        difference,
        interval,
        paired,
        verdict,
    }
}

/// Every figure both sides have in every cell, compared.
fn figures_of(base: &[CellResult], build: &[CellResult]) -> Vec<FigureVerdict> {
    let names: Vec<&String> = base
        .iter()
        .flat_map(|c| c.figures.keys())
        .filter(|n| {
            build.iter().all(|c| c.figures.contains_key(*n))
                && base.iter().all(|c| c.figures.contains_key(*n))
        })
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let series = |v: &[CellResult], n: &str| -> Vec<(u64, f64)> {
        v.iter().map(|c| (c.seed, c.figures[n])).collect()
    };
    names
        .iter()
        .map(|n| figure(n, &series(base, n), &series(build, n)))
        .collect()
}

/// Every seed of both sides ran and sent the same frames (their hashes equal).
fn same_frames(base: &[CellResult], build: &[CellResult]) -> bool {
    let hash_of = |s: u64| {
        build
            .iter()
            .find(|c| c.seed == s)
            .and_then(|c| c.sent_hash.as_ref())
    };
    base.len() == build.len()
        && base
            .iter()
            .all(|b| b.sent_hash.is_some() && hash_of(b.seed) == b.sent_hash.as_ref())
}

/// Why the same: the seeds, and the failures both had.
fn same_why(seeds: usize, passed: usize, failed: usize) -> String {
    let both = if failed > 0 {
        format!(" (both: {passed} passed, {failed} failed)")
    } else {
        String::new()
    };
    format!("the same frames as the baseline, bit for bit, with each of its {seeds} seeds{both}")
}

/// Why flaky: the seeds that failed.
fn flaky_why(build: &[CellResult], passed: usize, failed: usize) -> String {
    let seeds: Vec<String> = build
        .iter()
        .filter(|c| c.pass == Some(false))
        .map(|c| c.seed.to_string())
        .collect();
    format!(
        "its repeats disagree: {passed} passed, {failed} failed (seed {})",
        seeds.join(", ")
    )
}

/// The verdict of case `case` for the build whose cells are `build`, against the baseline's
/// cells `base` (both of that case only).
pub fn judge(case: &str, base: &[CellResult], build: &[CellResult]) -> CaseVerdict {
    let device = build.first().map_or_else(String::new, |c| c.device.clone());
    let done = |verdict: Verdict, why: String, figures: Vec<FigureVerdict>| CaseVerdict {
        case: case.to_string(),
        device: device.clone(),
        verdict,
        why,
        figures,
    };
    if base.is_empty() || build.is_empty() {
        let side = if base.is_empty() {
            "the baseline"
        } else {
            "this build"
        };
        return done(
            Verdict::Missing,
            format!("no result from {side}"),
            Vec::new(),
        );
    }
    let passes = |v: &[CellResult]| -> (usize, usize) {
        v.iter().fold((0, 0), |(p, f), c| match c.pass {
            Some(true) => (p + 1, f),
            Some(false) => (p, f + 1),
            None => (p, f),
        })
    };
    let (bp, bf) = passes(base);
    let (dp, df) = passes(build);
    let same = same_frames(base, build);
    if same {
        return done(Verdict::Same, same_why(base.len(), bp, bf), Vec::new());
    }
    let figures = figures_of(base, build);
    if dp > 0 && df > 0 {
        return done(Verdict::Flaky, flaky_why(build, dp, df), figures);
    }
    let listed = |v: Verdict| -> Vec<String> {
        figures
            .iter()
            .filter(|f| f.verdict == v)
            .map(|f| format!("{} {:.4} against {:.4}", f.name, f.build, f.baseline))
            .collect()
    };
    if bf == 0 && df > 0 {
        return done(
            Verdict::Worse,
            format!("failed ({df} of {}), the baseline passed", build.len()),
            figures,
        );
    }
    if bp == 0 && bf > 0 && dp > 0 {
        return done(
            Verdict::Better,
            "passed where the baseline failed".into(),
            figures,
        );
    }
    let (worse, better) = (listed(Verdict::Worse), listed(Verdict::Better));
    if !worse.is_empty() {
        return done(
            Verdict::Worse,
            format!("worse: {}", worse.join("; ")),
            figures,
        );
    }
    if !better.is_empty() {
        return done(
            Verdict::Better,
            format!("better: {}", better.join("; ")),
            figures,
        );
    }
    let why = if base.len() < 2 && build.len() < 2 {
        "one run a side: no scatter to judge a difference by".to_string()
    } else {
        "no figure differs beyond its 95 % interval".to_string()
    };
    done(Verdict::NotDistinguishable, why, figures)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn cell(device: &str, seed: u64, figures: &[(&str, f64)]) -> CellResult {
        CellResult {
            device: device.into(),
            case: "scenario:drive".into(),
            seed,
            pass: Some(true),
            figures: figures.iter().map(|(n, v)| (n.to_string(), *v)).collect(),
            sent_hash: None,
        }
    }

    /// `n` seeds of a figure around `mean` (+- `spread`, uniform), the luck of a seed shared
    /// between builds when `shared` (the same IMU and receiver noise for the same seed).
    fn runs(
        rng: &mut rand::rngs::StdRng,
        device: &str,
        n: u64,
        mean: f64,
        luck: &[f64],
        own: f64,
    ) -> Vec<CellResult> {
        (1..=n)
            .map(|s| {
                let v = mean + luck[(s - 1) as usize] + own * (rng.random::<f64>() - 0.5);
                cell(device, s, &[("rms_position_error_m", v)])
            })
            .collect()
    }

    #[test]
    fn a_known_shift_is_found_and_two_seeds_scatter_is_not() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let luck: Vec<f64> = (0..8).map(|_| 4.0 * (rng.random::<f64>() - 0.5)).collect();
        // a build 15 % worse on an error of 3 m whose seeds scatter it by +-2 m
        let base = runs(&mut rng, "base", 8, 3.0, &luck, 0.3);
        let worse = runs(&mut rng, "worse", 8, 3.45, &luck, 0.3);
        let v = judge("scenario:drive", &base, &worse);
        assert_eq!(v.verdict, Verdict::Worse, "{v:?}");
        assert!(v.figures[0].paired);
        let better = judge("scenario:drive", &worse, &base);
        assert_eq!(better.verdict, Verdict::Better, "{better:?}");
        // the same build, another 400 draws of its own scatter: called worse about 2.5 % of the
        // time (the interval's one tail), never more than 6 %
        let mut called = 0;
        for _ in 0..400 {
            let luck: Vec<f64> = (0..4).map(|_| 4.0 * (rng.random::<f64>() - 0.5)).collect();
            let a = runs(&mut rng, "a", 4, 3.0, &luck, 0.3);
            let b = runs(&mut rng, "b", 4, 3.0, &luck, 0.3);
            called += usize::from(judge("c", &a, &b).verdict == Verdict::Worse);
        }
        eprintln!("{called} of 400 called worse");
        assert!(called <= 24, "{called} of 400 called worse");
        // unpaired (other seeds each side): Welch's interval, the same shift at 8 a side
        let base: Vec<CellResult> = (0..8)
            .map(|s| {
                cell(
                    "base",
                    s,
                    &[("x_m", 3.0 + 0.3 * (rng.random::<f64>() - 0.5))],
                )
            })
            .collect();
        let worse: Vec<CellResult> = (100..108)
            .map(|s| {
                cell(
                    "worse",
                    s,
                    &[("x_m", 3.45 + 0.3 * (rng.random::<f64>() - 0.5))],
                )
            })
            .collect();
        let v = judge("c", &base, &worse);
        assert_eq!(v.verdict, Verdict::Worse, "{v:?}");
        assert!(!v.figures[0].paired);
    }

    #[test]
    fn a_nees_is_worse_away_from_one_either_way() {
        let side = |d: &str, x: f64| -> Vec<CellResult> {
            (1..=4)
                .map(|s| cell(d, s, &[("nees_position", x + 0.01 * s as f64)]))
                .collect()
        };
        assert_eq!(
            judge("c", &side("a", 1.0), &side("b", 3.0)).verdict,
            Verdict::Worse
        );
        assert_eq!(
            judge("c", &side("a", 1.0), &side("b", 0.3)).verdict,
            Verdict::Worse
        );
        assert_eq!(
            judge("c", &side("a", 0.3), &side("b", 0.9)).verdict,
            Verdict::Better
        );
    }

    #[test]
    fn flaky_same_failed_and_missing_are_said() {
        let with = |d: &str, s: u64, pass: bool, hash: &str| CellResult {
            pass: Some(pass),
            sent_hash: Some(hash.into()),
            ..cell(d, s, &[("latency_ms", 10.0)])
        };
        let base = vec![with("a", 1, true, "h1"), with("a", 2, true, "h2")];
        let same = vec![with("b", 1, true, "h1"), with("b", 2, true, "h2")];
        let v = judge("c", &base, &same);
        assert_eq!(v.verdict, Verdict::Same, "{v:?}");
        let flaky = vec![with("b", 1, true, "x"), with("b", 2, false, "y")];
        let v = judge("c", &base, &flaky);
        assert_eq!(v.verdict, Verdict::Flaky);
        assert!(v.why.contains("1 passed, 1 failed"), "{}", v.why);
        let failed = vec![with("b", 1, false, "x"), with("b", 2, false, "y")];
        assert_eq!(judge("c", &base, &failed).verdict, Verdict::Worse);
        assert_eq!(judge("c", &failed, &base).verdict, Verdict::Better);
        assert_eq!(judge("c", &base, &[]).verdict, Verdict::Missing);
        // one run a side, other frames: nothing to judge a difference by
        let one = |d: &str, x: f64| vec![cell(d, 0, &[("detection_latency_s", x)])];
        let v = judge("c", &one("a", 1.0), &one("b", 1.2));
        assert_eq!(v.verdict, Verdict::NotDistinguishable);
        assert!(v.why.contains("one run a side"), "{}", v.why);
    }
}
