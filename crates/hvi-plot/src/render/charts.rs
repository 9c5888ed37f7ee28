//! A run's charts: the fragment-size histogram and the cloud track over time.

use std::path::Path;

use crate::error::Result;
use hvi_engine::cloud::{CloudMeasurement, Fragment, TrackRow};
use plotters::chart::DualCoordChartContext;
use plotters::coord::combinators::{LogCoord, WithKeyPoints};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::common::{thousands, PixelRect, SceneInfo};
use crate::save::write_png;
use crate::theme::{
    dashed_key, fonts, line_key, series_legend, text_style, Area, ThemedAxes, AXIS_TEXT_LARGE,
    FAMILY, GRID, GUIDE, IMPACTOR, MEASURE, PLATE, RUN_LEGEND,
};

/// One bin of the histogram: diameters [lo, hi), mm.
#[derive(Debug, Clone, PartialEq)]
pub struct DiameterBin {
    /// Lower edge, mm.
    pub lo_mm: f64,
    /// Upper edge, mm.
    pub hi_mm: f64,
    /// Fragments in the bin.
    pub fragments: usize,
    /// Their share of the cloud's mass.
    pub mass_fraction: f64,
}

/// Log-spaced bins of volume-equivalent diameter, `per_decade` per decade, the first centred
/// on the smallest fragment (normally one particle).
pub fn diameter_bins(fragments: &[Fragment], per_decade: usize) -> Vec<DiameterBin> {
    let total: f64 = fragments.iter().map(|f| f.mass_kg).sum();
    let d_min = fragments
        .iter()
        .map(|f| f.diameter_m)
        .fold(f64::INFINITY, f64::min);
    let d_max = fragments.iter().map(|f| f.diameter_m).fold(0.0, f64::max);
    if fragments.is_empty() || total.is_nan() || total <= 0.0 {
        return Vec::new();
    }
    let step = 1.0 / per_decade.max(1) as f64;
    let start = d_min.log10() - 0.5 * step;
    let count = (((d_max.log10() - start) / step).floor() as usize + 1).max(1);
    let mut bins: Vec<DiameterBin> = (0..count)
        .map(|k| DiameterBin {
            lo_mm: 10f64.powf(start + k as f64 * step) * 1e3,
            hi_mm: 10f64.powf(start + (k + 1) as f64 * step) * 1e3,
            fragments: 0,
            mass_fraction: 0.0,
        })
        .collect();
    for f in fragments {
        let k = (((f.diameter_m.log10() - start) / step).floor() as usize).min(count - 1);
        bins[k].fragments += 1;
        bins[k].mass_fraction += f.mass_kg / total;
    }
    bins
}

/// Axis ticks at 1, 2 and 5 times powers of ten inside [lo, hi].
fn key_points(lo: f64, hi: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut p = 10f64.powf(lo.log10().floor());
    while p <= hi {
        for m in [1.0, 2.0, 5.0] {
            let v = m * p;
            if v >= lo && v <= hi {
                out.push(v);
            }
        }
        p *= 10.0;
    }
    out
}

/// The fragment histogram's chart: log diameter against share of mass (left) and against
/// the number of fragments, log (right).
type HistogramChart<'a, 'b> = DualCoordChartContext<
    'b,
    crate::theme::Png<'a>,
    Cartesian2d<WithKeyPoints<LogCoord<f64>>, RangedCoordf64>,
    Cartesian2d<LogCoord<f64>, LogCoord<f64>>,
>;

