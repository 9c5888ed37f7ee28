//! The time loop: velocity Verlet (eq. 1) with the contact and bond kernels, the energy
//! ledger, momentum, blow-up detection and a per-phase timing breakdown.
//!
//! Every kernel gathers per particle (full neighbour list, each bond seen from both ends), so a
//! particle's force is summed in the same order whatever the thread count. Sums over particles
//! (energies, momentum, broken-bond energy) are taken over fixed chunks of `CHUNK` particles and
//! the chunk results added in chunk order: results are bit-identical at any thread count.
//!
//! Under quarter symmetry (`crate::symmetry`) the kernels add the image pairs and image bonds,
//! and what the simulation reports (energies, bond counts, momentum, `full_particles`) is of
//! the full scene.

use std::borrow::Cow;
use std::time::{Duration, Instant};

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{EngineError, Result};
use crate::neighbour::{split_image, NeighbourList};
use crate::potential::{Materials, PairLaw};
use crate::scene::{Derived, RunSettings, Setup};
use crate::state::{
    Body, Particles, BONDS_PER_PARTICLE, BROKEN_FLAG, INDEX_MASK, NO_BOND, OWNED_BONDS,
};
use crate::step::{stiffness_step_s, LOOKAHEAD_SKIN_FRACTION, SPEED_REFRESH};
use crate::symmetry::{
    image_bond_flags, image_bond_intact, intact_image_bonds, reflect, unfold, unfold_ids, Symmetry,
    MIRROR_X, MIRROR_Y,
};
use crate::{simd, threads};

// The adaptive step's raise delay, also at the path it had when it was defined here.
pub use crate::step::STRIDE_RAISE_AFTER;

mod band;
mod saved;
pub use band::{AbsorbingBand, BAND_ABSORPTION};
pub use saved::SimState;

/// Particles per work unit and per partial sum.
pub const CHUNK: usize = 1024;

/// The bound this project states for the energy ledger (kinetic + contact + bond + broken):
/// its relative drift stays below this through a run at the default step. The engine's
/// physics tests check it, and `hvi-study accuracy` applies it to every candidate setting.
pub const LEDGER_DRIFT_BOUND: f64 = 1e-3;
/// Owned bonds per vectorised block of the bond kernel.
const BLOCK_BONDS: usize = 192;

/// The energy ledger (docs/model.md section 3): kinetic + contact + bond + broken is conserved.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Energy {
    /// Kinetic energy, J.
    pub kinetic_j: f64,
    /// Contact (repulsion) energy, J.
    pub contact_j: f64,
    /// Energy stored in intact stretched bonds, J.
    pub bond_j: f64,
    /// Energy carried away by broken bonds (booked once, when they break), J.
    pub broken_j: f64,
    /// Energy taken out by the absorbing band at the plate's edge (`run.absorbing_band_over_d`;
    /// zero without one), J.
    #[serde(default)]
    pub absorbed_j: f64,
}

impl Energy {
    /// The conserved sum, J.
    pub fn total_j(&self) -> f64 {
        self.kinetic_j + self.contact_j + self.bond_j + self.broken_j + self.absorbed_j
    }
}

/// Wall time spent per phase, like LAMMPS's breakdown.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct Timing {
    /// Contact repulsion over the neighbour list.
    pub contact: Duration,
    /// Bond springs and bond breaking.
    pub bonds: Duration,
    /// Neighbour-list builds (including re-sorting the particles).
    pub neighbour: Duration,
    /// Velocity Verlet updates and the rebuild check.
    pub integrate: Duration,
    /// Energy-ledger samples.
    pub energy: Duration,
}

/// What the first half-kick and drift read ([`drift_chunk`]).
struct DriftInputs<'a> {
    force: &'a [DVec3],
    inv_mass: &'a [f64],
    /// Positions at the last build and the frames' velocities (see `neighbour`).
    built: &'a [DVec3],
    frame: &'a [DVec3],
    /// Velocities at the last build (the adaptive step's speed bound).
    vel_built: &'a [DVec3],
    adaptive: bool,
    half: f64,
    dt: f64,
    /// Time since the build at the end of this step, s.
    since: f64,
}

simd::kernel! {
    /// The first half-kick and the drift of the chunk of particles from `base` (their `pos` and
    /// `vel`). Returns the largest squared displacement relative to the frame (infinite for NaN)
    /// and, with the adaptive step, the largest squared speed relative to a frame and to the
    /// velocity at the build.
    fn drift_chunk(
        inputs: &DriftInputs,
        base: usize,
        pos: &mut [DVec3],
        vel: &mut [DVec3],
    ) -> (f64, [f64; 2]) = drift_chunk_body;
}

/// [`drift_chunk`] as compiled for the instruction set it is called from.
#[inline(always)]
fn drift_chunk_body(
    inputs: &DriftInputs,
    base: usize,
    pos: &mut [DVec3],
    vel: &mut [DVec3],
) -> (f64, [f64; 2]) {
    let DriftInputs {
        force,
        inv_mass,
        built,
        frame,
        vel_built,
        adaptive,
        half,
        dt,
        since,
    } = *inputs;
    let mut max_d2: f64 = 0.0;
    let (mut max_e2, mut max_w2): (f64, f64) = (0.0, 0.0);
    for k in 0..pos.len() {
        let i = base + k;
        let v = vel[k] + force[i] * (half * inv_mass[i]);
        vel[k] = v;
        if adaptive {
            max_e2 = max_e2.max((v - frame[i]).length_squared());
            max_w2 = max_w2.max((v - vel_built[i]).length_squared());
        }
        let x = pos[k] + v * dt;
        pos[k] = x;
        // Displacement relative to the particle's frame (see `neighbour`).
        let d2 = (x - built[i] - frame[i] * since).length_squared();
        // NaN fails every comparison: make it win the max so it is caught below.
        max_d2 = if d2 <= max_d2 {
            max_d2
        } else if d2.is_nan() {
            f64::INFINITY
        } else {
            d2
        };
    }
    (max_d2, [max_e2, max_w2])
}

/// Per-chunk results of the bond kernel.
#[derive(Debug, Clone, Copy, Default)]
struct BondPartial {
    broken: u64,
    broken_energy: f64,
    min_r2: f64,
}

