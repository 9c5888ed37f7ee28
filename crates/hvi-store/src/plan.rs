//! The validated plan: every run of a study at one tier, with its full scene, its fingerprint
//! and its directory, checked before anything runs and written as `plan.json`.
//!
//! Overrides apply in this order: the study's `set`, the tier's `set`, the command line's
//! `--set`, `--particles`, then the run's axis values. An axis key may not appear in any of the
//! others (the study parser and [`build_plan`] reject it), so order only matters among fixed
//! overrides, where the later one wins.

use std::path::{Path, PathBuf};

use hvi_engine::scene::SceneSpec;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::spec::{json_to_override, override_key, Axis, Study, Tier};
use hvi_run::error::{Result, ResultExt, RunError};
use hvi_run::files::write_atomic_bytes;
use hvi_run::scene_file::parse_scene;

pub use hvi_run::files::{canonical_json, DIR_DIGITS, ENGINE_VERSION, STUDY_FORMAT_VERSION};

/// One run of a plan.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PlannedRun {
    /// Position in the plan (`hvi-study run-unit PLAN INDEX`).
    pub index: usize,
    /// Index into each axis's values.
    pub coords: Vec<usize>,
    /// The axis values, one per axis (same order as `Plan::axes`).
    pub values: Vec<serde_json::Value>,
    /// Every override applied to the base scene, in order.
    pub set: Vec<String>,
    /// SHA-256 of the canonical JSON of what determines the result ([`fingerprint`]).
    pub fingerprint: String,
    /// The run's directory, relative to the plan's directory.
    pub dir: String,
    /// The scene as it will run.
    pub scene: SceneSpec,
}

/// A study expanded at one tier.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Plan {
    /// [`STUDY_FORMAT_VERSION`].
    pub format: u32,
    /// The study's name.
    pub study: String,
    /// What it is.
    pub description: String,
    /// The study file.
    pub study_file: PathBuf,
    /// The base scene file.
    pub base_scene: PathBuf,
    /// The tier's name.
    pub tier: String,
    /// The tier's description.
    pub tier_description: String,
    /// Overrides common to every run (study, tier, command line), in order.
    pub set: Vec<String>,
    /// The axes.
    pub axes: Vec<Axis>,
    /// [`ENGINE_VERSION`].
    pub engine_version: String,
    /// The runs, the last axis varying fastest.
    pub runs: Vec<PlannedRun>,
}

/// What to plan: the tier and the command line's extra overrides.
#[derive(Debug, Clone, Default)]
pub struct PlanRequest {
    /// Tier name (default: the study's default tier).
    pub tier: Option<String>,
    /// `--particles N`: overrides `resolution.particles` after the tier.
    pub particles: Option<f64>,
    /// `--set KEY=VALUE` overrides, after the tier.
    pub set: Vec<String>,
}

/// The fingerprint of a run: SHA-256 (hex) of the canonical JSON of the format version, the
/// engine version, the tier and the full scene as run (which holds every parameter, the
/// resolution and the seed). Two runs with the same fingerprint give the same result.
pub fn fingerprint(scene: &SceneSpec, tier: &str) -> Result<String> {
    digest(scene, tier, ENGINE_VERSION)
}

/// The fingerprint of what a run simulates: [`fingerprint`] of its scene with the analysis
/// settings that only say how the cloud is measured at their defaults
/// ([`hvi_engine::scene::Analysis::as_simulated`]), for a run of `engine_version`. Runs with
/// the same key simulate the same thing and keep the same states; only their measurements
/// differ (the store measures one from the other's kept state, [`crate::store`]).
pub fn simulation_key(scene: &SceneSpec, tier: &str, engine_version: &str) -> Result<String> {
    let mut simulated = scene.clone();
    simulated.analysis = scene.analysis.as_simulated();
    digest(&simulated, tier, engine_version)
}

/// SHA-256 (hex) of the canonical JSON of the format version, `engine_version`, the tier and
/// the scene.
fn digest(scene: &SceneSpec, tier: &str, engine_version: &str) -> Result<String> {
    let doc = serde_json::json!({
        "format": STUDY_FORMAT_VERSION,
        "engine_version": engine_version,
        "tier": tier,
        "scene": serde_json::to_value(scene).context("scene as JSON")?,
    });
    let digest = Sha256::digest(canonical_json(&doc).as_bytes());
    Ok(digest.iter().map(|b| format!("{b:02x}")).collect())
}

