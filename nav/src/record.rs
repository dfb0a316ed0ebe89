//! MCAP recording on its own thread, so the receive path never waits for the disk.
//!
//! Channels:
//! - `/can/raw` (encoding `rlg-hil.can-frame.v1`): every received frame as
//!   `[id: u16 LE][len: u8][data: 8 bytes]`; log time = receive wall time.
//! - `/can/tx` (same encoding): every frame nav sent (turntable commands, the solution).
//! - `/imu/sample` (JSON): every decoded IMU sample; publish time = sample time on the IMU clock.
//! - `/nav/event` (JSON): irregularities (gaps, duplicates, bad frames, timeouts).
//! - `/nav/summary` (JSON): the run summary, once at the end.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Instant;
use thiserror::Error;
use wire::RawFrame;

/// Message encoding of `/can/raw` and `/can/tx`.
pub const RAW_FRAME_ENCODING: &str = "rlg-hil.can-frame.v1";

/// Bytes of one frame in [`RAW_FRAME_ENCODING`].
pub const RAW_FRAME_BYTES: usize = 11;

/// A frame in [`RAW_FRAME_ENCODING`]: `[id: u16 LE][len: u8][data: 8 bytes]`.
pub fn encode_frame(frame: &RawFrame) -> [u8; RAW_FRAME_BYTES] {
    let mut buf = [0u8; RAW_FRAME_BYTES];
    buf[..2].copy_from_slice(&frame.id.to_le_bytes());
    buf[2] = frame.len;
    buf[3..].copy_from_slice(&frame.data);
    buf
}

/// The frame of a [`RAW_FRAME_ENCODING`] message (none when it is not one).
pub fn decode_frame(data: &[u8]) -> Option<RawFrame> {
    if data.len() != RAW_FRAME_BYTES || data[2] > 8 {
        return None;
    }
    let mut d = [0u8; 8];
    d.copy_from_slice(&data[3..]);
    Some(RawFrame {
        id: u16::from_le_bytes([data[0], data[1]]),
        len: data[2],
        data: d,
    })
}

/// One thing to record.
#[derive(Debug)]
pub enum Record {
    /// A received frame.
    Frame {
        /// Receive wall time, ns since the epoch.
        t_ns: u64,
        /// The frame.
        frame: RawFrame,
    },
    /// A frame nav sent (turntable commands, the solution): `/can/tx`.
    Sent {
        /// Send wall time, ns since the epoch.
        t_ns: u64,
        /// The frame.
        frame: RawFrame,
    },
    /// A decoded IMU sample, serialized to JSON on the writer thread (off the receive path).
    Sample {
        /// Log time, ns.
        t_ns: u64,
        /// Publish time (IMU clock), ns.
        publish_ns: u64,
        /// The sample.
        sample: crate::imu::ImuSample,
    },
    /// A JSON message on a JSON channel.
    Json {
        /// Which channel.
        channel: JsonChannel,
        /// Log time, ns.
        t_ns: u64,
        /// Publish time (IMU clock), ns.
        publish_ns: u64,
        /// JSON text.
        json: String,
    },
}

/// The JSON channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum JsonChannel {
    /// `/imu/sample`.
    ImuSample,
    /// `/nav/event`.
    Event,
    /// `/nav/summary`.
    Summary,
    /// `/nav/attitude` (10 Hz).
    Attitude,
    /// `/gps/fix`.
    Gps,
    /// `/nav/solution` (1 Hz of IMU time while navigating).
    Solution,
}

impl JsonChannel {
    /// Every JSON channel (each gets its MCAP channel when the file is created).
    pub const ALL: [JsonChannel; 6] = [
        JsonChannel::ImuSample,
        JsonChannel::Event,
        JsonChannel::Summary,
        JsonChannel::Attitude,
        JsonChannel::Gps,
        JsonChannel::Solution,
    ];

    fn topic(self) -> &'static str {
        match self {
            JsonChannel::ImuSample => "/imu/sample",
            JsonChannel::Event => "/nav/event",
            JsonChannel::Summary => "/nav/summary",
            JsonChannel::Attitude => "/nav/attitude",
            JsonChannel::Gps => "/gps/fix",
            JsonChannel::Solution => "/nav/solution",
        }
    }
}

