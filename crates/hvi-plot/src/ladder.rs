//! The resolution ladder's figure (`ladder.png`): each calibrated parameter against the
//! particle count, its confidence interval as a bar, and the objective at each level's answer
//! (with the check run at a finer resolution, if any), and beside each interval a pale band
//! where the level's runs meet every target. One panel per parameter and one for the
//! objective, side by side; log particle axis. Shows numbers, derives none.

use std::path::Path;

use crate::error::{PlotError, Result};
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use crate::contour::{axis_tick, KeyedAxis};
use crate::render::{fonts, write_png, FAMILY};

/// One level on a parameter's panel: particles, the calibrated value, its interval (None: no
/// region), and whether the answer is interior (false: it touches a side of its box).
pub type LevelMark = (f64, f64, Option<(f64, f64)>, bool);

/// One parameter's panel.
#[derive(Debug, Clone)]
pub struct LadderPanel {
    /// Its label, with the unit (`eps (J)`).
    pub label: String,
    /// Whether the parameter is drawn on a log axis.
    pub log: bool,
    /// Per level, its mark.
    pub levels: Vec<LevelMark>,
    /// Per level, (particles, (lowest, highest)): where the level's runs meet every target
    /// (a pale band beside the interval; no entry: no run there meets them).
    pub met: Vec<(f64, (f64, f64))>,
    /// A reference value drawn across (the paper's fit), with its name.
    pub reference: Option<(f64, String)>,
}

/// The whole figure.
#[derive(Debug, Clone)]
pub struct LadderPlot {
    /// The title.
    pub title: String,
    /// The line under it (the verdict).
    pub subtitle: String,
    /// The parameters.
    pub panels: Vec<LadderPanel>,
    /// The objective J at each level's answer: (particles, J).
    pub objective: Vec<(f64, f64)>,
    /// The check: the last level's answer run at more particles, (particles, J).
    pub check: Option<(f64, f64)>,
    /// A reference point's J at each level (the paper's fit), with its name.
    pub reference_objective: Option<(Vec<(f64, f64)>, String)>,
}

const BLUE: RGBColor = RGBColor(31, 96, 196);
const RED: RGBColor = RGBColor(200, 30, 30);
const GREY: RGBColor = RGBColor(120, 120, 120);
const GREEN: RGBColor = RGBColor(40, 160, 80);

type Chart<'a, 'b> = ChartContext<'a, crate::theme::Png<'b>, Cartesian2d<KeyedAxis, KeyedAxis>>;
type Area<'b> = DrawingArea<crate::theme::Png<'b>, plotters::coord::Shift>;

/// A range around `vals` (already in plot coordinates), widened by a tenth each way (a unit
/// around a single value).
fn span(vals: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = vals
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return None;
    }
    let pad = if hi > lo { 0.1 * (hi - lo) } else { 0.5 };
    // Room above the data for the legend.
    Some((lo - pad, hi + pad + 0.45 * (hi - lo + 2.0 * pad)))
}

/// `text` in lines of at most `width` characters, broken at spaces.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.len() + 1 + word.len() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// A value in plot coordinates.
fn coord(v: f64, log: bool) -> f64 {
    if log {
        v.log10()
    } else {
        v
    }
}

fn axes<'a, 'b>(
    area: &'a DrawingArea<crate::theme::Png<'b>, plotters::coord::Shift>,
    caption: &str,
    x: (f64, f64),
    y: (f64, f64),
    y_log: bool,
) -> Result<Chart<'a, 'b>> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FAMILY, 22))
        .margin(18)
        .x_label_area_size(55)
        .y_label_area_size(85)
        .build_cartesian_2d(
            KeyedAxis::new(x.0, x.1, true),
            KeyedAxis::new(y.0, y.1, y_log),
        )?;
    chart
        .configure_mesh()
        .x_desc("particles N (log scale)")
        .x_label_formatter(&|u| axis_tick(*u, true, x.1))
        .y_label_formatter(&move |u| axis_tick(*u, y_log, y.1))
        .label_style((FAMILY, 16))
        .axis_desc_style((FAMILY, 17))
        .draw()?;
    Ok(chart)
}

