//! Building a scene: the spec validated, sized and laid out into a ready-to-run [`Setup`].
//!
//! [`SceneSpec::build`] runs the steps in order: check the geometry, derive the lattice
//! spacing from the resolution and sigma from it, size the material (eq. 12), lay out the
//! lattice (`layout`), give each body's particles their mass (eq. 20), check the run settings,
//! choose the time step against the stability bound, and place the impactor at its standoff.

use serde::{Deserialize, Serialize};

use super::keys;
use super::layout::{lay_out, rim_ids, Layout};
use super::spec::{Geometry, ImpactorMaterial, Material, Resolution, SceneSpec, SizingRule};
use super::time_step::choose_time_step;
use super::validate::Impact;
use crate::error::{check_range, EngineError, Result};
use crate::paper;
use crate::potential::{Interaction, Materials};
use crate::state::{Body, Particles};
use crate::step::stability_bound_s;
use crate::symmetry::Symmetry;

/// Numbers derived from a scene that every run prints (and the summary records).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Derived {
    /// Particle diameter sigma at this resolution, m.
    pub sigma_m: f64,
    /// Reference diameter at which eps and kappa are given, m.
    pub sigma_ref_m: f64,
    /// Lattice spacing r_eq, m.
    pub r_eq_m: f64,
    /// gamma = eps / sigma^3, Pa.
    pub gamma_pa: f64,
    /// lambda = kappa / sigma, Pa.
    pub lambda_pa: f64,
    /// eps at this sigma, J.
    pub eps_j: f64,
    /// kappa at this sigma, N/m.
    pub kappa_n_m: f64,
    /// rcut, m.
    pub rcut_m: f64,
    /// Particle mass of the impactor (flyer), kg.
    pub mass_impactor_kg: f64,
    /// Particle mass of the target plate, kg.
    pub mass_target_kg: f64,
    /// Density of the plate, and of the impactor unless `impactor` says otherwise, kg/m^3 (a
    /// particle stands for the volume mass / density).
    pub density_kg_m3: f64,
    /// The impactor's material where it differs from the plate's (then the fields above are
    /// the plate's); absent for one material.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub impactor: Option<ImpactorDerived>,
    /// Time step, s.
    pub dt_s: f64,
    /// Largest step the validation accepts, s.
    pub dt_max_s: f64,
    /// Impact velocity, m/s.
    pub v0_m_s: f64,
    /// z of the target plate's rear face at t = 0, m (the debris cloud lies beyond it).
    pub plate_rear_z_m: f64,
    /// z of the target plate's front face at t = 0, m.
    pub plate_front_z_m: f64,
    /// Time of first contact, s (tau = t - this).
    pub contact_time_s: f64,
    /// Number of steps to reach the end time.
    pub steps: u64,
}

/// The impactor's own material at this resolution (a scene with `[impactor]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImpactorDerived {
    /// The impactor's density, kg/m^3.
    pub density_kg_m3: f64,
    /// gamma = eps / sigma^3, Pa.
    pub gamma_pa: f64,
    /// lambda = kappa / sigma, Pa.
    pub lambda_pa: f64,
    /// eps at this sigma, J.
    pub eps_j: f64,
    /// kappa at this sigma, N/m.
    pub kappa_n_m: f64,
    /// rcut, m.
    pub rcut_m: f64,
    /// eps of the contact between the bodies, J.
    pub cross_eps_j: f64,
}

impl Derived {
    /// The impactor's density, kg/m^3.
    pub fn impactor_density_kg_m3(&self) -> f64 {
        self.impactor
            .map_or(self.density_kg_m3, |i| i.density_kg_m3)
    }

