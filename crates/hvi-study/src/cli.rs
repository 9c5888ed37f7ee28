//! Every command-line argument of `hvi-study`, in one place (clap). The structs here are raw
//! flags; each workflow validates its own into a plan or options before it runs anything.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::{Args, Parser, Subcommand};
use hvi_run::checkpoint::Every;
use hvi_store::exec::ExecOptions;
use hvi_store::plan::Plan;
use hvi_store::slurm::SlurmOptions;
use hvi_store::spec::Study;

use hvi_calibrate::config::{InitialDesign, Method};
use hvi_calibrate::CalibrateOptions;
use hvi_fidelity::FidelityOptions;
use hvi_ladder::LadderOptions;
use hvi_reproduce::ReproduceOptions;
use hvi_studies::collect::{CollectAs, CollectOptions, StatusOptions};
use hvi_studies::options::StudyOptions;
use hvi_studies::reanalyse::ReanalyseOptions;
use hvi_studies::stability::StabilityOptions;
use hvi_studies::validity::ValidityOptions;

/// Hypervelocity impact of a sphere on a plate with the discrete element method of Watson &
/// Steinhauser (Materials 2017): one scene, or studies of many (sweeps, calibration against
/// experiments, validity and stability maps, the paper's figures), on this machine or on Slurm.
#[derive(Parser, Debug)]
#[command(
    name = "hvi-study",
    version,
    long_about = None,
    after_help = "Start with `hvi-study run studies/scenes/default.toml --out runs/default` (one \
                  impact, under a minute) or `hvi-study calibrate studies/calibration.toml` (the \
                  paper's calibration at the quick tier). `hvi-study keys` lists every scene key; \
                  docs/running.md and docs/studies.md explain the rest."
)]
pub struct Cli {
    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run one scene and write summary.json, energy.csv, cloud_track.csv and fragments.csv
    /// into --out.
    Run(RunArgs),
    /// Every scene key a scene file or --set accepts: unit, allowed values, default, meaning.
    Keys(KeysArgs),
    /// Print a shell completion script, e.g. `hvi-study completions bash >
    /// ~/.local/share/bash-completion/completions/hvi-study`.
    Completions(CompletionsArgs),
    /// Write the man pages (hvi-study.1 and one per subcommand) into a directory.
    Man(ManArgs),
    /// Validate a study and write its plan.json (every run's scene checked), running nothing.
    Plan(PlanArgs),
    /// Run every run of a study (in parallel, finished runs reused) and write results.csv/json.
    Sweep(StudyArgs),
    /// Calibrate: the study's grid scored against experiments_data, then a surrogate search
    /// (batches of runs in parallel, at the study's seeds, until the expected improvement is
    /// below the noise) or Nelder-Mead; writes calibration.json, calibration.md and
    /// evaluations.csv.
    Calibrate(CalibrateArgs),
    /// Validity map: the study's grid over (v0, t/D), F contour with the cut-off in red
    /// (Fig. 16b), the boundary as validity_boundary.csv, runs marked valid in results.csv.
    #[command(mut_arg("study", |a| a.help("Study file (TOML), e.g. studies/validity-map.toml")))]
    ValidityMap(ValidityArgs),
    /// Stability map: every slice of studies/stability/ (v0 x t/D, v0 x step, eps x kappa)
    /// run through the study store; writes a map per slice, stability.csv and stability.md.
    Stability(StabilityArgs),
    /// Reproduce every figure of the paper through the study runner and its store, and write
    /// report.md: per figure the paper's result, ours, the deciding numbers and a verdict.
    Reproduce(ReproduceArgs),
    /// The readings study: the calibration grid under each reading of the paper (contact
    /// prefactor, sizing rule, thermal amplitude, observable definition) at several seeds,
    /// each reading's Figs. 9 and 10 judged side by side; writes reports/fidelity/.
    Fidelity(FidelityArgs),
    /// Run one run of a written plan.json by its index (for an external scheduler).
    RunUnit(RunUnitArgs),
    /// Submit the runs a study lacks to a Slurm cluster as one job array (one task per run,
    /// each `hvi-study run-unit`); prints the job id.
    Submit(SubmitArgs),
    /// A study's progress: done, failed, running and pending runs, from its run store (and
    /// Slurm's queue for its submissions).
    Status(StatusArgs),
    /// Write a study's tables (and figures) from its run store, running nothing.
    Collect(CollectArgs),
    /// Measure the debris cloud of a study's stored runs again from the state each run kept
    /// (state.bin), with other analysis settings, running no simulation; writes
    /// reanalysis.csv/json into the study directory.
    Reanalyse(ReanalyseArgs),
    /// Engine throughput: run a scene at several thread counts and print particle-steps/s.
    ///
    /// Defaults to the paper's calibration scene (2.7e5 particles) through the first 1 us of
    /// the impact. Also checks that every thread count gives bit-identical physics.
    Bench(BenchArgs),
    /// Run time against error: a reference run at the paper's step, other seeds (the noise
    /// floor) and variants of the accuracy knobs, each run to the analysis time; writes
    /// accuracy.csv/json/md and pareto.png and names the cheapest setting within tolerance.
    ///
    /// Finished runs are stored (fingerprinted) and reused, so a rerun or a killed benchmark
    /// picks up where it stopped.
    Accuracy(AccuracyArgs),
}

