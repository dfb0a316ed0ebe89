//! Running a command inside the QEMU guest where this kernel has no CAN, and the output folders.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use vcan_setup::{GUEST_ENV, VmOptions};

pub(crate) fn default_out(name: &str) -> PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    PathBuf::from("runs").join(format!("{name}-{secs}"))
}

pub(crate) fn absolute(p: &Path) -> Result<PathBuf> {
    Ok(if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir()?.join(p)
    })
}

/// This run's command line as clap parsed it, kept for running the same command again in the
/// guest ([`same_command`]).
static PARSED: std::sync::OnceLock<(clap::Command, clap::ArgMatches)> = std::sync::OnceLock::new();

/// Keep the command line `matches` of command `cmd` (hil's `main`, once).
pub(crate) fn remember(mut cmd: clap::Command, matches: clap::ArgMatches) {
    cmd.build();
    let _ = PARSED.set((cmd, matches));
}

/// This command again, for the guest, from its parsed arguments: every argument given on the
/// command line (or by the environment), the paths among them made absolute with their folders
/// shared, the options in `set` given the values there (added where absent: the output folder,
/// the nav binary, resolved here; those the command does not have left out) and those in `drop`
/// left out (`--junit`, handled by
/// [`run_in_guest_with_junit`]). Returns the arguments and the folders to share.
pub(crate) fn same_command(
    set: &[(&str, String)],
    drop: &[&str],
) -> Result<(Vec<String>, Vec<PathBuf>)> {
    as_command(None, set, drop)
}

/// [`same_command`], but as the command `target` (its path: `["run"]`) where this one hands its
/// work to it (a drill runs its scenario as `hil run` does): the options this command was given
/// that the target also has, with `set` (the target's options; the scenario the drill wrote).
pub(crate) fn as_command(
    target: Option<&[&str]>,
    set: &[(&str, String)],
    drop: &[&str],
) -> Result<(Vec<String>, Vec<PathBuf>)> {
    let (cmd, m) = PARSED
        .get()
        .context("the command line was not kept (hil's main calls cmd::guest::remember)")?;
    argv_of(cmd, m, target, set, drop)
}

/// A value for the guest's command line: a path made absolute, its folder (or itself, a
/// folder) added to `shares`.
fn value_for_guest(
    v: &std::ffi::OsStr,
    is_path: bool,
    shares: &mut Vec<PathBuf>,
) -> Result<String> {
    if !is_path {
        return Ok(v.to_string_lossy().into_owned());
    }
    let p = absolute(Path::new(v))?;
    shares.push(if p.is_dir() {
        p.clone()
    } else {
        p.parent().map(Path::to_path_buf).unwrap_or_default()
    });
    Ok(p.to_string_lossy().into_owned())
}

