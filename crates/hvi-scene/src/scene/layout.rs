//! The lattice layout: both bodies as simple cubic lattices at spacing r_eq, symmetric about
//! the impact axis, then the particles with their bonds (lattice nearest neighbours of the same
//! body), masses and seeded thermal velocities.

use glam::DVec3;

use super::spec::Geometry;
use crate::error::{check_range, EngineError, Result};
use crate::rng;
use crate::state::{Body, Particles, BONDS_PER_PARTICLE, NO_BOND};
use crate::symmetry::{Symmetry, IMAGE_BOND_X, IMAGE_BOND_Y};

/// Lattice sites of both bodies with integer coordinates, before masses and velocities.
pub(super) struct Layout {
    /// Integer lattice coordinates of each site.
    sites: Vec<[i32; 3]>,
    body: Vec<Body>,
    r_eq: f64,
    /// Lateral offset (0 or 1/2 r_eq) so that the lattice is symmetric about the impact axis.
    lateral_offset: f64,
    /// z shift of the impactor sites, m.
    impactor_z_shift: f64,
    /// z of the target plate's rear face, m.
    pub(super) plate_rear_z: f64,
    /// Only the quarter x > 0, y > 0 is kept ([`Self::keep_quarter`]).
    quarter: bool,
}

/// The six lattice directions, in bond-slot order (+x, -x, +y, -y, +z, -z).
const DIRS: [[i32; 3]; BONDS_PER_PARTICLE] = [
    [1, 0, 0],
    [-1, 0, 0],
    [0, 1, 0],
    [0, -1, 0],
    [0, 0, 1],
    [0, 0, -1],
];

impl Layout {
    /// Sites of body `b`.
    pub(super) fn count(&self, b: Body) -> usize {
        self.body.iter().filter(|&&x| x == b).count()
    }

    fn position(&self, k: usize) -> DVec3 {
        let [i, j, l] = self.sites[k];
        let mut p = DVec3::new(
            (i as f64 + self.lateral_offset) * self.r_eq,
            (j as f64 + self.lateral_offset) * self.r_eq,
            (l as f64 + 0.5) * self.r_eq,
        );
        if self.body[k] == Body::Impactor {
            p.z += self.impactor_z_shift;
        }
        p
    }

    /// Keeps the sites of the quarter x > 0, y > 0 (the lattice is symmetric about both
    /// planes with none of its sites on them: an even number of sites per side); the sites
    /// next to a plane get a bond to their own image across it ([`crate::symmetry`]).
    pub(super) fn keep_quarter(&mut self) {
        debug_assert_eq!(
            self.lateral_offset, 0.5,
            "quarter symmetry needs even sides"
        );
        let keep: Vec<bool> = self.sites.iter().map(|s| s[0] >= 0 && s[1] >= 0).collect();
        let mut k = 0;
        self.sites.retain(|_| {
            k += 1;
            keep[k - 1]
        });
        let mut k = 0;
        self.body.retain(|_| {
            k += 1;
            keep[k - 1]
        });
        self.quarter = true;
    }

    /// Moves the impactor's sites by -`dz` along z.
    pub(super) fn shift_impactor(&mut self, dz: f64) {
        self.impactor_z_shift -= dz;
    }

    /// Closest distance between an impactor and a target site (the impactor's leading layer
    /// against the target's front layer; both lattices are aligned laterally).
    pub(super) fn closest_impactor_target_distance(&self) -> f64 {
        let lead = (0..self.sites.len())
            .filter(|&k| self.body[k] == Body::Impactor)
            .map(|k| self.position(k).z)
            .fold(f64::NEG_INFINITY, f64::max);
        let front = (0..self.sites.len())
            .filter(|&k| self.body[k] == Body::Target)
            .map(|k| self.position(k).z)
            .fold(f64::INFINITY, f64::min);
        front - lead
    }

