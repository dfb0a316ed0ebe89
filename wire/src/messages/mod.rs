//! Typed messages of the contract. Every layout is a table of [`SignalSpec`]s, the single
//! source of truth in code, checked against `bench.dbc` by `tests/dbc_agreement.rs`.

pub(crate) use crate::codec::{DecodeError, EncodeError, MessageSpec, RawFrame, SignalSpec, check};

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

mod imu;
mod nav;
mod turntable;

pub use imu::*;
pub use nav::*;
pub use turntable::*;

/// Every message of the contract.
pub const ALL_MESSAGES: &[&MessageSpec] = &[
    &imu_gyro::SPEC,
    &imu_accel::SPEC,
    &imu_hk::SPEC,
    &mems_gyro::SPEC,
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

/// Any frame of the contract, decoded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    /// IMU_GYRO.
    ImuGyro(ImuGyro),
    /// IMU_ACCEL.
    ImuAccel(ImuAccel),
    /// IMU_HK.
    ImuHk(ImuHk),
    /// MEMS_GYRO.
    MemsGyro(MemsGyro),
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
            Message::MemsGyro(_) => &mems_gyro::SPEC,
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
            Message::MemsGyro(m) => {
                use mems_gyro::*;
                for (s, c) in GYROS.iter().zip(m.counts) {
                    s.put_wrapping(&mut d, i64::from(c));
                }
                SAMPLE_COUNTER_LOW.put_wrapping(&mut d, i64::from(m.sample_counter_low));
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
                ANGLE.put_angle_deg(&mut d, m.angle_deg)?;
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
                GPS_RX_BYTES.put_wrapping(&mut d, i64::from(m.gps_rx_bytes));
            }
            Message::NavAtt(m) => {
                use nav_att::*;
                SEQ.put(&mut d, i64::from(m.seq))?;
                HEADING.put_angle_deg(&mut d, m.heading_deg)?;
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
            0x090 => {
                use mems_gyro::*;
                Message::MemsGyro(MemsGyro {
                    counts: std::array::from_fn(|i| u16_of(&GYROS[i])),
                    sample_counter_low: u8_of(&SAMPLE_COUNTER_LOW),
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
                // the DBC's range is [0, 359.9999] deg; the 22-bit field could hold more
                let raw = ANGLE.get(&d);
                if raw >= 3_600_000 {
                    return Err(DecodeError::InvalidValue {
                        message: spec.name,
                        signal: ANGLE.name,
                        raw,
                    });
                }
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
                    gps_rx_bytes: GPS_RX_BYTES.get(&d) as u16,
                })
            }
            0x201 => {
                use nav_att::*;
                // headings are [0, 360): a raw 360 deg or more is not defined
                let raw = HEADING.get(&d);
                if raw >= 900_000 {
                    return Err(DecodeError::InvalidValue {
                        message: spec.name,
                        signal: HEADING.name,
                        raw,
                    });
                }
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
