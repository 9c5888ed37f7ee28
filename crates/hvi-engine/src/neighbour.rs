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

use crate::state::{Particles, PermuteScratch, BONDS_PER_PARTICLE};

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
    scratch: PermuteScratch,
    order: Vec<(u64, u32)>,
    perm: Vec<u32>,
    cell_start: Vec<u32>,
    cell_keys: Vec<u64>,
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
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
        // Sort by (key, index); the input is nearly sorted from the previous build. Elements are
        // distinct, so the result does not depend on the algorithm or the thread count.
        let mut order = std::mem::take(&mut self.order);
        order.clear();
        order.par_extend(p.pos.par_iter().enumerate().map(|(i, &x)| {
            let (key, ok) = cell_key(x, inv_h);
            // Out-of-range particles are counted through the flag bit below.
            (key, i as u32 | if ok { 0 } else { 1 << 31 })
        }));
        self.out_of_range = order.iter().filter(|o| o.1 & (1 << 31) != 0).count();
        for o in order.iter_mut() {
            o.1 &= !(1 << 31);
        }
        // std's stable sort finds the long sorted runs of a nearly sorted input (rayon's
        // parallel quicksort does not: ten times the work here).
        order.sort();
        let mut perm = std::mem::take(&mut self.perm);
        perm.clear();
        perm.extend(order.iter().map(|o| o.1));
        if perm.iter().enumerate().any(|(k, &o)| k as u32 != o) {
            p.permute(&perm, &mut self.scratch);
        }
        // Cells: runs of equal key.
        let mut cell_start = std::mem::take(&mut self.cell_start);
        let mut cell_key_list = std::mem::take(&mut self.cell_keys);
        cell_start.clear();
        cell_key_list.clear();
        for (i, o) in order.iter().enumerate() {
            if i == 0 || o.0 != order[i - 1].0 {
                cell_start.push(i as u32);
                cell_key_list.push(o.0);
            }
        }
        cell_start.push(n as u32);
        // Coordinates as separate arrays: the candidate loop below runs over contiguous
        // ranges of them.
        let (mut xs, mut ys, mut zs) = (
            std::mem::take(&mut self.xs),
            std::mem::take(&mut self.ys),
            std::mem::take(&mut self.zs),
        );
        xs.clear();
        ys.clear();
        zs.clear();
        xs.extend(p.pos.iter().map(|x| x.x));
        ys.extend(p.pos.iter().map(|x| x.y));
        zs.extend(p.pos.iter().map(|x| x.z));
        let ncell = cell_key_list.len();
        let r2 = radius * radius;
        let bonds = &p.bonds;
        let (xs_r, ys_r, zs_r) = (&xs, &ys, &zs);
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
                        let (xs, ys, zs) = (xs_r, ys_r, zs_r);
                        let (px, py, pz) = (xs[iu], ys[iu], zs[iu]);
                        let slots = &bonds[iu * BONDS_PER_PARTICLE..(iu + 1) * BONDS_PER_PARTICLE];
                        let before = list.len();
                        for &(a, b) in &ranges {
                            let (a, b) = (a as usize, b as usize);
                            let (cx, cy, cz) = (&xs[a..b], &ys[a..b], &zs[a..b]);
                            for k in 0..cx.len() {
                                let (dx, dy, dz) = (px - cx[k], py - cy[k], pz - cz[k]);
                                if dx * dx + dy * dy + dz * dz < r2 {
                                    let j = (a + k) as u32;
                                    if j != i && !slots.contains(&j) {
                                        list.push(j);
                                    }
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
        (self.order, self.perm, self.cell_start, self.cell_keys) =
            (order, perm, cell_start, cell_key_list);
        (self.xs, self.ys, self.zs) = (xs, ys, zs);
    }

    /// Neighbours of particle i.
    #[inline(always)]
    pub fn of(&self, i: usize) -> &[u32] {
        &self.neighbours[self.start[i] as usize..self.start[i + 1] as usize]
    }
}
