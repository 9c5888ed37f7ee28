//! Checks of the scene's own values (geometry and run settings) against their allowed
//! ranges, naming the key on error. Values that need the resolution (thicknesses in lattice
//! steps, the time step) are checked where they are derived.

use super::keys;
use super::spec::{Geometry, RunSettings, SceneSpec};
use crate::error::{EngineError, Result};
use crate::step::MAX_STRIDE;

/// The impact's numbers common to both geometries, once checked.
#[derive(Debug, Clone, Copy)]
pub(super) struct Impact {
    /// Impact velocity v0, m/s.
    pub v0_m_s: f64,
    /// Density of both bodies, kg/m^3.
    pub density_kg_m3: f64,
    /// Extra gap between the bodies at t = 0, m (finite; a negative one is an overlap).
    pub standoff_m: f64,
}

impl Geometry {
    /// Checks velocity, density, standoff and the bodies' dimensions.
    pub(super) fn validate(&self) -> Result<Impact> {
        let v0 = keys::check("scene.v0_m_s", self.v0_m_s())?;
        let (density, standoff) = match *self {
            Geometry::SphereOnPlate {
                density_kg_m3,
                standoff_m,
                ..
            }
            | Geometry::FlyerPlate {
                density_kg_m3,
                standoff_m,
                ..
            } => (density_kg_m3, standoff_m),
        };
        keys::check("scene.density_kg_m3", density)?;
        if !standoff.is_finite() {
            return Err(EngineError::invalid(
                "scene.standoff_m",
                standoff,
                "a finite number >= 0",
            ));
        }
        match *self {
            Geometry::SphereOnPlate {
                diameter_m,
                t_over_d,
                width_over_d,
                ..
            } => {
                keys::check("scene.diameter_m", diameter_m)?;
                keys::check("scene.t_over_d", t_over_d)?;
                keys::check("scene.width_over_d", width_over_d)?;
            }
            Geometry::FlyerPlate {
                flyer_thickness_m,
                target_thickness_m,
                width_m,
                ..
            } => {
                keys::check("scene.flyer_thickness_m", flyer_thickness_m)?;
                keys::check("scene.target_thickness_m", target_thickness_m)?;
                keys::check("scene.width_m", width_m)?;
            }
        }
        Ok(Impact {
            v0_m_s: v0,
            density_kg_m3: density,
            standoff_m: standoff,
        })
    }
}

impl RunSettings {
    /// Checks every run setting except the time step itself (see `time_step`).
    pub(super) fn validate(&self) -> Result<()> {
        self.validate_stepping()?;
        self.validate_guards()
    }

    /// End time, step factor, thermal velocities, neighbour list and adaptive step.
    fn validate_stepping(&self) -> Result<()> {
        keys::check("run.end_time_s", self.end_time_s)?;
        keys::check("run.dt_factor", self.dt_factor)?;
        keys::check("run.thermal_ratio", self.thermal_ratio)?;
        keys::check("run.skin_over_sigma", self.skin_over_sigma)?;
        let b = self.frame_block_over_sigma;
        if !(b == 0.0 || (2.0..=1e3).contains(&b)) {
            return Err(EngineError::invalid(
                "run.frame_block_over_sigma",
                b,
                "0 (off) or a number in [2, 1000]",
            ));
        }
        if !(1..=MAX_STRIDE).contains(&self.max_stride) {
            return Err(EngineError::invalid(
                "run.max_stride",
                self.max_stride.to_string(),
                format!("a whole number from 1 to {MAX_STRIDE} (1: a fixed step)"),
            ));
        }
        keys::check(
            "run.stride_displacement_over_sigma",
            self.stride_displacement_over_sigma,
        )?;
        Ok(())
    }

    /// The energy-ledger sampling, the blow-up guards and the ballistic cut-off.
    fn validate_guards(&self) -> Result<()> {
        if self.energy_every == 0 {
            return Err(EngineError::invalid(
                "run.energy_every",
                0,
                "an integer >= 1",
            ));
        }
        keys::check("run.max_energy_drift", self.max_energy_drift)?;
        keys::check("run.min_distance_over_sigma", self.min_distance_over_sigma)?;
        keys::check("run.cutoff_min_tau_s", self.cutoff_min_tau_s)?;
        keys::check("run.cutoff_quiet_s", self.cutoff_quiet_s)?;
        keys::check("run.cutoff_break_fraction", self.cutoff_break_fraction)?;
        if let Some(t) = self.free_flight_after_s {
            if !(t > 0.0 && t < self.end_time_s) {
                return Err(EngineError::invalid(
                    "run.free_flight_after_s",
                    t,
                    format!(
                        "a number > 0 and below run.end_time_s = {:e} s, or unset",
                        self.end_time_s
                    ),
                ));
            }
        }
        self.validate_screen()
    }

