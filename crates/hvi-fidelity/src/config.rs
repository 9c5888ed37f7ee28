//! The readings study's config (`studies/fidelity.toml`): the calibration study it runs, the
//! tier and seeds, and the readings. A reading either runs the grid with scene overrides (a
//! reading of the model: the contact prefactor, the sizing rule, the thermal amplitude) or
//! measures another reading's runs again (a reading of the observables: the quantile, the
//! shadowgraph), from their stored state when an analysis setting changes.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use hvi_analysis::observable::Observable;
use hvi_run::bail;
use hvi_run::error::{Result, ResultExt};
use serde::Deserialize;

use hvi_studies::reanalyse::AnalysisChanges;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    fidelity: Header,
    #[serde(default)]
    readings: Vec<ReadingFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    study: PathBuf,
    tier: String,
    seeds: Vec<u64>,
    #[serde(default)]
    set: Vec<String>,
    #[serde(default)]
    description: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ReadingFile {
    name: String,
    label: String,
    #[serde(default)]
    set: Vec<String>,
    from: Option<String>,
    #[serde(default)]
    analysis: Vec<String>,
    length_ratio: Option<String>,
    front_velocity: Option<String>,
    #[serde(default)]
    default: bool,
    seeds: Option<Vec<u64>>,
}

/// Where a reading's numbers come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// Its own runs of the grid, with these scene overrides (`section.key=value`).
    Runs {
        /// The overrides.
        set: Vec<String>,
    },
    /// The runs of an earlier reading, measured again.
    Measured {
        /// That reading's index in [`FidelityConfig::readings`].
        from: usize,
        /// The analysis settings changed (`analysis.KEY=VALUE`), as written.
        analysis: Vec<String>,
        /// The same, parsed.
        changes: AnalysisChanges,
    },
}

/// One reading of the paper.
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    /// Its name: its runs' directory and its files' prefix.
    pub name: String,
    /// What it is, in one line.
    pub label: String,
    /// Where its numbers come from.
    pub source: Source,
    /// The observable it reads as R (default `length_ratio`).
    pub length_ratio: Observable,
    /// The observable it reads as va/v0 (default `front_velocity_ratio`).
    pub front_velocity: Observable,
    /// Whether it is the project's default reading (no overrides, default observables).
    pub default: bool,
    /// Its own seeds instead of `fidelity.seeds` (a reading with runs of its own only).
    pub seeds: Option<Vec<u64>>,
}

impl Reading {
    /// The source in one line: `material.contact=wca`, `the runs of printed, analysis.quantile=0.9`.
    pub fn source_text(&self, readings: &[Reading]) -> String {
        let observables = format!(
            "R = `{}`, va/v0 = `{}`",
            self.length_ratio.name(),
            self.front_velocity.name()
        );
        match &self.source {
            Source::Runs { set } if set.is_empty() => {
                format!("its own runs, the defaults; {observables}")
            }
            Source::Runs { set } => format!("its own runs with `{}`; {observables}", set.join(" ")),
            Source::Measured { from, analysis, .. } => {
                let again = if analysis.is_empty() {
                    String::new()
                } else {
                    format!(" measured again with `{}`", analysis.join(" "))
                };
                format!(
                    "the runs of `{}`{again}; {observables}",
                    readings[*from].name
                )
            }
        }
    }
}

/// A validated readings config.
#[derive(Debug, Clone)]
pub struct FidelityConfig {
    /// The config file.
    pub path: PathBuf,
    /// The study file (resolved against the config's directory).
    pub study: PathBuf,
    /// The study's tier.
    pub tier: String,
    /// The thermal seeds every run reading is run at.
    pub seeds: Vec<u64>,
    /// Scene overrides of every run of every reading, before the reading's own `set`.
    pub set: Vec<String>,
    /// What the config is for.
    pub description: String,
    /// The readings, in the report's order.
    pub readings: Vec<Reading>,
}

fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name.starts_with(|c: char| c.is_ascii_lowercase() || c.is_ascii_digit())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || matches!(c, '-' | '_' | '.'))
}

