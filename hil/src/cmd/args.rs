//! Arguments several commands share: the bus (`--iface`, `--json`), the live view, a free-running
//! device under test.

use anyhow::{Result, bail};
use hil::scenario::Scenario;
use std::path::PathBuf;
use vcan_setup::{CanSupport, GUEST_ENV};

/// What every bench command on vcan takes: where, where to write, how to print.
#[derive(clap::Args, Clone)]
pub(crate) struct BusArgs {
    /// CAN interface (on the bench created when missing).
    #[arg(long, default_value = "vcan0")]
    pub(crate) iface: String,
    /// Output folder (default runs/<name>-<unix time>).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Print the report as JSON on stdout instead of the result card or table.
    #[arg(long)]
    pub(crate) json: bool,
    /// Always use the QEMU guest, even where this kernel has CAN.
    #[arg(long)]
    pub(crate) vm: bool,
}

/// The live view a run can be watched on.
#[derive(clap::Args, Clone, Default)]
pub(crate) struct LiveArgs {
    /// Serve a live view of the run over Foxglove's WebSocket protocol on ADDR (default
    /// 127.0.0.1:8765) for the command's whole length: open it in Foxglove or Lichtblick
    /// ("Open connection", "Foxglove WebSocket", ws://ADDR) with docs/foxglove-layout.json.
    /// Times are simulated time; the viewer's pause holds the run (its result does not change).
    /// Through the QEMU guest the port is forwarded to this host.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = hil::live::DEFAULT_ADDR)]
    pub(crate) live: Option<std::net::SocketAddr>,
    /// With --live: before the run starts, wait until N viewers have subscribed to every
    /// channel (at most 5 minutes), so that they see it from its first sample.
    #[arg(long, value_name = "N", default_value_t = 0, requires = "live")]
    pub(crate) live_wait: usize,
    /// The view, once started (a demo's parts share one).
    #[arg(skip)]
    pub(crate) view: Option<std::sync::Arc<hil::live::View>>,
}

impl LiveArgs {
    /// The view to run on: the one already started, or a new one (`true`: this caller owns it
    /// and finishes it), or none.
    pub(crate) fn view(
        &self,
        duration_s: f64,
    ) -> Result<(Option<std::sync::Arc<hil::live::View>>, bool)> {
        Ok(match (&self.view, self.live) {
            (Some(v), _) => (Some(v.clone()), false),
            (None, Some(addr)) => (
                Some(hil::live::View::start(addr, self.live_wait, duration_s)?),
                true,
            ),
            _ => (None, false),
        })
    }
}

/// Stop a live view this command started and say what its viewers got.
pub(crate) fn finish_view(v: std::sync::Arc<hil::live::View>) {
    let st = v.finish();
    for c in &st.clients {
        eprintln!(
            "hil: live view: client {}: {} messages sent, {} dropped (fell behind), {} subscriptions",
            c.peer, c.sent, c.dropped, c.subscriptions
        );
    }
    if st.clients.is_empty() {
        eprintln!(
            "hil: live view: nobody watched ({} messages published)",
            st.published
        );
    }
}

impl BusArgs {
    /// Whether the run goes here: this kernel has CAN and the guest was not asked for (or this
    /// is the guest). Otherwise the command runs again inside the QEMU guest.
    pub(crate) fn here(&self) -> bool {
        let in_guest = std::env::var_os(GUEST_ENV).is_some();
        (!self.vm || in_guest) && matches!(vcan_setup::can_support(), CanSupport::Available)
    }

    /// Defaults (vcan0, no JSON, the guest only where needed) writing to `out`.
    pub(crate) fn to(out: PathBuf) -> Self {
        Self {
            iface: "vcan0".into(),
            out: Some(out),
            json: false,
            vm: false,
        }
    }
}

