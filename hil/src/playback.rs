//! Replay of a nav recording through nav's pipeline in process: the frames nav received
//! (`/can/raw`), the fixes it decoded (`/gps/fix`) and its watchdog's changes (`/nav/event`),
//! in the order nav met them, go into a
//! [`Pipeline`] built from the run's config; what it sends is compared with what nav sent on the
//! bus (`/can/tx`). On a bench recording the two are identical bit for bit (the binary is a thin
//! shell around the same pipeline); on a vehicle's recording this replays a drive through a new
//! nav build.

use anyhow::{Context, Result};
use nav::config::NavConfig;
use nav::pipeline::{Output, Pipeline};
use nav::record::RAW_FRAME_ENCODING;
use serde::Serialize;
use std::path::Path;
use wire::RawFrame;

/// What a replay found.
#[derive(Debug, Clone, Serialize)]
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
    pub first_difference: Option<(u64, Option<String>, Option<String>)>,
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
        match &self.first_difference {
            None => "identical, bit for bit".to_string(),
            Some((i, a, b)) => format!(
                "DIFFERENT from frame {i}: nav sent {}, the replay {}",
                a.as_deref().unwrap_or("(none)"),
                b.as_deref().unwrap_or("(none)")
            ),
        }
    }
}

fn show(f: &RawFrame) -> String {
    format!("0x{:03X} [{}] {:02X?}", f.id, f.len, f.payload())
}

/// Replay the recording `mcap` through the pipeline of config `cfg`.
pub fn replay(mcap_path: &Path, cfg: &NavConfig) -> Result<Playback> {
    let buf =
        std::fs::read(mcap_path).with_context(|| format!("reading {}", mcap_path.display()))?;
    let mut p = Pipeline::new(cfg, false).context("nav's pipeline")?;
    let mut out = Vec::new();
    let mut replayed: Vec<RawFrame> = Vec::new();
    let mut recorded: Vec<RawFrame> = Vec::new();
    let (mut frames_in, mut fixes_in, mut bad) = (0u64, 0u64, 0u64);
    let stream = mcap::MessageStream::new(&buf)
        .with_context(|| format!("{} is not an MCAP file", mcap_path.display()))?;
    for m in stream {
        let m = match m {
            Ok(m) => m,
            Err(e) => {
                // a recording cut short still replays what it has
                tracing::warn!("{}: {e}; replaying what came before", mcap_path.display());
                bad += 1;
                break;
            }
        };
        match m.channel.topic.as_str() {
            "/can/raw" | "/can/tx" if m.channel.message_encoding != RAW_FRAME_ENCODING => bad += 1,
            "/can/raw" => match nav::record::decode_frame(&m.data) {
                Some(f) => {
                    frames_in += 1;
                    p.on_frame(&f, &mut out);
                }
                None => bad += 1,
            },
            "/can/tx" => match nav::record::decode_frame(&m.data) {
                Some(f) => recorded.push(f),
                None => bad += 1,
            },
            // the liveness watchdog's changes, where they happened
            "/nav/event" => match serde_json::from_slice::<serde_json::Value>(&m.data) {
                Ok(e) => match e["kind"].as_str() {
                    Some("imu_timeout") => {
                        let ms = e["after_ms"].as_u64().unwrap_or(0);
                        p.set_imu_timeout(true, ms, &mut out);
                    }
                    Some("imu_back") => p.set_imu_timeout(false, 0, &mut out),
                    _ => {}
                },
                Err(_) => bad += 1,
            },
            "/gps/fix" => match serde_json::from_slice::<nav::gps::GpsFix>(&m.data) {
                Ok(fix) => {
                    fixes_in += 1;
                    p.on_fix(fix, &mut out);
                }
                Err(_) => bad += 1,
            },
            _ => {}
        }
        replayed.extend(out.drain(..).filter_map(|o| match o {
            Output::Command(f) | Output::Solution(f) => Some(f),
            _ => None,
        }));
    }
    p.flush(&mut out);
    replayed.extend(out.drain(..).filter_map(|o| match o {
        Output::Command(f) | Output::Solution(f) => Some(f),
        _ => None,
    }));
    let n = recorded.len().max(replayed.len());
    let first_difference = (0..n)
        .find(|&i| recorded.get(i) != replayed.get(i))
        .map(|i| {
            (
                i as u64,
                recorded.get(i).map(show),
                replayed.get(i).map(show),
            )
        });
    let mut summary = p.summary();
    summary.interface = format!("replay of {}", mcap_path.display());
    Ok(Playback {
        frames_in,
        fixes_in,
        recorded_tx: recorded.len() as u64,
        replayed_tx: replayed.len() as u64,
        first_difference,
        bad_records: bad,
        summary,
    })
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
