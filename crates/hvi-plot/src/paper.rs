//! The reproduction's line figures (PNG): Fig. 3 (the pair laws), Fig. 4 (energy curves with
//! and without sizing), Fig. 5 (F against particle count) and Fig. 13 (va/v0 against t/D).
//! They draw numbers computed elsewhere: the laws come from `hvi_engine::potential`, the
//! curves and observables from the runs. The contour maps and snapshot matrices (Figs. 7, 9,
//! 10, 16, 17) and the cloud pictures (Figs. 11, 12) are drawn by [`crate::contour`],
//! [`crate::snapshots`] and [`crate::render`].

use std::path::Path;

use crate::error::Result;
use hvi_engine::potential::Interaction;
use plotters::coord::combinators::{LogCoord, WithKeyPoints};
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::save::write_png;
use crate::theme::{
    self, dashed_key, font, fonts, line_key, paper_legend, series_legend, Area, Chart2d,
    ThemedAxes, AXIS_TEXT, BLUE_LINE, FAMILY, GREY, GRID, RED_LINE,
};
use hvi_analysis::decide::EnergySample;

/// The colours of the curves of Fig. 4, one per particle count.
const SERIES: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

/// Draws into an RGB buffer of `w` x `h` and writes it as PNG.
fn png(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(&DrawingArea<crate::theme::Png, plotters::coord::Shift>) -> Result<()>,
) -> Result<()> {
    fonts()?;
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = crate::theme::png_area(&mut rgb, (w, h));
        root.fill(&WHITE)?;
        draw(&root)?;
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

fn dashed(
    points: Vec<(f64, f64)>,
    color: RGBColor,
    width: u32,
) -> DashedPathElement<std::vec::IntoIter<(f64, f64)>, i32> {
    DashedPathElement::new(points, 9, 6, color.stroke_width(width))
}

/// The pair laws of one interaction, against r / sigma.
struct Laws {
    /// r / sigma samples below r_eq, with (contact energy J, contact force N).
    contact: Vec<(f64, f64, f64)>,
    /// r / sigma samples above r_eq, with (spring energy J, spring force N).
    spring: Vec<(f64, f64, f64)>,
}

fn laws(ia: &Interaction, lo: f64, hi: f64, n: usize) -> Laws {
    let s = ia.sigma_m;
    let r_eq = ia.r_eq_m / s;
    let mut contact = Vec::new();
    let mut spring = Vec::new();
    for k in 0..=n {
        let x = lo + (hi - lo) * k as f64 / n as f64;
        let r = x * s;
        if x < r_eq {
            // Force along the pair axis, positive = repulsive: (F/r) * r.
            contact.push((
                x,
                ia.contact_energy(r * r),
                ia.contact_force_over_r(r * r) * r,
            ));
        } else {
            spring.push((x, ia.spring_energy(r), ia.spring_force_over_r(r) * r));
        }
    }
    // The laws meet at r_eq exactly.
    let r = ia.r_eq_m;
    contact.push((r_eq, ia.contact_energy(r * r * (1.0 - 1e-15)), 0.0));
    spring.insert(
        0,
        (r_eq, ia.spring_energy(r), ia.spring_force_over_r(r) * r),
    );
    Laws { contact, spring }
}

/// What a panel of Fig. 3 shows of each law sample (r / sigma, energy, force).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PairQuantity {
    /// Pair energy, J (top panel).
    Energy,
    /// Pair force, N, positive when repulsive (bottom panel).
    Force,
}

impl PairQuantity {
    /// The quantity of one law sample.
    fn of(self, l: &(f64, f64, f64)) -> f64 {
        match self {
            PairQuantity::Energy => l.1,
            PairQuantity::Force => l.2,
        }
    }
}

/// Fig. 3: energy (top) and force (bottom) of a particle pair against r / sigma: the contact
/// repulsion in both prefactor forms (printed solid, WCA dashed) left of r_eq, the bond's
/// spring right of it up to rcut (solid; dotted beyond, where the bond has broken), r_eq and
/// rcut marked. `printed` and `wca` differ only in the contact form.
pub fn potentials(
    path: &Path,
    printed: &Interaction,
    wca: &Interaction,
    title: &str,
) -> Result<()> {
    let s = printed.sigma_m;
    let r_eq = printed.r_eq_m / s;
    let rcut = printed.rcut_m / s;
    let (lo, hi) = (0.96, (rcut + 0.25).max(r_eq + 0.3));
    let p = laws(printed, lo, hi, 600);
    let w = laws(wca, lo, hi, 600);
    png(path, (1300, 1150), |root| {
        let (top, rest) = root.split_vertically(70);
        top.draw(&Text::new(title.to_string(), (20, 20), font(22)))?;
        let panels = rest.split_evenly((2, 1));
        for (panel, q) in panels
            .iter()
            .zip([PairQuantity::Energy, PairQuantity::Force])
        {
            law_panel(panel, q, (&p, &w), (lo, hi), (r_eq, rcut))?;
        }
        Ok(())
    })
}

