//! Replay of a nav recording through nav's pipeline in process: the frames nav received
//! (`/can/raw`), the bytes it read from the receiver (`/gps/raw`; the fixes it decoded,
//! `/gps/fix`, in a recording made before nav kept them) and its watchdog's changes
//! (`/nav/event`), in the order nav met them, go into a
//! [`Pipeline`] built from the run's config; what it sends is compared with what nav sent on the
//! bus (`/can/tx`). On a bench recording the two are identical bit for bit (the binary is a thin
//! shell around the same pipeline); on a vehicle's recording this replays a drive through a new
//! nav build.

use anyhow::{Context, Result};
use nav::config::NavConfig;
use nav::pipeline::{Output, Pipeline};
use serde::Serialize;
use std::path::Path;
use wire::RawFrame;

/// What a replay found.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct Playback {
    /// Frames fed in.
    pub frames_in: u64,
    /// Fixes fed in.
    pub fixes_in: u64,
    /// Frames nav sent in the recording.
    pub recorded_tx: u64,
    /// Frames the pipeline sent on replay.
    pub replayed_tx: u64,
    /// The first frame at which the two differ (index, recorded, replayed), if any.
    pub first_difference: Difference,
    /// Records that could not be read (counted, skipped).
    pub bad_records: u64,
    /// The pipeline's summary at the end of the replay.
    pub summary: nav::summary::Summary,
}

impl Playback {
    /// The replay sent exactly what nav sent.
    pub fn identical(&self) -> bool {
        self.first_difference.is_none() && self.recorded_tx == self.replayed_tx
    }

    /// `identical, bit for bit`, or where the two first part.
    pub fn verdict(&self) -> String {
        verdict(&self.first_difference)
    }
}

/// Where two runs' sent frames first part: (index, recorded, replayed).
pub type Difference = Option<(u64, Option<String>, Option<String>)>;

/// `identical, bit for bit`, or where the two first part.
pub fn verdict(d: &Difference) -> String {
    match d {
        None => "identical, bit for bit".to_string(),
        Some((i, a, b)) => format!(
            "DIFFERENT from frame {i}: nav sent {}, the replay {}",
            a.as_deref().unwrap_or("(none)"),
            b.as_deref().unwrap_or("(none)")
        ),
    }
}

/// The first frame at which what nav sent (`recorded`) and what a replay sent differ.
pub fn first_difference(recorded: &[RawFrame], replayed: &[RawFrame]) -> Difference {
    let n = recorded.len().max(replayed.len());
    (0..n)
        .find(|&i| recorded.get(i) != replayed.get(i))
        .map(|i| {
            (
                i as u64,
                recorded.get(i).map(show),
                replayed.get(i).map(show),
            )
        })
}

fn show(f: &RawFrame) -> String {
    format!("0x{:03X} [{}] {:02X?}", f.id, f.len, f.payload())
}

/// One thing met in a recording, in order.
#[derive(Clone)]
pub(crate) enum Input {
    /// A frame nav received.
    Frame(RawFrame),
    /// A frame nav sent.
    Sent(RawFrame),
    /// An error frame from nav's controller.
    Error(wire::errframe::ErrorFrame),
    /// A fix nav decoded.
    Fix(Box<nav::frontend::gps_receiver::GpsFix>),
    /// Bytes nav read from the receiver.
    Bytes(Vec<u8>),
    /// The watchdog's change: active, after ms.
    Timeout(bool, u64),
    /// An unreadable record.
    Bad,
}

/// The pipeline being fed, and what came out.
pub(crate) struct Replayer {
    p: Pipeline,
    out: Vec<Output>,
    /// Everything the pipeline put out, when tapped (a live view of the replay).
    pub(crate) tap: Option<Vec<Output>>,
    replayed: Vec<RawFrame>,
    recorded: Vec<RawFrame>,
    frames_in: u64,
    fixes_in: u64,
    bad: u64,
    has_bytes: bool,
}

impl Replayer {
    fn new(cfg: &NavConfig) -> Result<Self> {
        Self::with_records(cfg, false)
    }

