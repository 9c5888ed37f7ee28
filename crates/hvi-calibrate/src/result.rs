//! The result of a calibration, as `calibration.json` holds it: every evaluated point and the
//! best one. `calibrate` fills it; the maps and the reproduction read it.

use std::collections::BTreeMap;
use std::path::PathBuf;

use hvi_analysis::observable::{Observable, Observables};
use hvi_analysis::score::{Score, Target, Targets, MISSING_TERM};
use serde::{Deserialize, Serialize};

/// The stage of a calibration that evaluated a point. Written as its label: `grid`,
/// `grid-seeds`, `ego-<batch>`, `extend-<box>`, `refine`, `paper`, `check`, `coarse-answer`
/// or `held-out`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(into = "String", try_from = "String")]
pub enum EvalStage {
    /// A grid run at the scene's seed.
    Grid,
    /// A grid point at the search's seeds.
    GridSeeds,
    /// A batch of the surrogate (ego) search, numbered over the whole calibration.
    Search(usize),
    /// The grid points of an extended box, numbered by extension.
    Extend(usize),
    /// A Nelder-Mead step.
    Refine,
    /// The paper's fit, scored beside the answer.
    Paper,
    /// A coarser level's answer checked at this level (the ladder).
    Check,
    /// A coarser level's answer run at the search's seeds before the search (the ladder).
    CoarseAnswer,
    /// The held-out shot at the calibrated point.
    HeldOut,
}

impl std::fmt::Display for EvalStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EvalStage::Grid => f.write_str("grid"),
            EvalStage::GridSeeds => f.write_str("grid-seeds"),
            EvalStage::Search(n) => write!(f, "ego-{n}"),
            EvalStage::Extend(n) => write!(f, "extend-{n}"),
            EvalStage::Refine => f.write_str("refine"),
            EvalStage::Paper => f.write_str("paper"),
            EvalStage::Check => f.write_str("check"),
            EvalStage::CoarseAnswer => f.write_str("coarse-answer"),
            EvalStage::HeldOut => f.write_str("held-out"),
        }
    }
}

impl From<EvalStage> for String {
    fn from(s: EvalStage) -> String {
        s.to_string()
    }
}

impl TryFrom<String> for EvalStage {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        let numbered = |prefix: &str| s.strip_prefix(prefix).and_then(|n| n.parse().ok());
        Ok(match s.as_str() {
            "grid" => EvalStage::Grid,
            "grid-seeds" => EvalStage::GridSeeds,
            "refine" => EvalStage::Refine,
            "paper" => EvalStage::Paper,
            "check" => EvalStage::Check,
            "coarse-answer" => EvalStage::CoarseAnswer,
            "held-out" => EvalStage::HeldOut,
            _ => {
                if let Some(n) = numbered("ego-") {
                    EvalStage::Search(n)
                } else if let Some(n) = numbered("extend-") {
                    EvalStage::Extend(n)
                } else {
                    return Err(format!(
                        "unknown calibration stage `{s}` (allowed: grid, grid-seeds, ego-<n>, \
                         extend-<n>, refine, paper, check, coarse-answer, held-out)"
                    ));
                }
            }
        })
    }
}

impl EvalStage {
    /// A batch of the surrogate search.
    pub fn is_search(self) -> bool {
        matches!(self, EvalStage::Search(_))
    }

    /// An extended box's grid point.
    pub fn is_extension(self) -> bool {
        matches!(self, EvalStage::Extend(_))
    }
}

