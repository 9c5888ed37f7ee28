//! The `[calibrate]` section of a study file, and the search method it names.
//!
//! ```toml
//! [calibrate]
//! shots = ["../experiments_data/calibration-shot.toml"]   # relative to the study file
//! weights = { fragment_size = 0.5 }       # optional: override target weights by name
//! refine = ["material.eps_j", "material.kappa_n_m"]   # default: every axis with > 1 value
//! log_axes = ["material.eps_j", "material.kappa_n_m"] # searched in log10 (default these two)
//! method = "ego"          # or "nelder-mead"
//! ```
//!
//! Every key is listed in docs/calibration.md.

use std::collections::BTreeMap;
use std::path::PathBuf;

use hvi_run::bail;
use hvi_run::error::{Result, RunError};
use hvi_store::spec::Study;
use serde::Deserialize;

fn default_log_axes() -> Vec<String> {
    vec!["material.eps_j".into(), "material.kappa_n_m".into()]
}

fn default_max_iters() -> u64 {
    8
}

fn default_sd_tolerance() -> f64 {
    0.02
}

fn default_batch() -> usize {
    2
}

fn default_max_batches() -> usize {
    8
}

fn default_max_extensions() -> usize {
    2
}
fn default_ladder_values() -> usize {
    2
}

fn default_true() -> bool {
    true
}

fn default_noise_floor() -> f64 {
    0.02
}

fn default_seeds_within_decades() -> f64 {
    1.0
}

fn default_screen_after_transits() -> f64 {
    5.6
}

fn default_screen_after_plate_transits() -> f64 {
    13.3
}

fn default_screen_max_t_over_d() -> f64 {
    0.6
}

fn default_screen_above() -> f64 {
    0.25
}

fn default_screen_allowance() -> f64 {
    0.04
}

/// The search after the grid.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Efficient global optimisation: a kriging model of the objective, batches of runs by
    /// expected improvement, stopped when the improvement left is below the seed noise.
    #[default]
    Ego,
    /// Nelder-Mead (argmin) from the best grid point, one run at a time.
    NelderMead,
}

impl Method {
    /// The name as the study file and calibration.json spell it.
    pub fn name(self) -> &'static str {
        match self {
            Method::Ego => "ego",
            Method::NelderMead => "nelder-mead",
        }
    }
}

/// Which of the study grid's points the grid stage runs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InitialDesign {
    /// Every point of the grid.
    #[default]
    Grid,
    /// The corners of the searched axes' box and the grid point nearest its centre, at every
    /// value of the axes not searched ([`crate::design`]); the rest of the grid stays the
    /// lattice the box extends on and fills in near the answer.
    Corners,
}

impl InitialDesign {
    /// The name as the study file and calibration.json spell it.
    pub fn name(self) -> &'static str {
        match self {
            InitialDesign::Grid => "grid",
            InitialDesign::Corners => "corners",
        }
    }
}

