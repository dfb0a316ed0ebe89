//! The live view: a run watched as it happens, in Foxglove (or Lichtblick, or any client of
//! Foxglove's WebSocket protocol), on simulated time.
//!
//! `--live [ADDR]` on `hil run`, `hil drill`, `hil calibrate` and `hil demo` starts a
//! [`server`] for the command's whole length. A bench run publishes what the bench sees, never
//! anything that could change the run:
//! - the bus model's frames, watched after each sample on the scheduler's thread (a few
//!   decoded fields go into a bounded queue; the JSON and the sockets are another thread's):
//!   nav's NAV_* frames as its solution (`/nav/location` with the covariance its sigmas promise,
//!   `/nav/pose`, `/tf` between nav's body and the truth's, `/nav/status`), the turntable's
//!   status and nav's commands (`/turntable/status`, `/turntable/command`, `/turntable/dwell`),
//!   the IMU's rates from its pulse counts (`/imu/rates`);
//! - the truth, from the scenario's models (`/truth/state`, `/truth/location`,
//!   `/truth/turntable`), and the injected faults (`/bench/faults`): the same messages, made by
//!   the same code, as `truth.mcap`;
//! - nav's own lines (`/nav/log`) and the bench's (`/hil/log`), and at the end the report
//!   (`/hil/result`) and its result card.
//!
//! Channel names and schemas are those of the recordings wherever the recordings have the
//! channel, so one layout (`docs/foxglove-layout.json`) serves both. Times are simulated time,
//! as in the recordings; the server sends it as the Time capability's time.
//!
//! A viewer's pause holds the scheduler ([`emulators::adapters::scheduler::Hold`]): nav confirms every sample
//! sent, then is stopped (SIGSTOP) until the viewer plays again; the stream's next frames are
//! written before nav goes on (SIGCONT). nav's result does not change (the e2e live test
//! pauses a drill and checks it against the in-process reference).

pub mod bench_run;
pub mod server;

use anyhow::Result;
use server::{ChannelSpec, Control, Playback, Server, ServerStats};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

/// The default address of the live view.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";

use nav::record::channels::JsonChannel;
const FOXGLOVE_LOCATION: &str = JsonChannel::Location.schema().1;
const FOXGLOVE_LOG: &str = JsonChannel::Log.schema().1;
const FOXGLOVE_POSE: &str = JsonChannel::Pose.schema().1;
const FOXGLOVE_TF: &str = include_str!("../../../nav/schemas/foxglove/FrameTransforms.json");

/// The channels of the live view, in the order of [`CHANNELS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub enum Ch {
    /// `/truth/state`.
    TruthState,
    /// `/truth/location`.
    TruthLocation,
    /// `/truth/turntable`.
    TruthTurntable,
    /// `/bench/faults`.
    BenchFaults,
    /// `/nav/location`.
    NavLocation,
    /// `/nav/pose`.
    NavPose,
    /// `/tf`.
    Tf,
    /// `/nav/status`.
    NavStatus,
    /// `/turntable/status`.
    TurntableStatus,
    /// `/turntable/command`.
    TurntableCommand,
    /// `/turntable/dwell`.
    TurntableDwell,
    /// `/imu/rates`.
    ImuRates,
    /// `/nav/log`.
    NavLog,
    /// `/nav/event`.
    NavEvent,
    /// `/hil/log`.
    HilLog,
    /// `/hil/result`.
    HilResult,
}

/// Every channel of the live view: topic, schema name, schema.
pub const CHANNELS: &[ChannelSpec] = &[
    ChannelSpec {
        topic: "/truth/state",
        schema_name: "rlg-hil/bench/truth-state",
        schema: crate::engine::truthrec::STATE_SCHEMA,
    },
    ChannelSpec {
        topic: "/truth/location",
        schema_name: "foxglove.LocationFix",
        schema: FOXGLOVE_LOCATION,
    },
    ChannelSpec {
        topic: "/truth/turntable",
        schema_name: "rlg-hil/bench/turntable-truth",
        schema: crate::engine::truthrec::TURNTABLE_SCHEMA,
    },
    ChannelSpec {
        topic: "/bench/faults",
        schema_name: "foxglove.Log",
        schema: FOXGLOVE_LOG,
    },
    ChannelSpec {
        topic: "/nav/location",
        schema_name: "foxglove.LocationFix",
        schema: FOXGLOVE_LOCATION,
    },
    ChannelSpec {
        topic: "/nav/pose",
        schema_name: "foxglove.PoseInFrame",
        schema: FOXGLOVE_POSE,
    },
    ChannelSpec {
        topic: "/tf",
        schema_name: "foxglove.FrameTransforms",
        schema: FOXGLOVE_TF,
    },
    ChannelSpec {
        topic: "/nav/status",
        schema_name: "rlg-hil/live/nav-status",
        schema: include_str!("../../schemas/live/nav-status.json"),
    },
    ChannelSpec {
        topic: "/turntable/status",
        schema_name: "rlg-hil/live/turntable-status",
        schema: include_str!("../../schemas/live/turntable-status.json"),
    },
    ChannelSpec {
        topic: "/turntable/command",
        schema_name: "rlg-hil/live/turntable-command",
        schema: include_str!("../../schemas/live/turntable-command.json"),
    },
    ChannelSpec {
        topic: "/turntable/dwell",
        schema_name: "rlg-hil/live/turntable-dwell",
        schema: include_str!("../../schemas/live/turntable-dwell.json"),
    },
    ChannelSpec {
        topic: "/imu/rates",
        schema_name: "rlg-hil/live/imu-rates",
        schema: include_str!("../../schemas/live/imu-rates.json"),
    },
    ChannelSpec {
        topic: "/nav/log",
        schema_name: "foxglove.Log",
        schema: FOXGLOVE_LOG,
    },
    ChannelSpec {
        topic: "/nav/event",
        schema_name: JsonChannel::Event.schema().0,
        schema: JsonChannel::Event.schema().1,
    },
    ChannelSpec {
        topic: "/hil/log",
        schema_name: "foxglove.Log",
        schema: FOXGLOVE_LOG,
    },
    ChannelSpec {
        topic: "/hil/result",
        schema_name: "rlg-hil/live/result",
        schema: include_str!("../../schemas/live/result.json"),
    },
];