    /// Derived numbers for a hand-made particle set (tests and tools): the interaction's
    /// constants, the given step, the lattice's density mass / r_eq^3, and zeros for the
    /// scene geometry.
    pub fn for_interaction(ia: &Interaction, dt_s: f64, mass_kg: f64, steps: u64) -> Derived {
        Derived {
            sigma_m: ia.sigma_m,
            sigma_ref_m: paper::reference_sigma_m(),
            r_eq_m: ia.r_eq_m,
            gamma_pa: ia.eps_j / ia.sigma_m.powi(3),
            lambda_pa: ia.kappa_n_m / ia.sigma_m,
            eps_j: ia.eps_j,
            kappa_n_m: ia.kappa_n_m,
            rcut_m: ia.rcut_m,
            mass_impactor_kg: mass_kg,
            mass_target_kg: mass_kg,
            density_kg_m3: mass_kg / ia.r_eq_m.powi(3),
            impactor: None,
            dt_s,
            dt_max_s: f64::INFINITY,
            v0_m_s: 0.0,
            plate_rear_z_m: 0.0,
            plate_front_z_m: 0.0,
            contact_time_s: 0.0,
            steps,
        }
    }
}

/// A validated scene, laid out and ready to run.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The spec it came from.
    pub spec: SceneSpec,
    /// Derived numbers.
    pub derived: Derived,
    /// The pair laws at this sigma (one material, or the impactor's and the plate's).
    pub materials: Materials,
    /// Particles and bonds at t = 0.
    pub particles: Particles,
    /// Particles of the target that lie on its lateral rim at t = 0 (by id): the residual
    /// plate is the fragment that holds them (docs/model.md section 5).
    pub rim_ids: Vec<u32>,
}

/// Both bodies' materials at this resolution.
struct SizedBodies {
    /// The plate's material (and the impactor's unless `impactor` is given).
    plate: SizedMaterial,
    /// The impactor's own law, when `[impactor]` gives one.
    impactor: Option<SizedMaterial>,
    /// Densities of the impactor and of the plate, kg/m^3.
    density: [f64; 2],
    /// The pair laws built from them.
    materials: Materials,
}

impl SizedBodies {
    /// The impactor's derived numbers when it differs from the plate in law or density.
    fn impactor_derived(&self) -> Option<ImpactorDerived> {
        let [density_imp, density] = self.density;
        if self.impactor.is_none() && density_imp == density {
            return None;
        }
        let i = self.impactor.as_ref().unwrap_or(&self.plate);
        Some(ImpactorDerived {
            density_kg_m3: density_imp,
            gamma_pa: i.gamma_pa,
            lambda_pa: i.lambda_pa,
            eps_j: i.eps_j,
            kappa_n_m: i.kappa_n_m,
            rcut_m: i.interaction.rcut_m,
            cross_eps_j: self.materials.cross.eps_j,
        })
    }
}

/// The material at this resolution: the size-invariant (gamma, lambda), eps and kappa at this
/// sigma, and the interaction constants built from them.
struct SizedMaterial {
    gamma_pa: f64,
    lambda_pa: f64,
    eps_j: f64,
    kappa_n_m: f64,
    interaction: Interaction,
}

fn require(key: &str, value: Option<f64>) -> Result<f64> {
    value.ok_or_else(|| EngineError::invalid(key, "missing", "a finite number > 0"))
}

