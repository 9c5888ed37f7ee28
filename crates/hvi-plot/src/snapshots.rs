//! Snapshot matrices (Figs. 7 and 17): each run's debris cloud at the analysis time, seen from
//! the side (projected along y: z, the impact direction, across; x up), tiled over two axes of
//! the study and optionally framed by a verdict (Fig. 17: valid red, invalid blue).
//!
//! Every tile has the same scale, in z and x alike (a millimetre is as long across as up, so a
//! cloud's shape, R = La / Lr, reads off the picture) and the same ranges: the union of the
//! clouds' extents, so clouds compare at a glance. Axis values are drawn once, at the matrix's
//! left and bottom edges, with a scale bar in the footer; the caller labels the columns and
//! rows with their values and units and gives the footer the conditions of the runs. Pictures
//! only; the numbers come from the runs.

use std::path::Path;

use crate::error::Result;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::render::{nice_length, round_ticks};
use crate::save::{encode_png, write_atomic_bytes};
use crate::theme::{font, fonts, text_style, Area, GUIDE, IMPACTOR_RGB, PLATE_RGB};

/// A run's particles at the analysis time, projected along y.
#[derive(Debug, Clone, Default)]
pub struct TileCloud {
    /// (z, x) of every particle, mm.
    pub points: Vec<[f32; 2]>,
    /// Whether each particle is of the impactor (else the plate).
    pub impactor: Vec<bool>,
    /// z of the plate's original rear face, mm (drawn as a guide).
    pub rear_face_z_mm: f64,
}

/// One tile of the matrix.
#[derive(Debug, Clone)]
pub struct Tile {
    /// Column (x-axis value index, ascending).
    pub col: usize,
    /// Row (y-axis value index, ascending; drawn bottom-up so larger values are on top).
    pub row: usize,
    /// The run's cloud (None: the run has no kept state, e.g. it failed).
    pub cloud: Option<TileCloud>,
    /// Frame colour (None: thin grey).
    pub frame: Option<RGBColor>,
    /// A short caption over the picture (e.g. `F = 0.42, R = 1.5`).
    pub caption: String,
}

/// What the matrix says besides the tiles.
#[derive(Debug, Clone, Copy)]
pub struct MatrixText<'a> {
    /// The title.
    pub title: &'a str,
    /// The column headers, ascending (e.g. `ε = 0.01 J`).
    pub columns: &'a [String],
    /// The row headers, ascending (e.g. `κ = 9.12e6 N/m`).
    pub rows: &'a [String],
    /// The footer: the conditions of the runs (tier, resolution, plate, analysis time).
    pub footer: &'a str,
}

/// The common view of every tile: z and x ranges, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
struct View {
    z: (f64, f64),
    x: (f64, f64),
}

impl View {
    /// The ranges that hold every cloud's particles between their 0.2 % and 99.8 % quantiles
    /// (a few stray particles do not shrink the clouds), with a margin, widened so that the
    /// tile's height is between 0.35 and 1 times its width at equal scale.
    fn of(tiles: &[Tile]) -> View {
        let (mut z0, mut z1, mut xm) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for c in tiles.iter().filter_map(|t| t.cloud.as_ref()) {
            if c.points.is_empty() {
                continue;
            }
            let mut zs: Vec<f64> = c.points.iter().map(|p| p[0] as f64).collect();
            let mut xs: Vec<f64> = c.points.iter().map(|p| (p[1] as f64).abs()).collect();
            zs.sort_by(f64::total_cmp);
            xs.sort_by(f64::total_cmp);
            let at = |v: &[f64], q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
            z0 = z0.min(at(&zs, 0.002)).min(c.rear_face_z_mm);
            z1 = z1.max(at(&zs, 0.998));
            xm = xm.max(at(&xs, 0.998));
        }
        if z1.partial_cmp(&z0) != Some(std::cmp::Ordering::Greater) {
            return View {
                z: (-10.0, 10.0),
                x: (-5.0, 5.0),
            };
        }
        let pad = 0.04 * (z1 - z0);
        let (z0, mut z1) = (z0 - pad, z1 + pad);
        let mut xm = (xm * 1.08).max(1e-3);
        let ratio = 2.0 * xm / (z1 - z0);
        if ratio < 0.35 {
            xm = 0.35 * (z1 - z0) / 2.0;
        } else if ratio > 1.0 {
            z1 = z0 + 2.0 * xm;
        }
        View {
            z: (z0, z1),
            x: (-xm, xm),
        }
    }

