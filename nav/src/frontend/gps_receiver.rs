//! GPS receiver driver: NMEA-0183 framing, parsing (the `nmea` crate), range checks, fix-quality
//! gating and counters. Every byte that is not part of an accepted sentence is counted under
//! what was wrong with it; nothing is dropped silently.
//!
//! Framing: a sentence starts at `$` (or `!`) and ends at CR, LF or CRLF. Bytes before the start
//! are garbage; a line with bytes outside printable ASCII is binary; a line longer than
//! [`MAX_LINE`] is overlong. The parser rejects bad or missing checksums; the decoder then checks
//! ranges (a latitude of 99 deg parses but is not a place) and gates on fix quality.

use nmea::ParseResult;
use serde::{Deserialize, Serialize};

/// Longest line accepted (NMEA says 82 characters; some receivers send a little more).
pub const MAX_LINE: usize = 120;

/// Counters of the GPS stream.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
pub struct GpsStats {
    /// Bytes received.
    pub bytes: u64,
    /// Lines framed.
    pub lines: u64,
    /// Bytes outside any sentence (before a `$`, stray characters).
    pub garbage_bytes: u64,
    /// Lines with non-printable bytes.
    pub binary_lines: u64,
    /// Lines longer than the limit.
    pub overlong_lines: u64,
    /// Sentences with a wrong checksum.
    pub bad_checksum: u64,
    /// Lines the parser could not read (missing checksum, bad fields, truncated).
    pub unparsed: u64,
    /// Sentences of types we do not use (parsed and counted).
    pub unused: u64,
    /// Sentences accepted.
    pub accepted: u64,
    /// Position fixes decoded (GGA, RMC, GLL, GNS with a position).
    pub fixes: u64,
    /// Fixes marked invalid by the receiver (GGA quality 0, RMC/GLL status V).
    pub no_fix: u64,
    /// Fixes with impossible values (rejected).
    pub out_of_range: u64,
    /// Fixes whose time went backwards against the previous one (flagged).
    pub time_backwards: u64,
    /// The receiver's statements of its own accuracy (GST) with usable sigmas.
    #[serde(default)]
    pub accuracy: u64,
    /// GST sentences whose sigmas are missing or not plausible (a receiver without a fix
    /// states hundreds of kilometres): not used.
    #[serde(default)]
    pub accuracy_unusable: u64,
}

/// The largest 1-sigma error a GST may state and still be used, m.
pub const MAX_GST_SIGMA_M: f64 = 500.0;

/// The receiver's own statement of its accuracy (NMEA GST): 1-sigma errors of latitude,
/// longitude and altitude, m.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct GpsAccuracy {
    /// Seconds of the UTC day of the fix it describes.
    pub time_of_day_s: Option<f64>,
    /// Latitude (north) error, 1 sigma, m.
    pub lat_sigma_m: f64,
    /// Longitude (east) error, 1 sigma, m.
    pub lon_sigma_m: f64,
    /// Altitude error, 1 sigma, m (none when the receiver leaves it empty).
    pub alt_sigma_m: Option<f64>,
}

impl GpsFix {
    /// Height above the WGS 84 ellipsoid (what the filter navigates in), m: the altitude plus
    /// the geoid's separation where the sentence gives one, else the altitude as it is (a
    /// receiver without a geoid model reports ellipsoid heights with no separation).
    pub fn ellipsoid_height_m(&self) -> Option<f64> {
        self.alt_m.map(|a| a + self.geoid_sep_m.unwrap_or(0.0))
    }
}

impl GpsAccuracy {
    /// From a parsed GST: none when latitude or longitude sigma is missing, not positive or
    /// over [`MAX_GST_SIGMA_M`] (an altitude sigma like that is dropped alone).
    fn of(g: &nmea::sentences::GstData, time_of_day_s: Option<f64>) -> Option<Self> {
        let ok = |v: Option<f32>| {
            v.map(f64::from)
                .filter(|v| v.is_finite() && *v > 0.0 && *v <= MAX_GST_SIGMA_M)
        };
        Some(Self {
            time_of_day_s,
            lat_sigma_m: ok(g.lat_sd)?,
            lon_sigma_m: ok(g.long_sd)?,
            alt_sigma_m: ok(g.alt_sd),
        })
    }
}

