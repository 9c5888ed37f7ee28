//! The synthetic shadowgraph of the cloud (the picture a user holds against the experiment's
//! Fig. 6): light transmitted through the cloud seen side-on, exp(-tau) in grey, the
//! silhouette's outline, the rear face, and the silhouette's front and width.

use std::path::Path;

use anyhow::Result;
use hvi_engine::cloud::SilhouetteReport;
use hvi_engine::shadowgraph::Shadowgraph;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::common::{equal_aspect, scale_bar, z_x_mesh, PixelRect, SceneInfo};
use crate::save::write_png;
use crate::theme::{fonts, text_style, Area, Chart2d, FAMILY, GUIDE, MEASURE};

/// Image size, px.
const W: u32 = 1400;
/// Image size, px.
const H: u32 = 900;
/// Title band, px.
const TITLE_H: u32 = 60;
/// Footer band, px.
const FOOTER_H: u32 = 90;

/// The picture's frame: mm ranges with equal scale, and where they sit in the image.
struct ShadowFrame {
    z_mm: std::ops::Range<f64>,
    x_mm: std::ops::Range<f64>,
    rect: PixelRect,
    scale: f64,
}

/// The chart over the picture's middle band.
fn chart<'a, 'b>(
    area: &'b Area<'a>,
    z_mm: std::ops::Range<f64>,
    x_mm: std::ops::Range<f64>,
) -> Result<Chart2d<'a, 'b>> {
    Ok(ChartBuilder::on(area)
        .caption(
            "shadowgraph: transmitted light exp(-\u{3c4}), side view along y",
            (FAMILY, 22),
        )
        .margin(14)
        .margin_right(28)
        .x_label_area_size(52)
        .y_label_area_size(72)
        .build_cartesian_2d(z_mm, x_mm)?)
}

/// The middle band of the image.
fn band<'a>(root: &Area<'a>) -> Area<'a> {
    let (_, rest) = root.split_vertically(TITLE_H);
    rest.split_vertically(H - TITLE_H - FOOTER_H).0
}

/// Draws the shadowgraph `image` of a run described by `info` at `tau_s` with its silhouette
/// numbers `sil` into `path` (PNG).
pub fn shadowgraph(
    path: &Path,
    image: &Shadowgraph,
    sil: &SilhouetteReport,
    info: &SceneInfo,
    tau_s: f64,
) -> Result<()> {
    fonts()?;
    let mut rgb = vec![255u8; (W * H * 3) as usize];
    let frame = axes(&mut rgb, image, info, tau_s)?;
    fill(&mut rgb, image, &frame);
    overlays(&mut rgb, image, sil, info, &frame)?;
    write_png(path, &rgb, W, H)
}

/// Pass 1: title and axes, equal scale in z and x over the image and the rear face.
fn axes(rgb: &mut [u8], image: &Shadowgraph, info: &SceneInfo, tau_s: f64) -> Result<ShadowFrame> {
    let root = BitMapBackend::with_buffer(rgb, (W, H)).into_drawing_area();
    root.draw_text(
        &format!(
            "Synthetic shadowgraph at \u{3c4} = {:.1} \u{b5}s \u{2014} {}",
            tau_s * 1e6,
            info.caption()
        ),
        &text_style(28.0).pos(Pos::new(HPos::Center, VPos::Center)),
        ((W / 2) as i32, (TITLE_H / 2) as i32),
    )?;
    let area = band(&root);
    let h = image.settings.pixel_m;
    let mm = 1e3;
    let z = (
        info.plate_front_z_m.min(image.z0_m) * mm,
        (image.z0_m + image.nz as f64 * h) * mm,
    );
    let x = (image.x0_m * mm, (image.x0_m + image.nx as f64 * h) * mm);
    let probe = chart(&area, 0.0..1.0, 0.0..1.0)?;
    let rect = PixelRect::of(probe.plotting_area().get_pixel_range());
    drop(probe);
    let (z_mm, x_mm, scale) = equal_aspect(z, x, rect);
    let mut c = chart(&area, z_mm.clone(), x_mm.clone())?;
    z_x_mesh(&mut c)?;
    let rect = PixelRect::of(c.plotting_area().get_pixel_range());
    root.present()?;
    Ok(ShadowFrame {
        z_mm,
        x_mm,
        rect,
        scale,
    })
}

