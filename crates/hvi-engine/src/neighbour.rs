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
//! When to rebuild (`NeighbourList::stale`): the classic rule rebuilds once some particle has
//! moved half the skin, so a cloud flying at 7 km/s rebuilds every few steps although its
//! neighbouring particles hardly move relative to each other. Here each particle's
//! displacement is measured in the frame of its *block* (a cube of side `block` on a coarse
//! grid), moving with the block's mean velocity at the build. For a pair not on the list (farther
//! than the list radius at the build) to come within the contact radius, its separation must
//! shrink by more than the skin; the separation changes by at most
//! |e_i| + |e_j| + |u_a - u_b| t (e the displacements relative to the frames, u_a, u_b the two
//! frames' velocities, t the time since the build). Pairs in the same or adjacent blocks are
//! bounded block pair by block pair: E_a + E_b + |u_a - u_b| t, E_a the largest displacement in
//! block a (`measure_block_displacement`), over every adjacent pair of blocks and every block
//! with itself (`stale_by_blocks`). So the hottest particles and the largest frame difference
//! only add up where they meet; the global form 2 max e + max |u_a - u_b| t (`stale`, with
//! `near_dv`) is looser and still exact, so the time loop checks it first and measures the
//! blocks only when it fails. Pairs in blocks that are not adjacent were at least one block
//! side apart, and are covered by a bound on |u_a - u_b| over all blocks (`far_dv`) against
//! the block side less the contact radius. The rule is exact (no pair is ever missed); with
//! `block = 0` every frame is at rest and it is the classic rule. The adaptive step asks the
//! rule to look one step ahead (the same bound at the end of the next step, from the largest
//! speed relative to a frame), so that a pair is listed before it comes into contact.
//!
//! The list is full (each pair appears on both particles' lists) so forces are gathered per
//! particle and the result does not depend on the thread count. Pairs joined by an intact bond
//! are left out: the bond kernel handles their repulsion as well.
//!
//! Under quarter symmetry (`crate::symmetry`) each particle also has an image list: pairs with
//! the mirror images of particles across the planes x = 0 and y = 0 (`images_of`, found at each
//! build by the `images` submodule), and the rebuild rule counts the images' frames.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};

use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use serde::{Deserialize, Serialize};

use crate::state::{Particles, PermuteScratch, BONDS_PER_PARTICLE, BROKEN_FLAG, NO_BOND};
use crate::symmetry::{image_bond_flags, reflect, IMAGE_SHIFT, MIRROR_X, MIRROR_Y};

mod images;
pub use images::split_image;

const COORD_BITS: u32 = 21;
const COORD_OFFSET: i64 = 1 << (COORD_BITS - 1);
const COORD_MAX: i64 = (1 << COORD_BITS) - 2;
/// Cells per chunk of the parallel search (fixed, for reproducible work units).
const CELL_CHUNK: usize = 256;
/// Candidates per block of the branch-free distance filter (one bit each in a `u32`); the
/// search's coordinate arrays carry this many padding entries past the last particle.
const LANES: usize = 8;

/// The neighbour list in compressed-row form over the current particle order.
#[derive(Debug, Default, Clone)]
pub struct NeighbourList {
    /// `start[i]..start[i + 1]` indexes `neighbours` for particle i.
    pub start: Vec<u32>,
    /// Neighbour indices.
    pub neighbours: Vec<u32>,
    /// `later[i]..start[i + 1]` indexes particle i's partners j > i (lists are ascending).
    later: Vec<u32>,
    /// Positions at the last build.
    pub pos_at_build: Vec<DVec3>,
    /// Velocity of each particle's frame (its block's mean velocity at the last build), m/s.
    pub frame_vel: Vec<DVec3>,
    /// Largest |u_a - u_b| between a block's frame and an adjacent block's, m/s.
    pub near_dv: f64,
    /// Upper bound on |u_a - u_b| between any two blocks' frames, m/s.
    pub far_dv: f64,
    /// Block side, m (0: one frame at rest, the classic criterion).
    pub block: f64,
    /// List radius r_eq + skin, m.
    pub radius: f64,
    /// Number of builds so far.
    pub builds: u64,
    /// With `measure_speed` at the build: the largest relative speed |v_i - v_j| of any two
    /// particles within the list radius then (listed pairs and bond partners alike), m/s.
    pub pair_speed: f64,
    /// Particles outside the representable grid at the last build (a blow-up symptom).
    pub out_of_range: usize,
    /// Quarter symmetry: pairs with the images across the planes x = 0 and y = 0 are listed
    /// too ([`Self::images_of`]); set at each build from the particles (they carry image
    /// bonds).
    mirrors: bool,
    /// `image_start[i]..image_start[i + 1]` indexes `image_nbrs` for particle i (empty for a
    /// full scene).
    image_start: Vec<u32>,
    /// Image-list entries `j | code << IMAGE_SHIFT`.
    image_nbrs: Vec<u32>,
    scratch: PermuteScratch,
    order: Vec<(u64, u32)>,
    /// Each particle's cell key at the last build, in the particle order since then (with
    /// the cell side's inverse `sorted_inv_h`): the sort's hint.
    sorted_keys: Vec<u64>,
    sorted_inv_h: f64,
    /// The sort's buffers: particles whose cell is unchanged since the last build, and the
    /// others.
    kept: Vec<(u64, u32)>,
    moved: Vec<(u64, u32)>,
    perm: Vec<u32>,
    cell_start: Vec<u32>,
    cell_keys: Vec<u64>,
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
    /// Each list's next free entry while the lists are filled.
    fill: Vec<u32>,
    /// The search's pairs, one entry per chunk of cells (kept from build to build).
    found: Vec<ChunkPairs>,
    block_keys: Vec<u64>,
    /// Each particle's block (dense index, in order of first appearance at the build).
    block_of: Vec<u32>,
    /// The runs of particles in one block, at the build.
    block_runs: BlockRuns,
    /// Adjacent blocks (a, b) in the forward half (each unordered pair once, no block with
    /// itself) and |u_a - u_b|, m/s.
    block_pairs: Vec<(u32, u32, f64)>,
    /// Per block: the largest squared displacement relative to the frame since the build, as
    /// the bits of a non-negative f64 (their order is the numbers' order), as
    /// [`Self::measure_block_displacement`] last measured it.
    block_disp: AtomicBits,
    /// [`Self::stale_by_blocks`]'s buffer: each block's displacement plus the look-ahead.
    block_reach: Vec<f64>,
}

/// Numbers written from several threads at once (as the bits of non-negative f64s); a clone
/// copies the values as they are.
#[derive(Debug, Default)]
struct AtomicBits(Vec<AtomicU64>);

impl Clone for AtomicBits {
    fn clone(&self) -> Self {
        AtomicBits(
            self.0
                .iter()
                .map(|a| AtomicU64::new(a.load(Ordering::Relaxed)))
                .collect(),
        )
    }
}

impl std::ops::Deref for AtomicBits {
    type Target = Vec<AtomicU64>;
    fn deref(&self) -> &Vec<AtomicU64> {
        &self.0
    }
}

impl std::ops::DerefMut for AtomicBits {
    fn deref_mut(&mut self) -> &mut Vec<AtomicU64> {
        &mut self.0
    }
}

