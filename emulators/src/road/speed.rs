//! The vehicle's speed along the road as a function of time: standing, cruising, and smooth
//! changes of speed between them, `v(tau) = v0 + dv (1 - cos(pi tau / T)) / 2`, whose
//! acceleration rises from and falls to zero (no step a passenger would feel) and whose duration
//! `T` keeps both the acceleration (or braking) and the jerk within their limits:
//! `T >= pi |dv| / (2 a)` and `T >= pi sqrt(|dv| / (2 j))`.

use std::f64::consts::PI;

/// One phase of the speed profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Phase {
    /// Start, s.
    pub t0: f64,
    /// Duration, s (the last phase: standing for ever).
    pub dur: f64,
    /// Distance along the road at its start, m.
    pub s0: f64,
    /// Speed at its start, m/s.
    pub v0: f64,
    /// Change of speed over it, m/s (0: standing or cruising).
    pub dv: f64,
}

/// Where the vehicle is on the road at one time: distance, speed, acceleration, jerk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Along {
    /// Distance along the road, m.
    pub s: f64,
    /// Speed, m/s.
    pub v: f64,
    /// Acceleration along the road, m/s^2.
    pub a: f64,
    /// Its rate, m/s^3.
    pub j: f64,
}

impl Phase {
    /// The state `tau` seconds into the phase.
    pub fn at(&self, tau: f64) -> Along {
        if self.dv == 0.0 {
            return Along {
                s: self.s0 + self.v0 * tau,
                v: self.v0,
                a: 0.0,
                j: 0.0,
            };
        }
        let w = PI / self.dur;
        let (sin, cos) = (w * tau).sin_cos();
        Along {
            s: self.s0 + self.v0 * tau + 0.5 * self.dv * (tau - sin / w),
            v: self.v0 + 0.5 * self.dv * (1.0 - cos),
            a: 0.5 * self.dv * w * sin,
            j: 0.5 * self.dv * w * w * cos,
        }
    }

    /// Distance covered over the whole phase, m.
    pub fn distance(&self) -> f64 {
        (self.v0 + 0.5 * self.dv) * self.dur
    }
}

/// The limits a change of speed keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Limits {
    /// Acceleration, m/s^2.
    pub accel: f64,
    /// Braking, m/s^2.
    pub brake: f64,
    /// Jerk, m/s^3.
    pub jerk: f64,
}

impl Limits {
    /// Duration of a change of speed from `v0` to `v1`, s.
    pub fn ramp(&self, v0: f64, v1: f64) -> f64 {
        let dv = (v1 - v0).abs();
        if dv == 0.0 {
            return 0.0;
        }
        let a = if v1 > v0 { self.accel } else { self.brake };
        (PI * dv / (2.0 * a)).max(PI * (dv / (2.0 * self.jerk)).sqrt())
    }

    /// Distance a change of speed from `v0` to `v1` covers, m.
    pub fn ramp_distance(&self, v0: f64, v1: f64) -> f64 {
        0.5 * (v0 + v1) * self.ramp(v0, v1)
    }
}

/// One stretch of road driven between two stops, at a speed per piece.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Stretch {
    /// Where it starts (standing), m along the road.
    pub s0: f64,
    /// The pieces: (where each ends, m along the road; its speed, m/s). The last ends at the
    /// stop.
    pub pieces: Vec<(f64, f64)>,
    /// Standing at its end, s.
    pub wait_s: f64,
}

/// The profile's phases so far.
#[derive(Debug, Default)]
pub(crate) struct Profile {
    /// The phases in time order.
    pub phases: Vec<Phase>,
    t: f64,
    s: f64,
    v: f64,
}

impl Profile {
    fn push(&mut self, dur: f64, dv: f64) {
        if dur <= 0.0 {
            return;
        }
        let p = Phase {
            t0: self.t,
            dur,
            s0: self.s,
            v0: self.v,
            dv,
        };
        self.s += p.distance();
        self.t += dur;
        self.v += dv;
        self.phases.push(p);
    }

    /// Stand still for `dur` s.
    pub fn stand(&mut self, dur: f64) {
        self.push(dur, 0.0);
    }

    /// Change speed to `v1` within `lim`.
    fn ramp(&mut self, v1: f64, lim: &Limits) {
        let dur = lim.ramp(self.v, v1);
        self.push(dur, v1 - self.v);
        self.v = v1;
    }

    /// Cruise to `s_end` m along the road.
    fn cruise_to(&mut self, s_end: f64) {
        if self.v > 0.0 && s_end > self.s {
            self.push((s_end - self.s) / self.v, 0.0);
        }
    }

    /// Drive one stretch from standing to standing. The pieces' speeds are lowered (and said,
    /// in the returned list of (piece, speed driven)) where a piece is too short to reach its
    /// own and change to the next's within the limits.
    pub fn drive(&mut self, st: &Stretch, lim: &Limits) -> Vec<(usize, f64)> {
        let speeds = feasible_speeds(st, lim);
        let lowered = st
            .pieces
            .iter()
            .zip(&speeds)
            .enumerate()
            .filter(|(_, (p, v))| **v < p.1)
            .map(|(i, (_, v))| (i, *v))
            .collect();
        let n = speeds.len();
        for i in 0..n {
            let v = speeds[i];
            // a piece faster than the one before starts its change where it starts
            if v > self.v {
                self.ramp(v, lim);
            }
            // a slower next piece (or the stop) is reached where this one ends
            let next = if i + 1 < n { speeds[i + 1] } else { 0.0 };
            let s_end = st.pieces[i].0;
            if next < v {
                self.cruise_to(s_end - lim.ramp_distance(v, next));
                self.ramp(next, lim);
                // rounding: the stop is where the road says
                if i + 1 == n {
                    self.s = s_end;
                }
            } else {
                self.cruise_to(s_end);
            }
        }
        self.v = 0.0;
        self.stand(st.wait_s);
        lowered
    }

