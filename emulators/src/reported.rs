//! A turntable the bench does not model: its angle as its controller reports it (TT_STATUS), for
//! an emulated IMU that sits on a real table (or on a table emulated by another process).
//!
//! The IMU's truth needs the table's angle at every instant; the controller reports it at its
//! status rate (100 Hz by default), quantized to 0.0001 deg and wrapped to [0, 360). The track
//! unwraps the reports and follows them **a fixed delay behind** (two status periods by
//! default): the IMU at time t feels the angle the table reported at t - delay, linearly
//! interpolated between reports. So the gyros integrate exactly the angle the encoder reported
//! (the integral of the track's rate between two knots is their difference), only later by
//! the delay: the table's rotation reaches the IMU's truth as through a short transport delay,
//! which the card names.
//!
//! Every knot is put on the IMU's sample grid, so that the track's rate is constant over each
//! sample interval and the IMU's quadrature of it is exact. The history the IMU has read is
//! final: a report that comes later than the delay (a late frame, a stalled controller) cannot
//! change it; the track then moves to the reported angle over the next status period from where
//! the IMU has read to, and the report is counted late. Pure: no I/O, no wall time.

use crate::truth::AxisAngle;
use std::sync::{Arc, Mutex, MutexGuard};

/// The reported angle history of one axis, on the IMU's sample grid.
#[derive(Debug, Clone)]
pub struct ReportedTrack {
    /// (time, unwrapped angle rad), strictly increasing in time; before the first knot the
    /// angle is the first knot's (0 before any report).
    knots: Vec<(f64, f64)>,
    /// The IMU's sample period, s (the grid of knot times).
    grid_s: f64,
    /// Delay of the track behind the reports, s.
    delay_s: f64,
    /// Time up to which the IMU has read the track: the history before it is final.
    horizon: f64,
    /// The last report's angle, unwrapped, rad.
    last: Option<f64>,
    /// The fastest the track turns, rad/s (infinite: as fast as the reports say).
    max_rate: f64,
    /// What was taken.
    pub stats: ReportStats,
}

/// What a track made of the reports.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReportStats {
    /// Reports taken.
    pub reports: u64,
    /// Reports that came after the IMU had read past their place on the track (more than the
    /// delay late): the track moved to them over the next status period instead.
    pub late: u64,
    /// Reports left out because their encoder fault bit was set (the angle is not to be trusted).
    pub encoder_faults: u64,
    /// Reports that came closer together than the table could turn between them: the track
    /// went to them at its fastest rate instead (see [`ReportedTrack::with_max_rate`]).
    #[serde(default)]
    pub bunched: u64,
}

impl ReportedTrack {
    /// A track on the grid of an IMU sampling at `imu_rate_hz`, `delay_s` behind the reports.
    pub fn new(imu_rate_hz: f64, delay_s: f64) -> Self {
        Self {
            knots: Vec::new(),
            grid_s: 1.0 / imu_rate_hz,
            delay_s: delay_s.max(0.0),
            horizon: 0.0,
            last: None,
            max_rate: f64::INFINITY,
            stats: ReportStats::default(),
        }
    }

    /// The track turns no faster than `rad_s`: reports that come closer together than the
    /// table could turn between them (a controller starved by its host sends its backlog at
    /// once) are spread at this rate instead of making the IMU's truth jump, beyond what its
    /// gyros can read. Give the table's own limit with a margin, within the gyros' range.
    pub fn with_max_rate(mut self, rad_s: f64) -> Self {
        if rad_s > 0.0 {
            self.max_rate = rad_s;
        }
        self
    }

    /// The delay of the track behind the reports, s.
    pub fn delay_s(&self) -> f64 {
        self.delay_s
    }

