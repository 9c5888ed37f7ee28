//! What each subcommand does with its arguments: `main` parses the command line into
//! [`Command`] and calls [`dispatch`]; each arm is one small function here or a workflow of
//! [`hvi_studies`], [`hvi_calibrate`] or [`hvi_reproduce`], called with plain options.

use std::path::PathBuf;

use anyhow::{Context, Result};
use hvi_run::checkpoint::{CheckpointOptions, Every};
use hvi_run::run::{run_scene, RunOptions};
use hvi_run::scene_file::load_scene;

use crate::cli::{
    AccuracyArgs, BenchArgs, Command, KeysArgs, RunArgs, RunUnitArgs, StudyArgs, SubmitArgs,
};
use hvi_studies::collect::{CollectAs, CollectOptions};

/// Runs one subcommand.
pub fn dispatch(command: Command) -> Result<()> {
    match command {
        Command::Run(args) => run(args),
        Command::Keys(args) => {
            keys(&args);
            Ok(())
        }
        Command::Completions(args) => {
            let mut cmd = <crate::cli::Cli as clap::CommandFactory>::command();
            clap_complete::generate(args.shell, &mut cmd, "hvi-study", &mut std::io::stdout());
            Ok(())
        }
        Command::Man(args) => man(&args),
        Command::Bench(args) => bench(args),
        Command::Accuracy(args) => accuracy(args),
        Command::Stability(args) => {
            let cells = hvi_studies::stability::stability(&args.options())?;
            let stopped = cells.iter().filter(|c| c.status != "stable").count();
            println!(
                "{} cells, {} stopped; report: {}",
                cells.len(),
                stopped,
                args.out.join("stability.md").display()
            );
            Ok(())
        }
        Command::Plan(args) => Ok(hvi_studies::sweep::plan(&args.options())?),
        Command::Sweep(args) => {
            let r = hvi_studies::sweep::sweep(&args.options()).map_err(Into::into);
            tables_if_interrupted(&args, CollectAs::Sweep, r)
        }
        Command::Calibrate(args) => {
            if let Some(ladder) = args.ladder()? {
                hvi_ladder::ladder(&args.options()?, &ladder)?;
                return Ok(());
            }
            let r = args
                .options()
                .and_then(|o| Ok(hvi_calibrate::calibrate(&o)?))
                .map(|_| ());
            tables_if_interrupted(&args.study, CollectAs::Calibrate, r)
        }
        Command::ValidityMap(args) => {
            let r = hvi_studies::validity::validity_map(&args.options())
                .map(|_| ())
                .map_err(Into::into);
            tables_if_interrupted(&args.study, CollectAs::ValidityMap, r)
        }
        Command::Submit(args) => submit(&args),
        Command::Status(args) => Ok(hvi_studies::collect::status(&args.options())?),
        Command::Collect(args) => collect(&args.options()),
        Command::Reanalyse(args) => Ok(hvi_studies::reanalyse::reanalyse(&args.options())?),
        Command::Fidelity(args) => {
            hvi_fidelity::fidelity(&args.options())?;
            Ok(())
        }
        Command::Reproduce(args) => {
            hvi_reproduce::reproduce(&args.options())?;
            Ok(())
        }
        Command::RunUnit(args) => run_unit(&args),
    }
}

/// A rayon pool of `threads` workers (default: every core).
fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    if threads == Some(0) {
        anyhow::bail!("invalid value for `--threads`: 0 (allowed: an integer >= 1)");
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .context("cannot start worker threads")
}

/// After Ctrl-C or SIGTERM stopped a study command: its tables from the runs that finished
/// (as `collect --as KIND` writes them), then the interruption again.
fn tables_if_interrupted(study: &StudyArgs, kind: CollectAs, r: Result<()>) -> Result<()> {
    if r.as_ref()
        .err()
        .and_then(|e| hvi_run::interrupt::of(&**e))
        .is_some()
    {
        let opts = CollectOptions {
            study: study.store_options(),
            kind: Some(kind),
            cutoff: None,
        };
        match collect(&opts) {
            Ok(()) => eprintln!("the tables of the runs that finished are written"),
            Err(e) => eprintln!("the tables could not be written: {e:#}"),
        }
    }
    r
}

