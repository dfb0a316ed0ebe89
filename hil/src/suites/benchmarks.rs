//! Throughput benchmark of nav's pipeline on the IMU stream: decode, counter differencing,
//! dither filter, coning/sculling compensation, attitude update and the solution output, on one
//! core, over frames prepared in advance (the emulator's cost is not counted).

use crate::scenario::Scenario;
use crate::table::{Align, Table};
use anyhow::{Context, Result};
use emulators::adapters::transport::BusStream;
use emulators::imu::{ImuEmulator, ImuParams};
use emulators::truth::Coning;
use nav::pipeline::Pipeline;
use serde::Serialize;
use std::time::Instant;
use wire::RawFrame;

/// Benchmark result.
#[derive(Debug, Clone, Serialize)]
pub struct BenchResult {
    /// IMU samples processed per pass.
    pub samples: u64,
    /// CAN frames decoded per pass.
    pub frames: u64,
    /// Best pass, samples per second.
    pub samples_per_second: f64,
    /// Best pass, frames per second.
    pub frames_per_second: f64,
    /// Passes run.
    pub passes: u32,
    /// Build profile (`release` or `debug`): figures from debug builds are not the product's.
    pub profile: &'static str,
}

/// Run the benchmark on `seconds` of 2 kHz IMU data under 50 Hz coning with dither.
pub fn frontend(seconds: f64, passes: u32) -> Result<BenchResult> {
    let mut s = Scenario::builtin_static();
    s.coning = Some(Coning {
        half_angle_deg: 1.0,
        frequency_hz: 50.0,
    });
    s.imu = ImuParams::default();
    let imu = ImuEmulator::new(s.motion(), s.imu.clone());
    let mut bus = BusStream::new(imu, &Default::default());
    let mut frames: Vec<RawFrame> = Vec::new();
    while bus.next_time() <= seconds {
        bus.next_frames(&mut frames);
    }
    let cfg = crate::scenario::navconfig::nav_config(&s, None, None);
    let mut best = f64::INFINITY;
    let mut samples = 0;
    for _ in 0..passes.max(1) {
        let mut p = Pipeline::new(&cfg, false).context("nav's pipeline")?;
        let mut out = Vec::new();
        let t0 = Instant::now();
        for f in &frames {
            p.on_frame(f, &mut out);
            out.clear();
        }
        let dt = t0.elapsed().as_secs_f64();
        best = best.min(dt);
        samples = p.processor().stats().samples;
        std::hint::black_box(p.processor().attitude());
    }
    Ok(BenchResult {
        samples,
        frames: frames.len() as u64,
        samples_per_second: samples as f64 / best,
        frames_per_second: frames.len() as f64 / best,
        passes: passes.max(1),
        profile: if cfg!(debug_assertions) {
            "debug"
        } else {
            "release"
        },
    })
}

/// The emulators' own cost for one scenario: its IMU stream (truth, sensor model, wire encoding)
/// and, where it has one, its turntable's frames, produced in process without a bus.
#[derive(Debug, Clone, Serialize)]
pub struct EmulatorBench {
    /// Scenario name.
    pub scenario: String,
    /// Simulated seconds produced.
    pub seconds: f64,
    /// Frames produced.
    pub frames: u64,
    /// Simulated seconds per wall second (the speed factor the emulators alone could hold).
    pub speed_factor: f64,
    /// Frames per wall second.
    pub frames_per_second: f64,
}

/// Produce `seconds` of scenario `s`'s bus traffic in process and time it.
pub fn emulators(s: &Scenario, seconds: f64) -> EmulatorBench {
    let mut n = 0u64;
    let t0 = Instant::now();
    each_sample(s, seconds, |frames| {
        n += frames.len() as u64;
        std::hint::black_box(frames);
    });
    let dt = t0.elapsed().as_secs_f64().max(1e-9);
    EmulatorBench {
        scenario: s.name.clone(),
        seconds,
        frames: n,
        speed_factor: seconds / dt,
        frames_per_second: n as f64 / dt,
    }
}

/// A scenario's bus traffic without nav, sample by sample up to `seconds` of simulated time:
/// each IMU sample's frames, then the turntable's frames due after it (the scheduler's step,
/// [`emulators::step::Stepper`]; nothing answers the turntable, so it only reports its status).
pub fn each_sample(s: &Scenario, seconds: f64, mut f: impl FnMut(&[RawFrame])) {
    let (motion, tt) = s.build();
    let mut step = crate::engine::inproc::stepper(s, motion, tt, None, seconds);
    let mut st = emulators::step::Step::default();
    while step.running() {
        step.step(&mut st);
        f(&st.frames);
    }
}

