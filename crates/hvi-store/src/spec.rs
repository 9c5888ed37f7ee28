//! Study files: a base scene, axes of scene keys, named resolution tiers.
//!
//! ```toml
//! [study]
//! name = "calibration"
//! description = "Fig. 7 grid over (eps, kappa)"
//! scene = "scenes/calibration.toml"      # relative to the study file
//! set = ["analysis.quantile=0.995"]       # optional: every run
//! default_tier = "quick"                 # optional, default "quick"
//!
//! [[axes]]
//! key = "material.eps_j"                 # any key `hvi-study run --set` accepts
//! values = [0.01, 0.1, 1.0]
//!
//! [[axes]]
//! key = "scene.v0_m_s"
//! range = { from = 3000, to = 10000, count = 8 }   # or scale = "log"
//!
//! [tiers.quick]
//! description = "2000 particles: a 2-core machine in a few minutes"
//! set = ["resolution.particles=2000"]
//! ```
//!
//! Parsing here checks the study's own shape (unknown keys, empty axes, duplicate keys,
//! a key that is both an axis and a fixed override, ranges); every scene value is checked by
//! the engine when the plan builds each run's scene (`super::plan`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use hvi_analysis::number::round_sig;

use hvi_run::error::{Result, ResultExt, RunError};
use hvi_run::scene_file::SECTIONS;

/// The tier a study runs at when none is named.
pub const DEFAULT_TIER: &str = "quick";

/// `[study]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct StudyHeader {
    name: String,
    #[serde(default)]
    description: String,
    scene: PathBuf,
    #[serde(default)]
    set: Vec<String>,
    #[serde(default)]
    default_tier: Option<String>,
}

/// `range = { from, to, count, scale }`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RangeFile {
    from: f64,
    to: f64,
    count: usize,
    #[serde(default)]
    scale: Scale,
}

/// Spacing of a range axis.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scale {
    /// Evenly spaced values.
    #[default]
    Linear,
    /// Evenly spaced logarithms (all values > 0).
    Log,
}

/// `[[axes]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct AxisFile {
    key: String,
    #[serde(default)]
    values: Option<Vec<toml::Value>>,
    #[serde(default)]
    range: Option<RangeFile>,
    #[serde(default)]
    label: Option<String>,
}

/// `[tiers.NAME]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct TierFile {
    #[serde(default)]
    description: String,
    #[serde(default)]
    set: Vec<String>,
}

/// The whole study file. The `calibrate` and `validity` sections belong to the commands of the
/// same names and are parsed by them (kept here as raw TOML so that this module stays the
/// one place that knows the study's shape).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct StudyFile {
    study: StudyHeader,
    #[serde(default)]
    axes: Vec<AxisFile>,
    #[serde(default)]
    tiers: BTreeMap<String, TierFile>,
    #[serde(default)]
    calibrate: Option<toml::Value>,
    #[serde(default)]
    validity: Option<toml::Value>,
}

/// One axis of a study: a scene key and the values it takes, in order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Axis {
    /// The scene key, `section.key` (e.g. `material.eps_j`).
    pub key: String,
    /// Its values, in the order of the grid.
    pub values: Vec<serde_json::Value>,
    /// A label for tables and plots (default: the key).
    pub label: String,
}

/// A named resolution: the overrides that set particle count (and, if it must, end time).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tier {
    /// The tier's name (`quick`, `paper`, ...).
    pub name: String,
    /// What it is for and what it costs.
    pub description: String,
    /// Its `section.key=value` overrides.
    pub set: Vec<String>,
}

/// A validated study file.
#[derive(Debug, Clone)]
pub struct Study {
    /// The study's name (names its output directory).
    pub name: String,
    /// What it is.
    pub description: String,
    /// The study file.
    pub path: PathBuf,
    /// The base scene file (resolved against the study file's directory).
    pub scene_path: PathBuf,
    /// The base scene file's text.
    pub scene_text: String,
    /// Overrides every run gets, before the tier's.
    pub set: Vec<String>,
    /// The axes, outermost first (the last axis varies fastest in the run index).
    pub axes: Vec<Axis>,
    /// The tiers by name.
    pub tiers: BTreeMap<String, Tier>,
    /// The tier used when none is named.
    pub default_tier: String,
    /// `[calibrate]`, for `hvi-study calibrate`.
    pub calibrate: Option<toml::Value>,
    /// `[validity]`, for `hvi-study validity-map`.
    pub validity: Option<toml::Value>,
}

