//! What the host let a device have: a probe thread beside the device under test, at its
//! priority, that sleeps [`PERIOD`] at a time and measures how late it wakes. A device's
//! latency is its own only where the host did not hold it: the verdict on a device's timing
//! sets the host's delays against it ([`HostDelays::unexplained_ms`]).

use anyhow::{Context, Result};
use emulators::adapters::freerun::{Lateness, LatenessSummary};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The probe's sleep, each time.
pub const PERIOD: Duration = Duration::from_millis(2);
/// A wake-up later than this is kept as a delay with its time, s (the rest only in the
/// histogram).
const KEPT_S: f64 = 1e-3;
/// Delays kept at most (a long run of a loaded host: the first ones; the histogram has all).
const KEPT_MAX: usize = 1 << 20;

/// The host's scheduling delays as the probe saw them.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct HostDelays {
    /// All its wake-ups' lateness.
    pub summary: LatenessSummary,
    /// Wake-ups more than 1 ms late: when it was due (s since the run's origin) and how late
    /// it woke, s; in time order.
    #[serde(skip)]
    pub delays: Vec<(f64, f64)>,
}

impl HostDelays {
    /// The longest the host held the probe in `[from_s, to_s]`, s (a delay counts where it
    /// overlaps the interval).
    pub fn max_in(&self, from_s: f64, to_s: f64) -> f64 {
        // a delay due at d lasts until d + late: the first that may reach `from_s`
        let lo = self
            .delays
            .partition_point(|&(d, _)| d < from_s - self.summary.max_ms * 1e-3);
        self.delays[lo..]
            .iter()
            .take_while(|&&(d, _)| d <= to_s)
            .filter(|&&(d, l)| d + l >= from_s)
            .fold(0.0, |m, &(_, l)| m.max(l))
    }

    /// A device's latencies (arrival `rx_s`, latency s) less what the host held it of each: the
    /// longest delay the probe saw from `lookback_s` before the sample went on the bus (a stall
    /// just before leaves a backlog) to the answer; ms, at least 0.
    pub fn unexplained_ms(&self, epochs: &[(f64, f64)], lookback_s: f64) -> Vec<f64> {
        epochs
            .iter()
            .map(|&(rx, lat)| {
                let held = self.max_in(rx - lat.max(0.0) - lookback_s, rx);
                ((lat - held) * 1e3).max(lat.min(0.0) * 1e3)
            })
            .collect()
    }
}

/// The probe, running.
pub struct Probe {
    thread: std::thread::JoinHandle<HostDelays>,
}

impl Probe {
    /// Start it, its times in s since `origin`, until `stop`.
    pub fn start(origin: Instant, stop: Arc<AtomicBool>) -> Result<Self> {
        let thread = std::thread::Builder::new()
            .name("host-probe".into())
            .spawn(move || {
                let mut late = Lateness::default();
                let mut delays = Vec::new();
                while !stop.load(Ordering::Relaxed) {
                    let due = Instant::now() + PERIOD;
                    std::thread::sleep(PERIOD);
                    let l = Instant::now().saturating_duration_since(due);
                    late.add(l);
                    let (at, l) = (
                        due.saturating_duration_since(origin).as_secs_f64(),
                        l.as_secs_f64(),
                    );
                    if l > KEPT_S && delays.len() < KEPT_MAX {
                        delays.push((at, l));
                    }
                }
                HostDelays {
                    summary: late.summary(),
                    delays,
                }
            })
            .context("starting the host's probe")?;
        Ok(Self { thread })
    }

    /// What it saw (after the run's stop).
    pub fn finish(self) -> HostDelays {
        self.thread.join().unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_latency_is_the_devices_less_what_the_host_held_it() {
        let h = HostDelays {
            summary: LatenessSummary {
                max_ms: 120.0,
                ..Default::default()
            },
            delays: vec![(10.0, 0.120), (20.0, 0.002)],
        };
        assert_eq!(h.max_in(10.05, 10.06), 0.120);
        assert_eq!(h.max_in(10.2, 11.0), 0.0);
        assert_eq!(h.max_in(19.0, 20.0), 0.002);
        // an answer 150 ms after its sample, the host stalled 120 ms of it: 30 ms the device's
        let u = h.unexplained_ms(&[(10.1, 0.150), (15.0, 0.150), (10.1, -0.01)], 0.2);
        assert!(
            (u[0] - 30.0).abs() < 1e-9 && (u[1] - 150.0).abs() < 1e-9,
            "{u:?}"
        );
        // a sample named ahead stays what it is
        assert!((u[2] + 10.0).abs() < 1e-9, "{u:?}");
    }

    #[test]
    fn the_probe_measures_its_wake_ups() {
        let stop = Arc::new(AtomicBool::new(false));
        let p = Probe::start(Instant::now(), stop.clone()).unwrap();
        std::thread::sleep(Duration::from_millis(60));
        stop.store(true, Ordering::Relaxed);
        let d = p.finish();
        assert!(d.summary.count >= 5, "{d:?}");
        assert!(d.delays.windows(2).all(|w| w[0].0 <= w[1].0));
    }
}
