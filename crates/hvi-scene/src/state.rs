//! Particle state as a structure of arrays, and bonds as fixed slots per particle.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Bond slots per particle: a simple cubic lattice site has six nearest neighbours. Slot
/// `2m` (m = 0, 1, 2 for x, y, z) is the bond towards +m, which this particle *owns*: the force
/// and the break of that bond are computed once, by its owner. Slot `2m + 1` is the mirror:
/// the partner towards -m, whose slot `2m` owns the bond.
pub const BONDS_PER_PARTICLE: usize = 6;
/// Owned bonds per particle (+x, +y, +z).
pub const OWNED_BONDS: usize = 3;
/// An empty bond slot.
pub const NO_BOND: u32 = u32::MAX;
/// Flag bit of an owned slot whose bond broke since the last neighbour-list build. The pair
/// still repels through the slot until the next build puts it on the ordinary pair list (then
/// both the owned and the mirror slot are cleared).
pub const BROKEN_FLAG: u32 = 1 << 31;
/// Mask of the partner index in a slot.
pub const INDEX_MASK: u32 = !BROKEN_FLAG;

/// Which body a particle belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[repr(u8)]
pub enum Body {
    /// The sphere (or flyer plate).
    Impactor = 0,
    /// The target plate.
    Target = 1,
}

/// All particles. Index `i` is the particle's current storage slot; particles are re-sorted
/// along the cell grid at every neighbour-list build, so `id[i]` is the stable identity
/// (its index at t = 0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Particles {
    /// Positions, m.
    pub pos: Vec<DVec3>,
    /// Velocities, m/s.
    pub vel: Vec<DVec3>,
    /// Forces, N.
    pub force: Vec<DVec3>,
    /// Masses, kg.
    pub mass: Vec<f64>,
    /// Inverse masses, 1/kg.
    pub inv_mass: Vec<f64>,
    /// Body of each particle.
    pub body: Vec<Body>,
    /// Stable identity (index at t = 0).
    pub id: Vec<u32>,
    /// `BONDS_PER_PARTICLE` slots per particle: the partner's current index, `NO_BOND`, or a
    /// partner index with `BROKEN_FLAG` set.
    pub bonds: Vec<u32>,
    /// Under quarter symmetry ([`crate::symmetry`]), each particle's bonds to its own mirror
    /// images across the planes x = 0 and y = 0 (`IMAGE_BOND_X`, `IMAGE_BOND_Y`, each with
    /// its broken-since-the-build flag); empty for a full scene.
    #[serde(default)]
    pub image_bonds: Vec<u8>,
}

impl Particles {
    /// Particles in their initial order (id = index).
    pub fn new(
        pos: Vec<DVec3>,
        vel: Vec<DVec3>,
        mass: Vec<f64>,
        body: Vec<Body>,
        bonds: Vec<u32>,
    ) -> Self {
        let n = pos.len();
        assert_eq!(vel.len(), n);
        assert_eq!(mass.len(), n);
        assert_eq!(body.len(), n);
        assert_eq!(bonds.len(), n * BONDS_PER_PARTICLE);
        let inv_mass = mass.iter().map(|m| 1.0 / m).collect();
        Particles {
            pos,
            vel,
            force: vec![DVec3::ZERO; n],
            mass,
            inv_mass,
            body,
            id: (0..n as u32).collect(),
            bonds,
            image_bonds: Vec::new(),
        }
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.pos.len()
    }

    /// True when there are no particles.
    pub fn is_empty(&self) -> bool {
        self.pos.is_empty()
    }

    /// Number of intact bonds (each counted once).
    pub fn intact_bonds(&self) -> usize {
        self.intact_bond_pairs().count()
    }

