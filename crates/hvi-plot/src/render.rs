//! Pictures of a run, PNG through plotters with an embedded font (no system libraries):
//!
//! - [`side_view`]: the debris cloud seen from the side at the analysis time, like the paper's
//!   Figs. 7 and 11 (impactor particles red, plate blue, axes in mm, scale bar, time stamp),
//!   with the measured front, width and original rear face drawn in, and below it the
//!   mid-plane slice that shows the cloud's inside;
//! - [`series`]: 3-D perspective views at chosen times, like Fig. 12;
//! - [`fragment_histogram`]: the fragment-size distribution by mass;
//! - [`track_plot`]: La, Lr and the front velocity over time.
//!
//! Particles are rasterised straight into the bitmap as small squares through a depth buffer
//! (nearest wins, darker with depth), never as one plotters element per particle (the paper's
//! runs have 2.7e5 of them). plotters draws axes, text and overlays. Every number shown comes
//! from `hvi_engine::cloud`; nothing here re-derives a definition.

use std::ops::Range;
use std::path::Path;

use anyhow::{anyhow, Result};
use glam::DVec3;
use hvi_engine::cloud::{quantile, CloudMeasurement, Fragment, TrackRow};
use hvi_engine::scene::{Derived, Geometry, SceneSpec};
use hvi_engine::sim::Simulation;
use hvi_engine::state::Body;
use plotters::chart::DualCoordChartContext;
use plotters::coord::combinators::{LogCoord, WithKeyPoints};
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::theme::{
    line_key, series_legend, text_style, Area, Chart2d, ThemedAxes, AXIS_TEXT, AXIS_TEXT_LARGE,
    GRID, GUIDE, IMPACTOR, IMPACTOR_RGB, MEASURE, PLATE, PLATE_RGB, RUN_LEGEND,
};

/// The font and PNG writer, where callers of this module have always found them.
pub use crate::save::write_png;
pub use crate::theme::{fonts, FAMILY};

/// Smallest drawn particle, pixels: a lone particle in a sparse cloud stays visible.
const MIN_DOT_PX: i32 = 2;

/// The particles at one instant, as pictures need them (f32 is plenty for pixels).
#[derive(Debug, Clone)]
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
        let p = &sim.particles;
        Frame {
            tau_s: sim.tau_s(),
            pos: p
                .pos
                .iter()
                .map(|x| [x.x as f32, x.y as f32, x.z as f32])
                .collect(),
            impactor: p.body.iter().map(|b| *b == Body::Impactor).collect(),
        }
    }

    fn point(&self, i: usize) -> DVec3 {
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

    fn caption(&self) -> String {
        let mut s = format!("v0 = {:.2} km/s", self.v0_m_s / 1e3);
        if let Some(t) = self.t_over_d {
            s += &format!(", t/D = {t:.3}");
        }
        s + &format!(", N = {}", thousands(self.particles))
    }
}

