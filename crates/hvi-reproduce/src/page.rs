//! `index.html`: the reproduction as one self-contained web page beside `report.md`.
//!
//! - The summary table (every figure's verdict, what it was at the last run, and a strip of
//!   its verdicts over the history), then each figure with its verdict, the paper's result and
//!   ours, its pictures (by relative path: the PNGs beside the page) and its deciding numbers,
//!   each with a small chart of its history across the runs of this tier.
//! - Each chart point names its commit, date and value (an SVG `<title>`, shown on hover); a
//!   point whose value differs from the run before is drawn red, and a figure whose verdict
//!   changed since the last run is marked at the top of the page and in the table.
//! - The charts are SVG written here; the page loads nothing from a network. A few lines of
//!   inline script record on `<body>` how many pictures loaded and whether any error occurred
//!   (`data-images`, `data-images-loaded`, `data-errors`), which the browser test reads.
//!
//! docs/reproduction.md shows the page.

use std::fmt::Write as _;
use std::path::Path;

use hvi_run::error::Result;
use hvi_run::files::write_atomic_bytes;

use crate::history::{History, Record};
use crate::report::{fmt_duration, Figure, Reproduction, Value, Verdict};

/// The page's file name.
pub const PAGE_FILE: &str = "index.html";

/// Chart size, px.
const CHART: (f64, f64) = (260.0, 54.0);
/// Margins: left for the value labels, and around.
const PAD: (f64, f64) = (64.0, 8.0);

/// Writes `index.html` into `dir` for `rep` (the run just finished) and the history it was
/// appended to (its last record of `rep`'s tier is this run).
pub fn write_page(dir: &Path, rep: &Reproduction, history: &History) -> Result<()> {
    write_atomic_bytes(&dir.join(PAGE_FILE), page(rep, history).as_bytes())?;
    Ok(())
}

/// HTML-escaped text.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// An anchor id for a figure.
fn anchor(id: &str) -> String {
    format!("fig-{id}")
}

fn verdict_badge(v: Verdict) -> String {
    let class = match v {
        Verdict::Reproduced => "ok",
        Verdict::Partly => "partly",
        Verdict::Not => "not",
        Verdict::Pending => "pending",
    };
    format!("<span class=\"verdict {class}\">{}</span>", esc(v.word()))
}

const STYLE: &str = "body{font-family:system-ui,sans-serif;max-width:1100px;margin:1.5em auto;padding:0 1em;color:#222}\
h1{font-size:1.5em}h2{margin-top:2em;border-bottom:1px solid #ccc}\
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ddd;padding:3px 8px;vertical-align:middle;text-align:left}\
th{background:#f4f4f4}.verdict{padding:1px 6px;border-radius:3px;font-weight:600}\
.ok{background:#d4f4d4}.partly{background:#fbefc4}.not{background:#f8d0d0}.pending{background:#e4e4e4}\
.changed{outline:3px solid #d33;background:#fff0f0}.note{color:#555;font-size:0.9em}\
.figs img{max-width:100%;max-height:900px;border:1px solid #eee;margin:4px 0}\
svg.history .pt{fill:#246}svg.history .pt.moved{fill:#d33}svg.history .pt.last{stroke:#000;stroke-width:1}\
svg.history text{font-size:10px;fill:#555}svg.history polyline{fill:none;stroke:#89a;stroke-width:1.2}\
.strip span{display:inline-block;width:10px;height:10px;margin-right:1px}\
.warn{background:#fff4d6;padding:0.5em;border-left:4px solid #e0a000}";

/// Records on `<body>` how many pictures loaded and the errors seen (for the browser test and
/// for anyone who opens the console).
const SCRIPT: &str = "(function(){var errors=[];\
window.addEventListener('error',function(e){var t=e.target;errors.push(t&&t.src?'failed to load '+t.src:String(e.message));},true);\
window.addEventListener('load',function(){var im=document.images,ok=0;\
for(var i=0;i<im.length;i++){if(im[i].complete&&im[i].naturalWidth>0){ok++;}}\
var b=document.body;b.setAttribute('data-images',String(im.length));\
b.setAttribute('data-images-loaded',String(ok));b.setAttribute('data-errors',String(errors.length));\
b.setAttribute('data-error-text',errors.join(' | '));b.setAttribute('data-ready','1');});})();";

