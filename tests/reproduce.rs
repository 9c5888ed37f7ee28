//! End-to-end test of `hvi-study reproduce` at a tiny tier written here (a few hundred
//! particles, 2 us): every figure file is drawn, report.md has a verdict per figure,
//! reproduce.json is complete, running again simulates nothing and reports no change against
//! the first report, and bad input stops with a clear message before anything runs. The
//! deciding numbers themselves are unit-tested on synthetic input in
//! `hvi_analysis::decide`.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common;
use common::{bin, repo};

fn scratch(name: &str) -> PathBuf {
    common::scratch("hvi-reproduce", name)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A reproduce config with one tiny tier, `test`, over the repository's study files and
/// scenes, and a 3 x 3 validity map.
fn write_config(dir: &Path) -> PathBuf {
    let r = repo();
    let validity = dir.join("validity-small.toml");
    std::fs::write(
        &validity,
        format!(
            "[study]\nname = \"validity-small\"\nscene = \"{}\"\ndefault_tier = \"test\"\n\n\
             [[axes]]\nkey = \"scene.v0_m_s\"\nvalues = [4000, 7000, 10000]\n\n\
             [[axes]]\nkey = \"scene.t_over_d\"\nvalues = [0.2, 0.4, 0.6]\n\n\
             [tiers.test]\nset = [\"resolution.particles_across_d=6\", \"scene.width_over_d=2\", \"run.end_time_s=2e-6\"]\n",
            r.join("studies/scenes/validity-map.toml").display()
        ),
    )
    .expect("validity study");
    let config = dir.join("reproduce-test.toml");
    std::fs::write(
        &config,
        format!(
            r#"[estimate]
tier = "test"
particle_steps_per_second = 2.4e7
cores = 2
source = "test"

[tiers.test]
description = "tiny, for tests/reproduce.rs"
calibration = {{ study = "{cal}", tier = "quick", particles = 300, set = ["run.end_time_s=2e-6"] }}
validity = {{ study = "{val}", tier = "test" }}
sizing = {{ particles = [100, 300], set = ["run.end_time_s=0.2e-6"] }}
convergence = {{ scene = "{scene}", fractions = [0.5], set = ["run.end_time_s=2e-6"] }}
front_velocity = {{ scene = "{vscene}", t_over_d = [0.2, 0.4], set = ["resolution.particles_across_d=6", "run.end_time_s=2e-6"] }}
"#,
            cal = r.join("studies/calibration.toml").display(),
            val = validity.display(),
            scene = r.join("studies/scenes/calibration.toml").display(),
            vscene = r.join("studies/scenes/validity-map.toml").display(),
        ),
    )
    .expect("config");
    config
}

fn reproduce(config: &Path, out: &Path, runs: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("reproduce")
        .args(["--tier", "test", "--threads", "2", "--quiet"])
        .arg("--config")
        .arg(config)
        .arg("--out")
        .arg(out)
        .arg("--runs")
        .arg(runs)
        .args(extra)
        .output()
        .expect("runs")
}

const FIGURES: [&str; 10] = ["3", "4", "5", "7", "9", "10", "11-12", "13", "16", "17"];

const FILES: [&str; 11] = [
    "fig03_potentials.png",
    "fig04_sizing.png",
    "fig05_convergence.png",
    "fig07_snapshots.png",
    "fig09_R.png",
    "fig10_va.png",
    "fig11_side.png",
    "fig12_series.png",
    "fig13_front_velocity.png",
    "fig16_fragmentation.png",
    "fig17_snapshots.png",
];

#[test]
fn reproduce_draws_every_figure_gives_every_verdict_and_reruns_from_the_store() {
    let dir = scratch("e2e");
    let config = write_config(&dir);
    let (out, runs) = (dir.join("report"), dir.join("runs"));
    let o = reproduce(&config, &out, &runs, &[]);
    assert!(o.status.success(), "{}", stderr(&o));

    for f in FILES {
        let bytes = std::fs::read(out.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(&bytes[1..4], b"PNG", "{f}");
    }
    for f in [
        "fig04_energy.csv",
        "fig05_convergence.csv",
        "fig13_front_velocity.csv",
    ] {
        let text = std::fs::read_to_string(out.join(f)).expect(f);
        assert!(text.lines().count() > 2, "{f}: {text}");
    }

    // A verdict per figure, in its own section and in the summary.
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    for id in FIGURES {
        let figs = if id.contains('-') { "Figs." } else { "Fig." };
        let head = format!("## {figs} {id}: ");
        let at = md
            .find(&head)
            .unwrap_or_else(|| panic!("no section {head}\n{md}"));
        let section = &md[at..];
        let end = section[3..].find("\n## ").map_or(section.len(), |e| e + 3);
        let section = &section[..end];
        assert!(
            ["reproduced.**", "partly.**", "not reproduced.**"]
                .iter()
                .any(|v| section.contains(&format!("**Verdict: {v}"))),
            "no verdict in {section}"
        );
        assert!(section.contains("- **Paper:**") && section.contains("- **Ours:**"));
        assert!(
            md.contains(&format!("| [{id}](#fig-{id}) |")),
            "summary row {id}"
        );
    }
    assert!(!md.contains("pending"), "{md}");
    assert!(md.contains("## Machine and run times"));
    assert!(md.contains("## Expected wall time of the `test` tier on 2 cores"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("reproduce.json")).expect("json"))
            .expect("parses");
    assert_eq!(json["complete"], true);
    assert_eq!(
        json["figures"].as_array().expect("figures").len(),
        FIGURES.len()
    );
    // Fig. 3 needs no run and its laws meet at r_eq: reproduced at any tier.
    assert_eq!(json["figures"][0]["verdict"], "reproduced");
    // The history has this run; the page says it is the first.
    assert_eq!(history(&out).len(), 1);
    let html = std::fs::read_to_string(out.join("index.html")).expect("index.html");
    assert!(html.contains("This is the first run of this tier in the history."));

    // Again, comparing with the first report: nothing runs, nothing changes.
    let o = reproduce(
        &config,
        &out,
        &runs,
        &[
            "--previous",
            out.to_str().expect("utf-8"),
            "--fail-on-change",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("reproduce.json")).expect("json"))
            .expect("parses");
    for s in json["stages"].as_array().expect("stages") {
        assert_eq!(s["ran"], 0, "stage ran again: {s}");
    }
    assert_eq!(json["changes"], serde_json::json!([]));
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(
        md.contains("## What changed since the previous report\n\nNothing"),
        "{md}"
    );
    // Two runs: two records, and every tracked deciding number's chart has two points.
    let records = history(&out);
    assert_eq!(records.len(), 2);
    assert_eq!(records[0]["figures"], records[1]["figures"]);
    let tracked: usize = json["figures"]
        .as_array()
        .expect("figures")
        .iter()
        .map(|f| {
            f["numbers"]
                .as_array()
                .expect("numbers")
                .iter()
                .filter(|n| n["timing"] != true)
                .count()
        })
        .sum();
    let html = std::fs::read_to_string(out.join("index.html")).expect("index.html");
    assert_eq!(html.matches("<svg class=\"history\"").count(), tracked);
    assert_eq!(html.matches("data-points=\"2\"").count(), tracked, "{html}");
    assert!(html.contains("Nothing: every verdict and deciding number is the same."));

    // The run before had another Fig. 3 verdict and another Fig. 4 number (as after a
    // change): the next page shows both.
    let mut second = records[1].clone();
    second["figures"][0]["verdict"] = serde_json::json!("partly");
    let (name, _) = {
        let n = &second["figures"][1]["numbers"][0];
        (n[0].as_str().expect("name").to_string(), n[1].clone())
    };
    second["figures"][1]["numbers"][0][1] = serde_json::json!(99.0);
    std::fs::write(
        out.join("history.jsonl"),
        format!("{}\n{}\n", records[0], second),
    )
    .expect("history");

    // A changed number is listed, and --fail-on-change fails on it.
    let prev = dir.join("previous");
    std::fs::create_dir_all(&prev).expect("dir");
    let mut json = json;
    json["figures"][1]["numbers"][1]["value"] = serde_json::json!(99.0);
    std::fs::write(prev.join("reproduce.json"), json.to_string()).expect("write");
    let args = [
        "--previous",
        prev.to_str().expect("utf-8"),
        "--fail-on-change",
    ];
    let o = reproduce(&config, &out, &runs, &args);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("changed since"), "{}", stderr(&o));
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(md.contains("- Fig. 4: decades spanned: 99 -> "), "{md}");
    // A failed comparison still records the run.
    assert_eq!(history(&out).len(), 3);
    let html = std::fs::read_to_string(out.join("index.html")).expect("index.html");
    assert!(
        html.contains("<tr class=\"changed\"><td><a href=\"#fig-3\">3</a>"),
        "{html}"
    );
    assert!(
        html.contains("<section class=\"figure changed\" id=\"fig-3\">"),
        "{html}"
    );
    assert!(
        html.contains(&format!("Fig. 4</a>: {name}: 99 &rarr; ")),
        "{html}"
    );
    assert!(html.contains("class=\"pt moved last\""), "{html}");
    assert_eq!(
        html.matches("data-points=\"3\"").count(),
        html.matches("<svg class=\"history\"").count()
    );
    in_a_browser(&out, 3);

    // Another report directory on the same history (--history): a fourth record, charted on
    // its own page, and no history of its own.
    let other = dir.join("other");
    let shared = out.join("history.jsonl");
    let o = reproduce(
        &config,
        &other,
        &runs,
        &["--history", shared.to_str().expect("utf-8")],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(history(&out).len(), 4);
    assert!(!other.join("history.jsonl").exists());
    let html = std::fs::read_to_string(other.join("index.html")).expect("index.html");
    assert_eq!(
        html.matches("data-points=\"4\"").count(),
        html.matches("<svg class=\"history\"").count()
    );
}

/// The records of a report's history.
fn history(out: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(out.join("history.jsonl"))
        .expect("history.jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a record"))
        .collect()
}

/// Opens `out/index.html` in headless Chromium and checks that it loads without an error,
/// that every picture loads, and that each history chart has `runs` points. Skips with a
/// message where Chromium is missing, and fails then under CI=true (`.ci/run` installs it).
fn in_a_browser(out: &Path, runs: usize) {
    let Some(chromium) = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|c| {
            std::process::Command::new(c)
                .arg("--version")
                .output()
                .is_ok_and(|o| o.status.success())
        })
    else {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true but no Chromium to open index.html (.ci/run installs Debian's chromium)"
        );
        eprintln!("SKIP: no Chromium here: index.html not opened in a browser");
        return;
    };
    let profile = out.join("chromium-profile");
    let page = out.join("index.html").canonicalize().expect("page");
    let o = std::process::Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--allow-file-access-from-files",
            "--virtual-time-budget=10000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg("--dump-dom")
        .arg(format!("file://{}", page.display()))
        .output()
        .expect("chromium runs");
    assert!(o.status.success(), "{}", stderr(&o));
    let dom = String::from_utf8_lossy(&o.stdout);
    let body = &dom[dom.find("<body").expect("a body")..];
    let body = &body[..body.find('>').expect("the body tag")];
    let attr = |name: &str| -> String {
        let key = format!("{name}=\"");
        let at = body
            .find(&key)
            .unwrap_or_else(|| panic!("no {name} on <body>: {body}"))
            + key.len();
        body[at..][..body[at..].find('"').expect("quote")].to_string()
    };
    assert_eq!(attr("data-ready"), "1", "{body}");
    assert_eq!(attr("data-errors"), "0", "{}", attr("data-error-text"));
    let html = std::fs::read_to_string(&page).expect("page");
    let images = html.matches("<img ").count();
    assert!(images >= FILES.len(), "{images} pictures on the page");
    assert_eq!(attr("data-images"), images.to_string());
    assert_eq!(attr("data-images-loaded"), images.to_string(), "{body}");
    // Every chart in the rendered page has one point per recorded run.
    let charts: Vec<&str> = dom.split("<svg class=\"history\"").skip(1).collect();
    assert!(!charts.is_empty());
    for c in charts {
        let c = &c[..c.find("</svg>").expect("svg end")];
        assert_eq!(c.matches("<circle").count(), runs, "{c}");
    }
}