    /// Pixels per mm at tile width `tw`.
    fn scale(&self, tw: usize) -> f64 {
        tw as f64 / (self.z.1 - self.z.0)
    }
}

/// Where the matrix puts things, px.
struct Layout {
    left: usize,
    top: usize,
    /// Tile width and height.
    tw: usize,
    th: usize,
    cell_w: usize,
    cell_h: usize,
    caption_h: usize,
    rows: usize,
    cols: usize,
    w: usize,
    h: usize,
}

impl Layout {
    fn new(tw: usize, th: usize, cols: usize, rows: usize) -> Self {
        let (left, top, gap, caption_h) = (230usize, 110usize, 18usize, 26usize);
        let cell_w = tw + gap;
        let cell_h = caption_h + th + gap;
        Layout {
            left,
            top,
            tw,
            th,
            cell_w,
            cell_h,
            caption_h,
            rows,
            cols,
            w: left + cols * cell_w + 30,
            h: top + rows * cell_h + 150,
        }
    }

    /// The top-left corner of the tile at (col, row) (row 0 at the bottom).
    fn origin(&self, col: usize, row: usize) -> (i32, i32) {
        let x = self.left + col * self.cell_w;
        let y = self.top + (self.rows - 1 - row) * self.cell_h + self.caption_h;
        (x as i32, y as i32)
    }

    /// The bottom edge of the matrix's tiles.
    fn bottom(&self) -> i32 {
        (self.top + (self.rows - 1) * self.cell_h + self.caption_h + self.th) as i32
    }
}

/// Draws the matrix into `path` (PNG); returns how many tiles had a cloud.
pub fn snapshot_matrix(path: &Path, text: MatrixText<'_>, tiles: &[Tile]) -> Result<usize> {
    fonts()?;
    let tw = if text.columns.len() > 4 { 280 } else { 400 };
    let view = View::of(tiles);
    let th = ((view.x.1 - view.x.0) * view.scale(tw)).round() as usize;
    let layout = Layout::new(tw, th, text.columns.len().max(1), text.rows.len().max(1));
    let (w, h) = (layout.w, layout.h);
    let mut rgb = vec![255u8; w * h * 3];
    for t in tiles {
        if let Some(c) = &t.cloud {
            rasterise(&mut rgb, w, &layout, &view, t, c);
        }
    }
    {
        let root = crate::theme::png_area(&mut rgb, (w as u32, h as u32));
        root.draw(&Text::new(text.title.to_string(), (20, 18), font(28)))?;
        headers(&root, &layout, text)?;
        for t in tiles {
            tile_frame(&root, &layout, &view, t)?;
        }
        edge_axes(&root, &layout, &view)?;
        footer(&root, &layout, &view, text.footer)?;
        root.present()?;
    }
    let bytes = encode_png(&rgb, w as u32, h as u32, Some(png::Compression::Fast))?;
    write_atomic_bytes(path, &bytes)?;
    Ok(tiles.iter().filter(|t| t.cloud.is_some()).count())
}

/// Draws a tile's particles into the image: 2 x 2 px each, the plate first and the impactor
/// over it, clipped to the tile.
fn rasterise(rgb: &mut [u8], w: usize, l: &Layout, v: &View, t: &Tile, c: &TileCloud) {
    let (x0, y0) = l.origin(t.col, t.row);
    let s = v.scale(l.tw);
    for pass in [false, true] {
        let colour = if pass { IMPACTOR_RGB } else { PLATE_RGB };
        for (p, &imp) in c.points.iter().zip(&c.impactor) {
            if imp != pass {
                continue;
            }
            let px = ((p[0] as f64 - v.z.0) * s).floor();
            let py = ((v.x.1 - p[1] as f64) * s).floor();
            for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                let (qx, qy) = (px + dx, py + dy);
                if qx < 0.0 || qy < 0.0 || qx >= l.tw as f64 || qy >= l.th as f64 {
                    continue;
                }
                let k = ((y0 as usize + qy as usize) * w + x0 as usize + qx as usize) * 3;
                rgb[k..k + 3].copy_from_slice(&colour);
            }
        }
    }
}

