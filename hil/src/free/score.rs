//! Judging a device under test from what it sent on the bus, by the DBC only: its solution
//! epochs (NAV_TIME and the frames of the same Seq) against the truth at the IMU sample each
//! NAV_TIME names, its latency from that sample on the bus to the NAV_TIME, its output rate,
//! and what its data say of its time tags. Pure: times are seconds on the host's clock since
//! the run's origin.

use crate::stats::wrap180;
use serde::{Deserialize, Serialize};
use wire::NavMode;

/// One solution epoch as the device sent it.
#[derive(Debug, Clone, PartialEq)]
pub struct Epoch {
    /// NAV_TIME's SampleCount.
    pub sample_count: u32,
    /// NAV_TIME's Seq.
    pub seq: u8,
    /// NAV_TIME's mode.
    pub mode: NavMode,
    /// NAV_TIME's health bits that were set, by name.
    pub health: Vec<String>,
    /// When NAV_TIME arrived, s.
    pub rx_s: f64,
    /// The IMU sample it names (its index) and when that sample went on the bus, s (when it
    /// is due, for one not sent yet: `scheduled`); none when the bench cannot place it (one
    /// older than the bench keeps).
    pub sample: Option<(u64, f64)>,
    /// The named sample had not gone on the bus when the bench placed it: its time is when it
    /// was due.
    pub scheduled: bool,
    /// NAV_ATT of the same Seq: heading, pitch, roll, deg.
    pub att: Option<[f64; 3]>,
    /// NAV_VEL: east, north, up, m/s.
    pub vel: Option<[f64; 3]>,
    /// NAV_POS: latitude, longitude, deg.
    pub pos: Option<[f64; 2]>,
    /// NAV_HGT of the same Seq: height m, position sigma m, heading sigma deg.
    pub hgt: Option<[f64; 3]>,
}

#[cfg(test)]
impl Epoch {
    /// A NAV_TIME naming sample `k`, which went on the bus at `at_s`, heard at `rx_s`, in
    /// `mode`, with nothing else (the unit tests' epoch).
    pub(crate) fn named(k: u64, at_s: f64, rx_s: f64, mode: NavMode) -> Self {
        Epoch {
            sample_count: k as u32,
            seq: (k / 40) as u8,
            mode,
            health: Vec::new(),
            rx_s,
            sample: Some((k, at_s)),
            scheduled: false,
            att: None,
            vel: None,
            pos: None,
            hgt: None,
        }
    }
}

/// Percentiles of a set of values, ms.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Spread {
    /// Values.
    pub count: u64,
    /// Median, ms.
    pub p50_ms: f64,
    /// 99th percentile, ms.
    pub p99_ms: f64,
    /// Worst, ms.
    pub max_ms: f64,
}

impl Spread {
    /// Of `ms` (sorted here).
    pub fn of(mut ms: Vec<f64>) -> Self {
        if ms.is_empty() {
            return Self::default();
        }
        ms.sort_by(f64::total_cmp);
        let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
        Self {
            count: ms.len() as u64,
            p50_ms: at(0.5),
            p99_ms: at(0.99),
            max_ms: ms[ms.len() - 1],
        }
    }
}

/// The latency the device's time tags state: from the IMU sample on the bus to the NAV_TIME
/// naming it; and how many NAV_TIMEs named no sample sent.
pub fn stated_latency(epochs: &[Epoch]) -> (Spread, u64) {
    let ms = epochs
        .iter()
        .filter_map(|e| e.sample.map(|(_, at)| (e.rx_s - at) * 1e3))
        .collect();
    let unnamed = epochs.iter().filter(|e| e.sample.is_none()).count() as u64;
    (Spread::of(ms), unnamed)
}

/// The device's output rate on the host's clock.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Rate {
    /// Epochs.
    pub epochs: u64,
    /// Epochs per second of the host's clock.
    pub hz: f64,
    /// RMS departure of the intervals between epochs from their mean, ms.
    pub jitter_rms_ms: f64,
    /// Largest interval, ms.
    pub max_interval_ms: f64,
    /// The most common step of SampleCount between epochs, samples.
    pub step_samples: u32,
}