#[inline]
fn cell_key(p: DVec3, inv_h: f64) -> (u64, bool) {
    let mut ok = true;
    let mut c = [0i64; 3];
    for (a, v) in [p.x, p.y, p.z].into_iter().enumerate() {
        let y = v * inv_h;
        // floor(y) as an integer without `f64::floor` (a library call on x86-64's baseline,
        // where it cost as much as the rest of the key): truncation toward zero, one less
        // where that rounded a negative fraction up. Exact for every finite y: one that
        // truncates to within i64's range converts back exactly, and the cast saturates
        // beyond it as `floor(y) as i64` does.
        let q = if y.is_finite() {
            let t = y as i64;
            let floor = if (t as f64) > y {
                t.saturating_sub(1)
            } else {
                t
            };
            floor.wrapping_add(COORD_OFFSET)
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

crate::simd::kernel! {
    /// [`NeighbourList::search_cells`] for the widest instruction set this CPU has.
    fn search_cells_kernel(
        nl: &NeighbourList,
        search: &PairSearch,
        chunk: usize,
        out: &mut ChunkPairs,
    ) -> () = NeighbourList::search_cells_body;
}

/// Rows of the half stencil on the key grid: the own row, the next row, and the three rows of
/// the next plane (key offsets of each row's centre cell).
const FORWARD_ROWS: usize = 5;

fn forward_rows() -> [i64; FORWARD_ROWS] {
    let row = 1i64 << COORD_BITS;
    let plane = 1i64 << (2 * COORD_BITS);
    [0, row, plane - row, plane, plane + row]
}

/// What of a neighbour list lasts from one build to the next: the lists, the positions and
/// frames of the rebuild rule and the counters. The rest of [`NeighbourList`] is scratch space
/// of a build (a build depends only on the particles), so a list restored from this is the list
/// it was saved from (see [`crate::sim::SimState`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NeighbourState {
    start: Vec<u32>,
    neighbours: Vec<u32>,
    pos_at_build: Vec<DVec3>,
    frame_vel: Vec<DVec3>,
    near_dv: f64,
    far_dv: f64,
    block: f64,
    radius: f64,
    builds: u64,
    pair_speed: f64,
    out_of_range: usize,
    #[serde(default)]
    mirrors: bool,
    #[serde(default)]
    image_start: Vec<u32>,
    #[serde(default)]
    image_nbrs: Vec<u32>,
}

impl NeighbourState {
    /// Whether the state is a list of `n` particles (every array its length, every index in
    /// range): the check before it is restored.
    pub(crate) fn fits(&self, n: usize) -> std::result::Result<(), String> {
        if self.start.len() != n + 1 || self.pos_at_build.len() != n || self.frame_vel.len() != n {
            return Err(format!("its neighbour list is not of {n} particles"));
        }
        let ordered = self.start.windows(2).all(|w| w[0] <= w[1]);
        let last = self.start.last().map_or(0, |&s| s as usize);
        if !ordered || last != self.neighbours.len() {
            return Err("its neighbour list is not well formed".into());
        }
        if self.neighbours.iter().any(|&j| j as usize >= n) {
            return Err("its neighbour list names particles beyond the count".into());
        }
        let images_fit = if self.mirrors {
            self.image_start.len() == n + 1
                && self.image_start.windows(2).all(|w| w[0] <= w[1])
                && self.image_start.last().map_or(0, |&s| s as usize) == self.image_nbrs.len()
                && self.image_nbrs.iter().all(|&e| split_image(e).0 < n)
        } else {
            self.image_start.is_empty() && self.image_nbrs.is_empty()
        };
        if !images_fit {
            return Err("its image lists (quarter symmetry) are not well formed".into());
        }
        Ok(())
    }
}

impl NeighbourList {
    /// What lasts between builds ([`NeighbourState`]).
    pub fn save_state(&self) -> NeighbourState {
        NeighbourState {
            start: self.start.clone(),
            neighbours: self.neighbours.clone(),
            pos_at_build: self.pos_at_build.clone(),
            frame_vel: self.frame_vel.clone(),
            near_dv: self.near_dv,
            far_dv: self.far_dv,
            block: self.block,
            radius: self.radius,
            builds: self.builds,
            pair_speed: self.pair_speed,
            out_of_range: self.out_of_range,
            mirrors: self.mirrors,
            image_start: self.image_start.clone(),
            image_nbrs: self.image_nbrs.clone(),
        }
    }

    /// Puts back a saved [`NeighbourState`] (checked with [`NeighbourState::fits`] first).
    pub(crate) fn restore_state(&mut self, s: NeighbourState) {
        self.start = s.start;
        self.neighbours = s.neighbours;
        self.pos_at_build = s.pos_at_build;
        self.frame_vel = s.frame_vel;
        self.near_dv = s.near_dv;
        self.far_dv = s.far_dv;
        self.block = s.block;
        self.radius = s.radius;
        self.builds = s.builds;
        self.pair_speed = s.pair_speed;
        self.out_of_range = s.out_of_range;
        self.mirrors = s.mirrors;
        self.image_start = s.image_start;
        self.image_nbrs = s.image_nbrs;
        let (start, neighbours) = (&self.start, &self.neighbours);
        self.later.clear();
        self.later
            .par_extend((0..self.pos_at_build.len()).into_par_iter().map(|i| {
                let list = &neighbours[start[i] as usize..start[i + 1] as usize];
                start[i] + list.partition_point(|&j| (j as usize) < i) as u32
            }));
        // The blocks derive from the positions and frames at the build, which are saved.
        if self.block > 0.0 {
            let keys = block_keys_of(&self.pos_at_build, self.block, &mut self.block_keys);
            let firsts = self.block_runs.find(keys, &mut self.block_of);
            let blocks: Vec<(u64, DVec3)> = firsts
                .iter()
                .map(|&i| (keys[i], self.frame_vel[i]))
                .collect();
            self.link_blocks(&blocks);
        } else {
            self.block_of.clear();
            self.block_pairs.clear();
            self.block_disp.clear();
        }
    }

    /// Whether the list may miss a contact now or, with `ahead_s` > 0, by the end of a step of
    /// `ahead_s` taken at particle speeds at most `max_s` relative to their frames: `max_e` is
    /// the largest displacement of a particle relative to its frame since the build,
    /// `since_build_s` the time since the build, `contact_radius` the range of the contact
    /// force (see the module's rule).
    pub fn stale(
        &self,
        max_e: f64,
        since_build_s: f64,
        contact_radius: f64,
        max_s: f64,
        ahead_s: f64,
    ) -> bool {
        let two_e = 2.0 * max_e + 2.0 * max_s * ahead_s;
        let t = since_build_s + ahead_s;
        if two_e + self.near_dv * t >= self.radius - contact_radius {
            return true;
        }
        self.block > 0.0 && two_e + self.far_dv * t >= self.block - contact_radius
    }

    /// The block-pair form of the rule (see the module): whether some pair in the same or
    /// adjacent blocks, or in blocks farther apart, could come within `contact_radius` now or
    /// by the end of a look-ahead step of `ahead_s` at speeds at most `max_s` relative to the
    /// frames. The blocks' displacements are those [`Self::measure_block_displacement`] last
    /// measured. With `block = 0` (one frame at rest) it is [`Self::stale`]
    /// with `max_e`, the largest displacement of any particle.
    pub fn stale_by_blocks(
        &mut self,
        max_e: f64,
        since_build_s: f64,
        contact_radius: f64,
        max_s: f64,
        ahead_s: f64,
    ) -> bool {
        if self.block <= 0.0 || self.block_disp.is_empty() {
            return self.stale(max_e, since_build_s, contact_radius, max_s, ahead_s);
        }
        let t = since_build_s + ahead_s;
        let ahead = max_s * ahead_s;
        // Each block's E plus the look-ahead, once per block (into a buffer kept between calls:
        // this runs in the step loop).
        let e = &mut self.block_reach;
        e.resize(self.block_disp.len(), 0.0);
        e.par_iter_mut()
            .zip(self.block_disp.par_iter())
            .with_min_len(1024)
            .for_each(|(r, d)| *r = f64::from_bits(d.load(Ordering::Relaxed)).sqrt() + ahead);
        let skin = self.radius - contact_radius;
        // A block with itself: E_a + E_a.
        let largest = e.iter().fold(0.0f64, |a, &b| a.max(b));
        if 2.0 * largest >= skin {
            return true;
        }
        // Maxima do not depend on the order, so any thread count gives the same.
        let near = self
            .block_pairs
            .par_iter()
            .with_min_len(4096)
            .map(|&(a, b, dv)| e[a as usize] + e[b as usize] + dv * t)
            .reduce(|| 0.0, f64::max);
        near >= skin || 2.0 * largest + self.far_dv * t >= self.block - contact_radius
    }

    /// Measures each block's largest displacement relative to its frame, `since_build_s`
    /// after the build (positions `pos`), for [`Self::stale_by_blocks`]. Maxima do not depend
    /// on the order, so any thread count gives the same.
    pub fn measure_block_displacement(&self, pos: &[DVec3], since_build_s: f64) {
        if self.block_disp.is_empty() {
            return;
        }
        for a in self.block_disp.iter() {
            a.store(0, Ordering::Relaxed);
        }
        let disp = &self.block_disp;
        pos.par_chunks(4096).enumerate().for_each(|(c, chunk)| {
            // Particles of one block come in runs in cell order: one atomic update per run.
            let mut run: Option<(u32, f64)> = None;
            for (k, &x) in chunk.iter().enumerate() {
                let i = c * 4096 + k;
                let d = x - self.pos_at_build[i] - self.frame_vel[i] * since_build_s;
                let (b, d2) = (self.block_of[i], d.length_squared());
                run = match run {
                    Some((rb, m)) if rb == b => Some((b, m.max(d2))),
                    Some((rb, m)) => {
                        disp[rb as usize].fetch_max(m.to_bits(), Ordering::Relaxed);
                        Some((b, d2.max(0.0)))
                    }
                    None => Some((b, d2.max(0.0))),
                };
            }
            if let Some((rb, m)) = run {
                disp[rb as usize].fetch_max(m.to_bits(), Ordering::Relaxed);
            }
        });
    }

    /// The frames: each particle's block (side `block`) and its mean velocity; `near_dv`,
    /// `far_dv` and the adjacent blocks. Sums run in the (sorted) particle order, so they do
    /// not depend on threads.
    fn build_frames(&mut self, p: &Particles, block: f64) {
        let n = p.len();
        self.block = block;
        self.frame_vel.clear();
        if block <= 0.0 {
            self.frame_vel.resize(n, DVec3::ZERO);
            self.near_dv = 0.0;
            self.far_dv = 0.0;
            self.block_of.clear();
            self.block_pairs.clear();
            self.block_disp.clear();
            return;
        }
        let blocks = self.block_means(p);
        self.link_blocks(&blocks);
    }

    /// From the blocks (key and frame velocity, by dense index): the adjacent pairs with
    /// their frames' difference, `near_dv` (the largest of those), `far_dv` (a bound over all
    /// blocks) and the per-block displacements, zeroed.
    fn link_blocks(&mut self, blocks: &[(u64, DVec3)]) {
        // In key order for the walk (keys are distinct), with the dense indices.
        let mut sorted: Vec<(u64, DVec3, u32)> = blocks
            .iter()
            .enumerate()
            .map(|(b, &(k, u))| (k, u, b as u32))
            .collect();
        sorted.par_sort_unstable_by_key(|b| b.0);
        self.block_pairs = adjacent_blocks(&sorted);
        if self.mirrors {
            self.block_pairs.extend(images::image_block_pairs(&sorted));
        }
        self.near_dv = self.block_pairs.iter().fold(0.0f64, |a, p| a.max(p.2));
        let (mut lo, mut hi) = sorted.par_iter().map(|&(_, u, _)| (u, u)).reduce(
            || (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        );
        if self.mirrors && !sorted.is_empty() {
            (lo, hi) = images::mirrored_frame_spread(lo, hi);
        }
        self.far_dv = if sorted.is_empty() {
            0.0
        } else {
            (hi - lo).length()
        };
        self.block_disp.clear();
        self.block_disp
            .extend((0..blocks.len()).map(|_| AtomicU64::new(0)));
    }

    /// Each block's key and mean velocity (by dense index: order of first appearance), and
    /// each particle's frame velocity (its block's mean) into `frame_vel`. The particles'
    /// block keys are those [`Self::split_coordinates`] found.
    fn block_means(&mut self, p: &Particles) -> Vec<(u64, DVec3)> {
        let keys = &self.block_keys[..];
        let firsts = self.block_runs.find(keys, &mut self.block_of);
        // Sums in particle order (fixed by the sort): each run's in turn, then the runs' of a
        // block in run order. Runs are common in cell order.
        let runs = &self.block_runs;
        let vel = &p.vel;
        let mut run_sums = Vec::with_capacity(runs.block.len());
        run_sums.par_extend(runs.start.par_windows(2).map(|w| {
            let mut sum = DVec3::ZERO;
            for v in &vel[w[0] as usize..w[1] as usize] {
                sum += *v;
            }
            sum
        }));
        let mut sums = vec![(DVec3::ZERO, 0.0f64); firsts.len()];
        for ((&b, &sum), w) in runs.block.iter().zip(&run_sums).zip(runs.start.windows(2)) {
            let e = &mut sums[b as usize];
            e.0 += sum;
            e.1 += (w[1] - w[0]) as f64;
        }
        let blocks: Vec<(u64, DVec3)> = firsts
            .iter()
            .zip(&sums)
            .map(|(&i, &(s, c))| (keys[i], s / c))
            .collect();
        let blocks_r = &blocks;
        self.frame_vel
            .par_extend(self.block_of.par_iter().map(|&b| blocks_r[b as usize].1));
        blocks
    }

    /// Rebuilds the list: clears bond slots broken since the last build (those pairs join the
    /// ordinary list now), re-sorts the particles by cell, searches neighbouring cells and
    /// sets the frames of the rebuild rule (blocks of side `block`, 0 for the classic rule).
    ///
    /// With `measure_speed`, also finds [`Self::pair_speed`] (the search meets every such pair
    /// once, so this costs one velocity difference per pair).
    pub fn build(&mut self, p: &mut Particles, radius: f64, block: f64, measure_speed: bool) {
        self.radius = radius;
        self.builds += 1;
        self.mirrors = !p.image_bonds.is_empty();
        let n = p.len();
        p.clear_broken_slots();
        crate::symmetry::clear_broken_image_bonds(&mut p.image_bonds);
        self.sort_into_cells(p, 1.0 / radius);
        self.split_coordinates(p, block);
        let search = PairSearch {
            xs: &self.xs,
            ys: &self.ys,
            zs: &self.zs,
            bonds: &p.bonds,
            vel: &p.vel,
            r2: radius * radius,
            measure_speed,
        };
        let ncell = self.cell_keys.len();
        let mut found = std::mem::take(&mut self.found);
        found.resize_with(ncell.div_ceil(CELL_CHUNK), ChunkPairs::default);
        crate::threads::for_each_chunk(found.iter_mut(), |chunk, out| {
            self.search_cells(&search, chunk, out);
        });
        let mut max_w2 = found.iter().fold(0.0f64, |a, c| a.max(c.max_w2));
        self.fill_lists(&found, n);
        self.found = found;
        if self.mirrors {
            max_w2 = max_w2.max(self.search_images(p, radius * radius, measure_speed));
        } else {
            self.image_start.clear();
            self.image_nbrs.clear();
        }
        self.pair_speed = max_w2.sqrt();
        self.build_frames(p, block);
    }

    /// Sorts the particles by the key of their cell (`inv_h` = 1 / cell side), reorders the
    /// particle arrays accordingly and finds the cells: runs of equal key.
    fn sort_into_cells(&mut self, p: &mut Particles, inv_h: f64) {
        let n = p.len();
        // Sort by (key, index); the input is nearly sorted from the previous build. Elements are
        // distinct, so the result does not depend on the algorithm or the thread count.
        // One pass each (each parallel loop costs a start and an end on every thread: few and
        // full ones share the threads best): the keys with the count of out-of-range particles; after the sort, the
        // permutation, the keys in the new order (the next sort's hint) and whether it moves
        // anything.
        let order = &mut self.order;
        order.resize(n, (0, 0));
        self.out_of_range = order
            .par_iter_mut()
            .zip(p.pos.par_iter())
            .enumerate()
            .map(|(i, (o, &x))| {
                let (key, ok) = cell_key(x, inv_h);
                *o = (key, i as u32);
                usize::from(!ok)
            })
            .sum();
        if self.sorted_keys.len() == n && self.sorted_inv_h == inv_h {
            sort_by_hint(order, &self.sorted_keys, &mut self.kept, &mut self.moved);
        } else {
            // A merge sort finds the long sorted runs of a nearly sorted input (rayon's
            // parallel quicksort does not: ten times the work here).
            order.par_sort();
        }
        self.sorted_inv_h = inv_h;
        let perm = &mut self.perm;
        perm.resize(n, 0);
        self.sorted_keys.resize(n, 0);
        let moves = perm
            .par_iter_mut()
            .zip(self.sorted_keys.par_iter_mut())
            .zip(order.par_iter())
            .enumerate()
            .map(|(k, ((q, key), o))| {
                *q = o.1;
                *key = o.0;
                o.1 != k as u32
            })
            .reduce(|| false, |a, b| a | b);
        if moves {
            p.permute(perm, &mut self.scratch);
        }
        find_cells(&self.order, &mut self.cell_start, &mut self.cell_keys);
    }

    /// Coordinates as separate arrays (the candidate loop of the search runs over contiguous
    /// ranges of them), the positions at the build and, with frames (`block` > 0), each
    /// particle's block key, in one pass.
    fn split_coordinates(&mut self, p: &Particles, block: f64) {
        let n = p.len();
        // Padding for the search's fixed blocks of lanes (never within the radius; masked).
        for c in [&mut self.xs, &mut self.ys, &mut self.zs] {
            c.resize(n, 0.0);
            c.extend([f64::INFINITY; LANES]);
        }
        self.pos_at_build.resize(n, DVec3::ZERO);
        let frames = block > 0.0;
        let inv_b = 1.0 / block;
        self.block_keys.resize(n, 0);
        self.xs[..n]
            .par_iter_mut()
            .zip(self.ys[..n].par_iter_mut())
            .zip(self.zs[..n].par_iter_mut())
            .zip(self.pos_at_build.par_iter_mut())
            .zip(self.block_keys.par_iter_mut())
            .zip(p.pos.par_iter())
            .for_each(|(((((x, y), z), at_build), key), &r)| {
                (*x, *y, *z) = (r.x, r.y, r.z);
                *at_build = r;
                if frames {
                    *key = cell_key(r, inv_b).0;
                }
            });
    }

    /// The pairs found from the cells of chunk `chunk` (`CELL_CHUNK` cells) into `out`, with
    /// the largest squared relative speed among them when measured.
    ///
    /// Half stencil: rows whose keys follow the cell's own (same row from x - 1, the next
    /// row, and the three rows of the next plane). Sorted order is key order, so these hold
    /// exactly the candidates j > i: each pair is examined once and entered on both lists.
    fn search_cells(&self, search: &PairSearch, chunk: usize, out: &mut ChunkPairs) {
        search_cells_kernel(self, search, chunk, out);
    }

    /// [`Self::search_cells`] as compiled for the instruction set it is called from.
    #[inline(always)]
    fn search_cells_body(&self, search: &PairSearch, chunk: usize, out: &mut ChunkPairs) {
        let (cell_start, cell_keys) = (&self.cell_start, &self.cell_keys);
        let ncell = cell_keys.len();
        let c0 = chunk * CELL_CHUNK;
        let c1 = (c0 + CELL_CHUNK).min(ncell);
        let found = &mut out.pairs;
        found.clear();
        let mut max_w2: f64 = 0.0;
        let offsets = forward_rows();
        let k0 = cell_keys[c0] as i64;
        let mut ptr = [0usize; FORWARD_ROWS];
        for (r, off) in offsets.iter().enumerate() {
            let lo = (k0 + off - 1) as u64;
            ptr[r] = cell_keys.partition_point(|&k| k < lo);
        }
        for c in c0..c1 {
            let key = cell_keys[c] as i64;
            let mut ranges = [(0usize, 0usize); FORWARD_ROWS];
            for (r, off) in offsets.iter().enumerate() {
                let lo = (key + off - 1) as u64;
                let hi = (key + off + 1) as u64;
                let mut a = ptr[r];
                while a < ncell && cell_keys[a] < lo {
                    a += 1;
                }
                ptr[r] = a;
                let mut b = a;
                while b < ncell && cell_keys[b] <= hi {
                    b += 1;
                }
                ranges[r] = (cell_start[a] as usize, cell_start[b] as usize);
            }
            for i in cell_start[c] as usize..cell_start[c + 1] as usize {
                search.scan(i, &ranges, found, &mut max_w2);
            }
        }
        out.max_w2 = max_w2;
        out.max_j = found.iter().fold(0, |m, &(_, j)| m.max(j));
    }

    /// Full lists in compressed-row form: count, prefix-sum, fill in pair order (fixed by
    /// the sorted walk, so the lists are the same at any thread count). Each list comes out
    /// in ascending order: the pairs arrive ordered by their first particle, and within it by
    /// the second, so particle i's partners k < i (entered from k's pairs) precede its own
    /// pairs (i, j > i).
    ///
    /// Each step splits the particles into one contiguous range per thread: every thread
    /// walks the pairs that can touch its range in their order and handles the entries of its
    /// range's particles (its part of the counts, the prefix sums and the lists), so each list
    /// gets its entries in pair order whatever the split. Only the ranges' totals are added up
    /// serially.
    fn fill_lists(&mut self, pairs: &[ChunkPairs], n: usize) {
        let bounds = thread_bounds(n);
        let parts = bounds.len() - 1;
        // Counts first: `start[i + 1]` the length of i's list, `later[i]` its partners k < i
        // (they lead its list); then both become offsets into `neighbours`.
        let (start, later, fill) = (&mut self.start, &mut self.later, &mut self.fill);
        start.clear();
        start.resize(n + 1, 0);
        later.clear();
        later.resize(n, 0);
        fill.resize(n, 0);
        let mut totals = vec![0u32; parts];
        let ranges = split_at_bounds(&mut start[1..], &bounds)
            .into_iter()
            .zip(split_at_bounds(later, &bounds))
            .zip(totals.iter_mut().zip(bounds.windows(2)));
        crate::threads::for_each_chunk(ranges, |_, ((count, earlier), (total, r))| {
            let (a, b) = (r[0] as u32, r[1] as u32);
            for (i, j) in pairs_touching(pairs, a, b) {
                if i >= a {
                    count[(i - a) as usize] += 1;
                }
                if (a..b).contains(&j) {
                    count[(j - a) as usize] += 1;
                    earlier[(j - a) as usize] += 1;
                }
            }
            *total = count.iter().sum();
        });
        let list_bounds = offsets(totals.iter().map(|&t| t as usize));
        // Every entry is written below: no need to clear what a longer list left.
        self.neighbours.resize(list_bounds[parts], 0);
        let ranges = split_at_bounds(&mut self.neighbours, &list_bounds)
            .into_iter()
            .zip(split_at_bounds(&mut start[1..], &bounds))
            .zip(split_at_bounds(later, &bounds))
            .zip(split_at_bounds(fill, &bounds))
            .zip(bounds.windows(2).zip(&list_bounds));
        crate::threads::for_each_chunk(
            ranges,
            |_, ((((lists, ends), earlier), cursor), (r, &base))| {
                let (a, b) = (r[0] as u32, r[1] as u32);
                // Prefix sums from the range's first offset: `cursor` the next free entry of each
                // list, `ends` where each ends, `earlier` where its partners j > i begin.
                let mut at = base as u32;
                for ((end, e), c) in ends
                    .iter_mut()
                    .zip(earlier.iter_mut())
                    .zip(cursor.iter_mut())
                {
                    *c = at;
                    *e += at;
                    at += *end;
                    *end = at;
                }
                let mut put = |x: u32, partner: u32| {
                    let c = &mut cursor[(x - a) as usize];
                    lists[*c as usize - base] = partner;
                    *c += 1;
                };
                for (i, j) in pairs_touching(pairs, a, b) {
                    if i >= a {
                        put(i, j);
                    }
                    if (a..b).contains(&j) {
                        put(j, i);
                    }
                }
            },
        );
    }

    /// Pairs closer than `contact_radius` that are neither joined by a bond slot (intact, or
    /// broken since the build and still repelling through it) nor on the list: a check of the
    /// rebuild rule for tests and diagnostics (a grid search over all particles; not for the
    /// step loop). Zero whenever the rule holds.
    pub fn missing_pairs(&self, p: &Particles, contact_radius: f64) -> usize {
        let inv = 1.0 / contact_radius;
        let cell = |x: DVec3| {
            (
                (x.x * inv).floor() as i64,
                (x.y * inv).floor() as i64,
                (x.z * inv).floor() as i64,
            )
        };
        let mut grid: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::new();
        for (i, &x) in p.pos.iter().enumerate() {
            grid.entry(cell(x)).or_default().push(i);
        }
        let r2 = contact_radius * contact_radius;
        let mut missing = 0;
        for (i, &x) in p.pos.iter().enumerate() {
            for j in around(&grid, cell(x)) {
                if j <= i || (p.pos[j] - x).length_squared() >= r2 {
                    continue;
                }
                let slots = &p.bonds[i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE];
                let bonded = slots.iter().any(|&s| s & !BROKEN_FLAG == j as u32);
                if !bonded && !self.of(i).contains(&(j as u32)) {
                    missing += 1;
                }
            }
        }
        if !p.image_bonds.is_empty() {
            missing += self.missing_image_pairs(p, &grid, cell, r2);
        }
        missing
    }

    /// The image pairs (i, M j) closer than the contact radius (squared: `r2`) that are
    /// neither on i's image list nor an intact image bond, found through `grid` of cells
    /// `cell` (side at least the radius): [`Self::missing_pairs`] under quarter symmetry.
    fn missing_image_pairs(
        &self,
        p: &Particles,
        grid: &HashMap<(i64, i64, i64), Vec<usize>>,
        cell: impl Fn(DVec3) -> (i64, i64, i64),
        r2: f64,
    ) -> usize {
        let mut missing = 0;
        for (i, &x) in p.pos.iter().enumerate() {
            for code in [MIRROR_X, MIRROR_Y, MIRROR_X | MIRROR_Y] {
                for j in around(grid, cell(reflect(x, code))) {
                    if (x - reflect(p.pos[j], code)).length_squared() >= r2 {
                        continue;
                    }
                    let bonded = i == j
                        && code != MIRROR_X | MIRROR_Y
                        && p.image_bonds[i] & image_bond_flags(code).0 != 0;
                    let entry = j as u32 | (code << IMAGE_SHIFT);
                    if !bonded && !self.images_of(i).contains(&entry) {
                        missing += 1;
                    }
                }
            }
        }
        missing
    }

    /// The largest relative speed |v_i - v_j| of the pairs that can interact until the next
    /// build: listed pairs, and bond partners (`bonds`, slots intact or broken), m/s. Each
    /// pair is visited once: a particle's list is in ascending order (see [`Self::build`]), so
    /// its partners j > i are a tail of it, and each bond is seen from its owned slot. Maxima
    /// do not depend on the order, so any thread count gives the same.
    ///
    /// Under quarter symmetry the image pairs and image bonds (`image_bonds`, empty for a full
    /// scene) are included: |v_i - M v_j|.
    ///
    /// Also copies `vel` into `vel_now` in the same pass (the velocities the measurement was
    /// taken at, which the adaptive step keeps).
    pub fn interacting_pair_speed(
        &self,
        vel: &[DVec3],
        bonds: &[u32],
        image_bonds: &[u8],
        vel_now: &mut Vec<DVec3>,
    ) -> f64 {
        const PARTICLES: usize = 1024;
        vel_now.resize(vel.len(), DVec3::ZERO);
        vel_now
            .par_chunks_mut(PARTICLES)
            .enumerate()
            .with_max_len(1)
            .map(|(c, copy)| {
                let mut w2: f64 = 0.0;
                for (k, out) in copy.iter_mut().enumerate() {
                    let i = c * PARTICLES + k;
                    let vi = vel[i];
                    *out = vi;
                    w2 = w2.max(self.largest_pair_speed2(i, vel, bonds, image_bonds));
                }
                w2
            })
            .reduce(|| 0.0, f64::max)
            .sqrt()
    }

    /// The largest squared relative speed of particle i's pairs counted once (partners j > i
    /// on its list, its owned bond slots, its image pairs and image bonds), m^2/s^2.
    #[inline]
    fn largest_pair_speed2(
        &self,
        i: usize,
        vel: &[DVec3],
        bonds: &[u32],
        image_bonds: &[u8],
    ) -> f64 {
        let vi = vel[i];
        let mut w2: f64 = 0.0;
        let later = &self.neighbours[self.later[i] as usize..self.start[i + 1] as usize];
        for &j in later {
            w2 = w2.max((vi - vel[j as usize]).length_squared());
        }
        let slots = &bonds[i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE];
        for &s in slots.iter().step_by(2) {
            if s != NO_BOND {
                w2 = w2.max((vi - vel[(s & !BROKEN_FLAG) as usize]).length_squared());
            }
        }
        for &e in self.images_of(i) {
            let (j, code) = split_image(e);
            w2 = w2.max((vi - reflect(vel[j], code)).length_squared());
        }
        if let Some(&flags) = image_bonds.get(i) {
            for code in [MIRROR_X, MIRROR_Y] {
                if flags & image_bond_flags(code).0 != 0 {
                    w2 = w2.max((vi - reflect(vi, code)).length_squared());
                }
            }
        }
        w2
    }

    /// Neighbours of particle i.
    #[inline(always)]
    pub fn of(&self, i: usize) -> &[u32] {
        &self.neighbours[self.start[i] as usize..self.start[i + 1] as usize]
    }
}

/// The particles of a hash grid's 27 cells around cell `c` (the diagnostics' brute search).
fn around(
    grid: &HashMap<(i64, i64, i64), Vec<usize>>,
    (cx, cy, cz): (i64, i64, i64),
) -> impl Iterator<Item = usize> + '_ {
    (-1..=1)
        .flat_map(move |dz| (-1..=1).flat_map(move |dy| (-1..=1).map(move |dx| (dx, dy, dz))))
        .filter_map(move |(dx, dy, dz)| grid.get(&(cx + dx, cy + dy, cz + dz)))
        .flatten()
        .copied()
}

/// The cells of the sorted `order`: runs of equal key, each's first index into `start` (and
/// `n` after the last) and its key into `keys`.
fn find_cells(order: &[(u64, u32)], start: &mut Vec<u32>, keys: &mut Vec<u64>) {
    find_runs(order.len(), |i| order[i].0, start, keys);
}

/// The runs of equal `key(i)` among `0..n`: each run's first index into `start` (and `n`
/// after the last) and its key into `keys`. One contiguous range of indices per thread,
/// counted then written; without branches on whether an index starts a run (a branch on it
/// is often mispredicted).
fn find_runs(
    n: usize,
    key: impl Fn(usize) -> u64 + Sync,
    start: &mut Vec<u32>,
    keys: &mut Vec<u64>,
) {
    let new_run = |i: usize| i == 0 || key(i) != key(i - 1);
    // Writes the runs starting in `range` to `s` and `k` (room for at least as many) and
    // returns their number. Every index writes at the next free place, which moves on only
    // at a new run; the last place may be written again after the range's last new run, so
    // it is put right at the end.
    let write = |range: std::ops::Range<usize>, s: &mut [u32], k: &mut [u64]| {
        let Some(last) = s.len().checked_sub(1) else {
            return 0;
        };
        let (mut c, mut last_start) = (0, range.start);
        for i in range {
            let fresh = new_run(i);
            s[c.min(last)] = i as u32;
            k[c.min(last)] = key(i);
            last_start = if fresh { i } else { last_start };
            c += usize::from(fresh);
        }
        if c > 0 {
            s[c - 1] = last_start as u32;
            k[c - 1] = key(last_start);
        }
        c
    };
    let bounds = thread_bounds(n);
    let parts = bounds.len() - 1;
    if parts == 1 {
        // One pass into room for all, then cut to size.
        start.resize(n, 0);
        keys.resize(n, 0);
        let c = write(0..n, start, keys);
        start.truncate(c);
        keys.truncate(c);
    } else {
        // One contiguous range of indices per thread: count, then write in place.
        let mut counts = vec![0usize; parts];
        let ranges = counts.iter_mut().zip(bounds.windows(2));
        crate::threads::for_each_chunk(ranges, |_, (count, r)| {
            *count = (r[0]..r[1]).map(|i| usize::from(new_run(i))).sum();
        });
        let at = offsets(counts);
        start.resize(at[parts], 0);
        keys.resize(at[parts], 0);
        let ranges = split_at_bounds(start, &at)
            .into_iter()
            .zip(split_at_bounds(keys, &at))
            .zip(bounds.windows(2));
        crate::threads::for_each_chunk(ranges, |_, ((s, k), r)| {
            write(r[0]..r[1], s, k);
        });
    }
    start.push(n as u32);
}

/// Sorts `order` ((key, index) of each particle, in index order) by key, then index, given
/// `hint`: each particle's key at the last sort, which left the particles in key order, so the
/// hint ascends with the index. The particles whose key equals their hint then form a
/// sequence already in order (checked: if it is not, everything is sorted); only the others,
/// those that changed cells, are sorted, then the two are merged. Elements are distinct, so
/// the result is the one sorted order whatever the hint.
fn sort_by_hint(
    order: &mut [(u64, u32)],
    hint: &[u64],
    kept: &mut Vec<(u64, u32)>,
    moved: &mut Vec<(u64, u32)>,
) {
    let n = order.len();
    let unchanged = |o: &(u64, u32)| o.0 == hint[o.1 as usize];
    // Copies a range of `order` to the two sides; returns how many went to each and whether
    // the kept ones ascend.
    let split = |part: &[(u64, u32)], k: &mut [(u64, u32)], m: &mut [(u64, u32)]| {
        let (mut a, mut b, mut up) = (0, 0, true);
        for o in part {
            if unchanged(o) {
                up &= a == 0 || k[a - 1] < *o;
                k[a] = *o;
                a += 1;
            } else {
                m[b] = *o;
                b += 1;
            }
        }
        (a, b, up)
    };
    let bounds = thread_bounds(n);
    let parts = bounds.len() - 1;
    let ascending = if parts == 1 {
        // One pass into room for all, then cut to size.
        kept.resize(n, (0, 0));
        moved.resize(n, (0, 0));
        let (a, b, up) = split(order, kept, moved);
        kept.truncate(a);
        moved.truncate(b);
        up
    } else {
        // One contiguous range of `order` per thread: count, then copy each side to its
        // place.
        let mut counts = vec![0usize; parts];
        let ranges = counts.iter_mut().zip(bounds.windows(2));
        crate::threads::for_each_chunk(ranges, |_, (count, r)| {
            *count = order[r[0]..r[1]].iter().filter(|o| unchanged(o)).count();
        });
        let kept_at = offsets(counts.iter().copied());
        let moved_at = offsets(
            counts
                .iter()
                .zip(bounds.windows(2))
                .map(|(&c, r)| r[1] - r[0] - c),
        );
        kept.resize(kept_at[parts], (0, 0));
        moved.resize(moved_at[parts], (0, 0));
        let mut ascending = vec![true; parts];
        let ranges = split_at_bounds(kept, &kept_at)
            .into_iter()
            .zip(split_at_bounds(moved, &moved_at))
            .zip(ascending.iter_mut().zip(bounds.windows(2)));
        crate::threads::for_each_chunk(ranges, |_, ((k, m), (up, r))| {
            *up = split(&order[r[0]..r[1]], k, m).2;
        });
        // Across the ranges' joins too.
        let joined = kept_at[1..parts]
            .iter()
            .all(|&c| c == 0 || c == kept.len() || kept[c - 1] < kept[c]);
        joined && ascending.iter().all(|&u| u)
    };
    if !ascending {
        order.par_sort();
        return;
    }
    moved.par_sort_unstable();
    merge(kept, moved, order);
}

/// Merges the ascending sequences `a` and `b` of distinct elements into `out` (of their
/// combined length), one contiguous piece of `out` per thread: each piece's share of `a` and
/// `b` is found by bisection (the merge path).
fn merge<T: Ord + Copy + Send + Sync>(a: &[T], b: &[T], out: &mut [T]) {
    let n = out.len();
    debug_assert_eq!(n, a.len() + b.len());
    let bounds = thread_bounds(n);
    // How many of the first p merged elements come from `a`: the least i whose a[i] does not
    // come before b[p - i - 1] (the test flips once as i grows).
    let from_a = |p: usize| {
        let (mut lo, mut hi) = (p.saturating_sub(b.len()), p.min(a.len()));
        while lo < hi {
            let i = (lo + hi) / 2;
            if a[i] < b[p - i - 1] {
                lo = i + 1;
            } else {
                hi = i;
            }
        }
        lo
    };
    let cuts: Vec<usize> = bounds.iter().map(|&p| from_a(p)).collect();
    let pieces = split_at_bounds(out, &bounds)
        .into_iter()
        .zip(bounds.windows(2).zip(cuts.windows(2)));
    crate::threads::for_each_chunk(pieces, |_, (out, (p, c))| {
        let (mut a, mut b) = (&a[c[0]..c[1]], &b[p[0] - c[0]..p[1] - c[1]]);
        for o in out.iter_mut() {
            // The piece holds exactly its share: one side runs out only at the end.
            if b.is_empty() || (!a.is_empty() && a[0] < b[0]) {
                *o = a[0];
                a = &a[1..];
            } else {
                *o = b[0];
                b = &b[1..];
            }
        }
    });
}

/// The pairs of the search's chunks in order that can have an end in `a..b`: pairs come
/// ordered by their first particle `i` (and j > i), so it stops at the first with `i` at `b`
/// or more, and skips the chunks whose every `j` is below `a`.
fn pairs_touching(pairs: &[ChunkPairs], a: u32, b: u32) -> impl Iterator<Item = (u32, u32)> + '_ {
    pairs
        .iter()
        .filter(move |c| c.max_j >= a)
        .flat_map(|c| &c.pairs)
        .copied()
        .take_while(move |&(i, _)| i < b)
}

/// Bounds of one contiguous range of `0..n` per thread of the current pool (first 0, last
/// `n`; at least one range).
fn thread_bounds(n: usize) -> Vec<usize> {
    let parts = rayon::current_num_threads().clamp(1, n.max(1));
    (0..=parts).map(|t| n * t / parts).collect()
}

/// Where each of a sequence of pieces of the given `sizes` starts when laid end to end, and
/// their total last.
fn offsets(sizes: impl IntoIterator<Item = usize>) -> Vec<usize> {
    let mut at = vec![0usize];
    for c in sizes {
        at.push(at[at.len() - 1] + c);
    }
    at
}

/// `s` cut at the ascending offsets `bounds` (first 0, last `s.len()`): the pieces between
/// consecutive bounds.
fn split_at_bounds<'a, T>(mut s: &'a mut [T], bounds: &[usize]) -> Vec<&'a mut [T]> {
    let mut pieces = Vec::with_capacity(bounds.len().saturating_sub(1));
    for w in bounds.windows(2) {
        let (piece, rest) = s.split_at_mut(w[1] - w[0]);
        pieces.push(piece);
        s = rest;
    }
    pieces
}

