//! What the pipeline needs of a start-up procedure that commands the mechanism (north-finding,
//! self-calibration, the redundant unit's calibration), and the one place that drives any of
//! them: its commands out, its frames in, its progress and result lines.

use crate::northfind::NorthFinder;
use crate::selfcal::SelfCalibrator;
use crate::tetracal::TetraCalibrator;
use wire::{TtAck, TtCmd, TtStatus};

/// A procedure on the mechanism.
pub trait Procedure {
    /// Its name in nav's lines (`nav: <name> progress {...}`) and events.
    fn name(&self) -> &'static str;
    /// A status frame, at IMU time `t` (the end of the last sample nav has).
    fn status(&mut self, t: f64, st: &TtStatus);
    /// An acknowledgement.
    fn ack(&mut self, a: &TtAck);
    /// The next command at IMU time `t`.
    fn next_command(&mut self, t: f64) -> Option<TtCmd>;
    /// Done or given up.
    fn is_finished(&self) -> bool;
    /// The stage, compared for changes (a progress line at each): asked on every frame, so a
    /// number, not text.
    fn stage_key(&self) -> u64;
    /// The stage, for people.
    fn stage_name(&self) -> String;
    /// Progress as JSON.
    fn progress_json(&self) -> Option<String>;
    /// The result as JSON, once done.
    fn result_json(&self) -> Option<String>;
    /// Why it gave up.
    fn abort(&self) -> Option<&str>;
}

macro_rules! procedure {
    ($t:ty, $name:literal, |$s:ident, $time:ident, $st:ident| $on_status:expr) => {
        impl Procedure for $t {
            fn name(&self) -> &'static str {
                $name
            }
            fn status(&mut self, $time: f64, $st: &TtStatus) {
                let $s = self;
                $on_status
            }
            fn ack(&mut self, a: &TtAck) {
                self.on_ack(a)
            }
            fn next_command(&mut self, t: f64) -> Option<TtCmd> {
                self.poll(t)
            }
            fn is_finished(&self) -> bool {
                self.finished()
            }
            fn stage_key(&self) -> u64 {
                key(&self.stage())
            }
            fn stage_name(&self) -> String {
                format!("{:?}", self.stage())
            }
            fn progress_json(&self) -> Option<String> {
                serde_json::to_string(&self.progress()).ok()
            }
            fn result_json(&self) -> Option<String> {
                serde_json::to_string(self.result()?).ok()
            }
            fn abort(&self) -> Option<&str> {
                self.abort_reason()
            }
        }
    };
}

// north-finding stamps status frames with its own update time
procedure!(NorthFinder, "north-finding", |s, _t, st| s.on_status(st));
procedure!(SelfCalibrator, "self-calibration", |s, t, st| s
    .on_status(t, st));
procedure!(TetraCalibrator, "tetra-calibration", |s, t, st| s
    .on_status(t, st));

/// A stage as a number (its hash; `DefaultHasher::new` hashes alike within a run, which is
/// all a comparison with the last stage needs).
fn key<T: std::hash::Hash>(stage: &T) -> u64 {
    use std::hash::Hasher;
    let mut h = std::hash::DefaultHasher::new();
    stage.hash(&mut h);
    h.finish()
}

/// A procedure's reporting state in the pipeline.
#[derive(Debug, Clone, Default)]
pub struct Reporting {
    /// Commands sent.
    pub commands_sent: u64,
    /// Mechanism frames received (status, acks).
    pub frames: u64,
    /// IMU time of the last progress line.
    pub last_print: Option<f64>,
    /// The stage of the last progress line.
    pub last_stage: Option<u64>,
    /// The result (or the reason it gave up) was said.
    pub reported: bool,
}
