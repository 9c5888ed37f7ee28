//! `hvi-study validity-map`: fragmentation F over two axes (v0, t/D), the F = cut-off contour
//! as the boundary of the model's validity (Fig. 16b; the paper takes F = 0.3), exported as a
//! CSV polyline, and each run marked valid or not in the results table.
//!
//! The study's optional `[validity]` section:
//!
//! ```toml
//! [validity]
//! observable = "fragmentation"   # any run observable (default F)
//! cutoff = 0.3                   # default 0.3; the --cutoff flag overrides
//! ```

use std::path::{Path, PathBuf};

use hvi_run::bail;
use hvi_run::error::{Result, RunError};
use serde::Deserialize;
use serde_json::Value;

use crate::figures::{field_of, map_axes};
use crate::figures::{plan_tiles, shown_axis};
use crate::options::StudyOptions;
use crate::sweep::print_failures;
use hvi_analysis::contour::{Field, Point};
use hvi_analysis::observable::Observable;
use hvi_plot::contour::{contour_plot, ContourPlot};
use hvi_plot::snapshots::{snapshot_matrix, MatrixText};
use hvi_run::output::write_atomic_with;
use hvi_store::plan::Plan;
use hvi_store::store::{Record, RunStatus};
use hvi_store::study::execute_plan;
use hvi_store::table::Table;
use plotters::style::{RGBColor, BLUE, RED};

use crate::onset::{
    self, describe as describe_onset, find_onsets, write_onset, OnsetConfig, OnsetResult,
};
use hvi_analysis::onset::Onset;
use hvi_plot::contour::Curve;

/// The paper's cut-off of the validity region (section 5, Fig. 16): F = 0.3.
pub const PAPER_CUTOFF: f64 = hvi_engine::paper::VALIDITY_FRAGMENTATION_CUTOFF;

fn default_observable() -> Observable {
    Observable::Fragmentation
}
fn default_cutoff() -> f64 {
    PAPER_CUTOFF
}

/// `[validity]` of a study file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValidityConfig {
    /// The observable mapped (default `fragmentation`).
    #[serde(default = "default_observable")]
    pub observable: Observable,
    /// The cut-off level (default 0.3).
    #[serde(default = "default_cutoff")]
    pub cutoff: f64,
    /// The fragmentation onset's search (`[validity.onset]`, [`crate::onset`]).
    #[serde(default)]
    pub onset: OnsetConfig,
}

impl ValidityConfig {
    /// Reads `[validity]` of a study (the defaults without one) and checks the observable.
    pub fn of(study: &hvi_store::spec::Study) -> Result<ValidityConfig> {
        let cfg: ValidityConfig = match &study.validity {
            Some(v) => serde_path_to_error::deserialize(v.clone()).map_err(|e| {
                let p = e.path().to_string();
                RunError::Input(format!(
                    "study key `validity.{p}`: {}",
                    e.into_inner().message().trim()
                ))
            })?,
            None => ValidityConfig::default(),
        };
        Ok(cfg)
    }

    /// The cut-off: `--cutoff` when given, else the study's.
    pub fn cutoff(&self, flag: Option<f64>) -> Result<f64> {
        let cutoff = flag.unwrap_or(self.cutoff);
        if !cutoff.is_finite() {
            bail!("invalid value for `--cutoff`: {cutoff} (allowed: a finite number)");
        }
        Ok(cutoff)
    }
}

impl Default for ValidityConfig {
    fn default() -> Self {
        ValidityConfig {
            observable: default_observable(),
            cutoff: default_cutoff(),
            onset: OnsetConfig::default(),
        }
    }
}

/// Writes the boundary polylines as CSV: `polyline, point, <x key>, <y key>`.
pub fn write_boundary(path: &Path, keys: (&str, &str), lines: &[Vec<Point>]) -> Result<()> {
    write_atomic_with(path, |w| {
        writeln!(w, "polyline,point,{},{}", keys.0, keys.1)?;
        for (k, line) in lines.iter().enumerate() {
            for (i, (x, y)) in line.iter().enumerate() {
                writeln!(w, "{k},{i},{x},{y}")?;
            }
        }
        Ok(())
    })?;
    Ok(())
}

