//! Every message encodes and decodes back to itself (to the signal's resolution), and bad
//! frames are refused with a clear error.

use wire::*;

fn close(a: f64, b: f64, step: f64) -> bool {
    (a - b).abs() <= step / 2.0 + 1e-9
}

fn rt(m: Message) -> Message {
    let f = m.encode().expect("encodes");
    assert_eq!(f.len, m.spec().dlc);
    Message::decode(&f).expect("decodes")
}

#[test]
fn imu_frames_round_trip_exactly() {
    for sc in [0u16, 1, 0x7FFF, 0xFFFF] {
        let g = ImuGyro {
            counts: [0, 0xFFFF, 12345],
            sample_counter: sc,
        };
        assert_eq!(rt(Message::ImuGyro(g)), Message::ImuGyro(g));
        for pps in [None, Some(0u8), Some(255)] {
            let a = ImuAccel {
                counts: [65535, 1, 40000],
                sample_counter_low: (sc & 0xF) as u8,
                pps_offset: pps,
                bit_fail: sc % 2 == 0,
                saturated: sc % 3 == 0,
            };
            assert_eq!(rt(Message::ImuAccel(a)), Message::ImuAccel(a));
        }
    }
    for (i, low) in [0u8, 17, 255].into_iter().enumerate() {
        let m = MemsGyro {
            counts: [0, 0x3FFF, 12345, i as u16],
            sample_counter_low: low,
        };
        assert_eq!(rt(Message::MemsGyro(m)), Message::MemsGyro(m));
    }
    let hk = ImuHk {
        sample_counter: 999,
        temp_gyro_c: 41.25,
        temp_accel_c: -12.5,
        bit: BitFlags {
            gyro: [false, true, false],
            dither: true,
            ..Default::default()
        },
    };
    assert_eq!(rt(Message::ImuHk(hk)), Message::ImuHk(hk));
}

#[test]
fn turntable_frames_round_trip() {
    for c in TtCommand::ALL {
        let m = TtCmd {
            seq: 200,
            command: *c as u8,
            axis: 2,
            arg: -123.4567,
        };
        let Message::TtCmd(back) = rt(Message::TtCmd(m)) else {
            panic!("kind")
        };
        assert_eq!((back.seq, back.command, back.axis), (200, *c as u8, 2));
        assert!(close(back.arg, m.arg, 1e-4));
    }
    for r in TtResult::ALL {
        let m = TtAck {
            seq: 7,
            command: 4,
            axis: 1,
            result: *r,
        };
        assert_eq!(rt(Message::TtAck(m)), Message::TtAck(m));
    }
    for (i, s) in TtState::ALL.iter().enumerate() {
        let m = TtStatus {
            angle_deg: 359.9999 - i as f64 * 71.0,
            rate_dps: -300.0 + i as f64,
            state: *s,
            axis: (i % 3) as u8,
            faults: TtFaults {
                stall: i == 1,
                estop: i == 2,
                limit: true,
                ..Default::default()
            },
            ack_seq: 255,
            counter: (i % 16) as u8,
        };
        let Message::TtStatus(b) = rt(Message::TtStatus(m)) else {
            panic!("kind")
        };
        assert!(close(b.angle_deg, m.angle_deg, 1e-4) && close(b.rate_dps, m.rate_dps, 0.01));
        assert_eq!(
            (b.state, b.axis, b.faults, b.ack_seq, b.counter),
            (m.state, m.axis, m.faults, m.ack_seq, m.counter)
        );
    }
}