impl SceneSpec {
    /// Validates the spec and lays out the scene.
    ///
    /// ```
    /// use hvi_scene::scene::SceneSpec;
    ///
    /// let setup = SceneSpec::calibration(500.0, 1e-7).build().expect("valid scene");
    /// assert!(setup.derived.dt_s <= setup.derived.dt_max_s);
    /// assert_eq!(setup.particles.len(), setup.particles.id.len());
    ///
    /// let mut bad = SceneSpec::calibration(500.0, 1e-7);
    /// bad.run.thermal_ratio = 0.5;
    /// let err = bad.build().expect_err("out of range");
    /// assert!(err.to_string().contains("run.thermal_ratio"));
    /// ```
    pub fn build(&self) -> Result<Setup> {
        let geometry = &self.scene;
        let Impact {
            v0_m_s: v0,
            density_kg_m3: density,
            standoff_m: standoff,
        } = geometry.validate()?;
        let r_eq = self.resolution.lattice_spacing_m(geometry)?;
        let sigma = r_eq / paper::r_eq_over_sigma();
        let sigma_ref = paper::reference_sigma_m();
        let bodies = self.sized_bodies(sigma, sigma_ref, density)?;
        let (sized, materials) = (&bodies.plate, bodies.materials);

        let symmetry = self.run.symmetry;
        let mut layout = lay_out(geometry, r_eq, symmetry)?;
        let [mass_imp, mass_tgt] = particle_masses_kg(geometry, &layout, bodies.density);

        let run = &self.run;
        run.validate()?;
        self.validate_band()?;
        self.analysis.validate(run.end_time_s)?;
        let stiffness = materials.stiffest_at_r_eq();
        let dt_max = stability_bound_s(sigma, v0, mass_imp.min(mass_tgt), stiffness);
        let dt = choose_time_step(run, dt_max, sigma, sigma_ref)?;
        place_impactor(&mut layout, standoff, r_eq)?;

        let steps = ((run.end_time_s + standoff / v0) / dt).ceil() as u64;
        let derived = Derived {
            sigma_m: sigma,
            sigma_ref_m: sigma_ref,
            r_eq_m: r_eq,
            gamma_pa: sized.gamma_pa,
            lambda_pa: sized.lambda_pa,
            eps_j: sized.eps_j,
            kappa_n_m: sized.kappa_n_m,
            rcut_m: sized.interaction.rcut_m,
            mass_impactor_kg: mass_imp,
            mass_target_kg: mass_tgt,
            density_kg_m3: density,
            impactor: bodies.impactor_derived(),
            dt_s: dt,
            dt_max_s: dt_max,
            v0_m_s: v0,
            plate_rear_z_m: layout.plate_rear_z,
            plate_front_z_m: 0.0,
            contact_time_s: standoff / v0,
            steps,
        };
        if symmetry == Symmetry::Quarter {
            layout.keep_quarter();
        }
        let particles = layout.into_particles(mass_imp, mass_tgt, v0, run.thermal_ratio, run.seed);
        let rim_ids = rim_ids(&particles, r_eq);
        Ok(Setup {
            spec: self.clone(),
            derived,
            materials,
            particles,
            rim_ids,
        })
    }
}

impl SceneSpec {
    /// The plate's and the impactor's material at `sigma`, and their densities (`density`
    /// the plate's, from the geometry).
    fn sized_bodies(&self, sigma: f64, sigma_ref: f64, density: f64) -> Result<SizedBodies> {
        let plate = self.material.sized(sigma, sigma_ref)?;
        let impactor = self.impactor.sized(&self.material, sigma, sigma_ref)?;
        let density_imp = match self.impactor.density_kg_m3 {
            Some(d) => keys::check("impactor.density_kg_m3", d)?,
            None => density,
        };
        let materials = match &impactor {
            Some(i) => Materials::two(i.interaction, plate.interaction),
            None => Materials::from(plate.interaction),
        };
        Ok(SizedBodies {
            plate,
            impactor,
            density: [density_imp, density],
            materials,
        })
    }
}

impl Resolution {
    /// The lattice spacing r_eq, m: the cube root of the volume per particle, or the sphere
    /// diameter over the particles across it.
    pub(super) fn lattice_spacing_m(&self, geometry: &Geometry) -> Result<f64> {
        match (self.particles, self.particles_across_d) {
            (Some(n), None) => {
                keys::check("resolution.particles", n)?;
                Ok((geometry.volume_m3() / n).cbrt())
            }
            (None, Some(k)) => {
                keys::check("resolution.particles_across_d", k)?;
                match *geometry {
                    Geometry::SphereOnPlate { diameter_m, .. } => Ok(diameter_m / k),
                    Geometry::FlyerPlate { .. } => Err(EngineError::invalid(
                        "resolution.particles_across_d",
                        k,
                        "only for kind = \"sphere_on_plate\"; use resolution.particles",
                    )),
                }
            }
            (Some(_), Some(_)) => Err(EngineError::Conflict(
                "give either resolution.particles or resolution.particles_across_d, \
                 not both"
                    .into(),
            )),
            (None, None) => Err(EngineError::Conflict(
                "give resolution.particles or resolution.particles_across_d".into(),
            )),
        }
    }
}