/// `[calibrate]` of a study file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrateConfig {
    /// The shot files (each an experiment's impact and its targets), relative to the study
    /// file.
    #[serde(default)]
    pub shots: Vec<PathBuf>,
    /// One shot file, the same as `shots = [targets]` (the key of studies written before
    /// `shots`).
    #[serde(default)]
    pub targets: Option<PathBuf>,
    /// Weights by target name, overriding the target file's.
    #[serde(default)]
    pub weights: BTreeMap<String, f64>,
    /// The axes the refinement moves (default: every axis with more than one value).
    #[serde(default)]
    pub refine: Option<Vec<String>>,
    /// Axes refined in log10.
    #[serde(default = "default_log_axes")]
    pub log_axes: Vec<String>,
    /// Nelder-Mead iterations at most.
    #[serde(default = "default_max_iters")]
    pub max_iters: u64,
    /// Stop when the objective's standard deviation over the simplex falls below this.
    #[serde(default = "default_sd_tolerance")]
    pub sd_tolerance: f64,
    /// The search after the grid: `ego` (default) or `nelder-mead`.
    #[serde(default)]
    pub method: Method,
    /// The grid stage's points: `grid` (default, every point) or `corners` (the searched box's
    /// corners and centre).
    #[serde(default)]
    pub initial_design: InitialDesign,
    /// ego: points per batch (run together at the first seed, then at the further seeds where
    /// they are near the answer).
    #[serde(default = "default_batch")]
    pub batch: usize,
    /// ego: the seeds every point runs at (empty: the scene's seed only).
    #[serde(default)]
    pub seeds: Vec<u64>,
    /// ego: batches at most.
    #[serde(default = "default_max_batches")]
    pub max_batches: usize,
    /// ego: the least noise assumed for log10 of the objective (a seed mean's standard error);
    /// with one seed it is the noise.
    #[serde(default = "default_noise_floor")]
    pub noise_floor: f64,
    /// ego: the seeds after the first run only at points whose first seed's objective is
    /// within this many decades of the lowest objective measured so far (`inf`: every seed at
    /// every point).
    #[serde(default = "default_seeds_within_decades")]
    pub seeds_within_decades: f64,
    /// ego: steps each side of the box may move beyond the grid when the answer touches it (a
    /// decade on a log axis, the grid's spacing on a linear one).
    #[serde(default = "default_max_extensions")]
    pub max_extensions: usize,
    /// Resolution ladder (`--ladder`): the values each searched axis takes in the first box of
    /// a level after the first (its corners and the points between, spaced evenly in the
    /// axis's coordinate). Two by default: with the prior the corners only fix the
    /// difference from the coarse landscape.
    #[serde(default = "default_ladder_values")]
    pub ladder_values: usize,
    /// Resolution ladder: whether a level's search models the difference from the level
    /// before (a multi-fidelity prior; false: each level learns its landscape afresh).
    #[serde(default = "default_true")]
    pub ladder_prior: bool,
    /// Resolution ladder: the particle count at which the last level's answer is run again
    /// as a check (none: no check; `--ladder-check` overrides).
    #[serde(default)]
    pub ladder_check: Option<f64>,
    /// Overrides `calibrate` adds to every run it makes at a tier, by tier name (after the
    /// study's `set`, so the tier's own `set` and `--set` still win): settings that give the
    /// calibration its answer sooner at a cost measured in docs/model-decisions.md, such as the
    /// quarter-symmetric scene and free flight after a set time. `sweep` and the reproduction
    /// run the tier without them.
    #[serde(default)]
    pub tier_set: BTreeMap<String, Vec<String>>,
    /// The screen (`crate::screen`): whether runs whose length ratio or va/v0 alone puts J
    /// above `screen_above` go on in free flight from `screen_after_transits` instead of in
    /// full.
    #[serde(default = "default_true")]
    pub screen: bool,
    /// The screen's time after first contact in transit times D/v0 of each shot (5.6: 7.97 us
    /// for 9.53 mm at 6.7 km/s), or [`Self::screen_after_plate_transits`] if later (for the
    /// calibration shot, t/D = 0.425: 8.04 us).
    #[serde(default = "default_screen_after_transits")]
    pub screen_after_transits: f64,
    /// The screen's time after first contact in the plate's transit times t/v0 of each shot,
    /// when later than [`Self::screen_after_transits`] (13.3: 8 D/v0 at t/D = 0.6, where the
    /// debris front still slows after 5.6 D/v0; 0: the impactor's transits alone).
    #[serde(default = "default_screen_after_plate_transits")]
    pub screen_after_plate_transits: f64,
    /// The thickest plate, t/D as simulated, whose shot's runs are screened (0.6, the thickest
    /// where free flight from the screen's time was measured within `screen_allowance`; it
    /// moved va/v0 by up to 6.3 % at t/D = 0.8 and 8.7 % at 1.0); a thicker plate's runs go in
    /// full. `inf` screens every plate.
    #[serde(default = "default_screen_max_t_over_d")]
    pub screen_max_t_over_d: f64,
    /// The objective a run's screened term alone must put J above (never below the term of
    /// a missed target, 1).
    #[serde(default = "default_screen_above")]
    pub screen_above: f64,
    /// How far each window is widened on each side, as a fraction of the target's value: what
    /// free flight may move the screened observables.
    #[serde(default = "default_screen_allowance")]
    pub screen_allowance: f64,
}

