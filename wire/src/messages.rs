//! Typed messages of the contract. Every layout is a table of [`SignalSpec`]s, the single
//! source of truth in code, checked against `bench.dbc` by `tests/dbc_agreement.rs`.

use crate::codec::{DecodeError, EncodeError, MessageSpec, RawFrame, SignalSpec, check};

/// IMU sample rate in Hz (one IMU_GYRO and one IMU_ACCEL frame per sample).
pub const IMU_RATE_HZ: f64 = 2000.0;

macro_rules! sig {
    ($name:ident = $s:expr) => {
        #[doc = concat!("Signal `", stringify!($name), "`.")]
        pub const $name: SignalSpec = $s;
    };
}

macro_rules! u8_enum {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $var:ident = $val:expr),+ $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[repr(u8)]
        pub enum $name { $($(#[$vm])* $var = $val),+ }
        impl $name {
            /// Every value, in wire order.
            pub const ALL: &'static [$name] = &[$($name::$var),+];
            /// The value for a raw wire code, if defined.
            pub fn from_raw(raw: i64) -> Option<Self> {
                match raw { $($val => Some($name::$var),)+ _ => None }
            }
            /// Name as in the DBC value table.
            pub fn name(self) -> &'static str {
                match self { $($name::$var => stringify!($var)),+ }
            }
        }
    };
}

/// Signal specs of IMU_GYRO.
pub mod imu_gyro {
    use super::*;
    sig!(GYRO_X = SignalSpec::uint("GyroX_Count", 0, 16));
    sig!(GYRO_Y = SignalSpec::uint("GyroY_Count", 16, 16));
    sig!(GYRO_Z = SignalSpec::uint("GyroZ_Count", 32, 16));
    sig!(SAMPLE_COUNTER = SignalSpec::uint("SampleCounter", 48, 16));
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "IMU_GYRO",
        id: 0x080,
        dlc: 8,
        signals: &[&GYRO_X, &GYRO_Y, &GYRO_Z, &SAMPLE_COUNTER],
        frames_per_second: IMU_RATE_HZ,
    };
}

/// Signal specs of IMU_ACCEL.
pub mod imu_accel {
    use super::*;
    sig!(ACCEL_X = SignalSpec::uint("AccelX_Count", 0, 16));
    sig!(ACCEL_Y = SignalSpec::uint("AccelY_Count", 16, 16));
    sig!(ACCEL_Z = SignalSpec::uint("AccelZ_Count", 32, 16));
    sig!(SAMPLE_COUNTER_LOW = SignalSpec::uint("SampleCounterLow", 48, 4));
    sig!(PPS_LATCHED = SignalSpec::uint("PpsLatched", 52, 1));
    sig!(BIT_FAIL = SignalSpec::uint("BitFail", 53, 1));
    sig!(SATURATED = SignalSpec::uint("Saturated", 54, 1));
    sig!(PPS_OFFSET = SignalSpec::scaled("PpsOffset", 56, 8, false, 1.0 / 256.0));
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "IMU_ACCEL",
        id: 0x081,
        dlc: 8,
        signals: &[
            &ACCEL_X,
            &ACCEL_Y,
            &ACCEL_Z,
            &SAMPLE_COUNTER_LOW,
            &PPS_LATCHED,
            &BIT_FAIL,
            &SATURATED,
            &PPS_OFFSET,
        ],
        frames_per_second: IMU_RATE_HZ,
    };
}

