//! A filter's consistency where it breaks, not only on average: NEES per degree of freedom in
//! each ten-minute window of a drive (within [0.5, 2]), inside each receiver outage and in the
//! minute after it (at most 2: the drift within the sigmas promised), pooled over the runs of a
//! route. An average over an hour hides a filter that grows sure of
//! itself after forty minutes, or one that promises too much as it leaves a tunnel.

use crate::engine::navigate::NavSample;
use serde::{Deserialize, Serialize};

/// The window of the windowed verdict, s.
pub const WINDOW_S: f64 = 600.0;

/// A last window shorter than this joins the one before it, s.
pub const SHORTEST_WINDOW_S: f64 = 300.0;

/// After an outage, the stretch checked, s.
pub const AFTER_OUTAGE_S: f64 = 60.0;

/// NEES per degree of freedom over a stretch of the drive, pooled over the runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Stretch {
    /// Its start, s.
    pub from_s: f64,
    /// Its end, s.
    pub to_s: f64,
    /// Position and velocity NEES per degree of freedom (NaN where no sample fell in it).
    pub nees_per_dof: [f64; 2],
    /// The half-width of each figure's 95 % interval from the scatter between the runs:
    /// Student's t over the runs' own figures in the stretch, which holds however correlated
    /// a run's samples are in time (none with fewer than two runs). A figure past its bound by
    /// less than this is within what the runs can tell apart.
    #[serde(default)]
    pub interval_per_dof: Option<[f64; 2]>,
}

impl Stretch {
    /// How far outside `bounds` the worse of its two figures lies, as a factor (1: inside).
    pub fn excess(&self, bounds: [f64; 2]) -> f64 {
        self.nees_per_dof
            .iter()
            .map(|&x| {
                if !x.is_finite() {
                    1.0
                } else if x < bounds[0] {
                    bounds[0] / x.max(1e-12)
                } else if x > bounds[1] {
                    x / bounds[1]
                } else {
                    1.0
                }
            })
            .fold(1.0, f64::max)
    }

    /// Both figures within `bounds` (a stretch without samples has nothing to break).
    pub fn within(&self, bounds: [f64; 2]) -> bool {
        self.nees_per_dof
            .iter()
            .all(|x| !x.is_finite() || (bounds[0]..=bounds[1]).contains(x))
    }

    /// Both figures within `bounds` or past them by less than their 95 % interval: the runs
    /// cannot tell them from a figure within (without an interval, as [`Stretch::within`]).
    pub fn within_scatter(&self, bounds: [f64; 2]) -> bool {
        let half = self.interval_per_dof.unwrap_or([0.0; 2]);
        self.nees_per_dof
            .iter()
            .zip(half)
            .all(|(x, h)| !x.is_finite() || (bounds[0] - h..=bounds[1] + h).contains(x))
    }
}

/// One receiver outage: the filter inside it, and in the minute after it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OutageNees {
    /// Inside the outage.
    pub inside: Stretch,
    /// In the [`AFTER_OUTAGE_S`] after it.
    pub after: Stretch,
}

/// A route's windowed figures over its runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Windowed {
    /// Each ten-minute window of the drive from the start of navigation.
    pub windows: Vec<Stretch>,
    /// Each outage of the receiver that navigation saw.
    pub outages: Vec<OutageNees>,
}

impl Windowed {
    /// The figures of `runs` (each a run's samples) with the receiver's `outages` ([from, to] s).
    pub fn of(runs: &[&[NavSample]], outages: &[[f64; 2]]) -> Self {
        let start = runs
            .iter()
            .filter_map(|r| r.first().map(|x| x.t_s))
            .fold(f64::INFINITY, f64::min);
        let end = runs
            .iter()
            .filter_map(|r| r.last().map(|x| x.t_s))
            .fold(f64::NEG_INFINITY, f64::max);
        let mut windows = Vec::new();
        if start.is_finite() && end >= start {
            let n = (((end - start) / WINDOW_S).floor() as usize).max(1);
            for i in 0..n {
                let from = start + i as f64 * WINDOW_S;
                // the last window takes the rest when it is shorter than the shortest
                let to = if i + 1 == n && end - (from + WINDOW_S) < SHORTEST_WINDOW_S {
                    end + 1.0
                } else {
                    from + WINDOW_S
                };
                windows.push(stretch(runs, from, to));
            }
            let covered = windows.last().map_or(start, |w| w.to_s);
            if covered <= end {
                windows.push(stretch(runs, covered, end + 1.0));
            }
        }
        let outages = outages
            .iter()
            .filter(|o| o[0] >= start && o[0] <= end)
            .map(|o| OutageNees {
                inside: stretch(runs, o[0], o[1]),
                after: stretch(runs, o[1], o[1] + AFTER_OUTAGE_S),
            })
            .collect();
        Self { windows, outages }
    }

    /// The window farthest outside `bounds` (the first of equals).
    pub fn worst_window(&self, bounds: [f64; 2]) -> Option<&Stretch> {
        worst(self.windows.iter(), bounds)
    }

