//! The stability map of one slice (`<slice>.png`): a cell per run over two axes, green to
//! orange by the run's largest energy-ledger drift, red where the run stopped, each cell
//! labelled with its drift and its step over the stability bound.

use std::path::Path;

use crate::error::Result;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::render::{fonts, write_png, FAMILY};

/// One run of the slice.
#[derive(Debug, Clone, PartialEq)]
pub struct MapCell {
    /// Grid position (column, row).
    pub at: (usize, usize),
    /// The run stopped (the engine reported trouble).
    pub stopped: bool,
    /// Largest |relative ledger drift| over the run.
    pub max_drift: Option<f64>,
    /// Step over the stability bound.
    pub dt_over_bound: Option<f64>,
}

/// The map of one slice.
#[derive(Debug, Clone)]
pub struct StabilityMap<'a> {
    /// Title.
    pub title: &'a str,
    /// First words of the note under the map (the tier's description).
    pub subtitle: &'a str,
    /// First axis: its name and a label per column.
    pub x: (&'a str, &'a [String]),
    /// Second axis: its name and a label per row.
    pub y: (&'a str, &'a [String]),
    /// The runs.
    pub cells: &'a [MapCell],
    /// The ledger bound: the drift drawn full orange.
    pub drift_bound: f64,
}

type Chart<'a, 'b> =
    ChartContext<'a, crate::theme::Png<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Writes the map as PNG (1300 x 900).
pub fn stability_map(path: &Path, map: &StabilityMap) -> Result<()> {
    fonts()?;
    let (w, h) = (1300u32, 900u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = crate::theme::png_area(&mut rgb, (w, h));
        let (nx, ny) = (map.x.1.len(), map.y.1.len());
        let mut chart = ChartBuilder::on(&root)
            .caption(map.title, (FAMILY, 22))
            .margin(20)
            .x_label_area_size(60)
            .y_label_area_size(90)
            .build_cartesian_2d(0.0..nx as f64, 0.0..ny as f64)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(nx * 2 + 1)
            .y_labels(ny * 2 + 1)
            .x_desc(map.x.0)
            .y_desc(map.y.0)
            .label_style((FAMILY, 16))
            .axis_desc_style((FAMILY, 18))
            .x_label_formatter(&|v| cell_label(map.x.1, *v))
            .y_label_formatter(&|v| cell_label(map.y.1, *v))
            .draw()?;
        for c in map.cells {
            draw_cell(&mut chart, c, map.drift_bound)?;
        }
        root.draw(&Text::new(
            format!(
                "{}. Cell: largest ledger drift, step / stability bound; red = stopped.",
                map.subtitle
            ),
            (20, h as i32 - 22),
            (FAMILY, 14).into_font().color(&RGBColor(60, 60, 60)),
        ))?;
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

/// The axis label at coordinate `v`: a cell's label at its centre, nothing elsewhere.
fn cell_label(labels: &[String], v: f64) -> String {
    let k = (v - 0.5).round();
    if (v - 0.5 - k).abs() < 1e-6 && k >= 0.0 {
        labels.get(k as usize).cloned().unwrap_or_default()
    } else {
        String::new()
    }
}

/// One cell: its colour and two lines (the drift or `stopped`, the step over the bound).
fn draw_cell(chart: &mut Chart, c: &MapCell, drift_bound: f64) -> Result<()> {
    let (x0, y0) = (c.at.0 as f64, c.at.1 as f64);
    let fill = if c.stopped {
        RGBColor(210, 40, 40)
    } else {
        c.max_drift
            .map_or(RGBColor(200, 200, 200), |d| drift_color(d, drift_bound))
    };
    chart.draw_series(std::iter::once(Rectangle::new(
        [(x0 + 0.03, y0 + 0.03), (x0 + 0.97, y0 + 0.97)],
        fill.filled(),
    )))?;
    let line1 = if c.stopped {
        "stopped".into()
    } else {
        c.max_drift.map_or("-".into(), |d| format!("{d:.0e}"))
    };
    let line2 = c
        .dt_over_bound
        .map_or(String::new(), |f| format!("dt {f:.2}"));
    for (k, text) in [line1, line2].into_iter().enumerate() {
        chart.draw_series(std::iter::once(Text::new(
            text,
            (x0 + 0.12, y0 + 0.68 - 0.3 * k as f64),
            (FAMILY, 14).into_font().color(&BLACK),
        )))?;
    }
    Ok(())
}

/// Colour of a stable cell by its drift: green (1e-7 or less) to orange (`bound` or more).
fn drift_color(d: f64, bound: f64) -> RGBColor {
    let lo = -7.0;
    let hi = bound.log10();
    let t = ((d.max(1e-300).log10() - lo) / (hi - lo)).clamp(0.0, 1.0);
    let (a, b) = ([120.0, 200.0, 120.0], [245.0, 160.0, 40.0]);
    let c = |k: usize| (a[k] + (b[k] - a[k]) * t) as u8;
    RGBColor(c(0), c(1), c(2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drift_colours_run_green_to_orange() {
        let bound = 1e-3;
        assert_eq!(drift_color(1e-9, bound), RGBColor(120, 200, 120));
        assert_eq!(drift_color(1.0, bound), RGBColor(245, 160, 40));
        let mid = drift_color(1e-5, bound);
        assert!(mid.0 > 120 && mid.0 < 245);
    }

    #[test]
    fn labels_sit_at_cell_centres() {
        let labels = ["a".to_string(), "b".to_string()];
        assert_eq!(cell_label(&labels, 0.5), "a");
        assert_eq!(cell_label(&labels, 1.5), "b");
        assert_eq!(cell_label(&labels, 1.0), "");
        assert_eq!(cell_label(&labels, 2.5), "");
    }
}
