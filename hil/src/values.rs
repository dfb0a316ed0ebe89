//! The command line's numbers and the scenario file's fields, checked where they are parsed:
//! one [`Kind`] per kind of quantity, each with its range, for flags and fields alike. clap names the flag and the value in its error
//! (`invalid value 'nan' for '--heading <HEADING>'`); the parser says what the range is. A NaN, an
//! infinity or a dwell of 31 years never reaches a run.

/// A kind of quantity: what it is called, its unit and its range. The command line's value
/// parsers and the scenario file's field checks both go through one of these.
#[derive(Debug, Clone, Copy)]
pub struct Kind {
    /// What it is, for messages ("a heading").
    pub what: &'static str,
    /// Its unit ("deg").
    pub unit: &'static str,
    /// Lowest value.
    pub lo: f64,
    /// Highest value.
    pub hi: f64,
    /// The lowest value itself is refused (a duration above 0).
    pub above_lo: bool,
}

impl Kind {
    const fn within(what: &'static str, unit: &'static str, lo: f64, hi: f64) -> Self {
        Self {
            what,
            unit,
            lo,
            hi,
            above_lo: false,
        }
    }

    const fn positive(what: &'static str, unit: &'static str, hi: f64) -> Self {
        Self {
            what,
            unit,
            lo: 0.0,
            hi,
            above_lo: true,
        }
    }

    /// The range in words.
    fn range(&self) -> String {
        if self.above_lo {
            format!("above {} and at most {} {}", self.lo, self.hi, self.unit)
        } else {
            format!("a number from {} to {} {}", self.lo, self.hi, self.unit)
        }
    }

    /// `v` when it is of this kind, else what is wrong with it.
    pub fn check(&self, v: f64) -> Result<f64, String> {
        let low_ok = if self.above_lo {
            v > self.lo
        } else {
            v >= self.lo
        };
        if v.is_finite() && low_ok && v <= self.hi {
            Ok(v)
        } else {
            Err(format!("{} must be {}, got {v}", self.what, self.range()))
        }
    }

    /// A command-line value of this kind.
    pub fn parse(&self, s: &str) -> Result<f64, String> {
        let range = self.range();
        let v: f64 = s
            .trim()
            .parse()
            .map_err(|_| format!("not a number: {} is {range}", self.what))?;
        self.check(v)
    }

    /// A scenario field `name` of this kind: `v`, or an error naming the field, the value and
    /// the range.
    pub fn field(&self, name: &str, v: f64) -> Result<f64, String> {
        self.check(v).map_err(|e| format!("{name}: {e}"))
    }
}

/// The longest stretch of simulated time a flag or a scenario may ask for: a day.
pub const MAX_DURATION_S: f64 = 86_400.0;

/// The fastest speed factor over real time a run may ask for.
pub const MAX_SPEED: f64 = 100_000.0;

/// Latitude, deg: -90 to 90.
pub const LATITUDE: Kind = Kind::within("a latitude", "deg", -90.0, 90.0);
/// Longitude, deg: -180 to 360 (east of Greenwich either way of writing it).
/// A latency budget, ms: 0 to 10 s.
pub const LATENCY_BUDGET: Kind = Kind::within("a latency budget", "ms", 0.0, 10_000.0);
/// Longitude, deg.
pub const LONGITUDE: Kind = Kind::within("a longitude", "deg", -180.0, 360.0);
/// Height above the ellipsoid, m: from below the Dead Sea's shore to above any road.
pub const HEIGHT: Kind = Kind::within("a height", "m", -1000.0, 10_000.0);
/// A heading or an angle about the vertical, deg.
pub const HEADING: Kind = Kind::within("a heading", "deg", -360.0, 360.0);
/// A tilt (pitch, roll), deg.
pub const TILT: Kind = Kind::within("a tilt", "deg", -90.0, 90.0);
/// An angular tolerance, deg.
pub const TOLERANCE: Kind = Kind::positive("a tolerance", "deg", 180.0);
/// A stretch of simulated time that must last (a dwell, a turn, a run), s.
pub const DURATION: Kind = Kind::positive("a duration", "s", MAX_DURATION_S);
/// A stretch of simulated time that may be none (a rest, a delay), s.
pub const PAUSE: Kind = Kind::within("a pause", "s", 0.0, MAX_DURATION_S);
/// A speed factor over real time.
pub const SPEED: Kind = Kind::positive("a speed factor", "(1 = real time)", MAX_SPEED);
/// A turning rate, deg/s.
pub const RATE: Kind = Kind::positive("a rate", "deg/s", 1000.0);
/// A gyro's noise per sample, deg/s.
pub const NOISE: Kind = Kind::within("a noise", "deg/s", 0.0, 1.0);
/// A CAN bit rate, bit/s (CAN FD's data phase at most).
pub const BITRATE: Kind = Kind::within("a bit rate", "bit/s", 10_000.0, 8_000_000.0);
/// A classic CAN bus's bit rate, bit/s (1 Mbit/s at most).
pub const CLASSIC_BITRATE: Kind =
    Kind::within("a classic CAN bit rate", "bit/s", 10_000.0, 1_000_000.0);
