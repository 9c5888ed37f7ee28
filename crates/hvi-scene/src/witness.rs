//! A synthetic witness plate: where each cloud fragment would strike a plate at a given standoff
//! behind the target, and the crater it would leave there.
//!
//! The experiment judges fragment sizes from the craters on a witness plate (the paper's Fig. 8:
//! many craters of about 1 mm, none from a large central fragment). Each fragment flies on a
//! straight line from its centre of mass at its centre-of-mass velocity (the cloud is ballistic
//! once fragmented) to the plane z = rear face + standoff; fragments not moving towards it
//! leave no crater. The crater depth in a semi-infinite aluminium plate is the Cour-Palais
//! relation as given by Christiansen (1993, Int. J. Impact Eng. 14, 145-156, eq. 1):
//!
//! P = 5.24 d^(19/18) H^(-1/4) (rho_p / rho_t)^(1/2) (v_n / C)^(2/3)
//!
//! (P and the fragment diameter d in cm, Brinell hardness H, densities in g/cm^3, the normal
//! velocity v_n and the target's sound speed C in km/s), and the crater diameter is the depth
//! over the depth-to-diameter ratio 0.58 that Love et al. (1995, Int. J. Impact Eng. 16,
//! 405-418) measured for hypervelocity craters in aluminium (0.56-0.60 above 5 km/s).
//!
//! ```
//! use hvi_scene::witness::{crater, WitnessPlate};
//! let plate = WitnessPlate::aluminium_6061(0.1);
//! // A 1 mm aluminium fragment at 6.7 km/s leaves a crater a few millimetres wide.
//! let d = plate.crater_diameter_m(1e-3, 2700.0, 6700.0);
//! assert!(d > 2e-3 && d < 4e-3, "{d}");
//! let c = crater(&plate, [0.0, 0.0, 0.05], [100.0, 0.0, 6700.0], 1e-3, 2700.0, 0.0).expect("hits");
//! assert!((c.x_m - 100.0 * 0.05 / 6700.0).abs() < 1e-12);
//! ```

use serde::{Deserialize, Serialize};

/// Depth-to-diameter ratio of hypervelocity craters in aluminium (Love et al. 1995).
pub const DEPTH_OVER_DIAMETER: f64 = 0.58;

/// The witness plate: where it stands and what it is made of.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WitnessPlate {
    /// Distance of the plate behind the target's original rear face, m.
    pub standoff_m: f64,
    /// Brinell hardness of the plate.
    pub brinell_hardness: f64,
    /// Density of the plate, kg/m^3.
    pub density_kg_m3: f64,
    /// Sound speed of the plate, m/s.
    pub sound_speed_m_s: f64,
}

impl WitnessPlate {
    /// An aluminium 6061-T6 plate (H = 95, 2700 kg/m^3, C = 5.1 km/s, the values of
    /// Christiansen 1993) at `standoff_m` behind the target.
    pub fn aluminium_6061(standoff_m: f64) -> WitnessPlate {
        WitnessPlate {
            standoff_m,
            brinell_hardness: 95.0,
            density_kg_m3: 2700.0,
            sound_speed_m_s: 5100.0,
        }
    }

    /// Crater depth (Cour-Palais, Christiansen 1993 eq. 1) of a fragment of diameter
    /// `diameter_m` and density `density_kg_m3` striking at normal velocity `v_normal_m_s`, m.
    pub fn crater_depth_m(&self, diameter_m: f64, density_kg_m3: f64, v_normal_m_s: f64) -> f64 {
        let d_cm = diameter_m * 100.0;
        let rho_ratio = density_kg_m3 / self.density_kg_m3;
        let v_ratio = v_normal_m_s / self.sound_speed_m_s;
        let p_cm = 5.24
            * d_cm.powf(19.0 / 18.0)
            * self.brinell_hardness.powf(-0.25)
            * rho_ratio.sqrt()
            * v_ratio.powf(2.0 / 3.0);
        p_cm / 100.0
    }

