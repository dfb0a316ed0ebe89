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

/// The longest time a frame of `payload` bytes takes on the bus, s: standard or `extended`
/// identifier, classic CAN or CAN FD (`fd`, with the bit-rate switch: the data phase at
/// `data_bps`, the rest at `nominal_bps`), every stuff bit the rules allow counted (one per
/// four bits of the stuffed fields; CAN FD's CRC field with its fixed stuff bits). For classic
/// frames the bound of Davis et al. (2007): `g + 8n + 13 + floor((g + 8n - 1) / 4)` bits, `g`
/// 34 standard, 54 extended.
pub fn frame_time_worst_s(
    extended: bool,
    payload: usize,
    fd: bool,
    nominal_bps: f64,
    data_bps: f64,
) -> f64 {
    let (arb, data) = frame_bits_worst_phases(extended, payload, fd);
    let t = f64::from(arb) / nominal_bps;
    if data == 0 {
        t
    } else {
        t + f64::from(data) / data_bps
    }
}

/// [`frame_time_worst_s`]'s bits: those at the nominal rate and those in CAN FD's data phase
/// (0 for a classic frame).
pub fn frame_bits_worst_phases(extended: bool, payload: usize, fd: bool) -> (u32, u32) {
    let n = payload as u32 * 8;
    if !fd {
        let g = if extended { 54 } else { 34 };
        return (g + n + 13 + (g + n - 1) / 4, 0);
    }
    // arbitration phase: SOF, identifier (SRR, IDE and the 18 more bits when extended), RRS,
    // IDE/FDF, res, BRS
    let arb = if extended {
        1 + 11 + 2 + 18 + 1 + 1 + 1 + 1
    } else {
        1 + 11 + 1 + 1 + 1 + 1 + 1
    };
    // data phase: ESI, DLC, the data, stuffed; the stuff count (4) and CRC (17 or 21) with a
    // fixed stuff bit before every four bits, the CRC delimiter
    let crc = if payload <= 16 { 17 } else { 21 };
    let stuffed = 1 + 4 + n;
    let fixed = 4 + crc;
    let data = stuffed + stuffed / 4 + fixed + fixed.div_ceil(4) + 1;
    // after the switch back: ACK slot and delimiter, end of frame, intermission
    let tail = 1 + 1 + 7 + 3;
    (arb + (arb - 1) / 4 + tail, data)
}

/// A frame's place in arbitration: lower wins. The 11 base bits first; a standard frame wins
/// over an extended one with the same base bits (its IDE bit is dominant); then the 18 more.
pub fn arbitration_key(id: u32, extended: bool) -> u64 {
    if extended {
        (u64::from(id >> 18) << 19) | (1 << 18) | u64::from(id & 0x3_FFFF)
    } else {
        u64::from(id & 0x7FF) << 19
    }
}

/// A message sent periodically on a bus, for [`response_times`].
#[derive(Debug, Clone, PartialEq)]
pub struct Periodic {
    /// Its name (for reports).
    pub name: String,
    /// Its identifier (11 or 29 bits).
    pub id: u32,
    /// A 29-bit identifier.
    pub extended: bool,
    /// Data bytes.
    pub payload: usize,
    /// A CAN FD frame with the bit-rate switch.
    pub fd: bool,
    /// Its period, s (the shortest time between two of its frames).
    pub period_s: f64,
    /// Its queuing jitter, s (how late after its period's start it may be queued).
    pub jitter_s: f64,
}

impl Periodic {
    /// Its place in arbitration: lower wins. The 11 base bits first; a standard frame wins over
    /// an extended one with the same base bits (its IDE bit is dominant); then the 18 more.
    pub fn arbitration_key(&self) -> u64 {
        arbitration_key(self.id, self.extended)
    }
}

