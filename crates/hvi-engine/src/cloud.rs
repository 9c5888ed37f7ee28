//! The debris cloud and its observables (docs/model.md section 5): the one place that defines
//! them.
//!
//! Every number a run reports about the cloud, every plot of it and every score compares is
//! computed here; the study crate calls these functions and never re-derives a definition.
//!
//! # Definitions
//!
//! - **Fragment**: a connected set of particles under intact bonds; a lone particle is a
//!   fragment. Its *label* is the smallest particle id in it, so labels depend neither on the
//!   thread count nor on the storage order (which changes at every neighbour build).
//! - **Residual plate**: the fragment(s) holding at least one particle of the target plate's
//!   outer rim at t = 0 (`Simulation::rim_ids`).
//! - **Debris cloud** at time tau: the particles whose centre lies beyond the plate's original
//!   rear face (z > `plate_rear_z_m`) and that are not in the residual plate.
//! - **N_part**, **N_frag**: the cloud's particles, and the distinct fragments among them. A
//!   fragment that straddles the rear face counts with its cloud part only, so the cloud's mass
//!   is exactly the sum of its fragments' masses; how many fragments straddle is reported
//!   (`fragments_crossing_rear_face`, normally 0 once the cloud has left the plate).
//! - **Fragmentation** F = N_frag / N_part (eq. 21): 1 when every cloud particle is alone.
//! - **Front** z_f: the `quantile` (default 0.9) of the cloud particles' z. **Axial length**
//!   La = z_f - `plate_rear_z_m`. **Radial length** Lr, the full width, as `analysis.width`
//!   reads it ([`Width`]): side-on (the default), twice the same quantile of the particles'
//!   distances |x| and |y| from the two planes of view through the axis, pooled (what a
//!   side-view shadowgraph's projection records); or cylindrical, twice the quantile of their
//!   distance from the impact axis x = y = 0. Both readings are reported beside the chosen one
//!   (docs/model-decisions.md, "The width of the cloud"). **R** = La / Lr. The plain maxima
//!   (quantile 1) are reported beside them. Positions are particle centres.
//!   Quantiles interpolate linearly between order statistics (numpy's default, Hyndman-Fan
//!   type 7), see [`quantile`].
//! - **Front velocity** va = (z_f(t2) - z_f(t1)) / (t2 - t1): the front located at two times,
//!   as the experiment's pair of high-speed photographs does (default 28 and 32 us, see
//!   [`crate::scene::Analysis::front_times_s`]); also va / v0.
//! - **Fragment size**: particles; mass; volume-equivalent diameter d = (6 V / pi)^(1/3) with
//!   V = mass / density. A particle stands for the volume mass / density, which is its body's
//!   volume over the body's particle count (eq. 20): the impactor's and the plate's particles
//!   differ slightly in mass, and this keeps every fragment's volume exact. A lone particle has
//!   d of about 1.24 r_eq, the resolution floor of every size.
//! - **Largest fragment**: the cloud fragment of largest mass (ties go to the smaller label);
//!   its mass over the impactor's mass, and its d. **Mean fragment diameter**: mass-weighted,
//!   sum m_f d_f / sum m_f over the cloud's fragments.
//!
//! # Cost
//!
//! Fragment labelling is a union-find over the intact bonds, O(N) and about the cost of one
//! time step. It runs only when a measurement is due: at each sample of the cloud track
//! (`analysis.track_every` steps), at the two front times, and once for the full measurement at
//! the end of the run ([`CloudObserver`]). Sums are taken in particle-id order, so every result
//! is bit-identical at any thread count and any storage order.
//!
//! # Measuring again
//!
//! A run keeps the cloud's state at the two front times and at the analysis time
//! ([`CloudState`], `analysis.keep_state`): every particle's position, velocity, mass, body,
//! fragment label and membership. [`remeasure`] measures the cloud from them with another
//! quantile, camera or witness plate through the same functions the run uses, without
//! re-simulating.

use std::time::{Duration, Instant};

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::scene::{Analysis, Derived, Width};
use crate::shadowgraph::{Shadowgraph, ShadowgraphSettings};
use crate::sim::Simulation;
use crate::state::{Body, Particles};
use crate::witness::{self, Crater, WitnessPlate, WitnessSummary};

// The analysis defaults live with the settings that use them (`scene::Analysis`); also here,
// where they were defined before.
pub use crate::scene::{DEFAULT_FRONT_TIMES_S, DEFAULT_QUANTILE};
/// Fragments listed one by one in the summary (largest first).
pub const LARGEST_FRAGMENTS_LISTED: usize = 10;

/// The q-quantile of `values` by linear interpolation between order statistics (numpy's
/// default): with the values sorted, x_(h) at h = (n - 1) q. `None` when empty. Reorders
/// `values` (selection, O(n)); the result does not depend on their initial order.
pub fn quantile(values: &mut [f64], q: f64) -> Option<f64> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let h = (n - 1) as f64 * q.clamp(0.0, 1.0);
    let lo = (h.floor() as usize).min(n - 1);
    let (_, &mut x_lo, upper) = values.select_nth_unstable_by(lo, f64::total_cmp);
    let frac = h - lo as f64;
    if upper.is_empty() || frac == 0.0 {
        return Some(x_lo);
    }
    let x_hi = upper.iter().copied().fold(f64::INFINITY, f64::min);
    Some(x_lo + frac * (x_hi - x_lo))
}

/// Volume-equivalent diameter of a fragment of mass `mass_kg`: d = (6 m / (pi rho))^(1/3), m.
pub fn equivalent_diameter_m(mass_kg: f64, density_kg_m3: f64) -> f64 {
    (6.0 * mass_kg / (std::f64::consts::PI * density_kg_m3)).cbrt()
}

/// What the definitions need to know about a scene, fixed at t = 0.
#[derive(Debug, Clone)]
pub struct CloudReference {
    /// z of the target plate's original rear face, m: the cloud lies beyond it.
    pub plate_rear_z_m: f64,
    /// Density of the plate's material, kg/m^3 (a particle's volume is its mass over its
    /// body's density).
    pub density_kg_m3: f64,
    /// Density of the impactor's material, kg/m^3 (the plate's for one material).
    pub impactor_density_kg_m3: f64,
    /// The impactor's total mass, kg.
    pub impactor_mass_kg: f64,
    /// Impact velocity, m/s.
    pub v0_m_s: f64,
    /// Whether each id is on the plate's outer rim at t = 0.
    rim_by_id: Vec<bool>,
}

impl CloudReference {
    /// The reference of a particle set: `rim_ids` are the ids of the plate's outer rim.
    pub fn new(particles: &Particles, derived: &Derived, rim_ids: &[u32]) -> Self {
        let n = particles.len();
        let mut rim_by_id = vec![false; n];
        for &id in rim_ids {
            if let Some(r) = rim_by_id.get_mut(id as usize) {
                *r = true;
            }
        }
        let impactor_mass_kg = ids_in_order(particles)
            .filter(|&i| particles.body[i] == Body::Impactor)
            .map(|i| particles.mass[i])
            .sum();
        CloudReference {
            plate_rear_z_m: derived.plate_rear_z_m,
            density_kg_m3: derived.density_kg_m3,
            impactor_density_kg_m3: derived.impactor_density_kg_m3(),
            impactor_mass_kg,
            v0_m_s: derived.v0_m_s,
            rim_by_id,
        }
    }