/// The column headers over the matrix and the row headers left of it.
fn headers(root: &Area<'_>, l: &Layout, text: MatrixText<'_>) -> Result<()> {
    let centre = Pos::new(HPos::Center, VPos::Center);
    for (c, label) in text.columns.iter().enumerate() {
        let x = (l.left + c * l.cell_w + l.tw / 2) as i32;
        root.draw(&Text::new(
            label.clone(),
            (x, (l.top - 30) as i32),
            text_style(22.0).pos(centre),
        ))?;
    }
    for (r, label) in text.rows.iter().enumerate() {
        let (_, y) = l.origin(0, r);
        root.draw(&Text::new(
            label.clone(),
            (12, y + l.th as i32 / 2),
            text_style(20.0).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
    }
    Ok(())
}

/// A tile's frame (its verdict's colour, else thin grey), the rear face, the caption over it,
/// and a note when it has no cloud.
fn tile_frame(root: &Area<'_>, l: &Layout, v: &View, t: &Tile) -> Result<()> {
    let (x0, y0) = l.origin(t.col, t.row);
    let (x1, y1) = (x0 + l.tw as i32, y0 + l.th as i32);
    match &t.cloud {
        None => root.draw(&Text::new(
            "no kept state (failed run?)",
            (x0 + 20, y0 + 40),
            font(16),
        ))?,
        Some(c) => {
            let zx = x0 + ((c.rear_face_z_mm - v.z.0) * v.scale(l.tw)).round() as i32;
            if (x0..x1).contains(&zx) {
                root.draw(&DashedPathElement::new(
                    vec![(zx, y0), (zx, y1)],
                    5,
                    4,
                    GUIDE.stroke_width(1),
                ))?;
            }
        }
    }
    let style = match t.frame {
        Some(c) => c.stroke_width(4),
        None => RGBColor(170, 170, 170).stroke_width(1),
    };
    root.draw(&Rectangle::new([(x0 - 2, y0 - 2), (x1 + 2, y1 + 2)], style))?;
    root.draw(&Text::new(t.caption.clone(), (x0 + 2, y0 - 22), font(16)))?;
    Ok(())
}

/// The axis values: z under the bottom row's tiles, x left of the first column's, and the axis
/// names once.
fn edge_axes(root: &Area<'_>, l: &Layout, v: &View) -> Result<()> {
    let s = v.scale(l.tw);
    let tick = GUIDE.stroke_width(1);
    let z_ticks = round_ticks(v.z.0, v.z.1, if l.tw > 300 { 5.0 } else { 3.0 });
    let bottom = l.bottom();
    for c in 0..l.cols {
        let (x0, _) = l.origin(c, 0);
        for &z in &z_ticks {
            let x = x0 + ((z - v.z.0) * s).round() as i32;
            root.draw(&PathElement::new(
                vec![(x, bottom + 2), (x, bottom + 8)],
                tick,
            ))?;
            root.draw(&Text::new(
                format!("{z:.0}"),
                (x, bottom + 10),
                text_style(15.0).pos(Pos::new(HPos::Center, VPos::Top)),
            ))?;
        }
    }
    root.draw(&Text::new(
        "z (mm), impact direction \u{2192}",
        ((l.left + l.cols * l.cell_w / 2) as i32, bottom + 34),
        text_style(17.0).pos(Pos::new(HPos::Center, VPos::Top)),
    ))?;
    let x_ticks = round_ticks(v.x.0, v.x.1, 4.0);
    for r in 0..l.rows {
        let (x0, y0) = l.origin(0, r);
        for &x in &x_ticks {
            let y = y0 + ((v.x.1 - x) * s).round() as i32;
            root.draw(&PathElement::new(vec![(x0 - 8, y), (x0 - 2, y)], tick))?;
            root.draw(&Text::new(
                format!("{x:.0}"),
                (x0 - 10, y),
                text_style(15.0).pos(Pos::new(HPos::Right, VPos::Center)),
            ))?;
        }
    }
    let (x0, y0) = l.origin(0, l.rows - 1);
    root.draw(&Text::new(
        "x (mm)",
        (x0 - 10, y0 - 24),
        text_style(15.0).pos(Pos::new(HPos::Right, VPos::Top)),
    ))?;
    Ok(())
}

/// The footer: a scale bar, the colour key and the runs' conditions.
fn footer(root: &Area<'_>, l: &Layout, v: &View, conditions: &str) -> Result<()> {
    let s = v.scale(l.tw);
    let bar_mm = nice_length((v.z.1 - v.z.0) / 4.0);
    let y = l.bottom() + 70;
    let x = l.left as i32;
    let bar = (bar_mm * s).round() as i32;
    root.draw(&Rectangle::new([(x, y), (x + bar, y + 5)], BLACK.filled()))?;
    root.draw(&Text::new(
        format!("{bar_mm:.0} mm (every tile at this scale, in z and x alike)"),
        (x + bar + 12, y - 6),
        font(16),
    ))?;
    let key_x = x;
    let key_y = y + 22;
    for (k, (label, rgb)) in [("impactor", IMPACTOR_RGB), ("plate", PLATE_RGB)]
        .into_iter()
        .enumerate()
    {
        let kx = key_x + 130 * k as i32;
        root.draw(&Rectangle::new(
            [(kx, key_y + 3), (kx + 10, key_y + 13)],
            RGBColor(rgb[0], rgb[1], rgb[2]).filled(),
        ))?;
        root.draw(&Text::new(label, (kx + 16, key_y), font(16)))?;
    }
    root.draw(&DashedPathElement::new(
        vec![(key_x + 270, key_y + 2), (key_x + 270, key_y + 16)],
        4,
        3,
        GUIDE.stroke_width(1),
    ))?;
    root.draw(&Text::new(
        "the plate's original rear face",
        (key_x + 280, key_y),
        font(16),
    ))?;
    root.draw(&Text::new(
        conditions.to_string(),
        (x, key_y + 26),
        font(16),
    ))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(z: (f32, f32), x: f32) -> TileCloud {
        let points: Vec<[f32; 2]> = (0..=100)
            .map(|k| {
                let f = k as f32 / 100.0;
                [z.0 + f * (z.1 - z.0), x * (2.0 * f - 1.0)]
            })
            .collect();
        TileCloud {
            impactor: vec![false; points.len()],
            points,
            rear_face_z_mm: 0.0,
        }
    }

    fn tile(c: TileCloud) -> Tile {
        Tile {
            col: 0,
            row: 0,
            cloud: Some(c),
            frame: None,
            caption: String::new(),
        }
    }

    #[test]
    fn the_view_holds_every_cloud_at_one_scale_with_a_bounded_aspect() {
        let v = View::of(&[
            tile(cloud((0.0, 100.0), 10.0)),
            tile(cloud((-5.0, 200.0), 30.0)),
        ]);
        assert!(v.z.0 < -5.0 && v.z.1 > 199.0, "{v:?}");
        assert!(v.x.1 >= 30.0 && v.x.0 == -v.x.1, "{v:?}");
        let ratio = (v.x.1 - v.x.0) / (v.z.1 - v.z.0);
        assert!((0.35 - 1e-9..=1.0 + 1e-9).contains(&ratio), "{ratio}");
        // A narrow cloud is given room up to the least aspect; a fat one stretches z.
        let thin = View::of(&[tile(cloud((0.0, 100.0), 1.0))]);
        assert!(((thin.x.1 - thin.x.0) / (thin.z.1 - thin.z.0) - 0.35).abs() < 1e-9);
        let fat = View::of(&[tile(cloud((0.0, 10.0), 50.0))]);
        assert!(((fat.x.1 - fat.x.0) / (fat.z.1 - fat.z.0) - 1.0).abs() < 1e-9);
    }
}
