//! Quarter symmetry (`run.symmetry = "quarter"`): a normal impact of a sphere on a square plate
//! centred on the impact axis is symmetric under x -> -x and y -> -y, so only the quarter
//! x > 0, y > 0 is simulated and the other three are its mirror images, as hydrocode users
//! model hypervelocity impact routinely.
//!
//! The lattice is laid out so that no particle lies on a mirror plane (an even number of sites
//! per side: the planes pass half-way between lattice layers). Across a plane the simulated
//! particles interact with mirror images of simulated particles:
//! - contact pairs: the neighbour list holds, besides the ordinary pairs, pairs (i, M j) with
//!   M a reflection (`MIRROR_X`, `MIRROR_Y` or both), the image's position and velocity those
//!   of j reflected ([`reflect`]);
//! - bonds: the lattice bonds that cross a plane join a particle of the layer next to it to
//!   its own image (x = r_eq / 2 to x = -r_eq / 2): these are [`crate::state::Particles`]'s
//!   `image_bonds`, one flag per plane.
//!
//! Each pair (i, M j) stands for a pair of the full scene that crosses a plane, and the full
//! scene holds two of those for each such pair of the quarter; the force on i is the full
//! pair force, and the pair's energy counts one half in the quarter's ledger. The quarter's
//! ledger is then exactly a quarter of the full scene's (the quarter is a Hamiltonian system
//! whose energy is that quarter), so the engine reports energies, bond counts and momentum of
//! the full scene ([`QUARTER_COPIES`] times the quarter's); x and y momentum of the full scene
//! are zero by symmetry, and z momentum is conserved exactly as in a full run (every pair
//! (i, M j) has its partner (j, M i) with the opposite z force).
//!
//! What a user sees is the full scene: [`unfold`] builds the four copies (positions,
//! velocities, bonds with their ownership and broken flags), and the cloud's measurement and
//! every output read that.

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::state::{Particles, BONDS_PER_PARTICLE, BROKEN_FLAG, INDEX_MASK, NO_BOND};

/// Which part of the scene is simulated.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Symmetry {
    /// The whole scene.
    #[default]
    Full,
    /// The quarter x > 0, y > 0 (normal impact on a square plate centred on the axis).
    Quarter,
}

impl Symmetry {
    /// Copies of the simulated particles that make the full scene.
    pub fn copies(self) -> f64 {
        match self {
            Symmetry::Full => 1.0,
            Symmetry::Quarter => QUARTER_COPIES,
        }
    }
}

/// Copies of the quarter in the full scene.
pub const QUARTER_COPIES: f64 = 4.0;
/// Reflection x -> -x (an image code; codes combine as bits).
pub const MIRROR_X: u32 = 1;
/// Reflection y -> -y.
pub const MIRROR_Y: u32 = 2;
/// Where an image pair's code sits in a neighbour-list entry (the index below it).
pub const IMAGE_SHIFT: u32 = 30;
/// Mask of the partner index in an image-list entry.
pub const IMAGE_INDEX_MASK: u32 = (1 << IMAGE_SHIFT) - 1;
/// `image_bonds` flag: the particle is bonded to its own image across x = 0 (intact, or
/// broken since the last neighbour build and still repelling through the bond).
pub const IMAGE_BOND_X: u8 = 1;
/// `image_bonds` flag: bonded to its own image across y = 0.
pub const IMAGE_BOND_Y: u8 = 2;
/// `image_bonds` flag: the bond across x = 0 broke since the last neighbour build.
pub const IMAGE_BROKEN_X: u8 = 4;
/// `image_bonds` flag: the bond across y = 0 broke since the last neighbour build.
pub const IMAGE_BROKEN_Y: u8 = 8;

/// The sign of each component under each image code (index = code).
const SIGNS: [DVec3; 4] = [
    DVec3::new(1.0, 1.0, 1.0),
    DVec3::new(-1.0, 1.0, 1.0),
    DVec3::new(1.0, -1.0, 1.0),
    DVec3::new(-1.0, -1.0, 1.0),
];

/// `v` reflected by the image code `code` (bits `MIRROR_X`, `MIRROR_Y`): exact (a sign flip).
#[inline(always)]
pub fn reflect(v: DVec3, code: u32) -> DVec3 {
    v * SIGNS[(code & 3) as usize]
}

/// The image-bond flags of plane `code` (`MIRROR_X` or `MIRROR_Y`): (bond, broken).
#[inline]
pub fn image_bond_flags(code: u32) -> (u8, u8) {
    if code == MIRROR_X {
        (IMAGE_BOND_X, IMAGE_BROKEN_X)
    } else {
        (IMAGE_BOND_Y, IMAGE_BROKEN_Y)
    }
}