    /// The screen: a time inside the run, at least one window, each window in order.
    fn validate_screen(&self) -> Result<()> {
        let windows = [
            ("run.screen_length_ratio", self.screen_length_ratio),
            (
                "run.screen_front_velocity_ratio",
                self.screen_front_velocity_ratio,
            ),
        ];
        for (key, w) in windows {
            if let Some([lo, hi]) = w {
                if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                    return Err(EngineError::invalid(
                        key,
                        format!("[{lo}, {hi}]"),
                        "[low, high], two finite numbers with low < high, or unset",
                    ));
                }
            }
        }
        let any_window = windows.iter().any(|(_, w)| w.is_some());
        match self.screen_after_s {
            Some(t) if !(t > 0.0 && t < self.end_time_s) => Err(EngineError::invalid(
                "run.screen_after_s",
                t,
                format!(
                    "a number > 0 and below run.end_time_s = {:e} s, or unset",
                    self.end_time_s
                ),
            )),
            Some(t) if !any_window => Err(EngineError::invalid(
                "run.screen_after_s",
                t,
                "unset, or set with run.screen_length_ratio or run.screen_front_velocity_ratio",
            )),
            None if any_window => Err(EngineError::invalid(
                "run.screen_after_s",
                "unset",
                "a number > 0 and below run.end_time_s when a screen window is set",
            )),
            _ => Ok(()),
        }
    }
}

impl SceneSpec {
    /// The absorbing band: in range, narrower than half the plate, on a sphere-on-plate scene.
    pub(super) fn validate_band(&self) -> Result<()> {
        let band = keys::check("run.absorbing_band_over_d", self.run.absorbing_band_over_d)?;
        if band == 0.0 {
            return Ok(());
        }
        match self.scene {
            Geometry::SphereOnPlate { width_over_d, .. } if band < 0.5 * width_over_d => Ok(()),
            Geometry::SphereOnPlate { width_over_d, .. } => Err(EngineError::invalid(
                "run.absorbing_band_over_d",
                band,
                format!(
                    "less than half the plate's side over D (scene.width_over_d / 2 = {})",
                    0.5 * width_over_d
                ),
            )),
            Geometry::FlyerPlate { .. } => Err(EngineError::invalid(
                "run.absorbing_band_over_d",
                band,
                "0 on a flyer-plate scene (the band is for a sphere on a plate)",
            )),
        }
    }
}

/// Below this impact velocity a scene draws a warning (km/s typed as m/s?), m/s.
pub const SUSPICIOUS_V0_M_S: f64 = 100.0;

impl SceneSpec {
    /// Values that are allowed but almost surely a mistake, each as one sentence naming the
    /// key: an impact velocity below [`SUSPICIOUS_V0_M_S`], or a run too short for the sphere
    /// to get through the plate (no debris cloud forms) while the cloud is measured.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        let v0 = self.scene.v0_m_s();
        if v0 > 0.0 && v0 < SUSPICIOUS_V0_M_S {
            w.push(format!(
                "scene.v0_m_s = {v0} m/s is below {SUSPICIOUS_V0_M_S} m/s: hypervelocity impacts \
                 are 3000-10000 m/s (was it typed in km/s?)"
            ));
        }
        if let Geometry::SphereOnPlate {
            diameter_m,
            t_over_d,
            ..
        } = self.scene
        {
            let through = (diameter_m * t_over_d) / v0;
            // A time that is not allowed at all is an error of its own, not this warning.
            if self.analysis.cloud
                && v0 > 0.0
                && self.run.end_time_s > 0.0
                && self.run.end_time_s < through
            {
                w.push(format!(
                    "run.end_time_s = {:.3e} s is shorter than the {:.3e} s the sphere needs to \
                     cross the plate at v0 (t / v0): no debris cloud forms, so the cloud's \
                     numbers will be empty",
                    self.run.end_time_s, through
                ));
            }
        }
        w
    }
}
