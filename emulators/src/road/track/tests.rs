//! Tracks read, fitted and driven; every class of bad track refused with its reason.

use super::logger::{Logger, record, reference, write};
use super::*;
use crate::drive::{Drive, DriveSpec};
use crate::geodesy as earth;
use crate::road::Road;

/// 2026-05-01T08:00:00Z.
const T0: f64 = 1_777_622_400.0;

fn hilly_drive() -> Drive {
    Drive::plan(&crate::road::tests::hilly()).unwrap_or_else(|e| panic!("{}", e.problem))
}

/// A handheld logger's track of the hilly drive: 1 s +- 0.4 s, 3 m of wandering jitter,
/// 6 m in height, some elevations missing and glitches.
fn logged(seed: u64) -> Vec<TrackPoint> {
    let log = Logger {
        step_s: 1.0,
        step_spread_s: 0.4,
        standing_step_s: 5.0,
        jitter_m: 3.0,
        jitter_h_m: 6.0,
        no_elevation: 0.02,
        glitch: 0.004,
        seed,
        start_s: 0.0,
    };
    record(&hilly_drive(), &log, T0)
}

fn drive_of(text: &str, name: &str) -> Road {
    let track = parse(text, name).unwrap_or_else(|e| panic!("{e}"));
    // a driver's limits (the track's corners are sharper than the road's own: see
    // `hil plan track`)
    let spec = DriveSpec {
        start_wait_s: 5.0,
        ..DriveSpec::driver()
    };
    Road::from_track(&spec, &track).unwrap_or_else(|e| panic!("{e}"))
}

/// The horizontal distance of the truth's path (every second) from the road driven, m: RMS
/// and worst.
fn from_truth(truth: &Drive, road: &Road) -> (f64, f64) {
    let samples: Vec<[f64; 3]> = (0..=(road.length() / 2.0) as usize)
        .map(|k| road.placed.llh(&road.path, k as f64 * 2.0))
        .collect();
    let (mut sum, mut worst, mut n) = (0.0, 0.0f64, 0);
    let mut t = 0.0;
    while t < truth.duration() {
        let (lat, lon, _) = truth.position(t);
        let d = samples
            .iter()
            .map(|s| {
                let e = earth::enu_offset((lat, lon, 0.0), (s[0], s[1], 0.0));
                e[0].hypot(e[1])
            })
            .fold(f64::INFINITY, f64::min);
        sum += d * d;
        worst = worst.max(d);
        n += 1;
        t += 5.0;
    }
    ((sum / n as f64).sqrt(), worst)
}

/// A logger's track of a known drive, written as GPX, read back and driven: the road the
/// bench drives lies within a few metres of the road the track was logged on (the jitter is 3
/// m), the glitches are dropped and said, the stops found, and each corner is reached within
/// seconds of when the track was.
#[test]
fn a_logged_track_is_driven_on_the_road_it_was_logged_on() {
    let pts = logged(7);
    let glitches = 3;
    let text = write(&pts, Format::Gpx, false);
    let road = drive_of(&text, "hilly.gpx");
    let n = road.track_notes().expect("a track's notes");
    let (rms, worst) = from_truth(&hilly_drive(), &road);
    assert!(rms < 3.0 && worst < 12.0, "{rms} {worst} {n:#?}");
    assert!(
        n.distance_rms_m < 6.0 && n.distance_rms_m > 0.3,
        "the points scatter about the road by their jitter: {n:#?}"
    );
    let said = n.dropped.iter().filter(|d| d.contains("glitch")).count();
    assert!(said >= glitches.min(1), "{n:#?}");
    assert!(n.stops.len() >= 2, "the two stops of 20 s and 5 s: {n:#?}");
    assert!(n.time_rms_s < 3.0 && n.time_max_s < 8.0, "{n:#?}");
    // the drive lasts as long as the track, after the scenario's 5 s of standing
    let span = pts[pts.len() - 1].t - pts[0].t;
    assert!(
        (road.duration() - 5.0 - span).abs() < 5.0,
        "{} against {span}",
        road.duration()
    );
    // the logger's error wanders (30 s): over the few seconds the jitter is estimated on, it
    // moves less than its 3 m
    assert!(n.jitter_m > 0.1 && n.jitter_m < 3.0, "{n:#?}");
}

