//! The deciding numbers of the reproduction: pure functions of the runs' numbers, so each can
//! be tested on synthetic input. The report (`super::report`) turns them into verdicts; the
//! thresholds those verdicts use are the constants below, decisions of this project (the
//! paper states none of them).
//!
//! Missing values (a failed run) are NaN and are skipped where a function says so.

/// F (or any observable) is "monotone" when it never falls by more than this below an
/// earlier value of the same series: drops this small are below the resolution of the
/// quick tiers' fragment counts (a few hundred fragments).
pub const MONOTONE_TOLERANCE: f64 = 0.01;

/// Fig. 5: F has converged from the particle count after which every further step changes
/// it by less than this fraction.
pub const CONVERGENCE_TOLERANCE: f64 = 0.02;

/// Fig. 5: our convergence count "matches" the paper's when within this factor of it.
pub const CONVERGENCE_COUNT_FACTOR: f64 = 2.0;

/// Fig. 9: an R of ours "matches" the paper's plateau or peak when within this of it (the
/// paper's plateau and peak differ by 0.07).
pub const LENGTH_RATIO_TOLERANCE: f64 = 0.05;

/// Fig. 9: R's grid points apart from the peak form a plateau when their relative spread,
/// (max - min) / mean, is at most this. Decision (the paper gives no number): at R = 1.47 it
/// lets the points span about 0.15, twice the paper's rise from its plateau to its peak (0.07),
/// so scatter between neighbouring runs passes, while a map that changes by tens of per cent
/// across the grid is no plateau.
pub const PLATEAU_RELATIVE_SPREAD: f64 = 0.1;

/// One sample of an energy curve (Fig. 4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnergySample {
    /// Time since first contact, s.
    pub tau_s: f64,
    /// Kinetic energy, J.
    pub kinetic_j: f64,
    /// Potential energy (contact + bonds), J.
    pub potential_j: f64,
}

/// The finite values of a series with their positions.
fn finite(values: &[f64]) -> Vec<(usize, f64)> {
    values
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .collect()
}

/// The largest fall of a series below any earlier value of it (0 for a non-decreasing series);
/// None with fewer than two finite values. NaNs are skipped.
pub fn largest_drop(values: &[f64]) -> Option<f64> {
    let v = finite(values);
    if v.len() < 2 {
        return None;
    }
    let mut peak = f64::NEG_INFINITY;
    let mut drop: f64 = 0.0;
    for (_, x) in v {
        peak = peak.max(x);
        drop = drop.max(peak - x);
    }
    Some(drop)
}

/// Whether a series never falls by more than `tolerance` below an earlier value (None with
/// fewer than two finite values).
pub fn non_decreasing(values: &[f64], tolerance: f64) -> Option<bool> {
    largest_drop(values).map(|d| d <= tolerance)
}

/// The largest rise of a series above any earlier value of it (0 for a non-increasing series);
/// None with fewer than two finite values. NaNs are skipped.
pub fn largest_rise(values: &[f64]) -> Option<f64> {
    let neg: Vec<f64> = values.iter().map(|v| -v).collect();
    largest_drop(&neg)
}

/// Whether a series never rises by more than `tolerance` above an earlier value.
pub fn non_increasing(values: &[f64], tolerance: f64) -> Option<bool> {
    largest_rise(values).map(|r| r <= tolerance)
}

/// The last finite value minus the first (None with fewer than two finite values).
pub fn net_change(values: &[f64]) -> Option<f64> {
    let v = finite(values);
    (v.len() >= 2).then(|| v[v.len() - 1].1 - v[0].1)
}

/// Whether a series falls: it never rises by more than `tolerance` above an earlier value and
/// ends more than `tolerance` below where it starts (a level series does not fall). None with
/// fewer than two finite values. NaNs are skipped.
pub fn falls(values: &[f64], tolerance: f64) -> Option<bool> {
    let steady = non_increasing(values, tolerance)?;
    Some(steady && net_change(values)? < -tolerance)
}

