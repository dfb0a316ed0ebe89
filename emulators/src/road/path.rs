//! The road's shape as functions of the distance driven along it, `s` (m): the heading and its
//! curvature, the road's pitch (its grade) and its bank. Pure geometry: no time, no speed.
//!
//! Straight legs are joined by turns whose curvature rises and falls smoothly,
//! `kappa(u) = kappa_max sin^2(pi u / L)` over the turn's length `L`, so that the lateral
//! acceleration, and the roll it causes, have no step; the heading is its closed-form integral.
//! Changes of grade are vertical curves of the same kind: the pitch moves from one leg's to the
//! next's as `(1 - cos(pi u / L)) / 2`. The bank follows the turn's curvature.

use std::f64::consts::PI;

/// A turn: the heading changes by `kappa_max * len / 2` over `len` metres from `s0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Turn {
    /// Where it starts, m along the road.
    pub s0: f64,
    /// Its length, m.
    pub len: f64,
    /// Heading before it, rad (clockwise from north).
    pub psi0: f64,
    /// Peak curvature, rad/m (positive: a right turn).
    pub kappa_max: f64,
    /// The road's bank at the peak, rad (positive: right side down).
    pub bank_max: f64,
}

/// A vertical curve: the road's pitch moves from `gamma0` by `dgamma` over `len` metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Crest {
    /// Where it starts, m along the road.
    pub s0: f64,
    /// Its length, m.
    pub len: f64,
    /// Pitch before it, rad.
    pub gamma0: f64,
    /// Change of pitch over it, rad.
    pub dgamma: f64,
}

/// The road at one place: heading, pitch and bank with their derivatives along the road.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RoadPoint {
    /// Heading, rad.
    pub psi: f64,
    /// d psi / ds, rad/m (the horizontal curvature per metre of road).
    pub kappa: f64,
    /// d kappa / ds, rad/m^2.
    pub dkappa: f64,
    /// The road's pitch, rad.
    pub gamma: f64,
    /// d gamma / ds, rad/m.
    pub dgamma: f64,
    /// The road's bank, rad.
    pub bank: f64,
    /// d bank / ds, rad/m.
    pub dbank: f64,
}

/// The whole road: its turns and vertical curves in order, and the heading and pitch it starts
/// with.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Path {
    /// Heading at the start, rad.
    pub psi_start: f64,
    /// Pitch at the start, rad.
    pub gamma_start: f64,
    /// Turns, in order, not overlapping.
    pub turns: Vec<Turn>,
    /// Vertical curves, in order, not overlapping.
    pub crests: Vec<Crest>,
    /// Length, m.
    pub length: f64,
}

impl Turn {
    /// Heading change over the whole turn, rad.
    pub fn change(&self) -> f64 {
        0.5 * self.kappa_max * self.len
    }

    /// Heading, curvature, its derivative, bank and its derivative `u` metres into the turn.
    fn at(&self, u: f64) -> (f64, f64, f64, f64, f64) {
        let w = PI / self.len;
        let (s1, c1) = (w * u).sin_cos();
        let sin2 = 2.0 * s1 * c1; // sin(2 w u)
        let shape = s1 * s1; // sin^2(w u)
        let psi = self.psi0 + self.kappa_max * (0.5 * u - sin2 / (4.0 * w));
        let dshape = w * sin2;
        (
            psi,
            self.kappa_max * shape,
            self.kappa_max * dshape,
            self.bank_max * shape,
            self.bank_max * dshape,
        )
    }
}

impl Crest {
    /// Pitch and its derivative `u` metres into the curve.
    fn at(&self, u: f64) -> (f64, f64) {
        let w = PI / self.len;
        let (s, c) = (w * u).sin_cos();
        (
            self.gamma0 + 0.5 * self.dgamma * (1.0 - c),
            0.5 * self.dgamma * w * s,
        )
    }
}

impl Path {
    /// The road `s` metres from the start (before it and past its end: as at its ends).
    pub fn at(&self, s: f64) -> RoadPoint {
        let mut p = RoadPoint {
            psi: self.psi_start,
            kappa: 0.0,
            dkappa: 0.0,
            gamma: self.gamma_start,
            dgamma: 0.0,
            bank: 0.0,
            dbank: 0.0,
        };
        let i = self.turns.partition_point(|t| t.s0 <= s);
        if i > 0 {
            let t = &self.turns[i - 1];
            let u = s - t.s0;
            if u < t.len {
                (p.psi, p.kappa, p.dkappa, p.bank, p.dbank) = t.at(u);
            } else {
                p.psi = t.psi0 + t.change();
            }
        }
        let j = self.crests.partition_point(|c| c.s0 <= s);
        if j > 0 {
            let c = &self.crests[j - 1];
            let u = s - c.s0;
            if u < c.len {
                (p.gamma, p.dgamma) = c.at(u);
            } else {
                p.gamma = c.gamma0 + c.dgamma;
            }
        }
        p
    }

