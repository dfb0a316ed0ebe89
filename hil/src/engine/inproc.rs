//! The bench without a bus: the scenario's devices stepped on the IMU clock by the same step
//! the bench's scheduler puts on vcan and the pty ([`emulators::step::Stepper`]: its order is
//! written there once), driving nav's own [`Pipeline`] in process. What the pipeline sends goes
//! back to the devices through the same step ([`Stepper::from_nav`]): a turntable command
//! waits for the next NAV_TIME and takes effect the lockstep's latency after that NAV_TIME's
//! sample. No glue of nav's is copied here: the result of an in-process run equals the bench's
//! bit for bit (the end-to-end tests check it).
//!
//! Also here: the receiver's model a scenario sets up for both (nav's config is
//! [`crate::scenario::navconfig`]'s).

use crate::scenario::Scenario;
use anyhow::{Context, Result};
use emulators::adapters::scheduler::{Lockstep, TtBus};
use emulators::adapters::transport::BusStream;
use emulators::drive::Drive;
use emulators::gps::{GpsReceiver, GpsRun, NmeaWriter};
use emulators::imu::ImuEmulator;
use emulators::step::{FromNav, Step, Stepper};
use emulators::truth::Motion;
use emulators::turntable::Turntable;
use nav::config::NavConfig;
use nav::pipeline::{Output, Pipeline};
use std::path::Path;
use wire::RawFrame;

/// The scenario's devices on the IMU clock, in the one order every run follows: the IMU on
/// `motion` (with the scenario's bus faults), the turntable `tt`, the receiver `gps`, for
/// `duration_s`. A procedure on the mechanism with no drive after it (a drill, a calibration)
/// ends the stream when nav says it is over ([`Stepper::end_with_procedure`]).
pub fn stepper(
    s: &Scenario,
    motion: Box<dyn Motion>,
    tt: Option<Turntable>,
    gps: Option<GpsRun>,
    duration_s: f64,
) -> Stepper {
    let latency = Lockstep::at_rate(s.imu.rate_hz).latency;
    let step = Stepper::new(
        BusStream::new(ImuEmulator::new(motion, s.imu.clone()), &s.faults),
        tt.map(|t| TtBus::new(t, s.imu.rate_hz)),
        gps.map(GpsReceiver::new),
        duration_s,
        emulators::bus::model::CanBus::new(s.bus.timing()),
        latency,
    );
    if s.ends_with_procedure() {
        step.end_with_procedure(latency)
    } else {
        step
    }
}

/// The receiver of a scenario with a drive and a `[gps]` table, with receiver model `rx`.
pub fn gps_run(s: &Scenario, rx: &emulators::gps::ReceiverParams) -> Result<Option<GpsRun>> {
    let Some(d) = &s.drive else { return Ok(None) };
    Ok(Some(GpsRun {
        writer: NmeaWriter::new(rx.clone()),
        drive: Drive::plan(d)?,
        pps_phase_s: s.imu.pps_phase_s,
        latency_s: 0.05,
        // a fixed time of day: the run depends on its scenario and seed only
        utc0_s: 12.0 * 3600.0,
        date: (21, 11, 2026),
    }))
}

/// A fix the receiver sent, as the truth side knows it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReceiverFix {
    /// Its PPS edge, s.
    pub edge: f64,
    /// Its position error (east, north, up), m.
    pub error_enu: [f64; 3],
    /// The receiver's own 1-sigma of that error (east, north, up), m.
    pub sigma_enu: [f64; 3],
}

impl ReceiverFix {
    /// Its error is within 3 of the receiver's own sigma on every axis.
    pub fn good(&self) -> bool {
        (0..3).all(|i| self.error_enu[i].abs() <= 3.0 * self.sigma_enu[i])
    }
}

/// The scenario's devices driving nav's pipeline, one IMU sample at a time.
pub struct InProcessBench {
    step: Stepper,
    pipeline: Pipeline,
    out: Vec<Output>,
    st: Step,
    t_first: Option<f64>,
    sent: Option<Vec<RawFrame>>,
    bad_from_nav: u64,
    receiver_errors: Vec<ReceiverFix>,
    /// IMU times (nav's, s) of the fixes the filter's gate refused.
    refused: Vec<f64>,
    port_gone: bool,
    imu_timeout_ms: u64,
}

