//! The surrogate search, box after box: in the grid's box first, then, while the answer
//! touches a side, in the box extended past it (its new grid points run first), until the
//! answer is interior or every touched side is at its limit.

use std::collections::BTreeMap;

use hvi_run::error::Result;
use hvi_store::store::Record;

use crate::config::{CalibrateConfig, Method};
use crate::ego;
use crate::extend::{
    bounds_of, edges_of, extend, grid_coords, limit_line, new_points_near, ExtendRule,
};
use crate::grid::Grid;
use crate::identify;
use crate::problem::{Dim, Refinement, Stage};
use crate::result::{fmt_bounds, Edge, EvalStage, Evaluation, SearchedBox, Side};
use crate::{CalibrateOptions, SearchOutcome};

/// The surrogate search, box after box. A scored point outside the box (`anchor`, the paper's
/// fit at the search's seeds) that beats the box's answer moves the sides between them out
/// the same way, and joins the search once the box holds it.
pub(super) fn ego_boxes(
    stage: &Stage,
    first: &Refinement,
    cfg: &CalibrateConfig,
    args: &CalibrateOptions,
    grid: &Grid,
    refine_keys: &[String],
    anchor: Option<ego::Scored>,
) -> Result<SearchOutcome> {
    let settings = settings_of(first, cfg, args)?;
    let rule = ExtendRule {
        extend: args.extend,
        max_extensions: cfg.max_extensions,
    };
    if first.progress {
        announce(first, &settings, rule, refine_keys);
    }
    let mut walk = Walk::start(
        stage,
        first,
        settings,
        rule,
        grid,
        args.coarse.as_ref(),
        anchor,
    )?;
    loop {
        let problem = stage.problem(first.fixed.clone(), walk.dims.clone());
        walk.admit_anchor(&problem);
        if walk.rule.extend && walk.extend_before_batches(&problem)? {
            continue;
        }
        if let Some(outcome) = walk.search_box(&problem)? {
            return Ok(outcome);
        }
    }
}

/// The search's settings from the study and the command line.
fn settings_of(
    first: &Refinement,
    cfg: &CalibrateConfig,
    args: &CalibrateOptions,
) -> Result<ego::EgoSettings> {
    Ok(ego::EgoSettings {
        batch: cfg.batch,
        seeds: cfg.seeds.clone(),
        max_batches: args.max_batches.unwrap_or(cfg.max_batches),
        noise_floor: cfg.noise_floor,
        seeds_within_decades: cfg.seeds_within_decades,
        prior: match &args.coarse {
            Some(c) => Some(ego::prior_of(first, c)?),
            None => None,
        },
    })
}

/// The search's first line on the console.
fn announce(first: &Refinement, settings: &ego::EgoSettings, rule: ExtendRule, keys: &[String]) {
    log::info!(
        "search: efficient global optimisation over {} (log10 for {:?}), batches of {} at seeds {:?}{}, at most {} batches a box, noise floor {}; {}",
        keys.join(", "),
        first.dims.iter().filter(|d| d.log).map(|d| d.key.as_str()).collect::<Vec<_>>(),
        settings.batch,
        settings.seeds,
        ego::screening(settings),
        settings.max_batches,
        settings.noise_floor,
        if rule.extend {
            format!("a side the answer touches moves out, up to {} steps", rule.max_extensions)
        } else {
            "the box is kept (--no-extend)".to_string()
        }
    );
}

/// Prints the sides an answer touches, `when` after each side's name.
fn print_edges(edges: &[Edge], when: &str) {
    for e in edges {
        log::info!(
            "edge: {}{when}{}",
            e.describe(),
            e.limit.as_ref().map_or(String::new(), |l| format!(": {l}"))
        );
    }
}

