//! Tests of re-analysis without re-simulation (`state.bin`, `hvi_engine::cloud::remeasure`,
//! `hvi-study reanalyse`): the kept states measured again give the run's own numbers, and with
//! other settings the numbers a fresh run with those settings gives; a study whose runs lack
//! their state, or hold a damaged one, is reanalysed with those runs reported.
//!
//! Tolerances. In memory the states are f64 and the re-measurement goes through the run's own
//! functions, so it is bit-identical (`assert_eq!`). On disk positions and velocities are f32
//! (relative rounding 2^-24 = 6e-8 per coordinate); the cloud's members and labels are kept
//! as the run found them, so counts are exact and masses (sums of the same per-body masses in
//! the same order) are exact (serde_json reads floats back exactly: `float_roundtrip`); the
//! tolerance left for them, 1e-15 relative, costs nothing. Lengths, sizes, ratios and crater diameters
//! come back within 1e-6 relative (a coordinate's rounding over a length of the same order,
//! times a few); va, a difference of two fronts that in these 4 us runs lie 0.5 us (3 mm)
//! apart at z of about 3 cm, within 1e-5 (2 x 6e-8 x 3 cm / 3 mm = 1.2e-6, times a margin).

use std::path::{Path, PathBuf};
use std::process::Output;

use hvi_analysis::observable::{Observable, Observables};
use hvi_engine::cloud::{remeasure, CloudObserver, CloudResult};
use hvi_engine::scene::{Analysis, SceneSpec, Width, DEFAULT_QUANTILE};
use hvi_engine::sim::Simulation;
use hvi_run::run::{run_scene, RunOptions, Summary};
use hvi_run::state::{file_bytes, STATE_FILE};
use hvi_store::store::read_summary;
use hvi_studies::reanalyse::{reanalyse_run, AnalysisChanges};

use crate::common;
use common::{bin, repo};

fn scratch(name: &str) -> PathBuf {
    common::scratch("hvi-reanalyse", name)
}

/// A small impact that forms a cloud: 2000 particles, 4 us after first contact.
fn small_scene() -> SceneSpec {
    SceneSpec::calibration(2000.0, 4e-6)
}

/// Other analysis settings than the defaults: every one a re-analysis may change.
fn other_settings() -> [String; 5] {
    [
        "analysis.quantile=0.95".into(),
        "analysis.width=cylindrical".into(),
        "analysis.shadowgraph_pixel_m=1e-3".into(),
        "analysis.shadowgraph_optical_depth=0.5".into(),
        "analysis.witness_standoff_m=0.05".into(),
    ]
}

/// Steps `spec` to its end with one observer per analysis in `analyses` (observation does not
/// change the simulation, so every observer sees the same run); their results, in order.
fn observed(spec: &SceneSpec, analyses: &[Analysis]) -> Vec<CloudResult> {
    let mut sim = Simulation::new(spec.build().expect("valid scene")).expect("starts");
    let mut observers: Vec<CloudObserver> = analyses
        .iter()
        .map(|a| CloudObserver::new(&sim, a, spec.run.end_time_s))
        .collect();
    let end = sim.derived.steps;
    for o in &mut observers {
        o.observe(&sim);
    }
    while sim.step < end {
        let next = observers
            .iter()
            .filter_map(|o| o.next_due(sim.step))
            .min()
            .map_or(end, |due| due.min(end));
        sim.step_until(next).expect("stable");
        for o in &mut observers {
            o.observe(&sim);
        }
    }
    observers
        .iter_mut()
        .map(|o| o.finish(&sim).expect("cloud measured"))
        .collect()
}

