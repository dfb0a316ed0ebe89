//! Integrity of the navigation solution: is the filter still consistent with the receiver?
//! Three symptoms are watched, each a sign that the filter's errors have outgrown its sigmas:
//! - the innovations: the mean normalized innovation squared of the last fixes against what a
//!   consistent filter gives (3 per fix for 3 degrees of freedom);
//! - rejections: a run of fixes the gate refused;
//! - velocity: the INS's ground velocity against the receiver's speed and track (RMC), which
//!   a position-only filter does not measure and so cannot see go wrong by itself; while parked,
//!   the INS's whole speed (a parked land vehicle does not climb) against the receiver's;
//! - covariance growth: the filter's own horizontal position sigma beyond a limit (a long
//!   outage, or a filter that no longer converges).
//!
//! While any of them holds, the solution's `filter` health bit is set (nav's pipeline) and the
//! change is reported as an event; the summary counts what was seen.

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// Integrity settings (`[navigation.integrity]`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct IntegrityConfig {
    /// Fixes in the innovation window.
    pub window: usize,
    /// Alarm when the window's mean NIS (3 dof) exceeds this. A consistent filter's mean of 10
    /// fixes exceeds 8.0 with a probability of about 2e-6 (chi-square, 30 dof, over 10): over a
    /// 20-minute drive, one false alarm in a few hundred drives.
    pub max_mean_nis: f64,
    /// Alarm when this many fixes of the window were rejected by the gate.
    pub max_rejected: usize,
    /// Alarm when the INS's horizontal velocity differs from the receiver's by more than this
    /// while moving, m/s ...
    pub max_velocity_diff_mps: f64,
    /// ... or its speed from the receiver's by more than this while (nearly) parked, m/s ...
    pub max_parked_speed_diff_mps: f64,
    /// ... at this many fixes in a row (the receiver's velocity noise is a few tenths of m/s).
    pub velocity_fixes: u32,
    /// Below this speed the receiver's track is noise: only the speeds are compared, m/s.
    pub min_speed_mps: f64,
    /// Alarm while the filter's horizontal position sigma (1 sigma, the root of the two axes'
    /// variances) exceeds this, m: three times a 25 m class receiver's error.
    pub max_position_sigma_m: f64,
}

impl Default for IntegrityConfig {
    fn default() -> Self {
        Self {
            window: 10,
            max_mean_nis: 8.0,
            max_rejected: 3,
            max_velocity_diff_mps: 2.0,
            max_parked_speed_diff_mps: 1.0,
            velocity_fixes: 3,
            min_speed_mps: 1.0,
            max_position_sigma_m: 60.0,
        }
    }
}

/// What the monitor saw.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct IntegrityStats {
    /// The alarm is on now.
    pub alarm: bool,
    /// Times it came on.
    pub alarms: u64,
    /// Of which: the innovations were too large.
    pub nis_alarms: u64,
    /// Of which: a run of rejected fixes.
    pub rejection_alarms: u64,
    /// Of which: the velocity disagreed with the receiver's.
    pub velocity_alarms: u64,
    /// Of which: the position sigma grew beyond its limit.
    #[serde(default)]
    pub covariance_alarms: u64,
    /// Mean NIS of the current window.
    pub window_mean_nis: f64,
    /// Largest INS-receiver horizontal velocity difference seen, m/s.
    pub max_velocity_diff_mps: f64,
}

/// Why the alarm is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Symptom {
    /// The window's innovations are too large for the covariance.
    Innovations,
    /// A run of rejected fixes.
    Rejections,
    /// The velocity disagrees with the receiver's.
    Velocity,
    /// The filter's position sigma has grown beyond its limit.
    Covariance,
}

impl std::fmt::Display for Symptom {
    /// What went wrong, in words.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Innovations => "the innovations are too large for the covariance",
            Self::Rejections => "a run of rejected fixes",
            Self::Velocity => "the velocity disagrees with the receiver's",
            Self::Covariance => "the position sigma has grown beyond its limit",
        })
    }
}

/// The monitor.
#[derive(Debug, Clone, Default)]
pub struct IntegrityMonitor {
    cfg: IntegrityConfig,
    /// The last fixes: (NIS, rejected).
    window: VecDeque<(f64, bool)>,
    velocity_run: u32,
    sigma_over: bool,
    symptom: Option<Symptom>,
    stats: IntegrityStats,
}

impl IntegrityMonitor {
    /// A monitor with these settings.
    pub fn new(cfg: IntegrityConfig) -> Self {
        Self {
            cfg,
            ..Self::default()
        }
    }

    /// A fix went through the filter: its NIS and whether the gate rejected it. Returns the
    /// alarm's change, if any (`Some(Some(s))` on, `Some(None)` off).
    pub fn on_fix(&mut self, nis: f64, rejected: bool) -> Option<Option<Symptom>> {
        self.window.push_back((nis, rejected));
        while self.window.len() > self.cfg.window.max(1) {
            self.window.pop_front();
        }
        self.evaluate()
    }

    /// A receiver velocity (east, north, m/s) against the INS's (east, north, up) at the same
    /// time. Returns the alarm's change, if any.
    pub fn on_velocity(&mut self, ins: [f64; 3], receiver: [f64; 2]) -> Option<Option<Symptom>> {
        let speed = receiver[0].hypot(receiver[1]);
        let (d, limit) = if speed < self.cfg.min_speed_mps {
            // slow or parked: the receiver's track means nothing, its speed still does, and a
            // parked land vehicle does not climb: the INS's whole speed against the receiver's
            (
                (ins[0].hypot(ins[1]).hypot(ins[2]) - speed).abs(),
                self.cfg.max_parked_speed_diff_mps,
            )
        } else {
            (
                (ins[0] - receiver[0]).hypot(ins[1] - receiver[1]),
                self.cfg.max_velocity_diff_mps,
            )
        };
        self.stats.max_velocity_diff_mps = self.stats.max_velocity_diff_mps.max(d);
        if d > limit {
            self.velocity_run += 1;
        } else {
            self.velocity_run = 0;
        }
        self.evaluate()
    }

