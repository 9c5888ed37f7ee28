//! The shot a calibration scores against defines the impact it is scored at. The study
//! supplies the resolution, the model's parameters and the run's settings; the shot supplies
//! the impactor's diameter, v0, t/D (at its documented offset, `[shot.simulated]`), and where
//! it states them the density and the observation time ([`hvi_analysis::shot::Shot::impact_keys`]).
//!
//! A key the study's scene leaves out is set from the shot. A key the study gives (its scene
//! file, `study.set`, the tier's `set`, `--set`) must agree with the shot; a disagreement is an
//! error naming both values and where the study's came from. An axis over one of the shot's
//! keys is refused: each condition is a shot of its own.

use std::path::{Path, PathBuf};

use hvi_analysis::score::Targets;
use hvi_analysis::shot::ImpactKey;
use hvi_run::bail;
use hvi_run::error::{Result, RunError};
use hvi_run::scene_file::apply_overrides;
use hvi_store::plan::Plan;
use hvi_store::spec::{json_to_override, override_key, Study};
use hvi_store::store::Store;

use crate::problem::{fixed_overrides, Stage};
use crate::result::EvalStage;
use crate::result::{Evaluation, HeldOut, ShotUse};
use hvi_studies::options::StudyOptions;

/// A shot with the plan of its impact: the study's grid at the shot's conditions.
#[derive(Debug, Clone)]
pub struct ShotPlan {
    /// The shot's targets (the study's weights applied).
    pub targets: Targets,
    /// Its plan.
    pub plan: Plan,
}

/// A fragment-size target says little unless one particle is at most this fraction of the
/// size it measures: a fragment of that size is then at least a 3 x 3 x 3 cube of particles,
/// and sizes a factor 3 apart (the paper's shot's tolerance) are told apart.
pub const FRAGMENT_SIZE_RESOLUTION: f64 = 1.0 / 3.0;

/// Every resolution warning of a shot's plan (docs/running.md, "Resolution"), then whether one
/// particle is well below the fragment size a target measures
/// ([`FRAGMENT_SIZE_RESOLUTION`]), each as one line naming the shot.
pub fn resolution_warnings(study: &Study, shot: &ShotPlan) -> Result<Vec<String>> {
    let id = &shot.targets.shot.id;
    let mut out: Vec<String> = hvi_store::resolution::plan_warnings(study, &shot.plan)?
        .into_iter()
        .map(|w| format!("shot {id}: {}", w.line(&shot.plan)))
        .collect();
    let Some(run) = shot.plan.runs.first() else {
        return Ok(out);
    };
    let check = run.scene.resolution_check()?;
    // A lone particle's volume-equivalent diameter: (6 / pi)^(1/3) r_eq.
    let particle_m = (6.0 / std::f64::consts::PI).cbrt() * check.r_eq_m;
    for t in &shot.targets.targets {
        use hvi_analysis::observable::Observable::{LargestFragmentDiameter, MeanFragmentDiameter};
        if !matches!(t.observable, MeanFragmentDiameter | LargestFragmentDiameter) {
            continue;
        }
        let finest = FRAGMENT_SIZE_RESOLUTION * t.value;
        if particle_m <= finest {
            continue;
        }
        let scale = (particle_m / finest).powi(3);
        let particles = run.scene.resolution.particles.map_or(String::new(), |n| {
            format!(
                "; resolution.particles >= {} gives particles of {:.3} mm",
                hvi_store::spec::round_sig(n * scale, 2),
                finest * 1e3
            )
        });
        out.push(format!(
            "shot {id}: target `{}` measures fragments of {} mm, and one particle is already {:.3} \
             mm across (sigma {:.3} mm): more than {:.2} of that size, so the term cannot tell \
             fragment sizes apart at this resolution{particles}",
            t.name,
            t.value * 1e3,
            particle_m * 1e3,
            check.sigma_m * 1e3,
            FRAGMENT_SIZE_RESOLUTION
        ));
    }
    Ok(out)
}

/// One line per shot for the console: `shot emi-calibration-shot: ...`, synthetic ones marked.
pub fn describe_shot(t: &Targets) -> String {
    let shot = ShotUse::of(t);
    format!("shot {}: {}", shot.name(), shot.impact)
}

