//! The indexing mechanism's family: TT_CMD, TT_ACK, TT_STATUS.

use super::*;

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
        sender: "NAV",
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
        sender: "TT",
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
        sender: "TT",
    };
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
    pub(crate) fn to_array(self) -> [bool; 7] {
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
    pub(crate) fn from_array(b: [bool; 7]) -> Self {
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
