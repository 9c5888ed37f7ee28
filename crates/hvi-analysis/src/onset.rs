//! The fragmentation onset: where the impactor starts to fragment, as experiments give it
//! (relations of v over t/D with their sources, `experiments_data/fragmentation-onset.toml`)
//! and as the model gives it (found by bisection in v0, [`Bisection`]), and the rule that
//! compares them ([`compare`]).
//!
//! A relation is `v = max(offset + coefficient (t/D)^exponent, floor)` in km/s: the form both
//! published onsets take (Piekutowski's two branches, Reimerdes et al.'s eq. 11).
//!
//! ```
//! use hvi_analysis::onset::Relations;
//!
//! let r = Relations::shipped().expect("the shipped relations");
//! let p = r.get("piekutowski-2003").expect("Piekutowski");
//! // Thin plates: the descending branch; thick ones: the 2.60 km/s plateau.
//! assert!((p.onset_m_s(0.1) - 1436.0 * 0.1f64.powf(-0.333)).abs() < 1e-9);
//! assert_eq!(p.onset_m_s(0.4), 2600.0);
//! ```

use crate::error::{bail, AnalysisError, Result};
use serde::{Deserialize, Serialize};

/// The shipped relations file, `experiments_data/fragmentation-onset.toml`.
pub const SHIPPED: &str = include_str!("../../../experiments_data/fragmentation-onset.toml");

/// How far the model's onset may lie from an experiment's and still agree: 15 % of the
/// experiment's value (the two published relations differ by up to 10 % over t/D 0.02-0.45,
/// and each fits scattered shots).
pub const AGREEMENT: f64 = 0.15;

/// One published onset relation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Relation {
    /// Short name used in columns (`onset_<id>_m_s`).
    pub id: String,
    /// Name for legends and tables.
    pub name: String,
    /// Where it is published, with page.
    pub source: String,
    /// The impactors of the experiments.
    pub impactor: String,
    /// The plates of the experiments.
    pub plate: String,
    /// What the source calls the onset.
    pub onset: String,
    /// Offset, km/s.
    pub offset_km_s: f64,
    /// Coefficient of (t/D)^exponent, km/s.
    pub coefficient_km_s: f64,
    /// Exponent of t/D.
    pub exponent: f64,
    /// A lower bound of the onset (a plateau), km/s.
    #[serde(default)]
    pub floor_km_s: Option<f64>,
    /// Anything else the source says about it.
    #[serde(default)]
    pub note: String,
}

impl Relation {
    /// The onset velocity at `t_over_d`, m/s.
    pub fn onset_m_s(&self, t_over_d: f64) -> f64 {
        let v = self.offset_km_s + self.coefficient_km_s * t_over_d.powf(self.exponent);
        1e3 * self.floor_km_s.map_or(v, |f| v.max(f))
    }

    /// The t/D where the power law meets the floor (None without a floor or when they never
    /// meet): the boundary between the thin-plate and the thick-plate branch.
    pub fn branch_point(&self) -> Option<f64> {
        let floor = self.floor_km_s?;
        let x = (floor - self.offset_km_s) / self.coefficient_km_s;
        (x > 0.0 && self.exponent != 0.0)
            .then(|| x.powf(1.0 / self.exponent))
            .filter(|t| t.is_finite() && *t > 0.0)
    }

    fn check(&self) -> Result<()> {
        if self.id.is_empty()
            || !self
                .id
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-')
        {
            bail!(
                "relation key `id`: `{}` (allowed: letters, digits and '-')",
                self.id
            );
        }
        for (key, v) in [
            ("offset_km_s", self.offset_km_s),
            ("coefficient_km_s", self.coefficient_km_s),
            ("exponent", self.exponent),
        ] {
            if !v.is_finite() {
                bail!(
                    "relation `{}` key `{key}`: {v} (allowed: a finite number)",
                    self.id
                );
            }
        }
        if let Some(f) = self.floor_km_s {
            if !(f.is_finite() && f > 0.0) {
                bail!(
                    "relation `{}` key `floor_km_s`: {f} (allowed: a number > 0)",
                    self.id
                );
            }
        }
        if self.source.trim().is_empty() {
            bail!(
                "relation `{}` key `source`: empty (a relation needs its source)",
                self.id
            );
        }
        Ok(())
    }
}

