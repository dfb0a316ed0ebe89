use super::*;
use crate::drive::{Drive, DriveSpec};
use crate::truth::Motion;

/// A hilly route with switchbacks, stops and speeds per leg (about 5 km, 10 minutes).
pub(crate) fn hilly() -> DriveSpec {
    DriveSpec {
        lat_deg: 46.5,
        lon_deg: 7.9,
        height_m: 600.0,
        waypoints: vec![
            [0.0, 800.0],
            [400.0, 1500.0],
            [-300.0, 2000.0],
            [300.0, 2600.0],
            [300.0, 3600.0],
            [-500.0, 4200.0],
        ],
        heights_m: vec![640.0, 700.0, 760.0, 815.0, 760.0, 700.0],
        leg_speeds_mps: vec![14.0, 10.0, 7.0, 9.0, 16.0, 12.0],
        stops: vec![[2.0, 20.0], [4.0, 5.0]],
        speed_mps: 12.0,
        brake_mps2: Some(2.5),
        jerk_mps3: Some(1.0),
        bank_deg: Some(3.0),
        start_wait_s: 10.0,
        ..Default::default()
    }
}

/// A brisk drive through hills (about 7.6 km, 8 minutes): legs at up to 29 m/s, grades to
/// 10 %, corners taken at 3.5 m/s^2 lateral, braking at 3 m/s^2, three stops, a paved surface.
pub(crate) fn brisk() -> DriveSpec {
    DriveSpec {
        lat_deg: 41.15,
        lon_deg: -8.61,
        height_m: 80.0,
        waypoints: vec![
            [0.0, 900.0],
            [700.0, 1400.0],
            [1500.0, 1300.0],
            [1800.0, 600.0],
            [2600.0, 300.0],
            [2400.0, -500.0],
            [1300.0, -700.0],
            [600.0, -200.0],
            [0.0, 0.0],
        ],
        heights_m: vec![150.0, 120.0, 200.0, 120.0, 90.0, 40.0, 110.0, 70.0, 80.0],
        leg_speeds_mps: vec![25.0, 20.0, 29.0, 22.0, 28.0, 18.0, 29.0, 20.0, 14.0],
        stops: vec![[2.0, 12.0], [5.0, 20.0], [7.0, 8.0]],
        speed_mps: 25.0,
        accel_mps2: 2.5,
        brake_mps2: Some(3.0),
        jerk_mps3: Some(2.0),
        turn_rate_dps: 40.0,
        lateral_accel_mps2: 3.5,
        corner_radius_m: Some(45.0),
        roughness: Some(1.0),
        start_wait_s: 6.0,
        ..Default::default()
    }
}

/// `spec` without a road's fields: the level route of old.
fn level_of(mut spec: DriveSpec) -> DriveSpec {
    spec.heights_m.clear();
    spec.leg_speeds_mps.clear();
    spec.stops.clear();
    spec.brake_mps2 = None;
    spec.jerk_mps3 = None;
    spec.bank_deg = None;
    spec
}

fn road(spec: &DriveSpec) -> Road {
    Road::plan(spec).unwrap_or_else(|e| panic!("{}", e.problem))
}

