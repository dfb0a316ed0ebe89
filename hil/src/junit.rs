//! JUnit XML, the results format CI servers read (GitLab, Jenkins, GitHub's test reporters):
//! every row of a fault matrix, every check of a run or a validation, every test of
//! `./run-tests` as a test case with its time and, when it failed, its failure text.
//!
//! What is written validates against the schema Jenkins' xUnit plug-in and pytest use
//! (`junit-10.xsd`): `<testsuites>` holding `<testsuite>` elements (name, tests, failures,
//! errors, skipped, time, timestamp, hostname) holding `<testcase>` elements (name, classname,
//! time) with at most one `<failure>` or `<skipped>` and a `<system-out>`. Times are in seconds
//! with three decimals. Text is escaped and characters XML cannot carry (control characters,
//! terminal colour codes' escape) are replaced, so any test's output can go in.

use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::Path;

/// How a test case ended.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// It passed.
    Passed,
    /// It failed: a one-line message and the full text (expected and observed values, the
    /// test's output).
    Failed {
        /// One line: what failed.
        message: String,
        /// The whole story.
        text: String,
    },
    /// It was not run, and why.
    Skipped {
        /// Why.
        message: String,
    },
}

/// One test case.
#[derive(Debug, Clone, PartialEq)]
pub struct Case {
    /// The case's name (a test's name, a fault's name, a check's name).
    pub name: String,
    /// Where it belongs (a test binary, a command): CI servers group by it.
    pub classname: String,
    /// Wall time, s (0 where the case has no time of its own, as a check of a run).
    pub time_s: f64,
    /// How it ended.
    pub outcome: Outcome,
    /// What it printed, kept for CI servers that show it beside the case (empty: none).
    pub output: String,
}

impl Case {
    /// A case that passed or failed with `message` and `text` when it did not.
    pub fn judged(
        classname: &str,
        name: &str,
        time_s: f64,
        pass: bool,
        message: String,
        text: String,
    ) -> Self {
        Case {
            name: name.to_string(),
            classname: classname.to_string(),
            time_s,
            outcome: if pass {
                Outcome::Passed
            } else {
                Outcome::Failed { message, text }
            },
            output: String::new(),
        }
    }
}

/// A test suite: cases under one name.
#[derive(Debug, Clone, PartialEq)]
pub struct Suite {
    /// The suite's name.
    pub name: String,
    /// Wall time of the whole suite, s (cases may overlap: not their sum).
    pub time_s: f64,
    /// When it started, RFC 3339 (empty: not said).
    pub timestamp: String,
    /// Its cases in order.
    pub cases: Vec<Case>,
}

impl Suite {
    /// A suite of `cases` named `name`, taking `time_s`, started now.
    pub fn new(name: &str, time_s: f64, cases: Vec<Case>) -> Self {
        Suite {
            name: name.to_string(),
            time_s,
            timestamp: nav::procedures::unit_parameters::now_rfc3339(),
            cases,
        }
    }

    fn count(&self, f: impl Fn(&Outcome) -> bool) -> usize {
        self.cases.iter().filter(|c| f(&c.outcome)).count()
    }

    /// Cases that failed.
    pub fn failures(&self) -> usize {
        self.count(|o| matches!(o, Outcome::Failed { .. }))
    }

    /// Cases that were skipped.
    pub fn skipped(&self) -> usize {
        self.count(|o| matches!(o, Outcome::Skipped { .. }))
    }
}

/// A run's checks as a suite (`hil run --junit`): one case per check (name, passed, detail),
/// failing with its detail (the measured value and the limit, in words).
pub fn of_checks<'a>(
    suite: &str,
    classname: &str,
    time_s: f64,
    checks: impl IntoIterator<Item = (&'a str, bool, &'a str)>,
) -> Suite {
    let cases = checks
        .into_iter()
        .map(|(name, pass, detail)| {
            Case::judged(
                classname,
                name,
                0.0,
                pass,
                detail.lines().next().unwrap_or_default().to_string(),
                detail.to_string(),
            )
        })
        .collect();
    Suite::new(suite, time_s, cases)
}

/// The suites of a JUnit document written elsewhere (another `--junit` file), kept as they
/// were written, with their totals, to go into a document of ours beside its own suites.
#[derive(Debug, Clone, PartialEq)]
pub struct Foreign {
    /// The `<testsuite>` elements, verbatim.
    pub suites_xml: String,
    /// Test cases in them.
    pub tests: usize,
    /// Failed (failures and errors).
    pub failures: usize,
}

