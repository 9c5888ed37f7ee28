//! What the resolution makes of a scene file with its `--set` overrides, or of a plan's runs:
//! the engine's resolution warnings ([`hvi_engine::scene::ResolutionCheck`]), and sigma moved by
//! an override of a geometry key at the same resolution ([`hvi_engine::scene::sigma_change`]),
//! compared with the scene file's own scene (for a plan: the study's, with the study's own
//! `set`). A plan's warnings come once each, with the runs they concern. Nothing here prints;
//! the command line does.

use std::path::Path;

use hvi_engine::scene::{merged_warnings, sigma_change, ResolutionCheck, SceneSpec};

use crate::plan::Plan;
use crate::spec::{override_key, Study};
use hvi_run::error::Result;
use hvi_run::scene_file::{load_scene, parse_scene};

/// Whether an override names a geometry key (`scene.*`): the keys that may move sigma at a
/// fixed resolution.
fn is_geometry(set: &str) -> bool {
    override_key(set).starts_with("scene.")
}

/// The resolution warnings of one scene, each one sentence: the engine's warnings about its
/// plates, then sigma moved by the geometry overrides among `sets` (compared with the scene
/// file `path` under the other overrides). `spec` is the scene as run (`path` with `sets`);
/// a scene whose geometry or resolution is invalid has none (its error says what is wrong).
pub fn scene_warnings(path: &Path, sets: &[String], spec: &SceneSpec) -> Vec<String> {
    let Ok(check) = spec.resolution_check() else {
        return Vec::new();
    };
    let mut out: Vec<String> = check.warnings().into_iter().map(|w| w.message).collect();
    if sets.iter().any(|s| is_geometry(s)) {
        let own: Vec<String> = sets.iter().filter(|s| !is_geometry(s)).cloned().collect();
        if let Some(change) = load_scene(path, &own)
            .ok()
            .and_then(|before| sigma_change(&before, spec).ok().flatten())
        {
            out.push(change.message);
        }
    }
    out
}

/// A warning about some runs of a plan.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanWarning {
    /// The warning in one sentence, naming the key and the numbers.
    pub message: String,
    /// The runs it concerns (plan indices, ascending).
    pub runs: Vec<usize>,
}

impl PlanWarning {
    /// The warning with the runs it concerns, as the command line prints it:
    /// `... (16 of 56 runs: scene.t_over_d = 0.05, 0.1)`.
    pub fn line(&self, plan: &Plan) -> String {
        format!("{} ({})", self.message, describe_runs(plan, &self.runs))
    }
}

/// Each distinct resolution warning of a plan's runs once, with the runs it concerns: the
/// engine's warnings merged over the runs ([`merged_warnings`]: two labels of one plate read
/// as one warning), then sigma moved by the geometry overrides of the tier or the command line
/// compared with the study's own scene (with the study's `set` and the same resolution) at
/// the same axis values.
pub fn plan_warnings(study: &Study, plan: &Plan) -> Result<Vec<PlanWarning>> {
    let checks: Vec<ResolutionCheck> = plan
        .runs
        .iter()
        .map(|r| r.scene.resolution_check())
        .collect::<std::result::Result<_, _>>()?;
    let mut out: Vec<PlanWarning> = merged_warnings(&checks)
        .into_iter()
        .map(|m| PlanWarning {
            message: m.message,
            runs: m.scenes.iter().map(|&i| plan.runs[i].index).collect(),
        })
        .collect();
    out.extend(sigma_warnings(study, plan));
    Ok(out)
}

/// Sigma moved by the tier's or the command line's geometry overrides, each distinct message
/// once with its runs. The study's own `set` is part of its scene.
fn sigma_warnings(study: &Study, plan: &Plan) -> Vec<PlanWarning> {
    let theirs = plan.set.len().min(study.set.len());
    let added = &plan.set[theirs..];
    if !added.iter().any(|s| is_geometry(s)) {
        return Vec::new();
    }
    let own: Vec<&String> = plan.set[..theirs]
        .iter()
        .chain(added.iter().filter(|s| !is_geometry(s)))
        .collect();
    let mut out: Vec<PlanWarning> = Vec::new();
    for run in &plan.runs {
        let axes = run.set.iter().skip(plan.set.len());
        let set: Vec<String> = own.iter().copied().chain(axes).cloned().collect();
        let Some(change) = parse_scene(&study.scene_text, &set)
            .ok()
            .and_then(|before| sigma_change(&before, &run.scene).ok().flatten())
        else {
            continue;
        };
        match out.iter_mut().find(|w| w.message == change.message) {
            Some(w) => w.runs.push(run.index),
            None => out.push(PlanWarning {
                message: change.message,
                runs: vec![run.index],
            }),
        }
    }
    out
}

