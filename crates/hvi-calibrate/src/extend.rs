//! An optimum on the edge of its box is not an optimum: the sides of the searched box that the
//! chosen point or its confidence region touch, and the box extended past them.
//!
//! A side is touched when the chosen point lies on it, or when the confidence region reaches
//! it (the parameter may then lie beyond). Each touched side moves out by one step of its axis:
//! the grid's spacing at that side, in log10 on a log axis and at most a decade (a decade
//! when the axis has one value). The new grid points next to the answer (those of the larger
//! box's lattice within one grid step of it on every axis, or of a better point beyond the box
//! that pulled a side) run at the search's seeds before the
//! search goes on in the larger box; the surrogate's expected improvement decides whether
//! anything farther along the new side is worth a run. A side stops moving at a limit, which
//! the calibration then states: `calibrate.max_extensions` steps beyond the grid, or a value the
//! scene rejects (outside the key's allowed range).

use std::collections::BTreeMap;

use crate::problem::{as_num, Dim, Refinement};
pub use crate::result::{fmt_value, Edge, SearchedBox, Side};
use hvi_run::error::Result;
use hvi_store::plan::Plan;
use hvi_store::spec::round_sig;

/// How far a calibration may move the box's sides.
#[derive(Debug, Clone, Copy)]
pub struct ExtendRule {
    /// Whether to extend at all (`--no-extend`: no).
    pub extend: bool,
    /// Steps a side may move beyond the grid.
    pub max_extensions: usize,
}

/// The box in the parameters' units.
pub(super) fn bounds_of(dims: &[Dim]) -> BTreeMap<String, (f64, f64)> {
    dims.iter()
        .map(
            |Dim {
                 key: k,
                 log,
                 lo,
                 hi,
             }| {
                let v = |u: f64| round_sig(if *log { 10f64.powf(u) } else { u }, 6);
                (k.clone(), (v(*lo), v(*hi)))
            },
        )
        .collect()
}

/// The sides of the box (`dims`) that the chosen point (`best`, in the search's coordinates)
/// or the confidence region's per-axis sides touch.
pub(super) fn edges_of(
    dims: &[Dim],
    best: Option<&[f64]>,
    region_sides: Option<&BTreeMap<String, (bool, bool)>>,
) -> Vec<Edge> {
    let mut edges = Vec::new();
    for (k, Dim { key, log, lo, hi }) in dims.iter().enumerate() {
        let tol = 1e-9 * (hi - lo).abs().max(1.0);
        let at = best.and_then(|b| b.get(k)).copied();
        let region = region_sides.and_then(|s| s.get(key)).copied();
        for (side, bound, best_on, region_on) in [
            (
                Side::Low,
                *lo,
                at.is_some_and(|u| u <= lo + tol),
                region.is_some_and(|r| r.0),
            ),
            (
                Side::High,
                *hi,
                at.is_some_and(|u| u >= hi - tol),
                region.is_some_and(|r| r.1),
            ),
        ] {
            let touched_by = match (best_on, region_on) {
                (true, true) => "best point and confidence region",
                (true, false) => "best point",
                (false, true) => "confidence region",
                (false, false) => continue,
            };
            edges.push(Edge {
                key: key.clone(),
                side,
                value: round_sig(if *log { 10f64.powf(bound) } else { bound }, 6),
                touched_by: touched_by.into(),
                limit: None,
                targets_met: false,
                falling: None,
            });
        }
    }
    edges
}

/// The grid's values of each searched axis, in the search's coordinates, ascending.
pub(super) fn grid_coords(plan: &Plan, dims: &[Dim]) -> Result<Vec<Vec<f64>>> {
    dims.iter()
        .map(|Dim { key, log, .. }| {
            let axis = plan.axes.iter().find(|a| &a.key == key);
            let mut v: Vec<f64> = match axis {
                Some(a) => a
                    .values
                    .iter()
                    .map(|x| as_num(x, key).map(|x| if *log { x.log10() } else { x }))
                    .collect::<Result<_>>()?,
                None => Vec::new(),
            };
            v.sort_by(f64::total_cmp);
            v.dedup();
            Ok(v)
        })
        .collect()
}

