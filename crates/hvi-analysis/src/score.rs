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
//! produce (failed run, no cloud) is [`MISSING_TERM`], so such a run never wins. A target is
//! met when its term is at most 1 (within its tolerance); J = 0 is a perfect match, and since
//! J is a mean, J <= 1 does not by itself mean that every target is met. Gaps (targets whose
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

use crate::error::{bail, AnalysisError, Result};
use serde::{Deserialize, Serialize};

use crate::observable::Observable;
pub use crate::shot::Shot;

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
        let doc: toml::Value = toml::from_str(text)
            .map_err(|e| AnalysisError::context("target file is not valid TOML", e))?;
        let mut t: Targets = serde_path_to_error::deserialize(doc).map_err(|e| {
            let p = e.path().to_string();
            AnalysisError::Input(format!(
                "target file key `{p}`: {}",
                e.into_inner().message().trim()
            ))
        })?;
        t.path = path.to_path_buf();
        t.shot.check().map_err(AnalysisError::Input)?;
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
                .ok_or_else(|| {
                    AnalysisError::Input(format!("calibrate.weights: no target named `{name}`"))
                })?;
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

/// The objective over several shots: each shot's J over its own targets, combined as their
/// mean, J = (1/S) sum_s J_s, so that every shot counts alike whatever its number of
/// targets. The terms are every shot's, named `<shot id>:<target name>`, each with the weight
/// that makes J their weighted mean (w_i / sum of its shot's weights, over S). With one shot
/// this is [`objective`] itself, names and weights unchanged. `observable(s, o)` is shot s's
/// value of `o`.
pub fn combined_objective(
    shots: &[Targets],
    observable: impl Fn(usize, Observable) -> Option<f64>,
) -> Score {
    if let [one] = shots {
        return objective(&one.targets, |o| observable(0, o));
    }
    let n = shots.len() as f64;
    let mut terms = Vec::new();
    let mut sum = 0.0;
    for (s, shot) in shots.iter().enumerate() {
        let score = objective(&shot.targets, |o| observable(s, o));
        let wsum: f64 = shot.targets.iter().map(|t| t.weight).sum();
        sum += score.objective;
        terms.extend(score.terms.into_iter().map(|t| Term {
            name: shot_term_name(&shot.shot.id, &t.name),
            weight: t.weight / wsum / n,
            ..t
        }));
    }
    Score {
        objective: if shots.is_empty() { f64::NAN } else { sum / n },
        terms,
    }
}

/// The targets of several shots as [`combined_objective`] scores them, in the order of its
/// terms: named `<shot id>:<target name>`, weighted so that J is their weighted mean (with one
/// shot, its targets unchanged).
pub fn combined_targets(shots: &[Targets]) -> Vec<Target> {
    if let [one] = shots {
        return one.targets.clone();
    }
    let n = shots.len() as f64;
    shots
        .iter()
        .flat_map(|shot| {
            let wsum: f64 = shot.targets.iter().map(|t| t.weight).sum();
            shot.targets.iter().map(move |t| Target {
                name: shot_term_name(&shot.shot.id, &t.name),
                weight: t.weight / wsum / n,
                ..t.clone()
            })
        })
        .collect()
}

/// The name of a target's term in a calibration over several shots.
pub fn shot_term_name(shot: &str, target: &str) -> String {
    format!("{shot}:{target}")
}

