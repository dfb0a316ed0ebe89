//! The IMU family: IMU_GYRO, IMU_ACCEL, IMU_HK.

use super::*;

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
        sender: "IMU",
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
        sender: "IMU",
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
        sender: "IMU",
    };
}

/// Signal specs of MEMS_GYRO.
pub mod mems_gyro {
    use super::*;
    /// The four gyros' counters, in gyro order.
    pub const GYROS: [SignalSpec; 4] = [
        SignalSpec::uint("Gyro1_Count", 0, 14),
        SignalSpec::uint("Gyro2_Count", 14, 14),
        SignalSpec::uint("Gyro3_Count", 28, 14),
        SignalSpec::uint("Gyro4_Count", 42, 14),
    ];
    sig!(SAMPLE_COUNTER_LOW = SignalSpec::uint("SampleCounterLow", 56, 8));
    /// The message.
    pub const SPEC: MessageSpec = MessageSpec {
        name: "MEMS_GYRO",
        id: 0x090,
        dlc: 8,
        signals: &[
            &GYROS[0],
            &GYROS[1],
            &GYROS[2],
            &GYROS[3],
            &SAMPLE_COUNTER_LOW,
        ],
        // the paper's unit at 100 Hz (the frame rides on the IMU's strobe when present)
        frames_per_second: 100.0,
        sender: "MEMS",
    };
}

/// MEMS_GYRO: the redundant unit's four accumulated gyro pulse counters of one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemsGyro {
    /// Free-running 14-bit pulse counters, gyros 1-4.
    pub counts: [u16; 4],
    /// Low 8 bits of the IMU sample counter.
    pub sample_counter_low: u8,
}

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
    pub(crate) fn to_array(self) -> [bool; 9] {
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
    pub(crate) fn from_array(b: [bool; 9]) -> Self {
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
