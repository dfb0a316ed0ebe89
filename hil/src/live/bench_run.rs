//! A bench run on the live view: the scheduler's watcher (cheap, on its thread) and the
//! publisher (JSON and the server, on its own thread).

use super::{Ch, View};
use crate::scenario::Scenario;
use emulators::adapters::scheduler::TtTruth;
use emulators::drive::Drive;
use emulators::step::{Step, Stepper, Traced};
use nav::record::foxglove::{LOG_INFO, LOG_WARNING};
use serde_json::{Value, json};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use wire::{Message, NavAtt, NavHgt, NavPos, NavTime, NavVel, TtCmd, TtStatus};

/// Rate of `/imu/rates`, Hz (means of the samples between).
pub const IMU_RATES_HZ: f64 = 50.0;
/// Rate of the truth's channels and of the server's time, Hz.
pub const TICK_HZ: f64 = 10.0;
/// Most often `/nav/location`, `/nav/pose` and `/tf` are published, Hz (nav sends more; the
/// last epoch always goes out at the end).
pub const NAV_HZ: f64 = 10.0;
/// Events the watcher may have queued for the publisher before it drops (counted).
const QUEUE: usize = 8192;

/// What the watcher passes on.
enum Event {
    Tick(u64),
    Imu {
        t_ns: u64,
        gyro_dps: [f64; 3],
        accel_mps2: [f64; 3],
    },
    Status(u64, TtStatus),
    Command(u64, TtCmd),
    Truth(Box<TtTruth>),
    NavTime(u64, NavTime),
    Nav(Box<NavEpoch>),
    Line(String),
    End(Box<Value>, String),
    /// Stop without an end.
    Quit,
}

struct NavEpoch {
    t_ns: u64,
    att: NavAtt,
    vel: NavVel,
    pos: NavPos,
    hgt: NavHgt,
}

/// A bench run on the view.
pub struct BenchRun {
    view: Arc<View>,
    tx: SyncSender<Event>,
    dropped: Arc<AtomicU64>,
    thread: Option<JoinHandle<()>>,
}

/// What the view lost of a run (its queue was full: the publisher fell behind the scheduler).
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct RunViewStats {
    /// Events the watcher could not queue.
    pub dropped_events: u64,
    /// The server: every client's messages sent and dropped.
    pub server: super::server::ServerStats,
}

impl BenchRun {
    /// Begin run `name` on `view`, with the run's truth (its drive, site and faults) when
    /// known; `new_run`: after the view's last run on its timeline (else on the same
    /// timeline, from the start: a replay seeking back).
    pub fn begin(
        view: &Arc<View>,
        name: &str,
        truth: Option<&crate::engine::truthrec::RunTruth>,
        new_run: bool,
    ) -> anyhow::Result<Self> {
        if new_run {
            view.begin_run(name);
        }
        let (tx, rx) = sync_channel(QUEUE);
        let faults = truth.map(|t| t.faults.clone()).unwrap_or_default();
        let truth = truth.map(|t| (t.drive.clone(), t.site));
        let thread = {
            let view = view.clone();
            std::thread::Builder::new()
                .name("live-publish".into())
                .spawn(move || {
                    let mut p = Publisher {
                        view,
                        truth,
                        faults,
                        next_fault: 0,
                        nav_views: nav::record::foxglove::Views::default(),
                        last_nav: None,
                        next_nav_ns: 0,
                        dwell: Vec::new(),
                        last: 0,
                    };
                    p.run(&rx);
                })?
        };
        Ok(Self {
            view: view.clone(),
            tx,
            dropped: Arc::new(AtomicU64::new(0)),
            thread: Some(thread),
        })
    }

    /// The scheduler's watcher for scenario `s`.
    pub fn watcher(&self, s: &Scenario) -> emulators::adapters::scheduler::Watch {
        let mut w = self.frame_watcher(
            s.imu.gyro_pulse_arcsec,
            s.imu.accel_pulse_mps,
            s.imu.rate_hz,
        );
        Box::new(move |st, step| w.on_step(st, step))
    }

