//! The navigation mode: levelling, hand-over (heading from north-finding or the config, position
//! from the first good GPS fix), strapdown navigation, and the SINS/GPS filter with fixes tied
//! to IMU time by the receiver's PPS edge latched in the IMU stream.

use crate::frontend::gps_receiver::GpsFix;
use crate::frontend::imu_clock::ClockEstimate;
use crate::navigation::filter::{FilterConfig, FilterStats, Kf};
use crate::navigation::strapdown::{NavOutput, NavState};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Navigation settings (the `[navigation]` table of nav's config).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct NavigationConfig {
    /// Navigate (after north-finding, when that is enabled).
    pub enabled: bool,
    /// Heading at the start when north-finding does not provide one, deg.
    pub initial_heading_deg: Option<f64>,
    /// Static levelling time before navigation starts, s.
    pub level_s: f64,
    /// Use GPS fixes in the filter (false: pure inertial after the start).
    pub gps_aiding: bool,
    /// The filter.
    pub filter: FilterConfig,
    /// A fix is applied when IMU time reaches its PPS edge plus this (s), carried forward from
    /// the edge with the INS velocity; a fix that arrives later is applied at once and counted
    /// late. Applying fixes at a time set by the IMU stream, not by when the serial port
    /// happened to be read, makes the solution depend on the data alone. Allow for the
    /// receiver's output latency and the serial transfer (a few hundred bytes at 9600 baud take
    /// about 0.4 s).
    pub fix_delay_s: f64,
    /// The solution's integrity monitor.
    pub integrity: crate::navigation::integrity::IntegrityConfig,
    /// A PPS edge is taken when it lies a whole number of seconds after the last one taken
    /// (or after the last one seen) within this, s, plus an allowance for the IMU's clock
    /// ([`PPS_CLOCK_ALLOWANCE`] of the interval about the rate read from the edges, or
    /// [`PPS_CLOCK_ALLOWANCE_UNKNOWN`] before it is read); any other edge (a glitch on the PPS
    /// line) is rejected and counted.
    pub pps_tolerance_s: f64,
    /// The sigma of the receiver's velocity (RMC's speed and track) assumed when navigation
    /// starts in motion, m/s per axis.
    pub motion_velocity_sigma_mps: f64,
    /// Zero-velocity updates while the vehicle stands (judged each second from the IMU's own
    /// evidence as levelling judges it, with the receiver's speed where it tells one and the
    /// INS's own speed): the velocity measured as zero with this sigma, m/s per axis (the
    /// body rocking on its suspension at idle, millimetres a second); 0: none.
    pub zero_velocity_sigma_mps: f64,
}

impl NavigationConfig {
    /// The settings are usable: the filter's, the PPS tolerance, the velocity sigmas; the
    /// error names the key (under `navigation.`).
    pub fn check(&self) -> Result<(), String> {
        self.filter.check().map_err(|e| format!("navigation.{e}"))?;
        let tol = self.pps_tolerance_s;
        if !(tol > 0.0 && tol < 0.5) {
            return Err(format!(
                "navigation.pps_tolerance_s ({tol}) must lie in (0, 0.5) s"
            ));
        }
        for (name, v, zero) in [
            (
                "zero_velocity_sigma_mps",
                self.zero_velocity_sigma_mps,
                true,
            ),
            (
                "motion_velocity_sigma_mps",
                self.motion_velocity_sigma_mps,
                false,
            ),
        ] {
            let ok = v.is_finite() && v <= 10.0 && (v > 0.0 || (zero && v == 0.0));
            if !ok {
                return Err(format!(
                    "navigation.{name} ({v}) must lie in {} m/s{}",
                    if zero { "[0, 10]" } else { "(0, 10]" },
                    if zero {
                        " (0: no zero-velocity updates)"
                    } else {
                        ""
                    }
                ));
            }
        }
        Ok(())
    }
}

/// The IMU clock's allowance in the PPS check, per second of interval, about the rate read
/// from the edges (100 ppm: its wander between edges is far less).
pub const PPS_CLOCK_ALLOWANCE: f64 = 1e-4;

/// The same before the rate is read (1000 ppm: a unit's oscillator is off by tens of ppm; one
/// further off is taken once its edges have told its rate, one beyond is not a clock to
/// navigate on and its edges are rejected, counted).
pub const PPS_CLOCK_ALLOWANCE_UNKNOWN: f64 = 1e-3;

impl Default for NavigationConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            initial_heading_deg: None,
            level_s: 2.0,
            gps_aiding: true,
            filter: FilterConfig::default(),
            fix_delay_s: 0.5,
            integrity: crate::navigation::integrity::IntegrityConfig::default(),
            pps_tolerance_s: 0.002,
            motion_velocity_sigma_mps: 0.3,
            zero_velocity_sigma_mps: 0.01,
        }
    }
}

/// Levelling takes a window as still when the specific force's spread about its mean is
/// under this (m/s^2 RMS: a parked vehicle's idling engine is far less, a vehicle driving
/// over any road more), ...
pub const STILL_FORCE_SPREAD: f64 = 0.3;

/// ... the mean specific force is gravity within this (m/s^2, 15 mg: three of a tactical
/// accelerometer's bias of 5 mg; a vehicle accelerating at 1.7 m/s^2 or more is not still,
/// whatever else it shows), the mean forces of the window's two halves differ by less than
/// [`STILL_FORCE_CHANGE`] ...
pub const STILL_FORCE_OFF_G: f64 = 0.15;

/// See [`STILL_FORCE_OFF_G`] (m/s^2): a vehicle setting off or coming to a halt changes its
/// specific force within a second, however gently (within a jerk of 1 m/s^3, by 0.25 m/s^2
/// in half a second); a standing one's changes by its noise.
pub const STILL_FORCE_CHANGE: f64 = 0.03;

/// ... the body turns slower than this (rad/s, 0.3 deg/s) ...
pub const STILL_RATE: f64 = 0.3 * std::f64::consts::PI / 180.0;

/// ... and the receiver, where it tells its speed, says the vehicle moves slower than this
/// (m/s), or than four of its velocity's sigmas (a standing receiver's speed is its noise).
pub const STILL_SPEED: f64 = 0.5;

/// A vehicle found moving is aligned in motion when the receiver's speed is at least this
/// (m/s: its track then tells the way the vehicle goes) ...
pub const MOTION_MIN_SPEED: f64 = 3.0;

/// ... and the vehicle's acceleration between its last two velocities is under this (m/s^2)
/// and its turn rate under [`MOTION_MAX_RATE`]: the window's mean specific force, less that
/// acceleration, is then gravity to within what the velocities can tell.
pub const MOTION_MAX_ACCEL: f64 = 1.0;

/// See [`MOTION_MAX_ACCEL`] (rad/s, 3 deg/s).
pub const MOTION_MAX_RATE: f64 = 3.0 * std::f64::consts::PI / 180.0;

/// The window over which a navigating vehicle is judged standing, s.
pub const ZUPT_WINDOW_S: f64 = 1.0;

/// A vehicle is taken as standing only where the INS's own horizontal speed is under this
/// (m/s), or three of its sigmas: a vehicle cruising on a smooth road feels what a standing
/// one feels, and its INS knows it moves.
pub const ZUPT_MAX_INS_SPEED: f64 = 0.5;

/// ... and, navigating, the mean specific force of each half of the window has a horizontal
/// part (in the navigation frame, from the corrected attitude) under this (m/s^2, 5 mg: a
/// standing vehicle's force is gravity alone, to the attitude's error). The magnitude's test
/// ([`STILL_FORCE_OFF_G`]) passes a vehicle braking steadily at 1.5 m/s^2 (its force is 0.11
/// m/s^2 longer than gravity, and does not change): taken as standing half a metre a second
/// before it stops, its velocity error was that half metre a second against a sigma of 0.02.
/// Over half a second this bounds the speed lost to 25 mm/s.
pub const ZUPT_MAX_HORIZONTAL_FORCE: f64 = 0.05;

/// A land vehicle's slip, the angle between where it points and where it goes, allowed for
/// when its heading is taken from the receiver's track (rad, 0.5 deg).
pub const SLIP_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// How navigation started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StartKind {
    /// Levelled standing still, from rest.
    Still,
    /// Aligned in motion: the velocity and (without a heading given) the heading from the
    /// receiver's speed and track, the level from the specific force less the acceleration
    /// between the receiver's velocities, with the sigmas that leaves.
    InMotion,
}

/// What a levelling window that ended decides.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Judged {
    /// Navigation starts, so.
    Start(StartKind),
    /// Another window: the vehicle moves (not steadily enough to align), or it stands with
    /// no heading to start from.
    Wait {
        /// It moved.
        moving: bool,
    },
}

/// What the levelling window saw of the vehicle's motion.
#[derive(Debug, Clone, Copy, Default)]
struct LevelWindow {
    /// Sums over the window's updates: velocity increments, their specific forces' squared
    /// norms (times dt), rotation increments.
    dv: Vector3<f64>,
    ff_dt: f64,
    phi: Vector3<f64>,
    t: f64,
    /// The velocity increments' sum and the time at the window's half, once passed.
    half: Option<(Vector3<f64>, f64)>,
}

