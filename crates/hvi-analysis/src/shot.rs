//! An experiment's impact: the conditions a shot file (`experiments_data/*.toml`, `[shot]`)
//! defines, the offset at which it is simulated where the offset is a documented choice, and
//! the scene keys those conditions set. The calibration builds the scene it scores a shot
//! against from these keys (docs/calibration.md, "Your own shots").
//!
//! ```
//! use hvi_analysis::shot::{ImpactKey, Shot};
//! let shot: Shot = toml::from_str(r#"
//!     id = "my-shot"
//!     description = "Al sphere on an Al plate"
//!     source = "my lab, shot 42"
//!     impactor_diameter_m = 6.35e-3
//!     impactor_material = "Al 2017-T4"
//!     plate_material = "Al 6061-T6"
//!     v0_m_s = 5000.0
//!     t_over_d = 0.2
//! "#).unwrap();
//! shot.check().unwrap();
//! let keys = shot.impact_keys();
//! assert!(keys.iter().any(|k| k.key == "scene.v0_m_s" && k.value == 5000.0));
//! ```

use serde::{Deserialize, Serialize};

/// The largest relative offset between the experiment's conditions and the ones a shot is
/// simulated at (`[shot.simulated]`). The paper simulates its shot 3.1 % faster and 3.7 %
/// thicker than the experiment; an offset of more than a tenth is another impact, not a
/// rounding of this one, and belongs in a shot of its own.
pub const MAX_SIMULATED_OFFSET: f64 = 0.1;

/// Two values of one impact key agree when they differ by less than this, relatively (a
/// scene file writing 6.7e3 where the shot writes 6700.0 agrees; 6700 against 6500 does not).
pub const AGREEMENT: f64 = 1e-6;

/// The conditions at which a shot is simulated where they differ from the experiment's, as a
/// documented choice (the paper's shot: 6.7 km/s and t/D 0.425 for 6.5 km/s and 0.41).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulatedOffset {
    /// The impact velocity simulated, m/s (absent: the experiment's).
    #[serde(default)]
    pub v0_m_s: Option<f64>,
    /// The plate thickness over impactor diameter simulated (absent: the experiment's).
    #[serde(default)]
    pub t_over_d: Option<f64>,
    /// Why the shot is simulated at other conditions (required).
    pub reason: String,
}

/// The experiment a shot file describes: its impact, and where the numbers come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shot {
    /// Identifier (names the shot in tables, terms and `--hold-out`).
    pub id: String,
    /// What it is.
    pub description: String,
    /// Provenance.
    pub source: String,
    /// True for an invented example (tests, tutorials): reports say so beside every number.
    #[serde(default)]
    pub synthetic: bool,
    /// Impactor (sphere) diameter D, m.
    pub impactor_diameter_m: f64,
    /// The impactor's material as the source names it (e.g. `Al 2017-T4`).
    pub impactor_material: String,
    /// The plate's material as the source names it.
    pub plate_material: String,
    /// The impactor's density, kg/m^3, where the source states it.
    #[serde(default)]
    pub impactor_density_kg_m3: Option<f64>,
    /// The plate's density, kg/m^3, where the source states it.
    #[serde(default)]
    pub plate_density_kg_m3: Option<f64>,
    /// Impact velocity of the experiment, m/s.
    pub v0_m_s: f64,
    /// Angle of the impactor's path from the plate's normal, degrees (0: normal impact, the
    /// only one the model simulates yet).
    #[serde(default)]
    pub angle_deg: f64,
    /// Plate thickness over impactor diameter of the experiment.
    pub t_over_d: f64,
    /// Time after first contact at which the targets were observed (the film frame's), s,
    /// where the source states it; the cloud is then measured at this time.
    #[serde(default)]
    pub observation_time_s: Option<f64>,
    /// Conditions simulated instead of the experiment's, with the reason.
    #[serde(default)]
    pub simulated: Option<SimulatedOffset>,
}

/// One scene key whose value a shot sets.
#[derive(Debug, Clone, PartialEq)]
pub struct ImpactKey {
    /// The scene key, `section.key`.
    pub key: &'static str,
    /// The value the shot gives it, in the key's unit.
    pub value: f64,
    /// What it is, for messages (`v0`, `t/D`, ...).
    pub what: &'static str,
    /// The unit, for messages (`m/s`, `-`, ...).
    pub unit: &'static str,
}

impl ImpactKey {
    /// Whether `other` agrees with this key's value (relatively, [`AGREEMENT`]).
    pub fn agrees(&self, other: f64) -> bool {
        (other - self.value).abs() <= AGREEMENT * self.value.abs().max(other.abs())
    }
}

