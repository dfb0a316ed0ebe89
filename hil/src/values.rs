//! The command line's numbers, checked where they are parsed: one value parser per kind of
//! quantity, each with its range. clap names the flag and the value in its error
//! ("invalid value 'nan' for '--heading <HEADING>'"); the parser says what the range is. A NaN, an
//! infinity or a dwell of 31 years never reaches a run.

/// A finite number within `[lo, hi]`, in `unit`.
fn within(s: &str, lo: f64, hi: f64, what: &str, unit: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("not a number: {what} is a number from {lo} to {hi} {unit}"))?;
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(format!(
            "{what} must be a number from {lo} to {hi} {unit}, got {v}"
        ))
    }
}

/// A finite number above 0 and at most `hi`, in `unit`.
fn positive(s: &str, hi: f64, what: &str, unit: &str) -> Result<f64, String> {
    let range = format!("above 0 and at most {hi} {unit}");
    match within(s, 0.0, hi, what, unit) {
        Ok(v) if v > 0.0 => Ok(v),
        Err(e) if e.starts_with("not a number") => Err(format!("not a number: {what} is {range}")),
        _ => Err(format!(
            "{what} must be {range}, got {}",
            s.trim().parse::<f64>().unwrap_or(f64::NAN)
        )),
    }
}

/// The longest stretch of simulated time a flag may ask for: a day.
pub const MAX_DURATION_S: f64 = 86_400.0;

/// The fastest speed factor over real time a run may ask for.
pub const MAX_SPEED: f64 = 100_000.0;

/// Latitude, deg: -90 to 90.
pub fn latitude_deg(s: &str) -> Result<f64, String> {
    within(s, -90.0, 90.0, "a latitude", "deg")
}

/// A heading or an angle about the vertical, deg: -360 to 360.
pub fn heading_deg(s: &str) -> Result<f64, String> {
    within(s, -360.0, 360.0, "a heading", "deg")
}

/// A tilt (pitch, roll), deg: -90 to 90.
pub fn tilt_deg(s: &str) -> Result<f64, String> {
    within(s, -90.0, 90.0, "a tilt", "deg")
}

/// An angular tolerance, deg: above 0, at most 180.
pub fn tolerance_deg(s: &str) -> Result<f64, String> {
    positive(s, 180.0, "a tolerance", "deg")
}

/// A stretch of simulated time that must last (a dwell, a turn, a run), s: above 0, at most a
/// day.
pub fn duration_s(s: &str) -> Result<f64, String> {
    positive(s, MAX_DURATION_S, "a duration", "s")
}

/// A stretch of simulated time that may be none (a rest, a delay), s: 0 to a day.
pub fn pause_s(s: &str) -> Result<f64, String> {
    within(s, 0.0, MAX_DURATION_S, "a pause", "s")
}

/// A speed factor over real time: above 0, at most [`MAX_SPEED`].
pub fn speed(s: &str) -> Result<f64, String> {
    positive(s, MAX_SPEED, "a speed factor", "(1 = real time)")
}

/// A turning rate, deg/s: above 0, at most 1000.
pub fn rate_dps(s: &str) -> Result<f64, String> {
    positive(s, 1000.0, "a rate", "deg/s")
}

/// A gyro's noise per sample, deg/s: 0 to 1.
pub fn noise_dps(s: &str) -> Result<f64, String> {
    within(s, 0.0, 1.0, "a noise", "deg/s")
}

/// A CAN bit rate, bit/s: 10 kbit/s to 8 Mbit/s (CAN FD's data phase at most).
pub fn bitrate(s: &str) -> Result<f64, String> {
    within(s, 10_000.0, 8_000_000.0, "a bit rate", "bit/s")
}

/// A receiver's size the filter assumes, m per axis in all: above 0, at most 10 km.
pub fn sigma_m(s: &str) -> Result<f64, String> {
    positive(s, 10_000.0, "a sigma", "m")
}

/// A frequency step, Hz: above 0, at most 1000.
pub fn step_hz(s: &str) -> Result<f64, String> {
    positive(s, 1000.0, "a frequency step", "Hz")
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
}