/// Where the walk stands between boxes.
struct Walk<'s, 'a> {
    stage: &'s Stage<'a>,
    first: &'s Refinement<'a>,
    settings: ego::EgoSettings,
    rule: ExtendRule,
    /// Every point scored so far, with its runs' observables.
    scored: Vec<ego::Scored>,
    /// The current box.
    dims: Vec<Dim>,
    /// The grid's values on each axis, the extensions' included (search coordinates).
    values: Vec<Vec<f64>>,
    /// How far each side has moved.
    moved: BTreeMap<(String, Side), usize>,
    /// Every box searched so far.
    boxes: Vec<SearchedBox>,
    /// Search batches spent so far.
    batches: usize,
    /// Extensions made so far.
    extension: usize,
    /// Runs simulated so far.
    runs: usize,
    /// The paper's fit at the search's seeds, until the box holds it.
    anchor: Option<ego::Scored>,
}

impl<'s, 'a> Walk<'s, 'a> {
    /// The grid at the search's seeds, and a coarser level's answer beside it (unless the
    /// grid holds it).
    fn start(
        stage: &'s Stage<'a>,
        first: &'s Refinement<'a>,
        settings: ego::EgoSettings,
        rule: ExtendRule,
        grid: &Grid,
        coarse: Option<&crate::Coarse>,
        anchor: Option<ego::Scored>,
    ) -> Result<Self> {
        let pairs: Vec<(Evaluation, Vec<Record>)> = grid
            .evaluations
            .iter()
            .cloned()
            .zip(grid.shot_records.iter().cloned())
            .collect();
        let (mut scored, mut runs) = ego::seeded_grid(first, &settings, &pairs)?;
        let seeds = ego::seed_list(&settings);
        if let Some(c) = coarse {
            let at: BTreeMap<String, f64> = first
                .dims
                .iter()
                .filter_map(|d| c.best.get(&d.key).map(|v| (d.key.clone(), *v)))
                .collect();
            let coords = ego::coords(first, &at);
            let seen = scored
                .iter()
                .any(|(e, _)| ego::coords(first, &e.params) == coords);
            if coords.is_some() && !seen {
                let (evs, n) = ego::run_points(first, EvalStage::CoarseAnswer, &[at], &seeds)?;
                scored.extend(evs);
                runs += n;
            }
        }
        let dims = first.dims.clone();
        let values = grid_coords(first.plan, &dims)?;
        Ok(Walk {
            stage,
            first,
            settings,
            rule,
            scored,
            dims,
            values,
            moved: BTreeMap::new(),
            boxes: Vec::new(),
            batches: 0,
            extension: 0,
            runs,
            anchor,
        })
    }

    /// The anchor joins the observations once the box holds it (unless a scored point sits
    /// there already: the paper's fit is often a grid point).
    fn admit_anchor(&mut self, problem: &Refinement) {
        let inside = self
            .anchor
            .as_ref()
            .is_some_and(|a| outside_sides(&self.dims, problem, &a.0).is_empty());
        if !inside {
            return;
        }
        let a = self.anchor.take();
        let at = a.as_ref().and_then(|a| ego::coords(problem, &a.0.params));
        let seen = self
            .scored
            .iter()
            .any(|(e, _)| ego::coords(problem, &e.params) == at);
        if !seen {
            self.scored.extend(a);
        }
    }

    /// Where the points scored so far put the answer: on a side, the box moves out before any
    /// batch is spent inside it. Returns whether it moved.
    fn extend_before_batches(&mut self, problem: &Refinement) -> Result<bool> {
        let probe = ego::EgoSettings {
            max_batches: 0,
            ..self.settings.clone()
        };
        // Quiet: the search in this box, if it runs, reports the same numbers.
        let mut quiet = self
            .stage
            .problem(self.first.fixed.clone(), self.dims.clone());
        quiet.progress = false;
        let p = ego::search(&quiet, &probe, self.scored.clone(), self.batches)?;
        let at = ego::coords(problem, &p.best.params);
        let sides = p.region.as_ref().map(|r| &r.sides);
        let mut edges = edges_of(&self.dims, at.as_deref(), sides);
        identify::settle_flat_sides(&mut edges, &self.dims, &self.values, &self.scored, p.noise);
        let before = bounds_of(&self.dims);
        if edges.is_empty() || !self.extend(problem, &mut edges)? {
            return Ok(false);
        }
        if problem.progress {
            print_edges(&edges, " (before this box's batches)");
        }
        self.boxes.push(SearchedBox {
            bounds: before,
            termination: "extended before its batches: the answer from the points scored so \
                          far touches a side"
                .into(),
            edges,
        });
        let centres: Vec<Vec<f64>> = at.into_iter().collect();
        self.run_extension(&centres)?;
        Ok(true)
    }