impl FidelityConfig {
    /// Reads and validates a config file; errors name the file and the field.
    pub fn load(path: &Path) -> Result<FidelityConfig> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the readings config {}", path.display()))?;
        FidelityConfig::parse(&text, path)
            .with_context(|| format!("in the readings config {}", path.display()))
    }

    /// Parses and validates a config's text (`path` resolves the study file).
    pub fn parse(text: &str, path: &Path) -> Result<FidelityConfig> {
        let file: File = toml::from_str(text)?;
        let h = file.fidelity;
        if h.tier.trim().is_empty() {
            bail!("fidelity.tier: empty (allowed: a tier of the study)");
        }
        check_seeds(&h.seeds, "fidelity.seeds")?;
        let dir = path.parent().unwrap_or_else(|| Path::new("."));
        let mut readings: Vec<Reading> = Vec::new();
        for (i, r) in file.readings.into_iter().enumerate() {
            let reading = reading(i, r, &readings)?;
            readings.push(reading);
        }
        if readings.is_empty() {
            bail!("no [[readings]]: give at least one");
        }
        match readings.iter().filter(|r| r.default).count() {
            1 => {}
            n => bail!(
                "readings: {n} are marked `default = true` (allowed: exactly one, the reading \
                 the project's defaults give)"
            ),
        }
        Ok(FidelityConfig {
            path: path.to_path_buf(),
            study: dir.join(h.study),
            tier: h.tier,
            seeds: h.seeds,
            set: h.set,
            description: h.description,
            readings,
        })
    }
}

/// Checks a seed list: at least one, no repeats.
pub fn check_seeds(seeds: &[u64], what: &str) -> Result<()> {
    if seeds.is_empty() {
        bail!("{what}: empty (allowed: one or more distinct thermal seeds, e.g. [1, 2])");
    }
    let distinct: BTreeSet<u64> = seeds.iter().copied().collect();
    if distinct.len() != seeds.len() {
        bail!("{what}: {seeds:?} repeats a seed (allowed: distinct seeds)");
    }
    Ok(())
}

fn observable(field: &str, name: Option<&str>, default: Observable) -> Result<Observable> {
    match name {
        None => Ok(default),
        Some(n) => Observable::parse_named(field, n).map_err(hvi_run::error::RunError::Input),
    }
}

/// Where a reading's runs come from: its own (with its `set`), or another reading's measured
/// again (`from`, with its `analysis`), checked against the readings before it.
fn source_of(at: &str, r: &ReadingFile, before: &[Reading]) -> Result<Source> {
    let source = match &r.from {
        None => {
            if !r.analysis.is_empty() {
                bail!(
                    "{at}.analysis: a reading with its own runs takes its analysis from `set`; \
                     `analysis` re-measures another reading's runs (give `from`)"
                );
            }
            for s in &r.set {
                if !s.contains('=') {
                    bail!("{at}.set: `{s}` (allowed: section.key=value)");
                }
            }
            Source::Runs { set: r.set.clone() }
        }
        Some(from) => {
            if !r.set.is_empty() {
                bail!(
                    "{at}.set: a reading measured from `{from}`'s runs has no runs of its own \
                     (remove `set`, or `from` to give it its own runs)"
                );
            }
            let Some(k) = before.iter().position(|b| &b.name == from) else {
                bail!(
                    "{at}.from: `{from}` is not an earlier reading (allowed: a reading above it)"
                );
            };
            if !matches!(before[k].source, Source::Runs { .. }) {
                bail!("{at}.from: `{from}` has no runs of its own (allowed: a reading without `from`)");
            }
            let changes =
                AnalysisChanges::parse(&r.analysis).with_context(|| format!("{at}.analysis"))?;
            Source::Measured {
                from: k,
                analysis: r.analysis.clone(),
                changes,
            }
        }
    };
    Ok(source)
}

