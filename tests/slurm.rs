//! Studies on a Slurm cluster (`hvi-study submit --slurm`, `status`, `collect`), end to end.
//!
//! The first test runs against a real single-node Slurm (slurmctld + slurmd + munged on
//! 127.0.0.1): the one `SLURM_CONF` names (`.ci/run` starts it with `.ci/slurm.sh`), or one this
//! test starts itself with `.ci/slurm.sh` (as root; the script installs Debian's packages when
//! missing) and stops afterwards. Where Slurm cannot be started it prints SKIP and passes,
//! except under `CI=true`, where it fails. The other tests need no Slurm: the job script of a
//! dry run, and the errors when sbatch is missing or refuses the job (through stand-in
//! commands on PATH).

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::common;
use common::{bin, repo};

fn scratch(name: &str) -> PathBuf {
    common::scratch("hvi-slurm", name)
}

/// A 2 x 2 study of tiny runs (400 particles, 2 us after first contact: a fraction of a second
/// each) over the default scene.
fn write_study(dir: &Path) -> PathBuf {
    let text = format!(
        "[study]\nname = \"tiny\"\nscene = \"{}\"\n\n\
         [[axes]]\nkey = \"material.eps_j\"\nvalues = [0.01, 0.1]\n\n\
         [[axes]]\nkey = \"material.kappa_n_m\"\nvalues = [2.28e6, 4.56e6]\n\n\
         [tiers.quick]\nset = [\"resolution.particles=400\", \"run.end_time_s=2e-6\"]\n",
        repo().join("studies/scenes/default.toml").display()
    );
    let path = dir.join("tiny.toml");
    std::fs::write(&path, text).expect("study file");
    path
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn ok(o: Output) -> Output {
    assert!(
        o.status.success(),
        "exit {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status,
        stdout(&o),
        stderr(&o)
    );
    o
}

fn hvi(args: &[&str], env: &[(&str, &Path)]) -> Output {
    let mut c = bin();
    c.args(args);
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("hvi-study runs")
}

/// results.json's rows.
fn results(dir: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(dir.join("results.json")).expect("results.json");
    serde_json::from_str(&text).expect("results.json parses")
}

/// The first line of `status`: (done, failed, running, pending).
fn status_counts(o: &Output) -> (usize, usize, usize, usize) {
    let out = stdout(o);
    let line = out.lines().next().unwrap_or_default().to_string();
    let count = |word: &str| -> usize {
        let before = line
            .split(&format!(" {word}"))
            .next()
            .unwrap_or_else(|| panic!("no `{word}` in {line}"));
        before
            .rsplit(|c: char| !c.is_ascii_digit())
            .next()
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("no count before `{word}` in {line}"))
    };
    (
        count("done"),
        count("failed"),
        count("running"),
        count("pending"),
    )
}

/// A run's files that must be bit-identical wherever it ran (summary.json also holds wall
/// times, so the observables are compared through the tables instead).
const DETERMINISTIC_FILES: [&str; 3] = ["energy.csv", "cloud_track.csv", "fragments.csv"];

/// Checks that a study directory's results equal the reference's: same runs (fingerprints),
/// all completed, every observable bit-equal, and the runs' deterministic files byte-equal.
fn assert_same_results(reference: &Path, dir: &Path) {
    let (a, b) = (results(reference), results(dir));
    assert_eq!(a.len(), b.len());
    for (ra, rb) in a.iter().zip(&b) {
        assert_eq!(rb["status"], "completed", "{rb}");
        for (k, va) in ra.as_object().expect("row") {
            if k == "wall_seconds" {
                continue;
            }
            // JSON numbers are written in their shortest round-trip form: equal text, equal
            // bits.
            assert_eq!(&rb[k], va, "run {}: `{k}` differs", ra["index"]);
        }
        let run = ra["dir"].as_str().expect("dir");
        for f in DETERMINISTIC_FILES {
            let fa = std::fs::read(reference.join(run).join(f)).expect("reference file");
            let fb = std::fs::read(dir.join(run).join(f)).expect("file");
            assert!(fa == fb, "{run}/{f} differs");
        }
    }
}

