//! What the targets determine of each searched parameter: a two-sided interval, a one-sided
//! bound, or nothing over the box, from the points measured and the search's model.
//!
//! An answer on a side of the box is not always a failure. When every target is met at the
//! side itself, the targets bound the parameter from the other side only, and the answer is
//! that bound ("eps <= 1e-4 J, not identified below the box's 1e-5 J"). When the targets are
//! met at the side and one step inside it, and the objective is flat across that step (the
//! lowest J on the side's line is not below the lowest a step inside by more than the noise of
//! their difference), moving the side out cannot narrow the parameter: the search stops
//! extending that side and says so, instead of spending runs to reach its limit. Where the
//! targets are met but J still falls toward the side, the optimum may lie beyond it, and the
//! side moves out like any other.

use std::collections::BTreeMap;

use crate::ego::{log_objective, Scored};
use crate::problem::Dim;
pub use crate::result::Identified;
use crate::result::{fmt_value, Edge, Evaluation, ParamRegion, SearchedBox, Side, TargetsMet};

/// Each searched parameter's identification, from the last box searched, the model's region,
/// the span where the runs meet every target and the sides the answer touches. Empty without
/// a box (no search) or, on a parameter whose answer is interior, without a region.
pub fn identify(
    boxes: &[SearchedBox],
    region: Option<&ParamRegion>,
    met: Option<&TargetsMet>,
    edges: &[Edge],
) -> BTreeMap<String, Identified> {
    let Some(last) = boxes.last() else {
        return BTreeMap::new();
    };
    let mut out = BTreeMap::new();
    for (key, &(box_lo, box_hi)) in &last.bounds {
        let on = |side: Side| edges.iter().find(|e| &e.key == key && e.side == side);
        let interval = region.and_then(|r| r.intervals.get(key)).copied();
        let span = met.and_then(|m| m.spans.get(key)).copied();
        let id = match (on(Side::Low), on(Side::High)) {
            (Some(e), _) | (_, Some(e)) if !e.targets_met => Identified::BeyondLimit {
                side: e.side,
                value: e.value,
            },
            (Some(_), Some(_)) => Identified::NotIdentified {
                low: box_lo,
                high: box_hi,
            },
            (Some(_), None) => Identified::AtMost {
                high: [interval.map(|i| i.1), span.map(|s| s.1)]
                    .into_iter()
                    .flatten()
                    .fold(box_lo, f64::max),
                floor: box_lo,
            },
            (None, Some(_)) => Identified::AtLeast {
                low: [interval.map(|i| i.0), span.map(|s| s.0)]
                    .into_iter()
                    .flatten()
                    .fold(box_hi, f64::min),
                ceiling: box_hi,
            },
            (None, None) => match interval {
                Some((low, high)) => Identified::Interval { low, high },
                None => continue,
            },
        };
        out.insert(key.clone(), id);
    }
    out
}

/// Whether a point meets every target (each term within its tolerance at the seed means).
pub(super) fn meets_every_target(e: &Evaluation) -> bool {
    e.score
        .as_ref()
        .is_some_and(|s| !s.terms.is_empty() && s.terms.iter().all(|t| t.term <= 1.0))
}

/// The scored points with `key` at `value` (in the parameter's unit): the line of the box
/// through that value.
fn on_line<'a>(
    scored: &'a [Scored],
    key: &'a str,
    value: f64,
) -> impl Iterator<Item = &'a Evaluation> + 'a {
    scored.iter().map(|(e, _)| e).filter(move |e| {
        e.params
            .get(key)
            .is_some_and(|&v| (v - value).abs() <= 1e-5 * value.abs().max(v.abs()))
    })
}

/// Whether some scored point with `key` at `value` (in the parameter's unit) meets every
/// target.
fn met_at(scored: &[Scored], key: &str, value: f64) -> bool {
    on_line(scored, key, value).any(meets_every_target)
}

/// The lowest J of the scored points with `key` at `value` (the objective's profile along the
/// other axes), when one was scored.
fn profile_at(scored: &[Scored], key: &str, value: f64) -> Option<f64> {
    on_line(scored, key, value)
        .filter(|e| e.score.is_some())
        .map(|e| e.objective)
        .min_by(f64::total_cmp)
}

/// How far (in log10 J) the profile at a side may lie below the profile a step inside and
/// still count as flat: two standard deviations of the difference of two seed means, each of
/// standard error `noise`.
fn flat_within(noise: f64) -> f64 {
    2.0 * std::f64::consts::SQRT_2 * noise
}

