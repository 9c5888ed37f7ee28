//! The study figures: fields of an observable over two axes of a plan (the runs' records), the
//! tiles of a plan's runs, and the labels and conditions the pictures share.

use hvi_analysis::observable::Observable;
use std::path::Path;

use hvi_run::error::{Result, RunError};
use plotters::style::RGBColor;

use hvi_analysis::contour::Field;
use hvi_engine::state::Body;
use hvi_plot::snapshots::{Tile, TileCloud};
use hvi_run::state::STATE_FILE;
use hvi_store::plan::Plan;
use hvi_store::store::{Record, RunStatus};

/// The two axes a map is drawn over: the first two with more than one value (the others are
/// held at one run's values: [`field_of`]).
pub fn map_axes(plan: &Plan) -> Result<(usize, usize)> {
    let multi: Vec<usize> = (0..plan.axes.len())
        .filter(|&k| plan.axes[k].values.len() > 1)
        .collect();
    match multi.as_slice() {
        [a, b, ..] => Ok((*a, *b)),
        _ => Err(RunError::Input(format!(
            "a map needs two axes with at least two values each (this plan has {})",
            multi.len()
        ))),
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
            v.as_f64().map(|x| (x, i)).ok_or_else(|| {
                RunError::Input(format!("axis `{}` is not numeric", plan.axes[k].key))
            })
        })
        .collect::<Result<_>>()?;
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(v)
}

/// Whether a run with axis indices `coords` lies on the slice through `slice` (another run's
/// indices) over axes (ax, ay): every other axis at the slice's value.
pub fn on_slice(coords: &[usize], slice: &[usize], (ax, ay): (usize, usize)) -> bool {
    coords
        .iter()
        .enumerate()
        .all(|(k, &c)| k == ax || k == ay || c == slice[k])
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
        if !on_slice(&run.coords, slice, (ax, ay)) || rec.status != RunStatus::Completed {
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
    .ok_or_else(|| RunError::Input("axis values must be distinct to draw a map".to_string()))
}

/// An axis label: its label with the log note.
pub fn label(plan: &Plan, k: usize, log: bool) -> String {
    let a = &plan.axes[k];
    if log {
        format!("{} (log scale)", a.label)
    } else {
        a.label.clone()
    }
}

/// The tiles of a plan's runs over axes (ax, ay) at run `slice_run`'s other axis values, with
/// the column and row headers: each tile the run's cloud at the analysis time from its kept
/// state (`state.bin`; none for a run without one). `verdict(k)` frames and captions the run at
/// position k of `plan.runs` (a plan may hold a subset of a study's runs).
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
    for (position, run) in plan.runs.iter().enumerate() {
        if !on_slice(&run.coords, slice, (ax, ay)) {
            continue;
        }
        let col = xs.iter().position(|&i| i == run.coords[ax]).unwrap_or(0);
        let row = ys.iter().position(|&i| i == run.coords[ay]).unwrap_or(0);
        let (frame, caption) = verdict(position);
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
pub fn value_label(axis: &hvi_store::spec::Axis, value: &serde_json::Value) -> String {
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
pub fn shown_axis(axis: &hvi_store::spec::Axis) -> (String, f64) {
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
