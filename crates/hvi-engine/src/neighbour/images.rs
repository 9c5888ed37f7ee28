//! Pairs across the mirror planes of quarter symmetry ([`crate::symmetry`]): a particle i
//! within the list radius of the plane x = 0 (or y = 0, or of both) interacts with the images
//! M j of the particles j near the same plane. The cell grid is anchored at the origin, so the
//! particles within one cell side of x = 0 are those of the cells with x index 0, and the
//! images of a cell's neighbours across the plane are in the same row of cells with x index 0:
//! for each cell next to a plane, nine cells per plane (three for the corner image) are
//! looked up by key.
//!
//! The image lists are full like the ordinary lists: (i, M j) is on i's list and (j, M i) on
//! j's, the two pairs of the full scene that cross the plane there; (i, M i) once. An image
//! pair is left out while the particle is bonded to its own image (an intact image bond).
//!
//! For the rebuild rule an image M j moves with the image of j's frame, so the blocks next to
//! a plane meet the images of the blocks next to it ([`image_block_pairs`]), and the bound on
//! any two frames' difference covers the reflected frames too ([`mirrored_frame_spread`]).

use glam::DVec3;
use rayon::prelude::*;

use super::{NeighbourList, COORD_BITS, COORD_OFFSET};
use crate::state::Particles;
use crate::symmetry::{
    image_bond_flags, reflect, IMAGE_INDEX_MASK, IMAGE_SHIFT, MIRROR_X, MIRROR_Y,
};

const COORD_MASK: u64 = (1 << COORD_BITS) - 1;
/// The grid coordinate of the cells (or blocks) just beyond a plane (x or y in [0, side)).
const PLANE: i64 = COORD_OFFSET;

fn split_key(k: u64) -> [i64; 3] {
    [
        (k & COORD_MASK) as i64,
        ((k >> COORD_BITS) & COORD_MASK) as i64,
        (k >> (2 * COORD_BITS)) as i64,
    ]
}

fn make_key(c: [i64; 3]) -> u64 {
    ((c[2] as u64) << (2 * COORD_BITS)) | ((c[1] as u64) << COORD_BITS) | c[0] as u64
}

/// The image codes that apply to a cell (or block) at grid coordinates `c`, each with the
/// keys of the cells whose images can be within one side of it.
fn image_neighbour_keys(c: [i64; 3]) -> Vec<(u32, u64)> {
    let (at_x, at_y) = (c[0] == PLANE, c[1] == PLANE);
    let mut keys = Vec::new();
    for code in [MIRROR_X, MIRROR_Y, MIRROR_X | MIRROR_Y] {
        if (code & MIRROR_X != 0 && !at_x) || (code & MIRROR_Y != 0 && !at_y) {
            continue;
        }
        let lateral: &[i64] = if code == MIRROR_X | MIRROR_Y {
            &[0]
        } else {
            &[-1, 0, 1]
        };
        for dz in -1..=1 {
            for &d in lateral {
                let [x, y] = match code {
                    MIRROR_X => [PLANE, c[1] + d],
                    MIRROR_Y => [c[0] + d, PLANE],
                    _ => [PLANE, PLANE],
                };
                keys.push((code, make_key([x, y, c[2] + dz])));
            }
        }
    }
    keys
}