/// A free-running run: the device under test as it runs in the vehicle.
#[derive(clap::Args, Clone, Default)]
pub(crate) struct FreeArgs {
    /// Free-running, as in the vehicle: the emulators run on the host's clock at x1 and wait
    /// for nobody; the device under test (our nav by default, or --dut) is judged by what it
    /// sends on the bus, by the DBC only: its heading against truth at the sample its NAV_TIME
    /// names, its latency from that sample on the bus, its output rate, its time tags, frames
    /// outside the DBC. The bench's own lateness is measured apart; when the host cannot keep
    /// real time the run stops with no verdict (exit status 3). Results are measured, not
    /// bit-identical (docs/your-device.md).
    #[arg(long)]
    pub(crate) free: bool,
    /// With --free: the device under test, a command run through `sh -c` with {iface}, {gps}
    /// (the receiver's port), {config} (the nav.toml the bench wrote for the scenario), {out}
    /// (its folder) and {nav} (our nav binary) replaced; `none`: nothing to start, the device
    /// is already on the interface. Default: our nav (--nav).
    #[arg(long, requires = "free")]
    pub(crate) dut: Option<String>,
    /// With --free: a device that is real, not emulated: `turntable=IFACE` (a table on the
    /// bench's interface; the IMU rides it as its TT_STATUS reports), `gps=PORT` (a receiver on
    /// a serial port, handed to the device under test). Repeatable.
    #[arg(long, value_name = "DEVICE=PORT", requires = "free")]
    pub(crate) real: Vec<String>,
    /// With --free: the device's latency budget, ms: the 99th percentile of IMU sample on
    /// the bus to the NAV_TIME naming it (default: the scenario's `[bus] latency_budget_ms`,
    /// else 50).
    #[arg(long, value_parser = hil::values::latency_budget_ms, requires = "free")]
    pub(crate) latency_budget_ms: Option<f64>,
    /// With --free: the device must send its first NAV_TIME within this long, s.
    #[arg(long, value_parser = hil::values::duration_s, default_value_t = 15.0, requires = "free")]
    pub(crate) answer_within: f64,
    /// With --free: the bench's own lateness beyond which it stops, ms.
    #[arg(long, default_value_t = 200.0, requires = "free")]
    pub(crate) max_late_ms: f64,
    /// With --free: how far ahead of the IMU's stream a NAV_TIME may name a sample (a device
    /// that states predictions), ms (default: one of the device's output periods).
    #[arg(long, value_parser = hil::values::latency_budget_ms, requires = "free")]
    pub(crate) lead_allowance_ms: Option<f64>,
    /// With --free: the bus speaks a lab's own contract, not ours: its mapping file, with the
    /// DBC it names beside it (docs/your-dbc.md). The emulated IMU and turntable send and
    /// take the lab's frames (29-bit identifiers, CAN FD, alive counters, checksums); the
    /// device's solution is read where the mapping's [solution] says, and its protected frames'
    /// checksums and alive counters are checked. {mapping} and {dbc} in --dut are replaced.
    #[arg(long, requires = "free")]
    pub(crate) mapping: Option<PathBuf>,
}

impl FreeArgs {
    /// The run's options for scenario `s`, on `iface` into `out`, our nav being `nav`.
    pub(crate) fn options(
        &self,
        s: &Scenario,
        iface: &str,
        out: PathBuf,
        nav: PathBuf,
    ) -> Result<hil::free::FreeOptions> {
        let mut o = hil::free::FreeOptions {
            iface: iface.into(),
            out,
            dut: match self.dut.as_deref() {
                None => hil::free::Dut::Nav(nav),
                Some("none") => hil::free::Dut::Nothing,
                Some(c) => hil::free::Dut::Command(c.into(), nav),
            },
            real_turntable: false,
            real_gps: None,
            latency_budget_ms: self
                .latency_budget_ms
                .or(s.bus.latency_budget_ms)
                .unwrap_or(50.0),
            answer_within_s: self.answer_within,
            max_late_ms: self.max_late_ms,
            lead_allowance_ms: self.lead_allowance_ms,
            progress: true,
            lab: match &self.mapping {
                Some(p) => Some(std::sync::Arc::new(hil::free::lab_ear(p)?)),
                None => None,
            },
        };
        for r in &self.real {
            match r.split_once('=') {
                Some(("turntable", i)) if i == iface => o.real_turntable = true,
                Some(("turntable", _)) => bail!(
                    "--real {r}: the bench has one bus, --iface {iface}: the real turntable must be on it"
                ),
                Some(("gps", p)) => o.real_gps = Some(PathBuf::from(p)),
                _ => bail!("--real {r}: turntable=IFACE or gps=PORT"),
            }
        }
        if !(0.0..=10_000.0).contains(&self.max_late_ms) {
            bail!("--max-late-ms {}: between 0 and 10000", self.max_late_ms);
        }
        if o.lab.is_some() && self.dut.is_none() {
            bail!(
                "--mapping needs --dut: our nav speaks wire/bench.dbc only; name the device that speaks the lab's contract (or `none` for one already on the bus)"
            );
        }
        Ok(o)
    }
}