fn positive(key: &str, v: f64) -> Result<(), String> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(format!(
            "shot key `{key}`: {v} (allowed: a finite number > 0)"
        ))
    }
}

impl Shot {
    /// Checks the shot's values: positive, finite numbers; a simulated offset within
    /// [`MAX_SIMULATED_OFFSET`] of the experiment with its reason; normal impact only.
    pub fn check(&self) -> Result<(), String> {
        if self.id.trim().is_empty() || self.id.contains(char::is_whitespace) {
            return Err(format!(
                "shot key `id`: `{}` (allowed: a non-empty name without spaces)",
                self.id
            ));
        }
        positive("impactor_diameter_m", self.impactor_diameter_m)?;
        if self.angle_deg != 0.0 {
            return Err(format!(
                "shot key `angle_deg`: {} (allowed: 0; the model simulates normal impact only, \
                 docs/model.md, \"Scope\")",
                self.angle_deg
            ));
        }
        positive("v0_m_s", self.v0_m_s)?;
        positive("t_over_d", self.t_over_d)?;
        if let Some(t) = self.observation_time_s {
            positive("observation_time_s", t)?;
        }
        for (key, d) in [
            ("impactor_density_kg_m3", self.impactor_density_kg_m3),
            ("plate_density_kg_m3", self.plate_density_kg_m3),
        ] {
            if let Some(d) = d {
                positive(key, d)?;
            }
        }
        if let Some(s) = &self.simulated {
            if s.reason.trim().is_empty() {
                return Err(
                    "shot key `simulated.reason`: empty (allowed: why the shot is \
                            simulated at other conditions than the experiment's)"
                        .into(),
                );
            }
            for (key, sim, exp) in [
                ("simulated.v0_m_s", s.v0_m_s, self.v0_m_s),
                ("simulated.t_over_d", s.t_over_d, self.t_over_d),
            ] {
                let Some(sim) = sim else { continue };
                positive(key, sim)?;
                let off = (sim - exp).abs() / exp;
                if off > MAX_SIMULATED_OFFSET {
                    return Err(format!(
                        "shot key `{key}`: {sim} is {:.1} % away from the experiment's {exp} \
                         (allowed: within {:.0} %; a larger change is another impact, a shot of \
                         its own)",
                        100.0 * off,
                        100.0 * MAX_SIMULATED_OFFSET
                    ));
                }
            }
        }
        Ok(())
    }

    /// The impact velocity the shot is simulated at, m/s.
    pub fn simulated_v0_m_s(&self) -> f64 {
        self.simulated
            .as_ref()
            .and_then(|s| s.v0_m_s)
            .unwrap_or(self.v0_m_s)
    }

    /// The t/D the shot is simulated at.
    pub fn simulated_t_over_d(&self) -> f64 {
        self.simulated
            .as_ref()
            .and_then(|s| s.t_over_d)
            .unwrap_or(self.t_over_d)
    }

    /// The scene keys the shot sets, at the conditions it is simulated at: the sphere's
    /// diameter, v0, t/D, and, where the shot states them, the density and the run's end (the
    /// observation time: `run.end_time_s` is the time simulated after first contact).
    pub fn impact_keys(&self) -> Vec<ImpactKey> {
        let mut keys = vec![
            ImpactKey {
                key: "scene.diameter_m",
                value: self.impactor_diameter_m,
                what: "impactor diameter",
                unit: "m",
            },
            ImpactKey {
                key: "scene.v0_m_s",
                value: self.simulated_v0_m_s(),
                what: "v0",
                unit: "m/s",
            },
            ImpactKey {
                key: "scene.t_over_d",
                value: self.simulated_t_over_d(),
                what: "t/D",
                unit: "-",
            },
        ];
        // One density stated is both bodies'; two that differ are the plate's and the
        // impactor's own.
        let (imp, plate) = (self.impactor_density_kg_m3, self.plate_density_kg_m3);
        if let Some(d) = plate.or(imp) {
            keys.push(ImpactKey {
                key: "scene.density_kg_m3",
                value: d,
                what: if imp.is_some() && plate.is_some() {
                    "plate density"
                } else {
                    "density"
                },
                unit: "kg/m^3",
            });
        }
        if let (Some(a), Some(b)) = (imp, plate) {
            if (a - b).abs() > AGREEMENT * a.max(b) {
                keys.push(ImpactKey {
                    key: "impactor.density_kg_m3",
                    value: a,
                    what: "impactor density",
                    unit: "kg/m^3",
                });
            }
        }
        if let Some(t) = self.observation_time_s {
            keys.push(ImpactKey {
                key: "run.end_time_s",
                value: t,
                what: "observation time",
                unit: "s",
            });
        }
        keys
    }