/// Relative change of each step of a series, `|v[k+1] - v[k]| / |v[k]|` (NaN where either
/// is missing or `v[k] = 0`).
pub fn relative_changes(values: &[f64]) -> Vec<f64> {
    values
        .windows(2)
        .map(|w| {
            if w[0].is_finite() && w[1].is_finite() && w[0] != 0.0 {
                (w[1] - w[0]).abs() / w[0].abs()
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// The index of the first point of a series (ordered by particle count) from which every
/// further step changes the value by less than `tolerance` relative to the previous value:
/// the convergence count of Fig. 5. The last point never qualifies on its own (it has no step
/// after it), and a missing value anywhere after the candidate disqualifies it.
pub fn converged_from(values: &[f64], tolerance: f64) -> Option<usize> {
    let changes = relative_changes(values);
    let mut first = None;
    for k in (0..changes.len()).rev() {
        if changes[k].is_finite() && changes[k] < tolerance {
            first = Some(k);
        } else {
            break;
        }
    }
    first
}

/// The position of the largest finite value.
pub fn argmax(values: &[f64]) -> Option<usize> {
    finite(values)
        .into_iter()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// Whether the largest value of a series lies strictly inside it (a local maximum, not at
/// either end); None for fewer than three finite values.
pub fn interior_maximum(values: &[f64]) -> Option<bool> {
    let v = finite(values);
    if v.len() < 3 {
        return None;
    }
    let i = argmax(values)?;
    Some(i != v[0].0 && i != v[v.len() - 1].0)
}

/// The median of the finite values.
pub fn median(values: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// max - min of the finite values.
pub fn spread(values: &[f64]) -> Option<f64> {
    let v = finite(values);
    if v.is_empty() {
        return None;
    }
    let lo = v.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let hi = v.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    Some(hi - lo)
}

/// (max - min) / mean of the finite values: how far from level they are (None when there is
/// none or their mean is 0).
pub fn relative_spread(values: &[f64]) -> Option<f64> {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let s = spread(&v)?;
    (mean != 0.0).then(|| s / mean.abs())
}

/// A set of values that should be level, and how level they are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plateau {
    /// Finite values in it.
    pub points: usize,
    /// Their mean.
    pub mean: f64,
    /// Their smallest.
    pub min: f64,
    /// Their largest.
    pub max: f64,
    /// (max - min) / mean.
    pub relative_spread: f64,
}

impl Plateau {
    /// The plateau of the finite `values` (None for fewer than two, or a zero mean).
    pub fn of(values: &[f64]) -> Option<Plateau> {
        let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.len() < 2 {
            return None;
        }
        Some(Plateau {
            points: v.len(),
            mean: v.iter().sum::<f64>() / v.len() as f64,
            min: v.iter().copied().fold(f64::INFINITY, f64::min),
            max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            relative_spread: relative_spread(&v)?,
        })
    }

    /// Fig. 9's plateau: every finite value of the grid except its largest (the peak). The
    /// paper names a plateau and one peak above it ("the other points in the plateau"), so
    /// every other point belongs to the plateau.
    pub fn apart_from_peak(values: &[f64]) -> Option<Plateau> {
        let peak = argmax(values)?;
        let rest: Vec<f64> = values
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != peak)
            .map(|(_, v)| *v)
            .collect();
        Plateau::of(&rest)
    }

    /// Whether its relative spread is at most `tolerance` ([`PLATEAU_RELATIVE_SPREAD`]).
    pub fn is_flat(&self, tolerance: f64) -> bool {
        self.relative_spread <= tolerance
    }
}

/// Whether `z[row][col]` is larger than each of its finite grid neighbours (up, down, left,
/// right); None when it is missing or has no finite neighbour.
pub fn is_local_maximum(z: &[Vec<f64>], row: usize, col: usize) -> Option<bool> {
    let c = *z.get(row)?.get(col)?;
    if !c.is_finite() {
        return None;
    }
    let mut neighbours = Vec::new();
    if row > 0 {
        neighbours.push(z[row - 1][col]);
    }
    if row + 1 < z.len() {
        neighbours.push(z[row + 1][col]);
    }
    if col > 0 {
        neighbours.push(z[row][col - 1]);
    }
    if col + 1 < z[row].len() {
        neighbours.push(z[row][col + 1]);
    }
    let finite: Vec<f64> = neighbours.into_iter().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        return None;
    }
    Some(finite.iter().all(|&n| c > n))
}

/// The first x at which a series y(x) reaches `level` from below, by linear interpolation
/// between neighbouring finite points; None when it never does (or starts at or above it:
/// then the crossing lies before the first point).
pub fn upward_crossing(x: &[f64], y: &[f64], level: f64) -> Option<f64> {
    let pts: Vec<(f64, f64)> = x
        .iter()
        .zip(y)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
        .collect();
    if pts.first().is_some_and(|p| p.1 >= level) {
        return None;
    }
    pts.windows(2).find_map(|w| {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        (y0 < level && y1 >= level).then(|| x0 + (level - y0) / (y1 - y0) * (x1 - x0))
    })
}

/// Least-squares slope of y against x over the finite pairs (None for fewer than two or no
/// spread in x).
pub fn slope(x: &[f64], y: &[f64]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = x
        .iter()
        .zip(y)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// Linear interpolation of an energy curve at `tau` (the end segments extend the curve).
fn interpolate(curve: &[EnergySample], tau: f64) -> (f64, f64) {
    let k = curve
        .partition_point(|c| c.tau_s < tau)
        .clamp(1, curve.len() - 1);
    let (a, b) = (curve[k - 1], curve[k]);
    let w = if b.tau_s > a.tau_s {
        (tau - a.tau_s) / (b.tau_s - a.tau_s)
    } else {
        0.0
    };
    (
        a.kinetic_j + w * (b.kinetic_j - a.kinetic_j),
        a.potential_j + w * (b.potential_j - a.potential_j),
    )
}

/// Points at which two energy curves are compared over their common time span.
pub const DEVIATION_POINTS: usize = 200;

/// The largest difference between two energy curves, of the kinetic and of the potential
/// energy, relative to the reference curve's initial kinetic energy: sampled at
/// [`DEVIATION_POINTS`] - 1 interior times of the span both curves cover (Fig. 4's measure
/// of "the curves coincide"). NaN when either curve has fewer than two samples.
pub fn curve_deviation(curve: &[EnergySample], reference: &[EnergySample]) -> f64 {
    if curve.len() < 2 || reference.len() < 2 {
        return f64::NAN;
    }
    let ke0 = reference[0].kinetic_j;
    let t0 = curve[0].tau_s.max(reference[0].tau_s);
    let t1 = curve[curve.len() - 1]
        .tau_s
        .min(reference[reference.len() - 1].tau_s);
    (1..DEVIATION_POINTS)
        .map(|k| {
            let t = t0 + (t1 - t0) * k as f64 / DEVIATION_POINTS as f64;
            let (a, b) = (interpolate(curve, t), interpolate(reference, t));
            (a.0 - b.0).abs().max((a.1 - b.1).abs()) / ke0
        })
        .fold(0.0, f64::max)
}

/// The largest [`curve_deviation`] of any curve from the last one (the finest resolution).
pub fn largest_deviation_from_finest(curves: &[Vec<EnergySample>]) -> f64 {
    let Some(finest) = curves.last() else {
        return f64::NAN;
    };
    curves[..curves.len() - 1]
        .iter()
        .map(|c| curve_deviation(c, finest))
        .fold(0.0, f64::max)
}

/// How long every curve stays within `bound` of the last one (the finest): the time since first
/// contact, s, of the last of [`DEVIATION_POINTS`] - 1 interior times of the common span before
/// the first time any curve's kinetic or potential energy differs from the finest's by more
/// than `bound` times its initial kinetic energy; the span's end when none does, its start when
/// the first time already does. NaN with fewer than two curves or samples.
pub fn coincide_until(curves: &[Vec<EnergySample>], bound: f64) -> f64 {
    let Some((finest, others)) = curves.split_last() else {
        return f64::NAN;
    };
    if others.is_empty() || curves.iter().any(|c| c.len() < 2) {
        return f64::NAN;
    }
    let ke0 = finest[0].kinetic_j;
    let t0 = curves
        .iter()
        .map(|c| c[0].tau_s)
        .fold(f64::NEG_INFINITY, f64::max);
    let t1 = curves
        .iter()
        .map(|c| c[c.len() - 1].tau_s)
        .fold(f64::INFINITY, f64::min);
    let mut until = t0;
    for k in 1..DEVIATION_POINTS {
        let t = t0 + (t1 - t0) * k as f64 / DEVIATION_POINTS as f64;
        let f = interpolate(finest, t);
        let apart = others.iter().any(|c| {
            let a = interpolate(c, t);
            (a.0 - f.0).abs().max((a.1 - f.1).abs()) > bound * ke0
        });
        if apart {
            return until;
        }
        until = t;
    }
    t1
}

#[cfg(test)]
mod tests {
    use super::*;

    const NAN: f64 = f64::NAN;

    #[test]
    fn curves_coincide_until_the_first_time_one_parts() {
        let curve = |kin: &dyn Fn(f64) -> f64| -> Vec<EnergySample> {
            (0..=100)
                .map(|i| {
                    let t = i as f64 * 1e-8;
                    EnergySample {
                        tau_s: t,
                        kinetic_j: kin(t),
                        potential_j: 1.0 - kin(t),
                    }
                })
                .collect()
        };
        let finest = curve(&|_| 1.0);
        // Parts by 0.2 (over the initial 1 J) from 0.5 us on.
        let parting = curve(&|t| if t < 0.5e-6 { 1.0 } else { 0.8 });
        let until = coincide_until(&[parting, finest.clone()], 0.1);
        assert!((0.49e-6..0.5e-6).contains(&until), "{until}");
        let same = coincide_until(&[finest.clone(), finest.clone()], 0.1);
        assert_eq!(same, 1e-6, "the whole span");
        assert!(coincide_until(&[finest], 0.1).is_nan(), "one curve");
    }

    #[test]
    fn monotonicity_with_tolerance_and_gaps() {
        assert_eq!(largest_drop(&[0.1, 0.2, 0.3]), Some(0.0));
        assert_eq!(non_decreasing(&[0.1, 0.2, 0.3], 0.0), Some(true));
        // A fall below an earlier value, not only the previous one.
        let d = largest_drop(&[0.1, 0.5, 0.45, 0.42]).expect("drop");
        assert!((d - 0.08).abs() < 1e-12);
        assert_eq!(non_decreasing(&[0.1, 0.5, 0.45, 0.42], 0.01), Some(false));
        assert_eq!(non_decreasing(&[0.1, 0.5, 0.495, 0.6], 0.01), Some(true));
        // Missing runs are skipped.
        assert_eq!(non_decreasing(&[0.1, NAN, 0.3], 0.0), Some(true));
        assert_eq!(non_decreasing(&[NAN, 0.3], 0.0), None);
        assert_eq!(non_increasing(&[1.2, 1.1, 1.0], 0.0), Some(true));
        assert_eq!(non_increasing(&[1.0, 1.1], 0.05), Some(false));
        assert_eq!(largest_rise(&[1.0, 0.8, 1.1]), Some(0.30000000000000004));
    }

    #[test]
    fn a_series_falls_only_when_it_never_rises_and_ends_lower() {
        // Fig. 10 along eps: falling, rising, level, a dip that recovers, with gaps.
        assert_eq!(falls(&[1.10, 1.05, 1.00], 0.01), Some(true));
        assert_eq!(falls(&[1.02, 1.04, 1.15], 0.01), Some(false));
        assert_eq!(
            falls(&[1.00, 1.00, 1.00], 0.01),
            Some(false),
            "level is not falling"
        );
        assert_eq!(
            falls(&[1.16, 0.99, 1.01], 0.01),
            Some(false),
            "rises after the dip"
        );
        assert_eq!(
            falls(&[1.10, 1.105, 1.00], 0.01),
            Some(true),
            "within the tolerance"
        );
        assert_eq!(falls(&[1.10, NAN, 1.00], 0.01), Some(true));
        assert_eq!(falls(&[NAN, 1.00], 0.01), None);
        assert_eq!(net_change(&[1.02, NAN, 1.15, NAN]), Some(1.15 - 1.02));
    }

    #[test]
    fn a_flat_grid_is_a_plateau_and_a_rising_one_is_not() {
        // The paper's Fig. 9 as it describes it: 1.47 everywhere (within 0.03) but one peak.
        let flat = [
            1.46, 1.47, 1.48, 1.45, 1.49, 1.54, 1.47, 1.48, 1.46, 1.47, 1.47, 1.48,
        ];
        let p = Plateau::apart_from_peak(&flat).expect("plateau");
        assert_eq!((p.points, p.min, p.max), (11, 1.45, 1.49));
        assert!((p.mean - 1.4709).abs() < 1e-3, "{}", p.mean);
        assert!(p.is_flat(PLATEAU_RELATIVE_SPREAD), "{}", p.relative_spread);
        // R rising steadily with eps (the paper tier's map: 1.11 to 1.98): its median is
        // near 1.47, but it is no plateau.
        let rising = [
            1.11, 1.11, 1.15, 1.17, 1.44, 1.45, 1.42, 1.38, 1.98, 1.94, 1.87, 1.74,
        ];
        let r = Plateau::apart_from_peak(&rising).expect("plateau");
        assert!(median(&rising).is_some_and(|m| (m - 1.43).abs() < 0.01));
        assert!(!r.is_flat(PLATEAU_RELATIVE_SPREAD), "{}", r.relative_spread);
        assert!((r.relative_spread - (1.94 - 1.11) / r.mean).abs() < 1e-12);
        // Missing runs are skipped; too few points make no plateau.
        assert_eq!(
            Plateau::apart_from_peak(&[1.5, NAN, 1.4, 1.4]).map(|p| p.points),
            Some(2)
        );
        assert_eq!(Plateau::apart_from_peak(&[1.5, 1.4]), None);
        assert_eq!(relative_spread(&[1.0, 3.0]), Some(1.0));
        assert_eq!(relative_spread(&[NAN]), None);
    }

    #[test]
    fn convergence_count_is_the_first_point_of_the_quiet_tail() {
        // Changes: 50 %, 20 %, 1 %, 0.5 %: converged from the third point.
        let f = [0.2, 0.3, 0.36, 0.3636, 0.3654];
        assert_eq!(converged_from(&f, 0.02), Some(2));
        // A large change late resets it.
        assert_eq!(converged_from(&[0.3, 0.301, 0.302, 0.4], 0.02), None);
        // A quiet start followed by a jump and a quiet end: only the end counts.
        assert_eq!(converged_from(&[0.3, 0.301, 0.4, 0.401], 0.02), Some(2));
        // Missing values break the tail; a single point never converges.
        assert_eq!(converged_from(&[0.3, NAN, 0.3], 0.02), None);
        assert_eq!(converged_from(&[0.3], 0.02), None);
        let c = relative_changes(&[2.0, 3.0, 3.0]);
        assert_eq!(c, vec![0.5, 0.0]);
    }

    #[test]
    fn maxima_medians_crossings_slopes() {
        assert_eq!(interior_maximum(&[0.1, 0.4, 0.2]), Some(true));
        assert_eq!(interior_maximum(&[0.1, 0.2, 0.4]), Some(false));
        assert_eq!(interior_maximum(&[0.5, NAN, 0.4, 0.1]), Some(false));
        assert_eq!(interior_maximum(&[0.5, 0.6]), None);
        assert_eq!(median(&[3.0, 1.0, 2.0, NAN]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(spread(&[1.0, NAN, 4.0]), Some(3.0));
        let z = vec![
            vec![1.0, 1.0, 1.0],
            vec![1.0, 2.0, 1.5],
            vec![1.0, NAN, 3.0],
        ];
        assert_eq!(is_local_maximum(&z, 1, 1), Some(true));
        assert_eq!(is_local_maximum(&z, 1, 2), Some(false));
        assert_eq!(is_local_maximum(&z, 2, 2), Some(true));
        assert_eq!(is_local_maximum(&z, 2, 1), None);
        let x = [3.0, 4.0, 5.0, 6.0];
        assert_eq!(upward_crossing(&x, &[0.1, 0.2, 0.4, 0.5], 0.3), Some(4.5));
        assert_eq!(upward_crossing(&x, &[0.4, 0.5, 0.6, 0.7], 0.3), None);
        assert_eq!(upward_crossing(&x, &[0.1, 0.1, 0.2, 0.2], 0.3), None);
        let s = slope(&[0.1, 0.2, 0.3], &[1.0, 0.9, 0.8]).expect("slope");
        assert!((s + 1.0).abs() < 1e-12);
        assert_eq!(slope(&[0.1], &[1.0]), None);
    }

    fn curve(f: impl Fn(f64) -> (f64, f64), n: usize) -> Vec<EnergySample> {
        (0..=n)
            .map(|k| {
                let t = k as f64 / n as f64;
                let (kinetic_j, potential_j) = f(t);
                EnergySample {
                    tau_s: t,
                    kinetic_j,
                    potential_j,
                }
            })
            .collect()
    }

    #[test]
    fn curve_deviation_is_relative_to_initial_kinetic_energy() {
        // Kinetic energy falls 10 -> 0, potential rises 0 -> 10 (J).
        let reference = curve(|t| (10.0 * (1.0 - t), 10.0 * t), 50);
        // Same curves sampled differently: no deviation beyond interpolation round-off.
        let same = curve(|t| (10.0 * (1.0 - t), 10.0 * t), 17);
        assert!(curve_deviation(&same, &reference) < 1e-12);
        // Potential 1 J higher throughout: 1 / 10.
        let shifted = curve(|t| (10.0 * (1.0 - t), 10.0 * t + 1.0), 50);
        assert!((curve_deviation(&shifted, &reference) - 0.1).abs() < 1e-12);
        // Kinetic energy off by 2 J at the middle only (a triangle): nearly 0.2 at its peak.
        let bump = curve(
            |t| {
                (
                    10.0 * (1.0 - t) + 2.0 * (1.0 - (2.0 * t - 1.0).abs()),
                    10.0 * t,
                )
            },
            100,
        );
        let d = curve_deviation(&bump, &reference);
        assert!((d - 0.2).abs() < 0.002, "{d}");
        // Deviation from the finest (last) curve.
        let all = vec![shifted.clone(), bump.clone(), reference.clone()];
        assert!((largest_deviation_from_finest(&all) - d).abs() < 1e-12);
        assert!(curve_deviation(&reference[..1], &reference).is_nan());
    }
}