/// One panel of Fig. 3 over r / sigma in `x`: the printed (`p`) and WCA (`w`) laws' quantity
/// `q`, the zero line, r_eq and rcut marked, the legend.
fn law_panel(
    panel: &Area<'_>,
    q: PairQuantity,
    (p, w): (&Laws, &Laws),
    (lo, hi): (f64, f64),
    (r_eq, rcut): (f64, f64),
) -> Result<()> {
    let all = p
        .contact
        .iter()
        .chain(&p.spring)
        .chain(&w.contact)
        .map(|l| q.of(l))
        .collect::<Vec<_>>();
    let y_hi = all.iter().copied().fold(0.0, f64::max) * 1.08;
    let y_lo = all.iter().copied().fold(0.0, f64::min) * 1.08;
    let y_lo = if y_lo < 0.0 { y_lo } else { -0.04 * y_hi };
    let mut chart = ChartBuilder::on(panel)
        .margin(18)
        .x_label_area_size(55)
        .y_label_area_size(95)
        .build_cartesian_2d(lo..hi, y_lo..y_hi)?;
    let energy = q == PairQuantity::Energy;
    chart
        .configure_mesh()
        .light_line_style(GRID)
        .x_desc("r / \u{3c3}")
        .y_desc(if energy {
            "pair energy (J)"
        } else {
            "pair force (N), > 0 repulsive"
        })
        .axis_text(AXIS_TEXT)
        .x_label_formatter(&|v| format!("{v:.2}"))
        .y_label_formatter(&|v| {
            if energy {
                format!("{v:.3}")
            } else {
                format!("{v:.0}")
            }
        })
        .draw()?;
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(lo, 0.0), (hi, 0.0)],
        GREY.stroke_width(1),
    )))?;
    law_curves(&mut chart, q, (p, w), rcut)?;
    law_marks(&mut chart, (r_eq, rcut), (y_lo, y_hi))?;
    let position = if energy {
        SeriesLabelPosition::UpperMiddle
    } else {
        SeriesLabelPosition::UpperRight
    };
    series_legend(&mut chart, position, paper_legend(16))
}

/// The laws' curves of quantity `q`: contact repulsion printed (solid) and WCA (dashed), the
/// bond spring up to `rcut` (solid) and past it (dotted: broken).
fn law_curves(
    chart: &mut Chart2d<'_, '_>,
    q: PairQuantity,
    (p, w): (&Laws, &Laws),
    rcut: f64,
) -> Result<()> {
    let line = |v: &[(f64, f64, f64)]| v.iter().map(|l| (l.0, q.of(l))).collect::<Vec<_>>();
    chart
        .draw_series(LineSeries::new(line(&p.contact), BLUE_LINE.stroke_width(3)))?
        .label("contact repulsion, eq. (3) as printed (prefactor \u{3b5})")
        .legend(|(x, y)| line_key(x, y, 24, BLUE_LINE.stroke_width(3)));
    chart
        .draw_series(std::iter::once(dashed(line(&w.contact), BLUE_LINE, 2)))?
        .label("contact repulsion, WCA form (prefactor 4\u{3b5})")
        .legend(|(x, y)| dashed_key(x, y, BLUE_LINE));
    let bonded: Vec<(f64, f64)> = p
        .spring
        .iter()
        .filter(|l| l.0 <= rcut)
        .map(|l| (l.0, q.of(l)))
        .collect();
    let broken: Vec<(f64, f64)> = p
        .spring
        .iter()
        .filter(|l| l.0 >= rcut)
        .map(|l| (l.0, q.of(l)))
        .collect();
    chart
        .draw_series(LineSeries::new(bonded, RED_LINE.stroke_width(3)))?
        .label("bond spring, eq. (4), intact up to rcut")
        .legend(|(x, y)| line_key(x, y, 24, RED_LINE.stroke_width(3)));
    chart
        .draw_series(PointSeries::of_element(
            broken.into_iter().step_by(6),
            2,
            RED_LINE,
            &|c, s, st| EmptyElement::at(c) + Circle::new((0, 0), s, st.filled()),
        ))?
        .label("past rcut: the bond is broken (excluded)")
        .legend(|(x, y)| Circle::new((x + 12, y), 2, RED_LINE.filled()));
    Ok(())
}