/// The hilly route plans as asked: every leg at its speed, standing at its stops for as long
/// as asked, within its acceleration, braking and jerk limits and its lateral-acceleration
/// limit, climbing and descending through its waypoints' heights.
#[test]
fn a_hilly_route_stops_climbs_and_keeps_its_limits() {
    let spec = hilly();
    let r = road(&spec);
    let n = r.notes();
    assert!(n.slowed.is_empty(), "{n:?}");
    assert!(n.sharp_crests.is_empty(), "{n:?}");
    assert!(
        (n.climb_m - 215.0).abs() < 1e-6 && (n.descent_m - 115.0).abs() < 1e-6,
        "{n:?}"
    );
    let (mut t, dt) = (0.0, 0.01);
    let mut standing = Vec::new();
    let mut since: Option<f64> = None;
    while t < r.duration() + 1.0 {
        let s = r.state(t);
        let (v, a, j) = (s.along.v, s.along.a, s.along.j);
        assert!(
            (-2.5 - 1e-9..=1.5 + 1e-9).contains(&a) && j.abs() <= 1.0 + 1e-9,
            "{t}"
        );
        let lateral = v * s.hpr_rate[0];
        assert!(lateral.abs() <= 2.5 + 1e-9, "{t}: lateral {lateral}");
        assert!(s.hpr_rate[0].abs() <= 15f64.to_radians() + 1e-9, "{t}");
        match (v < 1e-9, since) {
            (true, None) => since = Some(t),
            (false, Some(t0)) => {
                standing.push(t - t0);
                since = None;
            }
            _ => {}
        }
        t += dt;
    }
    // the start's wait, the two stops, and standing at the end
    assert_eq!(standing.len(), 3, "{standing:?}");
    for (got, want) in standing.iter().zip([10.0, 20.0, 5.0]) {
        assert!((got - want).abs() < 0.02, "{standing:?}");
    }
    // the height at each waypoint (the middle of its turn), within the vertical curves'
    // rounding
    // a waypoint's height is on the grade lines: the road passes it by the middle ordinate of
    // its vertical curve, and is on the grade lines beyond the curves (the end)
    let ordinate = r
        .path
        .crests
        .iter()
        .map(|c| c.dgamma.abs() * c.len * (0.25 - 0.5 / std::f64::consts::PI))
        .fold(0.0, f64::max);
    assert!(
        ordinate > 0.3 && (n.height_miss_m - ordinate).abs() < 0.05,
        "{ordinate} {n:?}"
    );
    let end = r.position(r.duration() + 10.0);
    assert!((end.2 - 700.0).abs() < 0.02, "{end:?}");
}

/// Velocity is the derivative of the position on the ellipsoid, the velocity's stated rate its
/// derivative, and the body's stated rate the derivative of its attitude (central
/// differences, all along the route).
#[test]
fn velocity_and_rates_are_the_derivatives_of_position_and_attitude() {
    derivatives_within(&hilly(), 1e-3, [2e-5, 2e-5, 2e-6]);
    // on a poor road (the bumps' shortest wave 4 m: at 16 m/s their acceleration's third
    // derivative is 10^4 times larger, so a shorter step)
    let rough = DriveSpec {
        roughness: Some(2.0),
        ..hilly()
    };
    derivatives_within(&rough, 2e-4, [2e-5, 2e-5, 2e-6]);
}

/// Over `spec`'s road, every 0.731 s, the velocity is the position's central difference (step
/// `h`), the velocity's rate the velocity's, the body rate the attitude's, within `tol`.
fn derivatives_within(spec: &DriveSpec, h: f64, tol: [f64; 3]) {
    let r = road(spec);
    let mut t = 0.5;
    let mut worst = [0.0f64; 3];
    while t < r.duration() {
        let (p0, p1) = (r.position(t - h), r.position(t + h));
        let (rm, rn) = crate::geodesy::radii(p0.0);
        let s = r.state(t);
        let fd = Vector3::new(
            (p1.1 - p0.1) / (2.0 * h) * (rn + p0.2) * p0.0.cos(),
            (p1.0 - p0.0) / (2.0 * h) * (rm + p0.2),
            (p1.2 - p0.2) / (2.0 * h),
        );
        worst[0] = worst[0].max((fd - s.v).norm());
        let dv = (r.velocity(t + h) - r.velocity(t - h)) / (2.0 * h);
        worst[1] = worst[1].max((dv - s.dv).norm());
        // a shorter step for the attitude: its third derivative is larger
        let hr = 2e-4;
        let (c0, _) = r.rotation(t - hr);
        let (c1, _) = r.rotation(t + hr);
        let (c, w) = r.rotation(t);
        let d = c.matrix().transpose() * (c1.matrix() - c0.matrix()) / (2.0 * hr);
        let w_fd = Vector3::new(d[(2, 1)], d[(0, 2)], d[(1, 0)]);
        worst[2] = worst[2].max((w_fd - w).norm());
        t += 0.731;
    }
    assert!(
        worst[0] < tol[0] && worst[1] < tol[1] && worst[2] < tol[2],
        "{worst:?}"
    );
}