    /// The volume-equivalent diameter of `mass_kg` of which `impactor_kg` is of the
    /// impactor, m: its volume is each body's mass over its density ([`equivalent_diameter_m`]
    /// of the whole mass at the one density for one material).
    pub fn equivalent_diameter_m(&self, mass_kg: f64, impactor_kg: f64) -> f64 {
        if self.impactor_density_kg_m3 == self.density_kg_m3 {
            equivalent_diameter_m(mass_kg, self.density_kg_m3)
        } else {
            let volume = (mass_kg - impactor_kg) / self.density_kg_m3
                + impactor_kg / self.impactor_density_kg_m3;
            equivalent_diameter_m(volume, 1.0)
        }
    }

    /// The mass of plate material with the volume of a particle of `body` and mass `mass_kg`,
    /// kg: what the shadowgraph darkens by (it sees volume, not mass).
    pub fn plate_equivalent_kg(&self, body: Body, mass_kg: f64) -> f64 {
        match body {
            Body::Impactor if self.impactor_density_kg_m3 != self.density_kg_m3 => {
                mass_kg * self.density_kg_m3 / self.impactor_density_kg_m3
            }
            _ => mass_kg,
        }
    }

    /// The mean density of fragment `f`, kg/m^3: its mass over its volume (the one density
    /// for one material).
    pub fn fragment_density_kg_m3(&self, f: &Fragment) -> f64 {
        if self.impactor_density_kg_m3 == self.density_kg_m3 {
            self.density_kg_m3
        } else {
            f.mass_kg / (std::f64::consts::PI / 6.0 * f.diameter_m.powi(3))
        }
    }

    /// The reference of a running simulation (its rim ids and derived numbers).
    pub fn of(sim: &Simulation) -> Self {
        Self::new(&sim.full_particles(), &sim.derived, &sim.full_rim_ids())
    }

    /// True when particle `id` was on the plate's outer rim at t = 0.
    pub fn is_rim(&self, id: u32) -> bool {
        self.rim_by_id.get(id as usize).copied().unwrap_or(false)
    }
}

/// Current indices in id order (ids are 0..n).
fn ids_in_order(p: &Particles) -> impl Iterator<Item = usize> {
    p.index_of_id().into_iter().map(|i| i as usize)
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    // Path halving: every visited node skips to its grandparent.
    while parent[x as usize] != x {
        let grand = parent[parent[x as usize] as usize];
        parent[x as usize] = grand;
        x = grand;
    }
    x
}

/// Fragment labelling (union-find over intact bonds) with reusable buffers.
#[derive(Debug, Clone, Default)]
pub struct Labeller {
    parent: Vec<u32>,
    label_of_root: Vec<u32>,
}

impl Labeller {
    /// Writes into `labels[i]` the fragment label of the particle at current index `i`: the
    /// smallest id in its fragment.
    pub fn label(&mut self, p: &Particles, labels: &mut Vec<u32>) {
        let n = p.len();
        self.parent.clear();
        self.parent.extend(0..n as u32);
        for (i, j) in p.intact_bond_pairs() {
            let a = find(&mut self.parent, i as u32);
            let b = find(&mut self.parent, j as u32);
            if a != b {
                let (lo, hi) = if a < b { (a, b) } else { (b, a) };
                self.parent[hi as usize] = lo;
            }
        }
        self.label_of_root.clear();
        self.label_of_root.resize(n, u32::MAX);
        labels.clear();
        for i in 0..n {
            let r = find(&mut self.parent, i as u32) as usize;
            self.label_of_root[r] = self.label_of_root[r].min(p.id[i]);
            labels.push(r as u32);
        }
        for l in labels.iter_mut() {
            *l = self.label_of_root[*l as usize];
        }
    }
}

/// Fragment labels of every particle, by current index (see [`Labeller::label`]).
pub fn label_fragments(p: &Particles) -> Vec<u32> {
    let mut labels = Vec::new();
    Labeller::default().label(p, &mut labels);
    labels
}

/// The debris cloud at one instant, by current index.
#[derive(Debug, Clone, Default)]
pub struct CloudMembers {
    /// Fragment label of every particle (the smallest id in its fragment).
    pub labels: Vec<u32>,
    /// Whether each particle belongs to the residual plate.
    pub in_residual_plate: Vec<bool>,
    /// Whether each particle belongs to the debris cloud.
    pub in_cloud: Vec<bool>,
}

impl CloudMembers {
    /// Number of cloud particles, N_part.
    pub fn n_part(&self) -> usize {
        self.in_cloud.iter().filter(|&&c| c).count()
    }
}

/// Finds the debris cloud (labels, residual plate, members) with reusable buffers.
#[derive(Debug, Clone, Default)]
pub struct CloudFinder {
    labeller: Labeller,
    residual_by_label: Vec<bool>,
    members: CloudMembers,
}

impl CloudFinder {
    /// Labels the fragments and marks the residual plate and the cloud.
    pub fn find(&mut self, p: &Particles, reference: &CloudReference) -> &CloudMembers {
        let n = p.len();
        let m = &mut self.members;
        self.labeller.label(p, &mut m.labels);
        self.residual_by_label.clear();
        self.residual_by_label.resize(n, false);
        for i in 0..n {
            if reference.is_rim(p.id[i]) {
                self.residual_by_label[m.labels[i] as usize] = true;
            }
        }
        m.in_residual_plate.clear();
        m.in_residual_plate
            .extend(m.labels.iter().map(|&l| self.residual_by_label[l as usize]));
        m.in_cloud.clear();
        m.in_cloud.extend(
            p.pos
                .iter()
                .zip(&m.in_residual_plate)
                .map(|(x, &plate)| x.z > reference.plate_rear_z_m && !plate),
        );
        &self.members
    }
}

/// Finds the debris cloud of a particle set (see [`CloudFinder`]).
pub fn find_cloud(p: &Particles, reference: &CloudReference) -> CloudMembers {
    let mut f = CloudFinder::default();
    f.find(p, reference);
    f.members
}

/// The cloud's extent at one instant: front, La, Lr, R by the quantile and by the maximum.
/// Lengths are `None` while the cloud is empty; ratios while Lr is 0.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Extent {
    /// Cloud particles, N_part.
    pub n_part: usize,
    /// Front z_f (quantile of z), m.
    pub front_z_m: Option<f64>,
    /// La = z_f - rear face, m.
    pub length_axial_m: Option<f64>,
    /// Lr as `analysis.width` reads it (`length_radial_side_m` or
    /// `length_radial_cylindrical_m`), m.
    pub length_radial_m: Option<f64>,
    /// R = La / Lr.
    pub length_ratio: Option<f64>,
    /// Largest z, m.
    pub front_z_max_m: Option<f64>,
    /// Largest z - rear face, m.
    pub length_axial_max_m: Option<f64>,
    /// Twice the largest width as `analysis.width` reads it (largest |x| or |y| side-on,
    /// largest distance from the axis cylindrically), m.
    pub length_radial_max_m: Option<f64>,
    /// La / Lr by the maxima.
    pub length_ratio_max: Option<f64>,
    /// Lr seen side-on: twice the quantile of the particles' distance from the plane of view
    /// through the axis (|x| and |y| pooled: two perpendicular side views), m. The width a
    /// shadowgraph's projection records.
    #[serde(default)]
    pub length_radial_side_m: Option<f64>,
    /// R seen side-on: La / `length_radial_side_m`.
    #[serde(default)]
    pub length_ratio_side: Option<f64>,
    /// Lr as a cylindrical radius: twice the quantile of the distance from the axis, m (a
    /// width no camera sees).
    #[serde(default)]
    pub length_radial_cylindrical_m: Option<f64>,
    /// R with the cylindrical width: La / `length_radial_cylindrical_m`.
    #[serde(default)]
    pub length_ratio_cylindrical: Option<f64>,
}

