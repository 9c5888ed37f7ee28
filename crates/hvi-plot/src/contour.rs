//! Contour plots of study fields (Figs. 9, 10, 16b and the objective map), as PNG and SVG.
//!
//! The filled background is the field's bilinear interpolation between the runs (each grid cell
//! drawn as small tiles), iso-lines come from [`hvi_analysis::contour`], the runs are black dots. A
//! highlighted level (a target or the validity cut-off) is drawn in red. Log axes are drawn in
//! log10 coordinates with the tick labels in the physical value. Shows numbers, derives none.

use std::path::Path;

use crate::error::{PlotError, Result};
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use crate::render::round_ticks;
use crate::save::{encode_png, write_atomic_bytes};
use crate::theme::{
    font, fonts, line_key, series_legend, subtitle, text_style, LegendStyle, ThemedAxes, AXIS_TEXT,
    FAMILY,
};
use hvi_analysis::contour::{Field, Point};
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// The legend of a contour map: a lighter box with a black border over the field.
const MAP_LEGEND: LegendStyle = LegendStyle {
    opacity: 0.85,
    border: BLACK,
    label_px: 15,
};

/// A marked point with a label (the optimum, the paper's fit).
#[derive(Debug, Clone)]
pub struct Marker {
    /// Position in physical units.
    pub at: Point,
    /// Legend text.
    pub label: String,
    /// Colour.
    pub color: RGBColor,
    /// A cross (true) or a circle.
    pub cross: bool,
}

/// A curve over the map (an experiment's relation, a model's onset), in physical units.
#[derive(Debug, Clone)]
pub struct Curve {
    /// The points, joined in order.
    pub points: Vec<Point>,
    /// Legend text.
    pub label: String,
    /// Colour.
    pub color: RGBColor,
    /// Dashed (true) or solid.
    pub dashed: bool,
    /// Per point, an interval in x drawn as a bar through it (a bracket), or none.
    pub x_bars: Vec<Option<(f64, f64)>>,
}

/// A contour plot.
#[derive(Debug, Clone)]
pub struct ContourPlot {
    /// Title.
    pub title: String,
    /// Subtitle (one line under the title: the tier, the source of the highlighted level).
    pub subtitle: String,
    /// Axis labels.
    pub x_label: String,
    /// Axis labels.
    pub y_label: String,
    /// Draw x in log10.
    pub x_log: bool,
    /// Draw y in log10.
    pub y_log: bool,
    /// The field in physical coordinates.
    pub field: Field,
    /// The colour bar's label.
    pub value_label: String,
    /// Number of plain iso-lines.
    pub levels: usize,
    /// A level drawn in red, with its legend text.
    pub highlight: Option<(f64, String)>,
    /// Small hollow points (refinement evaluations), physical coordinates.
    pub extra_points: Vec<Point>,
    /// Where the simulations are, drawn as black dots, when the field is not made of them
    /// (a model's prediction on a finer lattice); `None`: every node of the field is a run
    /// (red rings where it has no value).
    pub samples: Option<Vec<Point>>,
    /// Marked points.
    pub markers: Vec<Marker>,
    /// A box drawn dashed, with its legend text: (lowest corner, highest corner) in physical
    /// units (the calibration's confidence region).
    pub region: Option<(Point, Point, String)>,
    /// Curves drawn over the map, each with its legend entry.
    pub curves: Vec<Curve>,
    /// Colours and iso-lines over the field's bulk only (the median within 3 median absolute
    /// deviations, inside the field's range), for a field that a few outlying values would
    /// otherwise flatten into one colour: values beyond saturate at the colour bar's ends, and
    /// the bar gives the field's whole range.
    pub bulk_colours: bool,
}

fn tx(v: f64, log: bool) -> f64 {
    if log {
        v.log10()
    } else {
        v
    }
}

