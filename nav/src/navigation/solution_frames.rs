//! The navigation solution on the bus: NAV_TIME, NAV_ATT, NAV_VEL, NAV_POS, NAV_HGT (the wire
//! contract's layouts), at the contract's 50 Hz of IMU time.

use crate::navigation::strapdown::NavOutput;
use wire::{Message, NavAtt, NavHealth, NavHgt, NavMode, NavPos, NavTime, NavVel, RawFrame};

/// One solution epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solution {
    /// IMU sample count the solution is valid at.
    pub sample_count: u64,
    /// Mode.
    pub mode: NavMode,
    /// Health.
    pub health: NavHealth,
    /// The navigation output (none before navigation starts: only NAV_TIME is sent).
    pub output: Option<NavOutput>,
    /// Horizontal position sigma, m.
    pub pos_sigma_m: f64,
    /// Heading sigma, deg.
    pub heading_sigma_deg: f64,
    /// Bytes taken from the GPS receiver so far.
    pub gps_rx_bytes: u64,
}

/// Encodes solutions into frames, numbering them.
#[derive(Debug, Default)]
pub struct SolutionEncoder {
    seq: u8,
    /// Epochs encoded.
    pub epochs: u64,
    /// Frames that could not be encoded (a NaN in the solution): counted, never silent.
    pub encode_errors: u64,
    /// Solutions not sent because they named an earlier sample than the last one sent: nav's
    /// time tags never go back on the bus (none is expected: the pipeline's sample count only
    /// grows; counted, never silent).
    pub backwards: u64,
    last_sample: Option<u64>,
}

impl SolutionEncoder {
    /// The frames of `s` (NAV_TIME first), appended to `out`. Values outside a signal's range
    /// are clamped to it (a sigma beyond the field's range reads as the largest value).
    pub fn encode(&mut self, s: &Solution, out: &mut Vec<RawFrame>) {
        if self.last_sample.is_some_and(|k| s.sample_count < k) {
            self.backwards += 1;
            tracing::error!(
                "a solution of sample {} after one of sample {:?}: not sent (time tags never go back)",
                s.sample_count,
                self.last_sample
            );
            return;
        }
        self.last_sample = Some(s.sample_count);
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        self.epochs += 1;
        let mut msgs = vec![Message::NavTime(NavTime {
            sample_count: (s.sample_count & 0xFFFF_FFFF) as u32,
            seq,
            mode: s.mode,
            health: s.health,
            gps_rx_bytes: (s.gps_rx_bytes & 0xFFF) as u16,
        })];
        if let Some(o) = &s.output {
            msgs.push(Message::NavAtt(NavAtt {
                seq,
                heading_deg: o.hpr_deg[0].rem_euclid(360.0).min(419.0),
                pitch_deg: o.hpr_deg[1].clamp(-90.0, 90.0),
                roll_deg: o.hpr_deg[2].clamp(-180.0, 180.0),
            }));
            msgs.push(Message::NavVel(NavVel {
                seq,
                enu_mps: o.vel_enu_mps.map(|v| v.clamp(-131.0, 131.0)),
            }));
            msgs.push(Message::NavPos(NavPos {
                lat_deg: o.lat_deg,
                lon_deg: o.lon_deg,
            }));
            msgs.push(Message::NavHgt(NavHgt {
                seq,
                height_m: o.h_m.clamp(-80_000.0, 80_000.0),
                pos_sigma_m: s.pos_sigma_m.clamp(0.0, 655.0),
                heading_sigma_deg: s.heading_sigma_deg.clamp(0.0, 6.5),
            }));
        }
        for m in &msgs {
            match m.encode() {
                Ok(f) => out.push(f),
                Err(e) => {
                    self.encode_errors += 1;
                    if self.encode_errors <= 3 {
                        tracing::warn!("solution frame {} not encoded: {e}", m.spec().name);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_solution_decodes_back_to_what_was_sent() {
        let o = NavOutput {
            lat_deg: 28.218157,
            lon_deg: 112.989583,
            h_m: 52.37,
            vel_enu_mps: [3.25, -4.5, 0.012],
            hpr_deg: [359.9, -0.25, 1.5],
        };
        let s = Solution {
            sample_count: 123_456,
            mode: NavMode::GpsAided,
            health: NavHealth {
                gps_stale: true,
                ..NavHealth::default()
            },
            output: Some(o),
            pos_sigma_m: 8.5,
            heading_sigma_deg: 0.05,
            gps_rx_bytes: 5000,
        };
        let mut enc = SolutionEncoder::default();
        let mut frames = Vec::new();
        enc.encode(&s, &mut frames);
        assert_eq!(frames.len(), 5);
        let msgs: Vec<Message> = frames.iter().map(|f| Message::decode(f).unwrap()).collect();
        match msgs[0] {
            Message::NavTime(t) => {
                assert_eq!(t.sample_count, 123_456);
                assert_eq!(t.mode, NavMode::GpsAided);
                assert!(t.health.gps_stale && !t.health.imu_bit);
            }
            ref m => panic!("{m:?}"),
        }
        match msgs[3] {
            Message::NavPos(p) => {
                assert!((p.lat_deg - o.lat_deg).abs() < 1e-7);
                assert!((p.lon_deg - o.lon_deg).abs() < 1e-7);
            }
            ref m => panic!("{m:?}"),
        }
        match msgs[2] {
            Message::NavVel(v) => assert!((v.enu_mps[1] + 4.5).abs() < 1e-3),
            ref m => panic!("{m:?}"),
        }
        // before navigation only the header goes out
        frames.clear();
        enc.encode(
            &Solution {
                output: None,
                mode: NavMode::NorthFinding,
                ..s
            },
            &mut frames,
        );
        assert_eq!(frames.len(), 1);
        assert_eq!(enc.epochs, 2);
        // a solution of an earlier sample never goes out; the same sample again may
        frames.clear();
        enc.encode(
            &Solution {
                sample_count: 123_416,
                ..s
            },
            &mut frames,
        );
        assert!(frames.is_empty());
        assert_eq!((enc.backwards, enc.epochs), (1, 2));
        enc.encode(&s, &mut frames);
        assert_eq!((frames.len(), enc.epochs), (5, 3));
    }
}