/// The reference strapdown integration of the truth's own increments at 2 kHz follows the
/// truth over the whole hilly route: the increments the IMU is given, and the position and
/// attitude the receiver and the scoring are given, are one motion.
#[test]
fn a_reference_integration_of_the_increments_follows_the_truth() {
    reference_follows(&hilly());
    // and on a poor road, shaken by its bumps
    reference_follows(&DriveSpec {
        roughness: Some(2.0),
        ..hilly()
    });
}

fn reference_follows(spec: &DriveSpec) {
    let r = Drive::plan(spec).unwrap();
    // ten minutes: the free vertical channel has not yet grown (its time constant is 10 min)
    let e = reference::integrate(&r, &r, 2000.0, r.duration() + 5.0, 60.0, false);
    let last = e.last().unwrap();
    let worst_h = e.iter().map(|x| x.horizontal_m).fold(0.0, f64::max);
    let worst_a = e.iter().map(|x| x.attitude_rad).fold(0.0, f64::max);
    let worst_v = e.iter().map(|x| x.velocity_mps).fold(0.0, f64::max);
    let worst_u = e.iter().map(|x| x.vertical_m.abs()).fold(0.0, f64::max);
    eprintln!(
        "reference over {:.0} s: horizontal {worst_h:.2e} m, vertical {worst_u:.2e} m, velocity {worst_v:.2e} m/s, attitude {worst_a:.2e} rad",
        last.t
    );
    // measured: 7.7e-4 m, 4.2e-6 m/s, 1.3e-9 rad; the transport rate left out of the truth's
    // gyro rates gives 347 m, 1.7 m/s, 6e-4 rad
    assert!(
        worst_h < 0.01 && worst_v < 1e-4 && worst_a < 2e-8 && worst_u < 0.01,
        "{e:?}"
    );
}

/// Along a meridian the distance driven is the meridian arc (Gauss-Legendre over the meridian
/// radius, apart from the road's own integral), across the equator; along a parallel at 80 N
/// the longitude is the distance over the parallel's radius; a climb of 2,000 m ends 2,000 m
/// up.
#[test]
fn long_roads_are_exact_on_the_ellipsoid() {
    // 300 km due north from 1.3 S at 50 m
    let north = DriveSpec {
        lat_deg: -1.3,
        lon_deg: 30.0,
        height_m: 50.0,
        waypoints: vec![[0.0, 300_000.0]],
        heights_m: vec![50.0],
        speed_mps: 30.0,
        ..Default::default()
    };
    let r = road(&north);
    let (lat, lon, _) = r.position(r.duration() + 1.0);
    let lat0 = (-1.3f64).to_radians();
    let n = 2000;
    let mut arc = 0.0;
    for k in 0..n {
        let (a, b) = (
            lat0 + (lat - lat0) * k as f64 / n as f64,
            lat0 + (lat - lat0) * (k + 1) as f64 / n as f64,
        );
        let i = crate::truth::gauss_legendre(a, b, |x| {
            (
                Vector3::new(crate::geodesy::radii(x).0 + 50.0, 0.0, 0.0),
                Vector3::zeros(),
            )
        });
        arc += i.dtheta.x;
    }
    assert!((arc - 300_000.0).abs() < 1e-3, "arc {arc}");
    assert!((lon - 30f64.to_radians()).abs() < 1e-15);
    assert!(lat.to_degrees() > 1.4);
    // 100 km due east at 80 N
    let east = DriveSpec {
        lat_deg: 80.0,
        lon_deg: 0.0,
        height_m: 0.0,
        waypoints: vec![[100_000.0, 0.0]],
        heights_m: vec![0.0],
        speed_mps: 25.0,
        ..Default::default()
    };
    let r = road(&east);
    let (lat, lon, _) = r.position(r.duration() + 1.0);
    let l80 = 80f64.to_radians();
    let want = 100_000.0 / (crate::geodesy::radii(l80).1 * l80.cos());
    assert!((lat - l80).abs() < 1e-15, "{lat}");
    assert!(((lon - want) * crate::geodesy::radii(l80).1 * l80.cos()).abs() < 1e-3);
    // a 2,000 m climb over 25 km
    let climb = DriveSpec {
        lat_deg: 30.0,
        lon_deg: 90.0,
        height_m: 1000.0,
        waypoints: vec![[0.0, 25_000.0]],
        heights_m: vec![3000.0],
        ..Default::default()
    };
    let r = road(&climb);
    let (_, _, h) = r.position(r.duration() + 1.0);
    assert!((h - 3000.0).abs() < 1e-6, "{h}");
}