impl LevelWindow {
    /// Add an update to a window of `len` s.
    fn add_of(&mut self, phi: [f64; 3], dv: [f64; 3], dt: f64, len: f64) {
        if self.half.is_none() && self.t >= 0.5 * len {
            self.half = Some((self.dv, self.t));
        }
        self.add(phi, dv, dt);
    }
    /// The change of the mean specific force from the window's first half to its second,
    /// m/s^2 (0 before the half).
    fn force_change(&self) -> f64 {
        match self.half {
            Some((dv1, t1)) if t1 > 0.0 && self.t > t1 => {
                (dv1 / t1 - (self.dv - dv1) / (self.t - t1)).norm()
            }
            _ => 0.0,
        }
    }
    fn add(&mut self, phi: [f64; 3], dv: [f64; 3], dt: f64) {
        let dv = Vector3::from(dv);
        self.dv += dv;
        if dt > 0.0 {
            self.ff_dt += dv.norm_squared() / dt;
        }
        self.phi += Vector3::from(phi);
        self.t += dt;
    }
    /// Mean specific force, m/s^2.
    fn force(&self) -> Vector3<f64> {
        self.dv / self.t.max(1e-9)
    }
    /// The specific force's RMS spread about its mean, m/s^2.
    fn spread(&self) -> f64 {
        (self.ff_dt / self.t.max(1e-9) - self.force().norm_squared())
            .max(0.0)
            .sqrt()
    }
    /// Mean turn rate, rad/s.
    fn rate(&self) -> f64 {
        self.phi.norm() / self.t.max(1e-9)
    }
}

/// A velocity the receiver stated (RMC's speed and track) while navigation had not started.
#[derive(Debug, Clone, Copy)]
struct Course {
    /// IMU time it was taken at, s.
    t: f64,
    /// East, north, m/s.
    v: [f64; 2],
    /// Speed, m/s.
    speed: f64,
}

/// Where navigation is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NavPhase {
    /// Waiting for a heading (north-finding) and a first good fix.
    Waiting,
    /// Levelling from the accelerometers.
    Levelling,
    /// Navigating.
    Navigating,
}

/// Counters and the latest output.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct NavigatorSummary {
    /// Phase.
    pub phase: NavPhase,
    /// IMU time navigation started, s.
    pub started_at_s: Option<f64>,
    /// The latest (filter-corrected) output.
    pub output: Option<NavOutput>,
    /// IMU time of that output, s from the first sample.
    pub output_t_s: f64,
    /// Filter counters.
    pub filter: Option<FilterStats>,
    /// Fixes seen, used, ignored (invalid, flagged, before the start).
    pub fixes_seen: u64,
    /// Fixes ignored.
    pub fixes_ignored: u64,
    /// PPS edges seen.
    pub pps_edges: u64,
    /// Fixes that arrived after their PPS edge plus `fix_delay_s` of IMU time (applied at once).
    pub late_fixes: u64,
    /// Fixes whose PPS edge never came (the PPS input missing): applied at their arrival less
    /// `fix_delay_s`, without the PPS tie.
    #[serde(default)]
    pub untied_fixes: u64,
    /// PPS edges rejected: not a whole number of seconds after the last edge (a glitch).
    #[serde(default)]
    pub pps_rejected: u64,
    /// The receiver's latency, fix after its PPS edge, learned from the first fixes (s).
    #[serde(default)]
    pub receiver_latency_s: Option<f64>,
    /// UTC second less the PPS edge's second number, as the fixes tie them (none before the
    /// first fix with a time).
    #[serde(default)]
    pub utc_edge_offset_s: Option<i64>,
    /// Times that tie was corrected once the receiver's latency was learned.
    #[serde(default)]
    pub utc_reanchors: u64,
    /// Fixes whose UTC time fitted no PPS edge near (set aside, as the receiver's clock jumped
    /// or the fix was seconds old).
    #[serde(default)]
    pub clock_jumps: u64,
    /// The integrity monitor.
    pub integrity: crate::navigation::integrity::IntegrityStats,
    /// The IMU's rate against the PPS, as navigation last used it (none before
    /// [`crate::frontend::imu_clock::MIN_EDGES`] edges).
    #[serde(default)]
    pub imu_clock: Option<ClockEstimate>,
    /// How navigation started: still, or aligned in motion (none: not yet).
    #[serde(default)]
    pub start: Option<StartKind>,
    /// Levelling windows refused because the vehicle moved and could not be aligned in
    /// motion (navigation waited).
    #[serde(default)]
    pub level_waits: u64,
}

/// The navigator.
#[derive(Debug)]
pub struct Navigator {
    cfg: NavigationConfig,
    phase: NavPhase,
    heading: Option<f64>,
    /// The sigma of the heading handed over, deg.
    heading_sigma_deg: Option<f64>,
    first_fix: Option<(f64, f64, f64)>,
    /// What the receiver said of the accuracy of the fix navigation starts at.
    first_fix_accuracy: crate::navigation::filter::StatedAccuracy,
    level: LevelWindow,
    /// The receiver's last velocities before the start, newest last.
    courses: std::collections::VecDeque<Course>,
    /// Levelling windows refused because the vehicle moved (and could not be aligned in
    /// motion).
    level_waits: u64,
    /// A levelling window saw the vehicle move: a heading given for power-on is stale.
    moved: bool,
    start_kind: Option<StartKind>,
    /// The current window of the standing judgement while navigating, and its first half.
    still: LevelWindow,
    still_first: Option<LevelWindow>,
    state: Option<NavState>,
    kf: Option<Kf>,
    f_acc: Vector3<f64>,
    t_acc: f64,
    last_pps: Option<f64>,
    /// The last edge seen, taken or not.
    last_pps_seen: Option<f64>,
    pps_rejected: u64,
    last_t: f64,
    started_at: Option<f64>,
    fixes_seen: u64,
    fixes_ignored: u64,
    pps_edges: u64,
    last_good_fix_t: Option<f64>,
    /// Fixes waiting for their time.
    held: Vec<Held>,
    /// The PPS edges taken, newest last (the last [`EDGES_KEPT`]): (second number, counted
    /// from the first edge by the whole seconds between edges; IMU time).
    edges: std::collections::VecDeque<(i64, f64)>,
    /// UTC second (unwrapped across midnight) less the second number of its edge, once the
    /// first fix has decided it.
    anchor: Option<i64>,
    /// The last UTC time of day seen, and the days added to make times continuous.
    utc_last: Option<f64>,
    utc_days: i64,
    /// The first fixes' ties, checked once the receiver's latency is learned.
    first_ties: Vec<FirstTie>,
    /// Fixes the filter's gate refused since [`Navigator::take_rejected`] was last called.
    rejected: Vec<RejectedFix>,
    /// The receiver's latest statements of its accuracy (GST), newest last: a fix takes the
    /// one of its own UTC time when it is applied (GST comes after GGA in an epoch).
    accuracies: std::collections::VecDeque<crate::frontend::gps_receiver::GpsAccuracy>,
    /// Times the tie between UTC seconds and edges was corrected.
    utc_reanchors: u64,
    /// Fixes whose UTC time fitted no edge near (set aside).
    clock_jumps: u64,
    /// The tie the last fixes whose time fitted no edge pointed to, and how many in a row.
    jump_streak: Option<(i64, u32)>,
    late_fixes: u64,
    untied_fixes: u64,
    integrity: crate::navigation::integrity::IntegrityMonitor,
    /// The INS's velocity (east, north, up) at the last PPS edge: when the fix was taken.
    v_at_pps: Option<[f64; 3]>,
    /// The first fixes' arrivals after the last edge, as unit vectors on the circle of one
    /// second (sums of cos and sin, count): the receiver's latency.
    arrivals: (f64, f64, u32),
    /// IMU time the last fix was taken at, and its sentence's index in the stream.
    last_fix_at: Option<(f64, u64)>,
    /// The IMU's rate against the PPS edges kept (the last good window's).
    clock: Option<ClockEstimate>,
}

/// A window of edges whose rate is more uncertain than this (ppm, one sigma: a PPS line with
/// a glitch taken, or one jittering by milliseconds) leaves the last good rate in use.
pub const CLOCK_SIGMA_LIMIT_PPM: f64 = 20.0;

/// The receiver's latency is learned from this many fixes; until then a fix belongs to the
/// latest edge at or before its arrival.
pub const LATENCY_FIXES: u32 = 5;

/// Fixes in a row whose UTC time fits no edge near, and that agree on a new tie, before the
/// receiver's seconds are tied to the edges anew.
pub const JUMPS_TO_REANCHOR: u32 = 3;

/// PPS edges kept for tying fixes that come late.
pub const EDGES_KEPT: usize = 64;

/// A fix the filter's gate refused: where the receiver put it, how far off (NIS), when.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct RejectedFix {
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Its normalized innovation squared.
    pub nis: Option<f64>,
    /// IMU time it was taken at, s.
    pub t_s: f64,
}

/// Rejected fixes kept between two calls of [`Navigator::take_rejected`].
const REJECTED_KEPT: usize = 64;

/// The receiver's accuracy statements kept for the fixes still held (10 Hz over 2 s).
pub const ACCURACIES_KEPT: usize = 20;

/// What a held fix is tied to.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Tie {
    /// The edge with this second number, and the fix's fraction of a second after it.
    Edge(i64, f64),
    /// Nothing yet: it came before the IMU stream showed any edge.
    Untied,
}

/// A fix waiting for its time.
#[derive(Debug, Clone)]
struct Held {
    fix: GpsFix,
    tie: Tie,
    /// IMU time it arrived at.
    arrived: f64,
}

/// One of the first fixes: its UTC second and fraction, its arrival, and the last edge then.
#[derive(Debug, Clone, Copy)]
struct FirstTie {
    whole: i64,
    frac: f64,
    arrived: f64,
    s_last: i64,
    t_last: f64,
}

/// A fix waits at most this long (IMU time, s) past `fix_delay_s` for its PPS edge (1 Hz: the
/// edge comes within a second); then the PPS input is taken for missing and the fix is applied
/// at its arrival.
pub const PPS_WAIT_S: f64 = 1.2;

