//! Surrogate-based global search for an expensive, noisy objective: efficient global
//! optimisation (EGO; Jones, Schonlau and Welch, J. Global Optim. 13, 455, 1998).
//!
//! - A Gaussian-process (kriging) model of the objective over a box (`egobox-gp`: constant mean,
//!   Matérn 5/2 correlation, hyperparameters by maximum likelihood), with a nugget that carries
//!   the objective's noise, so that the model does not chase seed scatter.
//! - Expected improvement over the best *predicted* value at an evaluated point (the plug-in
//!   rule for noisy objectives), maximised over a fixed lattice of candidates (the searches here
//!   have two to four parameters, where a dense lattice finds the maximum reliably and makes
//!   proposals reproducible).
//! - Batches of `q` points by the kriging believer (Ginsbourger, Le Riche and Carraro, 2010):
//!   after each pick the model believes its own prediction there and is refitted, so the next
//!   pick goes elsewhere and a whole batch can run at once.
//! - The stopping rule: converged when the largest expected improvement left is below the
//!   noise of the objective (its standard error); more runs could not tell a better point from
//!   scatter. On a prior, the model of the observations alone must agree ([`step`]).
//! - The confidence region: every lattice point whose predicted objective is within
//!   [`REGION_NOISE_MULTIPLE`] noise standard errors of the best prediction, and every
//!   observed point whose own value is (a model smooths a steep valley wall; a point measured
//!   inside the threshold is not ruled out by it), reported as one interval per parameter.
//!
//! - A prior from a lower fidelity (a coarser resolution of the same model, [`Prior`]): the
//!   model is then `rho * prior + a kriging model of the difference` (the autoregressive
//!   multi-fidelity model of Kennedy and O'Hagan, Biometrika 87, 1, 2000), with `rho` fitted to
//!   the observations by least squares, so that a few fine points correct a coarse landscape
//!   instead of learning it again from a grid.
//!
//! Coordinates are those of the search (e.g. log10 eps); the caller maps them to parameters.
//! Nothing here runs a simulation: an objective is whatever the caller measured.

use std::sync::Arc;

use crate::error::{bail, AnalysisError, Result};
use egobox_gp::correlation_models::Matern52Corr;
use egobox_gp::mean_models::ConstantMean;
use egobox_gp::GaussianProcess;
use linfa::prelude::{Dataset, Fit};
use ndarray::{Array1, Array2};
use serde::{Deserialize, Serialize};

/// The confidence region holds the points predicted within this many noise standard errors of
/// the best prediction (two: about 95 % for a normal error).
pub const REGION_NOISE_MULTIPLE: f64 = 2.0;

/// About how many candidate points the lattice has (fewer per axis the more axes there are).
const CANDIDATES: f64 = 4096.0;

/// The most axes a search may have (the lattice grows as its power).
pub const MAX_DIMS: usize = 4;

/// One evaluated point: its coordinates and its objective (a seed mean where several seeds
/// were run).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    /// Coordinates in the search's box.
    pub x: Vec<f64>,
    /// The objective there.
    pub y: f64,
}

/// The search's box: per axis (lowest, highest), in the search's coordinates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchBox {
    /// (lowest, highest) per axis.
    pub bounds: Vec<(f64, f64)>,
}

impl SearchBox {
    /// A box, checked: one to [`MAX_DIMS`] axes, each finite with lowest < highest.
    pub fn new(bounds: Vec<(f64, f64)>) -> Result<SearchBox> {
        if bounds.is_empty() || bounds.len() > MAX_DIMS {
            bail!(
                "a surrogate search needs 1 to {MAX_DIMS} axes, got {}",
                bounds.len()
            );
        }
        for (k, &(lo, hi)) in bounds.iter().enumerate() {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                bail!("axis {k} of the search box is [{lo}, {hi}] (allowed: finite, lowest < highest)");
            }
        }
        Ok(SearchBox { bounds })
    }

    /// Number of axes.
    pub fn dims(&self) -> usize {
        self.bounds.len()
    }

    /// A point's coordinates scaled to the unit cube.
    fn unit(&self, x: &[f64]) -> Vec<f64> {
        x.iter()
            .zip(&self.bounds)
            .map(|(v, (lo, hi))| (v - lo) / (hi - lo))
            .collect()
    }

    /// The candidate lattice: `n` points per axis, faces included, in the box's coordinates.
    pub fn lattice(&self) -> Vec<Vec<f64>> {
        let d = self.dims();
        let n = (CANDIDATES.powf(1.0 / d as f64).round() as usize).max(2);
        let total = n.pow(d as u32);
        (0..total)
            .map(|mut k| {
                (0..d)
                    .map(|a| {
                        let i = k % n;
                        k /= n;
                        let (lo, hi) = self.bounds[a];
                        lo + (hi - lo) * i as f64 / (n - 1) as f64
                    })
                    .collect()
            })
            .collect()
    }

    /// The lattice's spacing in the unit cube.
    fn spacing(&self) -> f64 {
        let n = (CANDIDATES.powf(1.0 / self.dims() as f64).round() as usize).max(2);
        1.0 / (n - 1) as f64
    }
}

