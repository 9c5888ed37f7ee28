//! The one look every picture shares: the embedded font, the colours, text styles, axis text
//! sizes, the series legend and the subtitle line. Renders, contour maps, snapshot matrices and
//! the paper's figures take them from here, so a change of look is made once.

use std::sync::OnceLock;

use crate::error::{PlotError, Result};
use crate::glyphs::Glyphs;
use ab_glyph::FontRef;
use plotters::chart::{ChartContext, MeshStyle, SecondaryMeshStyle, SeriesLabelPosition};
use plotters::coord::ranged1d::Ranged;
use plotters::coord::{CoordTranslate, Shift};
use plotters::element::{DashedPathElement, PathElement, Text};
use plotters::prelude::{
    BitMapBackend, Cartesian2d, DrawingArea, DrawingBackend, FontDesc, FontStyle, IntoFont,
};
use plotters::style::{Color, RGBColor, ShapeStyle, TextStyle, BLACK, WHITE};

/// DejaVu Sans (Bitstream Vera licence, see `assets/fonts/LICENSE-DejaVu.txt`).
pub(crate) const FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");
/// The font family every picture uses (DejaVu Sans, embedded).
pub const FAMILY: &str = "sans-serif";

/// Registers the embedded font with plotters once (every picture of the crate calls it).
pub fn fonts() -> Result<()> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err(PlotError::Input(
            "the embedded font could not be loaded".into(),
        ))
    }
}

/// Impactor particles, as raw RGB for the particle rasteriser.
pub(crate) const IMPACTOR_RGB: [u8; 3] = [214, 39, 40];
/// Plate particles, as raw RGB for the particle rasteriser.
pub(crate) const PLATE_RGB: [u8; 3] = [31, 96, 196];
/// Impactor red.
pub(crate) const IMPACTOR: RGBColor = RGBColor(IMPACTOR_RGB[0], IMPACTOR_RGB[1], IMPACTOR_RGB[2]);
/// Plate blue.
pub(crate) const PLATE: RGBColor = RGBColor(PLATE_RGB[0], PLATE_RGB[1], PLATE_RGB[2]);
/// The main line of the paper's figures (the plate's blue).
pub(crate) const BLUE_LINE: RGBColor = PLATE;
/// The second line of the paper's figures (the impactor's red).
pub(crate) const RED_LINE: RGBColor = IMPACTOR;
/// Guide lines (the original rear face, the resolution limit) and the run charts' legend border.
pub(crate) const GUIDE: RGBColor = RGBColor(90, 90, 90);
/// The measured front and width.
pub(crate) const MEASURE: RGBColor = RGBColor(0, 130, 60);
/// Zero lines, r_eq and the legend border of the paper's figures.
pub(crate) const GREY: RGBColor = RGBColor(110, 110, 110);
/// The light mesh lines of line charts.
pub(crate) const GRID: RGBColor = RGBColor(235, 235, 235);
/// Subtitles and notes under a figure.
const SUBTITLE: RGBColor = RGBColor(60, 60, 60);

/// A drawing area of a bitmap, its text drawn by [`Glyphs`].
pub(crate) type Area<'a> = DrawingArea<Png<'a>, Shift>;

/// The bitmap backend of every PNG, its text drawn by [`Glyphs`].
pub(crate) type Png<'a> = Glyphs<'static, BitMapBackend<'a>>;

/// The embedded font as the glyph drawing of bitmaps reads it.
fn font_ref() -> &'static FontRef<'static> {
    static FONT_REF: OnceLock<FontRef<'static>> = OnceLock::new();
    FONT_REF.get_or_init(|| FontRef::try_from_slice(FONT).expect("the embedded font parses"))
}

/// The drawing area of an RGB buffer of `size` pixels, its text drawn glyph by glyph where
/// the font puts each ([`Glyphs`]).
pub(crate) fn png_area(rgb: &mut [u8], size: (u32, u32)) -> Area<'_> {
    DrawingArea::from(Glyphs::new(
        BitMapBackend::with_buffer(rgb, size),
        font_ref(),
    ))
}
/// A linear chart on a bitmap.
pub(crate) type Chart2d<'a, 'b> = ChartContext<
    'b,
    Png<'a>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// Black text of `size` px in the embedded font.