/// The same track in the three formats reads as the same points (to the formats' rounding),
/// and GPX 1.0 as 1.1.
#[test]
fn the_three_formats_read_the_same_points() {
    let exact = reference(&hilly_drive(), 1.0, T0);
    for (fmt, v10, tol_m, tol_h) in [
        (Format::Gpx, false, 0.01, 0.02),
        (Format::Gpx, true, 0.01, 0.02),
        (Format::Nmea, false, 0.2, 0.1),
        (Format::Csv, false, 0.001, 0.002),
    ] {
        let back = parse(&write(&exact, fmt, v10), "x").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back.format, fmt);
        assert_eq!(back.points.len(), exact.len(), "{fmt:?}");
        for (a, b) in exact.iter().zip(&back.points) {
            let rm = earth::radii(a.lat_deg.to_radians()).0;
            assert!((a.t - b.t).abs() < 2e-3, "{fmt:?} {} {}", a.t, b.t);
            assert!(
                (a.lat_deg - b.lat_deg).to_radians().abs() * rm < tol_m
                    && (a.lon_deg - b.lon_deg).to_radians().abs() * rm < tol_m,
                "{fmt:?} {a:?} {b:?}"
            );
            let (ha, hb) = (a.h_m.unwrap_or(0.0), b.h_m.unwrap_or(f64::NAN));
            assert!((ha - hb).abs() < tol_h, "{fmt:?} {ha} {hb}");
        }
    }
}

/// A reference trajectory as CSV (every 0.5 s, with attitude and velocity) is driven within
/// centimetres... of its own path: no jitter to average, and the corners where its lines meet.
#[test]
fn a_reference_trajectory_is_driven_where_it_went() {
    let exact = reference(&hilly_drive(), 0.5, T0);
    let road = drive_of(&write(&exact, Format::Csv, false), "ref.csv");
    let n = road.track_notes().expect("notes");
    let (rms, worst) = from_truth(&hilly_drive(), &road);
    assert!(rms < 1.0 && worst < 4.0, "{rms} {worst} {n:#?}");
    assert!(n.dropped.is_empty(), "{n:#?}");
}

fn refused(text: &str, name: &str, at: &str, what: &str) {
    let e = parse(text, name)
        .and_then(|t| {
            Road::from_track(
                &DriveSpec {
                    start_wait_s: 1.0,
                    ..DriveSpec::default()
                },
                &t,
            )
        })
        .map(|_| ())
        .expect_err(what);
    let msg = e.to_string();
    assert!(
        msg.contains(name) && e.at.contains(at) && e.what.contains(what),
        "{msg}: wanted {at:?} and {what:?}"
    );
}

const GPX_HEAD: &str = "<?xml version=\"1.0\"?>\n<gpx version=\"1.1\" xmlns=\"http://www.topografix.com/GPX/1/1\"><trk><trkseg>\n";

fn gpx_of(pts: &[(f64, f64, Option<&str>)]) -> String {
    let mut s = GPX_HEAD.to_string();
    for (lat, lon, t) in pts {
        s.push_str(&format!("<trkpt lat=\"{lat}\" lon=\"{lon}\">"));
        if let Some(t) = t {
            s.push_str(&format!("<time>{t}</time>"));
        }
        s.push_str("</trkpt>\n");
    }
    s + "</trkseg></trk></gpx>\n"
}

/// Every class of track the bench cannot drive is refused with the file, the place and why.
#[test]
fn every_bad_track_is_refused_with_its_reason() {
    // no times
    refused(
        &gpx_of(&[(46.0, 7.0, None), (46.001, 7.0, None)]),
        "a.gpx",
        "trkpt 1 (line 3)",
        "no <time>",
    );
    // time going back
    refused(
        &gpx_of(&[
            (46.0, 7.0, Some("2026-05-01T08:00:00Z")),
            (46.001, 7.0, Some("2026-05-01T08:00:10Z")),
            (46.002, 7.0, Some("2026-05-01T08:00:05Z")),
        ]),
        "b.gpx",
        "point 3 (line 5)",
        "time goes back 5.000 s",
    );
    // too few points
    refused(
        &gpx_of(&[(46.0, 7.0, Some("2026-05-01T08:00:00Z"))]),
        "c.gpx",
        "the whole file",
        "too few to drive",
    );
    // a jump no vehicle makes (and stays there: not a glitch)
    let mut pts = Vec::new();
    for k in 0..10 {
        let lat = if k < 5 { 46.0 } else { 46.1 } + k as f64 * 1e-4;
        pts.push((lat, 7.0, Some(format!("2026-05-01T08:00:{:02}Z", k * 2))));
    }
    let pts: Vec<(f64, f64, Option<&str>)> =
        pts.iter().map(|(a, b, c)| (*a, *b, c.as_deref())).collect();
    refused(&gpx_of(&pts), "d.gpx", "point 6", "a jump no vehicle makes");
    // not XML
    refused(
        "<?xml version=\"1.0\"?><gpx><trk>",
        "e.gpx",
        "line 1",
        "not well-formed XML",
    );
    // a route, not a track
    refused(
        &format!("{GPX_HEAD}</trkseg></trk><rte><rtept lat=\"1\" lon=\"2\"/></rte></gpx>"),
        "f.gpx",
        "the whole file",
        "a route or waypoints",
    );
    // off the earth
    refused(
        &gpx_of(&[(96.0, 7.0, Some("2026-05-01T08:00:00Z"))]),
        "g.gpx",
        "trkpt 1",
        "not a place on the earth",
    );
    // CSV without the columns a track needs, and with a bad number
    refused("a,b,c\n1,2,3\n", "h.csv", "header", "time, lat and lon");
    refused(
        "time,lat,lon\n0,46.0,7.0\n1,46.0x,7.0\n",
        "i.csv",
        "line 3",
        "lat \"46.0x\" is not a number",
    );
    // NMEA whose every sentence fails its checksum
    let bad = "$GPGGA,080000.00,4600.0000,N,00700.0000,E,1,08,0.9,500.0,M,48.0,M,,*00\r\n";
    refused(
        &bad.repeat(3),
        "j.nmea",
        "the whole file",
        "no usable point",
    );
    // a time that is not a time
    refused(
        &gpx_of(&[(46.0, 7.0, Some("yesterday"))]),
        "k.gpx",
        "trkpt 1",
        "not ISO 8601",
    );
}

