//! What the readings study found: each reading measured and judged, and the whole study.

use std::path::PathBuf;

use hvi_analysis::contour::Field;

use crate::config::{FidelityConfig, Reading};
use hvi_reproduce::report::{Check, Figure, Verdict};

/// One reading, measured and judged.
#[derive(Debug, Clone)]
pub struct Judged {
    /// The reading.
    pub reading: Reading,
    /// The seeds its runs were run at.
    pub seeds: Vec<u64>,
    /// Where its runs are (its own or those it measures again).
    pub runs_dir: PathBuf,
    /// The runs it read (grid points x seeds) and how many of them were measured again from
    /// their state.
    pub runs: usize,
    /// How many of its runs came from the store (0 for a measured reading).
    pub cached: usize,
    /// R over (eps, kappa), one per seed, then the seed mean (the judged field).
    pub length_ratio: SeedFields,
    /// va/v0 over (eps, kappa), the same.
    pub front_velocity: SeedFields,
    /// Fig. 9 judged on the seed mean.
    pub fig9: Figure,
    /// Fig. 10 judged on the seed mean.
    pub fig10: Figure,
    /// Fig. 9's checks on the seed mean, (main, secondary).
    pub fig9_checks: (Vec<Check>, Vec<Check>),
    /// Fig. 10's checks on the seed mean.
    pub fig10_checks: (Vec<Check>, Vec<Check>),
    /// Fig. 9's and Fig. 10's verdicts at each seed alone.
    pub per_seed: Vec<(u64, Verdict, Verdict)>,
}

impl Judged {
    /// Every check, Fig. 9's then Fig. 10's, main before secondary.
    pub fn checks(&self) -> Vec<&Check> {
        let (a, b) = &self.fig9_checks;
        let (c, d) = &self.fig10_checks;
        a.iter().chain(b).chain(c).chain(d).collect()
    }

    /// (main-claim checks held, all checks held): how close the reading comes to the paper.
    pub fn score(&self) -> (usize, usize) {
        let held = |v: &[Check]| v.iter().filter(|c| c.held).count();
        let main = held(&self.fig9_checks.0) + held(&self.fig10_checks.0);
        (main, self.checks().iter().filter(|c| c.held).count())
    }
}

/// An observable's field per seed and the mean over seeds.
#[derive(Debug, Clone)]
pub struct SeedFields {
    /// (seed, field).
    pub seeds: Vec<(u64, Field)>,
    /// The mean over seeds, cell by cell (NaN where a seed has no value).
    pub mean: Field,
}

impl SeedFields {
    /// The mean over grid cells of the spread across seeds (max - min), None with one seed.
    pub fn seed_spread(&self) -> Option<f64> {
        if self.seeds.len() < 2 {
            return None;
        }
        let mut spreads = Vec::new();
        for (r, row) in self.mean.z.iter().enumerate() {
            for c in 0..row.len() {
                let v: Vec<f64> = self.seeds.iter().map(|(_, f)| f.z[r][c]).collect();
                if v.iter().all(|x| x.is_finite()) {
                    let (lo, hi) = v
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                            (a.min(x), b.max(x))
                        });
                    spreads.push(hi - lo);
                }
            }
        }
        (!spreads.is_empty()).then(|| spreads.iter().sum::<f64>() / spreads.len() as f64)
    }
}

/// The whole study, judged.
#[derive(Debug, Clone)]
pub struct FidelityResult {
    /// The config.
    pub config: FidelityConfig,
    /// The tier run.
    pub tier: String,
    /// Its particle count (as the first run reports it).
    pub particles: Option<f64>,
    /// The seeds.
    pub seeds: Vec<u64>,
    /// Each reading, in the config's order.
    pub readings: Vec<Judged>,
    /// Wall time of the command, s.
    pub wall_seconds: f64,
    /// Runs simulated by this command.
    pub ran: usize,
}

impl FidelityResult {
    /// The reading closest to the paper: most main-claim checks, then most checks, then the
    /// earlier in the config (the default first when it ties).
    pub fn closest(&self) -> Option<&Judged> {
        let mut best: Option<&Judged> = None;
        for j in &self.readings {
            if best.is_none() || best.is_some_and(|b| j.score() > b.score()) {
                best = Some(j);
            }
        }
        best
    }
}
