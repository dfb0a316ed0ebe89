//! The procedures the pipeline can run on the mechanism at start, as the pipeline sees them: the
//! inputs each takes beyond the mechanism's frames, the IMU time it runs on, nav's mode while it
//! runs, what it hands on when done (a heading, a parameter file) and its part of the summary.
//! [`REGISTRY`] lists them; the pipeline knows none of them by name.
//!
//! A new procedure: its file (settings, phases, steps on [`crate::procedure::Core`]), its
//! [`Mission`] here, a line in [`REGISTRY`] and its field in the summary.

use crate::config::NavConfig;
use crate::imu::ImuSample;
use crate::northfind::NorthFinder;
use crate::params::ParameterFile;
use crate::procedure::{Procedure, Reporting};
use crate::selfcal::{CalPhase, SelfCalibrationResult, SelfCalibrator};
use crate::summary::{
    NorthFindingSummary, SelfCalibrationSummary, Summary, TetraCalibrationSummary,
};
use crate::tetracal::{TetraCalibrator, TetraPhase};
use crate::ttlink::SettingError;
use std::any::Any;
use std::path::PathBuf;
use wire::{MemsGyro, NavMode};

/// A procedure on the mechanism as the pipeline runs it.
pub(crate) trait Mission: std::fmt::Debug {
    /// The procedure itself.
    fn procedure(&mut self) -> &mut dyn Procedure;
    /// The procedure itself, to read.
    fn procedure_ref(&self) -> &dyn Procedure;
    /// It runs on the processing chain's valid sample (its inputs are the chain's updates);
    /// else on the end of the last sample nav has.
    fn on_valid_sample(&self) -> bool {
        false
    }
    /// One IMU sample over `(t1 - dt, t1]`, IMU time, s.
    fn on_sample(&mut self, _t1: f64, _dt: f64, _s: &ImuSample) {}
    /// One update of the processing chain at IMU time `t`.
    fn on_update(&mut self, _t: f64, _phi: [f64; 3], _dv: [f64; 3]) {}
    /// A MEMS gyro frame after sample `k` (ending at `t`, samples `dt` long); true when it
    /// takes them.
    fn on_mems(&mut self, _k: u64, _t: f64, _dt: f64, _g: &MemsGyro) -> bool {
        false
    }
    /// nav's mode while it runs.
    fn mode(&self) -> NavMode;
    /// The heading it found, for navigation.
    fn heading_deg(&self) -> Option<f64> {
        None
    }
    /// It has just finished: the parameter file it made, and where its settings want it
    /// written (none: kept in the summary only).
    fn made(&mut self) -> Option<(Option<PathBuf>, ParameterFile)> {
        None
    }
    /// Its part of nav's summary.
    fn summarize(&self, rep: &Reporting, s: &mut Summary);
    /// For the pipeline's typed accessors.
    fn as_any(&self) -> &dyn Any;
}

/// What builds a procedure from nav's config (none when the config does not enable it).
pub(crate) type Make = fn(&NavConfig) -> Result<Option<Box<dyn Mission>>, SettingError>;

/// Every procedure nav can run at start, in the order the pipeline serves them.
pub(crate) const REGISTRY: [Make; 3] = [
    NorthFinding::make,
    SelfCalibration::make,
    TetraCalibration::make,
];

/// North-finding.
#[derive(Debug)]
pub(crate) struct NorthFinding {
    pub(crate) finder: NorthFinder,
}

impl NorthFinding {
    fn make(cfg: &NavConfig) -> Result<Option<Box<dyn Mission>>, SettingError> {
        if !cfg.north_finding.enabled {
            return Ok(None);
        }
        Ok(Some(Box::new(Self {
            finder: NorthFinder::new(cfg.north_finding.clone())?,
        })))
    }
}