/// One step of an axis beyond its side, in the search's coordinates: the grid's spacing there
/// (the distance between the two outermost values on that side), on a log axis in log10 and
/// at most a decade (a kappa grid in factor-2 steps moves by a factor 2, a grid in decades or
/// coarser by a decade). A log axis with one value moves by a decade; a linear one has no
/// step.
pub(super) fn step_of(log: bool, values: &[f64], side: Side) -> Option<f64> {
    let n = values.len();
    if n < 2 {
        return log.then_some(1.0);
    }
    let d = match side {
        Side::Low => values[1] - values[0],
        Side::High => values[n - 1] - values[n - 2],
    };
    let d = if log { d.min(1.0) } else { d };
    (d > 0.0).then_some(d)
}

/// Extends the box past `edges` (each side by one step, unless it reached its limit, which is
/// then written into the edge), adding the new values to `values`. Returns whether any side
/// moved. A value the scene rejects is a limit.
pub(super) fn extend(
    problem: &Refinement,
    dims: &mut [Dim],
    values: &mut [Vec<f64>],
    edges: &mut [Edge],
    moved: &mut BTreeMap<(String, Side), usize>,
    rule: ExtendRule,
) -> Result<bool> {
    let mut any = false;
    for edge in edges.iter_mut() {
        // Settled already (the targets do not bound it there).
        if edge.limit.is_some() {
            continue;
        }
        if !rule.extend {
            edge.limit = Some("not extended (--no-extend)".into());
            continue;
        }
        let Some(k) = dims.iter().position(|d| d.key == edge.key) else {
            continue;
        };
        let done = moved.entry((edge.key.clone(), edge.side)).or_insert(0);
        if *done >= rule.max_extensions {
            edge.limit = Some(format!(
                "calibrate.max_extensions = {} steps beyond the grid reached",
                rule.max_extensions
            ));
            continue;
        }
        let Dim { log, lo, hi, .. } = dims[k].clone();
        let Some(step) = step_of(log, &values[k], edge.side) else {
            edge.limit = Some("the axis has one grid value: no step to extend by".into());
            continue;
        };
        let u = match edge.side {
            Side::Low => lo - step,
            Side::High => hi + step,
        };
        // The new value must make a valid scene (with the other axes at the chosen point's).
        let mut probe = dims.to_vec();
        probe[k].lo = probe[k].lo.min(u);
        probe[k].hi = probe[k].hi.max(u);
        let params: BTreeMap<String, f64> = {
            let x: Vec<f64> = probe
                .iter()
                .enumerate()
                .map(|(a, d)| if a == k { u } else { 0.5 * (d.lo + d.hi) })
                .collect();
            problem.values_in(&probe, &x)
        };
        if let Some(why) = problem.invalid(&params)? {
            let v = params.get(&edge.key).copied().unwrap_or(f64::NAN);
            edge.limit = Some(format!(
                "{} = {} is rejected by the scene: {why}",
                edge.key,
                fmt_value(v)
            ));
            continue;
        }
        dims[k] = probe[k].clone();
        values[k].push(u);
        values[k].sort_by(f64::total_cmp);
        *done += 1;
        any = true;
    }
    Ok(any)
}

/// The values of each axis within one grid step of `near` (the grid value nearest to it and
/// its neighbours on either side).
fn values_near(values: &[Vec<f64>], near: &[f64]) -> Vec<Vec<f64>> {
    values
        .iter()
        .zip(near)
        .map(|(axis, &u)| {
            let Some(k) = (0..axis.len())
                .min_by(|&a, &b| (axis[a] - u).abs().total_cmp(&(axis[b] - u).abs()))
            else {
                return Vec::new();
            };
            axis[k.saturating_sub(1)..(k + 2).min(axis.len())].to_vec()
        })
        .collect()
}