    /// The outage stretch (inside or after) that promises most: its larger figure the
    /// largest.
    pub fn worst_outage(&self) -> Option<&Stretch> {
        let top = |s: &Stretch| {
            s.nees_per_dof
                .iter()
                .copied()
                .filter(|x| x.is_finite())
                .fold(0.0, f64::max)
        };
        self.outages
            .iter()
            .flat_map(|o| [&o.inside, &o.after])
            .fold(None, |w: Option<&Stretch>, s| match w {
                Some(w) if top(w) >= top(s) => Some(w),
                _ => Some(s),
            })
    }

    /// Every window within `bounds`, and the drift inside every outage and in the minute after
    /// it within the sigmas promised: NEES per dof at most `bounds[1]` there. (Inside a tunnel a
    /// filter that coasts on sigmas larger than its drift breaks no promise; one whose drift
    /// outgrows them does.)
    pub fn within(&self, bounds: [f64; 2]) -> bool {
        self.all(&|s, b| s.within(b), bounds)
    }

    /// As [`Windowed::within`], each stretch allowed its 95 % interval between the runs: no
    /// stretch is outside by more than the runs' own scatter.
    pub fn within_scatter(&self, bounds: [f64; 2]) -> bool {
        self.all(&|s, b| s.within_scatter(b), bounds)
    }

    fn all(&self, ok: &dyn Fn(&Stretch, [f64; 2]) -> bool, bounds: [f64; 2]) -> bool {
        self.windows.iter().all(|s| ok(s, bounds))
            && self
                .outages
                .iter()
                .flat_map(|o| [&o.inside, &o.after])
                .all(|s| ok(s, [0.0, bounds[1]]))
    }
}

fn worst<'a>(it: impl Iterator<Item = &'a Stretch>, bounds: [f64; 2]) -> Option<&'a Stretch> {
    it.fold(None, |w: Option<&Stretch>, s| match w {
        Some(w) if w.excess(bounds) >= s.excess(bounds) => Some(w),
        _ => Some(s),
    })
}