    /// Every intact bond once, as (owner, partner) in current indices.
    pub fn intact_bond_pairs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        (0..self.len()).flat_map(move |i| {
            (0..OWNED_BONDS).filter_map(move |m| {
                let s = self.bonds[i * BONDS_PER_PARTICLE + 2 * m];
                (s != NO_BOND && s & BROKEN_FLAG == 0).then_some((i, s as usize))
            })
        })
    }

    /// Partners of particle `i` through intact bonds (owned or mirror slots), current indices.
    pub fn intact_partners_of(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        (0..BONDS_PER_PARTICLE).filter_map(move |k| {
            let s = self.bonds[i * BONDS_PER_PARTICLE + k];
            if s == NO_BOND {
                return None;
            }
            let j = (s & INDEX_MASK) as usize;
            // A mirror slot is intact when the owner's slot carries no broken flag.
            let owner_slot = if k % 2 == 0 {
                s
            } else {
                self.bonds[j * BONDS_PER_PARTICLE + k - 1]
            };
            (owner_slot & BROKEN_FLAG == 0).then_some(j)
        })
    }

    /// Clears the owned and mirror slots of bonds that broke since the last call (the image
    /// bonds that did are `symmetry::clear_broken_image_bonds`'s).
    pub fn clear_broken_slots(&mut self) {
        for i in 0..self.len() {
            for m in 0..OWNED_BONDS {
                let s = self.bonds[i * BONDS_PER_PARTICLE + 2 * m];
                if s != NO_BOND && s & BROKEN_FLAG != 0 {
                    let j = (s & INDEX_MASK) as usize;
                    self.bonds[i * BONDS_PER_PARTICLE + 2 * m] = NO_BOND;
                    debug_assert_eq!(self.bonds[j * BONDS_PER_PARTICLE + 2 * m + 1], i as u32);
                    self.bonds[j * BONDS_PER_PARTICLE + 2 * m + 1] = NO_BOND;
                }
            }
        }
    }

    /// Index of each id: `index_of_id()[id] = i`.
    pub fn index_of_id(&self) -> Vec<u32> {
        let mut inv = vec![0u32; self.len()];
        for (i, &id) in self.id.iter().enumerate() {
            inv[id as usize] = i as u32;
        }
        inv
    }

    /// Reorders all arrays so that new index `k` holds old particle `perm[k]`, remapping bonds.
    /// Forces are not carried over: they are stale and recomputed right after a re-sort.
    /// Gathers go into `scratch` buffers that are swapped in, so a re-sort allocates nothing.
    pub fn permute(&mut self, perm: &[u32], scratch: &mut PermuteScratch) {
        use rayon::prelude::*;
        let n = self.len();
        if n == 0 {
            return;
        }
        scratch.inv.resize(n, 0);
        for (k, &old) in perm.iter().enumerate() {
            scratch.inv[old as usize] = k as u32;
        }
        // Every array in one parallel pass (each parallel loop costs a start and an end on every
        // thread).
        let s = &mut *scratch;
        s.pos.resize(n, DVec3::ZERO);
        s.vel.resize(n, DVec3::ZERO);
        s.mass.resize(n, 0.0);
        s.inv_mass.resize(n, 0.0);
        s.body.resize(n, Body::Target);
        s.id.resize(n, 0);
        s.bonds.resize(n * BONDS_PER_PARTICLE, NO_BOND);
        let inv = &s.inv;
        let old = &*self;
        s.pos
            .par_iter_mut()
            .zip(s.vel.par_iter_mut())
            .zip(s.mass.par_iter_mut())
            .zip(s.inv_mass.par_iter_mut())
            .zip(s.body.par_iter_mut())
            .zip(s.id.par_iter_mut())
            .zip(s.bonds.par_chunks_mut(BONDS_PER_PARTICLE))
            .zip(perm.par_iter())
            .with_min_len(1024)
            .for_each(|(((((((x, v), m), im), b), id), dst), &k)| {
                let k = k as usize;
                (*x, *v, *m, *im, *b, *id) = (
                    old.pos[k],
                    old.vel[k],
                    old.mass[k],
                    old.inv_mass[k],
                    old.body[k],
                    old.id[k],
                );
                let src = &old.bonds[k * BONDS_PER_PARTICLE..(k + 1) * BONDS_PER_PARTICLE];
                for (d, &b) in dst.iter_mut().zip(src) {
                    *d = if b == NO_BOND {
                        NO_BOND
                    } else {
                        inv[(b & INDEX_MASK) as usize] | (b & BROKEN_FLAG)
                    };
                }
            });
        std::mem::swap(&mut self.pos, &mut s.pos);
        std::mem::swap(&mut self.vel, &mut s.vel);
        std::mem::swap(&mut self.mass, &mut s.mass);
        std::mem::swap(&mut self.inv_mass, &mut s.inv_mass);
        std::mem::swap(&mut self.body, &mut s.body);
        std::mem::swap(&mut self.id, &mut s.id);
        std::mem::swap(&mut self.bonds, &mut s.bonds);
        if !self.image_bonds.is_empty() {
            s.flags.resize(n, 0);
            let flags = &self.image_bonds;
            s.flags
                .par_iter_mut()
                .zip(perm.par_iter())
                .for_each(|(f, &k)| *f = flags[k as usize]);
            std::mem::swap(&mut self.image_bonds, &mut s.flags);
        }
    }
}

/// Buffers reused by every re-sort of the particles.
#[derive(Debug, Default, Clone)]
pub struct PermuteScratch {
    inv: Vec<u32>,
    pos: Vec<DVec3>,
    vel: Vec<DVec3>,
    mass: Vec<f64>,
    inv_mass: Vec<f64>,
    body: Vec<Body>,
    id: Vec<u32>,
    bonds: Vec<u32>,
    flags: Vec<u8>,
}