/// r_eq and rcut as dashed verticals over `y`, named at 60 % height: r_eq's name to its
/// right, rcut's to its left (the legend sits above them, the curves below).
fn law_marks(
    chart: &mut Chart2d<'_, '_>,
    (r_eq, rcut): (f64, f64),
    (y_lo, y_hi): (f64, f64),
) -> Result<()> {
    let y_text = y_lo + 0.6 * (y_hi - y_lo);
    for (x, name, color, right) in [
        (r_eq, "r_eq = 2^(1/6) \u{3c3}", GREY, true),
        (rcut, "rcut", BLACK, false),
    ] {
        chart.draw_series(std::iter::once(dashed(
            vec![(x, y_lo), (x, y_hi)],
            color,
            2,
        )))?;
        let style = font(17).color(&color).pos(Pos::new(
            if right { HPos::Left } else { HPos::Right },
            VPos::Center,
        ));
        let dx = if right { 0.008 } else { -0.008 };
        chart.draw_series(std::iter::once(Text::new(
            format!("{name} = {x:.3} \u{3c3}"),
            (x + dx, y_text),
            style,
        )))?;
    }
    Ok(())
}

/// One energy curve of Fig. 4.
pub struct SizingCurve {
    /// Particles of the run.
    pub particles: usize,
    /// With geometric sizing.
    pub sizing: bool,
    /// The curve.
    pub samples: Vec<EnergySample>,
}

/// Fig. 4: kinetic (solid) and potential (dashed) energy against time, one colour per particle
/// count; top panel without sizing, bottom with it (the paper's layout). `deviations` are the
/// (unsized, sized) deciding numbers, printed in the panels.
pub fn sizing(
    path: &Path,
    curves: &[SizingCurve],
    deviations: (f64, f64),
    title: &str,
) -> Result<()> {
    let t_hi = curves
        .iter()
        .flat_map(|c| c.samples.last().map(|s| s.tau_s * 1e6))
        .fold(1e-9, f64::max);
    let e_hi = curves
        .iter()
        .flat_map(|c| c.samples.iter().map(|s| s.kinetic_j.max(s.potential_j)))
        .fold(1e-30, f64::max)
        * 1.45; // room for the legend above the curves
    let mut counts: Vec<usize> = curves.iter().map(|c| c.particles).collect();
    counts.sort_unstable();
    counts.dedup();
    png(path, (1300, 1150), |root| {
        let (top, rest) = root.split_vertically(60);
        top.draw(&Text::new(title.to_string(), (20, 18), font(22)))?;
        let panels = rest.split_evenly((2, 1));
        for (k, panel) in panels.iter().enumerate() {
            let sized = k == 1;
            let dev = if sized { deviations.1 } else { deviations.0 };
            let mut chart = sizing_axes(panel, sized, dev, (t_hi, e_hi))?;
            energy_curves(&mut chart, curves, &counts, sized)?;
            series_legend(
                &mut chart,
                SeriesLabelPosition::UpperRight,
                paper_legend(15),
            )?;
        }
        Ok(())
    })
}

/// One panel's chart of Fig. 4 up to `t_hi` (us) and `e_hi` (J), its caption naming the
/// panel (`sized` or not) and its deviation `dev`.
fn sizing_axes<'a, 'b>(
    panel: &'b Area<'a>,
    sized: bool,
    dev: f64,
    (t_hi, e_hi): (f64, f64),
) -> Result<Chart2d<'a, 'b>> {
    let mut chart = ChartBuilder::on(panel)
        .caption(
            format!(
                "{}: largest deviation from the finest run {:.1} % of the initial kinetic energy",
                if sized {
                    "with geometric sizing (eq. 12)"
                } else {
                    "unscaled (\u{3b5}, \u{3ba} as at \u{3c3}_ref at every count)"
                },
                100.0 * dev
            ),
            (FAMILY, 19),
        )
        .margin(16)
        .x_label_area_size(55)
        .y_label_area_size(90)
        .build_cartesian_2d(0.0..t_hi, 0.0..e_hi)?;
    chart
        .configure_mesh()
        .light_line_style(GRID)
        .x_desc("\u{3c4} (\u{b5}s)")
        .y_desc("energy (J)")
        .axis_text(AXIS_TEXT)
        .x_label_formatter(&|v| format!("{v:.1}"))
        .y_label_formatter(&|v| format!("{v:.2}"))
        .draw()?;
    Ok(chart)
}

