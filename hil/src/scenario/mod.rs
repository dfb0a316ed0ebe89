//! Scenario files (TOML): what the emulated vehicle does and how its sensors err.

pub mod busload;
pub mod fogunit;
pub mod lab_contract;
pub mod navconfig;
pub mod route;
pub mod trackview;
pub mod variant;

use anyhow::{Context, Result, bail};
use emulators::adapters::transport::BusFaults;
use emulators::drive::{Drive, DriveSpec};
use emulators::gps::ReceiverParams;
use emulators::imu::ImuParams;
use emulators::truth::{
    Composed, Coning, Disturbance, Disturbances, Indexer, Motion, RelativeRotation, Static,
    Vibration,
};
use emulators::turntable::{ProfileAxis, Turntable, TurntableParams};
use nav::frontend::processing::ProcessingConfig;
use nav::navigation::navigator::NavigationConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A bench scenario.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Name (used for run folders; default: the file's name).
    #[serde(default)]
    pub name: String,
    /// Simulated duration, s (a drive from a track: default, the track's drive and 5 s).
    #[serde(default = "unset")]
    pub duration_s: f64,
    /// Speed factor (1.0 real time).
    #[serde(default = "one")]
    pub speed: f64,
    /// Largest fraction of IMU frames the bus may lose before the run fails.
    #[serde(default)]
    pub max_bus_loss: f64,
    /// Where the vehicle is parked (a drive from a track: default, the track's start).
    #[serde(default = "unset_site")]
    pub site: Static,
    /// Classical coning on a lab fixture instead of the parked vehicle (inertial; the site then
    /// only names the place).
    #[serde(default)]
    pub coning: Option<Coning>,
    /// A drive along waypoints instead of standing at the site.
    #[serde(default)]
    pub drive: Option<DriveSpec>,
    /// The indexing mechanism the IMU sits on (none: the IMU is fixed to the vehicle).
    #[serde(default)]
    pub turntable: Option<TurntableParams>,
    /// nav runs four-position north-finding (needs a turntable); the run ends when it reports.
    #[serde(default)]
    pub north_finding: Option<nav::procedures::north_finding::NorthFindingConfig>,
    /// nav runs its self-calibration of a dual-axis rotating IMU (needs a turntable of two or
    /// more axes); the run ends when it reports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub self_calibration: Option<nav::procedures::self_calibration::SelfCalibrationConfig>,
    /// nav calibrates the redundant MEMS unit (`[imu.tetra]`) on a three-axis table; the run
    /// ends when it reports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tetra_calibration: Option<nav::procedures::tetra_calibration::TetraCalibrationConfig>,
    /// An IMU parameter file nav loads at start (`[calibration]`), for the emulated unit
    /// ([`Scenario::unit_id`]); e.g. what an earlier self-calibration wrote.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nav_parameters: Option<std::path::PathBuf>,
    /// A drill passes when the heading error is within this, deg.
    #[serde(default = "default_tolerance")]
    pub heading_tolerance_deg: f64,
    /// Disturbances of the parked vehicle (door slams, climbing in, wind).
    #[serde(default)]
    pub disturbance: Vec<Disturbance>,
    /// Engine and road vibration on top of the motion.
    #[serde(default)]
    pub vibration: Option<Vibration>,
    /// nav's processing settings for this run (dither filter, coning algorithm).
    #[serde(default)]
    pub processing: ProcessingConfig,
    /// IMU parameters.
    #[serde(default)]
    pub imu: ImuParams,
    /// Faults injected on the bus.
    #[serde(default)]
    pub faults: BusFaults,
    /// The GPS receiver, writing NMEA on a pty nav reads (needs a `[drive]`: the antenna rides on
    /// it).
    #[serde(default)]
    pub gps: Option<ReceiverParams>,
    /// nav navigates with these settings (nav's own `[navigation]` table). Without north-finding
    /// and without `initial_heading_deg` nav is given the true heading at the start (a surveyed
    /// heading); an all-zero filter lever arm is taken from the receiver's installation.
    #[serde(default)]
    pub navigation: Option<NavigationConfig>,
    /// A navigation run passes when nav's horizontal position error at the end is within this, m.
    #[serde(default = "default_position_tolerance")]
    pub position_tolerance_m: f64,
    /// How the bench's bus runs (lockstep, nav's receive buffer).
    #[serde(default)]
    pub bus: BusSettings,
}