impl Mission for NorthFinding {
    fn procedure(&mut self) -> &mut dyn Procedure {
        &mut self.finder
    }
    fn procedure_ref(&self) -> &dyn Procedure {
        &self.finder
    }
    fn on_valid_sample(&self) -> bool {
        true
    }
    fn on_update(&mut self, t: f64, phi: [f64; 3], dv: [f64; 3]) {
        self.finder.on_update(t, phi, dv);
    }
    fn mode(&self) -> NavMode {
        NavMode::NorthFinding
    }
    fn heading_deg(&self) -> Option<f64> {
        self.finder.result().map(|r| r.heading_deg)
    }
    fn summarize(&self, rep: &Reporting, s: &mut Summary) {
        let f = &self.finder;
        s.north_finding = Some(NorthFindingSummary {
            phase: f.phase(),
            result: f.result().cloned(),
            abort: f.abort().map(str::to_string),
            commands_sent: rep.commands_sent,
            turntable_frames: rep.frames,
            command_retries: f.ack_counters().0,
            stale_acks: f.ack_counters().1,
        });
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// The rotating IMU's self-calibration.
#[derive(Debug)]
pub(crate) struct SelfCalibration {
    pub(crate) cal: SelfCalibrator,
    /// The gyro parameters nav started with (the estimates are residuals on top of them).
    start: crate::params::GyroParameters,
    parameters: Option<crate::params::ImuParameters>,
}

impl SelfCalibration {
    fn make(cfg: &NavConfig) -> Result<Option<Box<dyn Mission>>, SettingError> {
        if !cfg.self_calibration.enabled {
            return Ok(None);
        }
        Ok(Some(Box::new(Self {
            cal: SelfCalibrator::new(cfg.self_calibration.clone())?,
            start: crate::params::GyroParameters {
                bias_dph: cfg.imu.gyro_bias_dph,
                scale_factor_ppm: cfg.imu.gyro_scale_factor_ppm,
            },
            parameters: None,
        })))
    }

    /// The parameter file of a result: the RLS's residual estimates composed with the
    /// parameters the front end applied (`(raw - b0) / (1 + k0)` read `(1 + k') w + b'`).
    fn parameters(&self, r: &SelfCalibrationResult) -> crate::params::ImuParameters {
        let c = self.cal.config();
        let (b0, k0) = (self.start.bias_dph, self.start.scale_factor_ppm);
        let mut g = self.start;
        for j in 0..3 {
            let k0f = k0[j] * 1e-6;
            g.bias_dph[j] = b0[j] + r.rls.gyro_bias_dph[j] * (1.0 + k0f);
            g.scale_factor_ppm[j] =
                ((1.0 + r.rls.gyro_scale_factor_ppm[j] * 1e-6) * (1.0 + k0f) - 1.0) * 1e6;
        }
        crate::params::ImuParameters {
            format: crate::params::FORMAT.into(),
            imu: c.imu.clone(),
            procedure: format!(
                "nav self-calibration (paper 004 decoupled RLS, integrated): dual-axis rotation at {} deg/s reversing every {} deg, inner axis {} s behind, {:.0} s, static base at latitude {} deg",
                c.rate_dps, c.turn_deg, c.inner_delay_s, r.rotation_s, c.latitude_deg
            ),
            // the shell stamps the date: the pipeline's output depends on its input only
            date: String::new(),
            gyro: g,
        }
    }
}

impl Mission for SelfCalibration {
    fn procedure(&mut self) -> &mut dyn Procedure {
        &mut self.cal
    }
    fn procedure_ref(&self) -> &dyn Procedure {
        &self.cal
    }
    fn on_sample(&mut self, t1: f64, dt: f64, s: &ImuSample) {
        self.cal.on_sample(t1, dt, s.dtheta, s.dv, s.saturated);
    }
    fn mode(&self) -> NavMode {
        match self.cal.phase() {
            CalPhase::Enabling | CalPhase::Levelling => NavMode::Levelling,
            _ => NavMode::Calibrating,
        }
    }
    fn made(&mut self) -> Option<(Option<PathBuf>, ParameterFile)> {
        let r = self.cal.result().cloned()?;
        let p = self.parameters(&r);
        self.parameters = Some(p.clone());
        Some((
            self.cal.config().parameters_out.clone(),
            ParameterFile::Imu(p),
        ))
    }
    fn summarize(&self, rep: &Reporting, s: &mut Summary) {
        let c = &self.cal;
        s.self_calibration = Some(SelfCalibrationSummary {
            phase: c.phase(),
            result: c.result().cloned(),
            abort: c.abort().map(str::to_string),
            parameters: self.parameters.clone(),
            parameters_file: None,
            commands_sent: rep.commands_sent,
            turntable_frames: rep.frames,
            command_retries: c.ack_counters().0,
            stale_acks: c.ack_counters().1,
        });
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// The redundant unit's calibration.
#[derive(Debug)]
pub(crate) struct TetraCalibration {
    pub(crate) cal: TetraCalibrator,
    parameters: Option<crate::params::RedundantParameters>,
}

impl TetraCalibration {
    fn make(cfg: &NavConfig) -> Result<Option<Box<dyn Mission>>, SettingError> {
        if !cfg.tetra_calibration.enabled {
            return Ok(None);
        }
        Ok(Some(Box::new(Self {
            cal: TetraCalibrator::new(cfg.tetra_calibration.clone())?,
            parameters: None,
        })))
    }
}

impl Mission for TetraCalibration {
    fn procedure(&mut self) -> &mut dyn Procedure {
        &mut self.cal
    }
    fn procedure_ref(&self) -> &dyn Procedure {
        &self.cal
    }
    fn on_mems(&mut self, k: u64, t: f64, dt: f64, g: &MemsGyro) -> bool {
        self.cal.on_mems(k, t, dt, g);
        true
    }
    fn mode(&self) -> NavMode {
        match self.cal.phase() {
            TetraPhase::Enabling => NavMode::Init,
            _ => NavMode::Calibrating,
        }
    }
    fn made(&mut self) -> Option<(Option<PathBuf>, ParameterFile)> {
        let p = self.cal.parameters()?;
        self.parameters = Some(p.clone());
        Some((
            self.cal.config().parameters_out.clone(),
            ParameterFile::Redundant(p),
        ))
    }
    fn summarize(&self, rep: &Reporting, s: &mut Summary) {
        let c = &self.cal;
        s.tetra_calibration = Some(TetraCalibrationSummary {
            parameters: self.parameters.clone(),
            parameters_file: None,
            phase: c.phase(),
            result: c.result().cloned(),
            abort: c.abort().map(str::to_string),
            commands_sent: rep.commands_sent,
            frames: rep.frames,
            command_retries: c.ack_counters().0,
            stale_acks: c.ack_counters().1,
        });
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