/// Viridis-like colour map on [0, 1].
pub fn colormap(t: f64) -> RGBColor {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (0.0, [68.0, 1.0, 84.0]),
        (0.25, [59.0, 82.0, 139.0]),
        (0.5, [33.0, 145.0, 140.0]),
        (0.75, [94.0, 201.0, 98.0]),
        (1.0, [253.0, 231.0, 37.0]),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let k = STOPS
        .windows(2)
        .position(|w| t <= w[1].0)
        .unwrap_or(STOPS.len() - 2);
    let (a, b) = (STOPS[k], STOPS[k + 1]);
    let s = (t - a.0) / (b.0 - a.0);
    let c = |i: usize| (a.1[i] + s * (b.1[i] - a.1[i])).round() as u8;
    RGBColor(c(0), c(1), c(2))
}

/// A linear axis (log10 values on a log axis) with the ticks of [`axis_keys`].
pub(crate) struct KeyedAxis {
    range: RangedCoordf64,
    keys: Vec<f64>,
}

impl KeyedAxis {
    pub(crate) fn new(a: f64, b: f64, log: bool) -> Self {
        KeyedAxis {
            range: (a..b).into(),
            keys: axis_keys(a, b, log),
        }
    }
}

impl Ranged for KeyedAxis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;
    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.range.map(value, limit)
    }
    fn key_points<Hint: KeyPointHint>(&self, _hint: Hint) -> Vec<f64> {
        self.keys.clone()
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.range.range()
    }
}

/// Tick values of a log axis from `lo` to `hi` (physical values): 1, 2 and 5 times each power
/// of ten, or every integer multiple when that gives fewer than three.
pub(crate) fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return Vec::new();
    }
    let within = |mantissas: &[f64]| -> Vec<f64> {
        (lo.log10().floor() as i32..=hi.log10().ceil() as i32)
            .flat_map(|e| mantissas.iter().map(move |m| m * 10f64.powi(e)))
            .filter(|&v| v >= lo && v <= hi)
            .collect()
    };
    let keys = within(&[1.0, 2.0, 5.0]);
    if keys.len() >= 3 {
        keys
    } else {
        within(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0])
    }
}

/// Tick positions on an axis from `a` to `b` (in log10 when `log`): on a log axis
/// [`log_ticks`], so labels read 0.01, 0.02, 0.05 rather than 10^(k/5); on a linear axis
/// plotters' own.
fn axis_keys(a: f64, b: f64, log: bool) -> Vec<f64> {
    if log {
        log_ticks(10f64.powf(a), 10f64.powf(b))
            .into_iter()
            .map(f64::log10)
            .collect()
    } else {
        let r: RangedCoordf64 = (a..b).into();
        r.key_points(10)
    }
}