/// `hvi-study man`: hvi-study.1 and hvi-study-SUBCOMMAND.1 into `--out`.
fn man(args: &crate::cli::ManArgs) -> Result<()> {
    let cmd = <crate::cli::Cli as clap::CommandFactory>::command();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create --out {}", args.out.display()))?;
    let mut pages = 0;
    let mut write = |name: String, cmd: clap::Command| -> Result<()> {
        let mut bytes = Vec::new();
        clap_mangen::Man::new(cmd)
            .title(name.to_uppercase())
            .render(&mut bytes)?;
        let path = args.out.join(format!("{name}.1"));
        hvi_run::output::write_atomic_bytes(&path, &bytes)?;
        pages += 1;
        Ok(())
    };
    for sub in cmd.get_subcommands() {
        let name = format!("hvi-study-{}", sub.get_name());
        let page = sub
            .clone()
            .display_name(name.clone())
            .bin_name(name.replace("hvi-study-", "hvi-study "));
        write(name, page)?;
    }
    write("hvi-study".into(), cmd)?;
    println!(
        "{pages} man pages in {} (man -l {}/hvi-study.1)",
        args.out.display(),
        args.out.display()
    );
    Ok(())
}

/// `hvi-study keys`: the key registry as a table (aligned text, or Markdown).
fn keys(args: &KeysArgs) {
    use hvi_engine::scene::keys::{markdown_of, KEYS};
    let keys: Vec<_> = KEYS
        .iter()
        .filter(|k| args.filter.as_deref().is_none_or(|f| k.name.contains(f)))
        .collect();
    if args.markdown {
        print!("{}", markdown_of(keys));
        return;
    }
    let plain = |t: &str| plain_links(&t.replace("  ", " "));
    let width = keys.iter().map(|k| k.name.len()).max().unwrap_or(0);
    for k in keys {
        println!(
            "{:width$}  {:6}  {}; default {}\n{:width$}  {}",
            k.name,
            k.unit(),
            k.allowed.describe(),
            if k.default.is_empty() {
                "none".to_string()
            } else {
                plain(k.default)
            },
            "",
            plain(k.meaning),
        );
    }
}

