//! End-to-end tests of the readings study (`hvi-study fidelity`): a tiny 2 x 2 grid at two
//! seeds under two readings with runs of their own and three that measure them again; the
//! report's maps and numbers come from the runs (seed means of the store's records, the
//! shadowgraph's observables, a re-measurement at another quantile), a second invocation runs
//! nothing and writes the same tables, and bad input is refused by name before anything runs.

use std::path::{Path, PathBuf};
use std::process::Output;

use serde_json::Value;

use crate::common;
use common::{bin, repo};

fn scratch(name: &str) -> PathBuf {
    common::scratch("hvi-fidelity", name)
}

/// A 2 x 2 calibration grid of tiny runs (1000 particles, 4 us after first contact).
fn write_study(dir: &Path) -> PathBuf {
    let text = format!(
        "[study]\nname = \"calibration\"\ndefault_tier = \"tiny\"\nscene = \"{}\"\n\n\
         [[axes]]\nkey = \"material.eps_j\"\nvalues = [0.01, 0.1]\n\n\
         [[axes]]\nkey = \"material.kappa_n_m\"\nvalues = [1.14e6, 4.56e6]\n\n\
         [[axes]]\nkey = \"material.rcut_over_sigma\"\nvalues = [1.5]\n\n\
         [tiers.tiny]\nset = [\"resolution.particles=1000\", \"run.end_time_s=4e-6\"]\n",
        repo().join("studies/scenes/calibration.toml").display()
    );
    let path = dir.join("study.toml");
    std::fs::write(&path, text).expect("study file");
    path
}

const READINGS: &str = r#"
[[readings]]
name = "printed"
label = "the defaults"
default = true

[[readings]]
name = "wca"
label = "WCA"
set = ["material.contact=wca"]

[[readings]]
name = "maximum"
label = "plain maximum"
from = "printed"
analysis = ["analysis.quantile=1"]

[[readings]]
name = "quantile-0.995"
label = "the runs' own quantile, measured again"
from = "printed"
analysis = ["analysis.quantile=0.995"]

[[readings]]
name = "shadowgraph"
label = "silhouette"
from = "wca"
length_ratio = "length_ratio_silhouette"
front_velocity = "front_velocity_ratio_silhouette"
"#;

fn write_config(dir: &Path, readings: &str) -> PathBuf {
    write_config_with(dir, "", readings)
}

/// The config with extra lines in its `[fidelity]` header.
fn write_config_with(dir: &Path, header: &str, readings: &str) -> PathBuf {
    write_study(dir);
    let text = format!(
        "[fidelity]\nstudy = \"study.toml\"\ntier = \"tiny\"\nseeds = [1, 2]\n{header}\n{readings}"
    );
    let path = dir.join("fidelity.toml");
    std::fs::write(&path, text).expect("config");
    path
}