/// The points of the lattice of `values` that `seen` does not hold and that lie within one grid
/// step of one of `centres` on every axis ([`new_lattice_points`] when there is no centre), in
/// the search's coordinates and the lattice's order.
pub(super) fn new_points_near(
    values: &[Vec<f64>],
    seen: &[Vec<f64>],
    centres: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    let near: Vec<Vec<Vec<f64>>> = centres.iter().map(|c| values_near(values, c)).collect();
    new_lattice_points(values, seen)
        .into_iter()
        .filter(|p| {
            near.is_empty()
                || near
                    .iter()
                    .any(|n| p.iter().zip(n).all(|(x, axis)| axis.contains(x)))
        })
        .collect()
}

/// Every point of the lattice of `values` (one list per axis) that `seen` does not hold, in
/// the search's coordinates.
fn new_lattice_points(values: &[Vec<f64>], seen: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut points: Vec<Vec<f64>> = vec![Vec::new()];
    for axis in values {
        points = points
            .into_iter()
            .flat_map(|p| {
                axis.iter().map(move |&u| {
                    let mut q = p.clone();
                    q.push(u);
                    q
                })
            })
            .collect();
    }
    let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9);
    points
        .into_iter()
        .filter(|p| !seen.iter().any(|s| close(p, s)))
        .collect()
}

