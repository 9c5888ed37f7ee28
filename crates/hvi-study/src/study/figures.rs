//! The study figures: fields of an observable over two axes of a plan (the runs' records), and
//! the calibration's three maps (Figs. 9 and 10, the objective with the optimum).

use hvi_analysis::observable::Observable;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Result};
use plotters::style::RGBColor;

use super::calibrate::result::EvalStage;
use super::calibrate::result::{CalibrationResult, Evaluation};
use hvi_analysis::contour::{Field, Point};
use hvi_analysis::score::{objective, Target};
use hvi_engine::scene::Width;
use hvi_engine::state::Body;
use hvi_plot::contour::{contour_plot, ContourPlot, Marker};
use hvi_plot::snapshots::{Tile, TileCloud};
use hvi_run::plan::Plan;
use hvi_run::state::STATE_FILE;
use hvi_run::store::{Record, RunStatus};

/// The two axes a map is drawn over: the first two with more than one value (the others are
/// held at one run's values: [`field_of`]).
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

/// Axis `k`'s values, sorted, each with its index in the plan's axis (an error naming the axis
/// when a value is not a number).
pub fn sorted_axis(plan: &Plan, k: usize) -> Result<Vec<(f64, usize)>> {
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
    let xs = sorted_axis(plan, ax)?;
    let ys = sorted_axis(plan, ay)?;
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
        let slice = result.best_grid.step;
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
    // With the model's field, the grid's runs are drawn where they are.
    let samples = match surface {
        Some(_) => {
            let xs = sorted_axis(f.plan, f.axes.0)?;
            let ys = sorted_axis(f.plan, f.axes.1)?;
            Some(
                ys.iter()
                    .flat_map(|&(y, _)| xs.iter().map(move |&(x, _)| (x, y)))
                    .collect(),
            )
        }
        None => None,
    };
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

/// The tiles of a plan's runs over axes (ax, ay) at run `slice_run`'s other axis values, with
/// the column and row headers: each tile the run's cloud at the analysis time from its kept
/// state (`state.bin`; none for a run without one).
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
    let label = |k: usize, i: usize| value_label(&plan.axes[k], &plan.axes[k].values[i]);
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
        let kept = hvi_run::state::read_state(&dir.join(&run.dir).join(STATE_FILE))?;
        tiles.push(Tile {
            col,
            row,
            cloud: kept.map(|k| tile_cloud(&k.end)),
            frame,
            caption,
        });
    }
    Ok((cols, rows, tiles))
}

/// A kept cloud state as a tile draws it: every particle projected along y, in mm.
fn tile_cloud(state: &hvi_engine::cloud::CloudState) -> TileCloud {
    TileCloud {
        points: state
            .pos
            .iter()
            .map(|p| [(p.z * 1e3) as f32, (p.x * 1e3) as f32])
            .collect(),
        impactor: state.body.iter().map(|b| *b == Body::Impactor).collect(),
        rear_face_z_mm: state.plate_rear_z_m * 1e3,
    }
}

/// A number in few characters: three significant digits, `9.12e6` for large and small ones.
pub fn short_number(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    if !(1e-2..1e4).contains(&a) {
        let s = format!("{v:.2e}");
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        let m = if m.contains('.') {
            m.trim_end_matches('0').trim_end_matches('.')
        } else {
            m
        };
        return format!("{m}e{e}");
    }
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// An axis value with its symbol and unit, as a figure's header shows it: `ε = 0.01 J`,
/// `κ = 9.12e6 N/m`, `v0 = 6.7 km/s`, `t/D = 0.425`; other keys as `label = value`.
pub fn value_label(axis: &hvi_run::spec::Axis, value: &serde_json::Value) -> String {
    let Some(v) = value.as_f64() else {
        return format!("{} = {value}", axis.label);
    };
    match axis.key.as_str() {
        "material.eps_j" => format!("\u{3b5} = {} J", short_number(v)),
        "material.kappa_n_m" => format!("\u{3ba} = {} N/m", short_number(v)),
        "scene.v0_m_s" => format!("v0 = {} km/s", short_number(v / 1e3)),
        "scene.t_over_d" => format!("t/D = {}", short_number(v)),
        "run.seed" => format!("seed {value}"),
        _ => format!("{} = {}", axis.label, short_number(v)),
    }
}

/// How a figure shows an axis: its label and the factor from the study's unit to the shown
/// one (impact velocities in km/s, as impact engineers quote them; the study keeps m/s).
pub fn shown_axis(axis: &hvi_run::spec::Axis) -> (String, f64) {
    match axis.key.as_str() {
        "scene.v0_m_s" => ("v0 (km/s)".to_string(), 1e-3),
        _ => (axis.label.clone(), 1.0),
    }
}

/// The conditions of a plan's runs, for a figure's footer, so that a figure of one tier is not
/// taken for another's: the tier, the particle count (its range where the runs differ), the
/// target and impactor, and the time the cloud is measured at (from the records).
pub fn conditions(plan: &Plan, records: &[Record]) -> String {
    let (lo, hi) = records
        .iter()
        .filter_map(|r| r.observables.get(Observable::Particles))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), n| {
            (lo.min(n), hi.max(n))
        });
    let tau = records
        .iter()
        .find_map(|r| r.observables.get(Observable::Tau));
    let mut s = format!("tier `{}`", plan.tier);
    if lo == hi {
        s.push_str(&format!(", {} particles", short_number(lo)));
    } else if lo < hi {
        s.push_str(&format!(
            ", {}-{} particles",
            short_number(lo),
            short_number(hi)
        ));
    }
    if let Some(run) = plan.runs.first() {
        if let hvi_engine::scene::Geometry::SphereOnPlate {
            diameter_m,
            width_over_d,
            ..
        } = run.scene.scene
        {
            s.push_str(&format!(
                ", sphere D = {:.2} mm on a plate {:.1} mm square (W = {} D)",
                diameter_m * 1e3,
                width_over_d * diameter_m * 1e3,
                short_number(width_over_d)
            ));
        }
    }
    if let Some(t) = tau {
        s.push_str(&format!(
            ", cloud at \u{3c4} = {:.1} \u{b5}s after first contact",
            t * 1e6
        ));
    }
    s
}
