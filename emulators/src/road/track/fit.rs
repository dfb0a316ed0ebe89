//! From a track's points to the corners, heights, times and stops of a road a vehicle can
//! drive, each step said in [`TrackNotes`]:
//!
//! 1. **Order**: times must not go back; a point repeating the time of the one before is
//!    dropped.
//! 2. **Glitches**: a point off the path its two neighbours make by more than a vehicle can
//!    swerve between them (the jitter allowance plus half of 8 m/s^2 over the two intervals) is
//!    dropped, the worst first; then a step between two kept points faster than the top speed
//!    (with the jitter allowance) is a jump no vehicle makes, and refused.
//! 3. **Stops**: points that stay within 8 m (or three jitters) of their mean for 3 s or more,
//!    drifting from the first no faster than 0.5 m/s, are one stop, at their median, for as long
//!    as they stayed.
//! 4. **Corners**: the path between stops is simplified (Douglas-Peucker) to a tolerance of
//!    three jitters, the jitter estimated from the points' scatter about the simplified path
//!    where the scenario does not give it; each corner is then moved to where the straight
//!    lines fitted (total least squares) through the points of its two legs meet, so a corner
//!    is where the road turns, not where one noisy point happened to fall. A turn back on the
//!    road (a U-turn) is driven as two quarter turns.
//! 5. **Heights**: each corner's height is a straight-line fit of the points' heights within
//!    100 m of road either side (weighted, tricube) of it (a receiver's heights jitter by metres); points without
//!    a height are left out of it, and a track without any is driven level.
//! 6. **Times**: each corner is passed when the track's point there was, each stop kept as
//!    long as the track stood; the planner sets each leg's speed from them.
//!
//! Gaps of more than a minute between points are bridged by a straight leg, and said; a step
//! of more than 5 km is a hole in the track, refused.

use super::{Track, TrackError, TrackNotes, TrackPoint};
use crate::geodesy as earth;
use nalgebra::{Vector2, Vector3};

/// What a fit may assume; the scenario's `[drive]` sets them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// The fastest the vehicle drives, m/s: a step faster is a jump.
    pub max_speed_mps: f64,
    /// The track's jitter, m (None: estimated from the track).
    pub jitter_m: Option<f64>,
    /// The height driven at where the track has none, m.
    pub level_height_m: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            max_speed_mps: 70.0,
            jitter_m: None,
            level_height_m: 0.0,
        }
    }
}

/// A corner (or the start, the end, a stop) of the fitted road.
#[derive(Debug, Clone, PartialEq)]
pub struct Vertex {
    /// Latitude, longitude (rad) and height (m).
    pub llh: [f64; 3],
    /// When the track reached it and left it, s from the track's first point.
    pub t_in: f64,
    /// See [`Vertex::t_in`].
    pub t_out: f64,
    /// The track's point it was fitted at, for messages.
    pub at: String,
}

/// A fitted track.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The road's corners, the first the start and the last the end.
    pub vertices: Vec<Vertex>,
    /// The points the fit kept (times from the track's first point).
    pub used: Vec<TrackPoint>,
    /// What it did.
    pub notes: TrackNotes,
}

/// A glitch's allowance for jitter, m, and the sharpest swerve a vehicle makes, m/s^2.
const GLITCH_SLACK_M: f64 = 15.0;
const SWERVE_MPS2: f64 = 8.0;
/// A stop: within this many jitters (at least [`STOP_RADIUS_M`]) of where it stands, for at
/// least this long.
const STOP_JITTERS: f64 = 3.0;
const STOP_RADIUS_M: f64 = 8.0;
/// A stop's points drift from its first no faster than this, m/s.
const STOP_CREEP_MPS: f64 = 0.5;
const STOP_MIN_S: f64 = 3.0;
/// A gap said, s; the longest step bridged by a straight leg, m.
const GAP_S: f64 = 60.0;
const BRIDGE_M: f64 = 5_000.0;
/// Heights are fitted over this much road either side of a corner, m.
const HEIGHT_WINDOW_M: f64 = 100.0;
/// A point's height this far from the median of its neighbours' is a glitch, m.
const HEIGHT_GLITCH_M: f64 = 50.0;
/// The fitted heights are simplified to at least this, m.
const GRADE_TOLERANCE_M: f64 = 0.5;
/// A turn back by more than this is driven as two quarter turns this far apart, rad and m.
const U_TURN_RAD: f64 = 2.6;
/// A turn back by more than this over legs shorter than two tolerances is a zigzag, rad.
const ZIGZAG_RAD: f64 = 2.0;
const U_TURN_WIDTH_M: f64 = 10.0;

