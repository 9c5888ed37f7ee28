//! Fig. 4, the sizing test: a flyer plate striking a target plate, at particle counts over
//! decades, with and without geometric sizing (eqs. 5-20). With sizing the kinetic and
//! potential energy curves coincide; without it they do not.
//!
//! One scene, used by the sizing test (`tests/sizing.rs`) and by `hvi-study reproduce`;
//! [`hvi_analysis::decide::curve_deviation`] is their common measure of "coincide".

use std::path::Path;

use hvi_engine::paper;
use hvi_engine::scene::{Analysis, Geometry, Material, Resolution, RunSettings, SceneSpec};
use hvi_run::error::{Result, ResultExt, RunError};

use hvi_analysis::decide::EnergySample;

/// The collision and the first rebound: the time the energy curves are compared over, s.
pub const END_TIME_S: f64 = 0.8e-6;

/// Steps between energy samples.
pub const SAMPLE_EVERY: u64 = 10;

/// "Coincide": with sizing, every count's energy curves stay this close to the finest count's,
/// as a fraction of the finest count's initial kinetic energy.
pub const SIZED_MAX_DEVIATION: f64 = 0.10;

/// "Diverge": without sizing, some count's energy curves differ from the finest count's by more
/// than this, in the same unit.
pub const UNSIZED_MIN_DEVIATION: f64 = 0.30;

/// The colliding plates at `particles` particles, with or without sizing: a 1 mm flyer at
/// 300 m/s on a 2 mm target, both 4 mm square, the paper's best-fit material, 10 times the
/// automatic step (the collision is slow), run to [`END_TIME_S`]. No cloud analysis, no
/// pictures.
pub fn plates_scene(particles: f64, sizing: bool) -> SceneSpec {
    SceneSpec {
        scene: Geometry::FlyerPlate {
            flyer_thickness_m: 1e-3,
            target_thickness_m: 2e-3,
            width_m: 4e-3,
            v0_m_s: 300.0,
            density_kg_m3: paper::ALUMINIUM_DENSITY_KG_M3,
            standoff_m: 0.0,
        },
        resolution: Resolution {
            particles: Some(particles),
            particles_across_d: None,
        },
        impactor: Default::default(),
        material: Material {
            sizing,
            ..Material::default()
        },
        run: RunSettings {
            end_time_s: END_TIME_S,
            dt_factor: 10.0,
            energy_every: SAMPLE_EVERY,
            ..RunSettings::default()
        },
        analysis: Analysis {
            cloud: false,
            track_every: 0,
            render_times_s: Vec::new(),
            ..Analysis::default()
        },
    }
}

/// [`plates_scene`] as scene-file TOML (the base scene of the reproduction's sizing study).
pub fn plates_scene_toml(particles: f64, sizing: bool) -> Result<String> {
    toml::to_string(&plates_scene(particles, sizing)).context("sizing scene as TOML")
}

/// The energy curve of a run from its `energy.csv` (`hvi_run::run`): kinetic, and contact +
/// bond as the potential energy, against time since first contact.
pub fn curve_from_energy_csv(path: &Path) -> Result<Vec<EnergySample>> {
    let mut reader =
        csv::Reader::from_path(path).with_context(|| format!("cannot read {}", path.display()))?;
    let headers = reader.headers()?.clone();
    let col = |name: &str| {
        headers
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| RunError::Input(format!("{}: no column `{name}`", path.display())))
    };
    let (tau, kin, contact, bond) = (
        col("tau_s")?,
        col("kinetic_j")?,
        col("contact_j")?,
        col("bond_j")?,
    );
    let mut out = Vec::new();
    for (i, rec) in reader.records().enumerate() {
        let rec = rec.with_context(|| format!("{}: row {}", path.display(), i + 2))?;
        let num = |k: usize| -> Result<f64> {
            rec.get(k)
                .unwrap_or("")
                .parse::<f64>()
                .with_context(|| format!("{}: row {}", path.display(), i + 2))
        };
        out.push(EnergySample {
            tau_s: num(tau)?,
            kinetic_j: num(kin)?,
            potential_j: num(contact)? + num(bond)?,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_round_trips_through_toml_and_validates() {
        let text = plates_scene_toml(500.0, false).expect("toml");
        let back = hvi_run::scene_file::parse_scene(&text, &[]).expect("parses");
        assert_eq!(back, plates_scene(500.0, false));
        let setup = back.build().expect("valid");
        assert!(setup.particles.len() > 300);
    }
}