/// How long the view waits for the clients asked for ([`View::start`]) before the run starts
/// anyway.
pub const WAIT_LIMIT: Duration = Duration::from_secs(300);

/// The live view of one command (one server, one or more runs).
pub struct View {
    server: Server,
    wait: usize,
    waited: AtomicBool,
    /// A viewer asked for a pause.
    paused: Arc<AtomicBool>,
    /// nav's process id while a run is on (0: none): the pause stops it.
    nav_pid: Arc<std::sync::atomic::AtomicI32>,
    /// Where the current run's time starts on the view's timeline, ns (runs of one command
    /// follow one another on it).
    offset_ns: AtomicU64,
    /// The latest time published, ns.
    now_ns: Arc<AtomicU64>,
    controls: Mutex<Option<std::thread::JoinHandle<()>>>,
    closing: Arc<AtomicBool>,
}

impl std::fmt::Debug for View {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("View")
            .field("addr", &self.server.addr())
            .finish_non_exhaustive()
    }
}

impl View {
    /// Serve the live view on `addr`; the first run waits until `wait` clients have subscribed
    /// to every channel (at most [`WAIT_LIMIT`]).
    pub fn start(addr: SocketAddr, wait: usize, duration_s: f64) -> Result<Arc<Self>> {
        let end = (duration_s.max(0.0) * 1e9) as u64;
        let server = Server::start(
            addr,
            CHANNELS.to_vec(),
            server::Options {
                playback: Some((0, end)),
                ..server::Options::default()
            },
        )?;
        let v = Arc::new(Self {
            server,
            wait,
            waited: AtomicBool::new(false),
            paused: Arc::new(AtomicBool::new(false)),
            nav_pid: Arc::new(std::sync::atomic::AtomicI32::new(0)),
            offset_ns: AtomicU64::new(0),
            now_ns: Arc::new(AtomicU64::new(0)),
            controls: Mutex::new(None),
            closing: Arc::new(AtomicBool::new(false)),
        });
        let (tx, rx) = mpsc::channel();
        v.server.on_control(tx);
        let weak = Arc::downgrade(&v);
        let closing = v.closing.clone();
        let t = std::thread::Builder::new()
            .name("live-controls".into())
            .spawn(move || control_loop(&rx, &weak, &closing))?;
        if let Ok(mut c) = v.controls.lock() {
            *c = Some(t);
        }
        eprintln!(
            "hil: live view on ws://{} (Foxglove: Open connection, Foxglove WebSocket; layout docs/foxglove-layout.json)",
            v.server.addr()
        );
        Ok(v)
    }

    /// The server's address.
    pub fn addr(&self) -> SocketAddr {
        self.server.addr()
    }

    /// Publish JSON `v` on `ch` at simulated time `t_ns` of the current run.
    pub(crate) fn publish(&self, ch: Ch, t_ns: u64, v: &serde_json::Value) {
        let at = self.offset_ns.load(Ordering::Relaxed) + t_ns;
        self.server
            .publish(ch as usize, at, v.to_string().as_bytes());
    }

    /// The server's time: simulated time `t_ns` of the current run.
    pub(crate) fn time(&self, t_ns: u64) {
        let at = self.offset_ns.load(Ordering::Relaxed) + t_ns;
        self.now_ns.fetch_max(at, Ordering::Relaxed);
        self.server.time(at);
    }

    /// A line on `/hil/log` at simulated time `t_ns` of the current run.
    pub(crate) fn log(&self, t_ns: u64, level: u8, text: &str) {
        let at = self.offset_ns.load(Ordering::Relaxed) + t_ns;
        let m = nav::record::foxglove::log(at, level, "hil", text.to_string());
        self.server
            .publish(Ch::HilLog as usize, at, m.to_string().as_bytes());
    }