/// The raw vcan limit on this machine: a trivial writer and reader, nothing else on the bus.
#[derive(Debug, Clone, Serialize)]
pub struct RawVcan {
    /// Frames per write: 1 (as `cangen -g 0` writes) or a `sendmmsg` batch (as the bench's
    /// scheduler writes).
    pub frames_per_write: usize,
    /// Frames written.
    pub sent: u64,
    /// Frames the reader received.
    pub received: u64,
    /// Frames lost between them.
    pub lost: u64,
    /// From the first write to the last frame read, s.
    pub seconds: f64,
    /// Frames received per second.
    pub frames_per_second: f64,
}

/// Write `frames` frames on `iface` as fast as the kernel takes them, `per_write` per system
/// call, while a reader (receive buffer 8 MiB, `recvmmsg`) counts them.
pub fn raw_vcan(iface: &str, frames: u64, per_write: usize) -> Result<RawVcan> {
    use socketcan::{CanSocket, Socket, SocketOptions};
    use std::os::fd::AsRawFd;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::Duration;
    let rx = CanSocket::open(iface).with_context(|| format!("opening {iface} to read"))?;
    rx.set_filters(&[socketcan::CanFilter::new(u32::from(RAW_ID), 0x7FF)])
        .with_context(|| format!("filtering {iface}"))?;
    if let Err(e) = wire::set_rcvbuf(rx.as_raw_fd(), 8 << 20) {
        tracing::warn!("{iface}: receive buffer stays at the default: {e}");
    }
    let tx = CanSocket::open(iface).with_context(|| format!("opening {iface} to write"))?;
    let done = Arc::new(AtomicBool::new(false));
    let reader = {
        let done = done.clone();
        std::thread::spawn(move || -> std::io::Result<(u64, Instant)> {
            let fd = rx.as_raw_fd();
            let (mut n, mut last) = (0u64, Instant::now());
            let mut buf = Vec::with_capacity(wire::BATCH);
            loop {
                wire::wait_readable(fd, Duration::from_millis(50));
                buf.clear();
                let k = wire::recv_batch(fd, &mut buf, wire::BATCH)? as u64;
                if k > 0 {
                    n += k;
                    last = Instant::now();
                } else if done.load(Ordering::Acquire)
                    && last.elapsed() > Duration::from_millis(300)
                {
                    return Ok((n, last));
                }
            }
        })
    };
    let per_write = per_write.clamp(1, wire::BATCH);
    let mut chunk = vec![
        RawFrame {
            id: RAW_ID,
            len: 8,
            data: [0; 8],
        };
        per_write
    ];
    let fd = tx.as_raw_fd();
    let t0 = Instant::now();
    let mut sent = 0u64;
    while sent < frames {
        let want = (frames - sent).min(per_write as u64) as usize;
        for (i, f) in chunk[..want].iter_mut().enumerate() {
            f.data = (sent + i as u64).to_le_bytes();
        }
        match wire::send_batch(fd, &chunk[..want]) {
            Ok(k) => sent += k as u64,
            Err(e) if e.raw_os_error() == Some(libc::ENOBUFS) => std::thread::yield_now(),
            Err(e) => {
                done.store(true, Ordering::Release);
                return Err(anyhow::Error::new(e).context(format!("writing on {iface}")));
            }
        }
    }
    done.store(true, Ordering::Release);
    let (received, last) = reader
        .join()
        .map_err(|_| anyhow::anyhow!("the reader panicked"))?
        .with_context(|| format!("reading {iface}"))?;
    let seconds = last.duration_since(t0).as_secs_f64().max(1e-9);
    Ok(RawVcan {
        frames_per_write: per_write,
        sent,
        received,
        lost: sent.saturating_sub(received),
        seconds,
        frames_per_second: received as f64 / seconds,
    })
}

/// The id the raw benchmark writes (outside the contract's ids).
const RAW_ID: u16 = 0x7EE;

/// nav's whole pipeline on a GPS-aided drive, without a bus: front end, navigator (strapdown
/// and Kalman filter with its receiver error states) and solution output, over the scenario's
/// frames and fixes prepared in advance (the emulators' cost is not counted).
#[derive(Debug, Clone, Serialize)]
pub struct PipelineBench {
    /// Scenario name.
    pub scenario: String,
    /// Simulated seconds.
    pub seconds: f64,
    /// Frames through the pipeline.
    pub frames: u64,
    /// GPS fixes through the pipeline.
    pub fixes: u64,
    /// Filter updates made.
    pub updates: u64,
    /// Simulated seconds per wall second.
    pub speed_factor: f64,
    /// Frames per wall second.
    pub frames_per_second: f64,
}

