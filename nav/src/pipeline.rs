//! nav's mission logic as one pipeline without I/O: decoded frames and GPS fixes in, what must
//! go out (turntable commands, solution frames, records, progress lines) back. The `nav` binary
//! is a thin shell around it (config, sockets, pty, signals, recorder), and every in-process run
//! of the bench (replay, drills, navigation experiments, Monte Carlo) drives this same pipeline.
//!
//! One CAN frame, followed from input to output ([`Pipeline::on_frame`]):
//! 1. **decode** it with the wire contract; bad frames are counted by kind ([`FrameCounters`]);
//! 2. **turntable** status and acknowledgements go to the procedure commanding the mechanism
//!    (north-finding or a calibration, `crate::procedures::mission`);
//! 3. the IMU **front end** turns gyro/accel frames into samples on the one IMU clock (the
//!    extended sample counter);
//! 4. **processing** (dither filter, coning and sculling) turns samples into updates; a PPS
//!    edge latched in a sample becomes an IMU time for the navigator;
//! 5. each update goes to the **procedure**, and once it is finished (or when there is none) to
//!    the **navigator**, as the [mission's phase](Pipeline::phase) says: the
//!    hand-over (`Pipeline::hand_over`) gives it north-finding's heading;
//! 6. the procedure's **commands** for the indexing mechanism go out;
//! 7. every `rate / 50` samples the **solution** (mode and health from [`Pipeline::mode`] and
//!    [`Pipeline::health`]) goes out as NAV_* frames.
//!
//! IMU time is `(sample - baseline) / rate`: seconds from the front end's first sample.

use crate::config::NavConfig;
use crate::frontend::gps_receiver::GpsFix;
use crate::frontend::imu_frames::{ImuEvent, ImuFrontEnd, ImuSample};
use crate::frontend::processing::{ImuProcessor, Update, quaternion_to_rotation_vector};
use crate::navigation::earth;
use crate::navigation::navigator::Navigator;
use crate::navigation::solution_frames::{Solution, SolutionEncoder};
use crate::procedures::common::{Procedure, Reporting};
use crate::procedures::mission::Mission;
use crate::procedures::north_finding::NorthFinder;
use crate::procedures::self_calibration::SelfCalibrator;
use crate::procedures::tetra_calibration::TetraCalibrator;
use crate::record::writer::JsonChannel;
use crate::summary::CanBusHealth;
use crate::summary::{AttitudeSummary, Summary};
use std::collections::BTreeMap;
use thiserror::Error;
use tracing::{info, warn};
use wire::{DecodeError, Message, RawFrame};

/// What the pipeline asks its shell to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    /// Send a turntable command on the bus (it must go out: a failure is the shell's error).
    Command(RawFrame),
    /// Send a solution frame on the bus (best effort: navigation never waits for its output).
    Solution(RawFrame),
    /// Record a JSON message (the shell stamps the wall time).
    Json {
        /// Channel.
        channel: JsonChannel,
        /// Publish time on the IMU clock, ns.
        publish_ns: u64,
        /// The message.
        json: String,
    },
    /// Record a decoded IMU sample.
    Sample {
        /// Publish time on the IMU clock, ns.
        publish_ns: u64,
        /// The sample.
        sample: ImuSample,
    },
    /// A line for the operator (stdout).
    Line(String),
    /// A GPS fix decoded from the receiver's bytes (the shell exports it as a JSON line).
    Fix(Box<GpsFix>),
    /// A calibration finished: the shell stamps this parameter file's date and writes it to
    /// `path` (the procedure's `parameters_out`).
    Parameters {
        /// Where.
        path: std::path::PathBuf,
        /// The file.
        file: Box<crate::procedures::unit_parameters::ParameterFile>,
    },
}

/// Setting the pipeline up failed.
#[derive(Debug, Error)]
pub enum PipelineError {
    /// The processing chain's settings.
    #[error("processing chain: {0}")]
    Processing(#[from] crate::frontend::dither_filter::FirError),
    /// A procedure's settings (north-finding, self-calibration, the redundant unit's).
    #[error(transparent)]
    Procedure(#[from] crate::procedures::turntable_link::SettingError),
}

/// Frames received, by outcome.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameCounters {
    /// Data frames.
    pub total: u64,
    /// Decoded, by message name.
    pub by_message: BTreeMap<&'static str, u64>,
    /// Unknown ids and how often each came.
    pub unknown: BTreeMap<u32, u64>,
    /// Wrong length for their id.
    pub bad_length: u64,
    /// A value out of its range.
    pub invalid: u64,
    /// Remote frames and others that are not data frames (error frames are counted in
    /// [`CanBusHealth`]).
    pub non_data: u64,
}

/// Running sums over the processed samples and updates (the summary's means).
#[derive(Debug, Clone, Default)]
struct Sums {
    samples: u64,
    first: Option<u64>,
    last: Option<u64>,
    phi: [f64; 3],
    dv: [f64; 3],
    updates: u64,
}

impl Sums {
    fn add_sample(&mut self, s: &ImuSample) {
        if s.ambiguous {
            return;
        }
        self.samples += u64::from(s.span);
        self.first.get_or_insert(s.sample - u64::from(s.span));
        self.last = Some(s.sample);
    }

    fn add_update(&mut self, u: &Update) {
        self.updates += 1;
        for a in 0..3 {
            self.phi[a] += u.phi[a];
            self.dv[a] += u.dv[a];
        }
    }
}

/// A procedure the pipeline runs on the mechanism, with its reporting state.
#[derive(Debug)]
struct Running {
    m: Box<dyn Mission>,
    rep: Reporting,
    /// Its heading has gone to the navigator.
    handed_over: bool,
}

/// What the IMU's updates are for: the mission's phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MissionPhase {
    /// A procedure on the mechanism runs: the updates are its; navigation only keeps time.
    Procedure,
    /// Navigating (after the procedure, when there was one).
    Navigating,
    /// No procedure running and no navigation configured: the updates are only processed.
    Processing,
}

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;

