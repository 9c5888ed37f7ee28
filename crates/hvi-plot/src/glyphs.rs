//! Text on bitmaps with each glyph where the font puts it.
//!
//! plotters 0.3.7 draws each glyph of a string at the pen position without the glyph's own
//! left side bearing, so glyphs that start right of their origin (i, l) or reach left of it
//! (j, J) come out shifted: "Objective J over" reads "Ob jective Jover". [`Glyphs`] wraps a
//! bitmap backend and draws its text itself, each glyph at the pen position plus its bounds
//! (ab_glyph's `px_bounds`), with plotters' advances, kerning, anchors, rotations and vertical
//! placement, so a label sits where plotters' layout expects it. Everything else goes to the
//! wrapped backend. SVG text is laid out by the viewer and needs none of this.

use ab_glyph::{point, Font, FontRef, ScaleFont};
use plotters::prelude::DrawingBackend;
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};

/// A bitmap backend whose text is drawn by [`Glyphs::draw_text`] with `font`.
pub struct Glyphs<'f, B> {
    inner: B,
    font: &'f FontRef<'f>,
}

impl<'f, B> Glyphs<'f, B> {
    /// `inner` with its text drawn in `font`.
    pub fn new(inner: B, font: &'f FontRef<'f>) -> Self {
        Glyphs { inner, font }
    }
}

/// The pixels of `text` in `font` at `size` pixels, as plotters lays it out (pen from x = 0,
/// the glyphs' tops at size / 2 + their own top), each with its coverage.
fn rasterise(font: &FontRef<'_>, size: f32, text: &str, mut put: impl FnMut(i32, i32, f32)) {
    let font = font.as_scaled(size);
    let mut pen = 0f32;
    let mut prev = None;
    for c in text.chars() {
        let id = font.glyph_id(c);
        if let Some(p) = prev {
            pen += font.kern(p, id);
        }
        prev = Some(id);
        if let Some(q) = font.outline_glyph(id.with_scale_and_position(size, point(pen, 0.0))) {
            let b = q.px_bounds();
            let (x0, y0) = (b.min.x as i32, (size / 2.0 + b.min.y) as i32);
            q.draw(|x, y, a| put(x0 + x as i32, y0 + y as i32, a));
        }
        pen += font.h_advance(id);
    }
}

impl<B: DrawingBackend> DrawingBackend for Glyphs<'_, B> {
    type ErrorType = B::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.inner.get_size()
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.ensure_prepared()
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.present()
    }

    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.fill_polygon(vert, style)
    }

    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        (iw, ih): (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.blit_bitmap(pos, (iw, ih), src)
    }

    /// plotters' own text drawing (the layout box, the anchor, the rotation, pixels outside
    /// the picture dropped) with [`rasterise`]'s glyph placement.
    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let ((min_x, min_y), (max_x, max_y)) = style
            .layout_box(text)
            .map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        let (width, height) = (max_x - min_x, max_y - min_y);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Right => -width,
            HPos::Center => -width / 2,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -height / 2,
            VPos::Bottom => -height,
        };
        let trans = style.transform();
        let (w, h) = self.get_size();
        let mut result = Ok(());
        rasterise(self.font, style.size() as f32, text, |x, y, a| {
            if result.is_err() {
                return;
            }
            let (x, y) = trans.transform(x + dx - min_x, y + dy - min_y);
            let (x, y) = (pos.0 + x, pos.1 + y);
            if x >= 0 && x < w as i32 && y >= 0 && y < h as i32 {
                result = self.inner.draw_pixel((x, y), color.mix(f64::from(a)));
            }
        });
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The columns a string's pixels cover, left to right, as runs of inked columns.
    fn ink_runs(font: &FontRef<'_>, text: &str) -> Vec<(i32, i32)> {
        let mut cols = std::collections::BTreeSet::new();
        rasterise(font, 40.0, text, |x, _, a| {
            if a > 0.5 {
                cols.insert(x);
            }
        });
        let mut runs: Vec<(i32, i32)> = vec![];
        for x in cols {
            match runs.last_mut() {
                Some((_, end)) if *end + 1 == x => *end = x,
                _ => runs.push((x, x)),
            }
        }
        runs
    }

    /// Each glyph's ink starts at its left side bearing from the pen: left of it for "J" (a
    /// negative bearing), right of it for "l" and "H" (plotters drew all three at the
    /// pen).
    #[test]
    fn each_glyph_starts_at_its_left_side_bearing() {
        let font = FontRef::try_from_slice(crate::theme::FONT).expect("the embedded font");
        let scaled = font.as_scaled(40.0);
        for (c, sign) in [('J', -1.0), ('l', 1.0), ('H', 1.0)] {
            let bearing = scaled.h_side_bearing(font.glyph_id(c));
            assert!(bearing * sign >= 1.0, "{c}: bearing {bearing} px");
            let first = ink_runs(&font, &c.to_string())[0].0;
            assert!(
                (first as f32 - bearing).abs() <= 1.5,
                "{c}: ink from x = {first}, bearing {bearing}"
            );
        }
    }

    /// The gap a space leaves between two words is about a space whichever letter stands
    /// before it: without "J"'s bearing "J o" closed up where "H o" did not.
    #[test]
    fn a_space_leaves_the_same_gap_beside_every_letter() {
        let font = FontRef::try_from_slice(crate::theme::FONT).expect("the embedded font");
        let gap = |text: &str| {
            let runs = ink_runs(&font, text);
            let (a, b) = (runs[runs.len() - 2], runs[runs.len() - 1]);
            b.0 - a.1
        };
        // The space's advance at 40 px is about 12.7 px; the gaps differ by the letters' own
        // right bearings (a pixel or two).
        let (j, h) = (gap("J o"), gap("H o"));
        assert!(j >= 10 && (j - h).abs() <= 3, "J {j}, H {h}");
    }
}