/// A fix older than this (IMU time, s) makes the GPS stale: the solution is coasting.
pub const GPS_STALE_S: f64 = 2.5;

impl Navigator {
    /// A navigator with these settings.
    pub fn new(cfg: NavigationConfig) -> Self {
        Self {
            heading: cfg.initial_heading_deg.map(f64::to_radians),
            heading_sigma_deg: None,
            integrity: crate::navigation::integrity::IntegrityMonitor::new(cfg.integrity.clone()),
            cfg,
            phase: NavPhase::Waiting,
            first_fix: None,
            first_fix_accuracy: crate::navigation::filter::StatedAccuracy::default(),
            level: LevelWindow::default(),
            courses: std::collections::VecDeque::new(),
            level_waits: 0,
            moved: false,
            start_kind: None,
            still: LevelWindow::default(),
            still_first: None,
            state: None,
            kf: None,
            f_acc: Vector3::zeros(),
            t_acc: 0.0,
            last_pps: None,
            last_pps_seen: None,
            pps_rejected: 0,
            last_t: 0.0,
            started_at: None,
            fixes_seen: 0,
            fixes_ignored: 0,
            pps_edges: 0,
            last_good_fix_t: None,
            held: Vec::new(),
            edges: std::collections::VecDeque::new(),
            anchor: None,
            utc_last: None,
            utc_days: 0,
            first_ties: Vec::new(),
            accuracies: std::collections::VecDeque::new(),
            rejected: Vec::new(),
            utc_reanchors: 0,
            clock_jumps: 0,
            jump_streak: None,
            late_fixes: 0,
            untied_fixes: 0,
            v_at_pps: None,
            arrivals: (0.0, 0.0, 0),
            last_fix_at: None,
            clock: None,
        }
    }

    /// The receiver's latency after its PPS edge (s, in [-0.2, 0.8)), once learned from [`LATENCY_FIXES`] fixes: the circular mean of their
    /// arrivals after the last edge, so that a few arriving behind the IMU stream (just before
    /// their edge's frame was processed) do not drag it a second away.
    pub fn receiver_latency(&self) -> Option<f64> {
        let (c, s, n) = self.arrivals;
        // a latency is positive: what comes out of the circle below -0.2 s is a latency of
        // most of a second (a stream steadily 0.2 s behind the receiver is not one)
        (n >= LATENCY_FIXES).then(|| {
            let l = s.atan2(c) / std::f64::consts::TAU;
            if l < -0.2 { l + 1.0 } else { l }
        })
    }

    /// IMU time the last fix was taken at (its PPS edge, or its arrival without PPS), and its
    /// sentence's index in the stream.
    pub fn last_fix_time(&self) -> Option<(f64, u64)> {
        self.last_fix_at
    }

    /// The mode for the solution header.
    pub fn mode(&self) -> wire::NavMode {
        use wire::NavMode;
        match self.phase {
            NavPhase::Waiting => NavMode::Init,
            NavPhase::Levelling => NavMode::Levelling,
            NavPhase::Navigating if !self.cfg.gps_aiding => NavMode::Navigation,
            NavPhase::Navigating if self.gps_stale() => NavMode::Coasting,
            NavPhase::Navigating => NavMode::GpsAided,
        }
    }

    /// No good fix within [`GPS_STALE_S`] of IMU time.
    pub fn gps_stale(&self) -> bool {
        self.last_good_fix_t
            .is_none_or(|t| self.last_t - t > GPS_STALE_S)
    }

    /// The filter's horizontal position sigma (m) and heading sigma (deg); none without it.
    pub fn sigmas(&self) -> Option<(f64, f64)> {
        let (k, st) = (self.kf.as_ref()?, self.state.as_ref()?);
        let p = k.covariance();
        let (rm, rn) = crate::navigation::earth::radii(st.lat);
        let pos = (p[(6, 6)] * (rm + st.h).powi(2)
            + p[(7, 7)] * ((rn + st.h) * st.lat.cos()).powi(2))
        .sqrt();
        Some((pos, p[(2, 2)].sqrt().to_degrees()))
    }