#[test]
fn bad_input_is_refused_before_anything_runs() {
    let dir = scratch("bad");
    let config = write_config(&dir);
    let runs = dir.join("runs");
    let check = |o: Output, needle: &str| {
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(
            stderr(&o).contains(needle),
            "wanted `{needle}` in: {}",
            stderr(&o)
        );
    };
    // Unknown tier: the message lists the tiers.
    let o = bin()
        .args(["reproduce", "--tier", "nightly", "--quiet", "--config"])
        .arg(&config)
        .arg("--runs")
        .arg(&runs)
        .output()
        .expect("runs");
    check(o, "tiers in");
    // --out is a file.
    let file = dir.join("a-file");
    std::fs::write(&file, "x").expect("file");
    check(reproduce(&config, &file, &runs, &[]), "is a file");
    // --out holds something else.
    let other = dir.join("other");
    std::fs::create_dir_all(&other).expect("dir");
    std::fs::write(other.join("notes.txt"), "mine").expect("file");
    check(reproduce(&config, &other, &runs, &[]), "refusing to write");
    // --previous without a report.
    check(
        reproduce(
            &config,
            &dir.join("new"),
            &runs,
            &["--previous", other.to_str().expect("utf-8")],
        ),
        "--previous",
    );
    // A missing config.
    let o = bin()
        .args(["reproduce", "--tier", "test", "--quiet", "--config"])
        .arg(dir.join("missing.toml"))
        .output()
        .expect("runs");
    check(o, "cannot read the reproduce config");
    // Nothing ran.
    assert!(!runs.exists() || std::fs::read_dir(&runs).expect("runs").next().is_none());
}