/// The extent of the particles marked `in_cloud` (see the module's definitions), at quantile
/// `q`, its width Lr read as `width` says (both readings are reported beside it).
pub fn extent(
    p: &Particles,
    in_cloud: &[bool],
    plate_rear_z_m: f64,
    q: f64,
    width: Width,
) -> Extent {
    let mut z: Vec<f64> = Vec::new();
    let mut rho: Vec<f64> = Vec::new();
    let mut side: Vec<f64> = Vec::new();
    for (x, _) in p.pos.iter().zip(in_cloud).filter(|(_, &c)| c) {
        z.push(x.z);
        rho.push(x.x.hypot(x.y));
        side.push(x.x.abs());
        side.push(x.y.abs());
    }
    let n_part = z.len();
    let max = |v: &[f64]| v.iter().copied().reduce(f64::max);
    let front_z_max_m = max(&z);
    let (rho_max, side_max) = (max(&rho), max(&side));
    let front_z_m = quantile(&mut z, q);
    let rho_q = quantile(&mut rho, q);
    let side_q = quantile(&mut side, q);
    let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => Some(a / b),
        _ => None,
    };
    let twice = |r: Option<f64>| r.map(|r| 2.0 * r);
    let length_axial_m = front_z_m.map(|f| f - plate_rear_z_m);
    let length_axial_max_m = front_z_max_m.map(|f| f - plate_rear_z_m);
    let length_radial_side_m = twice(side_q);
    let length_radial_cylindrical_m = twice(rho_q);
    let (length_radial_m, length_radial_max_m) = match width {
        Width::Side => (length_radial_side_m, twice(side_max)),
        Width::Cylindrical => (length_radial_cylindrical_m, twice(rho_max)),
    };
    Extent {
        n_part,
        front_z_m,
        length_axial_m,
        length_radial_m,
        length_ratio: ratio(length_axial_m, length_radial_m),
        front_z_max_m,
        length_axial_max_m,
        length_radial_max_m,
        length_ratio_max: ratio(length_axial_max_m, length_radial_max_m),
        length_radial_side_m,
        length_ratio_side: ratio(length_axial_m, length_radial_side_m),
        length_radial_cylindrical_m,
        length_ratio_cylindrical: ratio(length_axial_m, length_radial_cylindrical_m),
    }
}

/// Front velocity va from two front positions (m) at two times (s), m/s.
pub fn front_velocity(t1_s: f64, front1_m: f64, t2_s: f64, front2_m: f64) -> Option<f64> {
    (t2_s > t1_s).then(|| (front2_m - front1_m) / (t2_s - t1_s))
}

/// One fragment of the cloud (its cloud part, see the module's definitions).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fragment {
    /// Label: the smallest particle id in the fragment.
    pub label: u32,
    /// Particles.
    pub particles: usize,
    /// Of which impactor particles.
    pub impactor_particles: usize,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Volume-equivalent diameter, m.
    pub diameter_m: f64,
    /// Centre of mass, m.
    pub centroid_m: [f64; 3],
    /// Centre-of-mass velocity, m/s.
    pub velocity_m_s: [f64; 3],
}

/// The full measurement of the cloud at one instant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CloudMeasurement {
    /// Simulated time of the measurement, s.
    pub time_s: f64,
    /// Time since first contact of the measurement, s.
    pub tau_s: f64,
    /// Quantile used for the front and the radial extent.
    pub quantile: f64,
    /// How Lr was read (`analysis.width`); a measurement written before the key existed was
    /// cylindrical.
    #[serde(default = "Width::legacy")]
    pub width: Width,
    /// Cloud particles.
    pub n_part: usize,
    /// Distinct fragments among them.
    pub n_frag: usize,
    /// F = N_frag / N_part (eq. 21); `None` while the cloud is empty.
    pub fragmentation: Option<f64>,
    /// Front z_f, m.
    pub front_z_m: Option<f64>,
    /// La, m.
    pub length_axial_m: Option<f64>,
    /// Lr, m.
    pub length_radial_m: Option<f64>,
    /// R = La / Lr.
    pub length_ratio: Option<f64>,
    /// Largest z, m.
    pub front_z_max_m: Option<f64>,
    /// La by the maximum, m.
    pub length_axial_max_m: Option<f64>,
    /// Lr by the maximum, m.
    pub length_radial_max_m: Option<f64>,
    /// R by the maxima.
    pub length_ratio_max: Option<f64>,
    /// Lr seen side-on (twice the quantile of |x| and |y| pooled), m.
    #[serde(default)]
    pub length_radial_side_m: Option<f64>,
    /// R seen side-on: La over the side-on Lr.
    #[serde(default)]
    pub length_ratio_side: Option<f64>,
    /// Lr as a cylindrical radius (twice the quantile of the distance from the axis), m.
    #[serde(default)]
    pub length_radial_cylindrical_m: Option<f64>,
    /// R with the cylindrical width.
    #[serde(default)]
    pub length_ratio_cylindrical: Option<f64>,
    /// The cloud's mass, kg (the sum of its fragments' masses).
    pub mass_kg: f64,
    /// Share of the impactor's mass that is in the cloud.
    pub impactor_mass_fraction_in_cloud: f64,
    /// Mass of the largest fragment, kg.
    pub largest_fragment_mass_kg: Option<f64>,
    /// Mass of the cloud's largest fragment (of impactor or plate material, or both) over the
    /// impactor's mass.
    pub largest_fragment_mass_fraction: Option<f64>,
    /// The largest piece of the impactor in the cloud: the impactor mass of the cloud fragment
    /// that holds the most of it, over the impactor's mass (0 when no cloud fragment holds
    /// impactor particles). What "no large piece of the impactor remains intact" is about; the
    /// cloud's largest fragment can be a piece of the plate.
    #[serde(default)]
    pub impactor_largest_fragment_mass_fraction: Option<f64>,
    /// The impactor's largest piece anywhere (in the cloud, in the plate's crater or in front
    /// of it), over its mass: 1 for an intact impactor. Bonds never join the bodies, so a
    /// piece is of impactor particles only. What the fragmentation onset is read from
    /// (docs/model-decisions.md, "The fragmentation onset"); None without impactor particles.
    #[serde(default)]
    pub impactor_intact_mass_fraction: Option<f64>,
    /// Volume-equivalent diameter of the largest fragment, m.
    pub largest_fragment_diameter_m: Option<f64>,
    /// Particles in the largest fragment.
    pub largest_fragment_particles: usize,
    /// Mass-weighted mean volume-equivalent diameter of the cloud's fragments, m.
    pub mean_fragment_diameter_m: Option<f64>,
    /// Volume-equivalent diameter of one particle (the resolution floor), m.
    pub particle_diameter_m: f64,
    /// Fragments with particles on both sides of the rear face (counted by their cloud part).
    pub fragments_crossing_rear_face: usize,
}

/// A measurement and the fragments it counted (largest first).
#[derive(Debug, Clone, PartialEq)]
pub struct CloudAnalysis {
    /// The numbers.
    pub measurement: CloudMeasurement,
    /// Every cloud fragment, by decreasing mass (ties: smaller label first).
    pub fragments: Vec<Fragment>,
}

/// The impactor mass of the cloud fragment that holds the most of it (None without cloud
/// fragments or impactor particles). Every impactor particle has the impactor's particle mass.
fn impactor_largest_piece_kg(
    p: &Particles,
    order: &[usize],
    fragments: &[Fragment],
) -> Option<f64> {
    let particle_kg = order
        .iter()
        .find(|&&i| p.body[i] == Body::Impactor)
        .map(|&i| p.mass[i])?;
    let most = fragments.iter().map(|f| f.impactor_particles).max()?;
    Some(most as f64 * particle_kg)
}