impl Material {
    /// The material at particle diameter `sigma` with geometric sizing (eq. 12: eps = gamma
    /// sigma^3, kappa = lambda sigma), or at the reference diameter `sigma_ref` without it.
    fn sized(&self, sigma: f64, sigma_ref: f64) -> Result<SizedMaterial> {
        let rcut = rcut_over_sigma("material.rcut_over_sigma", self.rcut_over_sigma)?;
        let (gamma, lambda) = self.invariants(sigma_ref)?;
        Ok(self.at_sigma(gamma, lambda, rcut, sigma, sigma_ref))
    }

    /// (gamma, lambda) as the sizing rule scales them: eps = gamma sigma^p, kappa = lambda
    /// sigma, from (eps, kappa) at `sigma_ref` or given directly.
    fn invariants(&self, sigma_ref: f64) -> Result<(f64, f64)> {
        let m = self;
        let p = m.sizing_rule.eps_power();
        match (m.eps_j, m.kappa_n_m, m.gamma_pa, m.lambda_pa) {
            (eps, kappa, None, None) => {
                let eps = keys::check("material.eps_j", require("material.eps_j", eps)?)?;
                let kappa =
                    keys::check("material.kappa_n_m", require("material.kappa_n_m", kappa)?)?;
                Ok((eps / sigma_ref.powi(p), kappa / sigma_ref))
            }
            (None, None, Some(_), _) | (None, None, _, Some(_))
                if m.sizing_rule != SizingRule::Eq12 =>
            {
                Err(EngineError::Conflict(
                    "material.gamma_pa and material.lambda_pa are the constants of eq. 12; with \
                     material.sizing_rule = \"eqs5_6\" give material.eps_j and material.kappa_n_m"
                        .into(),
                ))
            }
            (None, None, gamma, lambda) => {
                let gamma = keys::check("material.gamma_pa", require("material.gamma_pa", gamma)?)?;
                let lambda =
                    keys::check("material.lambda_pa", require("material.lambda_pa", lambda)?)?;
                Ok((gamma, lambda))
            }
            _ => Err(EngineError::Conflict(
                "give material.eps_j and material.kappa_n_m, or material.gamma_pa and \
                 material.lambda_pa, not a mix"
                    .into(),
            )),
        }
    }

    /// The material of invariants (gamma, lambda) and break distance `rcut_over_sigma` at
    /// `sigma`, under this material's sizing and contact form.
    fn at_sigma(
        &self,
        gamma: f64,
        lambda: f64,
        rcut_over_sigma: f64,
        sigma: f64,
        sigma_ref: f64,
    ) -> SizedMaterial {
        let p = self.sizing_rule.eps_power();
        let (eps, kappa) = if self.sizing {
            (gamma * sigma.powi(p), lambda * sigma)
        } else {
            // Without sizing the reference values are used at any sigma (Fig. 4, top panel).
            (gamma * sigma_ref.powi(p), lambda * sigma_ref)
        };
        // Under eqs. 5/6 eps / sigma^3 is not size-invariant; report it at this sigma.
        let gamma = match self.sizing_rule {
            SizingRule::Eq12 => gamma,
            SizingRule::Eqs5And6 => eps / sigma.powi(3),
        };
        let interaction =
            Interaction::new(sigma, eps, kappa, rcut_over_sigma * sigma, self.contact);
        SizedMaterial {
            gamma_pa: gamma,
            lambda_pa: lambda,
            eps_j: eps,
            kappa_n_m: kappa,
            interaction,
        }
    }
}

/// A break distance over sigma, checked against its interval (r_eq / sigma, 10].
fn rcut_over_sigma(key: &str, value: f64) -> Result<f64> {
    check_range(key, value, paper::r_eq_over_sigma(), true, 10.0, false)
}

