//! A synthetic shadowgraph: the debris cloud as the experiment's side-on camera sees it.
//!
//! The experiment measures La, Lr and the front from high-speed photographs of the cloud's
//! silhouette (docs/model.md section 5), not from particle positions. The model's particles
//! stand for much finer debris, so the camera is modelled on the cloud's projected areal mass
//! density, not on the particles' own cross-sections: each particle's mass is deposited on a pixel grid in
//! (x, z), seen side-on along y (cloud-in-cell, in particle-id order), and blurred with a
//! Gaussian of standard deviation `blur_m` (the camera's resolution, and the scale over which
//! the model's discrete particles stand for a continuous cloud). Debris of grain diameter
//! `grain_m` and density rho with areal density Sigma has optical depth
//! tau = (3/2) Sigma / (rho d) (opaque spheres, Beer-Lambert), and a pixel is dark at
//! tau >= `optical_depth`. The silhouette is the largest connected region of dark pixels (the
//! cloud's bulk; specks apart from it are left out, as a photograph's reader would). From it:
//! the front is the far edge of its farthest pixel along z, La the front minus the plate's
//! original rear face, Lr its full width in x, R = La/Lr.
//!
//! ```
//! use glam::DVec3;
//! use hvi_scene::shadowgraph::{Shadowgraph, ShadowgraphSettings};
//! // A dense 10 x 10 x 20 block of particles 1 mm apart (1 mg each), its lower face at z = 0.
//! let pos: Vec<DVec3> = (0..2000)
//!     .map(|k| DVec3::new((k % 10) as f64, ((k / 10) % 10) as f64, (k / 100) as f64) * 1e-3)
//!     .collect();
//! let settings = ShadowgraphSettings { blur_m: 0.5e-3, ..ShadowgraphSettings::default() };
//! let s = Shadowgraph::of(&pos, 1e-6, 2700.0, &settings).expect("a cloud");
//! let (_, _, z_lo, _, _) = s.dark_extent().expect("a silhouette");
//! let m = s.measure(z_lo).expect("a silhouette");
//! assert!((m.length_ratio - 2.0).abs() < 0.25, "{m:?}");
//! ```

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Default pixel size, m.
pub const DEFAULT_PIXEL_M: f64 = 0.5e-3;
/// Default camera blur (standard deviation), m.
pub const DEFAULT_BLUR_M: f64 = 2e-3;
/// Default grain diameter of the debris the camera sees, m.
pub const DEFAULT_GRAIN_M: f64 = 10e-6;
/// Default threshold optical depth of the silhouette (transmission 1/e).
pub const DEFAULT_OPTICAL_DEPTH: f64 = 1.0;
/// The largest image, in pixels; a larger one is refused (choose a coarser pixel).
pub const MAX_PIXELS: usize = 50_000_000;

/// How the synthetic camera images the cloud.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ShadowgraphSettings {
    /// Pixel size, m (square pixels in x and z).
    pub pixel_m: f64,
    /// Standard deviation of the Gaussian blur, m (0: none).
    pub blur_m: f64,
    /// Grain diameter of the debris, m: sets the optical depth of an areal density.
    pub grain_m: f64,
    /// Optical depth at and above which a pixel is dark.
    pub optical_depth: f64,
}

impl Default for ShadowgraphSettings {
    fn default() -> Self {
        ShadowgraphSettings {
            pixel_m: DEFAULT_PIXEL_M,
            blur_m: DEFAULT_BLUR_M,
            grain_m: DEFAULT_GRAIN_M,
            optical_depth: DEFAULT_OPTICAL_DEPTH,
        }
    }
}

/// The optical depth of the cloud on a pixel grid, seen along y.
#[derive(Debug, Clone, PartialEq)]
pub struct Shadowgraph {
    /// Pixels along x.
    pub nx: usize,
    /// Pixels along z.
    pub nz: usize,
    /// x of the centre of pixel column 0, m.
    pub x0_m: f64,
    /// z of the centre of pixel row 0, m.
    pub z0_m: f64,
    /// The settings it was taken with.
    pub settings: ShadowgraphSettings,
    /// Optical depth per pixel, row-major (index z * nx + x).
    pub tau: Vec<f64>,
}

/// La, Lr and R of a silhouette.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SilhouetteMeasurement {
    /// The far edge of the farthest dark pixel along z, m.
    pub front_z_m: f64,
    /// La: the front minus the plate's original rear face, m.
    pub length_axial_m: f64,
    /// Lr: the full width of the dark pixels along x, m.
    pub length_radial_m: f64,
    /// R = La / Lr.
    pub length_ratio: f64,
    /// Dark pixels.
    pub dark_pixels: usize,
}

