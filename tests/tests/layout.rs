//! The code's layout rules, read from the sources (`crate::` paths outside comments and test
//! modules):
//! - no circle of module imports in any crate of the workspace;
//! - hil's folders import only from those before them (scenario, engine, procedures, report,
//!   run, experiments, suites), and its top-level helpers import nothing of the crate;
//! - nav's parts import only from those before them (frontend, navigation, procedures,
//!   record, then config, summary and pipeline, then the shell);
//! - the emulators' models are pure: nothing outside `emulators/src/adapters/` imports an
//!   adapter, reads the wall clock, sleeps, starts a thread or touches a socket;
//! - a file's name is used once in its crate (but `mod.rs`, `lib.rs`, `main.rs`, `tests.rs`,
//!   and hil's `cmd/`, whose files are named for the commands they parse);
//! - no function over 100 lines outside tests, but for the tables of data in [`DATA_TABLES`];
//! - no module imports its crate's root whole (`use crate::*`);
//! - the README and the docs record no dated results.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const CRATES: [&str; 5] = ["wire", "nav", "emulators", "hil", "vcan-setup"];

/// hil's folders in the order they may import (each from those before it).
const HIL_LAYERS: [&str; 11] = [
    "scenario",
    "engine",
    "live",
    "procedures",
    "report",
    "run",
    "replay",
    "free",
    "experiments",
    "suites",
    "campaign",
];

/// nav's parts in the order they may import (each from those before it): its folders and, between
/// the recording and the shell, the top-level modules the pipeline is made of.
const NAV_LAYERS: [&str; 8] = [
    "frontend",
    "navigation",
    "procedures",
    "record",
    "config",
    "summary",
    "pipeline",
    "shell",
];

fn src(krate: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(krate)
        .join("src")
}

/// Every source file under `dir` (recursively), with its text.
fn files(dir: &Path, out: &mut Vec<(PathBuf, String)>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("a directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            let t = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            out.push((p, t));
        }
    }
}

/// The file's text without its test modules (`#[cfg(test)]` on a `mod` at the top level, to
/// its closing brace), wherever they stand in the file.
fn without_tests(t: &str) -> String {
    let mut out = String::new();
    let mut lines = t.lines().peekable();
    while let Some(l) = lines.next() {
        if l == "#[cfg(test)]" && lines.peek().is_some_and(|n| n.starts_with("mod ")) {
            for m in lines.by_ref() {
                if m == "}" {
                    break;
                }
            }
            continue;
        }
        out.push_str(l);
        out.push('\n');
    }
    out
}

/// The module path of `file` under `root` (`engine::inproc`; `lib.rs`, `main.rs` by name).
fn module_of(root: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(root).expect("under the source folder");
    let mut parts: Vec<String> = rel
        .with_extension("")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if parts.len() > 1 && parts.last().is_some_and(|l| l == "mod") {
        parts.pop();
    }
    parts.join("::")
}

/// The crate's modules and the modules each imports (`crate::` paths, longest module prefix).
fn imports(krate: &str) -> BTreeMap<String, BTreeSet<String>> {
    let root = src(krate);
    let mut fs = Vec::new();
    files(&root, &mut fs);
    let mods: BTreeSet<String> = fs.iter().map(|(p, _)| module_of(&root, p)).collect();
    let mut edges = BTreeMap::new();
    for (p, t) in &fs {
        let m = module_of(&root, p);
        let mut deps = BTreeSet::new();
        for line in without_tests(t).lines() {
            if line.trim_start().starts_with("//") {
                continue;
            }
            for (i, _) in line.match_indices("crate::") {
                let path: String = line[i + 7..]
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
                    .collect();
                let segs: Vec<&str> = path.split("::").filter(|s| !s.is_empty()).collect();
                for n in (1..=segs.len()).rev() {
                    let c = segs[..n].join("::");
                    if mods.contains(&c) {
                        if c != m {
                            deps.insert(c);
                        }
                        break;
                    }
                }
            }
        }
        edges.insert(m, deps);
    }
    edges
}