/// The lowest and highest share of a prior in the fine model (`rho`).
pub const PRIOR_WEIGHT: (f64, f64) = (0.0, 2.0);

/// A model of the same objective at a lower fidelity (a coarser resolution), fitted to its own
/// observations over their bounding box; a fine [`Surrogate`] learns only the difference.
#[derive(Clone)]
pub struct Prior {
    model: Arc<Surrogate>,
}

impl std::fmt::Debug for Prior {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Prior")
            .field("bounds", &self.model.space.bounds)
            .finish()
    }
}

impl Prior {
    /// The coarse model of `observations` (noise `noise_sd`), over the box they span (an axis
    /// they do not spread along gets a unit width around their value).
    pub fn fit(observations: &[Observation], noise_sd: f64) -> Result<Prior> {
        Prior::fit_on(observations, noise_sd, None)
    }

    /// [`Prior::fit`] on a still coarser prior (a ladder's levels, each on the one before).
    pub fn fit_on(
        observations: &[Observation],
        noise_sd: f64,
        prior: Option<&Prior>,
    ) -> Result<Prior> {
        let d = observations
            .first()
            .map(|o| o.x.len())
            .ok_or_else(|| AnalysisError::Input("a prior needs observations".into()))?;
        let mut bounds = vec![(f64::INFINITY, f64::NEG_INFINITY); d];
        for o in observations {
            if o.x.len() != d {
                bail!(
                    "a prior's observations have {} and {d} coordinates",
                    o.x.len()
                );
            }
            for (b, &v) in bounds.iter_mut().zip(&o.x) {
                b.0 = b.0.min(v);
                b.1 = b.1.max(v);
            }
        }
        for b in &mut bounds {
            if b.1 - b.0 < 1e-9 {
                *b = (b.0 - 0.5, b.1 + 0.5);
            }
        }
        let space = SearchBox::new(bounds)?;
        Ok(Prior {
            model: Arc::new(Surrogate::fit_on(&space, observations, noise_sd, prior)?),
        })
    }

    /// The coarse model's mean and standard deviation at each point.
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, f64)>> {
        self.model.predict(points)
    }
}

/// A kriging model of the objective over a box.
pub struct Surrogate {
    gp: GaussianProcess<f64, ConstantMean, Matern52Corr>,
    space: SearchBox,
    /// The lower fidelity's model and its weight `rho`, when the model is of the difference.
    prior: Option<(Prior, f64)>,
}

impl Surrogate {
    /// Fits the model to `observations` whose objective has noise of standard deviation
    /// `noise_sd` (objective units; 0 for an exact objective). The nugget is the noise's
    /// variance relative to the observations' (egobox-gp adds it to the correlation matrix's
    /// diagonal), at least 1e-8 for a well-conditioned fit.
    pub fn fit(
        space: &SearchBox,
        observations: &[Observation],
        noise_sd: f64,
    ) -> Result<Surrogate> {
        Surrogate::fit_on(space, observations, noise_sd, None)
    }

    /// [`Surrogate::fit`] on a lower fidelity's model: the kriging model is of `y - rho *
    /// prior(x)`, with `rho` the least-squares slope of the observations on the prior's
    /// predictions there (within [`PRIOR_WEIGHT`]; 1 with fewer than three observations or
    /// predictions that do not vary).
    pub fn fit_on(
        space: &SearchBox,
        observations: &[Observation],
        noise_sd: f64,
        prior: Option<&Prior>,
    ) -> Result<Surrogate> {
        let Some(prior) = prior else {
            return Surrogate::fit_plain(space, observations, noise_sd);
        };
        let xs: Vec<Vec<f64>> = observations.iter().map(|o| o.x.clone()).collect();
        let c: Vec<f64> = prior.predict(&xs)?.into_iter().map(|p| p.0).collect();
        let rho = prior_weight(&c, &observations.iter().map(|o| o.y).collect::<Vec<_>>());
        let difference: Vec<Observation> = observations
            .iter()
            .zip(&c)
            .map(|(o, c)| Observation {
                x: o.x.clone(),
                y: o.y - rho * c,
            })
            .collect();
        let mut model = Surrogate::fit_plain(space, &difference, noise_sd)?;
        model.prior = Some((prior.clone(), rho));
        Ok(model)
    }

    /// The prior's weight in the model (None without a prior).
    pub fn prior_weight(&self) -> Option<f64> {
        self.prior.as_ref().map(|p| p.1)
    }

