//! `hvi-study stability`: the stress matrix. Each slice is an ordinary two-axis study
//! (`studies/stability/*.toml`: v0 x t/D, v0 x step, eps x kappa), run through the study store
//! (parallel, cached, resumable); for every cell the map records whether the run completed,
//! its largest energy-ledger drift, its step against the stability bound, and the first sign of
//! trouble the engine reported (`EngineError::Unstable`: the step, the time and what was seen).
//!
//! Writes into the report directory: `<slice>.png` (a cell per run: green to orange by the
//! drift, red where the run stopped), `stability.csv` (every cell) and `stability.md` (per
//! slice: cells, stopped runs, the largest drift, the verdict against the ledger bound).

use hvi_analysis::observable::Observable;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use hvi_run::bail;
use hvi_run::error::{Result, ResultExt};
use serde::Serialize;

use crate::options::StudyOptions;
use hvi_engine::sim::LEDGER_DRIFT_BOUND;
use hvi_plot::stability_map::{stability_map, MapCell, StabilityMap};
use hvi_run::output::{write_atomic_bytes, write_csv_atomic};
use hvi_store::plan::Plan;
use hvi_store::store::{read_summary, Record, RunStatus, Store};
use hvi_store::study::execute_plan;

/// One cell of the stress matrix.
#[derive(Debug, Clone, Serialize)]
pub struct Cell {
    /// The slice (study name).
    pub slice: String,
    /// First axis key and value.
    pub x_key: String,
    /// First axis value.
    pub x: String,
    /// Second axis key.
    pub y_key: String,
    /// Second axis value.
    pub y: String,
    /// `stable` (completed) or `stopped`.
    pub status: String,
    /// Largest |relative ledger drift| over the run.
    pub max_drift: Option<f64>,
    /// Time step, s.
    pub dt_s: Option<f64>,
    /// Step over the stability bound.
    pub dt_over_bound: Option<f64>,
    /// Bonds broken over bonds at t = 0.
    pub broken_fraction: Option<f64>,
    /// The engine's diagnostic when the run stopped.
    pub trouble: String,
    /// Grid position (column, row).
    #[serde(skip)]
    pub at: (usize, usize),
}

fn default_slices() -> Result<Vec<PathBuf>> {
    let dir = Path::new("studies/stability");
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| {
            format!(
                "cannot list {} (run from the repository root or name the slice files)",
                dir.display()
            )
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("no slice files in {}", dir.display());
    }
    Ok(files)
}