    /// A watcher of the frames of an IMU of these pulse weights and rate (a replay feeds it the
    /// recording's).
    pub(crate) fn frame_watcher(
        &self,
        gyro_pulse_arcsec: [f64; 3],
        accel_pulse_mps: [f64; 3],
        rate_hz: f64,
    ) -> Watcher {
        Watcher {
            tx: self.tx.clone(),
            dropped: self.dropped.clone(),
            gyro_deg: gyro_pulse_arcsec.map(|a| a / 3600.0),
            accel_mps: accel_pulse_mps,
            rate_hz,
            every: (rate_hz / IMU_RATES_HZ).round().max(1.0) as u32,
            tick_every: (rate_hz / TICK_HZ).round().max(1.0) as u64,
            gyro: None,
            accel: None,
            sum_g: [0; 3],
            sum_a: [0; 3],
            n: 0,
            tt_seen: 0,
            time: None,
            att: None,
            vel: None,
            pos: None,
        }
    }

    /// The view's pause for the scheduler.
    pub fn hold(&self) -> emulators::adapters::scheduler::Hold {
        self.view.hold()
    }

    /// nav's process: the pause stops it.
    pub fn set_nav_pid(&self, pid: u32) {
        self.view.set_nav_pid(pid);
    }

    /// One of nav's lines.
    pub fn line(&self, l: &str) {
        self.send(Event::Line(l.to_string()));
    }

