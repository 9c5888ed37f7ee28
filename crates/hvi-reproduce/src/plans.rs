//! The reproduction's plans: every run of every figure of a tier, validated before anything
//! runs, and the tier's expected cost. Figs. 7, 9, 10 and 16, 17 plan existing study files;
//! Figs. 4, 5, 11-12 and 13 plan studies that live only in memory.

use std::path::{Path, PathBuf};

use hvi_engine::paper;
use hvi_run::error::{Result, ResultExt, RunError};
use rayon::prelude::*;

use crate::config::{
    Config, ConvergenceConfig, EstimateConfig, FrontVelocityConfig, SizingConfig, StudyRef,
};
use crate::report::{Estimate, EstimateRow};
use crate::sizing;
use hvi_store::plan::{build_plan, Plan, PlanRequest};
use hvi_store::spec::{json_to_override, Axis, Study, Tier};

/// The plans of a tier: every run of every figure, validated.
#[derive(Debug, Clone)]
pub struct Plans {
    /// The calibration study file.
    pub calibration_study: PathBuf,
    /// Figs. 7, 9, 10.
    pub calibration: Plan,
    /// The validity-map study file.
    pub validity_study: PathBuf,
    /// Figs. 16, 17.
    pub validity: Plan,
    /// Fig. 4.
    pub sizing: Plan,
    /// Fig. 5, Figs. 11-12.
    pub convergence: Plan,
    /// Fig. 13.
    pub front_velocity: Plan,
}

impl Plans {
    /// (stage, figures, plan) in the order the stages run.
    pub fn stages(&self) -> [(&'static str, &'static str, &Plan); 5] {
        [
            ("sizing", "4", &self.sizing),
            ("convergence", "5, 11, 12", &self.convergence),
            ("calibration", "7, 9, 10", &self.calibration),
            ("front-velocity", "13", &self.front_velocity),
            ("validity-map", "16, 17", &self.validity),
        ]
    }
}

/// Plans every study of a tier (nothing is written, nothing runs). Every run's scene is built
/// by the engine, so a bad value fails here, naming the key.
pub fn build_plans(config: &Config, tier_name: &str) -> Result<Plans> {
    let t = config.tier(tier_name)?;
    let p = Planner { config, tier_name };
    let (calibration_study, calibration) = p.study_file("calibration", &t.calibration)?;
    let (validity_study, validity) = p.study_file("validity", &t.validity)?;
    let sizing = p.sizing(&t.sizing)?;
    let cal_n = calibration_particles(&calibration, tier_name)?;
    let convergence = p.convergence(&t.convergence, cal_n)?;
    let front_velocity = p.front_velocity(&t.front_velocity)?;
    Ok(Plans {
        calibration_study,
        calibration,
        validity_study,
        validity,
        sizing,
        convergence,
        front_velocity,
    })
}

/// Plans the studies of one tier of the config; errors name the tier's key.
struct Planner<'a> {
    config: &'a Config,
    tier_name: &'a str,
}

impl Planner<'_> {
    /// An existing study file at the tier its reference names.
    fn study_file(&self, what: &str, r: &StudyRef) -> Result<(PathBuf, Plan)> {
        let path = self.config.resolve(&r.study);
        let study = Study::load(&path)?;
        let request = PlanRequest {
            tier: Some(r.tier.clone()),
            particles: r.particles,
            set: r.set.clone(),
        };
        let plan = build_plan(&study, &request).with_context(|| self.key(what))?;
        Ok((path, plan))
    }

    /// A study of [`Planner::memory_study`] at this tier with overrides `set`.
    fn memory_plan(&self, what: &str, study: &Study, set: Vec<String>) -> Result<Plan> {
        let request = PlanRequest {
            tier: Some(self.tier_name.to_string()),
            particles: None,
            set,
        };
        build_plan(study, &request).with_context(|| self.key(what))
    }

    fn key(&self, what: &str) -> String {
        format!(
            "{}: tiers.{}.{what}",
            self.config.path.display(),
            self.tier_name
        )
    }

    /// A study that lives only in memory: a base scene, axes and one tier without overrides
    /// (the overrides go through the plan request, which keeps them off the axes).
    fn memory_study(
        &self,
        (name, description): (&str, &str),
        (scene_path, scene_text): (PathBuf, String),
        axes: Vec<Axis>,
    ) -> Study {
        let tier = self.tier_name;
        let mut tiers = std::collections::BTreeMap::new();
        tiers.insert(
            tier.to_string(),
            Tier {
                name: tier.to_string(),
                description: format!("`hvi-study reproduce --tier {tier}`"),
                set: Vec::new(),
            },
        );
        Study {
            name: name.into(),
            description: description.into(),
            path: self.config.path.clone(),
            scene_path,
            scene_text,
            set: Vec::new(),
            axes,
            tiers,
            default_tier: tier.to_string(),
            calibrate: None,
            validity: None,
        }
    }

    /// A scene file of the config: its resolved path and its text.
    fn scene(&self, p: &Path) -> Result<(PathBuf, String)> {
        let path = self.config.resolve(p);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read scene file {}", path.display()))?;
        Ok((path, text))
    }

    /// Fig. 4: the plates at each count, without and with sizing.
    fn sizing(&self, c: &SizingConfig) -> Result<Plan> {
        let mut counts = c.particles.clone();
        counts.sort_by(f64::total_cmp);
        counts.dedup();
        let study = self.memory_study(
            (
                "sizing",
                "Fig. 4: colliding plates with and without geometric sizing",
            ),
            (
                // A fixed label (not a path), as stored plans name it since it was written.
                PathBuf::from("hvi_study::reproduce::sizing::plates_scene"),
                sizing::plates_scene_toml(counts[0], true)?,
            ),
            vec![
                Axis {
                    key: "material.sizing".into(),
                    values: vec![serde_json::json!(false), serde_json::json!(true)],
                    label: "sizing".into(),
                },
                Axis {
                    key: "resolution.particles".into(),
                    values: numbers(counts),
                    label: "particles".into(),
                },
            ],
        );
        self.memory_plan("sizing", &study, c.set.clone())
    }

    /// Fig. 5 and Figs. 11-12: the best fit on the calibration scene at the counts of
    /// [`convergence_counts`].
    fn convergence(&self, c: &ConvergenceConfig, calibration_particles: f64) -> Result<Plan> {
        let study = self.memory_study(
            (
                "convergence",
                "Fig. 5 (F against particle count) and Figs. 11-12 (its finest run): the paper's best fit on the calibration scene",
            ),
            self.scene(&c.scene)?,
            vec![Axis {
                key: "resolution.particles".into(),
                values: numbers(convergence_counts(calibration_particles, &c.fractions)),
                label: "particles".into(),
            }],
        );
        let mut set = best_fit()?;
        set.extend(c.set.iter().cloned());
        self.memory_plan("convergence", &study, set)
    }

    /// Fig. 13: va/v0 against t/D at the paper's velocity, best fit.
    fn front_velocity(&self, c: &FrontVelocityConfig) -> Result<Plan> {
        let study = self.memory_study(
            (
                "front-velocity",
                "Fig. 13: va/v0 against t/D at the paper's velocity, best fit",
            ),
            self.scene(&c.scene)?,
            vec![Axis {
                key: "scene.t_over_d".into(),
                values: numbers(c.t_over_d.iter().copied()),
                label: "t/D".into(),
            }],
        );
        let mut set = vec![set_of("scene.v0_m_s", paper::FIG13_V0_M_S)?];
        set.extend(best_fit()?);
        set.extend(c.set.iter().cloned());
        self.memory_plan("front_velocity", &study, set)
    }
}