/// What `validity-map` produced.
#[derive(Debug, Clone)]
pub struct ValidityMap {
    /// The boundary polylines in physical units (x, y as the map's axes).
    pub boundary: Vec<Vec<Point>>,
    /// Runs at or above the cut-off.
    pub valid: usize,
    /// Completed runs below it.
    pub invalid: usize,
    /// The plot's stem (`.png`, `.svg`).
    pub plot: PathBuf,
}

/// What `validity-map` runs: the study and the cut-off.
#[derive(Debug, Clone)]
pub struct ValidityOptions {
    /// The study, tier, output and threads.
    pub study: StudyOptions,
    /// The cut-off of the observable (None: the study's, else the paper's F = 0.3).
    pub cutoff: Option<f64>,
    /// Find the fragmentation onset per t/D (when the study's `[validity.onset]` enables it).
    pub onset: bool,
    /// The onset's threshold, overriding the study's.
    pub onset_threshold: Option<f64>,
}

/// `hvi-study validity-map`.
pub fn validity_map(args: &ValidityOptions) -> Result<ValidityMap> {
    let (study, plan, out) = args.study.plan()?;
    crate::sweep::print_resolution_warnings(&study, &plan)?;
    let cfg = ValidityConfig::of(&study)?;
    let cutoff = cfg.cutoff(args.cutoff)?;
    map_axes(&plan)?;
    let mut onset_cfg = cfg.onset.clone();
    if let Some(t) = args.onset_threshold {
        onset_cfg.threshold = t;
    }
    let find_onset = args.onset && onset_cfg.enabled;
    if find_onset {
        onset_cfg.check()?;
        onset_cfg.relations(&study)?;
    }

    let (table, report) = execute_plan(&plan, &out, &args.study.exec_options())?;
    if !args.study.quiet {
        log::info!("{}", report.line());
    }
    print_failures(&report.records);
    let cut = Cut {
        observable: cfg.observable,
        cutoff,
    };
    let onset = if find_onset {
        let boundary = boundary_of(&plan, &report.records, cut)?;
        let r = find_onsets(
            &study,
            &plan,
            &out,
            &onset_cfg,
            &args.study.exec_options(),
            &boundary,
        )?;
        write_onset(&out, &r)?;
        if !args.study.quiet {
            log::info!("{}", (describe_onset(&r)).trim_end_matches('\n'));
            log::info!("onset: {}", out.join("onset.csv").display());
        }
        Some(r)
    } else {
        None
    };
    validity_outputs(
        &plan,
        &out,
        cut,
        table,
        &report.records,
        args.study.quiet,
        onset.as_ref(),
    )
}

/// The map's cut-off line in the plan's physical units (x, y as the map's axes).
fn boundary_of(plan: &Plan, records: &[Record], cut: Cut) -> Result<Vec<Vec<Point>>> {
    let axes = map_axes(plan)?;
    let field = field_of(plan, records, axes, 0, |r| cut.value(r))?;
    let lines = field.contour(cut.cutoff);
    // The onset reads the line as (v0, t/D).
    Ok(if plan.axes[axes.0].key == onset::T_OVER_D {
        lines
            .into_iter()
            .map(|l| l.into_iter().map(|(x, y)| (y, x)).collect())
            .collect()
    } else {
        lines
    })
}