/// The key of each position's block (side `block`) into `keys`.
fn block_keys_of<'k>(pos: &[DVec3], block: f64, keys: &'k mut Vec<u64>) -> &'k [u64] {
    let inv_b = 1.0 / block;
    keys.clear();
    keys.par_extend(pos.par_iter().map(|&x| cell_key(x, inv_b).0));
    keys
}

/// Runs of particles in one block (`keys` each particle's block key): each run's first
/// particle (and `n` after the last), key and dense block index, the blocks numbered in order of
/// first appearance.
#[derive(Debug, Default, Clone)]
struct BlockRuns {
    start: Vec<u32>,
    keys: Vec<u64>,
    block: Vec<u32>,
}

impl BlockRuns {
    /// The runs of `keys`, and each particle's dense block index into `block_of`; returns
    /// each block's first particle.
    fn find(&mut self, keys: &[u64], block_of: &mut Vec<u32>) -> Vec<usize> {
        find_runs(keys.len(), |i| keys[i], &mut self.start, &mut self.keys);
        // Numbering in order of first appearance: one lookup per run.
        let mut index: FxHashMap<u64, u32> = FxHashMap::default();
        let mut firsts = Vec::new();
        self.block.clear();
        for (r, &k) in self.keys.iter().enumerate() {
            let b = *index.entry(k).or_insert_with(|| {
                firsts.push(self.start[r] as usize);
                (firsts.len() - 1) as u32
            });
            self.block.push(b);
        }
        block_of.resize(keys.len(), 0);
        let bounds: Vec<usize> = self.start.iter().map(|&i| i as usize).collect();
        split_at_bounds(block_of, &bounds)
            .into_par_iter()
            .zip(self.block.par_iter())
            .for_each(|(run, &b)| run.fill(b));
        firsts
    }
}