/// The navigation computer's logic.
pub struct Pipeline {
    rate_hz: f64,
    sample_ns: f64,
    coning_samples: usize,
    gps_expected: bool,
    record: bool,
    fe: ImuFrontEnd,
    proc: ImuProcessor,
    fir: Option<crate::frontend::dither_filter::FirResponse>,
    coning_method: crate::frontend::coning::ConingMethod,
    /// The procedures on the mechanism the config enables ([`REGISTRY`]'s
    /// order; the config allows one).
    procedures: Vec<Running>,
    navigator: Option<Navigator>,
    out_every: u64,
    next_out: Option<u64>,
    encoder: SolutionEncoder,
    last_mode: Option<String>,
    frames: FrameCounters,
    sums: Sums,
    /// An IMU frame has arrived: the procedures have a clock.
    imu_heard: bool,
    imu_timeout: bool,
    timeouts: u64,
    fixes: u64,
    last_fix: Option<GpsFix>,
    /// The receiver's bytes, decoded here (in the order they came among the frames).
    decoder: crate::frontend::gps_receiver::GpsDecoder,
    decoded: Vec<GpsFix>,
    /// Bytes taken from the receiver.
    gps_rx_bytes: u64,
    /// The last sample at which the receiver's stream carried bad data.
    gps_bad_at: Option<u64>,
    /// What nav's CAN controller reported (error frames).
    can: CanBusHealth,
    /// The IMU sample at the last error frame that spoke of errors.
    can_error_at: Option<u64>,
    /// FNV-1a over every frame sent and the IMU sample it was sent at.
    sent_hash: u64,
    encode_errors: u64,
    integrity: Option<crate::navigation::integrity::Symptom>,
    /// The filter's re-anchors and relinearisations last reported.
    filter_resets: (u64, u64),
    samples: Vec<ImuSample>,
    events: Vec<ImuEvent>,
    updates: Vec<Update>,
    sol_frames: Vec<RawFrame>,
}

/// What builds a procedure from nav's config (none when the config does not enable it).
pub(crate) type Make =
    fn(
        &NavConfig,
    ) -> Result<Option<Box<dyn Mission>>, crate::procedures::turntable_link::SettingError>;

/// The gyro parameters nav's front end applies (a calibration's estimates are residuals on top
/// of them).
fn front_end_gyro(c: &NavConfig) -> crate::procedures::unit_parameters::GyroParameters {
    crate::procedures::unit_parameters::GyroParameters {
        bias_dph: c.imu.gyro_bias_dph,
        scale_factor_ppm: c.imu.gyro_scale_factor_ppm,
    }
}

/// Every procedure nav can run at start, in the order the pipeline serves them: each built from
/// its section of the config.
pub(crate) const REGISTRY: [Make; 3] = [
    |c| crate::procedures::north_finding::NorthFinding::make(&c.north_finding),
    |c| {
        crate::procedures::self_calibration::SelfCalibration::make(
            &c.self_calibration,
            front_end_gyro(c),
        )
    },
    |c| crate::procedures::tetra_calibration::TetraCalibration::make(&c.tetra_calibration),
];

impl Pipeline {
    /// The pipeline of config `cfg` (its device sections are the shell's). `record`: produce
    /// records for a recording (off for in-process runs that only want the result).
    pub fn new(cfg: &NavConfig, record: bool) -> Result<Self, PipelineError> {
        let proc = ImuProcessor::new(&cfg.processing)?;
        let mut procedures = Vec::new();
        for make in REGISTRY {
            if let Some(m) = make(cfg)? {
                procedures.push(Running {
                    m,
                    rep: Reporting::default(),
                    handed_over: false,
                });
            }
        }
        Ok(Self {
            rate_hz: cfg.imu.rate_hz,
            sample_ns: 1e9 / cfg.imu.rate_hz,
            coning_samples: cfg.processing.coning_samples,
            gps_expected: cfg.gps.is_some(),
            record,
            fe: ImuFrontEnd::new(cfg.imu),
            fir: proc.fir_response(),
            proc,
            coning_method: cfg.processing.coning,
            procedures,
            navigator: cfg
                .navigation
                .enabled
                .then(|| Navigator::new(cfg.navigation.clone())),
            out_every: (cfg.imu.rate_hz / 50.0).round().max(1.0) as u64,
            next_out: None,
            encoder: SolutionEncoder::default(),
            last_mode: None,
            frames: FrameCounters::default(),
            sums: Sums::default(),
            imu_heard: false,
            imu_timeout: false,
            timeouts: 0,
            fixes: 0,
            last_fix: None,
            decoder: crate::frontend::gps_receiver::GpsDecoder::default(),
            decoded: Vec::new(),
            gps_rx_bytes: 0,
            gps_bad_at: None,
            can: Default::default(),
            can_error_at: None,
            sent_hash: FNV_OFFSET,
            encode_errors: 0,
            integrity: None,
            filter_resets: (0, 0),
            samples: Vec::new(),
            events: Vec::new(),
            updates: Vec::new(),
            sol_frames: Vec::new(),
        })
    }

    /// One data frame from the bus.
    pub fn on_frame(&mut self, raw: &RawFrame, out: &mut Vec<Output>) {
        let from = out.len();
        self.on_frame_inner(raw, out);
        self.seal(out, from);
    }

    /// Fold what was just asked to go out (`out[from..]`) into the hash of what was sent.
    fn seal(&mut self, out: &[Output], from: usize) {
        let k = self.sums.last.unwrap_or(0);
        for o in out.get(from..).unwrap_or(&[]) {
            if let Output::Command(f) | Output::Solution(f) = o {
                let mut h = self.sent_hash;
                for b in k
                    .to_le_bytes()
                    .iter()
                    .chain(f.id.to_le_bytes().iter())
                    .chain(std::iter::once(&f.len))
                    .chain(f.payload())
                {
                    h = (h ^ u64::from(*b)).wrapping_mul(FNV_PRIME);
                }
                self.sent_hash = h;
            }
        }
    }

    /// A hash (FNV-1a, 64 bits, hex) over every frame the pipeline sent, each with the IMU
    /// sample it was sent at: two runs that sent the same frames at the same samples have the
    /// same hash.
    pub fn sent_hash(&self) -> String {
        format!("{:016x}", self.sent_hash)
    }

    /// Bytes from the GPS receiver's port, as read, in their place among the frames: decoded
    /// here, each fix to navigation ([`Pipeline::on_fix`]) and out for the shell's export.
    pub fn on_gps_bytes(&mut self, bytes: &[u8], out: &mut Vec<Output>) {
        let from = out.len();
        self.gps_rx_bytes += bytes.len() as u64;
        let bad = |s: &crate::frontend::gps_receiver::GpsStats| {
            s.garbage_bytes + s.binary_lines + s.overlong_lines + s.bad_checksum + s.unparsed
        };
        let before = bad(&self.decoder.stats());
        self.decoder.push_bytes(bytes, &mut self.decoded);
        if bad(&self.decoder.stats()) > before {
            self.gps_bad_at = Some(self.sums.last.unwrap_or(0));
        }
        let fixes = std::mem::take(&mut self.decoded);
        for f in fixes {
            out.push(Output::Fix(Box::new(f.clone())));
            self.on_fix_inner(f, out);
        }
        for a in self.decoder.take_accuracies() {
            if let Some(n) = self.navigator.as_mut() {
                n.on_accuracy(&a);
            }
        }
        self.seal(out, from);
    }