    /// A replayer whose pipeline also makes the records nav's recorder writes (`record`).
    pub(crate) fn with_records(cfg: &NavConfig, record: bool) -> Result<Self> {
        Ok(Self {
            p: Pipeline::new(cfg, record).context("nav's pipeline")?,
            out: Vec::new(),
            tap: None,
            replayed: Vec::new(),
            recorded: Vec::new(),
            frames_in: 0,
            fixes_in: 0,
            bad: 0,
            has_bytes: false,
        })
    }

    pub(crate) fn feed(&mut self, i: Input) {
        match i {
            Input::Frame(f) => {
                self.frames_in += 1;
                self.p.on_frame(&f, &mut self.out);
            }
            Input::Sent(f) => self.recorded.push(f),
            Input::Error(e) => self.p.on_can_error(&e, &mut self.out),
            // the fixes are decoded from the bytes where the recording has them
            Input::Fix(_) if self.has_bytes => {}
            Input::Fix(fix) => {
                self.fixes_in += 1;
                self.p.on_fix(*fix, &mut self.out);
            }
            Input::Bytes(b) => {
                self.has_bytes = true;
                let before = self.p.fixes().0;
                self.p.on_gps_bytes(&b, &mut self.out);
                self.fixes_in += self.p.fixes().0 - before;
            }
            Input::Timeout(active, ms) => self.p.set_imu_timeout(active, ms, &mut self.out),
            Input::Bad => self.bad += 1,
        }
        self.take_sent();
    }

    fn take_sent(&mut self) {
        for o in self.out.drain(..) {
            if let Output::Command(f) | Output::Solution(f) = &o {
                self.replayed.push(*f);
            }
            if let Some(t) = self.tap.as_mut() {
                t.push(o);
            }
        }
    }

    pub(crate) fn finish(mut self, what: &str) -> Playback {
        self.p.flush(&mut self.out);
        self.take_sent();
        let (recorded, replayed) = (&self.recorded, &self.replayed);
        let first_difference = first_difference(recorded, replayed);
        let mut summary = self.p.summary();
        summary.interface = format!("replay of {what}");
        Playback {
            frames_in: self.frames_in,
            fixes_in: self.fixes_in,
            recorded_tx: recorded.len() as u64,
            replayed_tx: replayed.len() as u64,
            first_difference,
            bad_records: self.bad,
            summary,
        }
    }
}

/// Every message of nav's recording `path`, part after part ([`nav::record::writer::parts`]), in
/// order, to `f`. A part cut short (nav killed outright) ends the reading there, with a warning
/// naming what was being done: what came before is kept. Returns whether it was cut short.
pub fn each_message(path: &Path, doing: &str, mut f: impl FnMut(&mcap::Message)) -> Result<bool> {
    let mut parts = nav::record::writer::parts(path);
    if parts.is_empty() {
        parts.push(path.to_path_buf());
    }
    for part in &parts {
        let buf = std::fs::read(part).with_context(|| format!("reading {}", part.display()))?;
        let stream = mcap::MessageStream::new(&buf)
            .with_context(|| format!("{} is not an MCAP file", part.display()))?;
        for m in stream {
            match m {
                Ok(m) => f(&m),
                Err(e) => {
                    tracing::warn!("{}: {e}; {doing} what came before", part.display());
                    return Ok(true);
                }
            }
        }
    }
    Ok(false)
}

/// Replay the recording `mcap` through the pipeline of config `cfg`.
pub fn replay(mcap_path: &Path, cfg: &NavConfig) -> Result<Playback> {
    let what = mcap_path.display().to_string();
    replay_and(mcap_path, &what, cfg, |_| {}).map(|(p, _)| p)
}

/// Replay the recording `mcap` through the pipeline of config `cfg`, and hand each of its
/// messages to `also` as well: one reading (and decompression) of the recording for the replay
/// and whatever else reads it. Returns the playback and whether the recording was cut short.
pub fn replay_and(
    mcap_path: &Path,
    what: &str,
    cfg: &NavConfig,
    mut also: impl FnMut(&mcap::Message),
) -> Result<(Playback, bool)> {
    let mut r = Replayer::new(cfg)?;
    let cut = each_message(mcap_path, "replaying", |m| {
        if let Some(input) = input_of(m) {
            r.feed(input);
        }
        also(m);
    })?;
    if cut {
        // a recording cut short still replays what it has
        r.feed(Input::Bad);
    }
    Ok((r.finish(what), cut))
}