    /// The controller reported `angle_deg` (wrapped, [0, 360)) at `t` (the time it reached the
    /// IMU's side, s of the IMU's clock); `encoder_fault`: its encoder fault bit.
    pub fn report(&mut self, t: f64, angle_deg: f64, encoder_fault: bool) {
        if encoder_fault || !angle_deg.is_finite() {
            self.stats.encoder_faults += 1;
            return;
        }
        self.stats.reports += 1;
        let wrapped = angle_deg.to_radians();
        let angle = match self.last {
            // the first report: the nearest turn to zero
            None => wrapped - std::f64::consts::TAU * (wrapped / std::f64::consts::TAU).round(),
            Some(prev) => {
                let d = wrapped - prev;
                prev + d - std::f64::consts::TAU * (d / std::f64::consts::TAU).round()
            }
        };
        self.last = Some(angle);
        let mut at = self.snap(t + self.delay_s);
        // the end of the sample interval the IMU has read into (it reads whole samples)
        let h = self.snap(self.horizon);
        let had_knots = !self.knots.is_empty();
        // the history the IMU has read is final: where it read past the last knot (holding
        // the angle there), that hold becomes a knot, so that a new knot after it cannot
        // reshape it, however timely the report
        // (before the first report the IMU felt no rate: the first knot only sets the angle)
        if self.knots.last().is_some_and(|k| k.0 < h) {
            let here = self.eval(h).0;
            self.knots.push((h, here));
        }
        // a report later than the delay: move over the next status period from there
        if at <= self.horizon {
            self.stats.late += 1;
            let period = if had_knots {
                self.delay_s * 0.5
            } else {
                self.grid_s
            };
            at = self.snap(h + period.max(self.grid_s));
        }
        if let Some(&(t_last, a_last)) = self.knots.last() {
            if at <= t_last {
                at = t_last + self.grid_s;
            }
            // no faster than the table can turn
            let need = (angle - a_last).abs() / self.max_rate;
            if had_knots && at - t_last < need {
                self.stats.bunched += 1;
                at = self.snap(t_last + need);
            }
        }
        // the whole history stays: it is the truth the bench scores against (16 bytes a
        // report, 5.8 MB an hour at 100 Hz)
        self.knots.push((at, angle));
    }

    /// The next grid point at or after `t`.
    fn snap(&self, t: f64) -> f64 {
        (t / self.grid_s - 1e-9).ceil() * self.grid_s
    }

    /// Angle (rad) and rate (rad/s) at `t`, without reading.
    pub fn eval(&self, t: f64) -> (f64, f64) {
        let Some(first) = self.knots.first() else {
            return (0.0, 0.0);
        };
        if t <= first.0 {
            return (first.1, 0.0);
        }
        let i = self.knots.partition_point(|k| k.0 < t);
        match self.knots.get(i) {
            None => (self.knots[i - 1].1, 0.0),
            Some(&(t1, a1)) => {
                let (t0, a0) = self.knots[i - 1];
                let rate = (a1 - a0) / (t1 - t0);
                (a0 + rate * (t - t0), rate)
            }
        }
    }

    /// The IMU has read the track up to `t`.
    pub fn read_to(&mut self, t: f64) {
        self.horizon = self.horizon.max(t);
    }

    /// The angle does not change over `[t0, t1]`.
    pub fn still(&self, t0: f64, t1: f64) -> bool {
        let a0 = self.eval(t0).0;
        let from = self.knots.partition_point(|k| k.0 <= t0);
        let to = self.knots.partition_point(|k| k.0 <= t1);
        self.knots[from..to].iter().all(|k| k.1 == a0) && self.eval(t1).0 == a0
    }
}

/// A track shared by the side that reads the reports and the IMU's truth.
pub type SharedTrack = Arc<Mutex<ReportedTrack>>;

fn lock(t: &SharedTrack) -> MutexGuard<'_, ReportedTrack> {
    t.lock().unwrap_or_else(|e| e.into_inner())
}

/// The IMU's view of a reported axis (an [`AxisAngle`] for [`crate::truth::Indexer`]).
#[derive(Clone)]
pub struct ReportedAxis(pub SharedTrack);