/// Which study, at which tier and resolution, and where its results are: the flags every
/// study command shares (`plan`, `sweep`, `status`, `collect`, `calibrate`, `validity-map`,
/// `submit`), declared once.
#[derive(Args, Debug, Clone)]
pub struct StudySelection {
    /// Study file (TOML), e.g. studies/calibration.toml (`status` and `collect` also take a
    /// study directory or its plan.json).
    pub study: PathBuf,
    /// Resolution tier, as named in the study's `[tiers]` (default: its default_tier, `quick`).
    #[arg(long)]
    pub tier: Option<String>,
    /// Override the tier's particle count (resolution.particles).
    #[arg(long, value_name = "N")]
    pub particles: Option<f64>,
    /// Override a scene key in every run: section.key=value (not an axis key).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Output directory (default: `runs/studies/<study>/<tier>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

impl StudySelection {
    /// The plain options of a study workflow with this selection; the running options
    /// (threads, jobs, checkpoints) at the values given.
    fn options(
        &self,
        threads: Option<usize>,
        jobs: Option<usize>,
        checkpoint_every: Every,
        quiet: bool,
    ) -> StudyOptions {
        StudyOptions {
            study: self.study.clone(),
            tier: self.tier.clone(),
            particles: self.particles,
            sets: self.sets.clone(),
            out: self.out.clone(),
            threads,
            jobs,
            checkpoint_every,
            quiet,
        }
    }
}

/// What every study command that runs takes: the study's selection and how to run it.
#[derive(Args, Debug, Clone)]
pub struct StudyArgs {
    /// The study, its tier and where its results go.
    #[command(flatten)]
    pub selection: StudySelection,
    /// Worker threads in all (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Runs at once (default: as many as threads; the rest of the threads go inside runs).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Each run writes a checkpoint this often (wall time: 90s, 10m, 2h; or base steps:
    /// 5000steps; or `off`) and when Ctrl-C or SIGTERM stops it; a run killed mid-way resumes
    /// from its last one, bit-identical.
    #[arg(long, value_name = "EVERY", default_value = "10m")]
    pub checkpoint_every: Every,
    /// No progress output.
    #[arg(long)]
    pub quiet: bool,
}

impl StudyArgs {
    /// The plain options these flags give.
    pub fn options(&self) -> StudyOptions {
        self.selection
            .options(self.threads, self.jobs, self.checkpoint_every, self.quiet)
    }

    /// Loads the study, builds and validates its plan, and writes `plan.json`.
    pub fn plan(&self) -> Result<(Study, Plan, PathBuf)> {
        Ok(self.options().plan()?)
    }

    /// Loads the study and builds and validates its plan; returns it with the output
    /// directory, writing nothing.
    pub fn build_plan(&self) -> Result<(Study, Plan, PathBuf)> {
        Ok(self.options().build_plan()?)
    }