/// How the bench's bus runs.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BusSettings {
    /// The emulators follow nav's NAV_TIME frames so that a run depends on its scenario and seed
    /// only (default). Off: they run free at the scenario's speed, as hardware does; a nav that
    /// falls behind then loses frames in its socket, which the kernel counts and nav reports.
    #[serde(default = "yes")]
    pub lockstep: bool,
    /// nav's CAN receive buffer, bytes (`[can] rcvbuf_bytes` of its config; the kernel doubles
    /// it for its bookkeeping and has a floor of about 2 KiB).
    #[serde(default = "default_rcvbuf")]
    pub nav_rcvbuf_bytes: usize,
    /// The bus's bit rate, bit/s (classic CAN: 1 Mbit/s at most). A scenario whose traffic
    /// does not fit it with worst-case bit stuffing is refused, with the figures.
    #[serde(default = "default_bitrate")]
    pub bitrate_bps: f64,
    /// `model` (default): the devices' frames reach vcan in the order, and at the simulated
    /// times, they would complete on a real bus of this bit rate (frame durations with their
    /// stuff bits, arbitration by identifier, a transmit queue per node; nav's frames on it
    /// too). `ideal`: vcan's own timing, every frame there the moment it is due.
    #[serde(default)]
    pub timing: TimingModel,
    /// Depth of each node's transmit queue on the model, frames: a frame queued on a full
    /// queue is lost and counted.
    #[serde(default = "default_tx_queue")]
    pub tx_queue_frames: usize,
    /// Faults of the physical layer on the bus model (`[bus.faults]`): a disturbed harness
    /// (error frames), a stuck-dominant bus, a babbling node, a node's faulty transmitter
    /// (error-passive, bus-off and recovery; `node = "NAV"`: nav's own controller).
    #[serde(
        default,
        skip_serializing_if = "emulators::bus::model::PhysicalFaults::is_empty"
    )]
    pub faults: emulators::bus::model::PhysicalFaults,
    /// Write the bus model's log (`bus.log` in the run folder, `candump -l` form): every frame
    /// on the modelled bus, nav's included, and the error frames of nav's controller, stamped
    /// with simulated time. About 35 bytes a frame (4,000 frames per second of a 2 kHz IMU):
    /// off by default.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub log: bool,
    /// In a free-running run, the device under test's latency budget, ms: the 99th percentile
    /// of IMU sample on the bus to the NAV_TIME naming it (`--latency-budget-ms` wins; 50 when
    /// neither says).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency_budget_ms: Option<f64>,
}

/// How the bus's timing is modelled.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum TimingModel {
    /// A physical bus of the scenario's bit rate.
    #[default]
    Model,
    /// vcan's: no time on the bus, no arbitration.
    Ideal,
}

impl BusSettings {
    /// The bus model of these settings.
    pub fn timing(&self) -> emulators::bus::model::BusTiming {
        emulators::bus::model::BusTiming {
            bitrate_bps: self.bitrate_bps,
            data_bitrate_bps: None,
            ideal: self.timing == TimingModel::Ideal,
            tx_queue: self.tx_queue_frames,
            faults: self.faults.clone(),
        }
    }
}

fn default_tx_queue() -> usize {
    emulators::bus::model::DEFAULT_TX_QUEUE
}

impl Default for BusSettings {
    fn default() -> Self {
        Self {
            lockstep: true,
            nav_rcvbuf_bytes: default_rcvbuf(),
            bitrate_bps: default_bitrate(),
            timing: TimingModel::default(),
            tx_queue_frames: default_tx_queue(),
            latency_budget_ms: None,
            faults: Default::default(),
            log: false,
        }
    }
}

fn default_bitrate() -> f64 {
    wire::busload::NOMINAL_BITRATE
}

fn yes() -> bool {
    true
}

fn default_rcvbuf() -> usize {
    8 << 20
}

fn default_position_tolerance() -> f64 {
    25.0
}

fn one() -> f64 {
    1.0
}

fn default_tolerance() -> f64 {
    0.1
}

/// A field the file left out, filled in from the track where it can be.
fn unset() -> f64 {
    f64::NAN
}

fn unset_site() -> Static {
    Static {
        lat_deg: f64::NAN,
        ..Static::level(0.0)
    }
}

/// A track's start farther than this from the scenario's site is refused, m.
const TRACK_SITE_M: f64 = 100.0;

