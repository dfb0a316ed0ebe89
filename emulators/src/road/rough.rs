//! The road's roughness: bumps along the road that pitch, roll and lift the body. They are
//! functions of the distance driven, so the body's rates grow with its speed and its vertical
//! acceleration with the speed squared, as a vehicle is shaken more the faster it drives over
//! the same road. A sum of waves per motion, each `amplitude sin(2 pi s / wavelength + phase)`
//! (the body's response to a road's profile as its suspension passes it on: the long waves its
//! body modes follow, the short ones about its wheels' hop, smaller).

use std::f64::consts::PI;

/// One wave along the road.
#[derive(Debug, Clone, Copy)]
struct Wave {
    /// Amplitude (rad for pitch and roll, m for heave).
    amp: f64,
    /// Wavenumber, rad/m.
    k: f64,
    /// Phase, rad.
    phase: f64,
}

impl Wave {
    const fn new(amp: f64, wavelength_m: f64, phase: f64) -> Self {
        Self {
            amp,
            k: 2.0 * PI / wavelength_m,
            phase,
        }
    }
}

/// A typical paved road (`roughness = 1`): heave of 8, 3 and 0.5 mm over waves of 31, 13 and
/// 4.1 m (the vertical acceleration 0.1 m/s^2 RMS at 10 m/s, 0.9 at 30: about what a car's body
/// feels on an ordinary road and on a highway); pitch of 0.08 and 0.02 deg over 17 and 6.3 m;
/// roll of 0.06 and 0.01 deg over 11 and 3.3 m (the rates about 1 deg/s at 30 m/s).
const HEAVE_M: [(f64, f64, f64); 3] = [(0.008, 31.0, 0.3), (0.003, 13.0, 2.1), (0.0005, 4.1, 4.4)];
const PITCH_DEG: [(f64, f64, f64); 2] = [(0.08, 17.0, 1.1), (0.02, 6.3, 5.0)];
const ROLL_DEG: [(f64, f64, f64); 2] = [(0.06, 11.0, 3.7), (0.01, 3.3, 0.6)];

/// The roughness of a road: its waves of pitch, roll and heave.
#[derive(Debug, Clone)]
pub(crate) struct Roughness {
    pitch: Vec<Wave>,
    roll: Vec<Wave>,
    heave: Vec<Wave>,
}

/// A motion's value and its first and second derivatives along the road (per m, per m^2).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Along3 {
    pub value: f64,
    pub d1: f64,
    pub d2: f64,
}

fn sum(waves: &[Wave], s: f64) -> Along3 {
    waves.iter().fold(Along3::default(), |acc, w| {
        let (sn, cs) = (w.k * s + w.phase).sin_cos();
        Along3 {
            value: acc.value + w.amp * sn,
            d1: acc.d1 + w.amp * w.k * cs,
            d2: acc.d2 - w.amp * w.k * w.k * sn,
        }
    })
}

impl Roughness {
    /// The typical paved road's waves scaled by `scale` (none for 0: a smooth road).
    pub fn new(scale: f64) -> Option<Self> {
        if scale == 0.0 {
            return None;
        }
        let waves = |table: &[(f64, f64, f64)], unit: f64| -> Vec<Wave> {
            table
                .iter()
                .map(|&(a, l, p)| Wave::new(a * unit * scale, l, p))
                .collect()
        };
        Some(Self {
            pitch: waves(&PITCH_DEG, PI / 180.0),
            roll: waves(&ROLL_DEG, PI / 180.0),
            heave: waves(&HEAVE_M, 1.0),
        })
    }

    /// Pitch, roll (rad) and heave (m) `s` metres along the road, with their derivatives along
    /// it.
    pub fn at(&self, s: f64) -> [Along3; 3] {
        [sum(&self.pitch, s), sum(&self.roll, s), sum(&self.heave, s)]
    }

    /// The heave `s` metres along the road, m.
    pub fn heave(&self, s: f64) -> f64 {
        sum(&self.heave, s).value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_derivatives_are_the_values_differences() {
        let r = Roughness::new(1.7).expect("rough");
        let h = 1e-3;
        for s in [0.0, 3.3, 250.0, 123_456.7] {
            let [a, b, c] = [r.at(s - h), r.at(s), r.at(s + h)];
            for i in 0..3 {
                let d1 = (c[i].value - a[i].value) / (2.0 * h);
                let d2 = (c[i].d1 - a[i].d1) / (2.0 * h);
                assert!(
                    (d1 - b[i].d1).abs() < 1e-7 * (1.0 + b[i].d1.abs()),
                    "{s} {i}"
                );
                assert!(
                    (d2 - b[i].d2).abs() < 1e-6 * (1.0 + b[i].d2.abs()),
                    "{s} {i}"
                );
            }
        }
        assert!(Roughness::new(0.0).is_none());
    }
}
