//! Checkpoints (`--checkpoint-every`): a run killed at any moment resumes from its last
//! checkpoint and ends bit-identical to a run never stopped, at any thread count; a damaged
//! checkpoint is reported and not used; a study's run killed or stopped mid-way resumes from its
//! checkpoint in the store, with the study's results identical to an uninterrupted study's; a
//! finished or stopped run extended to a later end time equals a run made to it in one go.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common;
use common::{bin, repo};

/// A run of the default scene at 2000 particles through 6 us, with pictures (frames captured at
/// render times inside the run) and dumps, so that a checkpoint must carry all of them.
fn run(out: &Path, every: &str, threads: usize) -> Command {
    run_to(out, "6e-6", every, threads)
}

/// [`run`] to another end time, s.
fn run_to(out: &Path, end_time_s: &str, every: &str, threads: usize) -> Command {
    let mut c = bin();
    c.arg("run")
        .arg(repo().join("studies/scenes/default.toml"))
        .arg("--out")
        .arg(out)
        .args([
            "--set",
            "resolution.particles=2000",
            "--set",
            &format!("run.end_time_s={end_time_s}"),
            "--set",
            "analysis.render_times_s=[0.0, 3.3e-6, 5.1e-6]",
            "--render",
            "--dump-every",
            "333",
            "--checkpoint-every",
            every,
            "--threads",
        ])
        .arg(threads.to_string())
        .stdout(Stdio::null());
    c
}

/// Every file under `dir` by relative path, `summary.json` without what depends on the
/// machine (wall times, rates, timings, the thread count of the last process).
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(dir).expect("dir").filter_map(|e| e.ok()) {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
                continue;
            }
            let rel = p.strip_prefix(root).expect("under root");
            let rel = rel.to_string_lossy().into_owned();
            // The state a later end continues from holds wall times, like a checkpoint.
            if rel == "continuation.bin" {
                continue;
            }
            let bytes = std::fs::read(&p).expect("file");
            let bytes = if rel == "summary.json" {
                let mut s: serde_json::Value = serde_json::from_slice(&bytes).expect("json");
                let o = s.as_object_mut().expect("object");
                for key in [
                    "wall_seconds",
                    "particle_steps_per_second",
                    "timing",
                    "threads",
                ] {
                    assert!(o.remove(key).is_some(), "summary lacks {key}");
                }
                serde_json::to_vec_pretty(&s).expect("json")
            } else {
                bytes
            };
            out.insert(rel, bytes);
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn assert_same(got: &BTreeMap<String, Vec<u8>>, want: &BTreeMap<String, Vec<u8>>, what: &str) {
    let names = |m: &BTreeMap<String, Vec<u8>>| m.keys().cloned().collect::<Vec<_>>();
    assert_eq!(names(got), names(want), "{what}: other files");
    for (name, bytes) in want {
        assert!(got[name] == *bytes, "{what}: {name} differs");
    }
}

/// The base step in a checkpoint's header, if there is one.
fn checkpoint_step(path: &Path) -> Option<u64> {
    let b = std::fs::read(path).ok()?;
    Some(u64::from_le_bytes(b.get(48..56)?.try_into().ok()?))
}