/// One decoded position fix (one line of the JSON-lines export).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct GpsFix {
    /// Sentence it came from (`GGA`, `RMC`, `GLL`, `GNS`).
    pub sentence: String,
    /// UTC date (from RMC or ZDA), `YYYY-MM-DD`.
    pub date: Option<String>,
    /// UTC time of day, `HH:MM:SS.sss`.
    pub time: Option<String>,
    /// Seconds of the UTC day.
    pub time_of_day_s: Option<f64>,
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Altitude above mean sea level (the geoid), m, as the sentence gives it.
    pub alt_m: Option<f64>,
    /// The geoid's height above the WGS 84 ellipsoid at the fix (GGA's separation), m.
    #[serde(default)]
    pub geoid_sep_m: Option<f64>,
    /// Fix quality (GGA: 0 none, 1 GPS, 2 DGPS, 4 RTK, ...; others: 1 valid, 0 invalid).
    pub quality: u8,
    /// Satellites used.
    pub satellites: Option<u32>,
    /// HDOP.
    pub hdop: Option<f64>,
    /// Speed over ground, m/s.
    pub speed_mps: Option<f64>,
    /// Track over ground, deg.
    pub track_deg: Option<f64>,
    /// The receiver says it is a fix.
    pub valid: bool,
    /// Its time is earlier than the previous fix's.
    pub time_backwards: bool,
    /// Index of the sentence in the stream (accepted sentences, from 0).
    pub seq: u64,
}

/// Splits a byte stream into candidate sentences.
#[derive(Debug, Default)]
pub struct LineFramer {
    buf: Vec<u8>,
    in_line: bool,
    overlong: bool,
}

impl LineFramer {
    /// Feed bytes; complete lines go to `out`, counters to `st`.
    pub fn push(&mut self, bytes: &[u8], st: &mut GpsStats, out: &mut Vec<String>) {
        st.bytes += bytes.len() as u64;
        for &b in bytes {
            match b {
                b'\r' | b'\n' => self.end(st, out),
                b'$' | b'!' => {
                    if self.in_line {
                        // a new start inside a line: the partial one was truncated
                        st.unparsed += 1;
                    }
                    self.buf.clear();
                    self.buf.push(b);
                    self.in_line = true;
                    self.overlong = false;
                }
                _ if !self.in_line => st.garbage_bytes += 1,
                _ => {
                    if self.buf.len() >= MAX_LINE {
                        self.overlong = true;
                    } else {
                        self.buf.push(b);
                    }
                }
            }
        }
    }

    fn end(&mut self, st: &mut GpsStats, out: &mut Vec<String>) {
        if !self.in_line {
            return;
        }
        self.in_line = false;
        st.lines += 1;
        if self.overlong {
            st.overlong_lines += 1;
        } else if self.buf.iter().any(|b| !(0x20..0x7f).contains(b)) {
            st.binary_lines += 1;
        } else {
            out.push(String::from_utf8_lossy(&self.buf).into_owned());
        }
        self.buf.clear();
    }
}

/// Why a line was not used.
#[derive(Debug, Clone, PartialEq)]
pub enum LineOutcome {
    /// A position fix.
    Fix(GpsFix),
    /// The receiver's accuracy (GST).
    Accuracy(GpsAccuracy),
    /// Accepted, no position in it (GSA, GSV, VTG, ZDA, ...).
    Other,
    /// Wrong checksum.
    BadChecksum,
    /// Not parseable.
    Unparsed(String),
    /// A position with impossible values.
    OutOfRange(String),
}

/// Turns sentences into fixes.
#[derive(Debug, Default)]
pub struct GpsDecoder {
    stats: GpsStats,
    framer: LineFramer,
    date: Option<chrono::NaiveDate>,
    last_tod: Option<f64>,
    backs_in_row: u32,
    accuracies: Vec<GpsAccuracy>,
}