/// Fragment-size histogram: share of the cloud's mass per diameter bin (bars) and the number
/// of fragments per bin (points, right axis).
pub fn fragment_histogram(
    path: &Path,
    fragments: &[Fragment],
    cloud: &CloudMeasurement,
    info: &SceneInfo,
) -> Result<()> {
    fonts()?;
    let (w, h) = (1400u32, 900u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    let bins = diameter_bins(fragments, 8);
    {
        let root = crate::theme::png_area(&mut rgb, (w, h));
        let title = format!(
            "Fragment sizes in the debris cloud at \u{3c4} = {:.1} \u{b5}s \u{2014} {}",
            cloud.tau_s * 1e6,
            info.caption()
        );
        if bins.is_empty() {
            root.draw_text(&title, &text_style(24.0), (40, 30))?;
            root.draw_text("the cloud is empty", &text_style(24.0), (40, 80))?;
        } else {
            draw_histogram(&root, &title, &bins, cloud)?;
        }
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

/// The histogram of a cloud with fragments: axes, bars and counts, the resolution limit,
/// the legend and a box with the cloud's fragment numbers.
fn draw_histogram(
    root: &Area<'_>,
    title: &str,
    bins: &[DiameterBin],
    cloud: &CloudMeasurement,
) -> Result<()> {
    let x_lo = bins[0].lo_mm;
    let x_hi = bins[bins.len() - 1].hi_mm.max(x_lo * 10.0);
    let y_hi = bins.iter().map(|b| b.mass_fraction).fold(0.0, f64::max) * 1.18;
    let n_hi = bins.iter().map(|b| b.fragments).max().unwrap_or(1) as f64 * 3.0;
    let mut chart = histogram_axes(root, title, (x_lo, x_hi), y_hi, n_hi)?;
    histogram_series(&mut chart, bins, cloud, y_hi)?;
    series_legend(&mut chart, SeriesLabelPosition::UpperRight, RUN_LEGEND)?;
    let rect = PixelRect::of(chart.plotting_area().get_pixel_range());
    info_box(
        root,
        (rect.x1 - 470, rect.y0 + (rect.height() * 0.32) as i32),
        &fragment_numbers(cloud),
    )
}

/// The histogram's chart and both axes: diameters `x` (mm, log), share of mass up to
/// `y_hi`, fragment counts up to `n_hi` (log).
fn histogram_axes<'a, 'b>(
    root: &'b Area<'a>,
    title: &str,
    (x_lo, x_hi): (f64, f64),
    y_hi: f64,
    n_hi: f64,
) -> Result<HistogramChart<'a, 'b>> {
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 24))
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .right_y_label_area_size(90)
        .build_cartesian_2d(
            (x_lo..x_hi)
                .log_scale()
                .with_key_points(key_points(x_lo, x_hi)),
            0.0..y_hi,
        )?
        .set_secondary_coord((x_lo..x_hi).log_scale(), (0.5..n_hi).log_scale());
    chart
        .configure_mesh()
        .light_line_style(GRID)
        .x_desc("volume-equivalent diameter d (mm)")
        .y_desc("share of the cloud's mass")
        .axis_text(AXIS_TEXT_LARGE)
        .x_label_formatter(&|v| format!("{}", (v * 1e6).round() / 1e6))
        .y_label_formatter(&|v| format!("{v:.2}"))
        .draw()?;
    chart
        .configure_secondary_axes()
        .y_desc("number of fragments")
        .axis_text(AXIS_TEXT_LARGE)
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    Ok(chart)
}

/// The bars (share of mass), the points (fragments per bin) and the one-particle diameter,
/// each with its legend entry.
fn histogram_series(
    chart: &mut HistogramChart<'_, '_>,
    bins: &[DiameterBin],
    cloud: &CloudMeasurement,
    y_hi: f64,
) -> Result<()> {
    chart
        .draw_series(bins.iter().map(|b| {
            Rectangle::new(
                [(b.lo_mm * 1.01, 0.0), (b.hi_mm / 1.01, b.mass_fraction)],
                PLATE.mix(0.75).filled(),
            )
        }))?
        .label("share of mass (left axis)")
        .legend(|(x, y)| Rectangle::new([(x, y - 7), (x + 16, y + 7)], PLATE.mix(0.75).filled()));
    let counted: Vec<(f64, f64)> = bins
        .iter()
        .filter(|b| b.fragments > 0)
        .map(|b| ((b.lo_mm * b.hi_mm).sqrt(), b.fragments as f64))
        .collect();
    chart
        .draw_secondary_series(
            counted
                .iter()
                .map(|&(x, y)| Circle::new((x, y), 6, IMPACTOR.filled())),
        )?
        .label("number of fragments in the bin (right axis)")
        .legend(|(x, y)| Circle::new((x + 8, y), 6, IMPACTOR.filled()));
    let one = cloud.particle_diameter_m * 1e3;
    chart
        .draw_series(DashedLineSeries::new(
            vec![(one, 0.0), (one, y_hi)],
            8,
            6,
            ShapeStyle::from(&GUIDE).stroke_width(2),
        ))?
        .label(format!("one particle, d = {one:.3} mm (resolution limit)"))
        .legend(|(x, y)| dashed_key(x, y, GUIDE));
    Ok(())
}

/// The histogram's box: fragmentation and counts, the largest fragment, the mean diameter.
fn fragment_numbers(cloud: &CloudMeasurement) -> [String; 3] {
    [
        format!(
            "F = {:.3}, N_part = {}, N_frag = {}",
            cloud.fragmentation.unwrap_or(f64::NAN),
            thousands(cloud.n_part),
            thousands(cloud.n_frag)
        ),
        format!(
            "largest: {:.2} mm, {:.2} % of the impactor's mass",
            cloud.largest_fragment_diameter_m.unwrap_or(f64::NAN) * 1e3,
            100.0 * cloud.largest_fragment_mass_fraction.unwrap_or(f64::NAN)
        ),
        format!(
            "mass-weighted mean d = {:.3} mm",
            cloud.mean_fragment_diameter_m.unwrap_or(f64::NAN) * 1e3
        ),
    ]
}

/// The cloud track's chart: lengths (mm, left) and the front velocity over v0 (right)
/// against tau (us).
type TrackChart<'a, 'b> = DualCoordChartContext<
    'b,
    crate::theme::Png<'a>,
    Cartesian2d<RangedCoordf64, RangedCoordf64>,
    Cartesian2d<RangedCoordf64, RangedCoordf64>,
>;

/// Top of the track chart's right axis, front velocity over v0.
const TRACK_SPEED_MAX: f64 = 1.6;

/// La and Lr (left axis, mm) and the front velocity over v0 (right axis) against tau, with the
/// two front times of va marked.
pub fn track_plot(
    path: &Path,
    track: &[TrackRow],
    front_times_s: [Option<f64>; 2],
    va_ratio: Option<f64>,
    info: &SceneInfo,
) -> Result<()> {
    fonts()?;
    let (w, h) = (1400u32, 850u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = crate::theme::png_area(&mut rgb, (w, h));
        let us = 1e6;
        let t_hi = track.iter().map(|r| r.tau_s * us).fold(1e-3, f64::max);
        let t_lo = track.iter().map(|r| r.tau_s * us).fold(0.0, f64::min);
        let l_hi = track
            .iter()
            .flat_map(|r| [r.length_axial_m, r.length_radial_m])
            .flatten()
            .fold(1e-6, f64::max)
            * 1e3
            * 1.1;
        let mut chart = track_axes(&root, info, (t_lo, t_hi), l_hi)?;
        track_lengths(&mut chart, track)?;
        track_front(
            &mut chart,
            track,
            info.v0_m_s,
            (t_lo, t_hi),
            front_times_s,
            va_ratio,
        )?;
        series_legend(&mut chart, SeriesLabelPosition::UpperLeft, RUN_LEGEND)?;
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

/// The track chart and both axes: tau over `t` (us), lengths up to `l_hi` (mm).
fn track_axes<'a, 'b>(
    root: &'b Area<'a>,
    info: &SceneInfo,
    (t_lo, t_hi): (f64, f64),
    l_hi: f64,
) -> Result<TrackChart<'a, 'b>> {
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!("Debris-cloud track \u{2014} {}", info.caption()),
            (FAMILY, 24),
        )
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .right_y_label_area_size(90)
        .build_cartesian_2d(t_lo..t_hi, 0.0..l_hi)?
        .set_secondary_coord(t_lo..t_hi, 0.0..TRACK_SPEED_MAX);
    chart
        .configure_mesh()
        .light_line_style(GRID)
        .x_desc("\u{3c4} (\u{b5}s)")
        .y_desc("length (mm)")
        .axis_text(AXIS_TEXT_LARGE)
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    chart
        .configure_secondary_axes()
        .y_desc("front velocity / v0")
        .axis_text(AXIS_TEXT_LARGE)
        .y_label_formatter(&|v| format!("{v:.1}"))
        .draw()?;
    Ok(chart)
}

/// La (green) and Lr (blue) over time, mm.
fn track_lengths(chart: &mut TrackChart<'_, '_>, track: &[TrackRow]) -> Result<()> {
    let us = 1e6;
    let series = |f: fn(&TrackRow) -> Option<f64>| -> Vec<(f64, f64)> {
        track
            .iter()
            .filter_map(|r| f(r).map(|v| (r.tau_s * us, v * 1e3)))
            .collect()
    };
    chart
        .draw_series(LineSeries::new(
            series(|r| r.length_axial_m),
            MEASURE.stroke_width(3),
        ))?
        .label("La")
        .legend(|(x, y)| line_key(x, y, 20, MEASURE.stroke_width(3)));
    chart
        .draw_series(LineSeries::new(
            series(|r| r.length_radial_m),
            PLATE.stroke_width(3),
        ))?
        .label("Lr")
        .legend(|(x, y)| line_key(x, y, 20, PLATE.stroke_width(3)));
    Ok(())
}

/// The front velocity over `v0_m_s` between samples (right axis), the two front times of va
/// (dashed, vertical) and va / v0 itself (dashed, across `t`).
fn track_front(
    chart: &mut TrackChart<'_, '_>,
    track: &[TrackRow],
    v0_m_s: f64,
    (t_lo, t_hi): (f64, f64),
    front_times_s: [Option<f64>; 2],
    va_ratio: Option<f64>,
) -> Result<()> {
    let us = 1e6;
    let speed: Vec<(f64, f64)> = track
        .iter()
        .filter_map(|r| r.front_velocity_m_s.map(|v| (r.tau_s * us, v / v0_m_s)))
        .collect();
    chart
        .draw_secondary_series(LineSeries::new(speed, IMPACTOR.stroke_width(1)))?
        .label("front velocity / v0 between samples (right axis)")
        .legend(|(x, y)| line_key(x, y, 20, IMPACTOR.stroke_width(2)));
    for t in front_times_s.iter().flatten() {
        chart.draw_secondary_series(DashedLineSeries::new(
            vec![(t * us, 0.0), (t * us, TRACK_SPEED_MAX)],
            8,
            6,
            ShapeStyle::from(&GUIDE).stroke_width(2),
        ))?;
    }
    if let Some(r) = va_ratio {
        chart
            .draw_secondary_series(DashedLineSeries::new(
                vec![(t_lo, r), (t_hi, r)],
                8,
                6,
                ShapeStyle::from(&BLACK).stroke_width(1),
            ))?
            .label(format!("va / v0 = {r:.3} (front at the two dashed times)"))
            .legend(|(x, y)| dashed_key(x, y, BLACK));
    }
    Ok(())
}
/// A white box with lines of text, top-left corner at `at` (pixels).
fn info_box(root: &Area<'_>, at: (i32, i32), lines: &[String]) -> Result<()> {
    let line_h = 28;
    let height = line_h * lines.len() as i32 + 14;
    root.draw(&Rectangle::new(
        [at, (at.0 + 456, at.1 + height)],
        WHITE.mix(0.85).filled(),
    ))?;
    root.draw(&Rectangle::new(
        [at, (at.0 + 456, at.1 + height)],
        ShapeStyle::from(&GUIDE).stroke_width(1),
    ))?;
    for (k, l) in lines.iter().enumerate() {
        root.draw_text(
            l,
            &text_style(19.0),
            (at.0 + 10, at.1 + 8 + line_h * k as i32),
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fragment(label: u32, particles: usize, diameter_m: f64) -> Fragment {
        Fragment {
            label,
            particles,
            impactor_particles: 0,
            mass_kg: particles as f64,
            diameter_m,
            centroid_m: [0.0; 3],
            velocity_m_s: [0.0; 3],
        }
    }

    #[test]
    fn bins_hold_every_fragment_and_all_the_mass() {
        let d1 = 0.5e-3;
        let frags: Vec<Fragment> = (1..=200usize)
            .map(|k| fragment(k as u32, k, d1 * (k as f64).cbrt()))
            .collect();
        let bins = diameter_bins(&frags, 8);
        assert_eq!(bins.iter().map(|b| b.fragments).sum::<usize>(), 200);
        let m: f64 = bins.iter().map(|b| b.mass_fraction).sum();
        assert!((m - 1.0).abs() < 1e-12);
        // The first bin is centred on the smallest diameter, the last holds the largest.
        assert!(bins[0].lo_mm < d1 * 1e3 && d1 * 1e3 < bins[0].hi_mm);
        let last = bins.last().expect("bins");
        let d_max = d1 * 200f64.cbrt() * 1e3;
        assert!(last.lo_mm <= d_max && d_max < last.hi_mm);
    }
}