/// One evaluated point: a grid run or a refinement step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Evaluation {
    /// The stage that evaluated it.
    pub stage: EvalStage,
    /// Sequence number within the stage.
    pub step: usize,
    /// Parameter values by key.
    pub params: BTreeMap<String, f64>,
    /// The score (None for a point that was not run).
    pub score: Option<Score>,
    /// The objective (OUTSIDE_COST for a point outside the box or invalid).
    pub objective: f64,
    /// Run status, or why it was not run.
    pub status: String,
    /// Whether the run was found in the store.
    pub cached: bool,
    /// The run's directory, relative to the study directory (the first seed's).
    pub dir: Option<String>,
    /// The seeds the point ran at (empty: the scene's own seed).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub seeds: Vec<u64>,
    /// The objective at each seed (the point's `objective` scores the seed-mean observables).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub seed_objectives: Vec<f64>,
    /// Every observable the point's runs measured, by name: the mean over its seeds (a grid
    /// run's own values), whether scored or not. What the maps draw over every box searched.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub means: BTreeMap<String, f64>,
}

impl Evaluation {
    /// The seed mean of `observable` at this point, when its runs measured it.
    pub fn mean(&self, observable: Observable) -> Option<f64> {
        self.means.get(observable.name()).copied()
    }
}

/// The mean over runs of every observable that all of them measured, by name (empty without
/// runs).
pub fn observed_means(runs: &[Observables]) -> BTreeMap<String, f64> {
    if runs.is_empty() {
        return BTreeMap::new();
    }
    Observable::ALL
        .iter()
        .filter_map(|&o| {
            let values: Option<Vec<f64>> = runs.iter().map(|r| r.get(o)).collect();
            let v = values?;
            Some((o.name().to_string(), v.iter().sum::<f64>() / v.len() as f64))
        })
        .collect()
}

/// The seed means of a point's runs over several shots (`runs[s]`: shot s's runs, one per
/// seed): the first shot's by observable name (what the maps draw), every other shot's as
/// `<shot id>:<name>`.
pub fn shot_means(
    shots: &[hvi_analysis::score::Targets],
    runs: &[Vec<Observables>],
) -> BTreeMap<String, f64> {
    let mut means = BTreeMap::new();
    for (s, r) in runs.iter().enumerate() {
        for (name, v) in observed_means(r) {
            match (s, shots.get(s)) {
                (0, _) | (_, None) => means.insert(name, v),
                (_, Some(t)) => {
                    means.insert(hvi_analysis::score::shot_term_name(&t.shot.id, &name), v)
                }
            };
        }
    }
    means
}

/// The grid stage's design as a calibration used it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DesignUse {
    /// `grid` or `corners`.
    pub name: String,
    /// Grid points the stage ran (per shot).
    pub points: usize,
    /// Points of the study's grid.
    pub grid_points: usize,
}

