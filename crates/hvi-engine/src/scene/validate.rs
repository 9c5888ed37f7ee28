//! Checks of the scene's own values (geometry and run settings) against their allowed
//! ranges, naming the key on error. Values that need the resolution (thicknesses in lattice
//! steps, the time step) are checked where they are derived.

use super::spec::{Geometry, RunSettings};
use crate::error::{check_positive, check_range, EngineError, Result};
use crate::step::{MAX_STRIDE, MAX_STRIDE_DISPLACEMENT_OVER_SIGMA};

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
        let v0 = check_range("scene.v0_m_s", self.v0_m_s(), 0.0, true, 1e5, false)?;
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
        check_positive("scene.density_kg_m3", density)?;
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
                check_positive("scene.diameter_m", diameter_m)?;
                check_positive("scene.t_over_d", t_over_d)?;
                check_range("scene.width_over_d", width_over_d, 1.0, false, 1e3, false)?;
            }
            Geometry::FlyerPlate {
                flyer_thickness_m,
                target_thickness_m,
                width_m,
                ..
            } => {
                check_positive("scene.flyer_thickness_m", flyer_thickness_m)?;
                check_positive("scene.target_thickness_m", target_thickness_m)?;
                check_positive("scene.width_m", width_m)?;
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
        check_positive("run.end_time_s", self.end_time_s)?;
        check_range("run.dt_factor", self.dt_factor, 0.0, true, 1e3, false)?;
        check_range(
            "run.thermal_ratio",
            self.thermal_ratio,
            0.0,
            false,
            0.1,
            false,
        )?;
        check_range(
            "run.skin_over_sigma",
            self.skin_over_sigma,
            0.0,
            true,
            2.0,
            false,
        )?;
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
        check_range(
            "run.stride_displacement_over_sigma",
            self.stride_displacement_over_sigma,
            0.0,
            true,
            MAX_STRIDE_DISPLACEMENT_OVER_SIGMA,
            false,
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
        check_range(
            "run.max_energy_drift",
            self.max_energy_drift,
            0.0,
            true,
            f64::INFINITY,
            false,
        )?;
        check_range(
            "run.min_distance_over_sigma",
            self.min_distance_over_sigma,
            0.0,
            false,
            1.0,
            true,
        )?;
        check_range(
            "run.cutoff_min_tau_s",
            self.cutoff_min_tau_s,
            0.0,
            false,
            f64::INFINITY,
            true,
        )?;
        check_range(
            "run.cutoff_quiet_s",
            self.cutoff_quiet_s,
            0.0,
            true,
            f64::INFINITY,
            true,
        )?;
        check_range(
            "run.cutoff_break_fraction",
            self.cutoff_break_fraction,
            0.0,
            false,
            1.0,
            false,
        )?;
        Ok(())
    }
}
