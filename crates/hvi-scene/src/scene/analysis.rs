//! The analysis settings (`[analysis]`): which debris-cloud observables a run measures, and
//! when. The observables themselves are defined in `hvi_engine::cloud`; their defaults (quantile,
//! front times) live here with the settings that use them.

use serde::{Deserialize, Serialize};

use super::keys;
use crate::error::{EngineError, Result};
use crate::paper;

/// Default quantile of the front and of the radial extent (docs/model.md section 5). The paper
/// does not say; the readings study (docs/model-decisions.md, "The readings of the paper behind
/// Figs. 9 and 10") found the 0.9 quantile the reading closest to the paper: at 0.99 and
/// above the front is a spray of a few per cent of the particles, which speeds up as eps grows
/// while the bulk of the cloud slows down, so va/v0 rises with eps where the paper's falls.
pub const DEFAULT_QUANTILE: f64 = 0.9;
/// Default times since first contact at which the front is located for va, s (docs/model.md
/// section 5: a pair ending at the analysis time, like the experiment's two photographs).
pub const DEFAULT_FRONT_TIMES_S: [f64; 2] = [28e-6, 32e-6];

/// How the cloud's width Lr (and so R = La / Lr) is read (docs/model-decisions.md, "The width
/// of the cloud: cylindrical or side-on").
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Width {
    /// As a side-view shadowgraph records it: twice the quantile of the particles' distance
    /// from the plane of view through the axis (|x| and |y| pooled: two perpendicular views of
    /// one cloud). The experiment's reading, and the default.
    #[default]
    Side,
    /// Twice the quantile of the particles' distance from the impact axis: a radius no camera
    /// sees, the project's default until the side-on reading replaced it.
    Cylindrical,
}

impl Width {
    /// The name a scene file gives it.
    pub fn name(self) -> &'static str {
        match self {
            Width::Side => "side",
            Width::Cylindrical => "cylindrical",
        }
    }

    /// How a caption names it: "side-on" or "cylindrical".
    pub fn label(self) -> &'static str {
        match self {
            Width::Side => "side-on",
            Width::Cylindrical => "cylindrical",
        }
    }

    /// Parses a scene file's name, naming the key and the allowed values on error.
    pub fn parse(text: &str) -> Result<Self> {
        match text.trim() {
            "side" => Ok(Width::Side),
            "cylindrical" => Ok(Width::Cylindrical),
            other => Err(EngineError::invalid(
                "analysis.width",
                other,
                "`side` or `cylindrical`",
            )),
        }
    }

    /// What a measurement written before the key existed read: the cylindrical
    /// width.
    pub fn legacy() -> Self {
        Width::Cylindrical
    }
}