/// A tick's label at drawn coordinate `v` (log10 on a log axis).
pub(crate) fn tick(v: f64, log: bool) -> String {
    let x = if log { 10f64.powf(v) } else { v };
    let a = x.abs();
    if a != 0.0 && !(1e-2..=1e5).contains(&a) {
        scientific(x)
    } else {
        let s = format!("{x:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// A tick's label on an axis whose top is `top` (drawn coordinate): as [`tick`], except that
/// on an axis reaching past 1e5 every label from 1e3 up is scientific, so that one axis does
/// not read `100000` beside `1e6`.
pub(crate) fn axis_tick(v: f64, log: bool, top: f64) -> String {
    let x = if log { 10f64.powf(v) } else { v };
    let reaches = if log { top > 5.0 } else { top > 1e5 };
    if reaches && x.abs() >= 1e3 {
        scientific(x)
    } else {
        tick(v, log)
    }
}

/// `x` as `m e k`: `5e4`, `4.56e6`.
fn scientific(x: f64) -> String {
    let e = x.abs().log10().floor();
    let m = x / 10f64.powf(e);
    if (m - m.round()).abs() < 1e-6 {
        format!("{}e{}", m.round(), e)
    } else {
        format!("{m:.2}e{e}")
    }
}

/// A contour map's chart: log10 or linear coordinates on both axes, ticks from [`axis_keys`].
type MapChart<'a, DB> = ChartContext<'a, DB, Cartesian2d<KeyedAxis, KeyedAxis>>;

/// What the map spans: the axis ranges in drawn coordinates (padded, with room above the data
/// for the legend) and the values the colours cover.
struct MapFrame {
    x: (f64, f64),
    y: (f64, f64),
    zmin: f64,
    zmax: f64,
    zspan: f64,
    /// The field's whole range, when the colours cover less of it.
    saturated: Option<(f64, f64)>,
}

impl MapFrame {
    /// The frame widened in x and y to hold every curve's points and bars (a curve is not
    /// cut at the field's edge), with the same 4 % margin.
    fn around_curves(mut self, p: &ContourPlot) -> Self {
        let mut xs: Vec<f64> = Vec::new();
        let mut ys: Vec<f64> = Vec::new();
        for c in &p.curves {
            for (k, &(x, y)) in c.points.iter().enumerate() {
                xs.push(tx(x, p.x_log));
                ys.push(tx(y, p.y_log));
                if let Some(Some((a, b))) = c.x_bars.get(k) {
                    xs.extend([tx(*a, p.x_log), tx(*b, p.x_log)]);
                }
            }
        }
        let widen = |(lo, hi): (f64, f64), v: &[f64]| {
            let (a, b) = v
                .iter()
                .filter(|x| x.is_finite())
                .fold((lo, hi), |(a, b), &x| (a.min(x), b.max(x)));
            let d = 0.04 * (b - a);
            (
                if a < lo { a - d } else { lo },
                if b > hi { b + d } else { hi },
            )
        };
        self.x = widen(self.x, &xs);
        self.y = widen(self.y, &ys);
        self
    }

    /// The frame of a field in drawn coordinates.
    fn of(field: &Field, bulk: bool) -> Self {
        let (x0, x1) = (field.x[0], field.x[field.x.len() - 1]);
        let (y0, y1) = (field.y[0], field.y[field.y.len() - 1]);
        let pad = |a: f64, b: f64| {
            let d = if b > a { 0.04 * (b - a) } else { 0.5 };
            (a - d, b + d)
        };
        let (xa, xb) = pad(x0, x1);
        let (ya, yb) = pad(y0, y1);
        // Room above the data for the legend, so it hides no run.
        let yb = yb + 0.22 * (yb - ya);
        let whole = field.range().unwrap_or((0.0, 1.0));
        let (zmin, zmax) = if bulk {
            bulk_range(field).unwrap_or(whole)
        } else {
            whole
        };
        let zspan = if zmax > zmin { zmax - zmin } else { 1.0 };
        MapFrame {
            x: (xa, xb),
            y: (ya, yb),
            zmin,
            zmax,
            zspan,
            saturated: ((zmin, zmax) != whole).then_some(whole),
        }
    }

    /// A value's place on the colour map: 0 at the smallest, 1 at the largest (values beyond
    /// the colours' range saturate).
    fn norm(&self, z: f64) -> f64 {
        ((z - self.zmin) / self.zspan).clamp(0.0, 1.0)
    }
}

/// The field's bulk: the median within 3 median absolute deviations, inside the field's range
/// (None when the deviation is zero).
fn bulk_range(field: &Field) -> Option<(f64, f64)> {
    let (lo, hi) = field.range()?;
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    };
    let values: Vec<f64> = field.finite_values().collect();
    let m = median(values.clone());
    let mad = median(values.iter().map(|v| (v - m).abs()).collect());
    (mad > 0.0).then(|| (lo.max(m - 3.0 * mad), hi.min(m + 3.0 * mad)))
}

/// The field in drawn coordinates (log10 on a log axis).
fn drawn_field(p: &ContourPlot) -> Field {
    let f = &p.field;
    Field {
        x: f.x.iter().map(|&v| tx(v, p.x_log)).collect(),
        y: f.y.iter().map(|&v| tx(v, p.y_log)).collect(),
        z: f.z.clone(),
    }
}

/// Draws the whole plot on `root` (a bitmap or an SVG): the map, its legend and subtitle, and
/// the colour bar.
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    p: &ContourPlot,
    max_tiles: usize,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let field = drawn_field(p);
    let frame = MapFrame::of(&field, p.bulk_colours).around_curves(p);
    let (main, bar) = root.split_horizontally(root.dim_in_pixel().0 - 150);
    let mut chart = map_axes(&main, p, &frame)?;
    fill_field(&mut chart, &field, &frame, max_tiles)?;
    iso_lines(&mut chart, &field, p, &frame)?;
    run_points(&mut chart, &field, p)?;
    region_box(&mut chart, p)?;
    curves(&mut chart, p)?;
    markers(&mut chart, p)?;
    series_legend(&mut chart, SeriesLabelPosition::UpperRight, MAP_LEGEND)?;
    subtitle(&main, &p.subtitle, 26)?;
    colour_bar(&bar, p, &frame)?;
    root.present()?;
    Ok(())
}

/// The map's chart with its title, axis titles and ticks (physical values on log axes).
fn map_axes<'a, DB: DrawingBackend>(
    main: &'a DrawingArea<DB, Shift>,
    p: &ContourPlot,
    frame: &MapFrame,
) -> Result<MapChart<'a, DB>>
where
    DB::ErrorType: 'static,
{
    let mut chart = ChartBuilder::on(main)
        .caption(&p.title, (FAMILY, 26))
        .margin(18)
        .margin_bottom(62)
        .x_label_area_size(70)
        .y_label_area_size(95)
        .build_cartesian_2d(
            KeyedAxis::new(frame.x.0, frame.x.1, p.x_log),
            KeyedAxis::new(frame.y.0, frame.y.1, p.y_log),
        )?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(&p.x_label)
        .y_desc(&p.y_label)
        .axis_text(AXIS_TEXT)
        .x_label_formatter(&|v| axis_tick(*v, p.x_log, frame.x.1))
        .y_label_formatter(&|v| axis_tick(*v, p.y_log, frame.y.1))
        .draw()?;
    Ok(chart)
}