    /// A run begins: it waits for the clients asked for (the first run only), and its time
    /// starts on the view's timeline after the last run's.
    pub(crate) fn begin_run(&self, name: &str) {
        if !self.waited.swap(true, Ordering::Relaxed) && self.wait > 0 {
            eprintln!(
                "hil: live view: waiting for {} client(s) to subscribe on ws://{}",
                self.wait,
                self.server.addr()
            );
            if !self.server.wait_for_subscribers(self.wait, WAIT_LIMIT) {
                eprintln!(
                    "hil: live view: {} client(s) did not subscribe within {} s; the run starts anyway",
                    self.wait,
                    WAIT_LIMIT.as_secs()
                );
            }
        }
        let now = self.now_ns.load(Ordering::Relaxed);
        let offset = if now == 0 {
            0
        } else {
            // a second later than the last run's last message, on a whole second
            (now / 1_000_000_000 + 1) * 1_000_000_000
        };
        self.offset_ns.store(offset, Ordering::Relaxed);
        self.log(
            0,
            nav::record::foxglove::LOG_INFO,
            &format!("run {name} begins"),
        );
    }

    /// The pause a viewer may ask for, for the scheduler; it stops and continues the process
    /// [`View::set_nav_pid`] names.
    pub(crate) fn hold(self: &Arc<Self>) -> emulators::adapters::scheduler::Hold {
        let pid = self.nav_pid.clone();
        let view = Arc::downgrade(self);
        emulators::adapters::scheduler::Hold {
            paused: self.paused.clone(),
            notify: Box::new(move |stand| {
                let p = pid.load(Ordering::Relaxed);
                if p > 0 {
                    let sig = if stand { libc::SIGSTOP } else { libc::SIGCONT };
                    // SAFETY: kill(2) on our own child's pid.
                    unsafe { libc::kill(p, sig) };
                }
                if let Some(v) = view.upgrade() {
                    let t = v.now_ns.load(Ordering::Relaxed);
                    let (status, text) = if stand {
                        (
                            Playback::Paused,
                            "paused: the stream stands, nav is stopped",
                        )
                    } else {
                        (Playback::Playing, "playing again")
                    };
                    v.server.playback_state(status, t, 1.0, false, None);
                    let m = nav::record::foxglove::log(
                        t,
                        nav::record::foxglove::LOG_INFO,
                        "hil",
                        text.into(),
                    );
                    v.server
                        .publish(Ch::HilLog as usize, t, m.to_string().as_bytes());
                }
            }),
        }
    }

    /// Viewers' playback requests go to `tx` (a replay's controls) rather than to the pause.
    pub(crate) fn controls_to(&self, tx: mpsc::Sender<Control>) {
        self.server.on_control(tx);
    }

    /// The playback state, at time `t_ns` of the current run, to the viewers that asked for
    /// playback.
    pub(crate) fn playback(
        &self,
        status: Playback,
        t_ns: u64,
        speed: f64,
        did_seek: bool,
        request: Option<&str>,
    ) {
        let at = self.offset() + t_ns;
        self.server
            .playback_state(status, at, speed as f32, did_seek, request);
    }

    /// Where the current run starts on the view's timeline, ns.
    pub(crate) fn offset(&self) -> u64 {
        self.offset_ns.load(Ordering::Relaxed)
    }

    /// Viewers connected now.
    pub fn clients(&self) -> usize {
        self.server.clients()
    }

    /// nav's process (0: none).
    pub(crate) fn set_nav_pid(&self, pid: u32) {
        self.nav_pid.store(pid as i32, Ordering::Relaxed);
    }

    /// Stop serving: clients get what is queued for them (at most 5 s). What every client got.
    pub fn finish(self: Arc<Self>) -> ServerStats {
        self.closing.store(true, Ordering::Relaxed);
        self.paused.store(false, Ordering::Relaxed);
        let t = self.controls.lock().ok().and_then(|mut c| c.take());
        if let Some(t) = t {
            let _ = t.join();
        }
        match Arc::try_unwrap(self) {
            Ok(v) => v.server.finish(Duration::from_secs(5)),
            Err(v) => v.server.stats(),
        }
    }

    /// What the server has done so far.
    pub fn stats(&self) -> ServerStats {
        self.server.stats()
    }
}

/// Viewers' playback requests: pause and play; seeking is refused (a run cannot go back), the
/// state says where it is. A pause nobody watches any more ends.
fn control_loop(rx: &mpsc::Receiver<Control>, view: &std::sync::Weak<View>, closing: &AtomicBool) {
    while !closing.load(Ordering::Relaxed) {
        let c = rx.recv_timeout(Duration::from_millis(100));
        let Some(v) = view.upgrade() else {
            return;
        };
        match c {
            Ok(c) => {
                let t = v.now_ns.load(Ordering::Relaxed);
                v.paused.store(!c.play, Ordering::Relaxed);
                let status = if c.play {
                    Playback::Playing
                } else {
                    Playback::Paused
                };
                v.server
                    .playback_state(status, t, 1.0, false, Some(&c.request_id));
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if v.paused.load(Ordering::Relaxed) && v.server.clients() == 0 {
                    v.paused.store(false, Ordering::Relaxed);
                    tracing::warn!("live view: paused and no viewer left: playing again");
                }
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => return,
        }
    }
}