impl Shadowgraph {
    /// Images particles at `pos` (pass them in id order, so the sums do not depend on storage
    /// order), each of mass `mass_kg`, of material of density `density_kg_m3`. `None` when
    /// there is no particle, the settings are not positive and finite, or the image would
    /// exceed [`MAX_PIXELS`].
    pub fn of(
        pos: &[DVec3],
        mass_kg: f64,
        density_kg_m3: f64,
        settings: &ShadowgraphSettings,
    ) -> Option<Shadowgraph> {
        let grains: Vec<(DVec3, f64)> = pos.iter().map(|&p| (p, mass_kg)).collect();
        Shadowgraph::of_masses(&grains, density_kg_m3, settings)
    }

    /// Images particles given as (position, mass), in id order; see [`Shadowgraph::of`].
    pub fn of_masses(
        particles: &[(DVec3, f64)],
        density_kg_m3: f64,
        settings: &ShadowgraphSettings,
    ) -> Option<Shadowgraph> {
        let h = settings.pixel_m;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let valid = positive(h)
            && positive(settings.grain_m)
            && positive(settings.optical_depth)
            && positive(density_kg_m3)
            && settings.blur_m.is_finite()
            && settings.blur_m >= 0.0;
        if particles.is_empty() || !valid {
            return None;
        }
        let lo = particles.iter().map(|p| p.0).reduce(DVec3::min)?;
        let hi = particles.iter().map(|p| p.0).reduce(DVec3::max)?;
        // Room for the blur's tails (3 standard deviations) and one empty pixel on every side.
        let pad = 3.0 * settings.blur_m + h;
        let x0 = lo.x - pad;
        let z0 = lo.z - pad;
        let nx = ((hi.x + pad - x0) / h).floor() as usize + 2;
        let nz = ((hi.z + pad - z0) / h).floor() as usize + 2;
        if !matches!(nx.checked_mul(nz), Some(n) if n <= MAX_PIXELS) {
            return None;
        }
        let mut s = Shadowgraph {
            nx,
            nz,
            x0_m: x0,
            z0_m: z0,
            settings: *settings,
            tau: vec![0.0; nx * nz],
        };
        // Optical depth per kilogram in one pixel: (3/2) / (rho d) / h^2.
        let per_kg = 1.5 / (density_kg_m3 * settings.grain_m) / (h * h);
        for &(p, m) in particles {
            s.deposit(p.x, p.z, per_kg * m);
        }
        s.blur();
        Some(s)
    }

    /// Convolves the image with the Gaussian of `blur_m` (separably, in x then z), truncated
    /// at three standard deviations and normalised, so the total optical depth is kept.
    fn blur(&mut self) {
        let sigma_px = self.settings.blur_m / self.settings.pixel_m;
        if sigma_px < 1e-3 {
            return;
        }
        let r = (3.0 * sigma_px).ceil() as usize;
        let mut kernel: Vec<f64> = (0..=2 * r)
            .map(|k| {
                let d = k as f64 - r as f64;
                (-0.5 * d * d / (sigma_px * sigma_px)).exp()
            })
            .collect();
        let total: f64 = kernel.iter().sum();
        kernel.iter_mut().for_each(|w| *w /= total);
        let (nx, nz) = (self.nx, self.nz);
        let mut tmp = vec![0.0; nx * nz];
        for j in 0..nz {
            for i in 0..nx {
                let (a, b) = (i.saturating_sub(r), (i + r).min(nx - 1));
                tmp[j * nx + i] = (a..=b)
                    .map(|k| kernel[k + r - i] * self.tau[j * nx + k])
                    .sum();
            }
        }
        for j in 0..nz {
            for i in 0..nx {
                let (a, b) = (j.saturating_sub(r), (j + r).min(nz - 1));
                self.tau[j * nx + i] = (a..=b).map(|k| kernel[k + r - j] * tmp[k * nx + i]).sum();
            }
        }
    }

    /// Adds optical depth `tau` at (x, z), shared among the four nearest pixel centres.
    fn deposit(&mut self, x: f64, z: f64, tau: f64) {
        let h = self.settings.pixel_m;
        let u = (x - self.x0_m) / h;
        let v = (z - self.z0_m) / h;
        let (i, j) = (u.floor(), v.floor());
        let (fx, fz) = (u - i, v - j);
        let (i, j) = (i as usize, j as usize);
        let weights = [
            (0, 0, (1.0 - fx) * (1.0 - fz)),
            (1, 0, fx * (1.0 - fz)),
            (0, 1, (1.0 - fx) * fz),
            (1, 1, fx * fz),
        ];
        for (di, dj, w) in weights {
            self.tau[(j + dj) * self.nx + i + di] += w * tau;
        }
    }

    /// Whether pixel (i, j) is dark.
    pub fn is_dark(&self, i: usize, j: usize) -> bool {
        self.tau[j * self.nx + i] >= self.settings.optical_depth
    }

