//! What the bench will drive (`hil plan route`): a route's length, duration, climb, speeds,
//! accelerations, attitude, stops, and what its plan had to assume, read from the truth itself
//! (sampled at 10 Hz), and the profile as CSV for a plot.

use crate::scenario::Scenario;
use anyhow::{Context, Result, bail};
use emulators::drive::Drive;
use serde::Serialize;
use std::fmt::Write as _;

/// A route as the bench will drive it.
#[derive(Debug, Clone, Serialize)]
pub struct RouteSummary {
    /// The scenario's name.
    pub scenario: String,
    /// `road` (heights, speeds per leg, stops, suspension: `emulators::road`) or `level` (one
    /// speed on a level road).
    pub kind: &'static str,
    /// Distance driven, m.
    pub length_m: f64,
    /// Duration of the drive, s (the vehicle stands still after it).
    pub duration_s: f64,
    /// The scenario's duration, s.
    pub scenario_s: f64,
    /// Height at the start and its lowest and highest, m.
    pub height_m: [f64; 3],
    /// Top speed, m/s.
    pub top_speed_mps: f64,
    /// Largest acceleration and braking along the road, m/s^2.
    pub accel_mps2: [f64; 2],
    /// Largest lateral acceleration, m/s^2.
    pub lateral_mps2: f64,
    /// Pitch and roll ranges of the body, deg: [min, max] each.
    pub pitch_deg: [f64; 2],
    /// See [`RouteSummary::pitch_deg`].
    pub roll_deg: [f64; 2],
    /// A road's vertical acceleration while driving, m/s^2: RMS and largest (over crests and
    /// dips, and the bumps of a rough road).
    pub vertical_mps2: Option<[f64; 2]>,
    /// Times the vehicle stands (at least 1 s): [from, for], s.
    pub standing: Vec<[f64; 2]>,
    /// What a road's plan had to do and assume.
    pub notes: Option<emulators::road::RoadNotes>,
    /// What was done with the recorded track the road was fitted to, when it was.
    pub track: Option<emulators::road::track::TrackNotes>,
    /// The truth's self-check (`--check`): the reference integration of the drive's own
    /// increments against its position, velocity and attitude.
    pub truth_check: Option<emulators::road::reference::SelfCheck>,
}

/// The route of scenario `s`, sampled at 10 Hz.
pub fn summary(s: &Scenario) -> Result<RouteSummary> {
    let Some(spec) = &s.drive else {
        bail!("scenario {} has no [drive]", s.name)
    };
    let d = Drive::plan(spec).map_err(|e| anyhow::anyhow!("[{}] {}", e.table, e.problem))?;
    Ok(summary_of(&s.name, s.duration_s, &d))
}

/// The route `d` (called `name`, in a run of `run_s`), sampled at 10 Hz.
pub fn summary_of(name: &str, run_s: f64, d: &Drive) -> RouteSummary {
    let end = d.duration();
    let n = (end * 10.0).ceil() as usize + 1;
    let mut r = RouteSummary {
        scenario: name.to_string(),
        kind: if d.road().is_some() { "road" } else { "level" },
        length_m: 0.0,
        duration_s: end,
        scenario_s: run_s,
        height_m: [d.position(0.0).2, f64::INFINITY, f64::NEG_INFINITY],
        top_speed_mps: 0.0,
        accel_mps2: [0.0; 2],
        lateral_mps2: 0.0,
        pitch_deg: [f64::INFINITY, f64::NEG_INFINITY],
        roll_deg: [f64::INFINITY, f64::NEG_INFINITY],
        vertical_mps2: None,
        standing: Vec::new(),
        notes: d.road().map(|r| r.notes().clone()),
        track: d.road().and_then(|r| r.track_notes().cloned()),
        truth_check: None,
    };
    let mut still_from: Option<f64> = None;
    let mut vertical = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..n {
        let t = (k as f64 * 0.1).min(end);
        let (v, _, a, w, _) = d.kinematics(t);
        let h = d.position(t).2;
        let [_, p, ro] = d.hpr(t);
        r.length_m += v * 0.1;
        r.height_m[1] = r.height_m[1].min(h);
        r.height_m[2] = r.height_m[2].max(h);
        r.top_speed_mps = r.top_speed_mps.max(v);
        r.accel_mps2 = [r.accel_mps2[0].max(a), r.accel_mps2[1].max(-a)];
        r.lateral_mps2 = r.lateral_mps2.max((v * w).abs());
        if let Some(road) = d.road().filter(|_| v > 1e-6) {
            let z = road.vertical_accel(t);
            vertical = (
                vertical.0 + z * z,
                vertical.1 + 1.0,
                vertical.2.max(z.abs()),
            );
        }
        r.pitch_deg = [
            r.pitch_deg[0].min(p.to_degrees()),
            r.pitch_deg[1].max(p.to_degrees()),
        ];
        r.roll_deg = [
            r.roll_deg[0].min(ro.to_degrees()),
            r.roll_deg[1].max(ro.to_degrees()),
        ];
        match (v < 1e-6, still_from) {
            (true, None) => still_from = Some(t),
            (false, Some(t0)) => {
                if t - t0 >= 1.0 {
                    r.standing.push([t0, t - t0]);
                }
                still_from = None;
            }
            _ => {}
        }
    }
    if let Some(road) = d.road() {
        r.length_m = road.length();
        r.vertical_mps2 = Some([(vertical.0 / vertical.1.max(1.0)).sqrt(), vertical.2]);
    }
    r
}

