//! The calibration parameters bound to one IMU unit (paper 004's "binding of calibration
//! parameters"): a TOML file a calibration procedure writes and nav loads at start, named by the
//! `[calibration]` table of nav's config.
//!
//! ```toml
//! format = "rlg-hil.imu-parameters.v1"
//! imu = "FOG-0001"                       # the unit's serial number
//! procedure = "paper 004 decoupled RLS, dual-axis rotation, 900 s, static base"
//! date = "2026-11-24T01:00:00Z"          # RFC 3339
//! [gyro]
//! bias_dph = [0.0100, 0.0101, -0.0099]   # deg/h, taken off each gyro's rate
//! scale_factor_ppm = [10.0, 9.97, 9.97]  # ppm: rate = (output - bias) / (1 + sf)
//! ```
//!
//! The whole file is read and checked before anything is used: a missing, corrupt or
//! mismatched file is an error naming the file and the field, and nav does not start.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The file format this nav reads.
pub const FORMAT: &str = "rlg-hil.imu-parameters.v1";

/// Largest gyro bias accepted, deg/h (beyond it the file is not for a navigation-grade IMU).
pub const MAX_BIAS_DPH: f64 = 100.0;
/// Largest gyro scale-factor error accepted, ppm.
pub const MAX_SF_PPM: f64 = 10_000.0;

/// The parameter file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuParameters {
    /// [`FORMAT`].
    pub format: String,
    /// Serial number of the IMU unit the parameters belong to.
    pub imu: String,
    /// How they were found.
    pub procedure: String,
    /// When, RFC 3339.
    pub date: String,
    /// The gyros' parameters.
    pub gyro: GyroParameters,
}

/// Per-gyro parameters (x, y, z).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GyroParameters {
    /// Bias, deg/h.
    pub bias_dph: [f64; 3],
    /// Scale-factor error, ppm.
    pub scale_factor_ppm: [f64; 3],
}