    /// The particles: positions, thermal velocities (per-component standard deviation
    /// `thermal` v0, seeded), each body's particle mass, and the lattice bonds.
    pub(super) fn into_particles(
        self,
        mass_imp: f64,
        mass_tgt: f64,
        v0: f64,
        thermal: f64,
        seed: u64,
    ) -> Particles {
        let n = self.sites.len();
        let pos: Vec<DVec3> = (0..n).map(|k| self.position(k)).collect();
        let bonds = self.lattice_bonds();
        let vel = self.thermal_velocities(v0, thermal, seed);
        let mass: Vec<f64> = self
            .body
            .iter()
            .map(|b| {
                if *b == Body::Impactor {
                    mass_imp
                } else {
                    mass_tgt
                }
            })
            .collect();
        let image_bonds: Vec<u8> = if self.quarter {
            self.sites
                .iter()
                .map(|s| {
                    (if s[0] == 0 { IMAGE_BOND_X } else { 0 })
                        | (if s[1] == 0 { IMAGE_BOND_Y } else { 0 })
                })
                .collect()
        } else {
            Vec::new()
        };
        let mut p = Particles::new(pos, vel, mass, self.body, bonds);
        p.image_bonds = image_bonds;
        p
    }

    /// Bonds: lattice nearest neighbours of the same body, found through a dense index grid;
    /// `BONDS_PER_PARTICLE` slots per site in the order of [`DIRS`].
    fn lattice_bonds(&self) -> Vec<u32> {
        let n = self.sites.len();
        let lo = self.sites.iter().fold([i32::MAX; 3], |a, s| {
            [a[0].min(s[0]), a[1].min(s[1]), a[2].min(s[2])]
        });
        let hi = self.sites.iter().fold([i32::MIN; 3], |a, s| {
            [a[0].max(s[0]), a[1].max(s[1]), a[2].max(s[2])]
        });
        let dim = [
            (hi[0] - lo[0] + 1) as usize,
            (hi[1] - lo[1] + 1) as usize,
            (hi[2] - lo[2] + 1) as usize,
        ];
        let cell = |s: [i32; 3]| -> Option<usize> {
            if (0..3).any(|a| s[a] < lo[a] || s[a] > hi[a]) {
                return None;
            }
            Some(
                ((s[2] - lo[2]) as usize * dim[1] + (s[1] - lo[1]) as usize) * dim[0]
                    + (s[0] - lo[0]) as usize,
            )
        };
        let mut grid = vec![NO_BOND; dim[0] * dim[1] * dim[2]];
        for (k, &s) in self.sites.iter().enumerate() {
            if let Some(c) = cell(s) {
                grid[c] = k as u32;
            }
        }
        let mut bonds = vec![NO_BOND; n * BONDS_PER_PARTICLE];
        for (k, &s) in self.sites.iter().enumerate() {
            for (slot, d) in DIRS.iter().enumerate() {
                let t = [s[0] + d[0], s[1] + d[1], s[2] + d[2]];
                if let Some(c) = cell(t) {
                    let other = grid[c];
                    if other != NO_BOND && self.body[other as usize] == self.body[k] {
                        bonds[k * BONDS_PER_PARTICLE + slot] = other;
                    }
                }
            }
        }
        bonds
    }

    /// Thermal velocities: Gaussian per component, counter-based on (seed, particle, axis),
    /// with each body's mean removed so the impactor moves at exactly v0.
    fn thermal_velocities(&self, v0: f64, thermal: f64, seed: u64) -> Vec<DVec3> {
        let n = self.sites.len();
        let sd = thermal * v0;
        let mut vel: Vec<DVec3> = (0..n)
            .map(|k| {
                DVec3::new(
                    rng::normal(seed, k as u64, 0),
                    rng::normal(seed, k as u64, 1),
                    rng::normal(seed, k as u64, 2),
                ) * sd
            })
            .collect();
        for b in [Body::Impactor, Body::Target] {
            let members: Vec<usize> = (0..n).filter(|&k| self.body[k] == b).collect();
            if members.is_empty() {
                continue;
            }
            let mean = members.iter().fold(DVec3::ZERO, |a, &k| a + vel[k]) / members.len() as f64;
            let drift = if b == Body::Impactor {
                DVec3::new(0.0, 0.0, v0)
            } else {
                DVec3::ZERO
            };
            for &k in &members {
                vel[k] = vel[k] - mean + drift;
            }
        }
        vel
    }
}