/// What a message of nav's recording gives its pipeline on replay (none: nothing).
pub(crate) fn input_of(m: &mcap::Message) -> Option<Input> {
    let frame = nav::record::raw::frame_of;
    Some(match m.channel.topic.as_str() {
        "/can/raw" => match (frame(m), nav::record::raw::error_frame_of(m)) {
            (Some(f), _) => Input::Frame(f),
            (None, Some(e)) => Input::Error(e),
            (None, None) => Input::Bad,
        },
        "/can/tx" => frame(m).map_or(Input::Bad, Input::Sent),
        // the liveness watchdog's changes, where they happened
        "/nav/event" => match serde_json::from_slice::<serde_json::Value>(&m.data) {
            Ok(e) => match e["kind"].as_str() {
                Some("imu_timeout") => Input::Timeout(true, e["after_ms"].as_u64().unwrap_or(0)),
                Some("imu_back") => Input::Timeout(false, 0),
                _ => return None,
            },
            Err(_) => Input::Bad,
        },
        "/gps/fix" => {
            match serde_json::from_slice::<nav::frontend::gps_receiver::GpsFix>(&m.data) {
                Ok(fix) => Input::Fix(Box::new(fix)),
                Err(_) => Input::Bad,
            }
        }
        "/gps/raw" => match nav::record::raw::serial_of(m) {
            Some(b) => Input::Bytes(b.to_vec()),
            None => Input::Bad,
        },
        _ => return None,
    })
}

/// Replay a `candump -l` log of the bus (made by can-utils' `candump`, or exported with
/// `hil candump`) through the pipeline of config `cfg`: the frames nav sends (by the DBC's
/// sender) are what nav sent, every other frame is what it received. A CAN log has no GPS fixes
/// (a drill replays bit for bit, a GPS-aided drive does not) and no watchdog events: they are
/// read from nav's NAV_TIME frames (the imu_timeout bit). Lines that
/// are not frames of our bus (extended ids, remote, FD, error frames) are counted as unreadable
/// records; a line not in the format is an error naming its number.
pub fn replay_candump(log: &Path, cfg: &NavConfig) -> Result<Playback> {
    use std::io::BufRead;
    let file = std::fs::File::open(log).with_context(|| format!("opening {}", log.display()))?;
    let nav_sends: Vec<u16> = wire::ALL_MESSAGES
        .iter()
        .filter(|m| m.sender == "NAV")
        .map(|m| m.id)
        .collect();
    let mut r = Replayer::new(cfg)?;
    let mut skipped: std::collections::BTreeMap<&str, u64> = Default::default();
    // (nav sent it, frame), in log order
    let mut frames: Vec<(bool, RawFrame)> = Vec::new();
    for (i, line) in std::io::BufReader::new(file).lines().enumerate() {
        let line = line.with_context(|| format!("reading {} line {}", log.display(), i + 1))?;
        let entry = wire::candump::parse_line(&line, i + 1)
            .with_context(|| format!("{} is not a candump -l log", log.display()))?;
        match entry {
            None => {}
            Some(wire::candump::LogEntry::Frame { frame, .. }) => {
                frames.push((nav_sends.contains(&frame.id), frame))
            }
            Some(wire::candump::LogEntry::Other { kind, .. }) => {
                *skipped.entry(kind).or_default() += 1;
                r.feed(Input::Bad);
            }
        }
    }
    // the watchdog's changes are not in a CAN log: nav's own NAV_TIME frames tell them. nav sends
    // an epoch with the imu_timeout bit when its watchdog fires (the replay's fires where that
    // epoch is in the log, after the frames nav had read), and clears the bit once data is back
    // (after the whole batch it read: the replay's clears before the frame that makes the first
    // epoch nav sent without the bit)
    let nav_time = |f: &RawFrame| match wire::Message::decode(f) {
        Ok(wire::Message::NavTime(t)) => Some(t.health.imu_timeout),
        _ => None,
    };
    let sent: Vec<RawFrame> = frames.iter().filter(|f| f.0).map(|f| f.1).collect();
    let mut timed_out = false;
    for (by_nav, f) in frames {
        if by_nav {
            if nav_time(&f) == Some(true) && !timed_out {
                timed_out = true;
                r.feed(Input::Timeout(true, 0));
            }
            r.feed(Input::Sent(f));
            continue;
        }
        if timed_out && sent.get(r.replayed.len()).and_then(nav_time) == Some(false) {
            timed_out = false;
            r.feed(Input::Timeout(false, 0));
        }
        r.feed(Input::Frame(f));
    }
    if !skipped.is_empty() {
        tracing::warn!(
            "{}: frames not of this bus, skipped: {skipped:?}",
            log.display()
        );
    }
    Ok(r.finish(&log.display().to_string()))
}

