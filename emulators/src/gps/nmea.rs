//! NMEA-0183 encoding of the receiver's epochs (GGA, RMC, VTG, GSA, GSV, GST, ZDA): the receiver
//! model ([`super::receiver::ReceiverModel`]) decides what an epoch holds, this writes it.

use super::receiver::{Observation, ReceiverModel};
use super::{AntennaTruth, ReceiverParams};

/// A fix's position error and the receiver's own 1-sigma of it (east, north, up), m: truth
/// for the bench's scoring, never on the wire.
pub type ErrorAndSigma = ([f64; 3], [f64; 3]);

/// A receiver that writes NMEA-0183: its model decides each epoch, [`encode`] writes it.
pub struct NmeaWriter {
    model: ReceiverModel,
}

fn with_checksum(body: &str) -> String {
    let ck = body.bytes().fold(0u8, |a, b| a ^ b);
    format!("${body}*{ck:02X}\r\n")
}

fn dm(deg: f64, deg_digits: usize, pos: char, neg: char) -> (String, char) {
    let a = deg.abs();
    let d = a.floor();
    let m = (a - d) * 60.0;
    let s = format!("{:0w$}{:08.5}", d as u32, m, w = deg_digits);
    (s, if deg >= 0.0 { pos } else { neg })
}

impl NmeaWriter {
    /// A receiver with these parameters.
    pub fn new(p: ReceiverParams) -> Self {
        Self {
            model: ReceiverModel::new(p),
        }
    }

    /// The parameters.
    pub fn params(&self) -> &ReceiverParams {
        self.model.params()
    }

    /// The sentences of the fix at `t` (s since the start; `utc0_s` is the UTC second of the
    /// day at t = 0, `date` is (day, month, year)), and the position error applied with the
    /// receiver's own sigma of it (E, N, U, m; none when there is no fix).
    pub fn fix(
        &mut self,
        t: f64,
        utc0_s: f64,
        date: (u32, u32, u32),
        truth: &AntennaTruth,
    ) -> (String, Option<ErrorAndSigma>) {
        let Some(obs) = self.model.observe(t, utc0_s, truth) else {
            return (String::new(), None);
        };
        let text = encode(&obs, self.model.params(), date);
        (text, obs.valid.then_some((obs.error_enu, obs.sigma_enu)))
    }
}

/// The sentences of one epoch, as a receiver with parameters `p` writes them on `date` (day,
/// month, year).
pub fn encode(o: &Observation, p: &ReceiverParams, date: (u32, u32, u32)) -> String {
    let valid = o.valid;
    let [ve, vn] = o.vel_en_mps;
    let speed = ve.hypot(vn);
    let track = ve.atan2(vn).to_degrees().rem_euclid(360.0);
    let tod = o.time_of_day_s;
    let (hh, mm, ss) = (
        (tod / 3600.0).floor(),
        ((tod % 3600.0) / 60.0).floor(),
        tod % 60.0,
    );
    let time = format!("{:02}{:02}{:05.2}", hh as u32, mm as u32, ss);
    let (dd, mo, yy) = date;
    let (la, ns) = dm(o.lat_deg, 2, 'N', 'S');
    let (lo, ew) = dm(o.lon_deg, 3, 'E', 'W');
    let (sats, hdop, geoid) = (o.satellites, o.hdop, o.geoid_m);
    let tk = &p.talker;
    let mut out = String::new();
    if o.garbage {
        // line noise before a start character, then a line with binary bytes
        out += "~#\u{1}noise\u{7f}%%";
        out += "$GPGGA,\u{1}\u{2}\u{3}\u{4}\r\n";
    }
    let (la_s, lo_s) = if valid {
        (la.as_str(), lo.as_str())
    } else {
        ("", "")
    };
    let (ns_s, ew_s) = if valid {
        (ns.to_string(), ew.to_string())
    } else {
        (String::new(), String::new())
    };
    out += &with_checksum(&format!(
        "{tk}GGA,{time},{la_s},{ns_s},{lo_s},{ew_s},{},{sats:02},{hdop:.1},{},M,{geoid:.1},M,,",
        u8::from(valid),
        if valid {
            format!("{:.1}", o.h_m - geoid)
        } else {
            String::new()
        }
    ));
    out += &with_checksum(&format!(
        "{tk}RMC,{time},{},{la_s},{ns_s},{lo_s},{ew_s},{:.1},{:.1},{dd:02}{mo:02}{:02},,,{}",
        if valid { 'A' } else { 'V' },
        speed / 0.514_444,
        track,
        yy % 100,
        if valid { 'A' } else { 'N' }
    ));
    out += &with_checksum(&format!(
        "{tk}VTG,{track:.1},T,,M,{:.1},N,{:.1},K,{}",
        speed / 0.514_444,
        speed * 3.6,
        if valid { 'A' } else { 'N' }
    ));
    out += &satellites(o, tk);
    if p.gst && valid {
        // the receiver's own accuracy: range residual RMS, the error ellipse (round: the
        // model's horizontal errors are alike on both axes), then latitude, longitude and
        // altitude 1-sigma, m
        let [se, sn, su] = o.sigma_enu;
        out += &with_checksum(&format!(
            "{tk}GST,{time},{:.2},{:.2},{:.2},0.0,{sn:.2},{se:.2},{su:.2}",
            p.errors.white_sigma_m,
            se.max(sn),
            se.min(sn)
        ));
    }
    out += &with_checksum(&format!("{tk}ZDA,{time},{dd:02},{mo:02},{yy:04},00,00"));
    out
}

/// GSA and GSV: the satellites used, their dilution of precision, and those in view.
fn satellites(o: &Observation, tk: &str) -> String {
    let (sats, hdop) = (o.satellites, o.hdop);
    let prns: Vec<String> = (1..=12)
        .map(|i| {
            if i <= sats {
                format!("{:02}", i * 2)
            } else {
                String::new()
            }
        })
        .collect();
    let mut out = with_checksum(&format!(
        "{tk}GSA,A,{},{},{:.1},{hdop:.1},{:.1}",
        if o.valid { 3 } else { 1 },
        prns.join(","),
        hdop * 1.6,
        hdop * 1.3
    ));
    let nsv = sats.max(1).div_ceil(4);
    // satellites in view are listed per constellation (NMEA 4.1): a multi-GNSS receiver
    // (talker GN) puts its GPS satellites, the ones listed here, under GP
    let sv_tk = if tk == "GN" { "GP" } else { tk };
    for k in 0..nsv {
        let mut body = format!("{sv_tk}GSV,{nsv},{},{sats:02}", k + 1);
        for j in 0..4 {
            let i = k * 4 + j;
            if i < sats {
                body += &format!(
                    ",{:02},{:02},{:03},{:02}",
                    (i + 1) * 2,
                    20 + (i * 7) % 60,
                    (i * 37) % 360,
                    35 + i % 10
                );
            }
        }
        out += &with_checksum(&body);
    }
    out
}