/// Signal specs of IMU_HK.
pub mod imu_hk {
    use super::*;
    sig!(SAMPLE_COUNTER = SignalSpec::uint("SampleCounter", 0, 16));
    sig!(TEMP_GYRO = SignalSpec::scaled("TempGyro", 16, 16, true, 0.01));
    sig!(TEMP_ACCEL = SignalSpec::scaled("TempAccel", 32, 16, true, 0.01));
    /// Built-in-test bits, in the order of [`super::BitFlags`]'s fields.
    pub const BITS: [SignalSpec; 9] = [
        SignalSpec::uint("BitGyroX", 48, 1),
        SignalSpec::uint("BitGyroY", 49, 1),
        SignalSpec::uint("BitGyroZ", 50, 1),
        SignalSpec::uint("BitAccelX", 51, 1),
        SignalSpec::uint("BitAccelY", 52, 1),
        SignalSpec::uint("BitAccelZ", 53, 1),
        SignalSpec::uint("BitDither", 54, 1),
        SignalSpec::uint("BitPower", 55, 1),
        SignalSpec::uint("BitOverTemp", 56, 1),
    ];
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "IMU_HK",
        id: 0x082,
        dlc: 8,
        signals: &[
            &SAMPLE_COUNTER,
            &TEMP_GYRO,
            &TEMP_ACCEL,
            &BITS[0],
            &BITS[1],
            &BITS[2],
            &BITS[3],
            &BITS[4],
            &BITS[5],
            &BITS[6],
            &BITS[7],
            &BITS[8],
        ],
        frames_per_second: 10.0,
    };
}

/// Signal specs of TT_CMD.
pub mod tt_cmd {
    use super::*;
    sig!(SEQ = SignalSpec::uint("Seq", 0, 8));
    sig!(COMMAND = SignalSpec::uint("Command", 8, 8));
    sig!(AXIS = SignalSpec::uint("Axis", 16, 2));
    sig!(ARG = SignalSpec::scaled("Arg", 32, 32, true, 0.0001));
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "TT_CMD",
        id: 0x100,
        dlc: 8,
        signals: &[&SEQ, &COMMAND, &AXIS, &ARG],
        frames_per_second: 20.0,
    };
}

/// Signal specs of TT_ACK.
pub mod tt_ack {
    use super::*;
    sig!(SEQ = SignalSpec::uint("Seq", 0, 8));
    sig!(COMMAND = SignalSpec::uint("Command", 8, 8));
    sig!(AXIS = SignalSpec::uint("Axis", 16, 2));
    sig!(RESULT = SignalSpec::uint("Result", 24, 8));
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "TT_ACK",
        id: 0x101,
        dlc: 4,
        signals: &[&SEQ, &COMMAND, &AXIS, &RESULT],
        frames_per_second: 20.0,
    };
}

/// Signal specs of TT_STATUS.
pub mod tt_status {
    use super::*;
    sig!(ANGLE = SignalSpec::scaled("Angle", 0, 22, false, 0.0001));
    sig!(RATE = SignalSpec::scaled("Rate", 22, 16, true, 0.01));
    sig!(STATE = SignalSpec::uint("State", 38, 3));
    sig!(AXIS = SignalSpec::uint("Axis", 41, 2));
    /// Fault bits, in the order of [`super::TtFaults`]'s fields.
    pub const FAULTS: [SignalSpec; 7] = [
        SignalSpec::uint("FaultStall", 43, 1),
        SignalSpec::uint("FaultLock", 44, 1),
        SignalSpec::uint("FaultEncoder", 45, 1),
        SignalSpec::uint("FaultHeartbeat", 46, 1),
        SignalSpec::uint("FaultEStop", 47, 1),
        SignalSpec::uint("FaultDrive", 48, 1),
        SignalSpec::uint("FaultLimit", 49, 1),
    ];
    sig!(ACK_SEQ = SignalSpec::uint("AckSeq", 50, 8));
    sig!(COUNTER = SignalSpec::uint("Counter", 58, 4));
    /// The message (100 Hz per axis, three axes budgeted).
    pub const SPEC: MessageSpec = MessageSpec {
        name: "TT_STATUS",
        id: 0x102,
        dlc: 8,
        signals: &[
            &ANGLE, &RATE, &STATE, &AXIS, &FAULTS[0], &FAULTS[1], &FAULTS[2], &FAULTS[3],
            &FAULTS[4], &FAULTS[5], &FAULTS[6], &ACK_SEQ, &COUNTER,
        ],
        frames_per_second: 300.0,
    };
}