fn rad(p: &TrackPoint) -> (f64, f64, f64) {
    (p.lat_deg.to_radians(), p.lon_deg.to_radians(), 0.0)
}

fn ecef(p: &TrackPoint) -> Vector3<f64> {
    let (lat, lon, h) = rad(p);
    Vector3::from(earth::ecef(lat, lon, h))
}

/// Horizontal distance between two points (on the ellipsoid's surface), m.
fn dist(a: &TrackPoint, b: &TrackPoint) -> f64 {
    (ecef(a) - ecef(b)).norm()
}

/// Fit `track` into a road's corners.
pub fn fit(track: &Track, opt: &FitOptions) -> Result<Fitted, TrackError> {
    let mut notes = TrackNotes {
        points_read: track.points.len(),
        ..TrackNotes::default()
    };
    notes.dropped.extend(track.skipped.iter().cloned());
    let pts = order(track, &mut notes)?;
    let pts = despike(pts, opt, &mut notes);
    jumps(track, &pts, opt)?;
    if pts.len() < 2 || pts.iter().all(|p| dist(p, &pts[0]) < 10.0) {
        return Err(TrackError::new(
            &track.file,
            "the whole file",
            format!(
                "{} usable point(s) within 10 m of each other: too few to drive (a track needs at least two points more than 10 m apart)",
                pts.len()
            ),
        ));
    }
    if let Some(p) = pts.iter().find(|p| p.lat_deg.abs() > 89.0) {
        return Err(TrackError::new(
            &track.file,
            p.at(),
            format!(
                "latitude {}: a road is driven within 89 deg of the equator",
                p.lat_deg
            ),
        ));
    }
    for w in pts.windows(2) {
        let dt = w[1].t - w[0].t;
        let d = dist(&w[0], &w[1]);
        if d > BRIDGE_M {
            return Err(TrackError::new(
                &track.file,
                w[1].at(),
                format!(
                    "{:.1} km from {} with nothing between ({dt:.0} s): a hole in the track no straight leg stands in for; cut the track there",
                    d / 1e3,
                    w[0].at()
                ),
            ));
        }
        if dt > GAP_S {
            notes.assumed.push(format!(
                "a gap of {dt:.0} s between {} and {}: bridged by a straight leg",
                w[0].at(),
                w[1].at()
            ));
        }
    }
    let jitter = match opt.jitter_m {
        Some(j) => j,
        None => estimate_jitter(&pts).unwrap_or_else(|| {
            let guess = simplify_all(&pts, &stops(&pts, 5.0), 5.0);
            scatter(&pts, &guess.1)
        }),
    }
    .clamp(0.3, 30.0);
    notes.jitter_m = jitter;
    let runs = stops(&pts, (STOP_JITTERS * jitter).max(STOP_RADIUS_M));
    let (stops_at, corners) = simplify_all(&pts, &runs, simplify_tolerance(jitter));
    let mut vertices = place(&pts, &runs, &stops_at, &corners);
    zigzags(&mut vertices, simplify_tolerance(jitter));
    u_turns(&mut vertices);
    heights(&pts, &mut vertices, opt, &mut notes);
    notes.points_used = pts.len();
    notes.stops = runs
        .iter()
        .filter(|r| r.stop)
        .map(|r| (pts[r.first].at(), pts[r.last].t - pts[r.first].t))
        .collect();
    notes.corners = vertices.len().saturating_sub(2);
    Ok(Fitted {
        vertices,
        used: pts,
        notes,
    })
}