    /// Execution options from the flags.
    pub fn exec_options(&self) -> ExecOptions {
        self.options().exec_options()
    }
}

/// `hvi-study plan` arguments: the study's, without the flags of running (it runs nothing).
#[derive(Args, Debug, Clone)]
pub struct PlanArgs {
    /// The study, its tier and where its plan goes.
    #[command(flatten)]
    pub selection: StudySelection,
    /// No progress output.
    #[arg(long)]
    pub quiet: bool,
}

impl PlanArgs {
    /// The plain options these flags give (no threads: nothing runs).
    pub fn options(&self) -> StudyOptions {
        self.selection.options(None, None, Every::Off, self.quiet)
    }
}

/// `hvi-study calibrate` arguments.
#[derive(Args, Debug, Clone)]
pub struct CalibrateArgs {
    /// The study, tier, output and threads.
    #[command(flatten)]
    pub study: StudyArgs,
    /// Only the grid stage: score the grid, no search after it, every run in full (the
    /// calibration's screen is for the search: docs/calibration.md, "The screen").
    #[arg(long)]
    pub no_refine: bool,
    /// The search after the grid (overrides calibrate.method).
    #[arg(long, value_enum)]
    pub method: Option<MethodArg>,
    /// The grid stage's points (overrides calibrate.initial_design): every grid point, or the
    /// searched box's corners and centre (docs/calibration.md, "Stages").
    #[arg(long, value_enum)]
    pub initial_design: Option<InitialDesignArg>,
    /// Nelder-Mead iterations at most (overrides calibrate.max_iters).
    #[arg(long)]
    pub max_iters: Option<u64>,
    /// Surrogate-search batches at most (overrides calibrate.max_batches).
    #[arg(long)]
    pub max_batches: Option<usize>,
    /// Keep the searched box: an optimum or a confidence region on its edge is reported as
    /// such instead of extending the axis beyond the grid (see docs/calibration.md).
    #[arg(long)]
    pub no_extend: bool,
    /// The seeds of the surrogate search, e.g. `1,2,3` (overrides calibrate.seeds): every
    /// point runs at the first, and at the others within calibrate.seeds_within_decades of the
    /// lowest J so far; one seed: the noise is calibrate.noise_floor.
    #[arg(long, value_delimiter = ',', value_name = "SEEDS")]
    pub seeds: Option<Vec<u64>>,
    /// Run every batch of runs (the grid, each search batch) as a Slurm job array and wait for
    /// it; this process only proposes, submits and scores. Stopped and started again, it waits
    /// for the arrays still running rather than submitting them twice.
    #[arg(long)]
    pub slurm: bool,
    /// With --slurm: the job arrays' options.
    #[command(flatten)]
    pub slurm_flags: SlurmFlags,
    /// With --slurm: seconds between looks at the queue while a batch runs (0.2 to 3600).
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    pub poll: f64,
    /// Calibrate over a ladder of ascending particle counts, e.g. `2e4,8e4,2.7e5`: each level
    /// a whole calibration in `<out>/n<N>/`, the first from the study's grid, each later one
    /// from the previous level's confidence region (moved by the trend of the last two);
    /// writes ladder.json, ladder.md and ladder.png with the verdict in N
    /// (docs/calibration.md). `--out` is the ladder's directory (default
    /// `runs/studies/<study>/<tier>-ladder`).
    #[arg(long, value_delimiter = ',', value_name = "N1,N2,...")]
    pub ladder: Option<Vec<f64>>,
    /// With --ladder: run the last level's answer again at this many particles and score it
    /// (overrides calibrate.ladder_check).
    #[arg(long, value_name = "N")]
    pub ladder_check: Option<f64>,
    /// Calibrate without this shot (its id, in a study of several shots), then run it at the
    /// answer and report its prediction against its measurement, with the seed spread.
    #[arg(long, value_name = "SHOT")]
    pub hold_out: Option<String>,
}

impl CalibrateArgs {
    /// The ladder's options, when `--ladder` is given (`--ladder-check` alone is refused).
    pub fn ladder(&self) -> Result<Option<LadderOptions>> {
        match (&self.ladder, self.ladder_check) {
            (Some(particles), check) => Ok(Some(LadderOptions {
                particles: particles.clone(),
                check,
            })),
            (None, Some(_)) => {
                bail!("--ladder-check checks a ladder's last answer: add --ladder N1,N2,...")
            }
            (None, None) => Ok(None),
        }
    }