/// The key part of a `section.key=value` override.
pub fn override_key(set: &str) -> &str {
    set.split_once('=').map_or(set, |(k, _)| k).trim()
}

/// Checks that `key` is `section.name` with a known section.
fn check_key(key: &str, what: &str) -> Result<()> {
    let Some((section, field)) = key.split_once('.') else {
        return Err(RunError::Input(format!(
            "{what}: key `{key}` must be section.name with section one of {SECTIONS:?}"
        )));
    };
    if !SECTIONS.contains(&section) || field.is_empty() || field.contains('.') {
        return Err(RunError::Input(format!(
            "{what}: key `{key}` must be section.name with section one of {SECTIONS:?}"
        )));
    }
    Ok(())
}

/// A TOML value as JSON (axes are stored as JSON in plans and tables).
pub fn toml_to_json(v: &toml::Value) -> Result<serde_json::Value> {
    serde_json::to_value(v).context("value cannot be represented in JSON")
}

/// A JSON axis value as the right-hand side of a `--set` override (TOML syntax).
pub fn json_to_override(v: &serde_json::Value) -> Result<String> {
    let t: toml::Value = serde_json::from_value(v.clone())
        .map_err(|e| RunError::Input(format!("axis value {v} cannot be written as TOML: {e}")))?;
    Ok(t.to_string())
}

fn expand_range(key: &str, r: &RangeFile) -> Result<Vec<serde_json::Value>> {
    let what = format!("axis `{key}`: range");
    if !(r.from.is_finite() && r.to.is_finite()) {
        return Err(RunError::Input(format!(
            "{what}: from and to must be finite numbers"
        )));
    }
    if r.count == 0 {
        return Err(RunError::Input(format!(
            "{what}: count = 0 (allowed: an integer >= 1)"
        )));
    }
    if r.count == 1 && r.from != r.to {
        return Err(RunError::Input(format!(
            "{what}: count = 1 needs from = to"
        )));
    }
    if r.scale == Scale::Log && (r.from <= 0.0 || r.to <= 0.0) {
        return Err(RunError::Input(format!(
            "{what}: scale = \"log\" needs from > 0 and to > 0 (got {} and {})",
            r.from, r.to
        )));
    }
    let n = r.count;
    let values = (0..n)
        .map(|i| {
            let s = if n == 1 {
                0.0
            } else {
                i as f64 / (n - 1) as f64
            };
            let x = match r.scale {
                Scale::Linear => r.from + s * (r.to - r.from),
                Scale::Log => (r.from.ln() + s * (r.to.ln() - r.from.ln())).exp(),
            };
            // Exact end points, and no 3000.0000000000005 in file names and tables.
            let x = if i == 0 {
                r.from
            } else if i == n - 1 {
                r.to
            } else {
                round_sig(x, 12)
            };
            serde_json::json!(x)
        })
        .collect();
    Ok(values)
}

/// The study file's TOML in its shape; a shape error names the key.
fn study_file(text: &str) -> Result<StudyFile> {
    let doc: toml::Value = toml::from_str(text).map_err(|e| RunError::Parse {
        message: "study file is not valid TOML".into(),
        source: Some(Box::new(e)),
    })?;
    serde_path_to_error::deserialize(doc).map_err(|e| {
        let p = e.path().to_string();
        let msg = e.into_inner().message().trim().to_string();
        if p.is_empty() || p == "." {
            RunError::Input(format!("study: {msg}"))
        } else {
            RunError::Input(format!("study key `{p}`: {msg}"))
        }
    })
}

/// Checks that a study's name can name its directory.
fn check_name(name: &str) -> Result<()> {
    if name.trim().is_empty()
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return Err(RunError::Input(format!(
            "study key `study.name`: {name:?} (allowed: letters, digits, '-' and '_'; it names a directory)"
        )));
    }
    Ok(())
}