/// A running simulation. Cloning copies the whole state (a probe of what free flight from now
/// would give: `hvi_run`'s screen).
#[derive(Clone)]
pub struct Simulation {
    /// Particle state (reordered along the cell grid at each neighbour build).
    pub particles: Particles,
    /// The pair laws (one material, or the impactor's, the plate's and between them).
    pub materials: Materials,
    /// Derived scene numbers.
    pub derived: Derived,
    neighbours: NeighbourList,
    skin_m: f64,
    block_m: f64,
    since_build_s: f64,
    min_distance2: f64,
    max_energy_drift: f64,
    /// Time reached, in base steps (`dt`): the clock every schedule (samples, renders, the
    /// end) is kept in. An adaptive step advances it by its stride.
    pub step: u64,
    /// The base time step, s: the step the impact is resolved with.
    pub dt: f64,
    /// Steps actually taken (each costs one force evaluation); equals `step` at a fixed step.
    pub steps_taken: u64,
    /// Base steps the next step takes (1 at a fixed step).
    pub stride: u64,
    /// The largest stride taken so far.
    pub largest_stride: u64,
    /// Which bound set the stride target after each adaptive step (see [`StrideLimits`]).
    pub stride_limits: StrideLimits,
    max_stride: u64,
    stride_disp_m: f64,
    stride_calm: u32,
    min_mass: f64,
    last_min_r2: f64,
    speed_partials: Vec<[f64; 2]>,
    vel_at_build: Vec<DVec3>,
    /// Measurements of the pairs' speed between builds (see [`Self::step_until`]).
    pub speed_refreshes: u64,
    /// Bonds at t = 0.
    pub bonds_initial: u64,
    /// Bonds broken so far.
    pub bonds_broken: u64,
    coast_velocity: Vec<DVec3>,
    coast_from_step: Option<u64>,
    /// The ledger when free flight began (see [`Self::energy`]).
    coast_energy: Option<Energy>,
    broken_energy: f64,
    /// The absorbing band: damping rate by particle id, 1/s (empty: no band), and by current
    /// index (refreshed at every re-sort); energy it took out, J; per-chunk partials.
    damping_by_id: Vec<f64>,
    damping: Vec<f64>,
    absorbed_energy: f64,
    absorbed_partials: Vec<f64>,
    /// Energy at t = 0.
    pub energy_initial: Energy,
    /// Momentum at t = 0, kg m/s.
    pub momentum_initial: DVec3,
    /// Time per phase.
    pub timing: Timing,
    /// Ids of the target particles on the plate's lateral rim at t = 0 (the residual plate is
    /// the fragment holding them, docs/model.md section 5).
    pub rim_ids: Vec<u32>,
    /// F/r of each owned bond (0 when empty or broken and stretched), per owned slot.
    bond_force_over_r: Vec<f64>,
    bond_partials: Vec<BondPartial>,
    /// Image bonds broken per chunk in the last step (quarter symmetry).
    image_partials: Vec<[u64; 2]>,
    contact_min_r2: Vec<f64>,
    disp_partials: Vec<f64>,
    /// The part of the scene simulated: the particles carry image bonds under quarter
    /// symmetry ([`crate::symmetry`]). Energies, bond counts and momentum are reported for
    /// the full scene.
    pub symmetry: Symmetry,
}

/// How often each bound of the adaptive step ([`Simulation::step_until`]) set the stride's
/// target: one count per step taken with `run.max_stride` > 1.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StrideLimits {
    /// The displacement bound on pairs that can interact until the next build.
    pub listed: u64,
    /// The look-ahead's share of the skin (pairs not yet listed).
    pub unlisted: u64,
    /// The stiffness bound.
    pub stiffness: u64,
    /// `run.max_stride`.
    pub cap: u64,
}

impl Simulation {
    /// Prepares a run: first neighbour build, forces, initial ledger.
    ///
    /// ```
    /// use hvi_engine::scene::SceneSpec;
    /// use hvi_engine::sim::Simulation;
    ///
    /// let setup = SceneSpec::calibration(500.0, 1e-7).build()?;
    /// let mut sim = Simulation::new(setup)?;
    /// sim.advance(20)?; // 20 base steps (fewer steps when the adaptive step strides)
    /// assert_eq!(sim.step, 20);
    /// let dp = (sim.momentum() - sim.momentum_initial).length();
    /// assert!(dp < 1e-9 * sim.momentum_initial.length());
    /// # Ok::<(), hvi_engine::EngineError>(())
    /// ```
    pub fn new(setup: Setup) -> Result<Self> {
        let Setup {
            spec,
            derived,
            materials,
            particles,
            rim_ids,
        } = setup;
        let mut sim = Self::from_parts(particles, materials, derived, &spec.run)?;
        sim.rim_ids = rim_ids;
        if let Some(band) = AbsorbingBand::of_scene(&spec) {
            sim.damping_by_id = band.damping_by_id(&sim.particles, &sim.materials.target);
            sim.refresh_damping();
        }
        Ok(sim)
    }

    /// Prepares a run from hand-made parts (tests and tools use this; scenes use [`Self::new`]):
    /// `materials` is one [`crate::potential::Interaction`] or a [`Materials`].
    pub fn from_parts(
        particles: Particles,
        materials: impl Into<Materials>,
        derived: Derived,
        run: &RunSettings,
    ) -> Result<Self> {
        let n = particles.len();
        let symmetry = if particles.image_bonds.is_empty() {
            Symmetry::Full
        } else {
            Symmetry::Quarter
        };
        // Bonds of the full scene: each bond of the quarter stands for `copies`, each image
        // bond for half as many (it joins two copies).
        let copies = symmetry.copies() as u64;
        let bonds_initial = copies * particles.intact_bonds() as u64
            + copies / 2 * intact_image_bonds(&particles) as u64;
        let nchunks = n.div_ceil(CHUNK);
        let mut sim = Simulation {
            particles,
            materials: materials.into(),
            derived,
            neighbours: NeighbourList::default(),
            skin_m: run.skin_over_sigma * derived.sigma_m,
            block_m: run.frame_block_over_sigma * derived.sigma_m,
            since_build_s: 0.0,
            min_distance2: (run.min_distance_over_sigma * derived.sigma_m).powi(2),
            max_energy_drift: run.max_energy_drift,
            step: 0,
            dt: derived.dt_s,
            steps_taken: 0,
            stride: 1,
            largest_stride: 1,
            stride_limits: StrideLimits::default(),
            max_stride: run.max_stride.max(1),
            stride_disp_m: run.stride_displacement_over_sigma * derived.sigma_m,
            stride_calm: 0,
            min_mass: 0.0,
            last_min_r2: f64::INFINITY,
            speed_partials: vec![[0.0; 2]; nchunks],
            vel_at_build: Vec::new(),
            speed_refreshes: 0,
            bonds_initial,
            bonds_broken: 0,
            coast_velocity: Vec::new(),
            coast_from_step: None,
            coast_energy: None,
            broken_energy: 0.0,
            damping_by_id: Vec::new(),
            damping: Vec::new(),
            absorbed_energy: 0.0,
            absorbed_partials: vec![0.0; nchunks],
            energy_initial: Energy::default(),
            momentum_initial: DVec3::ZERO,
            timing: Timing::default(),
            rim_ids: Vec::new(),
            bond_force_over_r: vec![0.0; n * OWNED_BONDS],
            bond_partials: vec![BondPartial::default(); nchunks],
            image_partials: vec![[0; 2]; nchunks],
            contact_min_r2: vec![f64::INFINITY; nchunks],
            disp_partials: vec![0.0; nchunks],
            symmetry,
        };
        sim.min_mass = sim
            .particles
            .mass
            .iter()
            .fold(f64::INFINITY, |a, &b| a.min(b));
        sim.rebuild();
        sim.compute_forces(0.0)?;
        sim.energy_initial = sim.energy();
        sim.momentum_initial = sim.momentum();
        Ok(sim)
    }

    /// Simulated time since t = 0, s.
    pub fn time_s(&self) -> f64 {
        self.step as f64 * self.dt
    }