    /// The plain options these flags give, checked: the Slurm flags only with `--slurm`,
    /// `--threads` and `--jobs` only without.
    pub fn options(&self) -> Result<CalibrateOptions> {
        let slurm = if self.slurm {
            if self.study.threads.is_some() {
                bail!("calibrate --slurm: --threads is not used (each run gets --cpus-per-task threads)");
            }
            if self.study.jobs.is_some() {
                bail!(
                    "calibrate --slurm: --jobs is not used (--array-limit K caps the runs at once)"
                );
            }
            Some((
                self.slurm_flags
                    .options(false, self.study.quiet, self.study.checkpoint_every)?,
                self.poll,
            ))
        } else {
            if self.slurm_flags.any_set() {
                bail!("--partition, --time, --cpus-per-task, --array-limit and --sbatch-option are options of the Slurm job arrays: add --slurm");
            }
            None
        };
        Ok(CalibrateOptions {
            study: self.study.options(),
            no_refine: self.no_refine,
            method: self.method.map(Method::from),
            max_iters: self.max_iters,
            max_batches: self.max_batches,
            seeds: self.seeds.clone(),
            initial_design: self.initial_design.map(InitialDesign::from),
            extend: !self.no_extend,
            slurm,
            coarse: None,
            hold_out: self.hold_out.clone(),
        })
    }
}

/// `hvi-study validity-map` arguments.
#[derive(Args, Debug, Clone)]
pub struct ValidityArgs {
    /// The study, tier, output and threads.
    #[command(flatten)]
    pub study: StudyArgs,
    /// The cut-off of the observable (default: the study's, else the paper's F = 0.3).
    #[arg(long)]
    pub cutoff: Option<f64>,
    /// Skip the fragmentation onset's search (onset.csv, the curves over the map).
    #[arg(long)]
    pub no_onset: bool,
    /// The impactor's intact mass fraction below which it counts as fragmented (default: the
    /// study's `[validity.onset] threshold`, else 0.8).
    #[arg(long, value_name = "FRACTION")]
    pub onset_threshold: Option<f64>,
}

impl ValidityArgs {
    /// The plain options these flags give.
    pub fn options(&self) -> ValidityOptions {
        ValidityOptions {
            study: self.study.options(),
            cutoff: self.cutoff,
            onset: !self.no_onset,
            onset_threshold: self.onset_threshold,
        }
    }
}

/// Which study store `status` and `collect` read: the study's selection, as the study ran it
/// (no threads or jobs: they run nothing).
#[derive(Args, Debug, Clone)]
pub struct StoreArgs {
    /// The study, its tier and its directory.
    #[command(flatten)]
    pub selection: StudySelection,
    /// No progress output.
    #[arg(long)]
    pub quiet: bool,
}

impl StudyArgs {
    /// The store these flags select, for `status` and `collect` (quiet: the caller speaks).
    pub fn store_options(&self) -> StudyOptions {
        self.selection.options(None, None, Every::Off, true)
    }
}

impl StoreArgs {
    /// The plain options of the store these flags select (nothing runs: no threads).
    pub fn options(&self) -> StudyOptions {
        self.selection.options(None, None, Every::Off, self.quiet)
    }
}

/// `hvi-study status` arguments.
#[derive(Args, Debug, Clone)]
pub struct StatusArgs {
    /// The study (a study file with the flags `sweep` takes, or a study directory or its
    /// plan.json).
    #[command(flatten)]
    pub store: StoreArgs,
    /// One line per run: its state, where it runs, its directory.
    #[arg(long, short)]
    pub verbose: bool,
}

/// `hvi-study collect` arguments.
#[derive(Args, Debug, Clone)]
pub struct CollectArgs {
    /// The study (a study file with the flags `sweep` takes, or a study directory or its
    /// plan.json).
    #[command(flatten)]
    pub store: StoreArgs,
    /// Write what this command writes (default: `calibrate` for a study with `[calibrate]`,
    /// `validity-map` for one with `[validity]`, else `sweep`).
    #[arg(long = "as", value_enum, value_name = "COMMAND")]
    pub kind: Option<CollectAsArg>,
    /// The validity cut-off (with `--as validity-map`; default: the study's, else 0.3).
    #[arg(long)]
    pub cutoff: Option<f64>,
}

impl StatusArgs {
    /// The plain options these flags give.
    pub fn options(&self) -> StatusOptions {
        StatusOptions {
            study: self.store.options(),
            verbose: self.verbose,
        }
    }
}

impl CollectArgs {
    /// The plain options these flags give.
    pub fn options(&self) -> CollectOptions {
        CollectOptions {
            study: self.store.options(),
            kind: self.kind.map(CollectAs::from),
            cutoff: self.cutoff,
        }
    }
}

/// `hvi-study reanalyse` arguments.
#[derive(Args, Debug, Clone)]
pub struct ReanalyseArgs {
    /// The study directory (the --out of a sweep: plan.json and runs/), or its plan.json.
    pub study_dir: PathBuf,
    /// Measure with another analysis setting, analysis.KEY=VALUE with KEY one of quantile,
    /// width (side or cylindrical), shadowgraph_pixel_m, shadowgraph_blur_m,
    /// shadowgraph_grain_m, shadowgraph_optical_depth, witness_standoff_m (default: each run's
    /// own).
    #[arg(long = "set", value_name = "analysis.KEY=VALUE")]
    pub sets: Vec<String>,
    /// The table's name in the study directory: NAME.csv and NAME.json.
    #[arg(long, value_name = "NAME", default_value = "reanalysis")]
    pub table: String,
    /// No progress output (runs that cannot be measured are still listed).
    #[arg(long)]
    pub quiet: bool,
}

/// `hvi-study stability` arguments.
#[derive(Args, Debug, Clone)]
pub struct StabilityArgs {
    /// Slice study files (default: every studies/stability/*.toml).
    pub studies: Vec<PathBuf>,
    /// Tier of every slice (default: each study's default tier, `quick`).
    #[arg(long)]
    pub tier: Option<String>,
    /// Report directory.
    #[arg(long, default_value = "reports/stability")]
    pub out: PathBuf,
    /// Run stores, one directory per slice under this.
    #[arg(long, default_value = "runs/stability")]
    pub store: PathBuf,
    /// Worker threads in all (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress output.
    #[arg(long)]
    pub quiet: bool,
}

impl StabilityArgs {
    /// The plain options these flags give.
    pub fn options(&self) -> StabilityOptions {
        StabilityOptions {
            studies: self.studies.clone(),
            tier: self.tier.clone(),
            out: self.out.clone(),
            store: self.store.clone(),
            threads: self.threads,
            quiet: self.quiet,
        }
    }
}

/// `hvi-study reproduce` arguments.
#[derive(Args, Debug, Clone)]
pub struct ReproduceArgs {
    /// The tier, as named in the config: `quick` (CI, a few minutes) or `paper` (the paper's
    /// resolutions: hours on two cores; `--dry-run` prints the estimate).
    #[arg(long)]
    pub tier: String,
    /// The report directory: report.md, reproduce.json and the figures (default
    /// `reports/<tier>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Where the runs are kept, one study store per stage (default `runs/reproduce/<tier>`).
    #[arg(long)]
    pub runs: Option<PathBuf>,
    /// A previous report directory: list what changed since its reproduce.json.
    #[arg(long, value_name = "DIR")]
    pub previous: Option<PathBuf>,
    /// With --previous: fail (exit code 2) when a verdict or deciding number changed, e.g. to
    /// check in CI that a committed report is current.
    #[arg(long, requires = "previous")]
    pub fail_on_change: bool,
    /// The history file each run appends its record to (default `<out>/history.jsonl`);
    /// several report directories may share one.
    #[arg(long, value_name = "FILE")]
    pub history: Option<PathBuf>,
    /// The reproduction's config.
    #[arg(long, default_value = "studies/reproduce.toml")]
    pub config: PathBuf,
    /// Worker threads in all (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Runs at once (default: as many as threads).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Validate every run and print the expected wall time; run nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// No progress output.
    #[arg(long)]
    pub quiet: bool,
}

/// `hvi-study fidelity` arguments.
#[derive(Args, Debug, Clone)]
pub struct FidelityArgs {
    /// The readings config.
    #[arg(long, default_value = "studies/fidelity.toml")]
    pub config: PathBuf,
    /// The calibration study's tier (default: the config's `fidelity.tier`).
    #[arg(long)]
    pub tier: Option<String>,
    /// Thermal seeds, comma-separated (default: the config's `fidelity.seeds`).
    #[arg(long, value_delimiter = ',')]
    pub seeds: Vec<u64>,
    /// The report directory (a new or empty directory, or an earlier report).
    #[arg(long, default_value = "reports/fidelity")]
    pub out: PathBuf,
    /// Where the runs are kept: one study store per reading, `<runs>/<tier>/<reading>/`.
    #[arg(long, default_value = "runs/fidelity")]
    pub runs: PathBuf,
    /// Worker threads in all (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Runs at once (default: as many as threads).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Validate every reading and run, print how many runs it takes; run nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// No progress output.
    #[arg(long)]
    pub quiet: bool,
}

impl ReanalyseArgs {
    /// The plain options these flags give.
    pub fn options(&self) -> ReanalyseOptions {
        ReanalyseOptions {
            study_dir: self.study_dir.clone(),
            sets: self.sets.clone(),
            table: self.table.clone(),
            quiet: self.quiet,
        }
    }
}

impl ReproduceArgs {
    /// The plain options these flags give.
    pub fn options(&self) -> ReproduceOptions {
        ReproduceOptions {
            tier: self.tier.clone(),
            out: self.out.clone(),
            runs: self.runs.clone(),
            previous: self.previous.clone(),
            fail_on_change: self.fail_on_change,
            history: self.history.clone(),
            config: self.config.clone(),
            threads: self.threads,
            jobs: self.jobs,
            dry_run: self.dry_run,
            quiet: self.quiet,
        }
    }
}

impl FidelityArgs {
    /// The plain options these flags give.
    pub fn options(&self) -> FidelityOptions {
        FidelityOptions {
            config: self.config.clone(),
            tier: self.tier.clone(),
            seeds: self.seeds.clone(),
            out: self.out.clone(),
            runs: self.runs.clone(),
            threads: self.threads,
            jobs: self.jobs,
            dry_run: self.dry_run,
            quiet: self.quiet,
        }
    }
}

/// `hvi-study submit` arguments.
#[derive(Args, Debug, Clone)]
pub struct SubmitArgs {
    /// The study, tier and output directory (the same flags as `sweep`).
    #[command(flatten)]
    pub study: StudyArgs,
    /// Submit to Slurm with sbatch (the one scheduler hvi-study knows; required, so that the
    /// command says where the runs go).
    #[arg(long, required = true)]
    pub slurm: bool,
    /// The job array's options.
    #[command(flatten)]
    pub slurm_flags: SlurmFlags,
    /// Print the script and what would be submitted; write nothing, submit nothing.
    #[arg(long)]
    pub dry_run: bool,
}

/// The options of a Slurm job array (`submit --slurm`, `calibrate --slurm`).
#[derive(Args, Debug, Clone)]
pub struct SlurmFlags {
    /// Slurm partition (`#SBATCH --partition`); default: the cluster's default partition.
    #[arg(long, value_name = "P")]
    pub partition: Option<String>,
    /// Time limit of each run, in Slurm's format (`MM`, `HH:MM:SS`, `D-HH:MM`, ...).
    #[arg(long, value_name = "T")]
    pub time: Option<String>,
    /// CPUs of each run: its worker threads (results are identical for any count).
    #[arg(long, value_name = "C", default_value_t = 1)]
    pub cpus_per_task: usize,
    /// At most K runs at once (`--array=0-(n-1)%K`); default: as many as Slurm allows.
    #[arg(long, value_name = "K")]
    pub array_limit: Option<usize>,
    /// Any other sbatch option, as an `#SBATCH` line, e.g. `--sbatch-option=--account=proj42`
    /// (repeatable).
    #[arg(long = "sbatch-option", value_name = "OPTION")]
    pub sbatch_options: Vec<String>,
}

impl Default for SlurmFlags {
    fn default() -> Self {
        SlurmFlags {
            partition: None,
            time: None,
            cpus_per_task: 1,
            array_limit: None,
            sbatch_options: Vec::new(),
        }
    }
}

impl SlurmFlags {
    /// The Slurm options these flags give, checked; each task's run checkpoints every
    /// `checkpoint_every`.
    pub fn options(
        &self,
        dry_run: bool,
        quiet: bool,
        checkpoint_every: Every,
    ) -> Result<SlurmOptions> {
        let opts = SlurmOptions {
            partition: self.partition.clone(),
            time: self.time.clone(),
            cpus_per_task: self.cpus_per_task,
            array_limit: self.array_limit,
            sbatch_options: self.sbatch_options.clone(),
            dry_run,
            quiet,
            checkpoint_every,
        };
        opts.validate()?;
        Ok(opts)
    }

