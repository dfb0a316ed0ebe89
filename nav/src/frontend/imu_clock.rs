//! The IMU's oscillator against the receiver's PPS: how far the IMU's sample rate is off its
//! nominal one, from the edges it latched.
//!
//! nav counts its time in IMU samples at the nominal rate. A real unit's oscillator is off that
//! rate by tens of ppm and wanders with its temperature; the receiver's PPS comes every true
//! second. The IMU times of the edges taken, against their second numbers, give the rate: the
//! least-squares slope over the last [`crate::navigation::navigator::EDGES_KEPT`] edges (about a minute)
//! is the IMU's seconds per true second. Navigation integrates what depends on the length of
//! a second (gravity, the earth's rate, the transport rate, the position, the filter's
//! propagation) over the true length of its updates, `dt / (1 + y)`; the increments the IMU
//! counted need nothing, and the fixes meet their samples through their edges.

use serde::{Deserialize, Serialize};

/// Edges needed before the rate is estimated.
pub const MIN_EDGES: usize = 8;

/// The longest a window of edges may be off before it is taken for nonsense (a receiver whose
/// seconds are not seconds), ppm.
pub const MAX_PPM: f64 = 10_000.0;

/// The IMU's rate against the PPS.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClockEstimate {
    /// The IMU's rate off nominal, ppm (positive: fast, more samples per true second).
    pub ppm: f64,
    /// Its one-sigma uncertainty from the edges' scatter about the line, ppm.
    pub sigma_ppm: f64,
    /// The true seconds the edges span.
    pub span_s: f64,
    /// Edges in the window.
    pub edges: usize,
    /// IMU time of the window's newest edge, s.
    pub end_s: f64,
}

impl ClockEstimate {
    /// From edges `(second number, IMU time s)`, oldest first: none with fewer than
    /// [`MIN_EDGES`], a span under `MIN_EDGES - 1` s, or a rate beyond [`MAX_PPM`].
    pub fn from_edges<'a>(edges: impl Iterator<Item = &'a (i64, f64)> + Clone) -> Option<Self> {
        let n = edges.clone().count();
        let &(s0, t0) = edges.clone().next()?;
        let end_s = edges.clone().last().map_or(t0, |e| e.1);
        let pts = || edges.clone().map(move |&(s, t)| ((s - s0) as f64, t - t0));
        let (sx, sy) = pts().fold((0.0, 0.0), |a, (x, y)| (a.0 + x, a.1 + y));
        let (mx, my) = (sx / n as f64, sy / n as f64);
        let (mut sxx, mut sxy) = (0.0, 0.0);
        let mut span = 0.0f64;
        for (x, y) in pts() {
            sxx += (x - mx) * (x - mx);
            sxy += (x - mx) * (y - my);
            span = span.max(x);
        }
        if n < MIN_EDGES || span < (MIN_EDGES - 1) as f64 || sxx <= 0.0 {
            return None;
        }
        let b = sxy / sxx;
        let a = my - b * mx;
        let rss: f64 = pts().map(|(x, y)| (y - a - b * x).powi(2)).sum();
        let s2 = rss / (n - 2) as f64;
        let ppm = (b - 1.0) * 1e6;
        (ppm.abs() <= MAX_PPM).then_some(Self {
            ppm,
            sigma_ppm: (s2 / sxx).sqrt() * 1e6,
            span_s: span,
            edges: n,
            end_s,
        })
    }

    /// The true length of `dt` s of the IMU's nominal seconds.
    pub fn true_dt(&self, dt: f64) -> f64 {
        dt / (1.0 + self.ppm * 1e-6)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Edges of an IMU `ppm` fast, each latched to within `q` s (a deterministic saw).
    fn edges(ppm: f64, n: i64, q: f64) -> Vec<(i64, f64)> {
        (0..n)
            .map(|s| {
                let t = 3.0 + s as f64 * (1.0 + ppm * 1e-6);
                (s, t + q * (((s * 7) % 5) as f64 / 4.0 - 0.5))
            })
            .collect()
    }

    #[test]
    fn the_rate_is_read_from_the_edges_with_its_uncertainty() {
        for ppm in [-120.0, 0.0, 47.0, 1000.0] {
            let e = ClockEstimate::from_edges(edges(ppm, 64, 1e-5).iter()).expect("enough edges");
            assert!(
                (e.ppm - ppm).abs() < 3.0 * e.sigma_ppm + 1e-6,
                "{ppm}: {e:?}"
            );
            assert!(e.sigma_ppm > 0.0 && e.sigma_ppm < 0.2, "{e:?}");
            assert_eq!(e.edges, 64);
            assert_eq!(e.span_s, 63.0);
            assert_eq!(e.end_s, edges(ppm, 64, 1e-5)[63].1);
            // an IMU 1000 ppm fast counts a true second in 1.001 of its own
            let dt = e.true_dt(1.0);
            assert!((dt * (1.0 + ppm * 1e-6) - 1.0).abs() < 1e-6, "{dt}");
        }
    }

    #[test]
    fn too_few_edges_or_nonsense_give_no_rate() {
        assert_eq!(ClockEstimate::from_edges(edges(50.0, 7, 0.0).iter()), None);
        assert_eq!(ClockEstimate::from_edges([].iter()), None);
        assert_eq!(
            ClockEstimate::from_edges(edges(20_000.0, 64, 0.0).iter()),
            None
        );
        // a missing second between edges keeps its number: the span counts it
        let mut e = edges(50.0, 12, 0.0);
        e.remove(5);
        let c = ClockEstimate::from_edges(e.iter()).expect("eleven edges over 11 s");
        assert!((c.ppm - 50.0).abs() < 1e-3, "{c:?}");
    }
}