    /// Time since first contact, tau, s.
    pub fn tau_s(&self) -> f64 {
        self.time_s() - self.derived.contact_time_s
    }

    /// The neighbour list (for checks such as [`NeighbourList::missing_pairs`]).
    pub fn neighbour_list(&self) -> &NeighbourList {
        &self.neighbours
    }

    /// Number of neighbour-list builds so far.
    pub fn neighbour_builds(&self) -> u64 {
        self.neighbours.builds
    }

    /// The band's damping rates in the current particle order (after a re-sort or a restore).
    fn refresh_damping(&mut self) {
        if self.damping_by_id.is_empty() {
            return;
        }
        let by_id = &self.damping_by_id;
        self.damping.clear();
        self.damping
            .par_extend(self.particles.id.par_iter().map(|&id| by_id[id as usize]));
    }

    fn rebuild(&mut self) {
        let t = Instant::now();
        let radius = self.materials.target.r_eq_m + self.skin_m;
        let adaptive = self.max_stride > 1;
        self.neighbours
            .build(&mut self.particles, radius, self.block_m, adaptive);
        self.refresh_damping();
        self.since_build_s = 0.0;
        if adaptive {
            // For the adaptive step: the velocities now (the build measured the largest
            // relative speed of any two particles within the list radius, listed pairs and
            // bond partners; stretched partners beyond it feel only the soft spring, which the
            // stiffness bound covers).
            self.vel_at_build.clear();
            self.vel_at_build
                .par_extend(self.particles.vel.par_iter().copied());
        }
        self.timing.neighbour += t.elapsed();
    }

    /// Forces into `particles.force`: first every owned bond once (spring, or repulsion when
    /// compressed; breaks booked here), then per particle the contact repulsion over the
    /// neighbour list plus the bond forces gathered from its owned and mirror slots.
    ///
    /// Also applies the second half-kick of velocity Verlet, `half_dt` (0: none).
    fn compute_forces(&mut self, half_dt: f64) -> Result<()> {
        let t0 = Instant::now();
        self.bond_forces();
        let t1 = Instant::now();
        self.timing.bonds += t1 - t0;
        self.contact_forces_and_kick(half_dt);
        let min_r2 = self.book_chunk_partials();
        self.timing.contact += t1.elapsed();
        self.last_min_r2 = min_r2;
        if min_r2 < self.min_distance2 {
            return Err(self.unstable(format!(
                "two particles {:.3} sigma apart (limit run.min_distance_over_sigma = {:.3}); \
                 the time step is too large for this impact",
                min_r2.sqrt() / self.derived.sigma_m,
                self.min_distance2.sqrt() / self.derived.sigma_m
            )));
        }
        Ok(())
    }

    /// F/r of every owned bond into `bond_force_over_r`, breaking those stretched past rcut;
    /// per chunk of particles, with the chunk's breaks and closest pair in `bond_partials`.
    fn bond_forces(&mut self) {
        if self.materials.is_one() {
            self.bond_forces_with(self.materials.target);
        } else {
            self.bond_forces_with(self.materials);
        }
        if self.symmetry == Symmetry::Quarter {
            self.break_image_bonds();
        }
    }

    /// [`Self::bond_forces`] under one law lookup (monomorphised per [`PairLaw`]).
    fn bond_forces_with<L: PairLaw>(&mut self, law: L) {
        let pos = &self.particles.pos;
        let bodies = &self.particles.body;
        let chunks = self
            .bond_force_over_r
            .chunks_mut(CHUNK * OWNED_BONDS)
            .zip(self.particles.bonds.chunks_mut(CHUNK * BONDS_PER_PARTICLE))
            .zip(self.bond_partials.iter_mut());
        threads::for_each_chunk(chunks, |c, ((fr, bonds), out)| {
            *out = bond_chunk(&law, bodies, pos, c * CHUNK, bonds, fr);
        });
    }

    /// Breaks the image bonds stretched past rcut (quarter symmetry), per chunk of particles
    /// with the chunk's count in `image_partials`. Their force is gathered with the contacts.
    fn break_image_bonds(&mut self) {
        let materials = self.materials;
        let pos = &self.particles.pos;
        let bodies = &self.particles.body;
        self.particles
            .image_bonds
            .par_chunks_mut(CHUNK)
            .zip(self.image_partials.par_iter_mut())
            .enumerate()
            .for_each(|(c, (flags, out))| {
                let mut broken = [0; 2];
                for (k, f) in flags.iter_mut().enumerate() {
                    if *f == 0 {
                        continue;
                    }
                    let i = c * CHUNK + k;
                    let pi = pos[i];
                    let rcut2 = materials.of_body(bodies[i]).rcut2();
                    for code in [MIRROR_X, MIRROR_Y] {
                        if image_bond_intact(*f, code)
                            && (pi - reflect(pi, code)).length_squared() > rcut2
                        {
                            *f |= image_bond_flags(code).1;
                            broken[bodies[i] as usize] += 1;
                        }
                    }
                }
                *out = broken;
            });
    }

    /// Per particle: the contact repulsion over the neighbour list, plus each bond slot's F/r
    /// times the separation (the owner's value for both ends: the pair force is exactly
    /// antisymmetric), then the second half-kick of velocity Verlet, fused here to save a pass
    /// over memory. Each chunk's closest listed pair goes to `contact_min_r2`.
    fn contact_forces_and_kick(&mut self, half_dt: f64) {
        if self.materials.is_one() {
            self.contact_forces_and_kick_with(self.materials.target, half_dt);
        } else {
            self.contact_forces_and_kick_with(self.materials, half_dt);
        }
    }

    /// [`Self::contact_forces_and_kick`] under one law lookup (monomorphised per [`PairLaw`]).
    fn contact_forces_and_kick_with<L: PairLaw>(&mut self, law: L, half_dt: f64) {
        let p = &mut self.particles;
        let inputs = ContactInputs {
            law,
            bodies: &p.body,
            pos: &p.pos,
            nl: &self.neighbours,
            fr_bond: &self.bond_force_over_r,
            bonds: &p.bonds,
            inv_mass: &p.inv_mass,
            mass: &p.mass,
            damping: &self.damping,
            damp: !self.damping.is_empty() && half_dt > 0.0,
            image_bonds: &p.image_bonds,
            mirrored: self.symmetry == Symmetry::Quarter,
            half_dt,
        };
        let chunks = p
            .force
            .chunks_mut(CHUNK)
            .zip(p.vel.chunks_mut(CHUNK))
            .zip(self.contact_min_r2.iter_mut())
            .zip(self.absorbed_partials.iter_mut());
        threads::for_each_chunk(chunks, |c, (((force, vel), min_out), absorbed_out)| {
            (*min_out, *absorbed_out) = contact_chunk(&inputs, c * CHUNK, force, vel);
        });
    }

