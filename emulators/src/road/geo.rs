//! Where the road is on the WGS-84 ellipsoid: latitude, longitude and height as the exact
//! integral, along the road, of its direction over the radii of curvature at the current
//! latitude and height,
//! `dlat/ds = cos(gamma) cos(psi) / (R_M + h)`,
//! `dlon/ds = cos(gamma) sin(psi) / ((R_N + h) cos(lat))`, `dh/ds = sin(gamma)`.
//!
//! The integral is kept at knots (every corner of the road's shape, and at most every 5 m, closer
//! in tight turns), each the last plus a 6-point Gauss-Legendre quadrature over the piece between
//! them; a place between two knots is the knot before it plus the same quadrature. Inside a piece
//! the radii are taken at the latitude and height of a second-order expansion about its knot: a
//! piece is at most 5 m, so the radii's error is below 1e-15 of themselves.

use super::path::Path;
use crate::geodesy as earth;

/// A place on the road where the integral is kept.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Knot {
    /// Distance along the road, m.
    pub s: f64,
    /// Latitude, longitude (rad) and height (m) there.
    pub llh: [f64; 3],
    /// Their first and second derivatives along the road there.
    d1: [f64; 3],
    d2: [f64; 3],
}

/// The road on the ellipsoid.
#[derive(Debug, Clone)]
pub(crate) struct Placed {
    knots: Vec<Knot>,
}

/// Derivatives of (lat, lon, h) along the road at `s`, where the road is at `llh`; with the
/// second derivatives when asked.
fn rates(path: &Path, s: f64, llh: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let p = path.at(s);
    let (sg, cg) = p.gamma.sin_cos();
    let (sp, cp) = p.psi.sin_cos();
    let (sl, cl) = llh[0].sin_cos();
    let (rm, rn) = earth::radii(llh[0]);
    let (m, n) = (rm + llh[2], (rn + llh[2]) * cl);
    let d1 = [cg * cp / m, cg * sp / n, sg];
    // the second derivatives, to the order the expansion needs (the radii's own change along
    // the road, 1e-7 of them per metre at most, is left out)
    let dn = -(rn + llh[2]) * sl * d1[0] + cl * sg;
    let d2 = [
        (-sg * p.dgamma * cp - cg * sp * p.kappa) / m - d1[0] * sg / m,
        (-sg * p.dgamma * sp + cg * cp * p.kappa) / n - d1[1] * dn / n,
        cg * p.dgamma,
    ];
    (d1, d2)
}

/// Latitude and height (the radii's arguments) `u` metres past knot `k`.
fn expanded(k: &Knot, u: f64) -> [f64; 3] {
    std::array::from_fn(|i| k.llh[i] + u * (k.d1[i] + 0.5 * u * k.d2[i]))
}

/// (lat, lon, h) at `s` from knot `k` (`s` at most one piece past it).
fn from_knot(path: &Path, k: &Knot, s: f64) -> [f64; 3] {
    let (c, h) = (0.5 * (k.s + s), 0.5 * (s - k.s));
    if h == 0.0 {
        return k.llh;
    }
    let mut out = k.llh;
    for (x, w) in crate::truth::GL6 {
        let si = c + h * x;
        let (d1, _) = rates(path, si, expanded(k, si - k.s));
        for i in 0..3 {
            out[i] += w * h * d1[i];
        }
    }
    out
}

impl Placed {
    /// Lay the road out from (lat, lon, h) at its start.
    pub fn new(path: &Path, start: [f64; 3]) -> Self {
        let corners = path.corners();
        // pieces no longer than 5 m, nor than a twentieth of the turn they are in
        let step = |s: f64| {
            let i = path.turns.partition_point(|t| t.s0 <= s);
            match i.checked_sub(1).map(|i| &path.turns[i]) {
                Some(t) if s < t.s0 + t.len => (t.len / 20.0).clamp(0.05, 5.0),
                _ => 5.0,
            }
        };
        let knot = |s: f64, llh: [f64; 3]| {
            let (d1, d2) = rates(path, s, llh);
            Knot { s, llh, d1, d2 }
        };
        let mut knots = vec![knot(0.0, start)];
        let mut next_corner = 0;
        let mut s = 0.0;
        while s < path.length {
            let mut s1 = (s + step(s)).min(path.length);
            while next_corner < corners.len() && corners[next_corner] <= s {
                next_corner += 1;
            }
            if let Some(&c) = corners.get(next_corner) {
                s1 = s1.min(c);
            }
            let last = knots[knots.len() - 1];
            let llh = from_knot(path, &last, s1);
            knots.push(knot(s1, llh));
            s = s1;
        }
        Self { knots }
    }

    fn knot(&self, s: f64) -> &Knot {
        let i = self.knots.partition_point(|k| k.s <= s).saturating_sub(1);
        &self.knots[i]
    }

    /// Latitude, longitude (rad) and height (m) `s` metres along the road (past its end: where
    /// it ends).
    pub fn llh(&self, path: &Path, s: f64) -> [f64; 3] {
        let s = s.clamp(0.0, path.length);
        from_knot(path, self.knot(s), s)
    }

    /// Latitude and height `s` metres along the road from the expansion about the knot before
    /// it: within 1e-9 rad and 1 mm of [`Placed::llh`], for the earth rate, transport rate and
    /// gravity the sensors feel (whose change over that is below 1e-12 of them).
    pub fn lat_h(&self, path: &Path, s: f64) -> (f64, f64) {
        let s = s.clamp(0.0, path.length);
        let k = self.knot(s);
        let e = expanded(k, s - k.s);
        (e[0], e[2])
    }
}