impl CalibrateConfig {
    /// Reads `[calibrate]` of a study.
    pub fn of(study: &Study) -> Result<CalibrateConfig> {
        let v = study.calibrate.clone().ok_or_else(|| {
            RunError::Input(format!(
                "study `{}` has no [calibrate] section (it needs at least targets = \"...\")",
                study.name
            ))
        })?;
        let cfg: CalibrateConfig = serde_path_to_error::deserialize(v).map_err(|e| {
            let p = e.path().to_string();
            RunError::Input(format!(
                "study key `calibrate.{p}`: {}",
                e.into_inner().message().trim()
            ))
        })?;
        if !(cfg.sd_tolerance.is_finite() && cfg.sd_tolerance >= 0.0) {
            bail!(
                "study key `calibrate.sd_tolerance`: {} (allowed: a number >= 0)",
                cfg.sd_tolerance
            );
        }
        if !(1..=64).contains(&cfg.batch) {
            bail!(
                "study key `calibrate.batch`: {} (allowed: 1 to 64 points per batch)",
                cfg.batch
            );
        }
        if cfg.max_batches > 1000 {
            bail!(
                "study key `calibrate.max_batches`: {} (allowed: 0 to 1000)",
                cfg.max_batches
            );
        }
        if !(cfg.noise_floor.is_finite() && cfg.noise_floor >= 0.0) {
            bail!(
                "study key `calibrate.noise_floor`: {} (allowed: a number >= 0)",
                cfg.noise_floor
            );
        }
        if cfg.seeds_within_decades.is_nan() || cfg.seeds_within_decades <= 0.0 {
            bail!(
                "study key `calibrate.seeds_within_decades`: {} (allowed: a number > 0, or inf to \
                 run every seed at every point)",
                cfg.seeds_within_decades
            );
        }
        if cfg.max_extensions > 10 {
            bail!(
                "study key `calibrate.max_extensions`: {} (allowed: 0 to 10 steps beyond the grid)",
                cfg.max_extensions
            );
        }
        if !(2..=9).contains(&cfg.ladder_values) {
            bail!(
                "study key `calibrate.ladder_values`: {} (allowed: 2 to 9 values per axis)",
                cfg.ladder_values
            );
        }
        if let Some(n) = cfg.ladder_check {
            if !(n.is_finite() && n >= 8.0) {
                bail!("study key `calibrate.ladder_check`: {n} (allowed: a particle count >= 8)");
            }
        }
        cfg.check_seeds("study key `calibrate.seeds`")?;
        cfg.check_tier_set(study)?;
        cfg.check_screen()?;
        match (&cfg.targets, cfg.shots.len()) {
            (Some(_), n) if n > 0 => bail!(
                "study keys `calibrate.targets` and `calibrate.shots` are both given (allowed: \
                 one of the two; `targets = \"f\"` is `shots = [\"f\"]`)"
            ),
            (None, 0) => bail!(
                "study key `calibrate.shots` is missing (allowed: a list of shot files, e.g. \
                 shots = [\"../experiments_data/calibration-shot.toml\"])"
            ),
            _ => {}
        }
        Ok(cfg)
    }

    /// The screen's keys, each in its range.
    fn check_screen(&self) -> Result<()> {
        if !(self.screen_after_transits.is_finite() && self.screen_after_transits > 0.0) {
            bail!(
                "study key `calibrate.screen_after_transits`: {} (allowed: a number of transit \
                 times D/v0 after first contact > 0; a run that ends before it is not screened)",
                self.screen_after_transits
            );
        }
        if !(self.screen_after_plate_transits.is_finite()
            && self.screen_after_plate_transits >= 0.0)
        {
            bail!(
                "study key `calibrate.screen_after_plate_transits`: {} (allowed: a number of the \
                 plate's transit times t/v0 after first contact >= 0; 0 leaves the time to \
                 `screen_after_transits`)",
                self.screen_after_plate_transits
            );
        }
        if self.screen_max_t_over_d.is_nan() || self.screen_max_t_over_d <= 0.0 {
            bail!(
                "study key `calibrate.screen_max_t_over_d`: {} (allowed: a plate thickness t/D \
                 > 0, or inf; a shot's plate thicker than it is not screened)",
                self.screen_max_t_over_d
            );
        }
        if !(self.screen_above.is_finite() && self.screen_above > 0.0) {
            bail!(
                "study key `calibrate.screen_above`: {} (allowed: a number > 0; `screen = false` \
                 turns the screen off)",
                self.screen_above
            );
        }
        if !(0.0..1.0).contains(&self.screen_allowance) {
            bail!(
                "study key `calibrate.screen_allowance`: {} (allowed: 0 <= a fraction < 1)",
                self.screen_allowance
            );
        }
        Ok(())
    }