    /// The receiver's port opened (`open`) or went away (`why`): recorded as an event
    /// (`gps_port`), where it happened among the frames.
    pub fn on_gps_port(&mut self, open: bool, why: &str, out: &mut Vec<Output>) {
        let json = serde_json::json!({"kind": "gps_port", "open": open, "why": why}).to_string();
        self.json(JsonChannel::Event, self.sums.last.unwrap_or(0), json, out);
    }

    /// The receiver's stream counters (bytes, lines, sentences, what was wrong).
    pub fn gps_stats(&self) -> crate::frontend::gps_receiver::GpsStats {
        self.decoder.stats()
    }

    fn on_frame_inner(&mut self, raw: &RawFrame, out: &mut Vec<Output>) {
        self.frames.total += 1;
        // the IMU is back with its first gyro frame, before that frame is processed: whatever
        // the shell read in one go with it, every epoch it makes is without the timeout bit
        if self.imu_timeout && raw.id == wire::imu_gyro::SPEC.id {
            self.set_imu_timeout(false, 0, out);
        }
        // 1. decode
        let m = match Message::decode(raw) {
            Ok(m) => m,
            Err(e) => {
                self.bad_frame(&e, raw, out);
                return;
            }
        };
        *self.frames.by_message.entry(m.spec().name).or_insert(0) += 1;
        // 2. the indexing mechanism's frames, to the procedure commanding it; a status frame
        // is stamped with the end of the last sample nav has (on the bench it follows the
        // sample it was taken at)
        let t_last = self.last_sample_time();
        for r in &mut self.procedures {
            match &m {
                Message::TtStatus(st) => {
                    r.rep.frames += 1;
                    r.m.procedure().status(t_last, st);
                }
                Message::TtAck(a) => {
                    r.rep.frames += 1;
                    r.m.procedure().ack(a);
                }
                Message::MemsGyro(g) => {
                    if let Some(k) = self.sums.last
                        && r.m.on_mems(k, t_last, self.sample_ns * 1e-9, g)
                    {
                        r.rep.frames += 1;
                    }
                }
                _ => {}
            }
        }
        // 3. the IMU front end
        self.imu_heard |= matches!(m, Message::ImuGyro(_) | Message::ImuAccel(_));
        self.fe.on_message(&m, &mut self.samples, &mut self.events);
        // 4, 5. processing, north-finding and navigation
        self.process(out);
        self.hand_over();
        // 6. the procedures' commands and progress
        self.procedures_step(out);
        // 7. the solution at 50 Hz of IMU time
        self.solution(out);
        self.integrity_changes(out);
    }

    /// The integrity monitor's alarm came on or went off: said in the log and the recording
    /// (the solution's `filter` health bit follows it, [`Pipeline::health`]).
    fn integrity_changes(&mut self, out: &mut Vec<Output>) {
        self.filter_resets(out);
        self.rejected_fixes(out);
        let now = self
            .navigator
            .as_ref()
            .and_then(|n| n.integrity().symptom());
        if now == self.integrity {
            return;
        }
        self.integrity = now;
        let t = self.navigator.as_ref().map_or(0.0, |n| n.time());
        match now {
            Some(s) => warn!("navigation integrity alarm at {t:.1} s: {s}"),
            None => info!("navigation integrity alarm cleared at {t:.1} s"),
        }
        let json = serde_json::json!({
            "kind": "integrity",
            "alarm": now.is_some(),
            "symptom": now.map(|s| format!("{s:?}")),
            "t_s": t,
        });
        self.json(
            JsonChannel::Event,
            self.sums.last.unwrap_or(0),
            json.to_string(),
            out,
        );
    }

    /// The filter re-anchored on the receiver or folded an open-loop estimate that left the
    /// linear range: a `filter` event in the recording (the log has the filter's warning).
    /// Each fix the filter's gate refused, in the recording (`fix_rejected`): where it was,
    /// for the report's track.
    /// Without a recording they stay with the navigator ([`Pipeline::take_rejected_fixes`]).
    fn rejected_fixes(&mut self, out: &mut Vec<Output>) {
        if !self.record {
            return;
        }
        let Some(n) = self.navigator.as_mut() else {
            return;
        };
        for r in n.take_rejected() {
            let mut json = serde_json::to_value(r).unwrap_or_default();
            json["kind"] = "fix_rejected".into();
            self.json(
                JsonChannel::Event,
                self.sums.last.unwrap_or(0),
                json.to_string(),
                out,
            );
        }
    }

    fn filter_resets(&mut self, out: &mut Vec<Output>) {
        let Some(n) = self.navigator.as_ref() else {
            return;
        };
        let Some(f) = n.filter().map(|k| k.stats()) else {
            return;
        };
        let now = (f.reanchors, f.relinearised);
        if now == self.filter_resets {
            return;
        }
        let what = if now.0 > self.filter_resets.0 {
            "reanchored on the receiver after a run of rejected fixes"
        } else {
            "open-loop error estimate left the linear range and was folded into the navigation state"
        };
        self.filter_resets = now;
        let json = serde_json::json!({
            "kind": "filter",
            "what": what,
            "reanchors": now.0,
            "relinearised": now.1,
            "t_s": n.time(),
        });
        self.json(
            JsonChannel::Event,
            self.sums.last.unwrap_or(0),
            json.to_string(),
            out,
        );
    }

