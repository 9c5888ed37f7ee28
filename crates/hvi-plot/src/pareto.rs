//! The accuracy benchmark's figure (`pareto.png`): wall time against relative error, log-log.
//! Left, the headline error of each setting with the Pareto front joined; right, each
//! observable's error. The tolerance and the noise floor are drawn. Shows numbers, derives none
//! but the front.

use std::ops::Range;
use std::path::Path;

use crate::error::{PlotError, Result};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::render::{fonts, write_png, FAMILY};

/// Errors of 0 (the reference against itself) are drawn at this floor of the error axis.
const ERROR_FLOOR: f64 = 1e-5;

/// Colours of the observables in the right panel, in order.
const SERIES: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

/// One setting on the figure: a candidate (a circle, green within tolerance, red not) or a run
/// at the reference step (a black triangle).
#[derive(Debug, Clone)]
pub struct ParetoPoint {
    /// Name drawn beside the point.
    pub label: String,
    /// Mean wall time, s.
    pub wall_s: f64,
    /// A candidate (true) or a run at the reference step.
    pub candidate: bool,
    /// The candidate is within tolerance.
    pub within: bool,
    /// The headline error: the largest relative error of the headline observables (None
    /// when one is missing).
    pub max_error: Option<f64>,
    /// Relative error per observable, in the order of [`ParetoPlot::observables`].
    pub errors: Vec<Option<f64>>,
}

/// The whole figure.
#[derive(Debug, Clone)]
pub struct ParetoPlot<'a> {
    /// The settings with a wall time.
    pub points: &'a [ParetoPoint],
    /// The observables of the headline error, as the left caption names them (`R, va/v0, F`).
    pub headline: &'a str,
    /// The noise floor of the headline error (the largest of its observables'), relative.
    pub headline_floor: f64,
    /// Per observable of the right panel: its symbol and its noise floor (relative).
    pub observables: &'a [(&'a str, f64)],
    /// The tolerance, relative (one line in both panels).
    pub tolerance: f64,
    /// Seeds per candidate (named in the noise floor's legend).
    pub seeds: u32,
}

type Chart<'a, 'b> =
    ChartContext<'a, crate::theme::Png<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The axes of both panels, in log10 of wall time (s) and of relative error.
struct Axes {
    x: Range<f64>,
    y: Range<f64>,
}

impl Axes {
    /// The wall-time range of the points, widened; an error when there is none.
    fn of(points: &[ParetoPoint]) -> Result<Axes> {
        let (w_lo, w_hi) = points
            .iter()
            .map(|p| p.wall_s)
            .fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
        if !w_lo.is_finite() {
            return Err(PlotError::Input("no completed run to plot".into()));
        }
        Ok(Axes {
            x: (w_lo * 0.7).max(1e-3).log10()..(w_hi * 1.4).log10(),
            y: ERROR_FLOOR.log10()..1.0f64.log10(),
        })
    }
}

/// An error on the log axis (0 at the floor).
fn ly(e: f64) -> f64 {
    e.max(ERROR_FLOOR).log10()
}

/// Writes the figure as PNG (1600 x 760).
pub fn pareto_plot(path: &Path, plot: &ParetoPlot) -> Result<()> {
    fonts()?;
    let (w, h) = (1600u32, 760u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    let axes = Axes::of(plot.points)?;
    {
        let root = crate::theme::png_area(&mut rgb, (w, h));
        let (left, right) = root.split_horizontally(w / 2);
        let caption = format!("largest error in {} against wall time", plot.headline);
        let mut chart = panel(&left, &caption, &axes, plot.tolerance)?;
        draw_headline(&mut chart, plot, &axes)?;
        draw_legend(&mut chart)?;
        let mut chart = panel(&right, "error per observable", &axes, plot.tolerance)?;
        draw_per_observable(&mut chart, plot)?;
        draw_legend(&mut chart)?;
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

/// One panel's frame: caption, axes and the tolerance line.
fn panel<'a, 'b>(
    area: &'a DrawingArea<crate::theme::Png<'b>, Shift>,
    caption: &str,
    axes: &Axes,
    tolerance: f64,
) -> Result<Chart<'a, 'b>> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FAMILY, 22))
        .margin(18)
        .x_label_area_size(55)
        .y_label_area_size(75)
        .build_cartesian_2d(axes.x.clone(), axes.y.clone())?;
    chart
        .configure_mesh()
        .light_line_style(RGBColor(235, 235, 235))
        .x_desc("wall time of the run (s)")
        .y_desc("relative error vs reference")
        .label_style((FAMILY, 16))
        .axis_desc_style((FAMILY, 18))
        .x_labels(8)
        .y_labels(6)
        .x_label_formatter(&|v| sig2(10f64.powf(*v)))
        .y_label_formatter(&|v| format!("{} %", sig2(100.0 * 10f64.powf(*v))))
        .draw()?;
    chart
        .draw_series(LineSeries::new(
            vec![
                (axes.x.start, tolerance.log10()),
                (axes.x.end, tolerance.log10()),
            ],
            RED.stroke_width(2),
        ))?
        .label(format!("tolerance {:.0} %", 100.0 * tolerance))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
    Ok(chart)
}

