//! The calibration's three maps over two axes of its grid: R (Fig. 9), va/v0 (Fig. 10) and the
//! objective with the optimum, the searched points and the confidence region.

use std::path::{Path, PathBuf};

use hvi_run::error::Result;

use crate::result::EvalStage;
use crate::result::{CalibrationResult, Evaluation};
use hvi_analysis::contour::{Field, Point};
use hvi_analysis::observable::Observable;
use hvi_analysis::score::{objective, Target};
use hvi_engine::scene::Width;
use hvi_plot::contour::{contour_plot, ContourPlot, Marker};
use hvi_store::plan::Plan;
use hvi_store::store::Record;
use hvi_studies::figures::{conditions, field_of, label, map_axes, on_slice};
use plotters::style::RGBColor;

/// Draws the calibration's maps into `dir`: `map_R`, `map_va`, `map_objective` (.png, .svg).
/// Returns the files' stems.
pub fn calibration_maps(
    dir: &Path,
    plan: &Plan,
    records: &[Record],
    result: &CalibrationResult,
    log_axes: &[String],
) -> Result<Vec<PathBuf>> {
    let frame = MapFrame::new(plan, records, result, log_axes)?;
    let mut stems = Vec::new();
    let mut draw = |name: &str, plot: ContourPlot| -> Result<()> {
        let stem = dir.join(name);
        contour_plot(&stem, &plot)?;
        stems.push(stem);
        Ok(())
    };
    draw("map_R", length_ratio_map(&frame)?)?;
    draw("map_va", front_velocity_map(&frame)?)?;
    draw("map_objective", objective_map(&frame)?)?;
    Ok(stems)
}

/// What the calibration's maps share: the runs, the two axes drawn and the slice through the
/// others (at the best grid point), the tier note and the marked points.
struct MapFrame<'a> {
    plan: &'a Plan,
    records: &'a [Record],
    result: &'a CalibrationResult,
    axes: (usize, usize),
    logs: (bool, bool),
    slice: usize,
    /// The tier, the particles and the slice, for the subtitles.
    tier: String,
    markers: Vec<Marker>,
    /// The calibration's confidence region over the map's axes, when it has one.
    region: Option<(Point, Point, String)>,
}

impl<'a> MapFrame<'a> {
    fn new(
        plan: &'a Plan,
        records: &'a [Record],
        result: &'a CalibrationResult,
        log_axes: &[String],
    ) -> Result<MapFrame<'a>> {
        let (ax, ay) = map_axes(plan)?;
        let (kx, ky) = (&plan.axes[ax].key, &plan.axes[ay].key);
        let slice = crate::design::position(plan, result.best_grid.step)?;
        Ok(MapFrame {
            plan,
            records,
            result,
            axes: (ax, ay),
            logs: (log_axes.contains(kx), log_axes.contains(ky)),
            slice,
            tier: tier_note(plan, records, (ax, ay), slice),
            markers: markers(result, |e| point_of(plan, (ax, ay), e)),
            region: region_of(result, (kx, ky)),
        })
    }

    /// The field of `value(record)` over the map's axes.
    fn field(&self, value: impl Fn(&Record) -> Option<f64>) -> Result<Field> {
        field_of(self.plan, self.records, self.axes, self.slice, value)
    }

    /// A map of `field` in this frame (axes, six iso-lines, the markers), untitled.
    fn plot(&self, field: Field, value_label: &str) -> ContourPlot {
        ContourPlot {
            title: String::new(),
            subtitle: String::new(),
            x_label: label(self.plan, self.axes.0, self.logs.0),
            y_label: label(self.plan, self.axes.1, self.logs.1),
            x_log: self.logs.0,
            y_log: self.logs.1,
            field,
            value_label: value_label.into(),
            levels: 6,
            highlight: None,
            extra_points: Vec::new(),
            samples: None,
            markers: self.markers.clone(),
            region: self.region.clone(),
            curves: Vec::new(),
            bulk_colours: false,
        }
    }

    /// The field of an observable and what it covers: over every box searched (seed means)
    /// when the calibration moved its box, else over the study's grid.
    fn searched_field(&self, observable: Observable) -> Result<(Field, String)> {
        Ok(match searched_lattice_field(self, observable) {
            Some((field, seeds)) => (
                field,
                format!(
                    "over every box searched, seed means at seeds {}",
                    seeds_text(&seeds)
                ),
            ),
            None => (
                self.field(|r| r.observables.get(observable))?,
                "over the study's grid".to_string(),
            ),
        })
    }

    /// Whether the calibration moved its box: its maps of R and va/v0 then reach points far
    /// from the answer (a decade beyond the grid), whose values would flatten the colours of
    /// the rest, so those maps colour the bulk of their values only.
    fn moved(&self) -> bool {
        self.result.boxes.len() > 1
    }

    /// The weighted target of an observable, if the calibration scores one.
    fn target_of(&self, observable: Observable) -> Option<&'a Target> {
        self.result
            .targets
            .iter()
            .find(|t| t.observable == observable && t.weight > 0.0)
    }
}

