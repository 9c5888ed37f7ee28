//! The pair interactions of the model (paper eqs. 3 and 4), defined once.
//!
//! * Contact repulsion, every pair closer than r_eq = 2^(1/6) sigma:
//!   `phi_rep(r) = c eps [(sigma/r)^12 - (sigma/r)^6] + c eps / 4`, with `c = 1` for the form
//!   printed in the paper and `c = 4` for the usual WCA form. The shift `c eps / 4` makes the
//!   energy zero at r_eq, so energy is continuous there (the printed `+ eps` is not; see
//!   docs/model.md section 3).
//! * Cohesive spring, intact bonds stretched past r_eq: `phi_coh(r) = kappa/2 (r - r_eq)^2`.
//! * A bond breaks for good the first time `r > rcut`.
//!
//! All quantities here are SI at the actual particle diameter (after geometric sizing).

use serde::{Deserialize, Serialize};

use crate::state::Body;

/// Which prefactor the contact repulsion carries (docs/model.md section 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ContactForm {
    /// `eps [(s/r)^12 - (s/r)^6] + eps/4`: the prefactor as printed in eq. (3).
    #[default]
    Printed,
    /// `4 eps [(s/r)^12 - (s/r)^6] + eps`: the Weeks-Chandler-Andersen form.
    Wca,
}

impl ContactForm {
    /// The prefactor c multiplying eps.
    pub fn prefactor(self) -> f64 {
        match self {
            ContactForm::Printed => 1.0,
            ContactForm::Wca => 4.0,
        }
    }

    /// Name used in files and reports.
    pub fn name(self) -> &'static str {
        match self {
            ContactForm::Printed => "printed",
            ContactForm::Wca => "wca",
        }
    }
}

/// The interaction constants at the actual particle diameter, ready for the kernels.
///
/// ```
/// use hvi_scene::potential::{ContactForm, Interaction};
///
/// // sigma = 1, eps = 1, kappa = 10, rcut = 1.5 sigma, in any consistent units.
/// let ia = Interaction::new(1.0, 1.0, 10.0, 1.5, ContactForm::Printed);
/// // The repulsion (eq. 3, shifted) is zero at r_eq = 2^(1/6) sigma and eps / 4 at sigma.
/// assert_eq!(ia.contact_energy(ia.r_eq2()), 0.0);
/// assert!((ia.contact_energy(1.0) - 0.25).abs() < 1e-15);
/// // A bond breaking at rcut holds kappa / 2 (rcut - r_eq)^2 (eq. 4).
/// let stretch = 1.5 - ia.r_eq_m;
/// assert!((ia.break_energy_at_rcut() - 5.0 * stretch * stretch).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Interaction {
    /// Particle diameter sigma, m.
    pub sigma_m: f64,
    /// Repulsion strength eps at this sigma, J.
    pub eps_j: f64,
    /// Spring stiffness kappa at this sigma, N/m.
    pub kappa_n_m: f64,
    /// Bond break distance rcut, m.
    pub rcut_m: f64,
    /// Contact prefactor form.
    pub contact: ContactForm,
    /// Zero-force distance r_eq = 2^(1/6) sigma, m.
    pub r_eq_m: f64,
    // Kernel constants.
    c_eps: f64,
    sigma2: f64,
    r_eq2: f64,
    rcut2: f64,
}

impl Interaction {
    /// Interaction constants for the given diameter and (already sized) eps, kappa, rcut.
    pub fn new(
        sigma_m: f64,
        eps_j: f64,
        kappa_n_m: f64,
        rcut_m: f64,
        contact: ContactForm,
    ) -> Self {
        let r_eq_m = sigma_m * crate::paper::r_eq_over_sigma();
        Interaction {
            sigma_m,
            eps_j,
            kappa_n_m,
            rcut_m,
            contact,
            r_eq_m,
            c_eps: contact.prefactor() * eps_j,
            sigma2: sigma_m * sigma_m,
            r_eq2: r_eq_m * r_eq_m,
            rcut2: rcut_m * rcut_m,
        }
    }

    /// r_eq^2, m^2: pairs closer than this repel.
    #[inline(always)]
    pub fn r_eq2(&self) -> f64 {
        self.r_eq2
    }

    /// rcut^2, m^2: bonds longer than this break.
    #[inline(always)]
    pub fn rcut2(&self) -> f64 {
        self.rcut2
    }