fn value_text(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Number(n) => n.as_f64().map_or(n.to_string(), |f| {
            format!("{}", hvi_store::spec::round_sig(f, 4))
        }),
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// What `stability` runs and where it writes.
#[derive(Debug, Clone)]
pub struct StabilityOptions {
    /// Slice study files (empty: every studies/stability/*.toml).
    pub studies: Vec<PathBuf>,
    /// Tier of every slice (None: each study's default tier).
    pub tier: Option<String>,
    /// Report directory.
    pub out: PathBuf,
    /// Run stores, one directory per slice under this.
    pub store: PathBuf,
    /// Worker threads in all (None: every core).
    pub threads: Option<usize>,
    /// No progress output.
    pub quiet: bool,
}

/// Runs every slice and writes the maps, the table and the summary. Returns the cells.
pub fn stability(args: &StabilityOptions) -> Result<Vec<Cell>> {
    let slices = if args.studies.is_empty() {
        default_slices()?
    } else {
        args.studies.clone()
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut cells: Vec<Cell> = Vec::new();
    let mut md = String::from("# Stability map\n\n");
    let _ = writeln!(
        md,
        "Each slice is a two-axis study; each cell one run. *stable*: the run reached its end with every guard quiet (no non-finite value, no pair closer than run.min_distance_over_sigma, ledger within run.max_energy_drift); *stopped*: the engine's diagnostic is quoted. The ledger bound this project states is {:.0e}.\n",
        LEDGER_DRIFT_BOUND
    );
    for file in &slices {
        let slice = run_slice(args, file)?;
        draw_slice(&args.out, &slice)?;
        md.push_str(&slice_summary(&slice));
        cells.extend(slice.cells);
    }
    write_csv_atomic(&args.out.join("stability.csv"), &cells)?;
    write_atomic_bytes(&args.out.join("stability.md"), md.as_bytes())?;
    Ok(cells)
}

/// One slice's runs as cells, with what the map and the summary say about the slice.
struct Slice {
    /// The slice file's stem: the map is `<stem>.png`.
    stem: String,
    /// The study's name.
    name: String,
    /// The study's description.
    description: String,
    /// The tier's name and description.
    tier: (String, String),
    /// Each axis: its label and its values as text.
    axes: [(String, Vec<String>); 2],
    /// A cell per run.
    cells: Vec<Cell>,
}

/// Plans and runs one slice (a two-axis study) through its store under `args.store`.
fn run_slice(args: &StabilityOptions, file: &Path) -> Result<Slice> {
    let stem = file
        .file_stem()
        .map_or("slice".into(), |s| s.to_string_lossy().into_owned());
    let study_args = StudyOptions {
        tier: args.tier.clone(),
        out: Some(args.store.join(&stem)),
        threads: args.threads,
        quiet: args.quiet,
        ..StudyOptions::new(file)
    };
    let (study, plan, out) = study_args.plan()?;
    if plan.axes.len() != 2 {
        bail!(
            "{}: a stability slice needs exactly 2 axes (has {})",
            file.display(),
            plan.axes.len()
        );
    }
    if !args.quiet {
        log::info!(
            "stability: slice `{}` ({} runs, tier {})",
            plan.study,
            plan.runs.len(),
            plan.tier
        );
    }
    let (_, report) = execute_plan(&plan, &out, &study_args.exec_options())?;
    let cells = cells_of(&plan, &report.records, &Store::open(&out)?);
    let axis = |k: usize| {
        let a = &plan.axes[k];
        (a.label.clone(), a.values.iter().map(value_text).collect())
    };
    Ok(Slice {
        stem,
        axes: [axis(0), axis(1)],
        name: plan.study,
        description: study.description,
        tier: (plan.tier, plan.tier_description),
        cells,
    })
}

/// A cell per run of a two-axis plan: its status, drift and step from the run's record and
/// summary.
fn cells_of(plan: &Plan, records: &[Record], store: &Store) -> Vec<Cell> {
    plan.runs
        .iter()
        .zip(records)
        .map(|(run, rec)| {
            let summary = read_summary(&store.dir(&run.fingerprint));
            let s = summary.as_ref();
            let dt = s.map(|s| s.dt_s).filter(|v| v.is_finite());
            let bound = s.map(|s| s.derived.dt_max_s).filter(|v| v.is_finite());
            Cell {
                slice: plan.study.clone(),
                x_key: plan.axes[0].key.clone(),
                x: value_text(&run.values[0]),
                y_key: plan.axes[1].key.clone(),
                y: value_text(&run.values[1]),
                status: if rec.status == RunStatus::Completed {
                    "stable"
                } else {
                    "stopped"
                }
                .into(),
                max_drift: s
                    .map(|s| s.energy.max_abs_relative_drift)
                    .filter(|v| v.is_finite()),
                dt_s: dt,
                dt_over_bound: dt.zip(bound).map(|(a, b)| a / b),
                broken_fraction: rec.observables.get(Observable::BondsBrokenFraction),
                trouble: rec.error.clone().unwrap_or_default(),
                at: (run.coords[0], run.coords[1]),
            }
        })
        .collect()
}

/// `<stem>.png` of a slice.
fn draw_slice(dir: &Path, slice: &Slice) -> Result<()> {
    let cells: Vec<MapCell> = slice
        .cells
        .iter()
        .map(|c| MapCell {
            at: c.at,
            stopped: c.status != "stable",
            max_drift: c.max_drift,
            dt_over_bound: c.dt_over_bound,
        })
        .collect();
    let [(x_name, x_labels), (y_name, y_labels)] = &slice.axes;
    Ok(stability_map(
        &dir.join(format!("{}.png", slice.stem)),
        &StabilityMap {
            title: &format!("{} \u{2014} {}", slice.name, slice.description),
            subtitle: &slice.tier.1,
            x: (x_name, x_labels),
            y: (y_name, y_labels),
            cells: &cells,
            drift_bound: LEDGER_DRIFT_BOUND,
        },
    )?)
}

/// A slice's section of `stability.md`: the counts, the largest drift, the cells within the
/// ledger bound and every stopped run with the engine's diagnostic.
fn slice_summary(slice: &Slice) -> String {
    let cells = &slice.cells;
    let mut md = String::new();
    let stopped: Vec<&Cell> = cells.iter().filter(|c| c.status != "stable").collect();
    let worst = cells
        .iter()
        .filter_map(|c| c.max_drift.map(|d| (d, c)))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    let _ = writeln!(md, "## {} ({})\n", slice.name, slice.description);
    let _ = writeln!(
        md,
        "Tier `{}`: {}. Map: `{}.png`.\n",
        slice.tier.0, slice.tier.1, slice.stem
    );
    let _ = writeln!(
        md,
        "- cells: {}; stable: {}; stopped: {}",
        cells.len(),
        cells.len() - stopped.len(),
        stopped.len()
    );
    if let Some((d, c)) = worst {
        let _ = writeln!(
            md,
            "- largest ledger drift: {d:.2e} at {} = {}, {} = {}{}",
            c.x_key,
            c.x,
            c.y_key,
            c.y,
            c.dt_over_bound
                .map_or(String::new(), |f| format!(" (step {f:.2} of the bound)"))
        );
    }
    let within = cells
        .iter()
        .filter(|c| c.status == "stable" && c.max_drift.is_some_and(|d| d < LEDGER_DRIFT_BOUND))
        .count();
    let _ = writeln!(
        md,
        "- within the ledger bound {:.0e}: {} of {}",
        LEDGER_DRIFT_BOUND,
        within,
        cells.len()
    );
    for c in &stopped {
        let _ = writeln!(
            md,
            "- stopped at {} = {}, {} = {}: {}",
            c.x_key, c.x, c.y_key, c.y, c.trouble
        );
    }
    md.push('\n');
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell(at: (usize, usize), stopped: bool, max_drift: Option<f64>) -> Cell {
        Cell {
            slice: "s".into(),
            x_key: "scene.v0_m_s".into(),
            x: (1000 * (at.0 + 1)).to_string(),
            y_key: "run.dt_over_bound".into(),
            y: (at.1 + 1).to_string(),
            status: if stopped { "stopped" } else { "stable" }.into(),
            max_drift,
            dt_s: None,
            dt_over_bound: Some((at.1 + 1) as f64),
            broken_fraction: None,
            trouble: if stopped {
                "too close".into()
            } else {
                String::new()
            },
            at,
        }
    }

    #[test]
    fn a_slice_summary_counts_stopped_runs_and_names_the_largest_drift() {
        let slice = Slice {
            stem: "step".into(),
            name: "stability-step".into(),
            description: "v0 x step".into(),
            tier: ("quick".into(), "tiny".into()),
            axes: [
                ("v0".into(), vec!["1000".into()]),
                ("step".into(), vec!["1".into(), "2".into()]),
            ],
            cells: vec![
                cell((0, 0), false, Some(1e-5)),
                cell((0, 1), false, Some(2e-3)),
                cell((1, 1), true, Some(1e6)),
            ],
        };
        let md = slice_summary(&slice);
        assert!(
            md.starts_with(
                "## stability-step (v0 x step)\n\nTier `quick`: tiny. Map: `step.png`.\n"
            ),
            "{md}"
        );
        assert!(md.contains("- cells: 3; stable: 2; stopped: 1\n"), "{md}");
        assert!(md.contains("- largest ledger drift: 1.00e6 at scene.v0_m_s = 2000, run.dt_over_bound = 2 (step 2.00 of the bound)\n"), "{md}");
        assert!(
            md.contains("- within the ledger bound 1e-3: 1 of 3\n"),
            "{md}"
        );
        assert!(
            md.contains("- stopped at scene.v0_m_s = 2000, run.dt_over_bound = 2: too close\n"),
            "{md}"
        );
    }
}