/// Signal specs of NAV_TIME.
pub mod nav_time {
    use super::*;
    sig!(SAMPLE_COUNT = SignalSpec::uint("SampleCount", 0, 32));
    sig!(SEQ = SignalSpec::uint("Seq", 32, 8));
    sig!(MODE = SignalSpec::uint("Mode", 40, 4));
    /// Health bits, in the order of [`super::NavHealth`]'s fields.
    pub const HEALTH: [SignalSpec; 6] = [
        SignalSpec::uint("HealthImuTimeout", 44, 1),
        SignalSpec::uint("HealthImuGaps", 45, 1),
        SignalSpec::uint("HealthImuBit", 46, 1),
        SignalSpec::uint("HealthGpsStale", 47, 1),
        SignalSpec::uint("HealthTurntable", 48, 1),
        SignalSpec::uint("HealthFilter", 49, 1),
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
        ],
        frames_per_second: 50.0,
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
    };
}

/// Every message of the contract.
pub const ALL_MESSAGES: &[&MessageSpec] = &[
    &imu_gyro::SPEC,
    &imu_accel::SPEC,
    &imu_hk::SPEC,
    &tt_cmd::SPEC,
    &tt_ack::SPEC,
    &tt_status::SPEC,
    &nav_time::SPEC,
    &nav_att::SPEC,
    &nav_vel::SPEC,
    &nav_pos::SPEC,
    &nav_hgt::SPEC,
];

/// The spec of a message id, if it is part of the contract.
pub fn spec_for_id(id: u16) -> Option<&'static MessageSpec> {
    ALL_MESSAGES.iter().copied().find(|m| m.id == id)
}

u8_enum!(
    /// Turntable command codes (TT_CMD.Command).
    TtCommand {
        /// Keep the heartbeat watchdog alive.
        Heartbeat = 0,
        /// Power the drive, hold position.
        Enable = 1,
        /// Remove drive power.
        Disable = 2,
        /// Return to zero.
        Home = 3,
        /// Index to an absolute angle (Arg, deg).
        IndexAbs = 4,
        /// Move by a relative angle (Arg, deg).
        MoveRel = 5,
        /// Rotate at a constant rate (Arg, deg/s).
        Rate = 6,
        /// Decelerate to rest.
        Stop = 7,
        /// Emergency stop: drive off at once, latch a fault.
        EStop = 8,
        /// Engage the lock pin (only at a detent).
        Lock = 9,
        /// Withdraw the lock pin.
        Unlock = 10,
    }
);

u8_enum!(
    /// Turntable answer codes (TT_ACK.Result).
    TtResult {
        /// Command accepted.
        Accepted = 0,
        /// Unknown command code.
        UnknownCommand = 1,
        /// Argument out of range.
        OutOfRange = 2,
        /// Axis is faulted.
        Faulted = 3,
        /// Axis not enabled.
        NotEnabled = 4,
        /// Axis is locked.
        Locked = 5,
        /// Axis busy with a move.
        Busy = 6,
        /// No such axis.
        BadAxis = 7,
        /// Lock requested away from a detent.
        NotAtDetent = 8,
    }
);

u8_enum!(
    /// Turntable axis state (TT_STATUS.State).
    TtState {
        /// Drive off.
        Disabled = 0,
        /// Enabled, holding.
        Idle = 1,
        /// Moving.
        Moving = 2,
        /// Settling at a target.
        Settling = 3,
        /// Lock pin engaged.
        Locked = 4,
        /// Faulted (see fault bits).
        Fault = 5,
    }
);

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
    }
);

/// IMU_GYRO: accumulated gyro pulse counters of one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImuGyro {
    /// Free-running 16-bit pulse counters, x, y, z.
    pub counts: [u16; 3],
    /// 16-bit IMU sample counter.
    pub sample_counter: u16,
}

/// IMU_ACCEL: accumulated accelerometer pulse counters and status of one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImuAccel {
    /// Free-running 16-bit pulse counters, x, y, z.
    pub counts: [u16; 3],
    /// Low 4 bits of the sample counter.
    pub sample_counter_low: u8,
    /// PPS edge in this sample: time from the edge to the end of the interval, in 1/256 sample.
    pub pps_offset: Option<u8>,
    /// Built-in-test failure summary.
    pub bit_fail: bool,
    /// A channel saturated in this sample.
    pub saturated: bool,
}

