//! From a `[drive]` table with a road's fields to the planned [`Road`]: the legs between the
//! waypoints at their heights, a turn at each inner waypoint sized for the faster of its two
//! legs within the lateral-acceleration and turn-rate limits, a vertical curve where the grade
//! changes sized within the vertical-acceleration limit, and the speed profile from stop to stop.

use super::Road;
use super::geo::Placed;
use super::path::{Crest, Path, Turn, tangent_length};
use super::rough;
use super::speed::{Limits, Profile, Stretch};
use crate::ParamError;
use crate::drive::DriveSpec;
use serde::Serialize;
use std::f64::consts::PI;

/// What the plan had to do and assume, for people: said by `hil` when it shows a route.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RoadNotes {
    /// Length of the road, m.
    pub length_m: f64,
    /// Duration of the drive, s.
    pub duration_s: f64,
    /// Height climbed and descended, m.
    pub climb_m: f64,
    /// See [`RoadNotes::climb_m`].
    pub descent_m: f64,
    /// Steepest grade, % (signed: negative downhill).
    pub steepest_grade_pct: f64,
    /// Legs driven slower than asked, because they are too short to reach their speed and
    /// change to the next's: (which, asked and driven, m/s).
    pub slowed: Vec<(String, f64, f64)>,
    /// The largest difference between a waypoint's height and the road's where it passes it
    /// (the middle of its turn), m. A waypoint's height is where the grade lines of its two legs
    /// meet, as a road designer's point of vertical intersection: the vertical curve between
    /// them passes above it over a dip and below it over a crest by its middle ordinate (about
    /// 0.09 of the change of grade times the curve's length); outside the curves the road is on
    /// the grade lines.
    pub height_miss_m: f64,
    /// Vertical curves kept shorter than the vertical-acceleration limit asks, because the legs
    /// beside them are short: (waypoint number, vertical acceleration at the leg's speed, m/s^2).
    pub sharp_crests: Vec<(usize, f64)>,
}

/// The route's points: the start, then each lap's waypoints, in metres east and north of the
/// start and height.
pub(in crate::road) fn points(spec: &DriveSpec) -> Result<Vec<[f64; 3]>, ParamError> {
    let n = spec.waypoints.len();
    if !spec.heights_m.is_empty() && spec.heights_m.len() != n {
        return Err(ParamError::new(
            "drive",
            format!(
                "heights_m has {} heights for {n} waypoints: give one per waypoint",
                spec.heights_m.len()
            ),
        ));
    }
    if !spec.leg_speeds_mps.is_empty() && spec.leg_speeds_mps.len() != n {
        return Err(ParamError::new(
            "drive",
            format!(
                "leg_speeds_mps has {} speeds for {n} waypoints: give one per leg (the leg to each waypoint)",
                spec.leg_speeds_mps.len()
            ),
        ));
    }
    let height = |i: usize| spec.heights_m.get(i).copied().unwrap_or(spec.height_m);
    if spec.laps > 1 {
        let last = spec.waypoints[n - 1];
        if last[0].hypot(last[1]) > 1.0 || (height(n - 1) - spec.height_m).abs() > 0.01 {
            return Err(ParamError::new(
                "drive",
                "with laps > 1 the last waypoint must be the start [0, 0], at the start's height",
            ));
        }
    }
    let mut pts = vec![[0.0, 0.0, spec.height_m]];
    for _ in 0..spec.laps {
        pts.extend((0..n).map(|i| [spec.waypoints[i][0], spec.waypoints[i][1], height(i)]));
    }
    Ok(pts)
}

/// A leg between two points: horizontal length (m), heading and pitch (rad), speed (m/s).
#[derive(Debug, Clone, Copy)]
pub(in crate::road) struct Leg {
    pub len_h: f64,
    pub dh: f64,
    pub psi: f64,
    pub gamma: f64,
    pub speed: f64,
}