/// A fixed-seed generator of numbers in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn a_run_killed_at_twenty_random_moments_resumes_bit_identical() {
    let dir = common::scratch("hvi-checkpoint", "kill");
    let reference = dir.join("reference");
    let t0 = Instant::now();
    let o = run(&reference, "40steps", 1).output().expect("runs");
    let wall = t0.elapsed();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let want = files(&reference);
    assert!(
        !want.contains_key("checkpoint.bin"),
        "a finished run keeps no checkpoint"
    );
    let summary: serde_json::Value =
        serde_json::from_slice(&want["summary.json"]).expect("summary");
    let base_steps = summary["base_steps"].as_u64().expect("base steps");
    assert!(
        base_steps > 1000,
        "{base_steps} base steps: too short a run to kill"
    );
    for f in [
        "trajectory.extxyz",
        "trajectory.pvd",
        "state.bin",
        "cloud_series.png",
    ] {
        assert!(want.contains_key(f), "the reference run has no {f}");
    }
    // Uninterrupted without checkpoints: the same files, so writing them changes nothing.
    let plain = dir.join("plain");
    let o = run(&plain, "off", 2).output().expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_same(&files(&plain), &want, "without checkpoints");

    // Killed (SIGKILL) 20 times at 1 or 2 threads in turn, then run to the end. Each kill
    // comes at a random moment after the run passed a random point of its course (stratified:
    // the k-th of 20 strata), up to one checkpoint interval later, so kills fall anywhere
    // between two checkpoints, during a checkpoint's write included; two come at a random moment
    // of the start (reading the checkpoint, building the scene).
    let out = dir.join("killed");
    let ckpt = out.join("checkpoint.bin");
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let interval = wall.mul_f64(40.0 / base_steps as f64);
    let last = base_steps - 300;
    let (mut resumed, mut steps_seen) = (0, Vec::new());
    for k in 0..20u64 {
        let mut child = run(&out, "40steps", 1 + k as usize % 2)
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawns");
        if k % 10 == 3 {
            std::thread::sleep(Duration::from_millis(1 + (20.0 * rng.next()) as u64));
        } else {
            let target = ((k as f64 + rng.next()) / 20.0 * last as f64) as u64;
            let t0 = Instant::now();
            while checkpoint_step(&ckpt).is_none_or(|s| s < target) {
                assert!(t0.elapsed() < Duration::from_secs(60), "kill {k}: stuck");
                std::thread::sleep(Duration::from_micros(500));
            }
            std::thread::sleep(interval.mul_f64(rng.next()));
        }
        assert!(
            child.try_wait().expect("wait").is_none(),
            "kill {k}: the run ended before its moment"
        );
        child.kill().expect("SIGKILL"); // Child::kill is SIGKILL on Unix
        let o = child.wait_with_output().expect("reaped");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("damaged"), "kill {k}: {err}");
        resumed += usize::from(err.contains("resuming from checkpoint"));
        steps_seen.extend(checkpoint_step(&ckpt));
    }
    let o = run(&out, "40steps", 2)
        .stderr(Stdio::piped())
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("resuming from checkpoint"), "{err}");
    steps_seen.dedup();
    assert!(
        resumed >= 15 && steps_seen.len() >= 15,
        "only {resumed} resumes and {} distinct checkpoints",
        steps_seen.len()
    );
    assert_same(&files(&out), &want, "killed 20 times");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Runs `c`, which must succeed; its stderr.
fn succeeds(mut c: Command) -> String {
    let o = c.stderr(Stdio::piped()).output().expect("runs");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    err
}

/// Runs `c`, which must fail; its stderr.
fn fails(mut c: Command) -> String {
    let o = c.stderr(Stdio::piped()).output().expect("runs");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "it ran: {err}");
    err
}