/// The impactor mass of its largest piece anywhere (every particle, cloud or not), kg: the
/// most impactor particles under one label times the impactor's particle mass (None without
/// impactor particles).
fn impactor_intact_kg(p: &Particles, labels: &[u32], order: &[usize]) -> Option<f64> {
    let particle_kg = order
        .iter()
        .find(|&&i| p.body[i] == Body::Impactor)
        .map(|&i| p.mass[i])?;
    let mut count = vec![0u32; p.len()];
    for &i in order {
        if p.body[i] == Body::Impactor {
            count[labels[i] as usize] += 1;
        }
    }
    let most = count.iter().copied().max()?;
    Some(f64::from(most) * particle_kg)
}

/// One fragment's sums while the cloud's particles are visited in id order.
struct FragmentSum {
    label: u32,
    particles: usize,
    impactor: usize,
    mass: f64,
    impactor_mass: f64,
    moment: glam::DVec3,
    momentum: glam::DVec3,
    crossing: bool,
}

impl FragmentSum {
    fn into_fragment(self, reference: &CloudReference) -> Fragment {
        Fragment {
            label: self.label,
            particles: self.particles,
            impactor_particles: self.impactor,
            mass_kg: self.mass,
            diameter_m: reference.equivalent_diameter_m(self.mass, self.impactor_mass),
            centroid_m: (self.moment / self.mass).to_array(),
            velocity_m_s: (self.momentum / self.mass).to_array(),
        }
    }
}

/// The cloud's fragments (their cloud parts), largest first (ties: smaller label first), and
/// how many of them straddle the rear face. `order` is the particles' indices in id order.
fn cloud_fragments(
    p: &Particles,
    members: &CloudMembers,
    order: &[usize],
    reference: &CloudReference,
) -> (Vec<Fragment>, usize) {
    let n = p.len();
    let mut slot_of_label = vec![u32::MAX; n];
    let mut acc: Vec<FragmentSum> = Vec::new();
    for &i in order {
        if !members.in_cloud[i] {
            continue;
        }
        let l = members.labels[i] as usize;
        if slot_of_label[l] == u32::MAX {
            slot_of_label[l] = acc.len() as u32;
            acc.push(FragmentSum {
                label: l as u32,
                particles: 0,
                impactor: 0,
                mass: 0.0,
                impactor_mass: 0.0,
                moment: glam::DVec3::ZERO,
                momentum: glam::DVec3::ZERO,
                crossing: false,
            });
        }
        let a = &mut acc[slot_of_label[l] as usize];
        let m = p.mass[i];
        a.particles += 1;
        if p.body[i] == Body::Impactor {
            a.impactor += 1;
            a.impactor_mass += m;
        }
        a.mass += m;
        a.moment += p.pos[i] * m;
        a.momentum += p.vel[i] * m;
    }
    for i in 0..n {
        let s = slot_of_label[members.labels[i] as usize];
        if s != u32::MAX && !members.in_cloud[i] {
            acc[s as usize].crossing = true;
        }
    }
    let crossing = acc.iter().filter(|a| a.crossing).count();
    let mut fragments: Vec<Fragment> = acc
        .into_iter()
        .map(|a| a.into_fragment(reference))
        .collect();
    fragments.sort_by(|a, b| b.mass_kg.total_cmp(&a.mass_kg).then(a.label.cmp(&b.label)));
    (fragments, crossing)
}

/// One particle's diameter, m: the smallest particle volume present (the finer body), as the
/// mass of plate material that fills it (0 without particles).
fn particle_diameter_m(p: &Particles, reference: &CloudReference) -> f64 {
    let particle_mass = (0..p.len())
        .map(|i| reference.plate_equivalent_kg(p.body[i], p.mass[i]))
        .fold(f64::INFINITY, f64::min);
    if particle_mass.is_finite() {
        equivalent_diameter_m(particle_mass, reference.density_kg_m3)
    } else {
        0.0
    }
}

/// Measures the cloud marked in `members` (see the module's definitions). Sums run in id order.
pub fn measure(
    p: &Particles,
    members: &CloudMembers,
    reference: &CloudReference,
    q: f64,
    width: Width,
    time_s: f64,
    tau_s: f64,
) -> CloudAnalysis {
    let order: Vec<usize> = ids_in_order(p).collect();
    let (fragments, fragments_crossing_rear_face) = cloud_fragments(p, members, &order, reference);

    let ext = extent(p, &members.in_cloud, reference.plate_rear_z_m, q, width);
    let n_part = ext.n_part;
    let n_frag = fragments.len();
    let mass_kg: f64 = fragments.iter().map(|f| f.mass_kg).sum();
    let impactor_in_cloud: f64 = order
        .iter()
        .filter(|&&i| members.in_cloud[i] && p.body[i] == Body::Impactor)
        .map(|&i| p.mass[i])
        .sum();
    let largest = fragments.first();
    let impactor_largest = impactor_largest_piece_kg(p, &order, &fragments);
    let impactor_intact = impactor_intact_kg(p, &members.labels, &order);
    let mean_fragment_diameter_m = (mass_kg > 0.0).then(|| {
        fragments
            .iter()
            .map(|f| f.mass_kg * f.diameter_m)
            .sum::<f64>()
            / mass_kg
    });
    let per_impactor = |m: f64| {
        if reference.impactor_mass_kg > 0.0 {
            m / reference.impactor_mass_kg
        } else {
            f64::NAN
        }
    };
    let measurement = CloudMeasurement {
        time_s,
        tau_s,
        quantile: q,
        width,
        n_part,
        n_frag,
        fragmentation: (n_part > 0).then(|| n_frag as f64 / n_part as f64),
        front_z_m: ext.front_z_m,
        length_axial_m: ext.length_axial_m,
        length_radial_m: ext.length_radial_m,
        length_ratio: ext.length_ratio,
        front_z_max_m: ext.front_z_max_m,
        length_axial_max_m: ext.length_axial_max_m,
        length_radial_max_m: ext.length_radial_max_m,
        length_ratio_max: ext.length_ratio_max,
        length_radial_side_m: ext.length_radial_side_m,
        length_ratio_side: ext.length_ratio_side,
        length_radial_cylindrical_m: ext.length_radial_cylindrical_m,
        length_ratio_cylindrical: ext.length_ratio_cylindrical,
        mass_kg,
        impactor_mass_fraction_in_cloud: per_impactor(impactor_in_cloud),
        largest_fragment_mass_kg: largest.map(|f| f.mass_kg),
        largest_fragment_mass_fraction: largest.map(|f| per_impactor(f.mass_kg)),
        impactor_largest_fragment_mass_fraction: impactor_largest.map(per_impactor),
        impactor_intact_mass_fraction: impactor_intact.map(per_impactor),
        largest_fragment_diameter_m: largest.map(|f| f.diameter_m),
        largest_fragment_particles: largest.map_or(0, |f| f.particles),
        mean_fragment_diameter_m,
        particle_diameter_m: particle_diameter_m(p, reference),
        fragments_crossing_rear_face,
    };
    CloudAnalysis {
        measurement,
        fragments,
    }
}

/// One class of the size distribution: all fragments with the same number of particles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SizeClass {
    /// Particles per fragment.
    pub particles: usize,
    /// Fragments of this size.
    pub fragments: usize,
    /// Their total mass, kg.
    pub mass_kg: f64,
    /// Their share of the cloud's mass.
    pub mass_fraction: f64,
    /// Share of the cloud's mass in fragments of at least this many particles.
    pub mass_fraction_at_least: f64,
    /// Mass-weighted mean volume-equivalent diameter of the class, m.
    pub diameter_m: f64,
}

