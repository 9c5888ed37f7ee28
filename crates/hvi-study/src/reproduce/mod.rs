//! `hvi-study reproduce`: every figure of Watson & Steinhauser (2017) regenerated through the
//! study runner and its store, and a report that puts the paper's result beside ours.
//!
//! ```text
//! studies/reproduce.toml (tier) --(config)--> plans of five studies, every scene validated
//!   sizing (Fig. 4), convergence (Figs. 5, 11, 12), calibration (Figs. 7, 9, 10),
//!   front-velocity (Fig. 13), validity-map (Figs. 16, 17); Fig. 3 needs no run
//! plans --(study::exec + store, runs/reproduce/<tier>/<study>/runs/<fingerprint>)--> records
//! records --(stages: decide, plots)--> figures, deciding numbers, verdicts
//!   --(report)--> reports/<tier>/report.md, reproduce.json, fig*.png, fig*.csv
//! ```
//!
//! Finished runs are reused by fingerprint, so running again simulates nothing new and a run
//! stopped at any point resumes. The report is rewritten after every stage (figures not yet
//! computed say `pending`), so a long tier shows where it stands. With `--previous DIR` the
//! report lists what changed since DIR's `reproduce.json` (verdicts and deciding numbers).
//! Every paper number comes from `hvi_engine::paper`.

pub mod config;
pub mod report;
pub mod sizing;
pub mod stages;

use crate::cli::ReproduceArgs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use hvi_engine::paper;
use rayon::prelude::*;

use config::{Config, EstimateConfig};
use hvi_run::exec::ExecOptions;
use hvi_run::plan::{build_plan, Plan, PlanRequest};
use hvi_run::spec::{json_to_override, Axis, Study, Tier};
use report::{fmt_duration, Estimate, EstimateRow, Figure, Machine, Reproduction, Verdict};
use stages::Ctx;

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

