//! CAN error frames as a Linux CAN controller reports them (`linux/can/error.h`): the class in
//! the identifier (with `CAN_ERR_FLAG`), the detail in eight data bytes. A raw socket receives
//! them only when asked (`CAN_RAW_ERR_FILTER`). The bench writes them on vcan where nav's own
//! controller would raise them; nav reads, counts and reports them.

/// `CAN_ERR_FLAG`: the identifier carries an error class.
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;
/// Every error class (`CAN_ERR_MASK`), for `CAN_RAW_ERR_FILTER`.
pub const CAN_ERR_MASK: u32 = 0x1FFF_FFFF;

/// Error classes (the identifier's bits).
pub mod class {
    /// Transmission timed out.
    pub const TX_TIMEOUT: u32 = 0x0001;
    /// Arbitration lost (bit in data\[0\]).
    pub const LOSTARB: u32 = 0x0002;
    /// Controller problems (data\[1\]).
    pub const CRTL: u32 = 0x0004;
    /// Protocol violation (type in data\[2\], location in data\[3\]).
    pub const PROT: u32 = 0x0008;
    /// Transceiver status (data\[4\]).
    pub const TRX: u32 = 0x0010;
    /// No acknowledgement on transmission.
    pub const ACK: u32 = 0x0020;
    /// The controller went bus-off.
    pub const BUSOFF: u32 = 0x0040;
    /// A bus error (may flood).
    pub const BUSERROR: u32 = 0x0080;
    /// The controller restarted after bus-off.
    pub const RESTARTED: u32 = 0x0100;
    /// TX and RX error counters in data\[6\] and data\[7\].
    pub const CNT: u32 = 0x0200;
}

/// Controller status (data\[1\] of a `CRTL` error).
pub mod crtl {
    /// Receive buffer overflow.
    pub const RX_OVERFLOW: u8 = 0x01;
    /// Transmit buffer overflow.
    pub const TX_OVERFLOW: u8 = 0x02;
    /// Receive errors reached the warning level (96).
    pub const RX_WARNING: u8 = 0x04;
    /// Transmit errors reached the warning level (96).
    pub const TX_WARNING: u8 = 0x08;
    /// Receive errors reached error-passive (128).
    pub const RX_PASSIVE: u8 = 0x10;
    /// Transmit errors reached error-passive (128).
    pub const TX_PASSIVE: u8 = 0x20;
    /// Back to error-active.
    pub const ACTIVE: u8 = 0x40;
}

/// Protocol error type (data\[2\] of a `PROT` error).
pub mod prot {
    /// Single bit error.
    pub const BIT: u8 = 0x01;
    /// Frame format error.
    pub const FORM: u8 = 0x02;
    /// Bit stuffing error.
    pub const STUFF: u8 = 0x04;
    /// Unable to send a dominant bit.
    pub const BIT0: u8 = 0x08;
    /// Unable to send a recessive bit.
    pub const BIT1: u8 = 0x10;
    /// The error happened on transmission.
    pub const TX: u8 = 0x80;
    /// Location (data\[3\]): the data section.
    pub const LOC_DATA: u8 = 0x0A;
    /// Location: start of frame.
    pub const LOC_SOF: u8 = 0x03;
}

/// The error state of a CAN controller (ISO 11898-1), from its error counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub enum ErrorState {
    /// Both counters below 96.
    #[default]
    Active,
    /// A counter at 96 or more.
    Warning,
    /// A counter at 128 or more: the controller sends passive error flags only.
    Passive,
    /// The transmit counter passed 255: the controller is off the bus.
    BusOff,
}

impl ErrorState {
    /// The state of counters `tec` and `rec` (a controller is bus-off by its own account only).
    pub fn of(tec: u16, rec: u16) -> Self {
        let worst = tec.max(rec);
        if tec > 255 {
            Self::BusOff
        } else if worst >= 128 {
            Self::Passive
        } else if worst >= 96 {
            Self::Warning
        } else {
            Self::Active
        }
    }
}

/// One error frame: its classes and its eight data bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorFrame {
    /// The classes ([`class`]), without `CAN_ERR_FLAG`.
    pub class: u32,
    /// The detail.
    pub data: [u8; 8],
}

impl ErrorFrame {
    /// A bus error seen by a controller whose counters are then `tec` and `rec`: protocol error
    /// of type `kind` ([`prot`]) at `location`.
    pub fn bus_error(kind: u8, location: u8, tec: u16, rec: u16) -> Self {
        let mut data = counters(tec, rec);
        data[2] = kind;
        data[3] = location;
        Self {
            class: class::PROT | class::BUSERROR | class::CNT,
            data,
        }
    }