    fn fit_plain(
        space: &SearchBox,
        observations: &[Observation],
        noise_sd: f64,
    ) -> Result<Surrogate> {
        let d = space.dims();
        if observations.len() < 2 {
            bail!(
                "a surrogate needs at least 2 evaluated points, got {}",
                observations.len()
            );
        }
        let mut x = Array2::zeros((observations.len(), d));
        for (i, o) in observations.iter().enumerate() {
            if o.x.len() != d || !o.y.is_finite() {
                bail!("observation {i} has {} coordinates (want {d}) or an objective that is not finite ({})", o.x.len(), o.y);
            }
            for (j, u) in space.unit(&o.x).into_iter().enumerate() {
                x[[i, j]] = u;
            }
        }
        let y = Array1::from_iter(observations.iter().map(|o| o.y));
        let var = y.var(0.0);
        let nugget = if var > 0.0 {
            (noise_sd * noise_sd / var).clamp(1e-8, 1.0)
        } else {
            1e-8
        };
        let gp = GaussianProcess::<f64, ConstantMean, Matern52Corr>::params(
            ConstantMean::default(),
            Matern52Corr::default(),
        )
        .nugget(nugget)
        .fit(&Dataset::new(x, y))
        .map_err(|e| AnalysisError::Surrogate(format!("the surrogate could not be fitted: {e}")))?;
        Ok(Surrogate {
            gp,
            space: space.clone(),
            prior: None,
        })
    }

    /// Predicted mean and standard deviation of the objective at each point. With a prior:
    /// `rho` times its mean plus the difference's mean, and the difference's deviation alone
    /// (the coarse model is the fine one's known trend, as a mean function is; adding its own
    /// deviation kept every prediction's deviation above the coarse level's noise, so the
    /// expected improvement never fell below the fine noise and a search never converged).
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, f64)>> {
        let own = self.predict_own(points)?;
        let Some((prior, rho)) = &self.prior else {
            return Ok(own);
        };
        Ok(prior
            .predict(points)?
            .into_iter()
            .zip(own)
            .map(|((pm, _), (m, s))| (rho * pm + m, s))
            .collect())
    }

    fn predict_own(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, f64)>> {
        let d = self.space.dims();
        let mut x = Array2::zeros((points.len(), d));
        for (i, p) in points.iter().enumerate() {
            for (j, u) in self.space.unit(p).into_iter().enumerate() {
                x[[i, j]] = u;
            }
        }
        let (m, v) = self
            .gp
            .predict_valvar(&x)
            .map_err(|e| AnalysisError::Surrogate(format!("surrogate prediction: {e}")))?;
        Ok(m.iter()
            .zip(&v)
            .map(|(&m, &v)| (m, v.max(0.0).sqrt()))
            .collect())
    }
}

/// The least-squares slope of `y` on `c` (with an intercept), within [`PRIOR_WEIGHT`]; 1 with
/// fewer than three points or a `c` that does not vary.
fn prior_weight(c: &[f64], y: &[f64]) -> f64 {
    let n = c.len().min(y.len());
    if n < 3 {
        return 1.0;
    }
    let (mc, my) = (
        c.iter().take(n).sum::<f64>() / n as f64,
        y.iter().take(n).sum::<f64>() / n as f64,
    );
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (a, b) in c.iter().zip(y).take(n) {
        sxy += (a - mc) * (b - my);
        sxx += (a - mc) * (a - mc);
    }
    if sxx <= 1e-12 * n as f64 {
        return 1.0;
    }
    (sxy / sxx).clamp(PRIOR_WEIGHT.0, PRIOR_WEIGHT.1)
}

/// The expected improvement below `best` of a normal prediction (mean, sd), for minimisation.
pub fn expected_improvement(mean: f64, sd: f64, best: f64) -> f64 {
    let gain = best - mean;
    if sd <= 0.0 || !sd.is_finite() {
        return gain.max(0.0);
    }
    let z = gain / sd;
    let pdf = (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let cdf = 0.5 * libm::erfc(-z / std::f64::consts::SQRT_2);
    (gain * cdf + sd * pdf).max(0.0)
}

/// A batch of proposed points.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Proposal {
    /// The points, in the order picked.
    pub points: Vec<Vec<f64>>,
    /// The largest expected improvement over the lattice before the batch (the stopping rule's
    /// number).
    pub max_expected_improvement: f64,
    /// The best predicted objective over the evaluated points (the improvement's reference).
    pub best_predicted: f64,
}

