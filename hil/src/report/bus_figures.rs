//! The bus model's figures as a report reads them: the load, each identifier's queueing delays,
//! each node's transmit queue and the turntable command round trip. One table for the run
//! report (Markdown and HTML) and for `hil busload --measure`.

use crate::report::page::esc;
use crate::table::Table;
use emulators::bus::model::BusStats;
use std::fmt::Write;

/// The rows of the per-identifier table: id, message, sender, frames, load %, p50, p99, worst.
fn id_rows(b: &BusStats) -> Vec<[String; 8]> {
    b.ids
        .iter()
        .map(|i| {
            [
                format!("0x{:03X}", i.id),
                i.name.clone(),
                i.sender.clone(),
                i.frames.to_string(),
                format!("{:.2}", 100.0 * i.load),
                format!("{:.0}", i.delay_p50_us),
                format!("{:.0}", i.delay_p99_us),
                format!("{:.0}", i.delay_max_us),
            ]
        })
        .collect()
}

const ID_HEADINGS: [&str; 8] = [
    "id",
    "message",
    "sender",
    "frames",
    "load %",
    "delay p50 µs",
    "delay p99 µs",
    "worst µs",
];

/// One line on the bus as a whole: bit rate, load, span.
pub fn headline(b: &BusStats) -> String {
    if b.ideal {
        return format!(
            "ideal bus (vcan's timing: no bit time, no arbitration), {} identifiers over {:.1} s",
            b.ids.len(),
            b.span_s
        );
    }
    format!(
        "{:.0} kbit/s, load {:.2} % over {:.1} s (exact frame lengths, stuff bits included)",
        b.bitrate_bps / 1000.0,
        100.0 * b.load,
        b.span_s
    )
}

/// The command round trip in words.
pub fn round_trip(b: &BusStats) -> String {
    let r = &b.round_trip;
    if r.commands == 0 {
        return "no turntable command answered".into();
    }
    format!(
        "TT_CMD queued to TT_ACK on the bus: {} commands, median {:.0} µs, p99 {:.0} µs, worst {:.0} µs",
        r.commands, r.p50_us, r.p99_us, r.max_us
    )
}

/// Each node's queue in words.
pub fn queues(b: &BusStats) -> String {
    b.nodes
        .iter()
        .map(|n| {
            format!(
                "{} sent {}, at most {} queued, {} lost to a full queue",
                n.name, n.sent, n.deepest, n.overflow
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The section of a Markdown report.
pub fn markdown(b: &BusStats) -> String {
    if b.ids.is_empty() {
        return String::new();
    }
    let mut t = Table::figures(&ID_HEADINGS);
    for r in id_rows(b) {
        t.row(r);
    }
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## The bus\n\n{}. Delay: from the frame's queueing by its node to its start of frame.\n\n{}\n- {}\n- transmit queues: {}\n",
        headline(b),
        t.finish(),
        round_trip(b),
        queues(b)
    );
    s
}

/// The section of an HTML report.
pub fn html(b: &BusStats) -> String {
    if b.ids.is_empty() {
        return String::new();
    }
    let mut s = format!(
        "<h2>The bus</h2>\n<p>{}.</p>\n<table>\n<tr>",
        esc(&headline(b))
    );
    for h in ID_HEADINGS {
        let _ = write!(s, "<th>{}</th>", esc(h));
    }
    s += "</tr>\n";
    for r in id_rows(b) {
        s += "<tr>";
        for c in r {
            let _ = write!(s, "<td>{}</td>", esc(&c));
        }
        s += "</tr>\n";
    }
    let _ = writeln!(
        s,
        "</table>\n<p>{}.</p>\n<p>Transmit queues: {}.</p>",
        esc(&round_trip(b)),
        esc(&queues(b))
    );
    s
}