/// record.json of each completed run: (directory, bytes, modification time).
fn records(dir: &Path) -> Vec<(String, Vec<u8>, std::time::SystemTime)> {
    let mut v: Vec<_> = std::fs::read_dir(dir.join("runs"))
        .expect("runs")
        .filter_map(|e| e.ok())
        .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
        .filter_map(|e| {
            let p = e.path().join("record.json");
            let bytes = std::fs::read(&p).ok()?;
            let mtime = std::fs::metadata(&p).ok()?.modified().ok()?;
            Some((e.file_name().to_string_lossy().into_owned(), bytes, mtime))
        })
        .collect();
    v.sort();
    v
}

/// A Slurm to submit to, stopped on drop when this test started it.
struct Cluster {
    conf: PathBuf,
    started: Option<PathBuf>,
}

impl Drop for Cluster {
    fn drop(&mut self) {
        if let Some(dir) = &self.started {
            let _ = Command::new("bash")
                .arg(repo().join(".ci/slurm.sh"))
                .arg("stop")
                .arg(dir)
                .output();
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

/// Runs a command with its output captured, killed after `limit` (Slurm's clients retry for a
/// minute when they cannot reach a controller).
fn output_within(cmd: &mut Command, limit: Duration) -> Result<Output, String> {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("{cmd:?}: {e}"))?;
    let t0 = Instant::now();
    while child.try_wait().map_err(|e| e.to_string())?.is_none() {
        if t0.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("{cmd:?} did not answer within {limit:?}"));
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    child.wait_with_output().map_err(|e| e.to_string())
}

/// Whether the node of the cluster `conf` describes answers and is idle or working.
fn node_up(conf: &Path) -> Result<(), String> {
    if !conf.is_file() {
        return Err(format!("SLURM_CONF={} is not a file", conf.display()));
    }
    let o = output_within(
        Command::new("sinfo")
            .args(["-h", "-N", "-o", "%t"])
            .env("SLURM_CONF", conf),
        Duration::from_secs(15),
    )?;
    let state = stdout(&o);
    if o.status.success()
        && state
            .lines()
            .any(|s| matches!(s.trim(), "idle" | "mix" | "alloc"))
    {
        Ok(())
    } else {
        Err(format!(
            "sinfo with SLURM_CONF={}: {} {}",
            conf.display(),
            state.trim(),
            stderr(&o).trim()
        ))
    }
}

/// The cluster from SLURM_CONF, or one started here; Err says why there is none.
fn cluster() -> Result<Cluster, String> {
    if let Some(conf) = std::env::var_os("SLURM_CONF").map(PathBuf::from) {
        return node_up(&conf).map(|()| Cluster {
            conf,
            started: None,
        });
    }
    let dir = std::env::temp_dir().join(format!("hvi-slurm-{}-cluster", std::process::id()));
    let o = Command::new("bash")
        .arg(repo().join(".ci/slurm.sh"))
        .arg("start")
        .arg(&dir)
        .output()
        .map_err(|e| format!("cannot run .ci/slurm.sh: {e}"))?;
    let cluster = Cluster {
        conf: dir.join("slurm.conf"),
        started: Some(dir),
    };
    if !o.status.success() {
        return Err(format!(
            "SLURM_CONF is not set and .ci/slurm.sh could not start Slurm: {}",
            stderr(&o).trim()
        ));
    }
    node_up(&cluster.conf)?;
    Ok(cluster)
}

/// The cluster, or None after a SKIP message; under CI=true a missing cluster fails the test.
fn cluster_or_skip() -> Option<Cluster> {
    match cluster() {
        Ok(c) => Some(c),
        Err(why) if std::env::var("CI").as_deref() == Ok("true") => {
            panic!("CI=true but no Slurm to test against: {why}")
        }
        Err(why) => {
            eprintln!(
                "SKIP tests/slurm.rs: no Slurm ({why}); start one with `.ci/slurm.sh start DIR` \
                 as root and set SLURM_CONF=DIR/slurm.conf"
            );
            None
        }
    }
}

/// Waits until Slurm has none of these jobs queued or running (bounded).
fn wait_for_jobs(conf: &Path, jobs: &[&str], dirs: &[&Path], timeout: Duration) {
    let t0 = Instant::now();
    loop {
        let o = Command::new("squeue")
            .args(["-h", "-j", &jobs.join(","), "-o", "%i %T"])
            .env("SLURM_CONF", conf)
            .output()
            .expect("squeue runs");
        assert!(o.status.success(), "squeue failed: {}", stderr(&o));
        let left = stdout(&o);
        if left.trim().is_empty() {
            return;
        }
        if t0.elapsed() > timeout {
            let mut logs = String::new();
            for d in dirs {
                for sub in std::fs::read_dir(d.join("slurm"))
                    .into_iter()
                    .flatten()
                    .flatten()
                {
                    for f in std::fs::read_dir(sub.path())
                        .into_iter()
                        .flatten()
                        .flatten()
                    {
                        if f.file_name().to_string_lossy().ends_with(".log") {
                            logs.push_str(&format!(
                                "--- {}\n{}\n",
                                f.path().display(),
                                std::fs::read_to_string(f.path()).unwrap_or_default()
                            ));
                        }
                    }
                }
            }
            panic!(
                "jobs {jobs:?} still in the queue after {timeout:?}:\n{left}\ntask logs:\n{logs}"
            );
        }
        std::thread::sleep(Duration::from_millis(300));
    }
}

#[test]
fn a_job_array_gives_the_local_results_and_finishes_a_study_started_locally() {
    let _turn = CLUSTER_TURN.lock().unwrap_or_else(|e| e.into_inner());
    let Some(cluster) = cluster_or_skip() else {
        return;
    };
    let t0 = Instant::now();
    let conf = cluster.conf.as_path();
    let env = [("SLURM_CONF", conf)];
    let dir = scratch("array");
    let study = write_study(&dir);
    let study_arg = study.to_str().expect("utf-8 path");
    let (reference, all, half) = (dir.join("local"), dir.join("cluster"), dir.join("half"));
    let arg = |p: &Path| p.to_str().expect("utf-8 path").to_string();

    // The reference: the study run locally.
    ok(hvi(
        &[
            "sweep",
            study_arg,
            "--out",
            &arg(&reference),
            "--threads",
            "2",
            "--quiet",
        ],
        &[],
    ));

    // The whole study as one job array, at most 2 runs at once.
    let o = ok(hvi(
        &[
            "submit",
            study_arg,
            "--out",
            &arg(&all),
            "--slurm",
            "--array-limit",
            "2",
            "--time",
            "5",
        ],
        &env,
    ));
    let job_all = stdout(&o).trim().to_string();
    assert!(job_all.parse::<u64>().is_ok(), "job id: {job_all}");
    let sub = all.join("slurm/submission-001");
    let script = std::fs::read_to_string(sub.join("job.sbatch")).expect("job script");
    assert!(script.contains("#SBATCH --array=0-3%2\n"), "{script}");
    assert!(script.contains(&format!("'{}' run-unit", env!("CARGO_BIN_EXE_hvi-study"))));
    assert_eq!(
        std::fs::read_to_string(sub.join("tasks.txt")).expect("tasks"),
        "0\n1\n2\n3\n"
    );

    // Half the study locally (runs 0 and 1), the rest on the cluster: only runs 2 and 3 go.
    ok(hvi(&["plan", study_arg, "--out", &arg(&half)], &[]));
    for i in ["0", "1"] {
        ok(hvi(
            &[
                "run-unit",
                &arg(&half.join("plan.json")),
                i,
                "--threads",
                "1",
            ],
            &[],
        ));
    }
    let local_runs = records(&half);
    assert_eq!(local_runs.len(), 2);
    let o = ok(hvi(
        &["submit", study_arg, "--out", &arg(&half), "--slurm"],
        &env,
    ));
    let job_half = stdout(&o).trim().to_string();
    assert!(stderr(&o).contains("2 done"), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(half.join("slurm/submission-001/tasks.txt")).expect("tasks"),
        "2\n3\n"
    );
    // Submitting again submits nothing: the rest is queued, running or done.
    let o = ok(hvi(
        &["submit", study_arg, "--out", &arg(&half), "--slurm"],
        &env,
    ));
    assert_eq!(stdout(&o), "", "{}", stderr(&o));
    assert!(stderr(&o).contains("nothing to submit"), "{}", stderr(&o));
    let o = ok(hvi(&["status", &arg(&half)], &env));
    let (done, failed, running, pending) = status_counts(&o);
    assert_eq!((done + running + pending, failed), (4, 0), "{}", stdout(&o));
    assert!(done >= 2, "{}", stdout(&o));

    wait_for_jobs(
        conf,
        &[&job_all, &job_half],
        &[&all, &half],
        Duration::from_secs(60),
    );
    let queued_s = t0.elapsed().as_secs_f64();

    for d in [&all, &half] {
        let o = ok(hvi(&["status", &arg(d), "--verbose"], &env));
        assert_eq!(status_counts(&o), (4, 0, 0, 0), "{}", stdout(&o));
        ok(hvi(&["collect", &arg(d)], &env));
        assert_same_results(&reference, d);
    }
    // The cluster ran its runs on 1 CPU each, and wrote each task's log.
    for (name, rec, _) in records(&all) {
        let r: serde_json::Value = serde_json::from_slice(&rec).expect("record");
        assert_eq!(r["threads"], 1, "{name}");
    }
    for k in 0..4 {
        let log = std::fs::read_to_string(sub.join(format!("task-{k}.log"))).expect("task log");
        assert!(log.contains(&format!("task {k}: run {k}")), "{log}");
    }
    // Nothing local was redone: the two local runs' records are untouched.
    let after = records(&half);
    for (name, bytes, mtime) in &local_runs {
        let a = after.iter().find(|r| &r.0 == name).expect("still there");
        assert!(&a.1 == bytes && a.2 == *mtime, "{name} was rewritten");
    }
    // And the reverse: a local sweep over the cluster's results runs nothing.
    let o = ok(hvi(
        &["sweep", study_arg, "--out", &arg(&half), "--threads", "2"],
        &[],
    ));
    assert!(
        stderr(&o).contains("runs: 4 total, 4 cached, 0 ran"),
        "{}",
        stderr(&o)
    );
    assert_same_results(&reference, &half);
    eprintln!(
        "slurm test: jobs {job_all} and {job_half} done {queued_s:.1} s after the start, all \
         checks in {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    drop(cluster);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Tests that need the cluster take turns: without SLURM_CONF each starts its own on the
/// same ports.
static CLUSTER_TURN: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// The submissions' array tasks of a study directory: each submitted run's fingerprint.
fn submitted_fingerprints(dir: &Path) -> Vec<String> {
    let mut v = Vec::new();
    for sub in std::fs::read_dir(dir.join("slurm"))
        .into_iter()
        .flatten()
        .flatten()
    {
        let Ok(text) = std::fs::read_to_string(sub.path().join("submission.json")) else {
            continue;
        };
        let s: serde_json::Value = serde_json::from_str(&text).expect("submission.json");
        for r in s["runs"].as_array().expect("runs") {
            v.push(r["fingerprint"].as_str().expect("fingerprint").to_string());
        }
    }
    v
}

#[test]
fn calibrate_runs_each_batch_as_a_job_array_and_a_killed_calibration_submits_nothing_twice() {
    let _turn = CLUSTER_TURN.lock().unwrap_or_else(|e| e.into_inner());
    let Some(cluster) = cluster_or_skip() else {
        return;
    };
    let conf = cluster.conf.as_path();
    let env = [("SLURM_CONF", conf)];
    let dir = scratch("calibrate");
    let study = write_study(&dir);
    let mut text = std::fs::read_to_string(&study).expect("study");
    // The box is kept (max_extensions = 0) so that the search runs its batches as arrays;
    // extending the box is tested in tests/study.rs. Every seed at every point, so that each
    // stage is one array (screening the seeds adds an array for the further seeds: tested in
    // tests/study.rs).
    text.push_str(&format!(
        "\n[calibrate]\ntargets = \"{}\"\nseeds = [1, 2]\nseeds_within_decades = inf\nbatch = 2\nmax_batches = 2\nnoise_floor = 0\nmax_extensions = 0\n",
        repo()
            .join("experiments_data/calibration-shot.toml")
            .display()
    ));
    std::fs::write(&study, text).expect("study");
    let study_arg = study.to_str().expect("utf-8 path").to_string();
    let arg = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let (local, cluster_dir) = (dir.join("local"), dir.join("cluster"));
    let calibrate = |out: &Path, slurm: bool| {
        let mut args = vec![
            "calibrate".to_string(),
            study_arg.clone(),
            "--out".into(),
            arg(out),
        ];
        if slurm {
            args.extend(["--slurm", "--poll", "0.3", "--time", "5"].map(String::from));
        } else {
            args.extend(["--threads", "2"].map(String::from));
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        hvi(&args, &env)
    };
    let json = |out: &Path| -> serde_json::Value {
        serde_json::from_str(
            &std::fs::read_to_string(out.join("calibration.json")).expect("calibration.json"),
        )
        .expect("json")
    };

    // The reference: the same calibration here.
    ok(calibrate(&local, false));
    let reference = json(&local);

    // On Slurm, killed as soon as its first job array is submitted, then run again.
    let mut child = bin()
        .args([
            "calibrate",
            &study_arg,
            "--out",
            &arg(&cluster_dir),
            "--slurm",
            "--poll",
            "0.3",
        ])
        .env("SLURM_CONF", conf)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("calibrate starts");
    let t0 = Instant::now();
    while submitted_fingerprints(&cluster_dir).is_empty() {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no job array submitted within a minute"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().expect("kill");
    let _ = child.wait();
    let o = ok(calibrate(&cluster_dir, true));
    let c = json(&cluster_dir);
    // The same answer as here: the runs are bit-identical wherever they ran.
    for key in ["best", "region", "converged", "noise", "termination"] {
        assert_eq!(c[key], reference[key], "`{key}` differs\n{}", stderr(&o));
    }
    assert_eq!(
        c["refinement"].as_array().map(Vec::len),
        reference["refinement"].as_array().map(Vec::len)
    );
    // Every run of the calibration went through Slurm, each submitted once, in several
    // arrays (the grid, the paper's point, the grid at the seeds, each search batch).
    let submitted = submitted_fingerprints(&cluster_dir);
    let mut distinct = submitted.clone();
    distinct.sort();
    distinct.dedup();
    assert_eq!(distinct.len(), submitted.len(), "a run was submitted twice");
    let stored = records(&cluster_dir).len();
    assert_eq!(
        submitted.len(),
        stored,
        "every stored run came from an array"
    );
    let arrays = std::fs::read_dir(cluster_dir.join("slurm"))
        .expect("slurm")
        .count();
    let mut stages: Vec<&str> = c["refinement"]
        .as_array()
        .expect("refinement")
        .iter()
        .filter_map(|e| e["stage"].as_str())
        .collect();
    stages.dedup();
    assert!(stages.iter().any(|s| s.starts_with("ego-")), "{stages:?}");
    // The paper's point is scored before the search: an array of its own unless every run
    // of it was in the store already.
    let paper_array = usize::from(c["paper"]["cached"] == serde_json::json!(false));
    assert_eq!(
        arrays,
        1 + stages.len() + paper_array,
        "one array for the grid, one per stage {stages:?}, one for the paper's point"
    );
    assert!(stderr(&o).contains("on Slurm"), "{}", stderr(&o));
    // `status` reads a calibration's store with its batches' submissions: the grid
    // (2 x 2) done.
    let o = ok(hvi(&["status", &arg(&cluster_dir)], &env));
    assert_eq!(status_counts(&o), (4, 0, 0, 0), "{}", stdout(&o));
    // ... and counts the search's runs beyond the grid, none in progress.
    let beyond = stored - 4;
    assert!(
        stdout(&o).contains(&format!(
            "beyond the plan (a calibration's search, or runs of another plan in this store): {beyond} done, 0 in progress here"
        )),
        "{}",
        stdout(&o)
    );
    // Again: nothing submitted, nothing run.
    let o = ok(calibrate(&cluster_dir, true));
    assert_eq!(json(&cluster_dir)["runs_made"], 0, "{}", stderr(&o));
    assert_eq!(submitted_fingerprints(&cluster_dir).len(), submitted.len());
    // Slurm options without --slurm are refused, naming them.
    let o = hvi(
        &[
            "calibrate",
            &study_arg,
            "--out",
            &arg(&local),
            "--time",
            "5",
        ],
        &env,
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--slurm"), "{}", stderr(&o));
    let o = calibrate_with_poll(&study_arg, &arg(&local), "0");
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--poll"), "{}", stderr(&o));
    drop(cluster);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `calibrate --slurm --poll P` (for the poll interval's check: refused before any run).
fn calibrate_with_poll(study: &str, out: &str, poll: &str) -> Output {
    hvi(
        &["calibrate", study, "--out", out, "--slurm", "--poll", poll],
        &[],
    )
}

#[test]
fn dry_run_prints_the_job_script_and_writes_nothing() {
    let dir = scratch("dry");
    let study = write_study(&dir);
    let out = dir.join("out");
    let dry_run = |extra: &[&str]| {
        let mut args = vec![
            "submit",
            study.to_str().expect("path"),
            "--out",
            out.to_str().expect("path"),
            "--slurm",
            "--dry-run",
        ];
        args.extend(extra);
        hvi(&args, &[])
    };
    let o = ok(dry_run(&[
        "--partition",
        "short",
        "--time",
        "0-01:00",
        "--cpus-per-task",
        "2",
        "--array-limit",
        "3",
        "--sbatch-option=--account=p42",
    ]));
    let script = stdout(&o);
    for line in [
        "#!/bin/bash",
        "#SBATCH --array=0-3%3",
        "#SBATCH --partition=short",
        "#SBATCH --time=0-01:00",
        "#SBATCH --cpus-per-task=2",
        "#SBATCH --account=p42",
    ] {
        assert!(
            script.lines().any(|l| l == line),
            "no `{line}` in\n{script}"
        );
    }
    let exec = script
        .lines()
        .find(|l| l.starts_with("exec "))
        .expect("exec line");
    assert!(
        exec.starts_with(&format!(
            "exec '{}' run-unit '{}",
            env!("CARGO_BIN_EXE_hvi-study"),
            out.display()
        )),
        "{exec}"
    );
    assert!(
        exec.contains(&format!("--study-dir '{}'", out.display())),
        "{exec}"
    );
    assert!(stderr(&o).contains("nothing submitted"), "{}", stderr(&o));
    assert!(!out.join("slurm").exists() && !out.join("plan.json").exists());

    // Bad Slurm options are refused before anything is written.
    for (flag, value) in [
        ("--time", "1h"),
        ("--partition", "a b"),
        ("--cpus-per-task", "0"),
        ("--array-limit", "0"),
    ] {
        let o = dry_run(&[flag, value]);
        assert_eq!(o.status.code(), Some(2), "{flag} {value}");
        assert!(stderr(&o).contains(flag), "{}", stderr(&o));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A directory holding stand-in Slurm commands (shell scripts), to put alone on PATH.
fn fake_slurm(dir: &Path, sbatch: &str, squeue: Option<&str>) -> PathBuf {
    let bin = dir.join("fake-bin");
    std::fs::create_dir_all(&bin).expect("bin dir");
    let mut tools = vec![("sbatch", sbatch)];
    tools.extend(squeue.map(|s| ("squeue", s)));
    for (name, body) in tools {
        let p = bin.join(name);
        std::fs::write(&p, format!("#!/bin/sh\n{body}\n")).expect("script");
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    }
    bin
}

#[test]
fn sbatch_missing_or_failing_is_a_clear_error_and_a_job_id_is_recorded() {
    let dir = scratch("errors");
    let study = write_study(&dir);
    let study = study.to_str().expect("path");
    let out = dir.join("out");
    let out_s = out.to_str().expect("path");
    let submit = ["submit", study, "--out", out_s, "--slurm"];

    // No sbatch on PATH.
    let empty = dir.join("empty-bin");
    std::fs::create_dir_all(&empty).expect("dir");
    let o = hvi(&submit, &[("PATH", &empty)]);
    assert_eq!(
        o.status.code(),
        Some(69),
        "a missing sbatch exits 69 (EX_UNAVAILABLE): {}",
        stderr(&o)
    );
    assert!(stderr(&o).contains("sbatch not found"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));

    // sbatch refuses the job: its message is shown, nothing is recorded.
    let bin = fake_slurm(
        &dir,
        "echo 'sbatch: error: Batch job submission failed: Invalid partition name specified' >&2\nexit 1",
        None,
    );
    let o = hvi(&submit, &[("PATH", &bin)]);
    assert_eq!(
        o.status.code(),
        Some(69),
        "sbatch refusing the job exits 69 (EX_UNAVAILABLE): {}",
        stderr(&o)
    );
    assert!(
        stderr(&o).contains("sbatch failed")
            && stderr(&o).contains("Invalid partition name specified"),
        "{}",
        stderr(&o)
    );
    assert!(!out.join("slurm/submission-001").exists());

    // sbatch accepts (`--parsable` prints `jobid;cluster`): the job id is printed and recorded
    // with the runs; without squeue, status says it cannot consult the queue.
    std::fs::remove_dir_all(dir.join("fake-bin")).expect("rm");
    let bin = fake_slurm(&dir, "echo '4242;hvi'", None);
    let o = ok(hvi(&submit, &[("PATH", &bin)]));
    assert_eq!(stdout(&o), "4242\n");
    let rec: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("slurm/submission-001/submission.json")).expect("record"),
    )
    .expect("json");
    assert_eq!(rec["job_id"], "4242");
    assert_eq!(rec["runs"].as_array().map(Vec::len), Some(4));
    assert_eq!(rec["runs"][3]["index"], 3);
    let o = ok(hvi(&["status", out_s, "--verbose"], &[("PATH", &bin)]));
    assert_eq!(status_counts(&o), (0, 0, 0, 4), "{}", stdout(&o));
    assert!(stdout(&o).contains("squeue not found"), "{}", stdout(&o));

    // With squeue: task 1 running and the others queued; submitting again submits nothing.
    let bin = fake_slurm(
        &dir,
        "echo 'should not be called' >&2; exit 1",
        Some("echo '4242|0|PENDING'; echo '4242|1|RUNNING'; echo '4242|2|PENDING'; echo '4242|3|PENDING'"),
    );
    let o = ok(hvi(&["status", out_s], &[("PATH", &bin)]));
    assert_eq!(status_counts(&o), (0, 0, 1, 3), "{}", stdout(&o));
    assert!(stdout(&o).contains("(3 queued in Slurm)"), "{}", stdout(&o));
    let o = ok(hvi(&submit, &[("PATH", &bin)]));
    assert!(
        stderr(&o).contains("4 already queued or running in job 4242"),
        "{}",
        stderr(&o)
    );

    // The job vanished without results (squeue lists nothing): status points at the logs, and
    // collect writes the table with every run `missing`.
    let bin = fake_slurm(&dir, "exit 1", Some("exit 0"));
    let o = ok(hvi(&["status", out_s, "-v"], &[("PATH", &bin)]));
    assert_eq!(status_counts(&o), (0, 0, 0, 4), "{}", stdout(&o));
    assert!(
        stdout(&o).contains("ended without a result: see"),
        "{}",
        stdout(&o)
    );
    let o = ok(hvi(&["collect", out_s], &[]));
    assert!(
        stderr(&o).contains("4 of 4 runs have no result yet"),
        "{}",
        stderr(&o)
    );
    assert!(results(&out).iter().all(|r| r["status"] == "missing"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A run the engine stops (an instability) is the run's result: `submit` counts it as failed
/// for good and submits nothing for it, as a local sweep run again does not run it again.
#[test]
fn a_reproducible_failure_is_not_submitted_again() {
    let dir = scratch("failed-for-good");
    // A ledger tolerance of 1e-14 trips at the first energy sample: that run is "unstable".
    let text = format!(
        "[study]\nname = \"fails\"\nscene = \"{}\"\n\n\
         [[axes]]\nkey = \"run.max_energy_drift\"\nvalues = [0.05, 1e-14]\n\n\
         [tiers.quick]\nset = [\"resolution.particles=400\", \"run.end_time_s=2e-6\"]\n",
        repo().join("studies/scenes/default.toml").display()
    );
    let study = dir.join("fails.toml");
    std::fs::write(&study, text).expect("study file");
    let out = dir.join("out");
    let (study, out) = (study.to_str().expect("path"), out.to_str().expect("path"));
    ok(hvi(&["sweep", study, "--out", out, "--quiet"], &[]));
    let o = ok(hvi(
        &["submit", study, "--out", out, "--slurm", "--dry-run"],
        &[],
    ));
    let err = stderr(&o);
    assert!(
        err.contains("2 runs, 1 done, 1 failed for good") && err.contains("nothing to submit"),
        "{err}"
    );
    assert!(!err.contains("submitted again"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
