//! MCAP recording on its own thread, so the receive path never waits for the disk.
//!
//! Channels:
//! - `/can/raw` (CDR, schema `rlg_hil/msg/CanFrame`, [`crate::record::raw`]): every received frame;
//!   stamp and log time = the kernel's receive time of the frame (`SO_TIMESTAMPNS`, what
//!   `candump` stamps), or nav's read time where the socket gives none.
//! - `/can/tx` (the same): every frame nav sent (turntable commands, the solution).
//! - `/gps/raw` (CDR, schema `rlg_hil/msg/SerialBytes`): the bytes nav read from its GPS source, as
//!   read (NMEA-0183 text, any garbage included; gpsd's JSON replies taken out), one message per
//!   read; log time = read wall time. In the order nav's loop took them among the frames: what
//!   `hil replay --bus` writes back onto a port.
//! - `/imu/sample` (JSON): every decoded IMU sample; publish time = sample time on the IMU clock.
//! - `/nav/event` (JSON): irregularities (gaps, duplicates, bad frames, timeouts).
//! - `/nav/summary` (JSON): the run summary, once at the end.
//! - `/nav/attitude`, `/gps/fix`, `/nav/solution` (JSON): see [`JsonChannel`].
//! - `/nav/location`, `/gps/location`, `/nav/pose`, `/nav/log`: Foxglove's well-known schemas,
//!   derived from the records above on the writer thread ([`crate::record::foxglove`]).
//!
//! Every JSON channel carries its JSON schema (`nav/schemas/*.json`, encoding `jsonschema`), so
//! viewers such as Foxglove know its fields and a reader can validate every message.

