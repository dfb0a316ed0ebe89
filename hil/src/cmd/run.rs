//! `hil run`: one scenario through the bench.

use crate::*;

pub(crate) fn run(a: RunArgs) -> Result<i32> {
    let mut s = match &a.scenario {
        Some(p) => Scenario::load(p)?,
        None => Scenario::builtin_static(),
    };
    if let Some(d) = a.duration {
        s.duration_s = d;
    }
    if let Some(x) = a.speed {
        s.speed = x;
    }
    s.check()?;
    let out = absolute(&match &a.bus.out {
        Some(o) => o.clone(),
        None => default_out(&s.name),
    })?;
    let in_guest = std::env::var_os(GUEST_ENV).is_some();
    if a.bus.here() {
        let nav_bin = match &a.nav {
            Some(n) => n.clone(),
            None => sibling_binary("nav")?,
        };
        let opts = RunOptions {
            progress: true,
            reference_checks: !a.no_reference,
            gps_via_gpsd: a.gpsd,
            ..RunOptions::new(&a.bus.iface, out.clone(), nav_bin)
        };
        let backend = if in_guest { "vm" } else { "native" };
        let r = run_here(&s, &opts, backend)?;
        if a.bus.json {
            println!("{}", serde_json::to_string_pretty(&r)?);
        } else {
            print!("{}", report::card(&r));
            println!(
                " report: {} (and report.md beside it)",
                out.join("report.html").display()
            );
        }
        return Ok(if r.pass { 0 } else { 1 });
    }
    // No CAN here: run this same command inside the QEMU guest.
    let mut args: Vec<String> = vec!["run".into()];
    let mut extra = vec![out.clone()];
    if let Some(p) = &a.scenario {
        let p = absolute(p)?;
        extra.push(p.parent().map(Path::to_path_buf).unwrap_or_default());
        args.extend(["--scenario".into(), p.to_string_lossy().into_owned()]);
    }
    args.extend([
        "--duration".into(),
        s.duration_s.to_string(),
        "--speed".into(),
        s.speed.to_string(),
    ]);
    args.extend([
        "--iface".into(),
        a.bus.iface.clone(),
        "--out".into(),
        out.to_string_lossy().into_owned(),
    ]);
    let nav = match &a.nav {
        Some(n) => absolute(n)?,
        None => sibling_binary("nav")?,
    };
    args.extend(["--nav".into(), nav.to_string_lossy().into_owned()]);
    if a.bus.json {
        args.push("--json".into());
    }
    if a.no_reference {
        args.push("--no-reference".into());
    }
    if a.gpsd {
        args.push("--gpsd".into());
    }
    run_in_guest(
        args,
        &out,
        extra,
        vec![nav],
        a.bus.json.then_some("report.json"),
    )
}
