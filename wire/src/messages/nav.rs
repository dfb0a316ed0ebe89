//! nav's solution family: NAV_TIME, NAV_ATT, NAV_VEL, NAV_POS, NAV_HGT.

use super::*;

/// Signal specs of NAV_TIME.
pub mod nav_time {
    use super::*;
    sig!(SAMPLE_COUNT = SignalSpec::uint("SampleCount", 0, 32));
    sig!(SEQ = SignalSpec::uint("Seq", 32, 8));
    sig!(MODE = SignalSpec::uint("Mode", 40, 4));
    sig!(GPS_RX_BYTES = SignalSpec::uint("GpsRxBytes", 50, 12));
    /// Health bits, in the order of [`super::NavHealth`]'s fields.
    pub const HEALTH: [SignalSpec; 8] = [
        SignalSpec::uint("HealthImuTimeout", 44, 1),
        SignalSpec::uint("HealthImuGaps", 45, 1),
        SignalSpec::uint("HealthImuBit", 46, 1),
        SignalSpec::uint("HealthGpsStale", 47, 1),
        SignalSpec::uint("HealthTurntable", 48, 1),
        SignalSpec::uint("HealthFilter", 49, 1),
        SignalSpec::uint("HealthGpsData", 62, 1),
        SignalSpec::uint("HealthCanBus", 63, 1),
    ];
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "NAV_TIME",
        id: 0x200,
        dlc: 8,
        signals: &[
            &SAMPLE_COUNT,
            &SEQ,
            &MODE,
            &HEALTH[0],
            &HEALTH[1],
            &HEALTH[2],
            &HEALTH[3],
            &HEALTH[4],
            &HEALTH[5],
            &GPS_RX_BYTES,
            &HEALTH[6],
            &HEALTH[7],
        ],
        frames_per_second: 50.0,
        sender: "NAV",
    };
}

/// Signal specs of NAV_ATT.
pub mod nav_att {
    use super::*;
    sig!(SEQ = SignalSpec::uint("Seq", 0, 8));
    sig!(HEADING = SignalSpec::scaled("Heading", 8, 20, false, 0.0004));
    sig!(PITCH = SignalSpec::scaled("Pitch", 28, 18, true, 0.0008));
    sig!(ROLL = SignalSpec::scaled("Roll", 46, 18, true, 0.0008));
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "NAV_ATT",
        id: 0x201,
        dlc: 8,
        signals: &[&SEQ, &HEADING, &PITCH, &ROLL],
        frames_per_second: 50.0,
        sender: "NAV",
    };
}

/// Signal specs of NAV_VEL.
pub mod nav_vel {
    use super::*;
    sig!(SEQ = SignalSpec::uint("Seq", 0, 8));
    sig!(EAST = SignalSpec::scaled("VelEast", 8, 18, true, 0.001));
    sig!(NORTH = SignalSpec::scaled("VelNorth", 26, 18, true, 0.001));
    sig!(UP = SignalSpec::scaled("VelUp", 44, 18, true, 0.001));
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "NAV_VEL",
        id: 0x202,
        dlc: 8,
        signals: &[&SEQ, &EAST, &NORTH, &UP],
        frames_per_second: 50.0,
        sender: "NAV",
    };
}

/// Signal specs of NAV_POS.
pub mod nav_pos {
    use super::*;
    sig!(LAT = SignalSpec::scaled("Latitude", 0, 32, true, 1e-7));
    sig!(LON = SignalSpec::scaled("Longitude", 32, 32, true, 1e-7));
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "NAV_POS",
        id: 0x203,
        dlc: 8,
        signals: &[&LAT, &LON],
        frames_per_second: 50.0,
        sender: "NAV",
    };
}