impl Scenario {
    /// The scenario files shipped under `scenarios/`, sorted.
    pub fn shipped_files() -> anyhow::Result<Vec<std::path::PathBuf>> {
        use anyhow::Context;
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let mut v: Vec<std::path::PathBuf> = std::fs::read_dir(&dir)
            .with_context(|| format!("listing {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        v.sort();
        Ok(v)
    }

    /// Load and check a scenario file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read scenario {}", path.display()))?;
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
        Self::from_text_named(&text, path.parent(), stem.as_deref())
            .with_context(|| format!("scenario {}", path.display()))
    }

    /// Parse and check a scenario's text; a `[drive] track` file is found relative to `dir`
    /// (the scenario's folder), and kept as an absolute path so that the scenario written into
    /// a run's folder finds it too.
    pub fn from_text_at(text: &str, dir: Option<&Path>) -> Result<Self> {
        Self::from_text_named(text, dir, None)
    }

    /// [`Scenario::from_text_at`], named `stem` where the text names no scenario; a drive from
    /// a track takes its site (the track's start) and its duration (the drive's, and 5 s)
    /// from the track where the text leaves them out, and a site the text gives that is more
    /// than 100 m from the track's start is refused.
    fn from_text_named(text: &str, dir: Option<&Path>, stem: Option<&str>) -> Result<Self> {
        let mut s: Scenario = toml::from_str(text)?;
        // a track is driven with a driver's limits where the file sets none (the level
        // route's gentle defaults drove a brisk track's corners seconds late)
        let table: toml::Table = toml::from_str(text)?;
        if let (Some(d), Some(toml::Value::Table(given))) = (s.drive.as_mut(), table.get("drive"))
            && d.track.is_some()
        {
            let driver = emulators::drive::DriveSpec::driver();
            let unset = |k: &str| !given.contains_key(k);
            if unset("accel_mps2") {
                d.accel_mps2 = driver.accel_mps2;
            }
            if unset("brake_mps2") {
                d.brake_mps2 = driver.brake_mps2;
            }
            if unset("jerk_mps3") {
                d.jerk_mps3 = driver.jerk_mps3;
            }
            if unset("turn_rate_dps") {
                d.turn_rate_dps = driver.turn_rate_dps;
            }
            if unset("lateral_accel_mps2") {
                d.lateral_accel_mps2 = driver.lateral_accel_mps2;
            }
        }
        if s.name.is_empty() {
            s.name = stem.unwrap_or("scenario").to_string();
        }
        if let Some(d) = s.drive.as_mut()
            && let Some(t) = d.track.as_mut()
        {
            let p = Path::new(t.as_str());
            let full = match dir {
                Some(dir) if p.is_relative() => dir.join(p),
                _ => p.to_path_buf(),
            };
            let full = std::path::absolute(&full).unwrap_or(full);
            *t = full.display().to_string();
        }
        s.fill_from_track()?;
        if s.duration_s.is_nan() {
            bail!("duration_s is missing (only a drive from a track has one of its own)");
        }
        if s.site.lat_deg.is_nan() {
            bail!("[site] is missing (only a drive from a track has one of its own)");
        }
        s.check()?;
        Ok(s)
    }

    /// A track's drive gives what the scenario leaves out: the site (its start) and the
    /// duration (its drive and 5 s); a site it gives must be where the track starts.
    fn fill_from_track(&mut self) -> Result<()> {
        let Some(d) = &self.drive else {
            return Ok(());
        };
        let Some(track) = &d.track else {
            return Ok(());
        };
        let plan = emulators::drive::Drive::plan(d)
            .map_err(|e| anyhow::anyhow!("[{}] {}", e.table, e.problem))?;
        let (lat, lon, h) = plan.position(0.0);
        let (lat_deg, lon_deg) = (lat.to_degrees(), lon.to_degrees());
        if self.site.lat_deg.is_nan() {
            self.site = Static {
                lat_deg,
                lon_deg,
                height_m: h,
                heading_deg: plan.heading(0.0).to_degrees().rem_euclid(360.0),
                ..Static::level(0.0)
            };
        } else {
            let e = emulators::geodesy::enu_offset(
                (lat, lon, 0.0),
                (
                    self.site.lat_deg.to_radians(),
                    self.site.lon_deg.to_radians(),
                    0.0,
                ),
            );
            let off = e[0].hypot(e[1]);
            if off.is_nan() || off > TRACK_SITE_M {
                bail!(
                    "the track {track} starts at {lat_deg:.6} N {lon_deg:.6} E, {off:.0} m from the site ({} N {} E): leave [site] out to start where the track does",
                    self.site.lat_deg,
                    self.site.lon_deg
                );
            }
        }
        if self.duration_s.is_nan() {
            self.duration_s = (plan.duration() + 5.0).ceil();
        }
        Ok(())
    }

    /// Parse and check a scenario's text.
    pub fn from_text(text: &str) -> Result<Self> {
        Self::from_text_at(text, None)
    }

    /// The bus model's physical faults make sense: windows in order and in the run, a
    /// babbling identifier of 11 bits, a faulty transmitter of a node the contract knows, and
    /// none on the ideal bus (which has no physical layer).
    fn check_bus_faults(&self) -> Result<()> {
        let f = &self.bus.faults;
        if f.is_empty() {
            return Ok(());
        }
        if self.bus.timing == TimingModel::Ideal {
            bail!("[bus.faults] need the bus model: bus.timing = \"ideal\" has no physical layer");
        }
        let window = |what: &str, from: f64, to: f64| -> Result<()> {
            if !(from >= 0.0 && to > from && to <= self.duration_s + 1e-9) {
                bail!(
                    "bus.faults.{what} [{from}, {to}]: a window from 0 s to the run's end ({} s), its end after its start",
                    self.duration_s
                );
            }
            Ok(())
        };
        for w in &f.disturbed_s {
            window("disturbed_s", w[0], w[1])?;
            if !(w[2] > 0.0 && w[2] <= 100_000.0) {
                bail!(
                    "bus.faults.disturbed_s: {} errors per second is not in (0, 100000]",
                    w[2]
                );
            }
        }
        for w in &f.stuck_dominant_s {
            window("stuck_dominant_s", w[0], w[1])?;
        }
        if f.stuck_dominant_s.windows(2).any(|p| p[1][0] < p[0][1]) {
            bail!("bus.faults.stuck_dominant_s: the windows must be in time order, apart");
        }
        for w in &f.babbling_s {
            window("babbling_s", w[0], w[1])?;
            if !(0.0..=2047.0).contains(&w[2]) || w[2].fract() != 0.0 {
                bail!(
                    "bus.faults.babbling_s: identifier {} is not an 11-bit identifier",
                    w[2]
                );
            }
        }
        for t in &f.tx_faults {
            window("tx_faults", t.from_s, t.to_s)?;
            if !wire::ALL_MESSAGES.iter().any(|m| m.sender == t.node) {
                let mut nodes: Vec<&str> = wire::ALL_MESSAGES.iter().map(|m| m.sender).collect();
                nodes.dedup();
                bail!(
                    "bus.faults.tx_faults: node {:?} sends nothing in the contract (its nodes: {})",
                    t.node,
                    nodes.join(", ")
                );
            }
        }
        Ok(())
    }

    /// Sanity checks.
    pub fn check(&self) -> Result<()> {
        self.check_fields().map_err(anyhow::Error::msg)?;
        if !(self.speed > 0.0 && self.speed <= 1000.0) {
            bail!("speed must be in (0, 1000]");
        }
        if !(1024..=(1 << 30)).contains(&self.bus.nav_rcvbuf_bytes) {
            bail!(
                "bus.nav_rcvbuf_bytes {} is not in [1024, 2^30]",
                self.bus.nav_rcvbuf_bytes
            );
        }
        if !(0.0..1.0).contains(&self.max_bus_loss) {
            bail!("max_bus_loss must be in [0, 1)");
        }
        // the contract's IMU frames carry any rate up to the RLG unit's 2 kHz; nav's solution
        // goes out at 50 Hz of IMU time, so a whole number of samples per epoch
        let r = self.imu.rate_hz;
        if !((50.0..=wire::IMU_RATE_HZ).contains(&r) && (r / 50.0).fract() == 0.0) {
            bail!(
                "imu.rate_hz ({r}) must be a multiple of 50 Hz from 50 to {} Hz (nav's solution goes out at 50 Hz of IMU time)",
                wire::IMU_RATE_HZ
            );
        }
        self.imu.check()?;
        self.check_procedures()?;
        if let Some(d) = &self.drive {
            Drive::plan(d)?;
            if self.coning.is_some() {
                bail!("a scenario has either [coning] or [drive], not both");
            }
        }
        if let Some(c) = &self.coning
            && !(c.half_angle_deg.abs() <= 10.0 && c.frequency_hz >= 0.0 && c.frequency_hz < 500.0)
        {
            bail!("coning: half_angle_deg must be within 10 deg and frequency_hz in [0, 500)");
        }
        if self.gps.is_some() && self.drive.is_none() {
            bail!("[gps] needs a [drive]: the antenna rides on the vehicle's route");
        }
        self.check_bus_faults()?;
        if !(1..=4096).contains(&self.bus.tx_queue_frames) {
            bail!(
                "bus.tx_queue_frames {} is not in [1, 4096]",
                self.bus.tx_queue_frames
            );
        }
        if let Some(g) = &self.gps
            && !(1.0..=10.0).contains(&g.rate_hz)
        {
            bail!("gps.rate_hz must be in [1, 10]");
        }
        if self.navigation.is_some() && self.gps.is_none() {
            bail!("[navigation] needs a [gps]: nav takes its start position from the first fix");
        }
        if let Some(n) = &self.navigation {
            n.check().map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        if let Some(d) = &self.drive
            && (self.turntable.is_some() || self.north_finding.is_some())
            && ((d.lat_deg - self.site.lat_deg).abs() > 1e-6
                || (d.lon_deg - self.site.lon_deg).abs() > 1e-6)
        {
            bail!(
                "drive starts at {} N {} E but the site is {} N {} E: north-finding uses the site's latitude, so they must agree",
                d.lat_deg,
                d.lon_deg,
                self.site.lat_deg,
                self.site.lon_deg
            );
        }
        nav::frontend::processing::ImuProcessor::new(&self.processing)
            .map_err(|e| anyhow::anyhow!("processing: {e}"))?;
        let r = self.imu.rate_hz;
        if (self.processing.fir.fs_hz - r).abs() > 1e-9 {
            bail!(
                "processing.fir.fs_hz ({}) must equal imu.rate_hz ({r}) (for a 100 Hz IMU, e.g. fs_hz = 100, passband_hz = 20, stopband_hz = 45, order = 16)",
                self.processing.fir.fs_hz
            );
        }
        // last: the devices' own checks first say what is wrong with a rate
        busload::fits(self)?;
        Ok(())
    }

    /// The turntable and the procedures on it (north-finding, the calibrations): each its own
    /// check, and they fit the unit and each other.
    fn check_procedures(&self) -> Result<()> {
        if let Some(t) = &self.turntable {
            t.check()?;
        }
        if let Some(nf) = &self.north_finding {
            nf.check()?;
            if self.turntable.is_none() {
                bail!("north_finding needs a [turntable]");
            }
        }
        if let Some(c) = &self.self_calibration {
            c.check()?;
            if self.turntable.as_ref().is_none_or(|t| t.axes < 2) {
                bail!("self_calibration needs a [turntable] of two or more axes");
            }
            if self.north_finding.is_some() {
                bail!("a scenario has either [north_finding] or [self_calibration], not both");
            }
            if self.drive.is_some() {
                bail!("self_calibration is on a static base: no [drive]");
            }
            // the mechanism's rate plus the earth's, with a margin for the reversals
            if c.rate_dps * 1.1 >= self.imu.gyro_range_dps {
                bail!(
                    "self_calibration.rate_dps ({}) is too close to the gyros' range, imu.gyro_range_dps ({})",
                    c.rate_dps,
                    self.imu.gyro_range_dps
                );
            }
        }
        if let Some(p) = &self.nav_parameters {
            nav::procedures::unit_parameters::ImuParameters::load(p, &self.unit_id())?;
        }
        if let Some(c) = &self.tetra_calibration {
            c.check()?;
            if self.turntable.as_ref().is_none_or(|t| t.axes != 3) {
                bail!("tetra_calibration needs a [turntable] of three axes");
            }
            let Some(u) = &self.imu.tetra else {
                bail!("tetra_calibration needs the redundant unit on the bus: [imu.tetra]");
            };
            if (u.pulse_deg - c.pulse_deg).abs() > 1e-15 {
                bail!(
                    "tetra_calibration.pulse_deg ({}) is not the unit's imu.tetra.pulse_deg ({})",
                    c.pulse_deg,
                    u.pulse_deg
                );
            }
            let most = 8191.0 * u.pulse_deg * self.imu.rate_hz;
            if c.rate_dps * 1.2 >= most {
                bail!(
                    "tetra_calibration.rate_dps ({}) is too close to what the unit's 14-bit counters carry at {} Hz ({most:.1} deg/s)",
                    c.rate_dps,
                    self.imu.rate_hz
                );
            }
            if let Some(p) = &c.parameters {
                nav::procedures::unit_parameters::RedundantParameters::load(
                    p,
                    &self.mems_unit_id(),
                )?;
            }
            if self.north_finding.is_some()
                || self.self_calibration.is_some()
                || self.drive.is_some()
            {
                bail!(
                    "tetra_calibration is a lab procedure: no [north_finding], [self_calibration] or [drive]"
                );
            }
        }
        Ok(())
    }

    /// Every field that is a quantity of a known kind, within its kind's range
    /// ([`crate::values`]: the same ranges as the command line's flags): the error names the
    /// field, the value and the range.
    fn check_fields(&self) -> std::result::Result<(), String> {
        use crate::values::{
            DURATION, HEADING, HEIGHT, LATITUDE, LONGITUDE, OFFSET, PAUSE, RATE, SIGMA, TILT,
            TOLERANCE, VEHICLE_ACCEL, VEHICLE_SPEED,
        };
        DURATION.field("duration_s", self.duration_s)?;
        crate::values::CLASSIC_BITRATE.field("bus.bitrate_bps", self.bus.bitrate_bps)?;
        if let Some(b) = self.bus.latency_budget_ms {
            crate::values::LATENCY_BUDGET.field("bus.latency_budget_ms", b)?;
        }
        TOLERANCE.field("heading_tolerance_deg", self.heading_tolerance_deg)?;
        SIGMA.field("position_tolerance_m", self.position_tolerance_m)?;
        let site = &self.site;
        LATITUDE.field("site.lat_deg", site.lat_deg)?;
        LONGITUDE.field("site.lon_deg", site.lon_deg)?;
        HEIGHT.field("site.height_m", site.height_m)?;
        HEADING.field("site.heading_deg", site.heading_deg)?;
        TILT.field("site.pitch_deg", site.pitch_deg)?;
        TILT.field("site.roll_deg", site.roll_deg)?;
        if let Some(d) = &self.drive {
            // a track's start and speeds are its own
            if d.track.is_none() {
                LATITUDE.field("drive.lat_deg", d.lat_deg)?;
                LONGITUDE.field("drive.lon_deg", d.lon_deg)?;
                VEHICLE_SPEED.field("drive.speed_mps", d.speed_mps)?;
            }
            HEIGHT.field("drive.height_m", d.height_m)?;
            VEHICLE_ACCEL.field("drive.accel_mps2", d.accel_mps2)?;
            RATE.field("drive.turn_rate_dps", d.turn_rate_dps)?;
            VEHICLE_ACCEL.field("drive.lateral_accel_mps2", d.lateral_accel_mps2)?;
            PAUSE.field("drive.start_wait_s", d.start_wait_s)?;
        }
        if let Some(nf) = &self.north_finding {
            DURATION.field("north_finding.dwell_s", nf.dwell_s)?;
            LATITUDE.field("north_finding.latitude_deg", nf.latitude_deg)?;
        }
        if let Some(c) = &self.self_calibration {
            DURATION.field("self_calibration.level_s", c.level_s)?;
            DURATION.field("self_calibration.rotate_s", c.rotate_s)?;
            RATE.field("self_calibration.rate_dps", c.rate_dps)?;
            PAUSE.field("self_calibration.inner_delay_s", c.inner_delay_s)?;
        }
        if let Some(c) = &self.tetra_calibration {
            RATE.field("tetra_calibration.rate_dps", c.rate_dps)?;
            DURATION.field("tetra_calibration.turn_s", c.turn_s)?;
        }
        if let Some(g) = &self.gps {
            for (a, v) in ["x", "y", "z"].iter().zip(g.lever_arm_m) {
                OFFSET.field(&format!("gps.lever_arm_m ({a})"), v)?;
            }
        }
        Ok(())
    }

    /// The truth motion and, when the scenario has one, the turntable whose true angle it
    /// follows (axis 0 turns about the vehicle's z, axis 1 about the IMU's x, axis 2 about y).
    pub fn build(&self) -> (Box<dyn Motion>, Option<Turntable>) {
        let Some(tp) = &self.turntable else {
            return (self.motion(), None);
        };
        let tt = Turntable::new(tp.clone());
        let m = self.on_table(tp.axes, |i, about| {
            Box::new(Indexer {
                about,
                axis: ProfileAxis(tt.profile(i)),
            })
        });
        (m, Some(tt))
    }

    /// One axis's track of a table the bench does not model, `delay_s` behind its reports: no
    /// faster than half again the table's rated rate (`[turntable] max_rate_dps`, its default
    /// without one), and within half the gyros' range, so that a backlog of reports read at
    /// once cannot turn the IMU's truth beyond what its gyros read.
    pub fn reported_track(&self, delay_s: f64) -> emulators::reported::SharedTrack {
        let rated = self.turntable.as_ref().map_or(
            emulators::turntable::TurntableParams::default().max_rate_dps,
            |t| t.max_rate_dps,
        );
        let limit = (1.5 * rated).min(0.5 * self.imu.gyro_range_dps);
        std::sync::Arc::new(std::sync::Mutex::new(
            emulators::reported::ReportedTrack::new(self.imu.rate_hz, delay_s)
                .with_max_rate(limit.to_radians()),
        ))
    }

    /// The truth motion of this scenario with its IMU on a table the bench does not model,
    /// following the table's reported angles (`tracks`, one per axis of the scenario's
    /// `[turntable]`; none: no table).
    pub fn following(&self, tracks: &[emulators::reported::SharedTrack]) -> Box<dyn Motion> {
        let axes = self.turntable.as_ref().map_or(0, |t| t.axes);
        if axes == 0 || tracks.is_empty() {
            return self.motion();
        }
        self.on_table(axes.min(tracks.len() as u8), |i, about| {
            Box::new(Indexer {
                about,
                axis: emulators::reported::ReportedAxis(tracks[i].clone()),
            })
        })
    }

    /// The base motion with the disturbances, the vibration and `axes` axes of a table (each
    /// made by `axis` from its index and the direction it turns about) on top.
    fn on_table(
        &self,
        axes: u8,
        axis: impl Fn(usize, nalgebra::Unit<nalgebra::Vector3<f64>>) -> Box<dyn RelativeRotation>,
    ) -> Box<dyn Motion> {
        let mut relative: Vec<Box<dyn RelativeRotation>> = Vec::new();
        if !self.disturbance.is_empty() {
            relative.push(Box::new(Disturbances(self.disturbance.clone())));
        }
        if let Some(v) = &self.vibration {
            relative.push(Box::new(v.clone()));
        }
        let about = [
            nalgebra::Vector3::z_axis(),
            nalgebra::Vector3::x_axis(),
            nalgebra::Vector3::y_axis(),
        ];
        for (i, about) in about.into_iter().enumerate().take(usize::from(axes)) {
            relative.push(axis(i, about));
        }
        Box::new(Composed {
            base: self.base_motion(),
            relative,
            linear: self.vibration.clone(),
        })
    }

    fn base_motion(&self) -> Box<dyn Motion> {
        match (&self.coning, &self.drive) {
            (Some(c), _) => Box::new(*c),
            // checked in `check`: a plan that fails never gets here
            (None, Some(d)) => match Drive::plan(d) {
                Ok(p) => Box::new(p),
                Err(_) => Box::new(self.site.site()),
            },
            (None, None) => Box::new(self.site.site()),
        }
    }

    /// The truth motion of this scenario without a turntable.
    pub fn motion(&self) -> Box<dyn Motion> {
        let base = self.base_motion();
        let mut relative: Vec<Box<dyn RelativeRotation>> = Vec::new();
        if !self.disturbance.is_empty() {
            relative.push(Box::new(Disturbances(self.disturbance.clone())));
        }
        if let Some(v) = &self.vibration {
            relative.push(Box::new(v.clone()));
        }
        if relative.is_empty() {
            return base;
        }
        Box::new(Composed {
            base,
            relative,
            linear: self.vibration.clone(),
        })
    }

    /// The true heading of the vehicle at the start, deg (the drive's, else the site's).
    pub fn truth_heading_deg(&self) -> f64 {
        match self.drive.as_ref().and_then(|d| Drive::plan(d).ok()) {
            Some(d) => d.heading(0.0).to_degrees(),
            None => self.site.heading_deg,
        }
    }

    /// The emulated IMU unit's serial number (what a parameter file for it names).
    pub fn unit_id(&self) -> String {
        format!("emulated-imu-seed-{}", self.imu.seed)
    }

    /// The emulated redundant unit's serial number.
    pub fn mems_unit_id(&self) -> String {
        format!(
            "emulated-mems-seed-{}",
            self.imu.tetra.as_ref().map_or(0, |t| t.gyros.seed)
        )
    }

    /// The scenario runs a procedure on the mechanism (north-finding, a self-calibration, the
    /// tetrahedral calibration).
    pub fn has_procedure(&self) -> bool {
        self.north_finding.is_some()
            || self.self_calibration.is_some()
            || self.tetra_calibration.is_some()
    }

    /// A procedure on the mechanism with no drive after it: the run is over when nav says the
    /// procedure is.
    pub fn ends_with_procedure(&self) -> bool {
        self.drive.is_none() && self.has_procedure()
    }

    /// True when the IMU sits still on the site (static checks apply).
    pub fn is_static(&self) -> bool {
        self.coning.is_none()
            && self.drive.is_none()
            && self.vibration.is_none()
            && self.turntable.is_none()
            && self.disturbance.is_empty()
    }

    /// The built-in static scenario (paper 003's start point).
    pub fn builtin_static() -> Self {
        toml::from_str(include_str!("../../../scenarios/static-campus.toml"))
            .expect("built-in scenario parses")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `[bus.faults]` are read from the scenario and checked: a node the contract does not
    /// know, a window past the run, a babbling identifier past 11 bits, faults on the ideal bus
    /// are refused with what was wrong.
    #[test]
    fn physical_faults_are_read_and_checked() {
        let mut b = Scenario::builtin_static();
        b.duration_s = 6.0;
        let base = format!("{}\n[bus.faults]\n", toml::to_string(&b).unwrap());
        let ok = format!(
            "{base}disturbed_s = [[2.0, 3.0, 200.0]]\nstuck_dominant_s = [[4.0, 4.05]]\nbabbling_s = [[5.0, 5.1, 1]]\ntx_faults = [{{ node = \"TT\", from_s = 1.0, to_s = 2.0 }}]\n"
        );
        let s: Scenario = toml::from_str(&ok).unwrap();
        s.check().unwrap();
        let f = s.bus.timing().faults;
        assert_eq!(
            (f.disturbed_s.len(), f.tx_faults[0].node.as_str()),
            (1, "TT")
        );
        for (bad, says) in [
            (
                "tx_faults = [{ node = \"GPS\", from_s = 1.0, to_s = 2.0 }]",
                "node \"GPS\"",
            ),
            ("stuck_dominant_s = [[5.0, 7.0]]", "run's end"),
            ("babbling_s = [[1.0, 2.0, 4096]]", "11-bit"),
            ("disturbed_s = [[1.0, 2.0, 0.0]]", "errors per second"),
        ] {
            let s: Scenario = toml::from_str(&format!("{base}{bad}\n")).unwrap();
            let e = format!("{:#}", s.check().unwrap_err());
            assert!(e.contains(says), "{bad}: {e}");
        }
        let mut s: Scenario = toml::from_str(&ok).unwrap();
        s.bus.timing = TimingModel::Ideal;
        assert!(format!("{:#}", s.check().unwrap_err()).contains("ideal"));
    }

    /// A free-running run's latency budget is the scenario's `[bus] latency_budget_ms`: read,
    /// range-checked, and left out of a scenario that does not set it.
    #[test]
    fn the_latency_budget_is_read_and_checked() {
        let b = Scenario::builtin_static();
        let text = toml::to_string(&b).unwrap();
        assert!(!text.contains("latency_budget_ms"), "{text}");
        let with = text.replace("[bus]\n", "[bus]\nlatency_budget_ms = 20.0\n");
        let s: Scenario = toml::from_str(&with).unwrap();
        s.check().unwrap();
        assert_eq!(s.bus.latency_budget_ms, Some(20.0));
        let s: Scenario = toml::from_str(&with.replace("= 20.0", "= 1e9")).unwrap();
        let e = format!("{:#}", s.check().unwrap_err());
        assert!(e.contains("bus.latency_budget_ms"), "{e}");
    }

    #[test]
    fn builtin_scenario_is_valid() {
        let s = Scenario::builtin_static();
        s.check().unwrap();
        assert_eq!(s.site.lat_deg, 28.218157);
    }

    /// Every shipped scenario loads and passes its checks; every route drives off after the
    /// wait and ends before the scenario does (its navigation is scored parked, not cut off).
    #[test]
    fn every_shipped_scenario_is_valid() {
        let mut n = 0;
        for p in Scenario::shipped_files().unwrap() {
            let s = Scenario::load(&p).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
            if let Some(d) = &s.drive {
                let plan = Drive::plan(d).unwrap();
                assert!(
                    plan.duration() <= s.duration_s,
                    "{}: the drive takes {} s, the scenario {} s",
                    p.display(),
                    plan.duration(),
                    s.duration_s
                );
            }
            n += 1;
        }
        assert!(n >= 7, "{n} scenarios");
    }

    /// An IMU may run at a multiple of 50 Hz up to 2 kHz, with its processing chain at the
    /// same rate; anything else is refused with the reason.
    #[test]
    fn the_imu_rate_is_a_multiple_of_the_solution_rate() {
        let mut s = Scenario::builtin_static();
        s.imu.rate_hz = 100.0;
        s.imu.dither_arcsec = [0.0; 3]; // a fibre-optic gyro's
        let e = s.check().unwrap_err().to_string();
        assert!(e.contains("processing.fir.fs_hz"), "{e}");
        s.processing.fir.fs_hz = 100.0;
        s.processing.fir.passband_hz = 20.0;
        s.processing.fir.stopband_hz = 45.0;
        s.processing.fir.order = 16;
        s.check().unwrap();
        for bad in [75.0, 30.0, 4000.0] {
            s.imu.rate_hz = bad;
            s.processing.fir.fs_hz = bad;
            let e = s.check().unwrap_err().to_string();
            assert!(
                e.contains("multiple of 50 Hz") || e.contains("processing"),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn bad_scenarios_say_what_is_wrong() {
        let mut s = Scenario::builtin_static();
        s.site.lat_deg = 99.0;
        assert!(s.check().unwrap_err().to_string().contains("latitude"));
        let e = toml::from_str::<Scenario>("name='x'\nduration_s=1\n[site]\nlat_deg=1\nbogus=2\n")
            .unwrap_err();
        assert!(e.to_string().contains("bogus"), "{e}");
    }

    /// A receiver's surroundings come from a preset, with any field changed in the file; a bad
    /// field is named.
    #[test]
    fn receiver_surroundings_take_a_preset_and_overrides() {
        use emulators::gps::errors::{Environment, EnvironmentPreset};
        let base = "name='x'\nduration_s=10\n[site]\nlat_deg=1\n[gps.errors.environment]\n";
        let s = toml::from_str::<Scenario>(&format!(
            "{base}preset = 'paper-003'\nmultipath_every_s = 60.0\n"
        ))
        .unwrap();
        let e = &s.gps.as_ref().unwrap().errors.environment;
        let paper = Environment::preset(EnvironmentPreset::Paper003);
        assert_eq!(e.multipath_every_s, 60.0);
        assert_eq!(
            e.constellation_change_every_s,
            paper.constellation_change_every_s
        );
        assert_eq!(e.preset, EnvironmentPreset::Paper003);
        // no table: open sky
        let s = toml::from_str::<Scenario>("name='x'\nduration_s=10\n[site]\nlat_deg=1\n[gps]\n")
            .unwrap();
        assert!(s.gps.unwrap().errors.environment.is_open_sky());
        for (bad, named) in [
            ("preset = 'moon'", "moon"),
            ("multipath_duration_s = [30.0, 5.0]", "multipath_duration_s"),
            ("min_satellites = 2", "min_satellites"),
            ("multipath_sigma = 3.0", "multipath_sigma"),
        ] {
            let e = format!(
                "{:#}",
                toml::from_str::<Scenario>(&format!("{base}{bad}\n")).unwrap_err()
            );
            assert!(e.contains(named), "{bad}: {e}");
        }
    }
}

#[cfg(test)]
mod campus_tests {
    use super::*;

    #[test]
    fn the_campus_loop_is_six_laps_of_about_a_kilometre() {
        let s = Scenario::load(Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scenarios/campus-loop.toml"
        )))
        .unwrap();
        let spec = s.drive.as_ref().unwrap();
        let d = Drive::plan(spec).unwrap();
        let drive_s = d.duration() - spec.start_wait_s;
        eprintln!("drive {drive_s:.1} s, total {:.1} s", d.duration());
        assert!((1300.0..1400.0).contains(&drive_s), "{drive_s}");
        assert!((s.truth_heading_deg() + 0.364616).abs() < 1e-3);
    }

    /// A track scenario of one line: the name is the file's, the site the track's start, the
    /// duration its drive and 5 s, the limits a driver's; a site far from the track's start is
    /// refused, naming both.
    #[test]
    fn a_track_is_a_scenario_of_one_line() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let text = "[drive]\ntrack = \"tracks/porto-moving.gpx\"\n";
        let s = Scenario::from_text_named(text, Some(&dir), Some("mine")).unwrap();
        assert_eq!(s.name, "mine");
        let d = s.drive.as_ref().unwrap();
        let plan = Drive::plan(d).unwrap();
        assert!(s.duration_s >= plan.duration() + 5.0 && s.duration_s < plan.duration() + 6.0);
        let (lat, lon, _) = plan.position(0.0);
        assert!((s.site.lat_deg - lat.to_degrees()).abs() < 1e-9);
        assert!((s.site.lon_deg - lon.to_degrees()).abs() < 1e-9);
        assert_eq!(d.accel_mps2, DriveSpec::driver().accel_mps2);
        assert_eq!(d.brake_mps2, DriveSpec::driver().brake_mps2);
        // a limit the file sets is kept
        let s = Scenario::from_text_named(
            "[drive]\ntrack = \"tracks/porto-moving.gpx\"\naccel_mps2 = 1.2\n",
            Some(&dir),
            None,
        )
        .unwrap();
        assert_eq!(s.drive.unwrap().accel_mps2, 1.2);
        let far = format!("{text}[site]\nlat_deg = 41.16\nlon_deg = -8.61\n");
        let e = format!(
            "{:#}",
            Scenario::from_text_named(&far, Some(&dir), None).unwrap_err()
        );
        assert!(e.contains("from the site") && e.contains("41.16"), "{e}");
        // without a track, the duration and the site are still needed
        let e = format!("{:#}", Scenario::from_text("[drive]\nwaypoints = [[0.0, 100.0]]\nlat_deg = 1.0\nlon_deg = 1.0\nspeed_mps = 5.0\n").unwrap_err());
        assert!(e.contains("duration_s is missing"), "{e}");
    }
}