fn fidelity(config: &Path, dir: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("fidelity")
        .arg("--config")
        .arg(config)
        .arg("--out")
        .arg(dir.join("report"))
        .arg("--runs")
        .arg(dir.join("runs"))
        .args(["--threads", "2", "--quiet"])
        .args(extra)
        .output()
        .expect("runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("readable")).expect("json")
}

/// The seed mean of `column` at (eps, kappa) from a reading's results.json.
fn seed_mean(results: &Value, column: &str, eps: f64, kappa: f64) -> f64 {
    let v: Vec<f64> = results
        .as_array()
        .expect("rows")
        .iter()
        .filter(|r| r["material.eps_j"] == eps && r["material.kappa_n_m"] == kappa)
        .map(|r| r[column].as_f64().expect("a number"))
        .collect();
    assert_eq!(v.len(), 2, "two seeds at ({eps}, {kappa})");
    (v[0] + v[1]) / 2.0
}

/// A reading's mean field of one observable from fidelity.json, `z[row][col]`.
fn field(report: &Value, reading: &str, which: &str) -> Vec<Vec<f64>> {
    let r = report["readings"]
        .as_array()
        .expect("readings")
        .iter()
        .find(|r| r["reading"] == reading)
        .unwrap_or_else(|| panic!("reading {reading}"));
    r[which]["z"]
        .as_array()
        .expect("z")
        .iter()
        .map(|row| {
            row.as_array()
                .expect("row")
                .iter()
                .map(|x| x.as_f64().unwrap_or(f64::NAN))
                .collect()
        })
        .collect()
}

#[test]
fn the_readings_study_reports_every_reading_from_its_runs_and_reruns_nothing() {
    let dir = scratch("study");
    // Every run at the 0.995 quantile (the header's `set`), which the default is not: the
    // `quantile-0.995` reading, measured again at 0.995, then gives the runs' own numbers.
    let config = write_config_with(&dir, "set = [\"analysis.quantile=0.995\"]", READINGS);
    let o = fidelity(&config, &dir, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = dir.join("report");
    let report = json(&out.join("fidelity.json"));
    assert_eq!(report["ran"], 16, "2 readings x 4 points x 2 seeds");
    for name in ["printed", "wca", "maximum", "quantile-0.995", "shadowgraph"] {
        for map in ["R", "va"] {
            let png = out.join(format!("{name}_{map}.png"));
            assert!(
                std::fs::metadata(&png).expect("map drawn").len() > 10_000,
                "{}",
                png.display()
            );
        }
    }
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(
        md.contains("## Side by side") && md.contains("Claims no reading reproduces"),
        "{md}"
    );

    // The judged fields are the seed means of the stores' records, of the observables each
    // reading names.
    let printed = json(&dir.join("runs/tiny/printed/results.json"));
    let wca = json(&dir.join("runs/tiny/wca/results.json"));
    let (eps, kappa) = ([0.01, 0.1], [1.14e6, 4.56e6]);
    for (r, &k) in kappa.iter().enumerate() {
        for (c, &e) in eps.iter().enumerate() {
            let got = |reading, which| field(&report, reading, which)[r][c];
            let want = seed_mean(&printed, "length_ratio", e, k);
            assert_eq!(got("printed", "length_ratio_mean"), want);
            let want = seed_mean(&printed, "front_velocity_ratio", e, k);
            assert_eq!(got("printed", "front_velocity_ratio_mean"), want);
            let want = seed_mean(&wca, "length_ratio_silhouette", e, k);
            assert_eq!(got("shadowgraph", "length_ratio_mean"), want);
            // Measured again from state.bin with the runs' own quantile: the runs' numbers
            // (f32 positions on disk: within 1e-5).
            let again = got("quantile-0.995", "length_ratio_mean");
            let own = got("printed", "length_ratio_mean");
            assert!((again - own).abs() <= 1e-5 * own, "{again} vs {own}");
        }
    }
    let max_r = field(&report, "maximum", "length_ratio_mean");
    let q_r = field(&report, "printed", "length_ratio_mean");
    assert_ne!(max_r, q_r, "the plain maximum is another definition");
    assert_ne!(
        field(&report, "wca", "length_ratio_mean"),
        q_r,
        "WCA is another model"
    );

    // The closest reading has the most main-claim checks, then the most checks.
    let rows = report["readings"].as_array().expect("readings");
    let score = |r: &Value| {
        (
            r["main_checks_held"].as_u64().expect("count"),
            r["checks_held"].as_u64().expect("count"),
        )
    };
    let best = rows.iter().map(score).max().expect("a reading");
    let closest = rows
        .iter()
        .find(|r| r["reading"] == report["closest"])
        .expect("closest");
    assert_eq!(score(closest), best);
    assert_eq!(rows[0]["checks_detail"].as_array().map(Vec::len), Some(7));

    // Again: nothing runs, the tables are the same bytes.
    let csv = std::fs::read(out.join("readings.csv")).expect("csv");
    let o = fidelity(&config, &dir, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(json(&out.join("fidelity.json"))["ran"], 0);
    assert_eq!(std::fs::read(out.join("readings.csv")).expect("csv"), csv);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_is_refused_by_name_before_anything_runs() {
    let dir = scratch("bad");
    let config = write_config(&dir, READINGS);
    let cases: [(&[&str], &str); 3] = [
        (&["--seeds", "1,1"], "--seeds"),
        (&["--tier", "huge"], "huge"),
        (&["--jobs", "0"], "--jobs"),
    ];
    for (args, want) in cases {
        let o = fidelity(&config, &dir, args);
        assert!(!o.status.success());
        assert!(stderr(&o).contains(want), "{want}: {}", stderr(&o));
    }
    let bad = write_config(
        &dir,
        &READINGS.replace("length_ratio_silhouette", "length_ratio_silhuette"),
    );
    let o = fidelity(&bad, &dir, &[]);
    assert!(
        stderr(&o).contains("readings[4] (`shadowgraph`).length_ratio"),
        "{}",
        stderr(&o)
    );
    let config = write_config(&dir, READINGS);
    let foreign = dir.join("report");
    std::fs::create_dir_all(&foreign).expect("dir");
    std::fs::write(foreign.join("notes.txt"), "mine").expect("file");
    let o = fidelity(&config, &dir, &[]);
    assert!(
        stderr(&o).contains("holds no fidelity.json"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("runs").exists(), "nothing ran");
    let o = fidelity(&config, &dir, &["--dry-run"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("16 runs (0 in the store, 16 to run)"),
        "{}",
        stderr(&o)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