/// The points in time order from the first's time: time going back refused, a repeated time
/// dropped.
fn order(track: &Track, notes: &mut TrackNotes) -> Result<Vec<TrackPoint>, TrackError> {
    let mut out: Vec<TrackPoint> = Vec::with_capacity(track.points.len());
    for p in &track.points {
        if let Some(last) = out.last() {
            let dt = p.t - last.t;
            if dt < 0.0 {
                return Err(TrackError::new(
                    &track.file,
                    p.at(),
                    format!(
                        "time goes back {:.3} s from {} (a track's points are in time order)",
                        -dt,
                        last.at()
                    ),
                ));
            }
            if dt == 0.0 {
                notes.dropped_points.push(p.index);
                notes.dropped.push(format!(
                    "{}: the same time as {} (a repeated fix)",
                    p.at(),
                    last.at()
                ));
                continue;
            }
        }
        out.push(*p);
    }
    let t0 = out.first().map_or(0.0, |p| p.t);
    for p in &mut out {
        p.t -= t0;
    }
    Ok(out)
}

/// How far a point is off the path of its neighbours (interpolated in time), and how far a
/// vehicle could be, m.
fn off_path(a: &TrackPoint, p: &TrackPoint, b: &TrackPoint) -> (f64, f64) {
    let (ta, tb) = (p.t - a.t, b.t - p.t);
    let u = ta / (ta + tb);
    let expect = ecef(a) * (1.0 - u) + ecef(b) * u;
    (
        (ecef(p) - expect).norm(),
        GLITCH_SLACK_M + 0.5 * SWERVE_MPS2 * ta * tb,
    )
}

/// Drop glitches, the worst first, until none is left: a point off the path of its two
/// neighbours, where the neighbours themselves are a step a vehicle makes (else the track
/// jumps there, which [`jumps`] refuses).
fn despike(mut pts: Vec<TrackPoint>, opt: &FitOptions, notes: &mut TrackNotes) -> Vec<TrackPoint> {
    loop {
        let worst = (1..pts.len().saturating_sub(1))
            .filter(|&i| {
                let (a, b) = (&pts[i - 1], &pts[i + 1]);
                dist(a, b) <= opt.max_speed_mps * (b.t - a.t) + 2.0 * GLITCH_SLACK_M
            })
            .map(|i| {
                let (d, allowed) = off_path(&pts[i - 1], &pts[i], &pts[i + 1]);
                (i, d, d / allowed)
            })
            .filter(|x| x.2 > 1.0)
            .max_by(|a, b| a.2.total_cmp(&b.2));
        let Some((i, d, _)) = worst else {
            return pts;
        };
        notes.dropped_points.push(pts[i].index);
        notes.dropped.push(format!(
            "{}: {d:.0} m off the path of the points either side (a glitch no vehicle drives)",
            pts[i].at()
        ));
        pts.remove(i);
    }
}

/// A step no vehicle makes is refused.
fn jumps(track: &Track, pts: &[TrackPoint], opt: &FitOptions) -> Result<(), TrackError> {
    for w in pts.windows(2) {
        let (d, dt) = (dist(&w[0], &w[1]), w[1].t - w[0].t);
        if d > opt.max_speed_mps * dt + 2.0 * GLITCH_SLACK_M {
            return Err(TrackError::new(
                &track.file,
                w[1].at(),
                format!(
                    "{d:.0} m from {} in {dt:.1} s ({:.0} m/s): a jump no vehicle makes (the fastest driven is {} m/s)",
                    w[0].at(),
                    d / dt,
                    opt.max_speed_mps
                ),
            ));
        }
    }
    Ok(())
}

/// A run of points: a stop (standing, from `first` to `last`) or one moving point.
#[derive(Debug, Clone, Copy)]
struct Run {
    first: usize,
    last: usize,
    stop: bool,
}