    /// Moves the sides `edges` out (each by one step, unless at its limit); whether any moved.
    fn extend(&mut self, problem: &Refinement, edges: &mut [Edge]) -> Result<bool> {
        extend(
            problem,
            &mut self.dims,
            &mut self.values,
            edges,
            &mut self.moved,
            self.rule,
        )
    }

    /// Runs the extended box's new grid points: those of its lattice not scored yet within a
    /// grid step of `centres` (the answer, and a better point beyond the box that pulled a side;
    /// in the search's coordinates; every new point without a centre: [`new_points_near`]), at
    /// the search's seeds as screened ([`ego::run_points_screened`]).
    fn run_extension(&mut self, centres: &[Vec<f64>]) -> Result<()> {
        let problem = self
            .stage
            .problem(self.first.fixed.clone(), self.dims.clone());
        let seeds = ego::seed_list(&self.settings);
        let seen: Vec<Vec<f64>> = self
            .scored
            .iter()
            .filter_map(|(e, _)| ego::coords(&problem, &e.params))
            .collect();
        let points: Vec<BTreeMap<String, f64>> = new_points_near(&self.values, &seen, centres)
            .iter()
            .map(|x| problem.values(x))
            .collect();
        let label = EvalStage::Extend(self.extension);
        if problem.progress {
            log::info!(
                "{label}: the box is now {}; {} new grid point(s) at {} seed(s){}",
                fmt_bounds(&bounds_of(&self.dims)),
                points.len(),
                seeds.len(),
                ego::screening(&self.settings)
            );
        }
        let (evs, n) = ego::run_points_screened(
            &problem,
            label,
            &points,
            &seeds,
            &self.settings,
            ego::lowest(&self.scored),
        )?;
        self.scored.extend(evs);
        self.runs += n;
        self.extension += 1;
        Ok(())
    }

    /// The search's batches in this box. The answer when no side moves (else the box has
    /// moved out and its new grid points have run).
    fn search_box(&mut self, problem: &Refinement) -> Result<Option<SearchOutcome>> {
        let scored = std::mem::take(&mut self.scored);
        let o = ego::search(problem, &self.settings, scored, self.batches)?;
        self.runs += o.runs;
        self.batches += o.batches;
        let at = ego::coords(problem, &o.best.params);
        let sides = o.region.as_ref().map(|r| &r.sides);
        let mut edges = edges_of(&self.dims, at.as_deref(), sides);
        self.pulled_by_anchor(problem, &o.best, &mut edges);
        identify::settle_flat_sides(
            &mut edges,
            &self.dims,
            &self.values,
            &o.evaluations,
            o.noise,
        );
        let moved_now = !edges.is_empty() && self.extend(problem, &mut edges)?;
        self.boxes.push(SearchedBox {
            bounds: bounds_of(&problem.dims),
            termination: o.termination.clone(),
            edges: edges.clone(),
        });
        if problem.progress {
            print_edges(&edges, "");
        }
        if !moved_now {
            return Ok(Some(self.outcome(o, edges)));
        }
        self.scored = o.evaluations;
        let centres: Vec<Vec<f64>> = at
            .into_iter()
            .chain(
                self.better_anchor(&o.best)
                    .and_then(|a| ego::coords(problem, &a.params)),
            )
            .collect();
        self.run_extension(&centres)?;
        Ok(None)
    }

    /// The anchor, while it waits outside the box, when it scores below `best`.
    fn better_anchor(&self, best: &Evaluation) -> Option<&Evaluation> {
        self.anchor
            .as_ref()
            .map(|a| &a.0)
            .filter(|a| a.objective < best.objective)
    }