/// What a run measures of the debris cloud, and when. The observables themselves are defined in
/// `hvi_engine::cloud` (docs/model.md section 5); these keys only choose the quantile, the times and
/// how often. Only what is asked for is computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Analysis {
    /// Measure the cloud at the end of the run (the analysis time): fragments, N_part, N_frag,
    /// F, La, Lr, R, fragment sizes, and the front velocity va from the two front times.
    pub cloud: bool,
    /// Quantile of the cloud particles' axial and radial positions that defines the front and
    /// the radial extent (so that a few stray particles do not decide La and Lr), in [0.5, 1];
    /// 1 is the plain maximum (always reported as well).
    pub quantile: f64,
    /// How the width Lr (and R) is read: `side` (the shadowgraph's projection, the default)
    /// or `cylindrical` (the distance from the axis). Both readings are always reported as
    /// well (`length_ratio_side`, `length_ratio_cylindrical`); this one is `length_ratio`, the
    /// R that the calibration, the figures and the verdicts use. Always written into the
    /// scene's JSON, so a run's fingerprint says which R its record holds.
    pub width: Width,
    /// The two times since first contact at which the front is located for va, s, with
    /// 0 <= t1 < t2 <= `run.end_time_s`. When not given: the experiment's 28 and 32 us if the
    /// run reaches 32 us, else 7/8 of the end time and the end time
    /// ([`Analysis::front_times_s`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub front_times_s: Option<[f64; 2]>,
    /// Steps between samples of the cloud track (front, La, Lr over time; one fragment
    /// labelling each, about the cost of one step); 0 turns the track off.
    pub track_every: u64,
    /// Times since first contact of the rendered 3-D series (`hvi-study run --render`, Fig. 12),
    /// s; times beyond the end of the run are skipped.
    pub render_times_s: Vec<f64>,
    /// Pixel size of the synthetic shadowgraph (the side-on camera, `crate::shadowgraph`), m,
    /// in (0, 0.01].
    #[serde(skip_serializing_if = "is_default_pixel")]
    pub shadowgraph_pixel_m: f64,
    /// Standard deviation of the shadowgraph's blur, m, in [0, 0.05].
    #[serde(skip_serializing_if = "is_default_blur")]
    pub shadowgraph_blur_m: f64,
    /// Grain diameter of the debris the shadowgraph sees, m, in (0, 0.01]: the optical depth
    /// of an areal density Sigma is (3/2) Sigma / (rho d).
    #[serde(skip_serializing_if = "is_default_grain")]
    pub shadowgraph_grain_m: f64,
    /// Optical depth at which a shadowgraph pixel counts as dark (1: transmission 1/e), in
    /// (0, 100].
    #[serde(skip_serializing_if = "is_default_optical_depth")]
    pub shadowgraph_optical_depth: f64,
    /// Standoff of the synthetic witness plate behind the target's original rear face
    /// (`crate::witness`), m, in (0, 10].
    #[serde(skip_serializing_if = "is_default_witness_standoff")]
    pub witness_standoff_m: f64,
    /// Keep the cloud's compact state at the analysis time and at the two front times (every
    /// particle's position, velocity, body, fragment label and membership; `state.bin` in the
    /// run's directory), so that the cloud can be measured again with other settings without
    /// re-simulating (`hvi_engine::cloud::remeasure`, `hvi-study reanalyse`).
    #[serde(skip_serializing_if = "is_true")]
    pub keep_state: bool,
}

/// Default standoff of the witness plate behind the target, m (the paper does not give the
/// experiment's; a decision, documented in docs/model-decisions.md).
pub const DEFAULT_WITNESS_STANDOFF_M: f64 = 0.1;

// Keys added after the first studies are left out of a scene's JSON at their defaults, so the
// fingerprints of stored runs stay what they were.
fn is_default_pixel(v: &f64) -> bool {
    *v == crate::shadowgraph::DEFAULT_PIXEL_M
}
fn is_default_blur(v: &f64) -> bool {
    *v == crate::shadowgraph::DEFAULT_BLUR_M
}
fn is_default_grain(v: &f64) -> bool {
    *v == crate::shadowgraph::DEFAULT_GRAIN_M
}
fn is_default_optical_depth(v: &f64) -> bool {
    *v == crate::shadowgraph::DEFAULT_OPTICAL_DEPTH
}
fn is_default_witness_standoff(v: &f64) -> bool {
    *v == DEFAULT_WITNESS_STANDOFF_M
}
fn is_true(v: &bool) -> bool {
    *v
}

impl Default for Analysis {
    fn default() -> Self {
        Analysis {
            cloud: true,
            quantile: DEFAULT_QUANTILE,
            width: Width::default(),
            front_times_s: None,
            track_every: 100,
            render_times_s: paper::FIG12_TIMES_S.to_vec(),
            shadowgraph_pixel_m: crate::shadowgraph::DEFAULT_PIXEL_M,
            shadowgraph_blur_m: crate::shadowgraph::DEFAULT_BLUR_M,
            shadowgraph_grain_m: crate::shadowgraph::DEFAULT_GRAIN_M,
            shadowgraph_optical_depth: crate::shadowgraph::DEFAULT_OPTICAL_DEPTH,
            witness_standoff_m: DEFAULT_WITNESS_STANDOFF_M,
            keep_state: true,
        }
    }
}

/// The `[analysis]` keys that only say how the cloud is measured from the states a run keeps
/// (`analysis.keep_state`): the quantile, the width, the camera and the witness plate. They
/// change neither the simulation nor when it is observed, so a re-analysis may change them
/// (`hvi-study reanalyse`), and a run that differs from a stored one only in them is measured
/// from that run's kept state instead of simulated again (docs/studies.md, "Runs measured from
/// a kept state"). The other keys (the front times, the track, the pictures) are fixed by what
/// the run kept.
pub const MEASUREMENT_KEYS: [&str; 7] = [
    "analysis.quantile",
    "analysis.width",
    "analysis.shadowgraph_pixel_m",
    "analysis.shadowgraph_blur_m",
    "analysis.shadowgraph_grain_m",
    "analysis.shadowgraph_optical_depth",
    "analysis.witness_standoff_m",
];

