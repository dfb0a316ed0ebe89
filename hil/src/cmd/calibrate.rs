//! `hil calibrate rotating-imu`: the self-calibration procedure, on the bus or in process.

use crate::*;

pub(crate) fn calibrate_rotating_imu(a: CalibrateArgs) -> Result<i32> {
    let o = hil::calibrate::CalibrateOptions {
        lat_deg: a.lat,
        heading_deg: a.heading.rem_euclid(360.0),
        tilt_deg: a.tilt,
        level_s: a.level,
        rotate_s: a.rotate,
        rate_dps: a.rate,
        inner_delay_s: a.inner_delay,
        seed: a.seed,
    };
    let mut s = hil::calibrate::scenario(&o);
    s.speed = a.speed;
    s.check()?;
    let out = absolute(
        &a.bus
            .out
            .clone()
            .unwrap_or_else(|| default_out("calibrate-rotating-imu")),
    )?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let scen = out.join("calibrate.toml");
    std::fs::write(&scen, toml::to_string_pretty(&s)?)?;
    eprintln!(
        "hil: self-calibration of the rotating IMU at latitude {} deg, heading {} deg: {} s at rest, {} s of rotation at {} deg/s, x{}",
        o.lat_deg, o.heading_deg, o.level_s, o.rotate_s, o.rate_dps, a.speed
    );
    if a.in_process {
        let o = hil::calibrate::run_in_process(&s, |p| {
            if let Ok(j) = serde_json::to_value(p) {
                hil::status::show(&hil::calibrate::progress_line(&j));
            }
        })?;
        hil::status::finish();
        let j = serde_json::json!({ "in_process": true, "calibration": o });
        std::fs::write(out.join("report.json"), serde_json::to_string_pretty(&j)?)?;
        if a.bus.json {
            println!("{}", serde_json::to_string_pretty(&j)?);
        } else {
            print!("{}", hil::calibrate::card(&o));
        }
        return Ok(i32::from(o.result.is_none()));
    }
    run(RunArgs {
        scenario: Some(scen),
        duration: None,
        speed: None,
        nav: None,
        no_reference: false,
        gpsd: false,
        bus: BusArgs {
            out: Some(out),
            ..a.bus
        },
    })
}