/// Why a parameter file is refused.
#[derive(Debug, Error)]
pub enum ParamsError {
    /// Not readable.
    #[error("IMU parameter file {path}: cannot read it")]
    Read {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Not TOML of this form (toml names the field, line and column).
    #[error("IMU parameter file {path}: {source}")]
    Parse {
        /// File.
        path: PathBuf,
        /// Cause.
        source: toml::de::Error,
    },
    /// A field's value is wrong.
    #[error("IMU parameter file {path}: field `{field}`: {what}")]
    Field {
        /// File.
        path: PathBuf,
        /// The field.
        field: &'static str,
        /// What is wrong.
        what: String,
    },
}

/// Read `path`, parse it as `T` and check it with `check` (`Err((field, what))`): the whole
/// file before any of it is used.
fn load_checked<T: serde::de::DeserializeOwned>(
    path: &Path,
    format: &str,
    check: impl FnOnce(&T) -> Result<(), (&'static str, String)>,
) -> Result<T, ParamsError> {
    let text = std::fs::read_to_string(path).map_err(|source| ParamsError::Read {
        path: path.into(),
        source,
    })?;
    // another kind of parameter file is named as such, not as a field that does not fit
    if let Ok(t) = toml::from_str::<toml::Table>(&text)
        && let Some(f) = t.get("format").and_then(|f| f.as_str())
        && f != format
    {
        return Err(ParamsError::Field {
            path: path.into(),
            field: "format",
            what: format!("{f:?}, this nav reads {format:?} here"),
        });
    }
    let p: T = toml::from_str(&text).map_err(|source| ParamsError::Parse {
        path: path.into(),
        source,
    })?;
    check(&p).map_err(|(field, what)| ParamsError::Field {
        path: path.into(),
        field,
        what,
    })?;
    Ok(p)
}

/// The checks every parameter file shares: its format, its unit, its date.
fn check_header(
    format: &str,
    want_format: &str,
    unit: &str,
    want_unit: &str,
    date: &str,
) -> Result<(), (&'static str, String)> {
    if format != want_format {
        return Err((
            "format",
            format!("{format:?}, this nav reads {want_format:?}"),
        ));
    }
    if unit != want_unit {
        return Err((
            "imu",
            format!(
                "the parameters belong to unit {unit:?}, nav's config names unit {want_unit:?}"
            ),
        ));
    }
    if chrono::DateTime::parse_from_rfc3339(date).is_err() {
        return Err(("date", format!("{date:?} is not an RFC 3339 time")));
    }
    Ok(())
}

impl ImuParameters {
    /// Read and check the file `path` for the IMU with serial number `imu`.
    pub fn load(path: &Path, imu: &str) -> Result<Self, ParamsError> {
        load_checked(path, FORMAT, |p: &Self| p.check(imu))
    }

    /// The checks: format, unit, date, values in range. `Err((field, what))`.
    pub fn check(&self, imu: &str) -> Result<(), (&'static str, String)> {
        check_header(&self.format, FORMAT, &self.imu, imu, &self.date)?;
        let bad = |v: &[f64; 3], max: f64| v.iter().any(|x| !(x.is_finite() && x.abs() <= max));
        if bad(&self.gyro.bias_dph, MAX_BIAS_DPH) {
            return Err((
                "gyro.bias_dph",
                format!(
                    "{:?}: each must be a number within +-{MAX_BIAS_DPH} deg/h",
                    self.gyro.bias_dph
                ),
            ));
        }
        if bad(&self.gyro.scale_factor_ppm, MAX_SF_PPM) {
            return Err((
                "gyro.scale_factor_ppm",
                format!(
                    "{:?}: each must be a number within +-{MAX_SF_PPM} ppm",
                    self.gyro.scale_factor_ppm
                ),
            ));
        }
        Ok(())
    }

    /// The file's text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }
}

/// The file format of a redundant gyro unit's parameters.
pub const REDUNDANT_FORMAT: &str = "rlg-hil.redundant-gyro-parameters.v1";

/// Largest redundant-unit gyro bias accepted, deg/s.
pub const MAX_REDUNDANT_BIAS_DPS: f64 = 10.0;
/// Largest redundant-unit mounting angle accepted, deg.
pub const MAX_MOUNTING_DEG: f64 = 5.0;

/// A redundant gyro unit's parameters (paper 001's four gyros in a tetrahedron): what its
/// calibration on the three-axis table found, and what nav's parity monitor corrects the
/// outputs with when it starts from a file.
///
/// ```toml
/// format = "rlg-hil.redundant-gyro-parameters.v1"
/// imu = "MEMS-0001"
/// procedure = "paper 001 16-state Kalman filter, three-axis table, 360 s"
/// date = "2026-11-24T05:00:00Z"
/// [[gyro]]                 # gyro 1, then 2, 3, 4
/// bias_dps = 0.0502        # w_m = P.w + R_k.w sigma_j - R_j.w sigma_k - K P.w - B
/// scale_factor = 0.00203
/// sigma_j_deg = 0.0994
/// sigma_k_deg = -0.1008
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RedundantParameters {
    /// [`REDUNDANT_FORMAT`].
    pub format: String,
    /// Serial number of the unit.
    pub imu: String,
    /// How they were found.
    pub procedure: String,
    /// When, RFC 3339.
    pub date: String,
    /// The four gyros, in order.
    pub gyro: Vec<RedundantGyro>,
}

/// One gyro of a redundant unit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RedundantGyro {
    /// Bias `B`, deg/s.
    pub bias_dps: f64,
    /// Scale-factor error `K`.
    pub scale_factor: f64,
    /// Mounting angle about `R_j`, deg.
    pub sigma_j_deg: f64,
    /// Mounting angle about `R_k`, deg.
    pub sigma_k_deg: f64,
}

impl RedundantGyro {
    /// From the filter's coefficients (angles in rad).
    pub fn of(c: &crate::procedures::rotating_estimator::GyroCoefficients) -> Self {
        Self {
            bias_dps: c.bias_dps,
            scale_factor: c.scale_factor,
            sigma_j_deg: c.sigma_j.to_degrees(),
            sigma_k_deg: c.sigma_k.to_degrees(),
        }
    }

