//! The side view of the debris cloud (Figs. 7 and 11): the projection along y and the
//! mid-plane slice at one scale, the measured front, width and original rear face, the legend
//! and the cloud's numbers.

use std::ops::Range;
use std::path::Path;

use crate::error::Result;
use hvi_engine::cloud::CloudMeasurement;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::common::{
    equal_aspect, scale_bar, shade, thousands, trimmed_range, z_x_mesh, Frame, PixelRect,
    SceneInfo, Splatter, MIN_DOT_PX,
};
use crate::save::write_png;
use crate::theme::{
    fonts, text_style, Area, Chart2d, FAMILY, GUIDE, IMPACTOR, IMPACTOR_RGB, MEASURE, PLATE,
    PLATE_RGB,
};

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
    let root = crate::theme::png_area(rgb, (layout.w, layout.h));
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
        z_x_mesh(&mut chart)?;
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
    let root = crate::theme::png_area(rgb, (layout.w, layout.h));
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
            "La = {} mm, Lr = {} mm, R = La/Lr = {}  ({:.1} % quantile, Lr {})",
            f(c.length_axial_m, mm, 1),
            f(c.length_radial_m, mm, 1),
            f(c.length_ratio, 1.0, 3),
            100.0 * c.quantile,
            c.width.label()
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
