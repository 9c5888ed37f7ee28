//! The study figures: fields of an observable over two axes of a plan (the runs' records), and
//! the calibration's three maps (Figs. 9 and 10, the objective with the optimum).

use hvi_analysis::observable::Observable;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Result};
use plotters::style::RGBColor;

use super::calibrate::CalibrationResult;
use hvi_analysis::contour::Field;
use hvi_analysis::score::objective;
use hvi_plot::contour::{contour_plot, ContourPlot, Marker};
use hvi_plot::snapshots::Tile;
use hvi_run::plan::Plan;
use hvi_run::store::{Record, RunStatus};

/// The two axes a map is drawn over: the first two with more than one value. Other axes are
/// held at the value of run `slice_run` (the best run for the calibration).
pub fn map_axes(plan: &Plan) -> Result<(usize, usize)> {
    let multi: Vec<usize> = (0..plan.axes.len())
        .filter(|&k| plan.axes[k].values.len() > 1)
        .collect();
    match multi.as_slice() {
        [a, b, ..] => Ok((*a, *b)),
        _ => Err(anyhow!(
            "a map needs two axes with at least two values each (this plan has {})",
            multi.len()
        )),
    }
}

/// The field of `value(record)` over axes (ax, ay) of a plan, at the other axes' values of
/// run `slice_run`. Failed or missing runs are NaN. Axis values are sorted.
pub fn field_of(
    plan: &Plan,
    records: &[Record],
    (ax, ay): (usize, usize),
    slice_run: usize,
    value: impl Fn(&Record) -> Option<f64>,
) -> Result<Field> {
    let num = |k: usize| -> Result<Vec<(f64, usize)>> {
        let mut v: Vec<(f64, usize)> = plan.axes[k]
            .values
            .iter()
            .enumerate()
            .map(|(i, v)| {
                v.as_f64()
                    .map(|x| (x, i))
                    .ok_or_else(|| anyhow!("axis `{}` is not numeric", plan.axes[k].key))
            })
            .collect::<Result<_>>()?;
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(v)
    };
    let xs = num(ax)?;
    let ys = num(ay)?;
    let slice = &plan.run(slice_run)?.coords;
    let mut z = vec![vec![f64::NAN; xs.len()]; ys.len()];
    for (run, rec) in plan.runs.iter().zip(records) {
        let others_match = run
            .coords
            .iter()
            .enumerate()
            .all(|(k, &c)| k == ax || k == ay || c == slice[k]);
        if !others_match || rec.status != RunStatus::Completed {
            continue;
        }
        let col = xs.iter().position(|&(_, i)| i == run.coords[ax]);
        let row = ys.iter().position(|&(_, i)| i == run.coords[ay]);
        if let (Some(c), Some(r)) = (col, row) {
            z[r][c] = value(rec).filter(|v| v.is_finite()).unwrap_or(f64::NAN);
        }
    }
    Field::new(
        xs.iter().map(|p| p.0).collect(),
        ys.iter().map(|p| p.0).collect(),
        z,
    )
    .ok_or_else(|| anyhow!("axis values must be distinct to draw a map"))
}

/// An axis label: its label with the log note.
fn label(plan: &Plan, k: usize, log: bool) -> String {
    let a = &plan.axes[k];
    if log {
        format!("{} (log scale)", a.label)
    } else {
        a.label.clone()
    }
}

