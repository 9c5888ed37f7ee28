//! The synthetic shadowgraph of the cloud (the picture a user holds against the experiment's
//! Fig. 6): light transmitted through the cloud seen side-on, exp(-tau) in grey, the
//! silhouette's outline, the rear face, and the silhouette's front and width.

use std::path::Path;

use crate::error::Result;
use hvi_engine::cloud::SilhouetteReport;
use hvi_engine::shadowgraph::Shadowgraph;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::common::{equal_aspect, scale_bar, z_x_mesh, PixelRect, SceneInfo};
use crate::save::write_png;
use crate::theme::{fonts, text_style, Area, Chart2d, FAMILY, GUIDE, MEASURE};

/// Image width, px.
const W: u32 = 1400;
/// Image height, px, at least and at most: between them, the height at which the picture's
/// content (the cloud and the plate) fills the plot at equal scale in z and x.
const H_RANGE: (u32, u32) = (600, 1800);
/// The plot's frame around the image: its caption, axis labels and margins, px.
const CHART_FRAME: (u32, u32) = (14 + 72 + 28, 14 + 30 + 52 + 14);
/// Optical depth below which a pixel is drawn white (exp(-tau) > 0.98): the content's edge.
const VISIBLE_TAU: f64 = 0.02;
/// Title band, px.
const TITLE_H: u32 = 60;
/// Footer band, px.
const FOOTER_H: u32 = 150;

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

/// The middle band of an image `h` px high.
fn band<'a>(root: &Area<'a>, h: u32) -> Area<'a> {
    let (_, rest) = root.split_vertically(TITLE_H);
    rest.split_vertically(h - TITLE_H - FOOTER_H).0
}

/// What the picture shows, mm: z from the plate's front face (or the image's start) to the
/// last visible pixel, x over the visible pixels (with the plate's face, so an empty image
/// still has a frame), each with a margin of 4 %.
fn content_mm(image: &Shadowgraph, info: &SceneInfo) -> ((f64, f64), (f64, f64)) {
    let h = image.settings.pixel_m;
    let (mut i_lo, mut i_hi, mut j_hi) = (usize::MAX, 0, 0);
    for (k, &t) in image.tau.iter().enumerate() {
        if t >= VISIBLE_TAU {
            let (i, j) = (k % image.nx, k / image.nx);
            i_lo = i_lo.min(i);
            i_hi = i_hi.max(i);
            j_hi = j_hi.max(j);
        }
    }
    let mm = 1e3;
    let z_lo = info.plate_front_z_m.min(image.z0_m) * mm;
    let (z_hi, x_lo, x_hi) = if i_lo == usize::MAX {
        (
            info.plate_rear_z_m * mm + 10.0,
            image.x0_m * mm,
            (image.x0_m + image.nx as f64 * h) * mm,
        )
    } else {
        (
            (image.z0_m + (j_hi as f64 + 0.5) * h) * mm,
            (image.x0_m + (i_lo as f64 - 0.5) * h) * mm,
            (image.x0_m + (i_hi as f64 + 0.5) * h) * mm,
        )
    };
    let z_hi = z_hi.max(info.plate_rear_z_m * mm);
    let pad = |lo: f64, hi: f64| {
        let m = 0.04 * (hi - lo).max(1.0);
        (lo - m, hi + m)
    };
    (pad(z_lo, z_hi), pad(x_lo, x_hi))
}

/// The image's height: the content at equal scale across the plot's width, within
/// [`H_RANGE`].
fn height_for(z: (f64, f64), x: (f64, f64)) -> u32 {
    let plot_w = f64::from(W - CHART_FRAME.0);
    let plot_h = plot_w * (x.1 - x.0) / (z.1 - z.0).max(1e-9);
    let h = plot_h + f64::from(CHART_FRAME.1 + TITLE_H + FOOTER_H);
    (h.ceil() as u32).clamp(H_RANGE.0, H_RANGE.1)
}

/// Draws the shadowgraph `image` of a run described by `info` at `tau_s` with its silhouette
/// numbers `sil` into `path` (PNG); `bulk_va_ratio` is va/v0 of the quantile front (the bulk
/// of the cloud), said beside the silhouette's when that is above 1.
pub fn shadowgraph(
    path: &Path,
    image: &Shadowgraph,
    sil: &SilhouetteReport,
    info: &SceneInfo,
    tau_s: f64,
    bulk_va_ratio: Option<f64>,
) -> Result<()> {
    fonts()?;
    let (z, x) = content_mm(image, info);
    let h = height_for(z, x);
    let mut rgb = vec![255u8; (W * h * 3) as usize];
    let frame = axes(&mut rgb, h, (z, x), info, tau_s)?;
    fill(&mut rgb, image, &frame);
    overlays(&mut rgb, h, image, sil, info, &frame, bulk_va_ratio)?;
    write_png(path, &rgb, W, h)
}

