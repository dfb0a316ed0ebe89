//! The procedures that command the mechanism at start (north-finding, self-calibration, the
//! redundant unit's calibration): what the pipeline needs of one ([`Procedure`]), the core every
//! one of them keeps alike (`Core`: its phase and since when, its clock, its link to the
//! mechanism, why it gave up), the one loop that advances any of them on the link (`poll`),
//! and the pipeline's reporting state for one.
//!
//! A new procedure is one file: its settings, its phases (with `Phases`), its steps
//! (`OnMechanism`), and `procedure!` for the rest.

use crate::procedures::turntable_link::{LinkPoll, TtLink};
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
    /// Commands sent again for want of an acknowledgement, and acknowledgements that came too
    /// late (or matched nothing).
    fn ack_counters(&self) -> (u64, u64);
}

/// A procedure's phases: the two it ends in.
pub(crate) trait Phases: Copy + PartialEq + std::fmt::Debug {
    /// Finished with a result.
    const DONE: Self;
    /// Gave up (the reason kept).
    const ABORTED: Self;
}

/// What every procedure on the mechanism keeps alike.
#[derive(Debug)]
pub(crate) struct Core<P> {
    /// Where it is.
    pub(crate) phase: P,
    /// The IMU time it has reached, s.
    pub(crate) t: f64,
    /// The IMU time it started at, s.
    pub(crate) t_start: Option<f64>,
    /// The IMU time the phase began at, s.
    pub(crate) phase_since: f64,
    /// Its commands and the mechanism's answers.
    pub(crate) link: TtLink,
    /// Why it gave up.
    pub(crate) abort: Option<String>,
}

impl<P: Phases> Core<P> {
    /// A procedure starting in phase `first` on `link`.
    pub(crate) fn new(first: P, link: TtLink) -> Self {
        Self {
            phase: first,
            t: 0.0,
            t_start: None,
            phase_since: 0.0,
            link,
            abort: None,
        }
    }

    /// Done or given up.
    pub(crate) fn finished(&self) -> bool {
        self.phase == P::DONE || self.phase == P::ABORTED
    }

    /// Give up for `why` (the first reason stands); nothing more goes to the mechanism.
    pub(crate) fn fail(&mut self, why: String) {
        if self.abort.is_none() {
            self.abort = Some(why);
            self.phase = P::ABORTED;
            self.link.clear();
        }
    }

    /// Enter phase `p` now.
    pub(crate) fn enter(&mut self, p: P) {
        self.phase = p;
        self.phase_since = self.t;
    }

    /// The IMU time since the procedure started, s.
    pub(crate) fn elapsed(&self) -> f64 {
        self.t - self.t_start.unwrap_or(self.t)
    }
}

/// A status frame's faults by name, when it reports any (or the fault state).
pub(crate) fn faults_of(st: &TtStatus) -> Option<String> {
    if st.faults.any() {
        Some(st.faults.names())
    } else if st.state == wire::TtState::Fault {
        Some("fault state".to_string())
    } else {
        None
    }
}

/// What [`poll`] and [`ack`] need of a procedure on the mechanism.
pub(crate) trait OnMechanism {
    /// Its phases.
    type Phase: Phases;
    /// Its core.
    fn core(&mut self) -> &mut Core<Self::Phase>;
    /// Where it is, for a reason ("position 2 of 4 (90 deg)", "rotating").
    fn at(&self) -> String;
    /// Advance on the mechanism's state: nothing is in flight or queued.
    fn advance(&mut self);
    /// The link failed: give up, saying where (unless the procedure can go on without the
    /// mechanism).
    fn link_failed(&mut self, f: crate::procedures::turntable_link::LinkFailure) {
        let w = self.at();
        self.core().fail(f.describe(&w));
    }
}

/// An acknowledgement: a refusal or a mismatch gives the procedure up, saying where it was.
pub(crate) fn ack<P: OnMechanism>(p: &mut P, a: &TtAck) {
    if let Err(f) = p.core().link.on_ack(a) {
        let w = p.at();
        p.core().fail(f.describe(&w));
    }
}

/// A procedure's next command at IMU time `t`: the link's resend or failure first; with
/// nothing in flight and nothing queued, the procedure advances; then its queue or a heartbeat.
pub(crate) fn poll<P: OnMechanism>(p: &mut P, t: f64) -> Option<TtCmd> {
    if p.core().finished() {
        return None;
    }
    match p.core().link.poll(t) {
        LinkPoll::Failed(f) => {
            p.link_failed(f);
            return None;
        }
        LinkPoll::Send(c) => return Some(c),
        LinkPoll::Waiting => return None,
        LinkPoll::Idle => {}
    }
    if !p.core().link.queued() {
        p.advance();
        if p.core().finished() {
            return None;
        }
    }
    p.core().link.next(t)
}

/// [`Procedure`] for a procedure type with a `core`, `on_status`, `poll`, `stage`, `progress`
/// and `result`: `procedure!(Type, "name", |self, t, status| on_status call)`.
macro_rules! procedure {
    ($t:ty, $name:literal, |$s:ident, $time:ident, $st:ident| $on_status:expr) => {
        impl $crate::procedures::common::Procedure for $t {
            fn name(&self) -> &'static str {
                $name
            }
            fn status(&mut self, $time: f64, $st: &wire::TtStatus) {
                let $s = self;
                $on_status
            }
            fn ack(&mut self, a: &wire::TtAck) {
                $crate::procedures::common::ack(self, a)
            }
            fn next_command(&mut self, t: f64) -> Option<wire::TtCmd> {
                self.poll(t)
            }
            fn is_finished(&self) -> bool {
                self.core.finished()
            }
            fn stage_key(&self) -> u64 {
                $crate::procedures::common::key(&self.stage())
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
                self.core.abort.as_deref()
            }
            fn ack_counters(&self) -> (u64, u64) {
                self.core.link.ack_counters()
            }
        }
    };
}
pub(crate) use procedure;

/// A stage as a number (its hash; `DefaultHasher::new` hashes alike within a run, which is
/// all a comparison with the last stage needs).
pub(crate) fn key<T: std::hash::Hash>(stage: &T) -> u64 {
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
