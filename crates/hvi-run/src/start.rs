//! What a run does with the output directory it is given, before it starts: the rules of
//! `hvi-study run` (docs/running.md).
//!
//! - A checkpoint of this very run (same scene, version and output flags) is resumed: what
//!   the run wrote stays, and [`crate::run::run_scene`] checks the checkpoint whole (a damaged
//!   one starts the run from t = 0).
//! - A finished run of this scene to an earlier end time that kept its continuation is
//!   extended from it (bit-identical to a run to the later end from t = 0); so is an
//!   unfinished one whose continuation this run shares. A finished run of another scene, or of
//!   this one to a later end, is refused with the keys that differ, and nothing is touched.
//! - Anything else, or `fresh`, starts from t = 0 in a cleared directory
//!   ([`crate::output::clear_run_dir`]): an earlier run's files are removed, a directory that
//!   holds other files is refused naming them.

use std::ffi::OsStr;
use std::path::Path;

use hvi_engine::scene::SceneSpec;

use crate::bail;
use crate::checkpoint;
use crate::error::Result;
use crate::run::{checkpoint_key, continuation_key, read_summary, RunOptions};

/// How the run starts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Start {
    /// From the checkpoint this run left in its directory.
    Resume,
    /// From the continuation of the run in the directory, to a later end time.
    Extend,
    /// From t = 0, with the earlier run's files removed (their names).
    Fresh(Vec<String>),
}

/// Decides how the run of `spec` with `opts` starts in `opts.out_dir` and readies the
/// directory for it: the options to run with (`extend` set when it extends) and the start.
/// `fresh` starts from t = 0 whatever is there; `keep` names files of the directory that are
/// the user's (a LAMMPS data file written there) and stay. Notes go to the log when
/// `opts.progress`.
pub fn prepare(
    spec: &SceneSpec,
    opts: RunOptions,
    fresh: bool,
    keep: &[&OsStr],
) -> Result<(RunOptions, Start)> {
    let key = checkpoint_key(spec, &opts)?;
    let resumes = opts
        .checkpoint
        .as_ref()
        .is_some_and(|c| checkpoint::key_of(&c.path) == Some(key));
    if resumes {
        return Ok((opts, Start::Resume));
    }
    let out = opts.out_dir.clone();
    let extend = !fresh && extends_finished_run(&out, spec, &opts)?;
    let opts = RunOptions { extend, ..opts };
    if extend {
        // An unfinished run's checkpoint of another end time: the run continues from its
        // continuation instead, and the checkpoint would only be reported as another run's.
        if let Some(c) = opts.checkpoint.as_ref().filter(|c| c.path.exists()) {
            checkpoint::remove(&c.path)?;
            if opts.progress {
                log::info!(
                    "{}: of this scene to another end time; the run continues from {} instead",
                    c.path.display(),
                    crate::files::CONTINUATION_FILE
                );
            }
        }
        return Ok((opts, Start::Extend));
    }
    let removed = crate::output::clear_run_dir(&out, keep)?;
    if !removed.is_empty() && opts.progress {
        log::info!(
            "{} held an earlier run: removed its {} files ({})",
            out.display(),
            removed.len(),
            removed.join(", ")
        );
    }
    Ok((opts, Start::Fresh(removed)))
}

/// Whether the run should extend the finished run in `out` (`hvi-study run` without
/// `--fresh`): true for a completed run of this scene to an earlier end time that kept its
/// continuation; false for nothing there, a failed or unfinished run, or this very run (run
/// again from t = 0). A completed run of another scene, or of this one to a later end, is
/// refused with the keys that differ, as is one that cannot be extended; nothing in `out`
/// is touched then.
fn extends_finished_run(out: &Path, spec: &SceneSpec, opts: &RunOptions) -> Result<bool> {
    let here = out.display();
    let continues = |path: &Path| -> Result<bool> {
        Ok(checkpoint::key_of(path) == Some(continuation_key(spec, opts)?))
    };
    let Some(old) = read_summary(out).filter(|s| s.status == "completed") else {
        // An unfinished run (stopped at a checkpoint) of this scene to another end: its
        // continuation is its last state that the new run shares (run_scene checks that it
        // lies before the new run's first end-dependent sample).
        return match &opts.continuation {
            Some(path) if continues(path)? => Ok(true),
            _ => Ok(false),
        };
    };
    let other = "pass --fresh to replace it, or choose another --out";
    let differ = scene_differences(&old.scene, spec)?;
    if !differ.is_empty() {
        bail!(
            "{here} holds a finished run of another scene ({}); {other}",
            differ.join("; ")
        );
    }
    let (was, now) = (old.scene.run.end_time_s, spec.run.end_time_s);
    if now == was {
        return Ok(false);
    }
    if now < was {
        bail!(
            "{here} holds this scene run to run.end_time_s = {was:e} s; a run to {now:e} s is \
             not a part of it (the samples at its end differ); {other}"
        );
    }
    let cannot = |why: String| -> Result<bool> {
        bail!(
            "{here} holds this scene run to run.end_time_s = {was:e} s, which cannot be \
             extended to {now:e} s: {why}; pass --fresh to run it from t = 0"
        )
    };
    let Some(path) = &opts.continuation else {
        return cannot("--no-continuation asks not to keep the state to continue from".into());
    };
    match checkpoint::key_of(path) {
        None => cannot(format!(
            "it kept no continuation ({} is missing: the run had --no-continuation or an \
             earlier hvi-study)",
            path.display()
        )),
        Some(_) if !continues(path)? => cannot(format!(
            "{} was written with other output flags (--render, --dump-every, --dump-format) or \
             another hvi-study version",
            path.display()
        )),
        Some(_) => Ok(true),
    }
}