/// A circle among `edges`, as the modules round it, if there is one.
fn circle(edges: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        m: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(m.to_string(), 1);
        path.push(m.to_string());
        for d in edges.get(m).into_iter().flatten() {
            match state.get(d.as_str()) {
                Some(1) => {
                    let from = path.iter().position(|p| p == d).unwrap_or(0);
                    let mut c = path[from..].to_vec();
                    c.push(d.clone());
                    return Some(c);
                }
                Some(_) => {}
                None => {
                    if let Some(c) = visit(d, edges, state, path) {
                        return Some(c);
                    }
                }
            }
        }
        path.pop();
        state.insert(m.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for m in edges.keys() {
        if !state.contains_key(m.as_str())
            && let Some(c) = visit(m, edges, &mut state, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

/// No module imports its crate's root whole: a glob hides which items it takes, and in a
/// binary (hil's commands under `main.rs`) it imports the root back, a circle the import graph
/// above cannot see (it reads named paths only).
#[test]
fn no_module_imports_its_crate_root_whole() {
    let mut found = Vec::new();
    let mut read = 0;
    for k in CRATES {
        let mut fs = Vec::new();
        files(&src(k), &mut fs);
        for (p, t) in &fs {
            read += 1;
            for line in without_tests(t).lines() {
                let l = line.trim_start();
                let l = l
                    .strip_prefix("pub(crate) ")
                    .or(l.strip_prefix("pub "))
                    .unwrap_or(l);
                if l.starts_with("use crate::*") || l.starts_with("use crate::{*") {
                    found.push(format!("{}: {}", p.display(), line.trim()));
                }
            }
        }
    }
    assert!(read > 50, "{read} files read");
    assert!(
        found.is_empty(),
        "glob imports of a crate root:\n{}",
        found.join("\n")
    );
}

#[test]
fn no_crate_has_a_circle_of_module_imports() {
    for k in CRATES {
        let edges = imports(k);
        assert!(edges.len() > 3, "{k}: {} modules read", edges.len());
        if let Some(c) = circle(&edges) {
            panic!(
                "{k}: modules import each other round a circle: {}",
                c.join(" -> ")
            );
        }
    }
}

/// Modules of `krate` that import a module of a later layer than their own (`layers`, the top
/// module of each path), and how many modules were checked. `lib`, `main` and the folders in
/// `skip` are not checked; a module in no layer may import nothing of the crate when
/// `top_helpers_import_nothing`, and is itself an error otherwise.
fn layer_violations(
    krate: &str,
    layers: &[&str],
    skip: &[&str],
    top_helpers_import_nothing: bool,
) -> (Vec<String>, usize) {
    let layer = |m: &str| -> Option<usize> {
        let top = m.split("::").next().unwrap_or(m);
        layers.iter().position(|l| *l == top)
    };
    let (mut bad, mut checked) = (Vec::new(), 0);
    for (m, deps) in imports(krate) {
        let top = m.split("::").next().unwrap_or(&m);
        if m == "lib" || m == "main" || skip.contains(&top) {
            continue;
        }
        checked += 1;
        for d in deps {
            match (layer(&m), layer(&d)) {
                (Some(a), Some(b)) if b > a => bad.push(format!(
                    "{krate}::{m} ({}) imports {krate}::{d} ({}), a part after its own",
                    layers[a], layers[b]
                )),
                (None, _) if top_helpers_import_nothing => bad.push(format!(
                    "{krate}'s top-level helper {m} imports {krate}::{d}"
                )),
                (None, _) => bad.push(format!("{krate}::{m} is in none of the parts {layers:?}")),
                _ => {}
            }
        }
    }
    (bad, checked)
}

#[test]
fn hils_folders_import_only_from_those_before_them() {
    let (bad, checked) = layer_violations("hil", &HIL_LAYERS, &["cmd"], true);
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    assert!(checked > 30, "{checked} modules of hil checked");
}

#[test]
fn navs_parts_import_only_from_those_before_them() {
    let (bad, checked) = layer_violations("nav", &NAV_LAYERS, &[], false);
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    assert!(checked > 30, "{checked} modules of nav checked");
    // every module of nav is in one of its parts (a new file at the top is a new part, named
    // in NAV_LAYERS, or belongs in a folder)
    let root = src("nav");
    let mut fs = Vec::new();
    files(&root, &mut fs);
    let outside: Vec<String> = fs
        .iter()
        .map(|(p, _)| module_of(&root, p))
        .filter(|m| {
            let top = m.split("::").next().unwrap_or(m);
            m != "lib" && m != "main" && !NAV_LAYERS.contains(&top)
        })
        .collect();
    assert!(
        outside.is_empty(),
        "nav's modules outside its parts: {outside:?}"
    );
}

/// "Pure" is a folder in the emulators: the models (truth, drive, road, IMU, turntable,
/// receiver, bus model, the step order) import no adapter, and none reads the wall clock,
/// sleeps, starts a thread or opens a socket (tests aside). Their results depend on simulated
/// time and the seed only; `adapters/` puts them on vcan and the pty.
#[test]
fn the_emulators_models_are_pure() {
    let root = src("emulators");
    let mut fs = Vec::new();
    files(&root, &mut fs);
    let mut bad = Vec::new();
    for (m, deps) in imports("emulators") {
        if m == "lib" || m.starts_with("adapters") {
            continue;
        }
        for d in deps.iter().filter(|d| d.starts_with("adapters")) {
            bad.push(format!("emulators::{m} imports emulators::{d}"));
        }
    }
    let io = [
        "Instant",
        "SystemTime",
        "thread::",
        "libc::",
        "socketcan",
        "std::net",
    ];
    for (p, t) in &fs {
        // the adapters, and a module's tests kept in a file of their own
        if module_of(&root, p).starts_with("adapters") || p.ends_with("tests.rs") {
            continue;
        }
        for line in without_tests(t).lines() {
            let l = line.trim_start();
            if l.starts_with("//") {
                continue;
            }
            if let Some(w) = io.iter().find(|w| l.contains(*w)) {
                bad.push(format!("{}: {w}: {}", p.display(), l));
            }
        }
    }
    assert!(fs.len() > 20, "{} files of the emulators read", fs.len());
    assert!(
        bad.is_empty(),
        "the emulators' models touch I/O:\n{}",
        bad.join("\n")
    );
}

/// No two files of a crate have the same name: a reader who meets `observe.rs` knows which one
/// is meant. Not counted: `mod.rs`, `lib.rs`, `main.rs`, `tests.rs` (a module's tests beside
/// it), and hil's `cmd/` (each file named for the command whose arguments it parses, whose work
/// lives elsewhere under a name of its own).
#[test]
fn a_files_name_is_used_once_in_its_crate() {
    let mut dups = Vec::new();
    for k in CRATES {
        let root = src(k);
        let mut fs = Vec::new();
        files(&root, &mut fs);
        let mut seen: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for (p, _) in &fs {
            let rel = p.strip_prefix(&root).expect("under the source folder");
            let name = rel
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned());
            if ["mod.rs", "lib.rs", "main.rs", "tests.rs"].contains(&name.as_str())
                || (k == "hil" && rel.starts_with("cmd"))
            {
                continue;
            }
            seen.entry(name)
                .or_default()
                .push(rel.display().to_string());
        }
        for (name, at) in seen {
            if at.len() > 1 {
                dups.push(format!("{k}: {name} at {}", at.join(", ")));
            }
        }
    }
    assert!(
        dups.is_empty(),
        "file names used twice:\n{}",
        dups.join("\n")
    );
}

/// Where a function starts on `line`: its indentation and name (none for other lines).
fn fn_start(line: &str) -> Option<(usize, String)> {
    let t = line.trim_start();
    let indent = line.len() - t.len();
    let mut rest = t;
    for p in [
        "pub(crate) ",
        "pub(super) ",
        "pub ",
        "const ",
        "async ",
        "unsafe ",
    ] {
        rest = rest.strip_prefix(p).unwrap_or(rest);
    }
    let name: String = rest
        .strip_prefix("fn ")?
        .chars()
        .take_while(|c| c.is_alphanumeric() || *c == '_')
        .collect();
    Some((indent, name))
}

/// The functions that are tables of data, not steps (file, function): each fault matrix row
/// with its injection and verdict, and the wire contract's decoding, one arm per message. They
/// may pass 100 lines, never 150.
const DATA_TABLES: [(&str, &str); 7] = [
    ("wire/src/messages/mod.rs", "decode"),
    ("hil/src/suites/faults/bus.rs", "interface"),
    ("hil/src/suites/faults/physical.rs", "bus_off"),
    ("hil/src/suites/faults/physical.rs", "disturbances"),
    ("hil/src/suites/faults/gps.rs", "stream"),
    ("hil/src/suites/faults/imu.rs", "sensor"),
    ("hil/src/suites/faults/imu.rs", "frames"),
];

#[test]
fn no_function_passes_100_lines_outside_tests_and_tables_of_data() {
    let mut long = Vec::new();
    let mut counted = 0;
    let mut tables_seen = BTreeSet::new();
    for k in CRATES {
        let root = src(k);
        let mut fs = Vec::new();
        files(&root, &mut fs);
        for (p, t) in &fs {
            let text = without_tests(t);
            let lines: Vec<&str> = text.lines().collect();
            for (i, l) in lines.iter().enumerate() {
                let Some((indent, name)) = fn_start(l) else {
                    continue;
                };
                // a declaration without a body (a trait's) ends with `;` before any `{`
                let sig_end = lines[i..]
                    .iter()
                    .position(|s| s.contains('{') || s.trim_end().ends_with(';'))
                    .map_or(i, |j| i + j);
                if !lines[sig_end].contains('{') {
                    continue;
                }
                let close = format!("{}}}", " ".repeat(indent));
                if lines[sig_end].trim_end().ends_with('}') {
                    continue;
                }
                let Some(end) = lines[sig_end..]
                    .iter()
                    .position(|s| s.trim_end() == close)
                    .map(|j| sig_end + j)
                else {
                    continue;
                };
                counted += 1;
                let n = end - i + 1;
                let rel = p
                    .strip_prefix(&root)
                    .map_or(p.clone(), |r| Path::new(k).join("src").join(r));
                let table = DATA_TABLES
                    .iter()
                    .any(|(f, n)| Path::new(f) == rel && *n == name);
                if table {
                    tables_seen.insert((rel.display().to_string(), name.clone()));
                }
                if n > 100 && !(table && n < 150) {
                    long.push(format!("{}: {name}, {n} lines", rel.display()));
                }
            }
        }
    }
    assert!(counted > 500, "{counted} functions measured");
    assert!(
        long.is_empty(),
        "functions over 100 lines (split where a function does two things):\n{}",
        long.join("\n")
    );
    // the list names functions that are there (a renamed table must not leave a stale entry)
    assert_eq!(
        tables_seen.len(),
        DATA_TABLES.len(),
        "tables of data found: {tables_seen:?}"
    );
}

/// A date (`YYYY-MM-DD`) in `line`, if it has one.
fn date_in(line: &str) -> Option<&str> {
    let b = line.as_bytes();
    (0..b.len().saturating_sub(9)).find_map(|i| {
        let w = &b[i..i + 10];
        let digits = |r: std::ops::Range<usize>| w[r].iter().all(u8::is_ascii_digit);
        let bounded = i == 0 || !b[i - 1].is_ascii_alphanumeric();
        (bounded && digits(0..4) && w[4] == b'-' && digits(5..7) && w[7] == b'-' && digits(8..10))
            .then(|| &line[i..i + 10])
    })
}

/// The README and the docs record no dated results (history is in git): no date outside a
/// code block (where a file format's own date field may stand as an example).
#[test]
fn no_document_records_dated_results() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut docs = vec![root.join("README.md")];
    for e in std::fs::read_dir(root.join("docs")).expect("docs/") {
        let p = e.expect("a directory entry").path();
        if p.extension().is_some_and(|x| x == "md") {
            docs.push(p);
        }
    }
    let mut dated = Vec::new();
    for p in &docs {
        let text = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        let mut in_code = false;
        for (n, l) in text.lines().enumerate() {
            if l.trim_start().starts_with("```") {
                in_code = !in_code;
                continue;
            }
            if let Some(d) = date_in(l).filter(|_| !in_code) {
                dated.push(format!("{}:{}: {d}", p.display(), n + 1));
            }
        }
    }
    assert!(docs.len() > 10, "{} documents read", docs.len());
    assert!(
        dated.is_empty(),
        "dated results in the docs (put the figure beside its command; history is in git):\n{}",
        dated.join("\n")
    );
    assert_eq!(date_in("re-measured 2026-11-23: x"), Some("2026-11-23"));
    assert_eq!(date_in("version 12026-11-23"), None);
}