/// Proposes up to `q` new points by expected improvement and the kriging believer. Lattice
/// points within half a lattice spacing of an evaluated or already picked point are skipped,
/// so a batch never repeats a run; fewer than `q` come back when no candidate is left or
/// the expected improvement is zero everywhere.
pub fn propose(
    space: &SearchBox,
    observations: &[Observation],
    noise_sd: f64,
    q: usize,
    prior: Option<&Prior>,
) -> Result<Proposal> {
    let candidates = space.lattice();
    let near = 0.5 * space.spacing();
    let mut believed = observations.to_vec();
    let mut points: Vec<Vec<f64>> = Vec::new();
    let mut first = None;
    for _ in 0..q {
        let model = Surrogate::fit_on(space, &believed, noise_sd, prior)?;
        let best = best_predicted(&model, &believed)?;
        let taken: Vec<Vec<f64>> = believed.iter().map(|o| space.unit(&o.x)).collect();
        let free: Vec<&Vec<f64>> = candidates
            .iter()
            .filter(|c| {
                let u = space.unit(c);
                taken.iter().all(|t| {
                    t.iter()
                        .zip(&u)
                        .map(|(a, b)| (a - b).abs())
                        .fold(0.0, f64::max)
                        > near
                })
            })
            .collect();
        if free.is_empty() {
            break;
        }
        let owned: Vec<Vec<f64>> = free.iter().map(|c| (*c).clone()).collect();
        let pred = model.predict(&owned)?;
        let (k, ei) = pred
            .iter()
            .map(|&(m, s)| expected_improvement(m, s, best))
            .enumerate()
            .fold((0, f64::NEG_INFINITY), |acc, (k, ei)| {
                if ei > acc.1 {
                    (k, ei)
                } else {
                    acc
                }
            });
        if first.is_none() {
            first = Some((ei, best));
        }
        if ei <= 0.0 {
            break;
        }
        believed.push(Observation {
            x: owned[k].clone(),
            y: pred[k].0,
        });
        points.push(owned[k].clone());
    }
    let (max_expected_improvement, best_predicted) = match first {
        Some(f) => f,
        None => {
            let model = Surrogate::fit_on(space, observations, noise_sd, prior)?;
            (0.0, best_predicted(&model, observations)?)
        }
    };
    Ok(Proposal {
        points,
        max_expected_improvement,
        best_predicted,
    })
}

/// The lowest predicted objective over the evaluated points.
fn best_predicted(model: &Surrogate, observations: &[Observation]) -> Result<f64> {
    let xs: Vec<Vec<f64>> = observations.iter().map(|o| o.x.clone()).collect();
    Ok(model
        .predict(&xs)?
        .iter()
        .map(|p| p.0)
        .fold(f64::INFINITY, f64::min))
}

/// The stopping rule: converged when the largest expected improvement left is below the noise
/// of the objective (its standard error at the points evaluated).
pub fn converged(max_expected_improvement: f64, noise_sd: f64) -> bool {
    max_expected_improvement < noise_sd
}

/// The next step of a search: the batch to run, or the stop.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Step {
    /// The batch to run (empty when the search stops or no candidate is left).
    pub proposal: Proposal,
    /// Whether the stopping rule holds.
    pub converged: bool,
    /// The largest expected improvement of the search's model (on its prior when it has one).
    pub expected_improvement: f64,
    /// On a prior, once its model sees nothing left to gain: the largest expected improvement
    /// of the model of the observations alone, which must see nothing either for the search
    /// to stop (the batch is then that model's).
    pub own_expected_improvement: Option<f64>,
}

/// The search's next step from the observations so far: a batch of `q` points by expected
/// improvement ([`propose`]) or the stop ([`converged`]).
///
/// On a prior the stop needs two opinions. A prior's model is confident wherever the coarse
/// landscape was sampled, and where the fine landscape has a basin the coarse one lacks it
/// predicts no gain: its expected improvement can fall below the noise after a few points in
/// the wrong place. So once it does, the model of the observations alone (no prior) is asked
/// too: the search stops when it also sees nothing left; otherwise its batch runs. The prior
/// steers where the search looks; it cannot end the search by itself.
pub fn step(
    space: &SearchBox,
    observations: &[Observation],
    noise_sd: f64,
    q: usize,
    prior: Option<&Prior>,
) -> Result<Step> {
    let proposal = propose(space, observations, noise_sd, q, prior)?;
    let expected_improvement = proposal.max_expected_improvement;
    if !converged(expected_improvement, noise_sd) {
        return Ok(Step {
            proposal,
            converged: false,
            expected_improvement,
            own_expected_improvement: None,
        });
    }
    let stop = |proposal: Proposal, own| Step {
        proposal: Proposal {
            points: Vec::new(),
            ..proposal
        },
        converged: true,
        expected_improvement,
        own_expected_improvement: own,
    };
    if prior.is_none() {
        return Ok(stop(proposal, None));
    }
    let own = propose(space, observations, noise_sd, q, None)?;
    let own_ei = own.max_expected_improvement;
    if converged(own_ei, noise_sd) {
        return Ok(stop(proposal, Some(own_ei)));
    }
    Ok(Step {
        proposal: own,
        converged: false,
        expected_improvement,
        own_expected_improvement: Some(own_ei),
    })
}