/// The validity map's files from a plan's results table and records (one per run, in plan
/// order; a run without a result is a failed record without observables): the `valid` column
/// of results.csv/json, validity_boundary.csv, validity_map.png/.svg and snapshots.png.
pub fn validity_outputs(
    plan: &Plan,
    out: &Path,
    cut: Cut,
    mut table: Table,
    records: &[Record],
    quiet: bool,
    onset: Option<&OnsetResult>,
) -> Result<ValidityMap> {
    let axes = map_axes(plan)?;
    let Cut { observable, cutoff } = cut;
    let (valid_col, valid, invalid) = valid_column(records, cut);
    table.push_column("valid", valid_col);
    table.write(out, "results")?;

    let field = field_of(plan, records, axes, 0, |r| cut.value(r))?;
    let boundary = field.contour(cutoff);
    let (kx, ky) = (&plan.axes[axes.0].key, &plan.axes[axes.1].key);
    write_boundary(&out.join("validity_boundary.csv"), (kx, ky), &boundary)?;
    let stem = out.join("validity_map");
    contour_plot(
        &stem,
        &ContourPlot {
            curves: onset.map_or_else(Vec::new, |o| onset_curves(plan, axes, o)),
            ..map_plot(plan, axes, records, field, cut, (valid, invalid))
        },
    )?;
    let snapshots = draw_snapshots(plan, out, axes, records, cut)?;
    if !quiet {
        log::info!(
            "validity: {valid} runs with {} >= {cutoff}, {invalid} below; boundary: {} polyline(s) in {}",
            observable,
            boundary.len(),
            out.join("validity_boundary.csv").display()
        );
        log::info!("plot: {}", stem.with_extension("png").display());
        log::info!("snapshots: {}", snapshots.display());
    }
    log::info!(target: hvi_run::STDOUT, "{}", out.join("results.csv").display());
    Ok(ValidityMap {
        boundary,
        valid,
        invalid,
        plot: stem,
    })
}

/// The observable mapped and its cut-off: a run at or above it is valid.
#[derive(Debug, Clone, Copy)]
pub struct Cut {
    /// The observable.
    pub observable: Observable,
    /// Its cut-off.
    pub cutoff: f64,
}

impl Cut {
    /// A run's value of the observable.
    fn value(&self, r: &Record) -> Option<f64> {
        r.observables.get(self.observable)
    }
}

/// The `valid` column (true, false, or null for a run without a value) and the counts of
/// valid and invalid runs.
fn valid_column(records: &[Record], cut: Cut) -> (Vec<Value>, usize, usize) {
    let column: Vec<Value> = records
        .iter()
        .map(|r| match (r.status, cut.value(r)) {
            (RunStatus::Completed, Some(v)) => Value::Bool(v >= cut.cutoff),
            _ => Value::Null,
        })
        .collect();
    let count = |b: bool| column.iter().filter(|v| **v == Value::Bool(b)).count();
    let (valid, invalid) = (count(true), count(false));
    (column, valid, invalid)
}

/// Fig. 16b: the observable over the map's axes, the cut-off in red.
fn map_plot(
    plan: &Plan,
    axes: (usize, usize),
    records: &[Record],
    field: Field,
    Cut { observable, cutoff }: Cut,
    (valid, invalid): (usize, usize),
) -> ContourPlot {
    let fragmentation = observable == Observable::Fragmentation;
    let ((x_label, fx), (y_label, fy)) = (
        shown_axis(&plan.axes[axes.0]),
        shown_axis(&plan.axes[axes.1]),
    );
    let field = Field {
        x: field.x.iter().map(|x| x * fx).collect(),
        y: field.y.iter().map(|y| y * fy).collect(),
        z: field.z,
    };
    ContourPlot {
        title: format!(
            "{} over ({x_label}, {y_label}) (Fig. 16b)",
            if fragmentation {
                "Fragmentation F"
            } else {
                observable.name()
            },
        ),
        subtitle: format!(
            "red: {} = {cutoff} (validity cut-off; the paper's is {PAPER_CUTOFF}); {valid} runs valid, {invalid} not\n{}",
            observable,
            crate::figures::conditions(plan, records),
        ),
        x_label,
        y_label,
        x_log: false,
        y_log: false,
        field,
        value_label: if fragmentation {
            "F".into()
        } else {
            observable.to_string()
        },
        levels: 6,
        highlight: Some((cutoff, format!("{} = {cutoff}", observable))),
        extra_points: Vec::new(),
        samples: None,
        region: None,
        curves: Vec::new(),
        bulk_colours: false,
        markers: Vec::new(),
    }
}

