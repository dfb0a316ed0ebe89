//! Bus load of the contract on classic CAN.
//!
//! Frame length for an 11-bit identifier and `n` data bytes, after Davis, Burns, Bril and
//! Lukkien (2007), "Controller Area Network (CAN) schedulability analysis: refuted, revisited
//! and revised": `34 + 8n` bits are exposed to bit stuffing, plus 13 bits of CRC delimiter,
//! ACK, end of frame and intermission that are not. Worst case adds one stuff bit per four
//! bits: `floor((34 + 8n - 1) / 4)`.

use crate::{ALL_MESSAGES, MessageSpec};

/// Nominal classic CAN bit rate of the bench, bit/s.
pub const NOMINAL_BITRATE: f64 = 1_000_000.0;

/// Bits on the wire for one frame without stuff bits.
pub fn frame_bits_nominal(dlc: u8) -> u32 {
    34 + 8 * u32::from(dlc) + 13
}

/// Bits on the wire for one frame with worst-case bit stuffing.
pub fn frame_bits_worst(dlc: u8) -> u32 {
    let exposed = 34 + 8 * u32::from(dlc);
    exposed + 13 + (exposed - 1) / 4
}

/// Load of one message type.
#[derive(Debug, Clone, Copy)]
pub struct MessageLoad {
    /// The message.
    pub spec: &'static MessageSpec,
    /// Frames per second.
    pub frames_per_second: f64,
    /// Bits per second without stuffing.
    pub nominal_bps: f64,
    /// Bits per second with worst-case stuffing.
    pub worst_bps: f64,
}

/// Per-message load of the contract at its nominal rates, and the totals (nominal, worst case)
/// as fractions of `bitrate`.
pub fn table(bitrate: f64) -> (Vec<MessageLoad>, f64, f64) {
    let rates: Vec<_> = ALL_MESSAGES
        .iter()
        .map(|spec| (*spec, spec.frames_per_second))
        .collect();
    load(&rates, bitrate)
}

/// Per-message load of the messages at the rates given (frames per second), and the totals
/// (nominal, worst case) as fractions of `bitrate`.
pub fn load(rates: &[(&'static MessageSpec, f64)], bitrate: f64) -> (Vec<MessageLoad>, f64, f64) {
    let rows: Vec<MessageLoad> = rates
        .iter()
        .map(|&(spec, fps)| MessageLoad {
            spec,
            frames_per_second: fps,
            nominal_bps: fps * f64::from(frame_bits_nominal(spec.dlc)),
            worst_bps: fps * f64::from(frame_bits_worst(spec.dlc)),
        })
        .collect();
    let nominal = rows.iter().map(|r| r.nominal_bps).sum::<f64>() / bitrate;
    let worst = rows.iter().map(|r| r.worst_bps).sum::<f64>() / bitrate;
    (rows, nominal, worst)
}

/// A printable bus-load report of the contract at its nominal rates.
pub fn report(bitrate: f64) -> String {
    report_of(&table(bitrate), bitrate)
}

/// A printable bus-load report of a [`load`] at `bitrate`.
pub fn report_of(load: &(Vec<MessageLoad>, f64, f64), bitrate: f64) -> String {
    use std::fmt::Write;
    let (rows, nominal, worst) = load;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<10} {:>6} {:>4} {:>9} {:>10} {:>10}",
        "message", "id", "dlc", "frames/s", "nominal %", "worst %"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<10} 0x{:03X} {:>4} {:>9.0} {:>10.2} {:>10.2}",
            r.spec.name,
            r.spec.id,
            r.spec.dlc,
            r.frames_per_second,
            100.0 * r.nominal_bps / bitrate,
            100.0 * r.worst_bps / bitrate
        );
    }
    let _ = writeln!(
        s,
        "total at {:.0} kbit/s: {:.1} % nominal, {:.1} % with worst-case bit stuffing",
        bitrate / 1000.0,
        100.0 * nominal,
        100.0 * worst
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_lengths_match_the_literature() {
        // 8-byte standard frame: 111 bits nominal, 135 worst case (Davis et al. 2007).
        assert_eq!(frame_bits_nominal(8), 111);
        assert_eq!(frame_bits_worst(8), 135);
        assert_eq!(frame_bits_worst(0), 55);
    }

    #[test]
    fn worst_case_load_stays_under_70_percent_at_1_mbit() {
        let (_, nominal, worst) = table(NOMINAL_BITRATE);
        assert!(nominal < worst);
        assert!(worst < 0.70, "worst-case load {:.1} %", worst * 100.0);
        // the IMU alone is two 8-byte frames at 2 kHz: 54 % worst case
        assert!(worst > 0.54);
    }
}
