//! A synthetic shadowgraph: the debris cloud as the experiment's side-on camera sees it.
//!
//! The experiment measures La, Lr and the front from high-speed photographs of the cloud's
//! silhouette (MODEL.md 5), not from particle positions. Here every particle is an opaque
//! sphere of the particle's volume-equivalent diameter d, seen side-on along y onto a pixel
//! grid in (x, z). For particles scattered at random within a pixel's column, the light
//! transmitted is exp(-tau) with the optical depth tau = N (pi d^2 / 4) / A_pixel
//! (Beer-Lambert for opaque grains). A pixel is dark, part of the silhouette, when tau reaches
//! the threshold `optical_depth` (default 1: transmission 1/e).
//!
//! Each particle's cross-section is deposited on the four nearest pixel centres
//! (cloud-in-cell), so the picture does not depend on where the grid's origin falls. From the
//! silhouette: the front is the far edge of the farthest dark pixel along z, La the front
//! minus the plate's original rear face, Lr the full width of the dark pixels in x, R = La/Lr.
//!
//! ```
//! use glam::DVec3;
//! use hvi_engine::shadowgraph::{Shadowgraph, ShadowgraphSettings};
//! // A dense 10 x 10 x 20 block of particles 1 mm apart, its lower face at z = 0.
//! let pos: Vec<DVec3> = (0..2000)
//!     .map(|k| DVec3::new((k % 10) as f64, ((k / 10) % 10) as f64, (k / 100) as f64) * 1e-3)
//!     .collect();
//! let settings = ShadowgraphSettings { pixel_m: 0.5e-3, optical_depth: 1.0 };
//! let s = Shadowgraph::of(&pos, 1.1e-3, &settings).expect("a cloud");
//! let m = s.measure(-0.5e-3).expect("a silhouette");
//! assert!((m.length_ratio - 2.0).abs() < 0.15, "{m:?}");
//! ```

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Default pixel size, m (a quarter millimetre: a few particle diameters at the paper's
/// resolution, finer than the centimetre-scale cloud).
pub const DEFAULT_PIXEL_M: f64 = 0.25e-3;
/// Default threshold optical depth of the silhouette (transmission 1/e).
pub const DEFAULT_OPTICAL_DEPTH: f64 = 1.0;
/// The largest image, in pixels; a larger one is refused (choose a coarser pixel).
pub const MAX_PIXELS: usize = 50_000_000;

/// How the synthetic camera images the cloud.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ShadowgraphSettings {
    /// Pixel size, m (square pixels in x and z).
    pub pixel_m: f64,
    /// Optical depth at and above which a pixel is dark.
    pub optical_depth: f64,
}