/// Each shot's own J from a combined score's terms (the weighted mean of the terms named
/// `<shot id>:...`), in the order of the shot ids given; with one shot, the score's objective.
pub fn shot_objectives(ids: &[String], score: &Score) -> Vec<(String, f64)> {
    if let [one] = ids {
        return vec![(one.clone(), score.objective)];
    }
    ids.iter()
        .map(|id| {
            let prefix = format!("{id}:");
            let (sum, wsum) = score
                .terms
                .iter()
                .filter(|t| t.name.starts_with(&prefix))
                .fold((0.0, 0.0), |(s, w), t| {
                    (s + t.weight * t.term, w + t.weight)
                });
            (id.clone(), if wsum > 0.0 { sum / wsum } else { f64::NAN })
        })
        .collect()
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

    fn one_shot(id: &str, targets: Vec<Target>) -> Targets {
        let text = format!(
            "[shot]\nid = \"{id}\"\ndescription = \"\"\nsource = \"\"\nimpactor_diameter_m = 1\n\
             impactor_material = \"Al\"\nplate_material = \"Al\"\nv0_m_s = 1\nt_over_d = 1\n\
             [[targets]]\nname = \"x\"\nobservable = \"length_ratio\"\nkind = \"value\"\n\
             value = 1\ntolerance = 1\nweight = 1\nsource = \"\"\n"
        );
        Targets {
            targets,
            ..Targets::parse(&text, Path::new("t.toml")).expect("shot")
        }
    }

    #[test]
    fn several_shots_count_alike_and_one_shot_is_its_own_objective() {
        let r = target(TargetKind::Value, 1.55, 0.1, 1.0);
        let big = Target {
            name: "big".into(),
            observable: Observable::LargestFragmentMassFraction,
            ..target(TargetKind::AtMost, 0.05, 0.05, 3.0)
        };
        let a = one_shot("a", vec![r.clone()]);
        let b = one_shot("b", vec![r.clone(), big.clone()]);
        // Shot a: R 1.35, term 4. Shot b: R 1.55 (0) and a fragment 3 tolerances over (9),
        // weights 1 and 3: J_b = 27 / 4.
        let obs = |s: usize, o: Observable| match (s, o) {
            (0, Observable::LengthRatio) => Some(1.35),
            (1, Observable::LengthRatio) => Some(1.55),
            (1, Observable::LargestFragmentMassFraction) => Some(0.2),
            _ => None,
        };
        let s = combined_objective(&[a.clone(), b.clone()], obs);
        assert!(
            (s.objective - (4.0 + 27.0 / 4.0) / 2.0).abs() < 1e-9,
            "{s:?}"
        );
        let names: Vec<&str> = s.terms.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(names, ["a:Value", "b:Value", "b:big"]);
        // The combined targets are the terms' names and weights, in order.
        let flat = combined_targets(&[a.clone(), b.clone()]);
        assert_eq!(
            flat.iter()
                .map(|t| (t.name.as_str(), t.weight))
                .collect::<Vec<_>>(),
            s.terms
                .iter()
                .map(|t| (t.name.as_str(), t.weight))
                .collect::<Vec<_>>()
        );
        // J is the weighted mean of the terms.
        let (sum, w) = s.terms.iter().fold((0.0, 0.0), |(x, w), t| {
            (x + t.weight * t.term, w + t.weight)
        });
        assert!((sum / w - s.objective).abs() < 1e-9);
        let per = shot_objectives(&["a".to_string(), "b".to_string()], &s);
        assert!(
            (per[0].1 - 4.0).abs() < 1e-9 && (per[1].1 - 6.75).abs() < 1e-9,
            "{per:?}"
        );
        // One shot: the plain objective, names and weights as the file gives them.
        let one = combined_objective(std::slice::from_ref(&b), |_, o| obs(1, o));
        assert_eq!(one, objective(&b.targets, |o| obs(1, o)));
        assert_eq!(one.terms[1].name, "big");
        assert_eq!(
            shot_objectives(&["b".to_string()], &one)[0].1,
            one.objective
        );
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
        // The paper simulates it at 6.7 km/s and t/D 0.425, an explicit offset.
        assert_eq!(t.shot.simulated_v0_m_s(), 6700.0);
        assert_eq!(t.shot.simulated_t_over_d(), 0.425);
        assert!(!t.shot.synthetic);
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
        let base = "[shot]\nid = \"x\"\ndescription = \"\"\nsource = \"\"\nimpactor_diameter_m = 1\nimpactor_material = \"Al\"\nplate_material = \"Al\"\nv0_m_s = 1\nt_over_d = 1\n";
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