    /// Contact repulsion energy at squared distance `r2` (J); zero for r >= r_eq.
    #[inline(always)]
    pub fn contact_energy(&self, r2: f64) -> f64 {
        if r2 >= self.r_eq2 {
            return 0.0;
        }
        let s6 = (self.sigma2 / r2).powi(3);
        self.c_eps * (s6 * s6 - s6 + 0.25)
    }

    /// Contact repulsion force divided by distance, F(r)/r (N/m), valid for r < r_eq.
    ///
    /// The force on particle i from j is `(x_i - x_j) * contact_force_over_r(r2)`.
    /// The caller checks `r2 < r_eq2()`; this function does not.
    #[inline(always)]
    pub fn contact_force_over_r(&self, r2: f64) -> f64 {
        let inv_r2 = 1.0 / r2;
        let s6 = (self.sigma2 * inv_r2).powi(3);
        self.c_eps * (12.0 * s6 * s6 - 6.0 * s6) * inv_r2
    }

    /// Spring energy of an intact bond at distance `r` (J); zero for r <= r_eq.
    #[inline(always)]
    pub fn spring_energy(&self, r: f64) -> f64 {
        if r <= self.r_eq_m {
            return 0.0;
        }
        let stretch = r - self.r_eq_m;
        0.5 * self.kappa_n_m * stretch * stretch
    }

    /// Spring force divided by distance (N/m, negative = attractive), valid for r > r_eq.
    ///
    /// The force on particle i from its bond partner j is `(x_i - x_j) * spring_force_over_r(r)`.
    #[inline(always)]
    pub fn spring_force_over_r(&self, r: f64) -> f64 {
        -self.kappa_n_m * (r - self.r_eq_m) / r
    }

    /// Spring force divided by distance from the squared distance (one sqrt, one division).
    #[inline(always)]
    pub fn spring_force_over_r2(&self, r2: f64) -> f64 {
        self.kappa_n_m * (self.r_eq_m / r2.sqrt() - 1.0)
    }

    /// Both F/r of the contact repulsion and of the spring at squared distance `r2`, with one
    /// square root and one division (the bond kernel needs both to stay branch-free).
    #[inline(always)]
    pub fn contact_and_spring_force_over_r(&self, r2: f64) -> (f64, f64) {
        let inv_r = 1.0 / r2.sqrt();
        let inv_r2 = inv_r * inv_r;
        let s6 = (self.sigma2 * inv_r2).powi(3);
        (
            self.c_eps * (12.0 * s6 * s6 - 6.0 * s6) * inv_r2,
            self.kappa_n_m * (self.r_eq_m * inv_r - 1.0),
        )
    }

    /// Energy one bond holds when it breaks exactly at rcut (J).
    pub fn break_energy_at_rcut(&self) -> f64 {
        self.spring_energy(self.rcut_m)
    }

    /// Stiffness of the contact repulsion at r_eq, d^2 phi / dr^2 (N/m): 18 c eps / r_eq^2.
    pub fn contact_stiffness_at_r_eq(&self) -> f64 {
        18.0 * self.c_eps / self.r_eq2
    }

    /// The stiffest pair law at squared distance `r2` (N/m): the contact repulsion's
    /// d^2 phi / dr^2 = c eps (156 s^12 / r^14 - 42 s^6 / r^8) at min(r, r_eq), or kappa if
    /// larger. The adaptive step resolves the closest pair with it.
    pub fn stiffness_at(&self, r2: f64) -> f64 {
        let r2 = r2.min(self.r_eq2);
        let s6 = (self.sigma2 / r2).powi(3);
        let contact = self.c_eps * (156.0 * s6 * s6 - 42.0 * s6) / r2;
        contact.max(self.kappa_n_m)
    }
}