/// The confidence region's box over the keys `kx`, `ky`, when the calibration has one on both.
fn region_of(result: &CalibrationResult, (kx, ky): (&str, &str)) -> Option<(Point, Point, String)> {
    let r = result.region.as_ref()?;
    let (x, y) = (r.intervals.get(kx)?, r.intervals.get(ky)?);
    Some((
        (x.0, y.0),
        (x.1, y.1),
        format!("confidence region (J < {:.3})", r.threshold),
    ))
}

/// The start of the maps' subtitles: the tier, its particles and the other axes' values at
/// the slice.
fn tier_note(plan: &Plan, records: &[Record], (ax, ay): (usize, usize), slice: usize) -> String {
    let sliced = plan
        .axes
        .iter()
        .enumerate()
        .filter(|&(k, a)| k != ax && k != ay && a.values.len() > 1)
        .map(|(k, a)| format!("{} = {}", a.key, plan.runs[slice].values[k]))
        .collect::<Vec<_>>();
    format!(
        "{}{}",
        conditions(plan, records),
        if sliced.is_empty() {
            String::new()
        } else {
            format!("; at {}", sliced.join(", "))
        }
    )
}

/// Where an evaluation sits on the map's axes (None when it lacks one of them).
fn point_of(plan: &Plan, (ax, ay): (usize, usize), e: &Evaluation) -> Option<Point> {
    let (kx, ky) = (&plan.axes[ax].key, &plan.axes[ay].key);
    Some((*e.params.get(kx)?, *e.params.get(ky)?))
}

/// The paper's fit (white circle) and the optimum (red cross), where they sit on the map.
fn markers(result: &CalibrationResult, at: impl Fn(&Evaluation) -> Option<Point>) -> Vec<Marker> {
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
    markers
}