    /// Time at the end of the phases so far, s.
    #[cfg(test)]
    pub fn end(&self) -> f64 {
        self.t
    }

    /// Distance at the end of the phases so far, m.
    #[cfg(test)]
    pub fn distance(&self) -> f64 {
        self.s
    }
}

/// The pieces' speeds, each lowered as far as it must be for its changes of speed to fit in
/// it: on each piece, the change from the speed it is entered at (where faster) and the change
/// to the next piece's (where slower).
fn feasible_speeds(st: &Stretch, lim: &Limits) -> Vec<f64> {
    let mut v: Vec<f64> = st.pieces.iter().map(|p| p.1).collect();
    let n = v.len();
    // lowering one piece can make its neighbours' changes longer or shorter: repeat until
    // nothing changes (each pass only lowers speeds, so it ends)
    for _ in 0..200 {
        let mut changed = false;
        for i in 0..n {
            let start = if i == 0 { st.s0 } else { st.pieces[i - 1].0 };
            let len = st.pieces[i].0 - start;
            let before = if i == 0 { 0.0 } else { v[i - 1] };
            let after = if i + 1 < n { v[i + 1] } else { 0.0 };
            let need = |x: f64| {
                let up = if x > before {
                    lim.ramp_distance(before, x)
                } else {
                    0.0
                };
                let down = if after < x {
                    lim.ramp_distance(x, after)
                } else {
                    0.0
                };
                up + down
            };
            if need(v[i]) > len {
                // the fastest speed that fits, by bisection
                let (mut lo, mut hi) = (0.0, v[i]);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if need(mid) <= len {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                v[i] = lo;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    v
}

/// The profile's state at `t`: the phase it is in (standing for ever after the last).
pub(crate) fn along(phases: &[Phase], t: f64) -> Along {
    let i = phases.partition_point(|p| p.t0 <= t).saturating_sub(1);
    match phases.get(i) {
        Some(p) if t <= p.t0 + p.dur => p.at((t - p.t0).max(0.0)),
        Some(p) => Along {
            s: p.s0 + p.distance(),
            v: (p.v0 + p.dv).max(0.0),
            a: 0.0,
            j: 0.0,
        },
        None => Along {
            s: 0.0,
            v: 0.0,
            a: 0.0,
            j: 0.0,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIM: Limits = Limits {
        accel: 1.5,
        brake: 2.5,
        jerk: 0.8,
    };

    /// A stretch of three speeds ends standing where it must, keeps the limits, and its
    /// distance is the integral of its speed (and speed of acceleration, acceleration of jerk).
    #[test]
    fn a_stretch_keeps_its_limits_and_stops_where_it_must() {
        let st = Stretch {
            s0: 0.0,
            pieces: vec![(500.0, 14.0), (700.0, 6.0), (1500.0, 20.0)],
            wait_s: 10.0,
        };
        let mut p = Profile::default();
        p.stand(5.0);
        let lowered = p.drive(&st, &LIM);
        assert!(lowered.is_empty(), "{lowered:?}");
        assert!((p.distance() - 1500.0).abs() < 1e-9, "{}", p.distance());
        let ph = &p.phases;
        let h = 1e-5;
        let mut t = 0.0;
        while t < p.end() {
            let (a, b, c) = (along(ph, t - h), along(ph, t), along(ph, t + h));
            assert!(b.v >= -1e-12 && b.v <= 20.0 + 1e-9, "{t}: {b:?}");
            assert!(
                b.a <= LIM.accel + 1e-9 && b.a >= -LIM.brake - 1e-9,
                "{t}: {b:?}"
            );
            assert!(b.j.abs() <= LIM.jerk + 1e-9, "{t}: {b:?}");
            if t > h {
                assert!(((c.s - a.s) / (2.0 * h) - b.v).abs() < 1e-6, "{t}");
                assert!(((c.v - a.v) / (2.0 * h) - b.a).abs() < 1e-6, "{t}");
            }
            // the slow piece is driven at its speed
            if b.s > 500.0 + 1e-6 && b.s < 700.0 - 1e-6 {
                assert!(b.v <= 6.0 + 1e-9, "{t}: {b:?}");
            }
            t += 0.01;
        }
        // standing at the end
        let end = along(ph, p.end() + 100.0);
        assert_eq!((end.v, end.a), (0.0, 0.0));
    }

    /// A piece too short for its speed is driven slower, and says so.
    #[test]
    fn a_short_piece_is_driven_slower_and_said() {
        let st = Stretch {
            s0: 0.0,
            pieces: vec![(60.0, 20.0)],
            wait_s: 0.0,
        };
        let mut p = Profile::default();
        let lowered = p.drive(&st, &LIM);
        assert_eq!(lowered.len(), 1);
        assert!(lowered[0].1 < 20.0 && lowered[0].1 > 3.0, "{lowered:?}");
        assert!((p.distance() - 60.0).abs() < 1e-6, "{}", p.distance());
    }
}