    /// An error frame from nav's CAN controller (`CAN_RAW_ERR_FILTER`): counted by class, the
    /// controller's state and counters followed, the health bit set (bus errors in the last
    /// second of IMU time, or a controller error-passive or bus-off), recorded as an event.
    pub fn on_can_error(&mut self, e: &wire::errframe::ErrorFrame, out: &mut Vec<Output>) {
        use wire::errframe::{ErrorState, class};
        let c = &mut self.can;
        c.error_frames += 1;
        if e.class & (class::PROT | class::BUSERROR) != 0 {
            c.bus_errors += 1;
        }
        if let Some((tec, rec)) = e.counters() {
            c.tx_errors = tec;
            c.rx_errors = rec;
            c.max_tx_errors = c.max_tx_errors.max(tec);
            c.max_rx_errors = c.max_rx_errors.max(rec);
        }
        if let Some(st) = e.state() {
            match st {
                ErrorState::Warning => c.warnings += 1,
                ErrorState::Passive => c.passives += 1,
                ErrorState::BusOff => c.bus_offs += 1,
                ErrorState::Active => {}
            }
            if e.class & class::RESTARTED != 0 {
                c.restarts += 1;
            }
            c.state = CanBusHealth::name(st).into();
            if CanBusHealth::rank(&c.worst_state) < CanBusHealth::rank(c.state.as_str()) {
                c.worst_state = c.state.clone();
            }
        }
        if e.class & !(class::CNT | class::RESTARTED) != 0 && e.state() != Some(ErrorState::Active)
        {
            self.can_error_at = Some(self.sums.last.unwrap_or(0));
        }
        if self.can.error_frames <= 20 {
            warn!("CAN controller: {}", e.describe());
        }
        if self.record {
            let json = serde_json::json!({
                "kind": "can_error",
                "class": e.class,
                "detail": e.describe(),
                "state": self.can.state,
            });
            self.json(
                JsonChannel::Event,
                self.fe.stats().samples,
                json.to_string(),
                out,
            );
        }
    }

    /// A remote or other non-data frame (`what` says which): counted and recorded, otherwise
    /// ignored.
    pub fn on_non_data(&mut self, what: &str, out: &mut Vec<Output>) {
        self.frames.total += 1;
        self.frames.non_data += 1;
        if self.frames.non_data <= 5 {
            warn!("ignored: {what}");
        }
        if self.record {
            let json = serde_json::json!({"kind": "non_data_frame", "detail": what});
            self.json(
                JsonChannel::Event,
                self.fe.stats().samples,
                json.to_string(),
                out,
            );
        }
    }

    /// A decoded GPS fix arrived (from a recording made before nav kept the receiver's bytes;
    /// the shell gives the bytes, [`Pipeline::on_gps_bytes`]).
    pub fn on_fix(&mut self, fix: GpsFix, out: &mut Vec<Output>) {
        let from = out.len();
        self.on_fix_inner(fix, out);
        self.seal(out, from);
    }

    fn on_fix_inner(&mut self, fix: GpsFix, out: &mut Vec<Output>) {
        self.fixes += 1;
        if self.record
            && let Ok(json) = serde_json::to_string(&fix)
        {
            let now = self.sums.last.unwrap_or(0);
            self.json(JsonChannel::Gps, now, json, out);
        }
        if let Some(n) = self.navigator.as_mut() {
            n.on_fix(&fix);
        }
        self.last_fix = Some(fix);
        self.integrity_changes(out);
    }

    /// The shell's liveness watchdog (wall time): IMU frames stopped (`true`) or came back. It
    /// sets the solution's `imu_timeout` health bit; both changes are recorded as events
    /// (`imu_timeout`, `imu_back`) so that a replay of the recording applies them where they
    /// happened. The pipeline itself clears it at the first IMU_GYRO frame after a timeout
    /// ([`Pipeline::on_frame`]), so where the shell's reads happen to split the stream does not
    /// change the solution frames.
    pub fn set_imu_timeout(&mut self, active: bool, after_ms: u64, out: &mut Vec<Output>) {
        let from = out.len();
        self.set_imu_timeout_inner(active, after_ms, false, out);
        self.seal(out, from);
    }

    /// The end of an in-process stream, as nav's watchdog reports it on the bench: what
    /// [`Pipeline::set_imu_timeout`] does, logged as the end it is rather than as a warning.
    pub fn stream_ended(&mut self, after_ms: u64, out: &mut Vec<Output>) {
        let from = out.len();
        self.set_imu_timeout_inner(true, after_ms, true, out);
        self.seal(out, from);
    }

    fn set_imu_timeout_inner(
        &mut self,
        active: bool,
        after_ms: u64,
        at_end: bool,
        out: &mut Vec<Output>,
    ) {
        if active == self.imu_timeout {
            return;
        }
        self.imu_timeout = active;
        if active {
            self.timeouts += 1;
            let last = self
                .sums
                .last
                .map_or_else(|| "no sample yet".into(), |k| format!("last sample {k}"));
            if at_end {
                tracing::debug!("the IMU stream ended ({last})");
            } else {
                warn!("no IMU frame for {after_ms} ms ({last})");
            }
            let json = format!("{{\"kind\":\"imu_timeout\",\"after_ms\":{after_ms}}}");
            self.json(JsonChannel::Event, self.sums.last.unwrap_or(0), json, out);
            // the solution epochs follow IMU time and stop with it: one more epoch now tells
            // whoever reads NAV_TIME that the solution is no longer current
            if let Some(last) = self.sums.last {
                self.emit_solution(last, out);
            }
        } else {
            info!("IMU data back");
            let json = "{\"kind\":\"imu_back\"}".to_string();
            self.json(JsonChannel::Event, self.sums.last.unwrap_or(0), json, out);
        }
    }

    /// IMU gyro frames received so far (the shell's watchdog watches it grow).
    pub fn gyro_frames(&self) -> u64 {
        self.fe.stats().gyro_frames
    }

    /// End of the stream: a sample still waiting for its accelerometer frame is processed.
    pub fn flush(&mut self, out: &mut Vec<Output>) {
        let from = out.len();
        self.fe.flush(&mut self.samples, &mut self.events);
        self.process(out);
        self.seal(out, from);
    }

    /// IMU time of sample `k`, s (from the front end's first sample).
    fn imu_time(&self, k: i64) -> f64 {
        let base = self.proc.baseline().map_or(0, |b| b as i64);
        (k - base) as f64 * self.sample_ns * 1e-9
    }