    /// Crater diameter of the same strike, m.
    pub fn crater_diameter_m(&self, diameter_m: f64, density_kg_m3: f64, v_normal_m_s: f64) -> f64 {
        self.crater_depth_m(diameter_m, density_kg_m3, v_normal_m_s) / DEPTH_OVER_DIAMETER
    }
}

/// One crater on the witness plate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Crater {
    /// Where it is on the plate, m (x and y; the impact axis is at 0, 0).
    pub x_m: f64,
    /// y, m.
    pub y_m: f64,
    /// Crater diameter, m.
    pub diameter_m: f64,
    /// Crater depth, m.
    pub depth_m: f64,
    /// The fragment's volume-equivalent diameter, m.
    pub fragment_diameter_m: f64,
    /// The fragment's normal velocity at the plate, m/s.
    pub velocity_m_s: f64,
}

/// The crater a fragment (centre of mass `centroid_m`, velocity `velocity_m_s`, diameter
/// `diameter_m`, density `density_kg_m3`) leaves on `plate` behind a target whose rear face is
/// at z = `plate_rear_z_m`; `None` when it does not move towards the plate.
pub fn crater(
    plate: &WitnessPlate,
    centroid_m: [f64; 3],
    velocity_m_s: [f64; 3],
    diameter_m: f64,
    density_kg_m3: f64,
    plate_rear_z_m: f64,
) -> Option<Crater> {
    let [x, y, z] = centroid_m;
    let [vx, vy, vz] = velocity_m_s;
    if !(vz > 0.0 && vz.is_finite() && diameter_m > 0.0) {
        return None;
    }
    // Straight flight, forward or (for a fragment already past the plane) backward in time.
    let t = (plate_rear_z_m + plate.standoff_m - z) / vz;
    let depth_m = plate.crater_depth_m(diameter_m, density_kg_m3, vz);
    Some(Crater {
        x_m: x + vx * t,
        y_m: y + vy * t,
        diameter_m: depth_m / DEPTH_OVER_DIAMETER,
        depth_m,
        fragment_diameter_m: diameter_m,
        velocity_m_s: vz,
    })
}

/// What the witness plate shows, as numbers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WitnessSummary {
    /// The plate's standoff behind the target, m.
    pub standoff_m: f64,
    /// Craters on the plate.
    pub crater_count: usize,
    /// Median crater diameter, m.
    pub crater_diameter_median_m: Option<f64>,
    /// Largest crater diameter, m.
    pub crater_diameter_max_m: Option<f64>,
    /// The largest crater whose centre lies within the impactor's radius of the axis, m.
    pub central_crater_diameter_m: Option<f64>,
    /// Whether that central crater is large: at least [`LARGE_CRATER_OVER_MEDIAN`] times the
    /// median crater (the paper's Fig. 8 shows none such at its fit).
    pub large_central_crater: bool,
}

/// A central crater at least this many times the median crater counts as large.
pub const LARGE_CRATER_OVER_MEDIAN: f64 = 5.0;