/// Marks each edge whose side's value holds a point meeting every target (`targets_met`), and
/// settles those where the targets are met one step inside as well and the objective is flat
/// across that step (its lowest log10 J on the side's line is not below the lowest a step inside
/// by more than [`flat_within`] of the search's `noise`): the side is not moved out (its
/// `limit` says why). Where J still falls toward the side, the side is left to move. `dims` is
/// the box, `values` its axes' grid values in the search's coordinates (ascending).
pub(super) fn settle_flat_sides(
    edges: &mut [Edge],
    dims: &[Dim],
    values: &[Vec<f64>],
    scored: &[Scored],
    noise: f64,
) {
    for edge in edges.iter_mut() {
        let Some(k) = dims.iter().position(|d| d.key == edge.key) else {
            continue;
        };
        let Dim { log, .. } = &dims[k];
        let value = |u: f64| if *log { 10f64.powf(u) } else { u };
        let axis = &values[k];
        let inner = match edge.side {
            Side::Low => axis.get(1),
            Side::High => axis.len().checked_sub(2).and_then(|i| axis.get(i)),
        };
        edge.targets_met = met_at(scored, &edge.key, edge.value);
        if edge.limit.is_none() && edge.targets_met {
            if let Some(&u) = inner {
                edge.falling = match (
                    profile_at(scored, &edge.key, edge.value),
                    profile_at(scored, &edge.key, value(u)),
                ) {
                    (Some(side), Some(inside))
                        if log_objective(inside) - log_objective(side) > flat_within(noise) =>
                    {
                        Some((side, inside))
                    }
                    _ => None,
                };
                if met_at(scored, &edge.key, value(u)) && edge.falling.is_none() {
                    edge.limit = Some(format!(
                        "the targets do not bound it on this side: every target is met at {} = \
                         {} and a step inside, at {}, and J is flat across that step",
                        edge.key,
                        fmt_value(edge.value),
                        fmt_value(value(u))
                    ));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvi_analysis::score::{Score, Term};

    fn edge(side: Side, value: f64, met: bool) -> Edge {
        Edge {
            key: "material.eps_j".into(),
            side,
            value,
            touched_by: "best point".into(),
            limit: Some("a limit".into()),
            targets_met: met,
            falling: None,
        }
    }

    fn boxes() -> Vec<SearchedBox> {
        vec![SearchedBox {
            bounds: BTreeMap::from([("material.eps_j".to_string(), (1e-5, 1.0))]),
            termination: String::new(),
            edges: Vec::new(),
        }]
    }

    fn met(lo: f64, hi: f64) -> TargetsMet {
        TargetsMet {
            points: 6,
            scored: 27,
            spans: BTreeMap::from([("material.eps_j".to_string(), (lo, hi))]),
        }
    }

    #[test]
    fn an_answer_on_a_side_where_the_targets_are_met_is_a_one_sided_bound() {
        let id = identify(
            &boxes(),
            None,
            Some(&met(1e-5, 1e-4)),
            &[edge(Side::Low, 1e-5, true)],
        );
        let eps = &id["material.eps_j"];
        assert_eq!(
            eps,
            &Identified::AtMost {
                high: 1e-4,
                floor: 1e-5
            }
        );
        assert!(eps.is_answer() && !eps.is_two_sided());
        let d = eps.describe("material.eps_j");
        assert!(
            d.starts_with("material.eps_j <= 1e-4 J, not identified below the box's 1e-5 J"),
            "{d}"
        );
        // The same side without the targets met there: the optimum is outside the box.
        let id = identify(
            &boxes(),
            None,
            Some(&met(1e-3, 1e-2)),
            &[edge(Side::Low, 1e-5, false)],
        );
        assert!(!id["material.eps_j"].is_answer());
        // Met at both sides: not identified.
        let id = identify(
            &boxes(),
            None,
            None,
            &[edge(Side::Low, 1e-5, true), edge(Side::High, 1.0, true)],
        );
        assert!(matches!(
            id["material.eps_j"],
            Identified::NotIdentified { .. }
        ));
        // Inside: the region's interval.
        let region = ParamRegion {
            intervals: BTreeMap::from([("material.eps_j".to_string(), (2e-3, 1e-2))]),
            at_boundary: BTreeMap::new(),
            sides: BTreeMap::new(),
            predicted_minimum: BTreeMap::new(),
            predicted_objective: (0.1, 0.01),
            threshold: 0.2,
            share_of_box: 0.1,
        };
        let id = identify(&boxes(), Some(&region), None, &[]);
        assert_eq!(
            id["material.eps_j"],
            Identified::Interval {
                low: 2e-3,
                high: 1e-2
            }
        );
    }

    fn scored(eps: f64, terms: &[f64]) -> Scored {
        scored_j(eps, terms, 0.1)
    }

    fn scored_j(eps: f64, terms: &[f64], objective: f64) -> Scored {
        let e = Evaluation {
            stage: crate::result::EvalStage::Extend(0),
            step: 0,
            params: BTreeMap::from([("material.eps_j".to_string(), eps)]),
            score: Some(Score {
                objective: 0.0,
                terms: terms
                    .iter()
                    .map(|&t| Term {
                        name: "t".into(),
                        observed: Some(1.0),
                        term: t,
                        weight: 1.0,
                    })
                    .collect(),
            }),
            objective,
            status: "completed".into(),
            cached: false,
            dir: None,
            seeds: vec![1, 2],
            seed_objectives: Vec::new(),
            means: BTreeMap::new(),
        };
        (e, Vec::new())
    }

    #[test]
    fn a_side_is_settled_when_the_targets_are_met_there_and_a_step_inside() {
        let dims: Vec<Dim> = vec![Dim::new("material.eps_j", true, -3.0, 0.0)];
        let values = vec![vec![-3.0, -2.0, -1.0, 0.0]];
        let mut e = vec![Edge {
            limit: None,
            ..edge(Side::Low, 1e-3, false)
        }];
        // Met at the side only: marked, not settled (the side may still move).
        settle_flat_sides(
            &mut e,
            &dims,
            &values,
            &[scored(1e-3, &[0.5]), scored(1e-2, &[1.5])],
            0.02,
        );
        assert!(e[0].targets_met && e[0].limit.is_none());
        // Met a step inside too: settled.
        settle_flat_sides(
            &mut e,
            &dims,
            &values,
            &[scored(1e-3, &[0.5]), scored(1e-2, &[0.9])],
            0.02,
        );
        let limit = e[0].limit.clone().expect("settled");
        assert!(limit.contains("do not bound it"), "{limit}");
        // Not met at the side: neither.
        let mut e = vec![Edge {
            limit: None,
            ..edge(Side::Low, 1e-3, false)
        }];
        settle_flat_sides(
            &mut e,
            &dims,
            &values,
            &[scored(1e-3, &[1.2]), scored(1e-2, &[0.1])],
            0.02,
        );
        assert!(!e[0].targets_met && e[0].limit.is_none());
    }

    /// The paper-resolution calibration's case (reports/seed-screening): every target met at
    /// the side and a step inside, but J six times lower at the side. The optimum may lie
    /// beyond it, so the side must stay free to move.
    #[test]
    fn a_side_where_the_targets_are_met_but_j_still_falls_is_not_settled() {
        let dims: Vec<Dim> = vec![Dim::new("material.eps_j", true, -3.0, 0.0)];
        let values = vec![vec![-3.0, -2.0, -1.0, 0.0]];
        let fresh = || {
            vec![Edge {
                limit: None,
                ..edge(Side::Low, 1e-3, false)
            }]
        };
        let falling = [
            scored_j(1e-3, &[0.3], 0.0335),
            scored_j(1e-2, &[0.9], 0.21),
            // A second point on the inner line, worse still: the profile is the lowest.
            scored_j(1e-2, &[0.95], 0.4),
        ];
        let mut e = fresh();
        settle_flat_sides(&mut e, &dims, &values, &falling, 0.033);
        assert!(e[0].targets_met, "{e:?}");
        assert!(e[0].limit.is_none(), "J falls toward the side: {e:?}");
        assert_eq!(e[0].falling, Some((0.0335, 0.21)));
        // At its limit, the side says so.
        e[0].limit = Some("calibrate.max_extensions = 2 steps beyond the grid reached".into());
        let line = crate::extend::limit_line(&e).expect("a limit");
        assert!(
            line.contains("J still falls toward it (0.0335 there against 0.2100 a step inside)"),
            "{line}"
        );
        // Within the noise of the difference (log10 0.0335/0.03 = 0.048 < 2 sqrt2 0.033): flat.
        let flat = [scored_j(1e-3, &[0.3], 0.03), scored_j(1e-2, &[0.9], 0.0335)];
        let mut e = fresh();
        settle_flat_sides(&mut e, &dims, &values, &flat, 0.033);
        assert!(e[0].limit.is_some(), "{e:?}");
        // The same fall under a noise that covers it: flat too.
        let mut e = fresh();
        settle_flat_sides(&mut e, &dims, &values, &falling, 0.3);
        assert!(e[0].limit.is_some(), "{e:?}");
    }
}