    /// Steps 4 and 5: the samples the front end produced, through processing, to north-finding
    /// and navigation.
    fn process(&mut self, out: &mut Vec<Output>) {
        for e in self.events.drain(..) {
            match e {
                ImuEvent::Gap { .. } | ImuEvent::AccelMissing { .. } => {
                    tracing::debug!("IMU: {e:?}")
                }
                _ => warn!("IMU: {e:?}"),
            }
            if self.record
                && let Ok(json) = serde_json::to_string(&e)
            {
                out.push(Output::Json {
                    channel: JsonChannel::Event,
                    publish_ns: 0,
                    json,
                });
            }
        }
        let samples = std::mem::take(&mut self.samples);
        for s in &samples {
            self.sums.add_sample(s);
            if let Some(b) = self.proc.baseline()
                && !s.ambiguous
            {
                let t1 = (s.sample as i64 - b as i64) as f64 * self.sample_ns * 1e-9;
                let dt = f64::from(s.span) * self.sample_ns * 1e-9;
                for r in &mut self.procedures {
                    r.m.on_sample(t1, dt, s);
                }
            }
            let invalid_before = self.proc.stats().invalid_since.is_some();
            self.proc.push_sample(s, &mut self.updates);
            // the PPS edge came `o` samples before the end of this sample
            if let (Some(n), Some(o), Some(b)) =
                (self.navigator.as_mut(), s.pps_offset, self.proc.baseline())
            {
                let t = ((s.sample - b) as f64 - o) * self.sample_ns * 1e-9;
                if !n.on_pps(t) && self.record {
                    out.push(Output::Json {
                        channel: JsonChannel::Event,
                        publish_ns: (t.max(0.0) * 1e9) as u64,
                        json: format!("{{\"kind\":\"pps_rejected\",\"imu_time_s\":{t:.6}}}"),
                    });
                }
            }
            if !invalid_before && let Some(k) = self.proc.stats().invalid_since {
                warn!("attitude invalid from sample {k}: counter gap too long to difference");
            }
            let updates = std::mem::take(&mut self.updates);
            for u in &updates {
                let t = self.imu_time(u.valid_sample);
                for r in &mut self.procedures {
                    r.m.on_update(t, u.phi, u.dv);
                }
                // navigation takes over once the procedure (when one runs) is finished
                let phase = self.phase();
                if let Some(n) = self.navigator.as_mut() {
                    if phase == MissionPhase::Navigating {
                        n.on_update(
                            t,
                            u.phi,
                            u.dv,
                            self.coning_samples as f64 * self.sample_ns * 1e-9,
                        );
                    } else {
                        n.on_time(t);
                    }
                }
                self.sums.add_update(u);
                if self.record && self.sums.updates.is_multiple_of(50) {
                    let rv =
                        quaternion_to_rotation_vector(&self.proc.attitude()).map(f64::to_degrees);
                    out.push(Output::Json {
                        channel: JsonChannel::Attitude,
                        publish_ns: (u.valid_sample.max(0) as f64 * self.sample_ns) as u64,
                        json: format!(
                            "{{\"valid_sample\":{},\"rotation_vector_deg\":[{:.9},{:.9},{:.9}]}}",
                            u.valid_sample, rv[0], rv[1], rv[2]
                        ),
                    });
                }
            }
            self.updates = updates;
            self.updates.clear();
            if self.record {
                out.push(Output::Sample {
                    publish_ns: (s.sample as f64 * self.sample_ns) as u64,
                    sample: *s,
                });
            }
        }
        self.samples = samples;
        self.samples.clear();
    }

    /// The hand-over: the heading a procedure found (north-finding's) goes to the navigator
    /// once, when it is found.
    fn hand_over(&mut self) {
        let Some(n) = self.navigator.as_mut() else {
            return;
        };
        for r in &mut self.procedures {
            if !r.handed_over
                && let Some(h) = r.m.heading_deg()
            {
                n.set_heading(h, r.m.heading_sigma_deg());
                r.handed_over = true;
            }
        }
    }

    /// The mission's phase: a procedure on the mechanism running holds the IMU's updates; once
    /// none is, they are navigation's (when it is configured).
    pub fn phase(&self) -> MissionPhase {
        if self
            .procedures
            .iter()
            .any(|r| !r.m.procedure_ref().is_finished())
        {
            MissionPhase::Procedure
        } else if self.navigator.is_some() {
            MissionPhase::Navigating
        } else {
            MissionPhase::Processing
        }
    }

    /// IMU time of the end of the last sample, s.
    fn last_sample_time(&self) -> f64 {
        let base = self.proc.baseline().map_or(0, |b| b as i64);
        self.sums
            .last
            .map_or(0.0, |k| (k as i64 - base) as f64 * self.sample_ns * 1e-9)
    }

    /// Step 6 for one procedure at IMU time `t`: its commands, its progress lines (at most once
    /// a second of IMU time and at every stage change), and once its result or the reason it
    /// gave up. True when it has just finished.
    fn drive(
        p: &mut dyn Procedure,
        rep: &mut Reporting,
        t: f64,
        record: bool,
        encode_errors: &mut u64,
        out: &mut Vec<Output>,
    ) -> bool {
        while let Some(c) = p.next_command(t.max(0.0)) {
            match Message::TtCmd(c).encode() {
                Ok(f) => {
                    out.push(Output::Command(f));
                    rep.commands_sent += 1;
                }
                Err(e) => {
                    *encode_errors += 1;
                    warn!("TT_CMD {c:?} cannot be encoded: {e}");
                }
            }
            if p.is_finished() {
                break;
            }
        }
        let name = p.name();
        let stage = p.stage_key();
        let due = rep.last_print.is_none_or(|l| t - l >= 1.0) && !p.is_finished();
        if rep.last_stage != Some(stage) || due {
            rep.last_print = Some(t);
            rep.last_stage = Some(stage);
            if let Some(j) = p.progress_json() {
                out.push(Output::Line(format!("nav: {name} progress {j}")));
                if record {
                    let kind = name.replace('-', "_");
                    out.push(Output::Json {
                        channel: JsonChannel::Event,
                        publish_ns: (t.max(0.0) * 1e9) as u64,
                        json: format!("{{\"kind\":\"{kind}_progress\",\"progress\":{j}}}"),
                    });
                }
            }
        }
        if !p.is_finished() || rep.reported {
            return false;
        }
        rep.reported = true;
        if let Some(j) = p.result_json() {
            info!("{name} finished: {j}");
            out.push(Output::Line(format!("nav: {name} result {j}")));
        } else {
            let why = p.abort().unwrap_or("unknown");
            warn!("{name} aborted: {why}");
            out.push(Output::Line(format!("nav: {name} aborted: {why}")));
        }
        true
    }