pub(in crate::road) fn legs(spec: &DriveSpec, pts: &[[f64; 3]]) -> Result<Vec<Leg>, ParamError> {
    let n = spec.waypoints.len();
    let mut out = Vec::with_capacity(pts.len() - 1);
    for (i, w) in pts.windows(2).enumerate() {
        let (de, dn, dh) = (w[1][0] - w[0][0], w[1][1] - w[0][1], w[1][2] - w[0][2]);
        let len_h = de.hypot(dn);
        if len_h < 1.0 {
            return Err(ParamError::new(
                "drive",
                format!(
                    "waypoint {} is {len_h:.2} m from the point before it: a leg needs at least 1 m",
                    i % n + 1
                ),
            ));
        }
        let grade = dh / len_h;
        if grade.abs() > 0.35 {
            return Err(ParamError::new(
                "drive",
                format!(
                    "the leg to waypoint {} climbs {:.0} % ({dh:.1} m in {len_h:.1} m): no road is steeper than 35 %",
                    i % n + 1,
                    grade * 100.0
                ),
            ));
        }
        let speed = spec
            .leg_speeds_mps
            .get(i % n)
            .copied()
            .unwrap_or(spec.speed_mps);
        out.push(Leg {
            len_h,
            dh,
            psi: de.atan2(dn),
            gamma: grade.atan(),
            speed,
        });
    }
    Ok(out)
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

/// The turn at an inner point.
#[derive(Debug, Clone, Copy, Default)]
struct Corner {
    /// Heading change, rad.
    change: f64,
    /// Length, m (0: no turn).
    len: f64,
    /// Tangent length, m.
    tangent: f64,
    /// Speed through it, m/s.
    speed: f64,
}

/// The turn at each inner point: as sharp as `corner_radius_m` asks, driven at the speed its
/// sharpest point allows within the lateral-acceleration and turn-rate limits; without a
/// radius, as wide as the faster of its two legs needs to be driven at its speed.
/// With `fit` (a fitted track's corners, `Some(tolerance)`), each turn is made sharp enough
/// to pass within the tolerance of its corner, turns whose tangents do not fit in a leg
/// between them are made sharper, each in proportion, and each is driven as slowly as that
/// needs.
fn turns(spec: &DriveSpec, legs: &[Leg], fit: Option<f64>) -> Result<Vec<Corner>, ParamError> {
    let mut tn = turns_for_speed(spec, legs)?;
    if let Some(tol) = fit {
        for c in tn.iter_mut().filter(|c| c.len > 0.0) {
            let most = tol / super::path::unit_turn_miss(c.change);
            if c.len > most {
                c.tangent *= most / c.len;
                c.len = most;
            }
        }
        let (rate, a_lat) = (spec.turn_rate_dps.to_radians(), spec.lateral_accel_mps2);
        let tangent = |i: Option<usize>| i.and_then(|i| tn.get(i)).map_or(0.0, |c| c.tangent);
        // each leg's share: 1 where its turns fit in it
        let share: Vec<f64> = legs
            .iter()
            .enumerate()
            .map(|(j, l)| {
                let need = tangent(j.checked_sub(1)) + tangent(Some(j));
                if need > 0.0 {
                    (l.len_h / need).min(1.0)
                } else {
                    1.0
                }
            })
            .collect();
        for (i, c) in tn.iter_mut().enumerate().filter(|(_, c)| c.len > 0.0) {
            let fit = share[i].min(share[i + 1]) * (1.0 - 1e-9);
            if fit < 1.0 {
                c.len *= fit;
                c.tangent *= fit;
            }
            let kappa = 2.0 * c.change.abs() / c.len;
            c.speed = c.speed.min((a_lat / kappa).sqrt()).min(rate / kappa);
        }
    }
    Ok(tn)
}

/// Each inner point's turn for the speeds of its legs.
fn turns_for_speed(spec: &DriveSpec, legs: &[Leg]) -> Result<Vec<Corner>, ParamError> {
    let n = spec.waypoints.len();
    let rate = spec.turn_rate_dps.to_radians();
    let a_lat = spec.lateral_accel_mps2;
    if let Some(r) = spec.corner_radius_m
        && !(r.is_finite() && r >= 2.0)
    {
        return Err(ParamError::new(
            "drive",
            format!("corner_radius_m {r}: a road's corner is at least 2 m in radius"),
        ));
    }
    legs.windows(2)
        .enumerate()
        .map(|(i, w)| {
            let change = wrap(w[1].psi - w[0].psi);
            if change.abs() > 170f64.to_radians() {
                return Err(ParamError::new(
                    "drive",
                    format!(
                        "the route turns back on itself by {:.0} deg at waypoint {}: U-turns are not driven; add a waypoint to turn around",
                        change.abs().to_degrees(),
                        i % n + 1
                    ),
                ));
            }
            let v = w[0].speed.max(w[1].speed);
            if change.abs() < 1e-9 {
                return Ok(Corner {
                    speed: v,
                    ..Corner::default()
                });
            }
            let (kappa, speed) = match spec.corner_radius_m {
                Some(r) => {
                    // no wider than the legs' own speed needs
                    let k = (1.0 / r).max((a_lat / (v * v)).min(rate / v));
                    (k, v.min((a_lat / k).sqrt()).min(rate / k))
                }
                None => ((a_lat / (v * v)).min(rate / v), v),
            };
            let len = 2.0 * change.abs() / kappa;
            Ok(Corner {
                change,
                len,
                tangent: tangent_length(change, len),
                speed,
            })
        })
        .collect()
}

/// The road's shape: straight legs and turns laid along `s`, and where each point is on it.
struct Laid {
    path: Path,
    /// Each point's place along the road (the middle of its turn), m.
    at: Vec<f64>,
    /// Each inner point's turn: where it starts and ends, m.
    turn_span: Vec<(f64, f64)>,
}

fn lay(spec: &DriveSpec, legs: &[Leg], tn: &[Corner]) -> Result<Laid, ParamError> {
    let n = spec.waypoints.len();
    let bank = spec.bank_deg.unwrap_or(0.0).to_radians();
    let mut turns_out = Vec::new();
    let mut at = vec![0.0];
    let mut turn_span = Vec::new();
    let mut s = 0.0;
    for (i, leg) in legs.iter().enumerate() {
        let before = if i > 0 { tn[i - 1].tangent } else { 0.0 };
        let after = tn.get(i).map_or(0.0, |t| t.tangent);
        let straight = leg.len_h / leg.gamma.cos() - before - after;
        if straight < -1e-9 {
            return Err(ParamError::new(
                "drive",
                format!(
                    "the turns at the ends of the leg to waypoint {} need {:.1} m of it, which has {:.1} m: lower its speed or the next's, or move the waypoints apart",
                    i % n + 1,
                    before + after,
                    leg.len_h
                ),
            ));
        }
        s += straight.max(0.0);
        if let Some(&Corner { change, len, .. }) = tn.get(i) {
            if len > 0.0 {
                turns_out.push(Turn {
                    s0: s,
                    len,
                    psi0: leg.psi,
                    kappa_max: 2.0 * change / len,
                    bank_max: bank * change.signum(),
                });
            }
            turn_span.push((s, s + len));
            at.push(s + 0.5 * len);
            s += len;
        } else {
            at.push(s);
        }
    }
    Ok(Laid {
        path: Path {
            psi_start: legs[0].psi,
            gamma_start: legs[0].gamma,
            turns: turns_out,
            crests: Vec::new(),
            length: s,
        },
        at,
        turn_span,
    })
}

/// The shortest vertical curve where its neighbours leave room, m: at 30 m/s, 100 ms (200
/// IMU samples at 2 kHz).
const MIN_CURVE_M: f64 = 3.0;

/// A change of grade whose point is nearer than this to the end of the vertical curve before
/// it (or inside it) is made by that curve, m.
const MIN_CURVE_GAP_M: f64 = 0.5;

/// Vertical curves where the grade changes, centred on the points; kept within their
/// neighbours (and said where that makes them sharper than the limit). The curves never
/// overlap, so the road's pitch is continuous, and none is squeezed into millimetres (a
/// feature the IMU's samples cannot resolve): a change of grade whose point falls inside the
/// curve before it, or within [`MIN_CURVE_GAP_M`] after it (a change too small, under 0.02 %,
/// to limit its neighbours' curves can), is made by that curve, which then ends on the grade
/// after it; a curve is [`MIN_CURVE_M`] long at least where there is room.
fn crests(spec: &DriveSpec, legs: &[Leg], laid: &mut Laid, notes: &mut RoadNotes) {
    let n = spec.waypoints.len();
    let a_v = spec.vertical_accel_mps2.unwrap_or(0.5);
    let mut last_end = 0.0;
    for i in 0..legs.len().saturating_sub(1) {
        let dg = legs[i + 1].gamma - legs[i].gamma;
        if dg.abs() < 1e-12 {
            continue;
        }
        let v = legs[i].speed.max(legs[i + 1].speed);
        let mid = laid.at[i + 1];
        if mid - last_end < MIN_CURVE_GAP_M
            && let Some(c) = laid.path.crests.last_mut()
        {
            // within the curve before, or just after it: that curve makes this change too
            c.dgamma += dg;
            continue;
        }
        // the next point where the grade changes (a point on one grade, to 0.02 %, is no limit)
        let next = (i + 1..legs.len().saturating_sub(1))
            .find(|&j| (legs[j + 1].gamma - legs[j].gamma).abs() >= 2e-4)
            .unwrap_or(legs.len() - 1);
        let next_mid = laid.at.get(next + 1).copied().unwrap_or(laid.path.length);
        let want = PI * dg.abs() * v * v / (2.0 * a_v);
        // room: up to the last curve's end before, half-way to the next point after
        let room = 2.0 * (mid - last_end).min(0.5 * (next_mid - mid));
        // at least a few metres where there is room: a small change's curve at the limit
        // would last a fraction of an IMU sample
        let len = want.max(MIN_CURVE_M).min(room).max(1e-3);
        if len < want * (1.0 - 1e-9) {
            notes
                .sharp_crests
                .push((i % n + 1, PI * dg.abs() * v * v / (2.0 * len)));
        }
        laid.path.crests.push(Crest {
            s0: mid - 0.5 * len,
            len,
            gamma0: legs[i].gamma,
            dgamma: dg,
        });
        last_end = mid + 0.5 * len;
    }
}

/// The speed profile: standing at the start, then stop to stop, each leg at its speed and
/// each turn at its own.
fn profile(
    spec: &DriveSpec,
    legs: &[Leg],
    corners: &[Corner],
    laid: &Laid,
    notes: &mut RoadNotes,
) -> Result<Vec<super::speed::Phase>, ParamError> {
    let n = spec.waypoints.len();
    let lim = Limits {
        accel: spec.accel_mps2,
        brake: spec.brake_mps2.unwrap_or(spec.accel_mps2),
        jerk: spec.jerk_mps3.unwrap_or(1.0),
    };
    if !(lim.brake.is_finite() && lim.brake > 0.0 && lim.jerk.is_finite() && lim.jerk > 0.0) {
        return Err(ParamError::new(
            "drive",
            "brake_mps2 and jerk_mps3 must be positive",
        ));
    }
    let wait = stops(spec, legs.len())?;
    let mut p = Profile::default();
    p.stand(spec.start_wait_s);
    // the pieces of the stretch being gathered, and what each is called
    let mut st = Stretch {
        s0: 0.0,
        pieces: Vec::new(),
        wait_s: 0.0,
    };
    let mut names: Vec<String> = Vec::new();
    let mut drive = |st: &mut Stretch, names: &mut Vec<String>, end: f64, wait_s: f64| {
        st.wait_s = wait_s;
        // a turn's speed is the most its sharpest point allows: one driven slower (pulling
        // away from a stop through it) is not a leg slowed against the plan
        for (k, v) in p.drive(st, &lim) {
            if !names[k].starts_with("the turn") {
                notes.slowed.push((names[k].clone(), st.pieces[k].1, v));
            }
        }
        *st = Stretch {
            s0: end,
            pieces: Vec::new(),
            wait_s: 0.0,
        };
        names.clear();
    };
    for (i, leg) in legs.iter().enumerate() {
        let point = i + 1;
        let span = laid.turn_span.get(i).copied();
        let end = span.map_or(laid.path.length, |(a, _)| a);
        st.pieces.push((end, leg.speed));
        names.push(format!("the leg to waypoint {}", i % n + 1));
        if span.is_none() || wait[point].is_some() {
            drive(&mut st, &mut names, end, wait[point].unwrap_or(0.0));
        }
        if let Some((_, b)) = span.filter(|(a, b)| b > a) {
            st.pieces.push((b, corners[i].speed));
            names.push(format!("the turn at waypoint {}", i % n + 1));
        }
    }
    Ok(p.phases)
}

/// Seconds standing at each route point (`None`: no stop), from the spec's stops in every lap.
fn stops(spec: &DriveSpec, n_legs: usize) -> Result<Vec<Option<f64>>, ParamError> {
    let n = spec.waypoints.len();
    let mut wait: Vec<Option<f64>> = vec![None; n_legs + 1];
    for &[k, secs] in &spec.stops {
        if k.fract() != 0.0 || k < 1.0 || k as usize > n || secs.is_nan() || secs < 0.0 {
            return Err(ParamError::new(
                "drive",
                format!(
                    "stop [{k}, {secs}]: a stop is [waypoint number 1..{n}, seconds standing >= 0]"
                ),
            ));
        }
        for lap in 0..spec.laps as usize {
            wait[lap * n + k as usize] = Some(secs);
        }
    }
    Ok(wait)
}

/// The longest road planned, m: its knots (one each 5 m at most) are kept in memory.
pub const MAX_LENGTH_M: f64 = 3.0e6;
/// The most legs a road has (waypoints times laps).
pub const MAX_LEGS: usize = 10_000;

/// Every number of a road's spec is finite, its heights are on the earth, and it is not so
/// long that planning it would not end: refused with the field before anything is planned.
pub(in crate::road) fn sane(spec: &DriveSpec) -> Result<(), ParamError> {
    let finite = |xs: &mut dyn Iterator<Item = f64>| {
        let mut all = true;
        for x in xs {
            all &= x.is_finite();
        }
        all
    };
    let opts = [
        spec.brake_mps2,
        spec.jerk_mps3,
        spec.vertical_accel_mps2,
        spec.pitch_per_accel_deg,
        spec.roll_per_lateral_accel_deg,
        spec.corner_radius_m,
        spec.bank_deg,
        spec.roughness,
    ];
    if !finite(&mut spec.waypoints.iter().flatten().copied())
        || !finite(&mut spec.heights_m.iter().copied().chain([spec.height_m]))
        || !finite(&mut spec.leg_speeds_mps.iter().copied())
        || !finite(&mut spec.stops.iter().flatten().copied())
        || !finite(&mut opts.iter().flatten().copied())
        || !finite(&mut [spec.lon_deg, spec.start_wait_s].into_iter())
    {
        return Err(ParamError::new(
            "drive",
            "every number of a road (waypoints, heights, speeds, stops, limits) must be finite",
        ));
    }
    if let Some(r) = spec.roughness.filter(|r| !(0.0..=5.0).contains(r)) {
        return Err(ParamError::new(
            "drive",
            format!("roughness {r}: from 0 (smooth) to 5 (1 is a typical paved road)"),
        ));
    }
    if let Some(h) = spec
        .heights_m
        .iter()
        .chain([&spec.height_m])
        .find(|h| !(-500.0..=9000.0).contains(*h))
    {
        return Err(ParamError::new(
            "drive",
            format!("height {h} m: a road is between -500 m and 9,000 m"),
        ));
    }
    if !(0.0..=86_400.0).contains(&spec.start_wait_s) || spec.stops.iter().any(|s| s[1] > 86_400.0)
    {
        return Err(ParamError::new(
            "drive",
            "start_wait_s and a stop's seconds are from 0 to a day",
        ));
    }
    let legs = spec.waypoints.len() * spec.laps as usize;
    let one_lap: f64 = std::iter::once(&[0.0, 0.0])
        .chain(&spec.waypoints)
        .collect::<Vec<_>>()
        .windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum();
    if legs > MAX_LEGS || one_lap * f64::from(spec.laps) > MAX_LENGTH_M {
        return Err(ParamError::new(
            "drive",
            format!(
                "{legs} legs, {:.0} km: a road has at most {MAX_LEGS} legs and {:.0} km",
                one_lap * f64::from(spec.laps) / 1e3,
                MAX_LENGTH_M / 1e3
            ),
        ));
    }
    // a land vehicle's speeds (the slowest: a drive that ends)
    let speeds = std::iter::once(("speed_mps".to_string(), spec.speed_mps)).chain(
        spec.leg_speeds_mps
            .iter()
            .enumerate()
            .map(|(i, v)| (format!("the speed of the leg to waypoint {}", i + 1), *v)),
    );
    for (what, v) in speeds {
        if !(0.1..=150.0).contains(&v) {
            return Err(ParamError::new(
                "drive",
                format!("{what} is {v} m/s: a road's speeds are from 0.1 m/s to 150 m/s"),
            ));
        }
    }
    Ok(())
}

impl Road {
    /// Plan the road of `spec`; errors name the field, the waypoint or the leg that is wrong.
    pub fn plan(spec: &DriveSpec) -> Result<Self, ParamError> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if !(pos(spec.speed_mps)
            && pos(spec.accel_mps2)
            && pos(spec.turn_rate_dps)
            && pos(spec.lateral_accel_mps2))
        {
            return Err(ParamError::new(
                "drive",
                "speed_mps, accel_mps2, turn_rate_dps and lateral_accel_mps2 must be positive",
            ));
        }
        if spec.waypoints.is_empty() || spec.laps == 0 {
            return Err(ParamError::new(
                "drive",
                "needs at least one waypoint and one lap",
            ));
        }
        if spec.lat_deg.is_nan() || spec.lat_deg.abs() > 89.0 {
            return Err(ParamError::new(
                "drive",
                format!(
                    "lat_deg {}: a road is driven within 89 deg of the equator",
                    spec.lat_deg
                ),
            ));
        }
        sane(spec)?;
        let pts = points(spec)?;
        let legs = legs(spec, &pts)?;
        Ok(Self::build(spec, &pts, legs, None)?.0)
    }

    /// Lay the road out along `legs` between the points `pts` (each's height third), plan its
    /// speed, and place it on the ellipsoid from the spec's start. With `fit` (a fitted track's
    /// corners, whose legs are as short as the track's: the tolerance, m) each turn passes
    /// within the tolerance of its corner and is as sharp as the legs either side of it leave
    /// room for, driven as slowly as that needs; without it a leg too short for its turns is
    /// refused. Also returns each point's places along the road:
    /// where its turn starts (where a stop there stands) and its middle (the ends for the first
    /// and last point), m.
    pub(in crate::road) fn build(
        spec: &DriveSpec,
        pts: &[[f64; 3]],
        legs: Vec<Leg>,
        fit: Option<f64>,
    ) -> Result<(Self, Vec<[f64; 2]>), ParamError> {
        let tn = turns(spec, &legs, fit)?;
        let mut legs = legs;
        let mut laid = lay(spec, &legs, &tn)?;
        // each leg's pitch climbs its height over the road between its waypoints (the middles
        // of their turns), which the pitch itself lengthens: a few rounds settle it to rounding
        for _ in 0..8 {
            for (i, leg) in legs.iter_mut().enumerate() {
                leg.gamma = (leg.dh / (laid.at[i + 1] - laid.at[i]))
                    .clamp(-1.0, 1.0)
                    .asin();
            }
            laid = lay(spec, &legs, &tn)?;
        }
        let mut notes = RoadNotes::default();
        crests(spec, &legs, &mut laid, &mut notes);
        let phases = profile(spec, &legs, &tn, &laid, &mut notes)?;
        let start = [
            spec.lat_deg.to_radians(),
            spec.lon_deg.to_radians(),
            spec.height_m,
        ];
        let placed = Placed::new(&laid.path, start);
        notes.height_miss_m = laid
            .at
            .iter()
            .zip(pts)
            .map(|(&s, p)| (placed.llh(&laid.path, s)[2] - p[2]).abs())
            .fold(0.0, f64::max);
        for leg in &legs {
            if leg.dh > 0.0 {
                notes.climb_m += leg.dh;
            } else {
                notes.descent_m -= leg.dh;
            }
            if leg.gamma.tan().abs() > notes.steepest_grade_pct.abs() / 100.0 {
                notes.steepest_grade_pct = leg.gamma.tan() * 100.0;
            }
        }
        let mut reached: Vec<[f64; 2]> = laid.at.iter().map(|&s| [s, s]).collect();
        for (r, span) in reached.iter_mut().skip(1).zip(&laid.turn_span) {
            r[0] = span.0;
        }
        let road = Road {
            placed,
            phases,
            pitch_per_accel: spec.pitch_per_accel_deg.unwrap_or(0.3).to_radians(),
            roll_per_lateral: spec.roll_per_lateral_accel_deg.unwrap_or(0.5).to_radians(),
            roughness: rough::Roughness::new(spec.roughness.unwrap_or(0.0)),
            notes: RoadNotes::default(),
            track: None,
            path: laid.path,
        };
        notes.length_m = road.path.length;
        notes.duration_s = road.duration();
        Ok((Road { notes, ..road }, reached))
    }
}