/// The summary for people.
pub fn text(r: &RouteSummary) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "{}: a {} route of {:.0} m in {:.1} s (the scenario lasts {:.1} s{})",
        r.scenario,
        r.kind,
        r.length_m,
        r.duration_s,
        r.scenario_s,
        if r.duration_s > r.scenario_s {
            ": it ends before the drive does"
        } else {
            ""
        }
    );
    let _ = writeln!(
        o,
        "  height {:.0} m at the start, {:.0} to {:.0} m",
        r.height_m[0], r.height_m[1], r.height_m[2]
    );
    let _ = writeln!(
        o,
        "  speed up to {:.1} m/s; acceleration up to {:.2} m/s^2, braking {:.2}, lateral {:.2}",
        r.top_speed_mps, r.accel_mps2[0], r.accel_mps2[1], r.lateral_mps2
    );
    let _ = writeln!(
        o,
        "  pitch {:+.2} to {:+.2} deg, roll {:+.2} to {:+.2} deg",
        r.pitch_deg[0], r.pitch_deg[1], r.roll_deg[0], r.roll_deg[1]
    );
    if let Some([rms, max]) = r.vertical_mps2 {
        let _ = writeln!(
            o,
            "  vertical acceleration while driving {rms:.2} m/s^2 RMS, up to {max:.2} (crests, dips and the road's bumps)"
        );
    }
    let stands: Vec<String> = r
        .standing
        .iter()
        .map(|[t, d]| format!("{d:.1} s from {t:.1} s"))
        .collect();
    let _ = writeln!(o, "  standing: {}", stands.join(", "));
    if let Some(n) = &r.notes {
        let _ = writeln!(
            o,
            "  climb {:.0} m, descent {:.0} m, steepest grade {:+.1} %; the waypoints' heights are met within {:.2} m (the vertical curves' middle ordinates)",
            n.climb_m, n.descent_m, n.steepest_grade_pct, n.height_miss_m
        );
        for (what, asked, driven) in &n.slowed {
            let _ = writeln!(
                o,
                "  {what} is driven at {driven:.1} m/s, not {asked:.1}: too short to reach it and change to the next speed within the limits"
            );
        }
        for (w, a) in &n.sharp_crests {
            let _ = writeln!(
                o,
                "  the vertical curve at waypoint {w} is short for its leg's speed: {a:.2} m/s^2 vertical"
            );
        }
    }
    if let Some(t) = &r.track {
        track_text(&mut o, t);
    }
    if let Some(c) = &r.truth_check {
        let _ = writeln!(
            o,
            "  {}: {}",
            if c.holds() {
                "one motion"
            } else {
                "NOT ONE MOTION"
            },
            c.summary()
        );
    }
    o
}

/// What was done with a recorded track, for people.
fn track_text(o: &mut String, t: &emulators::road::track::TrackNotes) {
    let _ = writeln!(
        o,
        "  from a track of {} points ({} used): {} corners, {} stops; jitter {:.1} m",
        t.points_read,
        t.points_used,
        t.corners,
        t.stops.len(),
        t.jitter_m
    );
    let _ = writeln!(
        o,
        "  the road driven is {:.1} m (RMS) from the track's points, {:.1} m at worst ({}); it passes the corners {:.1} s (RMS) from the track's times, {:.1} s at worst",
        t.distance_rms_m, t.distance_max_m, t.distance_max_at, t.time_rms_s, t.time_max_s
    );
    for (at, secs) in &t.stops {
        let _ = writeln!(o, "  stop: {secs:.0} s at {at}");
    }
    for d in &t.dropped {
        let _ = writeln!(o, "  dropped: {d}");
    }
    for a in &t.assumed {
        let _ = writeln!(o, "  assumed: {a}");
    }
}

/// The route's profile at `hz`: time, distance, latitude, longitude, height, speed, heading,
/// pitch, roll, as CSV.
pub fn csv(s: &Scenario, hz: f64, out: &std::path::Path) -> Result<()> {
    let spec = s.drive.as_ref().context("the scenario has no [drive]")?;
    let d = Drive::plan(spec).map_err(|e| anyhow::anyhow!("[{}] {}", e.table, e.problem))?;
    csv_of(&d, hz, out)
}

/// The profile of the drive `d` at `hz`, as [`csv`].
pub fn csv_of(d: &Drive, hz: f64, out: &std::path::Path) -> Result<()> {
    let mut o =
        String::from("t_s,dist_m,lat_deg,lon_deg,h_m,speed_mps,heading_deg,pitch_deg,roll_deg\n");
    let n = (d.duration() * hz).ceil() as usize + 1;
    let mut dist = 0.0;
    for k in 0..n {
        let t = k as f64 / hz;
        let (v, ..) = d.kinematics(t);
        let (lat, lon, h) = d.position(t);
        let [hd, p, r] = d.hpr(t);
        if let Some(road) = d.road() {
            dist = road.distance(t);
        }
        let _ = writeln!(
            o,
            "{t:.3},{dist:.3},{:.9},{:.9},{h:.3},{v:.4},{:.4},{:.4},{:.4}",
            lat.to_degrees(),
            lon.to_degrees(),
            hd.to_degrees().rem_euclid(360.0),
            p.to_degrees(),
            r.to_degrees()
        );
        dist += v / hz;
    }
    std::fs::write(out, o).with_context(|| format!("cannot write {}", out.display()))
}