/// A context note: a statement of a source without a relation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContextNote {
    /// Where it is published.
    pub source: String,
    /// What it says.
    pub note: String,
}

/// A relations file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Relations {
    /// The relations.
    pub relations: Vec<Relation>,
    /// Context notes.
    #[serde(default)]
    pub context: Vec<ContextNote>,
}

impl Relations {
    /// Parses and checks a relations file's text (`what` names it in errors).
    pub fn parse(text: &str, what: &str) -> Result<Relations> {
        let r: Relations = toml::from_str(text)
            .map_err(|e| AnalysisError::context(format!("onset relations {what}"), e))?;
        if r.relations.is_empty() {
            bail!("onset relations {what}: no [[relations]]");
        }
        for (i, a) in r.relations.iter().enumerate() {
            a.check()
                .map_err(|e| AnalysisError::context(format!("onset relations {what}"), e))?;
            if r.relations[..i].iter().any(|b| b.id == a.id) {
                bail!("onset relations {what}: id `{}` twice", a.id);
            }
        }
        Ok(r)
    }

    /// The relations shipped in `experiments_data/fragmentation-onset.toml`.
    pub fn shipped() -> Result<Relations> {
        Self::parse(SHIPPED, "experiments_data/fragmentation-onset.toml")
    }

    /// The relation of id `id`.
    pub fn get(&self, id: &str) -> Option<&Relation> {
        self.relations.iter().find(|r| r.id == id)
    }

    /// The t/D that splits thin from thick plates: the first relation's branch point that
    /// exists (Piekutowski's, near 0.168).
    pub fn branch_point(&self) -> Option<f64> {
        self.relations.iter().find_map(Relation::branch_point)
    }
}

/// Where the model's onset lies in v0, as bisection narrows it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Onset {
    /// Between two velocities (m/s): intact at `lo`, fragmented at `hi`.
    Between {
        /// Highest velocity found intact.
        lo: f64,
        /// Lowest velocity found fragmented.
        hi: f64,
    },
    /// Fragmented already at the lowest velocity searched.
    Below {
        /// That velocity, m/s.
        v: f64,
    },
    /// Intact still at the highest velocity searched.
    Above {
        /// That velocity, m/s.
        v: f64,
    },
}

impl Onset {
    /// The estimate: the bracket's middle (None outside the range searched).
    pub fn estimate_m_s(&self) -> Option<f64> {
        match *self {
            Onset::Between { lo, hi } => Some(0.5 * (lo + hi)),
            _ => None,
        }
    }

    /// In words: `3.09 km/s in [3.05, 3.13]`, `below 1.50 km/s`, `above 8.00 km/s`.
    pub fn describe(&self) -> String {
        match *self {
            Onset::Between { lo, hi } => format!(
                "{:.2} km/s in [{:.2}, {:.2}]",
                0.5e-3 * (lo + hi),
                1e-3 * lo,
                1e-3 * hi
            ),
            Onset::Below { v } => format!("below {:.2} km/s", 1e-3 * v),
            Onset::Above { v } => format!("above {:.2} km/s", 1e-3 * v),
        }
    }
}

/// Bisection in v0 for one t/D: first both ends of the range, then the middle of the bracket
/// until it is narrower than the tolerance. The caller runs [`Bisection::next`] and reports
/// whether the impactor fragmented there with [`Bisection::record`].
///
/// ```
/// use hvi_analysis::onset::{Bisection, Onset};
///
/// // A model whose impactor fragments from 3.3 km/s.
/// let mut b = Bisection::new(1500.0, 8000.0, 100.0).expect("a range");
/// while let Some(v) = b.next() {
///     b.record(v, v >= 3300.0);
/// }
/// let Onset::Between { lo, hi } = b.onset().expect("found") else { panic!() };
/// assert!(lo < 3300.0 && 3300.0 <= hi && hi - lo <= 100.0);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Bisection {
    range: (f64, f64),
    tolerance: f64,
    lo: Option<f64>,
    hi: Option<f64>,
    /// Every (v, fragmented) recorded, in order.
    pub visited: Vec<(f64, bool)>,
}