/// The axes, in order: each key valid and in one axis only, each with distinct finite values.
fn parse_axes(files: &[AxisFile]) -> Result<Vec<Axis>> {
    let mut axes: Vec<Axis> = Vec::new();
    for (i, a) in files.iter().enumerate() {
        let key = a.key.trim().to_string();
        check_key(&key, &format!("study key `axes[{i}].key`"))?;
        if axes.iter().any(|b| b.key == key) {
            return Err(RunError::Input(format!(
                "axis `{key}` appears twice (allowed: each key in one axis)"
            )));
        }
        let values = axis_values(&key, a)?;
        axes.push(Axis {
            label: a.label.clone().unwrap_or_else(|| key.clone()),
            key,
            values,
        });
    }
    Ok(axes)
}

/// An axis's values, listed or expanded from its range; distinct, and finite where numbers.
fn axis_values(key: &str, a: &AxisFile) -> Result<Vec<serde_json::Value>> {
    let values = match (&a.values, &a.range) {
        (Some(v), None) => {
            if v.is_empty() {
                return Err(RunError::Input(format!(
                    "axis `{key}`: values = [] (allowed: at least one value)"
                )));
            }
            v.iter()
                .map(toml_to_json)
                .collect::<Result<Vec<_>>>()
                .with_context(|| format!("axis `{key}`"))?
        }
        (None, Some(r)) => expand_range(key, r)?,
        (Some(_), Some(_)) => {
            return Err(RunError::Input(format!(
                "axis `{key}`: give either values or range, not both"
            )))
        }
        (None, None) => {
            return Err(RunError::Input(format!(
                "axis `{key}`: give values = [...] or range = {{...}}"
            )))
        }
    };
    for (j, v) in values.iter().enumerate() {
        if values[..j].contains(v) {
            return Err(RunError::Input(format!(
                "axis `{key}`: value {v} appears twice"
            )));
        }
        if let Some(x) = v.as_f64() {
            if !x.is_finite() {
                return Err(RunError::Input(format!(
                    "axis `{key}`: value {v} is not finite"
                )));
            }
        }
    }
    Ok(values)
}

/// The tiers by name, each override key valid and not an axis; at least one tier.
fn parse_tiers(
    files: &BTreeMap<String, TierFile>,
    axes: &[Axis],
) -> Result<BTreeMap<String, Tier>> {
    let mut tiers = BTreeMap::new();
    for (name, t) in files {
        for s in &t.set {
            let k = override_key(s);
            check_key(k, &format!("study key `tiers.{name}.set`"))?;
            if axes.iter().any(|a| a.key == k) {
                return Err(RunError::Input(format!(
                    "key `{k}` is both an axis and in `tiers.{name}.set` (allowed: one of the two)"
                )));
            }
        }
        tiers.insert(
            name.clone(),
            Tier {
                name: name.clone(),
                description: t.description.clone(),
                set: t.set.clone(),
            },
        );
    }
    if tiers.is_empty() {
        return Err(RunError::Input(format!(
            "study has no `[tiers]`: add at least `[tiers.{DEFAULT_TIER}]` with its resolution"
        )));
    }
    Ok(tiers)
}

impl Study {
    /// Parses study text; `path` is where it came from (relative paths resolve against its
    /// directory).
    pub fn parse(text: &str, path: &Path) -> Result<Study> {
        let file = study_file(text)?;
        let h = file.study;
        check_name(&h.name)?;
        for s in &h.set {
            check_key(override_key(s), "study key `study.set`")?;
        }
        let base_dir = path.parent().unwrap_or_else(|| Path::new("."));
        let scene_path = base_dir.join(&h.scene);
        let scene_text = std::fs::read_to_string(&scene_path).read_context(&scene_path, || {
            format!(
                "study key `study.scene`: cannot read scene file {}",
                scene_path.display()
            )
        })?;
        let axes = parse_axes(&file.axes)?;
        for s in &h.set {
            let k = override_key(s);
            if axes.iter().any(|a| a.key == k) {
                return Err(RunError::Input(format!(
                    "key `{k}` is both an axis and in `study.set` (allowed: one of the two)"
                )));
            }
        }
        let tiers = parse_tiers(&file.tiers, &axes)?;
        let default_tier = h.default_tier.unwrap_or_else(|| DEFAULT_TIER.to_string());
        if !tiers.contains_key(&default_tier) {
            return Err(RunError::Input(format!(
                "study key `study.default_tier`: `{default_tier}` is not a tier (tiers: {:?})",
                tiers.keys().collect::<Vec<_>>()
            )));
        }
        Ok(Study {
            name: h.name,
            description: h.description,
            path: path.to_path_buf(),
            scene_path,
            scene_text,
            set: h.set,
            axes,
            tiers,
            default_tier,
            calibrate: file.calibrate,
            validity: file.validity,
        })
    }