pub(crate) fn text_style(size: f64) -> TextStyle<'static> {
    TextStyle::from((FAMILY, size).into_font()).color(&BLACK)
}

/// The embedded font at `size` px.
pub(crate) fn font(size: u32) -> FontDesc<'static> {
    (FAMILY, size).into_font()
}

/// Tick-label and axis-title sizes, px.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AxisText {
    /// Tick labels.
    pub tick: u32,
    /// Axis titles.
    pub title: u32,
}

/// The axis text of the paper's figures, contour maps and the side view.
pub(crate) const AXIS_TEXT: AxisText = AxisText {
    tick: 17,
    title: 19,
};
/// The axis text of a run's charts (fragment histogram, cloud track).
pub(crate) const AXIS_TEXT_LARGE: AxisText = AxisText {
    tick: 18,
    title: 20,
};

/// Sets tick labels and axis titles in the embedded font (primary and secondary axes alike).
pub(crate) trait ThemedAxes {
    /// Tick labels at `text.tick` px, axis titles at `text.title` px.
    fn axis_text(&mut self, text: AxisText) -> &mut Self;
}

impl<X: Ranged, Y: Ranged, DB: DrawingBackend> ThemedAxes for MeshStyle<'_, '_, X, Y, DB> {
    fn axis_text(&mut self, text: AxisText) -> &mut Self {
        self.label_style((FAMILY, text.tick))
            .axis_desc_style((FAMILY, text.title))
    }
}

impl<X: Ranged, Y: Ranged, DB: DrawingBackend> ThemedAxes for SecondaryMeshStyle<'_, '_, X, Y, DB>
where
    X: plotters::coord::ranged1d::ValueFormatter<X::ValueType>,
    Y: plotters::coord::ranged1d::ValueFormatter<Y::ValueType>,
{
    fn axis_text(&mut self, text: AxisText) -> &mut Self {
        self.label_style((FAMILY, text.tick))
            .axis_desc_style((FAMILY, text.title))
    }
}

/// How a series legend looks: a white box `opacity` opaque, its border, its label size.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LegendStyle {
    /// Opacity of the white background.
    pub opacity: f64,
    /// Border colour.
    pub border: RGBColor,
    /// Label size, px.
    pub label_px: u32,
}

/// The legend of a run's charts.
pub(crate) const RUN_LEGEND: LegendStyle = LegendStyle {
    opacity: 0.9,
    border: GUIDE,
    label_px: 18,
};

/// The legend of the paper's figures, with labels of `label_px`.
pub(crate) const fn paper_legend(label_px: u32) -> LegendStyle {
    LegendStyle {
        opacity: 0.9,
        border: GREY,
        label_px,
    }
}

/// Draws the chart's series legend at `position`.
pub(crate) fn series_legend<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    style: LegendStyle,
) -> Result<()>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    CT: CoordTranslate,
{
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(style.opacity))
        .border_style(style.border)
        .label_font((FAMILY, style.label_px))
        .draw()?;
    Ok(())
}

/// A legend key: a line `len` px long from (x, y).
pub(crate) fn line_key(x: i32, y: i32, len: i32, style: ShapeStyle) -> PathElement<(i32, i32)> {
    PathElement::new(vec![(x, y), (x + len, y)], style)
}

/// A legend key of a dashed line of the paper's figures.
pub(crate) fn dashed_key(
    x: i32,
    y: i32,
    color: RGBColor,
) -> DashedPathElement<std::vec::IntoIter<(i32, i32)>, i32> {
    DashedPathElement::new(vec![(x, y), (x + 24, y)], 6, 4, color.stroke_width(2))
}

/// One grey 15 px line under a figure (its tier, its sources), `from_bottom` px above the
/// bottom edge of `area`.
pub(crate) fn subtitle<DB>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    from_bottom: i32,
) -> Result<()>
where
    DB: DrawingBackend,
    DB::ErrorType: 'static,
{
    // One line per `\n`, the last at `from_bottom`, the others above it.
    let lines: Vec<&str> = text.lines().collect();
    let h = area.dim_in_pixel().1 as i32;
    for (i, line) in lines.iter().enumerate() {
        let up = 19 * (lines.len() - 1 - i) as i32;
        area.draw(&Text::new(
            line.to_string(),
            (20, h - from_bottom - up),
            font(15).color(&SUBTITLE),
        ))?;
    }
    Ok(())
}
