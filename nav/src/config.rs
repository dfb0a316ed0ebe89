//! The `nav` config file (TOML). On a vehicle it names `can0` and `/dev/ttyS1`; on the bench it
//! names a vcan interface and a pty. Nothing else differs.

use crate::frontend::imu_frames::ImuCalibration;
use crate::frontend::processing::{ImuProcessor, ProcessingConfig};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Whole configuration.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NavConfig {
    /// CAN bus (IMU, turntable). Without it nav runs on the GPS alone (a receiver bring-up).
    #[serde(default)]
    pub can: Option<CanConfig>,
    /// GPS receiver on a serial port.
    #[serde(default)]
    pub gps: Option<GpsConfig>,
    /// IMU calibration bound to the unit.
    #[serde(default)]
    pub imu: ImuCalibration,
    /// The unit's calibration parameters from a file a calibration procedure wrote
    /// ([`crate::procedures::unit_parameters`]): its gyro biases and scale factors replace `[imu]`'s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationConfig>,
    /// Dither filter, coning and sculling compensation.
    #[serde(default)]
    pub processing: ProcessingConfig,
    /// Four-position north-finding on the indexing mechanism at start-up.
    #[serde(default)]
    pub north_finding: crate::procedures::north_finding::NorthFindingConfig,
    /// Self-calibration of a dual-axis rotating IMU at start-up (calibration mode).
    #[serde(default, skip_serializing_if = "is_off")]
    pub self_calibration: crate::procedures::self_calibration::SelfCalibrationConfig,
    /// Calibration of a redundant MEMS gyro unit on a three-axis table at start-up.
    #[serde(default, skip_serializing_if = "is_tetra_off")]
    pub tetra_calibration: crate::procedures::tetra_calibration::TetraCalibrationConfig,
    /// Navigation after start-up (levelling, hand-over, strapdown, SINS/GPS filter).
    #[serde(default)]
    pub navigation: crate::navigation::navigator::NavigationConfig,
    /// Liveness watchdog.
    #[serde(default)]
    pub watchdog: WatchdogConfig,
    /// Recording and reports.
    #[serde(default)]
    pub record: RecordConfig,
}

fn is_off(c: &crate::procedures::self_calibration::SelfCalibrationConfig) -> bool {
    !c.enabled
}

fn is_tetra_off(c: &crate::procedures::tetra_calibration::TetraCalibrationConfig) -> bool {
    !c.enabled
}

/// Where the IMU unit's calibration parameters come from.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CalibrationConfig {
    /// The IMU unit's serial number: the parameter file must name the same.
    pub imu: String,
    /// The parameter file (relative to the config file's folder).
    pub parameters: PathBuf,
}

/// CAN bus settings.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CanConfig {
    /// Interface name (`can0`, `vcan0`).
    pub interface: String,
    /// Socket receive buffer, bytes. Large enough to ride out scheduling hiccups at 4,000 frames/s.
    #[serde(default = "default_rcvbuf")]
    pub rcvbuf_bytes: usize,
}

/// GPS receiver settings.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GpsConfig {
    /// Where the receiver's sentences come from: its serial port (the default) or gpsd, the
    /// daemon through which a Linux vehicle shares one receiver.
    #[serde(default)]
    pub source: GpsSource,
    /// Serial device (`/dev/ttyUSB0`, `/dev/ttyS1`; on the bench a pty). Required with
    /// `source = "serial"`.
    #[serde(default)]
    pub port: PathBuf,
    /// Baud rate.
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// gpsd's address (`source = "gpsd"`), `host:port`.
    #[serde(default = "default_gpsd")]
    pub gpsd: String,
    /// With gpsd: the one device to watch (its path as gpsd knows it); all devices when absent.
    #[serde(default)]
    pub gpsd_device: Option<String>,
    /// Export of every decoded fix as JSON lines (relative to the config file).
    #[serde(default)]
    pub fixes_jsonl: Option<PathBuf>,
}

