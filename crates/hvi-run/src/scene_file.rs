//! Scene files: TOML with `[scene]`, `[resolution]`, `[material]`, `[impactor]`, `[run]`,
//! `[analysis]`, plus `--set` overrides `section.key=value`. Parsing and overriding happen
//! here; every value check is the engine's (`SceneSpec::build`), so there is one place that knows the allowed ranges.

use std::path::Path;

use hvi_engine::scene::keys::{find, KEYS};
use hvi_engine::scene::SceneSpec;

use crate::error::{Result, ResultExt, RunError};

/// The sections a scene file may have.
pub use hvi_engine::scene::keys::SECTIONS;

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

/// The key nearest to an unknown `name`: the same field in another section, else the closest
/// spelling (Jaro-Winkler similarity at least 0.8), else none.
pub fn suggest(name: &str) -> Option<&'static str> {
    let field = name.rsplit('.').next().unwrap_or(name);
    if let Some(k) = KEYS
        .iter()
        .find(|k| k.name.rsplit('.').next() == Some(field))
    {
        return Some(k.name);
    }
    KEYS.iter()
        .map(|k| (strsim::jaro_winkler(name, k.name), k.name))
        .filter(|&(s, _)| s >= 0.8)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, k)| k)
}

/// The error for an unknown key, with a did-you-mean and where to find the keys.
fn unknown_key(name: &str) -> String {
    let hint = suggest(name).map_or(String::new(), |k| format!(" (did you mean `{k}`?)"));
    format!("unknown key `{name}`{hint}; `hvi-study keys` lists every key")
}

/// Checks one `--set` and splits it into (section, field, value).
fn split_set(set: &str) -> Result<(&str, &str, &str)> {
    let (key, value) = set.split_once('=').ok_or_else(|| {
        RunError::Input(format!(
            "--set `{set}`: expected KEY=VALUE, e.g. scene.v0_m_s=6500"
        ))
    })?;
    let key = key.trim();
    let (section, field) = key.split_once('.').ok_or_else(|| {
        RunError::Input(format!(
            "--set `{set}`: key `{key}` must be section.name with section one of {SECTIONS:?}"
        ))
    })?;
    if !SECTIONS.contains(&section) {
        return Err(RunError::Input(format!(
            "--set `{set}`: unknown section `{section}` (allowed: {SECTIONS:?})"
        )));
    }
    if find(key).is_none() {
        return Err(RunError::Input(format!(
            "--set `{set}`: {}",
            unknown_key(key)
        )));
    }
    Ok((section, field, value))
}

/// Applies `section.key=value` overrides to a parsed scene document; an unknown key is an
/// error with a did-you-mean.
pub fn apply_overrides(doc: &mut toml::Table, sets: &[String]) -> Result<()> {
    for set in sets {
        let (section, field, value) = split_set(set)?;
        let table = doc
            .entry(section.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut()
            .ok_or_else(|| {
                RunError::Input(format!("`{section}` in the scene file is not a table"))
            })?;
        table.insert(field.to_string(), parse_value(value));
    }
    Ok(())
}

/// Refuses a study file (its `[study]`, `[[axes]]` or `[tiers]`) and unknown sections and keys
/// of a scene document, with a did-you-mean.
fn check_document(doc: &toml::Table) -> Result<()> {
    if ["study", "axes", "tiers"]
        .iter()
        .any(|k| doc.contains_key(*k))
    {
        return Err(RunError::Input(
            "this is a study file (it has [study], [[axes]] or [tiers]), not a scene: run it \
             with `hvi-study sweep FILE` (or `calibrate`, `validity-map`), or give `run` its \
             scene (the study's `scene = ...`)"
                .into(),
        ));
    }
    for (section, value) in doc {
        if !SECTIONS.contains(&section.as_str()) {
            return Err(RunError::Input(format!(
                "unknown section `[{section}]` (allowed: {SECTIONS:?})"
            )));
        }
        let Some(table) = value.as_table() else {
            return Err(RunError::Input(format!(
                "`{section}` must be a table `[{section}]`"
            )));
        };
        for field in table.keys() {
            let key = format!("{section}.{field}");
            if find(&key).is_none() {
                return Err(RunError::Input(unknown_key(&key)));
            }
        }
    }
    Ok(())
}

/// Deserialises a scene document; serde_path_to_error names the key of a type error where the
/// path is known (inside `[scene]` the geometry's tag hides it, so a `--set` is blamed by the
/// caller).
fn deserialise(doc: toml::Table) -> Result<SceneSpec> {
    serde_path_to_error::deserialize(toml::Value::Table(doc)).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let msg = inner.message().trim().to_string();
        if path.is_empty() || path == "." {
            RunError::Input(format!("scene: {msg}"))
        } else {
            RunError::Input(format!("scene key `{path}`: {msg}"))
        }
    })
}

