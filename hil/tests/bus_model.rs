//! The bus model against vcan's ideal bus, on a north-finding drill run in process: what
//! differs, and that it differs only where the model says it must.
//!
//! On the ideal bus a turntable command placed at a sample's end reaches the mechanism at that
//! instant. On the modelled 1 Mbit/s bus it is queued by nav's controller at that instant, waits
//! in arbitration for the frames of lower identifier pending then (the IMU's two frames, queued
//! at the same sample's end) or for a frame already on the bus, and reaches the mechanism when
//! its own 111 to 135 bits are over. So the mechanism does everything it did on the ideal bus,
//! in the same order and on the same commands, each command later by its delay on the bus
//! (a few hundred µs); the IMU on the table senses the moves that much later, and the heading
//! nav finds moves by far less than its sigma.

use emulators::bus::model::BusTiming;
use hil::engine::inproc::InProcessBench;
use hil::scenario::{Scenario, TimingModel};

/// A short drill (20 s dwells) in process, on the bus `timing`: the commands the mechanism
/// received (time, command), the IMU frames nav received before the first one, the heading.
fn drill(timing: TimingModel) -> (Vec<(f64, wire::TtCmd)>, Vec<wire::RawFrame>, f64, BusTiming) {
    let mut s: Scenario = hil::procedures::northfinding::scenario(30.0, 28.218157, 20.0, 7);
    s.bus.timing = timing;
    let mut bench = InProcessBench::of(&s).expect("the drill's bench");
    let mut before_first = Vec::new();
    while bench.running() {
        let got = bench
            .stepper()
            .turntable()
            .is_some_and(|t| !t.received.is_empty());
        bench.step();
        if !got {
            // the frames nav met in this step (the sample's IMU frames), while no command has
            // reached the mechanism yet
            before_first.extend(bench.last_frames().iter().filter(|f| f.id < 0x100));
        }
        if bench
            .pipeline()
            .finder()
            .is_some_and(nav::procedures::common::Procedure::is_finished)
        {
            break;
        }
    }
    bench.finish();
    let heading = bench
        .pipeline()
        .finder()
        .and_then(|f| f.result())
        .map(|r| r.heading_deg)
        .expect("the drill found a heading");
    let tt = bench.stepper().turntable().expect("a turntable");
    (tt.received.clone(), before_first, heading, s.bus.timing())
}

#[test]
fn the_bus_model_delays_each_command_by_its_time_on_the_bus_and_changes_nothing_else() {
    let (ideal_cmds, ideal_imu, ideal_heading, _) = drill(TimingModel::Ideal);
    let (model_cmds, model_imu, model_heading, timing) = drill(TimingModel::Model);
    assert!(ideal_cmds.len() > 20, "{} commands", ideal_cmds.len());
    // the same commands, in the same order: nav decided the same things at the same samples
    let seq = |c: &[(f64, wire::TtCmd)]| c.iter().map(|x| x.1).collect::<Vec<_>>();
    assert_eq!(seq(&ideal_cmds), seq(&model_cmds));
    // each later by its time on the bus: its own frame at least, at most behind the IMU's two
    // frames and one more frame already on the bus
    let bit = 1e6 / timing.bitrate_bps;
    let (least, most) = (111.0 * bit, (135.0 * 4.0) * bit);
    let late: Vec<f64> = ideal_cmds
        .iter()
        .zip(&model_cmds)
        .map(|(i, m)| (m.0 - i.0) * 1e6)
        .collect();
    eprintln!(
        "{} commands, later on the modelled bus by {:.1} to {:.1} us; heading {ideal_heading:.6} deg ideal, {model_heading:.6} deg modelled",
        late.len(),
        late.iter().copied().fold(f64::INFINITY, f64::min),
        late.iter().copied().fold(0.0, f64::max)
    );
    for ((ti, c), (tm, _)) in ideal_cmds.iter().zip(&model_cmds) {
        let late_us = (tm - ti) * 1e6;
        assert!(
            (least..=most).contains(&late_us),
            "command {c:?}: {late_us:.1} us later on the modelled bus, expected {least:.0}..{most:.0}"
        );
        // on the ideal bus a command arrives at a sample's end (2 kHz)
        let k = ti * 2000.0;
        assert!((k - k.round()).abs() < 1e-6, "ideal at {ti} s");
    }
    // before the mechanism moved, nav met the very same IMU frames
    assert!(!ideal_imu.is_empty());
    assert_eq!(ideal_imu, model_imu);
    // the table moves a few hundred µs later: the heading moves by far less than its sigma
    // (0.03 deg here)
    let d = (model_heading - ideal_heading).abs();
    assert!(d > 0.0, "the moves were later: the IMU sensed them later");
    assert!(
        d < 0.005,
        "heading {model_heading} on the model, {ideal_heading} ideal"
    );
}
