//! `studies/reproduce.toml`: what each tier of `hvi-study reproduce` runs for every figure.
//!
//! ```toml
//! [estimate]
//! tier = "paper"                       # the tier whose wall time every report estimates
//! particle_steps_per_second = 2.4e7    # particles x base steps per second on `cores` cores
//! cores = 2
//!
//! [tiers.quick]
//! description = "..."
//! calibration = { study = "calibration.toml", tier = "quick" }    # Figs. 7, 9, 10
//! validity = { study = "validity-map.toml", tier = "quick" }      # Figs. 16, 17
//! sizing = { particles = [500, 5000, 50000] }                      # Fig. 4
//! convergence = { scene = "scenes/calibration.toml", fractions = [0.125, 0.25, 0.5] }
//! front_velocity = { scene = "scenes/validity-map.toml", t_over_d = [0.1, 0.3, 0.5],
//!                    set = ["resolution.particles_across_d=8"] }  # Fig. 13
//! ```
//!
//! Paths are relative to the file. `calibration` and `validity` name existing study files and
//! their tiers (with optional `particles` and `set` overrides, as `--particles` and `--set` of
//! `calibrate` and `validity-map`). Fig. 5's series runs the paper's best fit on the
//! `convergence` scene at the calibration study's particle count times each of `fractions`,
//! times 1, and times the paper's final-over-calibration ratio (7.4e5 / 2.7e5; read from
//! `hvi_engine::paper`); its largest run is the best-fit run of Figs. 11-12. Every number of
//! the paper comes from `hvi_engine::paper`, never from this file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use hvi_run::bail;
use hvi_run::error::{Result, ResultExt, RunError};
use serde::Deserialize;

/// A study file and the tier to run it at.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StudyRef {
    /// The study file, relative to the config file.
    pub study: PathBuf,
    /// Its tier.
    pub tier: String,
    /// Overrides the tier's particle count (as `--particles`).
    #[serde(default)]
    pub particles: Option<f64>,
    /// Extra overrides of every run (as `--set`).
    #[serde(default)]
    pub set: Vec<String>,
}

/// Fig. 4.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SizingConfig {
    /// The particle counts (at least two; the last is the reference).
    pub particles: Vec<f64>,
    /// Overrides of every run.
    #[serde(default)]
    pub set: Vec<String>,
}

/// Fig. 5 and Figs. 11-12.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConvergenceConfig {
    /// The base scene (the calibration scene), relative to the config file.
    pub scene: PathBuf,
    /// Fractions of the calibration's particle count run besides 1 and the final ratio.
    #[serde(default)]
    pub fractions: Vec<f64>,
    /// Overrides of every run.
    #[serde(default)]
    pub set: Vec<String>,
}

/// Fig. 13.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrontVelocityConfig {
    /// The base scene, relative to the config file.
    pub scene: PathBuf,
    /// The plate thicknesses t/D.
    pub t_over_d: Vec<f64>,
    /// Overrides of every run (the resolution, for instance).
    #[serde(default)]
    pub set: Vec<String>,
}

/// One tier of the reproduction.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TierConfig {
    /// What the tier is for and what it costs.
    #[serde(default)]
    pub description: String,
    /// Figs. 7, 9, 10.
    pub calibration: StudyRef,
    /// Figs. 16, 17.
    pub validity: StudyRef,
    /// Fig. 4.
    pub sizing: SizingConfig,
    /// Fig. 5, Figs. 11-12.
    pub convergence: ConvergenceConfig,
    /// Fig. 13.
    pub front_velocity: FrontVelocityConfig,
}

/// `[estimate]`: how a tier's wall time is estimated.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimateConfig {
    /// The tier every report estimates (besides measuring its own).
    pub tier: Option<String>,
    /// Engine throughput on `cores` cores over a whole run: particles x base steps per second
    /// (with the adaptive step a run takes fewer steps than base steps; the estimate counts
    /// each scene's base steps, which the engine knows before running).
    pub particle_steps_per_second: f64,
    /// The cores that throughput holds for.
    pub cores: usize,
    /// Where the throughput comes from.
    #[serde(default)]
    pub source: String,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConfigFile {
    #[serde(default)]
    estimate: Option<EstimateConfig>,
    tiers: BTreeMap<String, TierConfig>,
}

/// The parsed config file.
#[derive(Debug, Clone)]
pub struct Config {
    /// The file.
    pub path: PathBuf,
    /// `[estimate]`.
    pub estimate: Option<EstimateConfig>,
    /// The tiers by name.
    pub tiers: BTreeMap<String, TierConfig>,
}