/// Pass 1: title and axes, equal scale in z and x over the content `(z, x)` (mm), in an
/// image `h` px high.
fn axes(
    rgb: &mut [u8],
    h: u32,
    (z, x): ((f64, f64), (f64, f64)),
    info: &SceneInfo,
    tau_s: f64,
) -> Result<ShadowFrame> {
    let root = crate::theme::png_area(rgb, (W, h));
    root.draw_text(
        &format!(
            "Synthetic shadowgraph at \u{3c4} = {:.1} \u{b5}s \u{2014} {}",
            tau_s * 1e6,
            info.caption()
        ),
        &text_style(28.0).pos(Pos::new(HPos::Center, VPos::Center)),
        ((W / 2) as i32, (TITLE_H / 2) as i32),
    )?;
    let area = band(&root, h);
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
    h: u32,
    image: &Shadowgraph,
    sil: &SilhouetteReport,
    info: &SceneInfo,
    f: &ShadowFrame,
    bulk_va_ratio: Option<f64>,
) -> Result<()> {
    let root = crate::theme::png_area(rgb, (W, h));
    let area = band(&root, h);
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
    let mut lines = vec![
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
    lines.extend(faster_than_impactor(
        sil.front_velocity_ratio,
        bulk_va_ratio,
    ));
    let y0 = (h - FOOTER_H + 14) as i32;
    for (k, l) in lines.iter().enumerate() {
        root.draw_text(l, &text_style(20.0), (60, y0 + 32 * k as i32))?;
    }
    root.present()?;
    Ok(())
}

/// Why the silhouette's va/v0 can exceed 1, when it does: its front is the farthest dark
/// spot, and a spot that advances faster than the impactor over the two image times is a
/// fragment faster than the impactor, ahead of the bulk (whose front, the quantile's, is
/// said beside it).
fn faster_than_impactor(silhouette: Option<f64>, bulk: Option<f64>) -> Vec<String> {
    let Some(s) = silhouette.filter(|&r| r > 1.0) else {
        return Vec::new();
    };
    vec![
        format!(
            "va/v0 = {s:.3} > 1: the silhouette's front is its farthest dark spot, here fragments ahead of the bulk"
        ),
        format!(
            "that move faster than the impactor; {}",
            bulk.map_or("the bulk's front (quantile) is not measured".to_string(), |b| format!(
                "the bulk's front (the 0.9 quantile of z) gives va/v0 = {b:.3}"
            ))
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_front_faster_than_the_impactor_says_why_and_gives_the_bulks() {
        assert!(faster_than_impactor(Some(0.98), Some(0.97)).is_empty());
        assert!(faster_than_impactor(None, Some(0.97)).is_empty());
        let why = faster_than_impactor(Some(1.032), Some(0.982));
        assert_eq!(why.len(), 2);
        assert!(why[0].starts_with("va/v0 = 1.032 > 1"), "{why:?}");
        assert!(why[1].ends_with("gives va/v0 = 0.982"), "{why:?}");
    }

    #[test]
    fn the_picture_ends_where_the_cloud_does_not_where_the_image_does() {
        // A 1 mm image 400 mm long and 300 mm wide whose cloud ends at z = 290 mm and spans
        // x = -100 to 100 mm: the picture shows that, not the image's 400 mm.
        let (nx, nz) = (300, 400);
        let mut tau = vec![0.0; nx * nz];
        for j in 0..290 {
            for i in 50..250 {
                tau[j * nx + i] = 2.0;
            }
        }
        let image = Shadowgraph {
            nx,
            nz,
            x0_m: -0.1495,
            z0_m: 0.0005,
            settings: hvi_engine::shadowgraph::ShadowgraphSettings {
                pixel_m: 1e-3,
                ..Default::default()
            },
            tau,
        };
        let info = SceneInfo {
            particles: 1,
            v0_m_s: 6700.0,
            t_over_d: None,
            r_eq_m: 1e-3,
            plate_front_z_m: -0.004,
            plate_rear_z_m: 0.0,
            plate_half_width_m: 0.1,
        };
        let ((z0, z1), (x0, x1)) = content_mm(&image, &info);
        let near = |a: f64, b: f64, tol: f64| (a - b).abs() < tol;
        assert!(near(z0, -4.0 - 0.04 * 294.0, 1.0), "{z0}");
        assert!(near(z1, 290.0 + 0.04 * 294.0, 1.0), "{z1}");
        assert!(
            near(x0, -100.0 - 8.0, 1.0) && near(x1, 100.0 + 8.0, 1.0),
            "{x0} {x1}"
        );
    }

    #[test]
    fn the_picture_is_as_high_as_its_content_at_equal_scale() {
        // A cloud as wide as long fills a tall picture; a long thin one a short one; both
        // within the bounds.
        let square = height_for((0.0, 300.0), (-150.0, 150.0));
        let thin = height_for((0.0, 300.0), (-20.0, 20.0));
        assert!(square > 1200 && square <= H_RANGE.1, "{square}");
        assert_eq!(thin, H_RANGE.0);
    }
}
