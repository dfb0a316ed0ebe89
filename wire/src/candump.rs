//! The `candump -l` log format of can-utils, which `canplayer` plays back and `cantools` decodes:
//! one frame per line, `(SECONDS.MICROSECONDS) INTERFACE ID#DATA`, the id in upper-case hex
//! (3 digits for a standard id, 8 for an extended one), the data in upper-case hex, `ID#R` for a
//! remote frame and `ID##F...` for CAN FD.
//!
//! Our bus carries classic frames with standard ids only ([`RawFrame`]); a log line with another
//! kind of frame parses as [`LogEntry::Other`] so that an importer can count what it skipped.

use crate::RawFrame;
use thiserror::Error;

/// One line of a log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LogEntry {
    /// A classic data frame with a standard id.
    Frame {
        /// Time stamp, microseconds since the epoch (or whatever origin the log used).
        t_us: u64,
        /// Interface name.
        iface: String,
        /// The frame.
        frame: RawFrame,
    },
    /// A frame of another kind (extended id, remote, CAN FD, error frame): what it was.
    Other {
        /// Time stamp, microseconds.
        t_us: u64,
        /// Its kind.
        kind: &'static str,
    },
}

/// A line that is not in the `candump -l` format.
#[derive(Debug, Clone, Error, PartialEq, Eq)]
#[error("line {line}: {what}: {text:?}")]
pub struct LogError {
    /// Line number, from 1.
    pub line: usize,
    /// What was wrong.
    pub what: &'static str,
    /// The line (cut to 80 characters).
    pub text: String,
}

/// The log line of `frame` received on `iface` at `t_us` microseconds.
pub fn format_line(t_us: u64, iface: &str, frame: &RawFrame) -> String {
    let mut s = String::with_capacity(48);
    push_line(&mut s, t_us, iface, frame);
    s
}

/// [`format_line`] appended to `out`, without its own allocation: a log of a million frames
/// is written through one buffer.
pub fn push_line(out: &mut String, t_us: u64, iface: &str, frame: &RawFrame) {
    push_head(out, t_us, iface);
    push_hex(out, u64::from(frame.id), 3);
    out.push('#');
    for &b in frame.payload() {
        push_hex(out, u64::from(b), 2);
    }
}

/// An error frame as `candump -l` writes it: its identifier with `CAN_ERR_FLAG` in eight hex
/// digits, its eight data bytes.
pub fn format_error_line(t_us: u64, iface: &str, e: &crate::errframe::ErrorFrame) -> String {
    let mut s = String::with_capacity(56);
    push_head(&mut s, t_us, iface);
    push_hex(&mut s, u64::from(e.can_id()), 8);
    s.push('#');
    for b in e.data {
        push_hex(&mut s, u64::from(b), 2);
    }
    s
}

/// `(SECONDS.MICROS) IFACE ` of a line.
fn push_head(out: &mut String, t_us: u64, iface: &str) {
    out.push('(');
    push_decimal(out, t_us / 1_000_000, 1);
    out.push('.');
    push_decimal(out, t_us % 1_000_000, 6);
    out.push_str(") ");
    out.push_str(iface);
    out.push(' ');
}

/// `v` in decimal, zero-padded to at least `width` digits.
fn push_decimal(out: &mut String, mut v: u64, width: usize) {
    let mut d = [b'0'; 20];
    let mut i = d.len();
    while v > 0 || d.len() - i < width {
        i -= 1;
        d[i] = b'0' + (v % 10) as u8;
        v /= 10;
    }
    out.extend(d[i..].iter().map(|&c| char::from(c)));
}

/// The `digits` low hex digits of `v`, upper case.
fn push_hex(out: &mut String, v: u64, digits: u32) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    for k in (0..digits).rev() {
        out.push(char::from(HEX[((v >> (4 * k)) & 0xF) as usize]));
    }
}