/// What `calibrate` writes into calibration.json.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CalibrationResult {
    /// The study.
    pub study: String,
    /// The calibration's label: its method, seeds and a digest of its settings and first box
    /// (`calibrations/<label>/` keeps its files beside other calibrations of the study).
    #[serde(default)]
    pub label: String,
    /// The tier.
    pub tier: String,
    /// Particles of the runs (from the best run).
    pub particles: Option<f64>,
    /// The particle count asked with `--particles` (None: the tier's); the lattice takes the
    /// nearest count it can lay out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub particles_asked: Option<f64>,
    /// The (first) shot's target file.
    pub targets_file: PathBuf,
    /// Every shot calibrated against, in order.
    #[serde(default)]
    pub shots: Vec<ShotUse>,
    /// The shot left out (`--hold-out`) and its prediction at the answer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOut>,
    /// The targets' names, kinds, values, tolerances and weights, as the objective scores them
    /// (with several shots, `<shot id>:<target>`, each shot counting alike).
    pub targets: Vec<hvi_analysis::score::Target>,
    /// The documented gaps (not scored).
    pub gaps: Vec<hvi_analysis::score::Gap>,
    /// The best point over grid and refinement.
    pub best: Evaluation,
    /// The best grid point.
    pub best_grid: Evaluation,
    /// The paper's best fit, scored at this tier.
    pub paper: Evaluation,
    /// Best over paper for each refined parameter.
    pub ratio_to_paper: BTreeMap<String, f64>,
    /// Why the refinement stopped (or that it was skipped).
    pub termination: String,
    /// Refinement runs made (not counting cache hits).
    pub refinement_runs: usize,
    /// Every refinement evaluation in order.
    pub refinement: Vec<Evaluation>,
    /// The search after the grid: `ego`, `nelder-mead` or `none`.
    #[serde(default)]
    pub method: String,
    /// Whether the search met its convergence rule with its answer inside the box (see
    /// `termination`); never true while the answer touches a side.
    #[serde(default)]
    pub converged: bool,
    /// Every box searched, the grid's first; each later one extended past the sides the
    /// answer touched.
    #[serde(default)]
    pub boxes: Vec<SearchedBox>,
    /// The sides of the last box that the answer touches (empty: the answer is interior).
    #[serde(default)]
    pub edges: Vec<Edge>,
    /// Where the extension stopped, in words (e.g. the parameter lies beyond a side at its
    /// limit).
    #[serde(default)]
    pub limit: Option<String>,
    /// The noise the search worked with: a seed mean's standard error of log10 J.
    #[serde(default)]
    pub noise: Option<f64>,
    /// Where the noise comes from: measured over the seeds, or the floor (and why).
    #[serde(default)]
    pub noise_source: Option<String>,
    /// The surrogate's predicted log10 J over two searched axes (ego; `surrogate.csv`).
    #[serde(skip)]
    pub surface: Option<Surface>,
    /// The calibrated parameters' confidence region (ego).
    #[serde(default)]
    pub region: Option<ParamRegion>,
    /// At the best point, each target's observable over the seeds.
    #[serde(default)]
    pub best_spread: Vec<Spread>,
    /// The grid stage's design (`calibrate.initial_design`) and how many of the study grid's
    /// points it ran (None in files written before the key).
    #[serde(default)]
    pub initial_design: Option<DesignUse>,
    /// Runs simulated by this invocation (grid, search and the paper's point).
    #[serde(default)]
    pub runs_made: usize,
    /// Wall time of this invocation, s.
    #[serde(default)]
    pub wall_seconds: f64,
    /// The coarser resolution the surrogate search modelled the difference from (None: none).
    #[serde(default)]
    pub prior: Option<PriorUse>,
    /// The evaluated points that meet every target, at the answer's seeds (None: none scored).
    #[serde(default)]
    pub targets_met: Option<TargetsMet>,
    /// What the targets determine of each searched parameter: an interval, a one-sided bound,
    /// nothing over the box, or an optimum beyond a side the search could not pass.
    #[serde(default)]
    pub identified: BTreeMap<String, Identified>,
    /// Whether the answer is a bound: the search's stopping rule held, the answer touches a
    /// side, and every target is met on each side it touches.
    #[serde(default)]
    pub bounded: bool,
}

/// The evaluated points that meet every target: each target's term within its tolerance
/// (term <= 1) at the seed-mean observables, among the points scored at the answer's seeds.
/// It reads the runs alone, no model: how far along a valley the targets are met where the
/// calibration has looked, which a confidence region (the model's, around one minimum)
/// does not say.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TargetsMet {
    /// Points that meet every target.
    pub points: usize,
    /// Distinct points scored at the answer's seeds.
    pub scored: usize,
    /// Per parameter that varies among the scored points, the lowest and highest value among
    /// those that meet every target.
    pub spans: BTreeMap<String, (f64, f64)>,
}