/// Which runs of a plan: `all 56 runs`; a block of the grid by its axes' values,
/// `16 of 56 runs: scene.t_over_d = 0.05, 0.1` (an axis at all its values left out); else
/// their indices, `runs 0, 3, 7 of 56`.
pub fn describe_runs(plan: &Plan, runs: &[usize]) -> String {
    let n = plan.runs.len();
    if runs.len() == n {
        return format!("all {n} runs");
    }
    let values_of = |axis: usize| {
        let mut c: Vec<usize> = runs
            .iter()
            .filter_map(|&i| plan.runs.get(i))
            .map(|r| r.coords[axis])
            .collect();
        c.sort_unstable();
        c.dedup();
        c
    };
    let per_axis: Vec<Vec<usize>> = (0..plan.axes.len()).map(values_of).collect();
    let block: usize = per_axis.iter().map(Vec::len).product();
    if block == runs.len() && !runs.is_empty() {
        let parts: Vec<String> = plan
            .axes
            .iter()
            .zip(&per_axis)
            .filter(|(a, c)| c.len() < a.values.len())
            .map(|(a, c)| {
                let values: Vec<String> = c.iter().map(|&k| a.values[k].to_string()).collect();
                format!("{} = {}", a.key, values.join(", "))
            })
            .collect();
        let of = if runs.len() == 1 { "run" } else { "runs" };
        return format!("{} of {n} {of}: {}", runs.len(), parts.join("; "));
    }
    const SHOWN: usize = 12;
    let mut shown: Vec<String> = runs.iter().take(SHOWN).map(|i| i.to_string()).collect();
    if runs.len() > SHOWN {
        shown.push(format!("... ({} in all)", runs.len()));
    }
    let of = if runs.len() == 1 { "run" } else { "runs" };
    format!("{of} {} of {n}", shown.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::{build_plan, PlanRequest};

    /// A study over t/D (and two seeds) of the calibration scene at 2000 particles.
    fn study(dir: &Path, tier_set: &str) -> Study {
        std::fs::create_dir_all(dir).expect("dir");
        std::fs::write(
            dir.join("scene.toml"),
            "[scene]\nkind = \"sphere_on_plate\"\ndiameter_m = 9.53e-3\nt_over_d = 0.425\n\
             width_over_d = 3.0\nv0_m_s = 6700\n[resolution]\nparticles = 2000\n[material]\n\
             eps_j = 0.01\nkappa_n_m = 4.56e6\n[run]\nend_time_s = 1e-7\n",
        )
        .expect("scene");
        let text = format!(
            "[study]\nname = \"t\"\nscene = \"scene.toml\"\ndefault_tier = \"quick\"\n\
             [[axes]]\nkey = \"scene.t_over_d\"\nvalues = [0.05, 0.1, 0.425]\n\
             [[axes]]\nkey = \"run.seed\"\nvalues = [1, 2]\n\
             [tiers.quick]\nset = [{tier_set}]\n"
        );
        std::fs::write(dir.join("study.toml"), text).expect("study");
        Study::load(&dir.join("study.toml")).expect("study")
    }

    fn scratch(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("hvi-run-resolution-{}-{name}", std::process::id()))
    }

    /// t/D 0.05 and 0.1 at 2000 particles are both one layer (r_eq 0.75 and 0.851 mm): one
    /// warning for the two, naming the 4 runs by their t/D; t/D 0.05's thickness (57 % off)
    /// and 0.1's (0.0893 for 0.1: 11 % thinner) once each.
    #[test]
    fn a_plans_thin_rows_warn_once_with_their_runs() {
        let dir = scratch("thin");
        let s = study(&dir, "");
        let plan = build_plan(&s, &PlanRequest::default()).expect("plan");
        let w = plan_warnings(&s, &plan).expect("warnings");
        assert_eq!(w.len(), 3, "{w:#?}");
        assert_eq!(w[0].runs, [0, 1, 2, 3]);
        let line = w[0].line(&plan);
        assert!(
            line.starts_with("scene.t_over_d = 0.05 and 0.1 give plates of 1 particle layer"),
            "{line}"
        );
        assert!(
            line.ends_with("(4 of 6 runs: scene.t_over_d = 0.05, 0.1)"),
            "{line}"
        );
        assert!(w[1].message.contains("57 % thicker"), "{}", w[1].message);
        assert_eq!(w[1].runs, [0, 1]);
        assert!(w[2].message.contains("11 % thinner"), "{}", w[2].message);
        assert_eq!(describe_runs(&plan, &[0, 3]), "runs 0, 3 of 6");
        assert_eq!(describe_runs(&plan, &[0, 1, 2, 3, 4, 5]), "all 6 runs");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A tier that widens the plate at its particle count moves sigma in every run: by hand
    /// at t/D 0.425 and 10000 particles, V = 4.3486 D^3 at W = 3 D and 15.824 D^3 at W = 6 D,
    /// sigma 0.643 mm -> 0.989 mm (times the cube root of 3.639). The same width in the
    /// study's own `set` is the study's scene: no warning.
    #[test]
    fn a_tiers_geometry_override_that_moves_sigma_warns() {
        let dir = scratch("sigma");
        let s = study(
            &dir,
            "\"resolution.particles=10000\", \"scene.width_over_d=6\"",
        );
        let plan = build_plan(&s, &PlanRequest::default()).expect("plan");
        let w = plan_warnings(&s, &plan).expect("warnings");
        let sigma: Vec<&PlanWarning> = w
            .iter()
            .filter(|w| w.message.contains("changes sigma"))
            .collect();
        assert_eq!(sigma.len(), 3, "one per t/D: {w:#?}");
        let at_0425 = sigma
            .iter()
            .find(|w| w.runs == [4, 5])
            .expect("t/D 0.425's runs");
        assert!(
            at_0425.message.starts_with(
                "scene.width_over_d = 6 (was 3) changes sigma from 0.643 mm to 0.989 mm at \
                 resolution.particles = 10000"
            ),
            "{}",
            at_0425.message
        );
        let mut plain = s.clone();
        plain.set.push("scene.width_over_d=6".into());
        let tier = plain.tiers.get_mut("quick").expect("tier");
        tier.set.retain(|s| s.starts_with("resolution."));
        let plan = build_plan(&plain, &PlanRequest::default()).expect("plan");
        let w = plan_warnings(&plain, &plan).expect("warnings");
        assert!(w.iter().all(|w| !w.message.contains("sigma")), "{w:#?}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
