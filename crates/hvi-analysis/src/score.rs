//! Scoring runs against the experiments: the targets of `experiments_data/*.toml` and the
//! objective that combines them.
//!
//! # The objective
//!
//! Each target i turns one observable x of a run into a dimensionless term t_i:
//!
//! | kind | term | meaning |
//! |---|---|---|
//! | `value` | ((x - value) / tolerance)^2 | a measured number, e.g. R = 1.55 |
//! | `at_most` | (max(0, x - value) / tolerance)^2 | an upper bound, e.g. no large fragment |
//! | `log_value` | (ln(x / value) / ln(tolerance))^2 | a size known within a factor |
//!
//! The objective is the weighted mean J = sum_i w_i t_i / sum_i w_i over the targets (weights
//! from the target file, overridable per study). A term whose observable the run did not
//! produce (failed run, no cloud) is [`MISSING_TERM`], so such a run never wins. J = 1 means
//! "every target met to within its tolerance"; J = 0 is a perfect match. Gaps (targets whose
//! numbers are not available) are listed and never scored.
//!
//! ```
//! use hvi_analysis::observable::Observable;
//! use hvi_analysis::score::{Target, TargetKind, objective};
//! let r = Target { name: "length_ratio".into(), observable: Observable::LengthRatio,
//!     kind: TargetKind::Value, value: 1.55, tolerance: 0.1, weight: 1.0, source: String::new() };
//! let s = objective(&[r], |_| Some(1.45));
//! assert!((s.objective - 1.0).abs() < 1e-12);
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::observable::Observable;

/// The term of a target whose observable is missing: larger than any plausible score.
pub const MISSING_TERM: f64 = 1e3;

/// How a target scores its observable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetKind {
    /// ((x - value) / tolerance)^2.
    Value,
    /// (max(0, x - value) / tolerance)^2.
    AtMost,
    /// (ln(x / value) / ln(tolerance))^2, tolerance a factor > 1.
    LogValue,
}

/// One scored target.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    /// The term's name (a column `score_<name>` in the tables).
    pub name: String,
    /// The observable it scores.
    pub observable: Observable,
    /// How.
    pub kind: TargetKind,
    /// The target value or bound, in the observable's unit.
    pub value: f64,
    /// The scale of one unit of the term (same unit; a factor for `log_value`).
    pub tolerance: f64,
    /// Weight in the objective.
    pub weight: f64,
    /// Where the number comes from.
    pub source: String,
}

/// A target whose number is not available: named with its source, never scored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gap {
    /// Name.
    pub name: String,
    /// The observable it would score.
    pub observable: Observable,
    /// Where it is (or would be) published.
    pub source: String,
    /// Why it is missing and what is done instead.
    pub note: String,
}

/// The experiment a target file describes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shot {
    /// Identifier.
    pub id: String,
    /// What it is.
    pub description: String,
    /// Provenance.
    pub source: String,
    /// Impactor diameter, m.
    pub impactor_diameter_m: f64,
    /// Impact velocity of the experiment, m/s.
    pub v0_m_s: f64,
    /// Plate thickness over diameter of the experiment.
    pub t_over_d: f64,
    /// The velocity the paper (and the calibration scene) simulates it at, m/s.
    pub simulated_v0_m_s: f64,
    /// The t/D the paper (and the calibration scene) simulates it at.
    pub simulated_t_over_d: f64,
}

/// A target file: the shot, its targets, its gaps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Targets {
    /// The experiment.
    pub shot: Shot,
    /// Scored targets.
    pub targets: Vec<Target>,
    /// Documented gaps.
    #[serde(default)]
    pub gaps: Vec<Gap>,
    /// The file it came from.
    #[serde(skip)]
    pub path: PathBuf,
}