use crate::record::raw;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Instant;
use thiserror::Error;
use wire::RawFrame;

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
    /// An error frame from nav's CAN controller: `/can/raw`, its identifier with
    /// `CAN_ERR_FLAG` as SocketCAN carries it.
    ErrorFrame {
        /// Receive wall time, ns since the epoch.
        t_ns: u64,
        /// The frame.
        frame: wire::errframe::ErrorFrame,
    },
    /// A frame nav sent (turntable commands, the solution): `/can/tx`.
    Sent {
        /// Send wall time, ns since the epoch.
        t_ns: u64,
        /// The frame.
        frame: RawFrame,
    },
    /// Bytes read from the GPS source: `/gps/raw`.
    GpsBytes {
        /// Read wall time, ns since the epoch.
        t_ns: u64,
        /// The bytes.
        bytes: Vec<u8>,
    },
    /// A decoded IMU sample, serialized to JSON on the writer thread (off the receive path).
    Sample {
        /// Log time, ns.
        t_ns: u64,
        /// Publish time (IMU clock), ns.
        publish_ns: u64,
        /// The sample.
        sample: crate::frontend::imu_frames::ImuSample,
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

pub use crate::record::channels::JsonChannel;

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
/// thread in batches ([`Recorder::ship_due`], [`Recorder::ship`]): one hand-over (and at most
/// one wake-up of the writer) every [`SHIP_AFTER`] rather than per record or per batch of
/// received frames (a bench free-running at x1 hands nav a batch every millisecond).
pub struct Recorder {
    tx: Option<mpsc::Sender<Vec<Record>>>,
    pending: std::sync::Mutex<Pending>,
    handle: Option<JoinHandle<Result<u64, RecordError>>>,
    path: PathBuf,
}

impl Recorder {
    /// Create the file and start the writer thread.
    pub fn start(path: &Path) -> Result<Self, RecordError> {
        Self::start_rotating(path, ROTATE_CHUNKS)
    }

    /// The same, going on in a new part ([`part_path`]) once a part holds about
    /// `rotate_chunks` chunks: the writer keeps an index entry per chunk in memory until its
    /// file is finished, so a long recording in one file would grow nav's memory without end.
    pub fn start_rotating(path: &Path, rotate_chunks: u64) -> Result<Self, RecordError> {
        let (mut w, mut ch) = open_part(path)?;
        let p = path.to_path_buf();
        let mcap_err = move |source| RecordError::Mcap {
            path: p.clone(),
            source,
        };
        let base = path.to_path_buf();
        let (tx, rx) = mpsc::channel::<Vec<Record>>();
        let handle = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || -> Result<u64, RecordError> {
                let mut seq: BTreeMap<u16, u32> = BTreeMap::new();
                let mut n = 0u64;
                let mut scratch = Scratch::default();
                let mut last_flush = Instant::now();
                let mut views = crate::record::foxglove::Views::default();
                let (mut chunks, mut chunk_bytes, mut part) = (0u64, 0u64, 0u32);
                let mut derived = Vec::new();
                loop {
                    let batch =
                        match rx.recv_timeout(FLUSH_EVERY.saturating_sub(last_flush.elapsed())) {
                            Ok(b) => b,
                            Err(mpsc::RecvTimeoutError::Timeout) => Vec::new(),
                            Err(mpsc::RecvTimeoutError::Disconnected) => break,
                        };
                    for r in batch {
                        let (c, log, publish, data) = scratch.encode(&r, &ch);
                        let mut put = |id: u16, data: &[u8]| {
                            let s = seq.entry(id).or_insert(0);
                            *s += 1;
                            let h = mcap::records::MessageHeader {
                                channel_id: id,
                                sequence: *s,
                                log_time: log,
                                publish_time: publish,
                            };
                            n += 1;
                            // a chunk closes when its uncompressed size reaches CHUNK_BYTES
                            chunk_bytes += data.len() as u64 + 31;
                            if chunk_bytes >= CHUNK_BYTES {
                                chunks += 1;
                                chunk_bytes = 0;
                            }
                            w.write_to_known_channel(&h, data)
                        };
                        put(c, data).map_err(mcap_err.clone())?;
                        // the Foxglove views of this record, beside it
                        if let Record::Json {
                            channel, json: j, ..
                        } = &r
                        {
                            views.derive(*channel, publish, j, &mut derived);
                            for (c, m) in derived.drain(..) {
                                put(ch.json[&c], m.as_bytes()).map_err(mcap_err.clone())?;
                            }
                        }
                    }
                    // a chunk on disk at least this often: a nav killed outright loses no more
                    if last_flush.elapsed() >= FLUSH_EVERY {
                        w.flush().map_err(mcap_err.clone())?;
                        last_flush = Instant::now();
                        chunks += 1;
                        chunk_bytes = 0;
                        // the part is full: finish it (its summary and footer) and go on in
                        // the next, whose index starts empty
                        if chunks >= rotate_chunks {
                            w.finish().map_err(mcap_err.clone())?;
                            part += 1;
                            let next = part_path(&base, part);
                            (w, ch) = open_part(&next)?;
                            tracing::info!("recording goes on in {}", next.display());
                            chunks = 0;
                        }
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
            pending: std::sync::Mutex::new(Pending {
                records: Vec::with_capacity(SHIP_EVERY),
                since: None,
            }),
            handle: Some(handle),
            path: path.into(),
        })
    }

    /// Queue a record (never blocks the caller); it goes to the writer with the next
    /// [`Recorder::ship`] or [`Recorder::ship_due`], or when [`SHIP_EVERY`] records are waiting.
    pub fn send(&self, r: Record) {
        let full = {
            let mut p = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            p.since.get_or_insert_with(Instant::now);
            p.records.push(r);
            p.records.len() >= SHIP_EVERY
        };
        if full {
            self.ship();
        }
    }

    /// Hand the queued records to the writer thread once the oldest has waited [`SHIP_AFTER`]
    /// (the caller does this once per batch of work, and on a timer when work may stop; never
    /// blocks).
    pub fn ship_due(&self) {
        let due = {
            let p = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            p.since.is_some_and(|t| t.elapsed() >= SHIP_AFTER)
        };
        if due {
            self.ship();
        }
    }

    /// Hand the queued records to the writer thread now (never blocks).
    pub fn ship(&self) {
        let batch = {
            let mut p = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            p.since = None;
            std::mem::take(&mut p.records)
        };
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

/// Records queued on the caller's side, and since when the oldest has waited.
struct Pending {
    records: Vec<Record>,
    since: Option<Instant>,
}

/// The channel ids of one part of a recording.
struct Channels {
    raw: u16,
    sent: u16,
    gps: u16,
    json: BTreeMap<JsonChannel, u16>,
}

/// The writer's buffers for one record's bytes, reused from record to record.
struct Scratch {
    frame: [u8; raw::CAN_FRAME_BYTES],
    serial: Vec<u8>,
    text: String,
}

impl Default for Scratch {
    fn default() -> Self {
        Self {
            frame: [0; raw::CAN_FRAME_BYTES],
            serial: Vec::new(),
            text: String::new(),
        }
    }
}

impl Scratch {
    /// Record `r` as its channel, log time, publish time and bytes.
    fn encode<'a>(&'a mut self, r: &'a Record, ch: &Channels) -> (u16, u64, u64, &'a [u8]) {
        match r {
            Record::Frame { t_ns, frame } | Record::Sent { t_ns, frame } => {
                self.frame = raw::encode_frame(frame, *t_ns);
                let c = if matches!(r, Record::Sent { .. }) {
                    ch.sent
                } else {
                    ch.raw
                };
                (c, *t_ns, *t_ns, &self.frame)
            }
            Record::ErrorFrame { t_ns, frame } => {
                self.frame = raw::encode_error_frame(frame, *t_ns);
                (ch.raw, *t_ns, *t_ns, &self.frame)
            }
            Record::GpsBytes { t_ns, bytes } => {
                raw::encode_serial(*t_ns, bytes, &mut self.serial);
                (ch.gps, *t_ns, *t_ns, &self.serial)
            }
            Record::Sample {
                t_ns,
                publish_ns,
                sample,
            } => {
                self.text = serde_json::to_string(sample).unwrap_or_default();
                (
                    ch.json[&JsonChannel::ImuSample],
                    *t_ns,
                    *publish_ns,
                    self.text.as_bytes(),
                )
            }
            Record::Json {
                channel,
                t_ns,
                publish_ns,
                json: j,
            } => (ch.json[channel], *t_ns, *publish_ns, j.as_bytes()),
        }
    }
}

type Writer = mcap::Writer<BufWriter<File>>;

/// Create one part of a recording with its schemas and channels (the same ids in every part).
fn open_part(path: &Path) -> Result<(Writer, Channels), RecordError> {
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
        .chunk_size(Some(CHUNK_BYTES))
        .profile("")
        .create(BufWriter::new(file))
        .map_err(mcap_err.clone())?;
    let meta = BTreeMap::new();
    let (name, text) = raw::CAN_FRAME_SCHEMA;
    let frames = w
        .add_schema(name, raw::ROS2MSG, text.as_bytes())
        .map_err(mcap_err.clone())?;
    let (name, text) = raw::SERIAL_BYTES_SCHEMA;
    let serial = w
        .add_schema(name, raw::ROS2MSG, text.as_bytes())
        .map_err(mcap_err.clone())?;
    let raw = w
        .add_channel(frames, "/can/raw", raw::CDR, &meta)
        .map_err(mcap_err.clone())?;
    let sent = w
        .add_channel(frames, "/can/tx", raw::CDR, &meta)
        .map_err(mcap_err.clone())?;
    let gps = w
        .add_channel(serial, "/gps/raw", raw::CDR, &meta)
        .map_err(mcap_err.clone())?;
    let mut json = BTreeMap::new();
    let mut schemas = BTreeMap::new();
    for c in JsonChannel::ALL {
        let (name, text) = c.schema();
        let schema = match schemas.get(name) {
            Some(id) => *id,
            None => {
                let id = w
                    .add_schema(name, "jsonschema", text.as_bytes())
                    .map_err(mcap_err.clone())?;
                schemas.insert(name, id);
                id
            }
        };
        json.insert(
            c,
            w.add_channel(schema, c.topic(), "json", &meta)
                .map_err(mcap_err.clone())?,
        );
    }
    Ok((
        w,
        Channels {
            raw,
            sent,
            gps,
            json,
        },
    ))
}

/// Part `k` of the recording `path`: `path` itself for part 0, then `nav.1.mcap`,
/// `nav.2.mcap`, ... beside it.
pub fn part_path(path: &Path, k: u32) -> PathBuf {
    if k == 0 {
        return path.to_path_buf();
    }
    let stem = path
        .file_stem()
        .map_or("recording".into(), |s| s.to_string_lossy());
    let ext = path
        .extension()
        .map_or("mcap".into(), |s| s.to_string_lossy());
    path.with_file_name(format!("{stem}.{k}.{ext}"))
}

/// Every part of the recording `path` that exists, in order (a reader takes them one after
/// the other).
pub fn parts(path: &Path) -> Vec<PathBuf> {
    (0..)
        .map(|k| part_path(path, k))
        .take_while(|p| p.is_file())
        .collect()
}

/// Uncompressed bytes at which the writer closes a chunk.
pub const CHUNK_BYTES: u64 = 256 * 1024;

/// Chunks per part of a recording before it goes on in the next ([`Recorder::start_rotating`]):
/// about 3 MB of the writer's chunk index; at 4,000 frames/s in real time a part holds about
/// 25 minutes.
pub const ROTATE_CHUNKS: u64 = 4096;

/// Records queued on the caller's side before they go to the writer without waiting for
/// [`Recorder::ship`].
pub const SHIP_EVERY: usize = 1024;

/// How long a record may wait on the caller's side before [`Recorder::ship_due`] hands it to
/// the writer: in a software-emulated guest each wake-up of the writer costs tens of
/// microseconds, and one per millisecond took a quarter of a free-running drill's CPU. What a
/// nav killed outright loses grows by at most this much (nav's loop ships on its 100 ms tick
/// too, when no frame comes).
pub const SHIP_AFTER: std::time::Duration = std::time::Duration::from_millis(50);

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

    /// `v` has the schema's type, required keys and no keys it does not list (when it says
    /// `additionalProperties: false`), recursively: the part of JSON Schema our schemas use.
    /// (`./run-tests` validates real recordings with Python's `jsonschema` as well.)
    fn conforms(schema: &serde_json::Value, v: &serde_json::Value, at: &str) {
        use serde_json::Value;
        let types: Vec<&str> = match &schema["type"] {
            Value::String(t) => vec![t.as_str()],
            Value::Array(a) => a.iter().filter_map(|t| t.as_str()).collect(),
            _ => vec![],
        };
        let kind = match v {
            Value::Null => "null",
            Value::Bool(_) => "boolean",
            Value::Number(n) if n.is_u64() || n.is_i64() => "integer",
            Value::Number(_) => "number",
            Value::String(_) => "string",
            Value::Array(_) => "array",
            Value::Object(_) => "object",
        };
        assert!(
            types.is_empty()
                || types.contains(&kind)
                || (kind == "integer" && types.contains(&"number")),
            "{at}: {kind} where the schema says {types:?}"
        );
        if let Value::Object(o) = v {
            for r in schema["required"].as_array().into_iter().flatten() {
                let r = r.as_str().unwrap();
                assert!(o.contains_key(r), "{at}: required {r} missing");
            }
            for (k, x) in o {
                match schema["properties"].get(k) {
                    Some(p) => conforms(p, x, &format!("{at}.{k}")),
                    None => assert!(
                        schema["additionalProperties"] != false,
                        "{at}: {k} is not in the schema"
                    ),
                }
            }
        }
        if let (Value::Array(a), Some(items)) = (v, schema.get("items")) {
            for (i, x) in a.iter().enumerate() {
                conforms(items, x, &format!("{at}[{i}]"));
            }
        }
    }

    /// Channel `c`'s schema, parsed: an object, titled by its topic or its name.
    fn parsed(c: JsonChannel) -> serde_json::Value {
        let (name, text) = c.schema();
        let s: serde_json::Value =
            serde_json::from_str(text).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(s["type"], "object", "{name}");
        assert!(
            s["title"]
                .as_str()
                .is_some_and(|t| t.starts_with(c.topic()) || t == name),
            "{name}"
        );
        s
    }

    /// A receiver's fix as nav records it.
    fn a_fix() -> crate::frontend::gps_receiver::GpsFix {
        crate::frontend::gps_receiver::GpsFix {
            sentence: "GGA".into(),
            date: None,
            time: Some("12:00:01.000".into()),
            time_of_day_s: Some(43201.0),
            lat_deg: -33.9,
            lon_deg: 18.4,
            alt_m: Some(12.0),
            geoid_sep_m: Some(32.5),
            quality: 1,
            satellites: Some(9),
            hdop: Some(0.9),
            speed_mps: None,
            track_deg: None,
            valid: true,
            time_backwards: false,
            seq: 3,
        }
    }

    /// A solution as nav records it, without its position covariance.
    fn a_solution() -> serde_json::Value {
        let o = crate::navigation::strapdown::NavOutput {
            lat_deg: 28.2,
            lon_deg: 112.9,
            h_m: 0.0,
            vel_enu_mps: [1.0, 2.0, 0.0],
            hpr_deg: [359.0, 0.1, -0.2],
        };
        serde_json::json!({"t_s": 1.0, "mode": "GpsAided", "output": o, "pos_sigma_m": 3.2, "heading_sigma_deg": 0.1})
    }

    #[test]
    fn every_json_channel_has_a_schema_its_messages_follow() {
        for c in JsonChannel::ALL {
            parsed(c);
        }
        let mut sample = crate::frontend::imu_frames::ImuSample {
            sample: 7,
            span: 1,
            dtheta: [1e-6, -2e-6, 3e-6],
            dv: [1e-4, 0.0, 4.9e-3],
            pps_offset: None,
            accel_missing: false,
            ambiguous: false,
            bit_fail: false,
            saturated: false,
        };
        let s = parsed(JsonChannel::ImuSample);
        conforms(&s, &serde_json::to_value(sample).unwrap(), "sample");
        sample.pps_offset = Some(0.25);
        sample.bit_fail = true;
        sample.saturated = true;
        sample.accel_missing = true;
        sample.ambiguous = true;
        conforms(&s, &serde_json::to_value(sample).unwrap(), "flagged sample");
        conforms(
            &parsed(JsonChannel::Gps),
            &serde_json::to_value(a_fix()).unwrap(),
            "fix",
        );
        let mut sol = a_solution();
        conforms(&parsed(JsonChannel::Solution), &sol, "solution");
        sol["pos_cov_enu_m2"] = serde_json::json!([4.0, 0.1, 0.0, 0.1, 5.0, 0.0, 0.0, 0.0, 9.0]);
        conforms(
            &parsed(JsonChannel::Solution),
            &sol,
            "solution with covariance",
        );
    }

    #[test]
    fn the_foxglove_views_follow_foxgloves_schemas() {
        let mut sol = a_solution();
        sol["pos_cov_enu_m2"] = serde_json::json!([4.0, 0.1, 0.0, 0.1, 5.0, 0.0, 0.0, 0.0, 9.0]);
        let mut views = crate::record::foxglove::Views::default();
        let mut derived = Vec::new();
        views.derive(JsonChannel::Solution, 7, &sol.to_string(), &mut derived);
        let fix_json = serde_json::to_string(&a_fix()).unwrap();
        views.derive(JsonChannel::Gps, 7, &fix_json, &mut derived);
        let event = "{\"kind\":\"imu_timeout\",\"after_ms\":100}";
        views.derive(JsonChannel::Event, 7, event, &mut derived);
        let kinds: Vec<JsonChannel> = derived.iter().map(|d| d.0).collect();
        assert_eq!(
            kinds,
            [
                JsonChannel::Location,
                JsonChannel::Pose,
                JsonChannel::GpsLocation,
                JsonChannel::Log
            ]
        );
        for (c, m) in &derived {
            let v: serde_json::Value = serde_json::from_str(m).unwrap();
            conforms(&parsed(*c), &v, c.topic());
        }
    }

    #[test]
    fn a_schema_catches_a_message_not_of_its_kind() {
        let caught = std::panic::catch_unwind(|| {
            conforms(
                &parsed(JsonChannel::Solution),
                &serde_json::json!({"t_s": 1.0}),
                "bad",
            )
        });
        assert!(caught.is_err());
    }

    /// A long recording goes on in new parts, each a whole MCAP file with its summary, and
    /// nothing is lost at the seams: the writer's in-memory index stays bounded.
    #[test]
    fn a_long_recording_rotates_into_whole_parts_and_loses_nothing() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("nav.mcap");
        let r = Recorder::start_rotating(&path, 2).unwrap();
        let mut k = 0u32;
        for _ in 0..3 {
            for _ in 0..10_000 {
                k += 1;
                r.send(Record::Frame {
                    t_ns: u64::from(k),
                    frame: RawFrame {
                        id: 0x100,
                        len: 4,
                        data: [k as u8, (k >> 8) as u8, 0, 0, 0, 0, 0, 0],
                    },
                });
            }
            r.ship();
            std::thread::sleep(FLUSH_EVERY + std::time::Duration::from_millis(150));
        }
        assert_eq!(r.finish().unwrap(), 30_000);
        let ps = parts(&path);
        assert!(ps.len() >= 2, "{ps:?}");
        assert_eq!(ps[1], d.path().join("nav.1.mcap"));
        let mut times = Vec::new();
        for p in &ps {
            let buf = std::fs::read(p).unwrap();
            let summary = mcap::Summary::read(&buf)
                .unwrap()
                .expect("a summary in every part");
            assert!(!summary.chunk_indexes.is_empty());
            for m in mcap::MessageStream::new(&buf).unwrap() {
                times.push(m.unwrap().log_time);
            }
        }
        assert_eq!(times, (1..=30_000).collect::<Vec<u64>>());
    }

    /// The raw channels carry their `ros2msg` schemas and CDR messages whose stamps are their
    /// log times; what went in reads back.
    #[test]
    fn raw_traffic_is_recorded_under_its_ros2msg_schemas() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("nav.mcap");
        let r = Recorder::start(&path).unwrap();
        let f = RawFrame {
            id: 0x081,
            len: 8,
            data: [1, 2, 3, 4, 5, 6, 7, 8],
        };
        r.send(Record::Frame {
            t_ns: 1_700_000_000_000_000_001,
            frame: f,
        });
        r.send(Record::Sent {
            t_ns: 1_700_000_000_000_000_002,
            frame: f,
        });
        r.send(Record::GpsBytes {
            t_ns: 1_700_000_000_000_000_003,
            bytes: b"$GPGGA,,*56\r\n".to_vec(),
        });
        r.finish().unwrap();
        let buf = std::fs::read(&path).unwrap();
        let mut seen = Vec::new();
        for m in mcap::MessageStream::new(&buf).unwrap() {
            let m = m.unwrap();
            let s = m.channel.schema.as_ref().expect("a schema");
            assert_eq!(
                (s.encoding.as_str(), m.channel.message_encoding.as_str()),
                ("ros2msg", "cdr")
            );
            let sec = i32::from_le_bytes(m.data[4..8].try_into().unwrap()) as u64;
            let nsec = u32::from_le_bytes(m.data[8..12].try_into().unwrap()) as u64;
            assert_eq!(
                sec * 1_000_000_000 + nsec,
                m.log_time,
                "{}",
                m.channel.topic
            );
            match m.channel.topic.as_str() {
                "/can/raw" | "/can/tx" => {
                    assert_eq!(s.name, "rlg_hil/msg/CanFrame");
                    assert_eq!(raw::frame_of(&m), Some(f));
                }
                "/gps/raw" => {
                    assert_eq!(s.name, "rlg_hil/msg/SerialBytes");
                    assert_eq!(raw::serial_of(&m), Some(&b"$GPGGA,,*56\r\n"[..]));
                }
                t => panic!("{t}"),
            }
            seen.push(m.channel.topic.clone());
        }
        assert_eq!(seen, ["/can/raw", "/can/tx", "/gps/raw"]);
    }
}