/// The whole page.
fn page(rep: &Reproduction, history: &History) -> String {
    let runs: Vec<&Record> = history.of_tier(&rep.tier).collect();
    let last = runs.last().copied();
    let before = runs.len().checked_sub(2).map(|i| runs[i]);
    let mut s = String::new();
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>hvi: reproduction of Watson &amp; Steinhauser (2017), tier {tier}</title>\n\
         <style>{STYLE}</style>\n<script>{SCRIPT}</script>\n</head>\n<body>\n\
         <h1>Reproduction of Watson &amp; Steinhauser (2017), tier <code>{tier}</code></h1>\n",
        tier = esc(&rep.tier)
    );
    header(&mut s, rep, last, runs.len(), history);
    changes(&mut s, rep, last, before);
    summary(&mut s, rep, &runs, before);
    for f in &rep.figures {
        figure(&mut s, f, &runs, before);
    }
    runs_table(&mut s, &runs);
    if !rep.notes.is_empty() {
        s.push_str("<h2 id=\"notes\">Notes</h2>\n<ul>\n");
        for n in &rep.notes {
            let _ = writeln!(s, "<li>{}</li>", esc(n));
        }
        s.push_str("</ul>\n");
    }
    s.push_str("</body>\n</html>\n");
    s
}

fn header(s: &mut String, rep: &Reproduction, last: Option<&Record>, n: usize, h: &History) {
    s.push_str("<p>");
    if let Some(r) = last {
        let _ = write!(
            s,
            "Commit <code>{}</code>, {}; engine {}, workspace {}. ",
            esc(&r.commit),
            esc(&r.date),
            esc(&r.engine_version),
            esc(&r.workspace_version)
        );
    }
    let _ = writeln!(
        s,
        "{} ({} cores, {}); wall time {}{}. {} run(s) of this tier in the history \
         (<code>{}</code>). The same in text: <a href=\"report.md\">report.md</a>, \
         <a href=\"reproduce.json\">reproduce.json</a>.</p>",
        esc(&rep.machine.cpu),
        rep.machine.cores,
        esc(&rep.machine.os),
        fmt_duration(rep.wall_seconds),
        if rep.complete {
            ""
        } else {
            ", <strong>incomplete: a stage failed</strong>"
        },
        n,
        esc(&h.path.display().to_string())
    );
    if !h.damaged.is_empty() {
        let _ = writeln!(
            s,
            "<p class=\"warn\">{} line(s) of the history do not parse and are left out of the \
             charts (kept in the file): {}.</p>",
            h.damaged.len(),
            h.damaged
                .iter()
                .map(|(l, e)| format!("line {l}: {}", esc(e)))
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
}

/// The verdicts and numbers that moved since the run before (and `--previous`'s list).
fn changes(s: &mut String, rep: &Reproduction, last: Option<&Record>, before: Option<&Record>) {
    s.push_str("<h2 id=\"changes\">What changed since the last run</h2>\n");
    let (Some(last), Some(before)) = (last, before) else {
        s.push_str("<p>This is the first run of this tier in the history.</p>\n");
        return;
    };
    let mut lines = Vec::new();
    for f in &last.figures {
        let Some(b) = before.figure(&f.id) else {
            continue;
        };
        if b.verdict != f.verdict {
            lines.push(format!(
                "<li class=\"changed\"><a href=\"#{}\">Fig. {}</a>: verdict {} &rarr; {}</li>",
                anchor(&f.id),
                esc(&f.id),
                verdict_badge(b.verdict),
                verdict_badge(f.verdict)
            ));
        }
        for (name, v) in &f.numbers {
            if let Some(old) = b.number(name).filter(|old| *old != v) {
                lines.push(format!(
                    "<li><a href=\"#{}\">Fig. {}</a>: {}: {} &rarr; {}</li>",
                    anchor(&f.id),
                    esc(&f.id),
                    esc(name),
                    esc(&old.show()),
                    esc(&v.show())
                ));
            }
        }
    }
    let _ = writeln!(
        s,
        "<p>Against the run before, commit <code>{}</code> of {}:</p>",
        esc(&before.commit),
        esc(&before.date)
    );
    if lines.is_empty() {
        s.push_str("<p>Nothing: every verdict and deciding number is the same.</p>\n");
    } else {
        let _ = writeln!(s, "<ul>\n{}\n</ul>", lines.join("\n"));
    }
    if let Some(c) = &rep.changes {
        let _ = writeln!(
            s,
            "<p>Against <code>--previous</code>: {}</p>",
            if c.is_empty() {
                "nothing changed.".to_string()
            } else {
                format!(
                    "<ul>{}</ul>",
                    c.iter()
                        .map(|l| format!("<li>{}</li>", esc(l)))
                        .collect::<String>()
                )
            }
        );
    }
}

fn summary(s: &mut String, rep: &Reproduction, runs: &[&Record], before: Option<&Record>) {
    s.push_str(
        "<h2 id=\"summary\">Summary</h2>\n<table class=\"summary\">\n\
         <tr><th>Fig.</th><th>what</th><th>verdict</th><th>at the run before</th>\
         <th>verdicts over the history</th></tr>\n",
    );
    for f in &rep.figures {
        let was = before.and_then(|b| b.figure(&f.id)).map(|b| b.verdict);
        let changed = was.is_some_and(|w| w != f.verdict);
        let strip: String = runs
            .iter()
            .filter_map(|r| r.figure(&f.id).map(|g| (r, g.verdict)))
            .map(|(r, v)| {
                format!(
                    "<span class=\"{}\" title=\"{} {}: {}\"></span>",
                    match v {
                        Verdict::Reproduced => "ok",
                        Verdict::Partly => "partly",
                        Verdict::Not => "not",
                        Verdict::Pending => "pending",
                    },
                    esc(&r.commit),
                    esc(&r.date),
                    esc(v.word())
                )
            })
            .collect();
        let _ = writeln!(
            s,
            "<tr{}><td><a href=\"#{}\">{}</a></td><td>{}</td><td>{}</td><td>{}</td>\
             <td class=\"strip\">{strip}</td></tr>",
            if changed { " class=\"changed\"" } else { "" },
            anchor(&f.id),
            esc(&f.id),
            esc(&f.title),
            verdict_badge(f.verdict),
            match was {
                Some(w) if changed => format!("<strong>changed</strong>: was {}", verdict_badge(w)),
                Some(w) => verdict_badge(w),
                None => "(no run before)".into(),
            }
        );
    }
    s.push_str("</table>\n");
}

fn figure(s: &mut String, f: &Figure, runs: &[&Record], before: Option<&Record>) {
    let figs = if f.id.contains('-') { "Figs." } else { "Fig." };
    let changed = before
        .and_then(|b| b.figure(&f.id))
        .is_some_and(|b| b.verdict != f.verdict);
    let _ = writeln!(
        s,
        "<section class=\"figure{}\" id=\"{}\">\n<h2>{figs} {}: {}</h2>\n<p>Verdict: {}{}</p>",
        if changed { " changed" } else { "" },
        anchor(&f.id),
        esc(&f.id),
        esc(&f.title),
        verdict_badge(f.verdict),
        if changed {
            " <strong>(changed since the last run)</strong>"
        } else {
            ""
        }
    );
    let _ = writeln!(
        s,
        "<p><strong>Paper:</strong> {}</p>\n<p><strong>Ours:</strong> {}</p>\n\
         <p><strong>Why:</strong> {}</p>",
        esc(&f.paper),
        esc(&f.ours),
        esc(&f.reason)
    );
    s.push_str("<div class=\"figs\">\n");
    for file in &f.files {
        let lower = file.to_ascii_lowercase();
        if lower.ends_with(".png") || lower.ends_with(".svg") {
            let _ = writeln!(
                s,
                "<a href=\"{0}\"><img src=\"{0}\" alt=\"{0}\" loading=\"eager\"></a><br>",
                esc(file)
            );
        } else {
            let _ = writeln!(s, "<a href=\"{0}\">{0}</a><br>", esc(file));
        }
    }
    s.push_str("</div>\n");
    if f.numbers.is_empty() {
        s.push_str("</section>\n");
        return;
    }
    s.push_str(
        "<table class=\"numbers\">\n<tr><th>deciding number</th><th>value</th><th>note</th>\
         <th>history</th></tr>\n",
    );
    for n in &f.numbers {
        let chart = if n.timing {
            "<span class=\"note\">a run time: not tracked</span>".to_string()
        } else {
            let series: Vec<(&Record, &Value)> = runs
                .iter()
                .filter_map(|r| {
                    r.figure(&f.id)
                        .and_then(|g| g.number(&n.name))
                        .map(|v| (*r, v))
                })
                .collect();
            history_chart(&series)
        };
        let _ = writeln!(
            s,
            "<tr><td>{}</td><td>{}</td><td class=\"note\">{}</td><td>{chart}</td></tr>",
            esc(&n.name),
            esc(&n.value.show()),
            esc(&n.note)
        );
    }
    s.push_str("</table>\n</section>\n");
}

/// A small SVG of one deciding number over the runs: numbers on a line between their least
/// and largest value, other values in a row; one point per run, a point whose value differs
/// from the run before in red, the last run outlined.
fn history_chart(series: &[(&Record, &Value)]) -> String {
    let (w, h) = CHART;
    let (left, pad) = PAD;
    let numbers: Option<Vec<f64>> = series
        .iter()
        .map(|(_, v)| match v {
            Value::Number(x) if x.is_finite() => Some(*x),
            _ => None,
        })
        .collect();
    let n = series.len();
    let x_of = |k: usize| {
        if n <= 1 {
            left + 0.5 * (w - left - pad)
        } else {
            left + (w - left - pad) * k as f64 / (n - 1) as f64
        }
    };
    let mut s = format!(
        "<svg class=\"history\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" \
         viewBox=\"0 0 {w} {h}\" data-points=\"{n}\">"
    );
    let ys = y_axis(&mut s, numbers.as_deref(), n);
    if numbers.is_some() && n > 1 {
        let pts: Vec<String> = ys
            .iter()
            .enumerate()
            .map(|(k, y)| format!("{:.1},{:.1}", x_of(k), y))
            .collect();
        let _ = write!(s, "<polyline points=\"{}\"/>", pts.join(" "));
    }
    for (k, ((r, v), y)) in series.iter().zip(&ys).enumerate() {
        let moved = k > 0 && series[k - 1].1 != *v;
        point(&mut s, (x_of(k), *y), (moved, k + 1 == n), r, v);
    }
    s.push_str("</svg>");
    s
}

/// The chart's y axis: each value's height, and its labels written into `s` (the highest and
/// the lowest value; one label for a flat series; "values" for a series that is not numbers,
/// drawn along the middle).
fn y_axis(s: &mut String, numbers: Option<&[f64]>, n: usize) -> Vec<f64> {
    let (_, h) = CHART;
    let (_, pad) = PAD;
    let Some(xs) = numbers.filter(|xs| !xs.is_empty()) else {
        let _ = write!(s, "<text x=\"2\" y=\"{}\">values</text>", 0.5 * h + 3.0);
        return vec![0.5 * h; n];
    };
    let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let span = hi - lo;
    if span > 0.0 {
        let _ = write!(
            s,
            "<text x=\"2\" y=\"{}\">{}</text><text x=\"2\" y=\"{}\">{}</text>",
            pad + 4.0,
            esc(&Value::Number(hi).show()),
            h - pad + 3.0,
            esc(&Value::Number(lo).show())
        );
    } else {
        let _ = write!(
            s,
            "<text x=\"2\" y=\"{}\">{}</text>",
            0.5 * h + 3.0,
            esc(&Value::Number(hi).show())
        );
    }
    xs.iter()
        .map(|&x| {
            if span > 0.0 {
                h - pad - (h - 2.0 * pad) * (x - lo) / span
            } else {
                0.5 * h
            }
        })
        .collect()
}

/// One run's point at (x, y), marked when its value moved from the run before and when it is
/// the last, with the run's commit, date and value as its tooltip.
fn point(s: &mut String, (x, y): (f64, f64), (moved, last): (bool, bool), r: &Record, v: &Value) {
    let class = match (moved, last) {
        (true, true) => "pt moved last",
        (true, false) => "pt moved",
        (false, true) => "pt last",
        (false, false) => "pt",
    };
    let _ = write!(
        s,
        "<circle class=\"{class}\" cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"3.5\"><title>{} {}: {}</title></circle>",
        esc(&r.commit),
        esc(&r.date),
        esc(&v.show())
    );
}

fn runs_table(s: &mut String, runs: &[&Record]) {
    s.push_str(
        "<h2 id=\"runs\">Runs in the history</h2>\n<table>\n<tr><th>#</th><th>date (UTC)</th>\
         <th>commit</th><th>engine</th><th>machine</th><th>wall time</th><th>runs simulated</th>\
         <th>reproduced / partly / not</th></tr>\n",
    );
    for (k, r) in runs.iter().enumerate().rev() {
        let count = |v: Verdict| r.figures.iter().filter(|f| f.verdict == v).count();
        let _ = writeln!(
            s,
            "<tr><td>{}</td><td>{}</td><td><code>{}</code></td><td>{}</td><td>{} ({} cores)</td>\
             <td>{}</td><td>{}</td><td>{} / {} / {}{}</td></tr>",
            k + 1,
            esc(&r.date),
            esc(&r.commit),
            esc(&r.engine_version),
            esc(&r.machine.cpu),
            r.machine.cores,
            fmt_duration(r.wall_seconds),
            r.stages.iter().map(|st| st.ran).sum::<usize>(),
            count(Verdict::Reproduced),
            count(Verdict::Partly),
            count(Verdict::Not),
            if r.complete { "" } else { " (incomplete)" }
        );
    }
    s.push_str("</table>\n");
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::history::FigureRecord;
    use crate::report::Machine;

    fn record(commit: &str, x: f64, verdict: Verdict) -> Record {
        Record {
            commit: commit.into(),
            engine_version: "0.6.0".into(),
            workspace_version: "0.6.0".into(),
            tier: "quick".into(),
            date: format!("2026-12-0{}T00:00:00Z", commit.len()),
            machine: Machine {
                cpu: "test".into(),
                cores: 2,
                os: "linux".into(),
            },
            wall_seconds: 1.0,
            complete: true,
            stages: vec![],
            figures: vec![FigureRecord {
                id: "9".into(),
                verdict,
                numbers: vec![
                    ("R".into(), Value::Number(x)),
                    ("where".into(), Value::Text("(1, 1.14e6)".into())),
                ],
            }],
        }
    }

    #[test]
    fn the_chart_has_a_point_per_run_and_marks_a_moved_value() {
        let (a, b, c) = (
            record("a", 1.5, Verdict::Reproduced),
            record("bb", 1.5, Verdict::Reproduced),
            record("ccc", 1.7, Verdict::Partly),
        );
        let (va, vb, vc) = (Value::Number(1.5), Value::Number(1.5), Value::Number(1.7));
        let svg = history_chart(&[(&a, &va), (&b, &vb), (&c, &vc)]);
        assert_eq!(svg.matches("<circle").count(), 3, "{svg}");
        assert!(svg.contains("data-points=\"3\""));
        assert_eq!(svg.matches("moved").count(), 1, "{svg}");
        assert!(
            svg.contains("<title>ccc 2026-12-03T00:00:00Z: 1.700</title>"),
            "{svg}"
        );
        // Text values: one point each too, no line.
        let t = Value::Text("x".into());
        let svg = history_chart(&[(&a, &t), (&b, &t)]);
        assert_eq!(svg.matches("<circle").count(), 2);
        assert!(!svg.contains("polyline"));
    }

    #[test]
    fn a_changed_verdict_stands_out_and_text_is_escaped() {
        let history = History {
            path: "history.jsonl".into(),
            records: vec![
                record("a", 1.5, Verdict::Reproduced),
                record("bb", 1.7, Verdict::Partly),
            ],
            damaged: vec![(3, "expected value".into())],
        };
        let rep = Reproduction {
            tier: "quick".into(),
            tier_description: String::new(),
            config: String::new(),
            version: "0.6.0".into(),
            machine: history.records[0].machine.clone(),
            complete: true,
            figures: vec![Figure {
                id: "9".into(),
                title: "R <plateau>".into(),
                paper: "p".into(),
                ours: "o".into(),
                numbers: vec![],
                verdict: Verdict::Partly,
                reason: "r & s".into(),
                files: vec!["fig09_R.png".into()],
            }],
            stages: vec![],
            wall_seconds: 1.0,
            estimates: vec![],
            notes: vec![],
            changes: None,
        };
        let html = page(&rep, &history);
        assert!(html.contains("R &lt;plateau&gt;") && html.contains("r &amp; s"));
        assert!(html.contains("<tr class=\"changed\">"), "{html}");
        assert!(html.contains("verdict <span class=\"verdict ok\">reproduced</span> &rarr;"));
        assert!(html.contains("R: 1.500 &rarr; 1.700"), "{html}");
        assert!(html.contains("<img src=\"fig09_R.png\""));
        assert!(html.contains("1 line(s) of the history do not parse"));
    }
}