/// The lattice sites of `geometry` at spacing `r_eq`, or an error naming the key when a body
/// would be less than one particle thick or the lattice too large.
/// Under quarter symmetry the plate has an even number of sites per side (its width rounded to
/// the nearest even count), so that the mirror planes pass between lattice layers.
pub(super) fn lay_out(geometry: &Geometry, r_eq: f64, symmetry: Symmetry) -> Result<Layout> {
    let even = symmetry == Symmetry::Quarter;
    match *geometry {
        Geometry::SphereOnPlate {
            diameter_m,
            t_over_d,
            width_over_d,
            ..
        } => lay_out_sphere_on_plate(diameter_m, t_over_d, width_over_d, r_eq, even),
        Geometry::FlyerPlate {
            flyer_thickness_m,
            target_thickness_m,
            width_m,
            ..
        } => lay_out_flyer_plate(flyer_thickness_m, target_thickness_m, width_m, r_eq, even),
    }
}

/// Particle layers through a plate of thickness `thickness_m` at spacing `r_eq`: the nearest
/// whole number. Both geometries lay out their plates as this many lattice layers, and
/// quarter symmetry keeps every layer (it halves the plate only laterally), so this is the
/// one count the resolution's checks (`resolution`) read.
pub(super) fn layer_count(thickness_m: f64, r_eq: f64) -> i64 {
    (thickness_m / r_eq).round() as i64
}

/// Sites per side of a square of side `width` at spacing `r_eq` (at least 1, or 2 when
/// `even`).
fn sites_per_side(width: f64, r_eq: f64, even: bool) -> i64 {
    if even {
        2 * ((0.5 * width / r_eq).round() as i64).max(1)
    } else {
        ((width / r_eq).round() as i64).max(1)
    }
}

/// A square of `nxy` sites per side, symmetric about the axis: sites at integer (`nxy` odd)
/// or half-integer (even) offsets. Returns the lateral offset and the first and last index.
fn square_indices(nxy: i64) -> (f64, i64, i64) {
    let lateral_offset = if nxy % 2 == 1 { 0.0 } else { 0.5 };
    let half = nxy / 2;
    let (ilo, ihi) = if nxy % 2 == 1 {
        (-half, half)
    } else {
        (-half, half - 1)
    };
    (lateral_offset, ilo, ihi)
}

/// A plate of `nxy` x `nxy` sites per layer over the layers `layers`, each site's body given
/// by its layer.
fn push_plate(
    sites: &mut Vec<[i32; 3]>,
    body: &mut Vec<Body>,
    nxy: i64,
    layers: std::ops::Range<i64>,
    body_of_layer: impl Fn(i64) -> Body,
) {
    let (_, ilo, ihi) = square_indices(nxy);
    for k in layers {
        for j in ilo..=ihi {
            for i in ilo..=ihi {
                sites.push([i as i32, j as i32, k as i32]);
                body.push(body_of_layer(k));
            }
        }
    }
}

fn lay_out_sphere_on_plate(
    diameter_m: f64,
    t_over_d: f64,
    width_over_d: f64,
    r_eq: f64,
    even: bool,
) -> Result<Layout> {
    let t = t_over_d * diameter_m;
    let nz = layer_count(t, r_eq);
    if nz < 1 {
        return Err(EngineError::invalid(
            "scene.t_over_d",
            t_over_d,
            format!(
                "a plate at least one particle thick: t/D >= {:.4} at this resolution \
                 (r_eq = {r_eq:.3e} m); raise the resolution or t/D",
                0.5 * r_eq / diameter_m
            ),
        ));
    }
    let nxy = sites_per_side(width_over_d * diameter_m, r_eq, even);
    let nsphere = diameter_m / r_eq;
    if nsphere < 1.0 {
        return Err(EngineError::invalid(
            "resolution",
            format!("r_eq = {r_eq:.3e} m"),
            "at least one particle across the sphere diameter",
        ));
    }
    check_range(
        "resolution (total sites)",
        (nxy * nxy * nz) as f64,
        1.0,
        false,
        5e8,
        false,
    )?;
    let (lateral_offset, _, _) = square_indices(nxy);
    let mut sites = Vec::new();
    let mut body = Vec::new();
    push_plate(&mut sites, &mut body, nxy, 0..nz, |_| Body::Target);
    let sphere = sphere_sites(0.5 * diameter_m, lateral_offset, r_eq)?;
    for s in sphere {
        sites.push(s);
        body.push(Body::Impactor);
    }
    Ok(Layout {
        sites,
        body,
        r_eq,
        lateral_offset,
        impactor_z_shift: 0.0,
        plate_rear_z: nz as f64 * r_eq,
        quarter: false,
    })
}