/// Tiles per grid cell side at most (a coarse grid's cells are shaded smoothly).
const TILES_PER_CELL: usize = 14;

/// Tiles in a bitmap map at most, and in an SVG one (each tile is an SVG element: a model's
/// 33 x 33 field at 14 x 14 tiles a cell made a 17 MB file).
const MAX_TILES_PNG: usize = usize::MAX;
const MAX_TILES_SVG: usize = 6000;

/// Tiles per cell side for `cells` cells within `max_tiles` in all (at least one).
fn tiles_per_cell(cells: usize, max_tiles: usize) -> usize {
    let by_budget = ((max_tiles as f64 / cells.max(1) as f64).sqrt().floor() as usize).max(1);
    by_budget.min(TILES_PER_CELL)
}

/// The filled field: each grid cell as tiles coloured by the interpolation at their centre
/// (grey where it is missing), at most `max_tiles` tiles in all.
fn fill_field<DB: DrawingBackend>(
    chart: &mut MapChart<'_, DB>,
    field: &Field,
    frame: &MapFrame,
    max_tiles: usize,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let cells = field.x.len().saturating_sub(1) * field.y.len().saturating_sub(1);
    let tiles_per = tiles_per_cell(cells, max_tiles);
    let mut tiles = Vec::new();
    for j in 0..field.y.len().saturating_sub(1) {
        for i in 0..field.x.len().saturating_sub(1) {
            let (cx0, cx1) = (field.x[i], field.x[i + 1]);
            let (cy0, cy1) = (field.y[j], field.y[j + 1]);
            for a in 0..tiles_per {
                for b in 0..tiles_per {
                    let n = tiles_per as f64;
                    let u0 = cx0 + (cx1 - cx0) * a as f64 / n;
                    let u1 = cx0 + (cx1 - cx0) * (a + 1) as f64 / n;
                    let v0 = cy0 + (cy1 - cy0) * b as f64 / n;
                    let v1 = cy0 + (cy1 - cy0) * (b + 1) as f64 / n;
                    let color = field
                        .at(0.5 * (u0 + u1), 0.5 * (v0 + v1))
                        .map_or(RGBColor(200, 200, 200), |z| colormap(frame.norm(z)));
                    tiles.push(Rectangle::new([(u0, v0), (u1, v1)], color.filled()));
                }
            }
        }
    }
    chart.draw_series(tiles)?;
    Ok(())
}