    /// The silhouette: the largest 4-connected region of dark pixels (the cloud's bulk, as the
    /// experiment measures it; isolated specks ahead of it or beside it are left out), as a
    /// mask over the pixels. Ties go to the region found first (lowest z, then x).
    pub fn silhouette_mask(&self) -> Vec<bool> {
        let (nx, nz) = (self.nx, self.nz);
        let mut region = vec![u32::MAX; nx * nz];
        let (mut best, mut best_size) = (u32::MAX, 0usize);
        let mut stack = Vec::new();
        let mut next = 0u32;
        for start in 0..nx * nz {
            if region[start] != u32::MAX || self.tau[start] < self.settings.optical_depth {
                continue;
            }
            let (id, mut size) = (next, 0usize);
            next += 1;
            region[start] = id;
            stack.push(start);
            while let Some(k) = stack.pop() {
                size += 1;
                let (i, j) = (k % nx, k / nx);
                let mut visit = |n: usize| {
                    if region[n] == u32::MAX && self.tau[n] >= self.settings.optical_depth {
                        region[n] = id;
                        stack.push(n);
                    }
                };
                if i > 0 {
                    visit(k - 1);
                }
                if i + 1 < nx {
                    visit(k + 1);
                }
                if j > 0 {
                    visit(k - nx);
                }
                if j + 1 < nz {
                    visit(k + nx);
                }
            }
            if size > best_size {
                (best, best_size) = (id, size);
            }
        }
        region
            .iter()
            .map(|&r| r == best && best != u32::MAX)
            .collect()
    }

    /// The silhouette's outer edges: (x low, x high, z low, z high) in m, and its pixel count;
    /// `None` when no pixel is dark.
    pub fn dark_extent(&self) -> Option<(f64, f64, f64, f64, usize)> {
        let h = self.settings.pixel_m;
        let mask = self.silhouette_mask();
        let mut dark = 0;
        let (mut i_lo, mut i_hi, mut j_lo, mut j_hi) = (usize::MAX, 0, usize::MAX, 0);
        for (k, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
            let (i, j) = (k % self.nx, k / self.nx);
            dark += 1;
            i_lo = i_lo.min(i);
            i_hi = i_hi.max(i);
            j_lo = j_lo.min(j);
            j_hi = j_hi.max(j);
        }
        (dark > 0).then_some((
            self.x0_m + (i_lo as f64 - 0.5) * h,
            self.x0_m + (i_hi as f64 + 0.5) * h,
            self.z0_m + (j_lo as f64 - 0.5) * h,
            self.z0_m + (j_hi as f64 + 0.5) * h,
            dark,
        ))
    }

    /// The optical depth at (x, z), m: that of the pixel holding it (0 outside the image).
    pub fn tau_at(&self, x: f64, z: f64) -> f64 {
        let h = self.settings.pixel_m;
        let i = ((x - self.x0_m) / h + 0.5).floor();
        let j = ((z - self.z0_m) / h + 0.5).floor();
        if i < 0.0 || j < 0.0 || i >= self.nx as f64 || j >= self.nz as f64 {
            return 0.0;
        }
        self.tau[j as usize * self.nx + i as usize]
    }