impl InProcessBench {
    /// The devices (IMU on `motion`, the turntable `tt`, the receiver `gps`) of scenario `s`
    /// driving a pipeline configured by `cfg`.
    pub fn new(
        s: &Scenario,
        cfg: &NavConfig,
        motion: Box<dyn Motion>,
        tt: Option<Turntable>,
        gps: Option<GpsRun>,
    ) -> Result<Self> {
        Ok(Self {
            step: stepper(s, motion, tt, gps, s.duration_s),
            pipeline: Pipeline::new(cfg, false).context("nav's pipeline")?,
            out: Vec::new(),
            st: Step::default(),
            t_first: None,
            sent: None,
            bad_from_nav: 0,
            receiver_errors: Vec::new(),
            refused: Vec::new(),
            port_gone: false,
            imu_timeout_ms: cfg.watchdog.imu_timeout_ms,
        })
    }

    /// Scenario `s` as the bench runs it: its devices and nav's config for it.
    pub fn of(s: &Scenario) -> Result<Self> {
        let (motion, tt) = s.build();
        let gps = match &s.gps {
            Some(rx) => gps_run(s, rx)?,
            None => None,
        };
        let port = gps.is_some().then(|| Path::new("(in process)"));
        Self::new(
            s,
            &crate::scenario::navconfig::nav_config(s, None, port),
            motion,
            tt,
            gps,
        )
    }

    /// Keep every frame the pipeline sends (for comparisons with the bench's).
    pub fn keep_sent_frames(&mut self) {
        self.sent.get_or_insert_with(Vec::new);
    }

    /// The frames the pipeline sent, when kept.
    pub fn sent_frames(&self) -> &[RawFrame] {
        self.sent.as_deref().unwrap_or(&[])
    }

    /// Simulated time at the end of the next sample, s.
    pub fn next_time(&self) -> f64 {
        self.step.next_time()
    }

    /// Whether the scenario's duration is not over yet.
    pub fn running(&self) -> bool {
        self.step.running()
    }

    /// One IMU sample: its frames, then the turntable's due after it, then the receiver's
    /// epochs due by its end, each through the pipeline, whose outputs go back to the devices.
    /// Returns the sample's simulated time.
    pub fn step(&mut self) -> f64 {
        self.step.step(&mut self.st);
        let t = self.st.t;
        if self.st.stop_begins {
            // the IMU stops: nav's watchdog fires before anything more comes (the bus holds
            // the stream until it has)
            self.pipeline
                .set_imu_timeout(true, self.imu_timeout_ms, &mut self.out);
            self.act();
        }
        if self.st.frames.len() > self.st.turntable_frames {
            self.t_first.get_or_insert(t);
        }
        let frames = std::mem::take(&mut self.st.frames);
        let errors = std::mem::take(&mut self.st.errors);
        let mut e = errors.iter().peekable();
        for (i, f) in frames.iter().enumerate() {
            // nav's controller's error frames where the bus raised them
            while let Some((_, _, err)) = e.next_if(|x| x.0 <= i) {
                self.pipeline.on_can_error(err, &mut self.out);
                self.act();
            }
            self.pipeline.on_frame(f, &mut self.out);
            self.act();
        }
        for (_, _, err) in e {
            self.pipeline.on_can_error(err, &mut self.out);
            self.act();
        }
        self.st.frames = frames;
        self.st.errors = errors;
        let epochs = std::mem::take(&mut self.st.epochs);
        for e in &epochs {
            // while the receiver's device is gone its output is lost; nav's port goes and comes
            // back (the bus waits for nav to open it again before the receiver writes)
            match (self.port_gone, e.port_drop.is_some()) {
                (false, true) => {
                    self.pipeline.on_gps_port(false, "port drop", &mut self.out);
                    self.port_gone = true;
                }
                (true, false) => {
                    self.pipeline.on_gps_port(true, "", &mut self.out);
                    self.port_gone = false;
                }
                _ => {}
            }
            if e.port_drop.is_none() && !e.text.is_empty() {
                self.pipeline.on_gps_bytes(e.text.as_bytes(), &mut self.out);
                if let (Some(error_enu), Some(sigma_enu)) = (e.error_enu, e.sigma_enu) {
                    self.receiver_errors.push(ReceiverFix {
                        edge: e.edge,
                        error_enu,
                        sigma_enu,
                    });
                }
            }
            self.act();
        }
        self.st.epochs = epochs;
        self.refused.extend(
            self.pipeline
                .take_rejected_fixes()
                .into_iter()
                .map(|r| r.t_s),
        );
        t
    }