/// The calibration's particle count, which Fig. 5's series scales.
fn calibration_particles(calibration: &Plan, tier_name: &str) -> Result<f64> {
    calibration
        .runs
        .first()
        .and_then(|r| r.scene.resolution.particles)
        .ok_or_else(|| {
            RunError::Input(format!(
                "tiers.{tier_name}.calibration: its runs set resolution.particles_across_d; Fig. 5 \
                 scales the calibration's particle count, so it needs resolution.particles"
            ))
        })
}

/// Fig. 5's counts: the calibration's count `cal_n` times each of `fractions`, times 1, and
/// times the paper's final-over-calibration ratio; rounded, sorted, without repeats.
fn convergence_counts(cal_n: f64, fractions: &[f64]) -> Vec<f64> {
    let mut counts: Vec<f64> = fractions
        .iter()
        .map(|f| (cal_n * f).round())
        .chain([
            cal_n.round(),
            (cal_n * paper::FINAL_PARTICLES / paper::CALIBRATION_PARTICLES).round(),
        ])
        .collect();
    counts.sort_by(f64::total_cmp);
    counts.dedup();
    counts
}

fn numbers(values: impl IntoIterator<Item = f64>) -> Vec<serde_json::Value> {
    values.into_iter().map(|v| serde_json::json!(v)).collect()
}

fn set_of(key: &str, v: f64) -> Result<String> {
    Ok(format!(
        "{key}={}",
        json_to_override(&serde_json::json!(v))?
    ))
}

/// The paper's best-fit material as overrides.
fn best_fit() -> Result<Vec<String>> {
    Ok(vec![
        set_of("material.eps_j", paper::BEST_EPS_J)?,
        set_of("material.kappa_n_m", paper::BEST_KAPPA_N_M)?,
        set_of("material.rcut_over_sigma", paper::BEST_RCUT_OVER_SIGMA)?,
    ])
}

/// The cost of a tier: per stage, the sum over runs of particles x base steps (each scene
/// built by the engine, so the base step is the one it would run with) over `[estimate]`'s
/// throughput in the same unit (whole runs with the adaptive step).
pub fn estimate(plans: &Plans, tier: &str, cfg: &EstimateConfig) -> Result<Estimate> {
    let mut rows = Vec::new();
    for (stage, figures, plan) in plans.stages() {
        let costs: Vec<(usize, f64)> = plan
            .runs
            .par_iter()
            .map(|r| hvi_store::exec::run_cost(&r.scene))
            .collect::<hvi_run::error::Result<_>>()?;
        let particle_steps: f64 = costs.iter().map(|c| c.1).sum();
        rows.push(EstimateRow {
            stage: stage.into(),
            figures: figures.into(),
            runs: costs.len(),
            particles: (
                costs.iter().map(|c| c.0).min().unwrap_or(0),
                costs.iter().map(|c| c.0).max().unwrap_or(0),
            ),
            particle_steps,
            seconds: particle_steps / cfg.particle_steps_per_second,
        });
    }
    Ok(Estimate {
        tier: tier.into(),
        rows,
        particle_steps_per_second: cfg.particle_steps_per_second,
        cores: cfg.cores,
        source: cfg.source.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn convergence_counts_scale_the_calibration_count_and_end_at_the_final_ratio() {
        let n = convergence_counts(1000.0, &[0.5, 0.25, 1.0]);
        let last = (1000.0 * paper::FINAL_PARTICLES / paper::CALIBRATION_PARTICLES).round();
        assert_eq!(n, vec![250.0, 500.0, 1000.0, last]);
    }
}