/// The calibrated point and its confidence region, from the surrogate.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Region {
    /// The lattice point with the lowest predicted objective.
    pub best: Vec<f64>,
    /// The predicted objective there, and its standard deviation.
    pub best_predicted: (f64, f64),
    /// The threshold: best prediction + [`REGION_NOISE_MULTIPLE`] x the noise.
    pub threshold: f64,
    /// Per axis, the lowest and highest coordinate of the region's lattice points.
    pub intervals: Vec<(f64, f64)>,
    /// The share of the box's lattice inside the region.
    pub share_of_box: f64,
    /// Whether the region touches the box's boundary on each axis (the interval may then be
    /// wider than the box shows).
    pub at_boundary: Vec<bool>,
    /// Per axis, whether the region touches the box's lowest and its highest side.
    #[serde(default)]
    pub sides: Vec<(bool, bool)>,
}

/// The confidence region of the minimum: the lattice points whose predicted objective is within
/// [`REGION_NOISE_MULTIPLE`] x `noise_sd` of the lowest prediction, widened to every observation
/// whose own value is within it (`share_of_box` counts the lattice points alone).
pub fn region(
    space: &SearchBox,
    observations: &[Observation],
    noise_sd: f64,
    prior: Option<&Prior>,
) -> Result<Region> {
    let model = Surrogate::fit_on(space, observations, noise_sd, prior)?;
    let lattice = space.lattice();
    let pred = model.predict(&lattice)?;
    let k_best = (0..pred.len())
        .min_by(|&a, &b| pred[a].0.total_cmp(&pred[b].0))
        .ok_or_else(|| AnalysisError::Invariant("empty lattice".into()))?;
    let threshold = pred[k_best].0 + REGION_NOISE_MULTIPLE * noise_sd;
    let d = space.dims();
    let mut intervals = vec![(f64::INFINITY, f64::NEG_INFINITY); d];
    let mut inside = 0usize;
    for (p, &(m, _)) in lattice.iter().zip(&pred) {
        if m <= threshold {
            inside += 1;
            for (iv, &v) in intervals.iter_mut().zip(p) {
                iv.0 = iv.0.min(v);
                iv.1 = iv.1.max(v);
            }
        }
    }
    // A point measured below the threshold stays in, wherever the model puts it.
    for o in observations.iter().filter(|o| o.y <= threshold) {
        for (iv, &v) in intervals.iter_mut().zip(&o.x) {
            iv.0 = iv.0.min(v);
            iv.1 = iv.1.max(v);
        }
    }
    let sides: Vec<(bool, bool)> = intervals
        .iter()
        .zip(&space.bounds)
        .map(|(iv, b)| (iv.0 <= b.0, iv.1 >= b.1))
        .collect();
    let at_boundary = sides.iter().map(|&(lo, hi)| lo || hi).collect();
    Ok(Region {
        best: lattice[k_best].clone(),
        best_predicted: pred[k_best],
        threshold,
        intervals,
        share_of_box: inside as f64 / lattice.len() as f64,
        at_boundary,
        sides,
    })
}