/// The worst-case response time of each message of `msgs` (queued to the end of its
/// transmission, s), on a bus at `nominal_bps` whose CAN FD data phases run at `data_bps`, by
/// the revised analysis of Davis, Burns, Bril and Lukkien (2007), eqs. 15-18: each frame at its
/// longest ([`frame_time_worst_s`]), blocked by the longest frame of lower priority, and every
/// instance in its level's busy period examined (a frame can be delayed most by its own
/// previous instance). `None` where the messages of its priority and above load the bus to 1 or
/// more: no bound.
pub fn response_times(msgs: &[Periodic], nominal_bps: f64, data_bps: f64) -> Vec<Option<f64>> {
    let c: Vec<f64> = msgs
        .iter()
        .map(|m| frame_time_worst_s(m.extended, m.payload, m.fd, nominal_bps, data_bps))
        .collect();
    let tau = 1.0 / nominal_bps;
    let keys: Vec<u64> = msgs.iter().map(Periodic::arbitration_key).collect();
    (0..msgs.len())
        .map(|i| {
            let m = &msgs[i];
            // higher priority (hp) and lower priority (lp) than message i
            let hp: Vec<usize> = (0..msgs.len()).filter(|&k| keys[k] < keys[i]).collect();
            let blocking = (0..msgs.len())
                .filter(|&k| keys[k] > keys[i])
                .map(|k| c[k])
                .fold(0.0, f64::max);
            let load: f64 =
                hp.iter().map(|&k| c[k] / msgs[k].period_s).sum::<f64>() + c[i] / m.period_s;
            let bounded = load < 1.0 && m.period_s > 0.0;
            if !bounded {
                return None;
            }
            let interference = |w: f64, with_tau: f64| -> f64 {
                hp.iter()
                    .map(|&k| ((w + msgs[k].jitter_s + with_tau) / msgs[k].period_s).ceil() * c[k])
                    .sum()
            };
            // the level-i busy period (eq. 16), then every instance q in it (eqs. 17-18)
            let mut t = c[i];
            loop {
                let next =
                    blocking + interference(t, 0.0) + ((t + m.jitter_s) / m.period_s).ceil() * c[i];
                if next <= t {
                    break;
                }
                t = next;
            }
            let instances = ((t + m.jitter_s) / m.period_s).ceil().max(1.0) as u64;
            let mut worst: f64 = 0.0;
            for q in 0..instances {
                let q = q as f64;
                let mut w = blocking + q * c[i];
                loop {
                    let next = blocking + q * c[i] + interference(w, tau);
                    if next <= w {
                        break;
                    }
                    w = next;
                }
                worst = worst.max(m.jitter_s + w - q * m.period_s + c[i]);
            }
            Some(worst)
        })
        .collect()
}

/// Bits on the wire for `frame` exactly as a classic CAN controller sends it (11-bit
/// identifier, data frame): start of frame, arbitration, control and data fields and the
/// CRC-15 sequence with their stuff bits (a bit of opposite value after five equal bits, the
/// stuff bit counting towards the next run), then the 13 unstuffed bits of CRC delimiter, ACK
/// slot and delimiter, end of frame and intermission. Between [`frame_bits_nominal`] and
/// [`frame_bits_worst`].
pub fn frame_bits_exact(frame: &crate::RawFrame) -> u32 {
    let len = frame.len.min(8);
    // the bits before the CRC, the first sent in the highest place (at most 1 + 11 + 3 + 4 +
    // 64 = 83 of them, 98 with the CRC): the bus model asks this of every frame it carries,
    // so no allocation
    let mut bits = Bits::default();
    bits.push(0, 1); // start of frame (dominant)
    bits.push(u64::from(frame.id), 11);
    bits.push(0, 3); // RTR, IDE, r0: a data frame, standard identifier
    bits.push(u64::from(len), 4);
    for &b in &frame.data[..usize::from(len)] {
        bits.push(u64::from(b), 8);
    }
    let crc = crc15(bits.word, bits.n);
    bits.push(u64::from(crc), 15);
    bits.n + stuff_bits(bits.word, bits.n) + 13
}