impl NeighbourList {
    /// The image lists (`image_start`, `image_nbrs`) of the particles in cell order, with the
    /// cells of the current build; returns the largest squared relative speed |v_i - M v_j|
    /// of the image pairs within the radius when `measure_speed`.
    pub(super) fn search_images(&mut self, p: &Particles, r2: f64, measure_speed: bool) -> f64 {
        let n = p.len();
        let (cell_start, cell_keys) = (&self.cell_start, &self.cell_keys);
        let (xs, ys, zs) = (&self.xs, &self.ys, &self.zs);
        let near_plane: Vec<usize> = (0..cell_keys.len())
            .filter(|&c| {
                let k = split_key(cell_keys[c]);
                k[0] == PLANE || k[1] == PLANE
            })
            .collect();
        let found: Vec<(Vec<(u32, u32)>, f64)> = near_plane
            .par_iter()
            .map(|&c| {
                let ranges: Vec<(u32, usize, usize)> =
                    image_neighbour_keys(split_key(cell_keys[c]))
                        .into_iter()
                        .filter_map(|(code, key)| {
                            let d = cell_keys.binary_search(&key).ok()?;
                            Some((code, cell_start[d] as usize, cell_start[d + 1] as usize))
                        })
                        .collect();
                let mut pairs = Vec::new();
                let mut max_w2: f64 = 0.0;
                for i in cell_start[c] as usize..cell_start[c + 1] as usize {
                    let pi = DVec3::new(xs[i], ys[i], zs[i]);
                    for &(code, a, b) in &ranges {
                        for j in a..b {
                            let pj = reflect(DVec3::new(xs[j], ys[j], zs[j]), code);
                            if (pi - pj).length_squared() >= r2 {
                                continue;
                            }
                            if measure_speed {
                                let w2 = (p.vel[i] - reflect(p.vel[j], code)).length_squared();
                                max_w2 = max_w2.max(w2);
                            }
                            let bonded = i == j
                                && code != MIRROR_X | MIRROR_Y
                                && p.image_bonds[i] & image_bond_flags(code).0 != 0;
                            if !bonded {
                                pairs.push((i as u32, j as u32 | (code << IMAGE_SHIFT)));
                            }
                        }
                    }
                }
                (pairs, max_w2)
            })
            .collect();
        self.image_start.clear();
        self.image_start.resize(n + 1, 0);
        for &(i, _) in found.iter().flat_map(|f| &f.0) {
            self.image_start[i as usize + 1] += 1;
        }
        for k in 0..n {
            self.image_start[k + 1] += self.image_start[k];
        }
        self.image_nbrs.clear();
        self.image_nbrs
            .extend(found.iter().flat_map(|f| f.0.iter().map(|&(_, j)| j)));
        found.iter().fold(0.0, |a, f| a.max(f.1))
    }

    /// Image pairs of particle i: entries `j | code << IMAGE_SHIFT` (see
    /// [`crate::symmetry`]); empty for a full scene.
    #[inline(always)]
    pub fn images_of(&self, i: usize) -> &[u32] {
        if self.image_start.is_empty() {
            return &[];
        }
        &self.image_nbrs[self.image_start[i] as usize..self.image_start[i + 1] as usize]
    }
}

/// Splits an image-list entry into the partner's index and the image code.
#[inline(always)]
pub fn split_image(entry: u32) -> (usize, u32) {
    ((entry & IMAGE_INDEX_MASK) as usize, entry >> IMAGE_SHIFT)
}

/// The pairs of blocks next to a plane and images of blocks next to it that meet (blocks
/// given as key, frame velocity and dense index, sorted by key), with |u_a - M u_b|, m/s:
/// each block with its own image included.
pub(super) fn image_block_pairs(blocks: &[(u64, DVec3, u32)]) -> Vec<(u32, u32, f64)> {
    blocks
        .par_iter()
        .flat_map_iter(|&(key, u, a)| {
            let c = split_key(key);
            let near = c[0] == PLANE || c[1] == PLANE;
            let keys = if near {
                image_neighbour_keys(c)
            } else {
                Vec::new()
            };
            keys.into_iter().filter_map(move |(code, k)| {
                let b = blocks.binary_search_by_key(&k, |b| b.0).ok()?;
                Some((a, blocks[b].2, (u - reflect(blocks[b].1, code)).length()))
            })
        })
        .collect()
}

/// The box of the frames `lo..hi` (component-wise) widened by their reflections: the bound on
/// any two frames' difference, images included, is its diagonal.
pub(super) fn mirrored_frame_spread(lo: DVec3, hi: DVec3) -> (DVec3, DVec3) {
    let lo2 = DVec3::new(lo.x.min(-hi.x), lo.y.min(-hi.y), lo.z);
    let hi2 = DVec3::new(hi.x.max(-lo.x), hi.y.max(-lo.y), hi.z);
    (lo2, hi2)
}
