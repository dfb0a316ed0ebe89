//! The GPS emulator's NMEA writer read back through nav's own decoder (a test that needs both
//! sides, so it lives here: emulators and nav share only the wire contract).

use emulators::gps::{AntennaTruth, NmeaWriter, ReceiverParams};

#[test]
fn sentences_decode_in_nav_with_the_applied_error() {
    let mut w = NmeaWriter::new(ReceiverParams::default());
    let truth = AntennaTruth {
        lat_deg: 28.218157,
        lon_deg: 112.989583,
        h_m: 50.0,
        vel_enu: [3.0, 4.0, 0.0],
    };
    let mut dec = nav::frontend::gps_receiver::GpsDecoder::default();
    let mut fixes = Vec::new();
    for i in 0..5 {
        let (s, e) = w.fix(f64::from(i), 4.0 * 3600.0, (21, 11, 2026), &truth);
        assert!(s.ends_with("\r\n"));
        dec.push_bytes(s.as_bytes(), &mut fixes);
        let (e, sigma) = e.unwrap();
        assert!(sigma.iter().all(|s| *s > 0.0), "{sigma:?}");
        let f = fixes.iter().rev().find(|f| f.sentence == "GGA").unwrap();
        let (rm, _) = emulators::geodesy::radii(truth.lat_deg.to_radians());
        let north = (f.lat_deg - truth.lat_deg).to_radians() * rm;
        // GGA carries 1e-5 minute: 2 cm
        assert!((north - e[1]).abs() < 0.05, "{north} vs {}", e[1]);
    }
    let st = dec.stats();
    assert_eq!(st.bad_checksum + st.unparsed, 0, "{st:?}");
    let rmc = fixes.iter().find(|f| f.sentence == "RMC").unwrap();
    assert!((rmc.speed_mps.unwrap() - 5.0).abs() < 1.5);
    assert_eq!(rmc.date.as_deref(), Some("2026-11-21"));
}

#[test]
fn outages_and_time_to_first_fix_give_void_or_no_sentences() {
    let p = ReceiverParams {
        ttff_s: 2.0,
        outages: vec![[5.0, 7.0]],
        ..ReceiverParams::default()
    };
    let mut w = NmeaWriter::new(p.clone());
    let truth = AntennaTruth {
        lat_deg: 10.0,
        lon_deg: 20.0,
        h_m: 0.0,
        vel_enu: [0.0; 3],
    };
    let valid: Vec<bool> = (0..9)
        .map(|i| w.fix(f64::from(i), 0.0, (1, 1, 2026), &truth).1.is_some())
        .collect();
    assert_eq!(
        valid,
        [false, false, true, true, true, false, false, true, true]
    );
    // an epoch without a fix (empty fields, no satellites in view) is well-formed NMEA
    let mut dec = nav::frontend::gps_receiver::GpsDecoder::default();
    let mut fixes = Vec::new();
    let (text, _) = NmeaWriter::new(p.clone()).fix(0.0, 0.0, (1, 1, 2026), &truth);
    dec.push_bytes(text.as_bytes(), &mut fixes);
    let st = dec.stats();
    assert_eq!(
        (st.accepted, st.unparsed, st.bad_checksum),
        (6, 0, 0),
        "{st:?}"
    );
    assert!(fixes.iter().all(|f| !f.valid));
    let mut silent = NmeaWriter::new(ReceiverParams {
        outage_void: false,
        ..p
    });
    assert!(silent.fix(6.0, 0.0, (1, 1, 2026), &truth).0.is_empty());
}

/// Heights keep their datum: the emulator's GGA gives the altitude above the geoid and the
/// geoid's separation (EGM2008), nav adds them back to the ellipsoid height it navigates in.
/// Checked where the geoid is far from the ellipsoid: +50 m in the Alps, -106 m south of India,
/// +20 m on the Altiplano.
#[test]
fn gga_altitude_is_above_the_geoid_and_nav_takes_the_ellipsoid_height() {
    for (lat, lon, h) in [
        (46.5, 7.9, 1700.0),
        (5.0, 78.0, 10.0),
        (-16.5, -68.2, 4000.0),
    ] {
        let mut w = NmeaWriter::new(ReceiverParams {
            errors: emulators::gps::GpsErrorParams {
                gm_sigma_m: 0.0,
                white_sigma_m: 0.0,
                ..Default::default()
            },
            ..ReceiverParams::default()
        });
        let truth = AntennaTruth {
            lat_deg: lat,
            lon_deg: lon,
            h_m: h,
            vel_enu: [0.0; 3],
        };
        let (s, _) = w.fix(1.0, 4.0 * 3600.0, (21, 11, 2026), &truth);
        let mut dec = nav::frontend::gps_receiver::GpsDecoder::default();
        let mut fixes = Vec::new();
        dec.push_bytes(s.as_bytes(), &mut fixes);
        let f = fixes.iter().find(|f| f.sentence == "GGA").unwrap();
        let sep = f.geoid_sep_m.unwrap();
        let n = f64::from(egm2008::geoid_height(lat as f32, lon as f32).unwrap());
        assert!(
            (sep - n).abs() < 0.06,
            "{lat} {lon}: separation {sep} against {n}"
        );
        assert!(
            sep.abs() > 15.0,
            "{lat} {lon}: a site where the geoid matters ({sep} m)"
        );
        assert!((f.alt_m.unwrap() - (h - n)).abs() < 0.06, "{f:?}");
        let e = f.ellipsoid_height_m().unwrap();
        assert!((e - h).abs() < 0.1, "{lat} {lon}: {e} against {h}");
    }
}

/// A multi-GNSS receiver (talker GN) puts out sentences nav reads, every one: GNGGA, GNRMC,
/// GNGSA, and its satellites in view under their constellation's talker (GPGSV).
#[test]
fn a_multi_gnss_receivers_sentences_all_decode() {
    let mut w = NmeaWriter::new(ReceiverParams {
        talker: "GN".into(),
        ..ReceiverParams::default()
    });
    let truth = AntennaTruth {
        lat_deg: 46.5,
        lon_deg: 7.9,
        h_m: 1700.0,
        vel_enu: [3.0, 4.0, 0.0],
    };
    let mut dec = nav::frontend::gps_receiver::GpsDecoder::default();
    let mut fixes = Vec::new();
    for i in 0..5 {
        let (s, _) = w.fix(f64::from(i), 4.0 * 3600.0, (21, 11, 2026), &truth);
        assert!(
            s.contains("$GNGGA") && s.contains("$GPGSV") && !s.contains("$GNGSV"),
            "{s}"
        );
        dec.push_bytes(s.as_bytes(), &mut fixes);
    }
    let st = dec.stats();
    assert_eq!((st.unparsed, st.bad_checksum), (0, 0), "{st:?}");
    assert_eq!(st.accuracy, 5, "GST with each fix: {st:?}");
}