impl ImpactorMaterial {
    /// The impactor's own law at `sigma`: each constant it gives replaces the plate's
    /// (`plate`), under the plate's sizing and contact form; `None` when it gives none (its
    /// density alone does not change the law).
    fn sized(&self, plate: &Material, sigma: f64, sigma_ref: f64) -> Result<Option<SizedMaterial>> {
        let own = ImpactorMaterial {
            density_kg_m3: None,
            ..self.clone()
        };
        if own.is_empty() {
            return Ok(None);
        }
        let (gamma, lambda) = plate.invariants(sigma_ref)?;
        let p = plate.sizing_rule.eps_power();
        let gamma = match (self.eps_j, self.gamma_pa) {
            (Some(_), Some(_)) => return Err(both("impactor.eps_j", "impactor.gamma_pa")),
            (Some(e), None) => keys::check("impactor.eps_j", e)? / sigma_ref.powi(p),
            (None, Some(_)) if plate.sizing_rule != SizingRule::Eq12 => {
                return Err(EngineError::Conflict(
                    "impactor.gamma_pa is a constant of eq. 12; with material.sizing_rule = \
                     \"eqs5_6\" give impactor.eps_j"
                        .into(),
                ));
            }
            (None, Some(g)) => keys::check("impactor.gamma_pa", g)?,
            (None, None) => gamma,
        };
        let lambda = match (self.kappa_n_m, self.lambda_pa) {
            (Some(_), Some(_)) => return Err(both("impactor.kappa_n_m", "impactor.lambda_pa")),
            (Some(k), None) => keys::check("impactor.kappa_n_m", k)? / sigma_ref,
            (None, Some(l)) => keys::check("impactor.lambda_pa", l)?,
            (None, None) => lambda,
        };
        let rcut = match self.rcut_over_sigma {
            Some(r) => rcut_over_sigma("impactor.rcut_over_sigma", r)?,
            None => rcut_over_sigma("material.rcut_over_sigma", plate.rcut_over_sigma)?,
        };
        Ok(Some(plate.at_sigma(gamma, lambda, rcut, sigma, sigma_ref)))
    }
}

/// The conflict of two keys that say the same thing.
fn both(a: &str, b: &str) -> EngineError {
    EngineError::Conflict(format!("give {a} or {b}, not both"))
}

/// Particle mass of the impactor and of the target, kg, from their `density` (impactor,
/// target): each body's mass over its particle count (eq. 20), so each body's mass is exact whatever the lattice rounding.
fn particle_masses_kg(geometry: &Geometry, layout: &Layout, density: [f64; 2]) -> [f64; 2] {
    let n_imp = layout.count(Body::Impactor);
    let n_tgt = layout.count(Body::Target);
    let (vol_imp, vol_tgt) = match *geometry {
        Geometry::SphereOnPlate {
            diameter_m,
            t_over_d,
            width_over_d,
            ..
        } => (
            std::f64::consts::PI / 6.0 * diameter_m.powi(3),
            (width_over_d * diameter_m).powi(2) * t_over_d * diameter_m,
        ),
        Geometry::FlyerPlate {
            flyer_thickness_m,
            target_thickness_m,
            width_m,
            ..
        } => (
            width_m * width_m * flyer_thickness_m,
            width_m * width_m * target_thickness_m,
        ),
    };
    let mass_imp = density[0] * vol_imp / n_imp as f64;
    let mass_tgt = density[1] * vol_tgt / n_tgt as f64;
    [mass_imp, mass_tgt]
}

