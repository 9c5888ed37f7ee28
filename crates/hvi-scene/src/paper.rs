//! The numbers Watson and Steinhauser (Materials 2017, 10, 379) report, in one place.
//!
//! Every test, default and report that needs one of these numbers calls this module; none of
//! them repeats the literal. Units are SI. The paper states its parameters without units or
//! the particle diameter they belong to; the project reads them as SI at the calibration
//! resolution (docs/model.md section 4), and [`reference_sigma_m`] computes that diameter.

/// Impactor (sphere) diameter D, m. Section 3.2 states it for the Fig. 13 comparison ("9.53 mm
/// in the simulation and experiment"); the EMI calibration shot's diameter is not given, and
/// the project uses the same D for the calibration scene (docs/model.md section 1).
pub const IMPACTOR_DIAMETER_M: f64 = 9.53e-3;
/// Aluminium density of impactor and plate, kg/m^3. Not given in the paper: our choice (the
/// density of aluminium alloys), docs/model.md section 1.
pub const ALUMINIUM_DENSITY_KG_M3: f64 = 2700.0;
/// Impact velocity of the paper's calibration simulations, m/s (section 3.1, Fig. 12 caption
/// text: "v0 = 6.7 km/s").
pub const CALIBRATION_V0_M_S: f64 = 6700.0;
/// Plate thickness over impactor diameter of the calibration simulations (section 3.1:
/// "t/D = 0.425").
pub const CALIBRATION_T_OVER_D: f64 = 0.425;
/// Impact velocity of the EMI calibration shot, m/s (section 3.1: "v0 = 6.5 km/s").
pub const CALIBRATION_SHOT_V0_M_S: f64 = 6500.0;
/// Plate thickness over diameter of the EMI calibration shot (section 3.1: "t/D = 0.41").
pub const CALIBRATION_SHOT_T_OVER_D: f64 = 0.41;
/// Plate side over impactor diameter. Not given in the paper; the project decides 3
/// (docs/model.md section 1).
pub const DEFAULT_WIDTH_OVER_D: f64 = 3.0;
/// Total particle count of the calibration runs (section 2.3: "N = 2.7 x 10^5"), the reference
/// resolution of eps and kappa (docs/model.md section 4).
pub const CALIBRATION_PARTICLES: f64 = 2.7e5;
/// Total particle count of the final runs, Figs. 11, 12 (section 2.3: "N = 7.4 x 10^5").
pub const FINAL_PARTICLES: f64 = 7.4e5;
/// Best-fit repulsion strength eps at the reference diameter, J (section 3.1; units ours).
pub const BEST_EPS_J: f64 = 0.01;
/// Best-fit spring stiffness kappa at the reference diameter, N/m (section 3.1; units ours).
pub const BEST_KAPPA_N_M: f64 = 4.56e6;
/// Best-fit bond break distance, in units of sigma (section 3.1).
pub const BEST_RCUT_OVER_SIGMA: f64 = 1.5;
/// Time step at the reference diameter, s: section 2.3 ("a stable timestep for the
/// simulations") and the 7.4e5-particle run of Fig. 12 (section 3.1).
pub const TIME_STEP_S: f64 = 1e-10;
/// Analysis time after first contact, Figs. 7 and 11 captions ("32 us after impact"), s.
pub const ANALYSIS_TIME_S: f64 = 32e-6;
/// Snapshot times of Fig. 12 (its panel captions), s.
pub const FIG12_TIMES_S: [f64; 4] = [0.0, 9.1e-6, 16.1e-6, 32e-6];
/// Wall time of the 7.4e5-particle run on one processor, s (section 3.1: "nine hours").
pub const PAPER_WALL_SECONDS: f64 = 9.0 * 3600.0;

/// Fig. 5: the particle count from which the fragmentation converges (section 2.3: "the
/// simulations begin to converge at about a quarter of a million particles").
pub const CONVERGED_PARTICLES: f64 = 2.5e5;
/// Fig. 4: the particle counts of the sizing test span "almost three orders of magnitude"
/// (section 2.3).
pub const SIZING_DECADES: f64 = 3.0;
/// Fig. 7: every run with kappa at or below this (N/m, at the reference sigma) fragments almost
/// completely (section 3.1).
pub const FIG7_FINE_MAX_KAPPA_N_M: f64 = 1.14e6;
/// Fig. 7: the size of those runs' fragments (section 3.1: "on the order of 0.1 mm"), m.
pub const FIG7_FINE_FRAGMENT_SIZE_M: f64 = 0.1e-3;
/// Fig. 7: (eps in J, kappa in N/m) of runs with a large central fragment (section 3.1).
pub const FIG7_LARGE_FRAGMENT_POINTS: [(f64, f64); 2] = [(1.0, 9.12e6), (0.1, 9.12e6)];
/// Fig. 9: the plateau of R = La/Lr over the (eps, kappa) grid (section 3.1: "approximately
/// 1.47").
pub const FIG9_R_PLATEAU: f64 = 1.47;
/// Fig. 9: the peak of R over the grid (section 3.1).
pub const FIG9_R_PEAK: f64 = 1.54;
/// Fig. 9: (eps in J, kappa in N/m) of that peak (section 3.1).
pub const FIG9_R_PEAK_AT: (f64, f64) = (1.0, 1.14e6);
/// R = La/Lr measured in the calibration shot (section 3.1, Fig. 6).
pub const CALIBRATION_SHOT_LENGTH_RATIO: f64 = 1.55;
/// The witness plate's average crater diameter, m (Fig. 8 caption: "approximately 1 mm", and
/// "no crater left by a large central fragment").
pub const FIG8_MEAN_CRATER_DIAMETER_M: f64 = 1e-3;
/// Fig. 13: impact velocity of the va/v0 against t/D comparison, m/s (the calibration's).
pub const FIG13_V0_M_S: f64 = CALIBRATION_V0_M_S;
/// Figs. 16-17: the fragmentation below which the model is not valid (section 3.3: "we define
/// fragmentation F = 0.3 to be the cutoff value").
pub const VALIDITY_FRAGMENTATION_CUTOFF: f64 = 0.3;

/// Zero-force distance of the Lennard-Jones repulsion over sigma: r_eq = 2^(1/6) sigma.
pub fn r_eq_over_sigma() -> f64 {
    2f64.powf(1.0 / 6.0)
}

/// Total volume (sphere plus square plate) of a sphere-on-plate scene, m^3.
pub fn sphere_on_plate_volume_m3(diameter_m: f64, t_over_d: f64, width_over_d: f64) -> f64 {
    let d = diameter_m;
    std::f64::consts::PI / 6.0 * d.powi(3) + (width_over_d * d).powi(2) * t_over_d * d
}

/// The particle diameter sigma at which the paper's eps and kappa apply, m.
///
/// Defined by the calibration scene (D = 9.53 mm, t/D = 0.425, W = 3 D) at N = 2.7e5:
/// one lattice cell r_eq^3 per particle, sigma = r_eq / 2^(1/6). About 0.21 mm.
pub fn reference_sigma_m() -> f64 {
    let volume = sphere_on_plate_volume_m3(
        IMPACTOR_DIAMETER_M,
        CALIBRATION_T_OVER_D,
        DEFAULT_WIDTH_OVER_D,
    );
    (volume / CALIBRATION_PARTICLES).cbrt() / r_eq_over_sigma()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_sigma_is_about_0_21_mm() {
        let s = reference_sigma_m();
        assert!((s - 0.2145e-3).abs() < 0.002e-3, "sigma_ref = {s}");
    }
}