/// The size distribution of `fragments` by particle count, smallest first.
pub fn size_distribution(fragments: &[Fragment]) -> Vec<SizeClass> {
    let mut sorted: Vec<&Fragment> = fragments.iter().collect();
    sorted.sort_by(|a, b| {
        a.particles
            .cmp(&b.particles)
            .then(a.mass_kg.total_cmp(&b.mass_kg))
            .then(a.label.cmp(&b.label))
    });
    let total: f64 = fragments.iter().map(|f| f.mass_kg).sum();
    let mut classes: Vec<SizeClass> = Vec::new();
    let mut weighted_d: Vec<f64> = Vec::new();
    for f in sorted {
        match classes.last_mut() {
            Some(c) if c.particles == f.particles => {
                c.fragments += 1;
                c.mass_kg += f.mass_kg;
                if let Some(w) = weighted_d.last_mut() {
                    *w += f.mass_kg * f.diameter_m;
                }
            }
            _ => {
                classes.push(SizeClass {
                    particles: f.particles,
                    fragments: 1,
                    mass_kg: f.mass_kg,
                    mass_fraction: 0.0,
                    mass_fraction_at_least: 0.0,
                    diameter_m: 0.0,
                });
                weighted_d.push(f.mass_kg * f.diameter_m);
            }
        }
    }
    let mut above = 0.0;
    for (c, w) in classes.iter_mut().zip(weighted_d).rev() {
        above += c.mass_kg;
        c.diameter_m = w / c.mass_kg;
        if total > 0.0 {
            c.mass_fraction = c.mass_kg / total;
            c.mass_fraction_at_least = above / total;
        }
    }
    classes
}

/// One sample of the cloud track (written as `cloud_track.csv`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackRow {
    /// Step number.
    pub step: u64,
    /// Simulated time, s.
    pub time_s: f64,
    /// Time since first contact, s.
    pub tau_s: f64,
    /// Cloud particles.
    pub n_part: usize,
    /// Front z_f (quantile), m.
    pub front_z_m: Option<f64>,
    /// La, m.
    pub length_axial_m: Option<f64>,
    /// Lr, m.
    pub length_radial_m: Option<f64>,
    /// R = La / Lr.
    pub length_ratio: Option<f64>,
    /// Largest z, m.
    pub front_z_max_m: Option<f64>,
    /// La by the maximum, m.
    pub length_axial_max_m: Option<f64>,
    /// Lr by the maximum, m.
    pub length_radial_max_m: Option<f64>,
    /// Front velocity between the previous sample and this one, m/s (a finite difference of
    /// the track, shown to see the front settle; va itself comes from the two front times).
    pub front_velocity_m_s: Option<f64>,
}

/// The front located at one of the two front times.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrontSample {
    /// Time since first contact, s (the step nearest the requested time).
    pub tau_s: f64,
    /// Front z_f, m (`None` if the cloud was empty).
    pub front_z_m: Option<f64>,
    /// The silhouette's front, m (`None` if no shadowgraph pixel was dark).
    pub front_z_silhouette_m: Option<f64>,
}

/// The cloud as the side-on camera sees it ([`crate::shadowgraph`]): La, Lr and R of the
/// silhouette at the analysis time, and va from the silhouette's front at the two front times.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SilhouetteReport {
    /// Pixel size of the shadowgraph, m.
    pub pixel_m: f64,
    /// Its blur (standard deviation), m.
    pub blur_m: f64,
    /// The debris grain diameter its optical depth refers to, m.
    pub grain_m: f64,
    /// Optical depth at which a pixel is dark.
    pub optical_depth: f64,
    /// Dark pixels at the analysis time.
    pub dark_pixels: usize,
    /// The silhouette's front, m.
    pub front_z_m: Option<f64>,
    /// La of the silhouette, m.
    pub length_axial_m: Option<f64>,
    /// Lr of the silhouette, m.
    pub length_radial_m: Option<f64>,
    /// R of the silhouette.
    pub length_ratio: Option<f64>,
    /// The silhouette's front at the two front times, m.
    pub front_positions_m: [Option<f64>; 2],
    /// va from the silhouette's front at the two front times, m/s.
    pub front_velocity_m_s: Option<f64>,
    /// That va over v0.
    pub front_velocity_ratio: Option<f64>,
}

/// The shadowgraph of the particles marked `in_cloud`, taken in id order (`order` maps ids to
/// storage indices). A particle darkens by its volume: an impactor particle of another density
/// counts as the plate material that fills it.
pub fn cloud_shadowgraph(
    p: &Particles,
    in_cloud: &[bool],
    order: &[u32],
    reference: &CloudReference,
    settings: &ShadowgraphSettings,
) -> Option<Shadowgraph> {
    let particles: Vec<(DVec3, f64)> = order
        .iter()
        .map(|&i| i as usize)
        .filter(|&i| in_cloud[i])
        .map(|i| {
            (
                p.pos[i],
                reference.plate_equivalent_kg(p.body[i], p.mass[i]),
            )
        })
        .collect();
    Shadowgraph::of_masses(&particles, reference.density_kg_m3, settings)
}

/// The cloud part of `summary.json`: the full measurement at the analysis time, va and the
/// largest fragments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CloudReport {
    /// The measurement at the analysis time (the end of the run).
    #[serde(flatten)]
    pub measurement: CloudMeasurement,
    /// va, m/s.
    pub front_velocity_m_s: Option<f64>,
    /// va / v0.
    pub front_velocity_ratio: Option<f64>,
    /// The two times since first contact of the front positions, s (as sampled).
    pub front_velocity_times_s: [Option<f64>; 2],
    /// The front positions z_f at those times, m.
    pub front_positions_m: [Option<f64>; 2],
    /// The cloud as the side-on camera sees it (absent in summaries of earlier versions).
    #[serde(default)]
    pub silhouette: Option<SilhouetteReport>,
    /// What the witness plate shows (absent in summaries of earlier versions).
    #[serde(default)]
    pub witness_plate: Option<WitnessSummary>,
    /// The largest fragments, largest first.
    pub largest_fragments: Vec<Fragment>,
}

/// The first base step at or after `tau_s` since first contact (where a setting that starts
/// at a time, such as free flight, begins; not capped at the end).
pub fn first_step_at_or_after(derived: &Derived, tau_s: f64) -> u64 {
    ((derived.contact_time_s + tau_s) / derived.dt_s).ceil() as u64
}

/// The step nearest to time `tau_s` since first contact, clamped to the run.
pub fn step_at_tau(derived: &Derived, tau_s: f64) -> u64 {
    let s = ((tau_s + derived.contact_time_s) / derived.dt_s).round();
    if s.is_nan() || s <= 0.0 {
        0
    } else {
        (s as u64).min(derived.steps)
    }
}