#[test]
fn nav_frames_round_trip() {
    let t = NavTime {
        sample_count: u32::MAX,
        seq: 3,
        mode: NavMode::GpsAided,
        health: NavHealth {
            imu_gaps: true,
            filter: true,
            gps_data: true,
            ..Default::default()
        },
        gps_rx_bytes: 4095,
    };
    assert_eq!(rt(Message::NavTime(t)), Message::NavTime(t));
    let a = NavAtt {
        seq: 3,
        heading_deg: 359.9,
        pitch_deg: -89.9,
        roll_deg: 100.0,
    };
    let Message::NavAtt(b) = rt(Message::NavAtt(a)) else {
        panic!("kind")
    };
    assert!(
        close(b.heading_deg, a.heading_deg, 4e-4)
            && close(b.pitch_deg, a.pitch_deg, 8e-4)
            && close(b.roll_deg, a.roll_deg, 8e-4)
    );
    let v = NavVel {
        seq: 3,
        enu_mps: [-130.0, 0.0015, 25.0],
    };
    let Message::NavVel(b) = rt(Message::NavVel(v)) else {
        panic!("kind")
    };
    for k in 0..3 {
        assert!(close(b.enu_mps[k], v.enu_mps[k], 1e-3));
    }
    let p = NavPos {
        lat_deg: 28.218157,
        lon_deg: 112.989583,
    };
    let Message::NavPos(b) = rt(Message::NavPos(p)) else {
        panic!("kind")
    };
    assert!(close(b.lat_deg, p.lat_deg, 1e-7) && close(b.lon_deg, p.lon_deg, 1e-7));
    let p = NavPos {
        lat_deg: -90.0,
        lon_deg: -180.0,
    };
    let Message::NavPos(b) = rt(Message::NavPos(p)) else {
        panic!("kind")
    };
    assert!(close(b.lat_deg, -90.0, 1e-7) && close(b.lon_deg, -180.0, 1e-7));
    let h = NavHgt {
        seq: 3,
        height_m: -12.34,
        pos_sigma_m: 25.0,
        heading_sigma_deg: 0.05,
    };
    let Message::NavHgt(b) = rt(Message::NavHgt(h)) else {
        panic!("kind")
    };
    assert!(
        close(b.height_m, h.height_m, 0.01)
            && close(b.pos_sigma_m, 25.0, 0.01)
            && close(b.heading_sigma_deg, 0.05, 1e-4)
    );
}

#[test]
fn bad_frames_are_refused_with_clear_errors() {
    let f = RawFrame {
        id: 0x7FF,
        len: 8,
        data: [0; 8],
    };
    let e = Message::decode(&f).unwrap_err();
    assert_eq!(e, DecodeError::UnknownId { id: 0x7FF });
    assert!(e.to_string().contains("0x7FF"));
    let f = RawFrame {
        id: 0x080,
        len: 6,
        data: [0; 8],
    };
    let e = Message::decode(&f).unwrap_err();
    assert!(
        matches!(
            e,
            DecodeError::WrongLength {
                name: "IMU_GYRO",
                expected: 8,
                got: 6,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("IMU_GYRO"));
    // State 7 is undefined
    let mut d = [0u8; 8];
    tt_status::STATE.put_wrapping(&mut d, 7);
    let e = Message::decode(&RawFrame {
        id: 0x102,
        len: 8,
        data: d,
    })
    .unwrap_err();
    assert!(
        matches!(
            e,
            DecodeError::InvalidValue {
                signal: "State",
                raw: 7,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn out_of_range_values_do_not_encode() {
    let v = NavVel {
        seq: 0,
        enu_mps: [200.0, 0.0, 0.0],
    };
    let e = Message::NavVel(v).encode().unwrap_err();
    assert!(e.to_string().contains("VelEast"), "{e}");
    let c = TtCmd {
        seq: 0,
        command: 4,
        axis: 4,
        arg: 0.0,
    };
    assert!(
        Message::TtCmd(c).encode().is_err(),
        "axis 4 does not fit 2 bits"
    );
}

/// Angles go out on [0, 360): one that rounds to a whole turn goes out as 0, never as the 360
/// the decoder refuses.
#[test]
fn angles_wrap_after_quantization() {
    for (deg, want) in [
        (359.99999, 0.0),
        (-0.00001, 0.0),
        (720.5, 0.5),
        (359.9, 359.9),
    ] {
        let st = TtStatus {
            angle_deg: deg,
            rate_dps: 0.0,
            state: TtState::ALL[0],
            axis: 0,
            faults: TtFaults::default(),
            ack_seq: 0,
            counter: 0,
        };
        let Message::TtStatus(back) = rt(Message::TtStatus(st)) else {
            panic!("not a TT_STATUS");
        };
        assert!(
            close(back.angle_deg, want, 1e-4),
            "{deg} -> {}",
            back.angle_deg
        );
        let att = NavAtt {
            seq: 1,
            heading_deg: deg,
            pitch_deg: 0.0,
            roll_deg: 0.0,
        };
        let Message::NavAtt(back) = rt(Message::NavAtt(att)) else {
            panic!("not a NAV_ATT");
        };
        assert!(
            close(back.heading_deg, want, 4e-4),
            "{deg} -> {}",
            back.heading_deg
        );
    }
}