/// The adjacent pairs among `blocks` (key, frame velocity, dense index; sorted by key), each
/// unordered pair once, with |u_a - u_b|, m/s. For each block the forward half of its 26
/// neighbours (the other half sees this block) is found by pointers that only move forward as
/// the sorted blocks are walked, as in the cell search. Chunks are concatenated in order, so
/// the list does not depend on the thread count.
fn adjacent_blocks(blocks: &[(u64, DVec3, u32)]) -> Vec<(u32, u32, f64)> {
    let nb = blocks.len();
    let offsets = forward_rows();
    let chunks: Vec<Vec<(u32, u32, f64)>> = (0..nb.div_ceil(CELL_CHUNK))
        .into_par_iter()
        .map(|chunk| {
            let c0 = chunk * CELL_CHUNK;
            let c1 = (c0 + CELL_CHUNK).min(nb);
            let first = |k: i64, r: usize| if r == 0 { k + 1 } else { k + offsets[r] - 1 };
            let k0 = blocks[c0].0 as i64;
            let mut ptr = [0usize; FORWARD_ROWS];
            for (r, p) in ptr.iter_mut().enumerate() {
                *p = blocks.partition_point(|b| (b.0 as i64) < first(k0, r));
            }
            let mut pairs = Vec::new();
            for &(k, u, a) in &blocks[c0..c1] {
                let k = k as i64;
                for (r, p) in ptr.iter_mut().enumerate() {
                    while *p < nb && (blocks[*p].0 as i64) < first(k, r) {
                        *p += 1;
                    }
                    let mut b = *p;
                    while b < nb && blocks[b].0 as i64 <= k + offsets[r] + 1 {
                        pairs.push((a, blocks[b].2, (u - blocks[b].1).length()));
                        b += 1;
                    }
                }
            }
            pairs
        })
        .collect();
    chunks.concat()
}

