//! Replaying a recording: nav's own recording (`nav.mcap`: every frame it received, every fix,
//! its watchdog's changes) onto a real bus and pty for a nav to run on again ([`on_bus`]), or
//! to the live view's clients as the run went ([`live_view`]). The recording is read by
//! `engine::recording`, which also replays it through nav's pipeline in process for every run's
//! check; `hil replay` (cmd/replay.rs) is the command.

pub mod live_view;
pub mod on_bus;