/// `p.levels` plain iso-lines evenly between the smallest and largest value, and the
/// highlighted level in red with its legend entry.
fn iso_lines<DB: DrawingBackend>(
    chart: &mut MapChart<'_, DB>,
    field: &Field,
    p: &ContourPlot,
    frame: &MapFrame,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let line_color = RGBColor(40, 40, 40);
    for k in 1..=p.levels {
        let level = frame.zmin + frame.zspan * k as f64 / (p.levels + 1) as f64;
        let lines = field.contour(level);
        // The level's value at the middle of its longest line, as the colour bar writes it.
        let label_at = lines
            .iter()
            .max_by_key(|l| l.len())
            .and_then(|l| l.get(l.len() / 2).copied());
        for line in lines {
            chart.draw_series(std::iter::once(PathElement::new(
                line,
                line_color.mix(0.55).stroke_width(1),
            )))?;
        }
        if let Some(at) = label_at {
            // On a pale box, so that it reads on the dark and the light end of the colours.
            let text = tick(level, false);
            let half = 4 * text.chars().count() as i32 + 3;
            chart.draw_series(std::iter::once(
                EmptyElement::at(at)
                    + Rectangle::new([(-half, -9), (half, 9)], WHITE.mix(0.75).filled())
                    + Text::new(
                        text,
                        (0, 0),
                        text_style(14.0)
                            .color(&line_color)
                            .pos(Pos::new(HPos::Center, VPos::Center)),
                    ),
            ))?;
        }
    }
    if let Some((level, label)) = &p.highlight {
        let lines = field.contour(*level);
        let mut first = true;
        for line in lines {
            let s =
                chart.draw_series(std::iter::once(PathElement::new(line, RED.stroke_width(4))))?;
            if first {
                s.label(label.clone())
                    .legend(|(x, y)| line_key(x, y, 22, RED.stroke_width(4)));
                first = false;
            }
        }
    }
    Ok(())
}

/// The runs as black dots (red rings where a run has no value) and the refinement points
/// hollow.
fn run_points<DB: DrawingBackend>(
    chart: &mut MapChart<'_, DB>,
    field: &Field,
    p: &ContourPlot,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let mut dots = Vec::new();
    if let Some(samples) = &p.samples {
        dots.extend(
            samples
                .iter()
                .map(|&(x, y)| Circle::new((tx(x, p.x_log), tx(y, p.y_log)), 5, BLACK.filled())),
        );
    }
    for (j, &y) in field.y.iter().enumerate() {
        if p.samples.is_some() {
            break;
        }
        for (i, &x) in field.x.iter().enumerate() {
            let missing = !field.z[j][i].is_finite();
            dots.push(Circle::new(
                (x, y),
                5,
                if missing {
                    RED.stroke_width(2)
                } else {
                    BLACK.filled()
                },
            ));
        }
    }
    chart
        .draw_series(dots)?
        .label("simulations")
        .legend(|(x, y)| Circle::new((x + 10, y), 5, BLACK.filled()));
    if !p.extra_points.is_empty() {
        chart
            .draw_series(p.extra_points.iter().map(|&(x, y)| {
                Circle::new((tx(x, p.x_log), tx(y, p.y_log)), 4, WHITE.stroke_width(2))
            }))?
            .label("runs after the grid")
            .legend(|(x, y)| Circle::new((x + 10, y), 4, BLACK.stroke_width(2)));
    }
    Ok(())
}

/// The region's box, dashed black over white so that it shows on any colour.
fn region_box<DB: DrawingBackend>(chart: &mut MapChart<'_, DB>, p: &ContourPlot) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let Some(((x0, y0), (x1, y1), label)) = &p.region else {
        return Ok(());
    };
    let (x0, x1) = (tx(*x0, p.x_log), tx(*x1, p.x_log));
    let (y0, y1) = (tx(*y0, p.y_log), tx(*y1, p.y_log));
    let ring = vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)];
    chart.draw_series(std::iter::once(PathElement::new(
        ring.clone(),
        WHITE.stroke_width(4),
    )))?;
    chart
        .draw_series(std::iter::once(DashedPathElement::new(
            ring,
            8,
            5,
            BLACK.stroke_width(2),
        )))?
        .label(label.clone())
        .legend(|(x, y)| {
            DashedPathElement::new(vec![(x, y), (x + 20, y)], 5, 3, BLACK.stroke_width(2))
        });
    Ok(())
}