/// The pairs (i, j > i) one chunk of cells found, in order, with the largest j among them
/// and the largest squared relative speed measured.
#[derive(Debug, Default, Clone)]
struct ChunkPairs {
    pairs: Vec<(u32, u32)>,
    max_j: u32,
    max_w2: f64,
}

/// What the pair search reads, in the sorted particle order: the coordinates as separate
/// arrays, the bond slots and the velocities; and the squared list radius.
struct PairSearch<'a> {
    xs: &'a [f64],
    ys: &'a [f64],
    zs: &'a [f64],
    bonds: &'a [u32],
    vel: &'a [DVec3],
    r2: f64,
    measure_speed: bool,
}

impl PairSearch<'_> {
    /// Adds to `found` the unbonded pairs (i, j > i) within the radius among the candidates
    /// `ranges` (particle index ranges of the forward rows), and raises `max_w2` to the largest
    /// squared relative speed of the pairs within the radius when measured.
    #[inline(always)]
    fn scan(
        &self,
        i: usize,
        ranges: &[(usize, usize); FORWARD_ROWS],
        found: &mut Vec<(u32, u32)>,
        max_w2: &mut f64,
    ) {
        let (xs, ys, zs, vel) = (self.xs, self.ys, self.zs, self.vel);
        let (px, py, pz) = (xs[i], ys[i], zs[i]);
        let slots: &[u32; BONDS_PER_PARTICLE] = self.bonds
            [i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE]
            .try_into()
            .expect("BONDS_PER_PARTICLE slots");
        for (r, &(a, b)) in ranges.iter().enumerate() {
            // The own row holds cells x - 1 .. x + 1: only j > i is forward.
            let a = if r == 0 { a.max(i + 1) } else { a };
            // Branch-free compaction of the candidates within the radius (a sixth of them,
            // so a branch would be mispredicted often), a fixed block of lanes at a time (the
            // coordinate arrays are padded, and lanes past the range are masked off); then the
            // few hits are checked against the bonds.
            let mut a0 = a;
            while a0 < b {
                let cx: &[f64; LANES] = xs[a0..a0 + LANES].try_into().expect("padded");
                let cy: &[f64; LANES] = ys[a0..a0 + LANES].try_into().expect("padded");
                let cz: &[f64; LANES] = zs[a0..a0 + LANES].try_into().expect("padded");
                let mut mask = 0u32;
                for k in 0..LANES {
                    let (dx, dy, dz) = (px - cx[k], py - cy[k], pz - cz[k]);
                    mask |= u32::from(dx * dx + dy * dy + dz * dz < self.r2) << k;
                }
                if b - a0 < LANES {
                    mask &= (1u32 << (b - a0)) - 1;
                }
                while mask != 0 {
                    let j = (a0 + mask.trailing_zeros() as usize) as u32;
                    mask &= mask - 1;
                    if self.measure_speed {
                        let w2 = (vel[i] - vel[j as usize]).length_squared();
                        *max_w2 = max_w2.max(w2);
                    }
                    // All the slots at once (no early exit to mispredict).
                    let bonded = slots.iter().fold(false, |acc, &s| acc | (s == j));
                    if !bonded {
                        found.push((i as u32, j));
                    }
                }
                a0 += LANES;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::{Body, NO_BOND};

    #[test]
    fn sort_by_hint_is_the_sort_whatever_the_hint_and_threads() {
        // Keys from a small generator, hints that are right, partly right, or not sorted.
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = move |m: u64| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x % m
        };
        for case in 0..40 {
            let n = 1 + next(500) as usize;
            let mut hint: Vec<u64> = (0..n).map(|_| next(60)).collect();
            if case % 2 == 0 {
                hint.sort_unstable();
            }
            let keys: Vec<u64> = hint
                .iter()
                .map(|&h| if next(4) == 0 { next(60) } else { h })
                .collect();
            let input: Vec<(u64, u32)> = keys
                .iter()
                .enumerate()
                .map(|(i, &k)| (k, i as u32))
                .collect();
            let mut want = input.clone();
            want.sort_unstable();
            // The cells: runs of equal key.
            let mut want_start: Vec<u32> = (0..n as u32)
                .filter(|&i| i == 0 || want[i as usize].0 != want[i as usize - 1].0)
                .collect();
            let want_keys: Vec<u64> = want_start.iter().map(|&i| want[i as usize].0).collect();
            want_start.push(n as u32);
            // One range per thread: one, two, and more ranges than cores.
            for threads in [1, 2, 3, 7] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .expect("a pool");
                pool.install(|| {
                    let mut got = input.clone();
                    sort_by_hint(&mut got, &hint, &mut Vec::new(), &mut Vec::new());
                    assert_eq!(got, want, "case {case}, {threads} threads");
                    let (mut start, mut keys) = (vec![9; 3], Vec::new());
                    find_cells(&got, &mut start, &mut keys);
                    assert_eq!(start, want_start, "case {case}, {threads} threads");
                    assert_eq!(keys, want_keys, "case {case}, {threads} threads");
                });
            }
        }
    }

    /// Unit-mass target particles without bonds.
    fn unbonded(pos: Vec<DVec3>, vel: Vec<DVec3>) -> Particles {
        let n = pos.len();
        Particles::new(
            pos,
            vel,
            vec![1.0; n],
            vec![Body::Target; n],
            vec![NO_BOND; n * BONDS_PER_PARTICLE],
        )
    }

    /// The positions each particle reaches in `t` moving with its frame.
    fn carried_by_frames(p: &Particles, nl: &NeighbourList, t: f64) -> Vec<DVec3> {
        p.pos
            .iter()
            .zip(&nl.frame_vel)
            .map(|(&x, &u)| x + u * t)
            .collect()
    }

    /// Each list is exactly the unbonded particles within the radius, in ascending order;
    /// returns the number of listed entries.
    fn assert_lists_exact(nl: &NeighbourList, p: &Particles, radius: f64) -> usize {
        let n = p.len();
        let mut brute = 0;
        for i in 0..n {
            let want: Vec<u32> = (0..n)
                .filter(|&j| {
                    j != i
                        && (p.pos[i] - p.pos[j]).length_squared() < radius * radius
                        && !p.intact_partners_of(i).any(|b| b == j)
                })
                .map(|j| j as u32)
                .collect();
            brute += want.len();
            assert_eq!(nl.of(i), &want[..], "particle {i}");
        }
        brute
    }

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
        let vel: Vec<DVec3> = (0..n as u64)
            .map(|k| {
                DVec3::new(
                    crate::rng::uniform(4, k, 0) - 0.5,
                    crate::rng::uniform(4, k, 1) - 0.5,
                    crate::rng::uniform(4, k, 2) - 0.5,
                )
            })
            .collect();
        let mut p = Particles::new(pos, vel, vec![1.0; n], vec![Body::Target; n], bonds);
        let radius = 1.3;
        let mut nl = NeighbourList::default();
        nl.build(&mut p, radius, 0.0, true);
        // The measured speed: the largest |v_i - v_j| over all pairs within the radius,
        // bonded or not.
        let mut fastest: f64 = 0.0;
        let mut bonded_within = 0;
        for i in 0..n {
            for j in i + 1..n {
                if (p.pos[i] - p.pos[j]).length_squared() < radius * radius {
                    fastest = fastest.max((p.vel[i] - p.vel[j]).length());
                    bonded_within += usize::from(p.intact_partners_of(i).any(|b| b == j));
                }
            }
        }
        assert!(
            bonded_within > 0,
            "bonded pairs within the radius are covered too"
        );
        assert_eq!(nl.pair_speed, fastest);
        // Measured again from the lists and bonds (no search): every listed or bonded pair,
        // here all within the radius except bonded ones beyond it.
        let mut interacting: f64 = 0.0;
        for i in 0..n {
            for j in 0..n {
                let listed = nl.of(i).contains(&(j as u32));
                if listed || p.intact_partners_of(i).any(|b| b == j) {
                    interacting = interacting.max((p.vel[i] - p.vel[j]).length());
                }
            }
        }
        let mut copied = Vec::new();
        assert_eq!(
            nl.interacting_pair_speed(&p.vel, &p.bonds, &p.image_bonds, &mut copied),
            interacting
        );
        assert_eq!(copied, p.vel, "the velocities the measurement was taken at");
        let brute = assert_lists_exact(&nl, &p, radius);
        assert!(
            brute > n,
            "the test must exercise real neighbours ({brute})"
        );
        assert_eq!(nl.missing_pairs(&p, radius), 0);
        // A particle moved next to another without a rebuild is a missed pair, and the
        // rebuild rule sees it: displacement beyond the skin.
        let (a, b) = (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .find(|&(a, b)| {
                (p.pos[a] - p.pos[b]).length() > 2.0 * radius
                    && !p.intact_partners_of(a).any(|x| x == b)
            })
            .expect("a distant pair");
        p.pos[a] = p.pos[b] + DVec3::new(0.5, 0.0, 0.0);
        assert!(nl.missing_pairs(&p, 1.0) >= 1);
        let moved = (p.pos[a] - nl.pos_at_build[a]).length();
        assert!(nl.stale(moved, 0.0, 1.0, 0.0, 0.0));
    }

    /// Frames: a block's mean velocity, the near and far bounds; block 0 is the classic rule.
    #[test]
    fn frames_bound_relative_motion() {
        // Two clumps 20 apart moving towards each other at 1 and -1 along x.
        let mut pos = Vec::new();
        let mut vel = Vec::new();
        for k in 0..8 {
            let o = DVec3::new((k % 2) as f64, ((k / 2) % 2) as f64, (k / 4) as f64) * 0.9;
            pos.push(o);
            vel.push(DVec3::X);
            pos.push(o + DVec3::new(20.0, 0.0, 0.0));
            vel.push(-DVec3::X);
        }
        let mut p = unbonded(pos, vel);
        let mut nl = NeighbourList::default();
        nl.build(&mut p, 1.3, 4.0, false);
        assert!(nl.frame_vel.iter().all(|u| (u.x.abs() - 1.0).abs() < 1e-12));
        assert_eq!(nl.near_dv, 0.0, "the clumps' blocks are not adjacent");
        assert!((nl.far_dv - 2.0).abs() < 1e-12);
        // Moving with their frames, nothing is stale until the far bound: 2 t >= 4 - 1.
        assert!(!nl.stale(0.0, 1.4, 1.0, 0.0, 0.0));
        assert!(nl.stale(0.0, 1.6, 1.0, 0.0, 0.0));
        nl.build(&mut p, 1.3, 0.0, false);
        assert!(nl.frame_vel.iter().all(|u| *u == DVec3::ZERO));
        assert!(nl.stale(0.16, 0.0, 1.0, 0.0, 0.0));
        assert!(!nl.stale(0.14, 0.0, 1.0, 0.0, 0.0));
        // The look-ahead: a step of 0.2 at speeds up to 0.1 adds 2 x 0.1 x 0.2 = 0.04.
        assert!(!nl.stale(0.12, 0.0, 1.0, 0.1, 0.2));
        assert!(nl.stale(0.14, 0.0, 1.0, 0.1, 0.2));
        // ... and counts the frames' relative motion over the step too.
        nl.build(&mut p, 1.3, 4.0, false);
        assert!(!nl.stale(0.0, 1.0, 1.0, 0.0, 0.45));
        assert!(nl.stale(0.0, 1.0, 1.0, 0.0, 0.55));
    }

    /// The block-pair form of the rule: the hottest block and the largest frame difference
    /// add up only where they meet. Three clumps on a line, in blocks of side 4: A at rest
    /// and B next to it moving at 1 (adjacent, frame difference 1), C two blocks beyond B at
    /// rest, with one particle displaced (hot). The global form counts C's displacement twice
    /// plus A-B's difference; the pair form counts C with itself, and A-B with their own.
    #[test]
    fn block_pairs_bound_only_blocks_that_meet() {
        let mut pos = Vec::new();
        let mut vel = Vec::new();
        for (x0, v) in [(0.5, 0.0), (4.5, 1.0), (12.5, 0.0)] {
            for k in 0..8 {
                let o = DVec3::new((k % 2) as f64, ((k / 2) % 2) as f64, (k / 4) as f64);
                pos.push(o + DVec3::new(x0, 0.5, 0.5));
                vel.push(DVec3::new(v, 0.0, 0.0));
            }
        }
        let n = pos.len();
        let mut p = unbonded(pos, vel);
        let mut nl = NeighbourList::default();
        let (radius, contact) = (1.5, 1.0);
        nl.build(&mut p, radius, 4.0, false);
        assert_eq!(nl.block_pairs.len(), 1, "A-B adjacent, C alone");
        assert_eq!(nl.near_dv, 1.0);
        let skin = radius - contact;
        // C's particle moved 0.2 (relative to its frame at rest), A-B apart by 0.2 in t = 0.2.
        let hot = (0..n)
            .find(|&i| p.pos[i].x > 12.0)
            .expect("a particle of C");
        // Every particle moves with its frame for t = 0.2; C's hot particle 0.2 beyond.
        let t = 0.2;
        let mut moved = carried_by_frames(&p, &nl, t);
        moved[hot].y += 0.2;
        nl.measure_block_displacement(&moved, t);
        assert!(
            nl.stale(0.2, t, contact, 0.0, 0.0),
            "global: 2 x 0.2 + 1 x 0.2 >= {skin}"
        );
        assert!(
            !nl.stale_by_blocks(0.2, t, contact, 0.0, 0.0),
            "pairs: C with itself 0.4, A-B 0.2"
        );
        // Moved 0.26: C with itself reaches the skin.
        moved[hot].y += 0.06;
        nl.measure_block_displacement(&moved, t);
        assert!(nl.stale_by_blocks(0.26, t, contact, 0.0, 0.0));
        // A-B alone: their difference over t = 0.5 reaches the skin, C's block does not matter.
        nl.measure_block_displacement(&carried_by_frames(&p, &nl, 0.45), 0.45);
        assert!(!nl.stale_by_blocks(0.0, 0.45, contact, 0.0, 0.0));
        assert!(nl.stale_by_blocks(0.0, 0.5, contact, 0.0, 0.0));
        // Restored from what a checkpoint keeps, the blocks are the same.
        let mut back = NeighbourList::default();
        back.restore_state(nl.save_state());
        assert_eq!(back.block_of, nl.block_of);
        assert_eq!(back.block_pairs, nl.block_pairs);
        assert_eq!(back.block_disp.len(), nl.block_disp.len());
    }

    /// Each particle's frame is the mean velocity of its block's particles (to round-off: the
    /// engine adds runs' sums), bit for bit the same on one thread, three and four; so are the
    /// lists.
    #[test]
    fn frames_are_block_means_at_any_thread_count() {
        let n = 3000;
        let pos: Vec<DVec3> = (0..n as u64)
            .map(|k| {
                DVec3::new(
                    crate::rng::uniform(5, k, 0) * 40.0 - 20.0,
                    crate::rng::uniform(5, k, 1) * 30.0,
                    crate::rng::uniform(5, k, 2) * 25.0 - 90.0,
                )
            })
            .collect();
        let vel: Vec<DVec3> = (0..n as u64)
            .map(|k| DVec3::new(crate::rng::uniform(6, k, 0) - 0.5, 1.0, k as f64 * 1e-3))
            .collect();
        let build = |threads: usize| {
            let mut p = unbonded(pos.clone(), vel.clone());
            let mut nl = NeighbourList::default();
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool")
                .install(|| nl.build(&mut p, 1.3, 4.0, false));
            (p, nl)
        };
        let (p, nl) = build(1);
        // Brute force over the particles in their (sorted) order.
        let mut sums: HashMap<u64, (DVec3, f64)> = HashMap::new();
        for (x, v) in p.pos.iter().zip(&p.vel) {
            let e = sums
                .entry(cell_key(*x, 0.25).0)
                .or_insert((DVec3::ZERO, 0.0));
            e.0 += *v;
            e.1 += 1.0;
        }
        for (x, u) in p.pos.iter().zip(&nl.frame_vel) {
            let (sum, count) = sums[&cell_key(*x, 0.25).0];
            assert!(
                (*u - sum / count).length() < 1e-12,
                "{u} vs {}",
                sum / count
            );
        }
        // The lists too: filled by one range of particles per thread (3: uneven ranges).
        assert!(nl.neighbours.len() > n / 2, "the test must list pairs");
        for threads in [3, 4] {
            let (pt, nlt) = build(threads);
            assert_eq!(pt.pos, p.pos);
            assert_eq!(nlt.frame_vel, nl.frame_vel);
            assert_eq!((nlt.near_dv, nlt.far_dv), (nl.near_dv, nl.far_dv));
            assert_eq!(nlt.start, nl.start, "{threads} threads");
            assert_eq!(nlt.neighbours, nl.neighbours, "{threads} threads");
            assert_eq!(nlt.later, nl.later, "{threads} threads");
        }
        // Each list ascending, its partners j > i from `later` on.
        for i in 0..n {
            let list = nl.of(i);
            assert!(
                list.windows(2).all(|w| w[0] < w[1]),
                "list of {i} ascending"
            );
            let split = nl.later[i] - nl.start[i];
            assert_eq!(split as usize, list.partition_point(|&j| (j as usize) < i));
        }
    }
}