impl TargetsMet {
    /// From the evaluations (each point counted once) scored at `seeds`; None when none is.
    pub fn of<'a>(
        evaluations: impl IntoIterator<Item = &'a Evaluation>,
        seeds: &[u64],
    ) -> Option<TargetsMet> {
        let mut scored: Vec<&Evaluation> = Vec::new();
        for e in evaluations {
            if e.seeds == seeds && e.score.is_some() && !scored.iter().any(|s| s.params == e.params)
            {
                scored.push(e);
            }
        }
        if scored.is_empty() {
            return None;
        }
        let meets = |e: &Evaluation| {
            e.score
                .as_ref()
                .is_some_and(|s| s.terms.iter().all(|t| t.term <= 1.0))
        };
        // The parameters that vary among the scored points (a key fixed by the study is no
        // span), and that every point names.
        let keys: Vec<&String> = scored[0]
            .params
            .keys()
            .filter(|k| scored.iter().all(|e| e.params.contains_key(*k)))
            .filter(|k| {
                let v = scored[0].params[*k];
                scored.iter().any(|e| e.params[*k] != v)
            })
            .collect();
        let met: Vec<&&Evaluation> = scored.iter().filter(|e| meets(e)).collect();
        let spans = keys
            .into_iter()
            .filter_map(|k| {
                let vals = met.iter().map(|e| e.params[k]);
                let lo = vals.clone().fold(f64::INFINITY, f64::min);
                let hi = vals.fold(f64::NEG_INFINITY, f64::max);
                lo.is_finite().then(|| (k.clone(), (lo, hi)))
            })
            .collect();
        Some(TargetsMet {
            points: met.len(),
            scored: scored.len(),
            spans,
        })
    }

    /// In words: `5 of 23 points scored meet every target: eps_j 1.4e-3 to 2.1e-3, ...`.
    pub fn describe(&self) -> String {
        if self.points == 0 {
            return format!(
                "none of the {} points scored meets every target",
                self.scored
            );
        }
        let spans = self
            .spans
            .iter()
            .map(|(k, (lo, hi))| {
                if lo == hi {
                    format!("{k} {}", fmt_value(*lo))
                } else {
                    format!("{k} {} to {}", fmt_value(*lo), fmt_value(*hi))
                }
            })
            .collect::<Vec<_>>()
            .join(", ");
        format!(
            "{} of the {} points scored meet every target: {spans}",
            self.points, self.scored
        )
    }
}

/// The coarser calibration a surrogate search started from.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PriorUse {
    /// Its particle count.
    pub particles: f64,
    /// Its scored points the prior was fitted to.
    pub points: usize,
    /// The prior's weight `rho` in the final model (log10 J = rho x prior + difference).
    pub weight: Option<f64>,
}

impl PriorUse {
    /// In words, for the reports.
    pub fn describe(&self) -> String {
        format!(
            "the difference from a model of the {}-particle calibration's {} scored points{}",
            self.particles,
            self.points,
            self.weight
                .map_or(String::new(), |w| format!(", weighted {w:.2}"))
        )
    }
}

/// The calibrated parameters' confidence region, in the parameters' own units.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ParamRegion {
    /// Per refined key, the lowest and highest value of the region.
    pub intervals: BTreeMap<String, (f64, f64)>,
    /// Per refined key, whether the region reaches the search box's edge there (the interval
    /// may extend beyond what was searched).
    pub at_boundary: BTreeMap<String, bool>,
    /// Per refined key, whether the region reaches the box's lowest and its highest side.
    #[serde(default)]
    pub sides: BTreeMap<String, (bool, bool)>,
    /// The surrogate's minimum.
    pub predicted_minimum: BTreeMap<String, f64>,
    /// The predicted objective J at the minimum and the standard deviation of its log10.
    pub predicted_objective: (f64, f64),
    /// The region holds every point predicted below this objective J.
    pub threshold: f64,
    /// The share of the searched box inside the region.
    pub share_of_box: f64,
}

/// A target's observable over the seeds at the best point.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Spread {
    /// The target.
    pub target: String,
    /// The observable's seed mean.
    pub mean: f64,
    /// Its standard deviation over the seeds (0 with one seed).
    pub sd: f64,
    /// Seeds with a value.
    pub seeds: usize,
}