/// The pair laws of a scene: the plate's, the impactor's and the one between them.
///
/// Both bodies share the lattice, so sigma and r_eq (and the contact form) are common; eps,
/// kappa and rcut may differ. Bonds never join the two bodies, so a bond takes its body's
/// law; a contact between the bodies takes the combining rule eps = sqrt(eps_impactor
/// eps_plate) (Lorentz-Berthelot with one sigma; docs/model.md section 3, "Two materials").
///
/// ```
/// use hvi_scene::potential::{ContactForm, Materials};
/// use hvi_scene::potential::Interaction;
///
/// let plate = Interaction::new(1.0, 1.0, 10.0, 1.5, ContactForm::Printed);
/// let sphere = Interaction::new(1.0, 4.0, 30.0, 1.4, ContactForm::Printed);
/// let m = Materials::two(sphere, plate);
/// assert!(!m.is_one());
/// assert_eq!(m.cross.eps_j, 2.0);
/// assert!(Materials::from(plate).is_one());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Materials {
    /// The target plate's law.
    pub target: Interaction,
    /// The impactor's law.
    pub impactor: Interaction,
    /// The law between an impactor and a plate particle (contact only).
    pub cross: Interaction,
}

impl From<Interaction> for Materials {
    fn from(ia: Interaction) -> Self {
        Materials {
            target: ia,
            impactor: ia,
            cross: ia,
        }
    }
}

impl Materials {
    /// The laws of an impactor and a plate of different materials on one lattice.
    ///
    /// # Panics
    /// If the two laws have different sigma or contact forms (one lattice, one law shape).
    pub fn two(impactor: Interaction, target: Interaction) -> Self {
        assert_eq!(impactor.sigma_m, target.sigma_m, "one lattice: one sigma");
        assert_eq!(impactor.contact, target.contact, "one contact form");
        let cross = Interaction::new(
            target.sigma_m,
            (impactor.eps_j * target.eps_j).sqrt(),
            0.0,
            target.rcut_m.min(impactor.rcut_m),
            target.contact,
        );
        Materials {
            target,
            impactor,
            cross,
        }
    }

    /// Whether both bodies are of one material (the kernels then take their one-law path,
    /// bit for bit what they computed before there were two).
    pub fn is_one(&self) -> bool {
        self.impactor == self.target
    }

    /// The law of a body's bonds.
    #[inline(always)]
    pub fn of_body(&self, b: Body) -> &Interaction {
        match b {
            Body::Impactor => &self.impactor,
            Body::Target => &self.target,
        }
    }

    /// The contact law between particles of bodies `a` and `b`.
    #[inline(always)]
    pub fn of_pair(&self, a: Body, b: Body) -> &Interaction {
        match (a, b) {
            (Body::Impactor, Body::Impactor) => &self.impactor,
            (Body::Target, Body::Target) => &self.target,
            _ => &self.cross,
        }
    }

    /// The stiffest law at r_eq (N/m): the largest of each law's kappa and contact stiffness
    /// at r_eq, what the time step's stability bound takes.
    pub fn stiffest_at_r_eq(&self) -> f64 {
        [self.target, self.impactor, self.cross]
            .iter()
            .map(|ia| ia.kappa_n_m.max(ia.contact_stiffness_at_r_eq()))
            .fold(0.0, f64::max)
    }

    /// The stiffest law at squared distance `r2` (N/m), over both bodies and the contact
    /// between them: what the adaptive step resolves.
    pub fn stiffness_at(&self, r2: f64) -> f64 {
        [self.target, self.impactor, self.cross]
            .iter()
            .map(|ia| ia.stiffness_at(r2))
            .fold(0.0, f64::max)
    }
}

/// How a kernel finds the law of a pair: one law for every pair ([`Interaction`], the fast
/// path) or by the bodies of the two particles ([`Materials`] with two materials). The
/// kernels are generic over it, so the one-material path compiles to what it was.
pub trait PairLaw: Copy + Send + Sync {
    /// The law of particle `i`'s bonds (`bodies` indexed by current particle index).
    fn bond(&self, bodies: &[Body], i: usize) -> &Interaction;
    /// The contact law between particles `i` and `j`.
    fn contact(&self, bodies: &[Body], i: usize, j: usize) -> &Interaction;
}

impl PairLaw for Interaction {
    #[inline(always)]
    fn bond(&self, _: &[Body], _: usize) -> &Interaction {
        self
    }
    #[inline(always)]
    fn contact(&self, _: &[Body], _: usize, _: usize) -> &Interaction {
        self
    }
}