/// The points as runs: stops where they stay within `radius` of where they began for
/// [`STOP_MIN_S`] or more.
fn stops(pts: &[TrackPoint], radius: f64) -> Vec<Run> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < pts.len() {
        // a stop goes on while the next point is within the radius of its points' mean (a
        // standing receiver's error wanders about where it stands)
        let mut j = i;
        let mut sum = ecef(&pts[i]);
        while j + 1 < pts.len()
            && (ecef(&pts[j + 1]) - sum / (j + 1 - i) as f64).norm() <= radius
            && standing(&pts[i], &pts[j + 1])
        {
            j += 1;
            sum += ecef(&pts[j]);
        }
        if j > i && pts[j].t - pts[i].t >= STOP_MIN_S {
            out.push(Run {
                first: i,
                last: j,
                stop: true,
            });
            i = j + 1;
        } else {
            out.push(Run {
                first: i,
                last: i,
                stop: false,
            });
            i += 1;
        }
    }
    merge_stops(pts, out, radius)
}

/// From `a` to `b` the vehicle may have stood: it moved no more than a few metres, or than a
/// creep of [`STOP_CREEP_MPS`] (a standing receiver's error wanders; a vehicle crawling along
/// moves on).
fn standing(a: &TrackPoint, b: &TrackPoint) -> bool {
    dist(a, b) <= (STOP_CREEP_MPS * (b.t - a.t)).max(4.0)
}

/// A stop that goes on after a few points that strayed (the vehicle crept forward, the jitter
/// wandered out of the radius and back) is one stop.
fn merge_stops(pts: &[TrackPoint], runs: Vec<Run>, radius: f64) -> Vec<Run> {
    let mut out: Vec<Run> = Vec::with_capacity(runs.len());
    for r in runs {
        if r.stop
            && let Some(k) = out.iter().rposition(|x| x.stop)
            && out.len() - k <= 4
            && dist(&pts[out[k].last], &pts[r.first]) <= radius
            && standing(&pts[out[k].first], &pts[r.last])
        {
            let first = out[k].first;
            out.truncate(k);
            out.push(Run {
                first,
                last: r.last,
                stop: true,
            });
            continue;
        }
        out.push(r);
    }
    out
}