/// The surrogate's prediction over the first two searched axes, the others at the chosen
/// point: what the search believes J looks like between the runs (the calibration's objective
/// map draws it).
#[derive(Debug, Clone)]
pub struct Surface {
    /// The keys along x and y.
    pub keys: (String, String),
    /// Predicted log10 J over the box, in the keys' own units.
    pub field: hvi_analysis::contour::Field,
}

impl Surface {
    /// The valley's floor as the model sees it: at each row (each value of the second key),
    /// the first key's value where the predicted log10 J is lowest, and that prediction; rows
    /// without a finite prediction are left out.
    pub fn floor(&self) -> Vec<FloorPoint> {
        let f = &self.field;
        f.y.iter()
            .zip(&f.z)
            .filter_map(|(&y, row)| {
                let (col, &z) = row
                    .iter()
                    .enumerate()
                    .filter(|(_, z)| z.is_finite())
                    .min_by(|a, b| a.1.total_cmp(b.1))?;
                Some(FloorPoint {
                    along: y,
                    at: f.x[col],
                    log10_objective: z,
                })
            })
            .collect()
    }
}

/// A point of the valley's floor: at `along` (the surface's second key), the first key's value
/// `at` where the model's J is lowest, and its predicted log10 J.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FloorPoint {
    /// The second key's value.
    pub along: f64,
    /// The first key's value at the floor.
    pub at: f64,
    /// The predicted log10 J there.
    pub log10_objective: f64,
}

/// A side of an axis of the searched box.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// The lowest value.
    Low,
    /// The highest value.
    High,
}

impl Side {
    /// `low` or `high`.
    pub fn name(self) -> &'static str {
        match self {
            Side::Low => "low",
            Side::High => "high",
        }
    }
}

/// A side of the box that the answer touches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Edge {
    /// The parameter's key.
    pub key: String,
    /// Which side.
    pub side: Side,
    /// The box's value on that side, in the parameter's unit.
    pub value: f64,
    /// What touches it: `best point`, `confidence region` or both.
    pub touched_by: String,
    /// Why it was not extended further (None while it can be).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limit: Option<String>,
    /// Whether a point on this side meets every target: the targets then bound the parameter
    /// from the other side only (docs/calibration.md, "What the targets determine").
    #[serde(default)]
    pub targets_met: bool,
    /// Where every target is met at the side and a step inside but J still falls toward the
    /// side beyond the noise: the lowest J on the side's line and a step inside (the optimum
    /// may lie beyond the side, which therefore moves out).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub falling: Option<(f64, f64)>,
}

impl Edge {
    /// The edge in words, e.g. `the high side of material.eps_j (1 J), touched by the best
    /// point`.
    pub fn describe(&self) -> String {
        format!(
            "the {} side of {} ({}), touched by the {}",
            self.side.name(),
            self.key,
            fmt_value(self.value),
            self.touched_by
        )
    }
}

/// One box a calibration searched.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchedBox {
    /// Per searched key, its (lowest, highest) value in the parameter's unit.
    pub bounds: BTreeMap<String, (f64, f64)>,
    /// Why the search in this box stopped.
    pub termination: String,
    /// The sides the answer in this box touched.
    pub edges: Vec<Edge>,
}

/// A number as the reports print it (four significant digits, no trailing zeros).
pub fn fmt_value(v: f64) -> String {
    let s = format!("{v:.4e}");
    // 1.0000e0 -> 1, 4.5600e6 -> 4.56e6
    let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
    let m = m.trim_end_matches('0').trim_end_matches('.');
    if e == "0" {
        m.to_string()
    } else {
        format!("{m}e{e}")
    }
}

