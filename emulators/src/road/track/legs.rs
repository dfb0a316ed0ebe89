//! The fitted track planned as a road: its legs laid on the ellipsoid between the corners'
//! latitudes and longitudes (each a line of constant heading, a rhumb line, which is what a
//! leg of the road is), each leg's speed set so that the vehicle reaches each corner when the
//! track did, and the road's distance from every point of the track measured.

use super::fit::{FitOptions, Fitted, Vertex, fit};
use super::{Track, TrackError, TrackNotes};
use crate::ParamError;
use crate::drive::DriveSpec;
use crate::geodesy as earth;
use crate::road::Road;
use crate::road::plan::{Leg, points, sane};
use crate::road::speed::Phase;
use nalgebra::Vector3;
use std::f64::consts::PI;

/// Rounds of setting the legs' speeds from the times the plan reaches the corners.
const TIMING_ROUNDS: usize = 6;
/// A leg's speed is kept within these, m/s (the top from the fit's options).
const SLOWEST_MPS: f64 = 0.5;

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

/// The line of constant heading from `a` to `b` (latitude, longitude in rad, height in m):
/// its horizontal length (m) and heading (rad), exact on the ellipsoid at the legs' mean
/// height: `tan(psi) = dlon / dq` with `q` the isometric latitude, and the length the meridian
/// arc over `cos(psi)` (along a parallel where the leg runs east or west).
pub(crate) fn rhumb(a: [f64; 3], b: [f64; 3]) -> (f64, f64) {
    let e2 = 1.0 - (earth::B * earth::B) / (earth::A * earth::A);
    let e = e2.sqrt();
    let q = |phi: f64| phi.sin().atanh() - e * (e * phi.sin()).atanh();
    let dq = q(b[0]) - q(a[0]);
    let dl = wrap(b[1] - a[1]);
    let psi = dl.atan2(dq);
    let h = 0.5 * (a[2] + b[2]);
    let mid = 0.5 * (a[0] + b[0]);
    let m = |phi: f64| earth::radii(phi).0 + h;
    let len = if dq.abs() > 1e-3 * dl.abs() {
        // Simpson's rule over the meridian radius: a leg is at most a few tens of kilometres
        (b[0] - a[0]) / 6.0 * (m(a[0]) + 4.0 * m(mid) + m(b[0])) / psi.cos()
    } else {
        (earth::radii(mid).1 + h) * mid.cos() * dl.abs()
    };
    (len, psi)
}