/// Built-in-test results (IMU_HK).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BitFlags {
    /// Gyro channel failures x, y, z.
    pub gyro: [bool; 3],
    /// Accelerometer channel failures x, y, z.
    pub accel: [bool; 3],
    /// Dither drive failure.
    pub dither: bool,
    /// Power supply failure.
    pub power: bool,
    /// Over-temperature.
    pub over_temp: bool,
}

impl BitFlags {
    fn to_array(self) -> [bool; 9] {
        let [gx, gy, gz] = self.gyro;
        let [ax, ay, az] = self.accel;
        [
            gx,
            gy,
            gz,
            ax,
            ay,
            az,
            self.dither,
            self.power,
            self.over_temp,
        ]
    }
    fn from_array(b: [bool; 9]) -> Self {
        Self {
            gyro: [b[0], b[1], b[2]],
            accel: [b[3], b[4], b[5]],
            dither: b[6],
            power: b[7],
            over_temp: b[8],
        }
    }
    /// Any failure.
    pub fn any(self) -> bool {
        self.to_array().iter().any(|b| *b)
    }
}

/// IMU_HK: housekeeping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuHk {
    /// Sample at which this was latched.
    pub sample_counter: u16,
    /// Gyro block temperature, degC.
    pub temp_gyro_c: f64,
    /// Accelerometer block temperature, degC.
    pub temp_accel_c: f64,
    /// Built-in test.
    pub bit: BitFlags,
}

/// TT_CMD: one turntable command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TtCmd {
    /// Sequence number echoed in TT_ACK.
    pub seq: u8,
    /// Command code; kept raw so that an unknown code can be sent (and rejected).
    pub command: u8,
    /// Axis 0..=2.
    pub axis: u8,
    /// Angle (deg) or rate (deg/s).
    pub arg: f64,
}

/// TT_ACK: the answer to one command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TtAck {
    /// Seq of the command answered.
    pub seq: u8,
    /// Its command code (raw).
    pub command: u8,
    /// Its axis.
    pub axis: u8,
    /// Accepted or why not.
    pub result: TtResult,
}

/// Turntable fault bits (TT_STATUS).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TtFaults {
    /// Motor stalled.
    pub stall: bool,
    /// Lock pin failed to engage or release.
    pub lock: bool,
    /// Encoder fault.
    pub encoder: bool,
    /// Heartbeat timeout stop.
    pub heartbeat: bool,
    /// Emergency stop latched.
    pub estop: bool,
    /// Drive fault.
    pub drive: bool,
    /// Limit / over-travel.
    pub limit: bool,
}

impl TtFaults {
    fn to_array(self) -> [bool; 7] {
        [
            self.stall,
            self.lock,
            self.encoder,
            self.heartbeat,
            self.estop,
            self.drive,
            self.limit,
        ]
    }
    fn from_array(b: [bool; 7]) -> Self {
        Self {
            stall: b[0],
            lock: b[1],
            encoder: b[2],
            heartbeat: b[3],
            estop: b[4],
            drive: b[5],
            limit: b[6],
        }
    }
    /// Any fault.
    pub fn any(self) -> bool {
        self.to_array().iter().any(|b| *b)
    }

    /// The names of the faults set, for messages ("stall, lock pin").
    pub fn names(self) -> String {
        const NAMES: [&str; 7] = [
            "stall",
            "lock pin",
            "encoder",
            "heartbeat timeout",
            "emergency stop",
            "drive",
            "limit",
        ];
        let set: Vec<&str> = self
            .to_array()
            .iter()
            .zip(NAMES)
            .filter(|(b, _)| **b)
            .map(|(_, n)| n)
            .collect();
        if set.is_empty() {
            "none".into()
        } else {
            set.join(", ")
        }
    }
}

/// TT_STATUS: one axis' status.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TtStatus {
    /// Encoder angle, deg, [0, 360).
    pub angle_deg: f64,
    /// Rate, deg/s.
    pub rate_dps: f64,
    /// State.
    pub state: TtState,
    /// Axis 0..=2.
    pub axis: u8,
    /// Fault bits.
    pub faults: TtFaults,
    /// Seq of the last acknowledged command.
    pub ack_seq: u8,
    /// 4-bit frame counter.
    pub counter: u8,
}

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
}

