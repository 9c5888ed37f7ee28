//! What the particle pictures share: the frame and the scene's caption, equal-aspect axes,
//! the splatter of particles into pixels, ticks, lengths and the scale bar.

use std::ops::Range;

use crate::error::Result;
use glam::DVec3;
use hvi_engine::cloud::quantile;
use hvi_engine::scene::{Derived, Geometry, SceneSpec};
use hvi_engine::sim::Simulation;
use hvi_engine::state::Body;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::theme::{text_style, Area, Chart2d, ThemedAxes, AXIS_TEXT};

/// Smallest drawn particle, pixels: a lone particle in a sparse cloud stays visible.
pub(super) const MIN_DOT_PX: i32 = 2;

/// The particles at one instant, as pictures need them (f32 is plenty for pixels). Serialisable
/// so that a run's checkpoint keeps the frames it has captured.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Frame {
    /// Time since first contact, s.
    pub tau_s: f64,
    /// Positions, m.
    pub pos: Vec<[f32; 3]>,
    /// True for impactor particles.
    pub impactor: Vec<bool>,
}

impl Frame {
    /// The simulation's particles now.
    pub fn capture(sim: &Simulation) -> Frame {
        let full = sim.full_particles();
        Frame::of(sim.tau_s(), &full.pos, &full.body)
    }

    /// The particles of a kept cloud state (`state.bin`: the analysis time or a front time),
    /// in id order.
    pub fn of_state(state: &hvi_engine::cloud::CloudState) -> Frame {
        Frame::of(state.tau_s, &state.pos, &state.body)
    }

    /// The frame of particles at `pos` of bodies `body`, `tau_s` after first contact.
    fn of(tau_s: f64, pos: &[DVec3], body: &[Body]) -> Frame {
        Frame {
            tau_s,
            pos: pos
                .iter()
                .map(|x| [x.x as f32, x.y as f32, x.z as f32])
                .collect(),
            impactor: body.iter().map(|b| *b == Body::Impactor).collect(),
        }
    }

    pub(super) fn point(&self, i: usize) -> DVec3 {
        let [x, y, z] = self.pos[i];
        DVec3::new(x as f64, y as f64, z as f64)
    }
}

/// What the captions say about the scene.
#[derive(Debug, Clone)]
pub struct SceneInfo {
    /// Particles.
    pub particles: usize,
    /// Impact velocity, m/s.
    pub v0_m_s: f64,
    /// Plate thickness over sphere diameter (sphere on plate).
    pub t_over_d: Option<f64>,
    /// Lattice spacing, m (sets the drawn particle size).
    pub r_eq_m: f64,
    /// z of the plate's original front face, m.
    pub plate_front_z_m: f64,
    /// z of the plate's original rear face, m.
    pub plate_rear_z_m: f64,
    /// Half the plate's side, m.
    pub plate_half_width_m: f64,
}

impl SceneInfo {
    /// From the scene as run.
    pub fn new(spec: &SceneSpec, derived: &Derived, particles: usize) -> Self {
        let (t_over_d, half) = match spec.scene {
            Geometry::SphereOnPlate {
                diameter_m,
                t_over_d,
                width_over_d,
                ..
            } => (Some(t_over_d), 0.5 * width_over_d * diameter_m),
            Geometry::FlyerPlate { width_m, .. } => (None, 0.5 * width_m),
        };
        SceneInfo {
            particles,
            v0_m_s: derived.v0_m_s,
            t_over_d,
            r_eq_m: derived.r_eq_m,
            plate_front_z_m: derived.plate_front_z_m,
            plate_rear_z_m: derived.plate_rear_z_m,
            plate_half_width_m: half,
        }
    }

    pub(super) fn caption(&self) -> String {
        let mut s = format!("v0 = {:.2} km/s", self.v0_m_s / 1e3);
        if let Some(t) = self.t_over_d {
            s += &format!(", t/D = {t:.3}");
        }
        s + &format!(", N = {}", thousands(self.particles))
    }
}

pub(super) fn thousands(n: usize) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (k, c) in s.chars().enumerate() {
        if k > 0 && k % 3 == s.len() % 3 {
            out.push('\u{2009}');
        }
        out.push(c);
    }
    out
}

/// A length for a scale bar or a tick step: 1, 2 or 5 times a power of ten, near `target`.
pub(crate) fn nice_length(target: f64) -> f64 {
    if !(target > 0.0 && target.is_finite()) {
        return 1.0;
    }
    let p = 10f64.powf(target.log10().floor());
    let m = target / p;
    p * if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    }
}

