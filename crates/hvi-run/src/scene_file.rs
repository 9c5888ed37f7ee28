//! Scene files: TOML with `[scene]`, `[resolution]`, `[material]`, `[run]`, `[analysis]`,
//! plus `--set` overrides `section.key=value`. Parsing and overriding happen here; every value check is the
//! engine's (`SceneSpec::build`), so there is one place that knows the allowed ranges.

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use hvi_engine::scene::SceneSpec;

/// The sections a scene file may have.
pub const SECTIONS: [&str; 5] = ["scene", "resolution", "material", "run", "analysis"];

/// Parses one `--set` right-hand side as a TOML value; bare words become strings.
fn parse_value(raw: &str) -> toml::Value {
    let raw = raw.trim();
    match toml::from_str::<toml::Table>(&format!("v = {raw}")) {
        Ok(mut t) => t
            .remove("v")
            .unwrap_or_else(|| toml::Value::String(raw.to_string())),
        Err(_) => toml::Value::String(raw.to_string()),
    }
}

/// Applies `section.key=value` overrides to a parsed scene document.
pub fn apply_overrides(doc: &mut toml::Table, sets: &[String]) -> Result<()> {
    for set in sets {
        let (key, value) = set
            .split_once('=')
            .ok_or_else(|| anyhow!("--set `{set}`: expected KEY=VALUE, e.g. scene.v0_m_s=6500"))?;
        let key = key.trim();
        let (section, field) = key.split_once('.').ok_or_else(|| {
            anyhow!(
                "--set `{set}`: key `{key}` must be section.name with section one of {SECTIONS:?}"
            )
        })?;
        if !SECTIONS.contains(&section) {
            bail!("--set `{set}`: unknown section `{section}` (allowed: {SECTIONS:?})");
        }
        let table = doc
            .entry(section.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut()
            .ok_or_else(|| anyhow!("`{section}` in the scene file is not a table"))?;
        table.insert(field.to_string(), parse_value(value));
    }
    Ok(())
}

/// Parses scene TOML text with overrides into a spec (unknown keys are errors naming them).
pub fn parse_scene(text: &str, sets: &[String]) -> Result<SceneSpec> {
    let mut doc: toml::Table = toml::from_str(text).context("scene file is not valid TOML")?;
    apply_overrides(&mut doc, sets)?;
    // serde_path_to_error names the key of any type error (e.g. `material.contact`).
    let spec: SceneSpec =
        serde_path_to_error::deserialize(toml::Value::Table(doc)).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.into_inner();
            let msg = inner.message().trim().to_string();
            if path.is_empty() || path == "." {
                anyhow!("scene: {msg}")
            } else {
                anyhow!("scene key `{path}`: {msg}")
            }
        })?;
    Ok(spec)
}

/// Reads and parses a scene file with overrides.
pub fn load_scene(path: &Path, sets: &[String]) -> Result<SceneSpec> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read scene file {}", path.display()))?;
    parse_scene(&text, sets).with_context(|| format!("in scene file {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"
[scene]
kind = "sphere_on_plate"
diameter_m = 9.53e-3
t_over_d = 0.425
v0_m_s = 6700
[resolution]
particles = 270000
[material]
eps_j = 0.01
kappa_n_m = 4.56e6
"#;

    #[test]
    fn parses_and_overrides() {
        let spec = parse_scene(SCENE, &["scene.v0_m_s=6500".into(), "run.dt_s=auto".into()])
            .expect("parses");
        assert_eq!(spec.scene.v0_m_s(), 6500.0);
        assert_eq!(spec.resolution.particles, Some(270000.0));
    }

    #[test]
    fn unknown_keys_are_named() {
        let e = parse_scene(SCENE, &["scene.v0=1".into()]).expect_err("unknown key");
        assert!(format!("{e:#}").contains("v0"), "{e:#}");
        let e = parse_scene(SCENE, &["material.epsilon=1".into()]).expect_err("unknown key");
        assert!(format!("{e:#}").contains("epsilon"), "{e:#}");
        let e = parse_scene(SCENE, &["bogus.x=1".into()]).expect_err("unknown section");
        assert!(format!("{e:#}").contains("bogus"), "{e:#}");
    }
}