/// Shifts the impactor back by the standoff (first contact then happens at standoff / v0) and
/// refuses bodies that overlap.
fn place_impactor(layout: &mut Layout, standoff: f64, r_eq: f64) -> Result<()> {
    if standoff < 0.0 {
        // Check the actual closest distance: a negative standoff overlaps the bodies.
        layout.shift_impactor(standoff);
        let d = layout.closest_impactor_target_distance();
        return Err(EngineError::Overlap {
            distance_m: d,
            r_eq_m: r_eq,
        });
    }
    layout.shift_impactor(standoff);
    let closest = layout.closest_impactor_target_distance();
    if closest < r_eq * (1.0 - 1e-9) {
        return Err(EngineError::Overlap {
            distance_m: closest,
            r_eq_m: r_eq,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::scene::{Geometry, SceneSpec, SizingRule};
    use crate::EngineError;

    /// Regression: a positive standoff moved the impactor towards the plate and was refused
    /// as an overlap; it moves it back, and first contact comes standoff / v0 later.
    #[test]
    fn a_standoff_moves_the_impactor_back() {
        let with = |s: f64| {
            let mut spec = SceneSpec::calibration(2000.0, 1e-6);
            if let Geometry::SphereOnPlate { standoff_m, .. } = &mut spec.scene {
                *standoff_m = s;
            }
            spec.build()
        };
        let at0 = with(0.0).expect("touching start");
        let back = with(1e-3).expect("a positive standoff is valid");
        let v0 = 6700.0;
        assert!((back.derived.contact_time_s - 1e-3 / v0).abs() < 1e-18);
        assert!(back.derived.steps > at0.derived.steps);
        assert!(matches!(with(-1e-3), Err(EngineError::Overlap { .. })));
    }

    /// The screen's keys: a time inside the run with at least one window, each window in
    /// order; every refusal names the key and what is allowed.
    #[test]
    fn a_bad_screen_is_refused_naming_its_key() {
        let with = |after: Option<f64>, r: Option<[f64; 2]>, va: Option<[f64; 2]>| {
            let mut spec = SceneSpec::calibration(2000.0, 4e-6);
            spec.run.screen_after_s = after;
            spec.run.screen_length_ratio = r;
            spec.run.screen_front_velocity_ratio = va;
            spec.build().err().map(|e| e.to_string())
        };
        assert_eq!(with(Some(1e-6), Some([1.0, 2.0]), None), None);
        assert_eq!(with(Some(1e-6), None, Some([0.5, 0.9])), None);
        assert_eq!(with(None, None, None), None);
        for (err, key, allowed) in [
            (
                with(Some(5e-6), Some([1.0, 2.0]), None),
                "run.screen_after_s",
                "below run.end_time_s",
            ),
            (
                with(Some(0.0), Some([1.0, 2.0]), None),
                "run.screen_after_s",
                "> 0",
            ),
            (
                with(Some(1e-6), None, None),
                "run.screen_after_s",
                "run.screen_length_ratio",
            ),
            (
                with(None, Some([1.0, 2.0]), None),
                "run.screen_after_s",
                "when a screen window",
            ),
            (
                with(Some(1e-6), Some([2.0, 1.0]), None),
                "run.screen_length_ratio",
                "low < high",
            ),
            (
                with(Some(1e-6), None, Some([f64::NAN, 1.0])),
                "run.screen_front_velocity_ratio",
                "finite",
            ),
        ] {
            let err = err.expect("refused");
            assert!(err.contains(key) && err.contains(allowed), "{err}");
        }
    }

    /// eq. 12 scales eps with sigma^3, the printed eqs. 5/6 with sigma; kappa with sigma in
    /// both, and at the reference sigma the two agree.
    #[test]
    fn the_sizing_rules_scale_eps_as_they_say() {
        let at = |n: f64, rule: SizingRule| {
            let mut spec = SceneSpec::calibration(n, 1e-6);
            spec.material.sizing_rule = rule;
            spec.build().expect("valid scene").derived
        };
        let (a, b) = (
            at(2000.0, SizingRule::Eq12),
            at(2000.0, SizingRule::Eqs5And6),
        );
        let s = a.sigma_m / a.sigma_ref_m;
        assert!(
            s > 2.0,
            "2000 particles are coarser than the reference: {s}"
        );
        assert!((a.eps_j / (0.01 * s.powi(3)) - 1.0).abs() < 1e-12);
        assert!((b.eps_j / (0.01 * s) - 1.0).abs() < 1e-12);
        assert_eq!(a.kappa_n_m, b.kappa_n_m);
        assert!((b.gamma_pa - b.eps_j / b.sigma_m.powi(3)).abs() <= 1e-12 * b.gamma_pa);
        let mut spec = SceneSpec::calibration(2000.0, 1e-6);
        spec.material.sizing_rule = SizingRule::Eqs5And6;
        spec.material.eps_j = None;
        spec.material.kappa_n_m = None;
        spec.material.gamma_pa = Some(1e9);
        spec.material.lambda_pa = Some(1e10);
        let e = spec
            .build()
            .expect_err("gamma with eqs5_6 is a conflict")
            .to_string();
        assert!(e.contains("material.sizing_rule"), "{e}");
        // The default rule is not serialised: fingerprints of existing scenes are unchanged.
        let json = serde_json::to_string(&SceneSpec::calibration(2000.0, 1e-6)).expect("json");
        assert!(!json.contains("sizing_rule"), "{json}");
    }
}