/// Seeds as a caption says them: `1, 2`.
fn seeds_text(seeds: &[u64]) -> String {
    seeds
        .iter()
        .map(|s| s.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// An observable's seed means over every box the calibration searched, when it moved the
/// box: the `grid-seeds` and `extend-*` evaluations (the grid and each extension's new grid
/// points, all at the search's seeds), at the best grid point's values of any other axis.
/// None when the box never moved or no point measured it.
fn searched_lattice_field(f: &MapFrame, observable: Observable) -> Option<(Field, Vec<u64>)> {
    if !f.moved() {
        return None;
    }
    let (kx, ky) = (&f.plan.axes[f.axes.0].key, &f.plan.axes[f.axes.1].key);
    let slice = &f.result.best_grid.params;
    let on_slice = |e: &Evaluation| {
        e.params
            .iter()
            .all(|(k, v)| k == kx || k == ky || slice.get(k).is_none_or(|s| s == v))
    };
    let points: Vec<(f64, f64, f64)> = f
        .result
        .refinement
        .iter()
        .filter(|e| e.stage == EvalStage::GridSeeds || e.stage.is_extension())
        .filter(|e| on_slice(e))
        .filter_map(|e| Some((*e.params.get(kx)?, *e.params.get(ky)?, e.mean(observable)?)))
        .collect();
    if points.is_empty() {
        return None;
    }
    let seeds = f
        .result
        .refinement
        .iter()
        .find(|e| e.stage == EvalStage::GridSeeds)
        .map(|e| e.seeds.clone())?;
    let axis = |pick: fn(&(f64, f64, f64)) -> f64| {
        let mut v: Vec<f64> = points.iter().map(pick).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    let (xs, ys) = (axis(|p| p.0), axis(|p| p.1));
    let mut z = vec![vec![f64::NAN; xs.len()]; ys.len()];
    for &(x, y, v) in &points {
        let (c, r) = (
            xs.iter().position(|&u| u == x),
            ys.iter().position(|&u| u == y),
        );
        if let (Some(c), Some(r)) = (c, r) {
            z[r][c] = v;
        }
    }
    Field::new(xs, ys, z).map(|field| (field, seeds))
}

/// Fig. 9: R, the experiment's value in red. Over every box searched (seed means) when the
/// calibration moved its box, else over the study's grid.
fn length_ratio_map(f: &MapFrame) -> Result<ContourPlot> {
    let target = f.target_of(Observable::LengthRatio);
    let (field, over) = f.searched_field(Observable::LengthRatio)?;
    Ok(ContourPlot {
        title: "Debris-cloud length ratio R = La/Lr (Fig. 9)".into(),
        subtitle: format!(
            "red: the experiment's R = {}; {}; {over}\n{}",
            target.map_or("n/a".into(), |t| t.value.to_string()),
            width_note(f.plan),
            f.tier
        ),
        highlight: target.map(|t| (t.value, format!("experiment R = {}", t.value))),
        bulk_colours: f.moved(),
        ..f.plot(field, "R")
    })
}

/// How the plan's runs read the cloud's width Lr, for the caption of a picture of R: "Lr read
/// side-on (analysis.width = side)", or both readings named where the runs differ.
pub fn width_note(plan: &Plan) -> String {
    let mut widths: Vec<Width> = plan.runs.iter().map(|r| r.scene.analysis.width).collect();
    widths.dedup();
    match widths.as_slice() {
        [w] => format!("Lr read {} (analysis.width = {})", w.label(), w.name()),
        _ => "Lr read side-on in some runs and cylindrically in others (analysis.width)".into(),
    }
}

/// Fig. 10: va / v0 (no experimental value available: no red line, said so), over the same
/// points as Fig. 9's map.
fn front_velocity_map(f: &MapFrame) -> Result<ContourPlot> {
    let target = f.target_of(Observable::FrontVelocityRatio);
    let (field, over) = f.searched_field(Observable::FrontVelocityRatio)?;
    let tier = &f.tier;
    Ok(ContourPlot {
        title: "Axial front velocity va/v0 (Fig. 10)".into(),
        subtitle: match target {
            Some(t) => format!("red: the experiment's va/v0 = {}; {over}\n{tier}", t.value),
            None => format!(
                "the experiment's va/v0 is not available (experiments_data gap): no red line; {over}\n{tier}"
            ),
        },
        highlight: target.map(|t| (t.value, format!("experiment va/v0 = {}", t.value))),
        bulk_colours: f.moved(),
        ..f.plot(field, "va/v0")
    })
}

/// The grid's objective at the search's seeds: log10 J of each grid point's seed-mean
/// observables (the `grid-seeds` evaluations), as the search scored them; None when the search
/// did not run the grid at its seeds.
fn seed_mean_field(f: &MapFrame) -> Result<Option<(Field, Vec<u64>)>> {
    let evals: Vec<&Evaluation> = f
        .result
        .refinement
        .iter()
        .filter(|e| e.stage == EvalStage::GridSeeds && e.score.is_some() && e.objective.is_finite())
        .collect();
    let Some(seeds) = evals.first().map(|e| e.seeds.clone()) else {
        return Ok(None);
    };
    let (kx, ky) = (&f.plan.axes[f.axes.0].key, &f.plan.axes[f.axes.1].key);
    let field = f.field(|r| {
        let at = |k: &String| r.params.get(k).and_then(|v| v.as_f64());
        let (x, y) = (at(kx)?, at(ky)?);
        evals
            .iter()
            .find(|e| e.params.get(kx) == Some(&x) && e.params.get(ky) == Some(&y))
            .map(|e| e.objective.max(1e-6).log10())
    })?;
    Ok(Some((field, seeds)))
}

/// Where the grid stage's runs sit on the map: each run of the plan at the slice's values of
/// the other axes, as (x, y).
fn grid_runs_on_slice(f: &MapFrame) -> Vec<(f64, f64)> {
    let (ax, ay) = f.axes;
    let slice = &f.plan.runs[f.slice].coords;
    f.plan
        .runs
        .iter()
        .filter(|r| on_slice(&r.coords, slice, f.axes))
        .filter_map(|r| Some((r.values[ax].as_f64()?, r.values[ay].as_f64()?)))
        .collect()
}

/// The objective, in log10 (it spans decades), with the refinement's points and the optimum:
/// the surrogate search's final model where there is one (it shows the valleys between grid
/// points that the search found), else over the grid at the search's seeds when it ran them
/// (the optimum's J is a seed mean), else over the grid's own runs.
fn objective_map(f: &MapFrame) -> Result<ContourPlot> {
    let result = f.result;
    let (kx, ky) = (&f.plan.axes[f.axes.0].key, &f.plan.axes[f.axes.1].key);
    let surface = result
        .surface
        .as_ref()
        .filter(|s| (&s.keys.0, &s.keys.1) == (kx, ky));
    // With the model's field, the grid's runs are drawn where they are (the grid stage's: with
    // a corner design, not every grid point).
    let samples = surface.map(|_| grid_runs_on_slice(f));
    let seed_means = match surface {
        Some(_) => None,
        None => seed_mean_field(f)?,
    };
    let (field, what) = match (surface, seed_means) {
        (Some(s), _) => (
            s.field.clone(),
            "J as the search's kriging model predicts it".to_string(),
        ),
        (None, Some((field, seeds))) => (
            field,
            format!(
                "J of the seed-mean observables at seeds {}",
                seeds_text(&seeds)
            ),
        ),
        (None, None) => (
            f.field(|r| {
                let j = objective(&result.targets, |n| r.observables.get(n)).objective;
                j.is_finite().then(|| j.max(1e-6).log10())
            })?,
            "J".to_string(),
        ),
    };
    Ok(ContourPlot {
        title: format!(
            "Objective J over the {}, log10 (optimum marked)",
            if surface.is_some() {
                "searched box"
            } else {
                "grid"
            }
        ),
        subtitle: format!(
            "{what} = weighted mean of the target terms (experiments_data/README.md); search: {} ({})\n{}",
            result.method,
            if result.converged {
                "converged"
            } else {
                "not converged"
            },
            f.tier
        ),
        highlight: Some((0.0, "J = 1: every target within tolerance".into())),
        extra_points: result
            .refinement
            .iter()
            .filter(|e| e.score.is_some() && e.stage != EvalStage::GridSeeds)
            .filter_map(|e| point_of(f.plan, f.axes, e))
            .collect(),
        samples,
        ..f.plot(field, "log10 J")
    })
}