/// The left panel: the noise floor, the Pareto front, the candidates and the runs at the
/// reference step.
fn draw_headline(chart: &mut Chart, plot: &ParetoPlot, axes: &Axes) -> Result<()> {
    let floor = plot.headline_floor;
    if floor > 0.0 {
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(axes.x.start, axes.y.start), (axes.x.end, ly(floor))],
                RGBColor(200, 200, 200).mix(0.4).filled(),
            )))?
            .label(format!(
                "noise floor (2 SE, {} seed(s)): {:.2} %",
                plot.seeds,
                100.0 * floor
            ))
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x, y - 6), (x + 20, y + 6)],
                    RGBColor(200, 200, 200).filled(),
                )
            });
    }
    let candidates: Vec<(f64, f64, &ParetoPoint)> = plot
        .points
        .iter()
        .filter(|p| p.candidate)
        .filter_map(|p| Some((p.wall_s.log10(), ly(p.max_error?), p)))
        .collect();
    chart
        .draw_series(LineSeries::new(
            pareto_front(&candidates),
            BLUE.stroke_width(1),
        ))?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(1)));
    for (x, y, p) in &candidates {
        let color = if p.within {
            RGBColor(0, 140, 0)
        } else {
            RGBColor(200, 0, 0)
        };
        chart.draw_series(std::iter::once(Circle::new((*x, *y), 6, color.filled())))?;
        chart.draw_series(std::iter::once(Text::new(
            p.label.clone(),
            (*x, *y),
            (FAMILY, 13).into_font().color(&BLACK),
        )))?;
    }
    for p in plot.points.iter().filter(|p| !p.candidate) {
        let at = (p.wall_s.log10(), ly(p.max_error.unwrap_or(0.0)));
        chart.draw_series(std::iter::once(TriangleMarker::new(at, 7, BLACK.filled())))?;
        chart.draw_series(std::iter::once(Text::new(
            p.label.clone(),
            at,
            (FAMILY, 15).into_font().color(&RGBColor(80, 80, 80)),
        )))?;
    }
    Ok(())
}

/// The Pareto front of (wall, error) points: by increasing wall time, each point with a
/// smaller error than every cheaper one.
fn pareto_front(points: &[(f64, f64, &ParetoPoint)]) -> Vec<(f64, f64)> {
    let mut sorted = points.to_vec();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut front: Vec<(f64, f64)> = Vec::new();
    let mut best = f64::INFINITY;
    for p in &sorted {
        if p.1 < best {
            best = p.1;
            front.push((p.0, p.1));
        }
    }
    front
}

/// The right panel: each candidate's error in each observable, a colour per observable.
fn draw_per_observable(chart: &mut Chart, plot: &ParetoPlot) -> Result<()> {
    for (k, &(symbol, floor)) in plot.observables.iter().enumerate() {
        let c = SERIES[k % SERIES.len()];
        let points: Vec<(f64, f64)> = plot
            .points
            .iter()
            .filter(|p| p.candidate)
            .filter_map(|p| Some((p.wall_s.log10(), ly(p.errors.get(k).copied()??))))
            .collect();
        chart
            .draw_series(points.iter().map(|p| Circle::new(*p, 5, c.filled())))?
            .label(format!("{symbol} (noise floor {:.2} %)", 100.0 * floor))
            .legend(move |(x, y)| Circle::new((x + 10, y), 5, c.filled()));
    }
    Ok(())
}

fn draw_legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>) -> Result<()> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font((FAMILY, 15))
        .draw()?;
    Ok(())
}

/// Two significant digits, without trailing zeros (axis labels).
fn sig2(v: f64) -> String {
    if v <= 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let e = v.log10().floor() as i32;
    let scale = 10f64.powi(1 - e);
    let rounded = (v * scale).round() / scale;
    let digits = (1 - e).max(0) as usize;
    let s = format!("{rounded:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_labels_have_two_significant_digits() {
        assert_eq!(sig2(39.811), "40");
        assert_eq!(sig2(0.031623), "0.032");
        assert_eq!(sig2(1000.0), "1000");
        assert_eq!(sig2(1.0), "1");
        assert_eq!(sig2(0.1), "0.1");
    }

    fn point(label: &str, wall_s: f64, max_error: Option<f64>) -> ParetoPoint {
        ParetoPoint {
            label: label.into(),
            wall_s,
            candidate: true,
            within: true,
            max_error,
            errors: vec![max_error],
        }
    }

    #[test]
    fn the_front_keeps_each_point_better_than_every_cheaper_one() {
        let points = [
            point("a", 10.0, Some(0.01)),
            point("b", 1.0, Some(0.1)),
            point("c", 5.0, Some(0.2)),
            point("d", 20.0, Some(0.001)),
        ];
        let placed: Vec<(f64, f64, &ParetoPoint)> = points
            .iter()
            .map(|p| (p.wall_s, p.max_error.unwrap_or(0.0), p))
            .collect();
        assert_eq!(
            pareto_front(&placed),
            vec![(1.0, 0.1), (10.0, 0.01), (20.0, 0.001)]
        );
    }

    fn plot(points: &[ParetoPoint]) -> ParetoPlot<'_> {
        ParetoPlot {
            points,
            headline: "R",
            headline_floor: 0.02,
            observables: &[("R", 0.02)],
            tolerance: 0.01,
            seeds: 1,
        }
    }

    #[test]
    fn no_point_is_an_error_and_points_draw() {
        let dir = tempfile::tempdir().expect("temporary directory");
        let path = dir.path().join("pareto.png");
        let e = pareto_plot(&path, &plot(&[])).expect_err("nothing to plot");
        assert!(e.to_string().contains("no completed run"), "{e}");
        let points = [
            point("dt2", 1.0, Some(0.005)),
            point("dt8", 0.3, Some(0.05)),
        ];
        pareto_plot(&path, &plot(&points)).expect("draws");
        assert!(path.exists());
    }
}