/// Every bad road is refused with what is wrong and where.
#[test]
fn bad_roads_say_what_is_wrong() {
    type Change = Box<dyn Fn(&mut DriveSpec)>;
    let cases: Vec<(Change, &str)> = vec![
        (
            Box::new(|s| s.heights_m.pop().map(|_| ()).unwrap_or(())),
            "heights_m has 5 heights for 6 waypoints",
        ),
        (
            Box::new(|s| s.leg_speeds_mps.push(3.0)),
            "leg_speeds_mps has 7 speeds",
        ),
        (
            Box::new(|s| s.heights_m[1] = 1000.0),
            "the leg to waypoint 2 climbs",
        ),
        (Box::new(|s| s.stops.push([9.0, 1.0])), "stop [9, 1]"),
        (Box::new(|s| s.stops.push([1.5, 1.0])), "stop [1.5, 1]"),
        (
            Box::new(|s| s.leg_speeds_mps[1] = 0.0),
            "the speed of the leg to waypoint 2",
        ),
        (
            Box::new(|s| s.waypoints[1] = [0.0, 800.5]),
            "waypoint 2 is 0.50 m",
        ),
        (
            Box::new(|s| s.waypoints[2] = [0.0, 0.0]),
            "turns back on itself",
        ),
        (
            Box::new(|s| {
                s.leg_speeds_mps = vec![30.0; 6];
                s.lateral_accel_mps2 = 0.5;
            }),
            "need",
        ),
        (
            Box::new(|s| s.jerk_mps3 = Some(0.0)),
            "jerk_mps3 must be positive",
        ),
        (Box::new(|s| s.lat_deg = 89.5), "within 89 deg"),
        (Box::new(|s| s.waypoints[3][0] = f64::NAN), "must be finite"),
        (Box::new(|s| s.heights_m[0] = 12_000.0), "height 12000 m"),
        (Box::new(|s| s.laps = 5000), "legs"),
        (Box::new(|s| s.waypoints[5] = [0.0, 4e6]), "km"),
        (
            Box::new(|s| s.leg_speeds_mps[0] = 1e-9),
            "from 0.1 m/s to 150 m/s",
        ),
        (Box::new(|s| s.stops[0][1] = 1e12), "from 0 to a day"),
        (Box::new(|s| s.roughness = Some(-1.0)), "roughness -1"),
    ];
    for (change, want) in cases {
        let mut s = hilly();
        change(&mut s);
        match Road::plan(&s) {
            Ok(_) => panic!("planned, expected: {want}"),
            Err(e) => assert!(e.problem.contains(want), "{} (expected: {want})", e.problem),
        }
    }
}

/// On a rough road the body is shaken more the faster it drives: its pitch and roll rates
/// grow with the speed, its vertical acceleration with the speed squared; on a smooth one it
/// is not shaken at all.
#[test]
fn a_rough_road_shakes_the_body_more_at_speed() {
    // straight and level, 3 km at one speed (after the start's acceleration)
    let at = |v: f64, roughness: Option<f64>| {
        let spec = DriveSpec {
            lat_deg: 50.0,
            lon_deg: 10.0,
            waypoints: vec![[0.0, 3000.0]],
            speed_mps: v,
            leg_speeds_mps: vec![v],
            roughness,
            ..Default::default()
        };
        let r = road(&spec);
        let (mut rate, mut accel, mut n) = (0.0, 0.0, 0.0);
        let mut t = 40.0;
        while t < 90.0 {
            let s = r.state(t);
            assert!((s.along.v - v).abs() < 1e-9, "{v} m/s at {t} s");
            rate += s.hpr_rate[1].powi(2) + s.hpr_rate[2].powi(2);
            accel += s.dv.z.powi(2);
            n += 1.0;
            t += 0.0123;
        }
        ((rate / n).sqrt().to_degrees(), (accel / n).sqrt())
    };
    let (slow, fast) = (at(10.0, Some(1.0)), at(30.0, Some(1.0)));
    eprintln!(
        "pitch and roll rate, vertical acceleration (RMS): {slow:?} at 10 m/s, {fast:?} at 30"
    );
    assert!((fast.0 / slow.0 - 3.0).abs() < 0.3, "{slow:?} {fast:?}");
    assert!((fast.1 / slow.1 - 9.0).abs() < 1.0, "{slow:?} {fast:?}");
    // a typical road: about a degree per second and 0.9 m/s^2 at 30 m/s
    assert!(
        (0.5..1.5).contains(&fast.0) && (0.6..1.2).contains(&fast.1),
        "{fast:?}"
    );
    assert_eq!(at(30.0, None), (0.0, 0.0));
}

