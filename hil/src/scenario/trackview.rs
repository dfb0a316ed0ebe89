//! A picture of a recorded track against the road the bench drives from it (`hil plan track
//! --svg`): the plan view (the track's points, the ones dropped, the stops, the road) and the
//! heights along the drive, as a self-contained SVG.

use emulators::drive::Drive;
use emulators::geodesy::enu_offset;
use emulators::road::track::{Track, TrackNotes};
use std::fmt::Write as _;

const W: f64 = 900.0;
const MAP_H: f64 = 640.0;
const PROFILE_H: f64 = 180.0;
const M: f64 = 40.0;
/// Room above the map for the title and the legend.
const TOP: f64 = 80.0;

/// A length for the scale bar near a fifth of `span`, m: 1, 2 or 5 times a power of ten.
fn nice(span: f64) -> f64 {
    let raw = (span / 5.0).max(1.0);
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|k| k * p)
        .rfind(|&x| x <= raw)
        .unwrap_or(p)
}

/// The picture of `track`, the road `drive` fitted to it (its notes `notes`), and `title`.
pub fn svg(track: &Track, drive: &Drive, notes: &TrackNotes, title: &str) -> String {
    let p0 = &track.points[0];
    let origin = (p0.lat_deg.to_radians(), p0.lon_deg.to_radians(), 0.0);
    let en = |lat: f64, lon: f64| {
        let e = enu_offset(origin, (lat, lon, 0.0));
        (e[0], e[1])
    };
    let pts: Vec<(f64, f64)> = track
        .points
        .iter()
        .map(|p| en(p.lat_deg.to_radians(), p.lon_deg.to_radians()))
        .collect();
    let end = drive.duration();
    let steps = ((end * 2.0).ceil() as usize).clamp(2, 200_000);
    let road: Vec<(f64, f64, f64, f64)> = (0..=steps)
        .map(|k| {
            let t = end * k as f64 / steps as f64;
            let (lat, lon, h) = drive.position(t);
            let (e, n) = en(lat, lon);
            (t, e, n, h)
        })
        .collect();
    // the frame: every point and the road, square metres
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in pts
        .iter()
        .chain(road.iter().map(|r| (r.1, r.2)).collect::<Vec<_>>().iter())
    {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    let span = (x1 - x0).max(y1 - y0).max(10.0);
    let scale = ((W - 2.0 * M) / (x1 - x0).max(1.0))
        .min((MAP_H - M - TOP) / (y1 - y0).max(1.0))
        .min((W - 2.0 * M) / span * 4.0);
    let sx = |x: f64| M + (x - x0) * scale;
    let sy = |y: f64| MAP_H - M - (y - y0) * scale;
    let mut o = String::new();
    let height = MAP_H + PROFILE_H + M;
    let _ = writeln!(
        o,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{height}\" viewBox=\"0 0 {W} {height}\" font-family=\"sans-serif\" font-size=\"12\">"
    );
    let _ = writeln!(o, "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>");
    let _ = writeln!(
        o,
        "<text x=\"{M}\" y=\"20\" font-size=\"14\">{}</text>",
        escape(title)
    );
    let _ = writeln!(
        o,
        "<text x=\"{M}\" y=\"36\" fill=\"#444\">road {:.1} m RMS from the points ({:.1} m at worst, {}), corners {:.1} s RMS from the track's times; {} points, {} dropped, {} stops</text>",
        notes.distance_rms_m,
        notes.distance_max_m,
        escape(&notes.distance_max_at),
        notes.time_rms_s,
        notes.points_read,
        notes.dropped_points.len(),
        notes.stops.len()
    );
    // the road
    let path = polyline(road.iter().map(|r| (sx(r.1), sy(r.2))));
    let _ = writeln!(
        o,
        "<path d=\"{path}\" fill=\"none\" stroke=\"#1f5fbf\" stroke-width=\"2\" stroke-linejoin=\"round\"/>"
    );
    marks(&mut o, track, notes, &pts, &sx, &sy, &en);
    // scale bar and north
    let bar = nice(span);
    let _ = writeln!(
        o,
        "<path d=\"M{M},{:.1} h{:.1}\" stroke=\"black\" stroke-width=\"3\"/><text x=\"{M}\" y=\"{:.1}\">{}</text>",
        MAP_H - 12.0,
        bar * scale,
        MAP_H - 18.0,
        if bar >= 1000.0 {
            format!("{} km", bar / 1000.0)
        } else {
            format!("{bar} m")
        }
    );
    let _ = writeln!(
        o,
        "<path d=\"M{0},60 l-6,16 h12 z\" fill=\"black\"/><text x=\"{1}\" y=\"90\">N</text>",
        W - M,
        W - M - 4.0
    );
    legend(&mut o);
    profile(&mut o, track, notes, &road);
    o.push_str("</svg>\n");
    o
}

/// The track's points (the dropped ones crossed) and its stops.
fn marks(
    o: &mut String,
    track: &Track,
    notes: &TrackNotes,
    pts: &[(f64, f64)],
    sx: &dyn Fn(f64) -> f64,
    sy: &dyn Fn(f64) -> f64,
    en: &dyn Fn(f64, f64) -> (f64, f64),
) {
    for (p, &(x, y)) in track.points.iter().zip(pts) {
        if notes.dropped_points.contains(&p.index) {
            let (cx, cy) = (sx(x), sy(y));
            let _ = writeln!(
                o,
                "<path d=\"M{:.1},{:.1} l8,8 m0,-8 l-8,8\" stroke=\"#d62728\" stroke-width=\"2\"><title>{} dropped</title></path>",
                cx - 4.0,
                cy - 4.0,
                p.at()
            );
        } else {
            let _ = writeln!(
                o,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"2.2\" fill=\"#ff7f0e\" fill-opacity=\"0.7\"><title>{}</title></circle>",
                sx(x),
                sy(y),
                p.at()
            );
        }
    }
    // the stops
    for (at, secs) in &notes.stops {
        if let Some(p) = track.points.iter().find(|p| &p.at() == at) {
            let (x, y) = en(p.lat_deg.to_radians(), p.lon_deg.to_radians());
            let _ = writeln!(
                o,
                "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"9\" height=\"9\" fill=\"#2ca02c\"/><text x=\"{:.1}\" y=\"{:.1}\" fill=\"#2ca02c\">{secs:.0} s</text>",
                sx(x) - 4.5,
                sy(y) - 4.5,
                sx(x) + 8.0,
                sy(y) - 6.0
            );
        }
    }
}

fn legend(o: &mut String) {
    let y = 56.0;
    let x = M;
    let _ = writeln!(
        o,
        "<circle cx=\"{x}\" cy=\"{y}\" r=\"3\" fill=\"#ff7f0e\"/><text x=\"{}\" y=\"{}\">the track's points</text>\
         <path d=\"M{},{} h18\" stroke=\"#1f5fbf\" stroke-width=\"2\"/><text x=\"{}\" y=\"{}\">the road the bench drives</text>\
         <path d=\"M{},{} l8,8 m0,-8 l-8,8\" stroke=\"#d62728\" stroke-width=\"2\"/><text x=\"{}\" y=\"{}\">dropped</text>\
         <rect x=\"{}\" y=\"{}\" width=\"9\" height=\"9\" fill=\"#2ca02c\"/><text x=\"{}\" y=\"{}\">stop</text>",
        x + 8.0,
        y + 4.0,
        x + 130.0,
        y,
        x + 154.0,
        y + 4.0,
        x + 320.0,
        y - 4.0,
        x + 334.0,
        y + 4.0,
        x + 400.0,
        y - 4.5,
        x + 414.0,
        y + 4.0
    );
}

/// Heights against time: the track's (points) and the road's (line).
fn profile(o: &mut String, track: &Track, notes: &TrackNotes, road: &[(f64, f64, f64, f64)]) {
    let top = MAP_H + 10.0;
    let t0 = track.points[0].t;
    // the drive's time is the track's after the wait before it
    let lag = notes.start_wait_s;
    let hs: Vec<(f64, f64)> = track
        .points
        .iter()
        .filter_map(|p| p.h_m.map(|h| (p.t - t0 + lag, h)))
        .collect();
    let (mut h0, mut h1) = (f64::MAX, f64::MIN);
    for &(_, h) in hs
        .iter()
        .chain(road.iter().map(|r| (r.0, r.3)).collect::<Vec<_>>().iter())
    {
        (h0, h1) = (h0.min(h), h1.max(h));
    }
    if h1 - h0 < 1.0 {
        h1 = h0 + 1.0;
    }
    let t_end = road.last().map_or(1.0, |r| r.0).max(1.0);
    let px = |t: f64| M + t / t_end * (W - 2.0 * M);
    let py = |h: f64| top + PROFILE_H - 20.0 - (h - h0) / (h1 - h0) * (PROFILE_H - 40.0);
    let _ = writeln!(
        o,
        "<text x=\"{M}\" y=\"{:.1}\">height, {:.0} to {:.0} m, over the drive's {:.0} s</text>",
        top + 12.0,
        h0,
        h1,
        t_end
    );
    let path = polyline(road.iter().map(|r| (px(r.0), py(r.3))));
    let _ = writeln!(
        o,
        "<path d=\"{path}\" fill=\"none\" stroke=\"#1f5fbf\" stroke-width=\"1.5\"/>"
    );
    for (t, h) in hs {
        let _ = writeln!(
            o,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"1.5\" fill=\"#ff7f0e\" fill-opacity=\"0.7\"/>",
            px(t),
            py(h)
        );
    }
}

/// An SVG path's `d` through points (pixels).
fn polyline(points: impl Iterator<Item = (f64, f64)>) -> String {
    let mut d = String::new();
    for (k, (x, y)) in points.enumerate() {
        let _ = write!(d, "{}{x:.1},{y:.1}", if k == 0 { "M" } else { " L" });
    }
    d
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