impl NavHealth {
    fn to_array(self) -> [bool; 6] {
        [
            self.imu_timeout,
            self.imu_gaps,
            self.imu_bit,
            self.gps_stale,
            self.turntable,
            self.filter,
        ]
    }
    fn from_array(b: [bool; 6]) -> Self {
        Self {
            imu_timeout: b[0],
            imu_gaps: b[1],
            imu_bit: b[2],
            gps_stale: b[3],
            turntable: b[4],
            filter: b[5],
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

/// Any frame of the contract, decoded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    /// IMU_GYRO.
    ImuGyro(ImuGyro),
    /// IMU_ACCEL.
    ImuAccel(ImuAccel),
    /// IMU_HK.
    ImuHk(ImuHk),
    /// TT_CMD.
    TtCmd(TtCmd),
    /// TT_ACK.
    TtAck(TtAck),
    /// TT_STATUS.
    TtStatus(TtStatus),
    /// NAV_TIME.
    NavTime(NavTime),
    /// NAV_ATT.
    NavAtt(NavAtt),
    /// NAV_VEL.
    NavVel(NavVel),
    /// NAV_POS.
    NavPos(NavPos),
    /// NAV_HGT.
    NavHgt(NavHgt),
}

fn frame(spec: &MessageSpec, data: [u8; 8]) -> RawFrame {
    RawFrame {
        id: spec.id,
        len: spec.dlc,
        data,
    }
}

fn enum_value<T>(
    spec: &MessageSpec,
    sig: &SignalSpec,
    data: &[u8; 8],
    f: impl Fn(i64) -> Option<T>,
) -> Result<T, DecodeError> {
    let raw = sig.get(data);
    f(raw).ok_or(DecodeError::InvalidValue {
        message: spec.name,
        signal: sig.name,
        raw,
    })
}

fn flags<const N: usize>(specs: &[SignalSpec; N], data: &[u8; 8]) -> [bool; N] {
    std::array::from_fn(|i| specs[i].flag(data))
}

fn put_flags<const N: usize>(specs: &[SignalSpec; N], data: &mut [u8; 8], v: [bool; N]) {
    for (s, b) in specs.iter().zip(v) {
        s.put_flag(data, b);
    }
}

impl Message {
    /// The spec of this message.
    pub fn spec(&self) -> &'static MessageSpec {
        match self {
            Message::ImuGyro(_) => &imu_gyro::SPEC,
            Message::ImuAccel(_) => &imu_accel::SPEC,
            Message::ImuHk(_) => &imu_hk::SPEC,
            Message::TtCmd(_) => &tt_cmd::SPEC,
            Message::TtAck(_) => &tt_ack::SPEC,
            Message::TtStatus(_) => &tt_status::SPEC,
            Message::NavTime(_) => &nav_time::SPEC,
            Message::NavAtt(_) => &nav_att::SPEC,
            Message::NavVel(_) => &nav_vel::SPEC,
            Message::NavPos(_) => &nav_pos::SPEC,
            Message::NavHgt(_) => &nav_hgt::SPEC,
        }
    }

    /// Encode into a frame. Physical values outside a signal's range are an error.
    pub fn encode(&self) -> Result<RawFrame, EncodeError> {
        let mut d = [0u8; 8];
        match *self {
            Message::ImuGyro(m) => {
                use imu_gyro::*;
                for (s, c) in [GYRO_X, GYRO_Y, GYRO_Z].iter().zip(m.counts) {
                    s.put_wrapping(&mut d, i64::from(c));
                }
                SAMPLE_COUNTER.put_wrapping(&mut d, i64::from(m.sample_counter));
            }
            Message::ImuAccel(m) => {
                use imu_accel::*;
                for (s, c) in [ACCEL_X, ACCEL_Y, ACCEL_Z].iter().zip(m.counts) {
                    s.put_wrapping(&mut d, i64::from(c));
                }
                SAMPLE_COUNTER_LOW.put_wrapping(&mut d, i64::from(m.sample_counter_low));
                PPS_LATCHED.put_flag(&mut d, m.pps_offset.is_some());
                BIT_FAIL.put_flag(&mut d, m.bit_fail);
                SATURATED.put_flag(&mut d, m.saturated);
                PPS_OFFSET.put(&mut d, i64::from(m.pps_offset.unwrap_or(0)))?;
            }
            Message::ImuHk(m) => {
                use imu_hk::*;
                SAMPLE_COUNTER.put_wrapping(&mut d, i64::from(m.sample_counter));
                TEMP_GYRO.put_phys(&mut d, m.temp_gyro_c)?;
                TEMP_ACCEL.put_phys(&mut d, m.temp_accel_c)?;
                put_flags(&BITS, &mut d, m.bit.to_array());
            }
            Message::TtCmd(m) => {
                use tt_cmd::*;
                SEQ.put(&mut d, i64::from(m.seq))?;
                COMMAND.put(&mut d, i64::from(m.command))?;
                AXIS.put(&mut d, i64::from(m.axis))?;
                ARG.put_phys(&mut d, m.arg)?;
            }
            Message::TtAck(m) => {
                use tt_ack::*;
                SEQ.put(&mut d, i64::from(m.seq))?;
                COMMAND.put(&mut d, i64::from(m.command))?;
                AXIS.put(&mut d, i64::from(m.axis))?;
                RESULT.put(&mut d, m.result as i64)?;
            }
            Message::TtStatus(m) => {
                use tt_status::*;
                ANGLE.put_phys(&mut d, m.angle_deg.rem_euclid(360.0) % 360.0)?;
                RATE.put_phys(&mut d, m.rate_dps)?;
                STATE.put(&mut d, m.state as i64)?;
                AXIS.put(&mut d, i64::from(m.axis))?;
                put_flags(&FAULTS, &mut d, m.faults.to_array());
                ACK_SEQ.put(&mut d, i64::from(m.ack_seq))?;
                COUNTER.put_wrapping(&mut d, i64::from(m.counter));
            }
            Message::NavTime(m) => {
                use nav_time::*;
                SAMPLE_COUNT.put(&mut d, i64::from(m.sample_count))?;
                SEQ.put(&mut d, i64::from(m.seq))?;
                MODE.put(&mut d, m.mode as i64)?;
                put_flags(&HEALTH, &mut d, m.health.to_array());
            }
            Message::NavAtt(m) => {
                use nav_att::*;
                SEQ.put(&mut d, i64::from(m.seq))?;
                HEADING.put_phys(&mut d, m.heading_deg.rem_euclid(360.0))?;
                PITCH.put_phys(&mut d, m.pitch_deg)?;
                ROLL.put_phys(&mut d, m.roll_deg)?;
            }
            Message::NavVel(m) => {
                use nav_vel::*;
                SEQ.put(&mut d, i64::from(m.seq))?;
                for (s, v) in [EAST, NORTH, UP].iter().zip(m.enu_mps) {
                    s.put_phys(&mut d, v)?;
                }
            }
            Message::NavPos(m) => {
                nav_pos::LAT.put_phys(&mut d, m.lat_deg)?;
                nav_pos::LON.put_phys(&mut d, m.lon_deg)?;
            }
            Message::NavHgt(m) => {
                use nav_hgt::*;
                SEQ.put(&mut d, i64::from(m.seq))?;
                HEIGHT.put_phys(&mut d, m.height_m)?;
                POS_SIGMA.put_phys(&mut d, m.pos_sigma_m)?;
                HEADING_SIGMA.put_phys(&mut d, m.heading_sigma_deg)?;
            }
        }
        Ok(frame(self.spec(), d))
    }

    /// Decode a frame: unknown ids, wrong lengths and undefined enum values are errors.
    pub fn decode(f: &RawFrame) -> Result<Message, DecodeError> {
        let spec = spec_for_id(f.id).ok_or(DecodeError::UnknownId {
            id: u32::from(f.id),
        })?;
        let d = check(spec, f)?;
        let u8_of = |s: &SignalSpec| s.get(&d) as u8;
        let u16_of = |s: &SignalSpec| s.get(&d) as u16;
        Ok(match spec.id {
            0x080 => {
                use imu_gyro::*;
                Message::ImuGyro(ImuGyro {
                    counts: [u16_of(&GYRO_X), u16_of(&GYRO_Y), u16_of(&GYRO_Z)],
                    sample_counter: u16_of(&SAMPLE_COUNTER),
                })
            }
            0x081 => {
                use imu_accel::*;
                Message::ImuAccel(ImuAccel {
                    counts: [u16_of(&ACCEL_X), u16_of(&ACCEL_Y), u16_of(&ACCEL_Z)],
                    sample_counter_low: u8_of(&SAMPLE_COUNTER_LOW),
                    pps_offset: PPS_LATCHED.flag(&d).then(|| u8_of(&PPS_OFFSET)),
                    bit_fail: BIT_FAIL.flag(&d),
                    saturated: SATURATED.flag(&d),
                })
            }
            0x082 => {
                use imu_hk::*;
                Message::ImuHk(ImuHk {
                    sample_counter: u16_of(&SAMPLE_COUNTER),
                    temp_gyro_c: TEMP_GYRO.phys(&d),
                    temp_accel_c: TEMP_ACCEL.phys(&d),
                    bit: BitFlags::from_array(flags(&BITS, &d)),
                })
            }
            0x100 => {
                use tt_cmd::*;
                Message::TtCmd(TtCmd {
                    seq: u8_of(&SEQ),
                    command: u8_of(&COMMAND),
                    axis: u8_of(&AXIS),
                    arg: ARG.phys(&d),
                })
            }
            0x101 => {
                use tt_ack::*;
                Message::TtAck(TtAck {
                    seq: u8_of(&SEQ),
                    command: u8_of(&COMMAND),
                    axis: u8_of(&AXIS),
                    result: enum_value(spec, &RESULT, &d, TtResult::from_raw)?,
                })
            }
            0x102 => {
                use tt_status::*;
                Message::TtStatus(TtStatus {
                    angle_deg: ANGLE.phys(&d),
                    rate_dps: RATE.phys(&d),
                    state: enum_value(spec, &STATE, &d, TtState::from_raw)?,
                    axis: u8_of(&AXIS),
                    faults: TtFaults::from_array(flags(&FAULTS, &d)),
                    ack_seq: u8_of(&ACK_SEQ),
                    counter: u8_of(&COUNTER),
                })
            }
            0x200 => {
                use nav_time::*;
                Message::NavTime(NavTime {
                    sample_count: SAMPLE_COUNT.get(&d) as u32,
                    seq: u8_of(&SEQ),
                    mode: enum_value(spec, &MODE, &d, NavMode::from_raw)?,
                    health: NavHealth::from_array(flags(&HEALTH, &d)),
                })
            }
            0x201 => {
                use nav_att::*;
                Message::NavAtt(NavAtt {
                    seq: u8_of(&SEQ),
                    heading_deg: HEADING.phys(&d),
                    pitch_deg: PITCH.phys(&d),
                    roll_deg: ROLL.phys(&d),
                })
            }
            0x202 => {
                use nav_vel::*;
                Message::NavVel(NavVel {
                    seq: u8_of(&SEQ),
                    enu_mps: [EAST.phys(&d), NORTH.phys(&d), UP.phys(&d)],
                })
            }
            0x203 => Message::NavPos(NavPos {
                lat_deg: nav_pos::LAT.phys(&d),
                lon_deg: nav_pos::LON.phys(&d),
            }),
            0x204 => {
                use nav_hgt::*;
                Message::NavHgt(NavHgt {
                    seq: u8_of(&SEQ),
                    height_m: HEIGHT.phys(&d),
                    pos_sigma_m: POS_SIGMA.phys(&d),
                    heading_sigma_deg: HEADING_SIGMA.phys(&d),
                })
            }
            other => {
                return Err(DecodeError::UnknownId {
                    id: u32::from(other),
                });
            }
        })
    }
}