impl Targets {
    /// Parses target TOML, checking kinds, tolerances, weights and observable names.
    pub fn parse(text: &str, path: &Path) -> Result<Targets> {
        let doc: toml::Value = toml::from_str(text).context("target file is not valid TOML")?;
        let mut t: Targets = serde_path_to_error::deserialize(doc).map_err(|e| {
            let p = e.path().to_string();
            anyhow!("target file key `{p}`: {}", e.into_inner().message().trim())
        })?;
        t.path = path.to_path_buf();
        for (i, x) in t.targets.iter().enumerate() {
            let key = format!("targets[{i}] ({})", x.name);
            if !x.value.is_finite() {
                bail!("{key}: value must be a finite number");
            }
            let tol_ok = match x.kind {
                TargetKind::LogValue => x.tolerance > 1.0 && x.value > 0.0,
                _ => x.tolerance > 0.0,
            };
            if !(tol_ok && x.tolerance.is_finite()) {
                bail!(
                    "{key}: tolerance {} (allowed: > 0; for kind = \"log_value\" a factor > 1 and value > 0)",
                    x.tolerance
                );
            }
            if !(x.weight.is_finite() && x.weight >= 0.0) {
                bail!("{key}: weight {} (allowed: a finite number >= 0)", x.weight);
            }
            if t.targets[..i].iter().any(|y| y.name == x.name) {
                bail!("{key}: name appears twice");
            }
        }
        if t.targets.iter().map(|x| x.weight).sum::<f64>() <= 0.0 {
            bail!("target file has no target with a weight > 0");
        }
        Ok(t)
    }

    /// Overrides weights by target name (a study's `[calibrate.weights]`).
    pub fn with_weights(mut self, weights: &BTreeMap<String, f64>) -> Result<Targets> {
        for (name, &w) in weights {
            let t = self
                .targets
                .iter_mut()
                .find(|t| &t.name == name)
                .ok_or_else(|| anyhow!("calibrate.weights: no target named `{name}`"))?;
            if !(w.is_finite() && w >= 0.0) {
                bail!("calibrate.weights.{name}: {w} (allowed: a finite number >= 0)");
            }
            t.weight = w;
        }
        if self.targets.iter().map(|x| x.weight).sum::<f64>() <= 0.0 {
            bail!("calibrate.weights: every weight is 0");
        }
        Ok(self)
    }
}

/// One target's term.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Term {
    /// The target's name.
    pub name: String,
    /// The observable's value, if the run has it.
    pub observed: Option<f64>,
    /// The term t_i (MISSING_TERM when the observable is missing).
    pub term: f64,
    /// Its weight.
    pub weight: f64,
}

/// A run's score: the objective and each term.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Score {
    /// J = sum w_i t_i / sum w_i.
    pub objective: f64,
    /// The terms, in target order.
    pub terms: Vec<Term>,
}

/// The term of one target for an observed value.
pub fn term(t: &Target, x: Option<f64>) -> f64 {
    let Some(x) = x.filter(|v| v.is_finite()) else {
        return MISSING_TERM;
    };
    let u = match t.kind {
        TargetKind::Value => (x - t.value) / t.tolerance,
        TargetKind::AtMost => (x - t.value).max(0.0) / t.tolerance,
        TargetKind::LogValue => {
            if x <= 0.0 {
                return MISSING_TERM;
            }
            (x / t.value).ln() / t.tolerance.ln()
        }
    };
    (u * u).min(MISSING_TERM)
}

