//! Snapshot matrices (Figs. 7 and 17): each run's side view (the left panel of the
//! `cloud_side.png` that `hvi_plot::render` draws for it) tiled over two axes of the study,
//! optionally framed by a verdict (Fig. 17: valid red, invalid blue). Pictures only; the
//! numbers come from the runs.

use std::io::BufReader;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use plotters::prelude::*;

use crate::save::{encode_png, write_atomic_bytes};
use crate::theme::{font, fonts, Area};

/// An RGB image.
#[derive(Debug, Clone)]
pub struct Image {
    /// Width, px.
    pub w: usize,
    /// Height, px.
    pub h: usize,
    /// RGB bytes, row-major.
    pub rgb: Vec<u8>,
}

impl Image {
    /// Reads an 8-bit RGB or RGBA PNG.
    pub fn read_png(path: &Path) -> Result<Image> {
        let file =
            std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
        let mut reader = png::Decoder::new(BufReader::new(file))
            .read_info()
            .with_context(|| format!("{} is not a PNG", path.display()))?;
        let size = reader
            .output_buffer_size()
            .ok_or_else(|| anyhow!("{}: image too large", path.display()))?;
        let mut buf = vec![0u8; size];
        let info = reader.next_frame(&mut buf)?;
        let (w, h) = (info.width as usize, info.height as usize);
        let channels = match info.color_type {
            png::ColorType::Rgb => 3,
            png::ColorType::Rgba => 4,
            other => bail!(
                "{}: colour type {other:?} (want RGB or RGBA)",
                path.display()
            ),
        };
        if info.bit_depth != png::BitDepth::Eight {
            bail!("{}: not 8 bits per channel", path.display());
        }
        let mut rgb = Vec::with_capacity(w * h * 3);
        for row in buf.chunks(info.line_size).take(h) {
            for px in row.chunks(channels).take(w) {
                rgb.extend_from_slice(&px[..3]);
            }
        }
        Ok(Image { w, h, rgb })
    }

    /// The part [x0, x1) x [y0, y1), scaled by box averaging to width `tw` (aspect kept).
    pub fn crop_scaled(
        &self,
        (x0, x1): (usize, usize),
        (y0, y1): (usize, usize),
        tw: usize,
    ) -> Image {
        let (x1, y1) = (x1.min(self.w), y1.min(self.h));
        let (cw, ch) = (x1.saturating_sub(x0).max(1), y1.saturating_sub(y0).max(1));
        let th = ((ch as f64) * tw as f64 / cw as f64).round().max(1.0) as usize;
        let mut rgb = vec![255u8; tw * th * 3];
        for ty in 0..th {
            let sy0 = y0 + ty * ch / th;
            let sy1 = (y0 + (ty + 1) * ch / th).max(sy0 + 1).min(y1);
            for tx in 0..tw {
                let sx0 = x0 + tx * cw / tw;
                let sx1 = (x0 + (tx + 1) * cw / tw).max(sx0 + 1).min(x1);
                let mut acc = [0u32; 3];
                let mut n = 0u32;
                for sy in sy0..sy1 {
                    for sx in sx0..sx1 {
                        let k = (sy * self.w + sx) * 3;
                        for (a, &v) in acc.iter_mut().zip(&self.rgb[k..k + 3]) {
                            *a += v as u32;
                        }
                        n += 1;
                    }
                }
                let k = (ty * tw + tx) * 3;
                for (o, a) in rgb[k..k + 3].iter_mut().zip(acc) {
                    *o = (a / n.max(1)) as u8;
                }
            }
        }
        Image { w: tw, h: th, rgb }
    }
}

/// One tile of a matrix: the run's picture (None when the run has none) and its frame colour.
pub struct Tile {
    /// Column (x-axis value index, ascending).
    pub col: usize,
    /// Row (y-axis value index, ascending; drawn bottom-up so larger values are on top).
    pub row: usize,
    /// The run's `cloud_side.png`.
    pub picture: Option<std::path::PathBuf>,
    /// Frame colour (None: thin grey).
    pub frame: Option<RGBColor>,
    /// A short caption under the picture (e.g. `F = 0.42`).
    pub caption: String,
}

/// Where the matrix puts things, px: label margins, the tile size and the grid of cells.
struct MatrixLayout {
    left: usize,
    top: usize,
    gap: usize,
    /// Tile width and height.
    tw: usize,
    th: usize,
    cell_w: usize,
    cell_h: usize,
    /// Rows of the matrix (row 0 is drawn at the bottom).
    rows: usize,
    /// Image width and height.
    w: usize,
    h: usize,
}

impl MatrixLayout {
    /// The layout of `cols` x `rows` tiles of `tw` x `th`.
    fn new(tw: usize, th: usize, cols: usize, rows: usize) -> Self {
        let (left, top, gap, cap) = (150usize, 120usize, 14usize, 24usize);
        let cell_w = tw + gap;
        let cell_h = th + gap + cap;
        MatrixLayout {
            left,
            top,
            gap,
            tw,
            th,
            cell_w,
            cell_h,
            rows,
            w: left + cols * cell_w + 20,
            h: top + rows * cell_h + 60,
        }
    }

    /// The top-left corner of a tile's picture.
    fn origin(&self, t: &Tile) -> (usize, usize) {
        let x = self.left + t.col * self.cell_w + self.gap / 2;
        let y = self.top + (self.rows - 1 - t.row) * self.cell_h + self.gap / 2;
        (x, y)
    }
}

