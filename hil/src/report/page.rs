//! The HTML page every report is: its frame and style, escaping, figures, and the page of a
//! folder whose results are written as Markdown (experiments, validation, the fault matrix,
//! fuzzing, the benchmarks). Generic: it knows no report.

use std::fmt::Write;
use std::path::Path;

/// Escape text for HTML.
pub fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1000px;margin:2em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top}\
th{background:#f3f3f3}.pass{color:#176b2c;font-weight:bold}.fail{color:#b00020;font-weight:bold}\
figure{margin:1.5em 0}figcaption{color:#555;font-size:90%}svg{max-width:100%;height:auto}";

/// A whole page: `title` and the body's HTML.
pub fn page(title: &str, body: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\n<style>{STYLE}</style></head>\n<body>\n<h1>{}</h1>\n{body}</body></html>\n",
        esc(title),
        esc(title)
    )
}

pub fn figure(svg: &str, caption: &str) -> String {
    format!(
        "<figure>\n{svg}<figcaption>{}</figcaption></figure>\n",
        esc(caption)
    )
}

/// The report page of a folder whose results are written as Markdown (experiments, turntable
/// validation, the fault matrix, fuzzing, the pace benchmark): `markdown` as HTML, every SVG
/// plot in `out` inline as a figure, and links to the folder's other files. Written to
/// `out/report.html` (self-contained: no scripts, nothing fetched); returns its path.
pub fn folder_page(out: &Path, title: &str, markdown: &str) -> anyhow::Result<std::path::PathBuf> {
    use anyhow::Context;
    use pulldown_cmark::{Options, Parser, html};
    let mut body = String::new();
    // a title of its own is given: the Markdown's first heading would repeat it
    let md = match markdown.strip_prefix("# ") {
        Some(rest) => rest.split_once('\n').map_or("", |x| x.1),
        None => markdown,
    };
    html::push_html(
        &mut body,
        Parser::new_ext(md, Options::ENABLE_TABLES | Options::ENABLE_STRIKETHROUGH),
    );
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(out)
        .with_context(|| format!("reading {}", out.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    let name = |p: &Path| {
        p.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let mut links = Vec::new();
    for f in &files {
        let n = name(f);
        if n == "report.html" {
            continue;
        }
        if n.ends_with(".svg") {
            let svg = std::fs::read_to_string(f).with_context(|| format!("reading {n}"))?;
            // inline SVG takes no XML prolog
            let svg = match svg.find("<svg") {
                Some(i) => &svg[i..],
                None => continue,
            };
            body += &figure(svg, &n);
        }
        links.push(n);
    }
    if !links.is_empty() {
        body += "<h2>Files</h2>\n<ul>\n";
        for n in links {
            let _ = writeln!(body, "<li><a href=\"{0}\">{0}</a></li>", esc(&n));
        }
        body += "</ul>\n";
    }
    let path = out.join("report.html");
    std::fs::write(&path, page(title, &body))
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_page_holds_the_markdown_its_plots_and_links() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(
            d.path().join("plot.svg"),
            "<?xml version=\"1.0\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\"><line/></svg>",
        )
        .unwrap();
        std::fs::write(d.path().join("runs.csv"), "a,b\n").unwrap();
        let md = "# Title\n\n| case | error |\n|---|---:|\n| a < b | 1.5 |\n\n- one\n";
        let p = folder_page(d.path(), "An experiment", md).unwrap();
        let h = std::fs::read_to_string(p).unwrap();
        assert!(
            h.contains("<h1>An experiment</h1>") && !h.contains("<h1>Title"),
            "{h}"
        );
        assert!(h.contains("<td>a &lt; b</td>"), "{h}");
        assert!(h.contains("<figure>\n<svg") && !h.contains("<?xml"), "{h}");
        assert!(
            h.contains("<a href=\"runs.csv\">") && h.contains("<li>one</li>"),
            "{h}"
        );
        assert!(!h.contains("<script"));
    }
}