impl Analysis {
    /// These settings with every [`MEASUREMENT_KEYS`] key at its default and the state kept:
    /// what decides the simulation and the states it keeps. Two runs whose scenes differ only
    /// in the measurement keys (and in `keep_state`) have equal `as_simulated` settings.
    pub fn as_simulated(&self) -> Analysis {
        let d = Analysis::default();
        Analysis {
            quantile: d.quantile,
            width: d.width,
            shadowgraph_pixel_m: d.shadowgraph_pixel_m,
            shadowgraph_blur_m: d.shadowgraph_blur_m,
            shadowgraph_grain_m: d.shadowgraph_grain_m,
            shadowgraph_optical_depth: d.shadowgraph_optical_depth,
            witness_standoff_m: d.witness_standoff_m,
            keep_state: true,
            ..self.clone()
        }
    }

    /// Whether the cloud's track (`cloud_track.csv`: the front, La and Lr over time, measured
    /// during the run) reads the same under these settings as under `other`: the same quantile
    /// and width.
    pub fn same_track_reading(&self, other: &Analysis) -> bool {
        self.quantile == other.quantile && self.width == other.width
    }

    /// The two front times for va, s since first contact, for a run that ends at `end_time_s`:
    /// the given ones, or the experiment's (28, 32) us when the run reaches 32 us, or else
    /// (7/8 T, T) with T the end time (the same ratio, so a short run still measures a speed).
    pub fn front_times_s(&self, end_time_s: f64) -> [f64; 2] {
        match self.front_times_s {
            Some(t) => t,
            None => {
                let [t1, t2] = DEFAULT_FRONT_TIMES_S;
                if end_time_s >= t2 {
                    [t1, t2]
                } else {
                    [t1 / t2 * end_time_s, end_time_s]
                }
            }
        }
    }

    /// Checks every value against its allowed range, naming the key.
    pub fn validate(&self, end_time_s: f64) -> Result<()> {
        // The intervals are the key registry's (`super::keys`).
        for (key, value) in [
            ("analysis.quantile", self.quantile),
            ("analysis.shadowgraph_pixel_m", self.shadowgraph_pixel_m),
            ("analysis.shadowgraph_blur_m", self.shadowgraph_blur_m),
            ("analysis.shadowgraph_grain_m", self.shadowgraph_grain_m),
            (
                "analysis.shadowgraph_optical_depth",
                self.shadowgraph_optical_depth,
            ),
            ("analysis.witness_standoff_m", self.witness_standoff_m),
        ] {
            keys::check(key, value)?;
        }
        if let Some([t1, t2]) = self.front_times_s {
            let ok = t1.is_finite() && t2.is_finite() && 0.0 <= t1 && t1 < t2 && t2 <= end_time_s;
            if !ok {
                return Err(EngineError::invalid(
                    "analysis.front_times_s",
                    format!("[{t1:e}, {t2:e}]"),
                    format!(
                        "two times since first contact in s with 0 <= t1 < t2 <= run.end_time_s = {end_time_s:e}"
                    ),
                ));
            }
        }
        for &t in &self.render_times_s {
            if !(t.is_finite() && t >= 0.0) {
                return Err(EngineError::invalid(
                    "analysis.render_times_s",
                    t,
                    "times since first contact in s, each finite and >= 0",
                ));
            }
        }
        Ok(())
    }
}

impl Analysis {
    /// The synthetic camera's settings.
    pub fn shadowgraph(&self) -> crate::shadowgraph::ShadowgraphSettings {
        crate::shadowgraph::ShadowgraphSettings {
            pixel_m: self.shadowgraph_pixel_m,
            blur_m: self.shadowgraph_blur_m,
            grain_m: self.shadowgraph_grain_m,
            optical_depth: self.shadowgraph_optical_depth,
        }
    }

    /// The synthetic witness plate (aluminium 6061-T6 at `witness_standoff_m`).
    pub fn witness_plate(&self) -> crate::witness::WitnessPlate {
        crate::witness::WitnessPlate::aluminium_6061(self.witness_standoff_m)
    }
}