    /// Whether any flag differs from its default (they mean nothing without `--slurm`).
    pub fn any_set(&self) -> bool {
        self.partition.is_some()
            || self.time.is_some()
            || self.cpus_per_task != 1
            || self.array_limit.is_some()
            || !self.sbatch_options.is_empty()
    }
}

impl SubmitArgs {
    /// The Slurm options, with the flags `submit` does not use refused.
    pub fn slurm_options(&self) -> Result<SlurmOptions> {
        if self.study.threads.is_some() {
            bail!("submit: --threads is not used (each run gets --cpus-per-task threads)");
        }
        if self.study.jobs.is_some() {
            bail!("submit: --jobs is not used (--array-limit K caps the runs at once)");
        }
        self.slurm_flags
            .options(self.dry_run, self.study.quiet, self.study.checkpoint_every)
    }
}

/// `hvi-study run` arguments.
#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// Scene file (TOML), e.g. studies/scenes/default.toml.
    pub scene: PathBuf,
    /// Output directory. A finished run of this scene there to an earlier run.end_time_s is
    /// extended; another earlier run's files are replaced (see --fresh).
    #[arg(long, default_value = "runs/last")]
    pub out: PathBuf,
    /// Override a scene key: section.key=value (e.g. scene.v0_m_s=6500, run.dt_s=auto).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Worker threads (default: all cores). Results are identical for any count.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Dump the particles at t = 0, at the first step at or after every K base steps, and at
    /// the end: trajectory.extxyz (OVITO, ASE) and trajectory.pvd with vtk/frame_NNNNN.vtu
    /// (ParaView). Never changes the trajectory.
    #[arg(long, value_name = "K")]
    pub dump_every: Option<u64>,
    /// Which files the dumps go to.
    #[arg(long, value_enum, default_value_t = DumpFormatArg::Both, requires = "dump_every")]
    pub dump_format: DumpFormatArg,
    /// Write the initial state as a LAMMPS data file (units si, atom_style bond).
    #[arg(long, value_name = "FILE")]
    pub lammps_data: Option<PathBuf>,
    /// Write the scene as LAMMPS runs it into DIR: data.lmp, bond.table, model.lmp and in.lmp
    /// with every coefficient, runnable as `lmp -in DIR/in.lmp`; and the same scene in LAMMPS's
    /// BPM package, `lmp -in DIR/in_bpm.lmp` (another model: its bonds also push and break in
    /// compression; needs a LAMMPS with BPM) (docs/running.md).
    #[arg(long, value_name = "DIR")]
    pub lammps: Option<PathBuf>,
    /// No progress output.
    #[arg(long)]
    pub quiet: bool,
    /// Write pictures: cloud_side.png (the cloud at the end, Figs. 7/11), cloud_series.png
    /// (3-D views at analysis.render_times_s, Fig. 12), fragments.png, cloud_track.png.
    #[arg(long)]
    pub render: bool,
    /// Write --out/checkpoint.bin this often (wall time: 90s, 10m, 2h; or base steps:
    /// 5000steps; or `off`) and when Ctrl-C or SIGTERM stops the run. The same command again
    /// resumes from it and ends bit-identical to a run never stopped.
    #[arg(long, value_name = "EVERY", default_value = "10m")]
    pub checkpoint_every: Every,
    /// Run from t = 0 whatever --out holds. Without it, a finished run of this scene there to
    /// an earlier run.end_time_s is extended from its continuation.bin (bit-identical to a run
    /// made to the new end in one go), and a finished run of another scene or to a later end
    /// is refused, naming the keys that differ.
    #[arg(long)]
    pub fresh: bool,
    /// Do not keep --out/continuation.bin, the state a later end time continues the run from
    /// (the checkpoint format: about 300 bytes per particle).
    #[arg(long)]
    pub no_continuation: bool,
}

