//! The recorded form of raw traffic: CAN frames (`/can/raw`, `/can/tx`, the bench's
//! `/bench/can/tx`) and serial bytes (`/gps/raw`, the bench's `/bench/gps/tx`).
//!
//! Messages are CDR (little-endian, as ROS 2 writes them) under published `ros2msg` schemas,
//! [`CAN_FRAME_SCHEMA`] and [`SERIAL_BYTES_SCHEMA`] (`nav/schemas/ros2msg/`), so a viewer
//! (Foxglove) or a reader (Python's `mcap-ros2-support`) shows their fields without our code:
//! 27 bytes a frame, against the 11 of the private encoding nav wrote before, which is still
//! read ([`LEGACY_FRAME_ENCODING`], [`LEGACY_GPS_ENCODING`]).

use wire::RawFrame;

/// Message encoding of the raw channels.
pub const CDR: &str = "cdr";
/// Schema encoding of the raw channels' schemas.
pub const ROS2MSG: &str = "ros2msg";
/// A CAN frame: name and `ros2msg` text.
pub const CAN_FRAME_SCHEMA: (&str, &str) = (
    "rlg_hil/msg/CanFrame",
    include_str!("../../schemas/ros2msg/CanFrame.msg"),
);
/// Bytes through a serial port: name and `ros2msg` text.
pub const SERIAL_BYTES_SCHEMA: (&str, &str) = (
    "rlg_hil/msg/SerialBytes",
    include_str!("../../schemas/ros2msg/SerialBytes.msg"),
);
/// The private frame encoding of earlier recordings: `[id: u16 LE][len: u8][data: 8 bytes]`.
pub const LEGACY_FRAME_ENCODING: &str = "rlg-hil.can-frame.v1";
/// The private encoding of `/gps/raw` in earlier recordings: the bytes alone.
pub const LEGACY_GPS_ENCODING: &str = "rlg-hil.gps-bytes.v1";

/// Bytes of one CDR [`CAN_FRAME_SCHEMA`] message.
pub const CAN_FRAME_BYTES: usize = 27;

/// CDR's encapsulation header: plain CDR, little-endian.
const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// `builtin_interfaces/Time` of `t_ns` (ns since the epoch).
fn stamp(t_ns: u64) -> [u8; 8] {
    let sec = i32::try_from(t_ns / 1_000_000_000).unwrap_or(i32::MAX);
    let nsec = (t_ns % 1_000_000_000) as u32;
    let mut b = [0u8; 8];
    b[..4].copy_from_slice(&sec.to_le_bytes());
    b[4..].copy_from_slice(&nsec.to_le_bytes());
    b
}

/// A frame and its time stamp (ns since the epoch) as a CDR [`CAN_FRAME_SCHEMA`] message.
pub fn encode_frame(frame: &RawFrame, t_ns: u64) -> [u8; CAN_FRAME_BYTES] {
    let mut b = [0u8; CAN_FRAME_BYTES];
    b[..4].copy_from_slice(&CDR_LE);
    b[4..12].copy_from_slice(&stamp(t_ns));
    b[12..16].copy_from_slice(&u32::from(frame.id).to_le_bytes());
    // extended and remote stay false: the contract has neither
    b[18] = frame.len;
    b[19..].copy_from_slice(&frame.data);
    b
}

/// An error frame and its time stamp as a CDR [`CAN_FRAME_SCHEMA`] message: its identifier with
/// `CAN_ERR_FLAG`, eight data bytes (SocketCAN's `struct can_frame`).
pub fn encode_error_frame(frame: &wire::errframe::ErrorFrame, t_ns: u64) -> [u8; CAN_FRAME_BYTES] {
    let mut b = [0u8; CAN_FRAME_BYTES];
    b[..4].copy_from_slice(&CDR_LE);
    b[4..12].copy_from_slice(&stamp(t_ns));
    b[12..16].copy_from_slice(&frame.can_id().to_le_bytes());
    b[18] = 8;
    b[19..].copy_from_slice(&frame.data);
    b
}

/// The error frame of a CDR [`CAN_FRAME_SCHEMA`] message, if it is one.
pub fn decode_error_frame(encoding: &str, data: &[u8]) -> Option<wire::errframe::ErrorFrame> {
    if encoding != CDR || data.len() < CAN_FRAME_BYTES {
        return None;
    }
    let id = u32::from_le_bytes([data[12], data[13], data[14], data[15]]);
    if id & wire::errframe::CAN_ERR_FLAG == 0 {
        return None;
    }
    let mut d = [0u8; 8];
    d.copy_from_slice(&data[19..27]);
    Some(wire::errframe::ErrorFrame {
        class: id & wire::errframe::CAN_ERR_MASK,
        data: d,
    })
}

/// The error frame of an MCAP message, by its channel's encoding.
pub fn error_frame_of(m: &mcap::Message) -> Option<wire::errframe::ErrorFrame> {
    decode_error_frame(&m.channel.message_encoding, &m.data)
}

