//! Reading the three formats of a recorded track into points with their times.
//!
//! - GPX 1.0 and 1.1: every `trkpt` of every `trkseg` of every `trk`, in order, with `lat` and
//!   `lon`, `ele` (above mean sea level) and `time` (ISO 8601); GPX 1.0's `speed` and `course`
//!   where given.
//! - NMEA-0183: GGA (position, altitude above the geoid and the geoid's separation) and RMC
//!   (position, date, speed and course) sentences of any talker, joined by their time of day; a
//!   log without RMC has no date, so its times count from its first midnight and roll over at
//!   the next. Sentences with a bad checksum and fixes the receiver marks invalid are skipped
//!   and counted.
//! - CSV with a header: time (seconds, or ISO 8601), latitude and longitude (deg), height above
//!   the ellipsoid (`height`, `h`) or altitude above mean sea level (`alt`, `ele`), and
//!   optionally heading, pitch, roll (deg) and velocities (`vn`, `ve`, `vu`, or `vd`; m/s).
//!
//! Heights above mean sea level are put on the ellipsoid with EGM2008's geoid.

use super::{Format, Track, TrackError, TrackPoint};

fn geoid(lat: f64, lon: f64) -> f64 {
    egm2008::geoid_height(lat as f32, lon as f32).map_or(0.0, f64::from)
}

fn rfc3339(s: &str) -> Option<f64> {
    let t = chrono::DateTime::parse_from_rfc3339(s.trim()).ok()?;
    Some(t.timestamp() as f64 + f64::from(t.timestamp_subsec_nanos()) * 1e-9)
}

/// A latitude and longitude a point can have.
fn check_position(file: &str, at: &str, lat: f64, lon: f64) -> Result<(), TrackError> {
    if !(lat.is_finite() && lat.abs() <= 90.0 && lon.is_finite() && lon.abs() <= 180.0) {
        return Err(TrackError::new(
            file,
            at,
            format!("latitude {lat}, longitude {lon}: not a place on the earth"),
        ));
    }
    Ok(())
}

/// A GPX 1.0 or 1.1 file's track points.
pub fn gpx(text: &str, file: &str) -> Result<Track, TrackError> {
    let opts = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    let doc = roxmltree::Document::parse_with_options(text, opts).map_err(|e| {
        let p = e.pos();
        TrackError::new(
            file,
            format!("line {}, column {}", p.row, p.col),
            format!("not well-formed XML: {e}"),
        )
    })?;
    let root = doc.root_element();
    if root.tag_name().name() != "gpx" {
        return Err(TrackError::new(
            file,
            "line 1",
            format!(
                "the root element is <{}>, not <gpx>",
                root.tag_name().name()
            ),
        ));
    }
    fn child<'a>(n: roxmltree::Node<'a, '_>, name: &str) -> Option<&'a str> {
        n.children()
            .find(|c| c.tag_name().name() == name)
            .and_then(|c| c.text())
            .map(str::trim)
    }
    let mut points = Vec::new();
    for (k, n) in root
        .descendants()
        .filter(|n| n.tag_name().name() == "trkpt")
        .enumerate()
    {
        let line = doc.text_pos_at(n.range().start).row as usize;
        let at = format!("trkpt {} (line {line})", k + 1);
        let num = |what: &str, v: Option<&str>| -> Result<Option<f64>, TrackError> {
            match v {
                None => Ok(None),
                Some(s) => s.parse::<f64>().map(Some).map_err(|_| {
                    TrackError::new(file, &at, format!("{what} {s:?} is not a number"))
                }),
            }
        };
        let (Some(lat), Some(lon)) = (
            num("lat", n.attribute("lat"))?,
            num("lon", n.attribute("lon"))?,
        ) else {
            return Err(TrackError::new(file, &at, "a trkpt needs lat and lon"));
        };
        check_position(file, &at, lat, lon)?;
        let t = match child(n, "time") {
            Some(s) => rfc3339(s).ok_or_else(|| {
                TrackError::new(
                    file,
                    &at,
                    format!("time {s:?} is not ISO 8601 (as 2026-05-01T10:00:00Z)"),
                )
            })?,
            None => {
                return Err(TrackError::new(
                    file,
                    &at,
                    "no <time>: a drive's track needs the time of every point (a route or a track without times says where, not when)",
                ));
            }
        };
        let ele = num("ele", child(n, "ele"))?;
        points.push(TrackPoint {
            t,
            lat_deg: lat,
            lon_deg: lon,
            h_m: ele.map(|e| e + geoid(lat, lon)),
            heading_deg: num("course", child(n, "course"))?,
            speed_mps: num("speed", child(n, "speed"))?,
            pitch_roll_deg: None,
            line,
            index: k + 1,
        });
    }
    if points.is_empty() {
        let what = if root.descendants().any(|n| {
            let t = n.tag_name().name();
            t == "rtept" || t == "wpt"
        }) {
            "no <trkpt>: the file has a route or waypoints, which say where but not when; a drive needs a track"
        } else {
            "no <trkpt>: not a track"
        };
        return Err(TrackError::new(file, "the whole file", what));
    }
    Ok(Track {
        file: file.to_string(),
        format: Format::Gpx,
        points,
        skipped: Vec::new(),
    })
}