    fn send(&self, e: Event) {
        if let Err(TrySendError::Full(_)) = self.tx.try_send(e) {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Stop publishing this run without an end (a replay seeking elsewhere).
    pub fn abandon(mut self) {
        // a watcher may still hold a sender: the publisher is told, not left waiting for them
        let _ = self.tx.send(Event::Quit);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }

    /// The run is over: its report and result card go out, the publisher ends.
    pub fn end(mut self, report: Value, card: String) -> RunViewStats {
        self.view.set_nav_pid(0);
        // the end is never dropped: it waits for room
        let _ = self.tx.send(Event::End(Box::new(report), card));
        drop(self.tx);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        RunViewStats {
            dropped_events: self.dropped.load(Ordering::Relaxed),
            server: self.view.stats(),
        }
    }
}

/// On the scheduler's thread after each sample: decodes what the view shows, queues it.
pub(crate) struct Watcher {
    tx: SyncSender<Event>,
    dropped: Arc<AtomicU64>,
    gyro_deg: [f64; 3],
    accel_mps: [f64; 3],
    rate_hz: f64,
    every: u32,
    tick_every: u64,
    gyro: Option<[u16; 3]>,
    accel: Option<[u16; 3]>,
    sum_g: [i64; 3],
    sum_a: [i64; 3],
    n: u32,
    tt_seen: usize,
    time: Option<NavTime>,
    att: Option<NavAtt>,
    vel: Option<NavVel>,
    pos: Option<NavPos>,
}

/// Counter steps from `last` to `now` (16-bit, wrapping), as signed counts.
fn steps(last: Option<[u16; 3]>, now: [u16; 3]) -> [i64; 3] {
    match last {
        Some(l) => std::array::from_fn(|i| i64::from(now[i].wrapping_sub(l[i]) as i16)),
        None => [0; 3],
    }
}

impl Watcher {
    fn send(&self, e: Event) {
        if let Err(TrySendError::Full(_)) = self.tx.try_send(e) {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    fn on_step(&mut self, st: &Step, step: &Stepper) {
        for (ns, e) in &st.trace {
            if let Traced::Frame(f) = e {
                self.on_frame(*ns, f);
            }
        }
        if let Some(tt) = step.turntable()
            && tt.truth.len() > self.tt_seen
        {
            for r in &tt.truth[self.tt_seen..] {
                self.send(Event::Truth(Box::new(r.clone())));
            }
            self.tt_seen = tt.truth.len();
        }
        self.after_sample(st.k, st.t);
    }

    /// A frame on the bus at `ns`.
    pub(crate) fn on_frame(&mut self, ns: u64, f: &wire::RawFrame) {
        match Message::decode(f) {
            Ok(Message::ImuGyro(g)) => {
                let d = steps(self.gyro, g.counts);
                self.gyro = Some(g.counts);
                for (s, d) in self.sum_g.iter_mut().zip(d) {
                    *s += d;
                }
                self.n += 1;
            }
            Ok(Message::ImuAccel(a)) => {
                let d = steps(self.accel, a.counts);
                self.accel = Some(a.counts);
                for (s, d) in self.sum_a.iter_mut().zip(d) {
                    *s += d;
                }
            }
            Ok(Message::TtStatus(s)) => self.send(Event::Status(ns, s)),
            Ok(Message::TtCmd(c)) if c.command != 0 => self.send(Event::Command(ns, c)),
            Ok(Message::NavTime(t)) => {
                self.send(Event::NavTime(ns, t));
                self.time = Some(t);
            }
            Ok(Message::NavAtt(a)) => self.att = Some(a),
            Ok(Message::NavVel(v)) => self.vel = Some(v),
            Ok(Message::NavPos(p)) => self.pos = Some(p),
            Ok(Message::NavHgt(h)) => {
                if let (Some(t), Some(att), Some(vel), Some(pos)) =
                    (self.time, self.att, self.vel, self.pos)
                {
                    let t_ns = (f64::from(t.sample_count) / self.rate_hz * 1e9) as u64;
                    self.send(Event::Nav(Box::new(NavEpoch {
                        t_ns,
                        att,
                        vel,
                        pos,
                        hgt: h,
                    })));
                }
            }
            _ => {}
        }
    }

    /// Sample `k` (0-based) is over at simulated time `t`, s.
    pub(crate) fn after_sample(&mut self, k: u64, t: f64) {
        if self.n >= self.every {
            let dt = f64::from(self.n) / self.rate_hz;
            let t_ns = (t * 1e9) as u64;
            let g: [f64; 3] = std::array::from_fn(|i| self.sum_g[i] as f64 * self.gyro_deg[i] / dt);
            let a: [f64; 3] =
                std::array::from_fn(|i| self.sum_a[i] as f64 * self.accel_mps[i] / dt);
            self.send(Event::Imu {
                t_ns,
                gyro_dps: g,
                accel_mps2: a,
            });
            (self.sum_g, self.sum_a, self.n) = ([0; 3], [0; 3], 0);
        }
        if (k + 1).is_multiple_of(self.tick_every) {
            self.send(Event::Tick((t * 1e9).round() as u64));
        }
    }
}

/// The publisher's state.
struct Publisher {
    view: Arc<View>,
    /// The truth's models (the drive, if any, and the site), when known.
    truth: Option<(Option<Drive>, emulators::truth::Static)>,
    faults: Vec<crate::engine::faultlog::FaultEvent>,
    next_fault: usize,
    nav_views: nav::record::foxglove::Views,
    /// The latest epoch not yet published.
    last_nav: Option<NavEpoch>,
    next_nav_ns: u64,
    /// Per axis: the dwell under way (angle, from ns).
    dwell: Vec<Option<(f64, u64)>>,
    /// The latest tick's time, ns.
    last: u64,
}

fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

impl Publisher {
    fn run(&mut self, rx: &Receiver<Event>) {
        while let Ok(e) = rx.recv() {
            match e {
                Event::Tick(t) => self.tick(t),
                Event::Imu {
                    t_ns,
                    gyro_dps,
                    accel_mps2,
                } => self.view.publish(
                    Ch::ImuRates,
                    t_ns,
                    &json!({"t_s": secs(t_ns), "gyro_dps": gyro_dps, "accel_mps2": accel_mps2}),
                ),
                Event::Status(t, s) => self.status(t, &s),
                Event::Command(t, c) => {
                    let name = wire::TtCommand::from_raw(i64::from(c.command))
                        .map_or_else(|| format!("command {}", c.command), |k| format!("{k:?}"));
                    self.view.publish(
                        Ch::TurntableCommand,
                        t,
                        &json!({"t_s": secs(t), "seq": c.seq, "command": name,
                                "axis": c.axis, "arg": c.arg}),
                    );
                }
                Event::Truth(r) => {
                    let t = (r.t_s.max(0.0) * 1e9) as u64;
                    self.view.publish(
                        Ch::TruthTurntable,
                        t,
                        &serde_json::to_value(&*r).unwrap_or(Value::Null),
                    );
                }
                Event::NavTime(t, n) => {
                    let h = n.health;
                    self.view.publish(
                        Ch::NavStatus,
                        t,
                        &json!({"t_s": secs(t), "sample_count": n.sample_count, "seq": n.seq,
                            "mode": format!("{:?}", n.mode),
                            "health": {"imu_timeout": h.imu_timeout, "imu_gaps": h.imu_gaps,
                                "imu_bit": h.imu_bit, "gps_stale": h.gps_stale,
                                "turntable": h.turntable, "filter": h.filter,
                                "gps_data": h.gps_data, "can_bus": h.can_bus},
                            "gps_rx_bytes": n.gps_rx_bytes}),
                    );
                }
                Event::Nav(e) => {
                    let due = e.t_ns >= self.next_nav_ns;
                    self.last_nav = Some(*e);
                    if due {
                        self.nav_epoch();
                    }
                }
                Event::Line(l) => {
                    let t = self.last;
                    let text = l.strip_prefix("nav: ").unwrap_or(&l).to_string();
                    let level = if text.contains("aborted") || text.contains("WARN") {
                        LOG_WARNING
                    } else {
                        LOG_INFO
                    };
                    let at = self.view.offset_ns.load(Ordering::Relaxed) + t;
                    if let Some(e) = procedure_event(&text) {
                        self.view.publish(Ch::NavEvent, t, &e);
                    }
                    let m = nav::record::foxglove::log(at, level, "nav", text);
                    self.view.publish(Ch::NavLog, t, &m);
                }
                Event::End(report, card) => {
                    self.end(&report, &card);
                    return;
                }
                Event::Quit => return,
            }
        }
    }

    fn tick(&mut self, t: u64) {
        self.last = self.last.max(t);
        let ts = secs(t);
        let offset = self.view.offset_ns.load(Ordering::Relaxed);
        if let Some((drive, site)) = &self.truth {
            let (state, loc) = crate::engine::truthrec::truth_messages(drive.as_ref(), site, ts);
            self.view.publish(Ch::TruthState, t, &state);
            self.view
                .publish(Ch::TruthLocation, t, &with_time(loc, offset + t));
        }
        while let Some(f) = self.faults.get(self.next_fault)
            && f.t_s <= ts
        {
            let m = crate::engine::truthrec::fault_message(f);
            let ft = (f.t_s.max(0.0) * 1e9) as u64;
            self.view
                .publish(Ch::BenchFaults, ft, &with_time(m, offset + ft));
            self.next_fault += 1;
        }
        self.view.time(t);
    }

    fn status(&mut self, t: u64, s: &TtStatus) {
        let f = s.faults;
        let faults: Vec<&str> = [
            ("stall", f.stall),
            ("lock", f.lock),
            ("encoder", f.encoder),
            ("heartbeat", f.heartbeat),
            ("estop", f.estop),
            ("drive", f.drive),
            ("limit", f.limit),
        ]
        .iter()
        .filter(|x| x.1)
        .map(|x| x.0)
        .collect();
        let state = format!("{:?}", s.state);
        self.view.publish(
            Ch::TurntableStatus,
            t,
            &json!({"t_s": secs(t), "axis": s.axis, "angle_deg": s.angle_deg,
                    "rate_dps": s.rate_dps, "state": state, "faults": faults,
                    "ack_seq": s.ack_seq}),
        );
        // a dwell: the axis locked at an angle, until it is not
        let ax = usize::from(s.axis);
        if self.dwell.len() <= ax {
            self.dwell.resize(ax + 1, None);
        }
        let locked = s.state == wire::TtState::Locked;
        match (self.dwell[ax], locked) {
            (None, true) => self.dwell[ax] = Some((s.angle_deg, t)),
            (Some((angle, from)), false) => {
                self.view.publish(
                    Ch::TurntableDwell,
                    t,
                    &json!({"axis": ax, "angle_deg": angle, "from_s": secs(from),
                            "to_s": secs(t), "duration_s": secs(t.saturating_sub(from))}),
                );
                self.dwell[ax] = None;
            }
            _ => {}
        }
    }

    fn nav_epoch(&mut self) {
        let Some(e) = self.last_nav.take() else {
            return;
        };
        self.next_nav_ns = e.t_ns + (1e9 / NAV_HZ) as u64;
        let offset = self.view.offset_ns.load(Ordering::Relaxed);
        let at = offset + e.t_ns;
        let llh = [e.pos.lat_deg, e.pos.lon_deg, e.hgt.height_m];
        let hpr = [e.att.heading_deg, e.att.pitch_deg, e.att.roll_deg];
        // the sigma nav promises, on the horizontal axes (NAV_HGT: one horizontal sigma)
        let s2 = e.hgt.pos_sigma_m * e.hgt.pos_sigma_m;
        let cov = vec![s2, 0.0, 0.0, 0.0, s2, 0.0, 0.0, 0.0, 0.0];
        let (loc, pose) = self.nav_views.location_and_pose(
            at,
            llh,
            hpr,
            e.vel.enu_mps,
            Some((cov, nav::record::foxglove::COVARIANCE_DIAGONAL)),
        );
        let mut loc = loc;
        loc["heading_sigma_deg"] = json!(e.hgt.heading_sigma_deg);
        self.view.publish(Ch::NavLocation, e.t_ns, &loc);
        self.view.publish(Ch::NavPose, e.t_ns, &pose);
        // nav's body and the truth's, in nav's start frame: the truth placed by the bench's own
        // geodesy around the same origin
        let mut transforms = vec![transform(at, "nav_body", &pose["pose"])];
        if let (Some(o), Some((drive, site))) = (self.nav_views.origin(), &self.truth) {
            let (lat, lon, h, _, thpr) =
                crate::engine::truthrec::state(drive.as_ref(), site, secs(e.t_ns));
            let d = emulators::geodesy::enu_offset(
                (o.0.to_radians(), o.1.to_radians(), o.2),
                (lat.to_radians(), lon.to_radians(), h),
            );
            let q = nav::record::foxglove::orientation_enu(thpr);
            transforms.push(transform(
                at,
                "truth_body",
                &json!({"position": {"x": d[0], "y": d[1], "z": d[2]},
                        "orientation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w}}),
            ));
        }
        self.view
            .publish(Ch::Tf, e.t_ns, &json!({ "transforms": transforms }));
    }

    fn end(&mut self, report: &Value, card: &str) {
        // the last epoch always goes out: the final heading is the report's
        self.nav_epoch();
        let t = self.last;
        for l in card.lines().filter(|l| !l.trim().is_empty()) {
            let level = if l.contains("FAIL") {
                LOG_WARNING
            } else {
                LOG_INFO
            };
            self.view.log(t, level, l.trim_end());
        }
        self.view.publish(Ch::HilResult, t, report);
        self.view.time(t);
    }
}

/// nav's line about a procedure (`<name> progress {...}`, `<name> result {...}`) as the
/// `/nav/event` its recording has (`{"kind": "north_finding_progress", "progress": {...}}`; the
/// result, which the recording keeps in nav's summary, as `..._result`).
fn procedure_event(text: &str) -> Option<Value> {
    for (word, key) in [(" progress ", "progress"), (" result ", "result")] {
        if let Some((name, j)) = text.split_once(word)
            && !name.contains(' ')
            && let Ok(v) = serde_json::from_str::<Value>(j)
        {
            let kind = format!("{}_{key}", name.replace('-', "_"));
            return Some(json!({ "kind": kind, key: v }));
        }
    }
    None
}

/// A `foxglove.FrameTransform` from [`nav::record::foxglove::POSE_FRAME`] to `child` with `pose`'s
/// position and orientation.
fn transform(at: u64, child: &str, pose: &Value) -> Value {
    json!({
        "timestamp": nav::record::foxglove::time(at),
        "parent_frame_id": nav::record::foxglove::POSE_FRAME,
        "child_frame_id": child,
        "translation": pose["position"],
        "rotation": pose["orientation"],
    })
}

/// A message's `timestamp` set to `at` (the view's timeline).
fn with_time(mut m: Value, at: u64) -> Value {
    m["timestamp"] = nav::record::foxglove::time(at);
    m
}