#[test]
fn a_finished_or_stopped_run_extends_to_a_later_end_bit_identical_to_one_run_in_one_go() {
    let dir = common::scratch("hvi-checkpoint", "extend");
    // The reference: to 8 us in one go. Runs shorter than 32 us place their front times at
    // 7/8 of the end and at the end, so a run to 6 us lands on steps one to 8 us does not:
    // the continuation must come from before 5.25 us.
    let one = dir.join("one");
    succeeds(run_to(&one, "8e-6", "off", 2));
    let want = files(&one);

    // Finished at 6 us, then extended to 8 us, at another thread count.
    let out = dir.join("finished");
    succeeds(run_to(&out, "6e-6", "off", 1));
    assert!(out.join("continuation.bin").is_file());
    let err = succeeds(run_to(&out, "8e-6", "off", 2));
    assert!(
        err.contains("extending the run from its continuation"),
        "{err}"
    );
    assert_same(&files(&out), &want, "extended from 6 us");

    // Killed on its way to 7 us after a few checkpoints, then asked for 8 us: it continues
    // from its last checkpoint before its first end-dependent landing.
    let out = dir.join("stopped");
    let mut child = run_to(&out, "7e-6", "40steps", 1).spawn().expect("spawns");
    let t0 = Instant::now();
    while checkpoint_step(&out.join("checkpoint.bin")).is_none_or(|s| s < 400) {
        assert!(t0.elapsed() < Duration::from_secs(60), "no checkpoint");
        assert!(child.try_wait().expect("wait").is_none(), "ended first");
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().expect("SIGKILL");
    child.wait().expect("reaped");
    let err = succeeds(run_to(&out, "8e-6", "40steps", 2));
    assert!(
        err.contains("extending the run from its continuation") && !err.contains("t = 0"),
        "{err}"
    );
    assert_same(&files(&out), &want, "a stopped run extended");

    // Refused, naming why, with nothing touched: an earlier end, another scene, other output
    // flags. --fresh runs from t = 0 instead.
    let before = files(&out);
    let err = fails(run_to(&out, "7e-6", "off", 2));
    assert!(
        err.contains("run.end_time_s = 8e-6 s") && err.contains("--fresh"),
        "{err}"
    );
    let mut other = run_to(&out, "9e-6", "off", 2);
    other.args(["--set", "material.eps_j=0.1"]);
    let err = fails(other);
    assert!(err.contains("material.eps_j: "), "{err}");
    let mut flags = run_to(&out, "9e-6", "off", 2);
    flags.args(["--dump-format", "extxyz"]);
    let err = fails(flags);
    assert!(err.contains("other output flags"), "{err}");
    assert_same(&files(&out), &before, "after the refusals");
    let mut fresh = run_to(&out, "6e-6", "off", 2);
    fresh.arg("--fresh");
    let err = succeeds(fresh);
    assert!(err.contains("held an earlier run"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_damaged_checkpoint_is_reported_and_the_run_starts_over() {
    let dir = common::scratch("hvi-checkpoint", "damaged");
    let reference = dir.join("reference");
    let o = run(&reference, "off", 2).output().expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let want = files(&reference);
    let out = dir.join("out");
    let ckpt = out.join("checkpoint.bin");
    let mut child = run(&out, "40steps", 2).spawn().expect("spawns");
    let t0 = Instant::now();
    while checkpoint_step(&ckpt).is_none_or(|s| s < 200) {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no checkpoint in 60 s"
        );
        assert!(child.try_wait().expect("wait").is_none(), "ended first");
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().expect("SIGKILL");
    child.wait().expect("reaped");
    // One bit of the payload flipped: caught by the checksum, never used.
    let mut bytes = std::fs::read(&ckpt).expect("checkpoint");
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x10;
    std::fs::write(&ckpt, &bytes).expect("write");
    // What a kill during an atomic write leaves (here planted, so the test does not depend on
    // when the kill lands): removed although the run starts over rather than resumes.
    std::fs::write(out.join(".continuation.bin.tmp.1"), b"half").expect("write");
    let o = run(&out, "40steps", 2)
        .stderr(Stdio::piped())
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("damaged (its checksum does not match its content)")
            && err.contains("starts from t = 0"),
        "{err}"
    );
    assert!(!err.contains("resuming from checkpoint"), "{err}");
    assert_same(&files(&out), &want, "after a damaged checkpoint");
    // A checkpoint of another scene is not used either: the directory is cleared first.
    let other = dir.join("other");
    let mut child = run(&other, "40steps", 2).spawn().expect("spawns");
    let t0 = Instant::now();
    while checkpoint_step(&other.join("checkpoint.bin")).is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no checkpoint in 60 s"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().expect("SIGKILL");
    child.wait().expect("reaped");
    let o = run(&other, "40steps", 2)
        .args(["--set", "scene.v0_m_s=6000"])
        .stderr(Stdio::piped())
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        !err.contains("resuming from checkpoint") && err.contains("checkpoint.bin"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A one-run study of 1500 particles through 6 us.
fn write_study(dir: &Path) -> std::path::PathBuf {
    let scene = repo().join("studies/scenes/default.toml");
    let text = format!(
        "[study]\nname = \"ckpt\"\nscene = \"{}\"\n\n[[axes]]\nkey = \"run.seed\"\nvalues = [7]\n\n\
         [tiers.quick]\nset = [\"resolution.particles=1500\", \"run.end_time_s=6e-6\"]\n",
        scene.display()
    );
    let path = dir.join("ckpt.toml");
    std::fs::write(&path, text).expect("study file");
    path
}

fn sweep(study: &Path, out: &Path) -> Command {
    let mut c = bin();
    c.arg("sweep")
        .arg(study)
        .arg("--out")
        .arg(out)
        .args(["--threads", "1", "--checkpoint-every", "30steps", "--quiet"])
        .stdout(Stdio::null());
    c
}

/// The store's checkpoint files.
fn store_checkpoints(out: &Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(out.join("runs"))
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| {
                    p.file_name()
                        .is_some_and(|n| n.to_string_lossy().starts_with(".checkpoint-"))
                })
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_study_run_killed_or_stopped_mid_way_resumes_from_its_checkpoint() {
    let dir = common::scratch("hvi-checkpoint", "store");
    let study = write_study(&dir);
    let whole = dir.join("whole");
    let o = sweep(&study, &whole).output().expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(store_checkpoints(&whole).is_empty());
    // The results table but for each run's wall time.
    let tables = |out: &Path| {
        let text = std::fs::read_to_string(out.join("results.json")).expect("results.json");
        let mut rows: Vec<serde_json::Value> = serde_json::from_str(&text).expect("json");
        for r in &mut rows {
            let o = r.as_object_mut().expect("row");
            assert!(
                o.remove("wall_seconds").is_some(),
                "no wall_seconds in {o:?}"
            );
        }
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0]["status"], "completed");
        rows
    };
    let want = tables(&whole);

    let out = dir.join("out");
    for (signal, code) in [("KILL", None), ("TERM", Some(143))] {
        let mut child = sweep(&study, &out)
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawns");
        let t0 = Instant::now();
        let before = store_checkpoints(&out)
            .first()
            .and_then(|p| checkpoint_step(p))
            .unwrap_or(0);
        // Until the run has written a checkpoint beyond the one it resumed from.
        while store_checkpoints(&out)
            .first()
            .and_then(|p| checkpoint_step(p))
            .is_none_or(|s| s <= before + 60)
        {
            assert!(
                t0.elapsed() < Duration::from_secs(60),
                "no checkpoint in 60 s"
            );
            assert!(child.try_wait().expect("wait").is_none(), "ended first");
            std::thread::sleep(Duration::from_millis(5));
        }
        let kill = Command::new("kill")
            .arg(format!("-{signal}"))
            .arg(child.id().to_string())
            .status()
            .expect("kill runs");
        assert!(kill.success());
        let o = child.wait_with_output().expect("reaped");
        assert_eq!(
            o.status.code(),
            code,
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert_eq!(store_checkpoints(&out).len(), 1, "the checkpoint stays");
    }
    // `status` says where the run stands.
    let o = bin()
        .arg("status")
        .arg(&study)
        .arg("--out")
        .arg(&out)
        .arg("--verbose")
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        text.contains("stopped mid-way; resumes from its checkpoint at base step"),
        "{text}"
    );
    let o = sweep(&study, &out)
        .stderr(Stdio::piped())
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("resumed from its checkpoint at base step"),
        "{err}"
    );
    assert!(
        store_checkpoints(&out).is_empty(),
        "a stored run keeps no checkpoint"
    );
    assert_eq!(
        tables(&out),
        want,
        "the results differ from the uninterrupted study's"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
