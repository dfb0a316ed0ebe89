//! The bench's ear on the bus in a free-running run: every frame but the IMU's stream, decoded
//! by the DBC only. The device under test's solution epochs (NAV_TIME and the frames of its
//! Seq), each NAV_TIME tied at once to the IMU sample it names and the instant that sample went
//! on the bus; its turntable commands counted; every frame outside the DBC counted and named.

use crate::free::score::Epoch;
use anyhow::{Context, Result};
use emulators::freerun::SentSamples;
use socketcan::{CanSocket, Socket, SocketOptions};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use wire::{Message, NavHealth};

/// What the bench has heard so far.
#[derive(Debug, Default)]
pub struct Observed {
    /// The device's solution epochs, in the order they came.
    pub epochs: Vec<Epoch>,
    /// Frames outside the DBC: an identifier it does not define, a length or a value its
    /// layout refuses, an extended or remote frame; by what they were.
    pub outside_dbc: BTreeMap<String, u64>,
    /// TT_CMD frames on the bus (the device under test commanding the table).
    pub commands: u64,
    /// Bytes the device says it took from the receiver (NAV_TIME's GpsRxBytes, 12 bits,
    /// accumulated), and the last value seen.
    pub receiver_bytes: u64,
    last_rx_bytes: Option<u16>,
}

impl Observed {
    /// Frames outside the DBC, in all.
    pub fn outside_count(&self) -> u64 {
        self.outside_dbc.values().sum()
    }
}

/// The names of the health bits set.
fn health_names(h: &NavHealth) -> Vec<String> {
    [
        (h.imu_timeout, "imu_timeout"),
        (h.imu_gaps, "imu_gaps"),
        (h.imu_bit, "imu_bit"),
        (h.gps_stale, "gps_stale"),
        (h.turntable, "turntable"),
        (h.filter, "filter"),
        (h.gps_data, "gps_data"),
        (h.can_bus, "can_bus"),
    ]
    .into_iter()
    .filter(|(on, _)| *on)
    .map(|(_, n)| n.to_string())
    .collect()
}

/// A socket on `iface` that hears everything but the IMU's stream (0x080-0x09F).
pub fn open(iface: &str) -> Result<CanSocket> {
    let sock = CanSocket::open(iface).with_context(|| format!("listening on {iface}"))?;
    sock.set_filters(&[socketcan::CanFilter::new_inverted(0x080, 0x7E0)])
        .with_context(|| format!("filters on {iface}"))?;
    Ok(sock)
}

/// Listen on `sock` until `stop`, into `seen`; times in s since `origin`.
pub fn listen(
    sock: CanSocket,
    origin: Instant,
    sent: &SentSamples,
    seen: &Mutex<Observed>,
    stop: &AtomicBool,
) -> Result<()> {
    while !stop.load(Ordering::Relaxed) {
        let f = match sock.read_frame_timeout(Duration::from_millis(20)) {
            Ok(f) => f,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                continue;
            }
            Err(e) => return Err(e).context("reading the bus"),
        };
        let rx_s = origin.elapsed().as_secs_f64();
        let mut o = seen.lock().unwrap_or_else(|e| e.into_inner());
        let raw = match wire::from_can_frame(&f) {
            Ok(r) => r,
            // a controller's error frame is no device's message
            Err(wire::FrameConvError::Error(_)) => continue,
            Err(e) => {
                *o.outside_dbc.entry(format!("{e}")).or_default() += 1;
                continue;
            }
        };
        let m = match Message::decode(&raw) {
            Ok(m) => m,
            Err(e) => {
                let what = match wire::spec_for_id(raw.id) {
                    Some(s) => format!("{} (0x{:03X}): {e}", s.name, raw.id),
                    None => format!("0x{:03X}: not in the DBC", raw.id),
                };
                *o.outside_dbc.entry(what).or_default() += 1;
                continue;
            }
        };
        take(&mut o, m, rx_s, origin, sent);
    }
    Ok(())
}

/// A decoded frame into what was heard.
fn take(o: &mut Observed, m: Message, rx_s: f64, origin: Instant, sent: &SentSamples) {
    let same = |o: &mut Observed, seq: Option<u8>| -> Option<usize> {
        let i = o.epochs.len().checked_sub(1)?;
        seq.is_none_or(|s| o.epochs[i].seq == s).then_some(i)
    };
    match m {
        Message::NavTime(t) => {
            if let Some(prev) = o.last_rx_bytes {
                o.receiver_bytes += u64::from(t.gps_rx_bytes.wrapping_sub(prev) & 0xFFF);
            }
            o.last_rx_bytes = Some(t.gps_rx_bytes);
            let sample = sent
                .find(t.sample_count as u16)
                .map(|(k, at)| (k, at.saturating_duration_since(origin).as_secs_f64()));
            o.epochs.push(Epoch {
                sample_count: t.sample_count,
                seq: t.seq,
                mode: t.mode,
                health: health_names(&t.health),
                rx_s,
                sample,
                att: None,
                vel: None,
                pos: None,
                hgt: None,
            });
        }
        Message::NavAtt(a) => {
            if let Some(i) = same(o, Some(a.seq)) {
                o.epochs[i].att = Some([a.heading_deg, a.pitch_deg, a.roll_deg]);
            }
        }
        Message::NavVel(v) => {
            if let Some(i) = same(o, Some(v.seq)) {
                o.epochs[i].vel = Some(v.enu_mps);
            }
        }
        // NAV_POS has no Seq: it belongs to the epoch whose NAV_VEL came last
        Message::NavPos(p) => {
            if let Some(i) = same(o, None).filter(|i| o.epochs[*i].vel.is_some()) {
                o.epochs[i].pos = Some([p.lat_deg, p.lon_deg]);
            }
        }
        Message::NavHgt(h) => {
            if let Some(i) = same(o, Some(h.seq)) {
                o.epochs[i].hgt = Some([h.height_m, h.pos_sigma_m, h.heading_sigma_deg]);
            }
        }
        Message::TtCmd(_) => o.commands += 1,
        _ => {}
    }
}

/// Listen in a thread of its own.
pub fn spawn(
    sock: CanSocket,
    origin: Instant,
    sent: Arc<SentSamples>,
    seen: Arc<Mutex<Observed>>,
    stop: Arc<AtomicBool>,
) -> Result<std::thread::JoinHandle<Result<()>>> {
    std::thread::Builder::new()
        .name("observer".into())
        .spawn(move || listen(sock, origin, &sent, &seen, &stop))
        .context("starting the bus observer")
}