    /// Step 6 for each procedure, at the IMU time it runs on (the processing chain's valid
    /// sample, or the end of the last sample); once one finishes, the parameter file it made.
    fn procedures_step(&mut self, out: &mut Vec<Output>) {
        // a procedure runs on IMU time: before the IMU's first frame it has no clock to keep
        // the mechanism's heartbeat on, so it commands nothing (a mechanism enabled then would
        // time out waiting for the next heartbeat, however long the IMU takes to start)
        if !self.imu_heard {
            return;
        }
        let base = self.proc.baseline().map_or(0, |b| b as i64);
        let t_valid = self.proc.valid_sample().saturating_sub(base) as f64 / self.rate_hz;
        let t_last = self.last_sample_time();
        let record = self.record;
        for r in &mut self.procedures {
            let t = if r.m.on_valid_sample() {
                t_valid
            } else {
                t_last
            };
            if Self::drive(
                r.m.procedure(),
                &mut r.rep,
                t,
                record,
                &mut self.encode_errors,
                out,
            ) && let Some((path, file)) = r.m.made()
                && let Some(path) = path
            {
                out.push(Output::Parameters {
                    path,
                    file: Box::new(file),
                });
            }
        }
    }

    /// The redundant unit's calibration (when enabled).
    pub fn tetra_calibrator(&self) -> Option<&TetraCalibrator> {
        self.mission::<crate::procedures::tetra_calibration::TetraCalibration>()
            .map(|c| &c.cal)
    }

    /// The self-calibration procedure (when enabled).
    pub fn calibrator(&self) -> Option<&SelfCalibrator> {
        self.mission::<crate::procedures::self_calibration::SelfCalibration>()
            .map(|c| &c.cal)
    }