/// The kinetic and potential curves of the runs with (`sized`) or without sizing, coloured by
/// their particle count's place in `counts`.
fn energy_curves(
    chart: &mut Chart2d<'_, '_>,
    curves: &[SizingCurve],
    counts: &[usize],
    sized: bool,
) -> Result<()> {
    for c in curves.iter().filter(|c| c.sizing == sized) {
        let i = counts.iter().position(|&n| n == c.particles).unwrap_or(0);
        let color = SERIES[i % SERIES.len()];
        let kin: Vec<(f64, f64)> = c
            .samples
            .iter()
            .map(|s| (s.tau_s * 1e6, s.kinetic_j))
            .collect();
        let pot: Vec<(f64, f64)> = c
            .samples
            .iter()
            .map(|s| (s.tau_s * 1e6, s.potential_j))
            .collect();
        chart
            .draw_series(LineSeries::new(kin, color.stroke_width(3)))?
            .label(format!("N = {}: kinetic", c.particles))
            .legend(move |(x, y)| line_key(x, y, 24, color.stroke_width(3)));
        chart
            .draw_series(std::iter::once(dashed(pot, color, 3)))?
            .label(format!("N = {}: potential (contact + bonds)", c.particles))
            .legend(move |(x, y)| dashed_key(x, y, color));
    }
    Ok(())
}

/// A log axis's label: `1e5`, `2e5`, `5e5` at 1, 2 and 5 times a power of ten, nothing
/// elsewhere.
fn log_label_125(v: f64) -> String {
    if !(v > 0.0 && v.is_finite()) {
        return String::new();
    }
    let e = v.log10().floor();
    let m = v / 10f64.powf(e);
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .find(|&&k| (m - k).abs() < 1e-6 * k)
        .map_or(String::new(), |&k| {
            if k == 10.0 {
                format!("1e{}", e as i32 + 1)
            } else {
                format!("{}e{}", k as i32, e as i32)
            }
        })
}

/// Fig. 5's chart: particle count on a log axis ticked at 1, 2 and 5 per decade, F linear.
type CountChart<'a, 'b> = ChartContext<
    'b,
    crate::theme::Png<'a>,
    Cartesian2d<WithKeyPoints<LogCoord<f64>>, RangedCoordf64>,
>;

/// Fig. 5: F against the particle count (log axis), the tier's convergence count (where F
/// changes by less than the tolerance from then on) and the paper's.
pub fn convergence(
    path: &Path,
    points: &[(f64, f64)],
    ours: Option<f64>,
    paper: f64,
    tolerance: f64,
    title: &str,
    subtitle: &str,
) -> Result<()> {
    let xs: Vec<f64> = points.iter().map(|p| p.0).chain([paper]).collect();
    let x_lo = xs.iter().copied().fold(f64::INFINITY, f64::min) / 1.6;
    let x_hi = xs.iter().copied().fold(0.0, f64::max) * 1.6;
    let y_hi = points
        .iter()
        .map(|p| p.1)
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        .max(0.1)
        * 1.35;
    png(path, (1300, 850), |root| {
        let mut chart = convergence_axes(root, title, (x_lo, x_hi), y_hi)?;
        let pts: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.1.is_finite()).collect();
        chart.draw_series(LineSeries::new(pts.clone(), BLUE_LINE.stroke_width(2)))?;
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 6, BLUE_LINE.filled())))?
            .label("our runs (the paper's best fit, calibration scene)")
            .legend(|(x, y)| Circle::new((x + 12, y), 6, BLUE_LINE.filled()));
        convergence_counts(&mut chart, paper, ours, tolerance, y_hi)?;
        series_legend(&mut chart, SeriesLabelPosition::UpperLeft, paper_legend(16))?;
        theme::subtitle(root, subtitle, 30)?;
        Ok(())
    })
}