impl PairLaw for Materials {
    #[inline(always)]
    fn bond(&self, bodies: &[Body], i: usize) -> &Interaction {
        self.of_body(bodies[i])
    }
    #[inline(always)]
    fn contact(&self, bodies: &[Body], i: usize, j: usize) -> &Interaction {
        self.of_pair(bodies[i], bodies[j])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stiffness_is_the_second_derivative() {
        for form in [ContactForm::Printed, ContactForm::Wca] {
            let ia = unit(form);
            assert!(
                (ia.stiffness_at(ia.r_eq2()) - ia.contact_stiffness_at_r_eq().max(ia.kappa_n_m))
                    .abs()
                    < 1e-9
            );
            for r in [0.8, 0.9, 1.0, 1.1] {
                let h = 1e-5;
                let e = |x: f64| ia.contact_energy(x * x);
                let fd = (e(r + h) - 2.0 * e(r) + e(r - h)) / (h * h);
                let k = ia.stiffness_at(r * r);
                assert!(
                    (k - fd.max(ia.kappa_n_m)).abs() < 1e-4 * k,
                    "r {r}: {k} vs {fd}"
                );
            }
            // Beyond r_eq the contact law is flat: its value at r_eq (or kappa) applies.
            assert_eq!(
                ia.stiffness_at(4.0 * ia.r_eq2()),
                ia.stiffness_at(ia.r_eq2())
            );
        }
    }

    fn unit(form: ContactForm) -> Interaction {
        // sigma = 1, eps = 1, kappa = 10, rcut = 1.5 in any consistent units.
        Interaction::new(1.0, 1.0, 10.0, 1.5, form)
    }

    #[test]
    fn contact_energy_hand_values() {
        let p = unit(ContactForm::Printed);
        let r_eq = 2f64.powf(1.0 / 6.0);
        assert!(p.contact_energy(r_eq * r_eq).abs() < 1e-15);
        // At r = sigma: (1 - 1) + 1/4.
        assert!((p.contact_energy(1.0) - 0.25).abs() < 1e-15);
        // At r = 0.9: s6 = 0.9^-6.
        let s6 = 0.9f64.powi(-6);
        assert!((p.contact_energy(0.81) - (s6 * s6 - s6 + 0.25)).abs() < 1e-12);
        let w = unit(ContactForm::Wca);
        assert!((w.contact_energy(1.0) - 1.0).abs() < 1e-15);
        assert!((w.contact_energy(0.81) - 4.0 * (s6 * s6 - s6 + 0.25)).abs() < 1e-11);
        // Beyond r_eq there is no repulsion.
        assert_eq!(p.contact_energy(1.3), 0.0);
    }

    #[test]
    fn contact_force_hand_values_and_derivative() {
        let p = unit(ContactForm::Printed);
        // At r = sigma: F = (12 - 6) / r, F/r = 6.
        assert!((p.contact_force_over_r(1.0) - 6.0).abs() < 1e-14);
        let w = unit(ContactForm::Wca);
        assert!((w.contact_force_over_r(1.0) - 24.0).abs() < 1e-13);
        // Zero force at r_eq.
        let r_eq2 = 2f64.powf(1.0 / 3.0);
        assert!(p.contact_force_over_r(r_eq2).abs() < 1e-12);
        // F = -dphi/dr by central differences.
        for r in [0.8, 0.9, 1.0, 1.1] {
            let h = 1e-6;
            let de = (p.contact_energy((r + h) * (r + h)) - p.contact_energy((r - h) * (r - h)))
                / (2.0 * h);
            let f = p.contact_force_over_r(r * r) * r;
            assert!(
                (f + de).abs() < 1e-6 * f.abs().max(1.0),
                "r={r} f={f} de={de}"
            );
        }
    }

    #[test]
    fn spring_hand_values() {
        let p = unit(ContactForm::Printed);
        let r_eq = 2f64.powf(1.0 / 6.0);
        assert_eq!(p.spring_energy(r_eq - 0.01), 0.0);
        assert!((p.spring_energy(r_eq + 0.1) - 0.5 * 10.0 * 0.01).abs() < 1e-14);
        assert!((p.spring_force_over_r(r_eq + 0.1) * (r_eq + 0.1) + 1.0).abs() < 1e-13);
        assert!((p.break_energy_at_rcut() - 0.5 * 10.0 * (1.5 - r_eq).powi(2)).abs() < 1e-14);
        assert!((p.contact_stiffness_at_r_eq() - 18.0 / (r_eq * r_eq)).abs() < 1e-12);
    }
}