/// The rate of `epochs`.
pub fn rate(epochs: &[Epoch]) -> Rate {
    let n = epochs.len();
    if n < 2 {
        return Rate {
            epochs: n as u64,
            ..Rate::default()
        };
    }
    let iv: Vec<f64> = epochs.windows(2).map(|w| w[1].rx_s - w[0].rx_s).collect();
    let mean = iv.iter().sum::<f64>() / iv.len() as f64;
    let var = iv.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / iv.len() as f64;
    let mut steps = std::collections::BTreeMap::new();
    for w in epochs.windows(2) {
        *steps
            .entry(w[1].sample_count.wrapping_sub(w[0].sample_count))
            .or_insert(0u64) += 1;
    }
    Rate {
        epochs: n as u64,
        hz: (n - 1) as f64 / (epochs[n - 1].rx_s - epochs[0].rx_s).max(1e-9),
        jitter_rms_ms: var.sqrt() * 1e3,
        max_interval_ms: iv.iter().copied().fold(0.0, f64::max) * 1e3,
        step_samples: steps.iter().max_by_key(|(_, n)| **n).map_or(0, |(s, _)| *s),
    }
}

/// NAV_TIMEs whose SampleCount went back from the one before (a wrap of the 32-bit count
/// aside), and the first such pair; and the pairs of neighbours the bus swapped, not counted
/// as going back: the later-sent one heard first, the earlier one filling the gap it left
/// (vcan hands a sender's frames to the receive queue of the CPU the sender is on, so a device
/// moving between CPUs can be heard out of order; a real controller keeps a sender's order).
pub fn backwards(epochs: &[Epoch]) -> (u64, Option<(u32, u32)>, u64) {
    let before = |a: u32, b: u32| b.wrapping_sub(a) < u32::MAX / 2 && a != b;
    let (mut n, mut first, mut swapped) = (0, None, 0);
    let mut i = 0;
    while i + 1 < epochs.len() {
        let (a, b) = (epochs[i].sample_count, epochs[i + 1].sample_count);
        if before(a, b) {
            i += 1;
            continue;
        }
        let prev_ok = i == 0 || before(epochs[i - 1].sample_count, b);
        let next_ok = epochs.get(i + 2).is_none_or(|c| before(a, c.sample_count));
        if a != b && prev_ok && next_ok {
            swapped += 1;
            // the swapped pair is one event: the next pair starts after it
            i += 2;
            continue;
        }
        if b.wrapping_sub(a) > u32::MAX / 2 {
            n += 1;
            first = first.or(Some((a, b)));
        }
        i += 1;
    }
    (n, first, swapped)
}

/// A heading against truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeadingScore {
    /// The IMU sample its NAV_TIME names.
    pub sample: u64,
    /// The device's heading, deg.
    pub heading_deg: f64,
    /// Truth at that sample, deg.
    pub truth_deg: f64,
    /// Error, deg (-180, 180].
    pub error_deg: f64,
    /// The device's sigma (NAV_HGT's HeadingSigma), deg; none when it sent none.
    pub sigma_deg: Option<f64>,
    /// The epoch it was taken at: its place in the device's stream (0 the first NAV_TIME).
    #[serde(default)]
    pub epoch: u64,
    /// That epoch's NAV_TIME Seq.
    #[serde(default)]
    pub seq: u8,
    /// That epoch's mode.
    #[serde(default)]
    pub mode: String,
    /// When it came, s since the stream's start.
    #[serde(default)]
    pub rx_s: f64,
    /// Taken at the first epoch after the device's mode left north-finding (false: the device
    /// never said it was finding north, and its last heading was taken).
    #[serde(default)]
    pub after_finding: bool,
}

impl HeadingScore {
    /// The error in the device's own sigmas.
    pub fn in_sigmas(&self) -> Option<f64> {
        self.sigma_deg
            .filter(|s| *s > 0.0)
            .map(|s| self.error_deg / s)
    }
}

/// The device finds north (with the mechanism, or by a static gyrocompass without it).
fn finding(m: NavMode) -> bool {
    matches!(m, NavMode::NorthFinding | NavMode::Gyrocompass)
}