    /// Books the chunks' broken bonds and their energy, in chunk order, and returns the
    /// squared distance of the closest pair (bonded or listed).
    fn book_chunk_partials(&mut self) -> f64 {
        let mut min_r2 = f64::INFINITY;
        // Counts are of the full scene: a bond of the quarter stands for `copies` bonds, an
        // image bond for half as many. The ledger is the quarter's (an image bond's energy
        // counts one half, see `crate::symmetry`).
        let copies = self.symmetry.copies() as u64;
        for (b, &c) in self.bond_partials.iter().zip(&self.contact_min_r2) {
            self.bonds_broken += copies * b.broken;
            self.broken_energy += b.broken_energy;
            min_r2 = min_r2.min(b.min_r2).min(c);
        }
        if self.symmetry == Symmetry::Quarter {
            let m = self.materials;
            let half_break = |b: Body| 0.5 * m.of_body(b).break_energy_at_rcut();
            for &[ki, kt] in &self.image_partials {
                self.bonds_broken += copies / 2 * (ki + kt);
                self.broken_energy += if m.is_one() {
                    half_break(Body::Target) * (ki + kt) as f64
                } else {
                    half_break(Body::Impactor) * ki as f64 + half_break(Body::Target) * kt as f64
                };
            }
        }
        if !self.damping.is_empty() {
            for &a in &self.absorbed_partials {
                self.absorbed_energy += a;
            }
        }
        min_r2
    }

    fn unstable(&self, reason: String) -> EngineError {
        EngineError::Unstable {
            step: self.step,
            time_s: self.time_s(),
            reason,
        }
    }

    /// Advances one velocity-Verlet step of the current stride (or, after
    /// [`Self::start_coasting`], free flight over as many base steps).
    pub fn step_once(&mut self) -> Result<()> {
        self.step_until(self.step.saturating_add(self.stride))
    }

    /// Advances one step, of the current stride but never past base step `limit` (a sample,
    /// a render, the end): `min(stride, limit - step)` base steps. In free flight (after
    /// [`Self::start_coasting`]) the step goes to `limit` at once: rigid motion is exact for
    /// any step.
    ///
    /// The adaptive step (`run.max_stride` > 1). The base step `dt` resolves the impact, and
    /// the bound on it is that a particle at v0 moves at most a small fraction of sigma per
    /// step. What the bound protects against is two neighbours closing in too far within one
    /// step, so the stride, the multiple of `dt` taken, applies the same bound to the speed at
    /// which neighbours actually close in. After each step:
    /// - pairs that can interact until the next build (the neighbour list's pairs and bond
    ///   partners): u = u_b + 2 max_i |v_i - v_i(b)| bounds their relative speed, where u_b is
    ///   the largest relative speed among them measured at the last build, or measured again
    ///   since (a pass over the lists and bonds, once 2 max_i |v_i - v_i(b)| exceeds
    ///   [`SPEED_REFRESH`] u_b), and v_i(b) each particle's velocity then. The displacement
    ///   bound: u m dt <= `run.stride_displacement_over_sigma` sigma;
    /// - pairs not yet listed close in at most at u' = 2 max_i |v_i - f_i| + df (f_i the
    ///   frame velocity of the particle's block, df the largest difference between adjacent
    ///   blocks' frames, see [`crate::neighbour`]). The list's rebuild rule looks one step
    ///   ahead: it rebuilds once a pair not listed could come within the contact radius by the
    ///   end of the next step (of at most m + 1 base steps: the stride rises by at most one),
    ///   so a pair enters contact only after it was listed, and its first step in contact is
    ///   within the listed pairs' bound. The look-ahead u' (m + 1) dt is held to
    ///   [`LOOKAHEAD_SKIN_FRACTION`] of the skin, so that most of the skin is left to the time
    ///   between builds;
    /// - the stiffness bound: m dt <= [`stiffness_step_s`] = [`crate::step::AUTO_STEP_SAFETY`]
    ///   x [`crate::step::MAX_STEP_OVER_SQRT_M_K`] x sqrt(m_min / k), k the stiffest pair law
    ///   at the closest pair now ([`crate::potential::Materials::stiffness_at`]);
    /// - m is the largest whole number, at most `run.max_stride`, within the three bounds. It
    ///   drops at once when the bounds fall below it and rises by one only after they have
    ///   allowed more for [`STRIDE_RAISE_AFTER`] consecutive steps, so the step changes
    ///   rarely.
    ///
    /// In the hot impact neighbours close at v0 and faster, so at the default bounds the
    /// stride stays 1 there (the impact is integrated as at the fixed step); in the expanding
    /// cloud they close at a fraction of v0 and the stride grows. Velocity Verlet is
    /// synchronised at the end of every step, so changing the step between steps needs nothing
    /// else.
    pub fn step_until(&mut self, limit: u64) -> Result<()> {
        if limit <= self.step {
            return Ok(());
        }
        if self.coast_from_step.is_some() {
            self.coast_step(limit - self.step);
            return Ok(());
        }
        let t0 = Instant::now();
        let m = self.stride.min(limit - self.step);
        let dt = self.dt * m as f64;
        let half = 0.5 * dt;
        let since = self.since_build_s + dt;
        let adaptive = self.max_stride > 1;
        let [max_d2, max_e2, max_w2] = self.kick_and_drift(half, dt, since);
        self.timing.integrate += t0.elapsed();
        self.step += m;
        self.steps_taken += 1;
        self.largest_stride = self.largest_stride.max(m);
        self.since_build_s = since;
        if !max_d2.is_finite() {
            return Err(self.unstable("non-finite or runaway particle position".into()));
        }
        let rebuilt = self.rebuild_if_stale(max_d2, since, max_e2)?;
        if adaptive && !rebuilt && 2.0 * max_w2.sqrt() > SPEED_REFRESH * self.neighbours.pair_speed
        {
            self.refresh_pair_speed();
        }
        self.compute_forces(half)?;
        if adaptive {
            self.adapt_stride(max_e2.sqrt(), max_w2.sqrt());
        }
        Ok(())
    }

    /// The first half-kick (`half` = dt / 2) and the drift over `dt` of velocity Verlet.
    /// Returns, each squared: the largest displacement of a particle relative to its frame
    /// since the build (`since` ago; infinite if any is NaN), and with the adaptive step the
    /// largest speed relative to a frame and relative to the velocity at the build.
    fn kick_and_drift(&mut self, half: f64, dt: f64, since: f64) -> [f64; 3] {
        let p = &mut self.particles;
        let built = &self.neighbours.pos_at_build;
        let frame = &self.neighbours.frame_vel;
        let adaptive = self.max_stride > 1;
        let vel_built = &self.vel_at_build;
        let chunks = p
            .pos
            .chunks_mut(CHUNK)
            .zip(p.vel.chunks_mut(CHUNK))
            .zip(self.disp_partials.iter_mut())
            .zip(self.speed_partials.iter_mut());
        let inputs = DriftInputs {
            force: &p.force,
            inv_mass: &p.inv_mass,
            built,
            frame,
            vel_built,
            adaptive,
            half,
            dt,
            since,
        };
        threads::for_each_chunk(chunks, |c, (((pos, vel), out), speed_out)| {
            (*out, *speed_out) = drift_chunk(&inputs, c * CHUNK, pos, vel);
        });
        let max_d2 = self.disp_partials.iter().fold(0.0f64, |a, &b| a.max(b));
        let [max_e2, max_w2] = self
            .speed_partials
            .iter()
            .fold([0.0f64; 2], |a, b| [a[0].max(b[0]), a[1].max(b[1])]);
        [max_d2, max_e2, max_w2]
    }