/// The curves over the map: a white casing under each line so it reads on any colour, dots
/// at its points with their x bars, and its legend entry.
fn curves<DB: DrawingBackend>(chart: &mut MapChart<'_, DB>, p: &ContourPlot) -> Result<()>
where
    DB::ErrorType: 'static,
{
    for c in &p.curves {
        let pts: Vec<(f64, f64)> = c
            .points
            .iter()
            .map(|&(x, y)| (tx(x, p.x_log), tx(y, p.y_log)))
            .collect();
        let color = c.color;
        chart.draw_series(std::iter::once(PathElement::new(
            pts.clone(),
            WHITE.stroke_width(6),
        )))?;
        for (at, bar) in pts.iter().zip(&c.x_bars) {
            if let Some((a, b)) = bar {
                let (a, b) = (tx(*a, p.x_log), tx(*b, p.x_log));
                chart.draw_series(std::iter::once(PathElement::new(
                    vec![(a, at.1), (b, at.1)],
                    color.stroke_width(3),
                )))?;
            }
        }
        if c.dashed {
            chart
                .draw_series(std::iter::once(DashedPathElement::new(
                    pts.clone(),
                    10,
                    6,
                    color.stroke_width(3),
                )))?
                .label(c.label.clone())
                .legend(move |(x, y)| {
                    DashedPathElement::new(vec![(x, y), (x + 20, y)], 5, 3, color.stroke_width(3))
                });
        } else {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    pts.clone(),
                    color.stroke_width(3),
                )))?
                .label(c.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
                });
        }
        if !c.x_bars.is_empty() {
            chart.draw_series(pts.iter().map(|&at| Circle::new(at, 5, color.filled())))?;
        }
    }
    Ok(())
}

