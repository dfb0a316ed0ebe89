//! Throughput benchmark of nav's pipeline on the IMU stream: decode, counter differencing,
//! dither filter, coning/sculling compensation, attitude update and the solution output, on one
//! core, over frames prepared in advance (the emulator's cost is not counted).

use crate::scenario::Scenario;
use anyhow::{Context, Result};
use emulators::can::BusStream;
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
    let cfg = crate::inproc::nav_config(&s, None, None);
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
    let (motion, tt) = s.build();
    let imu = ImuEmulator::new(motion, s.imu.clone());
    let mut bus = BusStream::new(imu, &s.faults);
    let mut tt = tt.map(|t| emulators::bus::TtBus::new(t, s.imu.rate_hz, 120));
    let (mut frames, mut msgs) = (Vec::new(), Vec::new());
    let mut n = 0u64;
    let t0 = Instant::now();
    while bus.next_time() <= seconds {
        let (k, t) = (bus.imu().next_index(), bus.next_time());
        frames.clear();
        bus.next_frames(&mut frames);
        if let Some(tt) = tt.as_mut() {
            msgs.clear();
            tt.after_sample(k, t, &mut msgs);
            frames.extend(msgs.iter().filter_map(|m| m.encode().ok()));
        }
        n += frames.len() as u64;
        std::hint::black_box(&frames);
    }
    let dt = t0.elapsed().as_secs_f64().max(1e-9);
    EmulatorBench {
        scenario: s.name.clone(),
        seconds,
        frames: n,
        speed_factor: seconds / dt,
        frames_per_second: n as f64 / dt,
    }
}