impl AxisAngle for ReportedAxis {
    fn angle(&self, t: f64) -> f64 {
        self.angle_and_rate(t).0
    }
    fn rate(&self, t: f64) -> f64 {
        self.angle_and_rate(t).1
    }
    fn angle_and_rate(&self, t: f64) -> (f64, f64) {
        let mut tr = lock(&self.0);
        tr.read_to(t);
        tr.eval(t)
    }
    fn still(&self, t0: f64, t1: f64) -> bool {
        let mut tr = lock(&self.0);
        tr.read_to(t1);
        tr.still(t0, t1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::truth::gauss_legendre;
    use nalgebra::Vector3;

    /// The IMU's integral of the track's rate over its samples.
    fn integrate(tr: &SharedTrack, k0: u64, k1: u64, dt: f64) -> f64 {
        let ax = ReportedAxis(tr.clone());
        (k0..k1)
            .map(|k| {
                let (t0, t1) = (k as f64 * dt, (k + 1) as f64 * dt);
                gauss_legendre(t0, t1, |t| {
                    (Vector3::new(ax.rate(t), 0.0, 0.0), Vector3::zeros())
                })
                .dtheta
                .x
            })
            .sum()
    }

    /// A move reported at 100 Hz while the IMU reads at 2 kHz: the gyros integrate exactly the
    /// reported angle change, across the wrap at 360 deg, the delay behind.
    #[test]
    fn the_imu_integrates_exactly_what_the_encoder_reported() {
        let dt = 1.0 / 2000.0;
        let tr: SharedTrack = Arc::new(Mutex::new(ReportedTrack::new(2000.0, 0.02)));
        let ax = ReportedAxis(tr.clone());
        // from 350 deg on, 10 deg/s for 3 s: through 360 to 20 deg
        let mut k = 0u64;
        let mut integrated = 0.0;
        for i in 0..400 {
            let t = i as f64 * 0.01 + 0.003;
            let angle = (350.0 + 10.0 * (t - 0.5).clamp(0.0, 3.0)).rem_euclid(360.0);
            // the IMU reads up to the report's arrival (it runs on the same clock)
            let k_to = (t / dt).floor() as u64;
            integrated += integrate(&tr, k, k_to, dt);
            k = k_to;
            lock(&tr).report(t, (angle * 1e4).round() / 1e4, false);
        }
        integrated += integrate(&tr, k, k + 200, dt);
        assert!(
            (integrated.to_degrees() - 30.0).abs() < 1e-9,
            "{}",
            integrated.to_degrees()
        );
        assert_eq!(lock(&tr).stats.late, 0);
        // the first report sets where the track starts: -10 deg, the nearest turn to zero
        assert!((ax.angle(10.0).to_degrees() - 20.0).abs() < 1e-9);
        // the delay: at 0.5 s + 20 ms the move has not yet reached the IMU
        assert!(ax.still(4.0, 5.0));
    }

    /// A report later than the delay cannot change what the IMU has read: the track moves to it
    /// over the next period, it is counted late, and the integral still lands on it.
    #[test]
    fn a_late_report_is_caught_up_not_rewritten() {
        let dt = 1.0 / 2000.0;
        let tr: SharedTrack = Arc::new(Mutex::new(ReportedTrack::new(2000.0, 0.02)));
        lock(&tr).report(0.0, 0.0, false);
        let before = integrate(&tr, 0, 1000, dt); // the IMU has read to 0.5 s
        assert_eq!(before, 0.0);
        // a report of 1 deg that belonged at 0.1 s
        lock(&tr).report(0.08, 1.0, false);
        assert_eq!(lock(&tr).stats.late, 1);
        let after = integrate(&tr, 1000, 1400, dt);
        assert!(
            (after.to_degrees() - 1.0).abs() < 1e-9,
            "{}",
            after.to_degrees()
        );
        // an encoder fault's angle is not taken
        lock(&tr).report(0.6, 200.0, true);
        assert_eq!(lock(&tr).stats.encoder_faults, 1);
        assert!((ReportedAxis(tr.clone()).angle(2.0).to_degrees() - 1.0).abs() < 1e-9);
    }

    /// The IMU reads past the last report (a host that delivers the reports late holds them
    /// back): it felt the angle held there, and a report that then comes, in time for its own
    /// place on the track, does not reshape what was read. Were the new knot joined to the last
    /// one by a line through the read past, the truth the judge scores against would turn
    /// earlier than the gyros had: on a loaded host an honest device's headings read as 100 ms
    /// off their tags.
    #[test]
    fn what_the_imu_read_past_the_last_report_stays_as_it_read_it() {
        let dt = 1.0 / 2000.0;
        let tr: SharedTrack = Arc::new(Mutex::new(ReportedTrack::new(2000.0, 0.02)));
        lock(&tr).report(0.0, 0.0, false);
        // the IMU reads to 0.3 s: the angle held at 0
        assert_eq!(integrate(&tr, 0, 600, dt), 0.0);
        let held: Vec<f64> = (0..600).map(|k| lock(&tr).eval(k as f64 * dt).0).collect();
        // a report at 0.29 s (its place, 0.31 s, not read yet): not late
        lock(&tr).report(0.29, 2.0, false);
        assert_eq!(lock(&tr).stats.late, 0);
        let now: Vec<f64> = (0..600).map(|k| lock(&tr).eval(k as f64 * dt).0).collect();
        assert_eq!(held, now, "the history read is final");
        // and the gyros still land on the report
        let after = integrate(&tr, 600, 800, dt);
        assert!(
            (after.to_degrees() - 2.0).abs() < 1e-9,
            "{}",
            after.to_degrees()
        );
    }

    /// A controller starved by its host sends a backlog at once: 100 ms of a 30 deg/s turn in
    /// ten reports read together. The track goes to them no faster than its limit (45 deg/s
    /// here) instead of in ten grid steps (600 deg/s, beyond a 400 deg/s gyro), counts them
    /// bunched, and the gyros still land on the last report.
    #[test]
    fn reports_read_together_are_spread_at_the_table_s_fastest() {
        let dt = 1.0 / 2000.0;
        let limit = 45f64.to_radians();
        let tr: SharedTrack = Arc::new(Mutex::new(
            ReportedTrack::new(2000.0, 0.02).with_max_rate(limit),
        ));
        lock(&tr).report(0.0, 0.0, false);
        assert_eq!(integrate(&tr, 0, 200, dt), 0.0);
        for i in 1..=10 {
            lock(&tr).report(0.1, 0.3 * f64::from(i), false);
        }
        assert!(lock(&tr).stats.bunched >= 9, "{:?}", lock(&tr).stats);
        let fastest = (200..2000)
            .map(|k| lock(&tr).eval((k as f64 + 0.5) * dt).1.abs())
            .fold(0.0, f64::max);
        assert!(
            fastest <= limit * (1.0 + 1e-9),
            "{} deg/s",
            fastest.to_degrees()
        );
        let turned = integrate(&tr, 200, 2000, dt);
        assert!(
            (turned.to_degrees() - 3.0).abs() < 1e-9,
            "{}",
            turned.to_degrees()
        );
    }

    /// Knots sit on the sample grid: the rate is constant inside each sample interval.
    #[test]
    fn knots_sit_on_the_sample_grid() {
        let tr = {
            let mut t = ReportedTrack::new(2000.0, 0.02);
            t.report(0.0101, 0.0, false);
            t.report(0.0203, 0.5, false);
            t
        };
        for &(t, _) in &tr.knots {
            let n = t * 2000.0;
            assert!((n - n.round()).abs() < 1e-6, "{t}");
        }
        // inside one interval the rate does not change
        let (_, r0) = tr.eval(0.04 + 0.0001);
        let (_, r1) = tr.eval(0.04 + 0.0004);
        assert_eq!(r0, r1);
    }
}