/// The marked points, crosses or circles, each with its legend entry.
fn markers<DB: DrawingBackend>(chart: &mut MapChart<'_, DB>, p: &ContourPlot) -> Result<()>
where
    DB::ErrorType: 'static,
{
    for m in &p.markers {
        let at = (tx(m.at.0, p.x_log), tx(m.at.1, p.y_log));
        let color = m.color;
        let s = if m.cross {
            chart.draw_series(std::iter::once(Cross::new(at, 11, color.stroke_width(4))))?
        } else {
            chart.draw_series(std::iter::once(Circle::new(at, 11, color.stroke_width(4))))?
        };
        let s = s.label(m.label.clone());
        if m.cross {
            s.legend(move |(x, y)| Cross::new((x + 10, y), 7, color.stroke_width(3)));
        } else {
            // A light marker needs a dark outline in the white legend box.
            s.legend(move |(x, y)| Circle::new((x + 10, y), 6, BLACK.stroke_width(3)));
        }
    }
    Ok(())
}

/// The colour bar beside the map: the colours from the smallest value (bottom) to the
/// largest, labels at round values, the highlighted level in red, the value's name on top.
fn colour_bar<DB: DrawingBackend>(
    bar: &DrawingArea<DB, Shift>,
    p: &ContourPlot,
    frame: &MapFrame,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let (_, bh) = bar.dim_in_pixel();
    let (top, bottom) = (70i32, bh as i32 - 110);
    let left = 20i32;
    let steps = 120;
    for s in 0..steps {
        let t0 = s as f64 / steps as f64;
        let ya_px = bottom - ((bottom - top) as f64 * (s + 1) as f64 / steps as f64) as i32;
        let yb_px = bottom - ((bottom - top) as f64 * t0) as i32;
        bar.draw(&Rectangle::new(
            [(left, ya_px), (left + 28, yb_px)],
            colormap(t0 + 0.5 / steps as f64).filled(),
        ))?;
    }
    bar.draw(&Rectangle::new([(left, top), (left + 28, bottom)], BLACK))?;
    for z in round_ticks(frame.zmin, frame.zmax, 4.0) {
        let y = bottom - ((bottom - top) as f64 * frame.norm(z)) as i32;
        bar.draw(&PathElement::new(
            vec![(left + 28, y), (left + 33, y)],
            BLACK,
        ))?;
        bar.draw(&Text::new(
            tick(z, false),
            (left + 37, y),
            text_style(15.0).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
    }
    if let Some((level, _)) = &p.highlight {
        if *level >= frame.zmin && *level <= frame.zmax {
            let y = bottom - ((bottom - top) as f64 * frame.norm(*level)) as i32;
            bar.draw(&PathElement::new(
                vec![(left - 4, y), (left + 32, y)],
                RED.stroke_width(3),
            ))?;
        }
    }
    bar.draw(&Text::new(
        p.value_label.clone(),
        (left, top - 30),
        font(16),
    ))?;
    if let Some((lo, hi)) = frame.saturated {
        for (k, line) in [
            "colours saturate;".to_string(),
            format!("values {} to {}", tick(lo, false), tick(hi, false)),
        ]
        .iter()
        .enumerate()
        {
            bar.draw(&Text::new(
                line.clone(),
                (left - 10, bottom + 14 + 18 * k as i32),
                text_style(13.0),
            ))?;
        }
    }
    Ok(())
}

/// Writes `<stem>.png` and `<stem>.svg`.
pub fn contour_plot(stem: &Path, p: &ContourPlot) -> Result<()> {
    fonts()?;
    if p.field.x.len() < 2 || p.field.y.len() < 2 {
        return Err(PlotError::Input(format!(
            "a contour plot needs at least 2 x 2 grid points (got {} x {})",
            p.field.x.len(),
            p.field.y.len()
        )));
    }
    let (w, h) = (1150u32, 860u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = crate::theme::png_area(&mut rgb, (w, h));
        draw(&root, p, MAX_TILES_PNG)?;
    }
    // The extension is appended, not substituted: a stem may hold dots (`quantile-0.9_R`).
    let with = |ext: &str| {
        let mut name = stem.as_os_str().to_owned();
        name.push(format!(".{ext}"));
        std::path::PathBuf::from(name)
    };
    let png_path = with("png");
    write_atomic_bytes(&png_path, &encode_png(&rgb, w, h, None)?)?;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        draw(&root, p, MAX_TILES_SVG)?;
    }
    write_atomic_bytes(&with("svg"), svg.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colormap_ends_and_ticks() {
        assert_eq!(colormap(0.0), RGBColor(68, 1, 84));
        assert_eq!(colormap(1.0), RGBColor(253, 231, 37));
        assert_eq!(colormap(f64::NAN), RGBColor(68, 1, 84));
        assert_eq!(tick(6.0, true), "1e6");
        assert_eq!(tick(-2.0, true), "0.01");
        assert_eq!(tick(0.5, false), "0.5");
        assert_eq!(tick(6500.0, false), "6500");
        assert_eq!(tick(1e4, false), "10000");
        // Log axes tick at 1, 2, 5 per decade: eps from 0.01 to 1 J.
        let labels: Vec<String> = axis_keys(-2.1, 0.1, true)
            .iter()
            .map(|&v| tick(v, true))
            .collect();
        assert_eq!(labels, ["0.01", "0.02", "0.05", "0.1", "0.2", "0.5", "1"]);
        // Less than a factor 5: every integer multiple.
        let labels: Vec<String> = axis_keys(6.05, 6.5, true)
            .iter()
            .map(|&v| tick(v, true))
            .collect();
        assert_eq!(labels, ["2e6", "3e6"]);
        // An axis reaching past 1e5 writes all its large labels alike.
        let labels: Vec<String> = axis_keys(4.0, 6.0, true)
            .iter()
            .map(|&v| axis_tick(v, true, 6.0))
            .collect();
        assert_eq!(labels, ["1e4", "2e4", "5e4", "1e5", "2e5", "5e5", "1e6"]);
        assert_eq!(axis_tick(3.0, true, 6.0), "1e3");
        assert_eq!(axis_tick(2.0, true, 6.0), "100");
        assert_eq!(axis_tick(4.0, true, 4.5), "10000");
    }

    #[test]
    fn the_bulk_of_a_field_leaves_its_outliers_out() {
        // Sixteen values near 1.5-1.9 and four far above: the colours cover the sixteen.
        let mut z: Vec<Vec<f64>> = (0..4)
            .map(|r| (0..5).map(|c| 1.4 + 0.1 * (r + c) as f64).collect())
            .collect();
        for row in z.iter_mut() {
            row[4] = 11.0;
        }
        let field = Field::new(
            (0..5).map(f64::from).collect(),
            (0..4).map(f64::from).collect(),
            z,
        )
        .expect("field");
        let (lo, hi) = bulk_range(&field).expect("a spread");
        assert_eq!(lo, 1.4);
        assert!(hi > 1.9 && hi < 3.0, "{hi}");
        let frame = MapFrame::of(&field, true);
        assert_eq!(frame.saturated, Some((1.4, 11.0)));
        assert_eq!(frame.norm(11.0), 1.0);
        // Without it, or on a field without outliers, the colours cover the whole range.
        assert_eq!(MapFrame::of(&field, false).saturated, None);
        let flat = Field::new(vec![0.0, 1.0], vec![0.0, 1.0], vec![vec![1.0; 2]; 2]).expect("f");
        assert_eq!(MapFrame::of(&flat, true).saturated, None);
    }

    #[test]
    fn writes_png_and_svg() {
        let field = Field::new(
            vec![0.01, 0.1, 1.0],
            vec![1e6, 2e6, 4e6],
            vec![
                vec![1.0, 1.2, 1.4],
                vec![1.1, 1.5, f64::NAN],
                vec![1.3, 1.6, 1.8],
            ],
        )
        .expect("field");
        let p = ContourPlot {
            title: "R".into(),
            subtitle: "test".into(),
            x_label: "eps".into(),
            y_label: "kappa".into(),
            x_log: true,
            y_log: true,
            field,
            value_label: "R".into(),
            levels: 5,
            highlight: Some((1.55, "target".into())),
            extra_points: vec![(0.05, 3e6)],
            samples: None,
            markers: vec![Marker {
                at: (0.1, 2e6),
                label: "best".into(),
                color: RED,
                cross: true,
            }],
            curves: Vec::new(),
            region: Some(((0.03, 1.5e6), (0.2, 4e6), "confidence region".into())),
            bulk_colours: false,
        };
        let dir = std::env::temp_dir().join(format!("hvi-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        contour_plot(&dir.join("r"), &p).expect("draws");
        let png = std::fs::read(dir.join("r.png")).expect("png");
        assert_eq!(&png[1..4], b"PNG");
        let svg = std::fs::read_to_string(dir.join("r.svg")).expect("svg");
        assert!(svg.starts_with("<svg"), "{}", &svg[..40.min(svg.len())]);
        // The iso-lines carry their values (levels at 1/6, 2/6, ... of the range 1-1.8).
        for label in ["1.133", "1.267", "1.4"] {
            assert!(
                svg.contains(&format!("\n{label}\n</text>")),
                "no label {label}"
            );
        }
    }

    #[test]
    fn a_fine_field_stays_a_small_svg() {
        // A kriging model's 33 x 33 prediction: 17 MB of tiles before the budget.
        let n = 33;
        let axis = |lo: f64, hi: f64| -> Vec<f64> {
            (0..n)
                .map(|k| lo * (hi / lo).powf(k as f64 / (n - 1) as f64))
                .collect()
        };
        let z = (0..n)
            .map(|j| (0..n).map(|i| ((i * j) as f64).sqrt()).collect())
            .collect();
        let field = Field::new(axis(1e-4, 1.0), axis(1e5, 1e8), z).expect("field");
        let p = ContourPlot {
            title: "J".into(),
            subtitle: "model".into(),
            x_label: "eps".into(),
            y_label: "kappa".into(),
            x_log: true,
            y_log: true,
            field,
            value_label: "J".into(),
            levels: 6,
            highlight: None,
            extra_points: vec![],
            samples: None,
            markers: vec![],
            region: None,
            curves: Vec::new(),
            bulk_colours: false,
        };
        let dir = std::env::temp_dir().join(format!("hvi-plot-fine-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        contour_plot(&dir.join("j"), &p).expect("draws");
        let svg = std::fs::metadata(dir.join("j.svg")).expect("svg").len();
        assert!(svg < 2_000_000, "{svg} bytes");
        assert_eq!(tiles_per_cell(6, MAX_TILES_SVG), TILES_PER_CELL);
        assert_eq!(tiles_per_cell(32 * 32, MAX_TILES_SVG), 2);
    }
}