/// Round tick values within `[lo, hi]`: multiples of a step of 1, 2 or 5 times a power of ten,
/// about `n` of them.
pub(crate) fn round_ticks(lo: f64, hi: f64, n: f64) -> Vec<f64> {
    if !(hi > lo && lo.is_finite() && hi.is_finite()) {
        return vec![lo];
    }
    let step = nice_length((hi - lo) / n);
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

pub(super) fn format_mm(mm: f64) -> String {
    if mm >= 1.0 {
        format!("{mm:.0} mm")
    } else {
        format!("{mm} mm")
    }
}

/// A rectangle of the image in pixels, [x0, x1) x [y0, y1).
#[derive(Debug, Clone, Copy)]
pub(super) struct PixelRect {
    pub(super) x0: i32,
    pub(super) x1: i32,
    pub(super) y0: i32,
    pub(super) y1: i32,
}

impl PixelRect {
    pub(super) fn of(range: (Range<i32>, Range<i32>)) -> Self {
        PixelRect {
            x0: range.0.start,
            x1: range.0.end,
            y0: range.1.start,
            y1: range.1.end,
        }
    }
    pub(super) fn width(&self) -> f64 {
        (self.x1 - self.x0) as f64
    }
    pub(super) fn height(&self) -> f64 {
        (self.y1 - self.y0) as f64
    }
}

/// Ranges (mm) with equal scale on both axes, covering `z` and `x` inside `rect`.
pub(super) fn equal_aspect(
    z: (f64, f64),
    x: (f64, f64),
    rect: PixelRect,
) -> (Range<f64>, Range<f64>, f64) {
    let scale = (rect.width() / (z.1 - z.0)).min(rect.height() / (x.1 - x.0));
    let (zc, xc) = (0.5 * (z.0 + z.1), 0.5 * (x.0 + x.1));
    let (hz, hx) = (0.5 * rect.width() / scale, 0.5 * rect.height() / scale);
    ((zc - hz)..(zc + hz), (xc - hx)..(xc + hx), scale)
}

/// The axes of a side-on picture: z (the impact direction) across, x up, both in mm.
pub(super) fn z_x_mesh(chart: &mut Chart2d<'_, '_>) -> Result<()> {
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("z (mm), impact direction \u{2192}")
        .y_desc("x (mm)")
        .axis_text(AXIS_TEXT)
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    Ok(())
}

/// Squares of `size` pixels at (x, y) with depth d into `rgb` (an image `width` wide), inside
/// `clip`, nearest first: a depth buffer over the clip rectangle decides.
pub(super) struct Splatter<'a> {
    pub(super) rgb: &'a mut [u8],
    pub(super) width: usize,
    pub(super) clip: PixelRect,
    pub(super) depth: Vec<f32>,
}

impl<'a> Splatter<'a> {
    pub(super) fn new(rgb: &'a mut [u8], width: usize, clip: PixelRect) -> Self {
        let n = (clip.x1 - clip.x0).max(0) as usize * (clip.y1 - clip.y0).max(0) as usize;
        Splatter {
            rgb,
            width,
            clip,
            depth: vec![f32::INFINITY; n],
        }
    }

    pub(super) fn splat(&mut self, x: f64, y: f64, d: f32, size: i32, color: [u8; 3]) {
        let half = size as f64 * 0.5;
        let (xa, ya) = ((x - half).round() as i32, (y - half).round() as i32);
        let c = self.clip;
        let cw = (c.x1 - c.x0) as usize;
        for py in ya.max(c.y0)..(ya + size).min(c.y1) {
            for px in xa.max(c.x0)..(xa + size).min(c.x1) {
                let k = (py - c.y0) as usize * cw + (px - c.x0) as usize;
                if d < self.depth[k] {
                    self.depth[k] = d;
                    let o = (py as usize * self.width + px as usize) * 3;
                    self.rgb[o..o + 3].copy_from_slice(&color);
                }
            }
        }
    }
}

/// `color` darkened with depth: 1 at the front (t = 0) to 0.55 at the back (t = 1).
pub(super) fn shade(color: [u8; 3], t: f64) -> [u8; 3] {
    let f = 1.0 - 0.45 * t.clamp(0.0, 1.0);
    color.map(|c| (c as f64 * f).round() as u8)
}

pub(super) fn trimmed_range(mut v: Vec<f64>, lo: f64, hi: f64) -> Option<(f64, f64)> {
    let a = quantile(&mut v, lo)?;
    let b = quantile(&mut v, hi)?;
    Some((a, b))
}
/// A scale bar near `target_px` long; `px_per_mm` converts.
pub(super) fn scale_bar(
    root: &Area<'_>,
    at: (i32, i32),
    px_per_mm: f64,
    target_px: f64,
) -> Result<()> {
    let len_mm = nice_length(target_px / px_per_mm);
    let len_px = (len_mm * px_per_mm).round() as i32;
    root.draw(&Rectangle::new(
        [(at.0, at.1), (at.0 + len_px, at.1 + 7)],
        BLACK.filled(),
    ))?;
    root.draw_text(
        &format_mm(len_mm),
        &text_style(20.0).pos(Pos::new(HPos::Center, VPos::Bottom)),
        (at.0 + len_px / 2, at.1 - 4),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_bar_lengths_are_round() {
        assert_eq!(nice_length(17.0), 20.0);
        assert_eq!(nice_length(0.9), 1.0);
        assert_eq!(nice_length(42.0), 50.0);
        assert_eq!(nice_length(130.0), 100.0);
    }

    #[test]
    fn ticks_are_round_and_inside() {
        assert_eq!(
            round_ticks(-12.0, 230.0, 5.0),
            vec![0.0, 50.0, 100.0, 150.0, 200.0]
        );
        assert_eq!(round_ticks(-64.0, 64.0, 6.0).len(), 7);
        let t = round_ticks(1.516, 6.36, 4.0);
        assert_eq!(t, vec![2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(round_ticks(1.0, 1.0, 4.0), vec![1.0]);
    }
}