fn thousands(n: usize) -> String {
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

/// A length for a scale bar: 1, 2 or 5 times a power of ten, near `target`.
fn nice_length(target: f64) -> f64 {
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

fn format_mm(mm: f64) -> String {
    if mm >= 1.0 {
        format!("{mm:.0} mm")
    } else {
        format!("{mm} mm")
    }
}

/// A rectangle of the image in pixels, [x0, x1) x [y0, y1).
#[derive(Debug, Clone, Copy)]
struct PixelRect {
    x0: i32,
    x1: i32,
    y0: i32,
    y1: i32,
}

impl PixelRect {
    fn of(range: (Range<i32>, Range<i32>)) -> Self {
        PixelRect {
            x0: range.0.start,
            x1: range.0.end,
            y0: range.1.start,
            y1: range.1.end,
        }
    }
    fn width(&self) -> f64 {
        (self.x1 - self.x0) as f64
    }
    fn height(&self) -> f64 {
        (self.y1 - self.y0) as f64
    }
}

/// Squares of `size` pixels at (x, y) with depth d into `rgb` (an image `width` wide), inside
/// `clip`, nearest first: a depth buffer over the clip rectangle decides.
struct Splatter<'a> {
    rgb: &'a mut [u8],
    width: usize,
    clip: PixelRect,
    depth: Vec<f32>,
}

impl<'a> Splatter<'a> {
    fn new(rgb: &'a mut [u8], width: usize, clip: PixelRect) -> Self {
        let n = (clip.x1 - clip.x0).max(0) as usize * (clip.y1 - clip.y0).max(0) as usize;
        Splatter {
            rgb,
            width,
            clip,
            depth: vec![f32::INFINITY; n],
        }
    }

    fn splat(&mut self, x: f64, y: f64, d: f32, size: i32, color: [u8; 3]) {
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
fn shade(color: [u8; 3], t: f64) -> [u8; 3] {
    let f = 1.0 - 0.45 * t.clamp(0.0, 1.0);
    color.map(|c| (c as f64 * f).round() as u8)
}

fn trimmed_range(mut v: Vec<f64>, lo: f64, hi: f64) -> Option<(f64, f64)> {
    let a = quantile(&mut v, lo)?;
    let b = quantile(&mut v, hi)?;
    Some((a, b))
}

/// The chart of one side-view panel (z horizontal, x vertical, both in mm).
fn side_chart<'a, 'b>(
    area: &'b Area<'a>,
    caption: &str,
    z_mm: Range<f64>,
    x_mm: Range<f64>,
) -> Result<Chart2d<'a, 'b>> {
    Ok(ChartBuilder::on(area)
        .caption(caption, (FAMILY, 22))
        .margin(14)
        .margin_right(24)
        .x_label_area_size(52)
        .y_label_area_size(72)
        .build_cartesian_2d(z_mm, x_mm)?)
}

/// Ranges (mm) with equal scale on both axes, covering `z` and `x` inside `rect`.
fn equal_aspect(z: (f64, f64), x: (f64, f64), rect: PixelRect) -> (Range<f64>, Range<f64>, f64) {
    let scale = (rect.width() / (z.1 - z.0)).min(rect.height() / (x.1 - x.0));
    let (zc, xc) = (0.5 * (z.0 + z.1), 0.5 * (x.0 + x.1));
    let (hz, hx) = (0.5 * rect.width() / scale, 0.5 * rect.height() / scale);
    ((zc - hz)..(zc + hz), (xc - hx)..(xc + hx), scale)
}

/// The two panels of the side view under a title band `title_h` high.
fn side_panels<'a>(root: &Area<'a>, title_h: u32, panel_w: u32, panel_h: u32) -> [Area<'a>; 2] {
    let (_, rest) = root.split_vertically(title_h);
    let (panels, _) = rest.split_vertically(panel_h);
    let (a, b) = panels.split_horizontally(panel_w);
    [a, b]
}

/// Where the side view puts things: the data's frame (mm) and the image's bands (px).
struct SideLayout {
    /// z from the front of the frame to its back, mm.
    z_mm: (f64, f64),
    /// Half the x range, mm.
    x_half_mm: f64,
    /// Height of the title band, px.
    title_h: u32,
    /// Width of one panel, px.
    panel_w: u32,
    /// Height of the panels, px.
    panel_h: u32,
    /// Image width, px.
    w: u32,
    /// Image height, px.
    h: u32,
    /// Half-thickness of the mid-plane slice, m.
    slab_half_m: f64,
}

impl SideLayout {
    /// The frame holds 0.05 % .. 99.95 % of the particles along z and |x| (a few strays may
    /// fall outside) and always the whole original plate; the image is as tall as the data's
    /// aspect asks, the slice 1 % of Lr thick (at least two lattice spacings).
    fn new(frame: &Frame, info: &SceneInfo, cloud: Option<&CloudMeasurement>) -> Self {
        let n = frame.pos.len();
        let mm = 1e3;
        let zs: Vec<f64> = (0..n).map(|i| frame.pos[i][2] as f64 * mm).collect();
        let xs: Vec<f64> = (0..n)
            .map(|i| (frame.pos[i][0] as f64).abs() * mm)
            .collect();
        let (z_lo, z_hi) = trimmed_range(zs, 0.0005, 0.9995).unwrap_or((0.0, 1.0));
        let (_, x_hi) = trimmed_range(xs, 0.0, 0.9995).unwrap_or((0.0, 1.0));
        let pad = 1.0 + 2.0 * info.r_eq_m * mm;
        let z_mm = (
            z_lo.min(info.plate_front_z_m * mm) - pad,
            z_hi.max(info.plate_rear_z_m * mm) + pad,
        );
        let x_half_mm = x_hi.max(info.plate_half_width_m * mm) * 1.04 + pad;
        // Plots about 760 px wide, as tall as the data asks.
        let plot_w = 760.0;
        let plot_h = (plot_w * 2.0 * x_half_mm / (z_mm.1 - z_mm.0)).clamp(380.0, 900.0);
        let (title_h, footer_h) = (56u32, 150u32);
        let panel_w = 870u32;
        let panel_h = plot_h as u32 + 120;
        let slab_half_m = (2.0 * info.r_eq_m).max(
            cloud
                .and_then(|c| c.length_radial_m)
                .map_or(0.0, |lr| 0.01 * lr),
        );
        SideLayout {
            z_mm,
            x_half_mm,
            title_h,
            panel_w,
            panel_h,
            w: 2 * panel_w,
            h: title_h + panel_h + footer_h,
            slab_half_m,
        }
    }

    /// The two panels under the title band.
    fn panels<'a>(&self, root: &Area<'a>) -> [Area<'a>; 2] {
        side_panels(root, self.title_h, self.panel_w, self.panel_h)
    }
}

/// One side-view panel as drawn: its plotting rectangle (px), its ranges (mm) and scale
/// (px per mm, equal in z and x).
struct SidePanel {
    rect: PixelRect,
    z_mm: Range<f64>,
    x_mm: Range<f64>,
    scale: f64,
}

/// Side view of the cloud (Figs. 7, 11) at the frame's time, with the measurement drawn in:
/// the projection along y on the left, the mid-plane slice on the right, both at the same
/// scale (equal in z and x), legend and numbers below.
pub fn side_view(
    path: &Path,
    frame: &Frame,
    info: &SceneInfo,
    cloud: Option<&CloudMeasurement>,
) -> Result<()> {
    fonts()?;
    let layout = SideLayout::new(frame, info, cloud);
    let mut rgb = vec![255u8; (layout.w * layout.h * 3) as usize];
    let title = format!(
        "Debris cloud at \u{3c4} = {:.1} \u{b5}s \u{2014} {}",
        frame.tau_s * 1e6,
        info.caption()
    );
    let captions = [
        "side view (projection along y)".to_string(),
        format!(
            "mid-plane slice |y| < {:.2} mm (the cloud's inside)",
            layout.slab_half_m * 1e3
        ),
    ];
    let panels = side_axes(&mut rgb, &layout, &title, &captions)?;
    side_particles(&mut rgb, &layout, frame, info, &panels);
    side_overlays(&mut rgb, &layout, &captions, &panels, frame, info, cloud)?;
    write_png(path, &rgb, layout.w, layout.h)
}

/// Pass 1 of the side view: the title and both panels' axes. Returns each panel's plotting
/// rectangle and ranges, which the particles then fill.
fn side_axes(
    rgb: &mut [u8],
    layout: &SideLayout,
    title: &str,
    captions: &[String; 2],
) -> Result<Vec<SidePanel>> {
    let root = BitMapBackend::with_buffer(rgb, (layout.w, layout.h)).into_drawing_area();
    root.draw_text(
        title,
        &text_style(28.0).pos(Pos::new(HPos::Center, VPos::Center)),
        ((layout.w / 2) as i32, (layout.title_h / 2) as i32),
    )?;
    let mut panels = Vec::new();
    for (area, caption) in layout.panels(&root).iter().zip(captions) {
        let probe = side_chart(area, caption, 0.0..1.0, 0.0..1.0)?;
        let rect = PixelRect::of(probe.plotting_area().get_pixel_range());
        drop(probe);
        let x_half = layout.x_half_mm;
        let (z_mm, x_mm, scale) = equal_aspect(layout.z_mm, (-x_half, x_half), rect);
        let mut chart = side_chart(area, caption, z_mm.clone(), x_mm.clone())?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("z (mm), impact direction \u{2192}")
            .y_desc("x (mm)")
            .axis_text(AXIS_TEXT)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .draw()?;
        let rect = PixelRect::of(chart.plotting_area().get_pixel_range());
        panels.push(SidePanel {
            rect,
            z_mm,
            x_mm,
            scale,
        });
    }
    root.present()?;
    Ok(panels)
}

/// Pass 2 of the side view: the particles, nearest (smallest y) in front, darker with depth
/// in the projection; the slice holds only those within the mid-plane slab.
fn side_particles(
    rgb: &mut [u8],
    layout: &SideLayout,
    frame: &Frame,
    info: &SceneInfo,
    panels: &[SidePanel],
) {
    let n = frame.pos.len();
    let mm = 1e3;
    let ys: Vec<f64> = (0..n).map(|i| frame.pos[i][1] as f64).collect();
    let (y_lo, y_hi) = trimmed_range(ys, 0.0, 1.0).unwrap_or((0.0, 1.0));
    let y_span = (y_hi - y_lo).max(f64::MIN_POSITIVE);
    for (k, panel) in panels.iter().enumerate() {
        let SidePanel {
            rect,
            z_mm,
            x_mm,
            scale,
        } = panel;
        let size = ((info.r_eq_m * mm * scale).round() as i32).clamp(MIN_DOT_PX, 6);
        let mut sp = Splatter::new(rgb, layout.w as usize, *rect);
        for i in 0..n {
            let [x, y, z] = frame.pos[i];
            let (x, y, z) = (x as f64, y as f64, z as f64);
            if k == 1 && y.abs() >= layout.slab_half_m {
                continue;
            }
            let px = rect.x0 as f64 + (z * mm - z_mm.start) * scale;
            let py = rect.y0 as f64 + (x_mm.end - x * mm) * scale;
            let base = if frame.impactor[i] {
                IMPACTOR_RGB
            } else {
                PLATE_RGB
            };
            let t = if k == 0 { (y - y_lo) / y_span } else { 0.0 };
            sp.splat(px, py, y as f32, size, shade(base, t));
        }
    }
}

/// Pass 3 of the side view: on each panel the original rear face, the measured front and
/// width, a scale bar (and the time stamp on the first); the legend and the cloud's numbers
/// in the footer.
fn side_overlays(
    rgb: &mut [u8],
    layout: &SideLayout,
    captions: &[String; 2],
    panels: &[SidePanel],
    frame: &Frame,
    info: &SceneInfo,
    cloud: Option<&CloudMeasurement>,
) -> Result<()> {
    let root = BitMapBackend::with_buffer(rgb, (layout.w, layout.h)).into_drawing_area();
    for (k, (area, caption)) in layout.panels(&root).iter().zip(captions).enumerate() {
        let SidePanel {
            rect,
            z_mm,
            x_mm,
            scale,
        } = &panels[k];
        let chart = side_chart(area, caption, z_mm.clone(), x_mm.clone())?;
        measurement_lines(&chart, info, cloud, x_mm)?;
        if k == 0 {
            root.draw_text(
                &format!("\u{3c4} = {:.1} \u{b5}s", frame.tau_s * 1e6),
                &text_style(26.0),
                (rect.x0 + 12, rect.y0 + 10),
            )?;
        }
        scale_bar(
            &root,
            (rect.x0 + 20, rect.y1 - 24),
            *scale,
            rect.width() * 0.18,
        )?;
    }
    let footer_y = (layout.title_h + layout.panel_h + 12) as i32;
    legend(
        &root,
        (60, footer_y),
        cloud.is_some(),
        cloud.map_or(0.995, |c| c.quantile),
    )?;
    if let Some(c) = cloud {
        for (k, l) in cloud_numbers(c).iter().enumerate() {
            root.draw_text(
                l,
                &text_style(20.0),
                ((layout.w / 2) as i32 - 200, footer_y + 30 * k as i32),
            )?;
        }
    }
    root.present()?;
    Ok(())
}

/// The original rear face (grey, dashed) and, when measured, the cloud's front and width
/// (green, dashed) on a side-view panel whose x range is `x_mm`.
fn measurement_lines(
    chart: &Chart2d<'_, '_>,
    info: &SceneInfo,
    cloud: Option<&CloudMeasurement>,
    x_mm: &Range<f64>,
) -> Result<()> {
    let mm = 1e3;
    let rear = info.plate_rear_z_m * mm;
    let plot = chart.plotting_area();
    plot.draw(&DashedPathElement::new(
        vec![(rear, x_mm.start), (rear, x_mm.end)],
        10,
        7,
        ShapeStyle::from(&GUIDE).stroke_width(2),
    ))?;
    if let (Some(front), Some(lr)) = (
        cloud.and_then(|c| c.front_z_m),
        cloud.and_then(|c| c.length_radial_m),
    ) {
        let (f, half) = (front * mm, 0.5 * lr * mm);
        let style = ShapeStyle::from(&MEASURE).stroke_width(2);
        plot.draw(&DashedPathElement::new(
            vec![(f, -half * 1.1), (f, half * 1.1)],
            10,
            6,
            style,
        ))?;
        for s in [-half, half] {
            plot.draw(&DashedPathElement::new(
                vec![(rear, s), (f, s)],
                10,
                6,
                style,
            ))?;
        }
    }
    Ok(())
}

/// The footer lines of the side view: the cloud's lengths (by the quantile and by the
/// maxima), fragmentation and largest fragment.
fn cloud_numbers(c: &CloudMeasurement) -> [String; 4] {
    let mm = 1e3;
    let f = |x: Option<f64>, k: f64, p: usize| {
        x.map_or("n/a".to_string(), |v| format!("{:.*}", p, v * k))
    };
    [
        format!(
            "La = {} mm, Lr = {} mm, R = La/Lr = {}  ({:.1} % quantile)",
            f(c.length_axial_m, mm, 1),
            f(c.length_radial_m, mm, 1),
            f(c.length_ratio, 1.0, 3),
            100.0 * c.quantile
        ),
        format!(
            "by the maxima: La = {} mm, Lr = {} mm, R = {}",
            f(c.length_axial_max_m, mm, 1),
            f(c.length_radial_max_m, mm, 1),
            f(c.length_ratio_max, 1.0, 3)
        ),
        format!(
            "F = {}: {} fragments among {} cloud particles",
            f(c.fragmentation, 1.0, 3),
            thousands(c.n_frag),
            thousands(c.n_part)
        ),
        format!(
            "largest fragment: d = {} mm, {} % of the impactor's mass",
            f(c.largest_fragment_diameter_m, mm, 2),
            f(c.largest_fragment_mass_fraction, 100.0, 2)
        ),
    ]
}

/// A white box with lines of text, top-left corner at `at` (pixels).
fn info_box(root: &Area<'_>, at: (i32, i32), lines: &[String]) -> Result<()> {
    let line_h = 28;
    let height = line_h * lines.len() as i32 + 14;
    root.draw(&Rectangle::new(
        [at, (at.0 + 456, at.1 + height)],
        WHITE.mix(0.85).filled(),
    ))?;
    root.draw(&Rectangle::new(
        [at, (at.0 + 456, at.1 + height)],
        ShapeStyle::from(&GUIDE).stroke_width(1),
    ))?;
    for (k, l) in lines.iter().enumerate() {
        root.draw_text(
            l,
            &text_style(19.0),
            (at.0 + 10, at.1 + 8 + line_h * k as i32),
        )?;
    }
    Ok(())
}

/// Legend: impactor and plate squares, and the guide lines when a measurement is drawn.
fn legend(root: &Area<'_>, at: (i32, i32), measured: bool, q: f64) -> Result<()> {
    let mut y = at.1;
    let entries: Vec<(&str, RGBColor)> = vec![("impactor", IMPACTOR), ("plate", PLATE)];
    for (label, color) in entries {
        root.draw(&Rectangle::new(
            [(at.0, y + 3), (at.0 + 16, y + 19)],
            color.filled(),
        ))?;
        root.draw_text(label, &text_style(19.0), (at.0 + 24, y))?;
        y += 26;
    }
    let mut dashes = vec![("original rear face".to_string(), GUIDE)];
    if measured {
        dashes.push((format!("front and width ({:.1} %)", 100.0 * q), MEASURE));
    }
    for (label, color) in dashes {
        root.draw(&DashedPathElement::new(
            vec![(at.0, y + 11), (at.0 + 30, y + 11)],
            7,
            4,
            ShapeStyle::from(&color).stroke_width(2),
        ))?;
        root.draw_text(&label, &text_style(19.0), (at.0 + 38, y))?;
        y += 26;
    }
    Ok(())
}

/// A scale bar near `target_px` long; `px_per_mm` converts.
fn scale_bar(root: &Area<'_>, at: (i32, i32), px_per_mm: f64, target_px: f64) -> Result<()> {
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
    /// The view of `f` in panel (col, row) of panels `pw` x `ph` px under a title band
    /// `title_h` high: the camera looks at the middle of 0.1 % .. 99.9 % of the particles
    /// along each axis, and the screen box of the same share fills the panel.
    fn framing(
        f: &Frame,
        (col, row): (u32, u32),
        (pw, ph): (u32, u32),
        title_h: u32,
        info: &SceneInfo,
    ) -> View {
        let n = f.pos.len();
        let axis = |a: usize| {
            let v: Vec<f64> = (0..n).map(|i| f.pos[i][a] as f64).collect();
            trimmed_range(v, 0.001, 0.999).unwrap_or((0.0, 1.0))
        };
        let (bx, by, bz) = (axis(0), axis(1), axis(2));
        let lo = DVec3::new(bx.0, by.0, bz.0);
        let hi = DVec3::new(bx.1, by.1, bz.1);
        let centre = 0.5 * (lo + hi);
        let radius = (0.5 * (hi - lo).length()).max(info.r_eq_m);
        let camera = Camera::new(centre, 3.2 * radius, VIEW_AZIMUTH_DEG, VIEW_ELEVATION_DEG);
        let mut sx = Vec::with_capacity(n);
        let mut sy = Vec::with_capacity(n);
        for i in 0..n {
            if let Some((x, y, _)) = camera.project(f.point(i)) {
                sx.push(x);
                sy.push(y);
            }
        }
        let (x0, x1) = trimmed_range(sx, 0.001, 0.999).unwrap_or((-1.0, 1.0));
        let (y0, y1) = trimmed_range(sy, 0.001, 0.999).unwrap_or((-1.0, 1.0));
        let rect = PixelRect {
            x0: (col * pw + 20) as i32,
            x1: ((col + 1) * pw - 20) as i32,
            y0: (title_h + row * ph + 56) as i32,
            y1: (title_h + (row + 1) * ph - 64) as i32,
        };
        let scale =
            0.94 * (rect.width() / (x1 - x0).max(1e-12)).min(rect.height() / (y1 - y0).max(1e-12));
        let centre_depth = camera.project(centre).map_or(1.0, |p| p.2);
        View {
            camera,
            rect,
            scale,
            offset: (0.5 * (x0 + x1), 0.5 * (y0 + y1)),
            centre_depth,
        }
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

/// 3-D perspective views at the frames' times (Fig. 12), each framed on its particles.
pub fn series(path: &Path, frames: &[Frame], info: &SceneInfo) -> Result<()> {
    fonts()?;
    if frames.is_empty() {
        return Err(anyhow!("no frames to render"));
    }
    let cols = frames.len().min(2) as u32;
    let rows = frames.len().div_ceil(2) as u32;
    let (pw, ph) = (880u32, 680u32);
    let title_h = 84u32;
    let (w, h) = (pw * cols, ph * rows + title_h);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    let views: Vec<View> = (0..frames.len() as u32)
        .map(|k| {
            View::framing(
                &frames[k as usize],
                (k % cols, k / cols),
                (pw, ph),
                title_h,
                info,
            )
        })
        .collect();
    // Pass 1: title, the original plate as a grey box (behind everything).
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
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
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
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

/// One bin of the histogram: diameters [lo, hi), mm.
#[derive(Debug, Clone, PartialEq)]
pub struct DiameterBin {
    /// Lower edge, mm.
    pub lo_mm: f64,
    /// Upper edge, mm.
    pub hi_mm: f64,
    /// Fragments in the bin.
    pub fragments: usize,
    /// Their share of the cloud's mass.
    pub mass_fraction: f64,
}

/// Log-spaced bins of volume-equivalent diameter, `per_decade` per decade, the first centred
/// on the smallest fragment (normally one particle).
pub fn diameter_bins(fragments: &[Fragment], per_decade: usize) -> Vec<DiameterBin> {
    let total: f64 = fragments.iter().map(|f| f.mass_kg).sum();
    let d_min = fragments
        .iter()
        .map(|f| f.diameter_m)
        .fold(f64::INFINITY, f64::min);
    let d_max = fragments.iter().map(|f| f.diameter_m).fold(0.0, f64::max);
    if fragments.is_empty() || total.is_nan() || total <= 0.0 {
        return Vec::new();
    }
    let step = 1.0 / per_decade.max(1) as f64;
    let start = d_min.log10() - 0.5 * step;
    let count = (((d_max.log10() - start) / step).floor() as usize + 1).max(1);
    let mut bins: Vec<DiameterBin> = (0..count)
        .map(|k| DiameterBin {
            lo_mm: 10f64.powf(start + k as f64 * step) * 1e3,
            hi_mm: 10f64.powf(start + (k + 1) as f64 * step) * 1e3,
            fragments: 0,
            mass_fraction: 0.0,
        })
        .collect();
    for f in fragments {
        let k = (((f.diameter_m.log10() - start) / step).floor() as usize).min(count - 1);
        bins[k].fragments += 1;
        bins[k].mass_fraction += f.mass_kg / total;
    }
    bins
}

/// Axis ticks at 1, 2 and 5 times powers of ten inside [lo, hi].
fn key_points(lo: f64, hi: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut p = 10f64.powf(lo.log10().floor());
    while p <= hi {
        for m in [1.0, 2.0, 5.0] {
            let v = m * p;
            if v >= lo && v <= hi {
                out.push(v);
            }
        }
        p *= 10.0;
    }
    out
}

/// The fragment histogram's chart: log diameter against share of mass (left) and against
/// the number of fragments, log (right).
type HistogramChart<'a, 'b> = DualCoordChartContext<
    'b,
    BitMapBackend<'a>,
    Cartesian2d<WithKeyPoints<LogCoord<f64>>, RangedCoordf64>,
    Cartesian2d<LogCoord<f64>, LogCoord<f64>>,
>;

/// Fragment-size histogram: share of the cloud's mass per diameter bin (bars) and the number
/// of fragments per bin (points, right axis).
pub fn fragment_histogram(
    path: &Path,
    fragments: &[Fragment],
    cloud: &CloudMeasurement,
    info: &SceneInfo,
) -> Result<()> {
    fonts()?;
    let (w, h) = (1400u32, 900u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    let bins = diameter_bins(fragments, 8);
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        let title = format!(
            "Fragment sizes in the debris cloud at \u{3c4} = {:.1} \u{b5}s \u{2014} {}",
            cloud.tau_s * 1e6,
            info.caption()
        );
        if bins.is_empty() {
            root.draw_text(&title, &text_style(24.0), (40, 30))?;
            root.draw_text("the cloud is empty", &text_style(24.0), (40, 80))?;
        } else {
            draw_histogram(&root, &title, &bins, cloud)?;
        }
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

/// The histogram of a cloud with fragments: axes, bars and counts, the resolution limit,
/// the legend and a box with the cloud's fragment numbers.
fn draw_histogram(
    root: &Area<'_>,
    title: &str,
    bins: &[DiameterBin],
    cloud: &CloudMeasurement,
) -> Result<()> {
    let x_lo = bins[0].lo_mm;
    let x_hi = bins[bins.len() - 1].hi_mm.max(x_lo * 10.0);
    let y_hi = bins.iter().map(|b| b.mass_fraction).fold(0.0, f64::max) * 1.18;
    let n_hi = bins.iter().map(|b| b.fragments).max().unwrap_or(1) as f64 * 3.0;
    let mut chart = histogram_axes(root, title, (x_lo, x_hi), y_hi, n_hi)?;
    histogram_series(&mut chart, bins, cloud, y_hi)?;
    series_legend(&mut chart, SeriesLabelPosition::UpperRight, RUN_LEGEND)?;
    let rect = PixelRect::of(chart.plotting_area().get_pixel_range());
    info_box(
        root,
        (rect.x1 - 470, rect.y0 + (rect.height() * 0.32) as i32),
        &fragment_numbers(cloud),
    )
}

/// The histogram's chart and both axes: diameters `x` (mm, log), share of mass up to
/// `y_hi`, fragment counts up to `n_hi` (log).
fn histogram_axes<'a, 'b>(
    root: &'b Area<'a>,
    title: &str,
    (x_lo, x_hi): (f64, f64),
    y_hi: f64,
    n_hi: f64,
) -> Result<HistogramChart<'a, 'b>> {
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 24))
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .right_y_label_area_size(90)
        .build_cartesian_2d(
            (x_lo..x_hi)
                .log_scale()
                .with_key_points(key_points(x_lo, x_hi)),
            0.0..y_hi,
        )?
        .set_secondary_coord((x_lo..x_hi).log_scale(), (0.5..n_hi).log_scale());
    chart
        .configure_mesh()
        .light_line_style(GRID)
        .x_desc("volume-equivalent diameter d (mm)")
        .y_desc("share of the cloud's mass")
        .axis_text(AXIS_TEXT_LARGE)
        .x_label_formatter(&|v| format!("{}", (v * 1e6).round() / 1e6))
        .y_label_formatter(&|v| format!("{v:.2}"))
        .draw()?;
    chart
        .configure_secondary_axes()
        .y_desc("number of fragments")
        .axis_text(AXIS_TEXT_LARGE)
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    Ok(chart)
}

/// The bars (share of mass), the points (fragments per bin) and the one-particle diameter,
/// each with its legend entry.
fn histogram_series(
    chart: &mut HistogramChart<'_, '_>,
    bins: &[DiameterBin],
    cloud: &CloudMeasurement,
    y_hi: f64,
) -> Result<()> {
    chart
        .draw_series(bins.iter().map(|b| {
            Rectangle::new(
                [(b.lo_mm * 1.01, 0.0), (b.hi_mm / 1.01, b.mass_fraction)],
                PLATE.mix(0.75).filled(),
            )
        }))?
        .label("share of mass (left axis)")
        .legend(|(x, y)| Rectangle::new([(x, y - 7), (x + 16, y + 7)], PLATE.mix(0.75).filled()));
    let counted: Vec<(f64, f64)> = bins
        .iter()
        .filter(|b| b.fragments > 0)
        .map(|b| ((b.lo_mm * b.hi_mm).sqrt(), b.fragments as f64))
        .collect();
    chart
        .draw_secondary_series(
            counted
                .iter()
                .map(|&(x, y)| Circle::new((x, y), 6, IMPACTOR.filled())),
        )?
        .label("number of fragments in the bin (right axis)")
        .legend(|(x, y)| Circle::new((x + 8, y), 6, IMPACTOR.filled()));
    let one = cloud.particle_diameter_m * 1e3;
    chart
        .draw_series(DashedLineSeries::new(
            vec![(one, 0.0), (one, y_hi)],
            8,
            6,
            ShapeStyle::from(&GUIDE).stroke_width(2),
        ))?
        .label(format!("one particle, d = {one:.3} mm (resolution limit)"))
        .legend(|(x, y)| line_key(x, y, 20, GUIDE.stroke_width(2)));
    Ok(())
}

/// The histogram's box: fragmentation and counts, the largest fragment, the mean diameter.
fn fragment_numbers(cloud: &CloudMeasurement) -> [String; 3] {
    [
        format!(
            "F = {:.3}, N_part = {}, N_frag = {}",
            cloud.fragmentation.unwrap_or(f64::NAN),
            thousands(cloud.n_part),
            thousands(cloud.n_frag)
        ),
        format!(
            "largest: {:.2} mm, {:.2} % of the impactor's mass",
            cloud.largest_fragment_diameter_m.unwrap_or(f64::NAN) * 1e3,
            100.0 * cloud.largest_fragment_mass_fraction.unwrap_or(f64::NAN)
        ),
        format!(
            "mass-weighted mean d = {:.3} mm",
            cloud.mean_fragment_diameter_m.unwrap_or(f64::NAN) * 1e3
        ),
    ]
}

/// The cloud track's chart: lengths (mm, left) and the front velocity over v0 (right)
/// against tau (us).
type TrackChart<'a, 'b> = DualCoordChartContext<
    'b,
    BitMapBackend<'a>,
    Cartesian2d<RangedCoordf64, RangedCoordf64>,
    Cartesian2d<RangedCoordf64, RangedCoordf64>,
>;

/// Top of the track chart's right axis, front velocity over v0.
const TRACK_SPEED_MAX: f64 = 1.6;

/// La and Lr (left axis, mm) and the front velocity over v0 (right axis) against tau, with the
/// two front times of va marked.
pub fn track_plot(
    path: &Path,
    track: &[TrackRow],
    front_times_s: [Option<f64>; 2],
    va_ratio: Option<f64>,
    info: &SceneInfo,
) -> Result<()> {
    fonts()?;
    let (w, h) = (1400u32, 850u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        let us = 1e6;
        let t_hi = track.iter().map(|r| r.tau_s * us).fold(1e-3, f64::max);
        let t_lo = track.iter().map(|r| r.tau_s * us).fold(0.0, f64::min);
        let l_hi = track
            .iter()
            .flat_map(|r| [r.length_axial_m, r.length_radial_m])
            .flatten()
            .fold(1e-6, f64::max)
            * 1e3
            * 1.1;
        let mut chart = track_axes(&root, info, (t_lo, t_hi), l_hi)?;
        track_lengths(&mut chart, track)?;
        track_front(
            &mut chart,
            track,
            info.v0_m_s,
            (t_lo, t_hi),
            front_times_s,
            va_ratio,
        )?;
        series_legend(&mut chart, SeriesLabelPosition::UpperLeft, RUN_LEGEND)?;
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

/// The track chart and both axes: tau over `t` (us), lengths up to `l_hi` (mm).
fn track_axes<'a, 'b>(
    root: &'b Area<'a>,
    info: &SceneInfo,
    (t_lo, t_hi): (f64, f64),
    l_hi: f64,
) -> Result<TrackChart<'a, 'b>> {
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!("Debris-cloud track \u{2014} {}", info.caption()),
            (FAMILY, 24),
        )
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .right_y_label_area_size(90)
        .build_cartesian_2d(t_lo..t_hi, 0.0..l_hi)?
        .set_secondary_coord(t_lo..t_hi, 0.0..TRACK_SPEED_MAX);
    chart
        .configure_mesh()
        .light_line_style(GRID)
        .x_desc("\u{3c4} (\u{b5}s)")
        .y_desc("length (mm)")
        .axis_text(AXIS_TEXT_LARGE)
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    chart
        .configure_secondary_axes()
        .y_desc("front velocity / v0")
        .axis_text(AXIS_TEXT_LARGE)
        .y_label_formatter(&|v| format!("{v:.1}"))
        .draw()?;
    Ok(chart)
}

/// La (green) and Lr (blue) over time, mm.
fn track_lengths(chart: &mut TrackChart<'_, '_>, track: &[TrackRow]) -> Result<()> {
    let us = 1e6;
    let series = |f: fn(&TrackRow) -> Option<f64>| -> Vec<(f64, f64)> {
        track
            .iter()
            .filter_map(|r| f(r).map(|v| (r.tau_s * us, v * 1e3)))
            .collect()
    };
    chart
        .draw_series(LineSeries::new(
            series(|r| r.length_axial_m),
            MEASURE.stroke_width(3),
        ))?
        .label("La")
        .legend(|(x, y)| line_key(x, y, 20, MEASURE.stroke_width(3)));
    chart
        .draw_series(LineSeries::new(
            series(|r| r.length_radial_m),
            PLATE.stroke_width(3),
        ))?
        .label("Lr")
        .legend(|(x, y)| line_key(x, y, 20, PLATE.stroke_width(3)));
    Ok(())
}

/// The front velocity over `v0_m_s` between samples (right axis), the two front times of va
/// (dashed, vertical) and va / v0 itself (dashed, across `t`).
fn track_front(
    chart: &mut TrackChart<'_, '_>,
    track: &[TrackRow],
    v0_m_s: f64,
    (t_lo, t_hi): (f64, f64),
    front_times_s: [Option<f64>; 2],
    va_ratio: Option<f64>,
) -> Result<()> {
    let us = 1e6;
    let speed: Vec<(f64, f64)> = track
        .iter()
        .filter_map(|r| r.front_velocity_m_s.map(|v| (r.tau_s * us, v / v0_m_s)))
        .collect();
    chart
        .draw_secondary_series(LineSeries::new(speed, IMPACTOR.stroke_width(1)))?
        .label("front velocity / v0 between samples (right axis)")
        .legend(|(x, y)| line_key(x, y, 20, IMPACTOR.stroke_width(2)));
    for t in front_times_s.iter().flatten() {
        chart.draw_secondary_series(DashedLineSeries::new(
            vec![(t * us, 0.0), (t * us, TRACK_SPEED_MAX)],
            8,
            6,
            ShapeStyle::from(&GUIDE).stroke_width(2),
        ))?;
    }
    if let Some(r) = va_ratio {
        chart
            .draw_secondary_series(DashedLineSeries::new(
                vec![(t_lo, r), (t_hi, r)],
                8,
                6,
                ShapeStyle::from(&BLACK).stroke_width(1),
            ))?
            .label(format!("va / v0 = {r:.3} (front at the two dashed times)"))
            .legend(|(x, y)| line_key(x, y, 20, BLACK.stroke_width(1)));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fragment(label: u32, particles: usize, diameter_m: f64) -> Fragment {
        Fragment {
            label,
            particles,
            impactor_particles: 0,
            mass_kg: particles as f64,
            diameter_m,
            centroid_m: [0.0; 3],
            velocity_m_s: [0.0; 3],
        }
    }

    #[test]
    fn bins_hold_every_fragment_and_all_the_mass() {
        let d1 = 0.5e-3;
        let frags: Vec<Fragment> = (1..=200usize)
            .map(|k| fragment(k as u32, k, d1 * (k as f64).cbrt()))
            .collect();
        let bins = diameter_bins(&frags, 8);
        assert_eq!(bins.iter().map(|b| b.fragments).sum::<usize>(), 200);
        let m: f64 = bins.iter().map(|b| b.mass_fraction).sum();
        assert!((m - 1.0).abs() < 1e-12);
        // The first bin is centred on the smallest diameter, the last holds the largest.
        assert!(bins[0].lo_mm < d1 * 1e3 && d1 * 1e3 < bins[0].hi_mm);
        let last = bins.last().expect("bins");
        let d_max = d1 * 200f64.cbrt() * 1e3;
        assert!(last.lo_mm <= d_max && d_max < last.hi_mm);
    }

    #[test]
    fn scale_bar_lengths_are_round() {
        assert_eq!(nice_length(17.0), 20.0);
        assert_eq!(nice_length(0.9), 1.0);
        assert_eq!(nice_length(42.0), 50.0);
        assert_eq!(nice_length(130.0), 100.0);
    }
}