/// The document: `<testsuites name=...>` with `suites` and then `foreign` ones.
pub fn document(name: &str, suites: &[Suite], foreign: &[Foreign]) -> String {
    let tests: usize = suites.iter().map(|s| s.cases.len()).sum::<usize>()
        + foreign.iter().map(|f| f.tests).sum::<usize>();
    let failures: usize = suites.iter().map(Suite::failures).sum::<usize>()
        + foreign.iter().map(|f| f.failures).sum::<usize>();
    let time: f64 = suites.iter().map(|s| s.time_s).sum();
    let mut x = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        x,
        "<testsuites name=\"{}\" tests=\"{tests}\" failures=\"{failures}\" errors=\"0\" time=\"{}\">",
        attr(name),
        seconds(time)
    );
    let host = hostname();
    for s in suites {
        let _ = write!(
            x,
            "  <testsuite name=\"{}\" tests=\"{}\" failures=\"{}\" errors=\"0\" skipped=\"{}\" time=\"{}\"",
            attr(&s.name),
            s.cases.len(),
            s.failures(),
            s.skipped(),
            seconds(s.time_s)
        );
        if !s.timestamp.is_empty() {
            let _ = write!(x, " timestamp=\"{}\"", attr(&s.timestamp));
        }
        let _ = writeln!(x, " hostname=\"{}\">", attr(&host));
        for c in &s.cases {
            case(&mut x, c);
        }
        x.push_str("  </testsuite>\n");
    }
    for f in foreign {
        x.push_str(&f.suites_xml);
        if !f.suites_xml.ends_with('\n') {
            x.push('\n');
        }
    }
    x.push_str("</testsuites>\n");
    x
}

fn case(x: &mut String, c: &Case) {
    let _ = write!(
        x,
        "    <testcase name=\"{}\" classname=\"{}\" time=\"{}\"",
        attr(&c.name),
        attr(&c.classname),
        seconds(c.time_s)
    );
    if c.outcome == Outcome::Passed && c.output.is_empty() {
        x.push_str("/>\n");
        return;
    }
    x.push_str(">\n");
    match &c.outcome {
        Outcome::Passed => {}
        Outcome::Failed { message, text } => {
            let _ = writeln!(
                x,
                "      <failure message=\"{}\" type=\"failure\">{}</failure>",
                attr(message),
                text_escape(text)
            );
        }
        Outcome::Skipped { message } => {
            let _ = writeln!(x, "      <skipped message=\"{}\"/>", attr(message));
        }
    }
    if !c.output.is_empty() {
        let _ = writeln!(
            x,
            "      <system-out>{}</system-out>",
            text_escape(&c.output)
        );
    }
    x.push_str("    </testcase>\n");
}

/// Seconds as the schema's time type takes them: digits, a point, three decimals, never
/// negative or not a number.
fn seconds(s: f64) -> String {
    format!("{:.3}", if s.is_finite() && s > 0.0 { s } else { 0.0 })
}

/// Characters XML 1.0 can carry (tab, newline, carriage return and from the space on, without
/// the surrogates and the two non-characters); anything else becomes U+FFFD.
fn xml_char(c: char) -> char {
    match c {
        '\t' | '\n' | '\r' => c,
        c if c < ' ' => '\u{fffd}',
        '\u{fffe}' | '\u{ffff}' => '\u{fffd}',
        c => c,
    }
}

/// Text as XML carries it: in element content (`attribute` false) or in a quoted attribute,
/// where line ends and tabs are kept as character references.
fn escape(s: &str, attribute: bool) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars().map(xml_char) {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' if attribute => o.push_str("&quot;"),
            '\n' if attribute => o.push_str("&#10;"),
            '\r' if attribute => o.push_str("&#13;"),
            '\t' if attribute => o.push_str("&#9;"),
            c => o.push(c),
        }
    }
    o
}

fn text_escape(s: &str) -> String {
    escape(s, false)
}

fn attr(s: &str) -> String {
    escape(s, true)
}

fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_else(|_| "localhost".into())
}

/// Write `document(name, suites, &[])` to `path` (its folder is made).
pub fn write(path: &Path, name: &str, suites: &[Suite]) -> Result<()> {
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    std::fs::write(path, document(name, suites, &[]))
        .with_context(|| format!("writing JUnit XML to {}", path.display()))
}