    /// Each fix nav was sent: its PPS edge, its error and the receiver's own sigma of it.
    pub fn receiver_errors(&self) -> &[ReceiverFix] {
        &self.receiver_errors
    }

    /// The fixes the filter's gate refused whose error was within 3 of the receiver's own
    /// sigma on every axis: good fixes no filter may refuse. Each refused fix is matched to
    /// the fix sent at its PPS edge.
    pub fn good_fixes_refused(&self) -> u64 {
        let mut n = 0;
        for &t_nav in &self.refused {
            let t = self.sim_time(t_nav);
            let nearest = self
                .receiver_errors
                .iter()
                .min_by(|a, b| (a.edge - t).abs().total_cmp(&(b.edge - t).abs()));
            if nearest.is_some_and(ReceiverFix::good) {
                n += 1;
            }
        }
        n
    }

    /// The end of the stream: nav's watchdog reports it (as the bus holds the stream's end until
    /// it has, [`Stepper::end_awaits_watchdog`]), then the pipeline flushes.
    pub fn finish(&mut self) {
        if self.step.end_awaits_watchdog() {
            self.pipeline
                .stream_ended(self.imu_timeout_ms, &mut self.out);
            self.act();
        }
        self.pipeline.flush(&mut self.out);
        self.act();
    }

    /// What the pipeline sent, to the devices: commands wait for a NAV_TIME, which places them.
    fn act(&mut self) {
        for o in self.out.drain(..) {
            let f = match o {
                Output::Command(f) | Output::Solution(f) => f,
                _ => continue,
            };
            if let Some(s) = self.sent.as_mut() {
                s.push(f);
            }
            if self.step.from_nav(f, true) == FromNav::Unexpected {
                self.bad_from_nav += 1;
            }
        }
    }

    /// nav's pipeline.
    pub fn pipeline(&self) -> &Pipeline {
        &self.pipeline
    }

    /// The IMU emulator.
    pub fn imu(&self) -> &ImuEmulator {
        self.step.imu().imu()
    }

    /// The IMU's time scale: nav's IMU time (which counts from the first sample, at the
    /// nominal rate) to simulated time, on the IMU's own oscillator.
    pub fn imu_timescale(&self) -> emulators::imu::ImuTimescale {
        self.imu()
            .oscillator()
            .timescale(self.t_first.unwrap_or(0.0))
    }

    /// Simulated time of nav's IMU time `t_nav` (which counts from the first sample).
    pub fn sim_time(&self, t_nav: f64) -> f64 {
        self.imu_timescale().sim_time(t_nav)
    }

    /// Simulated time of nav's sample number `k`.
    pub fn time_of(&self, k: i64) -> f64 {
        let base = self.pipeline.processor().baseline().unwrap_or(0) as i64;
        self.sim_time((k - base) as f64 / self.imu().params().rate_hz)
    }

    /// The devices' frames of the last step, in the order nav met them.
    pub fn last_frames(&self) -> &[RawFrame] {
        &self.st.frames
    }

    /// The devices, stepped.
    pub fn stepper(&self) -> &Stepper {
        &self.step
    }

    /// What the bus model did so far: load, each identifier's delays, the command round trip.
    pub fn bus_stats(&self) -> emulators::bus::model::BusStats {
        self.step.bus_stats()
    }

    /// Frames nav sent that no device here takes (a TT_CMD without a turntable).
    pub fn unexpected_frames(&self) -> u64 {
        self.bad_from_nav
    }
}
