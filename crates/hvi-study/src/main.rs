//! The `hvi-study` command.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use hvi_study::run::{run_scene, RunOptions};
use hvi_study::scene_file::load_scene;

/// Hypervelocity impact with the discrete element method (Watson & Steinhauser 2017).
#[derive(Parser, Debug)]
#[command(name = "hvi-study", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run one scene and write summary.json, energy.csv, cloud_track.csv and fragments.csv
    /// into --out.
    Run {
        /// Scene file (TOML), e.g. studies/scenes/default.toml.
        scene: PathBuf,
        /// Output directory.
        #[arg(long, default_value = "runs/last")]
        out: PathBuf,
        /// Override a scene key: section.key=value (e.g. scene.v0_m_s=6500, run.dt_s=auto).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        /// Worker threads (default: all cores). Results are identical for any count.
        #[arg(long)]
        threads: Option<usize>,
        /// Write an extended XYZ snapshot every K steps (OVITO, ASE).
        #[arg(long, value_name = "K")]
        dump_every: Option<u64>,
        /// Write the initial state as a LAMMPS data file (units si, atom_style bond).
        #[arg(long, value_name = "FILE")]
        lammps_data: Option<PathBuf>,
        /// No progress output.
        #[arg(long)]
        quiet: bool,
        /// Write pictures: cloud_side.png (the cloud at the end, Figs. 7/11), cloud_series.png
        /// (3-D views at analysis.render_times_s, Fig. 12), fragments.png, cloud_track.png.
        #[arg(long)]
        render: bool,
    },
    /// Validate a study and write its plan.json (every run's scene checked), running nothing.
    Plan(hvi_study::study::cli::StudyArgs),
    /// Run every run of a study (in parallel, finished runs reused) and write results.csv/json.
    Sweep(hvi_study::study::cli::StudyArgs),
    /// Calibrate: the study's grid scored against experiments_data, then a Nelder-Mead
    /// refinement from the best grid point; writes calibration.json and evaluations.csv.
    Calibrate(hvi_study::study::calibrate::CalibrateArgs),
    /// Validity map: the study's grid over (v0, t/D), F contour with the cut-off in red
    /// (Fig. 16b), the boundary as validity_boundary.csv, runs marked valid in results.csv.
    ValidityMap(hvi_study::study::validity::ValidityArgs),
    /// Stability map: every slice of studies/stability/ (v0 x t/D, v0 x step, eps x kappa)
    /// run through the study store; writes a map per slice, stability.csv and stability.md.
    Stability(hvi_study::study::stability::StabilityArgs),
    /// Reproduce every figure of the paper through the study runner and its store, and write
    /// report.md: per figure the paper's result, ours, the deciding numbers and a verdict.
    Reproduce(hvi_study::reproduce::ReproduceArgs),
    /// Run one run of a written plan.json by its index (for an external scheduler).
    RunUnit {
        /// The plan.json of a study's output directory.
        plan: PathBuf,
        /// The run's index in the plan.
        index: usize,
        /// Worker threads (default: every core).
        #[arg(long)]
        threads: Option<usize>,
        /// The study directory whose run store receives the result (default: the plan's
        /// directory; `submit --slurm` runs frozen copies of the plan kept beside its scripts).
        #[arg(long, value_name = "DIR")]
        study_dir: Option<PathBuf>,
    },
    /// Submit the runs a study lacks to a Slurm cluster as one job array (one task per run,
    /// each `hvi-study run-unit`); prints the job id.
    Submit(hvi_study::study::slurm::SubmitArgs),
    /// A study's progress: done, failed, running and pending runs, from its run store (and
    /// Slurm's queue for its submissions).
    Status(hvi_study::study::collect::StatusArgs),
    /// Write a study's tables (and figures) from its run store, running nothing.
    Collect(hvi_study::study::collect::CollectArgs),
    /// Engine throughput: run a scene at several thread counts and print particle-steps/s.
    ///
    /// Defaults to the paper's calibration scene (2.7e5 particles) through the first 1 us of
    /// the impact. Also checks that every thread count gives bit-identical physics.
    Bench {
        /// Scene file.
        #[arg(default_value = "studies/scenes/calibration.toml")]
        scene: PathBuf,
        /// Override a scene key: section.key=value.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        /// Simulated time after first contact, s.
        #[arg(long, default_value_t = 1e-6)]
        end_time: f64,
        /// Thread counts to run, comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "1,2")]
        threads: Vec<usize>,
        /// Where the runs and bench.csv go.
        #[arg(long, default_value = "runs/bench")]
        out: PathBuf,
    },
    /// Run time against error: a reference run at the paper's step, other seeds (the noise
    /// floor) and variants of the accuracy knobs, each run to the analysis time; writes
    /// accuracy.csv/json/md and pareto.png and names the cheapest setting within tolerance.
    ///
    /// Finished runs are stored (fingerprinted) and reused, so a rerun or a killed benchmark
    /// picks up where it stopped.
    Accuracy {
        /// Scene file.
        #[arg(default_value = "studies/scenes/default.toml")]
        scene: PathBuf,
        /// Override a scene key on every run: section.key=value.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        /// A candidate NAME:key=value[;key=value...] (repeatable); replaces the default
        /// candidates (dt_factor 2..16, skin, ballistic cut-off). The reference and the
        /// noise-floor seeds (`--noise-seeds`) always run.
        #[arg(long = "variant", value_name = "NAME:KEY=VALUE[;...]")]
        variants: Vec<String>,
        /// Worker threads per run (default: every core).
        #[arg(long)]
        threads: Option<usize>,
        /// Report directory (default: reports/accuracy/<scene file stem>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Run store (default: runs/accuracy/<scene file stem>).
        #[arg(long)]
        store: Option<PathBuf>,
        /// Noise-floor runs: other seeds at the paper's step (0 to 8). With 0 the tolerance
        /// alone applies; for scenes whose reference takes hours. Raised to seeds - 1 when
        /// `--seeds` asks for more.
        #[arg(long, default_value_t = 2)]
        noise_seeds: u32,
        /// Seeds per candidate (1 to 9): each candidate's value is the mean over its runs at
        /// seeds 1..K, compared with the reference value within two standard errors.
        #[arg(long, default_value_t = 1)]
        seeds: u32,
    },
}

fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    if threads == Some(0) {
        anyhow::bail!("invalid value for `--threads`: 0 (allowed: an integer >= 1)");
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .context("cannot start worker threads")
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run {
            scene,
            out,
            sets,
            threads,
            dump_every,
            lammps_data,
            quiet,
            render,
        } => (|| {
            if dump_every == Some(0) {
                anyhow::bail!("invalid value for `--dump-every`: 0 (allowed: an integer >= 1)");
            }
            let spec = load_scene(&scene, &sets)?;
            let pool = thread_pool(threads)?;
            let opts = RunOptions {
                out_dir: out.clone(),
                dump_every,
                lammps_data,
                progress: !quiet,
                render,
            };
            pool.install(|| run_scene(&spec, &opts))?;
            println!("{}", out.join("summary.json").display());
            Ok(())
        })(),
        Command::Bench {
            scene,
            mut sets,
            end_time,
            threads,
            out,
        } => (|| {
            sets.push(format!("run.end_time_s={end_time:e}"));
            let spec = load_scene(&scene, &sets)?;
            let (_, table) = hvi_study::bench::bench(&spec, &threads, &out)?;
            print!("{table}");
            println!("table: {}", out.join("bench.csv").display());
            Ok(())
        })(),
        Command::Accuracy {
            scene,
            sets,
            variants,
            threads,
            out,
            store,
            noise_seeds,
            seeds,
        } => (|| {
            use hvi_study::accuracy::{self, Variant};
            accuracy::check_seeds(seeds)?;
            let noise_seeds = noise_seeds.max(seeds.saturating_sub(1));
            let mut list: Vec<Variant> = accuracy::reference_variants(noise_seeds)?;
            if variants.is_empty() {
                list.extend(accuracy::default_candidates());
            } else {
                for v in &variants {
                    list.push(Variant::parse(v)?);
                }
            }
            let report_dir = out.unwrap_or_else(|| accuracy::default_report_dir(&scene));
            let stem = report_dir
                .file_name()
                .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
            let store = store.unwrap_or_else(|| PathBuf::from("runs/accuracy").join(stem));
            let pool = thread_pool(threads)?;
            let threads = pool.current_num_threads();
            let report =
                accuracy::accuracy(&scene, &sets, &list, seeds, threads, &store, &report_dir)?;
            print!("{}", accuracy::markdown(&report));
            println!("report: {}", report_dir.join("accuracy.md").display());
            Ok(())
        })(),
        Command::Stability(args) => hvi_study::study::stability::stability(&args).map(|cells| {
            let stopped = cells.iter().filter(|c| c.status != "stable").count();
            println!(
                "{} cells, {} stopped; report: {}",
                cells.len(),
                stopped,
                args.out.join("stability.md").display()
            );
        }),
        Command::Plan(args) => hvi_study::study::cli::plan(&args),
        Command::Sweep(args) => hvi_study::study::cli::sweep(&args),
        Command::Calibrate(args) => hvi_study::study::calibrate::calibrate(&args).map(|_| ()),
        Command::ValidityMap(args) => hvi_study::study::validity::validity_map(&args).map(|_| ()),
        Command::Submit(args) => hvi_study::study::slurm::submit(&args),
        Command::Status(args) => hvi_study::study::collect::status(&args),
        Command::Collect(args) => hvi_study::study::collect::collect(&args),
        Command::Reproduce(args) => hvi_study::reproduce::reproduce(&args).map(|_| ()),
        Command::RunUnit {
            plan,
            index,
            threads,
            study_dir,
        } => match hvi_study::study::cli::run_unit(&plan, index, threads, study_dir.as_deref()) {
            Ok(true) => Ok(()),
            Ok(false) => Err(anyhow::anyhow!(
                "run {index} failed (recorded in its directory)"
            )),
            Err(e) => Err(e),
        },
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