    /// Rebuilds the neighbour list when its rule says a contact could be missed (see
    /// [`NeighbourList::stale`]); `max_d2` and `max_e2` as from [`Self::kick_and_drift`].
    fn rebuild_if_stale(&mut self, max_d2: f64, since: f64, max_e2: f64) -> Result<bool> {
        // The adaptive step looks one step ahead (the next stride is at most one more than
        // this one), so that pairs enter contact only once listed.
        let ahead = if self.max_stride > 1 {
            (self.stride + 1).min(self.max_stride) as f64 * self.dt
        } else {
            0.0
        };
        let (max_e, max_s, rc) = (max_d2.sqrt(), max_e2.sqrt(), self.materials.target.r_eq_m);
        // The global form first: it is looser, so when it holds the block-pair form does.
        // Only when it fails are the blocks' displacements measured.
        if self.neighbours.stale(max_e, since, rc, max_s, ahead) && {
            self.neighbours
                .measure_block_displacement(&self.particles.pos, since);
            self.neighbours
                .stale_by_blocks(max_e, since, rc, max_s, ahead)
        } {
            self.rebuild();
            if self.neighbours.out_of_range > 0 {
                return Err(self.unstable(format!(
                    "{} particles left the representable grid (|x| > ~2^20 cells)",
                    self.neighbours.out_of_range
                )));
            }
            return Ok(true);
        }
        Ok(false)
    }

    /// Measures again, without a build, the largest relative speed of the pairs that can
    /// interact (listed pairs and bond partners, intact or broken since the build) into the
    /// list's `pair_speed`, and takes the velocities now as those at the build: the adaptive
    /// step's speed bound then starts again from the speeds now instead of growing by twice
    /// the largest change of any velocity since the build.
    fn refresh_pair_speed(&mut self) {
        let t = Instant::now();
        let w = self.neighbours.interacting_pair_speed(
            &self.particles.vel,
            &self.particles.bonds,
            &self.particles.image_bonds,
            &mut self.vel_at_build,
        );
        self.neighbours.pair_speed = w;
        self.speed_refreshes += 1;
        self.timing.integrate += t.elapsed();
    }

    /// The stride for the next step, from the speed bound and the closest pair (see
    /// [`Self::step_until`]).
    fn adapt_stride(&mut self, max_e: f64, max_w: f64) {
        // Pairs that can interact (listed or bonded): closing speed at most u.
        let u = self.neighbours.pair_speed + 2.0 * max_w;
        let by_speed = self.stride_disp_m / (u * self.dt);
        // Pairs not yet listed: the rebuild rule's look-ahead takes at most a fraction of the
        // skin.
        let u_new = 2.0 * max_e + self.neighbours.near_dv;
        let by_new = LOOKAHEAD_SKIN_FRACTION * self.skin_m / (u_new * self.dt) - 1.0;
        let k = self.materials.stiffness_at(self.last_min_r2);
        let by_stiffness = stiffness_step_s(self.min_mass, k) / self.dt;
        let allowed = by_speed.min(by_new).min(by_stiffness);
        // NaN (nothing moves) and infinity allow the most.
        let capped = allowed >= self.max_stride as f64 || allowed.is_nan();
        let l = &mut self.stride_limits;
        if capped {
            l.cap += 1;
        } else if allowed == by_speed {
            l.listed += 1;
        } else if allowed == by_new {
            l.unlisted += 1;
        } else {
            l.stiffness += 1;
        }
        let target = if capped {
            self.max_stride
        } else {
            (allowed.floor() as u64).max(1)
        };
        if target < self.stride {
            self.stride = target;
            self.stride_calm = 0;
        } else if target > self.stride {
            self.stride_calm += 1;
            if self.stride_calm >= STRIDE_RAISE_AFTER {
                self.stride += 1;
                self.stride_calm = 0;
            }
        } else {
            self.stride_calm = 0;
        }
    }

    /// Advances `n` base steps (fewer steps when the adaptive step strides), sampling nothing.
    pub fn advance(&mut self, n: u64) -> Result<()> {
        let end = self.step + n;
        while self.step < end {
            self.step_until(end)?;
        }
        Ok(())
    }

    /// The energy ledger now: a full pass over pairs and bonds ([`Self::energy_of_state`]),
    /// or in free flight ([`Self::start_coasting`]) the ledger as it was when free flight
    /// began. Free flight keeps every velocity and every distance inside a fragment, so the
    /// kinetic, bond and broken-bond energy and each fragment's own contact energy are those
    /// of its start; two fragments on crossing paths pass through each other without force,
    /// and their overlap is not energy of the model.
    pub fn energy(&mut self) -> Energy {
        match self.coast_energy {
            Some(e) => e,
            None => self.energy_of_state(),
        }
    }

    /// The energy of the particles as they are (a full pass over pairs and bonds), in free
    /// flight too.
    pub fn energy_of_state(&mut self) -> Energy {
        let t = Instant::now();
        let partials = if self.materials.is_one() {
            self.energy_partials(self.materials.target)
        } else {
            self.energy_partials(self.materials)
        };
        let mut e = Energy {
            broken_j: self.broken_energy,
            absorbed_j: self.absorbed_energy,
            ..Default::default()
        };
        for [k, c, b] in partials {
            e.kinetic_j += k;
            e.contact_j += c;
            e.bond_j += b;
        }
        // The full scene's ledger: `copies` times the quarter's.
        let copies = self.symmetry.copies();
        for x in [
            &mut e.kinetic_j,
            &mut e.contact_j,
            &mut e.bond_j,
            &mut e.broken_j,
            &mut e.absorbed_j,
        ] {
            *x *= copies;
        }
        self.timing.energy += t.elapsed();
        e
    }

