//! NMEA-0183 encoding of the receiver's fixes (GGA, RMC, VTG, GSA, GSV, GST, ZDA), with its outages,
//! time to first fix and multipath applied.

use super::{AntennaTruth, GpsError, ReceiverParams};

/// A fix's position error and the receiver's own 1-sigma of it (east, north, up), m: truth
/// for the bench's scoring, never on the wire.
pub type ErrorAndSigma = ([f64; 3], [f64; 3]);

/// Writes NMEA-0183 sentences for fixes.
pub struct NmeaWriter {
    p: ReceiverParams,
    err: GpsError,
    rng: rand::rngs::StdRng,
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
        use rand::SeedableRng;
        Self {
            err: GpsError::new(p.errors.clone()),
            rng: rand::rngs::StdRng::seed_from_u64(p.errors.seed ^ 0x5eed),
            p,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &ReceiverParams {
        &self.p
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
        use rand_distr::{Distribution, Normal};
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let in_outage = self.p.outages.iter().any(|o| t >= o[0] && t < o[1]);
        if in_outage && !self.p.outage_void {
            return (String::new(), None);
        }
        let valid = t >= self.p.ttff_s && !in_outage;
        let sample = self.err.sample(t);
        let mut e = sample.enu;
        for m in &self.p.multipath {
            if t >= m[0] && t < m[0] + m[1] {
                e[1] += m[2];
            }
        }
        let (rm, rn) = crate::geodesy::radii(truth.lat_deg.to_radians());
        let lat = truth.lat_deg + (e[1] / rm).to_degrees();
        let lon = truth.lon_deg + (e[0] / (rn * truth.lat_deg.to_radians().cos())).to_degrees();
        let h = truth.h_m + e[2];
        let ve = truth.vel_enu[0] + self.p.velocity_sigma_mps * n.sample(&mut self.rng);
        let vn = truth.vel_enu[1] + self.p.velocity_sigma_mps * n.sample(&mut self.rng);
        let speed = ve.hypot(vn);
        let track = ve.atan2(vn).to_degrees().rem_euclid(360.0);
        let at = |times: &[f64]| times.iter().any(|x| (t - x.floor()).abs() < 0.5);
        let back = if at(&self.p.time_backwards_at_s) {
            10.0
        } else {
            0.0
        };
        let tod = (utc0_s + t - back).rem_euclid(86_400.0);
        let (hh, mm, ss) = (
            (tod / 3600.0).floor(),
            ((tod % 3600.0) / 60.0).floor(),
            tod % 60.0,
        );
        let time = format!("{:02}{:02}{:05.2}", hh as u32, mm as u32, ss);
        let (dd, mo, yy) = date;
        let (la, ns) = dm(lat, 2, 'N', 'S');
        let (lo, ew) = dm(lon, 3, 'E', 'W');
        // the satellites used and the HDOP of the error model's geometry
        let sats: u32 = if valid { sample.satellites } else { 0 };
        let hdop = if valid { sample.hdop } else { 99.9 };
        // GGA's altitude is above the geoid, with the geoid's separation from the ellipsoid
        // beside it (EGM2008, a coarse grid: the receiver's own model is no finer)
        let geoid = egm2008::geoid_height(truth.lat_deg as f32, truth.lon_deg as f32)
            .map_or(0.0, f64::from);
        let tk = &self.p.talker;
        let mut out = String::new();
        if at(&self.p.garbage_at_s) {
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
                format!("{:.1}", h - geoid)
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
        let prns: Vec<String> = (1..=12)
            .map(|i| {
                if i <= sats {
                    format!("{:02}", i * 2)
                } else {
                    String::new()
                }
            })
            .collect();
        out += &with_checksum(&format!(
            "{tk}GSA,A,{},{},{:.1},{hdop:.1},{:.1}",
            if valid { 3 } else { 1 },
            prns.join(","),
            hdop * 1.6,
            hdop * 1.3
        ));
        let nsv = sats.max(1).div_ceil(4);
        // satellites in view are listed per constellation (NMEA 4.1): a multi-GNSS receiver
        // (talker GN) puts its GPS satellites, the ones listed here, under GP
        let sv_tk = if tk == "GN" { "GP" } else { tk.as_str() };
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
        if self.p.gst && valid {
            // the receiver's own accuracy: range residual RMS, the error ellipse (round: the
            // model's horizontal errors are alike on both axes), then latitude, longitude and
            // altitude 1-sigma, m
            let [se, sn, su] = sample.sigma_enu;
            out += &with_checksum(&format!(
                "{tk}GST,{time},{:.2},{:.2},{:.2},0.0,{sn:.2},{se:.2},{su:.2}",
                self.p.errors.white_sigma_m,
                se.max(sn),
                se.min(sn)
            ));
        }
        out += &with_checksum(&format!("{tk}ZDA,{time},{dd:02},{mo:02},{yy:04},00,00"));
        (out, valid.then_some((e, sample.sigma_enu)))
    }
}