/// Bytes and their time stamp as a CDR [`SERIAL_BYTES_SCHEMA`] message, written to `out`.
pub fn encode_serial(t_ns: u64, bytes: &[u8], out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&CDR_LE);
    out.extend_from_slice(&stamp(t_ns));
    out.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(bytes);
}

/// The frame of a recorded message in either encoding (none when it is not a classic frame of
/// the contract's kind).
pub fn decode_frame(encoding: &str, data: &[u8]) -> Option<RawFrame> {
    let (id, len, payload) = match encoding {
        CDR if data.len() == CAN_FRAME_BYTES && data[..4] == CDR_LE => {
            let id = u32::from_le_bytes([data[12], data[13], data[14], data[15]]);
            // an extended or remote frame, or an id past 11 bits, is not one of the contract's
            if data[16] != 0 || data[17] != 0 {
                return None;
            }
            (u16::try_from(id).ok()?, data[18], &data[19..])
        }
        LEGACY_FRAME_ENCODING if data.len() == 11 => {
            (u16::from_le_bytes([data[0], data[1]]), data[2], &data[3..])
        }
        _ => return None,
    };
    if len > 8 || id > 0x7FF {
        return None;
    }
    let mut d = [0u8; 8];
    d.copy_from_slice(payload);
    Some(RawFrame { id, len, data: d })
}

/// The bytes of a recorded serial message in either encoding (none when it is not one).
pub fn decode_serial<'a>(encoding: &str, data: &'a [u8]) -> Option<&'a [u8]> {
    match encoding {
        CDR if data.len() >= 16 && data[..4] == CDR_LE => {
            let n = u32::from_le_bytes([data[12], data[13], data[14], data[15]]) as usize;
            data[16..].get(..n).filter(|b| b.len() + 16 == data.len())
        }
        LEGACY_GPS_ENCODING => Some(data),
        _ => None,
    }
}

/// The frame of an MCAP message, by its channel's encoding.
pub fn frame_of(m: &mcap::Message) -> Option<RawFrame> {
    decode_frame(&m.channel.message_encoding, &m.data)
}

/// The serial bytes of an MCAP message, by its channel's encoding.
pub fn serial_of<'a>(m: &'a mcap::Message) -> Option<&'a [u8]> {
    decode_serial(&m.channel.message_encoding, &m.data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_reads_back_in_both_encodings_and_a_bad_one_does_not() {
        let f = RawFrame {
            id: 0x203,
            len: 6,
            data: [1, 2, 3, 4, 5, 6, 0, 0],
        };
        let b = encode_frame(&f, 1_700_000_000_123_456_789);
        assert_eq!(decode_frame(CDR, &b), Some(f));
        // the stamp: sec, nanosec
        assert_eq!(&b[4..8], &1_700_000_000i32.to_le_bytes());
        assert_eq!(&b[8..12], &123_456_789u32.to_le_bytes());
        assert_eq!(decode_frame(CDR, &b[..26]), None);
        assert_eq!(decode_frame("json", &b), None);
        let mut bad = b;
        bad[18] = 9;
        assert_eq!(decode_frame(CDR, &bad), None, "dlc 9");
        let mut ext = b;
        ext[16] = 1;
        assert_eq!(decode_frame(CDR, &ext), None, "extended");
        let mut wide = b;
        wide[13] = 0x08;
        assert_eq!(decode_frame(CDR, &wide), None, "id 0x803");
        let legacy = [0x03, 0x02, 6, 1, 2, 3, 4, 5, 6, 0, 0];
        assert_eq!(decode_frame(LEGACY_FRAME_ENCODING, &legacy), Some(f));
    }

    #[test]
    fn serial_bytes_read_back_and_a_short_message_does_not() {
        let mut out = Vec::new();
        encode_serial(5_000_000_001, b"$GPGGA,1*00\r\n", &mut out);
        assert_eq!(out.len(), 16 + 13);
        assert_eq!(decode_serial(CDR, &out), Some(&b"$GPGGA,1*00\r\n"[..]));
        assert_eq!(decode_serial(CDR, &out[..20]), None);
        assert_eq!(
            decode_serial(LEGACY_GPS_ENCODING, b"abc"),
            Some(&b"abc"[..])
        );
        encode_serial(0, b"", &mut out);
        assert_eq!(decode_serial(CDR, &out), Some(&b""[..]));
    }

    /// The layout written is the one the schema text declares, field by field (CDR aligns
    /// each primitive to its size from the end of the encapsulation header).
    #[test]
    fn the_schemas_declare_the_fields_written() {
        let fields = |text: &str| -> Vec<String> {
            text.lines()
                .take_while(|l| !l.starts_with("===="))
                .map(|l| l.split('#').next().unwrap_or("").trim().to_string())
                .filter(|l| !l.is_empty())
                .collect()
        };
        assert_eq!(
            fields(CAN_FRAME_SCHEMA.1),
            [
                "builtin_interfaces/Time stamp",
                "uint32 id",
                "bool extended",
                "bool remote",
                "uint8 dlc",
                "uint8[8] data"
            ]
        );
        assert_eq!(
            fields(SERIAL_BYTES_SCHEMA.1),
            ["builtin_interfaces/Time stamp", "uint8[] data"]
        );
    }
}
