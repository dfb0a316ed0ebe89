//! A drive from a recorded track: the file a vehicle's receiver, a handheld or in-car logger, or
//! a post-processed reference system wrote on a real drive, turned into a road the bench can
//! drive.
//!
//! Three layers, each on its own: reading a file into points with their times ([`formats`]: GPX
//! 1.0 and 1.1, NMEA GGA/RMC logs, CSV reference trajectories), cleaning and fitting the points
//! into the corners, heights, times and stops of a road ([`fit`]: outliers dropped, jitter
//! averaged out, gaps bridged, each said), and planning that road as any other
//! ([`super::plan`]: the legs are laid on the ellipsoid between the corners' latitudes and
//! longitudes, the speed of each leg set so the vehicle passes each corner when the track did).
//!
//! Every refusal names the file, the line or point, and what is wrong; nothing is dropped
//! without being counted in [`TrackNotes`].

pub mod fit;
pub mod formats;
mod legs;
pub mod logger;

use serde::Serialize;
use std::path::Path;

/// One point of a track, as the file gave it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrackPoint {
    /// Time, s (UTC seconds since 1970, or the file's own zero where it gives no date).
    pub t: f64,
    /// Latitude and longitude, deg.
    pub lat_deg: f64,
    /// See [`TrackPoint::lat_deg`].
    pub lon_deg: f64,
    /// Height above the WGS-84 ellipsoid, m (elevations above mean sea level are turned into
    /// it with EGM2008's geoid), when the file gives one.
    pub h_m: Option<f64>,
    /// Heading, deg clockwise from north, when the file gives one (a reference system's, or a
    /// receiver's course over ground).
    pub heading_deg: Option<f64>,
    /// Horizontal speed, m/s, when the file gives one.
    pub speed_mps: Option<f64>,
    /// Pitch and roll, deg, when the file gives them (a reference system's).
    pub pitch_roll_deg: Option<[f64; 2]>,
    /// Line of the file, from 1.
    pub line: usize,
    /// Number of the point in the file, from 1.
    pub index: usize,
}

impl TrackPoint {
    /// Where the point is in its file, for people: "point 17 (line 42)".
    pub fn at(&self) -> String {
        format!("point {} (line {})", self.index, self.line)
    }
}

/// The formats read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Format {
    /// GPX 1.0 or 1.1 (`trkpt`).
    Gpx,
    /// NMEA-0183 GGA and RMC sentences.
    Nmea,
    /// A CSV reference trajectory with a header line.
    Csv,
}

/// A track as read: its points in the file's order and what reading it skipped.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Track {
    /// The file's name, for messages.
    pub file: String,
    /// Its format.
    pub format: Format,
    /// The points, in the file's order.
    pub points: Vec<TrackPoint>,
    /// Lines or points read but not used, each with its place and why (a sentence with a bad
    /// checksum, a receiver without a fix).
    pub skipped: Vec<String>,
}

/// A track the bench cannot drive: the file, where in it, and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("track {file}: {at}: {what}")]
pub struct TrackError {
    /// The file.
    pub file: String,
    /// Where in it ("line 12", "point 4 (line 9)", "the whole file").
    pub at: String,
    /// What is wrong.
    pub what: String,
}

impl TrackError {
    pub(crate) fn new(file: &str, at: impl Into<String>, what: impl Into<String>) -> Self {
        Self {
            file: file.to_string(),
            at: at.into(),
            what: what.into(),
        }
    }
}

/// Read a track file; the format is told from its content (`<gpx`, `$..GGA`/`$..RMC` lines,
/// or else a CSV header).
pub fn read(path: &Path) -> Result<Track, TrackError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path)
        .map_err(|e| TrackError::new(&name, "the whole file", format!("cannot read it: {e}")))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        TrackError::new(
            &name,
            format!("byte {}", e.utf8_error().valid_up_to()),
            "not UTF-8 text: a track is a GPX, NMEA or CSV text file",
        )
    })?;
    parse(&text, &name)
}

/// Parse a track's text (`name` for messages).
pub fn parse(text: &str, name: &str) -> Result<Track, TrackError> {
    let head = text.trim_start_matches('\u{feff}').trim_start();
    let track = if head.starts_with("<?xml") || head.starts_with("<gpx") {
        formats::gpx(text, name)?
    } else if text.lines().take(50).any(|l| {
        // a sentence: `$`, its address (a talker and a type, or a maker's: letters and
        // digits), a comma
        l.find('$').is_some_and(|i| {
            let addr = l[i + 1..].split(',').next().unwrap_or("");
            (2..=6).contains(&addr.len())
                && addr.bytes().all(|c| c.is_ascii_alphanumeric())
                && l.len() > i + 1 + addr.len()
        })
    }) {
        formats::nmea(text, name)?
    } else {
        formats::csv(text, name)?
    };
    if track.points.is_empty() {
        return Err(TrackError::new(
            name,
            "the whole file",
            match track.skipped.first() {
                Some(s) => format!(
                    "no usable point ({} skipped, the first: {s})",
                    track.skipped.len()
                ),
                None => "no point with a position and a time".to_string(),
            },
        ));
    }
    Ok(track)
}

/// What the bench did with a track and how close it drives it, for people: said by `hil plan
/// track` and kept with the plan.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct TrackNotes {
    /// Points read, and points the fit used.
    pub points_read: usize,
    /// See [`TrackNotes::points_read`].
    pub points_used: usize,
    /// Points dropped, each with its place and why.
    pub dropped: Vec<String>,
    /// Their numbers in the file (from 1), for a picture.
    pub dropped_points: Vec<usize>,
    /// What the bench had to assume (no elevations, gaps bridged, a jitter it estimated).
    pub assumed: Vec<String>,
    /// The track's jitter about the fitted road, m (RMS of the points' distances from it,
    /// stops excluded): the fit's tolerance is set from it.
    pub jitter_m: f64,
    /// The driven road's horizontal distance from the track's points, m: RMS, worst, and the
    /// worst point's place.
    pub distance_rms_m: f64,
    /// See [`TrackNotes::distance_rms_m`].
    pub distance_max_m: f64,
    /// See [`TrackNotes::distance_rms_m`].
    pub distance_max_at: String,
    /// The driven time at each point less the track's, s: RMS and worst.
    pub time_rms_s: f64,
    /// See [`TrackNotes::time_rms_s`].
    pub time_max_s: f64,
    /// Stops found: (place, seconds standing).
    pub stops: Vec<(String, f64)>,
    /// Corners the road turns at.
    pub corners: usize,
    /// The drive's time less the track's (the scenario's standing before the track), s.
    pub start_wait_s: f64,
}

#[cfg(test)]
mod tests;