/// The directory of a run with this fingerprint, relative to the study's output directory.
pub fn run_dir_name(fingerprint: &str) -> String {
    format!("runs/{}", &fingerprint[..DIR_DIGITS.min(fingerprint.len())])
}

/// Describes a run's axis values, e.g. `material.eps_j=0.01, material.kappa_n_m=4560000.0`.
pub fn describe_values(axes: &[Axis], values: &[serde_json::Value]) -> String {
    axes.iter()
        .zip(values)
        .map(|(a, v)| format!("{}={v}", a.key))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Parses the base scene with overrides and checks every value with the engine (which lays
/// out the particles, so a check costs about a run's set-up).
pub fn validated_scene(study: &Study, set: &[String]) -> Result<SceneSpec> {
    let spec = parse_scene(&study.scene_text, set)?;
    spec.build()?;
    Ok(spec)
}

/// One run of the grid before its scene is checked: coordinates, axis values, overrides.
struct Draft {
    coords: Vec<usize>,
    values: Vec<serde_json::Value>,
    set: Vec<String>,
}

/// Expands a study at a tier into a validated plan. Every run's scene is built and checked
/// before this returns; the first errors (up to five distinct ones) are reported together,
/// each naming the key and the run.
pub fn build_plan(study: &Study, req: &PlanRequest) -> Result<Plan> {
    let tier = study.tier(req.tier.as_deref())?;
    let common = common_overrides(study, tier, req)?;
    let drafts = grid(study, &common)?;
    let scenes = checked_scenes(study, tier, &drafts)?;
    let mut runs = Vec::with_capacity(drafts.len());
    for (index, (draft, scene)) in drafts.into_iter().zip(scenes).enumerate() {
        let fp = fingerprint(&scene, &tier.name)?;
        runs.push(PlannedRun {
            index,
            coords: draft.coords,
            values: draft.values,
            set: draft.set,
            dir: run_dir_name(&fp),
            fingerprint: fp,
            scene,
        });
    }
    Ok(Plan {
        format: STUDY_FORMAT_VERSION,
        study: study.name.clone(),
        description: study.description.clone(),
        study_file: absolute(&study.path),
        base_scene: absolute(&study.scene_path),
        tier: tier.name.clone(),
        tier_description: tier.description.clone(),
        set: common,
        axes: study.axes.clone(),
        engine_version: ENGINE_VERSION.to_string(),
        runs,
    })
}

/// The overrides every run gets, in order: the study's, the tier's, the command line's
/// `--set` and `--particles` (neither may name an axis).
fn common_overrides(study: &Study, tier: &Tier, req: &PlanRequest) -> Result<Vec<String>> {
    let mut common: Vec<String> = study.set.clone();
    common.extend(tier.set.iter().cloned());
    for s in &req.set {
        let k = override_key(s);
        if study.axes.iter().any(|a| a.key == k) {
            return Err(RunError::Input(format!(
                "--set `{s}`: `{k}` is an axis of this study (allowed: keys that are not axes)"
            )));
        }
        common.push(s.clone());
    }
    if let Some(n) = req.particles {
        if !(n.is_finite() && n >= 8.0) {
            return Err(RunError::Input(format!(
                "invalid value for `--particles`: {n} (allowed: a number >= 8)"
            )));
        }
        if study.axes.iter().any(|a| a.key == "resolution.particles") {
            return Err(RunError::Input(
                "--particles: `resolution.particles` is an axis of this study".into(),
            ));
        }
        common.push(format!("resolution.particles={n}"));
    }
    Ok(common)
}

/// The grid's runs, the last axis fastest: each run's coordinates, its axis values, and the
/// `common` overrides followed by its axis values.
fn grid(study: &Study, common: &[String]) -> Result<Vec<Draft>> {
    let mut drafts = Vec::new();
    for index in 0..study.grid_len() {
        let mut coords = vec![0; study.axes.len()];
        let mut rest = index;
        for (k, a) in study.axes.iter().enumerate().rev() {
            coords[k] = rest % a.values.len();
            rest /= a.values.len();
        }
        let mut set = common.to_vec();
        let mut values = Vec::new();
        for (a, &c) in study.axes.iter().zip(&coords) {
            let v = &a.values[c];
            set.push(format!("{}={}", a.key, json_to_override(v)?));
            values.push(v.clone());
        }
        drafts.push(Draft {
            coords,
            values,
            set,
        });
    }
    Ok(drafts)
}

/// Every draft's scene, built and checked by the engine (in parallel: at high tiers each build
/// lays out the lattice). Any invalid scene fails the plan, with up to five distinct errors.
fn checked_scenes(study: &Study, tier: &Tier, drafts: &[Draft]) -> Result<Vec<SceneSpec>> {
    let checked: Vec<Result<SceneSpec>> = drafts
        .par_iter()
        .map(|d| validated_scene(study, &d.set))
        .collect();
    let mut errors: Vec<String> = Vec::new();
    let mut n_bad = 0;
    for (i, r) in checked.iter().enumerate() {
        if let Err(e) = r {
            n_bad += 1;
            let msg = format!("{e:#}");
            if errors.len() < 5 && !errors.iter().any(|m| m.ends_with(&msg)) {
                let what = describe_values(&study.axes, &drafts[i].values);
                errors.push(format!("run {i} ({what}): {msg}"));
            }
        }
    }
    if n_bad > 0 {
        return Err(RunError::Input(format!(
            "study `{}` at tier `{}`: {n_bad} of {} runs have invalid scenes; nothing was run:\n  {}",
            study.name,
            tier.name,
            drafts.len(),
            errors.join("\n  ")
        )));
    }
    checked.into_iter().collect()
}

fn absolute(p: &Path) -> PathBuf {
    std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf())
}

impl Plan {
    /// Writes `plan.json` into `dir` atomically. Refuses a directory that holds another
    /// study's or tier's plan, so results of different studies never mix.
    pub fn write(&self, dir: &Path) -> Result<PathBuf> {
        std::fs::create_dir_all(dir).write_context(dir, || {
            format!("cannot create study directory {}", dir.display())
        })?;
        // One planning process per study directory: a second waits (crate::lock).
        crate::lock::hold_study(dir)?;
        let path = dir.join("plan.json");
        if path.exists() {
            // Only the study and tier matter here: an older plan (another engine version, its
            // fingerprints stale) is replaced; its runs stay in the store under their own
            // fingerprints and are simply not reused.
            #[derive(Deserialize)]
            struct Header {
                study: String,
                tier: String,
            }
            let old: Header = std::fs::read_to_string(&path)
                .ok()
                .and_then(|t| serde_json::from_str(&t).ok())
                .ok_or_else(|| {
                    RunError::Store(format!(
                        "{} holds something that is not a plan; move it away or use another --out",
                        path.display()
                    ))
                })?;
            if old.study != self.study || old.tier != self.tier {
                return Err(RunError::Store(format!(
                    "{} holds study `{}` at tier `{}`, not `{}` at `{}`: use another --out",
                    dir.display(),
                    old.study,
                    old.tier,
                    self.study,
                    self.tier
                )));
            }
        }
        write_atomic_bytes(&path, serde_json::to_string_pretty(self)?.as_bytes())?;
        Ok(path)
    }

    /// Reads a `plan.json`, and checks that every run's fingerprint matches its scene (a plan
    /// edited by hand, or written by another version, is refused).
    pub fn load(path: &Path) -> Result<Plan> {
        let text = std::fs::read_to_string(path)
            .read_context(path, || format!("cannot read plan {}", path.display()))?;
        let plan: Plan = serde_json::from_str(&text).map_err(|e| RunError::Parse {
            message: format!("{} is not a plan.json", path.display()),
            source: Some(Box::new(e)),
        })?;
        if plan.format != STUDY_FORMAT_VERSION {
            return Err(RunError::parse(format!(
                "{}: plan format {} (this hvi-study reads {STUDY_FORMAT_VERSION}); plan the study again",
                path.display(),
                plan.format
            )));
        }
        for r in &plan.runs {
            let fp = fingerprint(&r.scene, &plan.tier)?;
            if fp != r.fingerprint {
                return Err(RunError::Store(format!(
                    "{}: run {} has fingerprint {} but its scene hashes to {fp} (edited plan, or \
                     another engine version {}); plan the study again",
                    path.display(),
                    r.index,
                    r.fingerprint,
                    plan.engine_version
                )));
            }
        }
        Ok(plan)
    }

    /// The run at `index`, or an error naming the valid range.
    pub fn run(&self, index: usize) -> Result<&PlannedRun> {
        self.runs.get(index).ok_or_else(|| {
            RunError::Input(format!(
                "invalid run index {index}: this plan has {} runs (allowed: 0..={})",
                self.runs.len(),
                self.runs.len().saturating_sub(1)
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonical_json_sorts_keys_at_every_level() {
        let a = serde_json::json!({"b": 1, "a": {"y": [1.5, "x"], "x": null}});
        assert_eq!(
            canonical_json(&a),
            r#"{"a":{"x":null,"y":[1.5,"x"]},"b":1}"#
        );
    }

    #[test]
    fn fingerprint_follows_the_scene_and_the_tier() {
        let text = "[scene]\nkind = \"sphere_on_plate\"\ndiameter_m = 1e-2\nt_over_d = 0.4\nv0_m_s = 6000\n[resolution]\nparticles = 500\n[material]\n";
        let a = parse_scene(text, &[]).expect("scene");
        let b = parse_scene(text, &["material.eps_j=0.1".into()]).expect("scene");
        let fa = fingerprint(&a, "quick").expect("fp");
        assert_eq!(fa.len(), 64);
        assert_eq!(fa, fingerprint(&a.clone(), "quick").expect("fp"));
        assert_ne!(fa, fingerprint(&b, "quick").expect("fp"));
        assert_ne!(fa, fingerprint(&a, "paper").expect("fp"));
        // R's reading is part of the run: a store never serves one reading's record as the
        // other's.
        let c = parse_scene(text, &["analysis.width=cylindrical".into()]).expect("scene");
        assert_ne!(fa, fingerprint(&c, "quick").expect("fp"));
        let json = serde_json::to_value(&a).expect("json");
        assert_eq!(
            json["analysis"]["width"], "side",
            "written even at its default"
        );
        // A scene survives the JSON round trip of plan.json with the same fingerprint.
        let back: SceneSpec =
            serde_json::from_str(&serde_json::to_string(&a).expect("json")).expect("back");
        assert_eq!(fa, fingerprint(&back, "quick").expect("fp"));
    }

    #[test]
    fn the_simulation_key_ignores_exactly_the_measurement_keys() {
        use hvi_engine::scene::MEASUREMENT_KEYS;
        let text = "[scene]\nkind = \"sphere_on_plate\"\ndiameter_m = 1e-2\nt_over_d = 0.4\nv0_m_s = 6000\n[resolution]\nparticles = 500\n[material]\n";
        let key = |set: &[&str]| {
            let set: Vec<String> = set.iter().map(|s| s.to_string()).collect();
            let scene = parse_scene(text, &set).expect("scene");
            (
                fingerprint(&scene, "quick").expect("fp"),
                simulation_key(&scene, "quick", ENGINE_VERSION).expect("key"),
            )
        };
        let (fp0, key0) = key(&[]);
        // A value other than the default for every measurement key, and keep_state off: each
        // is another run (fingerprint) of the same simulation (key).
        let others = [
            "analysis.quantile=0.95",
            "analysis.width=cylindrical",
            "analysis.shadowgraph_pixel_m=1e-3",
            "analysis.shadowgraph_blur_m=1e-3",
            "analysis.shadowgraph_grain_m=1e-3",
            "analysis.shadowgraph_optical_depth=0.5",
            "analysis.witness_standoff_m=0.05",
            "analysis.keep_state=false",
        ];
        for (k, set) in MEASUREMENT_KEYS.iter().zip(&others) {
            assert!(set.starts_with(&format!("{k}=")), "{k} has its case");
        }
        for set in others {
            let (fp, key) = key(&[set]);
            assert_ne!(fp, fp0, "{set}: another run");
            assert_eq!(key, key0, "{set}: the same simulation");
        }
        assert_eq!(key(&others).1, key0, "all of them at once");
        // What the run keeps or simulates differently is another simulation.
        for set in [
            "analysis.front_times_s=[1e-6, 2e-6]",
            "analysis.track_every=50",
            "material.eps_j=0.1",
            "run.seed=7",
        ] {
            assert_ne!(key(&[set]).1, key0, "{set}: another simulation");
        }
        let scene = parse_scene(text, &[]).expect("scene");
        assert_ne!(
            key0,
            simulation_key(&scene, "paper", ENGINE_VERSION).expect("key")
        );
        assert_ne!(key0, simulation_key(&scene, "quick", "0.0.1").expect("key"));
    }
}