/// Markdown links as a terminal shows them: `[words](fidelity.md#x)` becomes
/// `words (docs/fidelity.md#x)` (the meanings link within docs/).
fn plain_links(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(open) = rest.find('[') {
        let after = &rest[open + 1..];
        let link = after.find("](").and_then(|close| {
            let target = &after[close + 2..];
            target
                .find(')')
                .map(|end| (&after[..close], &target[..end], close + 2 + end + 1))
        });
        match link {
            Some((words, target, used)) => {
                out.push_str(&rest[..open]);
                let target = match target.strip_prefix("../") {
                    Some(t) => t.to_string(),
                    None if target.starts_with("http") || target.starts_with('#') => {
                        target.to_string()
                    }
                    None => format!("docs/{target}"),
                };
                out.push_str(&format!("{words} ({target})"));
                rest = &after[used..];
            }
            None => {
                out.push_str(&rest[..=open]);
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

/// `hvi-study run`.
fn run(args: RunArgs) -> Result<()> {
    if args.dump_every == Some(0) {
        anyhow::bail!("invalid value for `--dump-every`: 0 (allowed: an integer >= 1)");
    }
    let spec = load_scene(&args.scene, &args.sets)?;
    let resolution = hvi_store::resolution::scene_warnings(&args.scene, &args.sets, &spec);
    for w in spec.warnings().into_iter().chain(resolution) {
        eprintln!("warning: {w}");
    }
    let pool = thread_pool(args.threads)?;
    // The LAMMPS data file may be written into --out by an earlier run: it is the user's.
    let keep: Vec<&std::ffi::OsStr> = args
        .lammps_data
        .iter()
        .chain(args.lammps.iter())
        .filter(|p| p.parent() == Some(args.out.as_path()))
        .filter_map(|p| p.file_name())
        .collect();
    let opts = RunOptions {
        out_dir: args.out.clone(),
        dump_every: args.dump_every,
        dump_format: args.dump_format.into(),
        lammps_data: args.lammps_data.clone(),
        lammps_dir: args.lammps.clone(),
        progress: !args.quiet,
        render: args.render,
        checkpoint: (args.checkpoint_every != Every::Off).then(|| CheckpointOptions {
            path: args.out.join(hvi_run::checkpoint::CHECKPOINT_FILE),
            every: args.checkpoint_every,
        }),
        // The run shows its own progress on the terminal.
        progress_file: false,
        continuation: (!args.no_continuation)
            .then(|| args.out.join(hvi_run::files::CONTINUATION_FILE)),
        extend: false,
    };
    let (opts, _) = hvi_run::start::prepare(&spec, opts, args.fresh, &keep)?;
    pool.install(|| run_scene(&spec, &opts))?;
    println!("{}", args.out.join("summary.json").display());
    Ok(())
}

/// `hvi-study bench`.
fn bench(mut args: BenchArgs) -> Result<()> {
    args.sets
        .push(format!("run.end_time_s={:e}", args.end_time));
    let spec = load_scene(&args.scene, &args.sets)?;
    let (_, table) = hvi_run::bench::bench(&spec, &args.threads, &args.out)?;
    print!("{table}");
    println!("table: {}", args.out.join("bench.csv").display());
    Ok(())
}

/// `hvi-study accuracy`.
fn accuracy(args: AccuracyArgs) -> Result<()> {
    use hvi_studies::accuracy::{self, Variant};
    accuracy::check_seeds(args.seeds)?;
    let noise_seeds = args.noise_seeds.max(args.seeds.saturating_sub(1));
    let mut list: Vec<Variant> = accuracy::reference_variants(noise_seeds)?;
    if args.variants.is_empty() {
        list.extend(accuracy::default_candidates());
    } else {
        for v in &args.variants {
            list.push(Variant::parse(v)?);
        }
    }
    let report_dir = args
        .out
        .unwrap_or_else(|| accuracy::default_report_dir(&args.scene));
    let stem = report_dir
        .file_name()
        .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
    let store = args
        .store
        .unwrap_or_else(|| PathBuf::from("runs/accuracy").join(stem));
    let pool = thread_pool(args.threads)?;
    let threads = pool.current_num_threads();
    let report = accuracy::accuracy(
        &args.scene,
        &args.sets,
        &list,
        args.seeds,
        threads,
        &store,
        &report_dir,
    )?;
    print!("{}", accuracy::markdown(&report));
    println!("report: {}", report_dir.join("accuracy.md").display());
    Ok(())
}

/// `hvi-study submit --slurm`.
fn submit(args: &SubmitArgs) -> Result<()> {
    let opts = args.slurm_options()?;
    let (study, plan, out) = args.study.build_plan()?;
    hvi_studies::sweep::print_resolution_warnings(&study, &plan)?;
    match hvi_store::slurm::submit(&plan, &out, &opts)? {
        hvi_store::slurm::Submitted::Nothing => {}
        hvi_store::slurm::Submitted::DryRun { script } => print!("{script}"),
        hvi_store::slurm::Submitted::Job { id } => println!("{id}"),
    }
    Ok(())
}

/// `hvi-study run-unit`: a failed run is an error (recorded in its directory).
fn run_unit(args: &RunUnitArgs) -> Result<()> {
    let completed = hvi_studies::sweep::run_unit(
        &args.plan,
        args.index,
        args.threads,
        args.study_dir.as_deref(),
        args.checkpoint_every,
    )?;
    if completed {
        Ok(())
    } else {
        Err(anyhow::anyhow!(
            "run {} failed (recorded in its directory)",
            args.index
        ))
    }
}

/// `hvi-study collect`: the tables (and figures) of a local run from the store, running
/// nothing. Runs without a result are rows with status `missing` (and gaps in the figures),
/// listed on stderr; the command still writes everything and exits 0, so a partial study can
/// be looked at while the rest runs.
fn collect(args: &CollectOptions) -> Result<()> {
    let c = hvi_studies::collect::gather(args)?;
    match c.kind {
        CollectAs::Sweep => c.write_sweep()?,
        CollectAs::Calibrate => hvi_calibrate::grid::collect_calibration(
            &c.plan,
            &c.dir,
            c.table.clone(),
            &c.filled,
            &c.missing,
            c.quiet,
        )?,
        CollectAs::ValidityMap => c.write_validity_map(args.cutoff)?,
    }
    c.finish();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::plain_links;

    #[test]
    fn markdown_links_read_plainly_in_a_terminal() {
        assert_eq!(
            plain_links("why 0.9: [model decisions](model-decisions.md#readings); [x] stays"),
            "why 0.9: model decisions (docs/model-decisions.md#readings); [x] stays"
        );
        assert_eq!(
            plain_links("see [the data](../experiments_data/README.md)"),
            "see the data (experiments_data/README.md)"
        );
    }
}