/// Draws the figure to `path` (PNG).
pub fn ladder_plot(path: &Path, plot: &LadderPlot) -> Result<()> {
    if plot.panels.is_empty() || plot.objective.is_empty() {
        return Err(PlotError::Input(
            "a ladder figure needs a parameter and a level".into(),
        ));
    }
    fonts()?;
    let n_panels = plot.panels.len() + 1;
    let (w, h) = (560 * n_panels as u32, 680u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = crate::theme::png_area(&mut rgb, (w, h));
        root.fill(&WHITE)?;
        let (top, body) = root.split_vertically(110);
        header(&top, plot, w)?;
        let areas = body.split_evenly((1, n_panels));
        let ns: Vec<f64> = plot
            .objective
            .iter()
            .map(|p| p.0)
            .chain(plot.check.map(|c| c.0))
            .collect();
        // The particle axis needs no room for the legend: a tenth of a decade each side.
        let lo = ns.iter().copied().fold(f64::INFINITY, f64::min).log10();
        let hi = ns.iter().copied().fold(0.0, f64::max).log10();
        let x = (lo - 0.1, hi + 0.1);
        for (panel, area) in plot.panels.iter().zip(&areas) {
            parameter_panel(area, panel, x)?;
        }
        let area = areas
            .last()
            .expect("one area per panel and the objective's");
        objective_panel(area, plot, x)?;
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

/// The title and up to three lines of subtitle.
fn header(top: &Area<'_>, plot: &LadderPlot, w: u32) -> Result<()> {
    top.draw(&Text::new(
        plot.title.clone(),
        (20, 12),
        (FAMILY, 24).into_font(),
    ))?;
    let per_line = (w as usize - 40) / 9;
    let mut lines = wrap(&plot.subtitle, per_line);
    if lines.len() > 3 {
        lines.truncate(3);
        lines[2].push_str(" ...");
    }
    for (i, line) in lines.iter().enumerate() {
        top.draw(&Text::new(
            line.clone(),
            (20, 44 + 20 * i as i32),
            (FAMILY, 16).into_font().color(&GREY),
        ))?;
    }
    Ok(())
}

/// One parameter over the levels: its answers, intervals, where the runs meet every target,
/// and the reference.
fn parameter_panel(area: &Area<'_>, panel: &LadderPanel, x: (f64, f64)) -> Result<()> {
    let ys = panel
        .levels
        .iter()
        .flat_map(|(_, v, i, _)| {
            let (a, b) = i.unwrap_or((*v, *v));
            [*v, a, b]
        })
        .chain(panel.met.iter().flat_map(|(_, (a, b))| [*a, *b]))
        .chain(panel.reference.as_ref().map(|r| r.0))
        .map(|v| coord(v, panel.log));
    let y = span(ys).unwrap_or((0.0, 1.0));
    let mut chart = axes(area, &panel.label, x, y, panel.log)?;
    if let Some((v, name)) = &panel.reference {
        let u = coord(*v, panel.log);
        chart
            .draw_series(std::iter::once(DashedPathElement::new(
                vec![(x.0, u), (x.1, u)],
                8,
                6,
                GREY.stroke_width(2),
            )))?
            .label(name.clone())
            .legend(|(px, py)| crate::theme::dashed_key(px, py, GREY));
    }
    met_bands(&mut chart, panel, x, y)?;
    for &(n, v, interval, interior) in &panel.levels {
        let xn = n.log10();
        if let Some((a, b)) = interval {
            let (a, b) = (coord(a, panel.log), coord(b, panel.log));
            let tick = 0.02 * (x.1 - x.0);
            let bar = [
                vec![(xn, a), (xn, b)],
                vec![(xn - tick, a), (xn + tick, a)],
                vec![(xn - tick, b), (xn + tick, b)],
            ];
            chart.draw_series(
                bar.into_iter()
                    .map(|p| PathElement::new(p, BLUE.stroke_width(3))),
            )?;
        }
        let style = if interior {
            BLUE.filled()
        } else {
            RED.stroke_width(3)
        };
        chart.draw_series(std::iter::once(Circle::new(
            (xn, coord(v, panel.log)),
            8,
            style,
        )))?;
    }
    // The legend's keys for the markers (drawn off the chart, so only the key shows).
    chart
        .draw_series(std::iter::once(Circle::new((f64::NAN, f64::NAN), 0, BLUE)))?
        .label("answer inside its box (bar: interval)")
        .legend(|(px, py)| Circle::new((px + 12, py), 7, BLUE.filled()));
    chart
        .draw_series(std::iter::once(Circle::new((f64::NAN, f64::NAN), 0, RED)))?
        .label("answer touches its box's side")
        .legend(|(px, py)| Circle::new((px + 12, py), 7, RED.stroke_width(3)));
    legend(&mut chart)
}

/// Each level's band where the runs meet every target, right of the level's mark and at least
/// a few pixels tall.
fn met_bands(
    chart: &mut Chart<'_, '_>,
    panel: &LadderPanel,
    x: (f64, f64),
    y: (f64, f64),
) -> Result<()> {
    let half = 0.018 * (x.1 - x.0);
    for (k, &(n, (a, b))) in panel.met.iter().enumerate() {
        let xn = n.log10() + 2.2 * half;
        let (a, b) = (coord(a, panel.log), coord(b, panel.log));
        let pad = 0.004 * (y.1 - y.0);
        let band = chart.draw_series(std::iter::once(Rectangle::new(
            [(xn - half, a - pad), (xn + half, b + pad)],
            GREEN.mix(0.45).filled(),
        )))?;
        if k == 0 {
            band.label("where the runs meet every target")
                .legend(|(px, py)| {
                    Rectangle::new(
                        [(px + 6, py - 7), (px + 18, py + 7)],
                        GREEN.mix(0.45).filled(),
                    )
                });
        }
    }
    Ok(())
}

/// The objective at each level's answer, the reference's, and the check at more particles.
fn objective_panel(area: &Area<'_>, plot: &LadderPlot, x: (f64, f64)) -> Result<()> {
    let js = plot
        .objective
        .iter()
        .chain(plot.check.iter())
        .chain(plot.reference_objective.iter().flat_map(|r| r.0.iter()))
        .map(|p| p.1.max(1e-6).log10());
    let y = span(js).unwrap_or((-1.0, 1.0));
    let mut chart = axes(area, "objective J at the answer", x, y, true)?;
    let pts: Vec<(f64, f64)> = plot
        .objective
        .iter()
        .map(|p| (p.0.log10(), p.1.max(1e-6).log10()))
        .collect();
    chart.draw_series(LineSeries::new(pts.clone(), BLUE.stroke_width(2)))?;
    chart
        .draw_series(pts.iter().map(|&p| Circle::new(p, 7, BLUE.filled())))?
        .label("J at the level's answer (its seeds)")
        .legend(|(px, py)| Circle::new((px + 12, py), 7, BLUE.filled()));
    if let Some((pts, name)) = &plot.reference_objective {
        let pts: Vec<(f64, f64)> = pts
            .iter()
            .map(|p| (p.0.log10(), p.1.max(1e-6).log10()))
            .collect();
        chart.draw_series(LineSeries::new(pts.clone(), GREY.stroke_width(1)))?;
        let (dx, dy) = (0.012 * (x.1 - x.0), 0.012 * (y.1 - y.0));
        chart
            .draw_series(pts.iter().map(|&p| {
                Rectangle::new([(p.0 - dx, p.1 - dy), (p.0 + dx, p.1 + dy)], GREY.filled())
            }))?
            .label(format!("J of {name} at each level"))
            .legend(|(px, py)| {
                Rectangle::new([(px + 6, py - 6), (px + 18, py + 6)], GREY.filled())
            });
    }
    if let Some((n, j)) = plot.check {
        let p = (n.log10(), j.max(1e-6).log10());
        chart
            .draw_series(std::iter::once(TriangleMarker::new(p, 10, RED.filled())))?
            .label("the last answer run at more particles")
            .legend(|(px, py)| TriangleMarker::new((px + 12, py), 8, RED.filled()));
    }
    legend(&mut chart)
}

/// The series labels, upper left.
fn legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>) -> Result<()> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font((FAMILY, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(GREY)
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ladder_figure_is_drawn_and_a_figure_without_levels_is_refused() {
        let path = std::env::temp_dir().join(format!("hvi-ladder-{}.png", std::process::id()));
        let plot = LadderPlot {
            title: "calibration against resolution".into(),
            subtitle: "converged in N".into(),
            panels: vec![LadderPanel {
                label: "eps (J)".into(),
                log: true,
                levels: vec![
                    (2e4, 0.03, Some((0.01, 0.1)), true),
                    (8e4, 0.02, None, false),
                ],
                met: vec![(2e4, (0.02, 0.08)), (8e4, (0.02, 0.02))],
                reference: Some((0.01, "the paper".into())),
            }],
            objective: vec![(2e4, 0.5), (8e4, 0.3)],
            check: Some((2.7e5, 0.4)),
            reference_objective: Some((vec![(2e4, 3.0), (8e4, 0.2)], "the paper's fit".into())),
        };
        ladder_plot(&path, &plot).expect("drawn");
        assert!(std::fs::metadata(&path).expect("written").len() > 1000);
        std::fs::remove_file(&path).ok();
        let empty = LadderPlot {
            objective: Vec::new(),
            ..plot
        };
        assert!(ladder_plot(&path, &empty).is_err());
    }
}