/// Time nav's pipeline on `seconds` of drive scenario `s` (a drive with a receiver and no
/// turntable: nothing nav sends changes what the devices do).
pub fn pipeline_drive(s: &Scenario, seconds: f64) -> Result<PipelineBench> {
    enum Input {
        Frame(RawFrame),
        Gps(String),
    }
    let rx = s.gps.as_ref().context("the scenario has no [gps]")?;
    anyhow::ensure!(
        s.turntable.is_none(),
        "{}: a scenario with a turntable is a closed loop; choose a drive without one",
        s.name
    );
    let seconds = seconds.min(s.duration_s);
    let run = crate::engine::inproc::gps_run(s, rx)?.context("the scenario has no [drive]")?;
    let (motion, _) = s.build();
    // the devices in the scheduler's order, taken before the clock starts
    let mut step = crate::engine::inproc::stepper(s, motion, None, Some(run), seconds);
    let mut st = emulators::step::Step::default();
    let mut inputs = Vec::new();
    while step.running() {
        step.step(&mut st);
        inputs.extend(st.frames.iter().copied().map(Input::Frame));
        inputs.extend(
            st.epochs
                .drain(..)
                .filter(|e| e.port_drop.is_none())
                .map(|e| Input::Gps(e.text)),
        );
    }
    let cfg =
        crate::scenario::navconfig::nav_config(s, None, Some(std::path::Path::new("(in process)")));
    let mut p = Pipeline::new(&cfg, false).context("nav's pipeline")?;
    let mut out = Vec::new();
    let mut n_frames = 0u64;
    let t0 = Instant::now();
    for i in inputs {
        match i {
            Input::Frame(f) => {
                n_frames += 1;
                p.on_frame(&f, &mut out);
            }
            Input::Gps(text) => p.on_gps_bytes(text.as_bytes(), &mut out),
        }
        out.clear();
    }
    p.flush(&mut out);
    let dt = t0.elapsed().as_secs_f64().max(1e-9);
    let n_fixes = p.fixes().0;
    let updates = p
        .summary()
        .navigation
        .and_then(|n| n.filter)
        .map_or(0, |f| f.updates);
    Ok(PipelineBench {
        scenario: s.name.clone(),
        seconds,
        frames: n_frames,
        fixes: n_fixes,
        updates,
        speed_factor: seconds / dt,
        frames_per_second: n_frames as f64 / dt,
    })
}

/// One scenario through the bench on vcan, as fast as lockstep with nav allows.
#[derive(Debug, Clone, Serialize)]
pub struct BusPace {
    /// Scenario name.
    pub scenario: String,
    /// Simulated seconds run.
    pub simulated_s: f64,
    /// Wall seconds.
    pub wall_s: f64,
    /// Simulated seconds per wall second.
    pub pace_reached: f64,
    /// Frames written per wall second (IMU stream).
    pub frames_per_second: f64,
    /// `frames_per_second` over the raw vcan limit measured in the same run.
    pub fraction_of_limit: Option<f64>,
    /// Frames the bench counted lost between the emulators and nav.
    pub lost: i64,
    /// Frame-in to NAV_TIME-out latency on the bus, median, ms.
    pub latency_p50_ms: f64,
    /// The same, 99th percentile, ms.
    pub latency_p99_ms: f64,
    /// Times the scheduler gave up waiting for nav.
    pub stalls: u64,
}

impl BusPace {
    /// The pace figures of run `r`, with the raw limit `limit` (frames/s) when measured.
    pub fn of(r: &crate::report::RunReport, limit: Option<f64>) -> Self {
        Self {
            scenario: r.scenario.name.clone(),
            simulated_s: r.pace_reached * r.wall_seconds,
            wall_s: r.wall_seconds,
            pace_reached: r.pace_reached,
            frames_per_second: r.frames_per_wall_second,
            fraction_of_limit: limit.map(|l| r.frames_per_wall_second / l),
            lost: r.bus_lost_frames,
            latency_p50_ms: r.lockstep.latency_p50_ms,
            latency_p99_ms: r.lockstep.latency_p99_ms,
            stalls: r.lockstep.stalls,
        }
    }
}

/// The whole suite's figures, from one run on one machine.
#[derive(Debug, Clone, Serialize)]
pub struct Suite {
    /// Where it ran: `native` or `vm` (the QEMU guest).
    pub backend: String,
    /// The machine: CPUs, CPU model, kernel.
    pub machine: String,
    /// Build profile of these binaries.
    pub profile: &'static str,
    /// The raw vcan limit, one frame per write and batched.
    pub raw_vcan: Vec<RawVcan>,
    /// Each scenario through the bench on vcan.
    pub bus: Vec<BusPace>,
    /// Each scenario's emulators alone, in process.
    pub emulators: Vec<EmulatorBench>,
    /// nav's front end on the IMU stream, in process.
    pub front_end: Option<BenchResult>,
    /// nav's whole pipeline (with the filter) on a GPS-aided drive, in process.
    pub pipeline: Option<PipelineBench>,
}