/// Fixes in a row whose time is earlier than the latest before the decoder takes the
/// receiver's clock as reset and follows it.
pub const BACKWARDS_ACCEPTED: u32 = 6;

impl GpsDecoder {
    /// Counters.
    pub fn stats(&self) -> GpsStats {
        self.stats
    }

    /// Whether the time of day `t` is earlier than the latest before (not across midnight);
    /// counted. The time to beat stays the latest until the receiver's clock has stayed back
    /// for [`BACKWARDS_ACCEPTED`] fixes in a row: every sentence of an epoch that stepped back
    /// is flagged, not only its first, and a receiver whose clock was reset is followed again.
    fn stepped_back(&mut self, t: Option<f64>) -> bool {
        let back = match (t, self.last_tod) {
            // a day wrap (23:59 -> 00:00) is not backwards
            (Some(now), Some(prev)) => now < prev && prev - now < 43_200.0,
            _ => false,
        };
        if back {
            self.stats.time_backwards += 1;
            self.backs_in_row += 1;
        } else if t.is_some() {
            self.backs_in_row = 0;
        }
        if t.is_some() && (!back || self.backs_in_row >= BACKWARDS_ACCEPTED) {
            self.last_tod = t;
            self.backs_in_row = 0;
        }
        back
    }

    /// Feed raw bytes from the serial line; decoded fixes go to `fixes`, every line's outcome
    /// (for logs) to `outcomes` when given.
    pub fn push_bytes(&mut self, bytes: &[u8], fixes: &mut Vec<GpsFix>) {
        let mut lines = Vec::new();
        let mut st = self.stats;
        self.framer.push(bytes, &mut st, &mut lines);
        self.stats = st;
        for l in lines {
            match self.line(&l) {
                LineOutcome::Fix(f) => fixes.push(f),
                LineOutcome::Accuracy(a) => self.accuracies.push(a),
                _ => {}
            }
        }
    }

    /// The receiver's accuracy statements decoded by [`GpsDecoder::push_bytes`] since the last
    /// call.
    pub fn take_accuracies(&mut self) -> Vec<GpsAccuracy> {
        std::mem::take(&mut self.accuracies)
    }

    /// A GST statement, counted as usable or not.
    fn accuracy(&mut self, a: Option<GpsAccuracy>) -> LineOutcome {
        match a {
            Some(a) => {
                self.stats.accuracy += 1;
                LineOutcome::Accuracy(a)
            }
            None => {
                self.stats.accuracy_unusable += 1;
                LineOutcome::Other
            }
        }
    }

    /// What a position sentence reports (the time, the position, the fix's quality and
    /// motion); any other sentence's outcome as the error (GST's sigmas taken, ZDA's date).
    fn reported(&mut self, r: &ParseResult) -> Result<Reported, Box<LineOutcome>> {
        let (sentence, time, lat, lon, alt, quality, sats, hdop, speed, track, valid) = match r {
            ParseResult::GGA(g) => {
                let q = g.fix_type.map_or(0, fix_quality);
                (
                    "GGA",
                    g.fix_time,
                    g.latitude,
                    g.longitude,
                    g.altitude.map(f64::from),
                    q,
                    g.fix_satellites,
                    g.hdop.map(f64::from),
                    None,
                    None,
                    q > 0,
                )
            }
            ParseResult::RMC(m) => {
                if let Some(d) = m.fix_date {
                    self.date = Some(d);
                }
                let ok = m.status_of_fix != nmea::sentences::rmc::RmcStatusOfFix::Invalid;
                (
                    "RMC",
                    m.fix_time,
                    m.lat,
                    m.lon,
                    None,
                    u8::from(ok),
                    None,
                    None,
                    m.speed_over_ground.map(|k| f64::from(k) * 0.514_444),
                    m.true_course.map(f64::from),
                    ok,
                )
            }
            ParseResult::GLL(g) => (
                "GLL",
                g.fix_time,
                g.latitude,
                g.longitude,
                None,
                u8::from(g.valid),
                None,
                None,
                None,
                None,
                g.valid,
            ),
            ParseResult::GNS(g) => (
                "GNS",
                g.fix_time,
                g.lat,
                g.lon,
                g.alt.map(f64::from),
                1,
                Some(u32::from(g.nsattelites)),
                g.hdop.map(f64::from),
                None,
                None,
                true,
            ),
            ParseResult::GST(g) => {
                return Err(Box::new(
                    self.accuracy(GpsAccuracy::of(g, time_of_day(g.time))),
                ));
            }
            ParseResult::ZDA(z) => {
                if let Some(d) = z.utc_date() {
                    self.date = Some(d);
                }
                return Err(Box::new(LineOutcome::Other));
            }
            ParseResult::Unsupported(_) => {
                self.stats.unused += 1;
                return Err(Box::new(LineOutcome::Other));
            }
            _ => return Err(Box::new(LineOutcome::Other)),
        };
        Ok(Reported {
            sentence,
            time,
            lat,
            lon,
            alt,
            quality,
            sats,
            hdop,
            speed,
            track,
            valid,
        })
    }