/// Recording failures.
#[derive(Debug, Error)]
pub enum RecordError {
    /// File could not be created.
    #[error("cannot create MCAP file {path}")]
    Create {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The MCAP writer failed.
    #[error("MCAP file {path}")]
    Mcap {
        /// File.
        path: PathBuf,
        /// Cause.
        source: mcap::McapError,
    },
    /// The writer thread died.
    #[error("MCAP writer thread for {0} panicked")]
    Thread(PathBuf),
}

/// Handle to the recorder thread. Records queue up on the caller's side and go to the writer
/// thread in batches ([`Recorder::ship`]): one hand-over (and at most one wake-up of the
/// writer) per batch of received frames rather than per record.
pub struct Recorder {
    tx: Option<mpsc::Sender<Vec<Record>>>,
    pending: std::sync::Mutex<Vec<Record>>,
    handle: Option<JoinHandle<Result<u64, RecordError>>>,
    path: PathBuf,
}

impl Recorder {
    /// Create the file and start the writer thread.
    pub fn start(path: &Path) -> Result<Self, RecordError> {
        let file = File::create(path).map_err(|source| RecordError::Create {
            path: path.into(),
            source,
        })?;
        let p = path.to_path_buf();
        let mcap_err = move |source| RecordError::Mcap {
            path: p.clone(),
            source,
        };
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            // zstd's fastest level, in this writer thread: no extra compression threads
            // competing with the front end for the vehicle computer's cores
            .compression_level(1)
            .compression_threads(0)
            .chunk_size(Some(256 * 1024))
            .profile("")
            .create(BufWriter::new(file))
            .map_err(mcap_err.clone())?;
        let meta = BTreeMap::new();
        let raw = w
            .add_channel(0, "/can/raw", RAW_FRAME_ENCODING, &meta)
            .map_err(mcap_err.clone())?;
        let sent = w
            .add_channel(0, "/can/tx", RAW_FRAME_ENCODING, &meta)
            .map_err(mcap_err.clone())?;
        let mut json = BTreeMap::new();
        for c in JsonChannel::ALL {
            let schema = w
                .add_schema(c.topic(), "jsonschema", br#"{"type":"object"}"#)
                .map_err(mcap_err.clone())?;
            json.insert(
                c,
                w.add_channel(schema, c.topic(), "json", &meta)
                    .map_err(mcap_err.clone())?,
            );
        }
        let (tx, rx) = mpsc::channel::<Vec<Record>>();
        let handle = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || -> Result<u64, RecordError> {
                let mut seq: BTreeMap<u16, u32> = BTreeMap::new();
                let mut n = 0u64;
                let mut buf: [u8; RAW_FRAME_BYTES];
                let mut text: String;
                let mut last_flush = Instant::now();
                loop {
                    let batch =
                        match rx.recv_timeout(FLUSH_EVERY.saturating_sub(last_flush.elapsed())) {
                            Ok(b) => b,
                            Err(mpsc::RecvTimeoutError::Timeout) => Vec::new(),
                            Err(mpsc::RecvTimeoutError::Disconnected) => break,
                        };
                    for r in batch {
                        let (ch, log, publish, data): (u16, u64, u64, &[u8]) = match &r {
                            Record::Frame { t_ns, frame } | Record::Sent { t_ns, frame } => {
                                buf = encode_frame(frame);
                                let ch = if matches!(r, Record::Sent { .. }) {
                                    sent
                                } else {
                                    raw
                                };
                                (ch, *t_ns, *t_ns, &buf)
                            }
                            Record::Sample {
                                t_ns,
                                publish_ns,
                                sample,
                            } => {
                                text = serde_json::to_string(sample).unwrap_or_default();
                                (
                                    json[&JsonChannel::ImuSample],
                                    *t_ns,
                                    *publish_ns,
                                    text.as_bytes(),
                                )
                            }
                            Record::Json {
                                channel,
                                t_ns,
                                publish_ns,
                                json: j,
                            } => (json[channel], *t_ns, *publish_ns, j.as_bytes()),
                        };
                        let s = seq.entry(ch).or_insert(0);
                        *s += 1;
                        let h = mcap::records::MessageHeader {
                            channel_id: ch,
                            sequence: *s,
                            log_time: log,
                            publish_time: publish,
                        };
                        w.write_to_known_channel(&h, data)
                            .map_err(mcap_err.clone())?;
                        n += 1;
                    }
                    // a chunk on disk at least this often: a nav killed outright loses no more
                    if last_flush.elapsed() >= FLUSH_EVERY {
                        w.flush().map_err(mcap_err.clone())?;
                        last_flush = Instant::now();
                    }
                }
                w.finish().map_err(mcap_err)?;
                Ok(n)
            })
            .map_err(|source| RecordError::Create {
                path: path.into(),
                source,
            })?;
        Ok(Self {
            tx: Some(tx),
            pending: std::sync::Mutex::new(Vec::with_capacity(SHIP_EVERY)),
            handle: Some(handle),
            path: path.into(),
        })
    }

    /// Queue a record (never blocks the caller); it goes to the writer with the next
    /// [`Recorder::ship`], or when [`SHIP_EVERY`] records are waiting.
    pub fn send(&self, r: Record) {
        let full = {
            let mut p = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            p.push(r);
            p.len() >= SHIP_EVERY
        };
        if full {
            self.ship();
        }
    }

    /// Hand the queued records to the writer thread (the caller does this once per batch of
    /// work; never blocks).
    pub fn ship(&self) {
        let batch = std::mem::take(&mut *self.pending.lock().unwrap_or_else(|e| e.into_inner()));
        if let (false, Some(tx)) = (batch.is_empty(), &self.tx) {
            let _ = tx.send(batch);
        }
    }

    /// Close the file (writes the MCAP summary and footer); returns the message count.
    pub fn finish(mut self) -> Result<u64, RecordError> {
        self.ship();
        self.tx.take();
        match self.handle.take().map(|h| h.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(RecordError::Thread(self.path.clone())),
            None => Ok(0),
        }
    }
}

/// Records queued on the caller's side before they go to the writer without waiting for
/// [`Recorder::ship`].
pub const SHIP_EVERY: usize = 1024;

/// How often the writer closes its chunk and writes it out (wall time): what a nav killed
/// outright (SIGKILL, power loss) loses from its recording.
pub const FLUSH_EVERY: std::time::Duration = std::time::Duration::from_millis(500);

/// Wall time now, ns since the epoch.
pub fn wall_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recorded_frame_reads_back_and_a_bad_one_does_not() {
        let f = RawFrame {
            id: 0x203,
            len: 6,
            data: [1, 2, 3, 4, 5, 6, 0, 0],
        };
        assert_eq!(decode_frame(&encode_frame(&f)), Some(f));
        assert_eq!(decode_frame(&encode_frame(&f)[..10]), None);
        let mut b = encode_frame(&f);
        b[2] = 9;
        assert_eq!(decode_frame(&b), None);
    }
}