/// The stuff bits CAN puts in the `n` low bits of `word` (sent highest first): one of the
/// other value after five equal bits, which begins the next run. Counted a byte at a time
/// through [`STUFF_TABLE`] (the bus model asks this of every frame it carries).
fn stuff_bits(word: u128, n: u32) -> u32 {
    if n == 0 {
        return 0;
    }
    // the first bit begins a run of one
    let mut state = (((word >> (n - 1)) & 1) as u8) * 4;
    let mut left = n - 1;
    let mut stuffed = 0;
    while left >= 8 {
        let byte = ((word >> (left - 8)) & 0xFF) as usize;
        let (next, count) = STUFF_TABLE[usize::from(state)][byte];
        state = next;
        stuffed += u32::from(count);
        left -= 8;
    }
    while left > 0 {
        left -= 1;
        let (next, count) = stuff_step(state, ((word >> left) & 1) as u8);
        state = next;
        stuffed += u32::from(count);
    }
    stuffed
}

/// One bit through the stuffing rule. The state is the current run's value and length (1 to
/// 4), `value * 4 + length - 1`; a fifth equal bit brings a stuff bit of the other value,
/// which begins a run of that value. Returns the next state and the stuff bits added (0 or 1).
const fn stuff_step(state: u8, bit: u8) -> (u8, u8) {
    let (value, len) = (state / 4, state % 4 + 1);
    if bit != value {
        (bit * 4, 0)
    } else if len == 4 {
        ((1 - value) * 4, 1)
    } else {
        (value * 4 + len, 0)
    }
}

/// For each stuffing state and each byte (sent highest bit first): the state after the byte
/// and the stuff bits it brought.
const STUFF_TABLE: [[(u8, u8); 256]; 8] = {
    let mut t = [[(0u8, 0u8); 256]; 8];
    let mut state = 0;
    while state < 8 {
        let mut byte = 0;
        while byte < 256 {
            let (mut s, mut count) = (state as u8, 0u8);
            let mut i = 8;
            while i > 0 {
                i -= 1;
                let (next, c) = stuff_step(s, ((byte >> i) & 1) as u8);
                s = next;
                count += c;
            }
            t[state][byte] = (s, count);
            byte += 1;
        }
        state += 1;
    }
    t
};

/// Up to 128 bits in the order sent, the first in the highest place of `word`'s `n` low bits.
#[derive(Default)]
struct Bits {
    word: u128,
    n: u32,
}

impl Bits {
    /// Append the `k` low bits of `v`, highest first.
    fn push(&mut self, v: u64, k: u32) {
        self.word = (self.word << k) | u128::from(v & ((1u64 << k) - 1));
        self.n += k;
    }
}

/// CAN's CRC-15 (polynomial 0x4599) over the `n` low bits of `word`, the highest first: the
/// bits above a whole number of bytes one by one, then a byte at a time ([`CRC15_TABLE`]).
fn crc15(word: u128, n: u32) -> u16 {
    let mut crc = 0u16;
    let lead = n % 8;
    for i in (n - lead..n).rev() {
        let next = ((word >> i) & 1 == 1) ^ ((crc >> 14) & 1 == 1);
        crc = (crc << 1) & 0x7FFF;
        if next {
            crc ^= 0x4599;
        }
    }
    for k in (0..(n - lead) / 8).rev() {
        let byte = ((word >> (8 * k)) & 0xFF) as u16;
        crc = ((crc << 8) & 0x7FFF) ^ CRC15_TABLE[usize::from(((crc >> 7) ^ byte) & 0xFF)];
    }
    crc
}

/// The CRC-15 of each byte value, for [`crc15`]'s byte steps.
const CRC15_TABLE: [u16; 256] = {
    let mut t = [0u16; 256];
    let mut v = 0;
    while v < 256 {
        let mut crc = (v as u16) << 7;
        let mut i = 0;
        while i < 8 {
            crc = if crc & 0x4000 != 0 {
                ((crc << 1) ^ 0x4599) & 0x7FFF
            } else {
                (crc << 1) & 0x7FFF
            };
            i += 1;
        }
        t[v] = crc;
        v += 1;
    }
    t
};

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