/// Whether `flags` hold an intact image bond across plane `code` (`MIRROR_X` or `MIRROR_Y`):
/// present and not broken since the build.
#[inline]
pub fn image_bond_intact(flags: u8, code: u32) -> bool {
    let (bond, broken) = image_bond_flags(code);
    flags & bond != 0 && flags & broken == 0
}

/// Forgets image bonds that broke since the last build (the pair joins the image list).
pub fn clear_broken_image_bonds(flags: &mut [u8]) {
    for f in flags {
        for code in [MIRROR_X, MIRROR_Y] {
            let (bond, broken) = image_bond_flags(code);
            if *f & broken != 0 {
                *f &= !(bond | broken);
            }
        }
    }
}

/// Intact image bonds of the simulated particles.
pub fn intact_image_bonds(p: &Particles) -> usize {
    p.image_bonds
        .iter()
        .map(|&f| {
            [MIRROR_X, MIRROR_Y]
                .into_iter()
                .filter(|&c| image_bond_intact(f, c))
                .count()
        })
        .sum()
}

/// The ids of `ids` (of a quarter of `n` particles) and of their three images in
/// [`unfold`]'s numbering: copy k of id i is k n + i.
pub fn unfold_ids(ids: &[u32], n: usize) -> Vec<u32> {
    (0..4u32)
        .flat_map(|k| ids.iter().map(move |&i| k * n as u32 + i))
        .collect()
}

/// The full scene of a quarter: copy k (0..4, its image code) of particle i is particle
/// k n + i, with id k n + id; positions, velocities and forces reflected; bonds in the
/// slot convention of [`crate::state`] (the owner of a bond is its end towards -axis, so a
/// reflected axis swaps owned and mirror slots and the broken flag moves to the new owner),
/// and each image bond joining copy k to copy k ^ plane. A particle set without image bonds
/// (a full scene) comes back as it is.
pub fn unfold(p: &Particles) -> Particles {
    if p.image_bonds.is_empty() {
        return p.clone();
    }
    let n = p.len();
    let mut out = Particles {
        pos: Vec::with_capacity(4 * n),
        vel: Vec::with_capacity(4 * n),
        force: Vec::with_capacity(4 * n),
        mass: Vec::with_capacity(4 * n),
        inv_mass: Vec::with_capacity(4 * n),
        body: Vec::with_capacity(4 * n),
        id: Vec::with_capacity(4 * n),
        bonds: vec![NO_BOND; 4 * n * BONDS_PER_PARTICLE],
        image_bonds: Vec::new(),
    };
    for k in 0..4u32 {
        let shift = k * n as u32;
        out.pos.par_extend(p.pos.par_iter().map(|&x| reflect(x, k)));
        out.vel.par_extend(p.vel.par_iter().map(|&v| reflect(v, k)));
        out.force
            .par_extend(p.force.par_iter().map(|&f| reflect(f, k)));
        out.mass.extend_from_slice(&p.mass);
        out.inv_mass.extend_from_slice(&p.inv_mass);
        out.body.extend_from_slice(&p.body);
        out.id.extend(p.id.iter().map(|&id| id + shift));
    }
    out.bonds
        .par_chunks_mut(BONDS_PER_PARTICLE)
        .enumerate()
        .for_each(|(g, dst)| unfold_slots(p, (g / n) as u32, g % n, dst));
    out
}