    /// Kinetic, contact and bond energy per chunk of particles (of the simulated particles).
    fn energy_partials<L: PairLaw>(&self, law: L) -> Vec<[f64; 3]> {
        let bodies = &self.particles.body;
        let r_eq2 = self.materials.target.r_eq2();
        let p = &self.particles;
        let nl = &self.neighbours;
        let n = p.len();
        (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| {
                let mut kin = 0.0;
                let mut contact = 0.0;
                let mut bond = 0.0;
                for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                    kin += 0.5 * p.mass[i] * p.vel[i].length_squared();
                    let pi = p.pos[i];
                    let ia = law.bond(bodies, i);
                    for &j in nl.of(i) {
                        let j = j as usize;
                        contact += 0.5
                            * law
                                .contact(bodies, i, j)
                                .contact_energy((pi - p.pos[j]).length_squared());
                    }
                    // Pairs and bonds across a mirror plane count one half (crate::symmetry).
                    for &e in nl.images_of(i) {
                        let (j, code) = split_image(e);
                        contact += 0.5
                            * law
                                .contact(bodies, i, j)
                                .contact_energy((pi - reflect(p.pos[j], code)).length_squared());
                    }
                    if let Some(&flags) = p.image_bonds.get(i) {
                        for code in [MIRROR_X, MIRROR_Y] {
                            let (bonded, gone) = image_bond_flags(code);
                            if flags & bonded == 0 {
                                continue;
                            }
                            let r2 = (pi - reflect(pi, code)).length_squared();
                            if r2 < r_eq2 {
                                contact += 0.5 * ia.contact_energy(r2);
                            } else if flags & gone == 0 {
                                bond += 0.5 * ia.spring_energy(r2.sqrt());
                            }
                        }
                    }
                    for m in 0..OWNED_BONDS {
                        let s = p.bonds[i * BONDS_PER_PARTICLE + 2 * m];
                        if s == NO_BOND {
                            continue;
                        }
                        let r2 = (pi - p.pos[(s & INDEX_MASK) as usize]).length_squared();
                        if r2 < r_eq2 {
                            contact += ia.contact_energy(r2);
                        } else if s & BROKEN_FLAG == 0 {
                            bond += ia.spring_energy(r2.sqrt());
                        }
                    }
                }
                [kin, contact, bond]
            })
            .collect()
    }

    /// Checks the ledger against its initial value; an error when it drifted past the guard.
    pub fn check_energy(&self, e: &Energy) -> Result<f64> {
        let e0 = self.energy_initial.total_j();
        let drift = (e.total_j() - e0) / e0.abs().max(f64::MIN_POSITIVE);
        if !drift.is_finite() || drift.abs() > self.max_energy_drift {
            return Err(self.unstable(format!(
                "energy ledger drifted by {:.3e} (limit run.max_energy_drift = {:.3e})",
                drift, self.max_energy_drift
            )));
        }
        Ok(drift)
    }

    /// Whether the debris is in free flight (the ballistic cut-off): no fragment is held
    /// ([`Self::fragments_held`]). `labels` as there. Bonds breaking recently is the caller's
    /// check.
    pub fn fragments_separating(&self, labels: &[u32]) -> bool {
        !self.fragments_held(labels).contains(&true)
    }

    /// Per fragment label, whether the fragment is held: a particle of it is in contact
    /// (closer than r_eq) with a particle of another fragment, or closing in on one within
    /// the neighbour-list radius or across a bond slot, judged by the fragments'
    /// centre-of-mass velocities. `labels[i]` is the fragment of particle i (any id below the
    /// particle count, e.g. [`crate::cloud::label_fragments`]); the result is indexed by label.
    ///
    /// Under quarter symmetry the pairs with images count too: particle i and the image M j
    /// are of one fragment of the full scene when j is of i's fragment and that fragment spans
    /// every plane M reflects across (it is bonded to its own image there).
    pub fn fragments_held(&self, labels: &[u32]) -> Vec<bool> {
        let p = &self.particles;
        let (cm, spans) = fragment_velocities(p, labels);
        let r_eq2 = self.materials.target.r_eq2();
        let nl = &self.neighbours;
        let held_labels: Vec<u32> = (0..p.len())
            .into_par_iter()
            .filter(|&i| {
                let li = labels[i];
                let touching = |j: usize, code: u32| {
                    let lj = labels[j];
                    if lj == li && code & !spans[li as usize] == 0 {
                        return false;
                    }
                    let d = p.pos[i] - reflect(p.pos[j], code);
                    let closing = cm[li as usize] - reflect(cm[lj as usize], code);
                    d.length_squared() < r_eq2 || d.dot(closing) < 0.0
                };
                nl.of(i).iter().any(|&j| touching(j as usize, 0))
                    || nl.images_of(i).iter().any(|&e| {
                        let (j, code) = split_image(e);
                        touching(j, code)
                    })
                    || p.bonds[i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE]
                        .iter()
                        .any(|&s| s != NO_BOND && touching((s & INDEX_MASK) as usize, 0))
            })
            .map(|i| labels[i])
            .collect();
        let mut held = vec![false; p.len()];
        for l in held_labels {
            held[l as usize] = true;
        }
        held
    }

    /// Switches to free flight (the ballistic cut-off): from now on every step
    /// moves each fragment rigidly with its centre-of-mass velocity instead of computing
    /// forces. Internal distances, hence contact and bond energy, the bonds and the fragments
    /// themselves, are unchanged, and so is every particle's velocity: the energy ledger and
    /// momentum stay exactly those at the cut-off. What is dropped is each fragment's rotation
    /// and internal vibration, which moves a particle by at most its fragment's size times the
    /// angle turned: far below the cloud's extent. Observables that are quantiles of particle
    /// positions (front, La, Lr) and fragment counts are therefore unchanged to that order.
    /// `labels` as for [`Self::fragments_separating`].
    pub fn start_coasting(&mut self, labels: &[u32]) {
        let (cm, _) = fragment_velocities(&self.particles, labels);
        self.coast_energy = Some(self.energy_of_state());
        self.coast_velocity = labels.iter().map(|&l| cm[l as usize]).collect();
        self.coast_from_step = Some(self.step);
    }

    /// The step at which free flight began, if it did.
    pub fn coasting_since(&self) -> Option<u64> {
        self.coast_from_step
    }

    fn coast_step(&mut self, base_steps: u64) {
        let t = Instant::now();
        let dt = self.dt * base_steps as f64;
        self.particles
            .pos
            .par_chunks_mut(CHUNK)
            .zip(self.coast_velocity.par_chunks(CHUNK))
            .for_each(|(x, v)| {
                for (x, v) in x.iter_mut().zip(v) {
                    *x += *v * dt;
                }
            });
        self.step += base_steps;
        self.steps_taken += 1;
        self.timing.integrate += t.elapsed();
    }

    /// The particles of the full scene: the simulated ones, or under quarter symmetry the
    /// quarter with its three mirror images ([`crate::symmetry::unfold`]). What the cloud's
    /// measurement and every output read.
    pub fn full_particles(&self) -> Cow<'_, Particles> {
        match self.symmetry {
            Symmetry::Full => Cow::Borrowed(&self.particles),
            Symmetry::Quarter => Cow::Owned(unfold(&self.particles)),
        }
    }

    /// [`Self::rim_ids`] in the numbering of [`Self::full_particles`].
    pub fn full_rim_ids(&self) -> Cow<'_, [u32]> {
        match self.symmetry {
            Symmetry::Full => Cow::Borrowed(&self.rim_ids),
            Symmetry::Quarter => Cow::Owned(unfold_ids(&self.rim_ids, self.particles.len())),
        }
    }

    /// Particles of the full scene ([`Self::full_particles`]' count).
    pub fn full_particle_count(&self) -> usize {
        (self.symmetry.copies() as usize) * self.particles.len()
    }

    /// Total momentum of the full scene, kg m/s (under quarter symmetry its x and y
    /// components are zero by symmetry and z is four times the quarter's).
    pub fn momentum(&self) -> DVec3 {
        let p = &self.particles;
        let n = p.len();
        let partials: Vec<DVec3> = (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| {
                let mut m = DVec3::ZERO;
                for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                    m += p.vel[i] * p.mass[i];
                }
                m
            })
            .collect();
        let p = partials.into_iter().fold(DVec3::ZERO, |a, b| a + b);
        match self.symmetry {
            Symmetry::Full => p,
            Symmetry::Quarter => DVec3::new(0.0, 0.0, self.symmetry.copies() * p.z),
        }
    }
}

