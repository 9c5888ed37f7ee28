//! Verlet neighbour lists from a sorted cell grid, with a skin.
//!
//! Particles are sorted by the key of their cell (z-major, then y, then x, on a grid of side
//! r_eq + skin anchored at the origin), and the particle arrays are reordered accordingly, so
//! particles of one cell are contiguous and neighbouring cells are near in memory. No dense grid
//! is allocated: the cloud spreads over a box far larger than the particles fill. For each
//! occupied cell the three cells x-1, x, x+1 of each of the nine neighbouring (y, z) rows have
//! consecutive keys, so they are one contiguous range of particles; the start of each range is
//! found by nine pointers that only move forward while the cells are walked in key order.
//!
//! The list is full (each pair appears on both particles' lists) so forces are gathered per
//! particle and the result does not depend on the thread count. Pairs joined by an intact bond
//! are left out: the bond kernel handles their repulsion as well.

use glam::DVec3;
use rayon::prelude::*;

use crate::state::{Particles, BONDS_PER_PARTICLE};

const COORD_BITS: u32 = 21;
const COORD_OFFSET: i64 = 1 << (COORD_BITS - 1);
const COORD_MAX: i64 = (1 << COORD_BITS) - 2;
/// Cells per chunk of the parallel search (fixed, for reproducible work units).
const CELL_CHUNK: usize = 2048;

/// The neighbour list in compressed-row form over the current particle order.
#[derive(Debug, Default, Clone)]
pub struct NeighbourList {
    /// `start[i]..start[i + 1]` indexes `neighbours` for particle i.
    pub start: Vec<u32>,
    /// Neighbour indices.
    pub neighbours: Vec<u32>,
    /// Positions at the last build.
    pub pos_at_build: Vec<DVec3>,
    /// List radius r_eq + skin, m.
    pub radius: f64,
    /// Number of builds so far.
    pub builds: u64,
    /// Particles outside the representable grid at the last build (a blow-up symptom).
    pub out_of_range: usize,
}

#[inline]
fn cell_key(p: DVec3, inv_h: f64) -> (u64, bool) {
    let mut ok = true;
    let mut c = [0i64; 3];
    for (a, v) in [p.x, p.y, p.z].into_iter().enumerate() {
        let q = (v * inv_h).floor();
        let q = if q.is_finite() {
            q as i64 + COORD_OFFSET
        } else {
            -1
        };
        if !(1..=COORD_MAX).contains(&q) {
            ok = false;
        }
        c[a] = q.clamp(1, COORD_MAX);
    }
    (
        ((c[2] as u64) << (2 * COORD_BITS)) | ((c[1] as u64) << COORD_BITS) | c[0] as u64,
        ok,
    )
}

impl NeighbourList {
    /// Rebuilds the list: clears bond slots broken since the last build (those pairs join the
    /// ordinary list now), re-sorts the particles by cell and searches neighbouring cells.
    pub fn build(&mut self, p: &mut Particles, radius: f64) {
        self.radius = radius;
        self.builds += 1;
        let n = p.len();
        p.clear_broken_slots();
        let inv_h = 1.0 / radius;
        let keyed: Vec<(u64, bool)> = p.pos.par_iter().map(|&x| cell_key(x, inv_h)).collect();
        self.out_of_range = keyed.iter().filter(|k| !k.1).count();
        // Sort by (key, index); the input is nearly sorted from the previous build. Elements are
        // distinct, so the result does not depend on the algorithm or the thread count.
        let mut order: Vec<(u64, u32)> = keyed
            .iter()
            .enumerate()
            .map(|(i, k)| (k.0, i as u32))
            .collect();
        order.par_sort_unstable();
        let perm: Vec<u32> = order.iter().map(|o| o.1).collect();
        let is_identity = perm.iter().enumerate().all(|(k, &o)| k as u32 == o);
        if !is_identity {
            p.permute(&perm);
        }
        let keys: Vec<u64> = order.iter().map(|o| o.0).collect();
        // Cells: runs of equal key.
        let mut cell_start: Vec<u32> = Vec::with_capacity(n / 2 + 1);
        let mut cell_key_list: Vec<u64> = Vec::with_capacity(n / 2 + 1);
        for (i, &k) in keys.iter().enumerate() {
            if i == 0 || k != keys[i - 1] {
                cell_start.push(i as u32);
                cell_key_list.push(k);
            }
        }
        cell_start.push(n as u32);
        let ncell = cell_key_list.len();
        let r2 = radius * radius;
        let pos = &p.pos;
        let bonds = &p.bonds;
        let row = 1i64 << COORD_BITS;
        let plane = 1i64 << (2 * COORD_BITS);
        let mut offsets = [0i64; 9];
        let mut r = 0;
        for dz in -1..=1 {
            for dy in -1..=1 {
                offsets[r] = dz * plane + dy * row;
                r += 1;
            }
        }
        let chunks: Vec<(Vec<u32>, Vec<u32>)> = (0..ncell.div_ceil(CELL_CHUNK))
            .into_par_iter()
            .map(|chunk| {
                let c0 = chunk * CELL_CHUNK;
                let c1 = (c0 + CELL_CHUNK).min(ncell);
                let mut counts = Vec::with_capacity((cell_start[c1] - cell_start[c0]) as usize);
                let mut list = Vec::with_capacity(counts.capacity() * 4);
                let k0 = cell_key_list[c0] as i64;
                let mut ptr = [0usize; 9];
                for (r, off) in offsets.iter().enumerate() {
                    let lo = (k0 + off - 1) as u64;
                    ptr[r] = cell_key_list.partition_point(|&k| k < lo);
                }
                for c in c0..c1 {
                    let key = cell_key_list[c] as i64;
                    let mut ranges = [(0u32, 0u32); 9];
                    for (r, off) in offsets.iter().enumerate() {
                        let lo = (key + off - 1) as u64;
                        let hi = (key + off + 1) as u64;
                        let mut a = ptr[r];
                        while a < ncell && cell_key_list[a] < lo {
                            a += 1;
                        }
                        ptr[r] = a;
                        let mut b = a;
                        while b < ncell && cell_key_list[b] <= hi {
                            b += 1;
                        }
                        ranges[r] = (cell_start[a], cell_start[b]);
                    }
                    for i in cell_start[c]..cell_start[c + 1] {
                        let iu = i as usize;
                        let pi = pos[iu];
                        let slots = &bonds[iu * BONDS_PER_PARTICLE..(iu + 1) * BONDS_PER_PARTICLE];
                        let before = list.len();
                        for &(a, b) in &ranges {
                            for j in a..b {
                                if j == i {
                                    continue;
                                }
                                let d = pi - pos[j as usize];
                                if d.length_squared() < r2 && !slots.contains(&j) {
                                    list.push(j);
                                }
                            }
                        }
                        counts.push((list.len() - before) as u32);
                    }
                }
                (counts, list)
            })
            .collect();
        self.start.clear();
        self.start.reserve(n + 1);
        self.start.push(0);
        let total: usize = chunks.iter().map(|c| c.1.len()).sum();
        self.neighbours.clear();
        self.neighbours.reserve(total);
        let mut acc = 0u32;
        for (counts, list) in &chunks {
            for &c in counts {
                acc += c;
                self.start.push(acc);
            }
            self.neighbours.extend_from_slice(list);
        }
        self.pos_at_build.clear();
        self.pos_at_build.extend_from_slice(&p.pos);
    }

    /// Neighbours of particle i.
    #[inline(always)]
    pub fn of(&self, i: usize) -> &[u32] {
        &self.neighbours[self.start[i] as usize..self.start[i + 1] as usize]
    }
}