impl Bisection {
    /// A search over `[v_min, v_max]` m/s to a bracket of `tolerance` m/s.
    pub fn new(v_min: f64, v_max: f64, tolerance: f64) -> Result<Bisection> {
        if !(v_min.is_finite() && v_min > 0.0 && v_max > v_min && v_max.is_finite()) {
            bail!("onset range [{v_min}, {v_max}] m/s (allowed: 0 < v_min < v_max)");
        }
        if !(tolerance.is_finite() && tolerance > 0.0) {
            bail!("onset tolerance {tolerance} m/s (allowed: a number > 0)");
        }
        Ok(Bisection {
            range: (v_min, v_max),
            tolerance,
            lo: None,
            hi: None,
            visited: Vec::new(),
        })
    }

    /// The next velocity to run, or None when the search is done.
    pub fn next(&self) -> Option<f64> {
        let (v_min, v_max) = self.range;
        let seen = |v: f64| self.visited.iter().any(|&(x, _)| x == v);
        if !seen(v_min) {
            return Some(v_min);
        }
        // Fragmented at the bottom of the range: nothing to bisect.
        self.lo?;
        if !seen(v_max) {
            return Some(v_max);
        }
        match (self.lo, self.hi) {
            (Some(lo), Some(hi)) if hi - lo > self.tolerance => Some(0.5 * (lo + hi)),
            _ => None,
        }
    }

    /// Records the outcome at `v`.
    pub fn record(&mut self, v: f64, fragmented: bool) {
        self.visited.push((v, fragmented));
        if fragmented {
            self.hi = Some(self.hi.map_or(v, |h| h.min(v)));
        } else {
            self.lo = Some(self.lo.map_or(v, |l| l.max(v)));
        }
    }

    /// The onset once the search is done (None while it runs).
    pub fn onset(&self) -> Option<Onset> {
        if self.next().is_some() {
            return None;
        }
        Some(match (self.lo, self.hi) {
            (None, _) => Onset::Below { v: self.range.0 },
            (Some(_), None) => Onset::Above { v: self.range.1 },
            (Some(lo), Some(hi)) => Onset::Between { lo, hi },
        })
    }

    /// Whether an intact velocity was found above a fragmented one (the outcome is not
    /// monotone in v0 over the velocities run): the bracket is then the first crossing.
    pub fn monotone(&self) -> bool {
        let highest_intact = self
            .visited
            .iter()
            .filter(|x| !x.1)
            .map(|x| x.0)
            .fold(f64::NEG_INFINITY, f64::max);
        let lowest_fragmented = self
            .visited
            .iter()
            .filter(|x| x.1)
            .map(|x| x.0)
            .fold(f64::INFINITY, f64::min);
        highest_intact < lowest_fragmented
    }
}

/// How the model's onset compares with one relation at one t/D.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Agreement {
    /// Within [`AGREEMENT`] of the experiment's (or the bracket contains it).
    Agrees,
    /// The model fragments later (at a higher v0).
    Later,
    /// The model fragments earlier.
    Earlier,
}

impl Agreement {
    /// Its name in tables.
    pub fn name(self) -> &'static str {
        match self {
            Agreement::Agrees => "agrees",
            Agreement::Later => "later",
            Agreement::Earlier => "earlier",
        }
    }
}

/// The rule: the model agrees with an experiment's onset `v_exp` (m/s) when its bracket
/// overlaps `v_exp` widened by [`AGREEMENT`]; else it fragments later or earlier.
///
/// ```
/// use hvi_analysis::onset::{compare, Agreement, Onset};
///
/// let at = |lo, hi| Onset::Between { lo, hi };
/// assert_eq!(compare(&at(3000.0, 3100.0), 2800.0), Agreement::Agrees);
/// assert_eq!(compare(&at(4000.0, 4100.0), 2800.0), Agreement::Later);
/// assert_eq!(compare(&Onset::Below { v: 1500.0 }, 2800.0), Agreement::Earlier);
/// ```
pub fn compare(model: &Onset, v_exp: f64) -> Agreement {
    let (lo_ok, hi_ok) = ((1.0 - AGREEMENT) * v_exp, (1.0 + AGREEMENT) * v_exp);
    let (lo, hi) = match *model {
        Onset::Between { lo, hi } => (lo, hi),
        Onset::Below { v } => (0.0, v),
        Onset::Above { v } => (v, f64::INFINITY),
    };
    if hi < lo_ok {
        Agreement::Earlier
    } else if lo > hi_ok {
        Agreement::Later
    } else {
        Agreement::Agrees
    }
}