    /// Every place the road's shape changes its formula (turns' and curves' ends), in order.
    pub fn corners(&self) -> Vec<f64> {
        let mut c: Vec<f64> = self
            .turns
            .iter()
            .flat_map(|t| [t.s0, t.s0 + t.len])
            .chain(self.crests.iter().flat_map(|c| [c.s0, c.s0 + c.len]))
            .filter(|&s| s > 0.0 && s < self.length)
            .collect();
        c.sort_by(f64::total_cmp);
        c.dedup();
        c
    }
}

/// Where a turn of `change` rad and length 1 m ends, in the frame of its start (x to the right
/// of the way in, y along it), m: the shape scales with the length.
pub(crate) fn unit_turn_end(change: f64) -> (f64, f64) {
    unit_turn_to(change, 1.0)
}

/// How far the middle of a turn of `change` rad and length 1 m passes from the corner of its
/// two straight lines, m: the shape scales with the length.
pub(crate) fn unit_turn_miss(change: f64) -> f64 {
    let (x, y) = unit_turn_to(change.abs(), 0.5);
    x.hypot(y - tangent_length(change, 1.0))
}

/// Where a turn of `change` rad and length 1 m is `u` into it, as [`unit_turn_end`].
fn unit_turn_to(change: f64, u: f64) -> (f64, f64) {
    let t = Turn {
        s0: 0.0,
        len: 1.0,
        psi0: 0.0,
        kappa_max: 2.0 * change,
        bank_max: 0.0,
    };
    // 64 panels of 6-point Gauss-Legendre: the heading is smooth, so exact to rounding
    let n = 64;
    let (mut x, mut y) = (0.0, 0.0);
    for k in 0..n {
        let (a, b) = (u * k as f64 / n as f64, u * (k + 1) as f64 / n as f64);
        let i = crate::truth::gauss_legendre(a, b, |u| {
            let (sin, cos) = t.at(u).0.sin_cos();
            (
                nalgebra::Vector3::new(sin, cos, 0.0),
                nalgebra::Vector3::zeros(),
            )
        });
        x += i.dtheta.x;
        y += i.dtheta.y;
    }
    (x, y)
}

/// The tangent length of a turn of `change` rad and length `len` m: how far before the corner
/// of the two straight lines it starts, and after it ends (the shape is symmetric), m.
pub(crate) fn tangent_length(change: f64, len: f64) -> f64 {
    let (x, y) = unit_turn_end(change.abs());
    let c = change.abs();
    // the corner is where the way in (x = 0) meets the way out through (x, y) at heading c
    if c < 1e-9 {
        return 0.5 * len;
    }
    len * (y - x * c.cos() / c.sin())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_turn() -> Path {
        Path {
            psi_start: 0.3,
            gamma_start: 0.0,
            turns: vec![Turn {
                s0: 100.0,
                len: 60.0,
                psi0: 0.3,
                kappa_max: 2.0 * 1.2 / 60.0,
                bank_max: 0.05,
            }],
            crests: vec![Crest {
                s0: 120.0,
                len: 40.0,
                gamma0: 0.0,
                dgamma: 0.08,
            }],
            length: 300.0,
        }
    }

    /// Heading, pitch and bank are continuous, and their stated derivatives are the
    /// derivatives (central differences), through the turn and the vertical curve.
    #[test]
    fn the_derivatives_are_the_derivatives() {
        let p = one_turn();
        let h = 1e-4;
        let mut s = 0.0;
        while s < 300.0 {
            let (a, b, c) = (p.at(s - h), p.at(s), p.at(s + h));
            let d = |f: fn(&RoadPoint) -> f64| (f(&c) - f(&a)) / (2.0 * h);
            assert!((d(|r| r.psi) - b.kappa).abs() < 1e-8, "{s}");
            assert!((d(|r| r.kappa) - b.dkappa).abs() < 1e-8, "{s}");
            assert!((d(|r| r.gamma) - b.dgamma).abs() < 1e-8, "{s}");
            assert!((d(|r| r.bank) - b.dbank).abs() < 1e-8, "{s}");
            s += 0.37;
        }
        // the whole change is made, and no more
        assert!((p.at(200.0).psi - 1.5).abs() < 1e-15);
        assert!((p.at(200.0).gamma - 0.08).abs() < 1e-15);
        assert_eq!(p.at(200.0).bank, 0.0);
    }

    /// A turn of 90 deg ends off the straight lines by its tangent length, both ways; a
    /// turn of nothing is half its length.
    #[test]
    fn the_tangent_length_meets_both_lines() {
        let (x, y) = unit_turn_end(PI / 2.0);
        let t = tangent_length(PI / 2.0, 1.0);
        // way in along +y from the origin, way out along +x: the corner at (0, t)
        assert!(
            (y - t).abs() < 1e-12 && (x - t).abs() < 1e-12,
            "{x} {y} {t}"
        );
        assert!((tangent_length(1e-12, 10.0) - 5.0).abs() < 1e-9);
    }
}