/// `hvi-study completions` arguments.
#[derive(Args, Debug, Clone)]
pub struct CompletionsArgs {
    /// The shell.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

/// `hvi-study man` arguments.
#[derive(Args, Debug, Clone)]
pub struct ManArgs {
    /// Directory for the pages (created if missing).
    #[arg(long, default_value = "man")]
    pub out: PathBuf,
}

/// `hvi-study keys` arguments.
#[derive(Args, Debug, Clone)]
pub struct KeysArgs {
    /// Print the table as Markdown (the keys table of docs/running.md).
    #[arg(long)]
    pub markdown: bool,
    /// Only the keys whose name contains this text (e.g. `analysis.`, `shadowgraph`).
    pub filter: Option<String>,
}

/// `--dump-format`.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum DumpFormatArg {
    /// trajectory.extxyz only (OVITO, ASE).
    Extxyz,
    /// trajectory.pvd and vtk/frame_NNNNN.vtu only (ParaView, meshio).
    Vtk,
    /// Both.
    Both,
}

impl From<DumpFormatArg> for hvi_run::output::DumpFormat {
    fn from(f: DumpFormatArg) -> Self {
        match f {
            DumpFormatArg::Extxyz => Self::Extxyz,
            DumpFormatArg::Vtk => Self::Vtk,
            DumpFormatArg::Both => Self::Both,
        }
    }
}