/// [`as_command`] for the command line `m` of command `root` (built).
fn argv_of(
    root: &clap::Command,
    m: &clap::ArgMatches,
    target: Option<&[&str]>,
    set: &[(&str, String)],
    drop: &[&str],
) -> Result<(Vec<String>, Vec<PathBuf>)> {
    let mut args = Vec::new();
    let mut shares = Vec::new();
    let (mut given_cmd, mut m) = (root, m);
    let mut path = Vec::new();
    while let Some((name, sub)) = m.subcommand() {
        path.push(name.to_string());
        given_cmd = given_cmd
            .find_subcommand(name)
            .with_context(|| format!("no subcommand {name} in hil's command line"))?;
        m = sub;
    }
    let cmd = match target {
        None => given_cmd,
        Some(t) => {
            path = t.iter().map(|x| x.to_string()).collect();
            t.iter().try_fold(root, |c, name| {
                c.find_subcommand(name)
                    .with_context(|| format!("no command {name} in hil"))
            })?
        }
    };
    args.extend(path);
    let mut positional = Vec::new();
    for arg in cmd.get_arguments() {
        let id = arg.get_id().as_str();
        // (as another command: only the options this one was given too)
        if !given_cmd
            .get_arguments()
            .any(|a| a.get_id() == arg.get_id())
        {
            continue;
        }
        let given = matches!(
            m.value_source(id),
            Some(clap::parser::ValueSource::CommandLine | clap::parser::ValueSource::EnvVariable)
        );
        if drop.contains(&id) || set.iter().any(|(k, _)| *k == id) || !given {
            continue;
        }
        let flag = arg
            .get_long()
            .map(|l| format!("--{l}"))
            .or_else(|| arg.get_short().map(|c| format!("-{c}")));
        if !arg.get_action().takes_values() {
            let n = match arg.get_action() {
                clap::ArgAction::Count => usize::from(m.get_count(id)),
                _ => 1,
            };
            args.extend(std::iter::repeat_n(flag.clone().unwrap_or_default(), n));
            continue;
        }
        let is_path = arg.get_value_parser().type_id() == std::any::TypeId::of::<PathBuf>();
        for occurrence in m.get_raw_occurrences(id).into_iter().flatten() {
            let values = occurrence
                .map(|v| value_for_guest(v, is_path, &mut shares))
                .collect::<Result<Vec<_>>>()?;
            match &flag {
                None => positional.extend(values),
                Some(f) if values.is_empty() => args.push(f.clone()),
                Some(f) => {
                    for v in values {
                        // a value that starts with '-' (a negative latitude) stays with its option
                        if v.starts_with('-') {
                            args.push(format!("{f}={v}"));
                        } else {
                            args.extend([f.clone(), v]);
                        }
                    }
                }
            }
        }
    }
    // an option the command does not have (a drill names no nav binary: the guest takes the
    // one beside hil, as here) is not asked for
    for (id, v) in set {
        if let Some(long) = cmd
            .get_arguments()
            .find(|a| a.get_id().as_str() == *id)
            .and_then(|a| a.get_long())
        {
            args.extend([format!("--{long}"), v.clone()]);
        }
    }
    args.extend(positional);
    shares.sort();
    shares.dedup();
    Ok((args, shares))
}

/// Run this program with `args` inside the QEMU guest (this kernel has no CAN): shares the
/// workspace, `out` and `extra` folders, with the libraries of the programs `libs_for`; `json`:
/// the run's JSON file in `out` then goes to stdout alone. Returns the guest command's exit
/// status.
pub(crate) fn run_in_guest(
    args: Vec<String>,
    out: &Path,
    mut extra: Vec<PathBuf>,
    libs_for: Vec<PathBuf>,
    json: Option<&str>,
) -> Result<i32> {
    if std::env::var_os(GUEST_ENV).is_some() {
        bail!(
            "inside the QEMU guest and still no CAN support: the guest kernel lacks the can/vcan modules"
        );
    }
    eprintln!("hil: this kernel has no CAN support; running on real vcan inside a QEMU guest");
    vcan_setup::install_prereqs()?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    extra.push(out.to_path_buf());
    let exe = std::env::current_exe()?;
    let mut full = vec![exe.to_string_lossy().into_owned()];
    let (args, forward_tcp) = live_through_guest(args)?;
    full.extend(args);
    let shares = dedupe_nested(vcan_setup::default_shares(&exe, &extra));
    let shares_ro = programs_cached(&exe, &shares);
    let mut opts = VmOptions {
        shares,
        shares_ro,
        libs_for,
        forward_tcp,
        ..VmOptions::default()
    };
    // long runs (the full campus loop) may need more than the default 40 minutes
    if let Some(v) = std::env::var_os("HIL_GUEST_TIMEOUT_S") {
        let s: u64 = v
            .to_str()
            .and_then(|v| v.parse().ok())
            .context("HIL_GUEST_TIMEOUT_S must be a whole number of seconds")?;
        opts.timeout = std::time::Duration::from_secs(s);
    }
    // the run's reference, replay and scoring are judged here, on this machine's CPU, not
    // under the guest's emulation (hil::run::offload), unless HIL_JUDGE_SERVER=off
    let judge = JudgeHere::start(out, &mut opts);
    let o = vcan_setup::run_in_vm(&full, &opts);
    judge.stop();
    let o = o?;
    if let Some(name) = json {
        // the guest's console mixes its stdout and stderr: the JSON comes from the file the run
        // wrote in the shared output folder, so stdout carries the JSON alone
        let p = out.join(name);
        match std::fs::read_to_string(&p) {
            Ok(j) => println!("{}", j.trim_end()),
            Err(e) => eprintln!("hil: the run in the guest wrote no {}: {e}", p.display()),
        }
    }
    eprintln!(
        "hil: guest boot {:.1} s, run {:.1} s",
        o.boot_secs,
        o.total_secs - o.boot_secs
    );
    Ok(o.status)
}