/// The bond slots `dst` of copy `k` of particle `i` of the quarter `p` (see [`unfold`]).
fn unfold_slots(p: &Particles, k: u32, i: usize, dst: &mut [u32]) {
    let n = p.len() as u32;
    let shift = k * n;
    let src = &p.bonds[i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE];
    for m in 0..3 {
        let plane = if m < 2 { 1u32 << m } else { 0 };
        let flipped = k & plane != 0;
        let (owned, mirror) = (src[2 * m], src[2 * m + 1]);
        // The image bond across this axis's plane, if any: (partner copy, broken).
        let image = (plane != 0)
            .then(|| image_bond_flags(plane))
            .filter(|&(bond, _)| p.image_bonds[i] & bond != 0)
            .map(|(_, broken)| {
                let partner = (k ^ plane) * n + i as u32;
                let flag = if p.image_bonds[i] & broken != 0 {
                    BROKEN_FLAG
                } else {
                    0
                };
                (partner, flag)
            });
        let moved = |s: u32| {
            if s == NO_BOND {
                NO_BOND
            } else {
                ((s & INDEX_MASK) + shift) | (s & BROKEN_FLAG)
            }
        };
        if !flipped {
            dst[2 * m] = moved(owned);
            dst[2 * m + 1] = match image {
                Some((partner, _)) => partner,
                None => moved(mirror),
            };
        } else {
            // Towards +axis in the copy is towards -axis in the quarter.
            dst[2 * m] = match image {
                Some((partner, flag)) => partner | flag,
                None if mirror == NO_BOND => NO_BOND,
                None => {
                    let j = mirror as usize;
                    let flag = p.bonds[j * BONDS_PER_PARTICLE + 2 * m] & BROKEN_FLAG;
                    (mirror + shift) | flag
                }
            };
            dst[2 * m + 1] = if owned == NO_BOND {
                NO_BOND
            } else {
                (owned & INDEX_MASK) + shift
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::Body;

    /// Two particles in a row along x next to the plane x = 0 (the first bonded to its image
    /// and to the second), and a third above the first along y, bonded to it and to its own
    /// image across y = 0... laid out as a quarter.
    fn quarter() -> Particles {
        let r = 1.0;
        let pos = vec![
            DVec3::new(0.5 * r, 0.5 * r, 0.0),
            DVec3::new(1.5 * r, 0.5 * r, 0.0),
            DVec3::new(0.5 * r, 1.5 * r, 0.0),
        ];
        let mut bonds = vec![NO_BOND; 3 * BONDS_PER_PARTICLE];
        // 0 -> 1 along +x (0 owns), 0 -> 2 along +y (0 owns).
        bonds[0] = 1;
        bonds[BONDS_PER_PARTICLE + 1] = 0;
        bonds[2] = 2;
        bonds[2 * BONDS_PER_PARTICLE + 3] = 0;
        let vel = vec![DVec3::new(1.0, 2.0, 3.0); 3];
        let mut p = Particles::new(pos, vel, vec![1.0; 3], vec![Body::Target; 3], bonds);
        p.image_bonds = vec![IMAGE_BOND_X | IMAGE_BOND_Y, IMAGE_BOND_Y, IMAGE_BOND_X];
        p
    }

    #[test]
    fn unfolding_gives_the_full_lattice_with_every_bond_once() {
        let q = quarter();
        let f = unfold(&q);
        assert_eq!(f.len(), 12);
        // Bonds of the full 4 x 3 arrangement: within each copy 2, across x: particles 0 and
        // 2 of each x pair of copies (2 pairs x 2), across y: particles 0 and 1 (2 x 2).
        assert_eq!(f.intact_bonds(), 4 * 2 + 4 + 4);
        // Every owned slot points at a particle one lattice step away along its +axis, and
        // the partner's mirror slot points back.
        for i in 0..f.len() {
            for m in 0..3 {
                let s = f.bonds[i * BONDS_PER_PARTICLE + 2 * m];
                if s == NO_BOND {
                    continue;
                }
                let j = (s & INDEX_MASK) as usize;
                let d = f.pos[j] - f.pos[i];
                let mut e = DVec3::ZERO;
                e[m] = 1.0;
                assert!((d - e).length() < 1e-12, "slot {m} of {i}: {d}");
                assert_eq!(f.bonds[j * BONDS_PER_PARTICLE + 2 * m + 1], i as u32);
            }
        }
        // Momentum along x and y cancels; velocities are reflected.
        let px: f64 = f.vel.iter().map(|v| v.x).sum();
        assert_eq!(px, 0.0);
        // Particle 0 of copy 1 (reflected across x = 0).
        assert_eq!(f.vel[3], DVec3::new(-1.0, 2.0, 3.0));
    }

    #[test]
    fn a_broken_image_bond_unfolds_broken_on_its_owner() {
        let mut q = quarter();
        q.image_bonds[0] |= IMAGE_BROKEN_X;
        let f = unfold(&q);
        assert_eq!(f.intact_bonds(), 4 * 2 + 4 + 4 - 2);
        assert_eq!(intact_image_bonds(&q), 3);
        let mut flags = q.image_bonds.clone();
        clear_broken_image_bonds(&mut flags);
        assert_eq!(flags[0], IMAGE_BOND_Y);
    }

    #[test]
    fn ids_unfold_copy_by_copy() {
        assert_eq!(unfold_ids(&[0, 2], 3), vec![0, 2, 3, 5, 6, 8, 9, 11]);
    }
}