/// The messages of our contract that `rows` sends (those at no rate take no part), each at its
/// rate taken as its period, for [`response_times`].
pub fn periodic_of(rows: &[MessageLoad]) -> Vec<Periodic> {
    rows.iter()
        .filter(|r| r.frames_per_second > 0.0)
        .map(|r| Periodic {
            name: r.spec.name.to_string(),
            id: u32::from(r.spec.id),
            extended: false,
            payload: usize::from(r.spec.dlc),
            fd: false,
            period_s: 1.0 / r.frames_per_second,
            jitter_s: 0.0,
        })
        .collect()
}

/// A printable bus-load report of a [`load`] at `bitrate`.
pub fn report_of(load: &(Vec<MessageLoad>, f64, f64), bitrate: f64) -> String {
    use std::fmt::Write;
    let (rows, nominal, worst) = load;
    // every message's worst-case response time, its rate taken as its period
    let periodic = periodic_of(rows);
    let response = response_times(&periodic, bitrate, bitrate);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<10} {:>6} {:>4} {:>9} {:>10} {:>10} {:>13}",
        "message", "id", "dlc", "frames/s", "nominal %", "worst %", "response ms"
    );
    for r in rows {
        let resp = periodic
            .iter()
            .position(|x| x.id == u32::from(r.spec.id))
            .map(|k| response[k].map_or("no bound".to_string(), |t| format!("{:.3}", t * 1e3)))
            .unwrap_or_else(|| "-".to_string());
        let _ = writeln!(
            s,
            "{:<10} 0x{:03X} {:>4} {:>9.0} {:>10.2} {:>10.2} {:>13}",
            r.spec.name,
            r.spec.id,
            r.spec.dlc,
            r.frames_per_second,
            100.0 * r.nominal_bps / bitrate,
            100.0 * r.worst_bps / bitrate,
            resp
        );
    }
    let _ = writeln!(
        s,
        "response: the worst-case time from queued to sent, each message at its rate (Davis et al. 2007)"
    );
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

    /// Three classic 8-byte frames at 500 kbit/s (each 270 us at its longest) every 1, 2 and
    /// 4 ms: worked by hand from Davis et al. (2007). The first waits for one lower frame at
    /// most; the second for a lower one and the first; the last for both above it, never
    /// blocked.
    #[test]
    fn response_times_match_the_analysis_worked_by_hand() {
        let m = |name: &str, id: u32, period_s: f64| Periodic {
            name: name.into(),
            id,
            extended: false,
            payload: 8,
            fd: false,
            period_s,
            jitter_s: 0.0,
        };
        let msgs = [m("a", 1, 1e-3), m("b", 2, 2e-3), m("c", 3, 4e-3)];
        let r: Vec<f64> = response_times(&msgs, 500e3, 500e3)
            .into_iter()
            .map(|r| (r.unwrap() * 1e6).round())
            .collect();
        assert_eq!(r, [540.0, 810.0, 810.0]);
        // a message whose level is loaded past 100 % has no bound; those above it keep theirs
        let mut full = msgs.to_vec();
        full[2].period_s = 0.999 * 270e-6 / (1.0 - 270.0 / 1000.0 - 270.0 / 2000.0);
        let r = response_times(&full, 500e3, 500e3);
        assert!(r[0].is_some() && r[1].is_some() && r[2].is_none(), "{r:?}");
        // an extended frame loses to a standard one with the same 11 bits
        let mut ext = m("x", 1 << 18, 1e-3);
        ext.extended = true;
        assert!(ext.arbitration_key() > m("s", 1, 1e-3).arbitration_key());
        assert!(ext.arbitration_key() < m("s", 2, 1e-3).arbitration_key());
    }

    #[test]
    fn frame_lengths_match_the_literature() {
        // 8-byte standard frame: 111 bits nominal, 135 worst case (Davis et al. 2007).
        assert_eq!(frame_bits_nominal(8), 111);
        assert_eq!(frame_bits_worst(8), 135);
        assert_eq!(frame_bits_worst(0), 55);
    }

    #[test]
    fn exact_lengths_count_the_stuff_bits_of_the_frame() {
        use crate::RawFrame;
        // all zeros: 34 dominant bits before the CRC (which is zero too): a stuff bit after
        // every fifth, six in all, plus the 13 unstuffed bits
        let zero = RawFrame {
            id: 0,
            len: 0,
            data: [0; 8],
        };
        assert_eq!(crc15(0, 19), 0);
        assert_eq!(frame_bits_exact(&zero), 19 + 15 + 6 + 13);
        // every length lies between the unstuffed and the worst case, over many payloads
        let mut x = 0x1234_5678_u32;
        let mut digest = 0u64;
        for n in 0..2000u32 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let len = (n % 9) as u8;
            let mut data = [0u8; 8];
            for (i, d) in data.iter_mut().enumerate().take(usize::from(len)) {
                *d = (x >> (i % 4 * 8)) as u8 ^ (n as u8);
            }
            let f = RawFrame {
                id: (x % 0x800) as u16,
                len,
                data,
            };
            let b = frame_bits_exact(&f);
            digest = digest.wrapping_mul(31).wrapping_add(u64::from(b));
            assert!(
                (frame_bits_nominal(len)..=frame_bits_worst(len)).contains(&b),
                "{f:?}: {b} bits"
            );
        }
        // the lengths of these 2000 frames as the bit-by-bit count of the specification gave
        // them (a vector of bools, the stuffing rule applied to it)
        assert_eq!(digest, 302_380_154_055_583_620);
        // 0x7FF with 0xFF data: long recessive runs, many stuff bits
        let ones = RawFrame {
            id: 0x7FF,
            len: 8,
            data: [0xFF; 8],
        };
        assert!(frame_bits_exact(&ones) > frame_bits_nominal(8) + 12);
    }

    #[test]
    fn the_byte_wise_stuff_count_is_the_bit_by_bit_one() {
        // the rule of the specification, one bit at a time: after five equal bits (a stuff
        // bit counting as one of them) one of the other value
        let by_bits = |word: u128, n: u32| {
            let (mut stuffed, mut last, mut run) = (0, 2u8, 0);
            for i in (0..n).rev() {
                let b = ((word >> i) & 1) as u8;
                if b == last {
                    run += 1;
                } else {
                    (last, run) = (b, 1);
                }
                if run == 5 {
                    stuffed += 1;
                    (last, run) = (1 - b, 1);
                }
            }
            stuffed
        };
        let mut x = 0x2545_F491_4F6C_DD1D_u64;
        for n in 0..=113 {
            for pattern in 0..4 {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                // random bits, then long runs: sparse ones, sparse zeros, all equal
                let r = u128::from(x) << 64 | u128::from(x.rotate_left(29));
                let word = match pattern {
                    0 => r,
                    1 => r & (r >> 3) & (r >> 7),
                    2 => !(r & (r >> 3) & (r >> 7)),
                    _ => u128::MAX * u128::from(x & 1),
                } & ((1u128 << n) - 1);
                assert_eq!(
                    stuff_bits(word, n),
                    by_bits(word, n),
                    "{n} bits of {word:#x}"
                );
            }
        }
    }

    #[test]
    fn the_byte_wise_crc_is_the_bit_by_bit_one() {
        // the shift register of the specification, one bit at a time
        let by_bits = |word: u128, n: u32| {
            let mut crc = 0u16;
            for i in (0..n).rev() {
                let next = ((word >> i) & 1 == 1) ^ ((crc >> 14) & 1 == 1);
                crc = (crc << 1) & 0x7FFF;
                if next {
                    crc ^= 0x4599;
                }
            }
            crc
        };
        let mut x = 0x9E37_79B9_7F4A_7C15_u64;
        for n in 0..=113 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let word = (u128::from(x) << 64 | u128::from(x.rotate_left(29))) & ((1u128 << n) - 1);
            assert_eq!(crc15(word, n), by_bits(word, n), "{n} bits of {word:#x}");
        }
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