/// NEES per dof of every run's samples in [from, to), pooled, with the 95 % interval of each
/// figure from the scatter of the runs' own figures.
fn stretch(runs: &[&[NavSample]], from: f64, to: f64) -> Stretch {
    let mut sum = [0.0; 2];
    let mut n = [0usize; 2];
    // each run's own figure (per dof), for the scatter between runs
    let mut per_run: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    for r in runs {
        let mut own = [(0.0, 0usize); 2];
        for x in r.iter().filter(|x| x.t_s >= from && x.t_s < to) {
            for (i, v) in [x.nees_position, x.nees_velocity].into_iter().enumerate() {
                if let Some(v) = v.filter(|v| v.is_finite()) {
                    sum[i] += v;
                    n[i] += 1;
                    own[i].0 += v;
                    own[i].1 += 1;
                }
            }
        }
        for (i, (s, k)) in own.into_iter().enumerate() {
            if k > 0 {
                per_run[i].push(s / k as f64 / 3.0);
            }
        }
    }
    let per_dof = |i: usize| {
        if n[i] == 0 {
            f64::NAN
        } else {
            sum[i] / n[i] as f64 / 3.0
        }
    };
    Stretch {
        from_s: from,
        to_s: to,
        nees_per_dof: [per_dof(0), per_dof(1)],
        interval_per_dof: crate::stats::half_width_95(&per_run[0])
            .zip(crate::stats::half_width_95(&per_run[1]))
            .map(|(a, b)| [a, b]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t: f64, nees: f64) -> NavSample {
        NavSample {
            t_s: t,
            position_error_m: 0.0,
            velocity_error_mps: [0.0; 3],
            heading_error_deg: 0.0,
            nees_position: Some(3.0 * nees),
            nees_velocity: Some(3.0),
            position_sigma_m: None,
            velocity_sigma_mps: None,
        }
    }

    /// An hour whose last twenty minutes promise too much: the average over the hour (1.67)
    /// passes, the windows do not; a tunnel and the minute after it are judged on their own.
    #[test]
    fn a_filter_sure_of_itself_late_fails_its_late_windows() {
        let run: Vec<NavSample> = (0..3700)
            .map(|t| sample(t as f64, if t >= 2400 { 3.0 } else { 1.0 }))
            .collect();
        let w = Windowed::of(&[&run], &[[1000.0, 1100.0], [5000.0, 5100.0]]);
        // 0-600 ... 2400-3000, then 3000-3700 (the last 100 s join it)
        assert_eq!(w.windows.len(), 6, "{:?}", w.windows);
        assert_eq!(w.windows[5].from_s, 3000.0);
        assert!(w.windows[..4].iter().all(|s| s.within([0.5, 2.0])));
        assert!(!w.windows[4].within([0.5, 2.0]));
        let worst = w.worst_window([0.5, 2.0]).unwrap();
        assert_eq!(worst.nees_per_dof, [3.0, 1.0]);
        assert!((worst.excess([0.5, 2.0]) - 1.5).abs() < 1e-12);
        assert!(!w.within([0.5, 2.0]));
        // the outage after the drive's end is not one navigation saw
        assert_eq!(w.outages.len(), 1);
        assert_eq!(w.outages[0].inside.from_s, 1000.0);
        assert_eq!(w.outages[0].after.to_s, 1100.0 + AFTER_OUTAGE_S);
        assert!(w.outages[0].inside.within([0.5, 2.0]));
        // a tunnel coasted on generous sigmas passes; one whose drift outgrows them does not
        let mut coast = w.clone();
        coast.windows.clear();
        coast.outages[0].inside.nees_per_dof = [0.2, 0.3];
        assert!(coast.within([0.5, 2.0]));
        coast.outages[0].after.nees_per_dof = [2.5, 0.3];
        assert!(!coast.within([0.5, 2.0]));
        assert_eq!(coast.worst_outage().unwrap().nees_per_dof, [2.5, 0.3]);
        let mean: f64 = run
            .iter()
            .map(|x| x.nees_position.unwrap() / 3.0)
            .sum::<f64>()
            / run.len() as f64;
        assert!(mean < 2.0, "{mean}: the average alone would pass");
    }

    /// A short drive is one window; runs are pooled; an overconfident stretch is named worst.
    #[test]
    fn runs_pool_and_a_short_drive_is_one_window() {
        let a: Vec<NavSample> = (0..400).map(|t| sample(t as f64, 0.4)).collect();
        let b: Vec<NavSample> = (0..400).map(|t| sample(t as f64, 1.0)).collect();
        let w = Windowed::of(&[&a, &b], &[]);
        assert_eq!(w.windows.len(), 1);
        assert!((w.windows[0].nees_per_dof[0] - 0.7).abs() < 1e-12);
        assert!(w.within([0.5, 2.0]));
        assert!(!Windowed::of(&[&a], &[]).within([0.5, 2.0]));
        let low = Stretch {
            from_s: 0.0,
            to_s: 1.0,
            nees_per_dof: [0.25, 1.0],
            interval_per_dof: None,
        };
        assert!((low.excess([0.5, 2.0]) - 2.0).abs() < 1e-12);
    }

    /// Each stretch carries the 95 % interval of its figure from the scatter between runs:
    /// runs that disagree widely leave a figure over the bound within what they can tell
    /// apart; runs that agree do not. One run has no interval.
    #[test]
    fn the_scatter_between_runs_bounds_what_a_figure_can_tell() {
        let run = |v: f64| -> Vec<NavSample> {
            (0..60)
                .map(|t| NavSample {
                    nees_velocity: Some(3.0 * v),
                    ..sample(t as f64, 1.0)
                })
                .collect()
        };
        // eight runs: four at 0.6, four at 4.0 (mean 2.3 per dof, past the bound of 2)
        let scattered: Vec<Vec<NavSample>> = (0..8)
            .map(|i| run(if i % 2 == 0 { 0.6 } else { 4.0 }))
            .collect();
        let refs: Vec<&[NavSample]> = scattered.iter().map(|r| r.as_slice()).collect();
        let w = Windowed::of(&refs, &[]);
        let s = &w.windows[0];
        assert!((s.nees_per_dof[1] - 2.3).abs() < 1e-12);
        // sd 1.817 over 8 runs, t(7) = 2.365: +-1.52; the position runs all agree: +-0
        let h = s.interval_per_dof.unwrap();
        let sd = (8.0 * 1.7f64.powi(2) / 7.0).sqrt();
        assert!((h[1] - 2.365 * sd / 8f64.sqrt()).abs() < 1e-9, "{h:?}");
        assert!(h[0].abs() < 1e-12);
        assert!(!w.within([0.5, 2.0]));
        assert!(w.within_scatter([0.5, 2.0]));
        // the same mean from runs that agree is past the bound by more than they scatter
        let agreed: Vec<Vec<NavSample>> = (0..8).map(|i| run(2.2 + 0.2 * (i % 2) as f64)).collect();
        let refs: Vec<&[NavSample]> = agreed.iter().map(|r| r.as_slice()).collect();
        let w = Windowed::of(&refs, &[]);
        assert!((w.windows[0].nees_per_dof[1] - 2.3).abs() < 1e-12);
        assert!(!w.within_scatter([0.5, 2.0]));
        // one run: no interval, and the verdict is the figure's own
        let one = Windowed::of(&refs[..1], &[]);
        assert_eq!(one.windows[0].interval_per_dof, None);
        assert_eq!(one.within_scatter([0.5, 2.0]), one.within([0.5, 2.0]));
        // the t quantile past the table joins it
        assert!(
            (crate::stats::t_975(31) - 2.0395).abs() < 2e-3
                && (crate::stats::t_975(1000) - 1.962).abs() < 1e-3
        );
    }
}