/// Read back a document this module wrote (a `--junit` file of `hil`), to put its suites into
/// another: the `<testsuite>` elements verbatim and the totals from its `<testsuites>` element.
pub fn foreign(xml: &str, what: &str) -> Result<Foreign> {
    let open = xml
        .find("<testsuites")
        .with_context(|| format!("{what}: no <testsuites> element"))?;
    let head_end = xml[open..]
        .find('>')
        .map(|i| open + i)
        .with_context(|| format!("{what}: <testsuites> is not closed"))?;
    let close = xml
        .rfind("</testsuites>")
        .with_context(|| format!("{what}: no </testsuites>"))?;
    if close < head_end {
        bail!("{what}: </testsuites> before its start");
    }
    let head = &xml[open..head_end];
    let number = |key: &str| -> Result<usize> {
        let pat = format!(" {key}=\"");
        let i = head
            .find(&pat)
            .with_context(|| format!("{what}: <testsuites> says no {key}"))?
            + pat.len();
        let v = &head[i..];
        let v = &v[..v.find('"').unwrap_or(v.len())];
        v.parse()
            .with_context(|| format!("{what}: <testsuites> {key}=\"{v}\" is not a count"))
    };
    Ok(Foreign {
        suites_xml: xml[head_end + 1..close]
            .trim_start_matches('\n')
            .to_string(),
        tests: number("tests")?,
        failures: number("failures")? + number("errors")?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<Suite> {
        vec![Suite::new(
            "fault matrix",
            12.5,
            vec![
                Case::judged(
                    "hil faults",
                    "imu-stop",
                    1.25,
                    true,
                    String::new(),
                    String::new(),
                ),
                Case::judged(
                    "hil faults",
                    "gps-jump <\"big\">",
                    2.0,
                    false,
                    "expected: rejected & counted; observed: accepted".into(),
                    "expected: rejected\nobserved: accepted \u{1b}[31m\u{0}".into(),
                ),
                Case {
                    name: "skipped one".into(),
                    classname: "hil faults".into(),
                    time_s: f64::NAN,
                    outcome: Outcome::Skipped {
                        message: "no vcan".into(),
                    },
                    output: String::new(),
                },
            ],
        )]
    }

    /// Counts, escapes and failures as a CI server reads them; the text keeps its lines and
    /// loses only what XML cannot carry.
    #[test]
    fn a_document_counts_and_escapes() {
        let x = document("bench", &sample(), &[]);
        assert!(x.starts_with("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<testsuites name=\"bench\" tests=\"3\" failures=\"1\" errors=\"0\" time=\"12.500\">"), "{x}");
        assert!(x.contains("skipped=\"1\""), "{x}");
        assert!(
            x.contains("name=\"gps-jump &lt;&quot;big&quot;&gt;\""),
            "{x}"
        );
        assert!(x.contains(
            "<failure message=\"expected: rejected &amp; counted; observed: accepted\" type=\"failure\">expected: rejected\nobserved: accepted \u{fffd}[31m\u{fffd}</failure>"
        ), "{x}");
        assert!(
            x.contains("<testcase name=\"imu-stop\" classname=\"hil faults\" time=\"1.250\"/>")
        );
        assert!(
            x.contains("time=\"0.000\">\n      <skipped message=\"no vcan\"/>"),
            "{x}"
        );
        assert!(!x.chars().any(|c| c < ' ' && c != '\n'), "{x}");
    }

    /// A document read back as foreign suites keeps its suites verbatim and its totals, and a
    /// document holding it counts them.
    #[test]
    fn a_document_goes_into_another() {
        let inner = document("faults", &sample(), &[]);
        let f = foreign(&inner, "faults.xml").unwrap();
        assert_eq!((f.tests, f.failures), (3, 1));
        assert!(
            f.suites_xml
                .starts_with("  <testsuite name=\"fault matrix\"")
        );
        assert!(f.suites_xml.trim_end().ends_with("</testsuite>"));
        let outer = document("all", &sample(), &[f]);
        assert!(outer.contains("tests=\"6\" failures=\"2\""), "{outer}");
        assert_eq!(outer.matches("<testsuite ").count(), 2);
        assert!(foreign("<testsuite/>", "x").is_err());
        assert!(
            foreign(
                "<testsuites tests=\"a\" failures=\"0\" errors=\"0\"></testsuites>",
                "x"
            )
            .unwrap_err()
            .to_string()
            .contains("not a count")
        );
    }
}