fn check_counts(what: &str, v: &[f64], min_len: usize) -> Result<()> {
    if v.len() < min_len {
        bail!(
            "reproduce config key `{what}`: {} values (allowed: at least {min_len})",
            v.len()
        );
    }
    for x in v {
        if !(x.is_finite() && *x > 0.0) {
            bail!("reproduce config key `{what}`: {x} (allowed: finite numbers > 0)");
        }
    }
    Ok(())
}

impl Config {
    /// Reads and checks the config file.
    pub fn load(path: &Path) -> Result<Config> {
        let text = std::fs::read_to_string(path).with_context(|| {
            format!(
                "cannot read the reproduce config {} (run from the repository root, or pass --config)",
                path.display()
            )
        })?;
        Config::parse(&text, path)
    }

    /// Parses config text (`path` resolves its relative paths).
    pub fn parse(text: &str, path: &Path) -> Result<Config> {
        let doc: toml::Value = toml::from_str(text)
            .with_context(|| format!("{} is not valid TOML", path.display()))?;
        let file: ConfigFile = serde_path_to_error::deserialize(doc).map_err(|e| {
            let p = e.path().to_string();
            RunError::Input(format!(
                "{}: key `{p}`: {}",
                path.display(),
                e.into_inner().message().trim()
            ))
        })?;
        if file.tiers.is_empty() {
            bail!("{}: no [tiers.NAME]", path.display());
        }
        for (name, t) in &file.tiers {
            check_counts(
                &format!("tiers.{name}.sizing.particles"),
                &t.sizing.particles,
                2,
            )?;
            check_counts(
                &format!("tiers.{name}.convergence.fractions"),
                &t.convergence.fractions,
                0,
            )?;
            check_counts(
                &format!("tiers.{name}.front_velocity.t_over_d"),
                &t.front_velocity.t_over_d,
                2,
            )?;
        }
        if let Some(e) = &file.estimate {
            if !(e.particle_steps_per_second.is_finite() && e.particle_steps_per_second > 0.0) {
                bail!(
                    "{}: key `estimate.particle_steps_per_second`: {} (allowed: a number > 0)",
                    path.display(),
                    e.particle_steps_per_second
                );
            }
            if let Some(t) = &e.tier {
                if !file.tiers.contains_key(t) {
                    bail!(
                        "{}: key `estimate.tier`: `{t}` is not a tier (tiers: {:?})",
                        path.display(),
                        file.tiers.keys().collect::<Vec<_>>()
                    );
                }
            }
        }
        Ok(Config {
            path: path.to_path_buf(),
            estimate: file.estimate,
            tiers: file.tiers,
        })
    }

    /// The tier of that name, or an error listing the tiers.
    pub fn tier(&self, name: &str) -> Result<&TierConfig> {
        self.tiers.get(name).ok_or_else(|| {
            RunError::Input(format!(
                "invalid value for `--tier`: `{name}` (tiers in {}: {})",
                self.path.display(),
                self.tiers.keys().cloned().collect::<Vec<_>>().join(", ")
            ))
        })
    }

    /// A path of the config resolved against its directory.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        self.path.parent().unwrap_or_else(|| Path::new(".")).join(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TIER: &str = r#"
[tiers.quick]
calibration = { study = "calibration.toml", tier = "quick" }
validity = { study = "validity-map.toml", tier = "quick" }
sizing = { particles = [500, 5000] }
convergence = { scene = "scenes/calibration.toml", fractions = [0.5] }
front_velocity = { scene = "scenes/validity-map.toml", t_over_d = [0.1, 0.2] }
"#;

    #[test]
    fn parses_and_names_bad_keys() {
        let p = Path::new("studies/reproduce.toml");
        let c = Config::parse(TIER, p).expect("parses");
        assert_eq!(c.tier("quick").expect("tier").sizing.particles.len(), 2);
        let e = c.tier("nightly").expect_err("unknown tier");
        assert!(format!("{e}").contains("quick"), "{e}");
        assert_eq!(
            c.resolve(Path::new("calibration.toml")),
            Path::new("studies/calibration.toml")
        );
        for (bad, needle) in [
            (TIER.replace("[500, 5000]", "[500]"), "sizing.particles"),
            (TIER.replace("fractions = [0.5]", "fractions = [-1]"), "fractions"),
            (TIER.replace("tier = \"quick\" }\nvalidity", "tier = \"quick\", bogus = 1 }\nvalidity"), "bogus"),
            (format!("{TIER}\n[estimate]\ntier = \"paper\"\nparticle_steps_per_second = 1e7\ncores = 2\n"), "estimate.tier"),
        ] {
            let e = Config::parse(&bad, p).expect_err(needle);
            assert!(format!("{e:#}").contains(needle), "{needle}: {e:#}");
        }
    }
}