/// Draws the matrix into `path` (PNG). `cols`/`rows` are the axis labels of the columns and
/// rows (ascending). Returns how many tiles had a picture.
pub fn snapshot_matrix(
    path: &Path,
    title: &str,
    (x_label, cols): (&str, &[String]),
    (y_label, rows): (&str, &[String]),
    tiles: &[Tile],
) -> Result<usize> {
    fonts()?;
    let tw = if cols.len() > 4 { 260 } else { 380 };
    let (pictures, th) = tile_pictures(tiles, tw)?;
    let layout = MatrixLayout::new(tw, th, cols.len(), rows.len());
    let (w, h) = (layout.w, layout.h);
    let mut rgb = vec![255u8; w * h * 3];
    for (t, img) in tiles.iter().zip(&pictures) {
        if let Some(img) = img {
            blit(&mut rgb, w, img, layout.origin(t), th);
        }
    }
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w as u32, h as u32)).into_drawing_area();
        root.draw(&Text::new(title.to_string(), (20, 20), font(28)))?;
        root.draw(&Text::new(
            format!("columns: {x_label}; rows: {y_label}"),
            (20, 60),
            font(18),
        ))?;
        axis_labels(&root, &layout, cols, rows)?;
        for (t, img) in tiles.iter().zip(&pictures) {
            tile_frame(&root, &layout, t, img.is_some())?;
        }
        root.present()?;
    }
    let bytes = encode_png(&rgb, w as u32, h as u32, Some(png::Compression::Fast))?;
    write_atomic_bytes(path, &bytes)?;
    Ok(pictures.iter().filter(|p| p.is_some()).count())
}

/// Each tile's picture cropped to the side view's left panel (the projection along y, as
/// `render::side_view` lays it out) at width `tw`, and the tile height: that of the last
/// picture, 0.9 `tw` without any.
fn tile_pictures(tiles: &[Tile], tw: usize) -> Result<(Vec<Option<Image>>, usize)> {
    let crop =
        |img: &Image| img.crop_scaled((0, img.w / 2), (img.h * 6 / 100, img.h * 84 / 100), tw);
    let mut pictures = Vec::new();
    let mut th = (tw as f64 * 0.9) as usize;
    for t in tiles {
        let img = match &t.picture {
            Some(p) if p.exists() => Some(crop(&Image::read_png(p)?)),
            _ => None,
        };
        if let Some(i) = &img {
            th = i.h;
        }
        pictures.push(img);
    }
    Ok((pictures, th))
}

/// Copies `img` (at most `th` rows) into `rgb`, an image `w` wide, at `(x0, y0)`.
fn blit(rgb: &mut [u8], w: usize, img: &Image, (x0, y0): (usize, usize), th: usize) {
    for y in 0..img.h.min(th) {
        let src = &img.rgb[y * img.w * 3..(y + 1) * img.w * 3];
        let k = ((y0 + y) * w + x0) * 3;
        rgb[k..k + img.w * 3].copy_from_slice(src);
    }
}

/// The column labels above the matrix and the row labels left of it.
fn axis_labels(root: &Area<'_>, l: &MatrixLayout, cols: &[String], rows: &[String]) -> Result<()> {
    for (c, label) in cols.iter().enumerate() {
        root.draw(&Text::new(
            label.clone(),
            (
                (l.left + c * l.cell_w + l.tw / 2 - 30) as i32,
                (l.top - 30) as i32,
            ),
            font(18),
        ))?;
    }
    for (r, label) in rows.iter().enumerate() {
        let y = l.top + (rows.len() - 1 - r) * l.cell_h + l.th / 2;
        root.draw(&Text::new(label.clone(), (12, y as i32), font(18)))?;
    }
    Ok(())
}

/// A tile's frame (its verdict's colour, else thin grey), its caption, and a note when it
/// has no picture.
fn tile_frame(root: &Area<'_>, l: &MatrixLayout, t: &Tile, has_picture: bool) -> Result<()> {
    let (x0, y0) = l.origin(t);
    let (x0, y0) = (x0 as i32, y0 as i32);
    let (x1, y1) = (x0 + l.tw as i32, y0 + l.th as i32);
    if !has_picture {
        root.draw(&Text::new("no picture", (x0 + 20, y0 + 40), font(16)))?;
    }
    let style = match t.frame {
        Some(c) => c.stroke_width(5),
        None => RGBColor(170, 170, 170).stroke_width(1),
    };
    root.draw(&Rectangle::new([(x0 - 2, y0 - 2), (x1 + 2, y1 + 2)], style))?;
    root.draw(&Text::new(t.caption.clone(), (x0 + 4, y1 + 9), font(16)))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_scaling_averages() {
        let img = Image {
            w: 4,
            h: 2,
            rgb: vec![
                0, 0, 0, 255, 255, 255, 10, 10, 10, 30, 30, 30, //
                0, 0, 0, 255, 255, 255, 10, 10, 10, 30, 30, 30,
            ],
        };
        let s = img.crop_scaled((0, 4), (0, 2), 2);
        assert_eq!((s.w, s.h), (2, 1));
        assert_eq!(&s.rgb, &[127, 127, 127, 20, 20, 20]);
    }
}