/// [`run_in_guest`] for a command with `--junit FILE` (`junit`): the guest writes its JUnit XML
/// into the shared output folder, and it is copied to FILE once the guest is done.
pub(crate) fn run_in_guest_with_junit(
    mut args: Vec<String>,
    out: &Path,
    extra: Vec<PathBuf>,
    libs_for: Vec<PathBuf>,
    json: Option<&str>,
    junit: Option<&Path>,
) -> Result<i32> {
    let pair = junit_through_guest(&mut args, out, junit)?;
    let code = run_in_guest(args, out, extra, libs_for, json)?;
    junit_back(pair)?;
    Ok(code)
}

/// `--junit FILE` of a command re-run in the guest: the guest writes `junit.xml` into the
/// shared output folder, and [`junit_back`] copies it to FILE once the guest is done.
fn junit_through_guest(
    args: &mut Vec<String>,
    out: &Path,
    junit: Option<&Path>,
) -> Result<Option<(PathBuf, PathBuf)>> {
    let Some(to) = junit else { return Ok(None) };
    let from = out.join("junit.xml");
    args.extend(["--junit".into(), from.to_string_lossy().into_owned()]);
    Ok(Some((from, absolute(to)?)))
}

/// Copy the guest's JUnit XML to where `--junit` asked (see [`junit_through_guest`]).
fn junit_back(pair: Option<(PathBuf, PathBuf)>) -> Result<()> {
    let Some((from, to)) = pair else {
        return Ok(());
    };
    if from == to {
        return Ok(());
    }
    if let Some(d) = to.parent() {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    std::fs::copy(&from, &to).with_context(|| {
        format!(
            "the run in the guest wrote no JUnit XML ({}) to copy to {}",
            from.display(),
            to.display()
        )
    })?;
    Ok(())
}

/// The folder of this program (and nav beside it) as a read-only share cached in the guest:
/// on a read-write share every start of a program reads its pages from this machine again
/// (nav 0.2 s, hil 0.6 s in the guest, against 0.06 and 0.1 s cached). Not where a read-write
/// share is that folder or lies inside it (the run writes there).
pub(crate) fn programs_cached(exe: &Path, shares: &[PathBuf]) -> Vec<PathBuf> {
    match exe.parent() {
        Some(d) if !shares.iter().any(|s| s.starts_with(d)) => vec![d.to_path_buf()],
        _ => Vec::new(),
    }
}

/// Drop shares that lie inside another share.
pub(crate) fn dedupe_nested(mut shares: Vec<PathBuf>) -> Vec<PathBuf> {
    shares.retain(|p| !p.as_os_str().is_empty());
    let all = shares.clone();
    shares.retain(|p| !all.iter().any(|q| q != p && p.starts_with(q)));
    shares.dedup();
    shares
}

/// A TCP port of the guest reachable from this host: (host address, guest port).
pub(crate) type Forward = (std::net::SocketAddr, u16);

/// A live view (`--live ADDR`) asked of a command that runs again in the guest: the guest's
/// server listens on the same port on all its addresses (the guest has no network but QEMU's
/// forward), and QEMU forwards ADDR on this host to it. Port 0 becomes a free port here.
pub(crate) fn live_through_guest(mut args: Vec<String>) -> Result<(Vec<String>, Vec<Forward>)> {
    let mut forward = Vec::new();
    if let Some(i) = args.iter().position(|a| a == "--live")
        && let Some(addr) = args.get(i + 1)
    {
        let mut host: std::net::SocketAddr = addr
            .parse()
            .with_context(|| format!("--live {addr}: not ADDR:PORT"))?;
        if host.port() == 0 {
            let l = std::net::TcpListener::bind(host)
                .with_context(|| format!("--live {host}: no free port"))?;
            host = l.local_addr()?;
        }
        args[i + 1] = format!("0.0.0.0:{}", host.port());
        forward.push((host, host.port()));
        eprintln!(
            "hil: live view: ws://{host} on this host, forwarded into the guest (up once it has booted)"
        );
    }
    Ok((args, forward))
}

/// A judge server on this machine for the runs of a command in the guest, in a folder of the
/// shared output folder (`hil::run::offload`).
struct JudgeHere {
    dir: PathBuf,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    server: Option<std::thread::JoinHandle<Result<hil::run::offload::Served>>>,
}

impl JudgeHere {
    fn start(out: &Path, opts: &mut VmOptions) -> Self {
        use hil::run::offload::{ENV, serve};
        let dir = out.join(".judge-server");
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let mut me = Self {
            dir: dir.clone(),
            stop: std::sync::Arc::clone(&stop),
            server: None,
        };
        if std::env::var(ENV).is_ok_and(|v| v == "off") {
            return me;
        }
        me.server = Some(std::thread::spawn(move || serve(&dir, 2, &stop)));
        opts.env
            .push((ENV.into(), me.dir.to_string_lossy().into_owned()));
        me
    }

    fn stop(self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(h) = self.server {
            match h.join() {
                Ok(Ok(_)) => {}
                Ok(Err(e)) => eprintln!("hil: the judge server for the guest: {e:#}"),
                Err(_) => eprintln!("hil: the judge server for the guest panicked"),
            }
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_programs_folder_is_cached_unless_a_run_writes_inside_it() {
        let exe = Path::new("/w/target/debug/hil");
        let ws = PathBuf::from("/w");
        // the workspace and an output folder elsewhere: the programs' folder read-only, cached
        assert_eq!(
            programs_cached(exe, &[ws.clone(), "/tmp/run".into()]),
            vec![PathBuf::from("/w/target/debug")]
        );
        // an output folder inside it, or the folder itself shared (no workspace around the
        // program): left read-write
        assert!(programs_cached(exe, &[ws, "/w/target/debug/runs/a".into()]).is_empty());
        assert!(programs_cached(exe, &["/w/target/debug".into()]).is_empty());
    }
    use clap::{CommandFactory, FromArgMatches};

    /// hil's command line `argv`, parsed, then again as the guest is given it (with `set` and
    /// without `drop`): the guest's arguments and the folders shared.
    fn again(
        argv: &[&str],
        set: &[(&str, String)],
        drop: &[&str],
    ) -> (crate::Cli, Vec<String>, Vec<PathBuf>) {
        let mut cmd = crate::Cli::command();
        cmd.build();
        let m = cmd.clone().try_get_matches_from(argv).expect("parses");
        let (args, shares) = argv_of(&cmd, &m, None, set, drop).expect("the command again");
        let m2 = cmd
            .try_get_matches_from(std::iter::once("hil".to_string()).chain(args.iter().cloned()))
            .unwrap_or_else(|e| panic!("{args:?} parses again: {e}"));
        (
            crate::Cli::from_arg_matches(&m2).expect("a command"),
            args,
            shares,
        )
    }

    /// A command run again in the guest asks for what was asked here: every option given (a
    /// flag, a value, a value that starts with '-', an optional value left out), the paths
    /// made absolute with their folders shared, the output folder and nav set here, `--junit`
    /// left to the guest's own file; defaults are not spelled out (the guest takes the same).
    #[test]
    fn a_command_again_in_the_guest_parses_to_what_was_asked() {
        let here = std::env::current_dir().expect("a working folder");
        let (cli, args, shares) = again(
            &[
                "hil",
                "run",
                "--scenario",
                "x/drive.toml",
                "--speed",
                "5",
                "--no-reference",
                "--live",
                "--iface",
                "vcan9",
                "--junit",
                "j.xml",
                "--json",
            ],
            &[("out", "/o".into()), ("nav", "/bin/nav2".into())],
            &["junit"],
        );
        let crate::Cmd::Run(a) = cli.cmd else {
            panic!("{args:?}: not run")
        };
        assert_eq!(a.scenario, Some(here.join("x/drive.toml")));
        assert_eq!(shares, vec![here.join("x")]);
        assert_eq!(a.speed, Some(5.0));
        assert!(a.no_reference && a.bus.json && !a.gpsd);
        assert_eq!(
            a.live.live,
            Some(hil::live::DEFAULT_ADDR.parse().expect("an address"))
        );
        assert_eq!(a.bus.iface, "vcan9");
        assert_eq!(a.bus.out, Some(PathBuf::from("/o")));
        assert_eq!(a.nav, Some(PathBuf::from("/bin/nav2")));
        assert_eq!(a.junit, None);
        assert!(
            !args.iter().any(|x| x == "--duration"),
            "{args:?}: a default spelled out"
        );
    }

    /// A subcommand's subcommand again in the guest: a negative value kept with its option, an
    /// option it does not have (`--nav`) not asked for.
    #[test]
    fn a_subcommands_subcommand_again_in_the_guest_keeps_its_values() {
        let (cli, args, _) = again(
            &[
                "hil",
                "drill",
                "north-finding",
                "--lat",
                "-35.5",
                "--out-and-back",
            ],
            &[("out", "/o".into()), ("nav", "/bin/nav2".into())],
            &[],
        );
        assert!(
            !args.iter().any(|x| x == "--nav"),
            "{args:?}: the drill has no --nav"
        );
        let crate::Cmd::Drill(crate::cmd::drill::Drill::NorthFinding(a)) = cli.cmd else {
            panic!("{args:?}: not the drill")
        };
        assert_eq!(a.lat, -35.5, "{args:?}");
        assert_eq!(a.bus.out, Some(PathBuf::from("/o")), "{args:?}");
        assert!(a.out_and_back, "{args:?}");
    }

    /// A drill's scenario handed to `hil run` goes to the guest as `hil run`: the options both
    /// commands have, the scenario set, the drill's own options (`--seed`) left out.
    #[test]
    fn a_drill_handed_to_run_goes_to_the_guest_as_run() {
        let mut cmd = crate::Cli::command();
        cmd.build();
        let m = cmd
            .clone()
            .try_get_matches_from([
                "hil",
                "drill",
                "north-finding",
                "--seed",
                "7",
                "--speed",
                "10",
                "--iface",
                "vcan3",
                "--json",
            ])
            .expect("parses");
        let (args, _) = argv_of(
            &cmd,
            &m,
            Some(&["run"]),
            &[("scenario", "/o/scenario.toml".into())],
            &[],
        )
        .expect("as hil run");
        let m2 = cmd
            .try_get_matches_from(std::iter::once("hil".to_string()).chain(args.iter().cloned()))
            .unwrap_or_else(|e| panic!("{args:?}: {e}"));
        let crate::Cmd::Run(r) = crate::Cli::from_arg_matches(&m2).expect("a command").cmd else {
            panic!("{args:?}: not run")
        };
        assert_eq!(r.scenario, Some(PathBuf::from("/o/scenario.toml")));
        assert_eq!(
            (r.speed, r.bus.iface.as_str(), r.bus.json),
            (Some(10.0), "vcan3", true)
        );
        assert!(
            !args.iter().any(|x| x == "--seed"),
            "{args:?}: run has no --seed"
        );
    }
}