simd::kernel! {
    /// The bond kernel over one chunk of particles starting at index `base`: F/r of each owned
    /// slot into `fr`, in blocks of `BLOCK_BONDS` bonds; breaks are booked in the result.
    fn bond_chunk<L: PairLaw>(
        law: &L,
        bodies: &[Body],
        pos: &[DVec3],
        base: usize,
        bonds: &mut [u32],
        fr: &mut [f64],
    ) -> BondPartial = bond_chunk_body;
}

/// [`bond_chunk`] as compiled for the instruction set it is called from.
#[inline(always)]
fn bond_chunk_body<L: PairLaw>(
    law: &L,
    bodies: &[Body],
    pos: &[DVec3],
    base: usize,
    bonds: &mut [u32],
    fr: &mut [f64],
) -> BondPartial {
    // One lattice: r_eq is every body's.
    let r_eq2 = law.bond(bodies, base).r_eq2();
    let mut part = BondPartial {
        min_r2: f64::INFINITY,
        ..Default::default()
    };
    let nb_total = fr.len();
    let mut b0 = 0;
    while b0 < nb_total {
        let nb = (nb_total - b0).min(BLOCK_BONDS);
        // Stage 1 (scalar gathers): separation, squared distance and which law
        // applies. Breaks are booked here (rare, so the branch predicts well).
        let mut r2s = [r_eq2; BLOCK_BONDS];
        let mut w_contact = [0.0f64; BLOCK_BONDS];
        let mut w_spring = [0.0f64; BLOCK_BONDS];
        for b in 0..nb {
            let owned = b0 + b;
            let (k, m) = (owned / OWNED_BONDS, owned % OWNED_BONDS);
            let slot = &mut bonds[k * BONDS_PER_PARTICLE + 2 * m];
            let s = *slot;
            if s == NO_BOND {
                continue;
            }
            let d = pos[base + k] - pos[(s & INDEX_MASK) as usize];
            let r2 = d.length_squared();
            let intact = s & BROKEN_FLAG == 0;
            let ia = law.bond(bodies, base + k);
            if intact && r2 > ia.rcut2() {
                *slot = s | BROKEN_FLAG;
                part.broken += 1;
                // Book the energy the bond holds at rcut (docs/model.md section 3), not at the
                // overshoot r2 > rcut2: velocity Verlet's trapezoidal work over the
                // step in which the force drops to zero matches E(rcut) to O(dt^2),
                // while E(r) over-books by about kappa (rcut - r_eq) dr / 2.
                part.broken_energy += ia.break_energy_at_rcut();
                continue;
            }
            // Compressed (intact or just broken): contact repulsion; stretched and
            // intact: spring; stretched and broken: nothing.
            let compressed = f64::from(u8::from(r2 < r_eq2));
            r2s[b] = r2;
            w_contact[b] = compressed;
            w_spring[b] = (1.0 - compressed) * f64::from(u8::from(intact));
            part.min_r2 = part.min_r2.min(r2);
        }
        // Stage 2 (vectorised): both laws for every bond, blended by weight. A
        // branch here would be mispredicted half the time in a hot lattice.
        let fr = &mut fr[b0..b0 + nb];
        for b in 0..nb {
            let ia = law.bond(bodies, base + (b0 + b) / OWNED_BONDS);
            let (fc, fs) = ia.contact_and_spring_force_over_r(r2s[b]);
            fr[b] = w_contact[b] * fc + w_spring[b] * fs;
        }
        b0 += nb;
    }
    part
}

/// What the contact pass reads ([`contact_chunk`]).
struct ContactInputs<'a, L> {
    law: L,
    bodies: &'a [Body],
    pos: &'a [DVec3],
    nl: &'a NeighbourList,
    fr_bond: &'a [f64],
    bonds: &'a [u32],
    inv_mass: &'a [f64],
    mass: &'a [f64],
    damping: &'a [f64],
    /// Whether the absorbing band damps this kick.
    damp: bool,
    image_bonds: &'a [u8],
    /// Quarter symmetry: the image pairs and bonds too.
    mirrored: bool,
    half_dt: f64,
}

simd::kernel! {
    /// The contact pass over the chunk of particles from `base` (their `force` and `vel`): per
    /// particle the contact repulsion over its list, the bond forces gathered from its slots, the
    /// image pairs' and bonds' forces under quarter symmetry, and the second half-kick with the
    /// band's damping. Returns the chunk's closest listed pair (squared) and the energy the band
    /// took out.
    fn contact_chunk<L: PairLaw>(
        inputs: &ContactInputs<L>,
        base: usize,
        force: &mut [DVec3],
        vel: &mut [DVec3],
    ) -> (f64, f64) = contact_chunk_body;
}

/// [`contact_chunk`] as compiled for the instruction set it is called from.
#[inline(always)]
fn contact_chunk_body<L: PairLaw>(
    inputs: &ContactInputs<L>,
    base: usize,
    force: &mut [DVec3],
    vel: &mut [DVec3],
) -> (f64, f64) {
    let ContactInputs {
        law,
        bodies,
        pos,
        nl,
        fr_bond,
        bonds,
        inv_mass,
        mass,
        damping,
        damp,
        image_bonds,
        mirrored,
        half_dt,
    } = *inputs;
    let mut min_r2 = f64::INFINITY;
    let mut absorbed = 0.0;
    for (k, (f_out, v)) in force.iter_mut().zip(vel.iter_mut()).enumerate() {
        let i = base + k;
        let f = contact_force(&law, bodies, pos, i, nl.of(i), &mut min_r2);
        let slots = &bonds[i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE];
        let mut f = add_bond_forces(f, pos, i, slots, fr_bond);
        if mirrored {
            f += image_force(
                &law,
                bodies,
                pos,
                i,
                nl.images_of(i),
                image_bonds[i],
                &mut min_r2,
            );
        }
        *f_out = f;
        *v += f * (half_dt * inv_mass[i]);
        if damp && damping[i] > 0.0 {
            absorbed += band::damp(v, damping[i], 2.0 * half_dt, mass[i]);
        }
    }
    (min_r2, absorbed)
}

/// The contact repulsion on particle `i` from the pairs of its neighbour list `list`;
/// lowers `min_r2` to the closest listed pair's squared distance.
#[inline(always)]
fn contact_force<L: PairLaw>(
    law: &L,
    bodies: &[Body],
    pos: &[DVec3],
    i: usize,
    list: &[u32],
    min_r2: &mut f64,
) -> DVec3 {
    let r_eq2 = law.bond(bodies, i).r_eq2();
    let pi = pos[i];
    let mut closest = *min_r2;
    let mut f = DVec3::ZERO;
    // Most listed pairs are out of contact in the cloud (the skin): a branch-free pass
    // finds the pairs in contact (a bit each), then only they get the force. Leaving out
    // the others' zero force leaves f as it is (f starts at +0, and a sum is -0 only if
    // both terms are).
    for list in list.chunks(64) {
        let mut contact = 0u64;
        for (k, &j) in list.iter().enumerate() {
            let r2 = (pi - pos[j as usize]).length_squared();
            // Not f64::min: a NaN r2 leaves `closest` as f64::min would, without its fix-up.
            closest = if r2 < closest { r2 } else { closest };
            contact |= u64::from(r2 < r_eq2) << k;
        }
        while contact != 0 {
            let j = list[contact.trailing_zeros() as usize] as usize;
            contact &= contact - 1;
            let d = pi - pos[j];
            f += d * law
                .contact(bodies, i, j)
                .contact_force_over_r(d.length_squared());
        }
    }
    *min_r2 = closest;
    f
}