/// An NMEA log without RMC (GGA only: no date) counts its times from its first midnight and
/// rolls over at the next; sentences with a bad checksum or no fix are skipped and said.
#[test]
fn an_nmea_log_without_dates_rolls_over_midnight_and_says_what_it_skipped() {
    let exact = reference(&hilly_drive(), 1.0, T0 + 16.0 * 3600.0 - 60.0);
    let text = write(&exact[..180], Format::Nmea, false);
    let mut lines: Vec<String> = text
        .lines()
        .filter(|l| l.starts_with("$GPGGA"))
        .map(String::from)
        .collect();
    lines[10] = lines[10].replace('*', "1*"); // a corrupt sentence
    lines.insert(20, "$GPGGA,235930.000,,,,,0,00,,,M,,M,,*43".to_string());
    let t = parse(&lines.join("\r\n"), "gga.nmea").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(t.points.len(), 179, "{:?}", t.skipped);
    assert_eq!(t.skipped.len(), 2, "{:?}", t.skipped);
    assert!(
        t.skipped.iter().any(|s| s.starts_with("line 11")),
        "{:?}",
        t.skipped
    );
    // steps of one second through midnight (16:00 UTC + 8 h: the log's first midnight is 0)
    for w in t.points.windows(2) {
        let dt = w[1].t - w[0].t;
        assert!(dt > 0.9 && dt < 2.1, "{dt} at {}", w[1].line);
    }
}

/// A track across the date line and one at 70 N are driven where they went: the legs are laid
/// on the ellipsoid, so a long straight of constant heading stays on its line.
#[test]
fn tracks_across_the_date_line_and_far_north_stay_on_their_line() {
    for (lat, lon) in [(-16.8f64, 179.995f64), (70.2, 25.0)] {
        let mut s = String::from("time,lat,lon,height\n");
        // 40 km north-east on a line of constant heading (tan(psi) = dlon / dq, q the
        // isometric latitude), 25 m/s, a point every 10 s
        let e = (1.0 - (earth::B / earth::A).powi(2)).sqrt();
        let q = |p: f64| p.sin().atanh() - e * (e * p.sin()).atanh();
        let rm = earth::radii(lat.to_radians()).0;
        for k in 0..=160 {
            let la = lat + (k as f64 * 250.0 * 0.6 / rm).to_degrees();
            let dq = q(la.to_radians()) - q(f64::to_radians(lat));
            let lo = lon + (dq * 0.8 / 0.6).to_degrees();
            let lo = (lo + 180.0).rem_euclid(360.0) - 180.0;
            s.push_str(&format!("{},{la:.9},{lo:.9},100\n", k * 10));
        }
        let road = drive_of(&s, "line.csv");
        let n = road.track_notes().expect("notes");
        assert!(
            n.distance_max_m < 1.0 && n.corners < 40,
            "{lat} {lon}: {n:#?}"
        );
    }
}

