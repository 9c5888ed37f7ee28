//! The result of a calibration, as `calibration.json` holds it: every evaluated point and the
//! best one. `calibrate` fills it; the maps and the reproduction read it.

use std::collections::BTreeMap;
use std::path::PathBuf;

use hvi_analysis::score::Score;
use serde::{Deserialize, Serialize};

/// One evaluated point: a grid run or a refinement step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Evaluation {
    /// `grid`, `grid-seeds` (a grid point at the search's seeds), `ego-<batch>`, `refine`
    /// (Nelder-Mead) or `paper`.
    pub stage: String,
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
    /// The target file.
    pub targets_file: PathBuf,
    /// The targets' names, kinds, values, tolerances and weights.
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
    /// Runs simulated by this invocation (grid, search and the paper's point).
    #[serde(default)]
    pub runs_made: usize,
    /// Wall time of this invocation, s.
    #[serde(default)]
    pub wall_seconds: f64,
    /// The coarser resolution the surrogate search modelled the difference from (None: none).
    #[serde(default)]
    pub prior: Option<PriorUse>,
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