impl Default for ShadowgraphSettings {
    fn default() -> Self {
        ShadowgraphSettings {
            pixel_m: DEFAULT_PIXEL_M,
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
    /// order), each an opaque sphere of diameter `particle_diameter_m`. `None` when there is no
    /// particle, the settings are not positive and finite, or the image would exceed
    /// [`MAX_PIXELS`].
    pub fn of(
        pos: &[DVec3],
        particle_diameter_m: f64,
        settings: &ShadowgraphSettings,
    ) -> Option<Shadowgraph> {
        let grains: Vec<(DVec3, f64)> = pos.iter().map(|&p| (p, particle_diameter_m)).collect();
        Shadowgraph::of_grains(&grains, settings)
    }

    /// Images grains given as (position, diameter), in id order; see [`Shadowgraph::of`].
    pub fn of_grains(
        grains: &[(DVec3, f64)],
        settings: &ShadowgraphSettings,
    ) -> Option<Shadowgraph> {
        let pos: Vec<DVec3> = grains.iter().map(|g| g.0).collect();
        let h = settings.pixel_m;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if pos.is_empty() || !positive(h) || !positive(settings.optical_depth) {
            return None;
        }
        let lo = pos.iter().copied().reduce(DVec3::min)?;
        let hi = pos.iter().copied().reduce(DVec3::max)?;
        // One empty pixel beyond the outermost centres on every side.
        let x0 = lo.x - h;
        let z0 = lo.z - h;
        let nx = ((hi.x - x0) / h).floor() as usize + 3;
        let nz = ((hi.z - z0) / h).floor() as usize + 3;
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
        let per_area = std::f64::consts::PI / 4.0 / (h * h);
        for &(p, d) in grains {
            s.deposit(p.x, p.z, per_area * d * d);
        }
        Some(s)
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

    /// The silhouette's La, Lr and R, with La measured from the plate's original rear face
    /// at `plate_rear_z_m`; `None` when no pixel is dark.
    pub fn measure(&self, plate_rear_z_m: f64) -> Option<SilhouetteMeasurement> {
        let h = self.settings.pixel_m;
        let mut dark = 0;
        let (mut i_lo, mut i_hi, mut j_hi) = (usize::MAX, 0, 0);
        for j in 0..self.nz {
            for i in 0..self.nx {
                if self.is_dark(i, j) {
                    dark += 1;
                    i_lo = i_lo.min(i);
                    i_hi = i_hi.max(i);
                    j_hi = j_hi.max(j);
                }
            }
        }
        if dark == 0 {
            return None;
        }
        let front_z_m = self.z0_m + (j_hi as f64 + 0.5) * h;
        let length_axial_m = front_z_m - plate_rear_z_m;
        let length_radial_m = (i_hi - i_lo + 1) as f64 * h;
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
        for pixel_m in [0.1e-3, 0.25e-3, 0.5e-3] {
            let settings = ShadowgraphSettings {
                pixel_m,
                optical_depth: 1.0,
            };
            let s = Shadowgraph::of(&pos, 0.27e-3, &settings).expect("image");
            // La from the sphere's lowest point, so La and Lr both see the diameter.
            let m = s.measure(c.z - r).expect("silhouette");
            assert!((m.length_ratio - 1.0).abs() < 0.05, "{pixel_m}: {m:?}");
            // The edges sit within two pixels or two lattice spacings of the sphere's.
            let edge = 2.0 * pixel_m.max(a);
            assert!((m.length_radial_m - 2.0 * r).abs() < edge, "{m:?}");
            assert!((m.front_z_m - (c.z + r)).abs() < edge, "{m:?}");
        }
    }

    #[test]
    fn a_thin_scatter_casts_no_shadow_and_a_dense_one_does() {
        // Particles 2 mm apart in a plane seen edge-on would line up; a plane seen face-on
        // (normal along y) does not: each pixel holds at most one grain of tau << 1.
        let sparse: Vec<DVec3> = (0..100)
            .map(|k| DVec3::new((k % 10) as f64 * 2e-3, 0.0, (k / 10) as f64 * 2e-3))
            .collect();
        let settings = ShadowgraphSettings::default();
        let s = Shadowgraph::of(&sparse, 0.27e-3, &settings).expect("image");
        assert_eq!(s.measure(0.0), None);
        // The total optical depth is what was deposited: N pi d^2 / 4 over the pixel area.
        let total: f64 = s.tau.iter().sum();
        let expected = 100.0 * std::f64::consts::PI * 0.27e-3f64.powi(2) / 4.0 / 0.25e-3f64.powi(2);
        assert!((total - expected).abs() < 1e-9 * expected);
        // The same grains stacked 40 deep along the line of sight are opaque.
        let dense: Vec<DVec3> = sparse
            .iter()
            .flat_map(|p| (0..40).map(move |k| *p + DVec3::new(0.0, k as f64 * 0.24e-3, 0.0)))
            .collect();
        let s = Shadowgraph::of(&dense, 0.27e-3, &settings).expect("image");
        assert!(s.measure(0.0).is_some());
    }

    #[test]
    fn bad_settings_and_empty_clouds_give_no_image() {
        let p = [DVec3::ZERO];
        let bad = ShadowgraphSettings {
            pixel_m: 0.0,
            optical_depth: 1.0,
        };
        assert!(Shadowgraph::of(&p, 1e-4, &bad).is_none());
        assert!(Shadowgraph::of(&[], 1e-4, &ShadowgraphSettings::default()).is_none());
        let huge = [DVec3::ZERO, DVec3::new(10.0, 0.0, 10.0)];
        assert!(Shadowgraph::of(&huge, 1e-4, &ShadowgraphSettings::default()).is_none());
    }
}
