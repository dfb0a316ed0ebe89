//! The truth's earth model (emulators::geodesy: closed forms from the two axes) against nav's
//! (nav::navigation::earth: eccentricity series): written apart, they must agree to rounding at every
//! latitude of both hemispheres and at altitude, so neither can carry an error the other hides.

#[test]
fn truth_and_nav_earth_models_agree_everywhere() {
    for i in -90..=90 {
        let lat = f64::from(i).to_radians();
        for h in [-400.0, 0.0, 1500.0, 8000.0] {
            let (a, b) = (
                emulators::geodesy::gravity(lat, h),
                nav::navigation::earth::gravity(lat, h),
            );
            assert!(
                (a - b).abs() < 1e-9,
                "gravity at {i} deg, {h} m: {a} against {b}"
            );
        }
        let ((rm1, rn1), (rm2, rn2)) = (
            emulators::geodesy::radii(lat),
            nav::navigation::earth::radii(lat),
        );
        assert!(
            (rm1 - rm2).abs() < 1e-6 && (rn1 - rn2).abs() < 1e-6,
            "radii at {i} deg"
        );
        let (w1, w2) = (
            emulators::geodesy::earth_rate_enu(lat),
            nav::navigation::earth::earth_rate_enu(lat),
        );
        assert!(
            (0..3).all(|k| (w1[k] - w2[k]).abs() < 1e-18),
            "earth rate at {i} deg"
        );
    }
}

/// The redundant IMU's gyro layout, written apart in the emulator (`emulators::imu::mems::triad`)
/// and in nav's calibration (`nav::procedures::rotating_estimator::tetra_triad`), is the same: each gyro's sensitive axis
/// and the two axes of its mounting angles.
#[test]
fn truth_and_nav_agree_on_the_redundant_imus_layout() {
    for i in 0..nav::procedures::rotating_estimator::TETRA_GYROS {
        let (p, rj, rk) = emulators::imu::mems::triad(i);
        let [q, sj, sk] = nav::procedures::rotating_estimator::tetra_triad(i);
        for (a, b, what) in [(p, q, "P"), (rj, sj, "R_j"), (rk, sk, "R_k")] {
            assert!(
                (a - b).norm() < 1e-15,
                "gyro {}: {what} {a} against {b}",
                i + 1
            );
        }
    }
}