    /// Reads and parses a study file.
    pub fn load(path: &Path) -> Result<Study> {
        let text = std::fs::read_to_string(path).read_context(path, || {
            format!("cannot read study file {}", path.display())
        })?;
        Study::parse(&text, path).with_context(|| format!("in study file {}", path.display()))
    }

    /// The tier of that name, or the default one.
    pub fn tier(&self, name: Option<&str>) -> Result<&Tier> {
        let name = name.unwrap_or(&self.default_tier);
        self.tiers.get(name).ok_or_else(|| {
            RunError::Input(format!(
                "invalid value for `--tier`: `{name}` (this study's tiers: {:?})",
                self.tiers.keys().collect::<Vec<_>>()
            ))
        })
    }

    /// The number of runs of the grid (the product of the axes' lengths; 1 with no axes).
    pub fn grid_len(&self) -> usize {
        self.axes.iter().map(|a| a.values.len()).product()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(extra: &str) -> Result<Study> {
        let dir = std::env::temp_dir().join(format!("hvi-spec-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        std::fs::write(
            dir.join("scene.toml"),
            "[scene]\nkind = \"sphere_on_plate\"\ndiameter_m = 1e-2\nt_over_d = 0.4\nv0_m_s = 6000\n[resolution]\nparticles = 500\n[material]\n",
        )
        .expect("scene");
        let text = format!(
            "[study]\nname = \"t\"\nscene = \"scene.toml\"\n[tiers.quick]\nset = [\"resolution.particles=400\"]\n{extra}"
        );
        Study::parse(&text, &dir.join("study.toml"))
    }

    #[test]
    fn ranges_expand_with_exact_end_points() {
        let s = parse("[[axes]]\nkey = \"scene.v0_m_s\"\nrange = { from = 3000, to = 10000, count = 8 }\n[[axes]]\nkey = \"material.eps_j\"\nrange = { from = 0.01, to = 1, count = 3, scale = \"log\" }\n").expect("parses");
        assert_eq!(s.axes[0].values.len(), 8);
        assert_eq!(s.axes[0].values[0], serde_json::json!(3000.0));
        assert_eq!(s.axes[0].values[1], serde_json::json!(4000.0));
        assert_eq!(s.axes[0].values[7], serde_json::json!(10000.0));
        assert_eq!(s.axes[1].values[1], serde_json::json!(0.1));
        assert_eq!(s.grid_len(), 24);
    }

    #[test]
    fn shape_errors_name_the_key() {
        for (extra, needle) in [
            ("[[axes]]\nkey = \"material.eps_j\"\nvalues = []\n", "material.eps_j"),
            ("[[axes]]\nkey = \"bogus.x\"\nvalues = [1]\n", "bogus.x"),
            ("[[axes]]\nkey = \"eps\"\nvalues = [1]\n", "eps"),
            (
                "[[axes]]\nkey = \"material.eps_j\"\nvalues = [1, 1]\n",
                "appears twice",
            ),
            (
                "[[axes]]\nkey = \"material.eps_j\"\nrange = { from = 0, to = 1, count = 3, scale = \"log\" }\n",
                "log",
            ),
            (
                "[[axes]]\nkey = \"resolution.particles\"\nvalues = [1000]\n",
                "tiers.quick.set",
            ),
            ("[[axes]]\nkey = \"material.eps_j\"\nvalue = [1]\n", "value"),
        ] {
            let e = parse(extra).expect_err(extra);
            assert!(format!("{e:#}").contains(needle), "{extra}: {e:#}");
        }
    }

    #[test]
    fn override_values_round_trip() {
        for v in [
            serde_json::json!(1.14e6),
            serde_json::json!(0.01),
            serde_json::json!("wca"),
            serde_json::json!(3),
        ] {
            let s = json_to_override(&v).expect("toml");
            let back: toml::Table = toml::from_str(&format!("v = {s}")).expect("parses");
            assert_eq!(toml_to_json(&back["v"]).expect("json"), v);
        }
    }
}