/// Sphere sites on the plate's lattice, symmetric about the sphere's centre in all three
/// directions, then shifted by whole lattice steps so that the leading layer sits at l = -1
/// (one lattice spacing in front of the plate's first layer at l = 0): contact starts at t = 0.
fn sphere_sites(radius: f64, lateral_offset: f64, r_eq: f64) -> Result<Vec<[i32; 3]>> {
    let m = (radius / r_eq).ceil() as i64 + 1;
    let mut sphere = Vec::new();
    for l in -m..=m {
        for j in -m..=m {
            for i in -m..=m {
                let x = (i as f64 + lateral_offset) * r_eq;
                let y = (j as f64 + lateral_offset) * r_eq;
                let z = (l as f64 + lateral_offset) * r_eq;
                if x * x + y * y + z * z <= radius * radius {
                    sphere.push([i as i32, j as i32, l as i32]);
                }
            }
        }
    }
    if sphere.is_empty() {
        return Err(EngineError::invalid(
            "resolution",
            format!("r_eq = {r_eq:.3e} m"),
            "a resolution that puts at least one site inside the sphere",
        ));
    }
    let lead = sphere.iter().map(|s| s[2]).max().unwrap_or(0);
    for s in &mut sphere {
        s[2] -= lead + 1;
    }
    Ok(sphere)
}

fn lay_out_flyer_plate(
    flyer_thickness_m: f64,
    target_thickness_m: f64,
    width_m: f64,
    r_eq: f64,
    even: bool,
) -> Result<Layout> {
    let nt = layer_count(target_thickness_m, r_eq);
    let nf = layer_count(flyer_thickness_m, r_eq);
    if nt < 1 {
        return Err(EngineError::invalid(
            "scene.target_thickness_m",
            target_thickness_m,
            format!(
                ">= {:.3e} m (one particle at r_eq = {r_eq:.3e} m)",
                0.5 * r_eq
            ),
        ));
    }
    if nf < 1 {
        return Err(EngineError::invalid(
            "scene.flyer_thickness_m",
            flyer_thickness_m,
            format!(
                ">= {:.3e} m (one particle at r_eq = {r_eq:.3e} m)",
                0.5 * r_eq
            ),
        ));
    }
    let nxy = sites_per_side(width_m, r_eq, even);
    check_range(
        "resolution (total sites)",
        (nxy * nxy * (nt + nf)) as f64,
        1.0,
        false,
        5e8,
        false,
    )?;
    let (lateral_offset, _, _) = square_indices(nxy);
    let mut sites = Vec::new();
    let mut body = Vec::new();
    push_plate(&mut sites, &mut body, nxy, -nf..nt, |k| {
        if k < 0 {
            Body::Impactor
        } else {
            Body::Target
        }
    });
    Ok(Layout {
        sites,
        body,
        r_eq,
        lateral_offset,
        impactor_z_shift: 0.0,
        plate_rear_z: nt as f64 * r_eq,
        quarter: false,
    })
}

/// Ids of target particles on the plate's lateral rim (outermost lattice ring) at t = 0.
pub(super) fn rim_ids(p: &Particles, r_eq: f64) -> Vec<u32> {
    let mut max_x: f64 = 0.0;
    for k in 0..p.len() {
        if p.body[k] == Body::Target {
            max_x = max_x.max(p.pos[k].x.abs()).max(p.pos[k].y.abs());
        }
    }
    (0..p.len())
        .filter(|&k| {
            p.body[k] == Body::Target
                && (p.pos[k].x.abs().max(p.pos[k].y.abs()) > max_x - 0.5 * r_eq)
        })
        .map(|k| p.id[k])
        .collect()
}