/// Douglas-Peucker over `idx` (indices of `pts`), keeping the ends: the kept indices.
fn douglas_peucker(pts: &[TrackPoint], idx: &[usize], eps: f64, keep: &mut Vec<usize>) {
    let n = idx.len();
    if n < 3 {
        return;
    }
    let (a, b) = (ecef(&pts[idx[0]]), ecef(&pts[idx[n - 1]]));
    let ab = b - a;
    let len2 = ab.norm_squared();
    let (mut worst, mut at) = (0.0, 0);
    for (k, &i) in idx.iter().enumerate().take(n - 1).skip(1) {
        let p = ecef(&pts[i]) - a;
        let u = if len2 > 0.0 {
            (p.dot(&ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = (p - ab * u).norm();
        if d > worst {
            (worst, at) = (d, k);
        }
    }
    if worst > eps {
        douglas_peucker(pts, &idx[..=at], eps, keep);
        keep.push(idx[at]);
        douglas_peucker(pts, &idx[at..], eps, keep);
    }
}

/// The corners: each stop (its run's number), and the moving points kept between them
/// (indices of `pts`), in order. Returns (stop runs' indices into `runs`, kept corners as
/// (point index, Some(run) for a stop)).
fn simplify_all(pts: &[TrackPoint], runs: &[Run], eps: f64) -> (Vec<usize>, Vec<Corner>) {
    let stops_at: Vec<usize> = (0..runs.len()).filter(|&r| runs[r].stop).collect();
    let mut corners = Vec::new();
    // the ends of each stretch: the start, each stop, the end
    let mut ends: Vec<(usize, Option<usize>)> = Vec::new();
    if !runs[0].stop {
        ends.push((0, None));
    }
    for &r in &stops_at {
        ends.push((runs[r].first, Some(r)));
    }
    if !runs[runs.len() - 1].stop {
        ends.push((pts.len() - 1, None));
    }
    for (k, &(i, stop)) in ends.iter().enumerate() {
        corners.push(Corner { point: i, stop });
        if let Some(&(j, _)) = ends.get(k + 1) {
            // from this end's last point (a stop's) to the next's first
            let from = stop.map_or(i, |r| runs[r].last);
            let idx: Vec<usize> = (from..=j).collect();
            let mut keep = Vec::new();
            douglas_peucker(pts, &idx, eps, &mut keep);
            corners.extend(keep.into_iter().map(|p| Corner {
                point: p,
                stop: None,
            }));
        }
    }
    (stops_at, corners)
}

/// A corner of the simplified path: a point of the track, or a stop.
#[derive(Debug, Clone, Copy)]
struct Corner {
    point: usize,
    stop: Option<usize>,
}

/// The tolerance the path is simplified to, m, for a track that jitters by `jitter` m.
pub fn simplify_tolerance(jitter: f64) -> f64 {
    (3.0 * jitter).max(3.0)
}

/// The jitter, m: the median, over runs of five points a few seconds apart, of the scatter
/// about a quadratic in time through them (a vehicle's path over a few seconds is one; a
/// receiver's noise is not). None where the track has too few such runs (points far apart).
fn estimate_jitter(pts: &[TrackPoint]) -> Option<f64> {
    let mut var = Vec::new();
    for w in pts.windows(5) {
        if w[4].t - w[0].t > 10.0 {
            continue;
        }
        let mid = rad(&w[2]);
        let xy = local(mid, w);
        let ts: Vec<f64> = w.iter().map(|p| p.t - w[2].t).collect();
        let mut sum = 0.0;
        for axis in 0..2 {
            let ys: Vec<f64> = xy.iter().map(|q| q[axis]).collect();
            sum += quadratic_residual(&ts, &ys)?;
        }
        // five points less three coefficients, two axes
        var.push(sum / 4.0);
    }
    if var.len() < 10 {
        return None;
    }
    var.sort_by(f64::total_cmp);
    // the median of a chi-square with two degrees of freedom is 0.69 of its mean
    Some((var[var.len() / 2] / 0.69).sqrt())
}

/// The sum of squared residuals of a least-squares quadratic through `(t, y)`.
fn quadratic_residual(t: &[f64], y: &[f64]) -> Option<f64> {
    let a = nalgebra::DMatrix::from_fn(t.len(), 3, |i, j| t[i].powi(j as i32));
    let b = nalgebra::DVector::from_column_slice(y);
    let x = a.clone().svd(true, true).solve(&b, 1e-12).ok()?;
    Some((a * x - b).norm_squared())
}

/// The RMS distance of the moving points from the simplified path, m.
fn scatter(pts: &[TrackPoint], corners: &[Corner]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for w in corners.windows(2) {
        let (a, b) = (ecef(&pts[w[0].point]), ecef(&pts[w[1].point]));
        let ab = b - a;
        let len2 = ab.norm_squared();
        if len2 == 0.0 {
            continue;
        }
        for p in &pts[w[0].point + 1..w[1].point] {
            let q = ecef(p) - a;
            let u = (q.dot(&ab) / len2).clamp(0.0, 1.0);
            sum += (q - ab * u).norm_squared();
            n += 1;
        }
    }
    // the simplified path follows the jitter partly: the scatter about it understates it
    if n < 5 {
        3.0
    } else {
        (sum / n as f64).sqrt() * 1.5
    }
}

/// The points of a leg in east-north metres about `at`.
fn local(at: (f64, f64, f64), pts: &[TrackPoint]) -> Vec<Vector2<f64>> {
    pts.iter()
        .map(|p| {
            let e = earth::enu_offset(at, rad(p));
            Vector2::new(e[0], e[1])
        })
        .collect()
}

/// The straight line through points, total least squares: a point on it and its direction.
fn line(p: &[Vector2<f64>]) -> Option<(Vector2<f64>, Vector2<f64>)> {
    if p.len() < 3 {
        return None;
    }
    let c = p.iter().sum::<Vector2<f64>>() / p.len() as f64;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for q in p {
        let d = q - c;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
    }
    let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    Some((c, Vector2::new(theta.cos(), theta.sin())))
}

/// The corners on the ellipsoid: a stop at its points' median, a moving corner where the lines
/// of its two legs meet (when they meet near it).
fn place(pts: &[TrackPoint], runs: &[Run], _stops: &[usize], corners: &[Corner]) -> Vec<Vertex> {
    let mut out = Vec::with_capacity(corners.len());
    for (k, c) in corners.iter().enumerate() {
        let p = &pts[c.point];
        let at = rad(p);
        let (en, t_in, t_out) = match c.stop {
            Some(r) => {
                let run = &runs[r];
                let l = local(at, &pts[run.first..=run.last]);
                // where it stands: the median (the points of the last metres of its approach
                // and of its pulling away are few)
                let median = |axis: usize| {
                    let mut x: Vec<f64> = l.iter().map(|q| q[axis]).collect();
                    x.sort_by(f64::total_cmp);
                    x[x.len() / 2]
                };
                (
                    Vector2::new(median(0), median(1)),
                    pts[run.first].t,
                    pts[run.last].t,
                )
            }
            None => {
                let moved = match (k.checked_sub(1).map(|j| corners[j]), corners.get(k + 1)) {
                    (Some(a), Some(b)) => meet(pts, at, &a, c, b),
                    _ => None,
                };
                (moved.unwrap_or_else(Vector2::zeros), p.t, p.t)
            }
        };
        let (rm, rn) = earth::radii(at.0);
        out.push(Vertex {
            llh: [at.0 + en.y / rm, at.1 + en.x / (rn * at.0.cos()), 0.0],
            t_in,
            t_out,
            at: p.at(),
        });
    }
    out
}

/// Where the lines through the legs either side of corner `c` meet, in metres about it (None:
/// they are nearly parallel, too short to fit, or meet far from it).
fn meet(
    pts: &[TrackPoint],
    at: (f64, f64, f64),
    a: &Corner,
    c: &Corner,
    b: &Corner,
) -> Option<Vector2<f64>> {
    let (l1, d1) = line(&local(at, &pts[a.point..=c.point]))?;
    let (l2, d2) = line(&local(at, &pts[c.point..=b.point]))?;
    let cross = d1.x * d2.y - d1.y * d2.x;
    if cross.abs() < 0.1 {
        return None;
    }
    let w = l2 - l1;
    let s = (w.x * d2.y - w.y * d2.x) / cross;
    let x = l1 + d1 * s;
    (x.norm() < 20.0).then_some(x)
}

/// At corner `k`: the way in and the way out, east-north metres about it (to the corner from
/// the one before, to the next from it), and the turn between them, rad (positive: left).
fn turn_at(v: &[Vertex], k: usize) -> (Vector2<f64>, Vector2<f64>, f64) {
    let at = (v[k].llh[0], v[k].llh[1], 0.0);
    let off = |x: &Vertex| {
        let e = earth::enu_offset(at, (x.llh[0], x.llh[1], 0.0));
        Vector2::new(e[0], e[1])
    };
    let (a, b) = (-off(&v[k - 1]), off(&v[k + 1]));
    (a, b, (a.x * b.y - a.y * b.x).atan2(a.dot(&b)))
}

/// A corner where the path turns back on itself over less than a few tolerances is the
/// receiver's error zigzagging while the vehicle creeps, not the road: dropped.
fn zigzags(v: &mut Vec<Vertex>, tol: f64) {
    let mut k = 1;
    while k + 1 < v.len() {
        let (a, b, change) = turn_at(v, k);
        let stop = v[k].t_out > v[k].t_in;
        if !stop && change.abs() > ZIGZAG_RAD && a.norm().min(b.norm()) < 2.0 * tol {
            v.remove(k);
            k = k.saturating_sub(1).max(1);
        } else {
            k += 1;
        }
    }
}

/// A corner where the road turns back on itself is driven as two quarter turns, the second
/// [`U_TURN_WIDTH_M`] to the side of the first.
fn u_turns(v: &mut Vec<Vertex>) {
    let mut k = 1;
    while k + 1 < v.len() {
        let (a, b, change) = turn_at(v, k);
        if change.abs() > U_TURN_RAD && a.norm() > 1.0 && b.norm() > 1.0 {
            // the side the road turns to: right of the way in for a clockwise turn
            let dir = a / a.norm();
            let side = if change < 0.0 {
                Vector2::new(dir.y, -dir.x)
            } else {
                Vector2::new(-dir.y, dir.x)
            };
            let q = side * U_TURN_WIDTH_M;
            let lat = v[k].llh[0];
            let (rm, rn) = earth::radii(lat);
            let mut second = v[k].clone();
            second.llh[0] += q.y / rm;
            second.llh[1] += q.x / (rn * lat.cos());
            v.insert(k + 1, second);
            k += 1;
        }
        k += 1;
    }
}

/// Each corner's height: a straight-line fit of the points' heights within
/// [`HEIGHT_WINDOW_M`] of road either side (widened until it has two points).
fn heights(pts: &[TrackPoint], v: &mut [Vertex], opt: &FitOptions, notes: &mut TrackNotes) {
    let missing = pts.iter().filter(|p| p.h_m.is_none()).count();
    if missing == pts.len() {
        notes.assumed.push(format!(
            "no heights in the track: driven level at {} m",
            opt.level_height_m
        ));
        for x in v.iter_mut() {
            x.llh[2] = opt.level_height_m;
        }
        return;
    }
    let hs_all = height_glitches(pts, notes);
    if missing > 0 {
        notes.assumed.push(format!(
            "{missing} point(s) without a height: the road's height there is fitted from the others"
        ));
    }
    // distance along the fitted road of each corner, and of each point: its corner's (the
    // last reached by its time) and how far along the leg to the next it lies (jittery points
    // would lengthen a distance summed from point to point)
    let corner = |x: &Vertex| Vector3::from(earth::ecef(x.llh[0], x.llh[1], 0.0));
    let mut at_corner = vec![0.0; v.len()];
    for k in 1..v.len() {
        at_corner[k] = at_corner[k - 1] + (corner(&v[k]) - corner(&v[k - 1])).norm();
    }
    let hs: Vec<(f64, f64)> = pts
        .iter()
        .zip(&hs_all)
        .filter_map(|(p, h)| {
            let h = (*h)?;
            let k = v.partition_point(|x| x.t_in <= p.t).saturating_sub(1);
            let s = match v.get(k + 1) {
                Some(next) if p.t > v[k].t_out => {
                    let (a, b) = (corner(&v[k]), corner(next));
                    let len = (b - a).norm();
                    let u = if len > 0.0 {
                        ((ecef(p) - a).dot(&(b - a)) / len).clamp(0.0, len)
                    } else {
                        0.0
                    };
                    at_corner[k] + u
                }
                _ => at_corner[k],
            };
            Some((s, h))
        })
        .collect();
    for (x, &s) in v.iter_mut().zip(&at_corner) {
        let mut w = HEIGHT_WINDOW_M;
        let sel = loop {
            // tricube weights: the fit changes smoothly from one corner to the next, so that
            // corners close together are on one grade
            let sel: Vec<(f64, f64, f64)> = hs
                .iter()
                .filter(|(d, _)| (d - s).abs() < w)
                .map(|&(d, h)| (d, h, (1.0 - ((d - s).abs() / w).powi(3)).powi(3)))
                .collect();
            if sel.len() >= 3 || sel.len() == hs.len() {
                break sel;
            }
            w *= 2.0;
        };
        x.llh[2] = linear_at(&sel, s);
    }
    let h_jitter = height_jitter(pts);
    grade_breaks(v, &at_corner, (2.0 * h_jitter).max(GRADE_TOLERANCE_M));
}

/// The heights simplified to the corners where the grade changes by more than `tol` shows
/// (twice the heights' jitter, at least [`GRADE_TOLERANCE_M`]; Douglas-Peucker over distance
/// and height); the
/// corners between two such are put on the grade between them, so that a crest or a dip is
/// one vertical curve, not one squeezed between each pair of close corners.
fn grade_breaks(v: &mut [Vertex], s: &[f64], tol: f64) {
    fn dp(v: &[Vertex], s: &[f64], a: usize, b: usize, tol: f64, keep: &mut Vec<usize>) {
        if b <= a + 1 {
            return;
        }
        let grade = (v[b].llh[2] - v[a].llh[2]) / (s[b] - s[a]).max(1e-9);
        let (mut worst, mut at) = (0.0, a);
        for k in a + 1..b {
            let d = (v[k].llh[2] - (v[a].llh[2] + grade * (s[k] - s[a]))).abs();
            if d > worst {
                (worst, at) = (d, k);
            }
        }
        if worst > tol {
            dp(v, s, a, at, tol, keep);
            keep.push(at);
            dp(v, s, at, b, tol, keep);
        }
    }
    let n = v.len();
    if n < 3 {
        return;
    }
    let mut keep = vec![0];
    dp(v, s, 0, n - 1, tol, &mut keep);
    keep.push(n - 1);
    for w in keep.windows(2) {
        let (a, b) = (w[0], w[1]);
        let grade = (v[b].llh[2] - v[a].llh[2]) / (s[b] - s[a]).max(1e-9);
        for k in a + 1..b {
            v[k].llh[2] = v[a].llh[2] + grade * (s[k] - s[a]);
        }
    }
}

/// The heights' own jitter, m, as the positions' (from runs of five points a few seconds
/// apart; 3 m where there are none).
fn height_jitter(pts: &[TrackPoint]) -> f64 {
    let mut var = Vec::new();
    for w in pts.windows(5) {
        let hs: Option<Vec<f64>> = w.iter().map(|p| p.h_m).collect();
        if let Some(hs) = hs.filter(|_| w[4].t - w[0].t <= 10.0) {
            let ts: Vec<f64> = w.iter().map(|p| p.t - w[2].t).collect();
            if let Some(r) = quadratic_residual(&ts, &hs) {
                var.push(r / 2.0);
            }
        }
    }
    var.sort_by(f64::total_cmp);
    var.get(var.len() / 2).map_or(3.0, |m| (m / 0.45).sqrt())
}

/// Each point's height, but for those far from the heights about them (a glitch of the height
/// alone: dropped and said).
fn height_glitches(pts: &[TrackPoint], notes: &mut TrackNotes) -> Vec<Option<f64>> {
    let mut hs_all: Vec<Option<f64>> = pts.iter().map(|p| p.h_m).collect();
    let mut glitched = Vec::new();
    for i in 0..pts.len() {
        let Some(h) = hs_all[i] else { continue };
        let mut near: Vec<f64> = (i.saturating_sub(5)..(i + 6).min(pts.len()))
            .filter(|&j| j != i)
            .filter_map(|j| pts[j].h_m)
            .collect();
        if near.len() < 4 {
            continue;
        }
        near.sort_by(f64::total_cmp);
        let median = near[near.len() / 2];
        if (h - median).abs() > HEIGHT_GLITCH_M {
            glitched.push(format!("{} ({:+.0} m)", pts[i].at(), h - median));
            hs_all[i] = None;
        }
    }
    if !glitched.is_empty() {
        notes.dropped.push(format!(
            "the heights of {} point(s), off the heights about them by more than {HEIGHT_GLITCH_M} m: {}",
            glitched.len(),
            glitched.join(", ")
        ));
    }
    hs_all
}

/// A weighted straight-line fit of `(x, y, weight)` evaluated at `x0` (the mean where all `x`
/// are one).
fn linear_at(p: &[(f64, f64, f64)], x0: f64) -> f64 {
    let n = p.iter().map(|q| q.2).sum::<f64>().max(1e-300);
    let (mx, my) = (
        p.iter().map(|q| q.2 * q.0).sum::<f64>() / n,
        p.iter().map(|q| q.2 * q.1).sum::<f64>() / n,
    );
    let sxx: f64 = p.iter().map(|q| q.2 * (q.0 - mx).powi(2)).sum();
    let sxy: f64 = p.iter().map(|q| q.2 * (q.0 - mx) * (q.1 - my)).sum();
    if sxx < 1e-9 {
        my
    } else {
        my + sxy / sxx * (x0 - mx)
    }
}