/// Adds to `f` the bond forces on particle `i` from its bond `slots`: each slot's F/r (the
/// owner's, from `fr_bond`) times the separation.
#[inline(always)]
fn add_bond_forces(mut f: DVec3, pos: &[DVec3], i: usize, slots: &[u32], fr_bond: &[f64]) -> DVec3 {
    let pi = pos[i];
    let slots: &[u32; BONDS_PER_PARTICLE] = slots.try_into().expect("a particle's slots");
    let own: &[f64; OWNED_BONDS] = fr_bond[i * OWNED_BONDS..(i + 1) * OWNED_BONDS]
        .try_into()
        .expect("a particle's owned bonds");
    // Without a branch per slot (empty slots are scattered through a cloud, so a branch
    // would often be mispredicted): an empty slot stands for the particle itself, whose
    // separation is +0, so its term is a zero, and adding a zero leaves `f` as it is (f starts
    // at +0 and is never -0: a sum is -0 only if both terms are).
    for m in 0..OWNED_BONDS {
        let owned = slots[2 * m];
        let j = if owned == NO_BOND {
            i
        } else {
            (owned & INDEX_MASK) as usize
        };
        f += (pi - pos[j]) * own[m];
        let mirror = slots[2 * m + 1];
        let j = if mirror == NO_BOND {
            i
        } else {
            mirror as usize
        };
        f += (pi - pos[j]) * fr_bond[j * OWNED_BONDS + m];
    }
    f
}

/// The repulsion and image-bond force on particle `i` from across the mirror planes (quarter
/// symmetry): the contact force of each image pair in `images`, and of each image bond in
/// `flags` the same law as an ordinary bond (repulsion when compressed, the spring when
/// stretched and intact, nothing when broken and stretched). Lowers `min_r2` to the closest
/// such pair's squared distance.
#[inline(always)]
fn image_force<L: PairLaw>(
    law: &L,
    bodies: &[Body],
    pos: &[DVec3],
    i: usize,
    images: &[u32],
    flags: u8,
    min_r2: &mut f64,
) -> DVec3 {
    let ia = law.bond(bodies, i);
    let r_eq2 = ia.r_eq2();
    let pi = pos[i];
    let mut f = DVec3::ZERO;
    for &e in images {
        let (j, code) = split_image(e);
        let d = pi - reflect(pos[j], code);
        let r2 = d.length_squared();
        *min_r2 = min_r2.min(r2);
        if r2 < r_eq2 {
            f += d * law.contact(bodies, i, j).contact_force_over_r(r2);
        }
    }
    for code in [MIRROR_X, MIRROR_Y] {
        let (bond, gone) = image_bond_flags(code);
        if flags & bond == 0 {
            continue;
        }
        let d = pi - reflect(pi, code);
        let r2 = d.length_squared();
        *min_r2 = min_r2.min(r2);
        let (fc, fs) = ia.contact_and_spring_force_over_r(r2);
        if r2 < r_eq2 {
            f += d * fc;
        } else if flags & gone == 0 {
            f += d * fs;
        }
    }
    f
}

/// Centre-of-mass velocity of each fragment label (indexed by label) in the full scene,
/// summed in index order, and each label's mirror planes: under quarter symmetry a fragment
/// bonded to its own image across a plane is one fragment with it in the full scene, so its
/// velocity across that plane is zero (the bits `MIRROR_X`, `MIRROR_Y` of the planes it
/// spans; 0 for a full scene).
fn fragment_velocities(p: &Particles, labels: &[u32]) -> (Vec<DVec3>, Vec<u32>) {
    let n = p.len();
    let mut momentum = vec![DVec3::ZERO; n];
    let mut mass = vec![0.0f64; n];
    for ((&l, &v), &m) in labels.iter().zip(&p.vel).zip(&p.mass) {
        momentum[l as usize] += v * m;
        mass[l as usize] += m;
    }
    let mut spans = vec![0u32; n];
    for (&l, &f) in labels.iter().zip(&p.image_bonds) {
        for code in [MIRROR_X, MIRROR_Y] {
            if image_bond_intact(f, code) {
                spans[l as usize] |= code;
            }
        }
    }
    let cm = momentum
        .iter()
        .zip(&mass)
        .zip(&spans)
        .map(|((&q, &m), &s)| {
            let v = if m > 0.0 { q / m } else { DVec3::ZERO };
            // The mean of the fragment and its image across each plane it spans.
            0.5 * (v + reflect(v, s))
        })
        .collect();
    (cm, spans)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneSpec;

    /// The kernels' body-by-body path ([`Materials`]) computes bit for bit what the one-law
    /// path computes when the two bodies are of one material: forces, breaks, the closest
    /// pair and the ledger, on a lattice in the middle of the impact (contacts, stretched and
    /// broken bonds, both bodies).
    #[test]
    fn the_two_material_path_is_the_one_law_path_for_one_material() {
        let spec = SceneSpec::calibration(2000.0, 1e-6);
        let mut sim = Simulation::new(spec.build().expect("valid")).expect("starts");
        sim.advance(300).expect("stable");
        assert!(sim.bonds_broken > 0, "mid-impact");
        let one = sim.materials.target;
        let laws = Materials::from(one);
        let pos = sim.particles.pos.clone();
        let bodies = sim.particles.body.clone();
        let n = pos.len();
        let (mut bonds_a, mut bonds_b) = (sim.particles.bonds.clone(), sim.particles.bonds.clone());
        let (mut fr_a, mut fr_b) = (vec![0.0; n * OWNED_BONDS], vec![0.0; n * OWNED_BONDS]);
        let a = bond_chunk(&one, &bodies, &pos, 0, &mut bonds_a, &mut fr_a);
        let b = bond_chunk(&laws, &bodies, &pos, 0, &mut bonds_b, &mut fr_b);
        assert_eq!(bonds_a, bonds_b);
        assert_eq!(
            (a.broken, a.broken_energy.to_bits(), a.min_r2.to_bits()),
            (b.broken, b.broken_energy.to_bits(), b.min_r2.to_bits())
        );
        assert_eq!(
            fr_a.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            fr_b.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        let mut contacts = 0;
        for i in 0..n {
            let list = sim.neighbours.of(i);
            let (mut ra, mut rb) = (f64::INFINITY, f64::INFINITY);
            let fa = contact_force(&one, &bodies, &pos, i, list, &mut ra);
            let fb = contact_force(&laws, &bodies, &pos, i, list, &mut rb);
            assert_eq!(
                fa.to_array().map(f64::to_bits),
                fb.to_array().map(f64::to_bits)
            );
            assert_eq!(ra.to_bits(), rb.to_bits());
            contacts += usize::from(fa != DVec3::ZERO);
        }
        assert!(contacts > 0, "some particles are in contact");
        let (ea, eb) = (sim.energy_partials(one), sim.energy_partials(laws));
        assert_eq!(
            ea.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>(),
            eb.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
    }
}