    /// The procedure of type `M`, when the config runs it.
    fn mission<M: 'static>(&self) -> Option<&M> {
        self.procedures
            .iter()
            .find_map(|r| r.m.as_any().downcast_ref::<M>())
    }

    /// The solution's mode: self-calibration or north-finding while it runs, then the
    /// navigator's.
    pub fn mode(&self) -> wire::NavMode {
        match self.phase() {
            MissionPhase::Procedure => self
                .procedures
                .iter()
                .find(|r| !r.m.procedure_ref().is_finished())
                .map_or(wire::NavMode::Init, |r| r.m.mode()),
            MissionPhase::Navigating => self
                .navigator
                .as_ref()
                .map_or(wire::NavMode::Init, |n| n.mode()),
            MissionPhase::Processing => wire::NavMode::Init,
        }
    }

    /// The solution's health bits.
    pub fn health(&self) -> wire::NavHealth {
        let st = self.fe.stats();
        let nav = self.navigator.as_ref();
        wire::NavHealth {
            imu_timeout: self.imu_timeout,
            imu_gaps: st.gaps > 0,
            imu_bit: st.bit_fail_samples > 0,
            gps_stale: self.gps_expected && nav.is_none_or(|n| n.gps_stale()),
            turntable: self
                .procedures
                .iter()
                .any(|r| r.m.procedure_ref().abort().is_some() || r.m.mechanism_lost()),
            filter: self.proc.stats().invalid_since.is_some()
                || nav.is_some_and(|n| {
                    n.filter().is_some_and(|k| k.stats().reanchors > 0)
                        || n.integrity().symptom().is_some()
                }),
            gps_data: self
                .gps_bad_at
                .zip(self.sums.last)
                .is_some_and(|(b, k)| (k.saturating_sub(b) as f64) < self.rate_hz),
            can_bus: CanBusHealth::rank(&self.can.state) >= 2
                || self
                    .can_error_at
                    .zip(self.sums.last)
                    .is_some_and(|(b, k)| (k.saturating_sub(b) as f64) < self.rate_hz),
        }
    }

    /// Step 7: the solution epoch, every `rate / 50` samples of IMU time.
    fn solution(&mut self, out: &mut Vec<Output>) {
        let Some(last) = self.sums.last else { return };
        if last < *self.next_out.get_or_insert(last) {
            return;
        }
        self.next_out = Some(last + self.out_every);
        self.emit_solution(last, out);
    }

    /// One solution epoch (NAV_TIME and, once navigating, the rest) at IMU sample `last`.
    fn emit_solution(&mut self, last: u64, out: &mut Vec<Output>) {
        let mode = self.mode();
        let sigmas = self.navigator.as_ref().and_then(|n| n.sigmas());
        let solution = Solution {
            sample_count: last,
            mode,
            health: self.health(),
            output: self
                .navigator
                .as_ref()
                .and_then(|n| n.state())
                .map(|x| x.output()),
            pos_sigma_m: sigmas.map_or(0.0, |x| x.0),
            heading_sigma_deg: sigmas.map_or(0.0, |x| x.1),
            gps_rx_bytes: self.gps_rx_bytes,
        };
        // once a second of IMU time, the solution goes in the recording too
        if self.record
            && self.encoder.epochs.is_multiple_of(50)
            && let (Some(o), Some(n)) = (&solution.output, &self.navigator)
        {
            let mut j = serde_json::json!({
                "t_s": n.time(),
                "mode": format!("{mode:?}"),
                "output": o,
                "pos_sigma_m": solution.pos_sigma_m,
                "heading_sigma_deg": solution.heading_sigma_deg,
            });
            if let Some(c) = n.position_covariance_enu() {
                j["pos_cov_enu_m2"] = serde_json::json!(c);
            }
            if let Some(c) = n.velocity_covariance_enu() {
                j["vel_cov_enu_m2s2"] = serde_json::json!(c);
            }
            if let Some(a) = n.attitude_sigmas_deg() {
                j["att_sigma_enu_deg"] = serde_json::json!(a);
            }
            out.push(Output::Json {
                channel: JsonChannel::Solution,
                publish_ns: (last as f64 * self.sample_ns) as u64,
                json: j.to_string(),
            });
        }
        self.encoder.encode(&solution, &mut self.sol_frames);
        self.last_mode = Some(format!("{mode:?}"));
        out.extend(self.sol_frames.drain(..).map(Output::Solution));
    }

    fn bad_frame(&mut self, e: &DecodeError, raw: &RawFrame, out: &mut Vec<Output>) {
        let c = &mut self.frames;
        let first = match e {
            DecodeError::UnknownId { id } => {
                let n = c.unknown.entry(*id).or_insert(0);
                *n += 1;
                *n == 1
            }
            DecodeError::WrongLength { .. } => {
                c.bad_length += 1;
                c.bad_length <= 5
            }
            _ => {
                c.invalid += 1;
                c.invalid <= 5
            }
        };
        let sample = self.fe.stats().samples;
        if first {
            warn!(
                "bad frame near IMU sample {sample}: {e} (data {:02X?})",
                raw.payload()
            );
        }
        if self.record {
            let json = serde_json::json!({"kind": "bad_frame", "sample": sample, "id": raw.id, "len": raw.len, "error": e.to_string()});
            out.push(Output::Json {
                channel: JsonChannel::Event,
                publish_ns: 0,
                json: json.to_string(),
            });
        }
    }

    fn json(&self, channel: JsonChannel, sample: u64, json: String, out: &mut Vec<Output>) {
        if self.record {
            out.push(Output::Json {
                channel,
                publish_ns: (sample as f64 * self.sample_ns) as u64,
                json,
            });
        }
    }

    /// The front end.
    pub fn front_end(&self) -> &ImuFrontEnd {
        &self.fe
    }

    /// The processing chain.
    pub fn processor(&self) -> &ImuProcessor {
        &self.proc
    }

    /// The fixes the filter's gate refused since the last call, for an in-process run that
    /// scores them (a pipeline that records puts them in its recording instead; the
    /// navigator keeps the latest few dozen).
    pub fn take_rejected_fixes(&mut self) -> Vec<crate::navigation::navigator::RejectedFix> {
        self.navigator
            .as_mut()
            .map(Navigator::take_rejected)
            .unwrap_or_default()
    }

    /// The north-finder (when enabled).
    pub fn finder(&self) -> Option<&NorthFinder> {
        self.mission::<crate::procedures::north_finding::NorthFinding>()
            .map(|n| &n.finder)
    }

    /// The navigator (when enabled).
    pub fn navigator(&self) -> Option<&Navigator> {
        self.navigator.as_ref()
    }

    /// The frame counters.
    pub fn frames(&self) -> &FrameCounters {
        &self.frames
    }

    /// Fixes received, and the last one.
    pub fn fixes(&self) -> (u64, Option<&GpsFix>) {
        (self.fixes, self.last_fix.as_ref())
    }

    /// Solution epochs encoded.
    pub fn solution_epochs(&self) -> u64 {
        self.encoder.epochs
    }

    /// The last sample processed.
    pub fn last_sample(&self) -> Option<u64> {
        self.sums.last
    }

    /// The summary of the run so far with what only the shell knows (its devices, their I/O
    /// counts, the files it wrote): the binary's summary file.
    pub fn summary_with(&self, io: crate::summary::ShellCounts) -> Summary {
        let mut s = self.summary();
        s.interface = io.interface;
        s.read_errors = io.read_errors;
        s.command_send_errors = io.command_send_errors;
        for (file, p) in io.parameter_files {
            match p {
                crate::procedures::unit_parameters::ParameterFile::Imu(p) => {
                    if let Some(sc) = s.self_calibration.as_mut() {
                        sc.parameters = Some(p);
                        sc.parameters_file = file;
                    }
                }
                crate::procedures::unit_parameters::ParameterFile::Redundant(p) => {
                    if let Some(tc) = s.tetra_calibration.as_mut() {
                        tc.parameters = Some(p);
                        tc.parameters_file = file;
                    }
                }
            }
        }
        s.process_uid = io.process_uid;
        s.kernel_dropped_frames = io.kernel_dropped_frames;
        s.wall_seconds = io.wall_seconds;
        s.solution.frames_sent = io.frames_sent;
        s.solution.send_errors = io.send_errors;
        s.mcap = io.mcap;
        s.gps = io.gps.map(|g| {
            let (fixes, last_fix) = self.fixes();
            crate::summary::GpsSummary {
                port: g.port,
                stats: self.gps_stats(),
                port_errors: g.port_errors,
                opens: g.opens,
                reads_released_by_wait: g.reads_released_by_wait,
                fixes,
                last_fix: last_fix.cloned(),
                fixes_jsonl: g.fixes_jsonl,
            }
        });
        s
    }

    /// The run's summary (the shell fills in what only it knows: interface, read errors, wall
    /// time, the GPS port, the frames it sent, the recording).
    pub fn summary(&self) -> Summary {
        let dt = 1.0 / self.rate_hz;
        let n = (self.sums.updates * self.coning_samples as u64).max(1) as f64;
        let mean_rate_dph = self
            .sums
            .phi
            .map(|x| x / (n * dt) * earth::DEG_PER_HOUR_PER_RAD_S);
        let mean_f = self.sums.dv.map(|x| x / (n * dt));
        let pst = self.proc.stats();
        let q = self.proc.attitude();
        let attitude = AttitudeSummary {
            baseline_sample: self.proc.baseline(),
            origin_sample: self.proc.origin(),
            valid_sample: self.proc.valid_sample(),
            span_samples: self.proc.valid_sample() - self.proc.origin().unwrap_or(0),
            rotation_vector_deg: quaternion_to_rotation_vector(&q).map(f64::to_degrees),
            angle_deg: q.angle().to_degrees(),
            valid: pst.invalid_since.is_none(),
            delay_samples: self.proc.delay(),
            fir: self.fir,
            coning_method: self.coning_method,
            coning_coefficients: self.proc.coefficients().k.clone(),
        };
        let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let c = &self.frames;
        let mut s = Summary {
            interface: String::new(),
            frames_total: c.total,
            frames_by_message: c
                .by_message
                .iter()
                .map(|(k, v)| (k.to_string(), *v))
                .collect(),
            unknown_id_frames: c.unknown.values().sum(),
            unknown_ids: c.unknown.keys().map(|id| format!("0x{id:03X}")).collect(),
            bad_length_frames: c.bad_length,
            invalid_value_frames: c.invalid,
            non_data_frames: c.non_data,
            can_bus: self.can.clone(),
            read_errors: 0,
            command_send_errors: 0,
            kernel_dropped_frames: 0,
            process_uid: None,
            imu: self.fe.stats(),
            max_safe_gap_samples: self.fe.max_span(),
            first_sample: self.sums.first,
            last_sample: self.sums.last,
            imu_seconds: self.sums.samples as f64 * dt,
            wall_seconds: 0.0,
            imu_timeouts: self.timeouts,
            mean_rate_dph,
            mean_specific_force_mps2: mean_f,
            rate_norm_dph: norm(mean_rate_dph),
            specific_force_norm_mps2: norm(mean_f),
            processing: pst,
            attitude,
            north_finding: None,
            self_calibration: None,
            tetra_calibration: None,
            gps: None,
            navigation: self.navigator.as_ref().map(|n| n.summary()),
            housekeeping: self.fe.housekeeping(),
            solution: crate::summary::SolutionSummary {
                epochs: self.encoder.epochs,
                frames_sent: 0,
                send_errors: 0,
                last_mode: self.last_mode.clone(),
                sent_hash: self.sent_hash(),
                backwards: self.encoder.backwards,
            },
            encode_errors: self.encode_errors + self.encoder.encode_errors,
            mcap: None,
            mcap_messages: 0,
        };
        for r in &self.procedures {
            crate::summary::put_section(&mut s, r.m.as_ref(), &r.rep);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wire::{ImuAccel, ImuGyro, NavMode};

    fn config(extra: &str) -> NavConfig {
        toml::from_str(&format!("[can]\ninterface = \"can0\"\n{extra}")).unwrap()
    }

    /// The frames of IMU sample `k` of a unit at rest (counters still).
    fn sample(k: u64) -> [RawFrame; 2] {
        [
            Message::ImuGyro(ImuGyro {
                counts: [0; 3],
                sample_counter: k as u16,
            })
            .encode()
            .unwrap(),
            Message::ImuAccel(ImuAccel {
                counts: [0; 3],
                sample_counter_low: (k & 0xF) as u8,
                pps_offset: None,
                bit_fail: false,
                saturated: false,
            })
            .encode()
            .unwrap(),
        ]
    }

    fn nav_times(out: &[Output]) -> Vec<wire::NavTime> {
        out.iter()
            .filter_map(|o| match o {
                Output::Solution(f) => match Message::decode(f) {
                    Ok(Message::NavTime(t)) => Some(t),
                    _ => None,
                },
                _ => None,
            })
            .collect()
    }

    #[test]
    fn the_solution_goes_out_every_40_samples_and_bad_frames_are_counted() {
        let mut p = Pipeline::new(&config(""), false).unwrap();
        let mut out = Vec::new();
        for k in 0..=400 {
            for f in sample(k) {
                p.on_frame(&f, &mut out);
            }
        }
        let unknown = RawFrame {
            id: 0x7EE,
            len: 2,
            data: [1, 2, 0, 0, 0, 0, 0, 0],
        };
        p.on_frame(&unknown, &mut out);
        let mut short = sample(401)[0];
        short.len = 3;
        p.on_frame(&short, &mut out);
        let t = nav_times(&out);
        assert_eq!(t.len(), 10, "{t:?}");
        for w in t.windows(2) {
            assert_eq!(w[1].sample_count - w[0].sample_count, 40);
            assert_eq!(w[1].seq, w[0].seq.wrapping_add(1));
        }
        assert!(
            t.iter()
                .all(|x| x.mode == NavMode::Init && !x.health.imu_timeout)
        );
        let c = p.frames();
        assert_eq!((c.total, c.bad_length), (804, 1));
        assert_eq!(c.unknown.get(&0x7EE), Some(&1));
        assert!(
            out.iter().all(|o| !matches!(o, Output::Json { .. })),
            "not recording"
        );
        let s = p.summary();
        assert_eq!(s.imu.samples, 400);
        assert_eq!(s.solution.epochs, 10);
    }

    #[test]
    fn the_watchdog_sets_the_health_bit_and_both_changes_are_recorded() {
        let mut p = Pipeline::new(&config(""), true).unwrap();
        let mut out = Vec::new();
        for f in sample(0).into_iter().chain(sample(1)) {
            p.on_frame(&f, &mut out);
        }
        p.set_imu_timeout(true, 100, &mut out);
        p.set_imu_timeout(true, 100, &mut out);
        // the timeout sends one more epoch, with the bit
        let t = nav_times(&out);
        assert!(t.last().is_some_and(|t| t.health.imu_timeout), "{t:?}");
        out.clear();
        // the first gyro frame brings the IMU back before it is processed: the epochs it
        // makes have no timeout bit, however the shell's reads split the frames; the shell's
        // own clearing afterwards changes nothing
        for k in 2..=41 {
            for f in sample(k) {
                p.on_frame(&f, &mut out);
            }
        }
        p.set_imu_timeout(false, 100, &mut out);
        let t = nav_times(&out);
        assert!(t.len() == 1 && !t[0].health.imu_timeout, "{t:?}");
        let events: Vec<&str> = out
            .iter()
            .filter_map(|o| match o {
                Output::Json { channel, json, .. } if *channel == JsonChannel::Event => {
                    Some(json.as_str())
                }
                _ => None,
            })
            .collect();
        assert_eq!(events, ["{\"kind\":\"imu_back\"}"]);
        assert_eq!(p.summary().imu_timeouts, 1);
    }

    /// The mechanism's status before the IMU's first frame (a table powered before the IMU
    /// streams): no command, since nothing would keep its heartbeat; the IMU's first frames
    /// start the procedure.
    #[test]
    fn no_command_goes_to_the_mechanism_before_the_imus_first_frame() {
        let cfg = config("[north_finding]\nenabled = true\nlatitude_deg = -33.9\n");
        let mut p = Pipeline::new(&cfg, false).unwrap();
        let mut out = Vec::new();
        let status = Message::TtStatus(wire::TtStatus {
            angle_deg: 0.0,
            rate_dps: 0.0,
            state: wire::TtState::Disabled,
            axis: 0,
            faults: Default::default(),
            ack_seq: 0,
            counter: 0,
        })
        .encode()
        .unwrap();
        for _ in 0..50 {
            p.on_frame(&status, &mut out);
        }
        assert!(
            !out.iter().any(|o| matches!(o, Output::Command(_))),
            "no IMU time yet, no command"
        );
        for k in 0..=40 {
            for f in sample(k) {
                p.on_frame(&f, &mut out);
            }
        }
        assert!(out.iter().any(|o| matches!(o, Output::Command(_))));
    }

    #[test]
    fn north_finding_commands_go_out_before_the_solution_that_follows_them() {
        let cfg = config("[north_finding]\nenabled = true\nlatitude_deg = -33.9\n");
        let mut p = Pipeline::new(&cfg, false).unwrap();
        let mut out = Vec::new();
        for k in 0..=200 {
            for f in sample(k) {
                p.on_frame(&f, &mut out);
            }
        }
        let first_cmd = out
            .iter()
            .position(|o| matches!(o, Output::Command(_)))
            .expect("the finder enables the mechanism");
        match &out[first_cmd] {
            Output::Command(f) => assert!(matches!(Message::decode(f), Ok(Message::TtCmd(_)))),
            _ => unreachable!(),
        }
        // the NAV_TIME after a command is what places it in time on the bench
        assert!(
            out[first_cmd..]
                .iter()
                .any(|o| matches!(o, Output::Solution(_)))
        );
        assert!(
            nav_times(&out)
                .iter()
                .all(|t| t.mode == NavMode::NorthFinding)
        );
        assert!(p.finder().is_some_and(|f| !f.is_finished()));
    }
}