/// Pass 2: every plotting pixel grey by the light that passes, exp(-tau); the silhouette
/// (tau at or above the threshold) in a dark blue so its edge reads at a glance.
fn fill(rgb: &mut [u8], image: &Shadowgraph, f: &ShadowFrame) {
    let mm = 1e3;
    for py in f.rect.y0..f.rect.y1 {
        for px in f.rect.x0..f.rect.x1 {
            let z = (f.z_mm.start + (px - f.rect.x0) as f64 / f.scale) / mm;
            let x = (f.x_mm.end - (py - f.rect.y0) as f64 / f.scale) / mm;
            let tau = image.tau_at(x, z);
            if tau <= 0.0 {
                continue;
            }
            let g = (255.0 * (-tau).exp()) as u8;
            let c = if tau >= image.settings.optical_depth {
                [g / 2, g / 2, g / 2 + 40]
            } else {
                [g, g, g]
            };
            let k = 3 * (py as usize * W as usize + px as usize);
            rgb[k..k + 3].copy_from_slice(&c);
        }
    }
}

/// Pass 3: the rear face, the silhouette's front and width, a scale bar, and the numbers.
fn overlays(
    rgb: &mut [u8],
    image: &Shadowgraph,
    sil: &SilhouetteReport,
    info: &SceneInfo,
    f: &ShadowFrame,
) -> Result<()> {
    let root = BitMapBackend::with_buffer(rgb, (W, H)).into_drawing_area();
    let area = band(&root);
    let c = chart(&area, f.z_mm.clone(), f.x_mm.clone())?;
    let plot = c.plotting_area();
    let mm = 1e3;
    let rear = info.plate_rear_z_m * mm;
    plot.draw(&DashedPathElement::new(
        vec![(rear, f.x_mm.start), (rear, f.x_mm.end)],
        10,
        7,
        ShapeStyle::from(&GUIDE).stroke_width(2),
    ))?;
    if let Some((x_lo, x_hi, _, front, _)) = image.dark_extent() {
        let (x_lo, x_hi, front) = (x_lo * mm, x_hi * mm, front * mm);
        let style = ShapeStyle::from(&MEASURE).stroke_width(2);
        plot.draw(&DashedPathElement::new(
            vec![(front, x_lo), (front, x_hi)],
            10,
            6,
            style,
        ))?;
        for x in [x_lo, x_hi] {
            plot.draw(&DashedPathElement::new(
                vec![(rear, x), (front, x)],
                10,
                6,
                style,
            ))?;
        }
    }
    scale_bar(
        &root,
        (f.rect.x0 + 20, f.rect.y1 - 24),
        f.scale,
        f.rect.width() * 0.18,
    )?;
    let fmt =
        |v: Option<f64>, k: f64, d: usize| v.map_or("n/a".into(), |v| format!("{:.d$}", v * k));
    let lines = [
        format!(
            "silhouette: La = {} mm, Lr = {} mm, R = {}; va/v0 = {} (front at the two image times)",
            fmt(sil.length_axial_m, mm, 1),
            fmt(sil.length_radial_m, mm, 1),
            fmt(sil.length_ratio, 1.0, 3),
            fmt(sil.front_velocity_ratio, 1.0, 3),
        ),
        format!(
            "pixel {} mm, blur {} mm, grains of {} \u{b5}m; dark at \u{3c4} \u{2265} {} ({} pixels); grey: exp(-\u{3c4}); dashed grey: rear face; green: front and width",
            sil.pixel_m * mm,
            sil.blur_m * mm,
            sil.grain_m * 1e6,
            sil.optical_depth,
            sil.dark_pixels
        ),
    ];
    let y0 = (H - FOOTER_H + 14) as i32;
    for (k, l) in lines.iter().enumerate() {
        root.draw_text(l, &text_style(20.0), (60, y0 + 32 * k as i32))?;
    }
    root.present()?;
    Ok(())
}
