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
    fill: Vec<u32>,
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
        // Half stencil: rows whose keys follow the cell's own (same row from x - 1, the next
        // row, and the three rows of the next plane). Sorted order is key order, so these hold
        // exactly the candidates j > i: each pair is examined once and entered on both lists.
        const ROWS: usize = 5;
        let offsets: [i64; ROWS] = [0, row, plane - row, plane, plane + row];
        let pairs: Vec<Vec<(u32, u32)>> = (0..ncell.div_ceil(CELL_CHUNK))
            .into_par_iter()
            .map(|chunk| {
                let c0 = chunk * CELL_CHUNK;
                let c1 = (c0 + CELL_CHUNK).min(ncell);
                let mut found = Vec::with_capacity((cell_start[c1] - cell_start[c0]) as usize * 2);
                let k0 = cell_key_list[c0] as i64;
                let mut ptr = [0usize; ROWS];
                for (r, off) in offsets.iter().enumerate() {
                    let lo = (k0 + off - 1) as u64;
                    ptr[r] = cell_key_list.partition_point(|&k| k < lo);
                }
                let (xs, ys, zs) = (xs_r, ys_r, zs_r);
                for c in c0..c1 {
                    let key = cell_key_list[c] as i64;
                    let mut ranges = [(0usize, 0usize); ROWS];
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
                        ranges[r] = (cell_start[a] as usize, cell_start[b] as usize);
                    }
                    for i in cell_start[c] as usize..cell_start[c + 1] as usize {
                        let (px, py, pz) = (xs[i], ys[i], zs[i]);
                        let slots = &bonds[i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE];
                        for (r, &(a, b)) in ranges.iter().enumerate() {
                            // The own row holds cells x - 1 .. x + 1: only j > i is forward.
                            let a = if r == 0 { a.max(i + 1) } else { a };
                            if a >= b {
                                continue;
                            }
                            let (cx, cy, cz) = (&xs[a..b], &ys[a..b], &zs[a..b]);
                            for k in 0..cx.len() {
                                let (dx, dy, dz) = (px - cx[k], py - cy[k], pz - cz[k]);
                                if dx * dx + dy * dy + dz * dz < r2 {
                                    let j = (a + k) as u32;
                                    if !slots.contains(&j) {
                                        found.push((i as u32, j));
                                    }
                                }
                            }
                        }
                    }
                }
                found
            })
            .collect();
        // Full lists in compressed-row form: count, prefix-sum, fill in pair order (fixed by
        // the sorted walk, so the lists are the same at any thread count).
        let mut fill = std::mem::take(&mut self.fill);
        fill.clear();
        fill.resize(n + 1, 0);
        for &(i, j) in pairs.iter().flatten() {
            fill[i as usize + 1] += 1;
            fill[j as usize + 1] += 1;
        }
        for k in 0..n {
            fill[k + 1] += fill[k];
        }
        self.start.clear();
        self.start.extend_from_slice(&fill);
        self.neighbours.clear();
        self.neighbours.resize(fill[n] as usize, 0);
        for &(i, j) in pairs.iter().flatten() {
            self.neighbours[fill[i as usize] as usize] = j;
            fill[i as usize] += 1;
            self.neighbours[fill[j as usize] as usize] = i;
            fill[j as usize] += 1;
        }
        self.fill = fill;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::{Body, NO_BOND};

    /// The list equals a brute-force search: every unbonded pair closer than the radius, on
    /// both particles' lists, once; intact bonded pairs left out.
    #[test]
    fn matches_brute_force() {
        let n = 600;
        let pos: Vec<DVec3> = (0..n as u64)
            .map(|k| {
                DVec3::new(
                    crate::rng::uniform(3, k, 0) * 8.0 - 4.0,
                    crate::rng::uniform(3, k, 1) * 6.0,
                    crate::rng::uniform(3, k, 2) * 5.0 - 30.0,
                )
            })
            .collect();
        let mut bonds = vec![NO_BOND; n * BONDS_PER_PARTICLE];
        // Bond k to k + 1 along "x" for even k (owner slot 0, mirror slot 1).
        for k in (0..n - 1).step_by(2) {
            bonds[k * BONDS_PER_PARTICLE] = (k + 1) as u32;
            bonds[(k + 1) * BONDS_PER_PARTICLE + 1] = k as u32;
        }
        let mut p = Particles::new(
            pos,
            vec![DVec3::ZERO; n],
            vec![1.0; n],
            vec![Body::Target; n],
            bonds,
        );
        let radius = 1.3;
        let mut nl = NeighbourList::default();
        nl.build(&mut p, radius);
        let mut brute = 0;
        for i in 0..n {
            let mut got: Vec<u32> = nl.of(i).to_vec();
            got.sort_unstable();
            let mut want: Vec<u32> = (0..n)
                .filter(|&j| {
                    j != i
                        && (p.pos[i] - p.pos[j]).length_squared() < radius * radius
                        && !p.intact_partners_of(i).any(|b| b == j)
                })
                .map(|j| j as u32)
                .collect();
            want.sort_unstable();
            brute += want.len();
            assert_eq!(got, want, "particle {i}");
        }
        assert!(
            brute > n,
            "the test must exercise real neighbours ({brute})"
        );
    }
}