/// A study that lives only in memory: a base scene, axes and one tier without overrides (the
/// overrides go through the plan request, which keeps them off the axes).
fn memory_study(
    name: &str,
    description: &str,
    config: &Config,
    scene_path: PathBuf,
    scene_text: String,
    axes: Vec<Axis>,
    tier: &str,
) -> Study {
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
        path: config.path.clone(),
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

/// Plans every study of a tier (nothing is written, nothing runs). Every run's scene is built
/// by the engine, so a bad value fails here, naming the key.
pub fn build_plans(config: &Config, tier_name: &str) -> Result<Plans> {
    let t = config.tier(tier_name)?;
    let plan_ref = |what: &str, r: &config::StudyRef| -> Result<(PathBuf, Plan)> {
        let path = config.resolve(&r.study);
        let study = Study::load(&path)?;
        let plan = build_plan(
            &study,
            &PlanRequest {
                tier: Some(r.tier.clone()),
                particles: r.particles,
                set: r.set.clone(),
            },
        )
        .with_context(|| format!("{}: tiers.{tier_name}.{what}", config.path.display()))?;
        Ok((path, plan))
    };
    let (calibration_study, calibration) = plan_ref("calibration", &t.calibration)?;
    let (validity_study, validity) = plan_ref("validity", &t.validity)?;
    let plan_mem = |what: &str, study: &Study, set: Vec<String>| -> Result<Plan> {
        build_plan(
            study,
            &PlanRequest {
                tier: Some(tier_name.to_string()),
                particles: None,
                set,
            },
        )
        .with_context(|| format!("{}: tiers.{tier_name}.{what}", config.path.display()))
    };
    let read = |p: &Path| {
        std::fs::read_to_string(p)
            .with_context(|| format!("cannot read scene file {}", p.display()))
    };

    // Fig. 4: the plates at each count, without and with sizing.
    let mut counts = t.sizing.particles.clone();
    counts.sort_by(f64::total_cmp);
    counts.dedup();
    let study = memory_study(
        "sizing",
        "Fig. 4: colliding plates with and without geometric sizing",
        config,
        PathBuf::from("hvi_study::reproduce::sizing::plates_scene"),
        sizing::plates_scene_toml(counts[0], true)?,
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
        tier_name,
    );
    let sizing = plan_mem("sizing", &study, t.sizing.set.clone())?;

    // Fig. 5 and Figs. 11-12: the best fit at fractions of the calibration's count, at it, and
    // at the paper's final-over-calibration ratio of it.
    let cal_n = calibration
        .runs
        .first()
        .and_then(|r| r.scene.resolution.particles)
        .ok_or_else(|| {
            anyhow!(
                "tiers.{tier_name}.calibration: its runs set resolution.particles_across_d; Fig. 5 \
                 scales the calibration's particle count, so it needs resolution.particles"
            )
        })?;
    let mut counts: Vec<f64> = t
        .convergence
        .fractions
        .iter()
        .map(|f| (cal_n * f).round())
        .chain([
            cal_n.round(),
            (cal_n * paper::FINAL_PARTICLES / paper::CALIBRATION_PARTICLES).round(),
        ])
        .collect();
    counts.sort_by(f64::total_cmp);
    counts.dedup();
    let scene_path = config.resolve(&t.convergence.scene);
    let study = memory_study(
        "convergence",
        "Fig. 5 (F against particle count) and Figs. 11-12 (its finest run): the paper's best fit on the calibration scene",
        config,
        scene_path.clone(),
        read(&scene_path)?,
        vec![Axis {
            key: "resolution.particles".into(),
            values: numbers(counts),
            label: "particles".into(),
        }],
        tier_name,
    );
    let mut set = best_fit()?;
    set.extend(t.convergence.set.iter().cloned());
    let convergence = plan_mem("convergence", &study, set)?;

    // Fig. 13: va/v0 against t/D at the paper's velocity.
    let scene_path = config.resolve(&t.front_velocity.scene);
    let study = memory_study(
        "front-velocity",
        "Fig. 13: va/v0 against t/D at the paper's velocity, best fit",
        config,
        scene_path.clone(),
        read(&scene_path)?,
        vec![Axis {
            key: "scene.t_over_d".into(),
            values: numbers(t.front_velocity.t_over_d.iter().copied()),
            label: "t/D".into(),
        }],
        tier_name,
    );
    let mut set = vec![set_of("scene.v0_m_s", paper::FIG13_V0_M_S)?];
    set.extend(best_fit()?);
    set.extend(t.front_velocity.set.iter().cloned());
    let front_velocity = plan_mem("front_velocity", &study, set)?;

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

/// The cost of a tier: per stage, the sum over runs of particles x base steps (each scene
/// built by the engine, so the base step is the one it would run with) over `[estimate]`'s
/// throughput in the same unit (whole runs with the adaptive step).
pub fn estimate(plans: &Plans, tier: &str, cfg: &EstimateConfig) -> Result<Estimate> {
    let mut rows = Vec::new();
    for (stage, figures, plan) in plans.stages() {
        let costs: Vec<(usize, f64)> = plan
            .runs
            .par_iter()
            .map(|r| hvi_run::exec::run_cost(&r.scene))
            .collect::<Result<_>>()?;
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

/// Checks the report directory: a new or empty directory, or a previous report.
fn check_out(out: &Path) -> Result<()> {
    if out.exists() {
        if !out.is_dir() {
            bail!(
                "invalid value for `--out`: {} is a file (allowed: a directory)",
                out.display()
            );
        }
        let empty = std::fs::read_dir(out)
            .with_context(|| format!("cannot read --out {}", out.display()))?
            .next()
            .is_none();
        if !empty && !out.join("reproduce.json").exists() {
            bail!(
                "refusing to write into --out {}: it is not empty and holds no reproduce.json \
                 (not a report of `hvi-study reproduce`); choose a new or empty directory",
                out.display()
            );
        }
    }
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create --out {}", out.display()))?;
    let probe = out.join(format!(".write-test-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .with_context(|| format!("cannot write into --out {}", out.display()))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// Every figure, pending, in the paper's order.
fn pending_figures() -> Vec<Figure> {
    vec![
        stages::fig3_pending(),
        stages::fig4_pending(),
        stages::fig5_pending(),
        stages::fig7_pending(),
        stages::fig9_pending(),
        stages::fig10_pending(),
        stages::fig11_pending(),
        stages::fig13_pending(),
        stages::fig16_pending(),
        stages::fig17_pending(),
    ]
}

fn print_estimate(e: &Estimate) {
    println!(
        "tier `{}` on {} cores at {} particles x base steps per second:",
        e.tier,
        e.cores,
        report::fmt_num(e.particle_steps_per_second)
    );
    for r in &e.rows {
        println!(
            "  {:<15} Fig. {:<10} {:>3} runs, {:>7}-{:<7} particles, {:>10} particles x base steps, {}",
            r.stage,
            r.figures,
            r.runs,
            r.particles.0,
            r.particles.1,
            report::fmt_num(r.particle_steps),
            fmt_duration(r.seconds)
        );
    }
    println!(
        "  total: {} particles x base steps, expected {}",
        report::fmt_num(e.particle_steps()),
        fmt_duration(e.seconds())
    );
}

/// `hvi-study reproduce`.
pub fn reproduce(args: &ReproduceArgs) -> Result<Reproduction> {
    let t0 = Instant::now();
    if args.threads == Some(0) {
        bail!("invalid value for `--threads`: 0 (allowed: an integer >= 1)");
    }
    if args.jobs == Some(0) {
        bail!("invalid value for `--jobs`: 0 (allowed: an integer >= 1)");
    }
    let config = Config::load(&args.config)?;
    let tier = config.tier(&args.tier)?.clone();
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("reports").join(&args.tier));
    let runs = args
        .runs
        .clone()
        .unwrap_or_else(|| Path::new("runs").join("reproduce").join(&args.tier));
    // Read the previous report before anything is written (it may be --out itself).
    let previous = match &args.previous {
        Some(d) => Some(
            Reproduction::load(&d.join("reproduce.json"))
                .with_context(|| format!("--previous {}", d.display()))?,
        ),
        None => None,
    };
    if !args.dry_run {
        check_out(&out)?;
    }
    let say = |line: String| {
        if !args.quiet {
            eprintln!("[reproduce] {line}");
        }
    };

    say(format!(
        "tier `{}`: planning every figure's runs",
        args.tier
    ));
    let plans = build_plans(&config, &args.tier)?;
    let n_runs: usize = plans.stages().iter().map(|s| s.2.runs.len()).sum();
    say(format!("{n_runs} runs planned, every scene valid"));
    let mut estimates = Vec::new();
    if let Some(e) = &config.estimate {
        estimates.push(estimate(&plans, &args.tier, e)?);
        if let Some(other) = e.tier.as_ref().filter(|t| **t != args.tier) {
            say(format!("estimating tier `{other}` (planning only)"));
            let p = build_plans(&config, other)?;
            estimates.push(estimate(&p, other, e)?);
        }
    }
    if args.dry_run {
        for e in &estimates {
            print_estimate(e);
        }
        if estimates.is_empty() {
            println!("{n_runs} runs planned (the config has no [estimate] to time them)");
        }
        return Ok(Reproduction {
            tier: args.tier.clone(),
            tier_description: tier.description.clone(),
            config: args.config.display().to_string(),
            version: env!("CARGO_PKG_VERSION").into(),
            machine: Machine::detect(),
            complete: false,
            figures: pending_figures(),
            stages: Vec::new(),
            wall_seconds: t0.elapsed().as_secs_f64(),
            estimates,
            notes: Vec::new(),
            changes: None,
        });
    }
    std::fs::create_dir_all(&runs)
        .with_context(|| format!("cannot create --runs {}", runs.display()))?;

    let contact = plans
        .calibration
        .runs
        .first()
        .map_or("?", |r| r.scene.material.contact.name());
    let mut rep = Reproduction {
        tier: args.tier.clone(),
        tier_description: tier.description.clone(),
        config: args.config.display().to_string(),
        version: env!("CARGO_PKG_VERSION").into(),
        machine: Machine::detect(),
        complete: false,
        figures: pending_figures(),
        stages: Vec::new(),
        wall_seconds: 0.0,
        estimates,
        notes: vec![
            format!(
                "Contact form `{contact}` (eq. 3 with the prefactor as printed is the default; \
                 MODEL.md section 3); eps and kappa are the paper's values at \u{3c3}_ref = {:.4} mm \
                 and are sized to each run's \u{3c3} (eq. 12).",
                paper::reference_sigma_m() * 1e3
            ),
            format!(
                "Runs are kept by fingerprint under `{}` (one study store per stage): running the \
                 command again simulates only what is missing.",
                runs.display()
            ),
        ],
        changes: None,
    };
    rep.write(&out)?;

    let ctx = Ctx {
        out: out.clone(),
        runs: runs.clone(),
        exec: ExecOptions {
            threads: args.threads.unwrap_or(0),
            jobs: args.jobs,
            progress: !args.quiet,
        },
        threads: args.threads,
        jobs: args.jobs,
        quiet: args.quiet,
    };
    let targets = {
        let study = Study::load(&plans.calibration_study)?;
        let cfg = crate::study::calibrate::CalibrateConfig::of(&study)?;
        let base = study.path.parent().unwrap_or_else(|| Path::new("."));
        hvi_run::output::load_targets(&base.join(&cfg.targets))?
    };
    let fig13_gap = targets
        .gaps
        .iter()
        .find(|g| g.name.contains("fig13"))
        .map(|g| format!("{}: {}", g.source, g.note));

    type StageFn<'a> = Box<dyn Fn() -> Result<(Vec<Figure>, Option<report::StageTiming>)> + 'a>;
    let with_timing = |r: Result<(Vec<Figure>, report::StageTiming)>| r.map(|(f, t)| (f, Some(t)));
    let stage_list: Vec<(&str, &[&str], StageFn)> = vec![
        (
            "Fig. 3: the pair laws (no runs)",
            &["3"],
            Box::new(|| {
                let t = Instant::now();
                let figures = stages::fig3(&ctx)?;
                let timing = report::StageTiming {
                    stage: "potentials".into(),
                    figures: "3".into(),
                    runs: 0,
                    ran: 0,
                    cached: 0,
                    failed: 0,
                    wall_seconds: t.elapsed().as_secs_f64(),
                };
                Ok((figures, Some(timing)))
            }),
        ),
        (
            "Fig. 4: sizing",
            &["4"],
            Box::new(|| with_timing(stages::fig4(&ctx, &plans.sizing))),
        ),
        (
            "Fig. 5 and Figs. 11-12: convergence and the best fit",
            &["5", "11-12"],
            Box::new(|| with_timing(stages::fig5_11_12(&ctx, &plans.convergence, &targets))),
        ),
        (
            "Figs. 7, 9, 10: the calibration grid",
            &["7", "9", "10"],
            Box::new(|| {
                with_timing(stages::fig7_9_10(
                    &ctx,
                    &plans.calibration_study,
                    &tier.calibration,
                    &plans.calibration,
                ))
            }),
        ),
        (
            "Fig. 13: va/v0 against t/D",
            &["13"],
            Box::new(|| {
                with_timing(stages::fig13(
                    &ctx,
                    &plans.front_velocity,
                    fig13_gap.clone(),
                ))
            }),
        ),
        (
            "Figs. 16, 17: the validity map",
            &["16", "17"],
            Box::new(|| {
                with_timing(stages::fig16_17(
                    &ctx,
                    &plans.validity_study,
                    &tier.validity,
                    &plans.validity,
                ))
            }),
        ),
    ];
    let n_stages = stage_list.len();
    let mut errors = Vec::new();
    for (k, (name, ids, run)) in stage_list.into_iter().enumerate() {
        let ts = Instant::now();
        say(format!("stage {}/{n_stages}: {name}", k + 1));
        match run() {
            Ok((figures, timing)) => {
                for f in figures {
                    say(format!(
                        "Fig. {}: {} ({})",
                        f.id,
                        f.verdict.word(),
                        f.reason
                    ));
                    if let Some(slot) = rep.figures.iter_mut().find(|g| g.id == f.id) {
                        *slot = f;
                    }
                }
                if let Some(t) = timing {
                    rep.stages.push(t);
                }
            }
            Err(e) => {
                say(format!("stage {name} failed: {e:#}"));
                for id in ids {
                    if let Some(slot) = rep.figures.iter_mut().find(|g| g.id == *id) {
                        slot.verdict = Verdict::Not;
                        slot.ours = "the stage failed".into();
                        slot.reason = format!("the stage failed: {e:#}");
                    }
                }
                errors.push(format!("stage {name} failed: {e:#}"));
            }
        }
        say(format!(
            "stage {}/{n_stages} done in {}",
            k + 1,
            fmt_duration(ts.elapsed().as_secs_f64())
        ));
        rep.wall_seconds = t0.elapsed().as_secs_f64();
        rep.write(&out)?;
    }
    rep.complete = errors.is_empty();
    rep.wall_seconds = t0.elapsed().as_secs_f64();
    rep.changes = previous.as_ref().map(|p| report::diff(p, &rep));
    rep.write(&out)?;
    say(format!(
        "done in {}: {}",
        fmt_duration(rep.wall_seconds),
        rep.figures
            .iter()
            .map(|f| format!("Fig. {} {}", f.id, f.verdict.word()))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    println!("{}", out.join("report.md").display());
    if let (true, Some(changes)) = (args.fail_on_change, &rep.changes) {
        if !changes.is_empty() {
            errors.push(format!(
                "{} verdict(s) or deciding number(s) changed since {} (--fail-on-change):\n    {}",
                changes.len(),
                args.previous
                    .as_deref()
                    .map_or("the previous report".into(), |p| p.display().to_string()),
                changes.join("\n    ")
            ));
        }
    }
    if !errors.is_empty() {
        bail!("{}", errors.join("\n"));
    }
    Ok(rep)
}