/// The onset's curves over the map, in its shown units: each relation's onset over the map's
/// t/D range (dashed), and the model's onset per t/D with its bracket (solid, dots and bars).
fn onset_curves(plan: &Plan, axes: (usize, usize), o: &OnsetResult) -> Vec<Curve> {
    let (ax, ay) = (&plan.axes[axes.0], &plan.axes[axes.1]);
    let v_is_x = ax.key == onset::V0;
    if !(v_is_x && ay.key == onset::T_OVER_D || ay.key == onset::V0 && ax.key == onset::T_OVER_D) {
        return Vec::new();
    }
    let (fv, ft) = if v_is_x {
        (shown_axis(ax).1, shown_axis(ay).1)
    } else {
        (shown_axis(ay).1, shown_axis(ax).1)
    };
    let at = |v: f64, t: f64| {
        if v_is_x {
            (v * fv, t * ft)
        } else {
            (t * ft, v * fv)
        }
    };
    let ts: Vec<f64> = o.rows.iter().map(|r| r.t_over_d).collect();
    let (t0, t1) = (ts[0], ts[ts.len() - 1]);
    let colours = [RGBColor(0, 0, 0), RGBColor(120, 40, 160)];
    let mut curves: Vec<Curve> = o
        .relations
        .relations
        .iter()
        .zip(colours.iter().cycle())
        .map(|(rel, &color)| Curve {
            points: (0..=60)
                .map(|k| {
                    let t = t0 * (t1 / t0).powf(k as f64 / 60.0);
                    at(rel.onset_m_s(t), t)
                })
                .collect(),
            label: format!("onset, {}", rel.name),
            color,
            dashed: true,
            x_bars: Vec::new(),
        })
        .collect();
    let found: Vec<_> = o
        .rows
        .iter()
        .filter_map(|r| match r.model {
            Onset::Between { lo, hi } => Some((r.t_over_d, lo, hi)),
            _ => None,
        })
        .collect();
    if !found.is_empty() {
        curves.push(Curve {
            points: found
                .iter()
                .map(|&(t, lo, hi)| at(0.5 * (lo + hi), t))
                .collect(),
            label: format!("onset, model (intact < {}, bracket)", o.config.threshold),
            color: RGBColor(0, 130, 60),
            dashed: false,
            x_bars: found
                .iter()
                .map(|&(_, lo, hi)| v_is_x.then_some((lo * fv, hi * fv)))
                .collect(),
        });
    }
    curves
}

/// Fig. 17: the runs' side views, valid framed red, invalid blue. Returns the file.
fn draw_snapshots(
    plan: &Plan,
    out: &Path,
    axes: (usize, usize),
    records: &[Record],
    cut: Cut,
) -> Result<PathBuf> {
    let Cut { observable, cutoff } = cut;
    let (cols, rows, tiles) = plan_tiles(plan, out, axes, 0, |i| {
        let v = cut.value(&records[i]);
        (
            v.map(|v| if v >= cutoff { RED } else { BLUE }),
            v.map_or("no cloud".to_string(), |v| {
                format!("{} = {v:.3}", observable)
            }),
        )
    })?;
    let snapshots = out.join("snapshots.png");
    let title = format!(
        "Debris clouds over ({}, {}) (Fig. 17): red {} >= {cutoff} (valid), blue below",
        shown_axis(&plan.axes[axes.0]).0,
        shown_axis(&plan.axes[axes.1]).0,
        observable
    );
    snapshot_matrix(
        &snapshots,
        MatrixText {
            title: &title,
            columns: &cols,
            rows: &rows,
            footer: &crate::figures::conditions(plan, records),
        },
        &tiles,
    )?;
    Ok(snapshots)
}