    /// Decode one framed line.
    pub fn line(&mut self, l: &str) -> LineOutcome {
        let r = match nmea::parse_str(l) {
            Ok(r) => r,
            Err(nmea::Error::ChecksumMismatch { .. }) => {
                self.stats.bad_checksum += 1;
                return LineOutcome::BadChecksum;
            }
            // NMEA 2.0 GLL has no mode field, which the parser requires (the checksum was
            // good, or it would have said so)
            Err(nmea::Error::ParsingError(_)) if let Some(g) = gll_v20(l) => ParseResult::GLL(g),
            // a receiver with no satellites in view sends `$GPGSV,1,1,00`, which the parser
            // refuses; it is a well-formed sentence that tells nav nothing
            Err(nmea::Error::ParsingError(_)) if gsv_none_in_view(l) => {
                self.stats.accepted += 1;
                self.stats.unused += 1;
                return LineOutcome::Other;
            }
            Err(e) => {
                self.stats.unparsed += 1;
                return LineOutcome::Unparsed(format!("{e:?}"));
            }
        };
        let seq = self.stats.accepted;
        self.stats.accepted += 1;
        let geoid_sep = match &r {
            ParseResult::GGA(g) => g.geoid_separation.map(f64::from),
            _ => None,
        };
        let Reported {
            sentence,
            time,
            lat,
            lon,
            alt,
            quality,
            sats,
            hdop,
            speed,
            track,
            valid,
        } = match self.reported(&r) {
            Ok(p) => p,
            Err(o) => return *o,
        };
        let (Some(lat), Some(lon)) = (lat, lon) else {
            if !valid {
                self.stats.no_fix += 1;
            }
            return LineOutcome::Other;
        };
        if !(lat.is_finite() && lon.is_finite() && lat.abs() <= 90.0 && lon.abs() <= 180.0)
            || alt.is_some_and(|a| !(-1000.0..=50_000.0).contains(&a))
            || speed.is_some_and(|v| !(0.0..=600.0).contains(&v))
        {
            self.stats.out_of_range += 1;
            return LineOutcome::OutOfRange(format!(
                "{sentence}: lat {lat}, lon {lon}, alt {alt:?}, speed {speed:?}"
            ));
        }
        if !valid {
            self.stats.no_fix += 1;
        }
        let t = time_of_day(time);
        let back = self.stepped_back(t);
        self.stats.fixes += 1;
        LineOutcome::Fix(GpsFix {
            sentence: sentence.into(),
            date: self.date.map(|d| d.format("%Y-%m-%d").to_string()),
            time: time.map(|t| t.format("%H:%M:%S%.3f").to_string()),
            time_of_day_s: t,
            lat_deg: lat,
            lon_deg: lon,
            alt_m: alt,
            geoid_sep_m: geoid_sep,
            quality,
            satellites: sats,
            hdop,
            speed_mps: speed,
            track_deg: track,
            valid,
            time_backwards: back,
            seq,
        })
    }
}

