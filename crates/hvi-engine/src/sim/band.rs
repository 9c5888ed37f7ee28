//! The absorbing band at the plate's lateral edge (`run.absorbing_band_over_d`): a sponge
//! layer. In a band of width w inside the plate's edge, each target particle's velocity decays
//! at the rate gamma(s) = gamma_max (s / w)^2, s its depth into the band at t = 0, so that a
//! stress wave running out through the band is damped on its way in and out instead of
//! reflecting off the free edge back to the impact. A narrower plate then stands for a wider
//! one as far as the waves go (not as far as the plate's mass in the cloud goes: what the band
//! buys is measured in `reports/benchmark-0.6.0`).
//!
//! gamma_max = [`BAND_ABSORPTION`] c / w, c the lattice's sound speed r_eq sqrt(k / m) (k the
//! stiffest pair law at r_eq): a wave crossing the band and back is damped by about
//! exp(-2 gamma_max w / (3 c)) = exp(-4). The profile rises from zero, so the band's own
//! inner edge reflects little. The band damps towards rest, as a clamp far away would; the
//! energy it takes out is booked in the ledger (`Energy::absorbed_j`), and momentum is not
//! conserved with a band (the clamp takes it).

use glam::DVec3;

use crate::potential::Interaction;
use crate::scene::{Geometry, SceneSpec};
use crate::state::{Body, Particles};

/// gamma_max w / c of the band (see the module).
pub const BAND_ABSORPTION: f64 = 6.0;

/// The band of a scene: its width, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AbsorbingBand {
    /// Width of the band inside the plate's lateral edge, m.
    pub width_m: f64,
}

impl AbsorbingBand {
    /// The band a scene asks for (`run.absorbing_band_over_d` > 0 on a sphere-on-plate
    /// scene), or none.
    pub fn of_scene(spec: &SceneSpec) -> Option<Self> {
        let w = spec.run.absorbing_band_over_d;
        match spec.scene {
            Geometry::SphereOnPlate { diameter_m, .. } if w > 0.0 => Some(AbsorbingBand {
                width_m: w * diameter_m,
            }),
            _ => None,
        }
    }

    /// The damping rate of each particle by id, 1/s: zero outside the band and for the
    /// impactor. `p` in its initial order (index = id). The edge is the outermost target
    /// particle's lateral coordinate, max(|x|, |y|).
    pub fn damping_by_id(&self, p: &Particles, ia: &Interaction) -> Vec<f64> {
        let lateral = |x: DVec3| x.x.abs().max(x.y.abs());
        let targets = || (0..p.len()).filter(|&k| p.body[k] == Body::Target);
        let edge = targets().fold(0.0f64, |a, k| a.max(lateral(p.pos[k])));
        let m_target = targets().map(|k| p.mass[k]).fold(f64::INFINITY, f64::min);
        let k = ia.stiffness_at(ia.r_eq2());
        let c = ia.r_eq_m * (k / m_target).sqrt();
        let gamma_max = BAND_ABSORPTION * c / self.width_m;
        let mut by_id = vec![0.0; p.len()];
        for i in targets() {
            let depth = lateral(p.pos[i]) - (edge - self.width_m);
            if depth > 0.0 {
                let s = (depth / self.width_m).min(1.0);
                by_id[p.id[i] as usize] = gamma_max * s * s;
            }
        }
        by_id
    }
}

/// Damps `v` at rate `gamma` over `dt` (v -> v exp(-gamma dt)) and returns the kinetic energy
/// taken out, J, for a particle of mass `mass`.
#[inline(always)]
pub(super) fn damp(v: &mut DVec3, gamma: f64, dt: f64, mass: f64) -> f64 {
    let before = v.length_squared();
    *v *= (-gamma * dt).exp();
    0.5 * mass * (before - v.length_squared())
}