/// The heading at a drill's end: the first epoch with an attitude and a placed sample after
/// the device's mode has left north-finding (having shown it); for a device that never says
/// it finds north, its last epoch with an attitude. None for a device still finding north
/// (its headings then are not its answer). `truth_deg`: the true heading at an IMU sample.
pub fn drill_heading(epochs: &[Epoch], truth_deg: impl Fn(u64) -> f64) -> Option<HeadingScore> {
    let usable = |e: &Epoch| e.att.is_some() && e.sample.is_some();
    let (i, after_finding) = match epochs.iter().position(|e| finding(e.mode)) {
        Some(f) => (
            f + epochs[f..]
                .iter()
                .position(|e| !finding(e.mode) && usable(e))?,
            true,
        ),
        None => (epochs.iter().rposition(usable)?, false),
    };
    let found = &epochs[i];
    let (k, _) = found.sample?;
    let heading = found.att?[0];
    let truth = truth_deg(k);
    Some(HeadingScore {
        sample: k,
        heading_deg: heading,
        truth_deg: truth.rem_euclid(360.0),
        error_deg: wrap180(heading - truth),
        sigma_deg: found.hgt.map(|h| h[2]).filter(|s| s.is_finite()),
        epoch: i as u64,
        seq: found.seq,
        mode: format!("{:?}", found.mode),
        rx_s: found.rx_s,
        after_finding,
    })
}

/// The device's first heading after north-finding is over (the drill's end is then known).
pub fn drill_over(epochs: &[Epoch]) -> bool {
    epochs
        .iter()
        .position(|e| finding(e.mode))
        .is_some_and(|i| {
            epochs[i..]
                .iter()
                .any(|e| !finding(e.mode) && e.att.is_some())
        })
}

/// Navigation along a drive, against truth at the sample each epoch names.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct DriveScore {
    /// Epochs scored (with a position, while navigating).
    pub epochs: u64,
    /// RMS horizontal position error, m.
    pub rms_m: f64,
    /// Worst horizontal position error, m.
    pub max_m: f64,
    /// The last epoch's horizontal error, m, and its time, s.
    pub last_m: f64,
    /// The last epoch's time, s of the IMU's clock.
    pub last_t_s: f64,
    /// RMS horizontal velocity error, m/s.
    pub vel_rms_mps: f64,
    /// Mean of (error / PosSigma)^2 over the epochs that carry a sigma: the position's NEES
    /// per degree of freedom (1 when the sigmas hold); none without sigmas.
    pub nees: Option<f64>,
}