/// One `[[readings]]` table validated against the readings before it.
fn reading(i: usize, r: ReadingFile, before: &[Reading]) -> Result<Reading> {
    let at = format!("readings[{i}] (`{}`)", r.name);
    if !valid_name(&r.name) {
        bail!(
            "readings[{i}].name: `{}` (allowed: lower-case letters, digits, '-', '_', '.', \
             starting with a letter or digit, at most 64 characters)",
            r.name
        );
    }
    if before.iter().any(|b| b.name == r.name) {
        bail!("{at}.name: used twice (allowed: a name no other reading has)");
    }
    if r.label.trim().is_empty() {
        bail!("{at}.label: empty (allowed: one line saying what the reading is)");
    }
    let source = source_of(&at, &r, before)?;
    if let Some(seeds) = &r.seeds {
        if r.from.is_some() {
            bail!("{at}.seeds: a reading measured from another's runs has that reading's seeds");
        }
        check_seeds(seeds, &format!("{at}.seeds"))?;
    }
    let length_ratio = observable(
        &format!("{at}.length_ratio"),
        r.length_ratio.as_deref(),
        Observable::LengthRatio,
    )?;
    let front_velocity = observable(
        &format!("{at}.front_velocity"),
        r.front_velocity.as_deref(),
        Observable::FrontVelocityRatio,
    )?;
    let reading = Reading {
        name: r.name,
        label: r.label,
        source,
        length_ratio,
        front_velocity,
        default: r.default,
        seeds: r.seeds,
    };
    let plain = reading.source == Source::Runs { set: Vec::new() }
        && reading.length_ratio == Observable::LengthRatio
        && reading.front_velocity == Observable::FrontVelocityRatio;
    if reading.default && !plain {
        bail!(
            "{at}.default: the default reading has its own runs without `set` and the default \
             observables (length_ratio, front_velocity_ratio)"
        );
    }
    Ok(reading)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(readings: &str) -> Result<FidelityConfig> {
        let text = format!(
            "[fidelity]\nstudy = \"calibration.toml\"\ntier = \"quick\"\nseeds = [1, 2]\n{readings}"
        );
        FidelityConfig::parse(&text, Path::new("studies/fidelity.toml"))
    }

    const BASE: &str =
        "[[readings]]\nname = \"printed\"\nlabel = \"the defaults\"\ndefault = true\n";

    #[test]
    fn a_config_with_run_and_measured_readings_parses() {
        let c = parse(&format!(
            "{BASE}[[readings]]\nname = \"wca\"\nlabel = \"WCA\"\nset = [\"material.contact=wca\"]\n\
             [[readings]]\nname = \"q0.9\"\nlabel = \"quantile 0.9\"\nfrom = \"printed\"\n\
             analysis = [\"analysis.quantile=0.9\"]\n\
             [[readings]]\nname = \"silhouette\"\nlabel = \"shadowgraph\"\nfrom = \"wca\"\n\
             length_ratio = \"length_ratio_silhouette\"\n\
             front_velocity = \"front_velocity_ratio_silhouette\"\n"
        ))
        .expect("valid");
        assert_eq!(c.study, Path::new("studies/calibration.toml"));
        assert_eq!(c.readings.len(), 4);
        assert!(
            matches!(&c.readings[2].source, Source::Measured { from: 0, changes, .. }
            if changes.quantile == Some(0.9))
        );
        assert_eq!(
            c.readings[3].length_ratio,
            Observable::LengthRatioSilhouette
        );
        assert!(c.readings[3]
            .source_text(&c.readings)
            .contains("the runs of `wca`"));
    }

    #[test]
    fn bad_configs_name_the_field() {
        let cases = [
            ("", "no [[readings]]"),
            ("[[readings]]\nname = \"a\"\nlabel = \"x\"\n", "exactly one"),
            (&format!("{BASE}{BASE}"), "used twice"),
            (
                &format!("{BASE}[[readings]]\nname = \"Q\"\nlabel = \"x\"\n"),
                "readings[1].name",
            ),
            (
                &format!("{BASE}[[readings]]\nname = \"q\"\nlabel = \"x\"\nfrom = \"nope\"\n"),
                "not an earlier reading",
            ),
            (
                &format!(
                    "{BASE}[[readings]]\nname = \"q\"\nlabel = \"x\"\nfrom = \"printed\"\n\
                     analysis = [\"analysis.quantile=2\"]\n"
                ),
                "analysis.quantile",
            ),
            (
                &format!(
                    "{BASE}[[readings]]\nname = \"q\"\nlabel = \"x\"\nanalysis = [\"analysis.quantile=0.9\"]\n"
                ),
                "give `from`",
            ),
            (
                &format!(
                    "{BASE}[[readings]]\nname = \"q\"\nlabel = \"x\"\nfrom = \"printed\"\n\
                     length_ratio = \"lenght_ratio\"\n"
                ),
                "length_ratio",
            ),
            (
                "[[readings]]\nname = \"a\"\nlabel = \"x\"\ndefault = true\nset = [\"run.seed=3\"]\n",
                "readings[0] (`a`).default",
            ),
            (
                &format!(
                    "{BASE}[[readings]]\nname = \"q\"\nlabel = \"x\"\nfrom = \"printed\"\nseeds = [3]\n"
                ),
                "readings[1] (`q`).seeds: a reading measured",
            ),
            (
                &format!("{BASE}[[readings]]\nname = \"q\"\nlabel = \"x\"\nseeds = []\n"),
                "readings[1] (`q`).seeds: empty",
            ),
        ];
        for (readings, want) in cases {
            let e = format!("{:#}", parse(readings).expect_err(want));
            assert!(e.contains(want), "{want}: {e}");
        }
        let e = format!(
            "{:#}",
            FidelityConfig::parse(
                "[fidelity]\nstudy = \"s.toml\"\ntier = \"quick\"\nseeds = [1, 1]\n",
                Path::new("f.toml")
            )
            .expect_err("repeated seeds")
        );
        assert!(e.contains("fidelity.seeds"), "{e}");
    }
}