/// Scores observables against targets.
pub fn objective(targets: &[Target], observable: impl Fn(Observable) -> Option<f64>) -> Score {
    let mut sum = 0.0;
    let mut wsum = 0.0;
    let terms = targets
        .iter()
        .map(|t| {
            let x = observable(t.observable);
            let v = term(t, x);
            sum += t.weight * v;
            wsum += t.weight;
            Term {
                name: t.name.clone(),
                observed: x,
                term: v,
                weight: t.weight,
            }
        })
        .collect();
    Score {
        objective: if wsum > 0.0 { sum / wsum } else { f64::NAN },
        terms,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn target(kind: TargetKind, value: f64, tolerance: f64, weight: f64) -> Target {
        Target {
            name: format!("{kind:?}"),
            observable: Observable::LengthRatio,
            kind,
            value,
            tolerance,
            weight,
            source: String::new(),
        }
    }

    #[test]
    fn objective_on_known_numbers() {
        let r = target(TargetKind::Value, 1.55, 0.1, 1.0);
        let big = Target {
            name: "big".into(),
            observable: Observable::LargestFragmentMassFraction,
            ..target(TargetKind::AtMost, 0.05, 0.05, 1.0)
        };
        let size = Target {
            name: "size".into(),
            observable: Observable::MeanFragmentDiameter,
            ..target(TargetKind::LogValue, 1e-3, 3.0, 0.5)
        };
        let obs = |name: Observable| match name {
            Observable::LengthRatio => Some(1.35), // 2 tolerances off: 4
            Observable::LargestFragmentMassFraction => Some(0.2), // 3 tolerances over: 9
            Observable::MeanFragmentDiameter => Some(9e-3), // a factor 9 = 3^2: 4
            _ => None,
        };
        let s = objective(&[r.clone(), big.clone(), size.clone()], obs);
        assert!((s.terms[0].term - 4.0).abs() < 1e-9, "{:?}", s.terms);
        assert!((s.terms[1].term - 9.0).abs() < 1e-9, "{:?}", s.terms);
        assert!((s.terms[2].term - 4.0).abs() < 1e-9, "{:?}", s.terms);
        assert!((s.objective - (4.0 + 9.0 + 0.5 * 4.0) / 2.5).abs() < 1e-9);
        // Under the bound, an at_most term is zero; the log term is symmetric.
        let s = objective(&[big.clone(), size.clone()], |n| match n {
            Observable::LargestFragmentMassFraction => Some(0.01),
            _ => Some(1e-3 / 3.0),
        });
        assert_eq!(s.terms[0].term, 0.0);
        assert!((s.terms[1].term - 1.0).abs() < 1e-9);
        // A missing observable costs MISSING_TERM, so a failed run never wins.
        let s = objective(std::slice::from_ref(&r), |_| None);
        assert_eq!(s.objective, MISSING_TERM);
        assert_eq!(s.terms[0].observed, None);
    }

    #[test]
    fn the_shipped_target_file_parses_and_names_its_gaps() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../experiments_data/calibration-shot.toml");
        let text = std::fs::read_to_string(&path).expect("shipped file");
        let t = Targets::parse(&text, &path).expect("parses");
        let r = t
            .targets
            .iter()
            .find(|x| x.observable == Observable::LengthRatio)
            .expect("R target");
        assert_eq!(r.value, 1.55);
        assert_eq!(t.shot.v0_m_s, 6500.0);
        assert_eq!(t.shot.t_over_d, 0.41);
        assert!(t
            .gaps
            .iter()
            .any(|g| g.observable == Observable::FrontVelocityRatio));
        // No target invents a front velocity.
        assert!(t
            .targets
            .iter()
            .all(|x| x.observable != Observable::FrontVelocityRatio));
    }

    #[test]
    fn bad_target_files_are_refused() {
        let base = "[shot]\nid = \"x\"\ndescription = \"\"\nsource = \"\"\nimpactor_diameter_m = 1\nv0_m_s = 1\nt_over_d = 1\nsimulated_v0_m_s = 1\nsimulated_t_over_d = 1\n";
        for (extra, needle) in [
            ("[[targets]]\nname = \"a\"\nobservable = \"R\"\nkind = \"value\"\nvalue = 1\ntolerance = 1\nweight = 1\nsource = \"\"\n", "unknown observable"),
            ("[[targets]]\nname = \"a\"\nobservable = \"length_ratio\"\nkind = \"value\"\nvalue = 1\ntolerance = 0\nweight = 1\nsource = \"\"\n", "tolerance"),
            ("[[targets]]\nname = \"a\"\nobservable = \"length_ratio\"\nkind = \"log_value\"\nvalue = 1\ntolerance = 0.5\nweight = 1\nsource = \"\"\n", "tolerance"),
            ("[[targets]]\nname = \"a\"\nobservable = \"length_ratio\"\nkind = \"bigger\"\nvalue = 1\ntolerance = 1\nweight = 1\nsource = \"\"\n", "kind"),
        ] {
            let e = Targets::parse(&format!("{base}{extra}"), Path::new("t.toml"))
                .expect_err(extra);
            assert!(format!("{e:#}").contains(needle), "{e:#}");
        }
    }
}