/// The noise of a seed mean: the pooled standard deviation of the objective across seeds at
/// each point (points with one seed do not count), over the square root of the seeds per
/// point. None without any point at two seeds or more.
pub fn seed_mean_noise(groups: &[Vec<f64>]) -> Option<f64> {
    let (mut ss, mut dof, mut seeds) = (0.0, 0usize, 0usize);
    for g in groups.iter().filter(|g| g.len() > 1) {
        let mean = g.iter().sum::<f64>() / g.len() as f64;
        ss += g.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
        dof += g.len() - 1;
        seeds = seeds.max(g.len());
    }
    (dof > 0).then(|| (ss / dof as f64).sqrt() / (seeds as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reproducible normal deviate stream (splitmix64 and Box-Muller).
    struct Noise(u64);
    impl Noise {
        fn uniform(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u, v) = (self.uniform().max(1e-300), self.uniform());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        }
    }

    /// Runs the search as `calibrate` does: a 3 x 3 grid, then batches of `q` until the
    /// stopping rule holds or `max_batches`; returns the observations and whether it converged.
    fn search(
        space: &SearchBox,
        f: impl Fn(&[f64]) -> f64,
        noise_sd: f64,
        q: usize,
        max_batches: usize,
    ) -> (Vec<Observation>, bool) {
        search_from(space, f, noise_sd, q, max_batches, 3, None)
    }

    /// [`search`] from an `n` x `n` grid, on a prior when given.
    fn search_from(
        space: &SearchBox,
        f: impl Fn(&[f64]) -> f64,
        noise_sd: f64,
        q: usize,
        max_batches: usize,
        n: usize,
        prior: Option<&Prior>,
    ) -> (Vec<Observation>, bool) {
        let mut noise = Noise(7);
        let mut obs = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let x: Vec<f64> = [i, j]
                    .iter()
                    .zip(&space.bounds)
                    .map(|(&k, (lo, hi))| lo + (hi - lo) * k as f64 / (n - 1) as f64)
                    .collect();
                let y = f(&x) + noise_sd * noise.normal();
                obs.push(Observation { x, y });
            }
        }
        for _ in 0..max_batches {
            let s = step(space, &obs, noise_sd, q, prior).expect("step");
            if s.converged || s.proposal.points.is_empty() {
                return (obs, true);
            }
            for x in s.proposal.points {
                let y = f(&x) + noise_sd * noise.normal();
                obs.push(Observation { x, y });
            }
        }
        (obs, false)
    }

    #[test]
    fn a_coarse_prior_finds_the_fine_minimum_in_fewer_evaluations() {
        // The coarse landscape is the fine one moved and raised, as J at a coarser resolution
        // is: its minimum at (0.1, -0.4) against the fine one's (0.3, -0.2).
        let space = SearchBox::new(vec![(-1.0, 1.0), (-1.0, 1.0)]).expect("box");
        let fine = |x: &[f64]| (x[0] - 0.3).powi(2) + 2.0 * (x[1] + 0.2).powi(2);
        let coarse = |x: &[f64]| 0.3 + 1.2 * ((x[0] - 0.1).powi(2) + 2.0 * (x[1] + 0.4).powi(2));
        let noise = 0.01;
        let mut coarse_obs = Vec::new();
        for i in 0..6 {
            for j in 0..6 {
                let x = vec![-1.0 + 0.4 * i as f64, -1.0 + 0.4 * j as f64];
                coarse_obs.push(Observation { y: coarse(&x), x });
            }
        }
        let prior = Prior::fit(&coarse_obs, noise).expect("prior");
        let (plain, plain_converged) = search(&space, fine, noise, 2, 20);
        let (on_prior, prior_converged) = search_from(&space, fine, noise, 2, 20, 2, Some(&prior));
        assert!(plain_converged && prior_converged);
        assert!(
            on_prior.len() < plain.len(),
            "on the prior {} evaluations, without {}",
            on_prior.len(),
            plain.len()
        );
        let r = region(&space, &on_prior, noise, Some(&prior)).expect("region");
        for (k, truth) in [0.3, -0.2].iter().enumerate() {
            let (lo, hi) = r.intervals[k];
            assert!(
                lo <= *truth && *truth <= hi,
                "axis {k}: {truth} outside [{lo}, {hi}]"
            );
        }
        // The prior's weight is fitted, not assumed: the fine landscape is the coarse one
        // over 1.2 near the minimum.
        let model = Surrogate::fit_on(&space, &on_prior, noise, Some(&prior)).expect("model");
        let rho = model.prior_weight().expect("a prior");
        assert!((0.5..1.2).contains(&rho), "rho {rho}");
    }

    #[test]
    fn a_confident_prior_cannot_stop_a_search_short_of_a_basin_it_lacks() {
        // The fine landscape is the coarse one with a second, deeper basin at (0, 0) that
        // the coarse resolution does not have (as a fragment-size score that only a finer
        // lattice resolves). The search starts as a ladder level does: the box's corners and
        // the coarse answer.
        let space = SearchBox::new(vec![(-1.0, 1.0), (-1.0, 1.0)]).expect("box");
        let coarse = |x: &[f64]| (x[0] + 0.5).powi(2) + (x[1] + 0.5).powi(2);
        let fine = |x: &[f64]| coarse(x) - (-(x[0].powi(2) + x[1].powi(2)) / 0.3).exp();
        let noise = 0.02;
        let mut coarse_obs = Vec::new();
        for i in 0..7 {
            for j in 0..7 {
                let x = vec![-1.0 + i as f64 / 3.0, -1.0 + j as f64 / 3.0];
                coarse_obs.push(Observation { y: coarse(&x), x });
            }
        }
        let prior = Prior::fit(&coarse_obs, noise).expect("prior");
        let best = |obs: &[Observation]| obs.iter().map(|o| fine(&o.x)).fold(f64::MAX, f64::min);
        // The prior's model alone as the judge: it stops in the coarse basin.
        let mut obs: Vec<Observation> = [
            (-1.0, -1.0),
            (-1.0, 1.0),
            (1.0, -1.0),
            (1.0, 1.0),
            (-0.5, -0.5),
        ]
        .iter()
        .map(|&(a, b)| Observation {
            x: vec![a, b],
            y: fine(&[a, b]),
        })
        .collect();
        let start = obs.clone();
        let mut stopped = false;
        for _ in 0..20 {
            let p = propose(&space, &obs, noise, 2, Some(&prior)).expect("proposal");
            if converged(p.max_expected_improvement, noise) || p.points.is_empty() {
                stopped = true;
                break;
            }
            for x in p.points {
                obs.push(Observation { y: fine(&x), x });
            }
        }
        assert!(stopped, "the prior-only rule never stopped");
        assert!(
            best(&obs) > -0.3,
            "the prior-only rule found the hidden basin ({}): the case does not test the rule",
            best(&obs)
        );
        // Both models as judges: the search goes on until it finds the deeper basin (its
        // minimum is -0.62).
        let mut obs = start;
        let mut own_batches = 0;
        let mut stopped = false;
        for _ in 0..20 {
            let s = step(&space, &obs, noise, 2, Some(&prior)).expect("step");
            if s.converged || s.proposal.points.is_empty() {
                stopped = s.converged;
                break;
            }
            own_batches += usize::from(s.own_expected_improvement.is_some());
            for x in s.proposal.points {
                obs.push(Observation { y: fine(&x), x });
            }
        }
        assert!(stopped, "the two-opinion rule did not converge");
        assert!(own_batches > 0, "the model without the prior never steered");
        assert!(
            best(&obs) < -0.55,
            "the two-opinion rule stopped at {} ({} evaluations)",
            best(&obs),
            obs.len()
        );
    }

    #[test]
    fn a_prior_weight_is_the_slope_and_falls_back_to_one() {
        assert_eq!(prior_weight(&[1.0, 2.0], &[5.0, 9.0]), 1.0);
        assert_eq!(prior_weight(&[1.0, 1.0, 1.0], &[5.0, 9.0, 3.0]), 1.0);
        assert!((prior_weight(&[0.0, 1.0, 2.0], &[1.0, 1.5, 2.0]) - 0.5).abs() < 1e-12);
        assert_eq!(prior_weight(&[0.0, 1.0, 2.0], &[9.0, 0.0, -9.0]), 0.0);
    }

    #[test]
    fn expected_improvement_has_its_closed_form() {
        // No uncertainty: the plain gain. At the best value with unit sd: phi(0).
        assert_eq!(expected_improvement(1.0, 0.0, 3.0), 2.0);
        assert_eq!(expected_improvement(4.0, 0.0, 3.0), 0.0);
        let phi0 = 1.0 / (2.0 * std::f64::consts::PI).sqrt();
        assert!((expected_improvement(3.0, 1.0, 3.0) - phi0).abs() < 1e-12);
        // One sd below: 1 * Phi(1) + phi(1) = 0.841345 + 0.241971.
        assert!((expected_improvement(2.0, 1.0, 3.0) - 1.083315).abs() < 1e-5);
    }

    #[test]
    fn a_noisy_quadratic_is_found_with_its_minimum_inside_the_region() {
        // Minimum 0 at (0.3, -0.2) in [-1, 1]^2; noise 0.01, as seed scatter is for J.
        let space = SearchBox::new(vec![(-1.0, 1.0), (-1.0, 1.0)]).expect("box");
        let f = |x: &[f64]| (x[0] - 0.3).powi(2) + 2.0 * (x[1] + 0.2).powi(2);
        let noise = 0.01;
        let (obs, conv) = search(&space, f, noise, 2, 15);
        assert!(conv, "did not converge in {} evaluations", obs.len());
        let r = region(&space, &obs, noise, None).expect("region");
        log::info!(
            "quadratic: {} evaluations, best {:?}, region {:?}",
            obs.len(),
            r.best,
            r.intervals
        );
        let err = ((r.best[0] - 0.3).powi(2) + (r.best[1] + 0.2).powi(2)).sqrt();
        assert!(err < 0.1, "best {:?} is {err} from the optimum", r.best);
        for (iv, want) in r.intervals.iter().zip([0.3, -0.2]) {
            assert!(iv.0 <= want && want <= iv.1, "{iv:?} misses {want}");
        }
        // The region is where f < ~ 2 noise: a small ellipse, not the whole box.
        assert!(r.share_of_box < 0.1, "{}", r.share_of_box);
        assert!(obs.len() <= 9 + 2 * 15);
    }

    #[test]
    fn branin_is_found_to_its_known_minimum() {
        // Branin on [-5, 10] x [0, 15]: global minimum 0.397887 at three points.
        let space = SearchBox::new(vec![(-5.0, 10.0), (0.0, 15.0)]).expect("box");
        let pi = std::f64::consts::PI;
        let f = |x: &[f64]| {
            let (a, b, c) = (1.0, 5.1 / (4.0 * pi * pi), 5.0 / pi);
            let (r, s, t) = (6.0, 10.0, 1.0 / (8.0 * pi));
            a * (x[1] - b * x[0] * x[0] + c * x[0] - r).powi(2) + s * (1.0 - t) * x[0].cos() + s
        };
        let noise = 0.05;
        let (obs, _) = search(&space, f, noise, 3, 12);
        let r = region(&space, &obs, noise, None).expect("region");
        let truth = f(&r.best);
        log::info!(
            "branin: {} evaluations, best {:?}, f = {truth}",
            obs.len(),
            r.best
        );
        assert!(
            truth < 0.397887 + 0.2,
            "best {:?}: f = {truth} after {} evaluations",
            r.best,
            obs.len()
        );
    }

    #[test]
    fn a_flat_objective_converges_at_once_and_its_region_is_the_box() {
        let space = SearchBox::new(vec![(0.0, 1.0), (0.0, 1.0)]).expect("box");
        let (obs, conv) = search(&space, |_| 1.0, 0.02, 2, 5);
        assert!(conv);
        assert_eq!(
            obs.len(),
            9,
            "no run beyond the grid when nothing can improve"
        );
        let r = region(&space, &obs, 0.02, None).expect("region");
        assert!(r.share_of_box > 0.9, "{}", r.share_of_box);
        assert!(r.at_boundary.iter().all(|&b| b));
    }

    #[test]
    fn a_point_measured_inside_the_threshold_stays_in_the_region() {
        // A bowl at x = 0.3, and at x = 0.8 two neighbouring measurements that disagree: the
        // model averages them above the threshold, but the lower one is inside it.
        let space = SearchBox::new(vec![(0.0, 1.0)]).expect("box");
        let mut obs: Vec<Observation> = (0..=10)
            .map(|k| k as f64 / 10.0)
            .filter(|&x| (x - 0.8).abs() > 1e-9)
            .map(|x| Observation {
                x: vec![x],
                y: 4.0 * (x - 0.3) * (x - 0.3),
            })
            .collect();
        obs.push(Observation {
            x: vec![0.8],
            y: -0.5,
        });
        obs.push(Observation {
            x: vec![0.81],
            y: 2.5,
        });
        let noise = 0.05;
        let r = region(&space, &obs, noise, None).expect("region");
        let model = Surrogate::fit_on(&space, &obs, noise, None).expect("model");
        let at = model.predict(&[vec![0.8]]).expect("prediction")[0].0;
        assert!(
            at > r.threshold,
            "the model alone keeps x = 0.8 out ({at} > {})",
            r.threshold
        );
        assert!(r.intervals[0].1 >= 0.8, "{:?}", r.intervals[0]);
        assert!(r.intervals[0].0 <= 0.3, "{:?}", r.intervals[0]);
    }

    #[test]
    fn the_region_names_the_side_it_touches() {
        // The minimum lies beyond the high side of x and inside on y.
        let space = SearchBox::new(vec![(0.0, 1.0), (0.0, 1.0)]).expect("box");
        let f = |x: &[f64]| (x[0] - 1.5).powi(2) + 4.0 * (x[1] - 0.5).powi(2);
        let (obs, _) = search(&space, f, 0.01, 2, 6);
        let r = region(&space, &obs, 0.01, None).expect("region");
        assert_eq!(r.sides[0], (false, true), "x: {:?}", r.intervals[0]);
        assert_eq!(r.sides[1], (false, false), "y: {:?}", r.intervals[1]);
        assert_eq!(r.at_boundary, vec![true, false]);
    }

    #[test]
    fn a_batch_never_repeats_a_point() {
        let space = SearchBox::new(vec![(0.0, 1.0)]).expect("box");
        let obs: Vec<Observation> = [0.0, 0.5, 1.0]
            .iter()
            .map(|&x| Observation {
                x: vec![x],
                y: (x - 0.4f64).powi(2),
            })
            .collect();
        let p = propose(&space, &obs, 0.0, 4, None).expect("proposal");
        assert_eq!(p.points.len(), 4);
        let mut all: Vec<f64> = obs.iter().map(|o| o.x[0]).collect();
        all.extend(p.points.iter().map(|x| x[0]));
        for (i, a) in all.iter().enumerate() {
            for b in &all[i + 1..] {
                assert!((a - b).abs() > 1e-9, "{a} twice in {all:?}");
            }
        }
        // Deterministic: the same data proposes the same batch.
        let again = propose(&space, &obs, 0.0, 4, None).expect("proposal");
        assert_eq!(p.points, again.points);
    }

    #[test]
    fn seed_noise_is_pooled_over_points() {
        // Two points at two seeds: deviations +-1 and +-2 -> pooled sd sqrt((2 + 8) / 2).
        let sd = seed_mean_noise(&[vec![1.0, 3.0], vec![0.0, 4.0], vec![9.0]]).expect("noise");
        assert!((sd - (5.0f64).sqrt() / 2f64.sqrt()).abs() < 1e-12, "{sd}");
        assert_eq!(seed_mean_noise(&[vec![1.0], vec![2.0]]), None);
    }

    #[test]
    fn bad_boxes_are_refused_with_the_axis_named() {
        let e = SearchBox::new(vec![(1.0, 1.0)]).expect_err("empty axis");
        assert!(e.to_string().contains("axis 0"), "{e}");
        assert!(SearchBox::new(vec![]).is_err());
        assert!(SearchBox::new(vec![(0.0, 1.0); 5]).is_err());
    }
}