    /// As the filter's coefficients (angles in rad).
    pub fn coefficients(&self) -> crate::procedures::rotating_estimator::GyroCoefficients {
        crate::procedures::rotating_estimator::GyroCoefficients {
            bias_dps: self.bias_dps,
            scale_factor: self.scale_factor,
            sigma_j: self.sigma_j_deg.to_radians(),
            sigma_k: self.sigma_k_deg.to_radians(),
        }
    }
}

impl RedundantParameters {
    /// Read and check the file `path` for the unit with serial number `unit`.
    pub fn load(path: &Path, unit: &str) -> Result<Self, ParamsError> {
        load_checked(path, REDUNDANT_FORMAT, |p: &Self| p.check(unit))
    }

    /// The checks: format, unit, date, four gyros, values in range. `Err((field, what))`.
    pub fn check(&self, unit: &str) -> Result<(), (&'static str, String)> {
        check_header(&self.format, REDUNDANT_FORMAT, &self.imu, unit, &self.date)?;
        if self.gyro.len() != crate::procedures::rotating_estimator::TETRA_GYROS {
            return Err((
                "gyro",
                format!(
                    "{} gyros, the unit has {}",
                    self.gyro.len(),
                    crate::procedures::rotating_estimator::TETRA_GYROS
                ),
            ));
        }
        let within = |x: f64, m: f64| x.is_finite() && x.abs() <= m;
        for g in &self.gyro {
            if !(within(g.bias_dps, MAX_REDUNDANT_BIAS_DPS)
                && within(g.scale_factor, 0.1)
                && within(g.sigma_j_deg, MAX_MOUNTING_DEG)
                && within(g.sigma_k_deg, MAX_MOUNTING_DEG))
            {
                return Err((
                    "gyro",
                    format!(
                        "{g:?}: the bias within +-{MAX_REDUNDANT_BIAS_DPS} deg/s, the scale factor within +-0.1, the angles within +-{MAX_MOUNTING_DEG} deg"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The coefficients, per gyro.
    pub fn coefficients(
        &self,
    ) -> [crate::procedures::rotating_estimator::GyroCoefficients;
        crate::procedures::rotating_estimator::TETRA_GYROS] {
        std::array::from_fn(|i| {
            self.gyro
                .get(i)
                .map(RedundantGyro::coefficients)
                .unwrap_or_default()
        })
    }

    /// The file's text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }
}

/// A parameter file a procedure made, for the shell to date and write.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ParameterFile {
    /// A three-gyro IMU's.
    Imu(ImuParameters),
    /// A redundant unit's.
    Redundant(RedundantParameters),
}

impl ParameterFile {
    /// Stamp its date.
    pub fn set_date(&mut self, date: String) {
        match self {
            Self::Imu(p) => p.date = date,
            Self::Redundant(p) => p.date = date,
        }
    }

    /// The file's text.
    pub fn to_toml(&self) -> String {
        match self {
            Self::Imu(p) => p.to_toml(),
            Self::Redundant(p) => p.to_toml(),
        }
    }
}

/// The time now, RFC 3339 in UTC, to the second (a parameter file's `date`).
pub fn now_rfc3339() -> String {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as i64);
    chrono::DateTime::from_timestamp(now, 0)
        .map(|d| d.to_rfc3339_opts(chrono::SecondsFormat::Secs, true))
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
format = "rlg-hil.imu-parameters.v1"
imu = "FOG-0001"
procedure = "test"
date = "2026-11-24T01:00:00Z"
[gyro]
bias_dph = [0.01, 0.0101, -0.0099]
scale_factor_ppm = [10.0, 9.97, 9.97]
"#;

    fn load(text: &str, imu: &str) -> Result<ImuParameters, ParamsError> {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("gyro.toml");
        std::fs::write(&p, text).unwrap();
        ImuParameters::load(&p, imu)
    }

    #[test]
    fn a_good_file_loads_and_writes_back_the_same() {
        let p = load(GOOD, "FOG-0001").unwrap();
        assert_eq!(p.gyro.bias_dph[2], -0.0099);
        let again: ImuParameters = toml::from_str(&p.to_toml()).unwrap();
        assert_eq!(again, p);
    }

    /// Each way a file can be wrong is refused with the field named.
    #[test]
    fn a_bad_file_is_refused_naming_the_field() {
        let msg = |text: &str, imu: &str| load(text, imu).unwrap_err().to_string();
        assert!(msg(GOOD, "FOG-0002").contains("field `imu`"));
        let m = msg(&GOOD.replace("v1\"", "v9\""), "FOG-0001");
        assert!(m.contains("field `format`"), "{m}");
        let m = msg(
            &GOOD.replace("2026-11-24T01:00:00Z", "yesterday"),
            "FOG-0001",
        );
        assert!(m.contains("field `date`"), "{m}");
        let m = msg(&GOOD.replace("0.0101", "1e9"), "FOG-0001");
        assert!(m.contains("gyro.bias_dph"), "{m}");
        let m = msg(&GOOD.replace("9.97, 9.97]", "9.97]"), "FOG-0001");
        assert!(m.contains("scale_factor_ppm"), "{m}");
        let m = msg(&GOOD.replace("procedure = \"test\"\n", ""), "FOG-0001");
        assert!(m.contains("procedure"), "{m}");
        let m = msg(&format!("{GOOD}\nextra = 1\n"), "FOG-0001");
        assert!(m.contains("extra"), "{m}");
        let m = msg("format = \"rlg-hil.imu-param", "FOG-0001");
        assert!(m.contains("IMU parameter file"), "{m}");
        let e = ImuParameters::load(Path::new("/nonexistent/gyro.toml"), "x").unwrap_err();
        assert!(e.to_string().contains("/nonexistent/gyro.toml"));
    }

    /// The redundant unit's file: four gyros read and written back; not four, an angle out of
    /// range or the other kind of file are refused naming the field.
    #[test]
    fn the_redundant_units_file_round_trips_and_its_errors_name_the_field() {
        let g = RedundantGyro {
            bias_dps: 0.05,
            scale_factor: 2e-3,
            sigma_j_deg: 0.1,
            sigma_k_deg: -0.1,
        };
        let p = RedundantParameters {
            format: REDUNDANT_FORMAT.into(),
            imu: "MEMS-1".into(),
            procedure: "test".into(),
            date: "2026-11-24T01:00:00Z".into(),
            gyro: vec![g; 4],
        };
        let d = tempfile::tempdir().unwrap();
        let f = d.path().join("tetra.toml");
        std::fs::write(&f, p.to_toml()).unwrap();
        let back = RedundantParameters::load(&f, "MEMS-1").unwrap();
        assert_eq!(back, p);
        assert!((back.coefficients()[3].sigma_k - (-0.1f64).to_radians()).abs() < 1e-15);
        let field = |e: ParamsError| match e {
            ParamsError::Field { field, .. } => field,
            other => panic!("{other}"),
        };
        let mut three = p.clone();
        three.gyro.pop();
        std::fs::write(&f, three.to_toml()).unwrap();
        assert_eq!(
            field(RedundantParameters::load(&f, "MEMS-1").unwrap_err()),
            "gyro"
        );
        let mut tilted = p.clone();
        tilted.gyro[1].sigma_j_deg = 30.0;
        std::fs::write(&f, tilted.to_toml()).unwrap();
        assert_eq!(
            field(RedundantParameters::load(&f, "MEMS-1").unwrap_err()),
            "gyro"
        );
        std::fs::write(&f, GOOD).unwrap();
        assert_eq!(
            field(RedundantParameters::load(&f, "FOG-0001").unwrap_err()),
            "format"
        );
        std::fs::write(&f, p.to_toml()).unwrap();
        assert_eq!(
            field(ImuParameters::load(&f, "MEMS-1").unwrap_err()),
            "format"
        );
        assert_eq!(
            field(RedundantParameters::load(&f, "MEMS-2").unwrap_err()),
            "imu"
        );
    }
}