/// Write the frames of nav's recording `mcap` (received and sent, in the order nav met them)
/// to `out` as a `candump -l` log of interface `iface`, time-stamped with nav's receive and send
/// times. Returns the lines written.
pub fn export_candump(mcap_path: &Path, iface: &str, out: &mut impl std::io::Write) -> Result<u64> {
    let mut n = 0u64;
    let mut failed = None;
    each_message(mcap_path, "exporting", |m| {
        if failed.is_some() || !matches!(m.channel.topic.as_str(), "/can/raw" | "/can/tx") {
            return;
        }
        let line = match (
            nav::record::raw::frame_of(m),
            nav::record::raw::error_frame_of(m),
        ) {
            (Some(f), _) => wire::candump::format_line(m.log_time / 1000, iface, &f),
            (None, Some(e)) => wire::candump::format_error_line(m.log_time / 1000, iface, &e),
            (None, None) => return,
        };
        match writeln!(out, "{line}") {
            Ok(()) => n += 1,
            Err(e) => failed = Some(e),
        }
    })?;
    if let Some(e) = failed {
        return Err(e.into());
    }
    Ok(n)
}

/// The replay for people.
pub fn text(r: &Playback) -> String {
    let mut s = format!(
        "replayed {} frames and {} fixes ({} unreadable records)\nnav sent {} frames, the replay {}: {}\n",
        r.frames_in,
        r.fixes_in,
        r.bad_records,
        r.recorded_tx,
        r.replayed_tx,
        r.verdict()
    );
    s += &r.summary.text();
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use nav::record::writer::{Record, Recorder};

    fn frame(id: u16, b: u8) -> RawFrame {
        RawFrame {
            id,
            len: 2,
            data: [b, 0xA5, 0, 0, 0, 0, 0, 0],
        }
    }

    /// A recording's frames, received and sent, come out as `candump -l` lines in the order
    /// nav met them, stamped with nav's times to the microsecond; the log parses back to them.
    #[test]
    fn a_recording_exports_as_a_candump_log_in_the_order_nav_met_its_frames() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.mcap");
        let rec = Recorder::start(&p).unwrap();
        let frames = [
            (1_795_435_864_120_951_789, frame(0x080, 1), false),
            (1_795_435_864_121_000_000, frame(0x200, 2), true),
            (1_795_435_865_000_001_999, frame(0x081, 3), false),
        ];
        for (t_ns, frame, sent) in frames {
            rec.send(if sent {
                Record::Sent { t_ns, frame }
            } else {
                Record::Frame { t_ns, frame }
            });
        }
        rec.finish().unwrap();
        let mut out = Vec::new();
        assert_eq!(export_candump(&p, "vcan0", &mut out).unwrap(), 3);
        let text = String::from_utf8(out).unwrap();
        assert_eq!(
            text,
            "(1795435864.120951) vcan0 080#01A5\n(1795435864.121000) vcan0 200#02A5\n(1795435865.000001) vcan0 081#03A5\n"
        );
        for (i, l) in text.lines().enumerate() {
            match wire::candump::parse_line(l, i + 1) {
                Ok(Some(wire::candump::LogEntry::Frame { frame, .. })) => {
                    assert_eq!(frame, frames[i].1)
                }
                r => panic!("{r:?}"),
            }
        }
    }
}