/// A route without a road's fields is the level route of old; with any of them, a road.
#[test]
fn a_road_is_planned_only_where_the_spec_names_one() {
    let level = level_of(hilly());
    assert!(!level.is_road() && Drive::plan(&level).unwrap().road().is_none());
    let d = Drive::plan(&hilly()).unwrap();
    assert!(d.road().is_some());
    // the drive's truth is the road's
    let t = 200.0;
    assert_eq!(d.position(t), road(&hilly()).position(t));
    assert_eq!(d.rate_and_force(t), road(&hilly()).rate_and_force(t));
}

/// A city corner of 15 m radius is driven at the speed its sharpest point allows (within the
/// lateral-acceleration limit), then the next leg at its own.
#[test]
fn a_sharp_corner_is_driven_slowly() {
    let spec = DriveSpec {
        lat_deg: 38.72,
        lon_deg: -9.14,
        waypoints: vec![[0.0, 300.0], [300.0, 300.0]],
        heights_m: vec![0.0, 0.0],
        speed_mps: 13.0,
        turn_rate_dps: 30.0,
        corner_radius_m: Some(15.0),
        ..Default::default()
    };
    let r = road(&spec);
    assert!(r.notes().slowed.is_empty(), "{:?}", r.notes());
    let (mut t, mut slowest_in_turn, mut fastest) = (0.0, f64::INFINITY, 0.0f64);
    while t < r.duration() {
        let s = r.state(t);
        let lateral = s.along.v * s.hpr_rate[0];
        assert!(lateral.abs() <= 2.5 + 1e-9, "{t}: {lateral}");
        if s.hpr_rate[0].abs() > 0.3 {
            slowest_in_turn = slowest_in_turn.min(s.along.v);
        }
        fastest = fastest.max(s.along.v);
        t += 0.05;
    }
    // sqrt(2.5 m/s^2 x 15 m) at the sharpest
    assert!((fastest - 13.0).abs() < 1e-9, "{fastest}");
    assert!(slowest_in_turn <= 6.2, "{slowest_in_turn}");
}

/// The attitude matrices built from each angle's sine and cosine are the truth's `c_b_n`
/// (nalgebra's rotations about the axes), all along the route.
#[test]
fn the_attitude_from_sines_and_cosines_is_c_b_n() {
    let r = road(&hilly());
    let mut t = 0.0;
    while t < r.duration() {
        let s = r.state(t);
        let (m, _) = r.rotation(t);
        let want = crate::truth::c_b_n(s.hpr[0], s.hpr[1], s.hpr[2]);
        assert!((m.matrix() - want.matrix()).norm() < 1e-15, "{t}");
        t += 1.37;
    }
}

/// The truth's cost per IMU sample against the level route's (figures for docs/routes.md:
/// `cargo test -p emulators --release --lib road::tests::truth_pace -- --ignored --nocapture`).
#[test]
#[ignore = "figures"]
fn truth_pace() {
    let road = Drive::plan(&hilly()).unwrap();
    let rough = Drive::plan(&DriveSpec {
        roughness: Some(1.0),
        ..hilly()
    })
    .unwrap();
    let level = level_of(hilly());
    let level = Drive::plan(&level).unwrap();
    for (name, d) in [("road", &road), ("rough road", &rough), ("level", &level)] {
        let t0 = std::time::Instant::now();
        let mut acc = 0.0;
        let n = 240_000;
        for k in 0..n {
            let i = d.increments(k as f64 / 2000.0, (k + 1) as f64 / 2000.0);
            acc += i.dtheta.x;
        }
        let s = t0.elapsed().as_secs_f64();
        eprintln!(
            "{name}: {:.0} ns per sample, x{:.0} ({acc:.3e})",
            s / n as f64 * 1e9,
            120.0 / s
        );
    }
}