/// Where the GPS sentences come from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GpsSource {
    /// The receiver's serial port, read directly.
    #[default]
    Serial,
    /// gpsd over TCP: nav asks for the receiver's NMEA (`?WATCH={"nmea":true}`), which gpsd
    /// passes on as the device sent it (or generates from the fix for a binary-protocol
    /// receiver), and decodes it as from a port.
    Gpsd,
}

impl Default for GpsConfig {
    fn default() -> Self {
        Self {
            source: GpsSource::Serial,
            port: PathBuf::new(),
            baud: default_baud(),
            gpsd: default_gpsd(),
            gpsd_device: None,
            fixes_jsonl: None,
        }
    }
}

fn default_gpsd() -> String {
    "127.0.0.1:2947".into()
}

fn default_baud() -> u32 {
    9600
}

fn default_rcvbuf() -> usize {
    8 << 20
}

/// Watchdog settings (wall time: liveness only, never navigation time).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WatchdogConfig {
    /// Report an IMU timeout after this long without IMU frames.
    pub imu_timeout_ms: u64,
}

impl Default for WatchdogConfig {
    fn default() -> Self {
        Self {
            imu_timeout_ms: 500,
        }
    }
}

/// Recording settings. Relative paths are relative to the config file's folder.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RecordConfig {
    /// MCAP file of raw frames, decoded samples and events.
    pub mcap: Option<PathBuf>,
    /// JSON summary written at exit.
    pub summary: Option<PathBuf>,
}