/// What a position sentence reports.
struct Reported {
    sentence: &'static str,
    time: Option<chrono::NaiveTime>,
    lat: Option<f64>,
    lon: Option<f64>,
    alt: Option<f64>,
    quality: u8,
    sats: Option<u32>,
    hdop: Option<f64>,
    speed: Option<f64>,
    track: Option<f64>,
    valid: bool,
}

/// Seconds since midnight of a time of day.
fn time_of_day(t: Option<chrono::NaiveTime>) -> Option<f64> {
    t.map(|t| {
        use chrono::Timelike;
        f64::from(t.num_seconds_from_midnight()) + f64::from(t.nanosecond()) * 1e-9
    })
}

/// `$xxGLL,ddmm.mm,N,dddmm.mm,W,hhmmss.ss,A*hh` (NMEA 2.0: no mode field).
fn gll_v20(l: &str) -> Option<nmea::sentences::GllData> {
    let body = l.get(1..)?.split('*').next()?;
    let f: Vec<&str> = body.split(',').collect();
    if f.len() != 7 || !f[0].ends_with("GLL") {
        return None;
    }
    let angle = |v: &str, hemi: &str, deg_digits: usize, neg: &str| -> Option<f64> {
        let d: f64 = v.get(..deg_digits)?.parse().ok()?;
        let m: f64 = v.get(deg_digits..)?.parse().ok()?;
        let a = d + m / 60.0;
        Some(if hemi == neg { -a } else { a })
    };
    let t = f[5];
    let time = chrono::NaiveTime::parse_from_str(t, "%H%M%S%.f")
        .or_else(|_| chrono::NaiveTime::parse_from_str(t, "%H%M%S"))
        .ok();
    Some(nmea::sentences::GllData {
        latitude: angle(f[1], f[2], 2, "S"),
        longitude: angle(f[3], f[4], 3, "W"),
        fix_time: time,
        valid: f[6] == "A",
        faa_mode: None,
    })
}

/// `$xxGSV,1,1,00*hh`: no satellites in view.
fn gsv_none_in_view(l: &str) -> bool {
    let body = l.get(1..).and_then(|b| b.split('*').next()).unwrap_or("");
    let f: Vec<&str> = body.split(',').collect();
    f.len() == 4 && f[0].ends_with("GSV") && f[1] == "1" && f[2] == "1" && f[3] == "00"
}

