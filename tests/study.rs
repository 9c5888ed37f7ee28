//! End-to-end tests of the study runner (`hvi-study plan`, `sweep`, `run-unit`) on tiny
//! studies: plan validation, caching by fingerprint, resuming after SIGKILL, invalidation of
//! only the runs a change affects, failed runs recorded without stopping the study.

use std::path::{Path, PathBuf};
use std::process::{Output, Stdio};
use std::time::{Duration, Instant};

use crate::common;
use common::{bin, repo};

fn scratch(name: &str) -> PathBuf {
    common::scratch("hvi-study", name)
}

/// A study over the default scene with the given axes and quick tier; returns its path.
fn write_study(dir: &Path, name: &str, axes: &str, tier_set: &str) -> PathBuf {
    let scene = repo().join("studies/scenes/default.toml");
    let text = format!(
        "[study]\nname = \"{name}\"\nscene = \"{}\"\n\n{axes}\n[tiers.quick]\nset = [{tier_set}]\n",
        scene.display()
    );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).expect("study file");
    path
}

/// Tiny runs: 400 particles, 2 us after first contact (a fraction of a second each).
const TINY: &str = "\"resolution.particles=400\", \"run.end_time_s=2e-6\"";

fn sweep(study: &Path, out: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("sweep")
        .arg(study)
        .arg("--out")
        .arg(out)
        .args(["--threads", "2"])
        .args(extra)
        .output()
        .expect("runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn assert_ok(o: &Output) {
    assert!(o.status.success(), "exit {:?}\n{}", o.status, stderr(o));
}

/// The `runs: N total, C cached, R ran, F failed` line's numbers.
fn counts(o: &Output) -> (usize, usize, usize, usize) {
    let err = stderr(o);
    let line = err
        .lines()
        .map(|l| l.trim_start_matches("grid: "))
        .find(|l| l.starts_with("runs: "))
        .unwrap_or_else(|| panic!("no summary line in\n{err}"));
    let nums: Vec<usize> = line
        .split(|c: char| !c.is_ascii_digit() && c != '.')
        .filter_map(|w| w.parse().ok())
        .collect();
    (nums[0], nums[1], nums[2], nums[3])
}

/// Completed run directories (name -> record.json bytes and modification time).
fn records(out: &Path) -> Vec<(String, Vec<u8>, std::time::SystemTime)> {
    let mut v: Vec<_> = std::fs::read_dir(out.join("runs"))
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
                .filter_map(|e| {
                    let p = e.path().join("record.json");
                    let bytes = std::fs::read(&p).ok()?;
                    let mtime = std::fs::metadata(&p).ok()?.modified().ok()?;
                    Some((e.file_name().to_string_lossy().into_owned(), bytes, mtime))
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn results(out: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(out.join("results.json")).expect("results.json");
    serde_json::from_str::<Vec<serde_json::Value>>(&text).expect("results.json parses")
}

const GRID_2X2: &str = "[[axes]]\nkey = \"material.eps_j\"\nvalues = [0.01, 0.1]\n\n[[axes]]\nkey = \"material.kappa_n_m\"\nvalues = [2.28e6, 4.56e6]\n";

#[test]
fn plan_rejects_bad_studies_before_running_anything() {
    let dir = scratch("bad");
    let cases: [(&str, &str, &str); 7] = [
        (
            "[[axes]]\nkey = \"material.epsilon\"\nvalues = [0.01]\n",
            TINY,
            "epsilon",
        ),
        (
            "[[axes]]\nkey = \"material.eps_j\"\nvalues = []\n",
            TINY,
            "material.eps_j",
        ),
        (
            "[[axes]]\nkey = \"material.eps_j\"\nvalues = [0.01, -1.0]\n",
            TINY,
            "material.eps_j",
        ),
        (
            "[[axes]]\nkey = \"material.rcut_over_sigma\"\nvalues = [1.5, 1.0]\n",
            TINY,
            "material.rcut_over_sigma",
        ),
        (
            "[[axes]]\nkey = \"scene.v0_m_s\"\nrange = { from = 1000, to = 2000, count = 0 }\n",
            TINY,
            "scene.v0_m_s",
        ),
        (GRID_2X2, "\"run.end_time=1e-6\"", "end_time"),
        (
            GRID_2X2,
            "\"resolution.particles=-5\"",
            "resolution.particles",
        ),
    ];
    for (k, (axes, tier, needle)) in cases.iter().enumerate() {
        let study = write_study(&dir, &format!("bad{k}"), axes, tier);
        let out = dir.join(format!("out{k}"));
        let o = sweep(&study, &out, &[]);
        assert_eq!(o.status.code(), Some(2), "case {k}: {}", stderr(&o));
        assert!(
            stderr(&o).contains(needle),
            "case {k}: error does not name `{needle}`:\n{}",
            stderr(&o)
        );
        assert!(
            !out.join("runs").exists(),
            "case {k}: something ran before the plan was valid"
        );
    }
    // An axis key may not also be a fixed override.
    let study = write_study(&dir, "clash", GRID_2X2, TINY);
    let o = sweep(&study, &dir.join("clash"), &["--set", "material.eps_j=1"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("material.eps_j"), "{}", stderr(&o));
    // An unknown tier lists the study's tiers.
    let o = sweep(&study, &dir.join("tier"), &["--tier", "huge"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("quick"), "{}", stderr(&o));
}

#[test]
fn running_again_does_no_new_simulation() {
    let dir = scratch("again");
    let study = write_study(&dir, "again", GRID_2X2, TINY);
    let out = dir.join("out");
    let first = sweep(&study, &out, &[]);
    assert_ok(&first);
    assert_eq!(counts(&first), (4, 0, 4, 0), "{}", stderr(&first));
    // Each finished run's line says how much is left, but the last.
    let lines: Vec<String> = stderr(&first)
        .lines()
        .filter(|l| l.contains("completed in"))
        .map(String::from)
        .collect();
    assert_eq!(lines.len(), 4, "{}", stderr(&first));
    for (k, l) in lines.iter().enumerate() {
        assert_eq!(
            l.contains(&format!("; {} left, about ", 3 - k)),
            k < 3,
            "{l}"
        );
    }
    // study.log: every run's start and end, stamped; a run directory keeps no progress file.
    let log = || std::fs::read_to_string(out.join("study.log")).expect("study.log");
    let text = log();
    assert_eq!(text.matches(" start ").count(), 4, "{text}");
    assert_eq!(text.matches(": completed in ").count(), 4, "{text}");
    assert!(text.lines().all(|l| l.starts_with("20")), "{text}");
    assert!(text.contains("material.eps_j"), "{text}");
    for r in results(&out) {
        let run = out.join(r["dir"].as_str().expect("dir"));
        assert!(!run.join("progress.json").exists(), "{}", run.display());
    }
    let before = records(&out);
    assert_eq!(before.len(), 4);
    let rows = results(&out);
    assert_eq!(rows.len(), 4);
    for r in &rows {
        assert_eq!(r["status"], "completed", "{r}");
        assert!(r["particles"].as_f64().is_some(), "{r}");
    }
    let csv = std::fs::read_to_string(out.join("results.csv")).expect("csv");
    assert!(csv.starts_with("index,material.eps_j,material.kappa_n_m,status,fingerprint"));
    // Counts and yes/no columns are whole numbers, as pandas reads an integer column.
    let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
    for line in csv.lines().skip(1) {
        let cells: Vec<&str> = line.split(',').collect();
        for name in [
            "particles",
            "n_part",
            "n_frag",
            "crater_count",
            "large_central_crater",
        ] {
            let k = header.iter().position(|h| *h == name).expect("column");
            let cell = cells[k];
            assert!(
                cell.is_empty() || cell.parse::<i64>().is_ok(),
                "{name} = `{cell}` is not an integer"
            );
        }
        let k = header
            .iter()
            .position(|h| *h == "fragmentation")
            .expect("column");
        assert!(cells[k].contains('.'), "fragmentation `{}`", cells[k]);
    }

    let tables = |out: &Path| {
        ["results.csv", "results.json"].map(|f| std::fs::read(out.join(f)).expect("table"))
    };
    let fresh = tables(&out);

    let second = sweep(&study, &out, &[]);
    assert_ok(&second);
    assert_eq!(counts(&second), (4, 4, 0, 0), "{}", stderr(&second));
    assert_eq!(log(), text, "a cached run is not logged as run");
    assert_eq!(records(&out), before, "a cached run was rewritten");
    assert_eq!(results(&out), rows);
    // Byte for byte: numbers read back from the records are the numbers written.
    assert!(
        tables(&out) == fresh,
        "tables from stored runs differ from fresh ones"
    );
}

#[test]
fn changed_parameter_invalidates_only_the_affected_runs() {
    let dir = scratch("change");
    let study = write_study(&dir, "change", GRID_2X2, TINY);
    let out = dir.join("out");
    assert_ok(&sweep(&study, &out, &[]));
    // One eps value changes: the two runs at eps = 0.01 are kept, two new ones run.
    let changed = GRID_2X2.replace("[0.01, 0.1]", "[0.01, 0.3]");
    let study = write_study(&dir, "change", &changed, TINY);
    let o = sweep(&study, &out, &[]);
    assert_ok(&o);
    assert_eq!(counts(&o), (4, 2, 2, 0), "{}", stderr(&o));
    // A change every run sees (the seed) invalidates all of them.
    let o = sweep(&study, &out, &["--set", "run.seed=2"]);
    assert_ok(&o);
    assert_eq!(counts(&o), (4, 0, 4, 0), "{}", stderr(&o));
    // ...and going back finds the earlier results again.
    let o = sweep(&study, &out, &[]);
    assert_ok(&o);
    assert_eq!(counts(&o), (4, 4, 0, 0), "{}", stderr(&o));
}

#[test]
fn a_study_killed_mid_way_resumes_without_loss() {
    let dir = scratch("kill");
    // Six runs of about a second each, one at a time.
    let study = write_study(
        &dir,
        "kill",
        "[[axes]]\nkey = \"run.seed\"\nvalues = [1, 2, 3, 4, 5, 6]\n",
        "\"resolution.particles=1500\", \"run.end_time_s=6e-6\"",
    );
    let out = dir.join("out");
    let mut child = bin()
        .arg("sweep")
        .arg(&study)
        .arg("--out")
        .arg(&out)
        .args(["--threads", "1", "--quiet"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawns");
    let t0 = Instant::now();
    while records(&out).is_empty() {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "no run finished in 2 min"
        );
        if let Some(status) = child.try_wait().expect("wait") {
            panic!("the study ended before it could be killed: {status}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().expect("SIGKILL"); // Child::kill is SIGKILL on Unix
    child.wait().expect("reaped");
    let survived = records(&out);
    assert!(
        !survived.is_empty() && survived.len() < 6,
        "{}",
        survived.len()
    );

    let o = sweep(&study, &out, &[]);
    assert_ok(&o);
    let (total, cached, ran, failed) = counts(&o);
    assert_eq!((total, failed), (6, 0), "{}", stderr(&o));
    assert_eq!(cached, survived.len(), "{}", stderr(&o));
    assert_eq!(ran, 6 - survived.len(), "{}", stderr(&o));
    let after = records(&out);
    assert_eq!(after.len(), 6);
    for s in &survived {
        assert!(after.contains(s), "run {} was redone or changed", s.0);
    }
    let leftovers: Vec<_> = std::fs::read_dir(out.join("runs"))
        .expect("runs")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        // Temporary directories of killed processes; the runs' lock files stay by design.
        .filter(|n| n.starts_with(".tmp-") || n.starts_with(".old-"))
        .collect();
    assert!(
        leftovers.is_empty(),
        "temporary directories left: {leftovers:?}"
    );
    for r in results(&out) {
        assert_eq!(r["status"], "completed", "{r}");
    }
}

#[test]
fn a_failed_run_is_recorded_and_the_study_goes_on() {
    let dir = scratch("fail");
    // A ledger tolerance of 1e-14 trips at the first energy sample: that run is "unstable".
    let study = write_study(
        &dir,
        "fail",
        "[[axes]]\nkey = \"run.max_energy_drift\"\nvalues = [0.05, 1e-14]\n",
        TINY,
    );
    let out = dir.join("out");
    let o = sweep(&study, &out, &[]);
    assert_ok(&o);
    assert_eq!(counts(&o), (2, 0, 2, 1), "{}", stderr(&o));
    let rows = results(&out);
    assert_eq!(rows[0]["status"], "completed");
    assert_eq!(rows[1]["status"], "failed");
    assert!(
        rows[1]["error"].as_str().unwrap_or("").contains("energy"),
        "{}",
        rows[1]
    );
    let summary = std::fs::read_to_string(
        out.join(rows[1]["dir"].as_str().expect("dir"))
            .join("summary.json"),
    )
    .expect("the failed run keeps its summary");
    assert!(summary.contains("\"unstable\""));
    let log = std::fs::read_to_string(out.join("study.log")).expect("study.log");
    assert!(log.contains(": FAILED after "), "{log}");
    assert!(log.contains(": completed in "), "{log}");
    // The engine's verdict on the scene is the run's result: its record says so, and a study
    // run again keeps it rather than repeating it (a failure that may not recur, a full disk
    // say, runs again: `a_full_disk_gives_an_error_naming_the_file_and_leaves_a_consistent_store`).
    let record: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(
            out.join(rows[1]["dir"].as_str().expect("dir"))
                .join("record.json"),
        )
        .expect("record.json"),
    )
    .expect("json");
    assert_eq!(record["reproducible"], true, "{record}");
    let completed = std::fs::read_to_string(
        out.join(rows[0]["dir"].as_str().expect("dir"))
            .join("record.json"),
    )
    .expect("record.json");
    assert!(!completed.contains("reproducible"), "{completed}");
    let o = sweep(&study, &out, &[]);
    assert_ok(&o);
    assert_eq!(counts(&o), (2, 2, 0, 1), "{}", stderr(&o));
    assert!(stderr(&o).contains("kept, not run again"), "{}", stderr(&o));
    let o = hvi_study(&["status".as_ref(), out.as_os_str()]);
    assert_ok(&o);
    let line = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(line.contains("2 runs: 1 done, 1 failed for good"), "{line}");
    let log = std::fs::read_to_string(out.join("study.log")).expect("study.log");
    assert_eq!(log.matches(": FAILED after ").count(), 1, "{log}");
    assert_eq!(results(&out)[1]["status"], "failed");
}

/// `hvi-study ARGS`, its output.
fn hvi_study(args: &[&std::ffi::OsStr]) -> Output {
    bin().args(args).output().expect("runs")
}

/// A run of `out`'s store in progress in this (live) process, as the store names its working
/// directory (`.tmp-DIGITS-PID-0`), holding `progress` as its progress.json; the directory.
fn run_in_progress(out: &Path, digits: &str, progress: &str) -> PathBuf {
    let work = out
        .join("runs")
        .join(format!(".tmp-{digits}-{}-0", std::process::id()));
    std::fs::create_dir_all(&work).expect("work dir");
    std::fs::write(work.join("progress.json"), progress).expect("progress");
    work
}

#[test]
fn status_shows_a_running_runs_progress() {
    let dir = scratch("status-progress");
    let study = write_study(&dir, "progress", GRID_2X2, TINY);
    let out = dir.join("out");
    let o = hvi_study(&[
        "plan".as_ref(),
        study.as_ref(),
        "--out".as_ref(),
        out.as_ref(),
    ]);
    assert_ok(&o);
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("plan.json")).expect("plan"))
            .expect("json");
    let run_dir = doc["runs"][1]["dir"].as_str().expect("dir").to_string();
    let digits = run_dir.trim_start_matches("runs/");
    // A run in progress in this (live) process, with the progress file a store run keeps.
    run_in_progress(
        &out,
        digits,
        r#"{"step":500,"steps":1000,"time_s":1e-6,"end_time_s":2e-6,"wall_s":120.0}"#,
    );
    let o = hvi_study(&[
        "status".as_ref(),
        study.as_ref(),
        "--out".as_ref(),
        out.as_ref(),
        "--verbose".as_ref(),
    ]);
    assert_ok(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("1 running"), "{text}");
    let line = text
        .lines()
        .find(|l| l.contains(&run_dir))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(
        line.contains("running")
            && line.contains(": 50 % (1.0 of 2.0 us simulated, 2.0 min so far)"),
        "{line}"
    );
    // A run beyond the plan (a calibration's search) in progress: listed with its progress.
    let beyond = run_in_progress(
        &out,
        "ffffffffffffffff",
        r#"{"step":250,"steps":1000,"time_s":8e-6,"end_time_s":3.2e-5,"wall_s":30.0}"#,
    );
    let o = hvi_study(&[
        "status".as_ref(),
        out.join("plan.json").as_os_str(),
        "--verbose".as_ref(),
    ]);
    assert_ok(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("1 in progress here"), "{text}");
    assert!(
        text.contains(&format!(
            "  runs/ffffffffffffffff in progress here, process {}: 25 % (8.0 of 32.0 us simulated, 30 s so far)",
            std::process::id()
        )),
        "{text}"
    );
    std::fs::remove_dir_all(&beyond).expect("removed");
    // Asked with a study file whose plan differs from the directory's (another end time here,
    // as a ladder level's or a running calibration's directory differs from its study file's
    // grid), status looks and writes nothing.
    let before = std::fs::read(out.join("plan.json")).expect("plan");
    let o = hvi_study(&[
        "status".as_ref(),
        study.as_ref(),
        "--out".as_ref(),
        out.as_ref(),
        "--set".as_ref(),
        "run.end_time_s=3e-6".as_ref(),
    ]);
    assert_ok(&o);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("4 pending"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    assert_eq!(
        std::fs::read(out.join("plan.json")).expect("plan"),
        before,
        "status rewrote plan.json"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn run_unit_executes_one_run_of_a_plan() {
    let dir = scratch("unit");
    let study = write_study(&dir, "unit", GRID_2X2, TINY);
    let out = dir.join("out");
    let o = bin()
        .arg("plan")
        .arg(&study)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("runs");
    assert_ok(&o);
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("material.eps_j (2 values) x material.kappa_n_m (2 values)"),
        "{said}"
    );
    let plan = out.join("plan.json");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&plan).expect("plan")).expect("json");
    assert_eq!(doc["runs"].as_array().map(Vec::len), Some(4));
    // One value is one value, not "1 values".
    let single = write_study(
        &dir,
        "single",
        "[[axes]]\nkey = \"material.eps_j\"\nvalues = [0.01]\n",
        TINY,
    );
    let o = bin()
        .arg("plan")
        .arg(&single)
        .arg("--out")
        .arg(dir.join("single"))
        .output()
        .expect("runs");
    assert_ok(&o);
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("material.eps_j (1 value)"), "{said}");
    assert!(!out.join("runs").read_dir().expect("runs").any(|_| true));

    let o = bin()
        .args(["run-unit"])
        .arg(&plan)
        .args(["2", "--threads", "1"])
        .output()
        .expect("runs");
    assert_ok(&o);
    let run_dir = PathBuf::from(String::from_utf8_lossy(&o.stdout).trim());
    assert!(run_dir.join("record.json").exists());
    assert!(run_dir.join("summary.json").exists());
    assert_eq!(
        run_dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned()),
        doc["runs"][2]["dir"]
            .as_str()
            .and_then(|d| d.strip_prefix("runs/"))
            .map(String::from)
    );
    let o = bin()
        .args(["run-unit"])
        .arg(&plan)
        .arg("4")
        .output()
        .expect("runs");
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("0..=3"), "{}", stderr(&o));
    // The sweep finds the run-unit's result.
    let o = sweep(&study, &out, &[]);
    assert_eq!(counts(&o), (4, 1, 3, 0), "{}", stderr(&o));
}

#[test]
fn results_of_different_studies_never_mix() {
    let dir = scratch("mix");
    let a = write_study(&dir, "alpha", GRID_2X2, TINY);
    let b = write_study(&dir, "beta", GRID_2X2, TINY);
    let out = dir.join("out");
    let o = bin()
        .arg("plan")
        .arg(&a)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("runs");
    assert_ok(&o);
    let o = sweep(&b, &out, &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("alpha"), "{}", stderr(&o));
    // A run directory whose record names another fingerprint is refused, not reused.
    let o = sweep(&a, &out, &[]);
    assert_ok(&o);
    let rows = results(&out);
    let d0 = out.join(rows[0]["dir"].as_str().expect("dir"));
    let d1 = out.join(rows[1]["dir"].as_str().expect("dir"));
    std::fs::copy(d1.join("record.json"), d0.join("record.json")).expect("tamper");
    let o = sweep(&a, &out, &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("refusing to mix"), "{}", stderr(&o));
}

/// `hvi-study calibrate STUDY --out OUT` on 2 threads.
fn calibrate(study: &Path, out: &Path) -> Output {
    calibrate_with(study, out, &[])
}

/// A calibration's calibration.json.
fn calibration_json(out: &Path) -> serde_json::Value {
    serde_json::from_str(
        &std::fs::read_to_string(out.join("calibration.json")).expect("calibration.json"),
    )
    .expect("json")
}

#[test]
fn calibrate_scores_the_grid_refines_through_the_store_and_compares_with_the_paper() {
    let dir = scratch("calibrate");
    let targets = repo().join("experiments_data/calibration-shot.toml");
    let axes = format!(
        "{GRID_2X2}\n[calibrate]\ntargets = \"{}\"\nmethod = \"nelder-mead\"\nmax_iters = 2\nsd_tolerance = 0\n",
        targets.display()
    );
    let study = write_study(&dir, "cal", &axes, TINY);
    let out = dir.join("out");
    let run = || calibrate(&study, &out);
    let o = run();
    assert_ok(&o);
    for needle in ["best:", "paper's fit:", "length_ratio", "not scored (gap)"] {
        assert!(
            stderr(&o).contains(needle),
            "no `{needle}` in\n{}",
            stderr(&o)
        );
    }
    let read = || calibration_json(&out);
    let c = read();
    let best = c["best"]["objective"].as_f64().expect("best objective");
    assert!(
        best <= c["best_grid"]["objective"]
            .as_f64()
            .expect("grid objective")
    );
    assert!(c["best"]["params"]["material.eps_j"].as_f64().is_some());
    assert_eq!(
        c["paper"]["params"]["material.kappa_n_m"].as_f64(),
        Some(4.56e6)
    );
    let terms = c["best"]["score"]["terms"].as_array().expect("terms");
    assert_eq!(terms.len(), 3);
    assert!(c["termination"]
        .as_str()
        .unwrap_or("")
        .contains("iterations"));
    let evaluations = c["refinement"].as_array().expect("refinement").len();
    assert!(evaluations >= 3, "{evaluations}");
    let table = std::fs::read_to_string(out.join("results.csv")).expect("results.csv");
    assert!(table
        .lines()
        .next()
        .unwrap_or("")
        .contains("score_length_ratio"));
    assert!(out.join("evaluations.csv").exists());
    assert!(out.join("snapshots.png").exists(), "{}", stderr(&o));
    for stem in ["map_R", "map_va", "map_objective"] {
        for ext in ["png", "svg"] {
            assert!(
                out.join(format!("{stem}.{ext}")).exists(),
                "{stem}.{ext} missing:\n{}",
                stderr(&o)
            );
        }
    }
    // The map of R says which width it read (the scene's default, side-on).
    let svg = std::fs::read_to_string(out.join("map_R.svg")).expect("map_R.svg");
    assert!(
        svg.contains("Lr read side-on (analysis.width = side)"),
        "map_R.svg does not name its reading of the width"
    );

    // Again: grid and refinement come from the store, the same result, no new run.
    let o = run();
    assert_ok(&o);
    let c2 = read();
    assert_eq!(c2["refinement_runs"], 0, "{}", stderr(&o));
    // The same point, objective and score; only `cached` may differ (a refinement point is
    // computed the first time and comes from the store the second).
    let without_cached = |v: &serde_json::Value| {
        let mut v = v.clone();
        v.as_object_mut().expect("best").remove("cached");
        v
    };
    assert_eq!(without_cached(&c2["best"]), without_cached(&c["best"]));
    assert_eq!(c2["best"]["cached"], true);
    assert_eq!(counts(&o).2, 0, "{}", stderr(&o));
}

#[test]
fn calibrate_searches_by_surrogate_in_batches_at_two_seeds_and_resumes_without_new_runs() {
    let dir = scratch("calibrate-ego");
    let targets = repo().join("experiments_data/calibration-shot.toml");
    // Three eps values so the box has an inside; a zero noise floor so that the seeds' scatter
    // alone decides when to stop.
    let axes = format!(
        "[[axes]]\nkey = \"material.eps_j\"\nvalues = [0.01, 0.1, 1.0]\n\n[[axes]]\nkey = \"material.kappa_n_m\"\nvalues = [2.28e6, 4.56e6]\n\n[calibrate]\ntargets = \"{}\"\nseeds = [1, 2]\nseeds_within_decades = inf\nbatch = 2\nmax_batches = 2\nnoise_floor = 0\nmax_extensions = 0\n",
        targets.display()
    );
    let study = write_study(&dir, "ego", &axes, TINY);
    let out = dir.join("out");
    let run = || calibrate(&study, &out);
    let o = run();
    assert_ok(&o);
    let read = || calibration_json(&out);
    let c = read();
    assert_eq!(c["method"], "ego");
    let termination = c["termination"].as_str().expect("termination");
    let converged = c["converged"].as_bool().expect("converged");
    assert_eq!(
        converged,
        termination.starts_with("converged"),
        "{termination}"
    );
    if !converged {
        // The batches ran out, or the answer touches a side (the box is kept here:
        // max_extensions = 0; extending is tested below).
        assert!(
            termination.contains("max_batches = 2") || termination.contains("touches"),
            "{termination}"
        );
    }
    // Every point after the grid ran at both seeds, and each is scored.
    let evals = c["refinement"].as_array().expect("evaluations");
    let grid_seeds = evals.iter().filter(|e| e["stage"] == "grid-seeds").count();
    assert_eq!(grid_seeds, 6, "the grid at the seeds");
    for e in evals {
        assert_eq!(e["seeds"], serde_json::json!([1, 2]), "{e}");
        assert_eq!(
            e["seed_objectives"].as_array().map(Vec::len),
            Some(2),
            "{e}"
        );
    }
    // Runs: the grid (6 at seed 1) + the grid at seed 2 (6) + 2 per point of each batch.
    let batches = evals
        .iter()
        .filter(|e| e["stage"].as_str().is_some_and(|s| s.starts_with("ego-")))
        .count();
    assert!(batches <= 4, "{batches} points in at most 2 batches of 2");
    assert_eq!(c["runs_made"].as_u64(), Some((12 + 2 * batches) as u64));
    assert!(
        c["noise"].as_f64().is_some_and(|n| n > 0.0),
        "{}",
        c["noise"]
    );
    // Two seeds and a zero floor: the noise is the seeds' scatter, and says so.
    let source = c["noise_source"].as_str().expect("noise_source");
    assert!(source.starts_with("measured"), "{source}");
    // A region, one interval per searched axis, holding the chosen point.
    for key in ["material.eps_j", "material.kappa_n_m"] {
        let iv = &c["region"]["intervals"][key];
        let (lo, hi) = (iv[0].as_f64().expect("lo"), iv[1].as_f64().expect("hi"));
        let best = c["best"]["params"][key].as_f64().expect("best");
        assert!(lo <= hi, "{key}: {iv}");
        assert!(best > 0.0);
    }
    assert_eq!(c["best_spread"].as_array().map(Vec::len), Some(3));
    let md = std::fs::read_to_string(out.join("calibration.md")).expect("calibration.md");
    assert!(md.contains("CONVERGED"), "{md}");
    assert!(md.contains("| `material.eps_j` |"), "{md}");
    let csv = std::fs::read_to_string(out.join("evaluations.csv")).expect("evaluations.csv");
    let header = csv.lines().next().unwrap_or("");
    assert!(
        header.contains(",seeds,status,cached,screened,dir"),
        "{header}"
    );
    // The model's prediction over the two searched axes, the map's background.
    let surface = std::fs::read_to_string(out.join("surrogate.csv")).expect("surrogate.csv");
    let rows: Vec<&str> = surface.lines().collect();
    assert_eq!(
        rows[0],
        "material.eps_j,material.kappa_n_m,predicted_log10_objective"
    );
    assert_eq!(rows.len(), 1 + 33 * 33);
    assert!(rows[1..].iter().all(|r| r
        .rsplit(',')
        .next()
        .and_then(|z| z.parse::<f64>().ok())
        .is_some_and(f64::is_finite)));
    // The first time nothing after the grid came from the store, but for the grid point
    // where the paper's fit sits (its runs at the seeds were made for the paper's point,
    // which is scored before the search).
    let paper = &c["paper"]["params"];
    let at_paper = |e: &serde_json::Value| {
        e["params"]
            .as_object()
            .expect("params")
            .iter()
            .all(|(k, v)| paper.get(k).is_none_or(|p| p == v))
    };
    assert!(
        evals.iter().all(|e| e["cached"] == false || at_paper(e)),
        "{evals:?}"
    );

    // Again: the same proposals, every run from the store, the same answer.
    let o = run();
    assert_ok(&o);
    let c2 = read();
    assert_eq!(c2["runs_made"], 0, "{}", stderr(&o));
    assert_eq!(c2["best"]["params"], c["best"]["params"]);
    assert_eq!(c2["region"], c["region"]);
    let evals2 = c2["refinement"].as_array().expect("evaluations");
    assert_eq!(evals2.len(), evals.len());
    assert!(evals2.iter().all(|e| e["cached"] == true), "{evals2:?}");
}

/// `calibrate.seeds_within_decades` (at its default, 1): the grid and each batch run at the
/// first seed, and at the second only the points whose first-seed J is within a decade of the
/// lowest so far; the runs made are exactly those, and a second invocation makes the same
/// decisions from the store without a run. The target (R = 1.2, read cylindrically, at 2000
/// particles) puts J decades apart over eps from 1e-4 to 1 J.
#[test]
fn calibrate_runs_the_further_seeds_only_near_the_lowest_objective() {
    let dir = scratch("calibrate-screened");
    let targets = dir.join("targets.toml");
    edge_targets(&targets);
    let study = eps_study(
        &dir,
        "screened",
        "[1e-4, 1e-3, 1e-2, 0.1, 1.0]",
        &targets,
        "seeds = [1, 2]\nbatch = 2\nmax_batches = 1\nmax_extensions = 0\n",
    );
    let out = dir.join("out");
    let o = calibrate(&study, &out);
    assert_ok(&o);
    assert!(
        stderr(&o).contains("within 1 decade(s) of the lowest"),
        "{}",
        stderr(&o)
    );
    let c = calibration_json(&out);
    let evals = c["refinement"].as_array().expect("evaluations");
    // Each stage in turn: the lowest J so far (seed means, and the stage's own first seeds)
    // decides which points run the second seed.
    let log = |j: f64| j.max(1e-6).log10();
    let mut lowest = f64::INFINITY;
    let (mut runs, mut one, mut both) = (0, 0, 0);
    let mut stages: Vec<&serde_json::Value> = evals.iter().map(|e| &e["stage"]).collect();
    stages.dedup();
    for stage in stages {
        let of_stage: Vec<&serde_json::Value> =
            evals.iter().filter(|e| &e["stage"] == stage).collect();
        let first = |e: &serde_json::Value| e["seed_objectives"][0].as_f64().expect("J at seed 1");
        let cut = log(of_stage.iter().map(|e| first(e)).fold(lowest, f64::min)) + 1.0;
        for e in &of_stage {
            let near = log(first(e)) <= cut;
            let seeds = if near {
                serde_json::json!([1, 2])
            } else {
                serde_json::json!([1])
            };
            assert_eq!(e["seeds"], seeds, "{stage}, cut-off log10 J {cut}: {e}");
            // The grid's runs at seed 1 are the grid's own.
            runs += usize::from(stage != "grid-seeds") + usize::from(near);
            (one, both) = if near {
                (one, both + 1)
            } else {
                (one + 1, both)
            };
        }
        lowest = of_stage
            .iter()
            .map(|e| e["objective"].as_f64().expect("J"))
            .fold(lowest, f64::min);
    }
    assert!(
        one > 0 && both > 0,
        "{one} points at one seed, {both} at two: {evals:?}"
    );
    assert!(
        stderr(&o).contains(&format!("{one} of them at one seed")),
        "{}",
        stderr(&o)
    );
    // The paper's fit (a grid point here) runs at both seeds before the search: its second
    // seed is one more run when the screening gave its grid point one seed.
    let paper = evals
        .iter()
        .find(|e| e["stage"] == "grid-seeds" && e["params"] == c["paper"]["params"])
        .expect("the paper's fit is a grid point");
    runs += usize::from(paper["seeds"] == serde_json::json!([1]));
    assert_eq!(
        c["runs_made"].as_u64(),
        Some(5 + runs as u64),
        "{}",
        stderr(&o)
    );

    let o = calibrate(&study, &out);
    assert_ok(&o);
    let c2 = calibration_json(&out);
    assert_eq!(c2["runs_made"], 0, "{}", stderr(&o));
    let seeds = |c: &serde_json::Value| -> Vec<serde_json::Value> {
        let evals = c["refinement"].as_array().expect("evaluations");
        evals.iter().map(|e| e["seeds"].clone()).collect()
    };
    assert_eq!(seeds(&c2), seeds(&c));
    assert_eq!(c2["best"]["params"], c["best"]["params"]);
}

/// A calibration of eps alone on the calibration scene at 2000 particles (a quarter of a
/// second a run) against a length ratio of 1.2 alone, with R's width read cylindrically: R
/// rises with eps there (about 1.05 at 1e-4 J, 1.2 at 1e-3 J, 1.7 at 1e-2 J), so the optimum
/// lies a decade below a first box of [0.01, 1] J. (Side-on, the default, R is 2.3 already
/// at 1e-2 J at this coarse resolution; the search's mechanics are what these tests check.)
fn edge_study(dir: &Path, extra: &str) -> PathBuf {
    let targets = dir.join("targets.toml");
    edge_targets(&targets);
    edge_study_with(dir, &targets, extra)
}

fn edge_targets(targets: &Path) {
    std::fs::write(
        targets,
        "[shot]\nid = \"test\"\ndescription = \"a test\"\nsource = \"a test\"\nimpactor_diameter_m = 9.53e-3\nv0_m_s = 6700.0\nt_over_d = 0.425\nimpactor_material = \"Al\"\nplate_material = \"Al\"\n\n[[targets]]\nname = \"length_ratio\"\nobservable = \"length_ratio\"\nkind = \"value\"\nvalue = 1.2\ntolerance = 0.1\nweight = 1.0\nsource = \"a test\"\n",
    )
    .expect("targets");
}

/// The edge study over eps at 2000 particles (R read cylindrically) against `targets`.
fn edge_study_with(dir: &Path, targets: &Path, extra: &str) -> PathBuf {
    eps_study(
        dir,
        "edge",
        "[0.01, 0.1, 1.0]",
        targets,
        &format!("seeds = [1, 2]\nbatch = 2\nmax_batches = 3\n{extra}"),
    )
}

/// A study `name` over eps at the values `values` (a TOML array) on the calibration scene at
/// 2000 particles (kappa 4.56e6 N/m, R read cylindrically), calibrated against `targets` with
/// the rest of its `[calibrate]` section `calibrate`; written to `dir/<name>.toml`.
fn eps_study(dir: &Path, name: &str, values: &str, targets: &Path, calibrate: &str) -> PathBuf {
    let text = format!(
        "[study]\nname = \"{name}\"\nscene = \"{}\"\n\n[[axes]]\nkey = \"material.eps_j\"\nvalues = {values}\n\n[tiers.quick]\nset = [\"resolution.particles=2000\", \"material.kappa_n_m=4.56e6\", \"analysis.width=cylindrical\"]\n\n[calibrate]\ntargets = \"{}\"\n{calibrate}",
        repo().join("studies/scenes/calibration.toml").display(),
        targets.display()
    );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).expect("study");
    path
}

#[test]
fn an_optimum_outside_the_first_box_extends_it_and_ends_inside() {
    let dir = scratch("calibrate-extend");
    let study = edge_study(&dir, "");
    let out = dir.join("out");
    let o = calibrate(&study, &out);
    assert_ok(&o);
    let c = calibration_json(&out);
    let boxes = c["boxes"].as_array().expect("boxes");
    assert!(boxes.len() >= 2, "the first box was extended: {boxes:?}");
    // The first box is the grid's, and the answer touched its low side.
    assert_eq!(
        boxes[0]["bounds"]["material.eps_j"],
        serde_json::json!([0.01, 1.0])
    );
    assert_eq!(boxes[0]["edges"][0]["side"], "low", "{}", boxes[0]);
    // Each later box reaches a decade further down; the new grid values ran at the first
    // seed, and at both near the answer (a point left at one seed is more than a decade above
    // the lowest J, calibrate.seeds_within_decades).
    let last = &boxes[boxes.len() - 1]["bounds"]["material.eps_j"];
    assert!(last[0].as_f64().expect("lo") <= 1.0001e-3, "{last}");
    let extended = extension_points(&c);
    assert!(!extended.is_empty());
    let lowest = c["refinement"]
        .as_array()
        .expect("evaluations")
        .iter()
        .filter_map(|e| e["objective"].as_f64())
        .fold(f64::INFINITY, f64::min);
    for e in &extended {
        let j = e["seed_objectives"][0].as_f64().expect("J at seed 1");
        if e["seeds"] == serde_json::json!([1]) {
            assert!(j > 10.0 * lowest, "{e}");
        } else {
            assert_eq!(e["seeds"], serde_json::json!([1, 2]), "{e}");
        }
        assert!(e["params"]["material.eps_j"].as_f64().expect("eps") < 0.01);
    }
    assert!(
        extended
            .iter()
            .any(|e| e["seeds"] == serde_json::json!([1, 2])),
        "{extended:?}"
    );
    // It ends inside: no edge left, the best point and its interval inside the last box, and
    // the best eps within the decade where R crosses 1.2.
    assert_eq!(c["edges"], serde_json::json!([]), "{}", stderr(&o));
    let best = c["best"]["params"]["material.eps_j"]
        .as_f64()
        .expect("best");
    assert!((2e-4..5e-3).contains(&best), "best eps {best}");
    let iv = &c["region"]["intervals"]["material.eps_j"];
    let (lo, hi) = (iv[0].as_f64().expect("lo"), iv[1].as_f64().expect("hi"));
    assert!(
        lo > last[0].as_f64().expect("box lo") && hi < 1.0,
        "interval {iv}, box {last}"
    );
    assert_eq!(
        c["converged"].as_bool(),
        Some(
            c["termination"]
                .as_str()
                .is_some_and(|t| t.starts_with("converged"))
        )
    );
    // The paper's fit is scored over the same seeds as the answer.
    assert_eq!(
        c["paper"]["seeds"],
        serde_json::json!([1, 2]),
        "{}",
        c["paper"]
    );
    assert_eq!(
        c["best_grid"]["seeds"],
        serde_json::json!([1, 2]),
        "{}",
        c["best_grid"]
    );
}

/// The evaluations of calibration.json at the grid points each extension of the box added.
fn extension_points(c: &serde_json::Value) -> Vec<&serde_json::Value> {
    c["refinement"]
        .as_array()
        .expect("refinement")
        .iter()
        .filter(|e| {
            e["stage"]
                .as_str()
                .is_some_and(|s| s.starts_with("extend-"))
        })
        .collect()
}

/// `initial_design = "corners"`: the grid stage runs the box's ends and centre (3 of 5 eps
/// values), the extension runs the skipped grid point next to the answer, the answer and the
/// last box are the full grid's, with fewer runs, and a second invocation runs nothing.
#[test]
fn a_corner_design_runs_fewer_grid_points_and_fills_the_skipped_ones_near_the_answer() {
    let dir = scratch("calibrate-corners");
    let targets = dir.join("targets.toml");
    edge_targets(&targets);
    let calibrate_section = "seeds = [1, 2]\nbatch = 2\nmax_batches = 3\n";
    let values = "[0.002, 0.005, 0.02, 0.05, 0.2]";
    let full = eps_study(&dir, "full", values, &targets, calibrate_section);
    let corners = eps_study(
        &dir,
        "corners",
        values,
        &targets,
        &format!("{calibrate_section}initial_design = \"corners\"\n"),
    );
    let eps = |e: &serde_json::Value| e["params"]["material.eps_j"].as_f64().expect("eps");
    let (out_full, out_corners) = (dir.join("full-out"), dir.join("corners-out"));
    assert_ok(&calibrate(&full, &out_full));
    let o = calibrate(&corners, &out_corners);
    assert_ok(&o);
    let c = calibration_json(&out_corners);
    assert_eq!(
        c["initial_design"],
        serde_json::json!({"name": "corners", "points": 3, "grid_points": 5})
    );
    assert!(
        stderr(&o).contains("the grid stage ran the corners design, 3 of the grid's 5 points"),
        "{}",
        stderr(&o)
    );
    // The grid stage: the two ends and the value nearest the centre (in log10: 0.02 J).
    let grid: Vec<f64> = c["refinement"]
        .as_array()
        .expect("refinement")
        .iter()
        .filter(|e| e["stage"] == "grid-seeds")
        .map(eps)
        .collect();
    assert_eq!(grid, vec![0.002, 0.02, 0.2], "{}", stderr(&o));
    let rows = std::fs::read_to_string(out_corners.join("results.csv")).expect("results.csv");
    assert_eq!(rows.lines().count(), 1 + 3, "{rows}");
    // The answer touched the low side: the first extension ran a step below the box and the
    // grid's skipped 5e-3 J, one grid step from the answer.
    let first: Vec<f64> = extension_points(&c)
        .into_iter()
        .filter(|e| e["stage"] == "extend-0")
        .map(eps)
        .collect();
    assert!(
        first.iter().any(|&e| e < 0.002) && first.contains(&0.005),
        "extend-0 ran {first:?}"
    );
    // The full grid's calibration ends at the same point in the same box.
    let f = calibration_json(&out_full);
    assert_eq!(c["best"]["params"], f["best"]["params"], "{}", stderr(&o));
    let last = |c: &serde_json::Value| c["boxes"].as_array().and_then(|b| b.last()).cloned();
    assert_eq!(
        last(&c).map(|b| b["bounds"].clone()),
        last(&f).map(|b| b["bounds"].clone())
    );
    assert_ne!(c["label"], f["label"], "the design is part of the label");
    assert!(
        c["runs_made"].as_u64() < f["runs_made"].as_u64(),
        "{} runs against {}",
        c["runs_made"],
        f["runs_made"]
    );

    // `status` says why the skipped grid value (0.05 J) is pending.
    let o = hvi_study(&["status".as_ref(), out_corners.as_os_str()]);
    let said = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        said.contains("5 runs: 4 done, 0 failed, 0 running, 1 pending"),
        "{said}"
    );
    assert!(
        said.contains("ran the corners design (3 of the grid's 5 points)"),
        "{said}"
    );

    let o = calibrate(&corners, &out_corners);
    assert_ok(&o);
    let c2 = calibration_json(&out_corners);
    assert_eq!(c2["runs_made"], 0, "{}", stderr(&o));
    assert_eq!(c2["best"]["params"], c["best"]["params"]);
}

/// A corner design over two axes (`--initial-design corners`) draws its maps and snapshots
/// from the points it ran, each
/// evaluation of the grid at the search's seeds keeping its grid run's index.
#[test]
fn a_corner_design_over_two_axes_draws_its_maps() {
    let dir = scratch("calibrate-corners-maps");
    let targets = dir.join("targets.toml");
    edge_targets(&targets);
    let study = eps_study(
        &dir,
        "corners2",
        "[0.002, 0.02, 0.2]",
        &targets,
        "seeds = [1, 2]\nbatch = 1\nmax_batches = 1\nmax_extensions = 0\n",
    );
    let text = std::fs::read_to_string(&study).expect("study");
    let two_axes = text
        .replace(
            "\n\n[tiers.quick]",
            "\n\n[[axes]]\nkey = \"material.kappa_n_m\"\nvalues = [1.14e6, 4.56e6]\n\n[tiers.quick]",
        )
        .replace("\"material.kappa_n_m=4.56e6\", ", "");
    std::fs::write(&study, two_axes).expect("study");
    // The command line's design, over the study's (the default, every point).
    let out = dir.join("out");
    let o = calibrate_with(&study, &out, &["--initial-design", "corners"]);
    assert_ok(&o);
    let c = calibration_json(&out);
    assert_eq!(c["initial_design"]["points"], 5, "{}", stderr(&o));
    for file in [
        "map_R.png",
        "map_va.png",
        "map_objective.png",
        "snapshots.png",
    ] {
        assert!(out.join(file).exists(), "{file} missing:\n{}", stderr(&o));
    }
    // The grid stage's run indices, and the same indices on the grid at the seeds.
    let evals = std::fs::read_to_string(out.join("evaluations.csv")).expect("evaluations.csv");
    let steps = |stage: &str| -> Vec<String> {
        evals
            .lines()
            .filter(|l| l.starts_with(&format!("{stage},")))
            .map(|l| l.split(',').nth(1).unwrap_or("").to_string())
            .collect()
    };
    assert_eq!(steps("grid"), vec!["0", "1", "2", "4", "5"], "{evals}");
    assert_eq!(steps("grid-seeds"), steps("grid"), "{evals}");
}

/// The map of R after the box moved shows every box searched (the new grid points' seed
/// means), not only the study's grid, and says so.
#[test]
fn the_map_of_r_covers_every_box_searched() {
    let dir = scratch("calibrate-extend-map");
    let study = edge_study(&dir, "max_extensions = 1\nmax_batches = 1\n");
    let text = std::fs::read_to_string(&study).expect("study");
    let two_axes = text
        .replace(
            "\n\n[tiers.quick]",
            "\n\n[[axes]]\nkey = \"material.kappa_n_m\"\nvalues = [2.28e6, 4.56e6]\n\n[tiers.quick]",
        )
        .replace("\"material.kappa_n_m=4.56e6\", ", "")
        .replace("max_batches = 3\n", "");
    std::fs::write(&study, two_axes).expect("study");
    let out = dir.join("out");
    let o = calibrate(&study, &out);
    assert_ok(&o);
    let c = calibration_json(&out);
    let boxes = c["boxes"].as_array().expect("boxes");
    assert!(boxes.len() >= 2, "the box moved: {boxes:?}");
    // Fig. 9's and Fig. 10's maps both cover the extension.
    for map in ["map_R.svg", "map_va.svg"] {
        let svg = std::fs::read_to_string(out.join(map)).expect(map);
        assert!(
            svg.contains("over every box searched, seed means at seeds 1, 2"),
            "{map}: {}",
            stderr(&o)
        );
        // The eps axis reaches the extension's decade (1e-3 J), below the grid's 0.01 J.
        assert!(
            svg.lines().any(|l| l.trim() == "1e-3"),
            "no 1e-3 tick on {map}"
        );
    }
    // What they draw: each extension point's seed means of every observable, the scored R
    // among them equal to its term's.
    let extended = extension_points(&c);
    assert!(!extended.is_empty(), "no extension point");
    for e in extended {
        let means = &e["means"];
        let va = means["front_velocity_ratio"].as_f64().expect("va/v0 mean");
        assert!(va > 0.0 && va < 1.5, "{e}");
        let r_term = e["score"]["terms"]
            .as_array()
            .and_then(|t| t.iter().find(|t| t["name"] == "length_ratio"))
            .and_then(|t| t["observed"].as_f64())
            .expect("R's term");
        assert_eq!(means["length_ratio"].as_f64(), Some(r_term), "{e}");
    }
}

#[test]
fn an_optimum_on_the_edge_is_never_converged() {
    let dir = scratch("calibrate-edge");
    let out = dir.join("out");
    // The box kept (--no-extend), and a box allowed no step beyond the grid: both report the
    // side and the limit, and neither says converged.
    for (extra, flags, why) in [
        ("", &["--no-extend"][..], "not extended (--no-extend)"),
        (
            "max_extensions = 0\n",
            &[][..],
            "calibrate.max_extensions = 0",
        ),
    ] {
        let study = edge_study(&dir, extra);
        let o = bin()
            .arg("calibrate")
            .arg(&study)
            .arg("--out")
            .arg(&out)
            .args(["--threads", "2"])
            .args(flags)
            .output()
            .expect("runs");
        assert_ok(&o);
        let c = calibration_json(&out);
        assert_eq!(c["converged"], false, "{}", c["termination"]);
        assert_eq!(c["boxes"].as_array().map(Vec::len), Some(1));
        let edge = &c["edges"][0];
        assert_eq!(edge["key"], "material.eps_j");
        assert_eq!(edge["side"], "low");
        assert_eq!(edge["value"], 0.01);
        assert!(
            edge["limit"].as_str().is_some_and(|l| l.contains(why)),
            "{edge}"
        );
        let termination = c["termination"].as_str().expect("termination");
        assert!(
            termination
                .starts_with("not converged: the answer touches the low side of material.eps_j"),
            "{termination}"
        );
        assert!(
            c["limit"]
                .as_str()
                .is_some_and(|l| l.contains("material.eps_j")),
            "{}",
            c["limit"]
        );
        let err = stderr(&o);
        assert!(err.contains("NOT CONVERGED"), "{err}");
        assert!(!err.contains(": CONVERGED"), "{err}");
        let md = std::fs::read_to_string(out.join("calibration.md")).expect("calibration.md");
        assert!(
            md.contains("**NOT CONVERGED") && md.contains("Not an optimum inside the box"),
            "{md}"
        );
        // Each calibration is kept under its own label.
        let label = c["label"].as_str().expect("label");
        assert!(label.starts_with("ego-seeds1_2-"), "{label}");
        let kept = out.join("calibrations").join(label);
        assert_eq!(
            calibration_json(&kept)["label"],
            label,
            "{}",
            kept.display()
        );
    }
    // The two calibrations (other settings) sit side by side: neither overwrote the other.
    let index = std::fs::read_to_string(out.join("calibrations/index.csv")).expect("index.csv");
    let rows: Vec<&str> = index.lines().skip(1).collect();
    assert_eq!(rows.len(), 2, "{index}");
    assert!(
        rows.iter()
            .all(|r| r.starts_with("ego-seeds1_2-") && r.contains(",false,1,")),
        "{index}"
    );
    // Asked again under the other width: the stored grid is measured from its kept states, not
    // simulated, and the answer sits beside the others under a label of its own.
    let o = bin()
        .arg("calibrate")
        .arg(edge_study(&dir, ""))
        .arg("--out")
        .arg(&out)
        .args([
            "--threads",
            "2",
            "--no-extend",
            "--set",
            "analysis.width=side",
        ])
        .output()
        .expect("runs");
    assert_ok(&o);
    let err = stderr(&o);
    assert!(
        err.contains("grid: runs: 3 total, 0 cached, 0 ran, 3 measured from kept states"),
        "{err}"
    );
    let c = calibration_json(&out);
    assert_ne!(
        c["label"],
        calibration_json(
            &out.join("calibrations")
                .join(rows[0].split(',').next().expect("label"))
        )["label"]
    );
    let index = std::fs::read_to_string(out.join("calibrations/index.csv")).expect("index.csv");
    assert_eq!(index.lines().skip(1).count(), 3, "{index}");
}

#[test]
fn validity_map_draws_f_with_the_cutoff_contour_and_exports_the_boundary() {
    let dir = scratch("validity");
    let study = write_study(
        &dir,
        "vm",
        "[[axes]]\nkey = \"scene.v0_m_s\"\nrange = { from = 3000, to = 9000, count = 3 }\n\n[[axes]]\nkey = \"scene.t_over_d\"\nvalues = [0.3, 0.5]\n",
        TINY,
    );
    let out = dir.join("out");
    let o = bin()
        .arg("validity-map")
        .arg(&study)
        .arg("--out")
        .arg(&out)
        .args(["--threads", "2", "--cutoff", "0.3"])
        .output()
        .expect("runs");
    assert_ok(&o);
    for f in [
        "validity_map.png",
        "validity_map.svg",
        "snapshots.png",
        "validity_boundary.csv",
        "results.csv",
    ] {
        assert!(out.join(f).exists(), "{f} missing:\n{}", stderr(&o));
    }
    let boundary = std::fs::read_to_string(out.join("validity_boundary.csv")).expect("csv");
    assert!(boundary.starts_with("polyline,point,scene.v0_m_s,scene.t_over_d\n"));
    let rows = results(&out);
    assert_eq!(rows.len(), 6);
    let mut measured = 0;
    for r in &rows {
        // A run with no cloud yet (slow impact, thick plate, 2 us) has no F and no verdict.
        match r["fragmentation"].as_f64() {
            Some(f) => {
                measured += 1;
                assert_eq!(r["valid"].as_bool(), Some(f >= 0.3), "{r}");
            }
            None => assert!(r["valid"].is_null(), "{r}"),
        }
    }
    assert!(measured >= 4, "{rows:?}");
    let png = std::fs::read(out.join("validity_map.png")).expect("png");
    assert_eq!(&png[1..4], b"PNG");
    check_onset(&out, &[0.3, 0.5]);
    let o = bin()
        .arg("validity-map")
        .arg(&study)
        .arg("--out")
        .arg(&out)
        .args(["--onset-threshold", "1.5"])
        .output()
        .expect("runs");
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("validity.onset.threshold"),
        "{}",
        stderr(&o)
    );
    let o = bin()
        .arg("validity-map")
        .arg(&study)
        .arg("--out")
        .arg(&out)
        .args(["--cutoff", "nan"])
        .output()
        .expect("runs");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

/// The onset's files: one row per t/D with both relations and the model's bracket, and the
/// bracket held by the runs: the seeds' mean intact fraction at its low end is at or above
/// the threshold, at its high end below, and the two ends are within the tolerance.
fn check_onset(out: &Path, ts: &[f64]) {
    let csv = std::fs::read_to_string(out.join("onset.csv")).expect("onset.csv");
    let header = csv.lines().next().expect("header");
    for col in [
        "t_over_d",
        "onset_model_m_s",
        "onset_model_lo_m_s",
        "onset_model_hi_m_s",
        "onset_piekutowski_2003_m_s",
        "onset_reimerdes_2006_m_s",
        "agreement_reimerdes_2006",
        "cutoff_line_m_s",
    ] {
        assert!(
            header.split(',').any(|c| c == col),
            "{col} missing: {header}"
        );
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("onset.json")).expect("json"))
            .expect("onset.json");
    let threshold = json["config"]["threshold"].as_f64().expect("threshold");
    let tolerance = json["config"]["tolerance_m_s"].as_f64().expect("tolerance");
    let rows = json["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), ts.len());
    for (row, &t) in rows.iter().zip(ts) {
        assert_eq!(row["t_over_d"].as_f64(), Some(t));
        let runs: Vec<(f64, f64)> = row["runs"]
            .as_array()
            .expect("runs")
            .iter()
            .map(|r| (num(&r[0]), num(&r[1])))
            .collect();
        let at = |v: f64| runs.iter().find(|r| r.0 == v).expect("a run at the end").1;
        let m = &row["model"];
        match m["kind"].as_str() {
            Some("between") => {
                let (lo, hi) = (num(&m["lo"]), num(&m["hi"]));
                assert!(lo < hi && hi - lo <= tolerance, "{m}");
                assert!(at(lo) >= threshold && at(hi) < threshold, "{row}");
            }
            Some("above") => assert!(runs.iter().all(|r| r.1 >= threshold), "{row}"),
            Some("below") => assert!(at(num(&m["v"])) < threshold, "{row}"),
            k => panic!("kind {k:?}"),
        }
        assert_eq!(row["experiments"].as_array().map(Vec::len), Some(2));
    }
}

#[test]
fn a_damaged_or_edited_record_is_moved_aside_and_run_again() {
    let dir = scratch("damaged");
    let study = write_study(&dir, "damaged", GRID_2X2, TINY);
    let out = dir.join("out");
    assert_ok(&sweep(&study, &out, &[]));
    let fresh = results(&out);
    let recs = records(&out);
    assert_eq!(recs.len(), 4);
    // One record truncated, one with a number edited (still valid JSON), one removed.
    let rec = |i: usize| out.join("runs").join(&recs[i].0).join("record.json");
    let text = std::fs::read_to_string(rec(0)).expect("record");
    std::fs::write(rec(0), &text[..text.len() / 2]).expect("truncate");
    let edited = std::fs::read_to_string(rec(1)).expect("record").replacen(
        "\"wall_seconds\": ",
        "\"wall_seconds\": 1",
        1,
    );
    std::fs::write(rec(1), edited).expect("edit");
    std::fs::remove_file(rec(2)).expect("remove");

    // A read-only look names the damage and changes nothing.
    let o = bin().args(["reanalyse"]).arg(&out).output().expect("runs");
    assert!(!o.status.success());
    assert!(stderr(&o).contains("damaged run"), "{}", stderr(&o));

    let again = sweep(&study, &out, &[]);
    assert_ok(&again);
    assert_eq!(counts(&again), (4, 1, 3, 0), "{}", stderr(&again));
    let err = stderr(&again);
    for why in ["not a run record", "checksum mismatch", "no record.json"] {
        assert!(err.contains(why), "{why}: {err}");
    }
    let aside: Vec<String> = std::fs::read_dir(out.join("runs"))
        .expect("runs")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("damaged-"))
        .collect();
    assert_eq!(aside.len(), 3, "kept for inspection: {aside:?}");
    // The study is whole again, with the same numbers (the engine is deterministic).
    let strip = |rows: Vec<serde_json::Value>| -> Vec<serde_json::Value> {
        rows.into_iter()
            .map(|mut r| {
                r.as_object_mut().map(|o| o.remove("wall_seconds"));
                r
            })
            .collect()
    };
    assert_eq!(strip(results(&out)), strip(fresh));
    let live = records(&out)
        .into_iter()
        .filter(|(n, ..)| !n.starts_with("damaged-"))
        .count();
    assert_eq!(live, 4);
    let third = sweep(&study, &out, &[]);
    assert_eq!(counts(&third), (4, 4, 0, 0), "{}", stderr(&third));
}

#[test]
fn concurrent_processes_on_one_study_do_each_run_once() {
    let dir = scratch("concurrent");
    let study = write_study(&dir, "concurrent", GRID_2X2, TINY);
    let out = dir.join("out");
    // Two sweeps at once (the second given another seed would plan over the first's plan):
    // the second waits for the first, then reuses its runs.
    let spawn = || {
        bin()
            .arg("sweep")
            .arg(&study)
            .arg("--out")
            .arg(&out)
            .args(["--threads", "1"])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("starts")
    };
    let (a, b) = (spawn(), spawn());
    let (a, b) = (
        a.wait_with_output().expect("a"),
        b.wait_with_output().expect("b"),
    );
    assert_ok(&a);
    assert_ok(&b);
    let (ca, cb) = (counts(&a), counts(&b));
    assert_eq!(ca.2 + cb.2, 4, "each run once: {ca:?} {cb:?}");
    let waited = format!("{}{}", stderr(&a), stderr(&b));
    assert!(
        waited.contains("is working in this study directory; waiting"),
        "{waited}"
    );

    // Two Slurm-like tasks of the same run at once: one computes it, the other waits for it
    // and keeps its result.
    let plan = out.join("plan.json");
    std::fs::remove_dir_all(out.join("runs")).expect("fresh store");
    let unit = || {
        bin()
            .args(["run-unit"])
            .arg(&plan)
            .args(["1", "--threads", "1"])
            .stderr(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .expect("starts")
    };
    let (a, b) = (unit(), unit());
    let (a, b) = (
        a.wait_with_output().expect("a"),
        b.wait_with_output().expect("b"),
    );
    assert_ok(&a);
    assert_ok(&b);
    let both = format!("{}{}", stderr(&a), stderr(&b));
    assert!(
        both.contains("done by another process meanwhile") || both.contains("already done"),
        "{both}"
    );
    let runs: Vec<_> = std::fs::read_dir(out.join("runs"))
        .expect("runs")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with('.'))
        .collect();
    assert_eq!(runs.len(), 1, "{runs:?}");
}

/// Starts a sweep, waits for `finished` records beyond those already there, and sends `signal`
/// (`INT` or `TERM`); returns the exit code and stderr.
fn interrupt_sweep(
    study: &Path,
    out: &Path,
    signal: &str,
    finished: usize,
) -> (Option<i32>, String) {
    let before = records(out).len();
    let mut child = bin()
        .arg("sweep")
        .arg(study)
        .arg("--out")
        .arg(out)
        .args(["--threads", "1", "--quiet"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawns");
    let t0 = Instant::now();
    while records(out).len() < before + finished {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "no run finished in 2 min"
        );
        if let Some(status) = child.try_wait().expect("wait") {
            panic!("the study ended before it could be interrupted: {status}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let kill = std::process::Command::new("kill")
        .arg(format!("-{signal}"))
        .arg(child.id().to_string())
        .status()
        .expect("kill runs");
    assert!(kill.success());
    let o = child.wait_with_output().expect("reaped");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Temporary and set-aside directories in a store (the runs' lock files stay by design).
fn leftovers(out: &Path) -> Vec<String> {
    std::fs::read_dir(out.join("runs"))
        .expect("runs")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".tmp-") || n.starts_with(".old-"))
        .collect()
}

#[test]
fn ctrl_c_and_sigterm_stop_a_study_cleanly_and_it_resumes() {
    let dir = scratch("interrupt");
    let study = write_study(
        &dir,
        "interrupt",
        "[[axes]]\nkey = \"run.seed\"\nvalues = [1, 2, 3, 4, 5, 6]\n",
        "\"resolution.particles=1500\", \"run.end_time_s=6e-6\"",
    );
    let out = dir.join("out");
    // Ctrl-C after the first run: the run in progress stops and leaves nothing, the tables of
    // what finished are written, exit 130 with how to resume.
    let (code, err) = interrupt_sweep(&study, &out, "INT", 1);
    assert_eq!(code, Some(130), "{err}");
    assert!(err.contains("interrupted by SIGINT"), "{err}");
    assert!(
        err.contains("run the same command again to resume"),
        "{err}"
    );
    assert!(leftovers(&out).is_empty(), "{:?}", leftovers(&out));
    let first = records(&out);
    assert!(!first.is_empty() && first.len() < 6, "{}", first.len());
    let done = |out: &Path| {
        results(out)
            .iter()
            .filter(|r| r["status"] == "completed")
            .count()
    };
    assert_eq!(
        done(&out),
        first.len(),
        "results.csv holds the finished runs"
    );
    // SIGTERM (a scheduler's stop) after one more: exit 143, the same guarantees.
    let (code, err) = interrupt_sweep(&study, &out, "TERM", 1);
    assert_eq!(code, Some(143), "{err}");
    assert!(err.contains("interrupted by SIGTERM"), "{err}");
    assert!(leftovers(&out).is_empty(), "{:?}", leftovers(&out));
    let second = records(&out);
    assert!(
        second.len() > first.len() && second.len() < 6,
        "{}",
        second.len()
    );
    for s in &first {
        assert!(second.contains(s), "run {} was redone or changed", s.0);
    }
    // Resumed: the finished runs come from the store, the rest run once.
    let o = sweep(&study, &out, &[]);
    assert_ok(&o);
    let (total, cached, ran, failed) = counts(&o);
    assert_eq!((total, failed), (6, 0), "{}", stderr(&o));
    assert_eq!(
        (cached, ran),
        (second.len(), 6 - second.len()),
        "{}",
        stderr(&o)
    );
    assert_eq!(done(&out), 6);
}

#[test]
fn a_full_disk_gives_an_error_naming_the_file_and_leaves_a_consistent_store() {
    // A 700 kB tmpfs holds one tiny run with its pictures, not two. Mounting needs root; where
    // it cannot be mounted the test says so and skips.
    let dir = scratch("full");
    let disk = dir.join("disk");
    std::fs::create_dir_all(&disk).expect("dir");
    let mounted = std::process::Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=700k", "tmpfs"])
        .arg(&disk)
        .status()
        .is_ok_and(|s| s.success());
    if !mounted {
        eprintln!("skipped: cannot mount a tmpfs here (needs root)");
        return;
    }
    let study = write_study(
        &dir,
        "full",
        "[[axes]]\nkey = \"run.seed\"\nvalues = [1, 2, 3, 4]\n",
        TINY,
    );
    let out = disk.join("out");
    let o = sweep(&study, &out, &["--jobs", "1", "--quiet"]);
    // Completed runs (a run the full disk stopped mid-way may be recorded as failed; it runs
    // again on resume, as any failed run does).
    let kept: Vec<_> = records(&out)
        .into_iter()
        .filter(|r| String::from_utf8_lossy(&r.1).contains("\"status\": \"completed\""))
        .collect();
    let left = if out.join("runs").exists() {
        leftovers(&out)
    } else {
        vec!["no runs/".into()]
    };
    // Move the store to a disk with room before unmounting, then resume there.
    let moved = dir.join("moved");
    let copy = std::process::Command::new("cp")
        .arg("-a")
        .arg(&out)
        .arg(&moved)
        .status();
    let _ = std::process::Command::new("umount").arg(&disk).status();
    assert_eq!(
        o.status.code(),
        Some(74),
        "an output that cannot be written exits 74 (EX_IOERR): {}",
        stderr(&o)
    );
    let err = stderr(&o);
    assert!(err.contains("No space left on device"), "{err}");
    assert!(
        err.contains(&format!("cannot write {}", out.join("runs").display())),
        "{err}"
    );
    assert!(left.is_empty(), "half-written directories left: {left:?}");
    assert!(!kept.is_empty() && kept.len() < 4, "{}", kept.len());
    assert!(copy.is_ok_and(|s| s.success()));
    let o = sweep(&study, &moved, &[]);
    assert_ok(&o);
    let (total, cached, ran, failed) = counts(&o);
    assert_eq!(
        (total, cached, ran, failed),
        (4, kept.len(), 4 - kept.len(), 0),
        "{}",
        stderr(&o)
    );
}

/// `hvi-study calibrate STUDY --out OUT --threads 2` with `extra` flags.
fn calibrate_with(study: &Path, out: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("calibrate")
        .arg(study)
        .arg("--out")
        .arg(out)
        .args(["--threads", "2"])
        .args(extra)
        .output()
        .expect("runs")
}

fn num(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn a_resolution_ladder_steers_each_level_by_the_last_and_resumes_without_running_anything() {
    let dir = scratch("calibrate-ladder");
    let study = edge_study(&dir, "");
    let out = dir.join("ladder");
    let flags = ["--ladder", "1000,2000,3000", "--ladder-check", "4000"];
    let o = calibrate_with(&study, &out, &flags);
    assert_ok(&o);
    let read = || -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join("ladder.json")).expect("ladder"))
            .expect("json")
    };
    let l = read();
    let levels = l["levels"].as_array().expect("levels");
    assert_eq!(levels.len(), 3);
    for (lv, n) in levels.iter().zip([1000, 2000, 3000]) {
        assert_eq!(num(&lv["particles"]), f64::from(n));
        let c = calibration_json(&out.join(format!("n{n}")));
        assert_eq!(c["best"]["params"], lv["best"], "level {n}");
        assert!(num(&lv["runs"]) > 0.0);
        // The level's points that meet every target, counted again here: each term within
        // its tolerance, over the distinct points scored at the answer's seeds.
        let met = &lv["targets_met"];
        assert_eq!(met, &c["targets_met"], "level {n}");
        let seeds = &c["best"]["seeds"];
        let mut scored: Vec<&serde_json::Value> = Vec::new();
        for e in c["refinement"]
            .as_array()
            .expect("refinement")
            .iter()
            .chain([&c["paper"]])
        {
            if &e["seeds"] == seeds
                && !e["score"].is_null()
                && !scored.iter().any(|p| p["params"] == e["params"])
            {
                scored.push(e);
            }
        }
        let meeting: Vec<&&serde_json::Value> = scored
            .iter()
            .filter(|e| {
                e["score"]["terms"]
                    .as_array()
                    .expect("terms")
                    .iter()
                    .all(|t| num(&t["term"]) <= 1.0)
            })
            .collect();
        assert_eq!(
            num(&met["scored"]) as usize,
            scored.len(),
            "level {n}: {met}"
        );
        assert_eq!(
            num(&met["points"]) as usize,
            meeting.len(),
            "level {n}: {met}"
        );
        if let Some(e) = meeting.first() {
            let v = num(&e["params"]["material.eps_j"]);
            let span = &met["spans"]["material.eps_j"];
            assert!(num(&span[0]) <= v && v <= num(&span[1]), "level {n}: {met}");
        }
    }
    for f in ["ladder.md", "ladder.png"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let eps = |lv: &serde_json::Value, what: &str| -> (f64, f64) {
        let v = &lv[what]["material.eps_j"];
        (num(&v[0]).log10(), num(&v[1]).log10())
    };
    // Level 2's first box: level 1's interval (with its answer), padded, at least half a
    // decade wide, two values (the default).
    assert_eq!(levels[0]["steered_by"], "the study's grid");
    let (lo1, hi1) = eps(&levels[0], "intervals");
    let (b_lo, b_hi) = eps(&levels[1], "first_box");
    let best1 = num(&levels[0]["best"]["material.eps_j"]).log10();
    let (lo1, hi1) = (lo1.min(best1), hi1.max(best1));
    assert!(b_lo <= lo1 + 0.01 && b_hi >= hi1 - 0.01, "{l}");
    assert!(b_hi - b_lo >= 0.49, "{l}");
    let plan: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("n2000/plan.json")).expect("plan"))
            .expect("plan json");
    assert_eq!(
        plan["axes"][0]["values"].as_array().expect("values").len(),
        2
    );
    // Each level after the first searched the difference from the level before: its
    // calibration records the prior, fitted to that level's scored points.
    assert!(calibration_json(&out.join("n1000"))["prior"].is_null());
    for (k, n) in [(1, 2000), (2, 3000)] {
        let c = calibration_json(&out.join(format!("n{n}")));
        let prior = &c["prior"];
        assert_eq!(
            num(&prior["particles"]),
            num(&levels[k - 1]["particles"]),
            "{c}"
        );
        let below = calibration_json(&out.join(format!("n{}", [1000, 2000][k - 1])));
        let scored = below["refinement"]
            .as_array()
            .expect("refinement")
            .iter()
            .filter(|e| e["objective"].as_f64().is_some_and(f64::is_finite))
            .count();
        assert!(num(&prior["points"]) >= scored as f64, "{prior}");
        let rho = num(&prior["weight"]);
        assert!((0.0..=2.0).contains(&rho), "{prior}");
        let words = levels[k]["steered_by"].as_str().expect("words");
        assert!(words.contains("difference from"), "{words}");
        // The level below's answer ran here too, at the search's seeds.
        let below_best = &levels[k - 1]["best"]["material.eps_j"];
        assert!(
            c["refinement"]
                .as_array()
                .expect("refinement")
                .iter()
                .any(|e| &e["params"]["material.eps_j"] == below_best
                    && e["seeds"] == serde_json::json!([1, 2])),
            "{c}"
        );
    }
    assert!(levels[2]["steered_by"]
        .as_str()
        .expect("words")
        .contains("itself on the levels below"));
    // Level 3's box holds level 2's interval and that interval moved by the trend of levels
    // 1 and 2, when both answers are inside their boxes on eps (an answer on a side gives no
    // trend).
    let (best1, best2) = (
        num(&levels[0]["best"]["material.eps_j"]).log10(),
        num(&levels[1]["best"]["material.eps_j"]).log10(),
    );
    let on_eps_side = |lv: &serde_json::Value| {
        lv["edges"]
            .as_array()
            .expect("edges")
            .iter()
            .any(|e| e["key"] == "material.eps_j")
    };
    let trended = !on_eps_side(&levels[0]) && !on_eps_side(&levels[1]);
    let shift = if trended {
        (best2 - best1) / 2f64.log10() * 1.5f64.log10()
    } else {
        0.0
    };
    let (lo2, hi2) = eps(&levels[1], "intervals");
    let (lo2, hi2) = (lo2.min(best2), hi2.max(best2));
    let (c_lo, c_hi) = eps(&levels[2], "first_box");
    let (want_lo, want_hi) = (lo2.min(lo2 + shift), hi2.max(hi2 + shift));
    assert!(
        c_lo <= want_lo + 0.01 && c_hi >= want_hi - 0.01,
        "box [{c_lo}, {c_hi}] against the interval [{lo2}, {hi2}] and the trend {shift}: {l}"
    );
    // Padded by a quarter of the width on each side (or to half a decade).
    let w = want_hi - want_lo;
    let pad = (0.25 * w).max(0.5 * (0.5 - w));
    assert!(
        (c_lo - (want_lo - pad)).abs() < 0.01 && (c_hi - (want_hi + pad)).abs() < 0.01,
        "box [{c_lo}, {c_hi}], want [{}, {}]: {l}",
        want_lo - pad,
        want_hi + pad
    );
    let words = levels[2]["steered_by"].as_str().expect("words");
    if shift.abs() > 1e-9 {
        assert!(words.contains("widened along the trend"), "{l}");
    }
    if !trended {
        assert!(words.contains("no trend on material.eps_j"), "{l}");
    }
    // The verdict is the rule applied to the last two levels.
    let overlap = {
        let (a, b) = (eps(&levels[1], "intervals"), eps(&levels[2], "intervals"));
        a.0 <= b.1 && b.0 <= a.1
    };
    let interior = levels[1..]
        .iter()
        .all(|lv| lv["edges"].as_array().is_some_and(Vec::is_empty));
    assert_eq!(l["converged_in_n"], overlap && interior, "{l}");
    let verdict = l["verdict"].as_str().expect("verdict");
    assert_eq!(verdict.starts_with("CONVERGED IN N"), overlap && interior);
    // The region to carry: the overlap of the last two levels' spans of the points that meet
    // every target, recomputed here from the levels' own counts.
    let span = |lv: &serde_json::Value| -> Option<(f64, f64)> {
        let m = &lv["targets_met"];
        (num(&m["points"]) > 0.0).then_some(())?;
        let s = m["spans"].get("material.eps_j")?;
        Some((num(&s[0]), num(&s[1])))
    };
    let want = match (span(&levels[1]), span(&levels[2])) {
        (Some(a), Some(b)) if a.0.max(b.0) <= a.1.min(b.1) => {
            serde_json::json!({"material.eps_j": [a.0.max(b.0), a.1.min(b.1)]})
        }
        _ => serde_json::Value::Null,
    };
    assert_eq!(l["targets_met_in_n"], want, "{l}");
    assert_eq!(
        verdict.contains("The region to carry across resolutions"),
        !want.is_null(),
        "{verdict}"
    );
    let trend = (num(&levels[2]["best"]["material.eps_j"]).log10() - best2) / 1.5f64.log10();
    assert!(
        (num(&l["trend_per_decade"]["material.eps_j"]) - trend).abs() < 1e-9,
        "{l}"
    );
    // The check ran the last answer at 4000 particles at both seeds.
    let check = &l["check"];
    assert_eq!(num(&check["particles"]), 4000.0);
    assert_eq!(check["params"], levels[2]["best"]);
    assert!(num(&check["objective"]).is_finite());
    assert_eq!(num(&check["runs"]), 2.0);

    // Again: every level from its store, nothing run, the same answers.
    let o = calibrate_with(&study, &out, &flags);
    assert_ok(&o);
    let again = read();
    for (a, b) in levels
        .iter()
        .zip(again["levels"].as_array().expect("levels"))
    {
        assert_eq!(num(&b["runs_made"]), 0.0, "{b}");
        for k in [
            "best",
            "intervals",
            "first_box",
            "objective",
            "runs",
            "verdict",
        ] {
            assert_eq!(a[k], b[k], "{k}");
        }
    }
    assert_eq!(l["verdict"], again["verdict"]);
    assert_eq!(l["check"], again["check"]);
}

#[test]
fn a_ladder_refuses_counts_it_cannot_climb_naming_the_flag() {
    let dir = scratch("calibrate-ladder-refusals");
    let study = edge_study(&dir, "");
    let out = dir.join("out");
    for (flags, says) in [
        (vec!["--ladder", "2000"], "--ladder"),
        (vec!["--ladder", "2000,1000"], "ascending"),
        (
            vec!["--ladder", "1000,2000", "--ladder-check", "1500"],
            "--ladder-check",
        ),
        (vec!["--ladder-check", "4000"], "--ladder"),
        (
            vec!["--ladder", "1000,2000", "--particles", "500"],
            "--particles",
        ),
        (
            vec!["--ladder", "1000,2000", "--method", "nelder-mead"],
            "ego",
        ),
    ] {
        let o = calibrate_with(&study, &out, &flags);
        assert!(!o.status.success(), "{flags:?} was accepted");
        assert!(stderr(&o).contains(says), "{flags:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    }
    assert!(!out.join("n1000").exists(), "nothing was run");
}

/// `calibrate.seeds_within_decades` must be a number above zero (or inf): anything else is
/// refused before a run, naming the key and what it allows.
#[test]
fn a_seed_cut_off_that_is_not_above_zero_is_refused_naming_the_key() {
    for value in ["0", "-1", "nan"] {
        let dir = scratch(&format!("calibrate-seed-cutoff-{value}"));
        let study = edge_study(&dir, &format!("seeds_within_decades = {value}\n"));
        let out = dir.join("out");
        let o = calibrate(&study, &out);
        assert!(!o.status.success(), "{value} was accepted");
        let err = stderr(&o);
        assert!(
            err.contains("calibrate.seeds_within_decades") && err.contains("allowed: a number > 0"),
            "{value}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            !out.join("calibration.json").exists(),
            "nothing was written"
        );
    }
}

/// A study of the calibration grid over eps at 400 particles (the scene's other keys at the
/// paper's fit), scored against `shots` (paths relative to the study file's directory).
fn shots_study(dir: &Path, scene: &str, shots: &[PathBuf], extra: &str) -> PathBuf {
    let list = shots
        .iter()
        .map(|p| format!("\"{}\"", p.display()))
        .collect::<Vec<_>>()
        .join(", ");
    let text = format!(
        "[study]\nname = \"shots\"\nscene = \"{}\"\n\n[[axes]]\nkey = \"material.eps_j\"\nvalues = [0.01, 0.1]\n\n[tiers.quick]\nset = [\"resolution.particles=400\"]\n\n[calibrate]\nshots = [{list}]\nseeds = [1, 2]\nbatch = 1\nmax_batches = 1\nmax_extensions = 0\n{extra}",
        repo().join(scene).display()
    );
    let path = dir.join("shots.toml");
    std::fs::write(&path, text).expect("study");
    path
}

#[test]
fn a_calibration_whose_scene_disagrees_with_its_shot_is_refused_naming_both_values() {
    let dir = scratch("shot-disagrees");
    // The paper's calibration scene (6.7 km/s, t/D 0.425, D 9.53 mm, 32 us) against a shot at
    // 5 km/s, t/D 0.2, D 6.35 mm, observed at 20 us.
    let synthetic = repo().join("experiments_data/examples/synthetic-al-5kms.toml");
    let study = shots_study(&dir, "studies/scenes/calibration.toml", &[synthetic], "");
    let out = dir.join("out");
    let o = calibrate(&study, &out);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    for needle in [
        "shot `synthetic-al-5kms`",
        "scene.v0_m_s = 6700 m/s (the scene file",
        "the shot's v0 = 5000 m/s",
        "scene.t_over_d = 0.425 (",
        "the shot's t/D = 0.2",
        "scene.diameter_m = 9.53e-3 m",
        "run.end_time_s = 3.2e-5 s",
    ] {
        assert!(e.contains(needle), "`{needle}` missing from:\n{e}");
    }
    // Refused before anything ran.
    assert!(!out.join("runs").exists());
    // A --set that moves the paper's shot off its documented offset is refused the same way.
    let paper = repo().join("experiments_data/calibration-shot.toml");
    let study = shots_study(&dir, "studies/scenes/calibration.toml", &[paper], "");
    let o = calibrate_with(&study, &out, &["--set", "scene.v0_m_s=6500"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("scene.v0_m_s = 6500 m/s (--set), the shot's v0 = 6700 m/s"),
        "{}",
        stderr(&o)
    );
}

/// Behind a plate thicker than `calibrate.screen_max_t_over_d` (0.6) free flight from the
/// screen's time was measured to move va/v0 beyond the allowance: such a shot's runs go in
/// full, and the console says why even when it is the calibration's only shot.
#[test]
fn a_shot_behind_a_thick_plate_is_not_screened_and_the_console_says_so() {
    let dir = scratch("thick-shot");
    let synthetic =
        std::fs::read_to_string(repo().join("experiments_data/examples/synthetic-al-5kms.toml"))
            .expect("the synthetic shot");
    let thick = synthetic
        .replace("t_over_d = 0.2", "t_over_d = 1.0")
        .replace("id = \"synthetic-al-5kms\"", "id = \"synthetic-thick\"");
    assert_ne!(thick, synthetic, "the shot file changed");
    let shot = dir.join("thick.toml");
    std::fs::write(&shot, thick).expect("shot");
    let study = shots_study(&dir, "studies/scenes/shot.toml", &[shot], "");
    let out = dir.join("out");
    let o = calibrate(&study, &out);
    assert_ok(&o);
    let e = stderr(&o);
    assert!(
        e.contains("screen (shot 1): off, its plate (t/D = ")
            && e.contains("is thicker than calibrate.screen_max_t_over_d = 0.6"),
        "{e}"
    );
    let table = std::fs::read_to_string(out.join("evaluations.csv")).expect("evaluations.csv");
    let mut lines = table.lines();
    let col = lines
        .next()
        .expect("header")
        .split(',')
        .position(|h| h == "screened")
        .expect("a screened column");
    let rows: Vec<&str> = lines.collect();
    assert!(!rows.is_empty(), "no evaluations");
    for r in rows {
        let screened = r.split(',').nth(col);
        assert!(
            matches!(screened, Some("" | "0")),
            "a run was screened: {r}"
        );
    }
    // No run carries the screen's keys.
    let mut runs = 0;
    for entry in std::fs::read_dir(out.join("runs")).expect("the store") {
        let summary = entry.expect("entry").path().join("summary.json");
        let Ok(text) = std::fs::read_to_string(&summary) else {
            continue;
        };
        let v: serde_json::Value = serde_json::from_str(&text).expect("json");
        assert!(
            v["scene"]["run"]["screen_after_s"].is_null(),
            "{}: screened",
            summary.display()
        );
        runs += 1;
    }
    assert!(runs > 0, "no runs in the store");
}

#[test]
fn a_two_shot_calibration_scores_each_shot_at_its_impact_and_predicts_a_held_out_one() {
    let dir = scratch("two-shots");
    let paper = repo().join("experiments_data/calibration-shot.toml");
    let synthetic = repo().join("experiments_data/examples/synthetic-al-5kms.toml");
    // The shots' scene gives no impact: each shot sets its own.
    let study = shots_study(&dir, "studies/scenes/shot.toml", &[paper, synthetic], "");
    let out = dir.join("out");
    let o = calibrate(&study, &out);
    assert_ok(&o);
    // At 400 particles the synthetic shot's plate (t/D 0.2) is thinner than 3 layers, and no
    // particle is well below the paper's shot's 1 mm fragments: both said, with their numbers.
    let e = stderr(&o);
    assert!(
        e.contains("warning: shot synthetic-al-5kms: scene.t_over_d = 0.2 gives a plate of 1 particle layer"),
        "{e}"
    );
    assert!(
        e.contains("warning: shot emi-calibration-shot: target `fragment_size` measures fragments of 1 mm, and one particle is already"),
        "{e}"
    );
    let c = calibration_json(&out);
    let ids: Vec<&str> = c["shots"]
        .as_array()
        .expect("shots")
        .iter()
        .map(|s| s["id"].as_str().expect("id"))
        .collect();
    assert_eq!(ids, ["emi-calibration-shot", "synthetic-al-5kms"]);
    assert_eq!(c["shots"][1]["synthetic"], true);
    // Every shot's terms, named by shot; J is the mean of the shots' own J.
    let terms = c["best"]["score"]["terms"].as_array().expect("terms");
    let names: Vec<&str> = terms
        .iter()
        .map(|t| t["name"].as_str().expect("name"))
        .collect();
    assert_eq!(
        names,
        [
            "emi-calibration-shot:length_ratio",
            "emi-calibration-shot:no_large_fragment",
            "emi-calibration-shot:fragment_size",
            "synthetic-al-5kms:length_ratio",
            "synthetic-al-5kms:no_large_fragment",
        ]
    );
    let (sum, w) = terms.iter().fold((0.0, 0.0), |(s, w), t| {
        (
            s + num(&t["weight"]) * num(&t["term"]),
            w + num(&t["weight"]),
        )
    });
    assert!((sum / w - num(&c["best"]["score"]["objective"])).abs() < 1e-9);
    assert!((w - 1.0).abs() < 1e-9, "weights sum to 1: {w}");
    // Each shot ran at its own impact: the grid's runs of the second shot are at 5 km/s.
    let table = std::fs::read_to_string(out.join("results-synthetic-al-5kms.csv"))
        .expect("the second shot's table");
    assert_eq!(table.lines().count(), 3, "{table}");
    let scene = |dir: &str| -> serde_json::Value {
        let s: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join(dir).join("summary.json")).expect("summary"),
        )
        .expect("json");
        s["scene"].clone()
    };
    let first = scene(c["best_grid"]["dir"].as_str().expect("dir"));
    assert_eq!(num(&first["scene"]["v0_m_s"]), 6700.0);
    assert_eq!(num(&first["scene"]["t_over_d"]), 0.425);
    let header: Vec<&str> = table.lines().next().expect("header").split(',').collect();
    let col = header.iter().position(|h| *h == "dir").expect("dir column");
    let row: Vec<&str> = table.lines().nth(1).expect("row").split(',').collect();
    let second = scene(row[col]);
    assert_eq!(num(&second["scene"]["v0_m_s"]), 5000.0);
    assert_eq!(num(&second["scene"]["t_over_d"]), 0.2);
    assert_eq!(num(&second["scene"]["diameter_m"]), 6.35e-3);
    assert_eq!(num(&second["run"]["end_time_s"]), 20e-6);
    let report = std::fs::read_to_string(out.join("calibration.md")).expect("md");
    assert!(report.contains("its J at the best point"), "{report}");
    assert!(report.contains("SYNTHETIC"), "{report}");

    // Held out: calibrated on the paper's shot alone, the synthetic one predicted at the answer.
    let o = calibrate_with(&study, &out, &["--hold-out", "synthetic-al-5kms"]);
    assert_ok(&o);
    let c = calibration_json(&out);
    assert_eq!(c["shots"].as_array().expect("shots").len(), 1);
    let h = &c["held_out"];
    assert_eq!(h["shot"]["id"], "synthetic-al-5kms");
    assert_eq!(h["evaluation"]["seeds"], serde_json::json!([1, 2]));
    assert_eq!(h["evaluation"]["params"], c["best"]["params"]);
    let spread = h["spread"].as_array().expect("spread");
    assert!(
        spread
            .iter()
            .any(|s| s["target"] == "length_ratio" && s["seeds"] == 2),
        "{spread:?}"
    );
    assert!(
        stderr(&o).contains("prediction:  length_ratio: predicted"),
        "{}",
        stderr(&o)
    );
    // A shot the study does not name is refused, naming those it does.
    let o = calibrate_with(&study, &out, &["--hold-out", "nope"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("synthetic-al-5kms"), "{}", stderr(&o));
    // A resolution ladder calibrates against both shots at each count.
    let ladder = dir.join("ladder");
    let o = calibrate_with(&study, &ladder, &["--ladder", "400,800"]);
    assert_ok(&o);
    for level in ["n400", "n800"] {
        let c = calibration_json(&ladder.join(level));
        assert_eq!(c["shots"].as_array().map(Vec::len), Some(2), "{level}");
    }
}

#[test]
fn a_calibration_whose_targets_bound_eps_from_above_only_reports_the_bound() {
    let dir = scratch("calibrate-bound");
    // R read cylindrically rises with eps (about 1.05 at 1e-4 J, 1.2 at 1e-3 J, 1.7 at 1e-2 J
    // at 2000 particles): R <= 1.3 holds everywhere below about 2e-3 J, so the target bounds
    // eps from above and not from below.
    let targets = dir.join("targets.toml");
    std::fs::write(
        &targets,
        "[shot]\nid = \"bound\"\ndescription = \"a test\"\nsource = \"a test\"\nimpactor_diameter_m = 9.53e-3\nimpactor_material = \"Al\"\nplate_material = \"Al\"\nv0_m_s = 6700.0\nt_over_d = 0.425\n\n[[targets]]\nname = \"length_ratio\"\nobservable = \"length_ratio\"\nkind = \"at_most\"\nvalue = 1.3\ntolerance = 0.1\nweight = 1.0\nsource = \"a test\"\n",
    )
    .expect("targets");
    let study = edge_study_with(&dir, &targets, "max_extensions = 4\n");
    let out = dir.join("out");
    let o = calibrate(&study, &out);
    assert_ok(&o);
    let c = calibration_json(&out);
    assert_eq!(c["bounded"], true, "{}", c["termination"]);
    assert_eq!(c["converged"], false);
    let eps = &c["identified"]["material.eps_j"];
    assert_eq!(eps["kind"], "at_most", "{eps}");
    let (high, floor) = (num(&eps["high"]), num(&eps["floor"]));
    assert!(high > 3e-4 && high < 5e-3, "{eps}");
    // The side stopped moving where the targets stopped telling points apart (met at the side
    // and a step inside), well before its 4 allowed steps.
    assert!(floor >= 0.99e-4, "{eps}");
    let e = stderr(&o);
    assert!(e.contains("BOUNDED (ego)"), "{e}");
    assert!(
        e.contains("material.eps_j <= ") && e.contains("not identified below the box's"),
        "{e}"
    );
}

/// `calibrate.tier_set`: calibrate adds the tier's settings to every run it makes (here free
/// flight from 20 us), says so, and `sweep` of the same study runs the tier without them; a
/// tier the study does not have is refused naming the key.
#[test]
fn calibrate_adds_its_tier_settings_and_sweep_does_not() {
    let dir = scratch("calibrate-tier-set");
    // Without the screen, which would send the runs far from the target on in free flight
    // from 5.6 transit times.
    let study = edge_study(
        &dir,
        "screen = false\n\n[calibrate.tier_set]\nquick = [\"run.free_flight_after_s=2e-5\"]\n",
    );
    let cutoffs = |out: &Path| -> Vec<Option<f64>> {
        summaries(out)
            .iter()
            .map(|s| s["ballistic_cutoff_tau_s"].as_f64())
            .collect()
    };
    let out = dir.join("calibrated");
    let o = calibrate_with(&study, &out, &["--no-refine"]);
    assert_ok(&o);
    assert!(
        stderr(&o).contains("calibrate sets at this tier")
            && stderr(&o).contains("run.free_flight_after_s=2e-5"),
        "{}",
        stderr(&o)
    );
    let c = cutoffs(&out);
    assert!(c.len() >= 3, "every grid point ran: {c:?}");
    for t in c {
        let t = t.expect("free flight began");
        assert!((2e-5..2.001e-5).contains(&t), "{t}");
    }
    let swept = dir.join("swept");
    assert_ok(&sweep(&study, &swept, &[]));
    assert!(cutoffs(&swept).iter().all(Option::is_none));

    let bad = edge_study(&dir, "\n[calibrate.tier_set]\nnope = [\"run.seed=3\"]\n");
    let o = calibrate_with(&bad, &dir.join("bad"), &["--no-refine"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("calibrate.tier_set.nope") && stderr(&o).contains("\"quick\""),
        "{}",
        stderr(&o)
    );
}

/// Every run's summary in a study directory's store.
fn summaries(out: &Path) -> Vec<serde_json::Value> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(out.join("runs")).expect("runs") {
        let run = e.expect("entry").path();
        if run.is_dir() && run.join("summary.json").is_file() {
            let text = std::fs::read_to_string(run.join("summary.json")).expect("summary");
            v.push(serde_json::from_str(&text).expect("json"));
        }
    }
    v
}

/// The `screened` column of evaluations.csv, by row.
fn screened_column(out: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(out.join("evaluations.csv")).expect("evaluations.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let k = header
        .iter()
        .position(|h| *h == "screened")
        .expect("a screened column");
    lines
        .map(|l| l.split(',').nth(k).unwrap_or("").to_string())
        .collect()
}

/// The screen (docs/calibration.md, "The screen"): by default every run the calibration makes
/// carries a window on R, the target's tolerance widened by 4 % of its value, and goes on in
/// free flight from 5.65 transit times D/v0 (8 us) exactly when what free flight gives lies
/// outside it; the answer's runs are full. Runs the store holds without a screen (a sweep's)
/// are taken as they are, `--no-refine` runs the grid in full, and `screen = false` runs
/// everything in full.
#[test]
fn calibrate_screens_the_runs_far_from_the_targets_and_reuses_full_ones() {
    let dir = scratch("calibrate-screen");
    let study = edge_study(&dir, "");
    let out = dir.join("screened");
    let o = calibrate(&study, &out);
    assert_ok(&o);
    assert!(stderr(&o).contains("screen (shot 1)"), "{}", stderr(&o));
    // The target: R = 1.2 within 0.1, one target, so the window is 1.2 -+ (0.1 + 0.048).
    let (lo, hi) = (1.2 - 0.148, 1.2 + 0.148);
    // At the later of 5.6 transit times D/v0 of the shot (9.53 mm at 6700 m/s) and 13.3 of
    // its plate (t/D = 0.425): the plate's, 5.65 D/v0.
    let after = (5.6f64).max(13.3 * 0.425) * 9.53e-3 / 6700.0;
    let (mut far, mut near) = (0, 0);
    for s in summaries(&out) {
        let t = s["scene"]["run"]["screen_after_s"]
            .as_f64()
            .expect("a time");
        assert!((t - after).abs() < 1e-12 * after, "{t} against {after}");
        let w = &s["scene"]["run"]["screen_length_ratio"];
        assert!((w[0].as_f64().expect("a number") - lo).abs() < 1e-9, "{w}");
        assert!((w[1].as_f64().expect("a number") - hi).abs() < 1e-9, "{w}");
        let screen = &s["screen"];
        let r = screen["length_ratio"].as_f64().expect("the probe's R");
        let outside = !(lo..=hi).contains(&r);
        assert_eq!(screen["free_flight"].as_bool(), Some(outside), "{screen}");
        let coasted = s["ballistic_cutoff_tau_s"].as_f64();
        if outside {
            far += 1;
            assert_eq!(coasted, screen["tau_s"].as_f64());
            // What free flight gave at the end, to round-off (the probe coasts in one step).
            let end = s["cloud"]["length_ratio"].as_f64().expect("R");
            assert!(
                (end - r).abs() <= 1e-12 * r,
                "{end} against the probe's {r}"
            );
        } else {
            near += 1;
            assert_eq!(coasted, None);
        }
    }
    assert!(far > 0 && near > 0, "{far} runs screened, {near} in full");
    let c = calibration_json(&out);
    let best_dir = c["best"]["dir"].as_str().expect("best dir");
    let best: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join(best_dir).join("summary.json")).expect("summary"),
    )
    .expect("json");
    assert_eq!(
        best["screen"]["free_flight"], false,
        "the answer's run is full"
    );
    let column = screened_column(&out);
    assert!(column.iter().any(|x| x == "1") && column.iter().any(|x| x == "0"));

    // A store that holds the grid in full: the calibration takes those runs as they are.
    let reused = dir.join("reused");
    assert_ok(&sweep(&study, &reused, &[]));
    let o = calibrate(&study, &reused);
    assert_ok(&o);
    let (total, cached, ..) = counts(&o);
    assert_eq!((total, cached), (3, 3), "{}", stderr(&o));
    let grid_rows = screened_column(&reused);
    assert!(grid_rows[..3].iter().all(String::is_empty), "{grid_rows:?}");

    // `--no-refine` runs the grid in full (the maps are the product): a sweep of the same
    // study then finds every run it plans finished (as `reproduce` reads Figs. 7, 9, 10).
    let grid = dir.join("grid");
    let o = calibrate_with(&study, &grid, &["--no-refine"]);
    assert_ok(&o);
    assert!(!stderr(&o).contains("screen (shot 1)"), "{}", stderr(&o));
    assert!(summaries(&grid).iter().all(|s| s.get("screen").is_none()));
    let o = sweep(&study, &grid, &[]);
    assert_ok(&o);
    let (total, cached, ..) = counts(&o);
    assert_eq!((total, cached), (3, 3), "{}", stderr(&o));

    let off = edge_study(&dir, "screen = false\n");
    let full = dir.join("full");
    assert_ok(&calibrate(&off, &full));
    assert!(summaries(&full).iter().all(|s| s.get("screen").is_none()));
    assert!(screened_column(&full).iter().all(String::is_empty));
}
