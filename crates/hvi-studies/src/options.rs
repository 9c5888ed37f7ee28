//! The plain options of a study workflow: which study, at which tier, where its results go and
//! how many threads run it. The command line (`cli::StudyArgs`) builds them; a library caller
//! fills them in directly, without clap.

use std::path::PathBuf;

use hvi_run::bail;
use hvi_run::checkpoint::Every;
use hvi_run::error::Result;
use hvi_store::exec::ExecOptions;
use hvi_store::plan::{build_plan, Plan, PlanRequest};
use hvi_store::spec::Study;
use hvi_store::study::default_out_dir;

/// The study, its tier and where its results go; threads and progress.
#[derive(Debug, Clone)]
pub struct StudyOptions {
    /// The study file (TOML).
    pub study: PathBuf,
    /// The resolution tier (None: the study's default tier).
    pub tier: Option<String>,
    /// The tier's particle count, overridden.
    pub particles: Option<f64>,
    /// Scene overrides of every run, `section.key=value`.
    pub sets: Vec<String>,
    /// The output directory (None: `runs/studies/<study>/<tier>`).
    pub out: Option<PathBuf>,
    /// Worker threads in all (None: every core).
    pub threads: Option<usize>,
    /// Runs at once (None: as many as threads).
    pub jobs: Option<usize>,
    /// How often each run writes a checkpoint.
    pub checkpoint_every: Every,
    /// No progress output.
    pub quiet: bool,
}

impl StudyOptions {
    /// Options for `study` at its default tier with every other option at its default.
    pub fn new(study: impl Into<PathBuf>) -> StudyOptions {
        StudyOptions {
            study: study.into(),
            tier: None,
            particles: None,
            sets: Vec::new(),
            out: None,
            threads: None,
            jobs: None,
            checkpoint_every: Every::default(),
            quiet: false,
        }
    }

    /// Loads the study, builds and validates its plan, and writes `plan.json`.
    pub fn plan(&self) -> Result<(Study, Plan, PathBuf)> {
        let (study, plan, out) = self.build_plan()?;
        plan.write(&out)?;
        Ok((study, plan, out))
    }

    /// Loads the study and builds and validates its plan; returns it with the output
    /// directory, writing nothing.
    pub fn build_plan(&self) -> Result<(Study, Plan, PathBuf)> {
        let study = self.load_study()?;
        let (plan, out) = self.build_plan_of(&study)?;
        Ok((study, plan, out))
    }

    /// Checks the thread and job counts and loads the study file.
    pub fn load_study(&self) -> Result<Study> {
        if self.threads == Some(0) {
            bail!("invalid value for `--threads`: 0 (allowed: an integer >= 1)");
        }
        if self.jobs == Some(0) {
            bail!("invalid value for `--jobs`: 0 (allowed: an integer >= 1)");
        }
        Study::load(&self.study)
    }

    /// Builds and validates the plan of `study` (loaded, and possibly changed, by the caller)
    /// at these options; returns it with the output directory, writing nothing.
    pub fn build_plan_of(&self, study: &Study) -> Result<(Plan, PathBuf)> {
        let plan = build_plan(
            study,
            &PlanRequest {
                tier: self.tier.clone(),
                particles: self.particles,
                set: self.sets.clone(),
            },
        )?;
        let out = self
            .out
            .clone()
            .unwrap_or_else(|| default_out_dir(&plan.study, &plan.tier, self.particles));
        Ok((plan, out))
    }

    /// Execution options.
    pub fn exec_options(&self) -> ExecOptions {
        ExecOptions {
            threads: self.threads.unwrap_or(0),
            jobs: self.jobs,
            progress: !self.quiet,
            checkpoint_every: self.checkpoint_every,
        }
    }
}