/// Watches a run: samples the cloud track every `analysis.track_every` steps, locates the front
/// at the two front times, and measures the cloud at the end. Call [`CloudObserver::observe`]
/// at step 0 and after every step; it does nothing (two comparisons) unless a sample is due.
/// With `analysis.keep_state` it also keeps the cloud's state at the front times and at the end
/// ([`CloudResult::kept`]), from which [`remeasure`] measures it again.
///
/// ```
/// use hvi_engine::cloud::CloudObserver;
/// use hvi_engine::scene::SceneSpec;
/// use hvi_engine::sim::Simulation;
///
/// let spec = SceneSpec::calibration(500.0, 2e-7);
/// let mut sim = Simulation::new(spec.build()?)?;
/// let mut observer = CloudObserver::new(&sim, &spec.analysis, spec.run.end_time_s);
/// observer.observe(&sim);
/// let end = sim.derived.steps;
/// while sim.step < end {
///     // An adaptive step must land on every step at which a sample is due.
///     let next = observer.next_due(sim.step).map_or(end, |due| due.min(end));
///     sim.step_until(next)?;
///     observer.observe(&sim);
/// }
/// let cloud = observer.finish(&sim).expect("analysis.cloud is on by default");
/// // 0.2 us after first contact nothing has passed the plate's rear face yet.
/// assert_eq!(cloud.report.measurement.n_part, 0);
/// assert_eq!(observer.track.last().map(|row| row.step), Some(end));
/// # Ok::<(), hvi_engine::EngineError>(())
/// ```
#[derive(Debug, Clone)]
pub struct CloudObserver {
    reference: CloudReference,
    settings: Settings,
    measure_cloud: bool,
    keep_state: bool,
    track_every: u64,
    last_step: u64,
    front_steps: [u64; 2],
    /// Whether the front times follow the end time (the defaults of a run shorter than 32 us).
    front_follows_end: bool,
    finder: CloudFinder,
    /// The cloud track so far.
    pub track: Vec<TrackRow>,
    /// The front at the two front times, once reached.
    pub front: [Option<FrontSample>; 2],
    /// The cloud's state at the two front times, once reached (with `analysis.keep_state`).
    front_states: [Option<CloudState>; 2],
    /// Wall time spent observing (labelling, quantiles, the final measurement).
    pub elapsed: Duration,
}

/// What a [`CloudObserver`] has gathered during a run ([`CloudObserver::save_state`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObserverState {
    track: Vec<TrackRow>,
    front: [Option<FrontSample>; 2],
    front_states: [Option<CloudState>; 2],
    elapsed: Duration,
}

/// What a measurement depends on besides the particles: the quantile, the camera and the
/// witness plate of `[analysis]`.
#[derive(Debug, Clone, Copy)]
struct Settings {
    quantile: f64,
    width: Width,
    shadowgraph: ShadowgraphSettings,
    witness_plate: WitnessPlate,
}

impl Settings {
    fn of(analysis: &Analysis) -> Self {
        Settings {
            quantile: analysis.quantile,
            width: analysis.width,
            shadowgraph: analysis.shadowgraph(),
            witness_plate: analysis.witness_plate(),
        }
    }
}

impl CloudObserver {
    /// An observer of `sim` (a run ending at `sim.derived.steps`) as `analysis` asks;
    /// `end_time_s` is the run's `run.end_time_s` (it sets the default front times).
    pub fn new(sim: &Simulation, analysis: &Analysis, end_time_s: f64) -> Self {
        let [t1, t2] = analysis.front_times_s(end_time_s);
        CloudObserver {
            reference: CloudReference::of(sim),
            settings: Settings::of(analysis),
            measure_cloud: analysis.cloud,
            keep_state: analysis.cloud && analysis.keep_state,
            track_every: analysis.track_every,
            last_step: sim.derived.steps,
            front_steps: [step_at_tau(&sim.derived, t1), step_at_tau(&sim.derived, t2)],
            front_follows_end: analysis.front_times_s(end_time_s)
                != analysis.front_times_s(f64::INFINITY),
            finder: CloudFinder::default(),
            track: Vec::new(),
            front: [None, None],
            front_states: [None, None],
            elapsed: Duration::ZERO,
        }
    }

    /// The reference the observer measures against.
    pub fn reference(&self) -> &CloudReference {
        &self.reference
    }

    /// What the observer has gathered so far (the track, the front samples and the states
    /// kept at the front times), for a checkpoint: an observer made by [`Self::new`] for the
    /// same scene and given it back ([`Self::restore_state`]) goes on as this one would.
    pub fn save_state(&self) -> ObserverState {
        ObserverState {
            track: self.track.clone(),
            front: self.front,
            front_states: self.front_states.clone(),
            elapsed: self.elapsed,
        }
    }

    /// Takes over what a saved observer had gathered ([`Self::save_state`]).
    pub fn restore_state(&mut self, s: ObserverState) {
        self.track = s.track;
        self.front = s.front;
        self.front_states = s.front_states;
        self.elapsed = s.elapsed;
    }

    /// The first base step at which this observer samples something only because the run
    /// ends where it does: the end itself (the track's last sample and the measurement), or
    /// the first front time when the front times follow the end (`analysis.front_times_s`
    /// not given and a run shorter than 32 us). Every sample before it a run to a later end
    /// takes too, at the same steps.
    pub fn first_end_dependent_step(&self) -> u64 {
        if self.measure_cloud && self.front_follows_end {
            self.front_steps[0].min(self.last_step)
        } else {
            self.last_step
        }
    }

