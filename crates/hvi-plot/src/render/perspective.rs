//! The 3-D perspective series (Fig. 12): one view per frame, all from the same camera at the
//! same scale (framed on every frame's particles, so the cloud visibly grows), with the
//! original plate, a scale bar and the impact direction.

use std::path::Path;

use crate::error::{PlotError, Result};
use glam::DVec3;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::common::{
    scale_bar, shade, trimmed_range, Frame, PixelRect, SceneInfo, Splatter, MIN_DOT_PX,
};
use crate::save::write_png;
use crate::theme::{fonts, text_style, Area, IMPACTOR, IMPACTOR_RGB, PLATE, PLATE_RGB};

/// A perspective camera: looks at `centre` from direction (azimuth about x towards +z,
/// elevation towards +x), x up.
struct Camera {
    eye: DVec3,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
}

impl Camera {
    fn new(centre: DVec3, distance: f64, azimuth_deg: f64, elevation_deg: f64) -> Self {
        let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
        let dir = DVec3::new(el.sin(), -el.cos() * az.cos(), el.cos() * az.sin());
        let eye = centre + dir * distance;
        let forward = -dir;
        let right = DVec3::X.cross(forward).normalize();
        let up = forward.cross(right);
        Camera {
            eye,
            forward,
            right,
            up,
        }
    }

    /// Screen coordinates (tangents) and depth; `None` behind the camera.
    fn project(&self, p: DVec3) -> Option<(f64, f64, f64)> {
        let q = p - self.eye;
        let d = q.dot(self.forward);
        (d > 0.0).then(|| (q.dot(self.right) / d, q.dot(self.up) / d, d))
    }
}

/// Camera of the 3-D views: azimuth from the side view (looking along +y) towards the
/// impactor's side (negative) or the cloud's side (positive), and elevation, degrees.
const VIEW_AZIMUTH_DEG: f64 = -35.0;
/// See [`VIEW_AZIMUTH_DEG`].
const VIEW_ELEVATION_DEG: f64 = 25.0;

/// One panel of the 3-D series: its camera, pixel rectangle, scale (px per tangent unit), the
/// centre of its screen box and the depth of the view's centre.
struct View {
    camera: Camera,
    rect: PixelRect,
    scale: f64,
    offset: (f64, f64),
    centre_depth: f64,
}

impl View {
    /// One view per frame in panels (col, row) of `pw` x `ph` px under a title band
    /// `title_h` high, all with the same camera and scale so that the cloud visibly grows from
    /// panel to panel: the camera looks at the middle of the box that holds 0.1 % .. 99.9 % of
    /// every frame's particles along each axis, and the screen box of the same share of every
    /// frame fills a panel.
    fn common(frames: &[Frame], (pw, ph): (u32, u32), title_h: u32, info: &SceneInfo) -> Vec<View> {
        let union = |a: (f64, f64), b: (f64, f64)| (a.0.min(b.0), a.1.max(b.1));
        let empty = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for f in frames {
            for a in 0..3 {
                let v: Vec<f64> = f.pos.iter().map(|p| p[a] as f64).collect();
                if let Some((l, h)) = trimmed_range(v, 0.001, 0.999) {
                    lo[a] = lo[a].min(l);
                    hi[a] = hi[a].max(h);
                }
            }
        }
        if !(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z) {
            (lo, hi) = (DVec3::ZERO, DVec3::ONE);
        }
        let centre = 0.5 * (lo + hi);
        let radius = (0.5 * (hi - lo).length()).max(info.r_eq_m);
        let camera = || Camera::new(centre, 3.2 * radius, VIEW_AZIMUTH_DEG, VIEW_ELEVATION_DEG);
        let probe = camera();
        let (mut sx, mut sy) = (empty, empty);
        for f in frames {
            let (mut x, mut y) = (
                Vec::with_capacity(f.pos.len()),
                Vec::with_capacity(f.pos.len()),
            );
            for i in 0..f.pos.len() {
                if let Some((a, b, _)) = probe.project(f.point(i)) {
                    x.push(a);
                    y.push(b);
                }
            }
            sx = trimmed_range(x, 0.001, 0.999).map_or(sx, |r| union(sx, r));
            sy = trimmed_range(y, 0.001, 0.999).map_or(sy, |r| union(sy, r));
        }
        let (x0, x1) = if sx.0 <= sx.1 { sx } else { (-1.0, 1.0) };
        let (y0, y1) = if sy.0 <= sy.1 { sy } else { (-1.0, 1.0) };
        let centre_depth = probe.project(centre).map_or(1.0, |p| p.2);
        let cols = frames.len().min(2) as u32;
        (0..frames.len() as u32)
            .map(|k| {
                let (col, row) = (k % cols, k / cols);
                let rect = PixelRect {
                    x0: (col * pw + 20) as i32,
                    x1: ((col + 1) * pw - 20) as i32,
                    y0: (title_h + row * ph + 56) as i32,
                    y1: (title_h + (row + 1) * ph - 64) as i32,
                };
                let scale = 0.94
                    * (rect.width() / (x1 - x0).max(1e-12))
                        .min(rect.height() / (y1 - y0).max(1e-12));
                View {
                    camera: camera(),
                    rect,
                    scale,
                    offset: (0.5 * (x0 + x1), 0.5 * (y0 + y1)),
                    centre_depth,
                }
            })
            .collect()
    }