/// Parses scene TOML text with overrides into a spec. Unknown keys are errors naming them with
/// a did-you-mean; a value that does not parse is blamed on the `--set` that gave it, naming
/// its key, or on the file.
pub fn parse_scene(text: &str, sets: &[String]) -> Result<SceneSpec> {
    let doc: toml::Table = toml::from_str(text).map_err(|e| RunError::Parse {
        message: "scene file is not valid TOML".into(),
        source: Some(Box::new(e)),
    })?;
    check_document(&doc)?;
    let mut full = doc.clone();
    apply_overrides(&mut full, sets)?;
    let err = match deserialise(full) {
        Ok(spec) => return Ok(spec),
        Err(e) => e,
    };
    // Which input is at fault: the file alone, or the first --set after which it fails.
    let mut partial = doc;
    if deserialise(partial.clone()).is_ok() {
        for set in sets {
            apply_overrides(&mut partial, std::slice::from_ref(set))?;
            if let Err(e) = deserialise(partial.clone()) {
                let (key, _) = set.split_once('=').unwrap_or((set, ""));
                let key = key.trim();
                let what = find(key).map_or(String::new(), |k| {
                    format!(" (allowed: {})", k.allowed.describe())
                });
                let msg = format!("{e:#}");
                let msg = msg.strip_prefix("scene key `").map_or(msg.as_str(), |m| {
                    m.split_once("`: ").map_or(m, |(_, rest)| rest)
                });
                return Err(RunError::Input(format!(
                    "--set `{set}`: key `{key}`: {msg}{what}"
                )));
            }
        }
    }
    Err(err)
}

/// Reads and parses a scene file with overrides.
pub fn load_scene(path: &Path, sets: &[String]) -> Result<SceneSpec> {
    let text = std::fs::read_to_string(path).read_context(path, || {
        format!("cannot read scene file {}", path.display())
    })?;
    // An error of a --set names the --set; any other is the file's.
    parse_scene(&text, sets).map_err(|e| {
        if e.to_string().starts_with("--set ") {
            e
        } else {
            e.context(format!("in scene file {}", path.display()))
        }
    })
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

    #[test]
    fn unknown_keys_get_a_did_you_mean() {
        let e = parse_scene(SCENE, &["scene.v0_ms=5000".into()]).expect_err("unknown key");
        let e = format!("{e:#}");
        assert!(e.contains("--set `scene.v0_ms=5000`"), "{e}");
        assert!(e.contains("did you mean `scene.v0_m_s`?"), "{e}");
        assert!(e.contains("hvi-study keys"), "{e}");
        // The right field in the wrong section.
        let e = parse_scene(SCENE, &["run.quantile=0.9".into()]).expect_err("wrong section");
        assert!(
            format!("{e:#}").contains("did you mean `analysis.quantile`?"),
            "{e:#}"
        );
        // In the file itself.
        let text = SCENE.replace("kappa_n_m", "kapa_n_m");
        let e = parse_scene(&text, &[]).expect_err("unknown key in the file");
        let e = format!("{e:#}");
        assert!(
            e.starts_with("unknown key `material.kapa_n_m` (did you mean `material.kappa_n_m`?)"),
            "{e}"
        );
    }

    #[test]
    fn a_bad_value_is_blamed_on_its_set_and_names_the_key() {
        let e = parse_scene(SCENE, &["run.seed=3".into(), "scene.v0_m_s=fast".into()])
            .expect_err("not a number");
        let e = format!("{e:#}");
        assert!(
            e.starts_with("--set `scene.v0_m_s=fast`: key `scene.v0_m_s`: invalid type"),
            "{e}"
        );
        assert!(e.contains("(allowed: (0, 1e5])"), "{e}");
        let e = parse_scene(SCENE, &["material.contact=strong".into()]).expect_err("no such law");
        assert!(format!("{e:#}").contains("key `material.contact`"), "{e:#}");
    }

    #[test]
    fn a_study_file_is_refused_with_the_command_to_use() {
        let study = "[study]\nname = \"x\"\nscene = \"s.toml\"\n[[axes]]\nkey = \"run.seed\"\nvalues = [1]\n";
        let e = parse_scene(study, &[]).expect_err("a study");
        assert!(format!("{e:#}").contains("hvi-study sweep FILE"), "{e:#}");
    }

    #[test]
    fn every_key_a_scene_serialises_is_in_the_registry() {
        // The calibration scene and a flyer plate with every optional key given.
        let mut specs = vec![SceneSpec::calibration(2000.0, 1e-6)];
        let flyer = "[scene]\nkind = \"flyer_plate\"\nflyer_thickness_m = 1e-3\ntarget_thickness_m = 1e-3\nwidth_m = 5e-3\nv0_m_s = 1000\n[resolution]\nparticles = 1000\n[material]\ngamma_pa = 1e9\nlambda_pa = 1e10\nsizing_rule = \"eqs5_6\"\n[run]\ndt_over_bound = 0.5\nmax_stride = 4\nstride_displacement_over_sigma = 0.02\n[analysis]\nfront_times_s = [1e-7, 2e-7]\nshadowgraph_pixel_m = 1e-3\n";
        specs.push(parse_scene(flyer, &[]).expect("flyer"));
        let mut seen = 0;
        for spec in &specs {
            let v = serde_json::to_value(spec).expect("json");
            for (section, table) in v.as_object().expect("object") {
                for field in table.as_object().expect("table").keys() {
                    let key = format!("{section}.{field}");
                    assert!(find(&key).is_some(), "`{key}` is not in the key registry");
                    seen += 1;
                }
            }
        }
        assert!(seen > 40, "{seen}");
    }
}