/// A box in words: `material.eps_j in [0.01, 10], material.kappa_n_m in [1.14e6, 9.12e6]`.
pub fn fmt_bounds(bounds: &BTreeMap<String, (f64, f64)>) -> String {
    bounds
        .iter()
        .map(|(k, (lo, hi))| format!("{k} in [{}, {}]", fmt_value(*lo), fmt_value(*hi)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// What the targets determine of one searched parameter, in its unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Identified {
    /// Bounded on both sides: the confidence region lies inside the box.
    Interval {
        /// The region's lowest value.
        low: f64,
        /// Its highest.
        high: f64,
    },
    /// Bounded above only: every target is met down to the box's low side, `floor`; below it
    /// nothing was looked at, and the targets did not rise towards it.
    AtMost {
        /// The highest value at which the targets are met or the model's region reaches.
        high: f64,
        /// The box's low side.
        floor: f64,
    },
    /// Bounded below only (the mirror image of [`Identified::AtMost`]).
    AtLeast {
        /// The lowest value at which the targets are met or the model's region reaches.
        low: f64,
        /// The box's high side.
        ceiling: f64,
    },
    /// Every target is met at both sides of the box: the targets do not determine it here.
    NotIdentified {
        /// The box's low side.
        low: f64,
        /// Its high side.
        high: f64,
    },
    /// The answer lies beyond a side the search could not pass, and the targets are not met
    /// there: the optimum is outside what was searched.
    BeyondLimit {
        /// Which side.
        side: Side,
        /// The side's value.
        value: f64,
    },
}

impl Identified {
    /// Whether this is an answer (an interval, a bound or "not identified"), as opposed to an
    /// optimum left outside the box.
    pub fn is_answer(&self) -> bool {
        !matches!(self, Identified::BeyondLimit { .. })
    }

    /// Whether it is bounded on both sides.
    pub fn is_two_sided(&self) -> bool {
        matches!(self, Identified::Interval { .. })
    }

    /// In words, with the key and its unit: `material.eps_j <= 1e-4 J, not identified below
    /// the box's 1e-5 J`.
    pub fn describe(&self, key: &str) -> String {
        let unit = hvi_engine::scene::keys::find(key)
            .map(|k| k.unit())
            .filter(|u| *u != "-")
            .map_or(String::new(), |u| format!(" {u}"));
        let v = |x: f64| format!("{}{unit}", fmt_value(x));
        match *self {
            Identified::Interval { low, high } => {
                format!("{key} in [{}, {}]", fmt_value(low), v(high))
            }
            Identified::AtMost { high, floor } => format!(
                "{key} <= {}, not identified below the box's {} (every target is met down to it)",
                v(high),
                v(floor)
            ),
            Identified::AtLeast { low, ceiling } => format!(
                "{key} >= {}, not identified above the box's {} (every target is met up to it)",
                v(low),
                v(ceiling)
            ),
            Identified::NotIdentified { low, high } => format!(
                "{key} not identified in [{}, {}]: every target is met at both sides",
                fmt_value(low),
                v(high)
            ),
            Identified::BeyondLimit { side, value } => format!(
                "{key} lies {} the box's {} side, {}, which the search could not pass, and the \
                 targets are not met there",
                match side {
                    Side::Low => "below",
                    Side::High => "beyond",
                },
                side.name(),
                v(value)
            ),
        }
    }
}

/// A shot as calibration.json records it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShotUse {
    /// The shot's id.
    pub id: String,
    /// Its file.
    pub file: PathBuf,
    /// An invented example, not a measurement.
    #[serde(default)]
    pub synthetic: bool,
    /// The impact it is simulated at, in words (with its documented offset, if any).
    pub impact: String,
}

impl ShotUse {
    /// From a shot's targets.
    pub fn of(t: &Targets) -> ShotUse {
        ShotUse {
            id: t.shot.id.clone(),
            file: t.path.clone(),
            synthetic: t.shot.synthetic,
            impact: impact_words(t),
        }
    }

    /// The shot's id, marked when it is an invented example: `synthetic-al-5kms (SYNTHETIC: an
    /// invented example, not a measurement)`.
    pub fn name(&self) -> String {
        if self.synthetic {
            format!(
                "{} (SYNTHETIC: an invented example, not a measurement)",
                self.id
            )
        } else {
            self.id.clone()
        }
    }
}

/// The impact of a shot in words: `a 9.53 mm sphere (aluminium) at 6700 m/s on a plate
/// (aluminium) of t/D 0.425 (simulated at ...: reason)`.
fn impact_words(t: &Targets) -> String {
    let s = &t.shot;
    let mut w = format!(
        "a {} mm sphere ({}) at {} m/s on a plate ({}) of t/D {}",
        hvi_store::spec::round_sig(s.impactor_diameter_m * 1e3, 6),
        s.impactor_material,
        s.simulated_v0_m_s(),
        s.plate_material,
        s.simulated_t_over_d()
    );
    if let Some(t) = s.observation_time_s {
        w.push_str(&format!(", observed {} us after first contact", t * 1e6));
    }
    if let Some(o) = s.describe_offset() {
        w.push_str(&format!(" ({o})"));
    }
    w
}

/// A held-out shot's prediction at the calibrated point: every target's observable over the
/// seeds against its measurement.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct HeldOut {
    /// The shot.
    pub shot: ShotUse,
    /// Its targets.
    pub targets: Vec<Target>,
    /// Its runs at the calibrated point, scored against its targets (seed means).
    pub evaluation: Evaluation,
    /// Each target's observable over the seeds.
    pub spread: Vec<Spread>,
}