    /// A better point outside the box (the anchor) pulls the sides between them out.
    fn pulled_by_anchor(&self, problem: &Refinement, best: &Evaluation, edges: &mut Vec<Edge>) {
        let Some(a) = self.better_anchor(best) else {
            return;
        };
        for (key, side, value) in outside_sides(&self.dims, problem, a) {
            if !edges.iter().any(|e| e.key == key && e.side == side) {
                edges.push(Edge {
                    key,
                    side,
                    value,
                    touched_by: format!(
                        "a better point beyond it (the paper's fit, J = {:.4} against {:.4})",
                        a.objective, best.objective
                    ),
                    limit: None,
                    targets_met: false,
                    falling: None,
                });
            }
        }
    }

    /// The answer of the last box.
    fn outcome(&mut self, o: ego::EgoOutcome, edges: Vec<Edge>) -> SearchOutcome {
        let limit = limit_line(&edges);
        let (termination, converged, bounded) =
            verdict_of(o.converged, &o.termination, &edges, limit.as_deref());
        SearchOutcome {
            method: Method::Ego.name(),
            evaluations: o
                .evaluations
                .into_iter()
                .map(|(e, _)| e)
                .filter(|e| e.stage != EvalStage::Grid && e.stage != EvalStage::Paper)
                .collect(),
            best: Some(o.best),
            termination,
            converged,
            bounded,
            noise: Some(o.noise),
            noise_source: Some(o.noise_source),
            surface: o.surface,
            region: o.region,
            spread: o.spread,
            runs: self.runs,
            boxes: std::mem::take(&mut self.boxes),
            edges,
            limit,
            seeds: self.settings.seeds.clone(),
            prior_weight: o.prior_weight,
        }
    }
}

/// The search's termination in words, whether it converged (the stopping rule held with the
/// answer inside the box) and whether the answer is a bound (the rule held, and every target
/// is met on each side the answer touches).
pub(super) fn verdict_of(
    rule_held: bool,
    why: &str,
    edges: &[Edge],
    limit: Option<&str>,
) -> (String, bool, bool) {
    let sides =
        |f: &dyn Fn(&Edge) -> String, sep: &str| edges.iter().map(f).collect::<Vec<_>>().join(sep);
    let bounded = rule_held && !edges.is_empty() && edges.iter().all(|e| e.targets_met);
    let termination =
        if edges.is_empty() && rule_held {
            format!("converged: {why}")
        } else if edges.is_empty() {
            why.to_string()
        } else if bounded {
            format!(
            "bounded: every target is met on the side{} the answer touches ({}), so the targets \
             bound it from the other side only; {why}",
            if edges.len() > 1 { "s" } else { "" },
            sides(&|e| format!("the {} side of {}", e.side.name(), e.key), ", ")
        )
        } else {
            format!(
                "not converged: the answer touches {}; {}",
                sides(&Edge::describe, " and "),
                limit.unwrap_or_default()
            )
        };
    (termination, rule_held && edges.is_empty(), bounded)
}

/// The sides of the box `dims` that a point lies beyond: (key, side, the side's value).
pub(super) fn outside_sides(
    dims: &[Dim],
    problem: &Refinement,
    e: &Evaluation,
) -> Vec<(String, Side, f64)> {
    let Some(x) = ego::coords(problem, &e.params) else {
        return Vec::new();
    };
    let tol = 1e-9;
    dims.iter()
        .zip(x)
        .filter_map(
            |(
                Dim {
                    key: k,
                    log,
                    lo,
                    hi,
                },
                u,
            )| {
                let value = |c: f64| if *log { 10f64.powf(c) } else { c };
                if u < lo - tol {
                    Some((k.clone(), Side::Low, value(*lo)))
                } else if u > hi + tol {
                    Some((k.clone(), Side::High, value(*hi)))
                } else {
                    None
                }
            },
        )
        .collect()
}