    /// `calibrate.tier_set`: each name a tier of the study, each entry an override of a key
    /// that is not an axis.
    fn check_tier_set(&self, study: &Study) -> Result<()> {
        for (tier, set) in &self.tier_set {
            if !study.tiers.contains_key(tier) {
                bail!(
                    "study key `calibrate.tier_set.{tier}`: `{tier}` is not a tier of this study \
                 (allowed: {:?})",
                    study.tiers.keys().collect::<Vec<_>>()
                );
            }
            for o in set {
                let k = hvi_store::spec::override_key(o);
                if !o.contains('=') || study.axes.iter().any(|a| a.key == k) {
                    bail!(
                        "study key `calibrate.tier_set.{tier}`: `{o}` (allowed: section.key=value \
                     overrides of keys that are not axes)"
                    );
                }
            }
        }
        Ok(())
    }

    /// The overrides `calibrate` adds at `tier` (the study's default tier when None).
    pub fn tier_set_of(&self, study: &Study, tier: Option<&str>) -> Result<Vec<String>> {
        let name = &study.tier(tier)?.name;
        Ok(self.tier_set.get(name).cloned().unwrap_or_default())
    }

    /// The shot files, as the study names them (relative to the study file).
    pub fn shot_files(&self) -> Vec<PathBuf> {
        match &self.targets {
            Some(t) => vec![t.clone()],
            None => self.shots.clone(),
        }
    }

    /// The first shot's target file (resolved against the study file's directory), with the
    /// study's weights applied.
    pub fn load_targets(&self, study: &Study) -> Result<hvi_analysis::score::Targets> {
        self.load_shots(study)?
            .into_iter()
            .next()
            .ok_or_else(|| RunError::Input("study key `calibrate.shots` is empty".to_string()))
    }

    /// Every shot's target file (resolved against the study file's directory), with the
    /// study's weights applied (a weight names a target of some shot); shot ids distinct.
    pub fn load_shots(&self, study: &Study) -> Result<Vec<hvi_analysis::score::Targets>> {
        let base = study
            .path
            .parent()
            .unwrap_or_else(|| std::path::Path::new("."));
        let shots: Vec<hvi_analysis::score::Targets> = self
            .shot_files()
            .iter()
            .map(|f| hvi_run::output::load_targets(&base.join(f)))
            .collect::<Result<_>>()?;
        for (i, s) in shots.iter().enumerate() {
            if shots[..i].iter().any(|t| t.shot.id == s.shot.id) {
                bail!(
                    "study key `calibrate.shots`: two files name the shot `{}` (allowed: distinct \
                     shot ids)",
                    s.shot.id
                );
            }
        }
        for name in self.weights.keys() {
            if !shots
                .iter()
                .any(|s| s.targets.iter().any(|t| &t.name == name))
            {
                bail!("calibrate.weights: no shot has a target named `{name}`");
            }
        }
        shots
            .into_iter()
            .map(|s| {
                let own: BTreeMap<String, f64> = self
                    .weights
                    .iter()
                    .filter(|(k, _)| s.targets.iter().any(|t| &t.name == *k))
                    .map(|(k, v)| (k.clone(), *v))
                    .collect();
                s.with_weights(&own).map_err(hvi_run::error::RunError::from)
            })
            .collect()
    }

    /// The seeds are distinct (`what` names where they came from in the error).
    pub(super) fn check_seeds(&self, what: &str) -> Result<()> {
        let mut seeds = self.seeds.clone();
        seeds.sort_unstable();
        seeds.dedup();
        if seeds.len() != self.seeds.len() {
            bail!(
                "{what}: {:?} names a seed twice (allowed: distinct seeds)",
                self.seeds
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_max_t_over_d(v: f64) -> CalibrateConfig {
        let mut cfg: CalibrateConfig =
            serde_json::from_value(serde_json::json!({})).expect("the defaults");
        cfg.screen_max_t_over_d = v;
        cfg
    }

    /// `calibrate.screen_max_t_over_d` is a thickness above zero, or inf; anything else is
    /// refused naming the key and what it allows.
    #[test]
    fn the_thickest_screened_plate_must_be_a_thickness_above_zero() {
        for ok in [0.6, 2.0, f64::INFINITY] {
            assert!(with_max_t_over_d(ok).check_screen().is_ok(), "{ok} refused");
        }
        for bad in [0.0, -0.5, f64::NAN] {
            let err = with_max_t_over_d(bad)
                .check_screen()
                .expect_err("refused")
                .to_string();
            assert!(
                err.contains("calibrate.screen_max_t_over_d") && err.contains("allowed: a plate"),
                "{bad}: {err}"
            );
        }
        let defaults: CalibrateConfig =
            serde_json::from_value(serde_json::json!({})).expect("the defaults");
        assert_eq!(defaults.screen_max_t_over_d, 0.6);
    }
}