#[test]
fn remeasuring_the_kept_states_in_memory_is_bit_identical() {
    let spec = small_scene();
    let mut other = spec.analysis.clone();
    other.quantile = 0.95;
    other.width = Width::Cylindrical;
    other.shadowgraph_pixel_m = 1e-3;
    other.shadowgraph_optical_depth = 0.5;
    other.witness_standoff_m = 0.05;
    let results = observed(&spec, &[spec.analysis.clone(), other.clone()]);
    let own = &results[0];
    let kept = own
        .kept
        .as_ref()
        .expect("analysis.keep_state is on by default");
    assert!(
        kept.front.iter().all(Option::is_some),
        "both front times kept"
    );
    assert!(own.report.measurement.n_part > 100, "a cloud formed");
    // The run's own settings: the run's measurement, bit for bit.
    let again = remeasure(kept, &spec.analysis);
    assert_eq!(again.report, own.report);
    assert_eq!(again.fragments, own.fragments);
    assert_eq!(again.craters, own.craters);
    assert_eq!(again.labels_by_id, own.labels_by_id);
    assert_eq!(again.shadowgraph, own.shadowgraph);
    // Other settings: what an observer with those settings measured in the same run.
    let fresh = &results[1];
    let changed = remeasure(kept, &other);
    assert_eq!(changed.report, fresh.report);
    assert_eq!(changed.craters, fresh.craters);
    assert_ne!(changed.report, own.report, "the settings matter");
    // Without keep_state nothing is kept.
    let mut off = spec.analysis.clone();
    off.keep_state = false;
    assert!(observed(&spec, &[off])[0].kept.is_none());
}

/// Runs `spec` with `sets` applied to its analysis into `dir` as `hvi-study run` does; its
/// summary.
fn run_into(dir: &Path, sets: &[String]) -> Summary {
    let changes = AnalysisChanges::parse(sets).expect("valid settings");
    let mut spec = small_scene();
    spec.analysis = changes
        .apply(&spec.analysis, spec.run.end_time_s)
        .expect("valid");
    let opts = RunOptions {
        out_dir: dir.to_path_buf(),
        ..RunOptions::default()
    };
    run_scene(&spec, &opts).expect("runs");
    read_summary(dir).expect("summary.json")
}

/// Observables that are counts: equal exactly.
const COUNTS: [Observable; 5] = [
    Observable::Particles,
    Observable::NPart,
    Observable::NFrag,
    Observable::CraterCount,
    Observable::LargeCentralCrater,
];

/// Asserts that two runs' observables agree to the tolerances of the module's doc.
fn assert_same_observables(got: &Observables, want: &Observables) {
    for o in Observable::ALL {
        let (g, w) = (got.get(o), want.get(o));
        let rel = if COUNTS.contains(&o) {
            0.0
        } else if matches!(
            o,
            Observable::FrontVelocity
                | Observable::FrontVelocityRatio
                | Observable::FrontVelocityRatioSilhouette
        ) {
            1e-5
        } else {
            1e-6
        };
        match (g, w) {
            (Some(g), Some(w)) => assert!(
                (g - w).abs() <= rel * w.abs().max(g.abs()),
                "{}: {g} against {w} (tolerance {rel:e} relative)",
                o.name()
            ),
            (None, None) => {}
            _ => panic!("{}: {g:?} against {w:?}", o.name()),
        }
    }
}

/// Asserts that the largest fragments agree: the same fragments (labels, particles, masses to
/// 1e-15) at f32-rounded centroids and velocities.
fn assert_same_fragments(got: &Summary, want: &Summary) {
    let (g, w) = (
        &got.cloud.as_ref().expect("cloud").largest_fragments,
        &want.cloud.as_ref().expect("cloud").largest_fragments,
    );
    assert_eq!(g.len(), w.len());
    for (a, b) in g.iter().zip(w) {
        assert_eq!(
            (a.label, a.particles, a.impactor_particles),
            (b.label, b.particles, b.impactor_particles)
        );
        assert!((a.mass_kg - b.mass_kg).abs() <= 1e-15 * b.mass_kg);
        for k in 0..3 {
            // Coordinates of about 3 cm and speeds of about 7 km/s, rounded to f32.
            assert!(
                (a.centroid_m[k] - b.centroid_m[k]).abs() < 1e-8,
                "{a:?} {b:?}"
            );
            assert!(
                (a.velocity_m_s[k] - b.velocity_m_s[k]).abs() < 2e-3,
                "{a:?} {b:?}"
            );
        }
    }
}

