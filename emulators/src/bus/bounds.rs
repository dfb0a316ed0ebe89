//! What the bus model measured against what the analysis bounds: each periodic message's worst
//! time from queued to sent (its worst queueing delay on the model plus its frame at its
//! longest) beside its worst-case response time (`wire::busload::response_times`, Davis et al.
//! 2007). The analysis assumes a node sends its lowest identifier first; the model's nodes keep
//! a FIFO queue, as SocketCAN does, so a frame queued behind its own node's earlier ones can pass
//! its bound, and is marked so. Pure.

use super::model::BusStats;
use std::fmt::Write;
use wire::busload::Periodic;

/// The markdown table of `periodic`'s messages on a bus at `nominal_bps` (CAN FD's data phase
/// at `data_bps`) as the model measured them in `b` (a message it did not carry is left out),
/// and how many passed their bound.
pub fn against_bounds(
    b: &BusStats,
    periodic: &[Periodic],
    nominal_bps: f64,
    data_bps: f64,
) -> (String, usize) {
    let bounds = wire::busload::response_times(periodic, nominal_bps, data_bps);
    let mut s = String::from(
        "| message | frames | measured worst, queued to sent (us) | bound (us) | within |\n|---|---:|---:|---:|---|\n",
    );
    let mut over = 0;
    for (p, bound) in periodic.iter().zip(&bounds) {
        let Some(id) = b
            .ids
            .iter()
            .find(|i| i.id == p.id && i.extended == p.extended)
        else {
            continue;
        };
        let own =
            wire::busload::frame_time_worst_s(p.extended, p.payload, p.fd, nominal_bps, data_bps);
        let measured = id.delay_max_us + own * 1e6;
        let (bound, within) = match bound {
            Some(r) if measured <= r * 1e6 + 1e-6 => (format!("{:.0}", r * 1e6), "yes"),
            Some(r) => {
                over += 1;
                (
                    format!("{:.0}", r * 1e6),
                    "no: behind its own node's earlier frames (a FIFO queue, as SocketCAN's; the analysis assumes a node sends its lowest identifier first) or a burst",
                )
            }
            None => ("none".into(), "-"),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {measured:.0} | {bound} | {within} |",
            p.name, id.frames
        );
    }
    (s, over)
}