fn fix_quality(f: nmea::sentences::FixType) -> u8 {
    use nmea::sentences::FixType as F;
    match f {
        F::Invalid => 0,
        F::Gps => 1,
        F::DGps => 2,
        F::Pps => 3,
        F::Rtk => 4,
        F::FloatRtk => 5,
        F::Estimated => 6,
        F::Manual => 7,
        F::Simulation => 8,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(body: &str) -> String {
        let ck = body.bytes().fold(0u8, |a, b| a ^ b);
        format!("${body}*{ck:02X}")
    }

    #[test]
    fn framing_survives_garbage_binary_and_any_line_ending() {
        let mut d = GpsDecoder::default();
        let mut fixes = Vec::new();
        let gga = line("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
        let mut bytes = Vec::new();
        bytes.extend_from_slice(b"noise\x00\xff");
        bytes.extend_from_slice(gga.as_bytes());
        bytes.extend_from_slice(b"\r\n");
        bytes.extend_from_slice(gga.as_bytes());
        bytes.push(b'\n');
        bytes.extend_from_slice(gga.as_bytes());
        bytes.push(b'\r');
        bytes.extend_from_slice(b"$GPGGA,\x01\x02binary\r\n");
        bytes.extend_from_slice(format!("${}\r\n", "A".repeat(300)).as_bytes());
        bytes.extend_from_slice(
            b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*00\r\n",
        );
        for c in bytes.chunks(7) {
            d.push_bytes(c, &mut fixes);
        }
        let st = d.stats();
        assert_eq!(fixes.len(), 3, "{st:?}");
        assert!((fixes[0].lat_deg - 48.1173).abs() < 1e-9);
        assert!((fixes[0].lon_deg - 11.516_666_666).abs() < 1e-6);
        assert_eq!(st.binary_lines, 1);
        assert_eq!(st.overlong_lines, 1);
        assert_eq!(st.bad_checksum, 1);
        assert!(st.garbage_bytes >= 7);
    }

    /// Every sentence of an epoch whose time stepped back is flagged, not only the first (the
    /// RMC after the GGA: a fix tied by its time must not be tied ten seconds back); a clock
    /// that stays back (a receiver reset) is followed after a few fixes.
    #[test]
    fn a_step_back_flags_the_whole_epoch_and_a_reset_clock_is_followed() {
        let mut d = GpsDecoder::default();
        let at = |hms: &str| {
            line(&format!(
                "GPGGA,{hms},4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"
            ))
        };
        let back = |d: &mut GpsDecoder, hms: &str| match d.line(&at(hms)) {
            LineOutcome::Fix(f) => f.time_backwards,
            other => panic!("{other:?}"),
        };
        assert!(!back(&mut d, "120014"));
        assert!(back(&mut d, "120005"));
        assert!(back(&mut d, "120005"), "the epoch's second sentence");
        assert!(!back(&mut d, "120016"));
        // a reset: the clock stays an hour back
        let flagged: Vec<bool> = (0..10)
            .map(|i| back(&mut d, &format!("1100{:02}", 20 + i)))
            .collect();
        let n = BACKWARDS_ACCEPTED as usize;
        assert!(
            flagged[..n].iter().all(|b| *b) && flagged[n..].iter().all(|b| !b),
            "{flagged:?}"
        );
    }

    #[test]
    fn impossible_values_and_backward_time_are_caught() {
        let mut d = GpsDecoder::default();
        let far = line("GPGGA,123519,9907.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
        assert!(matches!(d.line(&far), LineOutcome::OutOfRange(_)));
        let a = line("GPGGA,123520,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
        let b = line("GPGGA,123510,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
        assert!(matches!(d.line(&a), LineOutcome::Fix(f) if !f.time_backwards));
        assert!(matches!(d.line(&b), LineOutcome::Fix(f) if f.time_backwards));
        let none = line("GPGGA,123521,4807.038,N,01131.000,E,0,00,,,M,,M,,");
        assert!(matches!(d.line(&none), LineOutcome::Fix(f) if !f.valid));
        let st = d.stats();
        assert_eq!((st.out_of_range, st.time_backwards, st.no_fix), (1, 1, 1));
    }

    /// GGA's altitude is above the geoid; the filter navigates in ellipsoid heights: the
    /// separation is added where the sentence gives one, and the altitude taken as it is where
    /// it does not.
    #[test]
    fn ellipsoid_height_is_the_altitude_plus_the_geoid_separation() {
        let mut d = GpsDecoder::default();
        let with = line("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
        let without = line("GPGGA,123520,4807.038,N,01131.000,E,1,08,0.9,545.4,M,,M,,");
        let height = |d: &mut GpsDecoder, l: &str| match d.line(l) {
            LineOutcome::Fix(f) => (f.alt_m, f.geoid_sep_m, f.ellipsoid_height_m()),
            o => panic!("{o:?}"),
        };
        let near = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 1e-4);
        let (alt, sep, h) = height(&mut d, &with);
        assert!(
            near(alt, 545.4) && near(sep, 46.9) && near(h, 592.3),
            "{alt:?} {sep:?} {h:?}"
        );
        let (alt, sep, h) = height(&mut d, &without);
        assert!(near(alt, 545.4) && sep.is_none() && near(h, 545.4), "{h:?}");
    }

    #[test]
    fn nmea_2_0_gll_without_mode_is_read() {
        let mut d = GpsDecoder::default();
        let l = line("GPGLL,4527.458,S,16709.165,E,225309,A");
        match d.line(&l) {
            LineOutcome::Fix(f) => {
                assert!((f.lat_deg + 45.457_633_333).abs() < 1e-6);
                assert!((f.lon_deg - 167.152_75).abs() < 1e-6);
                assert_eq!(f.time.as_deref(), Some("22:53:09.000"));
            }
            o => panic!("{o:?}"),
        }
    }
}