impl Suite {
    /// An empty suite for `backend`, describing this machine.
    pub fn new(backend: &str) -> Self {
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        let model = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|c| {
                c.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, m)| m.trim().to_string())
            })
            .unwrap_or_else(|| "unknown CPU".into());
        let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease")
            .map(|k| k.trim().to_string())
            .unwrap_or_default();
        Self {
            backend: backend.into(),
            machine: format!("{cpus} CPUs, {model}, kernel {kernel}"),
            profile: if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            },
            raw_vcan: Vec::new(),
            bus: Vec::new(),
            emulators: Vec::new(),
            front_end: None,
            pipeline: None,
        }
    }

    /// The raw vcan limit: the best of the raw measurements, frames/s.
    pub fn raw_limit(&self) -> Option<f64> {
        self.raw_vcan
            .iter()
            .map(|r| r.frames_per_second)
            .max_by(f64::total_cmp)
    }
}

/// The suite as Markdown tables.
pub fn markdown(s: &Suite) -> String {
    let mut m = format!(
        "# hil bench\n\n{} build, {} ({})\n\n",
        s.profile,
        s.machine,
        if s.backend == "vm" {
            "inside the QEMU guest"
        } else {
            "native"
        }
    );
    m += &raw_vcan_markdown(s);
    if !s.bus.is_empty() {
        m += "## Each scenario through the bench on vcan (emulators + nav, lockstep, as fast as it goes)\n\n";
        let mut t = Table::figures(&[
            "scenario",
            "simulated s",
            "wall s",
            "pace",
            "frames/s",
            "of the raw limit",
            "lost",
            "latency p50 / p99, ms",
            "stalls",
        ]);
        for b in &s.bus {
            t.row([
                b.scenario.clone(),
                format!("{:.1}", b.simulated_s),
                format!("{:.1}", b.wall_s),
                format!("x{:.1}", b.pace_reached),
                format!("{:.0}", b.frames_per_second),
                b.fraction_of_limit
                    .map_or("-".into(), |f| format!("{:.0} %", 100.0 * f)),
                b.lost.to_string(),
                format!("{:.1} / {:.1}", b.latency_p50_ms, b.latency_p99_ms),
                b.stalls.to_string(),
            ]);
        }
        m += &t.finish();
        m += "\n";
    }
    if !s.emulators.is_empty() {
        m += "## Each scenario's emulators alone (truth + sensor model + encoding), one core, in process\n\n";
        let mut t = Table::figures(&["scenario", "simulated s", "pace", "frames/s"]);
        for e in &s.emulators {
            t.row([
                e.scenario.clone(),
                format!("{:.1}", e.seconds),
                format!("x{:.1}", e.speed_factor),
                format!("{:.3e}", e.frames_per_second),
            ]);
        }
        m += &t.finish();
        m += "\n";
    }
    if s.front_end.is_some() || s.pipeline.is_some() {
        m += "## nav, one core, in process\n\n";
        let mut t = Table::figures(&["what", "samples or frames", "per second", "pace"]);
        if let Some(f) = &s.front_end {
            t.row([
                "front end (decode, dither FIR, coning/sculling, attitude)".to_string(),
                format!("{} samples", f.samples),
                format!("{:.3e} samples/s", f.samples_per_second),
                format!("x{:.0}", f.samples_per_second / 2000.0),
            ]);
        }
        if let Some(p) = &s.pipeline {
            t.row([
                format!(
                    "whole pipeline with the filter on {} ({} fixes, {} updates)",
                    p.scenario, p.fixes, p.updates
                ),
                format!("{} frames", p.frames),
                format!("{:.3e} frames/s", p.frames_per_second),
                format!("x{:.0}", p.speed_factor),
            ]);
        }
        m += &t.finish();
    }
    m
}

/// The raw vcan section: a trivial writer and reader at each batch size.
fn raw_vcan_markdown(s: &Suite) -> String {
    if s.raw_vcan.is_empty() {
        return String::new();
    }
    let mut m = String::new();
    m += "## Raw vcan (a trivial writer and reader, nothing else on the bus)\n\n";
    let mut t = Table::new(&[
        ("frames per write", Align::Right),
        ("sent", Align::Right),
        ("received", Align::Right),
        ("lost", Align::Right),
        ("frames/s", Align::Right),
        ("x of the IMU stream", Align::Right),
    ]);
    for r in &s.raw_vcan {
        t.row([
            r.frames_per_write.to_string(),
            r.sent.to_string(),
            r.received.to_string(),
            r.lost.to_string(),
            format!("{:.0}", r.frames_per_second),
            format!("x{:.1}", r.frames_per_second / IMU_FRAMES_PER_S),
        ]);
    }
    m += &t.finish();
    m += "\n";
    m
}

/// Frames per second of the 2 kHz IMU stream (gyro and accelerometer frames per sample, and
/// housekeeping every 200th).
const IMU_FRAMES_PER_S: f64 = 2000.0 * 2.0 + 10.0;