/// A change of grade too small to limit its neighbours (under 0.02 %) a few metres after a
/// large one, inside the large one's vertical curve (as a fitted track's corners give): the
/// road's pitch stays continuous and the truth one motion. (The curves overlapped once: the
/// small one's start stepped the pitch by the large one's unfinished part, 3 mrad on a track of
/// a brisk drive, and the reference integration walked 1.5 km from the truth.)
#[test]
fn a_small_change_of_grade_inside_a_curve_keeps_the_pitch_continuous() {
    let spec = DriveSpec {
        lat_deg: 41.15,
        lon_deg: -8.61,
        height_m: 0.0,
        waypoints: vec![[0.0, 200.0], [0.0, 230.0], [0.0, 800.0]],
        heights_m: vec![0.0, 1.5, 1.5 + 570.0 * 0.0501],
        speed_mps: 20.0,
        start_wait_s: 2.0,
        ..Default::default()
    };
    let r = road(&spec);
    let mut prev = r.hpr(0.0)[1];
    let mut t = 0.0;
    while t < r.duration() {
        t += 1e-3;
        let p = r.hpr(t)[1];
        // at 20 m/s along a curve of 5 % over 60 m the pitch moves by 2e-5 rad a millisecond
        assert!(
            (p - prev).abs() < 1e-4,
            "the pitch steps at {t:.3} s: {prev} to {p}"
        );
        prev = p;
    }
    reference_follows(&spec);
}
/// The truth's self-check holds on a road, and fails where the increments and the truth are
/// not one motion: a pitch step of 1 mrad the increments never saw is found when it happens,
/// and where.
#[test]
fn the_truths_self_check_finds_where_the_truth_disagrees_with_itself() {
    let d = Drive::plan(&hilly()).unwrap();
    let ok = reference::self_check(&d, 2000.0, 120.0);
    assert!(ok.holds(), "{}", ok.summary());
    assert_eq!(ok.bound, reference::ROAD_BOUND);
    // a level route (its latitude and longitude from metres on the plane of its start) is held
    // to its own, looser bound, and holds it
    let level = Drive::plan(&level_of(hilly())).unwrap();
    let c = reference::self_check(&level, 2000.0, 120.0);
    assert_eq!(c.bound, reference::LEVEL_BOUND);
    assert!(c.holds(), "{}", c.summary());
    /// The drive's truth with a pitch step at 60 s that its increments lack.
    struct Stepped<'a>(&'a Drive);
    impl reference::Truth for Stepped<'_> {
        fn llh(&self, t: f64) -> [f64; 3] {
            reference::Truth::llh(self.0, t)
        }
        fn vel(&self, t: f64) -> nalgebra::Vector3<f64> {
            reference::Truth::vel(self.0, t)
        }
        fn q_bn(&self, t: f64) -> UnitQuaternion<f64> {
            let q = reference::Truth::q_bn(self.0, t);
            if t >= 60.0 {
                q * UnitQuaternion::from_euler_angles(1e-3, 0.0, 0.0)
            } else {
                q
            }
        }
    }
    let bad = reference::check_motion(&d, &Stepped(&d), reference::ROAD_BOUND, 2000.0, 120.0);
    assert!(!bad.holds());
    let p = bad.first_past.unwrap();
    assert!((p.t - 60.0).abs() < 0.011, "{p:?}");
    assert!((p.attitude_rad - 1e-3).abs() < 1e-5, "{p:?}");
    let (lat, lon, _) = d.position(p.t);
    assert!((p.lat_lon_deg[0] - lat.to_degrees()).abs() < 1e-12);
    assert!((p.lat_lon_deg[1] - lon.to_degrees()).abs() < 1e-12);
    assert!(
        bad.summary().contains("not the navigator"),
        "{}",
        bad.summary()
    );
}