/// The first time the plan is `s` metres along the road, s.
fn time_at(phases: &[Phase], s: f64) -> f64 {
    let i = phases.partition_point(|p| p.s0 < s);
    let Some(p) = i.checked_sub(1).map(|j| phases[j]) else {
        return phases.first().map_or(0.0, |p| p.t0);
    };
    let (mut lo, mut hi) = (0.0, p.dur);
    if p.at(hi).s < s {
        return p.t0 + p.dur;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if p.at(mid).s < s {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    p.t0 + hi
}

/// Corners closer than this to the one before are merged into it, m.
const MERGE_M: f64 = 2.0;

/// Merge corners too close to drive a leg between.
fn merged(v: Vec<Vertex>) -> Vec<Vertex> {
    let mut out: Vec<Vertex> = Vec::with_capacity(v.len());
    for x in v {
        if let Some(last) = out.last_mut() {
            let (len, _) = rhumb(last.llh, x.llh);
            if len < MERGE_M {
                last.t_out = x.t_out;
                continue;
            }
        }
        out.push(x);
    }
    out
}

impl Road {
    /// Drive the recorded `track`: fitted ([`fit`]) with the options of `spec`, whose limits
    /// (acceleration, braking, jerk, lateral acceleration, turn rate) and body (pitch and roll
    /// per acceleration, bank) the road keeps; `spec.start_wait_s` is spent standing at the
    /// track's start before its first point's time.
    pub fn from_track(spec: &DriveSpec, track: &Track) -> Result<Self, TrackError> {
        let opt = fit_options(spec, track)?;
        let Fitted {
            vertices,
            used,
            mut notes,
        } = fit(track, &opt)?;
        let v = merged(vertices);
        let wrong = |e: ParamError| {
            let mut what = e.problem;
            // the corner a waypoint's message names, by where it is in the track
            if let Some(k) = what
                .split("waypoint ")
                .nth(1)
                .and_then(|r| r.split(|c: char| !c.is_ascii_digit()).next())
                .and_then(|d| d.parse::<usize>().ok())
                .and_then(|k| v.get(k))
            {
                what += &format!(" (waypoint: the corner fitted at {})", k.at);
            }
            TrackError::new(&track.file, "the road fitted to it", what)
        };
        if v.len() < 2 {
            return Err(TrackError::new(
                &track.file,
                "the whole file",
                "the track stays in one place: nothing to drive",
            ));
        }
        let mut spec2 = track_spec(spec, &v);
        sane(&spec2).map_err(wrong)?;
        let pts = points(&spec2).map_err(wrong)?;
        let legs0 = geodetic_legs(&v);
        check_legs(track, &v, &legs0)?;
        let want: Vec<f64> = v.windows(2).map(|w| w[1].t_in - w[0].t_out).collect();
        let mut speeds = first_speeds(&legs0, &want, opt.max_speed_mps);
        // the plan's time is the track's plus the scenario's wait before it
        let offset = spec.start_wait_s;
        // standing at each corner: the start's wait, then the stops'
        let mut waits: Vec<f64> = v.iter().map(|x| x.t_out - x.t_in).collect();
        waits[0] = spec2.start_wait_s;
        // each turn passes within the simplification's tolerance of its corner
        let tol = super::fit::simplify_tolerance(notes.jitter_m);
        let mut planned = None;
        for _ in 0..TIMING_ROUNDS {
            spec2.leg_speeds_mps.clone_from(&speeds);
            spec2.stops = (1..v.len())
                .filter(|&k| v[k].t_out > v[k].t_in)
                .map(|k| [k as f64, waits[k]])
                .collect();
            let legs: Vec<Leg> = legs0
                .iter()
                .zip(&speeds)
                .map(|(l, &speed)| Leg { speed, ..*l })
                .collect();
            let (road, reached) = Road::build(&spec2, &pts, legs, Some(tol)).map_err(wrong)?;
            // a corner is passed at the middle of its turn; a stop is reached where its turn
            // starts
            let times: Vec<f64> = reached
                .iter()
                .zip(&v)
                .map(|(s, x)| time_at(&road.phases, s[usize::from(x.t_out <= x.t_in)]))
                .collect();
            retime(
                &mut speeds,
                &legs0,
                &want,
                &waits,
                &times,
                opt.max_speed_mps,
            );
            // a stop absorbs what the plan is late or early at the corner after it (the track
            // stands until the vehicle has moved a little: its time of leaving is late)
            for k in 1..v.len() - 1 {
                let stood = v[k].t_out - v[k].t_in;
                if stood > 0.0 {
                    let late = times[k + 1] - (v[k + 1].t_in + offset);
                    waits[k] = (waits[k] - late).clamp(0.3 * stood, 2.0 * stood + 5.0);
                }
            }
            planned = Some((road, times));
        }
        let Some((mut road, times)) = planned else {
            return Err(TrackError::new(&track.file, "the whole file", "no plan"));
        };
        notes.start_wait_s = offset;
        timing(&v, &times, offset, &mut notes);
        distances(&road, &used, offset, &mut notes);
        finish_notes(spec, &mut road, &mut notes, offset);
        road.track = Some(Box::new(notes));
        Ok(road)
    }
}

/// Each leg's speed scaled by how much longer the plan took than the track over the legs
/// around it (at least [`RETIME_WINDOW_S`] of the track): a leg that cannot be driven faster
/// (a short one in a bend) is made up for by its neighbours; the stops absorb what is left. A
/// leg is driven at most twice
/// its average on the track, and 5 m/s more.
fn retime(speeds: &mut [f64], legs: &[Leg], want: &[f64], waits: &[f64], times: &[f64], top: f64) {
    let n = speeds.len();
    // the plan's time on each leg, from leaving its start
    let took: Vec<f64> = (0..n)
        .map(|k| times[k + 1] - (times[k] + waits[k]))
        .collect();
    for k in 0..n {
        let (a, b) = window(want, k);
        let (w, t) = (
            want[a..=b].iter().sum::<f64>(),
            took[a..=b].iter().sum::<f64>(),
        );
        if w > 0.1 && t > 0.0 {
            let avg = legs[k].len_h / want[k].max(0.1);
            let cap = (2.0 * avg).max(avg + 5.0).min(top);
            speeds[k] = (speeds[k] * (t / w).clamp(0.5, 2.0)).clamp(SLOWEST_MPS, cap);
        }
    }
}

/// The legs around leg `k` (first and last) over at least [`RETIME_WINDOW_S`] of the track.
fn window(want: &[f64], k: usize) -> (usize, usize) {
    let n = want.len();
    let (mut a, mut b) = (k, k);
    let span = |a: usize, b: usize| want[a..=b].iter().sum::<f64>();
    while span(a, b) < RETIME_WINDOW_S && (a > 0 || b + 1 < n) {
        a = a.saturating_sub(1);
        b = (b + 1).min(n - 1);
    }
    (a, b)
}

/// The track's time over which a leg's speed is set, s.
const RETIME_WINDOW_S: f64 = 30.0;

/// The legs are a road's: none steeper than 35 %, and no longer in all than the bench drives.
fn check_legs(track: &Track, v: &[Vertex], legs: &[Leg]) -> Result<(), TrackError> {
    if let Some(k) = legs.iter().position(|l| l.dh.abs() > 0.35 * l.len_h) {
        return Err(TrackError::new(
            &track.file,
            format!("from {} to {}", v[k].at, v[k + 1].at),
            format!(
                "the road fitted to it climbs {:.0} m in {:.0} m: no road is steeper than 35 %",
                legs[k].dh, legs[k].len_h
            ),
        ));
    }
    let length: f64 = legs.iter().map(|l| l.len_h).sum();
    if !(length.is_finite() && length <= crate::road::plan::MAX_LENGTH_M) {
        return Err(TrackError::new(
            &track.file,
            "the whole file",
            format!(
                "{:.0} km of road: the bench drives at most {:.0} km",
                length / 1e3,
                crate::road::plan::MAX_LENGTH_M / 1e3
            ),
        ));
    }
    Ok(())
}

/// The fit's options from the scenario's `[drive]`, refused where out of range.
fn fit_options(spec: &DriveSpec, track: &Track) -> Result<FitOptions, TrackError> {
    let bad = |what: &str, x: Option<f64>, lo: f64, hi: f64| {
        x.filter(|x| !(x.is_finite() && *x > lo && *x <= hi))
            .map(|x| {
                TrackError::new(
                    &track.file,
                    "the scenario's [drive]",
                    format!("{what} {x}: from {lo} (not included) to {hi}"),
                )
            })
            .map_or(Ok(()), Err)
    };
    bad("track_jitter_m", spec.track_jitter_m, 0.0, 100.0)?;
    bad("track_max_speed_mps", spec.track_max_speed_mps, 1.0, 150.0)?;
    Ok(FitOptions {
        max_speed_mps: spec.track_max_speed_mps.unwrap_or(70.0),
        jitter_m: spec.track_jitter_m,
        level_height_m: spec.height_m,
    })
}

/// The legs between the corners on the ellipsoid (lines of constant heading).
fn geodetic_legs(v: &[Vertex]) -> Vec<Leg> {
    v.windows(2)
        .map(|w| {
            let (len_h, psi) = rhumb(w[0].llh, w[1].llh);
            Leg {
                len_h,
                dh: w[1].llh[2] - w[0].llh[2],
                psi,
                gamma: 0.0,
                speed: 0.0,
            }
        })
        .collect()
}

/// Each leg's speed to begin with: the track's average over the legs around it (a short leg's
/// own time is a few jittery seconds; neighbours asked for different speeds would need
/// changes of speed the legs have no room for).
fn first_speeds(legs: &[Leg], want: &[f64], top: f64) -> Vec<f64> {
    (0..legs.len())
        .map(|k| {
            let (a, b) = window(want, k);
            let len: f64 = legs[a..=b].iter().map(|l| l.len_h).sum();
            let t: f64 = want[a..=b].iter().sum();
            (len / t.max(0.1)).clamp(SLOWEST_MPS, top)
        })
        .collect()
}

/// What the plan had to do, said in the track's notes.
fn finish_notes(spec: &DriveSpec, road: &mut Road, notes: &mut TrackNotes, offset: f64) {
    if !road.notes.slowed.is_empty() {
        notes.assumed.push(format!(
            "{} leg(s) driven slower than the track, too short for the change of speed between them within the limits",
            road.notes.slowed.len()
        ));
        road.notes.slowed.clear();
    }
    if notes.time_max_s > 10.0 {
        notes.assumed.push(format!(
            "the drive passes a corner {:.0} s from when the track did: where the track's points are far apart its corners are sharper than the road's, or the [drive] limits (acceleration {} m/s^2, braking {}, jerk {} m/s^3, lateral {} m/s^2, turn rate {} deg/s) are gentler than the track was driven",
            notes.time_max_s,
            spec.accel_mps2,
            spec.brake_mps2.unwrap_or(spec.accel_mps2),
            spec.jerk_mps3.unwrap_or(1.0),
            spec.lateral_accel_mps2,
            spec.turn_rate_dps
        ));
    }
    if offset > 0.0 {
        notes.assumed.push(format!(
            "standing {offset:.0} s at the start before the track's first point (start_wait_s)"
        ));
    }
}

/// The scenario's `[drive]` with the fitted corners as its waypoints (east and north of the
/// start, the straight line through the earth: only for the spec's checks and names; the legs
/// are laid between the corners on the ellipsoid), heights, stops and the start's wait.
fn track_spec(spec: &DriveSpec, v: &[Vertex]) -> DriveSpec {
    let s = v[0].llh;
    let n = v.len() - 1;
    let en: Vec<[f64; 3]> = v
        .iter()
        .map(|x| earth::enu_offset((s[0], s[1], s[2]), (x.llh[0], x.llh[1], x.llh[2])))
        .collect();
    let stops = (1..=n)
        .filter(|&k| v[k].t_out > v[k].t_in)
        .map(|k| [k as f64, v[k].t_out - v[k].t_in])
        .collect();
    DriveSpec {
        lat_deg: s[0].to_degrees(),
        lon_deg: s[1].to_degrees(),
        height_m: s[2],
        waypoints: en.iter().skip(1).map(|e| [e[0], e[1]]).collect(),
        heights_m: v.iter().skip(1).map(|x| x.llh[2]).collect(),
        leg_speeds_mps: vec![10.0; n],
        speed_mps: 10.0,
        stops,
        laps: 1,
        start_wait_s: spec.start_wait_s + (v[0].t_out - v[0].t_in),
        track: None,
        ..spec.clone()
    }
}

/// The plan's time at each corner against the track's.
fn timing(v: &[Vertex], times: &[f64], offset: f64, notes: &mut TrackNotes) {
    let d: Vec<f64> = v
        .iter()
        .zip(times)
        .skip(1)
        .map(|(x, &t)| t - (x.t_in + offset))
        .collect();
    notes.time_rms_s = (d.iter().map(|x| x * x).sum::<f64>() / d.len().max(1) as f64).sqrt();
    notes.time_max_s = d.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
}

/// The road's horizontal distance from each point the fit used.
fn distances(road: &Road, used: &[super::TrackPoint], _offset: f64, notes: &mut TrackNotes) {
    const STEP_M: f64 = 2.0;
    let n = (road.length() / STEP_M).ceil() as usize + 1;
    let samples: Vec<Vector3<f64>> = (0..n)
        .map(|k| {
            let [lat, lon, _] = road
                .placed
                .llh(&road.path, (k as f64 * STEP_M).min(road.length()));
            Vector3::from(earth::ecef(lat, lon, 0.0))
        })
        .collect();
    let seg = |p: &Vector3<f64>, j: usize| {
        let (a, b) = (samples[j], samples[(j + 1).min(n - 1)]);
        let ab = b - a;
        let l2 = ab.norm_squared();
        let u = if l2 > 0.0 {
            ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (p - a - ab * u).norm()
    };
    let (mut k, mut sum, mut worst, mut at) = (0usize, 0.0, 0.0, String::new());
    let mut last_t = 0.0;
    for p in used {
        let x = Vector3::from(earth::ecef(
            p.lat_deg.to_radians(),
            p.lon_deg.to_radians(),
            0.0,
        ));
        let ahead = ((1000.0 + 70.0 * (p.t - last_t)) / STEP_M) as usize;
        last_t = p.t;
        let (lo, hi) = (k.saturating_sub(250), (k + ahead).min(n - 1));
        let j = (lo..=hi)
            .min_by(|&a, &b| (x - samples[a]).norm().total_cmp(&(x - samples[b]).norm()))
            .unwrap_or(k);
        k = j;
        let d = seg(&x, j).min(seg(&x, j.saturating_sub(1)));
        sum += d * d;
        if d > worst {
            worst = d;
            at = p.at();
        }
    }
    notes.distance_rms_m = (sum / used.len().max(1) as f64).sqrt();
    notes.distance_max_m = worst;
    notes.distance_max_at = at;
}