    /// The offset in words ("simulated at v0 = 6700 m/s (experiment 6500, +3.1 %) and t/D =
    /// 0.425 (0.41, +3.7 %): reason"), or None when the shot is simulated as measured.
    pub fn describe_offset(&self) -> Option<String> {
        let s = self.simulated.as_ref()?;
        let mut parts = Vec::new();
        if let Some(v) = s.v0_m_s {
            parts.push(format!(
                "v0 = {v} m/s (experiment {}, {:+.1} %)",
                self.v0_m_s,
                100.0 * (v / self.v0_m_s - 1.0)
            ));
        }
        if let Some(t) = s.t_over_d {
            parts.push(format!(
                "t/D = {t} (experiment {}, {:+.1} %)",
                self.t_over_d,
                100.0 * (t / self.t_over_d - 1.0)
            ));
        }
        Some(format!(
            "simulated at {}: {}",
            parts.join(" and "),
            s.reason.trim()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shot(extra: &str) -> Shot {
        toml::from_str(&format!(
            "id = \"s\"\ndescription = \"\"\nsource = \"\"\nimpactor_diameter_m = 9.53e-3\n\
             impactor_material = \"Al\"\nplate_material = \"Al\"\nv0_m_s = 6500.0\n\
             t_over_d = 0.41\n{extra}"
        ))
        .expect("shot")
    }

    #[test]
    fn an_offset_is_checked_and_sets_the_simulated_keys() {
        let s = shot("[simulated]\nv0_m_s = 6700.0\nt_over_d = 0.425\nreason = \"the paper's\"\n");
        s.check().expect("3 % offsets are allowed");
        let keys = s.impact_keys();
        let get = |k: &str| keys.iter().find(|x| x.key == k).expect(k).value;
        assert_eq!(get("scene.v0_m_s"), 6700.0);
        assert_eq!(get("scene.t_over_d"), 0.425);
        assert_eq!(get("scene.diameter_m"), 9.53e-3);
        assert!(keys.iter().all(|k| k.key != "run.end_time_s"));
        let d = s.describe_offset().expect("offset");
        assert!(d.contains("+3.1 %") && d.contains("+3.7 %"), "{d}");
        // 12 % away is another impact.
        let e = shot("[simulated]\nv0_m_s = 7280.0\nreason = \"x\"\n")
            .check()
            .expect_err("12 %");
        assert!(
            e.contains("simulated.v0_m_s") && e.contains("12.0 %"),
            "{e}"
        );
        let e = shot("[simulated]\nv0_m_s = 6700.0\nreason = \" \"\n")
            .check()
            .expect_err("no reason");
        assert!(e.contains("simulated.reason"), "{e}");
    }

    #[test]
    fn two_densities_are_the_bodies_own_and_one_is_both() {
        let steel = shot("impactor_density_kg_m3 = 7850.0\nplate_density_kg_m3 = 2700.0\n");
        steel.check().expect("steel on aluminium");
        let keys = steel.impact_keys();
        let value = |key: &str| keys.iter().find(|k| k.key == key).map(|k| k.value);
        assert_eq!(value("scene.density_kg_m3"), Some(2700.0));
        assert_eq!(value("impactor.density_kg_m3"), Some(7850.0));
        let same = shot("impactor_density_kg_m3 = 2700.0\nplate_density_kg_m3 = 2700.0\n");
        assert!(same
            .impact_keys()
            .iter()
            .all(|k| k.key != "impactor.density_kg_m3"));
        let s = shot("impactor_density_kg_m3 = 2800.0\nobservation_time_s = 2.5e-5\n");
        s.check().expect("one density");
        let keys = s.impact_keys();
        assert!(keys
            .iter()
            .any(|k| k.key == "scene.density_kg_m3" && k.value == 2800.0));
        assert!(keys
            .iter()
            .any(|k| k.key == "run.end_time_s" && k.value == 2.5e-5));
        let negative = Shot {
            v0_m_s: -1.0,
            ..shot("")
        };
        assert!(negative.check().expect_err("v0 < 0").contains("v0_m_s"));
        let e = shot("angle_deg = 45.0\n").check().expect_err("oblique");
        assert!(
            e.contains("angle_deg") && e.contains("normal impact"),
            "{e}"
        );
    }

    #[test]
    fn agreement_is_relative() {
        let k = ImpactKey {
            key: "scene.v0_m_s",
            value: 6700.0,
            what: "v0",
            unit: "m/s",
        };
        assert!(k.agrees(6.7e3));
        assert!(k.agrees(6700.000001));
        assert!(!k.agrees(6500.0));
    }
}