/// Tracks broken every way a file breaks (bytes changed, lines cut, dropped, repeated or
/// swapped, the end cut off) are read and driven or refused with a reason: never a panic,
/// never a hang.
#[test]
fn broken_tracks_are_driven_or_refused_never_a_panic() {
    use rand::{Rng, SeedableRng};
    let exact = reference(&hilly_drive(), 2.0, T0);
    let log = Logger {
        jitter_m: 3.0,
        step_spread_s: 0.4,
        glitch: 0.01,
        ..Logger::default()
    };
    let logged = record(&hilly_drive(), &log, T0);
    let texts = [
        write(&logged, Format::Gpx, false),
        write(&logged, Format::Nmea, false),
        write(&exact, Format::Csv, false),
    ];
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let spec = DriveSpec {
        start_wait_s: 2.0,
        ..DriveSpec::default()
    };
    let (mut driven, mut refused) = (0, 0);
    for k in 0..120 {
        let mut lines: Vec<String> = texts[k % 3].lines().map(String::from).collect();
        for _ in 0..rng.random_range(1..6) {
            let n = lines.len();
            let i = rng.random_range(0..n);
            match rng.random_range(0..5) {
                0 => {
                    let mut b = lines[i].clone().into_bytes();
                    if !b.is_empty() {
                        let j = rng.random_range(0..b.len());
                        b[j] = rng.random_range(b' '..b'~');
                    }
                    lines[i] = String::from_utf8_lossy(&b).into_owned();
                }
                1 => {
                    let half = lines[i].len() / 2;
                    lines[i].truncate(half);
                }
                2 => {
                    lines.remove(i);
                }
                3 => lines.insert(i, lines[i].clone()),
                _ => lines.swap(i, rng.random_range(0..n)),
            }
        }
        if k % 7 == 0 {
            let cut = rng.random_range(0..lines.len());
            lines.truncate(cut);
        }
        match parse(&lines.join("\n"), "broken").and_then(|t| Road::from_track(&spec, &t)) {
            Ok(r) => {
                assert!(r.duration().is_finite() && r.length() > 0.0);
                driven += 1;
            }
            Err(e) => {
                assert!(!e.what.is_empty() && !e.at.is_empty(), "{e}");
                refused += 1;
            }
        }
    }
    assert!(
        driven > 20 && refused > 5,
        "{driven} driven, {refused} refused"
    );
}

/// A track file is read and fitted once per process for the same spec: planned again it is the
/// same drive; the file rewritten (another track), it is read again.
#[test]
fn a_track_is_planned_once_until_its_file_changes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("drive.csv");
    let exact = reference(&hilly_drive(), 1.0, T0);
    std::fs::write(&file, write(&exact, Format::Csv, false)).expect("written");
    let spec = DriveSpec {
        track: Some(file.display().to_string()),
        ..DriveSpec::driver()
    };
    let plan = || Drive::plan(&spec).unwrap_or_else(|e| panic!("{}", e.problem));
    let (a, b) = (plan(), plan());
    assert_eq!(a.duration(), b.duration());
    assert_eq!(a.position(100.0), b.position(100.0));
    // the first half of the drive only: another size, another plan
    std::fs::write(&file, write(&exact[..exact.len() / 2], Format::Csv, false)).expect("written");
    let c = plan();
    assert!(
        c.duration() < 0.7 * a.duration(),
        "{} {}",
        c.duration(),
        a.duration()
    );
}

/// The truth of a brisk drive logged as a handheld 1 Hz logger logs it (1 s +- 0.4 s, 3 m of
/// wandering jitter, glitches, missing heights), fitted and driven with a brisk driver's
/// limits, is one motion: the reference integration of its increments stays within the road's
/// bound. (Fitted tracks once gave vertical curves that overlapped, a pitch step of 3 mrad and
/// 1.5 km of departure, and curves and changes of speed shorter than an IMU sample.)
#[test]
fn the_truth_of_a_brisk_logged_track_is_one_motion() {
    let truth =
        Drive::plan(&crate::road::tests::brisk()).unwrap_or_else(|e| panic!("{}", e.problem));
    let log = Logger {
        step_s: 1.0,
        step_spread_s: 0.4,
        standing_step_s: 5.0,
        jitter_m: 3.0,
        jitter_h_m: 6.0,
        no_elevation: 0.03,
        glitch: 0.005,
        seed: 5,
        start_s: 0.0,
    };
    let text = write(&record(&truth, &log, T0), Format::Gpx, false);
    let track = parse(&text, "brisk.gpx").unwrap_or_else(|e| panic!("{e}"));
    let spec = DriveSpec {
        start_wait_s: 6.0,
        accel_mps2: 2.5,
        brake_mps2: Some(3.0),
        jerk_mps3: Some(2.0),
        lateral_accel_mps2: 3.5,
        ..DriveSpec::driver()
    };
    let road = Road::from_track(&spec, &track).unwrap_or_else(|e| panic!("{e}"));
    let d = Drive::from_road(road);
    let c = crate::road::reference::self_check(&d, 2000.0, d.duration() + 5.0);
    eprintln!("{}", c.summary());
    assert!(c.holds(), "{}", c.summary());
}