/// Config file problems.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// Unreadable.
    #[error("cannot read config file {path}")]
    Read {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Not valid.
    #[error("config file {path}")]
    Parse {
        /// File.
        path: PathBuf,
        /// Cause.
        source: toml::de::Error,
    },
    /// The IMU parameter file named in `[calibration]` is refused.
    #[error(transparent)]
    Parameters(#[from] crate::procedures::unit_parameters::ParamsError),
    /// A value makes no sense.
    #[error("config file {path}: {what}")]
    Invalid {
        /// File.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
}

impl NavConfig {
    /// The files nav reads beyond its config (the parameter files), each with a name for a
    /// copy of it beside the config: `(the path, the copy's name)`.
    pub fn input_files_mut(&mut self) -> impl Iterator<Item = (&mut PathBuf, &'static str)> {
        let imu = self
            .calibration
            .as_mut()
            .map(|c| (&mut c.parameters, "nav-parameters.toml"));
        let tetra = self
            .tetra_calibration
            .parameters
            .as_mut()
            .map(|p| (p, "nav-tetra-parameters.toml"));
        imu.into_iter().chain(tetra)
    }

    /// Load and check a config file; relative record paths are resolved against its folder.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.into(),
            source,
        })?;
        Self::from_text(&text, path)
    }

    /// Parse and check a config's text; `path` names it in errors and anchors relative record
    /// paths.
    pub fn from_text(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let mut cfg: NavConfig = toml::from_str(text).map_err(|source| ConfigError::Parse {
            path: path.into(),
            source,
        })?;
        cfg.check().map_err(|what| ConfigError::Invalid {
            path: path.into(),
            what,
        })?;
        cfg.load_files(path)?;
        Ok(cfg)
    }

    /// The keys' values make sense together (what is wrong, when they do not).
    fn check(&self) -> Result<(), String> {
        if self.can.as_ref().is_some_and(|c| c.interface.is_empty()) {
            return Err("can.interface is empty".into());
        }
        if self.can.is_none() && self.gps.is_none() {
            return Err("names no device: give [can] and/or [gps]".into());
        }
        // the IMU's silence is told from a late loop by it, and the receiver's bytes wait up to
        // it for a frame received after them (nav::shell::arrival)
        if !(20..=600_000).contains(&self.watchdog.imu_timeout_ms) {
            return Err(format!(
                "watchdog.imu_timeout_ms = {}: from 20 ms (many IMU periods) to 600,000 ms",
                self.watchdog.imu_timeout_ms
            ));
        }
        if let Some(g) = &self.gps {
            match g.source {
                GpsSource::Serial if g.port.as_os_str().is_empty() => {
                    return Err(
                        "gps.port is missing (the receiver's serial device; or source = \"gpsd\")"
                            .into(),
                    );
                }
                GpsSource::Gpsd if !g.gpsd.contains(':') => {
                    return Err(format!(
                        "gps.gpsd ({:?}) must be host:port, e.g. \"127.0.0.1:2947\"",
                        g.gpsd
                    ));
                }
                _ => {}
            }
        }
        let c = &self.imu;
        if c.gyro_pulse_arcsec
            .iter()
            .chain(&c.accel_pulse_mps)
            .any(|w| !(w.is_finite() && *w > 0.0))
        {
            return Err("imu pulse weights must be positive".into());
        }
        if !(c.rate_hz > 0.0 && c.gyro_range_dps > 0.0 && c.accel_range_mps2 > 0.0) {
            return Err("imu.rate_hz, gyro_range_dps and accel_range_mps2 must be positive".into());
        }
        if (self.processing.fir.fs_hz - c.rate_hz).abs() > 1e-9 {
            return Err(format!(
                "processing.fir.fs_hz ({}) must equal imu.rate_hz ({})",
                self.processing.fir.fs_hz, c.rate_hz
            ));
        }
        if let Err(e) = self.north_finding.check() {
            return Err(e.to_string());
        }
        if self.self_calibration.enabled {
            if let Err(e) = self.self_calibration.check() {
                return Err(e.to_string());
            }
            if self.north_finding.enabled {
                return Err(
                    "self_calibration and north_finding both command the mechanism at start: enable one".into());
            }
            if self.self_calibration.rate_dps >= self.imu.gyro_range_dps {
                return Err(format!(
                    "self_calibration.rate_dps ({}) must stay below the gyros' range, imu.gyro_range_dps ({})",
                    self.self_calibration.rate_dps, self.imu.gyro_range_dps
                ));
            }
        }
        if self.tetra_calibration.enabled {
            if let Err(e) = self.tetra_calibration.check() {
                return Err(e.to_string());
            }
            if self.north_finding.enabled || self.self_calibration.enabled {
                return Err(
                    "tetra_calibration commands the table at start: north_finding and self_calibration must be off".into());
            }
        }
        self.navigation.check()?;
        if let Err(e) = ImuProcessor::new(&self.processing) {
            return Err(format!("processing: {e}"));
        }
        Ok(())
    }

    /// Paths relative to the config file at `path` made absolute, and the parameter files it
    /// names loaded into it.
    fn load_files(&mut self, path: &Path) -> Result<(), ConfigError> {
        self.load_input_files(path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        let gps_export = self.gps.as_mut().and_then(|g| g.fixes_jsonl.as_mut());
        for p in [
            &mut self.record.mcap,
            &mut self.record.summary,
            &mut self.self_calibration.parameters_out,
            &mut self.tetra_calibration.parameters_out,
        ]
        .into_iter()
        .flatten()
        .chain(gps_export)
        {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        }
        Ok(())
    }

    /// The parameter files the config names ([`NavConfig::input_files_mut`]), relative to the
    /// config file at `path`, loaded into it: what [`NavConfig::load`] does with them after
    /// parsing, for a config that came another way (deserialized: what it held of them is not
    /// serialized). Output paths are left as they are.
    pub fn load_input_files(&mut self, path: &Path) -> Result<(), ConfigError> {
        let base = path.parent().unwrap_or(Path::new("."));
        if let Some(c) = self.calibration.as_mut() {
            if c.parameters.is_relative() {
                c.parameters = base.join(&c.parameters);
            }
            let p = crate::procedures::unit_parameters::ImuParameters::load(&c.parameters, &c.imu)?;
            let imu = &mut self.imu;
            let zero = [0.0; 3];
            for (inline, from_file, name) in [
                (&mut imu.gyro_bias_dph, p.gyro.bias_dph, "gyro_bias_dph"),
                (
                    &mut imu.gyro_scale_factor_ppm,
                    p.gyro.scale_factor_ppm,
                    "gyro_scale_factor_ppm",
                ),
            ] {
                if *inline != zero && *inline != from_file {
                    return Err(ConfigError::Invalid {
                        path: path.into(),
                        what: format!(
                            "imu.{name} is given here and, differently, in the parameter file {}: keep one",
                            c.parameters.display()
                        ),
                    });
                }
                *inline = from_file;
            }
        }
        // the redundant unit's parameter file, when the procedure starts from one
        let t = &mut self.tetra_calibration;
        if t.enabled
            && let Some(p) = t.parameters.as_mut()
        {
            if p.is_relative() {
                *p = base.join(&*p);
            }
            let f = crate::procedures::unit_parameters::RedundantParameters::load(p, &t.imu)?;
            t.coefficients = Some(f.coefficients());
        }
        Ok(())
    }

    /// Serialize (the bench writes configs with this).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Found by `hil fuzz`: a 1 Hz passband made the fitted coning coefficients' system
    /// singular and nav panicked at start-up; it must refuse the config and say why.
    #[test]
    fn a_degenerate_coning_fit_is_refused_not_fatal() {
        let text = "[can]\ninterface = \"can0\"\n[processing.fir]\npassband_hz = 1.0\n";
        let e = NavConfig::from_text(text, Path::new("/etc/nav.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/etc/nav.toml") && e.contains("coning"), "{e}");
    }

    #[test]
    fn minimal_config_loads_with_defaults_and_resolves_paths() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("nav.toml");
        std::fs::write(
            &p,
            "[can]\ninterface = \"can0\"\n[record]\nmcap = \"x.mcap\"\n",
        )
        .unwrap();
        let c = NavConfig::load(&p).unwrap();
        assert_eq!(c.can.as_ref().unwrap().interface, "can0");
        assert_eq!(c.imu, ImuCalibration::default());
        assert_eq!(
            c.record.mcap.as_deref(),
            Some(dir.path().join("x.mcap").as_path())
        );
        // and it round-trips through the writer
        std::fs::write(&p, c.to_toml()).unwrap();
        assert_eq!(NavConfig::load(&p).unwrap().can.unwrap().interface, "can0");
    }

    /// `[calibration]` names the unit and its parameter file: the file's gyro parameters go to
    /// the IMU front end; a file of another unit, or one that contradicts `[imu]`, stops nav.
    #[test]
    fn the_calibration_file_is_loaded_for_its_unit_only() {
        let dir = tempfile::tempdir().unwrap();
        let params = crate::procedures::unit_parameters::ImuParameters {
            format: crate::procedures::unit_parameters::FORMAT.into(),
            imu: "FOG-7".into(),
            procedure: "test".into(),
            date: crate::procedures::unit_parameters::now_rfc3339(),
            gyro: crate::procedures::unit_parameters::GyroParameters {
                bias_dph: [0.01, -0.02, 0.03],
                scale_factor_ppm: [10.0, 11.0, 12.0],
            },
        };
        std::fs::write(dir.path().join("gyro.toml"), params.to_toml()).unwrap();
        let p = dir.path().join("nav.toml");
        let write = |text: &str| {
            std::fs::write(&p, format!("[can]\ninterface = \"can0\"\n{text}")).unwrap()
        };
        write("[calibration]\nimu = \"FOG-7\"\nparameters = \"gyro.toml\"\n");
        let c = NavConfig::load(&p).unwrap();
        assert_eq!(c.imu.gyro_bias_dph, [0.01, -0.02, 0.03]);
        assert_eq!(c.imu.gyro_scale_factor_ppm, [10.0, 11.0, 12.0]);
        // what the bench writes back loads again
        std::fs::write(&p, c.to_toml()).unwrap();
        assert_eq!(NavConfig::load(&p).unwrap().imu, c.imu);
        write("[calibration]\nimu = \"FOG-8\"\nparameters = \"gyro.toml\"\n");
        let e = NavConfig::load(&p).unwrap_err().to_string();
        assert!(e.contains("field `imu`") && e.contains("FOG-8"), "{e}");
        let mut other = c.clone();
        other.imu.gyro_bias_dph = [1.0, 0.0, 0.0];
        std::fs::write(&p, other.to_toml()).unwrap();
        let e = NavConfig::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("imu.gyro_bias_dph") && e.contains("keep one"),
            "{e}"
        );
        write("[calibration]\nimu = \"FOG-7\"\nparameters = \"missing.toml\"\n");
        let e = NavConfig::load(&p).unwrap_err().to_string();
        assert!(e.contains("missing.toml"), "{e}");
    }

    /// A `[gps]` names its source: a serial port, or gpsd at host:port; what is missing is said.
    #[test]
    fn the_gps_source_is_a_port_or_gpsd() {
        let load = |gps: &str| NavConfig::from_text(&format!("[gps]\n{gps}"), Path::new("n.toml"));
        let c = load("port = \"/dev/ttyUSB0\"\n").unwrap().gps.unwrap();
        assert_eq!((c.source, c.baud), (GpsSource::Serial, 9600));
        let e = load("baud = 4800\n").unwrap_err().to_string();
        assert!(e.contains("gps.port is missing"), "{e}");
        let c = load("source = \"gpsd\"\n").unwrap().gps.unwrap();
        assert_eq!(
            (c.source, c.gpsd.as_str()),
            (GpsSource::Gpsd, "127.0.0.1:2947")
        );
        let e = load("source = \"gpsd\"\ngpsd = \"localhost\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("host:port"), "{e}");
        let e = full(load("source = \"usb\"\n").unwrap_err());
        assert!(e.contains("usb") && e.contains("serial"), "{e}");
    }

    /// The message with its causes, as the binaries print it.
    fn full(e: ConfigError) -> String {
        format!("{:#}", anyhow::Error::from(e))
    }

    #[test]
    fn bad_configs_name_the_file_and_the_problem() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("nav.toml");
        std::fs::write(&p, "[can]\ninterfac = \"can0\"\n").unwrap();
        let e = full(NavConfig::load(&p).unwrap_err());
        assert!(e.contains("nav.toml") && e.contains("interfac"), "{e}");
        std::fs::write(&p, "[can]\ninterface = \"can0\"\n[imu]\ngyro_pulse_arcsec = [1.0, 0.0, 1.0]\naccel_pulse_mps=[1e-4,1e-4,1e-4]\ngyro_range_dps=1\naccel_range_mps2=1\nrate_hz=2000\n").unwrap();
        let e = full(NavConfig::load(&p).unwrap_err());
        assert!(e.contains("pulse weights"), "{e}");
        std::fs::write(
            &p,
            "[can]\ninterface = \"can0\"\n[processing.fir]\norder = 20\n",
        )
        .unwrap();
        let e = full(NavConfig::load(&p).unwrap_err());
        assert!(e.contains("processing") && e.contains("order 20"), "{e}");
        std::fs::write(
            &p,
            "[can]\ninterface = \"can0\"\n[navigation.filter]\nkind = \"adaptive\"\nadaptive_forgetting = 1.5\n",
        )
        .unwrap();
        let e = full(NavConfig::load(&p).unwrap_err());
        assert!(e.contains("navigation.filter.adaptive_forgetting"), "{e}");
        std::fs::write(
            &p,
            "[can]\ninterface = \"can0\"\n[watchdog]\nimu_timeout_ms = 0\n",
        )
        .unwrap();
        let e = full(NavConfig::load(&p).unwrap_err());
        assert!(e.contains("watchdog.imu_timeout_ms = 0"), "{e}");
        let e = NavConfig::load(&dir.path().join("missing.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.toml"), "{e}");
    }
}