/// Signal specs of NAV_HGT.
pub mod nav_hgt {
    use super::*;
    sig!(SEQ = SignalSpec::uint("Seq", 0, 8));
    sig!(HEIGHT = SignalSpec::scaled("Height", 8, 24, true, 0.01));
    sig!(POS_SIGMA = SignalSpec::scaled("PosSigma", 32, 16, false, 0.01));
    sig!(HEADING_SIGMA = SignalSpec::scaled("HeadingSigma", 48, 16, false, 0.0001));
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "NAV_HGT",
        id: 0x204,
        dlc: 8,
        signals: &[&SEQ, &HEIGHT, &POS_SIGMA, &HEADING_SIGMA],
        frames_per_second: 50.0,
        sender: "NAV",
    };
}

u8_enum!(
    /// Navigation mode (NAV_TIME.Mode).
    NavMode {
        /// Starting up, waiting for sensors.
        Init = 0,
        /// Coarse levelling.
        Levelling = 1,
        /// Four-position north-finding.
        NorthFinding = 2,
        /// Pure inertial navigation.
        Navigation = 3,
        /// GPS-aided navigation.
        GpsAided = 4,
        /// Coasting through a GPS outage.
        Coasting = 5,
        /// Fault.
        Fault = 6,
        /// Self-calibration: the mechanism turns the IMU to make its errors observable.
        Calibrating = 7,
        /// North-finding without the mechanism (lost mid-drill): a static gyrocompass where
        /// the table stands, its heading less sure.
        Gyrocompass = 8,
    }
);

/// Navigation health bits (NAV_TIME).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NavHealth {
    /// IMU data stopped arriving.
    pub imu_timeout: bool,
    /// IMU sample gaps were seen.
    pub imu_gaps: bool,
    /// IMU built-in test reports a failure.
    pub imu_bit: bool,
    /// GPS data stale.
    pub gps_stale: bool,
    /// Turntable fault.
    pub turntable: bool,
    /// Filter inconsistency.
    pub filter: bool,
    /// The receiver's stream carried bad data (a checksum, framing or binary line, garbage
    /// bytes) in the last second of IMU time.
    pub gps_data: bool,
    /// nav's CAN controller is error-passive or bus-off, or reported bus errors in the last
    /// second of IMU time.
    pub can_bus: bool,
}

impl NavHealth {
    pub(crate) fn to_array(self) -> [bool; 8] {
        [
            self.imu_timeout,
            self.imu_gaps,
            self.imu_bit,
            self.gps_stale,
            self.turntable,
            self.filter,
            self.gps_data,
            self.can_bus,
        ]
    }
    pub(crate) fn from_array(b: [bool; 8]) -> Self {
        Self {
            imu_timeout: b[0],
            imu_gaps: b[1],
            imu_bit: b[2],
            gps_stale: b[3],
            turntable: b[4],
            filter: b[5],
            gps_data: b[6],
            can_bus: b[7],
        }
    }
}

/// NAV_TIME: solution header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NavTime {
    /// IMU sample count (extended, 32 bits) the solution is valid at.
    pub sample_count: u32,
    /// Solution sequence number.
    pub seq: u8,
    /// Mode.
    pub mode: NavMode,
    /// Health.
    pub health: NavHealth,
    /// Bytes nav has taken from the GPS receiver, wrapping at 12 bits: what it has received, for
    /// the receiver's health and for a bench that must know its bytes arrived before it lets
    /// the IMU stream run past them.
    pub gps_rx_bytes: u16,
}

/// NAV_ATT: attitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavAtt {
    /// Solution sequence number.
    pub seq: u8,
    /// Heading, deg [0, 360).
    pub heading_deg: f64,
    /// Pitch, deg.
    pub pitch_deg: f64,
    /// Roll, deg.
    pub roll_deg: f64,
}

/// NAV_VEL: velocity in the local level frame (east, north, up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavVel {
    /// Solution sequence number.
    pub seq: u8,
    /// East, north, up velocity, m/s.
    pub enu_mps: [f64; 3],
}

/// NAV_POS: latitude and longitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavPos {
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
}

/// NAV_HGT: height and accuracy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavHgt {
    /// Solution sequence number.
    pub seq: u8,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// Horizontal position sigma, m.
    pub pos_sigma_m: f64,
    /// Heading sigma, deg.
    pub heading_sigma_deg: f64,
}