    /// The filter's position covariance in a local East-North-Up plane, m^2, row-major (none
    /// before the filter runs).
    pub fn position_covariance_enu(&self) -> Option<[f64; 9]> {
        let (k, st) = (self.kf.as_ref()?, self.state.as_ref()?);
        let p = k.covariance();
        let (rm, rn) = crate::navigation::earth::radii(st.lat);
        // states 6, 7, 8: latitude and longitude (rad), height (m); to east, north, up metres
        let scale = [(rn + st.h) * st.lat.cos(), rm + st.h, 1.0];
        let state = [7, 6, 8];
        let mut c = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                c[3 * i + j] = p[(state[i], state[j])] * scale[i] * scale[j];
            }
        }
        Some(c)
    }

    /// The filter's velocity covariance, East-North-Up, (m/s)^2, row-major (none before the
    /// filter runs).
    pub fn velocity_covariance_enu(&self) -> Option<[f64; 9]> {
        let p = self.kf.as_ref()?.covariance();
        Some(std::array::from_fn(|k| p[(3 + k / 3, 3 + k % 3)]))
    }

    /// The filter's attitude sigmas about east, north and up (up: heading), deg.
    pub fn attitude_sigmas_deg(&self) -> Option<[f64; 3]> {
        let p = self.kf.as_ref()?.covariance();
        Some(std::array::from_fn(|i| {
            p[(i, i)].max(0.0).sqrt().to_degrees()
        }))
    }

    /// North-finding's heading (deg) becomes available.
    pub fn set_heading(&mut self, deg: f64, sigma_deg: Option<f64>) {
        self.heading = Some(deg.to_radians());
        self.heading_sigma_deg = sigma_deg;
    }

    /// A PPS edge at IMU time `t`; false when it was rejected (see
    /// [`NavigationConfig::pps_tolerance_s`]).
    pub fn on_pps(&mut self, t: f64) -> bool {
        let tol = self.cfg.pps_tolerance_s;
        // a true second in the IMU's seconds, and how far it may be off
        let (second, allowance) = match self.clock {
            Some(c) => (1.0 + c.ppm * 1e-6, PPS_CLOCK_ALLOWANCE),
            None => (1.0, PPS_CLOCK_ALLOWANCE_UNKNOWN),
        };
        let fits = |r: Option<f64>| {
            r.is_some_and(|r| {
                let d = t - r;
                let n = (d / second).round();
                n >= 1.0 && (d - n * second).abs() <= tol + allowance * d
            })
        };
        // the first edge, one that keeps the rhythm, or the second of a new rhythm (the last
        // edge taken was the glitch)
        let take = self.last_pps.is_none() || fits(self.last_pps) || fits(self.last_pps_seen);
        self.last_pps_seen = Some(t);
        if !take {
            self.pps_rejected += 1;
            if self.pps_rejected == 1 {
                tracing::warn!(
                    "a PPS edge at IMU time {t:.4} s is {:.4} s after the last one: not a whole second, rejected",
                    self.last_pps.map_or(0.0, |p| t - p)
                );
            }
            return false;
        }
        self.pps_edges += 1;
        let sec = match (self.edges.back(), self.last_pps) {
            (Some(&(s, _)), Some(p)) => s + (((t - p) / second).round() as i64).max(1),
            _ => 0,
        };
        self.edges.push_back((sec, t));
        if self.edges.len() > EDGES_KEPT {
            self.edges.pop_front();
        }
        if let Some(c) = ClockEstimate::from_edges(self.edges.iter())
            .filter(|c| c.sigma_ppm <= CLOCK_SIGMA_LIMIT_PPM)
        {
            self.clock = Some(c);
        }
        self.last_pps = Some(t);
        self.v_at_pps = self.state().map(|s| [s.v.x, s.v.y, s.v.z]);
        true
    }

    /// IMU time has reached `t` while the navigator does not yet take updates (north-finding
    /// still runs): fixes are tied to their PPS edges and taken as they fall due, so that the
    /// position is current at the handover and no fix waits for an edge that already came.
    pub fn on_time(&mut self, t: f64) {
        self.last_t = t;
        self.apply_due_fixes();
    }

    /// A processing-chain update valid at IMU time `t` over `dt` s.
    pub fn on_update(&mut self, t: f64, phi: [f64; 3], dv: [f64; 3], dt: f64) {
        self.last_t = t;
        self.apply_due_fixes();
        match self.phase {
            NavPhase::Waiting => {
                // a heading (north-finding or the config) and a position (the first good fix)
                // (or, in motion, the receiver's track where no heading is given)
                if (self.heading.is_some() || !self.courses.is_empty()) && self.first_fix.is_some()
                {
                    self.phase = NavPhase::Levelling;
                    self.level = LevelWindow::default();
                }
            }
            NavPhase::Levelling => {
                self.level.add_of(phi, dv, dt, self.cfg.level_s);
                if self.level.t >= self.cfg.level_s {
                    match self.judge_window(t) {
                        Judged::Start(kind) => self.start(t, kind),
                        Judged::Wait { moving } => {
                            // moving, and not steadily enough to align (or standing with no
                            // heading yet): a new window
                            if moving {
                                if self.level_waits == 0 {
                                    tracing::warn!(
                                        "the vehicle moves: levelling waits for it to drive steadily"
                                    );
                                }
                                self.level_waits += 1;
                                self.moved = true;
                            }
                            self.level = LevelWindow::default();
                        }
                    }
                }
            }
            NavPhase::Navigating => {
                // what depends on a second's length goes over the update's true length
                let dt = self.clock.map_or(dt, |c| c.true_dt(dt));
                let (Some(st), kf) = (self.state.as_mut(), self.kf.as_mut()) else {
                    return;
                };
                let (phi, dv) = match kf.as_ref() {
                    Some(k) => k.compensate(phi, dv, dt),
                    None => (phi, dv),
                };
                self.f_acc += st.q_nb * Vector3::from(dv);
                self.t_acc += dt;
                st.update(phi, dv, dt);
                if self.cfg.zero_velocity_sigma_mps > 0.0 {
                    self.still.add(phi, dv, dt);
                }
                if let Some(k) = kf
                    && self.t_acc >= 0.1
                {
                    k.propagate(st, &(self.f_acc / self.t_acc), self.t_acc);
                    self.f_acc = Vector3::zeros();
                    self.t_acc = 0.0;
                    if let Some((sigma, _)) = self.sigmas() {
                        self.integrity.on_position_sigma(sigma);
                    }
                }
                if self.still.t >= 0.5 * ZUPT_WINDOW_S {
                    match self.still_first.take() {
                        None => self.still_first = Some(self.still),
                        Some(first) => self.zero_velocity(t, &first),
                    }
                    self.still = LevelWindow::default();
                }
            }
        }
    }

    /// Whether the levelling window just ended lets navigation start, and how: still (the
    /// IMU's own evidence, and the receiver's speed where it tells one), or in motion (the
    /// receiver's velocity steady and fast enough to tell the way); none: wait.
    fn judge_window(&self, t: f64) -> Judged {
        let w = &self.level;
        let f = w.force();
        let (lat, h) = self.first_fix.map_or((0.0, 0.0), |(lat, _, h)| (lat, h));
        let g = crate::navigation::earth::gravity(lat, h);
        // the receiver's latest velocity, if it is recent (fixes are applied `fix_delay_s`
        // after they are taken, 1 Hz receivers the slowest)
        let recent = self
            .courses
            .back()
            .filter(|c| t - c.t <= 1.5 + self.cfg.fix_delay_s);
        let still_imu = w.spread() < STILL_FORCE_SPREAD
            && (f.norm() - g).abs() < STILL_FORCE_OFF_G
            && w.force_change() < STILL_FORCE_CHANGE
            && w.rate() < STILL_RATE;
        let still_speed = STILL_SPEED.max(4.0 * self.cfg.motion_velocity_sigma_mps);
        let still = still_imu && recent.is_none_or(|c| c.speed < still_speed);
        // a heading given for power-on (or found standing) is stale once the vehicle has
        // moved: after that only the receiver's track gives one, in motion
        if still && self.heading.is_some() && !self.moved {
            return Judged::Start(StartKind::Still);
        }
        let wait = Judged::Wait { moving: !still };
        let Some([a, b]) = self.last_two_courses() else {
            return wait;
        };
        let dt = b.t - a.t;
        let accel = ((b.v[0] - a.v[0]).hypot(b.v[1] - a.v[1])) / dt;
        if recent.is_some()
            && b.speed >= MOTION_MIN_SPEED
            && accel < MOTION_MAX_ACCEL
            && w.rate() < MOTION_MAX_RATE
        {
            Judged::Start(StartKind::InMotion)
        } else {
            wait
        }
    }

    /// The vehicle stood through the window just ended (the IMU's evidence, the receiver's
    /// speed where recent, and the INS's own speed): its velocity is measured as zero.
    fn zero_velocity(&mut self, t: f64, first: &LevelWindow) {
        let second = self.still;
        let mut w = *first;
        w.dv += second.dv;
        w.ff_dt += second.ff_dt;
        w.phi += second.phi;
        w.t += second.t;
        let (Some(st), Some(k)) = (self.state.as_mut(), self.kf.as_mut()) else {
            return;
        };
        let g = crate::navigation::earth::gravity(st.lat, st.h);
        // standing: its specific force is gravity and does not change (a vehicle setting off
        // or coming to a halt changes its force within a second, however gently)
        let still_imu = w.spread() < STILL_FORCE_SPREAD
            && (w.force().norm() - g).abs() < STILL_FORCE_OFF_G
            && (first.force() - second.force()).norm() < STILL_FORCE_CHANGE
            && w.rate() < STILL_RATE;
        let still_speed = STILL_SPEED.max(4.0 * self.cfg.motion_velocity_sigma_mps);
        let gps_still = self
            .courses
            .back()
            .filter(|c| t - c.t <= 1.5 + self.cfg.fix_delay_s)
            .is_none_or(|c| c.speed < still_speed);
        let p = k.covariance();
        let ins_sigma = (p[(3, 3)] + p[(4, 4)]).sqrt();
        let c = k.corrected(st);
        let ins_still = c.v.x.hypot(c.v.y) < ZUPT_MAX_INS_SPEED.max(3.0 * ins_sigma);
        // a steady force along the road is braking (or speeding up), not standing: the force
        // as the corrected state has it (with output correction the accelerometer bias learnt
        // is not yet out of the increments, and a 5 mg bias alone is 0.05 m/s^2)
        let bias = k.accel_bias_unapplied();
        let level = |h: &LevelWindow| {
            let f = c.q_nb * (h.force() - bias);
            f.x.hypot(f.y) < ZUPT_MAX_HORIZONTAL_FORCE
        };
        let unforced = level(first) && level(&second);
        if still_imu && gps_still && ins_still && unforced {
            k.zero_velocity(st, self.cfg.zero_velocity_sigma_mps);
        }
    }

    /// The receiver's last two velocities, 0.05 to 2.5 s apart.
    fn last_two_courses(&self) -> Option<[Course; 2]> {
        let n = self.courses.len();
        if n < 2 {
            return None;
        }
        let (a, b) = (self.courses[n - 2], self.courses[n - 1]);
        (b.t - a.t > 0.05 && b.t - a.t <= 2.5).then_some([a, b])
    }

    fn start(&mut self, t: f64, kind: StartKind) {
        let mut f = self.level.force();
        let (lat, lon, h) = self.first_fix.unwrap_or((0.0, 0.0, 0.0));
        let mut fc = self.cfg.filter.clone();
        let mut v0 = Vector3::zeros();
        let mut heading = self.heading.unwrap_or(0.0);
        if kind == StartKind::InMotion
            && let Some([a, b]) = self.last_two_courses()
        {
            // the vehicle's acceleration (ENU) between the receiver's last two velocities
            let dt = b.t - a.t;
            let acc = Vector3::new((b.v[0] - a.v[0]) / dt, (b.v[1] - a.v[1]) / dt, 0.0);
            let sv = self.cfg.motion_velocity_sigma_mps;
            // the heading is the way the vehicle goes (a heading given for power-on is stale
            // once it has driven), to within the track's noise and a land vehicle's slip
            heading = b.v[0].atan2(b.v[1]);
            let track_sigma = (sv / b.speed).atan().hypot(SLIP_RAD);
            fc.init_att_deg[2] = fc.init_att_deg[2].max(track_sigma.to_degrees());
            // the level from the specific force less that acceleration, taken into the body
            // by the attitude the raw force gives (twice: the second with the first's tilt)
            for _ in 0..2 {
                let (pitch, roll) = level_of(&f);
                let q = NavState::from_euler(heading, pitch, roll, v0, lat, lon, h).q_nb;
                f = self.level.force() - q.inverse() * acc;
            }
            // what is left unknown of the acceleration: the velocities' noise over their
            // interval, and its change since (as large as the acceleration itself)
            let sa = (2.0f64.sqrt() * sv / dt).hypot(acc.norm()).hypot(0.1);
            let tilt = (sa / f.norm()).atan().to_degrees();
            fc.init_att_deg[0] = fc.init_att_deg[0].max(tilt);
            fc.init_att_deg[1] = fc.init_att_deg[1].max(tilt);
            // the velocity carried from the fix to now; the vertical along the body's pitch
            // (a land vehicle goes where it points)
            let age = (t - b.t).max(0.0);
            let (pitch, _) = level_of(&f);
            v0 = Vector3::new(
                b.v[0] + acc.x * age,
                b.v[1] + acc.y * age,
                b.speed * pitch.tan(),
            );
            let vz_sigma = b.speed * (fc.init_att_deg[1].to_radians() + 0.5f64.to_radians());
            fc.init_vel_mps = fc.init_vel_mps.max(sv.hypot(sa * age)).max(vz_sigma);
            tracing::info!(
                speed_mps = b.speed,
                accel_mps2 = acc.norm(),
                tilt_sigma_deg = tilt,
                "navigation starts in motion"
            );
        }
        let (pitch, roll) = level_of(&f);
        // in motion the fix is behind the vehicle by its age: carried to now
        let (lat, lon, h) = match (kind, self.courses.back()) {
            (StartKind::InMotion, Some(b)) => {
                let age = (t - b.t).max(0.0);
                let (rm, rn) = crate::navigation::earth::radii(lat);
                (
                    lat + v0.y * age / (rm + h),
                    lon + v0.x * age / ((rn + h) * lat.cos()),
                    h + v0.z * age,
                )
            }
            _ => (lat, lon, h),
        };
        let st = NavState::from_euler(heading, pitch, roll, v0, lat, lon, h);
        self.kf = self.cfg.gps_aiding.then(|| {
            // the filter starts no surer of the heading than what found it (a degraded
            // north-finding's sigma is larger than the configured one)
            if let Some(s) = self.heading_sigma_deg {
                fc.init_att_deg[2] = fc.init_att_deg[2].max(s);
            }
            let mut k = Kf::new(fc, lat);
            k.levelled(&st.q_nb, f.norm());
            if self.first_fix.is_some() {
                k.started_at_fix(&self.first_fix_accuracy, &st);
            }
            k
        });
        self.state = Some(st);
        self.phase = NavPhase::Navigating;
        self.started_at = Some(t);
        self.start_kind = Some(kind);
        tracing::info!(
            lat_deg = lat.to_degrees(),
            lon_deg = lon.to_degrees(),
            heading_deg = heading.to_degrees(),
            ?kind,
            "navigation started"
        );
    }

    /// What the receiver said of a fix's accuracy: its HDOP, and the GST of the same UTC time.
    fn stated_accuracy(&self, fix: &GpsFix) -> crate::navigation::filter::StatedAccuracy {
        let gst = fix.time_of_day_s.and_then(|t| {
            self.accuracies
                .iter()
                .rev()
                .find(|a| a.time_of_day_s.is_some_and(|u| (u - t).abs() < 1e-3))
        });
        crate::navigation::filter::StatedAccuracy {
            gst: gst.map(|a| ([a.lat_sigma_m, a.lon_sigma_m], a.alt_sigma_m)),
            hdop: fix.hdop,
        }
    }

    /// The fixes the filter's gate refused since the last call.
    pub fn take_rejected(&mut self) -> Vec<RejectedFix> {
        std::mem::take(&mut self.rejected)
    }

    /// The receiver's statement of its accuracy (GST): kept for the fix of the same UTC time.
    pub fn on_accuracy(&mut self, a: &crate::frontend::gps_receiver::GpsAccuracy) {
        if self.accuracies.len() >= ACCURACIES_KEPT {
            self.accuracies.pop_front();
        }
        self.accuracies.push_back(*a);
    }

    /// A decoded GPS fix arrived (IMU time is that of the latest update). It is tied to its PPS
    /// edge and waits until IMU time reaches that edge (plus the fix's fraction of a second at
    /// receivers faster than 1 Hz) plus `fix_delay_s` (see [`NavigationConfig::fix_delay_s`]).
    ///
    /// The tie comes from the data: the fix's UTC time against the count of PPS edges in the
    /// IMU stream. The first fix decides which UTC second an edge is (the latest edge at or
    /// before its arrival, less its fraction of a second: a receiver outputs its fix after the
    /// pulse); from then on every fix's edge is its UTC second, whenever its bytes came, and
    /// after [`LATENCY_FIXES`] fixes the decision is checked against the receiver's learned
    /// latency (a receiver later than the IMU stream's lag behind it by most of a second). A
    /// fix without a time, or before any edge, is tied by its arrival.
    pub fn on_fix(&mut self, fix: &GpsFix) {
        let a = self.last_t;
        let utc = fix
            .time_of_day_s
            .filter(|_| !fix.time_backwards)
            .map(|u| self.unwrap_utc(u));
        if !fix.valid || fix.quality == 0 || fix.time_backwards {
            // nothing to tie: counted and set aside at once
            self.apply_fix(fix, a);
            return;
        }
        let Some(&(s_last, t_last)) = self.edges.back() else {
            // no PPS in the IMU stream (yet): wait for an edge, then by arrival
            self.held.push(Held {
                fix: fix.clone(),
                tie: Tie::Untied,
                arrived: a,
            });
            return;
        };
        let Some(u) = utc else {
            // no time in the sentence: the edge the fix came the receiver's latency after
            let sec = self.edge_by_arrival(a, 0.0, s_last, t_last);
            self.hold_or_apply(fix, sec, 0.0, a);
            return;
        };
        let (whole, frac) = (u.floor(), u - u.floor());
        let whole = whole as i64;
        if self.anchor.is_none() {
            let sec = self.edge_by_arrival(a, frac, s_last, t_last);
            self.anchor = Some(whole - sec);
        }
        if self.first_ties.len() < LATENCY_FIXES as usize {
            self.first_ties.push(FirstTie {
                whole,
                frac,
                arrived: a,
                s_last,
                t_last,
            });
            let anchor = self.anchor.unwrap_or(0);
            let edge_t = t_last + (whole - anchor - s_last) as f64;
            let ph = (a - edge_t - frac) * std::f64::consts::TAU;
            self.arrivals = (
                self.arrivals.0 + ph.cos(),
                self.arrivals.1 + ph.sin(),
                self.arrivals.2 + 1,
            );
            if self.first_ties.len() == LATENCY_FIXES as usize {
                self.check_anchor();
            }
        }
        let mut sec = whole - self.anchor.unwrap_or(0);
        if sec > s_last + 2 || sec < s_last - 2 {
            // a time that fits no edge near: a receiver whose clock jumped, or a fix seconds
            // old. Set aside, unless the receiver's clock stays where it jumped to: then the
            // edges are tied to its seconds anew.
            let candidate = whole - self.edge_by_arrival(a, frac, s_last, t_last);
            self.jump_streak = match self.jump_streak {
                Some((c, n)) if c == candidate => Some((c, n + 1)),
                _ => Some((candidate, 1)),
            };
            if self.jump_streak.is_some_and(|(_, n)| n < JUMPS_TO_REANCHOR) {
                self.clock_jumps += 1;
                self.fixes_seen += 1;
                self.fixes_ignored += 1;
                return;
            }
            tracing::warn!("the receiver's clock moved: its fixes are tied to the PPS edges anew");
            self.anchor = Some(candidate);
            self.utc_reanchors += 1;
            sec = whole - candidate;
        }
        self.jump_streak = None;
        self.hold_or_apply(fix, sec, frac, a);
    }

    /// The edge (its second number) a fix arriving at IMU time `a`, `frac` s after its UTC
    /// second, belongs to: the latest edge at or before `a - frac` until the receiver's
    /// latency is learned, then the edge nearest `a - frac - latency`.
    fn edge_by_arrival(&self, a: f64, frac: f64, s_last: i64, t_last: f64) -> i64 {
        let x = a - frac - t_last;
        let n = match self.receiver_latency() {
            Some(l) => (x - l).round(),
            None => (x + 1e-9).floor(),
        };
        s_last + n as i64
    }

    /// With the receiver's latency learned, the first fixes' edges by their arrival: when most
    /// say another UTC second for the edges than the first fix did, the tie moves there.
    fn check_anchor(&mut self) {
        let votes: Vec<i64> = self
            .first_ties
            .iter()
            .map(|f| f.whole - self.edge_by_arrival(f.arrived, f.frac, f.s_last, f.t_last))
            .collect();
        let best = votes
            .iter()
            .copied()
            .max_by_key(|v| (votes.iter().filter(|w| *w == v).count(), -*v))
            .unwrap_or(0);
        if Some(best) != self.anchor
            && votes.iter().filter(|v| **v == best).count() * 2 > votes.len()
        {
            tracing::warn!(
                "the receiver's fixes belong to the PPS edge a second {} than the first fix said (its latency {:.2} s): tied anew",
                if best < self.anchor.unwrap_or(0) {
                    "later"
                } else {
                    "earlier"
                },
                self.receiver_latency().unwrap_or(0.0)
            );
            self.utc_reanchors += 1;
            self.anchor = Some(best);
        }
    }

    /// A UTC time of day (s) made continuous across midnight.
    fn unwrap_utc(&mut self, u: f64) -> f64 {
        if let Some(last) = self.utc_last {
            if u < last - 43_200.0 {
                self.utc_days += 1;
            } else if u > last + 43_200.0 {
                self.utc_days -= 1;
            }
        }
        self.utc_last = Some(u);
        u + self.utc_days as f64 * 86_400.0
    }

    /// IMU time of the edge numbered `sec` (extrapolated a whole number of seconds from the
    /// nearest edge kept when it was missing); none when it has not come yet.
    fn edge_time(&self, sec: i64) -> Option<f64> {
        let &(s_last, t_last) = self.edges.back()?;
        if sec > s_last {
            return None;
        }
        let (s, t) = self
            .edges
            .iter()
            .rev()
            .find(|e| e.0 <= sec)
            .or(self.edges.front())
            .copied()
            .unwrap_or((s_last, t_last));
        Some(t + (sec - s) as f64)
    }

    /// Take the fix now when its time has passed (counted late), else hold it.
    fn hold_or_apply(&mut self, fix: &GpsFix, sec: i64, frac: f64, a: f64) {
        if let Some(t) = self.edge_time(sec)
            && self.last_t >= t + frac + self.cfg.fix_delay_s
        {
            self.late_fixes += 1;
            self.apply_fix(fix, t + frac);
            return;
        }
        self.held.push(Held {
            fix: fix.clone(),
            tie: Tie::Edge(sec, frac),
            arrived: a,
        });
    }

    /// Fixes whose PPS edge has not come within [`PPS_WAIT_S`] plus `fix_delay_s` of their
    /// arrival: the PPS input is missing. They are applied at their arrival less `fix_delay_s`
    /// and counted, rather than held until an edge comes back and then applied at the wrong
    /// time.
    fn apply_untied_fixes(&mut self) {
        let wait = PPS_WAIT_S + self.cfg.fix_delay_s;
        if !self.held.iter().any(|h| self.last_t - h.arrived > wait) {
            return;
        }
        let held = std::mem::take(&mut self.held);
        for h in held {
            if self.last_t - h.arrived > wait {
                self.untied_fixes += 1;
                if self.untied_fixes == 1 {
                    tracing::warn!(
                        "a GPS fix waited {wait} s for its PPS edge: the PPS input is missing; fixes are applied at their arrival"
                    );
                }
                self.apply_fix(&h.fix, h.arrived - self.cfg.fix_delay_s);
            } else {
                self.held.push(h);
            }
        }
    }

    /// When the held fix is due: IMU time of its edge (plus its fraction), once that edge has
    /// come; a fix that came before any edge is tied by its arrival once there is one.
    fn due_at(&self, h: &Held) -> Option<f64> {
        match h.tie {
            Tie::Edge(sec, frac) => self.edge_time(sec).map(|t| t + frac),
            Tie::Untied => None,
        }
    }

    /// Apply the held fixes whose time has come (their edge, plus their fraction, plus the
    /// delay), in the order of those times.
    fn apply_due_fixes(&mut self) {
        // fixes that came before the first edge: tied now that there is one
        if !self.edges.is_empty() && self.held.iter().any(|h| h.tie == Tie::Untied) {
            let held = std::mem::take(&mut self.held);
            for h in held {
                if h.tie == Tie::Untied
                    && let Some(&(s_last, t_last)) = self.edges.front()
                {
                    let frac = h.fix.time_of_day_s.map_or(0.0, |u| u - u.floor());
                    let sec = self.edge_by_arrival(h.arrived.max(t_last), frac, s_last, t_last);
                    if let Some(u) = h.fix.time_of_day_s
                        && self.anchor.is_none()
                    {
                        self.anchor = Some(u.floor() as i64 - sec);
                    }
                    self.held.push(Held {
                        tie: Tie::Edge(sec, frac),
                        ..h
                    });
                } else {
                    self.held.push(h);
                }
            }
        }
        self.apply_untied_fixes();
        let d = self.cfg.fix_delay_s;
        if !self
            .held
            .iter()
            .any(|h| self.due_at(h).is_some_and(|t| self.last_t >= t + d))
        {
            return;
        }
        let mut held = std::mem::take(&mut self.held);
        held.sort_by(|a, b| {
            let (ta, tb) = (self.due_at(a), self.due_at(b));
            ta.unwrap_or(f64::INFINITY)
                .total_cmp(&tb.unwrap_or(f64::INFINITY))
        });
        for h in held {
            match self.due_at(&h) {
                Some(t) if self.last_t >= t + d => self.apply_fix(&h.fix, t),
                _ => self.held.push(h),
            }
        }
    }

    /// Apply a fix taken at IMU time `taken_at`.
    fn apply_fix(&mut self, fix: &GpsFix, taken_at: f64) {
        self.fixes_seen += 1;
        self.last_fix_at = Some((taken_at, fix.seq));
        if !fix.valid || fix.time_backwards || fix.quality == 0 {
            self.fixes_ignored += 1;
            return;
        }
        self.last_good_fix_t = Some(self.last_t);
        // RMC, GLL carry no height: they keep the one GGA gave (a start at height 0 wherever the
        // vehicle is had every later fix rejected at 1700 m)
        let alt = fix
            .ellipsoid_height_m()
            .or(self.first_fix.map(|f| f.2))
            .unwrap_or(0.0);
        let p = (fix.lat_deg.to_radians(), fix.lon_deg.to_radians(), alt);
        if let (Some(speed), Some(track)) = (fix.speed_mps, fix.track_deg)
            && speed.is_finite()
            && track.is_finite()
        {
            let (s, c) = track.to_radians().sin_cos();
            if self.courses.len() >= 4 {
                self.courses.pop_front();
            }
            self.courses.push_back(Course {
                t: taken_at,
                v: [speed * s, speed * c],
                speed,
            });
        }
        if self.phase != NavPhase::Navigating {
            self.first_fix = Some(p);
            if fix.sentence == "GGA" {
                self.first_fix_accuracy = self.stated_accuracy(fix);
            }
            return;
        }
        // RMC's speed and track against the INS's velocity when the fix was taken
        if let (Some(v), Some(speed), Some(track)) = (self.v_at_pps, fix.speed_mps, fix.track_deg) {
            let (s, c) = track.to_radians().sin_cos();
            self.integrity.on_velocity(v, [speed * s, speed * c]);
        }
        // only GGA carries a full position (RMC repeats it without height)
        if fix.sentence != "GGA" {
            return;
        }
        let stated = self.stated_accuracy(fix);
        let (Some(st), Some(k)) = (self.state.as_mut(), self.kf.as_mut()) else {
            self.fixes_ignored += 1;
            return;
        };
        // carry the fix forward from when it was taken to now with the INS velocity
        let dt = (self.last_t - taken_at).clamp(0.0, 2.0);
        let (rm, rn) = crate::navigation::earth::radii(st.lat);
        let lat = p.0 + st.v.y * dt / (rm + st.h);
        let lon = p.1 + st.v.x * dt / ((rn + st.h) * st.lat.cos());
        let h = p.2 + st.v.z * dt;
        let used = k.update(st, lat, lon, h, &stated);
        if !used {
            self.fixes_ignored += 1;
            if self.rejected.len() < REJECTED_KEPT {
                self.rejected.push(RejectedFix {
                    lat_deg: fix.lat_deg,
                    lon_deg: fix.lon_deg,
                    nis: k.last_nis(),
                    t_s: taken_at,
                });
            }
        }
        if let Some(nis) = k.last_nis() {
            self.integrity.on_fix(nis, !used);
        }
    }

    /// The solution's integrity monitor.
    pub fn integrity(&self) -> &crate::navigation::integrity::IntegrityMonitor {
        &self.integrity
    }

    /// IMU time of the latest update, s.
    pub fn time(&self) -> f64 {
        self.last_t
    }

    /// The filter (once navigating with GPS aiding).
    pub fn filter(&self) -> Option<&Kf> {
        self.kf.as_ref()
    }

    /// The best current state.
    pub fn state(&self) -> Option<NavState> {
        let st = self.state?;
        Some(self.kf.as_ref().map_or(st, |k| k.corrected(&st)))
    }

    /// Summary.
    pub fn summary(&self) -> NavigatorSummary {
        NavigatorSummary {
            phase: self.phase,
            started_at_s: self.started_at,
            output: self.state().map(|s| s.output()),
            output_t_s: self.last_t,
            filter: self.kf.as_ref().map(Kf::stats),
            fixes_seen: self.fixes_seen,
            fixes_ignored: self.fixes_ignored,
            pps_edges: self.pps_edges,
            late_fixes: self.late_fixes,
            untied_fixes: self.untied_fixes,
            pps_rejected: self.pps_rejected,
            receiver_latency_s: self.receiver_latency(),
            utc_edge_offset_s: self.anchor,
            utc_reanchors: self.utc_reanchors,
            clock_jumps: self.clock_jumps,
            integrity: self.integrity.stats(),
            imu_clock: self.clock,
            start: self.start_kind,
            level_waits: self.level_waits,
        }
    }
}