/// An epoch of an NMEA log being gathered: what its GGA and RMC said.
#[derive(Default)]
struct Epoch {
    tod: f64,
    line: usize,
    lat_lon: Option<(f64, f64)>,
    h: Option<f64>,
    date_days: Option<i64>,
    course: Option<f64>,
    speed: Option<f64>,
}

/// An NMEA-0183 log's fixes.
pub fn nmea(text: &str, file: &str) -> Result<Track, TrackError> {
    let mut skipped = Vec::new();
    let mut epochs: Vec<Epoch> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        // loggers put their own time stamps or other text before a sentence
        let Some(start) = raw.find('$') else {
            continue;
        };
        let s = raw[start..].trim_end();
        let kind = s.get(3..6).unwrap_or("");
        if kind != "GGA" && kind != "RMC" {
            continue;
        }
        let parsed = match nmea::parse_str(s) {
            Ok(p) => p,
            Err(e) => {
                skipped.push(format!("line {line}: {e}"));
                continue;
            }
        };
        let (tod, mut e) = match parsed {
            nmea::ParseResult::GGA(g) => {
                let fixed = g.fix_type.is_some_and(|f| f.is_valid());
                let (Some(t), Some(lat), Some(lon), true) =
                    (g.fix_time, g.latitude, g.longitude, fixed)
                else {
                    skipped.push(format!("line {line}: GGA without a fix"));
                    continue;
                };
                let h = g
                    .altitude
                    .map(|a| f64::from(a) + g.geoid_separation.map_or(geoid(lat, lon), f64::from));
                (
                    t,
                    Epoch {
                        lat_lon: Some((lat, lon)),
                        h,
                        ..Epoch::default()
                    },
                )
            }
            nmea::ParseResult::RMC(r) => {
                let (Some(t), Some(lat), Some(lon), false) = (
                    r.fix_time,
                    r.lat,
                    r.lon,
                    r.status_of_fix == nmea::sentences::rmc::RmcStatusOfFix::Invalid,
                ) else {
                    skipped.push(format!("line {line}: RMC without a valid fix"));
                    continue;
                };
                (
                    t,
                    Epoch {
                        lat_lon: Some((lat, lon)),
                        date_days: r.fix_date.map(|d| {
                            d.signed_duration_since(chrono::NaiveDate::default())
                                .num_days()
                        }),
                        course: r.true_course.map(f64::from),
                        speed: r.speed_over_ground.map(|k| f64::from(k) * 1852.0 / 3600.0),
                        ..Epoch::default()
                    },
                )
            }
            _ => continue,
        };
        use chrono::Timelike;
        e.tod = f64::from(tod.num_seconds_from_midnight()) + f64::from(tod.nanosecond()) * 1e-9;
        e.line = line;
        if let Some((lat, lon)) = e.lat_lon {
            check_position(file, &format!("line {line}"), lat, lon)?;
        }
        match epochs.last_mut() {
            Some(last) if (last.tod - e.tod).abs() < 1e-6 => {
                // the same epoch's other sentence: GGA's height, RMC's date, speed and course
                last.h = last.h.or(e.h);
                last.date_days = last.date_days.or(e.date_days);
                last.course = last.course.or(e.course);
                last.speed = last.speed.or(e.speed);
            }
            _ => epochs.push(e),
        }
    }
    Ok(Track {
        file: file.to_string(),
        format: Format::Nmea,
        points: nmea_points(&epochs),
        skipped,
    })
}

/// The epochs' times: from their RMC's date where one was given (the last date seen carried
/// on), else from the log's first midnight, a day added where the time of day falls back by
/// more than 12 h.
fn nmea_points(epochs: &[Epoch]) -> Vec<TrackPoint> {
    let mut day: Option<i64> = epochs.iter().find_map(|e| e.date_days);
    let mut days_counted = 0i64;
    let mut last_tod: Option<f64> = None;
    let mut out = Vec::with_capacity(epochs.len());
    for e in epochs {
        if let Some(d) = e.date_days {
            day = Some(d);
        } else if let Some(prev) = last_tod
            && e.tod < prev - 43_200.0
        {
            days_counted += 1;
            if let Some(d) = day.as_mut() {
                *d += 1;
            }
        }
        last_tod = Some(e.tod);
        let Some((lat, lon)) = e.lat_lon else {
            continue;
        };
        let t = match day {
            Some(d) => d as f64 * 86_400.0 + e.tod,
            None => days_counted as f64 * 86_400.0 + e.tod,
        };
        out.push(TrackPoint {
            t,
            lat_deg: lat,
            lon_deg: lon,
            h_m: e.h,
            heading_deg: e.course,
            speed_mps: e.speed,
            pitch_roll_deg: None,
            line: e.line,
            index: out.len() + 1,
        });
    }
    out
}