#[test]
fn reanalysis_from_disk_gives_the_runs_numbers_and_a_fresh_runs_with_other_settings() {
    let dir = scratch("disk");
    let own_dir = dir.join("own");
    let own = run_into(&own_dir, &[]);
    let bytes = std::fs::metadata(own_dir.join(STATE_FILE))
        .expect("state.bin written")
        .len();
    assert_eq!(
        Some(bytes),
        file_bytes(own.particles as u64, 3),
        "three frames"
    );

    // (a) The run's own settings reproduce its summary.json.
    let again = reanalyse_run(&own_dir, &AnalysisChanges::default())
        .expect("reads")
        .expect("has state");
    assert_same_observables(&again.summary.observables(), &own.observables());
    assert_same_fragments(&again.summary, &own);
    let (a, b) = (
        again.summary.cloud.as_ref().expect("cloud"),
        own.cloud.as_ref().expect("cloud"),
    );
    for (x, y) in a
        .front_velocity_times_s
        .iter()
        .zip(&b.front_velocity_times_s)
    {
        let (x, y) = (x.expect("front time"), y.expect("front time"));
        assert!((x - y).abs() <= 1e-15 * y.abs(), "{x} {y}");
    }
    assert_eq!(a.measurement.n_part, b.measurement.n_part);
    assert_eq!(
        a.measurement.fragments_crossing_rear_face,
        b.measurement.fragments_crossing_rear_face
    );
    let (sa, sb) = (
        a.silhouette.expect("silhouette"),
        b.silhouette.expect("silhouette"),
    );
    assert_eq!(sa.dark_pixels, sb.dark_pixels);

    // (b) Other settings give what a fresh run with them gives.
    let sets = other_settings();
    let fresh_dir = dir.join("fresh");
    let fresh = run_into(&fresh_dir, &sets);
    assert_eq!(fresh.bonds_broken, own.bonds_broken, "the same simulation");
    let changes = AnalysisChanges::parse(&sets).expect("valid");
    let changed = reanalyse_run(&own_dir, &changes)
        .expect("reads")
        .expect("has state");
    assert_eq!(changed.analysis.quantile, 0.95);
    assert_eq!(changed.analysis.width, Width::Cylindrical);
    assert_eq!(changed.analysis.witness_standoff_m, 0.05);
    assert_same_observables(&changed.summary.observables(), &fresh.observables());
    assert_same_fragments(&changed.summary, &fresh);
    let r = |s: &Summary, o| s.observables().get(o).expect("measured");
    assert!(
        (r(&changed.summary, Observable::LengthRatio) - r(&own, Observable::LengthRatio)).abs()
            > 1e-3,
        "another quantile, another R"
    );
    // The run's files were only read.
    assert_eq!(read_summary(&own_dir).expect("summary").cloud, own.cloud);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A two-run study of tiny runs (2000 particles, 4 us); returns its file.
fn write_study(dir: &Path) -> PathBuf {
    let text = format!(
        "[study]\nname = \"reanalyse\"\nscene = \"{}\"\n\n[[axes]]\nkey = \"material.eps_j\"\nvalues = [0.01, 0.1]\n\n[tiers.quick]\nset = [\"resolution.particles=2000\", \"run.end_time_s=4e-6\"]\n",
        repo().join("studies/scenes/default.toml").display()
    );
    let path = dir.join("study.toml");
    std::fs::write(&path, text).expect("study file");
    path
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Every file of the store's runs with its bytes, by path.
fn store_files(out: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut v = Vec::new();
    for run in std::fs::read_dir(out.join("runs")).expect("runs") {
        let run = run.expect("entry").path();
        if !run.is_dir() {
            continue; // a run's lock file
        }
        for f in std::fs::read_dir(&run).expect("run dir") {
            let p = f.expect("file").path();
            v.push((p.clone(), std::fs::read(&p).expect("readable")));
        }
    }
    v.sort();
    v
}

/// The rows of a table's JSON.
fn rows(path: &Path) -> Vec<serde_json::Value> {
    serde_json::from_str(&std::fs::read_to_string(path).expect("table")).expect("json")
}

fn reanalyse(out: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("reanalyse")
        .arg(out)
        .args(extra)
        .output()
        .expect("runs")
}

#[test]
fn a_study_is_reanalysed_with_runs_without_state_reported_and_skipped() {
    let dir = scratch("study");
    let out = dir.join("out");
    let o = bin()
        .arg("sweep")
        .arg(write_study(&dir))
        .arg("--out")
        .arg(&out)
        .args(["--threads", "2", "--quiet"])
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", stderr(&o));
    let results = rows(&out.join("results.json"));

    // Every run measured again with its own settings: the table is results.csv's, plus the
    // settings used.
    let o = reanalyse(&out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("reanalysis.csv"));
    let csv = std::fs::read_to_string(out.join("reanalysis.csv")).expect("csv");
    let results_header = std::fs::read_to_string(out.join("results.csv"))
        .expect("results")
        .lines()
        .next()
        .expect("header")
        .to_string();
    assert!(csv.starts_with(&format!("{results_header},analysis_quantile,")));
    let table = rows(&out.join("reanalysis.json"));
    assert_eq!(table.len(), 2);
    for (r, want) in table.iter().zip(&results) {
        assert_eq!(r["status"], "completed");
        assert_eq!(r["material.eps_j"], want["material.eps_j"]);
        assert_eq!(r["n_frag"], want["n_frag"]);
        assert_eq!(r["analysis_quantile"], DEFAULT_QUANTILE);
        let (a, b) = (
            r["length_ratio"].as_f64().expect("R"),
            want["length_ratio"].as_f64().expect("R"),
        );
        assert!((a - b).abs() <= 1e-6 * b, "{a} {b}");
    }

    // (c) One run's state removed: reported by name and skipped, the other measured again
    // under another name and quantile; no run's file changes.
    let victim = out.join(table[1]["dir"].as_str().expect("dir"));
    std::fs::remove_file(victim.join(STATE_FILE)).expect("remove state");
    let before = store_files(&out);
    let o = reanalyse(&out, &["--set", "analysis.quantile=0.95", "--table", "q95"]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains(&format!(
            "run {} (material.eps_j=0.1) has no state: rerun it with a current version",
            table[1]["dir"].as_str().expect("dir")
        )),
        "{err}"
    );
    assert!(
        err.contains("reanalysed 1 of 2 completed runs (1 without state"),
        "{err}"
    );
    let q95 = rows(&out.join("q95.json"));
    assert_eq!(q95[0]["status"], "completed");
    assert_eq!(q95[0]["analysis_quantile"], 0.95);
    assert_ne!(q95[0]["length_ratio"], table[0]["length_ratio"]);
    assert_eq!(q95[1]["status"], "no_state");
    assert!(q95[1]["length_ratio"].is_null());
    assert!(q95[1]["error"].as_str().expect("why").contains("no state"));
    assert_eq!(store_files(&out), before, "the runs' files are only read");

    // (d) A truncated state file: the table is written, the error names the file, no panic.
    let kept = out
        .join(table[0]["dir"].as_str().expect("dir"))
        .join(STATE_FILE);
    let bytes = std::fs::read(&kept).expect("state");
    std::fs::write(&kept, &bytes[..bytes.len() / 2]).expect("truncate");
    let o = reanalyse(&out, &[]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains(&kept.display().to_string()), "{err}");
    assert!(err.contains("truncated"), "{err}");
    assert_eq!(rows(&out.join("reanalysis.json"))[0]["status"], "bad_state");
    // A flipped byte is caught by the checksum.
    let mut flipped = bytes;
    flipped[1000] ^= 0x10;
    std::fs::write(&kept, &flipped).expect("corrupt");
    let err = stderr(&reanalyse(&out, &[]));
    assert!(
        err.contains(&kept.display().to_string()) && err.contains("SHA-256"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn settings_that_need_new_runs_and_bad_values_are_refused_by_name() {
    let dir = scratch("args");
    for (set, says) in [
        ("analysis.front_times_s=[1e-6, 2e-6]", "front times"),
        ("analysis.track_every=5", "analysis.quantile"),
        ("material.eps_j=0.1", "cannot change in a re-analysis"),
        (
            "analysis.quantle=0.95",
            "unknown key `analysis.quantle` (did you mean `analysis.quantile`?)",
        ),
        ("analysis.quantile=2", "analysis.quantile"),
        ("analysis.shadowgraph_pixel_m=abc", "not a number"),
    ] {
        let o = reanalyse(&dir, &["--set", set]);
        assert_eq!(o.status.code(), Some(2), "{set}");
        let err = stderr(&o);
        assert!(err.contains(says), "{set}: {err}");
    }
    let o = reanalyse(&dir, &["--table", "results"]);
    assert!(stderr(&o).contains("--table"), "{}", stderr(&o));
    let o = reanalyse(&dir, &[]);
    assert!(stderr(&o).contains("no plan.json"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `sweep` of the two-run study into `out` with `sets` as `--set` overrides; its output.
fn sweep_with(study: &Path, out: &Path, sets: &[&str]) -> Output {
    let mut cmd = bin();
    cmd.arg("sweep")
        .arg(study)
        .arg("--out")
        .arg(out)
        .args(["--threads", "2"]);
    for s in sets {
        cmd.args(["--set", s]);
    }
    cmd.output().expect("runs")
}

/// The records of a study's store, by run directory.
fn store_records(out: &Path) -> Vec<(PathBuf, hvi_store::store::Record)> {
    let mut v: Vec<(PathBuf, hvi_store::store::Record)> = std::fs::read_dir(out.join("runs"))
        .expect("runs")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.join("record.json").is_file())
        .map(|p| {
            let text = std::fs::read_to_string(p.join("record.json")).expect("record");
            (p, serde_json::from_str(&text).expect("a record"))
        })
        .collect();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

#[test]
fn a_run_that_differs_only_in_its_measurement_is_measured_from_a_kept_state() {
    let dir = scratch("measured");
    let study = write_study(&dir);
    let out = dir.join("out");
    let o = sweep_with(&study, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let simulated = store_records(&out);
    assert_eq!(simulated.len(), 2);
    assert!(simulated.iter().all(|(_, r)| r.measured_from.is_none()));

    // (a) Another width and quantile: both runs measured from the kept states, none simulated,
    // each naming its source; the numbers are a re-analysis's, bit for bit.
    let sets = ["analysis.width=cylindrical", "analysis.quantile=0.95"];
    let o = sweep_with(&study, &out, &sets);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("2 to run, 2 of them measured from kept states"),
        "{err}"
    );
    assert!(err.contains("measured from the state of run"), "{err}");
    assert!(
        err.contains("0 ran, 2 measured from kept states, 0 failed"),
        "{err}"
    );
    let all = store_records(&out);
    assert_eq!(all.len(), 4);
    let changes = AnalysisChanges::parse(&sets.map(String::from)).expect("valid");
    let mut measured = Vec::new();
    for (run_dir, rec) in &all {
        let Some(source) = &rec.measured_from else {
            continue;
        };
        let (src_dir, _) = simulated
            .iter()
            .find(|(_, s)| &s.fingerprint == source)
            .expect("the source is a simulated run of the store");
        let again = reanalyse_run(src_dir, &changes)
            .expect("reads")
            .expect("has state");
        assert_eq!(rec.observables, again.summary.observables());
        let summary = read_summary(run_dir).expect("summary");
        assert_eq!(summary.measured_from.as_deref(), Some(source.as_str()));
        assert_eq!(summary.scene.analysis.width, Width::Cylindrical);
        assert_eq!(summary.scene.analysis.quantile, 0.95);
        // The simulation's files are the source's; the measurement's are drawn anew; a track
        // read with the other width is not the run's, so it has none.
        for f in ["energy.csv", STATE_FILE] {
            assert_eq!(
                std::fs::read(run_dir.join(f)).expect("taken over"),
                std::fs::read(src_dir.join(f)).expect("source"),
                "{f}"
            );
        }
        for f in [
            "fragments.csv",
            "craters.csv",
            "cloud_side.png",
            "fragments.png",
        ] {
            assert!(run_dir.join(f).is_file(), "{f} drawn anew");
        }
        assert!(!run_dir.join("cloud_track.csv").exists());
        assert!(!run_dir.join("cloud_track.png").exists());
        measured.push((run_dir.clone(), summary));
    }
    assert_eq!(measured.len(), 2, "both runs measured");
    // results.csv says so too.
    for row in rows(&out.join("results.json")) {
        let source = row["measured_from"]
            .as_str()
            .expect("a measured run's source");
        assert!(simulated.iter().any(|(_, s)| s.fingerprint == source));
    }

    // (b) What a fresh simulation with those settings gives, in a store of its own.
    let fresh_out = dir.join("fresh");
    let o = sweep_with(&study, &fresh_out, &sets);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("2 ran, 0 failed"), "{}", stderr(&o));
    let fresh = store_records(&fresh_out);
    for (_, summary) in &measured {
        let (_, want) = fresh
            .iter()
            .find(|(d, _)| {
                read_summary(d).expect("summary").scene.material.eps_j
                    == summary.scene.material.eps_j
            })
            .expect("the fresh run of the same eps");
        assert_same_observables(&summary.observables(), &want.observables);
    }

    // (c) Running it again measures nothing; another camera keeps the track, which reads the
    // same (quantile and width unchanged).
    let o = sweep_with(&study, &out, &sets);
    assert!(
        stderr(&o).contains("2 cached, 0 ran, 0 failed"),
        "{}",
        stderr(&o)
    );
    let o = sweep_with(&study, &out, &["analysis.shadowgraph_optical_depth=0.5"]);
    assert!(
        stderr(&o).contains("0 ran, 2 measured from kept states"),
        "{}",
        stderr(&o)
    );
    for (run_dir, rec) in store_records(&out) {
        let summary = read_summary(&run_dir).expect("summary");
        if summary.scene.analysis.shadowgraph_optical_depth != 0.5 {
            continue;
        }
        let source = rec.measured_from.expect("measured");
        let (src_dir, _) = simulated
            .iter()
            .find(|(_, s)| s.fingerprint == source)
            .expect("a simulated source");
        assert_eq!(
            std::fs::read(run_dir.join("cloud_track.csv")).expect("track kept"),
            std::fs::read(src_dir.join("cloud_track.csv")).expect("source track")
        );
    }

    // (d) A source whose state no longer reads: its run is simulated, nothing is lost, the
    // other is measured.
    let (victim, _) = &simulated[0];
    let bytes = std::fs::read(victim.join(STATE_FILE)).expect("state");
    std::fs::write(victim.join(STATE_FILE), &bytes[..bytes.len() / 2]).expect("truncate");
    let o = sweep_with(&study, &out, &["analysis.witness_standoff_m=0.05"]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("1 ran, 1 measured from kept states, 0 failed"),
        "{err}"
    );
    assert!(err.contains("simulating it"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