/// Pitch and roll (rad) of a body whose mean specific force is `f` (gravity's reaction).
fn level_of(f: &Vector3<f64>) -> (f64, f64) {
    let roll = (-f.x).atan2(f.z);
    let pitch = f.y.atan2((f.x * f.x + f.z * f.z).sqrt());
    (pitch, roll)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A PPS line with jitter within the tolerance keeps every edge; a glitch between two edges
    /// is rejected and counted, the rhythm goes on; a gap of whole seconds (PPS missing) is no
    /// glitch; when the first edge ever was the glitch, the true rhythm is taken from its
    /// second edge on.
    #[test]
    fn pps_edges_off_the_whole_second_are_rejected_and_counted() {
        let mut n = Navigator::new(NavigationConfig::default());
        let taken: Vec<bool> = [1.0, 2.0008, 2.9993, 4.0, 4.37, 5.0011, 9.0, 10.0]
            .into_iter()
            .map(|t| n.on_pps(t))
            .collect();
        assert_eq!(taken, [true, true, true, true, false, true, true, true]);
        let s = n.summary();
        assert_eq!((s.pps_edges, s.pps_rejected), (7, 1));
        assert_eq!(n.last_pps, Some(10.0));

        let mut n = Navigator::new(NavigationConfig::default());
        for t in [0.63, 1.0, 2.0, 3.0] {
            n.on_pps(t);
        }
        let s = n.summary();
        assert_eq!((s.pps_edges, s.pps_rejected), (3, 1));
        assert_eq!(n.last_pps, Some(3.0));
    }

    /// An IMU whose oscillator runs 2,500 ppm fast: its edges are taken, the rate is read from
    /// them, the edges are then held to it (a glitch is still refused), and a gap of seconds
    /// keeps its second numbers.
    #[test]
    fn the_imus_rate_is_read_from_its_edges_and_they_are_held_to_it() {
        let mut n = Navigator::new(NavigationConfig::default());
        let second = 1.0025;
        let edge = |k: i64| 0.4 + k as f64 * second;
        for k in 0..20 {
            assert!(n.on_pps(edge(k)), "edge {k}");
        }
        assert!(!n.on_pps(edge(20) - 0.3), "a glitch");
        // thirty seconds without a pulse: 75 ms of the IMU's seconds, a numbering nominal
        // seconds would get wrong past 200 s
        for k in 50..60 {
            assert!(n.on_pps(edge(k)), "edge {k}");
        }
        let s = n.summary();
        assert_eq!((s.pps_edges, s.pps_rejected), (30, 1));
        let c = s.imu_clock.expect("the rate is read");
        assert!((c.ppm - 2500.0).abs() < 1e-3, "{c:?}");
        assert_eq!((c.edges, c.span_s), (30, 59.0));
        assert!((c.true_dt(second) - 1.0).abs() < 1e-12);
    }

    /// While north-finding runs the navigator takes no updates, only the time: fixes are still
    /// tied to their PPS edges and taken when due (the position stays current), none is held
    /// past its edge and none is counted as lacking one. Until 2026-11-23 every fix of a
    /// 145 s north-finding piled up and was then counted "untied" (PPS missing) at once.
    #[test]
    fn fixes_during_north_finding_are_taken_at_their_edges() {
        let mut n = Navigator::new(NavigationConfig::default());
        let fix = |k: u32| GpsFix {
            sentence: "GGA".into(),
            lat_deg: -45.0 + f64::from(k) * 1e-6,
            lon_deg: 170.0,
            alt_m: Some(5.0),
            quality: 1,
            valid: true,
            ..GpsFix::default()
        };
        let mut t = 0.0;
        for k in 0..150u32 {
            // the edge at the whole second, the fix 0.1 s later, time moving in 10 ms steps
            for step in 0..100 {
                t = f64::from(k) + f64::from(step) * 0.01;
                n.on_time(t);
                if step == 0 {
                    assert!(n.on_pps(t));
                }
                if step == 10 {
                    n.on_fix(&fix(k));
                }
            }
        }
        assert!(t > 149.0);
        let s = n.summary();
        assert_eq!(s.untied_fixes, 0);
        assert_eq!(s.fixes_seen, 150, "every fix taken once due");
        assert!(n.held.is_empty());
        let (lat, _, _) = n.first_fix.expect("a position");
        assert!((lat.to_degrees() - (-45.0 + 149e-6)).abs() < 1e-9);
    }

    /// A receiver whose fixes come 0.7 s after their pulse: once its latency is learned, each
    /// fix is taken at its own edge, not the next one (which the half-second rule alone picks:
    /// a position error of a second's travel); and a bench receiver 0.05 s after the pulse
    /// whose fix now and then reaches nav before the edge's IMU frame is still tied right.
    #[test]
    fn fixes_are_tied_to_their_own_edge_whatever_the_receivers_latency() {
        for (latency, early_every) in [(0.7, None), (0.05, Some(4))] {
            let mut n = Navigator::new(NavigationConfig::default());
            let mut taken = Vec::new();
            for k in 0..20u32 {
                let edge = f64::from(k);
                for step in 0..100 {
                    let t = edge + f64::from(step) * 0.01;
                    // the IMU stream behind the receiver now and then: the edge's frame is
                    // processed after the fix
                    let early = early_every.is_some_and(|e| k % e == 3);
                    if step == 0 && !early {
                        assert!(n.on_pps(edge));
                    }
                    n.on_time(t);
                    let arrive = (latency * 100.0f64).round() as i32;
                    if k > 0 && step == arrive {
                        n.on_fix(&GpsFix {
                            sentence: "GGA".into(),
                            lat_deg: 60.0,
                            lon_deg: 25.0,
                            alt_m: Some(5.0),
                            quality: 1,
                            valid: true,
                            seq: u64::from(k),
                            time_of_day_s: Some(43_200.0 + f64::from(k)),
                            ..GpsFix::default()
                        });
                    }
                    if step == 0 && early {
                        assert!(n.on_pps(edge));
                    }
                    if step == 99
                        && let Some(at) = n.last_fix_time()
                    {
                        taken.push((k, at));
                    }
                }
            }
            // by the end of each second from the seventh on (the latency learned), that
            // second's fix was taken, at its own edge
            for &(k, (at, seq)) in taken.iter().filter(|(k, _)| *k >= 7) {
                assert_eq!(
                    seq,
                    u64::from(k),
                    "latency {latency}: second {k}: fix {seq} last"
                );
                assert!(
                    (at - f64::from(k)).abs() < 1e-9,
                    "latency {latency}: fix of second {k} taken at {at}"
                );
            }
            let l = n.receiver_latency().expect("learned");
            assert!((l - latency).abs() < 0.02, "{l}");
        }
    }

    /// The fix last taken, when it is new.
    fn note_taken(n: &Navigator, taken: &mut Vec<(f64, u64)>) {
        if let Some(x) = n.last_fix_time()
            && taken.last() != Some(&x)
        {
            taken.push(x);
        }
    }

    fn timed_fix(utc: f64, seq: u64) -> GpsFix {
        GpsFix {
            sentence: "GGA".into(),
            lat_deg: 60.0,
            lon_deg: 25.0,
            alt_m: Some(5.0),
            quality: 1,
            valid: true,
            seq,
            time_of_day_s: Some(utc),
            ..GpsFix::default()
        }
    }

    /// Each fix is taken at the IMU time its UTC time says (its edge, plus its fraction of a
    /// second at 5 Hz), however late or early within its second its bytes came: the arrival
    /// only decides which UTC second the first edge is. A first fix that comes before the IMU
    /// stream has shown any edge is tied once the edge is there, not applied at its arrival.
    #[test]
    fn fixes_are_taken_at_the_time_their_utc_says_whenever_they_arrive() {
        // arrivals: a fixed offset, or jumping about within the second (a loaded host)
        for jitter in [false, true] {
            let mut n = Navigator::new(NavigationConfig::default());
            let mut taken = Vec::new();
            let mut seq = 0u64;
            // the receiver's UTC second of day at IMU time 0.3 (the first edge)
            let utc0 = 50_000.0;
            let mut pending: Vec<(f64, GpsFix)> = Vec::new();
            for i in 0..2000u32 {
                let t = f64::from(i) * 0.005;
                n.on_time(t);
                // edges at 0.3, 1.3, ...; the first one comes after the first fix arrives
                if ((t - 0.3) / 1.0).fract().abs() < 1e-9 && t >= 0.3 {
                    assert!(n.on_pps(t));
                }
                // epochs at 5 Hz from the first edge on, their bytes 0.06-0.35 s later
                if t >= 0.3 - 1e-9 && (((t - 0.3) * 5.0).round() - (t - 0.3) * 5.0).abs() < 1e-9 {
                    let e = ((t - 0.3) * 5.0).round();
                    let delay = if jitter {
                        0.06 + 0.29 * ((e * 0.37).sin().abs())
                    } else {
                        0.08
                    };
                    seq += 1;
                    pending.push((t + delay, timed_fix(utc0 + e * 0.2, seq)));
                }
                // a fix whose bytes came before the first edge was seen
                if i == 50 {
                    n.on_fix(&timed_fix(utc0 - 0.2 + 0.0, 0));
                }
                pending.retain(|(at, f)| {
                    if t >= *at - 1e-9 {
                        n.on_fix(f);
                        false
                    } else {
                        true
                    }
                });
                note_taken(&n, &mut taken);
            }
            let s = n.summary();
            assert_eq!(
                (s.late_fixes, s.untied_fixes, s.utc_reanchors),
                (0, 0, 0),
                "{s:?}"
            );
            for &(at, seq) in taken.iter().filter(|x| x.1 > 0) {
                let want = 0.3 + (seq - 1) as f64 * 0.2;
                assert!(
                    (at - want).abs() < 1e-9,
                    "jitter {jitter}: fix {seq} taken at {at}, not {want}"
                );
            }
            assert!(taken.len() > 40, "{}", taken.len());
            assert_eq!(s.utc_edge_offset_s, Some(50_000));
        }
    }

    /// A receiver whose clock jumps (here 100 s ahead, and stays there): the first fixes with
    /// the new time fit no edge and are set aside, then the edges are tied to its seconds anew
    /// and its fixes are taken at their edges again.
    #[test]
    fn a_receiver_clock_that_jumps_and_stays_is_followed_after_three_fixes() {
        let mut n = Navigator::new(NavigationConfig::default());
        let mut taken = Vec::new();
        for k in 0..30u32 {
            for step in 0..100 {
                let t = f64::from(k) + f64::from(step) * 0.01;
                n.on_time(t);
                if step == 0 {
                    assert!(n.on_pps(t));
                }
                if step == 10 {
                    let jump = if k >= 15 { 100.0 } else { 0.0 };
                    n.on_fix(&timed_fix(1000.0 + f64::from(k) + jump, u64::from(k)));
                }
                note_taken(&n, &mut taken);
            }
        }
        let s = n.summary();
        assert_eq!(
            (s.clock_jumps, s.utc_reanchors, s.late_fixes),
            (2, 1, 0),
            "{s:?}"
        );
        assert_eq!(s.utc_edge_offset_s, Some(1100));
        let seqs: Vec<u64> = taken.iter().map(|x| x.1).collect();
        assert!(!seqs.contains(&15) && !seqs.contains(&16), "{seqs:?}");
        for &(at, seq) in &taken {
            assert!((at - seq as f64).abs() < 1e-9, "fix {seq} taken at {at}");
        }
        assert!(seqs.contains(&17) && seqs.contains(&28), "{seqs:?}");
    }

    /// Navigation starts at the height the receiver gives, whatever the sentence that came last
    /// before the start (RMC has none), at an alpine pass and at the Dead Sea: no fix of the
    /// first minute is rejected.
    #[test]
    fn navigation_starts_at_the_receivers_height_with_no_rejection() {
        for height in [1700.0, -430.0, 4000.0, 5000.0] {
            let mut n = Navigator::new(NavigationConfig {
                enabled: true,
                initial_heading_deg: Some(0.0),
                ..NavigationConfig::default()
            });
            let dt = 0.01;
            let g = 9.80665 - height * 3.086e-6;
            for i in 0..6000u32 {
                let t = f64::from(i + 1) * dt;
                n.on_update(t, [0.0; 3], [0.0, 0.0, g * dt], dt);
                if (i + 1) % 100 == 0 {
                    assert!(n.on_pps(t));
                    let k = u64::from((i + 1) / 100);
                    let utc = 40_000.0 + k as f64;
                    let gga = GpsFix {
                        alt_m: Some(height),
                        ..timed_fix(utc, 2 * k)
                    };
                    let rmc = GpsFix {
                        sentence: "RMC".into(),
                        alt_m: None,
                        ..timed_fix(utc, 2 * k + 1)
                    };
                    n.on_fix(&gga);
                    n.on_fix(&rmc);
                }
            }
            let s = n.summary();
            assert_eq!(s.phase, NavPhase::Navigating, "{height} m");
            let f = s.filter.expect("the filter runs");
            assert!(f.updates > 40, "{height} m: {f:?}");
            assert_eq!(f.rejected, 0, "{height} m: {f:?}");
            let h = s.output.expect("a solution").h_m;
            assert!((h - height).abs() < 5.0, "{height} m: at {h} m");
        }
    }

    /// A vehicle driving north on a level road: from rest it accelerates at `accel` m/s^2 from
    /// `t_go` s for `accel_s` s, then cruises; updates at 100 Hz, a fix (GGA and RMC with the
    /// speed and track) at each PPS edge. Returns the navigator after `end` s.
    fn drive_north(
        t_go: f64,
        accel: f64,
        accel_s: f64,
        end: f64,
        heading: Option<f64>,
    ) -> Navigator {
        drive_north_with(
            |t| {
                if t > t_go && t <= t_go + accel_s {
                    accel
                } else {
                    0.0
                }
            },
            end,
            heading,
        )
    }

    /// A vehicle driving north on a level road from rest with the acceleration `accel_at(t)`
    /// (m/s^2, constant over each 10 ms step), as [`drive_north`].
    fn drive_north_with(
        accel_at: impl Fn(f64) -> f64,
        end: f64,
        heading: Option<f64>,
    ) -> Navigator {
        let mut n = Navigator::new(NavigationConfig {
            enabled: true,
            initial_heading_deg: heading,
            ..NavigationConfig::default()
        });
        let dt = 0.01;
        let g = crate::navigation::earth::gravity(60f64.to_radians(), 5.0);
        let (mut speed, mut distance) = (0.0, 0.0);
        let steps = (end / dt).round() as u32;
        for i in 0..steps {
            let t = f64::from(i + 1) * dt;
            let a = accel_at(t);
            distance += speed * dt + 0.5 * a * dt * dt;
            speed += a * dt;
            // metres north to degrees at 60 N (the meridian's degree there)
            let lat = 60.0 + distance / 111_412.0;
            // the body level, pointing north (x east, y north, z up): its forward (y) axis
            // feels the acceleration, its gyros the earth's rate and the turn over the earth's
            // curve as the vehicle drives north
            let l = lat.to_radians();
            let omega = crate::navigation::earth::OMEGA_IE;
            let w = [-speed / 6_381_000.0, omega * l.cos(), omega * l.sin()];
            n.on_update(t, w.map(|x| x * dt), [0.0, a * dt, g * dt], dt);
            if (i + 1) % 100 == 0 {
                assert!(n.on_pps(t));
                let k = u64::from((i + 1) / 100);
                let utc = 40_000.0 + k as f64;
                n.on_fix(&GpsFix {
                    lat_deg: lat,
                    ..timed_fix(utc, 2 * k)
                });
                n.on_fix(&GpsFix {
                    sentence: "RMC".into(),
                    alt_m: None,
                    lat_deg: lat,
                    speed_mps: Some(speed),
                    track_deg: Some(0.0),
                    ..timed_fix(utc, 2 * k + 1)
                });
            }
        }
        n
    }

    /// Levelling refuses a vehicle that moves: one accelerating at 2 m/s^2 from power-on is
    /// neither levelled as if it stood (its tilt would be 12 deg) nor aligned while its speed
    /// changes; once it cruises steadily it is aligned in motion, with the receiver's velocity
    /// and track, and the solution's pitch is level. A vehicle standing is levelled still.
    #[test]
    fn levelling_refuses_motion_and_aligns_once_the_vehicle_drives_steadily() {
        // standing: still, at once
        let n = drive_north(1e9, 0.0, 0.0, 10.0, Some(0.0));
        let s = n.summary();
        assert_eq!(s.start, Some(StartKind::Still));
        assert_eq!(s.level_waits, 0);
        // accelerating from power-on for 15 s, then cruising at 30 m/s
        let n = drive_north(0.0, 2.0, 15.0, 12.0, Some(0.0));
        assert_ne!(
            n.summary().phase,
            NavPhase::Navigating,
            "levelled while accelerating"
        );
        assert!(n.summary().level_waits >= 2, "{:?}", n.summary());
        let n = drive_north(0.0, 2.0, 15.0, 18.0, Some(0.0));
        let s = n.summary();
        assert_eq!(s.start, Some(StartKind::InMotion), "{s:?}");
        let started = s.started_at_s.expect("started");
        assert!(
            started > 15.0,
            "aligned at {started} s, before the speed settled"
        );
        let st = n.state().expect("a state");
        let (_, pitch, roll) = st.euler();
        assert!(pitch.abs() < 1e-3 && roll.abs() < 1e-3, "{pitch} {roll}");
        assert!(
            (st.v.y - 30.0).abs() < 0.5 && st.v.x.abs() < 0.5,
            "{:?}",
            st.v
        );
        // accelerating gently and steadily (0.5 m/s^2, the IMU's force constant, gravity's size
        // within a few mg): the receiver's speed says it moves; once fast enough it is aligned
        // in motion, its level the force less the acceleration between the receiver's
        // velocities (taken as still, its pitch would be 0.05 rad)
        let n = drive_north(0.0, 0.5, 100.0, 12.0, Some(0.0));
        let s = n.summary();
        assert_eq!(s.start, Some(StartKind::InMotion), "{s:?}");
        assert!(s.level_waits >= 1, "{s:?}");
        let (_, pitch, roll) = n.state().expect("a state").euler();
        assert!(pitch.abs() < 2e-3 && roll.abs() < 1e-3, "{pitch} {roll}");
        // the filter says it is less sure of its level and its velocity than a still start
        let k = n.filter().expect("the filter");
        let still = drive_north(1e9, 0.0, 0.0, 10.0, Some(0.0));
        let ks = still.filter().expect("the filter");
        assert!(k.covariance()[(0, 0)] > 10.0 * ks.covariance()[(0, 0)]);
    }

    /// At a stop the vehicle's velocity is known to be zero: a standing vehicle gets a
    /// zero-velocity update each second and its velocity sigma shrinks to what standing
    /// leaves; one cruising at a constant speed on a smooth road feels what a standing one
    /// feels, but its INS and its receiver know it moves, and it gets none.
    #[test]
    fn zero_velocity_updates_at_stops_and_never_while_cruising() {
        let n = drive_north(1e9, 0.0, 0.0, 60.0, Some(0.0));
        let f = n.filter().expect("the filter").stats();
        assert!(f.zero_velocity_updates >= 50, "{f:?}");
        assert_eq!(f.zero_velocity_refused, 0, "{f:?}");
        let p = n.filter().expect("the filter").covariance();
        let sigma = (p[(3, 3)] + p[(4, 4)]).sqrt();
        assert!(sigma < 0.01, "velocity sigma {sigma} m/s at a stop");
        let n = drive_north(0.0, 2.0, 15.0, 60.0, Some(0.0));
        let f = n.filter().expect("the filter").stats();
        assert_eq!(f.zero_velocity_updates, 0, "{f:?}");
        // braking steadily and gently to a halt at 0.2 m/s^2 (the force's size within 2 mm/s^2
        // of gravity's, and constant): for its last 2.5 s the INS's and the receiver's speeds
        // are under their limits, and only the force's level part says it still moves; no
        // update until it stands, and its velocity at the stop is the receiver's and the
        // IMU's, not a zero taken before it
        let braking = |t: f64| match t {
            t if t > 10.0 && t <= 13.0 => 1.0,
            t if t > 23.0 && t <= 38.0 => -0.2,
            _ => 0.0,
        };
        let updates = |end: f64| {
            let n = drive_north_with(braking, end, Some(0.0));
            n.filter().expect("the filter").stats()
        };
        let (before, braked) = (updates(10.0), updates(37.9));
        assert!(before.zero_velocity_updates >= 5, "{before:?}");
        assert_eq!(
            braked.zero_velocity_updates, before.zero_velocity_updates,
            "an update while the vehicle moved"
        );
        let n = drive_north_with(braking, 55.0, Some(0.0));
        let f = n.filter().expect("the filter").stats();
        assert_eq!(f.zero_velocity_refused, 0, "{f:?}");
        assert!(
            f.zero_velocity_updates >= before.zero_velocity_updates + 12,
            "{f:?}"
        );
        let v = n.state().expect("a state").v;
        assert!(v.norm() < 0.02, "standing 17 s after braking: {v:?} m/s");
        // and none where they are switched off
        let mut cfg = NavigationConfig {
            enabled: true,
            initial_heading_deg: Some(0.0),
            zero_velocity_sigma_mps: 0.0,
            ..NavigationConfig::default()
        };
        cfg.filter.kind = crate::navigation::filter::FilterKind::Standard;
        let mut n = Navigator::new(cfg);
        let g = crate::navigation::earth::gravity(60f64.to_radians(), 5.0);
        for i in 0..3000u32 {
            let t = f64::from(i + 1) * 0.01;
            n.on_update(t, [0.0; 3], [0.0, 0.0, g * 0.01], 0.01);
            if (i + 1) % 100 == 0 {
                assert!(n.on_pps(t));
                let k = u64::from((i + 1) / 100);
                n.on_fix(&timed_fix(40_000.0 + k as f64, k));
            }
        }
        let f = n.filter().expect("the filter").stats();
        assert!(
            f.updates > 20 && f.zero_velocity_updates == 0,
            "{f:?} {:?}",
            n.summary()
        );
    }
}
