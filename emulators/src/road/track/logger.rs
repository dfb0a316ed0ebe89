//! A drive recorded as a logger records it, and a track written in each format: the bench's
//! own tracks (shipped, and in the tests) are made this way from a drive whose truth is known,
//! so that the fit of a track can be scored against the road it came from.
//!
//! The logger's imperfections are a real one's: points at irregular steps (a nominal step with
//! a random spread), fewer while standing, a jitter of metres that wanders (first-order Markov,
//! 30 s) rather than jumps, heights noisier than positions, some elevations missing, and now
//! and then a glitch hundreds of metres off.

use super::{Format, TrackPoint};
use crate::drive::Drive;
use crate::geodesy as earth;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use std::fmt::Write as _;

/// How the logger records.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Logger {
    /// Nominal step between points, s, and its random spread (uniform, +-), s.
    pub step_s: f64,
    /// See [`Logger::step_s`].
    pub step_spread_s: f64,
    /// Step while standing, s (loggers record less when nothing moves).
    pub standing_step_s: f64,
    /// Horizontal and vertical jitter, m (1 sigma).
    pub jitter_m: f64,
    /// See [`Logger::jitter_m`].
    pub jitter_h_m: f64,
    /// Chance that a point has no elevation, and that it is a glitch.
    pub no_elevation: f64,
    /// See [`Logger::no_elevation`].
    pub glitch: f64,
    /// Seed of its random numbers.
    pub seed: u64,
    /// When it is switched on, s into the drive (a logger switched on while driving, as most
    /// are: its track starts in motion).
    pub start_s: f64,
}

impl Default for Logger {
    fn default() -> Self {
        Self {
            step_s: 1.0,
            step_spread_s: 0.0,
            standing_step_s: 1.0,
            jitter_m: 0.0,
            jitter_h_m: 0.0,
            no_elevation: 0.0,
            glitch: 0.0,
            seed: 1,
            start_s: 0.0,
        }
    }
}

/// Record `drive` from `t0_utc` (s since 1970): the points a logger writes.
pub fn record(drive: &Drive, log: &Logger, t0_utc: f64) -> Vec<TrackPoint> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(log.seed);
    let unit = Normal::new(0.0, 1.0).unwrap_or_else(|_| unreachable!("a unit normal"));
    let end = drive.duration();
    // the wandering jitter: first-order Markov with a 30 s time constant
    let tau = 30.0;
    let mut wander = [0.0f64; 3];
    let (mut t, mut last) = (log.start_s.max(0.0), log.start_s.max(0.0));
    let mut out = Vec::new();
    while t <= end {
        let dt = t - last;
        let a = (-dt / tau).exp();
        let sd = (1.0 - a * a).sqrt();
        let sigma = [log.jitter_m, log.jitter_m, log.jitter_h_m];
        for (w, s) in wander.iter_mut().zip(sigma) {
            *w = a * *w + sd * s * unit.sample(&mut rng);
        }
        last = t;
        let (lat, lon, h) = drive.position(t);
        let (rm, rn) = earth::radii(lat);
        let glitch = rng.random::<f64>() < log.glitch && t > 0.0;
        let off = if glitch { 400.0 } else { 0.0 };
        let v = drive.velocity(t);
        let speed = v.x.hypot(v.y);
        out.push(TrackPoint {
            t: t0_utc + t,
            lat_deg: (lat + (wander[1] + off) / rm).to_degrees(),
            lon_deg: (lon + (wander[0] + 0.5 * off) / (rn * lat.cos())).to_degrees(),
            h_m: (rng.random::<f64>() >= log.no_elevation).then_some(h + wander[2]),
            heading_deg: None,
            speed_mps: None,
            pitch_roll_deg: None,
            line: 0,
            index: out.len() + 1,
        });
        let step = if speed < 0.05 {
            log.standing_step_s
        } else {
            log.step_s + log.step_spread_s * (2.0 * rng.random::<f64>() - 1.0)
        };
        // whole milliseconds, as loggers write them
        t = ((t + step.max(0.05)) * 1000.0).round() / 1000.0;
    }
    out
}

/// A reference trajectory's points: every `step_s` of the drive, exact, with the body's
/// heading, pitch, roll and velocity (as a post-processed reference system exports them).
pub fn reference(drive: &Drive, step_s: f64, t0_utc: f64) -> Vec<TrackPoint> {
    let n = (drive.duration() / step_s).floor() as usize;
    (0..=n)
        .map(|k| {
            let t = k as f64 * step_s;
            let (lat, lon, h) = drive.position(t);
            let [psi, pitch, roll] = drive.hpr(t);
            let v = drive.velocity(t);
            TrackPoint {
                t: t0_utc + t,
                lat_deg: lat.to_degrees(),
                lon_deg: lon.to_degrees(),
                h_m: Some(h),
                heading_deg: Some(psi.to_degrees().rem_euclid(360.0)),
                speed_mps: Some(v.x.hypot(v.y)),
                pitch_roll_deg: Some([pitch.to_degrees(), roll.to_degrees()]),
                line: 0,
                index: k + 1,
            }
        })
        .collect()
}