/// `hvi-study bench` arguments.
#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// Scene file.
    #[arg(default_value = "studies/scenes/calibration.toml")]
    pub scene: PathBuf,
    /// Override a scene key: section.key=value.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Simulated time after first contact, s.
    #[arg(long, default_value_t = 1e-6)]
    pub end_time: f64,
    /// Thread counts to run, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    pub threads: Vec<usize>,
    /// Where the runs and bench.csv go.
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
}

/// `hvi-study accuracy` arguments.
#[derive(Args, Debug, Clone)]
pub struct AccuracyArgs {
    /// Scene file.
    #[arg(default_value = "studies/scenes/default.toml")]
    pub scene: PathBuf,
    /// Override a scene key on every run: section.key=value.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// A candidate NAME:key=value[;key=value...] (repeatable); replaces the default
    /// candidates (dt_factor 2..16, skin, ballistic cut-off). The reference and the
    /// noise-floor seeds (`--noise-seeds`) always run.
    #[arg(long = "variant", value_name = "NAME:KEY=VALUE[;...]")]
    pub variants: Vec<String>,
    /// Worker threads per run (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Report directory (default: `reports/accuracy/<scene file stem>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Run store (default: `runs/accuracy/<scene file stem>`).
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// Noise-floor runs: other seeds at the paper's step (0 to 8). With 0 the tolerance
    /// alone applies; for scenes whose reference takes hours. Raised to seeds - 1 when
    /// `--seeds` asks for more.
    #[arg(long, default_value_t = 2)]
    pub noise_seeds: u32,
    /// Seeds per candidate (1 to 9): each candidate's value is the mean over its runs at
    /// seeds 1..K, compared with the reference value within two standard errors.
    #[arg(long, default_value_t = 1)]
    pub seeds: u32,
}