    /// Pixel position of the screen coordinates (tangents) `sx`, `sy`.
    fn to_px(&self, sx: f64, sy: f64) -> (f64, f64) {
        let cx = 0.5 * (self.rect.x0 + self.rect.x1) as f64;
        let cy = 0.5 * (self.rect.y0 + self.rect.y1) as f64;
        (
            cx + (sx - self.offset.0) * self.scale,
            cy - (sy - self.offset.1) * self.scale,
        )
    }
}

/// 3-D perspective views at the frames' times (Fig. 12), one camera and scale for all.
pub fn series(path: &Path, frames: &[Frame], info: &SceneInfo) -> Result<()> {
    fonts()?;
    if frames.is_empty() {
        return Err(PlotError::Input("no frames to render".into()));
    }
    let cols = frames.len().min(2) as u32;
    let rows = frames.len().div_ceil(2) as u32;
    let (pw, ph) = (880u32, 680u32);
    let title_h = 84u32;
    let (w, h) = (pw * cols, ph * rows + title_h);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    let views = View::common(frames, (pw, ph), title_h, info);
    // Pass 1: title, the original plate as a grey box (behind everything).
    {
        let root = crate::theme::png_area(&mut rgb, (w, h));
        root.draw_text(
            &format!("Impact in perspective \u{2014} {}", info.caption()),
            &text_style(28.0).pos(Pos::new(HPos::Center, VPos::Center)),
            ((w / 2) as i32, 24),
        )?;
        for v in &views {
            plate_box(&root, v, info)?;
        }
        root.present()?;
    }
    // Pass 2: particles.
    for (f, v) in frames.iter().zip(&views) {
        splat_view(&mut rgb, w, f, v, info);
    }
    // Pass 3: panel frames, time stamps, scale bars, impact-direction arrows, legend.
    {
        let root = crate::theme::png_area(&mut rgb, (w, h));
        for (f, v) in frames.iter().zip(&views) {
            view_marks(&root, f, v)?;
            impact_arrow(&root, v)?;
        }
        body_legend(&root, ((w / 2) as i32 - 130, 40))?;
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

/// The original plate's edges, grey, in view `v`.
fn plate_box(root: &Area<'_>, v: &View, info: &SceneInfo) -> Result<()> {
    let c = &v.camera;
    let (a, r, zf, zr) = (
        info.plate_half_width_m,
        info.plate_half_width_m,
        info.plate_front_z_m,
        info.plate_rear_z_m,
    );
    let corners = [
        DVec3::new(-a, -r, zf),
        DVec3::new(a, -r, zf),
        DVec3::new(a, r, zf),
        DVec3::new(-a, r, zf),
        DVec3::new(-a, -r, zr),
        DVec3::new(a, -r, zr),
        DVec3::new(a, r, zr),
        DVec3::new(-a, r, zr),
    ];
    let edges = [
        (0, 1),
        (1, 2),
        (2, 3),
        (3, 0),
        (4, 5),
        (5, 6),
        (6, 7),
        (7, 4),
        (0, 4),
        (1, 5),
        (2, 6),
        (3, 7),
    ];
    for (p, q) in edges {
        if let (Some(pa), Some(pb)) = (c.project(corners[p]), c.project(corners[q])) {
            let (ax, ay) = v.to_px(pa.0, pa.1);
            let (bx, by) = v.to_px(pb.0, pb.1);
            root.draw(&PathElement::new(
                vec![(ax as i32, ay as i32), (bx as i32, by as i32)],
                ShapeStyle::from(&RGBColor(175, 175, 175)).stroke_width(1),
            ))?;
        }
    }
    Ok(())
}

/// The particles of `f` in view `v` (an image `w` wide): nearest in front, sized by their
/// distance, darker from 0.7 to 1.3 times the depth of the view's centre.
fn splat_view(rgb: &mut [u8], w: u32, f: &Frame, v: &View, info: &SceneInfo) {
    let n = f.pos.len();
    let mut sp = Splatter::new(rgb, w as usize, v.rect);
    let near = v.centre_depth * 0.7;
    let far = v.centre_depth * 1.3;
    for i in 0..n {
        if let Some((sx, sy, d)) = v.camera.project(f.point(i)) {
            let (px, py) = v.to_px(sx, sy);
            let size = ((info.r_eq_m / d * v.scale).round() as i32).clamp(MIN_DOT_PX, 6);
            let base = if f.impactor[i] {
                IMPACTOR_RGB
            } else {
                PLATE_RGB
            };
            sp.splat(
                px,
                py,
                d as f32,
                size,
                shade(base, (d - near) / (far - near)),
            );
        }
    }
}

/// The frame around view `v`, its time stamp and a scale bar at the depth of its centre.
fn view_marks(root: &Area<'_>, f: &Frame, v: &View) -> Result<()> {
    let mm = 1e3;
    let r = v.rect;
    root.draw(&Rectangle::new(
        [(r.x0 - 8, r.y0 - 48), (r.x1 + 8, r.y1 + 56)],
        ShapeStyle::from(&RGBColor(200, 200, 200)).stroke_width(1),
    ))?;
    root.draw_text(
        &format!("\u{3c4} = {:.1} \u{b5}s", f.tau_s * 1e6),
        &text_style(26.0),
        (r.x0, r.y0 - 40),
    )?;
    let px_per_mm = v.scale / v.centre_depth / mm;
    scale_bar(root, (r.x0 + 10, r.y1 + 30), px_per_mm, r.width() * 0.18)?;
    root.draw_text(
        "(at the centre of view)",
        &text_style(16.0),
        (r.x0 + 10 + (r.width() * 0.18) as i32 + 60, r.y1 + 22),
    )?;
    Ok(())
}

/// The impact direction +z as an arrow labelled v0, drawn from the lower right of view `v`.
fn impact_arrow(root: &Area<'_>, v: &View) -> Result<()> {
    let r = v.rect;
    let c = &v.camera;
    let o = c.eye + c.forward * v.centre_depth;
    let (Some(a), Some(b)) = (c.project(o), c.project(o + DVec3::Z * 1e-3)) else {
        return Ok(());
    };
    let (ax, ay) = v.to_px(a.0, a.1);
    let (bx, by) = v.to_px(b.0, b.1);
    let (dx, dy) = (bx - ax, by - ay);
    let len = (dx * dx + dy * dy).sqrt().max(1e-9);
    let (ux, uy) = (dx / len, dy / len);
    let start = ((r.x1 - 120) as f64, (r.y1 + 28) as f64);
    let end = (start.0 + 70.0 * ux, start.1 + 70.0 * uy);
    let style = ShapeStyle::from(&BLACK).stroke_width(2);
    root.draw(&PathElement::new(
        vec![
            (start.0 as i32, start.1 as i32),
            (end.0 as i32, end.1 as i32),
        ],
        style,
    ))?;
    for s in [-1.0, 1.0] {
        let (hx, hy) = (
            end.0 - 12.0 * ux + s * 6.0 * uy,
            end.1 - 12.0 * uy - s * 6.0 * ux,
        );
        root.draw(&PathElement::new(
            vec![(end.0 as i32, end.1 as i32), (hx as i32, hy as i32)],
            style,
        ))?;
    }
    root.draw_text(
        "v0",
        &text_style(18.0),
        ((end.0 + 8.0) as i32, (end.1 - 10.0) as i32),
    )?;
    Ok(())
}

/// The series' legend in one row: impactor and plate squares.
fn body_legend(root: &Area<'_>, at: (i32, i32)) -> Result<()> {
    for (k, (label, color)) in [("impactor", IMPACTOR), ("plate", PLATE)]
        .into_iter()
        .enumerate()
    {
        let x = at.0 + 150 * k as i32;
        root.draw(&Rectangle::new(
            [(x, at.1 + 16), (x + 16, at.1 + 32)],
            color.filled(),
        ))?;
        root.draw_text(label, &text_style(19.0), (x + 24, at.1 + 13))?;
    }
    Ok(())
}