/// The limit in words for a report: `outside the box up to material.eps_j = 10`.
pub(super) fn limit_line(edges: &[Edge]) -> Option<String> {
    let limited: Vec<String> = edges
        .iter()
        .filter(|e| e.limit.is_some())
        .map(|e| {
            if e.targets_met {
                let falling = e.falling.map_or(String::new(), |(side, inside)| {
                    format!(
                        ", and J still falls toward it ({side:.4} there against {inside:.4} a \
                         step inside): the objective's optimum may lie beyond"
                    )
                });
                return format!(
                    "every target is met at the box's {} side, {} = {}: the targets do not bound \
                     it {} ({}){falling}",
                    e.side.name(),
                    e.key,
                    fmt_value(e.value),
                    match e.side {
                        Side::Low => "from below",
                        Side::High => "from above",
                    },
                    e.limit.as_deref().unwrap_or("")
                );
            }
            format!(
                "{} lies at or {} the box's {} side, {} = {} ({})",
                e.key,
                match e.side {
                    Side::Low => "below",
                    Side::High => "beyond",
                },
                e.side.name(),
                e.key,
                fmt_value(e.value),
                e.limit.as_deref().unwrap_or("")
            )
        })
        .collect();
    (!limited.is_empty()).then(|| limited.join("; "))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dims() -> Vec<Dim> {
        vec![
            Dim::new("material.eps_j", true, -2.0, 0.0),
            Dim::new("material.kappa_n_m", true, 6.0, 7.0),
        ]
    }

    #[test]
    fn a_best_point_on_a_side_and_a_region_on_another_are_both_edges() {
        let sides: BTreeMap<String, (bool, bool)> = [
            ("material.eps_j".to_string(), (false, true)),
            ("material.kappa_n_m".to_string(), (true, false)),
        ]
        .into();
        let e = edges_of(&dims(), Some(&[0.0, 6.5]), Some(&sides));
        assert_eq!(e.len(), 2, "{e:?}");
        assert_eq!(
            (e[0].side, e[0].touched_by.as_str()),
            (Side::High, "best point and confidence region")
        );
        assert_eq!(e[0].value, 1.0);
        assert_eq!(
            (e[1].side, e[1].touched_by.as_str()),
            (Side::Low, "confidence region")
        );
        assert!(edges_of(&dims(), Some(&[-1.0, 6.5]), None).is_empty());
    }

    #[test]
    fn an_axis_moves_by_its_grid_spacing_at_the_side() {
        assert_eq!(step_of(true, &[-2.0, -1.0, 0.0], Side::High), Some(1.0));
        // kappa in factor-2 steps (log10): a factor 2 at either side, not a decade.
        let kappa: Vec<f64> = [1.14e6, 2.28e6, 4.56e6, 9.12e6]
            .iter()
            .map(|k: &f64| k.log10())
            .collect();
        for side in [Side::Low, Side::High] {
            let step = step_of(true, &kappa, side).expect("a step");
            assert!((step - 2f64.log10()).abs() < 1e-12, "{step}");
        }
        assert_eq!(step_of(true, &[6.0], Side::High), Some(1.0));
        // A log grid coarser than a decade moves by a decade.
        assert_eq!(step_of(true, &[-4.4, -2.2], Side::Low), Some(1.0));
        assert_eq!(
            step_of(false, &[1.3, 1.5, 1.8], Side::High),
            Some(0.30000000000000004)
        );
        assert_eq!(
            step_of(false, &[1.3, 1.5, 1.8], Side::Low),
            Some(0.19999999999999996)
        );
        assert_eq!(step_of(false, &[1.5], Side::Low), None);
    }

    #[test]
    fn the_new_lattice_points_are_those_not_run() {
        let values = vec![vec![-2.0, -1.0, 0.0, 1.0], vec![6.0, 7.0]];
        let seen: Vec<Vec<f64>> = [-2.0, -1.0, 0.0]
            .iter()
            .flat_map(|&a| [vec![a, 6.0], vec![a, 7.0]])
            .collect();
        let new = new_lattice_points(&values, &seen);
        assert_eq!(new, vec![vec![1.0, 6.0], vec![1.0, 7.0]]);
    }

    #[test]
    fn the_new_points_are_those_within_a_grid_step_of_a_centre() {
        let values = vec![vec![-3.0, -2.0, -1.0, 0.0], vec![6.0, 6.3, 6.6, 6.9, 7.2]];
        // One step either way of the nearest value, clipped at the ends; off the grid, from
        // the nearest value.
        assert_eq!(
            values_near(&values, &[-2.0, 6.9]),
            vec![vec![-3.0, -2.0, -1.0], vec![6.6, 6.9, 7.2]]
        );
        assert_eq!(
            values_near(&values, &[-0.2, 6.05]),
            vec![vec![-1.0, 0.0], vec![6.0, 6.3]]
        );
        // After two sides moved (eps down to -3, kappa up to 7.2), the points of the new
        // lines next to the answer at (-2, 6.9) are the ones to run; the far ends are not.
        let seen: Vec<Vec<f64>> = [-2.0, -1.0, 0.0]
            .iter()
            .flat_map(|&a| [6.0, 6.3, 6.6, 6.9].map(|k| vec![a, k]))
            .collect();
        let answer = vec![-2.0, 6.9];
        assert_eq!(
            new_points_near(&values, &seen, std::slice::from_ref(&answer)),
            vec![
                vec![-3.0, 6.6],
                vec![-3.0, 6.9],
                vec![-3.0, 7.2],
                vec![-2.0, 7.2],
                vec![-1.0, 7.2]
            ]
        );
        // A second centre (a better point that pulled a side, say) adds the points near it.
        let near_both = new_points_near(&values, &seen, &[answer, vec![-3.0, 6.0]]);
        assert_eq!(near_both.len(), 7, "{near_both:?}");
        assert!(near_both.contains(&vec![-3.0, 6.0]) && near_both.contains(&vec![-3.0, 6.3]));
        assert!(!near_both.contains(&vec![0.0, 7.2]));
        // No centre: every new point.
        assert_eq!(new_points_near(&values, &seen, &[]).len(), 8);
    }

    #[test]
    fn values_print_short() {
        assert_eq!(fmt_value(1.0), "1");
        assert_eq!(fmt_value(4.56e6), "4.56e6");
        assert_eq!(fmt_value(0.01), "1e-2");
    }
}