    /// The first step after `step` at which something is due (a track sample or a front
    /// time), if any: an adaptive step must land on it.
    pub fn next_due(&self, step: u64) -> Option<u64> {
        let track = (self.track_every > 0).then(|| {
            (step / self.track_every + 1)
                .saturating_mul(self.track_every)
                .min(self.last_step.max(step + 1))
        });
        let front = self.next_front(step);
        match (track, front) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The first front time after `step`, in base steps, if the cloud is measured and one
    /// follows: what a measurement of the cloud at the end needs besides the end itself.
    pub fn next_front(&self, step: u64) -> Option<u64> {
        self.front_steps
            .iter()
            .copied()
            .filter(|&s| self.measure_cloud && s > step)
            .min()
    }

    fn track_due(&self, step: u64) -> bool {
        step.checked_rem(self.track_every) == Some(0)
            || (self.track_every > 0 && step == self.last_step)
    }

    fn front_due(&self, step: u64) -> bool {
        self.measure_cloud && self.front_steps.contains(&step)
    }

    /// Samples whatever is due at the simulation's current step.
    pub fn observe(&mut self, sim: &Simulation) {
        let step = sim.step;
        let (track, front) = (self.track_due(step), self.front_due(step));
        if !track && !front {
            return;
        }
        let t0 = Instant::now();
        let full = sim.full_particles();
        let members = self.finder.find(&full, &self.reference);
        let ext = extent(
            &full,
            &members.in_cloud,
            self.reference.plate_rear_z_m,
            self.settings.quantile,
            self.settings.width,
        );
        let tau = sim.tau_s();
        if track {
            let front_velocity_m_s =
                self.track
                    .last()
                    .and_then(|prev| match (prev.front_z_m, ext.front_z_m) {
                        (Some(a), Some(b)) => front_velocity(prev.tau_s, a, tau, b),
                        _ => None,
                    });
            self.track.push(TrackRow {
                step,
                time_s: sim.time_s(),
                tau_s: tau,
                n_part: ext.n_part,
                front_z_m: ext.front_z_m,
                length_axial_m: ext.length_axial_m,
                length_radial_m: ext.length_radial_m,
                length_ratio: ext.length_ratio,
                front_z_max_m: ext.front_z_max_m,
                length_axial_max_m: ext.length_axial_max_m,
                length_radial_max_m: ext.length_radial_max_m,
                front_velocity_m_s,
            });
        }
        if front {
            let sample = front_sample(
                &full,
                &members.in_cloud,
                ext.front_z_m,
                &self.reference,
                &self.settings.shadowgraph,
                tau,
            );
            for k in 0..2 {
                if self.front_steps[k] == step {
                    self.front[k] = Some(sample);
                    if self.keep_state {
                        self.front_states[k] =
                            Some(CloudState::capture(sim, &full, members, &self.reference));
                    }
                }
            }
        }
        self.elapsed += t0.elapsed();
    }

    /// The full measurement of the cloud now (the analysis time), with va from the front
    /// samples; `None` when the scene does not ask for it (`analysis.cloud = false`).
    pub fn finish(&mut self, sim: &Simulation) -> Option<CloudResult> {
        if !self.measure_cloud {
            return None;
        }
        let t0 = Instant::now();
        let full = sim.full_particles();
        let members = self.finder.find(&full, &self.reference);
        let mut result = cloud_result(
            &full,
            members,
            &self.reference,
            &self.settings,
            &self.front,
            sim.time_s(),
            sim.tau_s(),
        );
        if self.keep_state {
            result.kept = Some(KeptStates {
                end: CloudState::capture(sim, &full, members, &self.reference),
                front: std::mem::take(&mut self.front_states),
            });
        }
        self.elapsed += t0.elapsed();
        Some(result)
    }
}

/// The front at one of the two front times: z_f by the quantile (`front_z_m`, from the extent
/// already taken) and the silhouette's front.
fn front_sample(
    p: &Particles,
    in_cloud: &[bool],
    front_z_m: Option<f64>,
    reference: &CloudReference,
    shadowgraph: &ShadowgraphSettings,
    tau_s: f64,
) -> FrontSample {
    let silhouette = cloud_shadowgraph(p, in_cloud, &p.index_of_id(), reference, shadowgraph)
        .and_then(|s| s.measure(reference.plate_rear_z_m));
    FrontSample {
        tau_s,
        front_z_m,
        front_z_silhouette_m: silhouette.map(|m| m.front_z_m),
    }
}

/// The silhouette's numbers now, with va from its front at the two front times.
fn silhouette(
    p: &Particles,
    in_cloud: &[bool],
    reference: &CloudReference,
    settings: &ShadowgraphSettings,
    front: &[Option<FrontSample>; 2],
) -> (SilhouetteReport, Option<Shadowgraph>) {
    let image = cloud_shadowgraph(p, in_cloud, &p.index_of_id(), reference, settings);
    let m = image
        .as_ref()
        .and_then(|s| s.measure(reference.plate_rear_z_m));
    let fronts = front.map(|f| f.and_then(|f| Some((f.tau_s, f.front_z_silhouette_m?))));
    let va = match fronts {
        [Some((t1, z1)), Some((t2, z2))] => front_velocity(t1, z1, t2, z2),
        _ => None,
    };
    let v0 = reference.v0_m_s;
    let report = SilhouetteReport {
        pixel_m: settings.pixel_m,
        blur_m: settings.blur_m,
        grain_m: settings.grain_m,
        optical_depth: settings.optical_depth,
        dark_pixels: m.map_or(0, |m| m.dark_pixels),
        front_z_m: m.map(|m| m.front_z_m),
        length_axial_m: m.map(|m| m.length_axial_m),
        length_radial_m: m.map(|m| m.length_radial_m),
        length_ratio: m.map(|m| m.length_ratio),
        front_positions_m: front.map(|f| f.and_then(|f| f.front_z_silhouette_m)),
        front_velocity_m_s: va,
        front_velocity_ratio: va.filter(|_| v0 > 0.0).map(|v| v / v0),
    };
    (report, image)
}

/// The craters of the cloud's fragments on the witness plate.
fn craters(
    plate: &WitnessPlate,
    reference: &CloudReference,
    fragments: &[Fragment],
) -> Vec<Crater> {
    fragments
        .iter()
        .filter_map(|f| {
            witness::crater(
                plate,
                f.centroid_m,
                f.velocity_m_s,
                f.diameter_m,
                reference.fragment_density_kg_m3(f),
                reference.plate_rear_z_m,
            )
        })
        .collect()
}

/// The full measurement of the cloud marked in `members` at the analysis time, with va from
/// the two front samples: what [`CloudObserver::finish`] and [`remeasure`] return (without
/// kept states).
fn cloud_result(
    p: &Particles,
    members: &CloudMembers,
    reference: &CloudReference,
    settings: &Settings,
    front: &[Option<FrontSample>; 2],
    time_s: f64,
    tau_s: f64,
) -> CloudResult {
    let analysis = measure(
        p,
        members,
        reference,
        settings.quantile,
        settings.width,
        time_s,
        tau_s,
    );
    let [a, b] = *front;
    let va = match (a, b) {
        (
            Some(FrontSample {
                tau_s: t1,
                front_z_m: Some(z1),
                ..
            }),
            Some(FrontSample {
                tau_s: t2,
                front_z_m: Some(z2),
                ..
            }),
        ) => front_velocity(t1, z1, t2, z2),
        _ => None,
    };
    let v0 = reference.v0_m_s;
    let (silhouette, shadowgraph) = silhouette(
        p,
        &members.in_cloud,
        reference,
        &settings.shadowgraph,
        front,
    );
    let craters = craters(&settings.witness_plate, reference, &analysis.fragments);
    let witness = witness::summarise(
        &craters,
        settings.witness_plate.standoff_m,
        equivalent_diameter_m(reference.impactor_mass_kg, reference.impactor_density_kg_m3),
    );
    let report = CloudReport {
        measurement: analysis.measurement.clone(),
        front_velocity_m_s: va,
        front_velocity_ratio: va.filter(|_| v0 > 0.0).map(|v| v / v0),
        front_velocity_times_s: [a.map(|s| s.tau_s), b.map(|s| s.tau_s)],
        front_positions_m: [a.and_then(|s| s.front_z_m), b.and_then(|s| s.front_z_m)],
        silhouette: Some(silhouette),
        witness_plate: Some(witness),
        largest_fragments: analysis
            .fragments
            .iter()
            .take(LARGEST_FRAGMENTS_LISTED)
            .cloned()
            .collect(),
    };
    let mut labels_by_id = vec![0u32; p.len()];
    for (i, &l) in members.labels.iter().enumerate() {
        labels_by_id[p.id[i] as usize] = l;
    }
    CloudResult {
        report,
        fragments: analysis.fragments,
        craters,
        shadowgraph,
        labels_by_id,
        kept: None,
    }
}

/// What [`CloudObserver::finish`] and [`remeasure`] return.
#[derive(Debug, Clone, PartialEq)]
pub struct CloudResult {
    /// The `cloud` object of `summary.json`.
    pub report: CloudReport,
    /// Every cloud fragment, largest first (for the size distribution).
    pub fragments: Vec<Fragment>,
    /// The fragment label of every particle, indexed by id.
    pub labels_by_id: Vec<u32>,
    /// The craters the fragments leave on the witness plate, in fragment order.
    pub craters: Vec<Crater>,
    /// The shadowgraph at the analysis time (`None` for an empty cloud).
    pub shadowgraph: Option<Shadowgraph>,
    /// The cloud's state at the analysis time and the front times, when the scene keeps it
    /// (`analysis.keep_state`; `None` from [`remeasure`]).
    pub kept: Option<KeptStates>,
}

/// The cloud at one of its sample times as a run keeps it (`state.bin`, written by
/// `hvi_run::state`): every particle in id order with its position, velocity, mass, body and
/// the cloud labelling of that instant, and the reference numbers it is measured against.
/// Enough to measure the cloud again, with other settings, without re-simulating
/// ([`remeasure`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CloudState {
    /// Base step of the sample.
    pub step: u64,
    /// Simulated time, s.
    pub time_s: f64,
    /// Time since first contact, s.
    pub tau_s: f64,
    /// z of the target plate's original rear face, m.
    pub plate_rear_z_m: f64,
    /// Density of the plate's material, kg/m^3.
    pub density_kg_m3: f64,
    /// Density of the impactor's material, kg/m^3.
    pub impactor_density_kg_m3: f64,
    /// The impactor's total mass, kg.
    pub impactor_mass_kg: f64,
    /// Impact velocity, m/s.
    pub v0_m_s: f64,
    /// Positions by id, m.
    pub pos: Vec<DVec3>,
    /// Velocities by id, m/s.
    pub vel: Vec<DVec3>,
    /// Masses by id, kg.
    pub mass: Vec<f64>,
    /// Bodies by id.
    pub body: Vec<Body>,
    /// Fragment labels by id (the smallest id in each fragment).
    pub labels: Vec<u32>,
    /// Whether each particle (by id) is in the residual plate.
    pub in_residual_plate: Vec<bool>,
    /// Whether each particle (by id) is in the debris cloud.
    pub in_cloud: Vec<bool>,
}