/// `hvi-study rununit` arguments.
#[derive(Args, Debug, Clone)]
pub struct RunUnitArgs {
    /// The plan.json of a study's output directory.
    pub plan: PathBuf,
    /// The run's index in the plan.
    pub index: usize,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// The study directory whose run store receives the result (default: the plan's
    /// directory; `submit --slurm` runs frozen copies of the plan kept beside its scripts).
    #[arg(long, value_name = "DIR")]
    pub study_dir: Option<PathBuf>,
    /// The run writes a checkpoint this often (as for `sweep`) and when SIGTERM stops it
    /// (Slurm's `--signal` before a time limit); a task run again resumes from it.
    #[arg(long, value_name = "EVERY", default_value = "10m")]
    pub checkpoint_every: Every,
}

/// `--method`: the search after the grid ([`Method`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MethodArg {
    /// Efficient global optimisation: a kriging model of the objective, batches of runs by
    /// expected improvement, stopped when the improvement left is below the seed noise.
    Ego,
    /// Nelder-Mead (argmin) from the best grid point, one run at a time.
    NelderMead,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Method {
        match m {
            MethodArg::Ego => Method::Ego,
            MethodArg::NelderMead => Method::NelderMead,
        }
    }
}

/// `--initial-design`: the grid stage's points ([`InitialDesign`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InitialDesignArg {
    /// Every point of the study's grid.
    Grid,
    /// The corners of the searched axes' box and the grid point nearest its centre; the
    /// skipped grid points near the answer run when the box moves.
    Corners,
}

impl From<InitialDesignArg> for InitialDesign {
    fn from(d: InitialDesignArg) -> InitialDesign {
        match d {
            InitialDesignArg::Grid => InitialDesign::Grid,
            InitialDesignArg::Corners => InitialDesign::Corners,
        }
    }
}

/// `collect --as`: which command's outputs to write ([`CollectAs`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CollectAsArg {
    /// results.csv / results.json, as `sweep`.
    Sweep,
    /// The results with the objective and each target's score, as the grid stage of
    /// `calibrate` (the refinement needs new runs: `hvi-study calibrate` does it).
    Calibrate,
    /// The results with `valid`, the map, its boundary and the snapshots, as `validity-map`.
    ValidityMap,
}

impl From<CollectAsArg> for CollectAs {
    fn from(k: CollectAsArg) -> CollectAs {
        match k {
            CollectAsArg::Sweep => CollectAs::Sweep,
            CollectAsArg::Calibrate => CollectAs::Calibrate,
            CollectAsArg::ValidityMap => CollectAs::ValidityMap,
        }
    }
}