/// The columns of a CSV track, by what its header calls them.
#[derive(Default)]
struct Columns {
    time: Option<usize>,
    lat: Option<usize>,
    lon: Option<usize>,
    height: Option<usize>,
    alt: Option<usize>,
    heading: Option<usize>,
    pitch: Option<usize>,
    roll: Option<usize>,
    vn: Option<usize>,
    ve: Option<usize>,
    vu: Option<usize>,
    vd: Option<usize>,
}

impl Columns {
    fn from_header(names: &csv::StringRecord) -> Self {
        let mut c = Columns::default();
        for (i, raw) in names.iter().enumerate() {
            // "Latitude (deg)", "lat_deg", "height_m" -> "latitude", "lat", "height"
            let lower = raw.trim().to_ascii_lowercase();
            let base = lower
                .split(['(', '['])
                .next()
                .unwrap_or("")
                .trim()
                .trim_end_matches("_deg")
                .trim_end_matches("_mps")
                .trim_end_matches("_m")
                .trim_end_matches("_s")
                .to_string();
            let slot = match base.as_str() {
                "time" | "t" | "utc" | "timestamp" | "gps_time" | "datetime" => &mut c.time,
                "lat" | "latitude" => &mut c.lat,
                "lon" | "lng" | "long" | "longitude" => &mut c.lon,
                "height" | "h" | "ellipsoidal_height" | "h_ell" => &mut c.height,
                "alt" | "altitude" | "ele" | "elevation" | "msl" | "alt_msl" => &mut c.alt,
                "heading" | "yaw" | "azimuth" | "course" => &mut c.heading,
                "pitch" => &mut c.pitch,
                "roll" => &mut c.roll,
                "vn" | "v_n" | "vel_n" | "v_north" => &mut c.vn,
                "ve" | "v_e" | "vel_e" | "v_east" => &mut c.ve,
                "vu" | "v_u" | "vel_u" | "v_up" => &mut c.vu,
                "vd" | "v_d" | "vel_d" | "v_down" => &mut c.vd,
                _ => continue,
            };
            slot.get_or_insert(i);
        }
        c
    }
}

/// A CSV reference trajectory's points.
pub fn csv(text: &str, file: &str) -> Result<Track, TrackError> {
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .flexible(true)
        .from_reader(text.as_bytes());
    let header = rdr
        .headers()
        .map_err(|e| TrackError::new(file, "line 1", format!("no CSV header: {e}")))?
        .clone();
    let c = Columns::from_header(&header);
    let (Some(ct), Some(clat), Some(clon)) = (c.time, c.lat, c.lon) else {
        return Err(TrackError::new(
            file,
            "line 1 (the header)",
            format!(
                "a track's CSV names its columns time, lat and lon (and height or alt; heading, pitch, roll, vn, ve, vu optional); this header has: {}",
                header.iter().collect::<Vec<_>>().join(", ")
            ),
        ));
    };
    let mut points = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line() as usize);
            TrackError::new(file, format!("line {line}"), format!("not CSV: {e}"))
        })?;
        let line = rec.position().map_or(0, |p| p.line() as usize);
        let at = format!("line {line}");
        let num = |col: Option<usize>, what: &str| -> Result<Option<f64>, TrackError> {
            let Some(s) = col.and_then(|i| rec.get(i)).filter(|s| !s.is_empty()) else {
                return Ok(None);
            };
            match s.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(TrackError::new(
                    file,
                    &at,
                    format!("{what} {s:?} is not a number"),
                )),
            }
        };
        let t = match rec.get(ct).filter(|s| !s.is_empty()) {
            None => return Err(TrackError::new(file, &at, "no time")),
            Some(s) => match s.parse::<f64>() {
                Ok(x) if x.is_finite() => x,
                _ => rfc3339(s).ok_or_else(|| {
                    TrackError::new(
                        file,
                        &at,
                        format!("time {s:?} is neither seconds nor ISO 8601"),
                    )
                })?,
            },
        };
        let (Some(lat), Some(lon)) = (num(Some(clat), "lat")?, num(Some(clon), "lon")?) else {
            return Err(TrackError::new(file, &at, "no latitude or longitude"));
        };
        check_position(file, &at, lat, lon)?;
        let h = match (num(c.height, "height")?, num(c.alt, "alt")?) {
            (Some(h), _) => Some(h),
            (None, Some(a)) => Some(a + geoid(lat, lon)),
            _ => None,
        };
        let (vn, ve) = (num(c.vn, "vn")?, num(c.ve, "ve")?);
        let pitch_roll = match (num(c.pitch, "pitch")?, num(c.roll, "roll")?) {
            (Some(p), Some(r)) => Some([p, r]),
            _ => None,
        };
        let _vertical = (num(c.vu, "vu")?, num(c.vd, "vd")?);
        points.push(TrackPoint {
            t,
            lat_deg: lat,
            lon_deg: lon,
            h_m: h,
            heading_deg: num(c.heading, "heading")?,
            speed_mps: vn.zip(ve).map(|(n, e)| n.hypot(e)),
            pitch_roll_deg: pitch_roll,
            line,
            index: points.len() + 1,
        });
    }
    Ok(Track {
        file: file.to_string(),
        format: Format::Csv,
        points,
        skipped: Vec::new(),
    })
}