/// A size in metres (a receiver's sigma, a tolerance on position), m.
pub const SIGMA: Kind = Kind::positive("a sigma", "m", 10_000.0);
/// A frequency step, Hz.
pub const STEP_HZ: Kind = Kind::positive("a frequency step", "Hz", 1000.0);
/// A land vehicle's speed, m/s.
pub const VEHICLE_SPEED: Kind = Kind::positive("a vehicle's speed", "m/s", 100.0);
/// A land vehicle's acceleration, m/s^2.
pub const VEHICLE_ACCEL: Kind = Kind::positive("a vehicle's acceleration", "m/s^2", 20.0);
/// An offset on the vehicle (a lever arm), m.
pub const OFFSET: Kind = Kind::within("an offset on the vehicle", "m", -100.0, 100.0);

/// Latitude, deg: -90 to 90.
pub fn latitude_deg(s: &str) -> Result<f64, String> {
    LATITUDE.parse(s)
}

/// A latency budget, ms: 0 to 10,000.
pub fn latency_budget_ms(s: &str) -> Result<f64, String> {
    LATENCY_BUDGET.parse(s)
}

/// Longitude, deg: -180 to 360.
pub fn longitude_deg(s: &str) -> Result<f64, String> {
    LONGITUDE.parse(s)
}

/// A heading or an angle about the vertical, deg: -360 to 360.
pub fn heading_deg(s: &str) -> Result<f64, String> {
    HEADING.parse(s)
}

/// A tilt (pitch, roll), deg: -90 to 90.
pub fn tilt_deg(s: &str) -> Result<f64, String> {
    TILT.parse(s)
}

/// An angular tolerance, deg: above 0, at most 180.
pub fn tolerance_deg(s: &str) -> Result<f64, String> {
    TOLERANCE.parse(s)
}

/// A stretch of simulated time that must last (a dwell, a turn, a run), s: above 0, at most a
/// day.
pub fn duration_s(s: &str) -> Result<f64, String> {
    DURATION.parse(s)
}

/// A stretch of simulated time that may be none (a rest, a delay), s: 0 to a day.
pub fn pause_s(s: &str) -> Result<f64, String> {
    PAUSE.parse(s)
}

/// A speed factor over real time: above 0, at most [`MAX_SPEED`].
pub fn speed(s: &str) -> Result<f64, String> {
    SPEED.parse(s)
}

/// A turning rate, deg/s: above 0, at most 1000.
pub fn rate_dps(s: &str) -> Result<f64, String> {
    RATE.parse(s)
}

/// A gyro's noise per sample, deg/s: 0 to 1.
pub fn noise_dps(s: &str) -> Result<f64, String> {
    NOISE.parse(s)
}

/// A CAN bit rate, bit/s: 10 kbit/s to 8 Mbit/s (CAN FD's data phase at most).
pub fn bitrate(s: &str) -> Result<f64, String> {
    BITRATE.parse(s)
}

/// A receiver's size the filter assumes, m per axis in all: above 0, at most 10 km.
pub fn sigma_m(s: &str) -> Result<f64, String> {
    SIGMA.parse(s)
}

/// A frequency step, Hz: above 0, at most 1000.
pub fn step_hz(s: &str) -> Result<f64, String> {
    STEP_HZ.parse(s)
}

/// How many runs, passes or seeds: 1 to 1,000,000.
pub fn count(s: &str) -> Result<usize, String> {
    let v: usize = s
        .trim()
        .parse()
        .map_err(|_| "a count is a whole number from 1 to 1000000".to_string())?;
    if (1..=1_000_000).contains(&v) {
        Ok(v)
    } else {
        Err(format!("a count must be from 1 to 1000000, got {v}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The values a new user tried: a NaN heading, a 31-year dwell, a negative speed; each is
    /// refused with its range, and ordinary values pass.
    #[test]
    fn out_of_range_values_are_refused_with_their_range() {
        let e = heading_deg("nan").unwrap_err();
        assert!(e.contains("-360 to 360 deg") && e.contains("NaN"), "{e}");
        let e = duration_s("1e9").unwrap_err();
        assert!(
            e.contains("at most 86400 s") && e.contains("1000000000"),
            "{e}"
        );
        assert!(speed("-2").is_err() && speed("0").is_err() && speed("inf").is_err());
        assert!(latitude_deg("91").unwrap_err().contains("-90 to 90 deg"));
        assert!(latitude_deg("north").unwrap_err().contains("not a number"));
        assert!(count("0").is_err() && count("-3").is_err());
        assert_eq!(heading_deg("287.5"), Ok(287.5));
        assert_eq!(latitude_deg("-33.9"), Ok(-33.9));
        assert_eq!(pause_s("0"), Ok(0.0));
        assert_eq!(speed("25"), Ok(25.0));
        assert_eq!(count("8"), Ok(8));
    }

    /// A scenario field gets the same check, its name in front.
    #[test]
    fn a_field_out_of_range_is_named_with_its_range() {
        let e = HEADING.field("site.heading_deg", f64::NAN).unwrap_err();
        assert_eq!(
            e,
            "site.heading_deg: a heading must be a number from -360 to 360 deg, got NaN"
        );
        let e = DURATION.field("north_finding.dwell_s", 1e9).unwrap_err();
        assert!(
            e.starts_with("north_finding.dwell_s: a duration must be above 0"),
            "{e}"
        );
        assert_eq!(HEIGHT.field("site.height_m", -430.0), Ok(-430.0));
    }
}