impl CloudState {
    /// The state of `sim` now (its particles of the full scene `p`,
    /// [`Simulation::full_particles`]), with the labelling `members` (by index in `p`, as
    /// [`CloudFinder::find`] gives it) found against `reference`.
    pub fn capture(
        sim: &Simulation,
        p: &Particles,
        members: &CloudMembers,
        reference: &CloudReference,
    ) -> Self {
        let order: Vec<usize> = ids_in_order(p).collect();
        CloudState {
            step: sim.step,
            time_s: sim.time_s(),
            tau_s: sim.tau_s(),
            plate_rear_z_m: reference.plate_rear_z_m,
            density_kg_m3: reference.density_kg_m3,
            impactor_density_kg_m3: reference.impactor_density_kg_m3,
            impactor_mass_kg: reference.impactor_mass_kg,
            v0_m_s: reference.v0_m_s,
            pos: order.iter().map(|&i| p.pos[i]).collect(),
            vel: order.iter().map(|&i| p.vel[i]).collect(),
            mass: order.iter().map(|&i| p.mass[i]).collect(),
            body: order.iter().map(|&i| p.body[i]).collect(),
            labels: order.iter().map(|&i| members.labels[i]).collect(),
            in_residual_plate: order
                .iter()
                .map(|&i| members.in_residual_plate[i])
                .collect(),
            in_cloud: order.iter().map(|&i| members.in_cloud[i]).collect(),
        }
    }

    /// Particles.
    pub fn len(&self) -> usize {
        self.pos.len()
    }

    /// True when there are no particles.
    pub fn is_empty(&self) -> bool {
        self.pos.is_empty()
    }

    /// The reference of the state: its numbers, without the rim (the residual plate is
    /// already marked).
    pub fn reference(&self) -> CloudReference {
        CloudReference {
            plate_rear_z_m: self.plate_rear_z_m,
            density_kg_m3: self.density_kg_m3,
            impactor_density_kg_m3: self.impactor_density_kg_m3,
            impactor_mass_kg: self.impactor_mass_kg,
            v0_m_s: self.v0_m_s,
            rim_by_id: Vec::new(),
        }
    }

    /// The particles, in id order (no bonds: the labels hold the fragments).
    pub fn particles(&self) -> Particles {
        let n = self.len();
        Particles::new(
            self.pos.clone(),
            self.vel.clone(),
            self.mass.clone(),
            self.body.clone(),
            vec![crate::state::NO_BOND; n * crate::state::BONDS_PER_PARTICLE],
        )
    }

    /// The labelling, by the index of [`CloudState::particles`].
    pub fn members(&self) -> CloudMembers {
        CloudMembers {
            labels: self.labels.clone(),
            in_residual_plate: self.in_residual_plate.clone(),
            in_cloud: self.in_cloud.clone(),
        }
    }
}

/// The states a run keeps: at the analysis time (the end), and at the two front times when
/// they were reached.
#[derive(Debug, Clone, PartialEq)]
pub struct KeptStates {
    /// At the analysis time.
    pub end: CloudState,
    /// At the two front times.
    pub front: [Option<CloudState>; 2],
}

/// The cloud measured again from kept states with `analysis`'s quantile, camera and witness
/// plate: what [`CloudObserver::finish`] returns for a run observed with these settings (the
/// front times are those of the kept states; nothing else of `analysis` matters). The cloud is
/// the one the run found (its labels and members are kept), and every definition is the one
/// the run uses, so for the run's own settings and unrounded states the result is
/// bit-identical to the run's.
pub fn remeasure(kept: &KeptStates, analysis: &Analysis) -> CloudResult {
    let settings = Settings::of(analysis);
    let front = kept.front.each_ref().map(|state| {
        state.as_ref().map(|s| {
            let p = s.particles();
            let reference = s.reference();
            let ext = extent(
                &p,
                &s.in_cloud,
                s.plate_rear_z_m,
                settings.quantile,
                settings.width,
            );
            front_sample(
                &p,
                &s.in_cloud,
                ext.front_z_m,
                &reference,
                &settings.shadowgraph,
                s.tau_s,
            )
        })
    });
    let end = &kept.end;
    cloud_result(
        &end.particles(),
        &end.members(),
        &end.reference(),
        &settings,
        &front,
        end.time_s,
        end.tau_s,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn quantile_interpolates_like_numpy() {
        let mut v = vec![4.0, 1.0, 3.0, 2.0, 5.0];
        assert_eq!(quantile(&mut v, 0.5), Some(3.0));
        assert_eq!(quantile(&mut v, 1.0), Some(5.0));
        assert_eq!(quantile(&mut v, 0.0), Some(1.0));
        // h = 4 * 0.9 = 3.6: 4 + 0.6 * (5 - 4).
        let q = quantile(&mut v, 0.9).expect("non-empty");
        assert!((q - 4.6).abs() < 1e-12, "{q}");
        assert_eq!(quantile(&mut [], 0.5), None);
        assert_eq!(quantile(&mut [7.0], 0.995), Some(7.0));
    }

    #[test]
    fn equivalent_diameter_of_a_sphere_is_its_diameter() {
        let d: f64 = 2e-3;
        let rho = 2700.0;
        let m = rho * std::f64::consts::PI / 6.0 * d.powi(3);
        assert!((equivalent_diameter_m(m, rho) - d).abs() < 1e-15);
    }

    #[test]
    fn labels_are_the_smallest_id_of_each_chain() {
        // Two chains along x: ids 0-1-2 and 3-4, plus a loner 5; stored in shuffled order.
        let n = 6;
        let pos: Vec<DVec3> = (0..n).map(|k| DVec3::new(k as f64, 0.0, 0.0)).collect();
        let mut p = Particles::new(
            pos,
            vec![DVec3::ZERO; n],
            vec![1.0; n],
            vec![Body::Target; n],
            vec![crate::state::NO_BOND; n * crate::state::BONDS_PER_PARTICLE],
        );
        // Storage: index -> id.
        p.id = vec![4, 2, 5, 0, 3, 1];
        let idx = p.index_of_id();
        let mut bond = |a: u32, b: u32| {
            let (i, j) = (idx[a as usize] as usize, idx[b as usize] as usize);
            p.bonds[i * crate::state::BONDS_PER_PARTICLE] = j as u32;
            p.bonds[j * crate::state::BONDS_PER_PARTICLE + 1] = i as u32;
        };
        bond(1, 0);
        bond(2, 1);
        bond(4, 3);
        let labels = label_fragments(&p);
        let by_id: Vec<u32> = (0..n).map(|id| labels[idx[id] as usize]).collect();
        assert_eq!(by_id, vec![0, 0, 0, 3, 3, 5]);
    }
}