/// Parse line number `line` (from 1) of a log; `Ok(None)` for a blank line.
pub fn parse_line(text: &str, line: usize) -> Result<Option<LogEntry>, LogError> {
    let t = text.trim();
    if t.is_empty() {
        return Ok(None);
    }
    let err = |what| LogError {
        line,
        what,
        text: t.chars().take(80).collect(),
    };
    let rest = t.strip_prefix('(').ok_or(err("no '(' time stamp"))?;
    let (stamp, rest) = rest
        .split_once(')')
        .ok_or(err("no ')' after the time stamp"))?;
    let (secs, micros) = stamp
        .split_once('.')
        .ok_or(err("time stamp without a fraction"))?;
    let secs: u64 = secs
        .parse()
        .map_err(|_| err("time stamp seconds not a number"))?;
    if micros.len() != 6 || !micros.bytes().all(|b| b.is_ascii_digit()) {
        return Err(err("time stamp fraction is not 6 digits"));
    }
    let micros: u64 = micros.parse().map_err(|_| err("time stamp fraction"))?;
    let t_us = secs
        .checked_mul(1_000_000)
        .and_then(|s| s.checked_add(micros))
        .ok_or(err("time stamp out of range"))?;
    let mut fields = rest.split_whitespace();
    let iface = fields.next().ok_or(err("no interface"))?;
    let frame = fields.next().ok_or(err("no frame"))?;
    let (id, data) = frame.split_once('#').ok_or(err("no '#' in the frame"))?;
    if !id.bytes().all(|b| b.is_ascii_hexdigit()) || id.is_empty() {
        return Err(err("frame id is not hex"));
    }
    let other = |kind| Ok(Some(LogEntry::Other { t_us, kind }));
    match id.len() {
        3 => {}
        8 => {
            let raw = u32::from_str_radix(id, 16).map_err(|_| err("frame id"))?;
            return other(if raw & 0x2000_0000 != 0 {
                "error frame"
            } else {
                "extended id"
            });
        }
        _ => return Err(err("frame id is neither 3 nor 8 hex digits")),
    }
    if data.starts_with('#') {
        return other("CAN FD");
    }
    if data.starts_with('R') {
        return other("remote");
    }
    if data.len() % 2 != 0 || data.len() > 16 || !data.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(err("data is not 0 to 8 bytes of hex"));
    }
    let id = u16::from_str_radix(id, 16).map_err(|_| err("frame id"))?;
    if id > 0x7FF {
        return Err(err("standard id above 0x7FF"));
    }
    let mut bytes = [0u8; 8];
    for (i, b) in bytes.iter_mut().enumerate().take(data.len() / 2) {
        *b = u8::from_str_radix(&data[2 * i..2 * i + 2], 16).map_err(|_| err("data"))?;
    }
    Ok(Some(LogEntry::Frame {
        t_us,
        iface: iface.to_string(),
        frame: RawFrame {
            id,
            len: (data.len() / 2) as u8,
            data: bytes,
        },
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_read_back_as_written() {
        let f = RawFrame {
            id: 0x080,
            len: 8,
            data: [0x01, 0xAB, 0, 0xFF, 0x10, 0x20, 0x30, 0x7F],
        };
        let l = format_line(1_700_000_000_000_042, "vcan0", &f);
        assert_eq!(l, "(1700000000.000042) vcan0 080#01AB00FF1020307F");
        assert_eq!(
            parse_line(&l, 1),
            Ok(Some(LogEntry::Frame {
                t_us: 1_700_000_000_000_042,
                iface: "vcan0".into(),
                frame: f
            }))
        );
        let empty = RawFrame {
            id: 0x7FF,
            len: 0,
            data: [0; 8],
        };
        let l = format_line(5, "can0", &empty);
        assert_eq!(l, "(0.000005) can0 7FF#");
        // as the standard formatter writes them, over times and identifiers
        for (t, id) in [
            (0, 0),
            (999_999, 0x1),
            (1_000_000, 0x7FF),
            (u64::MAX, 0x123),
        ] {
            let f = RawFrame {
                id,
                len: 2,
                data: [0x0F, 0xF0, 0, 0, 0, 0, 0, 0],
            };
            let std = format!(
                "({}.{:06}) vcan9 {id:03X}#0FF0",
                t / 1_000_000,
                t % 1_000_000
            );
            assert_eq!(format_line(t, "vcan9", &f), std);
        }
        let e = crate::errframe::ErrorFrame {
            class: 0x44,
            data: [0, 0x08, 0, 0, 0, 0, 0x80, 0x7F],
        };
        assert_eq!(
            format_error_line(1_000_001, "can0", &e),
            "(1.000001) can0 20000044#000800000000807F"
        );
        assert!(
            matches!(parse_line(&l, 1), Ok(Some(LogEntry::Frame { frame, .. })) if frame == empty)
        );
    }

    #[test]
    fn other_kinds_are_named_and_bad_lines_say_what_is_wrong() {
        let kind = |l: &str| match parse_line(l, 3) {
            Ok(Some(LogEntry::Other { kind, .. })) => kind,
            r => panic!("{r:?}"),
        };
        assert_eq!(kind("(1.000000) can0 12345678#00"), "extended id");
        assert_eq!(
            kind("(1.000000) can0 20000004#0000000000000000"),
            "error frame"
        );
        assert_eq!(kind("(1.000000) can0 123#R"), "remote");
        assert_eq!(kind("(1.000000) can0 123##1112233"), "CAN FD");
        assert_eq!(parse_line("   ", 1), Ok(None));
        for (l, what) in [
            ("1.000000 can0 123#00", "no '(' time stamp"),
            ("(1.0) can0 123#00", "time stamp fraction is not 6 digits"),
            ("(1.000000) can0 123#0", "data is not 0 to 8 bytes of hex"),
            (
                "(1.000000) can0 123#00112233445566778",
                "data is not 0 to 8 bytes of hex",
            ),
            (
                "(1.000000) can0 1234#00",
                "frame id is neither 3 nor 8 hex digits",
            ),
            ("(1.000000) can0 800#00", "standard id above 0x7FF"),
            ("(1.000000) can0", "no frame"),
            ("(1.000000) can0 G23#00", "frame id is not hex"),
        ] {
            let e = parse_line(l, 7).unwrap_err();
            assert_eq!((e.line, e.what), (7, what), "{l}");
        }
    }
}