/// The verdict over a range of t/D from its rows' agreements (one per t/D and relation):
/// "agrees" when every one agrees, else how many fragment later and earlier.
pub fn range_verdict(agreements: &[Agreement]) -> String {
    let n = agreements.len();
    let count = |a: Agreement| agreements.iter().filter(|&&x| x == a).count();
    match (count(Agreement::Later), count(Agreement::Earlier)) {
        _ if n == 0 => "no t/D in this range".into(),
        (0, 0) => "agrees".into(),
        (later, earlier) => format!(
            "disagrees: {later} of {n} comparisons later, {earlier} earlier (rule: within {:.0} %)",
            100.0 * AGREEMENT
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The transcriptions against values computed by hand (km/s).
    #[test]
    fn the_relations_give_the_hand_computed_onsets() {
        let r = Relations::shipped().expect("shipped");
        let p = r.get("piekutowski-2003").expect("piekutowski");
        let q = r.get("reimerdes-2006").expect("reimerdes");
        // 1.436 * 0.05^-0.333 = 1.436 * 2.71171 = 3.8940 km/s; 0.1: 1.436 * 2.15278 = 3.0914.
        assert!(
            (p.onset_m_s(0.05) - 3894.0).abs() < 0.5,
            "{}",
            p.onset_m_s(0.05)
        );
        assert!(
            (p.onset_m_s(0.1) - 3091.4).abs() < 0.5,
            "{}",
            p.onset_m_s(0.1)
        );
        // Thick plates: the 2.60 km/s branch.
        assert_eq!(p.onset_m_s(0.3), 2600.0);
        // 1.853 + 0.397 * 0.1^-0.565 = 1.853 + 0.397 * 3.67282 = 3.3111 km/s;
        // 0.3: 1.853 + 0.397 * 1.97436 = 2.6368 km/s.
        assert!(
            (q.onset_m_s(0.1) - 3311.1).abs() < 0.5,
            "{}",
            q.onset_m_s(0.1)
        );
        assert!(
            (q.onset_m_s(0.3) - 2636.8).abs() < 0.5,
            "{}",
            q.onset_m_s(0.3)
        );
        // The branches meet near t/D = 0.168, as the source says.
        let t = r.branch_point().expect("a branch point");
        assert!((t - 0.168).abs() < 0.002, "{t}");
        assert!(q.branch_point().is_none());
    }

    #[test]
    fn a_bad_relation_is_refused_naming_the_key() {
        let bad = SHIPPED.replacen("exponent = -0.333", "exponent = nan", 1);
        let e = format!("{:#}", Relations::parse(&bad, "x").expect_err("nan"));
        assert!(e.contains("exponent"), "{e}");
        let twice = format!(
            "{SHIPPED}\n{}",
            &SHIPPED[SHIPPED.find("[[relations]]").expect("a relation")
                ..SHIPPED.find("[[context]]").expect("a context")]
        );
        let e = format!("{:#}", Relations::parse(&twice, "x").expect_err("twice"));
        assert!(e.contains("twice"), "{e}");
    }

    #[test]
    fn bisection_brackets_ends_and_reports_outside_the_range() {
        let run = |threshold: f64| {
            let mut b = Bisection::new(1500.0, 8000.0, 100.0).expect("range");
            while let Some(v) = b.next() {
                b.record(v, v >= threshold);
            }
            (b.onset().expect("done"), b.visited.len(), b.monotone())
        };
        let (o, n, mono) = run(4321.0);
        match o {
            Onset::Between { lo, hi } => assert!(lo < 4321.0 && 4321.0 <= hi && hi - lo <= 100.0),
            _ => panic!("{o:?}"),
        }
        assert!(mono);
        // Two ends and ceil(log2(6500 / 100)) = 7 halvings.
        assert_eq!(n, 9);
        assert_eq!(run(1000.0).0, Onset::Below { v: 1500.0 });
        assert_eq!(run(1000.0).1, 1);
        assert_eq!(run(9000.0).0, Onset::Above { v: 8000.0 });
        assert!(Bisection::new(8000.0, 1500.0, 100.0).is_err());
    }

    #[test]
    fn verdicts_follow_the_rule() {
        assert_eq!(
            range_verdict(&[Agreement::Agrees, Agreement::Agrees]),
            "agrees"
        );
        let v = range_verdict(&[Agreement::Agrees, Agreement::Later]);
        assert!(v.starts_with("disagrees: 1 of 2 comparisons later"), "{v}");
    }
}