/// Every shot of the calibration with its plan, the first plan written as the study's
/// plan.json, with the study directory. A shot named by `hold_out` must be among them.
/// `screen`: the plans carry the study's screen (false: every run in full).
pub fn shot_plans(
    opts: &StudyOptions,
    hold_out: Option<&str>,
    screen: bool,
) -> Result<(Study, Vec<ShotPlan>, PathBuf)> {
    let mut study = opts.load_study()?;
    let cfg = crate::CalibrateConfig::of(&study)?;
    let shots = cfg.load_shots(&study)?;
    let extra = cfg.tier_set_of(&study, opts.tier.as_deref())?;
    if !extra.is_empty() {
        log::info!(
            "calibrate sets at this tier (calibrate.tier_set; their measured cost: \
             docs/model-decisions.md): {}",
            extra.join(", ")
        );
        study.set.extend(extra);
    }
    if let Some(h) = hold_out {
        if !shots.iter().any(|t| t.shot.id == h) {
            bail!(
                "invalid value for `--hold-out`: `{h}` (allowed: a shot of the study: {})",
                shots
                    .iter()
                    .map(|t| t.shot.id.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        if shots.len() < 2 {
            bail!("--hold-out needs a study of two or more shots (it calibrates on the others)");
        }
    }
    let (plans, out) = plans_of(opts, &study, shots, hold_out, screen)?;
    Ok((study, plans, out))
}

/// The plan of each shot of `study` at these options (the study's grid at the shot's impact),
/// the first calibrated shot's (not `hold_out`) written as the study directory's plan.json;
/// with that directory. `screen`: the calibrated shots' plans carry the study's screen
/// (`calibrate.screen`; false: every run in full).
pub fn plans_of(
    opts: &StudyOptions,
    study: &Study,
    shots: Vec<Targets>,
    hold_out: Option<&str>,
    screen: bool,
) -> Result<(Vec<ShotPlan>, PathBuf)> {
    let mut plans = Vec::new();
    let mut out = None;
    for targets in shots {
        let s = study_for_shot(study, opts.tier.as_deref(), &opts.sets, &targets)?;
        let (plan, dir) = opts.build_plan_of(&s)?;
        out.get_or_insert(dir);
        plans.push(ShotPlan { targets, plan });
    }
    let out =
        out.ok_or_else(|| RunError::Input("study key `calibrate.shots` is empty".to_string()))?;
    if screen {
        screen_plans(study, &mut plans, hold_out, &out)?;
    }
    let first = plans
        .iter()
        .find(|p| Some(p.targets.shot.id.as_str()) != hold_out)
        .ok_or_else(|| RunError::Input("no shot left to calibrate on".to_string()))?;
    first.plan.write(&out)?;
    Ok((plans, out))
}

/// The calibrated shots' plans as the calibration's screen runs them
/// ([`crate::screen::Screen::apply_to_plan`]; the held-out shot's is run in full).
fn screen_plans(
    study: &Study,
    plans: &mut [ShotPlan],
    hold_out: Option<&str>,
    out: &Path,
) -> Result<()> {
    let calibrated = |p: &ShotPlan| Some(p.targets.shot.id.as_str()) != hold_out;
    let targets: Vec<Targets> = plans
        .iter()
        .filter(|p| calibrated(p))
        .map(|p| p.targets.clone())
        .collect();
    let screen = crate::screen::Screen::of(&crate::CalibrateConfig::of(study)?, &targets);
    let store = Store::existing(out).ok();
    for (shot, p) in plans.iter_mut().filter(|p| calibrated(p)).enumerate() {
        screen.apply_to_plan(shot, &mut p.plan, store.as_ref())?;
    }
    Ok(())
}

/// Runs the held-out shot at the calibrated point (the best grid run's values beside the
/// searched parameters `refine_keys`) at the answer's seeds and scores it against its own
/// targets.
pub(super) fn predict_held_out(
    stage: &Stage,
    held: &ShotPlan,
    best_values: &[serde_json::Value],
    refine_keys: &[String],
    best: &Evaluation,
) -> Result<HeldOut> {
    let fixed = fixed_overrides(&[&held.plan], best_values, |k| refine_keys.contains(k))?;
    let targets = [held.targets.clone()];
    let plans = [&held.plan];
    // A prediction is run in full.
    let off = crate::screen::Screen::off();
    let own = Stage {
        study: stage.study,
        plan: &held.plan,
        plans: &plans,
        store: stage.store,
        targets: &targets,
        threads: stage.threads,
        runner: stage.runner,
        out: stage.out,
        progress: stage.progress,
        screen: &off,
    };
    let problem = own.problem(fixed, Vec::new());
    let seeds = crate::ego::seeds_of(&best.seeds);
    if stage.progress {
        log::info!(
            "held out: shot {} at the calibrated point ({})",
            held.targets.shot.id,
            crate::problem::fmt_params(&best.params)
        );
    }
    let (mut evs, _) = crate::ego::run_points(
        &problem,
        EvalStage::HeldOut,
        std::slice::from_ref(&best.params),
        &seeds,
    )?;
    let (evaluation, observables) = evs
        .pop()
        .ok_or_else(|| RunError::Input("the held-out shot has no evaluation".to_string()))?;
    Ok(HeldOut {
        shot: ShotUse::of(&held.targets),
        targets: held.targets.targets.clone(),
        spread: crate::ego::spread_of(&problem, &observables),
        evaluation,
    })
}

/// The study as a calibration against `targets`' shot plans it: the shot's keys that the
/// study's scene leaves out added to `study.set`, after checking that every key it gives
/// agrees with the shot (`tier`: the tier asked, None for the default; `sets`: the command
/// line's `--set`).
pub fn study_for_shot(
    study: &Study,
    tier: Option<&str>,
    sets: &[String],
    targets: &Targets,
) -> Result<Study> {
    let shot = &targets.shot;
    let keys = shot.impact_keys();
    for a in &study.axes {
        if let Some(k) = keys.iter().find(|k| k.key == a.key) {
            bail!(
                "study axis `{}` varies the shot's {} (shot `{}` in {} defines it: {} {}); a \
                 calibration runs each shot at its own impact (allowed: axes over the model's \
                 parameters; for other conditions, a shot file of their own)",
                a.key,
                k.what,
                shot.id,
                targets.path.display(),
                k.value,
                k.unit
            );
        }
    }
    let given = given_values(study, tier, sets, &keys)?;
    let mut disagree = Vec::new();
    let mut fill = Vec::new();
    for (k, g) in keys.iter().zip(&given) {
        match g {
            Some((value, from)) if !k.agrees(*value) => disagree.push(format!(
                "  {} = {} ({from}), the shot's {} = {}{}",
                k.key,
                with_unit(*value, k.unit),
                k.what,
                with_unit(k.value, k.unit),
                offset_note(targets, k)
            )),
            Some(_) => {}
            None => fill.push(format!(
                "{}={}",
                k.key,
                json_to_override(&serde_json::json!(k.value))?
            )),
        }
    }
    if !disagree.is_empty() {
        bail!(
            "shot `{}` ({}) defines the impact its targets were measured at, and the study's \
             scene disagrees with it:\n{}\nThe shot's keys come from the shot: remove them from \
             the scene (they are then set from the shot) or make them agree; for another \
             impact, write a shot file of its own (docs/calibration.md, \"Your own shots\")",
            shot.id,
            targets.path.display(),
            disagree.join("\n")
        );
    }
    check_kind(study, tier, sets)?;
    let mut study = study.clone();
    study.set.extend(fill);
    Ok(study)
}

/// A value with its unit as messages print it: `6700 m/s`, `0.425`, `3.2e-5 s`.
fn with_unit(v: f64, unit: &str) -> String {
    let n = if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e6) {
        format!("{v:e}")
    } else {
        format!("{v}")
    };
    if unit == "-" {
        n
    } else {
        format!("{n} {unit}")
    }
}

/// " (simulated at the documented offset; the experiment's 6500)" when the shot is simulated
/// away from the experiment on this key.
fn offset_note(targets: &Targets, k: &ImpactKey) -> String {
    let shot = &targets.shot;
    let experiment = match k.key {
        "scene.v0_m_s" => shot.v0_m_s,
        "scene.t_over_d" => shot.t_over_d,
        _ => return String::new(),
    };
    if k.agrees(experiment) {
        String::new()
    } else {
        format!(" (its documented offset, [shot.simulated]; the experiment's {experiment})")
    }
}

/// The sources of a study's scene values, in the order they apply.
fn sources(
    study: &Study,
    tier: Option<&str>,
    sets: &[String],
) -> Result<Vec<(String, Vec<String>)>> {
    let tier = study.tier(tier)?;
    Ok(vec![
        ("study.set".to_string(), study.set.clone()),
        (format!("the tier `{}`'s set", tier.name), tier.set.clone()),
        ("--set".to_string(), sets.to_vec()),
    ])
}

/// The value each key takes in the study's scene, with where it came from (None: the scene
/// leaves it out).
fn given_values(
    study: &Study,
    tier: Option<&str>,
    sets: &[String],
    keys: &[ImpactKey],
) -> Result<Vec<Option<(f64, String)>>> {
    let mut doc: toml::Table = toml::from_str(&study.scene_text)?;
    let mut given: Vec<Option<(f64, String)>> = keys
        .iter()
        .map(|k| {
            number_at(&doc, k.key)
                .map(|v| (v, format!("the scene file {}", study.scene_path.display())))
        })
        .collect();
    for (what, overrides) in sources(study, tier, sets)? {
        apply_overrides(&mut doc, &overrides)?;
        for (k, g) in keys.iter().zip(given.iter_mut()) {
            if overrides.iter().any(|s| override_key(s) == k.key) {
                *g = number_at(&doc, k.key).map(|v| (v, what.clone()));
            }
        }
    }
    Ok(given)
}

/// A numeric value at `section.key` of a scene document.
fn number_at(doc: &toml::Table, key: &str) -> Option<f64> {
    let (section, field) = key.split_once('.')?;
    match doc.get(section)?.get(field)? {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// A shot is a sphere striking a plate.
fn check_kind(study: &Study, tier: Option<&str>, sets: &[String]) -> Result<()> {
    let mut doc: toml::Table = toml::from_str(&study.scene_text)?;
    for (_, overrides) in sources(study, tier, sets)? {
        apply_overrides(&mut doc, &overrides)?;
    }
    let kind = doc
        .get("scene")
        .and_then(|s| s.get("kind"))
        .and_then(|k| k.as_str());
    if kind != Some("sphere_on_plate") {
        bail!(
            "scene.kind = {kind:?}: a shot is a sphere striking a plate (allowed: \
             \"sphere_on_plate\")"
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::{Path, PathBuf};

    fn repo() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
    }

    fn shot(file: &str) -> Targets {
        hvi_run::output::load_targets(&repo().join("experiments_data").join(file)).expect(file)
    }

    #[test]
    fn the_papers_shot_agrees_with_the_paper_and_its_study() {
        use hvi_engine::paper;
        let t = shot("calibration-shot.toml");
        assert_eq!(t.shot.v0_m_s, paper::CALIBRATION_SHOT_V0_M_S);
        assert_eq!(t.shot.t_over_d, paper::CALIBRATION_SHOT_T_OVER_D);
        assert_eq!(t.shot.simulated_v0_m_s(), paper::CALIBRATION_V0_M_S);
        assert_eq!(t.shot.simulated_t_over_d(), paper::CALIBRATION_T_OVER_D);
        assert_eq!(t.shot.impactor_diameter_m, paper::IMPACTOR_DIAMETER_M);
        let r = t.targets.iter().find(|x| x.name == "length_ratio");
        assert_eq!(
            r.map(|x| x.value),
            Some(paper::CALIBRATION_SHOT_LENGTH_RATIO)
        );
        // The calibration study's scene states every key, in agreement: nothing is added.
        let study = Study::load(&repo().join("studies/calibration.toml")).expect("study");
        let s = study_for_shot(&study, None, &[], &t).expect("agrees");
        assert_eq!(s.set, study.set);
    }

    #[test]
    fn a_scene_that_disagrees_with_the_shot_is_refused_naming_both_values() {
        let study = Study::load(&repo().join("studies/calibration.toml")).expect("study");
        // The paper's study against a user's shot at 5 km/s, t/D 0.2, D 6.35 mm.
        let e = study_for_shot(&study, None, &[], &shot("examples/synthetic-al-5kms.toml"))
            .expect_err("6.7 km/s against 5 km/s");
        let e = format!("{e:#}");
        for needle in [
            "scene.v0_m_s = 6700",
            "the shot's v0 = 5000",
            "scene.t_over_d = 0.425 (",
            "the shot's t/D = 0.2\n",
            "scene.diameter_m = 9.53e-3 m",
            "studies/scenes/calibration.toml",
            "synthetic-al-5kms",
            // The observation time (20 us) against the scene's 32 us.
            "run.end_time_s = 3.2e-5 s",
        ] {
            assert!(e.contains(needle), "`{needle}` missing from: {e}");
        }
        // A --set that moves the paper's shot is blamed on the --set, with the offset named.
        let e = study_for_shot(
            &study,
            None,
            &["scene.v0_m_s=6500".into()],
            &shot("calibration-shot.toml"),
        )
        .expect_err("6500 is the experiment's, not the simulated 6700");
        let e = format!("{e:#}");
        assert!(e.contains("scene.v0_m_s = 6500 m/s (--set)"), "{e}");
        assert!(e.contains("documented offset"), "{e}");
    }

    #[test]
    fn a_scene_without_the_impact_gets_it_from_the_shot_and_an_axis_over_it_is_refused() {
        let dir = std::env::temp_dir().join(format!("hvi-shots-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        std::fs::write(
            dir.join("base.toml"),
            "[scene]\nkind = \"sphere_on_plate\"\n\n[resolution]\nparticles = 2000\n\n\
             [material]\neps_j = 0.01\nkappa_n_m = 4.56e6\n",
        )
        .expect("scene");
        let study_text = |axes: &str| {
            format!(
                "[study]\nname = \"s\"\nscene = \"base.toml\"\n{axes}\n[tiers.quick]\nset = []\n"
            )
        };
        std::fs::write(dir.join("s.toml"), study_text("")).expect("study");
        let study = Study::load(&dir.join("s.toml")).expect("study");
        let t = shot("examples/synthetic-al-5kms.toml");
        let s = study_for_shot(&study, None, &[], &t).expect("filled");
        for (key, want) in [
            ("scene.diameter_m", 6.35e-3),
            ("scene.v0_m_s", 5000.0),
            ("scene.t_over_d", 0.2),
            ("run.end_time_s", 20e-6),
        ] {
            let got = s
                .set
                .iter()
                .filter_map(|x| x.split_once('='))
                .find(|(k, _)| *k == key)
                .and_then(|(_, v)| v.parse::<f64>().ok());
            assert_eq!(got, Some(want), "{key} in {:?}", s.set);
        }
        // The filled study plans: its scene is the shot's impact.
        let scene = hvi_store::plan::validated_scene(&s, &s.set).expect("scene");
        assert_eq!(scene.scene.v0_m_s(), 5000.0);
        // A steel sphere on the same plate: each body gets its own density.
        let mut steel = t.clone();
        steel.shot.impactor_density_kg_m3 = Some(7850.0);
        steel.shot.plate_density_kg_m3 = Some(2700.0);
        let s = study_for_shot(&study, None, &[], &steel).expect("two densities");
        let scene = hvi_store::plan::validated_scene(&s, &s.set).expect("scene");
        assert_eq!(scene.impactor.density_kg_m3, Some(7850.0));
        let setup = scene.build().expect("builds");
        assert_eq!(setup.derived.density_kg_m3, 2700.0);
        assert_eq!(setup.derived.impactor_density_kg_m3(), 7850.0);
        std::fs::write(
            dir.join("s.toml"),
            study_text("[[axes]]\nkey = \"scene.v0_m_s\"\nvalues = [4000, 5000]\n"),
        )
        .expect("study");
        let study = Study::load(&dir.join("s.toml")).expect("study");
        let e = study_for_shot(&study, None, &[], &t).expect_err("an axis over v0");
        assert!(
            format!("{e:#}").contains("study axis `scene.v0_m_s`"),
            "{e:#}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