/// Fig. 5's chart and axes: counts over `x` (log), F up to `y_hi`.
fn convergence_axes<'a, 'b>(
    root: &'b Area<'a>,
    title: &str,
    (x_lo, x_hi): (f64, f64),
    y_hi: f64,
) -> Result<CountChart<'a, 'b>> {
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FAMILY, 22))
        .margin(20)
        .margin_bottom(45)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .build_cartesian_2d(
            (x_lo..x_hi)
                .log_scale()
                .with_key_points(crate::contour::log_ticks(x_lo, x_hi)),
            0.0..y_hi,
        )?;
    chart
        .configure_mesh()
        .light_line_style(GRID)
        .x_desc("particles N (log scale)")
        .y_desc("fragmentation F = N_frag / N_part")
        .axis_text(AXIS_TEXT)
        // Labels at 1, 2 and 5 per decade: the default key points left the lowest counts
        // unlabelled and crowded the decade's end.
        .x_label_formatter(&|v| log_label_125(*v))
        .y_label_formatter(&|v| format!("{v:.2}"))
        .draw()?;
    Ok(chart)
}

/// The paper's convergence count (red, dashed) and ours when there is one (black, dashed),
/// up to `y_hi`, with their legend entries.
fn convergence_counts(
    chart: &mut CountChart<'_, '_>,
    paper: f64,
    ours: Option<f64>,
    tolerance: f64,
    y_hi: f64,
) -> Result<()> {
    chart
        .draw_series(std::iter::once(dashed(
            vec![(paper, 0.0), (paper, y_hi)],
            RED_LINE,
            3,
        )))?
        .label(format!(
            "the paper: converges from about {} particles",
            hvi_analysis::number::short(paper)
        ))
        .legend(|(x, y)| dashed_key(x, y, RED_LINE));
    if let Some(n) = ours {
        chart
            .draw_series(std::iter::once(dashed(vec![(n, 0.0), (n, y_hi)], BLACK, 2)))?
            .label(format!(
                "ours: F changes by < {} % per step from N = {n} on",
                100.0 * tolerance
            ))
            .legend(|(x, y)| dashed_key(x, y, BLACK));
    }
    Ok(())
}

/// Fig. 13: va/v0 against t/D, with a note on the experimental points.
pub fn front_velocity(path: &Path, points: &[(f64, f64)], title: &str, note: &str) -> Result<()> {
    let finite: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.1.is_finite()).collect();
    let x_hi = points.iter().map(|p| p.0).fold(0.0, f64::max) * 1.1 + 0.02;
    let x_lo = (points.iter().map(|p| p.0).fold(f64::INFINITY, f64::min) - 0.05).max(0.0);
    let y_hi = finite.iter().map(|p| p.1).fold(1.0, f64::max) * 1.15;
    let y_lo = finite.iter().map(|p| p.1).fold(1.0, f64::min) * 0.8;
    png(path, (1300, 850), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FAMILY, 22))
            .margin(20)
            .margin_bottom(45)
            .x_label_area_size(60)
            .y_label_area_size(90)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
        chart
            .configure_mesh()
            .light_line_style(GRID)
            .x_desc("t / D")
            .y_desc("axial front velocity va / v0")
            .axis_text(AXIS_TEXT)
            .x_label_formatter(&|v| format!("{v:.2}"))
            .y_label_formatter(&|v| format!("{v:.2}"))
            .draw()?;
        chart.draw_series(LineSeries::new(finite.clone(), BLUE_LINE.stroke_width(2)))?;
        chart
            .draw_series(
                finite
                    .iter()
                    .map(|&p| Circle::new(p, 6, BLUE_LINE.filled())),
            )?
            .label("our runs")
            .legend(|(x, y)| Circle::new((x + 12, y), 6, BLUE_LINE.filled()));
        series_legend(
            &mut chart,
            SeriesLabelPosition::UpperRight,
            paper_legend(16),
        )?;
        theme::subtitle(root, note, 30)?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axis_labels_at_1_2_5() {
        assert_eq!(log_label_125(1e5), "1e5");
        assert_eq!(log_label_125(2e4), "2e4");
        assert_eq!(log_label_125(5.000000001e5), "5e5");
        assert_eq!(log_label_125(9.99999999e5), "1e6");
        assert_eq!(log_label_125(3e4), "");
        assert_eq!(log_label_125(0.0), "");
        assert_eq!(
            crate::contour::log_ticks(150.0, 2500.0),
            vec![200.0, 500.0, 1000.0, 2000.0]
        );
        assert!(crate::contour::log_ticks(0.0, 1.0).is_empty());
    }
}