    /// The controller's error state changed to `state`, its counters `tec` and `rec`.
    pub fn state_change(state: ErrorState, tec: u16, rec: u16) -> Self {
        let mut data = counters(tec, rec);
        let class = match state {
            ErrorState::BusOff => class::BUSOFF | class::CNT,
            ErrorState::Active => {
                data[1] = crtl::ACTIVE;
                class::CRTL | class::CNT
            }
            ErrorState::Warning | ErrorState::Passive => {
                let passive = state == ErrorState::Passive;
                let (tx, rx) = if passive {
                    (crtl::TX_PASSIVE, crtl::RX_PASSIVE)
                } else {
                    (crtl::TX_WARNING, crtl::RX_WARNING)
                };
                let at = if passive { 128 } else { 96 };
                data[1] = if tec >= at { tx } else { 0 } | if rec >= at { rx } else { 0 };
                class::CRTL | class::CNT
            }
        };
        Self { class, data }
    }

    /// The controller restarted after bus-off.
    pub fn restarted() -> Self {
        Self {
            class: class::RESTARTED,
            data: [0; 8],
        }
    }

    /// The identifier as the kernel carries it (`CAN_ERR_FLAG` set).
    pub fn can_id(&self) -> u32 {
        CAN_ERR_FLAG | (self.class & CAN_ERR_MASK)
    }

    /// The transmit and receive error counters, when the frame carries them.
    pub fn counters(&self) -> Option<(u8, u8)> {
        (self.class & class::CNT != 0).then_some((self.data[6], self.data[7]))
    }

    /// The controller's state this frame reports, if it reports one.
    pub fn state(&self) -> Option<ErrorState> {
        if self.class & class::BUSOFF != 0 {
            return Some(ErrorState::BusOff);
        }
        if self.class & class::RESTARTED != 0 {
            return Some(ErrorState::Active);
        }
        if self.class & class::CRTL != 0 {
            let s = self.data[1];
            return Some(if s & (crtl::TX_PASSIVE | crtl::RX_PASSIVE) != 0 {
                ErrorState::Passive
            } else if s & (crtl::TX_WARNING | crtl::RX_WARNING) != 0 {
                ErrorState::Warning
            } else if s & crtl::ACTIVE != 0 {
                ErrorState::Active
            } else {
                return None;
            });
        }
        None
    }

    /// A line for a log: the classes by name, and the detail that matters.
    pub fn describe(&self) -> String {
        let names = [
            (class::TX_TIMEOUT, "tx-timeout"),
            (class::LOSTARB, "lost-arbitration"),
            (class::CRTL, "controller"),
            (class::PROT, "protocol-violation"),
            (class::TRX, "transceiver"),
            (class::ACK, "no-ack"),
            (class::BUSOFF, "bus-off"),
            (class::BUSERROR, "bus-error"),
            (class::RESTARTED, "restarted"),
        ];
        let mut s: Vec<String> = names
            .iter()
            .filter(|(b, _)| self.class & b != 0)
            .map(|(_, n)| n.to_string())
            .collect();
        if let Some(st) = self.state() {
            s.push(format!("state {st:?}"));
        }
        if let Some((tec, rec)) = self.counters() {
            s.push(format!("tec {tec} rec {rec}"));
        }
        s.join(", ")
    }
}

fn counters(tec: u16, rec: u16) -> [u8; 8] {
    let mut d = [0u8; 8];
    d[6] = tec.min(255) as u8;
    d[7] = rec.min(255) as u8;
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_follow_the_counters_thresholds() {
        assert_eq!(ErrorState::of(0, 95), ErrorState::Active);
        assert_eq!(ErrorState::of(96, 0), ErrorState::Warning);
        assert_eq!(ErrorState::of(0, 128), ErrorState::Passive);
        assert_eq!(ErrorState::of(255, 0), ErrorState::Passive);
        assert_eq!(ErrorState::of(256, 0), ErrorState::BusOff);
    }

    #[test]
    fn frames_say_what_they_carry() {
        let e = ErrorFrame::bus_error(prot::STUFF, prot::LOC_DATA, 0, 3);
        assert_eq!(e.can_id(), 0x2000_0288);
        assert_eq!(e.counters(), Some((0, 3)));
        assert_eq!(e.state(), None);
        let p = ErrorFrame::state_change(ErrorState::Passive, 0, 130);
        assert_eq!(
            (p.data[1], p.state()),
            (crtl::RX_PASSIVE, Some(ErrorState::Passive))
        );
        let off = ErrorFrame::state_change(ErrorState::BusOff, 256, 0);
        assert_eq!(off.state(), Some(ErrorState::BusOff));
        assert_eq!(off.counters(), Some((255, 0)));
        assert_eq!(ErrorFrame::restarted().state(), Some(ErrorState::Active));
        assert!(off.describe().contains("bus-off"), "{}", off.describe());
    }
}