    /// The filter's horizontal position sigma now, m. Returns the alarm's change, if any (cheap
    /// when nothing changes: call it at every update).
    pub fn on_position_sigma(&mut self, sigma_m: f64) -> Option<Option<Symptom>> {
        let over = sigma_m.is_nan() || sigma_m > self.cfg.max_position_sigma_m;
        if over == self.sigma_over {
            return None;
        }
        self.sigma_over = over;
        self.evaluate()
    }

    fn evaluate(&mut self) -> Option<Option<Symptom>> {
        let used: Vec<f64> = self.window.iter().filter(|w| !w.1).map(|w| w.0).collect();
        let mean = if used.is_empty() {
            0.0
        } else {
            used.iter().sum::<f64>() / used.len() as f64
        };
        self.stats.window_mean_nis = mean;
        let rejected = self.window.iter().filter(|w| w.1).count();
        let now = if rejected >= self.cfg.max_rejected.max(1) {
            Some(Symptom::Rejections)
        } else if used.len() * 2 >= self.cfg.window && mean > self.cfg.max_mean_nis {
            Some(Symptom::Innovations)
        } else if self.velocity_run >= self.cfg.velocity_fixes.max(1) {
            Some(Symptom::Velocity)
        } else if self.sigma_over {
            Some(Symptom::Covariance)
        } else {
            None
        };
        if now == self.symptom {
            return None;
        }
        if self.symptom.is_none() {
            self.stats.alarms += 1;
        }
        match now {
            Some(Symptom::Innovations) => self.stats.nis_alarms += 1,
            Some(Symptom::Rejections) => self.stats.rejection_alarms += 1,
            Some(Symptom::Velocity) => self.stats.velocity_alarms += 1,
            Some(Symptom::Covariance) => self.stats.covariance_alarms += 1,
            None => {}
        }
        self.symptom = now;
        self.stats.alarm = now.is_some();
        Some(now)
    }

    /// Why the alarm is on, if it is.
    pub fn symptom(&self) -> Option<Symptom> {
        self.symptom
    }

    /// Counters.
    pub fn stats(&self) -> IntegrityStats {
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn consistent_innovations_raise_nothing_and_large_ones_do() {
        let mut m = IntegrityMonitor::new(IntegrityConfig::default());
        for i in 0..50 {
            // chi-square-like values around 3
            let nis = [1.0, 2.5, 3.0, 4.5, 6.0][i % 5];
            assert_eq!(m.on_fix(nis, false), None);
        }
        let mut change = None;
        for _ in 0..10 {
            change = change.or(m.on_fix(25.0, false));
        }
        assert_eq!(change, Some(Some(Symptom::Innovations)));
        assert!(m.stats().alarm && m.stats().nis_alarms == 1);
        let mut off = None;
        for _ in 0..10 {
            off = off.or(m.on_fix(3.0, false));
        }
        assert_eq!(off, Some(None));
        assert!(!m.stats().alarm);
    }

    #[test]
    fn a_run_of_rejections_and_a_velocity_disagreement_raise_the_alarm() {
        let mut m = IntegrityMonitor::new(IntegrityConfig::default());
        assert_eq!(m.on_fix(40.0, true), None);
        assert_eq!(m.on_fix(40.0, true), None);
        assert_eq!(m.on_fix(40.0, true), Some(Some(Symptom::Rejections)));
        let mut m = IntegrityMonitor::new(IntegrityConfig::default());
        // parked: the receiver's track is noise, only the speeds count
        for _ in 0..5 {
            assert_eq!(m.on_velocity([0.1, -0.2, 0.0], [0.2, 0.1]), None);
        }
        assert_eq!(m.on_velocity([10.0, 0.0, 0.0], [7.0, 0.0]), None);
        assert_eq!(m.on_velocity([10.0, 0.0, 0.0], [7.0, 0.0]), None);
        assert_eq!(
            m.on_velocity([10.0, 0.0, 0.0], [7.0, 0.0]),
            Some(Some(Symptom::Velocity))
        );
        assert_eq!(m.on_velocity([10.0, 0.0, 0.0], [8.5, 0.3]), Some(None));
        assert_eq!(m.stats().velocity_alarms, 1);
        assert!((m.stats().max_velocity_diff_mps - 3.0).abs() < 1e-12);
        // a parked INS that believes it sinks at 1.5 m/s
        for _ in 0..2 {
            assert_eq!(m.on_velocity([0.1, 0.0, -1.5], [0.05, 0.0]), None);
        }
        assert_eq!(
            m.on_velocity([0.1, 0.0, -1.5], [0.05, 0.0]),
            Some(Some(Symptom::Velocity))
        );
        // the position sigma grows beyond its limit and comes back
        let mut m = IntegrityMonitor::new(IntegrityConfig::default());
        assert_eq!(m.on_position_sigma(20.0), None);
        assert_eq!(m.on_position_sigma(59.0), None);
        assert_eq!(m.on_position_sigma(61.0), Some(Some(Symptom::Covariance)));
        assert_eq!(m.on_position_sigma(80.0), None);
        assert_eq!(m.on_position_sigma(f64::NAN), None);
        assert_eq!(m.on_position_sigma(30.0), Some(None));
        assert_eq!(m.stats().covariance_alarms, 1);
    }
}