/// Draws the calibration's maps into `dir`: `map_R`, `map_va`, `map_objective` (.png, .svg).
/// Returns the files' stems.
pub fn calibration_maps(
    dir: &Path,
    plan: &Plan,
    records: &[Record],
    result: &CalibrationResult,
    log_axes: &[String],
) -> Result<Vec<PathBuf>> {
    let (ax, ay) = map_axes(plan)?;
    let (kx, ky) = (plan.axes[ax].key.clone(), plan.axes[ay].key.clone());
    let (lx, ly) = (log_axes.contains(&kx), log_axes.contains(&ky));
    let slice = result.best_grid.step;
    let sliced = plan
        .axes
        .iter()
        .enumerate()
        .filter(|&(k, a)| k != ax && k != ay && a.values.len() > 1)
        .map(|(k, a)| format!("{} = {}", a.key, plan.runs[slice].values[k]))
        .collect::<Vec<_>>();
    let tier = format!(
        "tier `{}`, {} particles{}",
        plan.tier,
        result.particles.map_or("?".into(), |n| format!("{n}")),
        if sliced.is_empty() {
            String::new()
        } else {
            format!("; at {}", sliced.join(", "))
        }
    );
    let at = |e: &super::calibrate::Evaluation| -> Option<(f64, f64)> {
        Some((*e.params.get(&kx)?, *e.params.get(&ky)?))
    };
    let mut markers = Vec::new();
    if let Some(p) = at(&result.paper) {
        markers.push(Marker {
            at: p,
            label: "paper's fit (0.01, 4.56e6)".into(),
            color: RGBColor(255, 255, 255),
            cross: false,
        });
    }
    if let Some(p) = at(&result.best) {
        markers.push(Marker {
            at: p,
            label: format!("optimum (J = {:.3})", result.best.objective),
            color: RGBColor(230, 0, 0),
            cross: true,
        });
    }
    let refinement: Vec<(f64, f64)> = result
        .refinement
        .iter()
        .filter(|e| e.score.is_some())
        .filter_map(at)
        .collect();
    let target_of = |observable: Observable| {
        result
            .targets
            .iter()
            .find(|t| t.observable == observable && t.weight > 0.0)
    };
    let mut stems = Vec::new();

    // Fig. 9: R.
    let r_target = target_of(Observable::LengthRatio);
    let plot = ContourPlot {
        title: "Debris-cloud length ratio R = La/Lr (Fig. 9)".into(),
        subtitle: format!(
            "{tier}; red: the experiment's R = {}",
            r_target.map_or("n/a".into(), |t| t.value.to_string())
        ),
        x_label: label(plan, ax, lx),
        y_label: label(plan, ay, ly),
        x_log: lx,
        y_log: ly,
        field: field_of(plan, records, (ax, ay), slice, |r| {
            r.observables.get(Observable::LengthRatio)
        })?,
        value_label: "R".into(),
        levels: 6,
        highlight: r_target.map(|t| (t.value, format!("experiment R = {}", t.value))),
        extra_points: Vec::new(),
        markers: markers.clone(),
    };
    let stem = dir.join("map_R");
    contour_plot(&stem, &plot)?;
    stems.push(stem);

    // Fig. 10: va / v0 (no experimental value available: no red line, said so).
    let va_target = target_of(Observable::FrontVelocityRatio);
    let plot = ContourPlot {
        title: "Axial front velocity va/v0 (Fig. 10)".into(),
        subtitle: match va_target {
            Some(t) => format!("{tier}; red: the experiment's va/v0 = {}", t.value),
            None => format!(
                "{tier}; the experiment's va/v0 is not available (experiments_data gap): no red line"
            ),
        },
        highlight: va_target.map(|t| (t.value, format!("experiment va/v0 = {}", t.value))),
        field: field_of(plan, records, (ax, ay), slice, |r| {
            r.observables.get(Observable::FrontVelocityRatio)
        })?,
        value_label: "va/v0".into(),
        ..plot
    };
    let stem = dir.join("map_va");
    contour_plot(&stem, &plot)?;
    stems.push(stem);

    // The objective, in log10 (it spans decades), with the refinement and the optimum.
    let plot = ContourPlot {
        title: "Objective J over the grid, log10 (optimum marked)".into(),
        subtitle: format!(
            "{tier}; J = weighted mean of the target terms (experiments_data/README.md); {}",
            result.termination
        ),
        highlight: Some((0.0, "J = 1: every target within tolerance".into())),
        field: field_of(plan, records, (ax, ay), slice, |r| {
            let j = objective(&result.targets, |n| r.observables.get(n)).objective;
            j.is_finite().then(|| j.max(1e-6).log10())
        })?,
        value_label: "log10 J".into(),
        extra_points: refinement,
        ..plot
    };
    let stem = dir.join("map_objective");
    contour_plot(&stem, &plot)?;
    stems.push(stem);
    Ok(stems)
}

/// The tiles of a plan's runs over axes (ax, ay) at run `slice_run`'s other axis values.
pub fn plan_tiles(
    plan: &Plan,
    dir: &Path,
    (ax, ay): (usize, usize),
    slice_run: usize,
    verdict: impl Fn(usize) -> (Option<RGBColor>, String),
) -> Result<(Vec<String>, Vec<String>, Vec<Tile>)> {
    let sorted = |k: usize| -> Vec<usize> {
        let mut idx: Vec<usize> = (0..plan.axes[k].values.len()).collect();
        idx.sort_by(|&a, &b| {
            let f = |i: usize| plan.axes[k].values[i].as_f64().unwrap_or(f64::NAN);
            f(a).total_cmp(&f(b))
        });
        idx
    };
    let (xs, ys) = (sorted(ax), sorted(ay));
    let label = |k: usize, i: usize| format!("{}", plan.axes[k].values[i]);
    let cols = xs.iter().map(|&i| label(ax, i)).collect();
    let rows = ys.iter().map(|&i| label(ay, i)).collect();
    let slice = &plan.run(slice_run)?.coords;
    let mut tiles = Vec::new();
    for run in &plan.runs {
        let others = run
            .coords
            .iter()
            .enumerate()
            .all(|(k, &c)| k == ax || k == ay || c == slice[k]);
        if !others {
            continue;
        }
        let col = xs.iter().position(|&i| i == run.coords[ax]).unwrap_or(0);
        let row = ys.iter().position(|&i| i == run.coords[ay]).unwrap_or(0);
        let (frame, caption) = verdict(run.index);
        tiles.push(Tile {
            col,
            row,
            picture: Some(dir.join(&run.dir).join("cloud_side.png")),
            frame,
            caption,
        });
    }
    Ok((cols, rows, tiles))
}