impl HeldOut {
    /// Per target, in words: `length_ratio: predicted 1.43 (sd 0.02 over 2 seeds), measured
    /// 1.40 within 0.1: term 0.09`.
    pub fn lines(&self) -> Vec<String> {
        let Some(score) = &self.evaluation.score else {
            return vec![format!("no prediction: {}", self.evaluation.status)];
        };
        self.targets
            .iter()
            .zip(&score.terms)
            .map(|(t, term)| {
                let sp = self.spread.iter().find(|s| s.target == t.name);
                let predicted = match (term.observed, sp) {
                    (Some(v), Some(s)) => {
                        format!("{v:.4} (sd {:.4} over {} seeds)", s.sd, s.seeds)
                    }
                    (Some(v), None) => format!("{v:.4}"),
                    (None, _) => "not measured".into(),
                };
                format!(
                    "{}: predicted {predicted}, measured {} {} (tolerance {}): term {}",
                    t.name,
                    match t.kind {
                        hvi_analysis::score::TargetKind::AtMost => "at most",
                        _ => "",
                    },
                    t.value,
                    t.tolerance,
                    fmt_term(term)
                )
                .replace("measured  ", "measured ")
            })
            .collect()
    }
}

/// A term as reports print it: `>= 1000 (capped)` where an observed value lies so far off
/// that its term reached the cap (the same value a missing observable costs), `n/a (missing)`
/// where the run did not measure it.
pub fn fmt_term(t: &hvi_analysis::score::Term) -> String {
    match t.observed {
        None => format!("{:.0} (observable missing)", t.term),
        Some(_) if t.term >= MISSING_TERM => format!(">= {MISSING_TERM:.0} (capped)"),
        Some(_) => format!("{:.4}", t.term),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvi_analysis::score::Term;

    /// calibration.json keeps its stage labels: every stage reads back from what it writes,
    /// and an unknown label is refused with the allowed ones.
    #[test]
    fn stage_labels_round_trip() {
        let all = [
            EvalStage::Grid,
            EvalStage::GridSeeds,
            EvalStage::Search(12),
            EvalStage::Extend(3),
            EvalStage::Refine,
            EvalStage::Paper,
            EvalStage::Check,
            EvalStage::CoarseAnswer,
            EvalStage::HeldOut,
        ];
        for s in all {
            let json = serde_json::to_string(&s).expect("a stage writes");
            assert_eq!(
                serde_json::from_str::<EvalStage>(&json).expect("a stage reads back"),
                s,
                "{json}"
            );
        }
        assert_eq!(
            serde_json::to_string(&EvalStage::Search(2)).expect("a stage writes"),
            "\"ego-2\""
        );
        let err = serde_json::from_str::<EvalStage>("\"ego-x\"").expect_err("not a stage");
        assert!(err.to_string().contains("allowed: grid"), "{err}");
    }

    #[test]
    fn a_mean_is_over_every_seed_or_absent() {
        let run = |r: Option<f64>, va: f64| {
            let mut o = Observables::default();
            o.set(Observable::LengthRatio, r);
            o.set(Observable::FrontVelocityRatio, Some(va));
            o
        };
        let means = observed_means(&[run(Some(1.5), 0.9), run(Some(1.7), 0.8)]);
        assert_eq!(means.get("length_ratio"), Some(&1.6));
        assert!((means["front_velocity_ratio"] - 0.85).abs() < 1e-15);
        // A seed without R: no mean of R, the other observable's mean kept.
        let means = observed_means(&[run(Some(1.5), 0.9), run(None, 0.8)]);
        assert_eq!(means.get("length_ratio"), None);
        assert!(means.contains_key("front_velocity_ratio"));
        assert!(observed_means(&[]).is_empty());
    }

    fn eval(eps: f64, kappa: f64, seeds: &[u64], terms: &[f64]) -> Evaluation {
        let terms: Vec<Term> = terms
            .iter()
            .enumerate()
            .map(|(k, &t)| Term {
                name: format!("t{k}"),
                observed: Some(1.0),
                term: t,
                weight: 1.0,
            })
            .collect();
        Evaluation {
            stage: EvalStage::Search(0),
            step: 0,
            params: BTreeMap::from([
                ("eps".to_string(), eps),
                ("kappa".to_string(), kappa),
                ("rcut".to_string(), 1.5),
            ]),
            objective: terms.iter().map(|t| t.term).sum::<f64>() / terms.len() as f64,
            score: Some(Score {
                objective: 0.0,
                terms,
            }),
            status: "completed".into(),
            cached: false,
            dir: None,
            seeds: seeds.to_vec(),
            seed_objectives: Vec::new(),
            means: BTreeMap::new(),
        }
    }

    #[test]
    fn the_targets_met_span_reads_every_term_at_the_answers_seeds_once() {
        let seeds = [1, 2];
        let evals = [
            eval(1e-3, 1e7, &seeds, &[0.5, 0.9]),
            // Met, but the same point again: counted once.
            eval(1e-3, 1e7, &seeds, &[0.5, 0.9]),
            eval(4e-3, 8e6, &seeds, &[1.0, 0.0]),
            // One term past its tolerance: not met, though J = 0.55 is lower than others'.
            eval(1e-2, 9e6, &seeds, &[1.1, 0.0]),
            // Met, at another seed: not compared with these.
            eval(1e-1, 1e6, &[3], &[0.0, 0.0]),
            // Not scored.
            Evaluation {
                score: None,
                ..eval(2e-3, 2e7, &seeds, &[0.0])
            },
        ];
        let m = TargetsMet::of(&evals, &seeds).expect("scored points");
        assert_eq!((m.points, m.scored), (2, 3));
        // rcut is the same at every point: no span.
        assert_eq!(
            m.spans,
            BTreeMap::from([
                ("eps".to_string(), (1e-3, 4e-3)),
                ("kappa".to_string(), (8e6, 1e7)),
            ])
        );
        assert!(
            m.describe().starts_with("2 of the 3 points"),
            "{}",
            m.describe()
        );
        let none = TargetsMet::of(&evals[3..4], &seeds).expect("one scored");
        assert_eq!((none.points, none.spans.len()), (0, 0));
        assert!(none.describe().contains("none of the 1"));
        assert!(TargetsMet::of(&evals[4..], &seeds).is_none());
    }
}