/// Sums up `craters` for an impactor of diameter `impactor_diameter_m`.
pub fn summarise(craters: &[Crater], standoff_m: f64, impactor_diameter_m: f64) -> WitnessSummary {
    let mut d: Vec<f64> = craters.iter().map(|c| c.diameter_m).collect();
    d.sort_by(f64::total_cmp);
    let median = match d.len() {
        0 => None,
        n if n % 2 == 1 => Some(d[n / 2]),
        n => Some(0.5 * (d[n / 2 - 1] + d[n / 2])),
    };
    let r_axis = 0.5 * impactor_diameter_m;
    let central = craters
        .iter()
        .filter(|c| c.x_m.hypot(c.y_m) <= r_axis)
        .map(|c| c.diameter_m)
        .reduce(f64::max);
    WitnessSummary {
        standoff_m,
        crater_count: craters.len(),
        crater_diameter_median_m: median,
        crater_diameter_max_m: d.last().copied(),
        central_crater_diameter_m: central,
        large_central_crater: match (central, median) {
            (Some(c), Some(m)) => c >= LARGE_CRATER_OVER_MEDIAN * m,
            _ => false,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cour_palais_on_a_known_strike() {
        // d = 0.1 cm, H = 95, same density, v = 5.1 km/s (v/C = 1):
        // P = 5.24 * 0.1^(19/18) * 95^(-1/4) cm.
        let plate = WitnessPlate::aluminium_6061(0.1);
        let p = plate.crater_depth_m(1e-3, 2700.0, 5100.0);
        let expected_cm = 5.24 * 0.1f64.powf(19.0 / 18.0) / 95f64.powf(0.25);
        assert!((p - expected_cm / 100.0).abs() < 1e-15, "{p}");
        // Depth grows as v^(2/3) and d^(19/18).
        let p8 = plate.crater_depth_m(1e-3, 2700.0, 8.0 * 5100.0);
        assert!((p8 / p - 4.0).abs() < 1e-12);
        let d = plate.crater_diameter_m(1e-3, 2700.0, 5100.0);
        assert!((d * DEPTH_OVER_DIAMETER - p).abs() < 1e-18);
    }

    #[test]
    fn fragments_fly_straight_to_the_plate() {
        let plate = WitnessPlate::aluminium_6061(0.1);
        // From z = 0.02 past a rear face at 0.01: 0.09 m to go at 6 km/s, drifting 600 m/s in x.
        let c = crater(
            &plate,
            [0.001, 0.0, 0.02],
            [600.0, -300.0, 6000.0],
            5e-4,
            2700.0,
            0.01,
        )
        .expect("hits");
        assert!((c.x_m - (0.001 + 600.0 * 0.09 / 6000.0)).abs() < 1e-15);
        assert!((c.y_m + 300.0 * 0.09 / 6000.0).abs() < 1e-15);
        // Already beyond the plane: traced back to where it crossed it.
        let c = crater(
            &plate,
            [0.0, 0.0, 0.2],
            [600.0, 0.0, 6000.0],
            5e-4,
            2700.0,
            0.01,
        )
        .expect("hits");
        assert!((c.x_m - 600.0 * (0.11 - 0.2) / 6000.0).abs() < 1e-15);
        // Moving back towards the target: no crater.
        assert!(crater(
            &plate,
            [0.0, 0.0, 0.02],
            [0.0, 0.0, -10.0],
            5e-4,
            2700.0,
            0.0
        )
        .is_none());
    }

    #[test]
    fn a_known_set_of_fragments_gives_known_craters() {
        let plate = WitnessPlate::aluminium_6061(0.1);
        let d_imp = 9.53e-3;
        // Nine small fragments spread out and one large one on the axis.
        let mut craters: Vec<Crater> = (0..9)
            .map(|k| {
                let x = 0.01 * (k as f64 - 4.0);
                crater(&plate, [x, 0.0, 0.0], [0.0, 0.0, 6000.0], 3e-4, 2700.0, 0.0).expect("hits")
            })
            .collect();
        let small = craters[0].diameter_m;
        let s = summarise(&craters, 0.1, d_imp);
        assert_eq!(s.crater_count, 9);
        assert_eq!(s.crater_diameter_median_m, Some(small));
        // Only the crater at x = 0 is central; it is no larger than the rest.
        assert_eq!(s.central_crater_diameter_m, Some(small));
        assert!(!s.large_central_crater);
        let big = crater(
            &plate,
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 6000.0],
            4e-3,
            2700.0,
            0.0,
        )
        .expect("hits");
        craters.push(big);
        let s = summarise(&craters, 0.1, d_imp);
        assert_eq!(s.crater_diameter_max_m, Some(big.diameter_m));
        assert_eq!(s.central_crater_diameter_m, Some(big.diameter_m));
        assert!(s.large_central_crater, "{s:?}");
        assert_eq!(summarise(&[], 0.1, d_imp).crater_diameter_median_m, None);
    }
}