    /// The silhouette's La, Lr and R, with La measured from the plate's original rear face
    /// at `plate_rear_z_m`; `None` when no pixel is dark.
    pub fn measure(&self, plate_rear_z_m: f64) -> Option<SilhouetteMeasurement> {
        let (x_lo, x_hi, _, front_z_m, dark) = self.dark_extent()?;
        let length_axial_m = front_z_m - plate_rear_z_m;
        let length_radial_m = x_hi - x_lo;
        Some(SilhouetteMeasurement {
            front_z_m,
            length_axial_m,
            length_radial_m,
            length_ratio: length_axial_m / length_radial_m,
            dark_pixels: dark,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sites of a simple cubic lattice (spacing `a`) inside a ball of radius `r` about `c`.
    fn ball(c: DVec3, r: f64, a: f64) -> Vec<DVec3> {
        let n = (r / a).ceil() as i64;
        let mut v = Vec::new();
        for i in -n..=n {
            for j in -n..=n {
                for k in -n..=n {
                    let p = DVec3::new(i as f64, j as f64, k as f64) * a;
                    if p.length() <= r {
                        v.push(c + p);
                    }
                }
            }
        }
        v
    }

    #[test]
    fn a_sphere_of_particles_has_r_one_by_silhouette() {
        let (a, r) = (0.24e-3, 5e-3);
        let c = DVec3::new(0.0, 0.0, 20e-3);
        let pos = ball(c, r, a);
        let m = 2700.0 * a.powi(3);
        for (pixel_m, blur_m) in [(0.1e-3, 0.25e-3), (0.25e-3, 0.5e-3), (0.5e-3, 2e-3)] {
            let settings = ShadowgraphSettings {
                pixel_m,
                blur_m,
                ..ShadowgraphSettings::default()
            };
            let s = Shadowgraph::of(&pos, m, 2700.0, &settings).expect("image");
            // La from the silhouette's own near edge, so La and Lr both see its diameter.
            let (_, _, z_lo, _, _) = s.dark_extent().expect("dark");
            let sil = s.measure(z_lo).expect("silhouette");
            assert!((sil.length_ratio - 1.0).abs() < 0.05, "{pixel_m}: {sil:?}");
            // The edge moves out by the blur at most (the sphere is far above the threshold).
            let edge = 2.0 * pixel_m.max(a) + 3.0 * blur_m;
            assert!(
                (sil.length_radial_m - 2.0 * r).abs() < 2.0 * edge,
                "{sil:?}"
            );
            assert!((sil.front_z_m - (c.z + r)).abs() < edge, "{sil:?}");
        }
    }

    #[test]
    fn the_threshold_is_an_areal_density_whatever_the_particle_count() {
        // The same 1 g spread evenly over 10 mm x 10 mm (a thin sheet seen face-on), as 100 or
        // as 10,000 particles: the same optical depth, (3/2) Sigma / (rho d).
        let settings = ShadowgraphSettings {
            pixel_m: 1e-3,
            blur_m: 1e-3,
            ..ShadowgraphSettings::default()
        };
        let tau_of = |n: usize| {
            let side = (n as f64).sqrt() as usize;
            let pos: Vec<DVec3> = (0..n)
                .map(|k| {
                    DVec3::new((k % side) as f64, 0.0, (k / side) as f64) * (10e-3 / side as f64)
                })
                .collect();
            let s = Shadowgraph::of(&pos, 1e-3 / n as f64, 2700.0, &settings).expect("image");
            s.tau_at(5e-3, 5e-3)
        };
        let sigma = 1e-3 / (10e-3 * 10e-3);
        let expected = 1.5 * sigma / (2700.0 * DEFAULT_GRAIN_M);
        for n in [100, 10_000] {
            let tau = tau_of(n);
            assert!(
                (tau / expected - 1.0).abs() < 0.1,
                "{n}: {tau} vs {expected}"
            );
        }
    }

    #[test]
    fn a_thin_scatter_casts_no_shadow_and_the_total_is_kept() {
        let sparse: Vec<DVec3> = (0..100)
            .map(|k| DVec3::new((k % 10) as f64 * 20e-3, 0.0, (k / 10) as f64 * 20e-3))
            .collect();
        let settings = ShadowgraphSettings::default();
        let m = 1e-9;
        let s = Shadowgraph::of(&sparse, m, 2700.0, &settings).expect("image");
        assert_eq!(s.measure(0.0), None);
        // The blur keeps the total optical depth: N m (3/2) / (rho d) / h^2.
        let total: f64 = s.tau.iter().sum();
        let h = settings.pixel_m;
        let expected = 100.0 * m * 1.5 / (2700.0 * settings.grain_m) / (h * h);
        assert!(
            (total - expected).abs() < 1e-9 * expected,
            "{total} vs {expected}"
        );
    }

    #[test]
    fn a_dense_speck_apart_from_the_cloud_is_not_its_front() {
        let (a, r) = (0.24e-3, 5e-3);
        let c = DVec3::new(0.0, 0.0, 20e-3);
        let mut pos = ball(c, r, a);
        let m = 2700.0 * a.powi(3);
        let settings = ShadowgraphSettings {
            blur_m: 0.5e-3,
            ..ShadowgraphSettings::default()
        };
        let alone = Shadowgraph::of(&pos, m, 2700.0, &settings).expect("image");
        let front = alone.measure(0.0).expect("silhouette").front_z_m;
        // A small dense clump 20 mm ahead: dark, but not connected to the cloud.
        pos.extend(ball(c + DVec3::new(0.0, 0.0, 25e-3), 1e-3, a));
        let both = Shadowgraph::of(&pos, m, 2700.0, &settings).expect("image");
        assert_eq!(both.measure(0.0).expect("silhouette").front_z_m, front);
    }

    #[test]
    fn bad_settings_and_empty_clouds_give_no_image() {
        let p = [DVec3::ZERO];
        let bad = ShadowgraphSettings {
            pixel_m: 0.0,
            ..ShadowgraphSettings::default()
        };
        assert!(Shadowgraph::of(&p, 1e-6, 2700.0, &bad).is_none());
        assert!(Shadowgraph::of(&[], 1e-6, 2700.0, &ShadowgraphSettings::default()).is_none());
        let huge = [DVec3::ZERO, DVec3::new(10.0, 0.0, 10.0)];
        assert!(Shadowgraph::of(&huge, 1e-6, 2700.0, &ShadowgraphSettings::default()).is_none());
    }
}