fn iso(t: f64) -> String {
    let ms = (t * 1000.0).round() as i64;
    chrono::DateTime::from_timestamp_millis(ms)
        .map(|d| d.format("%Y-%m-%dT%H:%M:%S%.3fZ").to_string())
        .unwrap_or_default()
}

fn geoid(p: &TrackPoint) -> f64 {
    egm2008::geoid_height(p.lat_deg as f32, p.lon_deg as f32).map_or(0.0, f64::from)
}

/// The points as a file of `format` (GPX 1.1, or 1.0 with `gpx10`).
pub fn write(points: &[TrackPoint], format: Format, gpx10: bool) -> String {
    match format {
        Format::Gpx => gpx(points, gpx10),
        Format::Nmea => nmea(points),
        Format::Csv => csv(points),
    }
}

fn gpx(points: &[TrackPoint], v10: bool) -> String {
    let mut s = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    if v10 {
        s.push_str(
            "<gpx version=\"1.0\" creator=\"hil\" xmlns=\"http://www.topografix.com/GPX/1/0\">\n",
        );
    } else {
        s.push_str(
            "<gpx version=\"1.1\" creator=\"hil\" xmlns=\"http://www.topografix.com/GPX/1/1\">\n",
        );
    }
    s.push_str(" <trk><name>hil track</name><trkseg>\n");
    for p in points {
        let _ = write!(
            s,
            "  <trkpt lat=\"{:.8}\" lon=\"{:.8}\">",
            p.lat_deg, p.lon_deg
        );
        if let Some(h) = p.h_m {
            let _ = write!(s, "<ele>{:.2}</ele>", h - geoid(p));
        }
        let _ = write!(s, "<time>{}</time>", iso(p.t));
        if v10 && let Some(v) = p.speed_mps {
            let _ = write!(s, "<speed>{v:.2}</speed>");
        }
        s.push_str("</trkpt>\n");
    }
    s.push_str(" </trkseg></trk>\n</gpx>\n");
    s
}

fn checksum(body: &str) -> String {
    let x = body.bytes().fold(0u8, |a, b| a ^ b);
    format!("${body}*{x:02X}\r\n")
}

fn nmea(points: &[TrackPoint]) -> String {
    let mut s = String::new();
    let ddm = |deg: f64, width: usize| {
        let a = deg.abs();
        let d = a.floor();
        format!("{:0width$}{:07.4}", d as u32, (a - d) * 60.0)
    };
    for p in points {
        let ms = (p.t * 1000.0).round() as i64;
        let Some(d) = chrono::DateTime::from_timestamp_millis(ms) else {
            continue;
        };
        let hms = d.format("%H%M%S%.3f").to_string();
        let lat = format!(
            "{},{}",
            ddm(p.lat_deg, 2),
            if p.lat_deg < 0.0 { 'S' } else { 'N' }
        );
        let lon = format!(
            "{},{}",
            ddm(p.lon_deg, 3),
            if p.lon_deg < 0.0 { 'W' } else { 'E' }
        );
        let n = geoid(p);
        let alt = p.h_m.map_or(String::new(), |h| format!("{:.1}", h - n));
        s.push_str(&checksum(&format!(
            "GPGGA,{hms},{lat},{lon},1,08,0.9,{alt},M,{n:.1},M,,"
        )));
        let knots = p
            .speed_mps
            .map_or(String::new(), |v| format!("{:.2}", v * 3600.0 / 1852.0));
        let course = p.heading_deg.map_or(String::new(), |c| format!("{c:.1}"));
        s.push_str(&checksum(&format!(
            "GPRMC,{hms},A,{lat},{lon},{knots},{course},{},,,A",
            d.format("%d%m%y")
        )));
    }
    s
}

fn csv(points: &[TrackPoint]) -> String {
    let mut s = String::from("time,lat,lon,height,heading,pitch,roll,vn,ve\n");
    for p in points {
        let opt = |x: Option<f64>, prec: usize| x.map_or(String::new(), |x| format!("{x:.prec$}"));
        let _ = writeln!(
            s,
            "{:.3},{:.9},{:.9},{},{},{},{},{},{}",
            p.t,
            p.lat_deg,
            p.lon_deg,
            opt(p.h_m, 3),
            opt(p.heading_deg, 4),
            opt(p.pitch_roll_deg.map(|x| x[0]), 4),
            opt(p.pitch_roll_deg.map(|x| x[1]), 4),
            opt(
                p.heading_deg
                    .zip(p.speed_mps)
                    .map(|(h, v)| v * h.to_radians().cos()),
                3
            ),
            opt(
                p.heading_deg
                    .zip(p.speed_mps)
                    .map(|(h, v)| v * h.to_radians().sin()),
                3
            ),
        );
    }
    s
}