/// Score the epochs that carry a position while the device navigates. `truth`: at a time, the
/// truth's east, north error of a position (lat, lon deg, height m) in m and its horizontal
/// velocity (east, north) m/s; `t_of`: the time of a sample.
pub fn drive(
    epochs: &[Epoch],
    truth: impl Fn(f64, [f64; 3]) -> ([f64; 2], [f64; 2]),
    t_of: impl Fn(u64) -> f64,
) -> Option<DriveScore> {
    let navigating = |m: NavMode| {
        matches!(
            m,
            NavMode::Navigation | NavMode::GpsAided | NavMode::Coasting
        )
    };
    let (mut sum, mut vsum, mut max, mut n, mut vn) = (0.0, 0.0, 0.0f64, 0u64, 0u64);
    let (mut nees, mut nees_n) = (0.0, 0u64);
    let mut last = (0.0, 0.0);
    for e in epochs.iter().filter(|e| navigating(e.mode)) {
        let (Some((k, _)), Some(p)) = (e.sample, e.pos) else {
            continue;
        };
        let t = t_of(k);
        let h = e.hgt.map_or(0.0, |h| h[0]);
        let (d, v) = truth(t, [p[0], p[1], h]);
        let err = d[0].hypot(d[1]);
        sum += err * err;
        max = max.max(err);
        n += 1;
        last = (err, t);
        if let Some(ve) = e.vel {
            vsum += (ve[0] - v[0]).powi(2) + (ve[1] - v[1]).powi(2);
            vn += 1;
        }
        // 655.35 m is the field's top: a sigma it cannot state
        if let Some(sg) = e.hgt.map(|h| h[1]).filter(|s| *s > 0.0 && *s < 655.0) {
            nees += (err / sg).powi(2);
            nees_n += 1;
        }
    }
    (n > 0).then(|| DriveScore {
        epochs: n,
        rms_m: (sum / n as f64).sqrt(),
        max_m: max,
        last_m: last.0,
        last_t_s: last.1,
        vel_rms_mps: (vsum / vn.max(1) as f64).sqrt(),
        nees: (nees_n > 0).then(|| nees / nees_n as f64),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn epoch(k: u64, rate: f64, lag_s: f64) -> Epoch {
        let t = k as f64 / rate;
        Epoch::named(k, t, t + lag_s, NavMode::Navigation)
    }

    #[test]
    fn latency_rate_and_backward_tags_come_from_the_epochs() {
        let mut e: Vec<Epoch> = (1..=100).map(|i| epoch(i * 40, 2000.0, 0.004)).collect();
        e[50].sample = None;
        let (l, unnamed) = stated_latency(&e);
        assert_eq!((l.count, unnamed), (99, 1));
        assert!(
            (l.p50_ms - 4.0).abs() < 1e-9 && (l.max_ms - 4.0).abs() < 1e-9,
            "{l:?}"
        );
        let r = rate(&e);
        assert!(
            (r.hz - 50.0).abs() < 1e-6 && r.jitter_rms_ms < 1e-6,
            "{r:?}"
        );
        assert_eq!(r.step_samples, 40);
        assert_eq!(backwards(&e), (0, None, 0));
        // two neighbours swapped by the bus: heard out of order, not going back
        e.swap(30, 31);
        assert_eq!(backwards(&e), (0, None, 1));
        e.swap(30, 31);
        // a tag 1000 samples back (tests/dut/northfinder.py --backwards)
        e[70].sample_count = 10;
        assert_eq!(backwards(&e).0, 1);
        assert_eq!(backwards(&e).1, Some((70 * 40, 10)));
        assert_eq!(backwards(&e).2, 0);
    }

    #[test]
    fn a_drive_is_scored_where_the_device_navigates() {
        let mut e: Vec<Epoch> = (1..=10).map(|i| epoch(i * 40, 2000.0, 0.0)).collect();
        for (i, x) in e.iter_mut().enumerate() {
            // 3 m east, 4 m north off: 5 m; sigma 5 m from the third epoch on
            x.pos = Some([0.0, 0.0]);
            x.vel = Some([1.0, 0.0, 0.0]);
            x.hgt = Some([0.0, if i >= 2 { 5.0 } else { 655.35 }, 0.1]);
        }
        e[0].mode = NavMode::Levelling;
        let d = drive(&e, |_, _| ([3.0, 4.0], [1.0, 0.0]), |k| k as f64 / 2000.0).unwrap();
        assert_eq!(d.epochs, 9);
        assert!((d.rms_m - 5.0).abs() < 1e-12 && (d.max_m - 5.0).abs() < 1e-12);
        assert!((d.last_t_s - 0.2).abs() < 1e-12 && d.vel_rms_mps == 0.0);
        assert!((d.nees.unwrap() - 1.0).abs() < 1e-12);
        assert!(drive(&e[..1], |_, _| ([0.0; 2], [0.0; 2]), |k| k as f64).is_none());
    }

    #[test]
    fn the_heading_is_taken_when_north_finding_is_over() {
        let mut e: Vec<Epoch> = (1..=10).map(|i| epoch(i * 40, 2000.0, 0.0)).collect();
        for x in &mut e[..5] {
            x.mode = NavMode::NorthFinding;
        }
        assert!(!drill_over(&e));
        e[7].att = Some([30.2, 0.0, 0.0]);
        e[7].hgt = Some([0.0, 0.0, 0.1]);
        e[9].att = Some([99.0, 0.0, 0.0]);
        assert!(drill_over(&e));
        let h = drill_heading(&e, |_| 30.0).unwrap();
        assert_eq!((h.sample, h.epoch, h.seq), (320, 7, 8));
        assert!(h.after_finding && h.mode == "Navigation", "{h:?}");
        assert!((h.error_deg - 0.2).abs() < 1e-9 && (h.in_sigmas().unwrap() - 2.0).abs() < 1e-9);
        // across north
        e[7].att = Some([0.2, 0.0, 0.0]);
        let h = drill_heading(&e, |_| 359.9).unwrap();
        assert!((h.error_deg - 0.3).abs() < 1e-9, "{h:?}");
        // still finding north: its headings are not its answer
        let mut still = e.clone();
        for x in &mut still {
            x.mode = NavMode::NorthFinding;
        }
        assert_eq!(drill_heading(&still, |_| 30.0), None);
        // a device that never says it finds north: its last heading
        let mut plain = e.clone();
        for x in &mut plain {
            x.mode = NavMode::Navigation;
        }
        let h = drill_heading(&plain, |_| 99.0).unwrap();
        assert!(h.epoch == 9 && !h.after_finding, "{h:?}");
    }
}