/// The keys whose values differ between two scenes, apart from `run.end_time_s`, as
/// `key: old there, new here`.
fn scene_differences(old: &SceneSpec, new: &SceneSpec) -> Result<Vec<String>> {
    use std::collections::BTreeMap;
    fn flatten(prefix: &str, v: &serde_json::Value, out: &mut BTreeMap<String, String>) {
        match v.as_object() {
            Some(map) => {
                for (k, v) in map {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    flatten(&key, v, out);
                }
            }
            None => {
                out.insert(prefix.to_string(), v.to_string());
            }
        }
    }
    let (mut a, mut b) = (BTreeMap::new(), BTreeMap::new());
    flatten("", &serde_json::to_value(old)?, &mut a);
    flatten("", &serde_json::to_value(new)?, &mut b);
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    let unset = "(not set)".to_string();
    Ok(keys
        .into_iter()
        .filter(|k| k.as_str() != "run.end_time_s")
        .filter_map(|k| {
            let (x, y) = (a.get(k).unwrap_or(&unset), b.get(k).unwrap_or(&unset));
            (x != y).then(|| format!("{k}: {x} there, {y} here"))
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene_file::parse_scene;

    const SCENE: &str = r#"
[scene]
kind = "sphere_on_plate"
diameter_m = 9.53e-3
t_over_d = 0.425
v0_m_s = 6700.0
[resolution]
particles = 800
[material]
eps_j = 0.01
kappa_n_m = 4.56e6
[run]
end_time_s = 1e-6
"#;

    #[test]
    fn differences_name_each_key_but_the_end_time() {
        let a = parse_scene(SCENE, &[]).expect("scene");
        let b = parse_scene(
            SCENE,
            &["scene.v0_m_s=5000".into(), "run.end_time_s=2e-6".into()],
        )
        .expect("scene");
        let d = scene_differences(&a, &b).expect("differences");
        assert_eq!(d.len(), 1, "{d:?}");
        assert!(d[0].starts_with("scene.v0_m_s: 6700"), "{d:?}");
        assert!(scene_differences(&a, &a).expect("none").is_empty());
    }

    #[test]
    fn an_empty_directory_starts_fresh_and_another_scenes_finished_run_is_refused() {
        let out = std::env::temp_dir().join(format!("hvi-start-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let spec = parse_scene(SCENE, &[]).expect("scene");
        let opts = RunOptions {
            out_dir: out.clone(),
            continuation: Some(out.join(crate::files::CONTINUATION_FILE)),
            ..RunOptions::default()
        };
        let (o, start) = prepare(&spec, opts.clone(), false, &[]).expect("prepared");
        assert_eq!(start, Start::Fresh(Vec::new()));
        assert!(!o.extend);
        // A finished run of another scene is there: refused, naming the key, nothing removed.
        let other = parse_scene(SCENE, &["scene.v0_m_s=5000".into()]).expect("scene");
        crate::run::run_scene(&other, &opts).expect("runs");
        let e = prepare(&spec, opts.clone(), false, &[]).expect_err("refused");
        assert!(format!("{e}").contains("scene.v0_m_s"), "{e}");
        assert!(out.join("summary.json").exists());
        // This scene to a later end time extends it.
        let later = parse_scene(
            SCENE,
            &["scene.v0_m_s=5000".into(), "run.end_time_s=2e-6".into()],
        )
        .expect("scene");
        let (o, start) = prepare(&later, opts.clone(), false, &[]).expect("prepared");
        assert_eq!(start, Start::Extend);
        assert!(o.extend);
        // --fresh clears it.
        let (_, start) = prepare(&spec, opts, true, &[]).expect("prepared");
        assert!(
            matches!(&start, Start::Fresh(r) if r.iter().any(|f| f == "summary.json")),
            "{start:?}"
        );
        assert!(!out.join("summary.json").exists());
        let _ = std::fs::remove_dir_all(&out);
    }
}
