//! The state of a running simulation that its future depends on, for checkpoints
//! (`hvi_run::checkpoint`). Saved between two steps and restored into a simulation built from
//! the same scene, the run continues bit-identically: the particles in their current order with
//! the forces of the last step (velocity Verlet's first half-kick uses them), the neighbour list
//! as built ([`NeighbourState`]), the adaptive step's memory, the ledger's bookings and the
//! free flight's velocities and ledger. What a scene fixes (the interaction, the derived numbers, the rim)
//! and scratch space are rebuilt from the scene.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::{Energy, Simulation, StrideLimits, Timing};
use crate::error::{EngineError, Result};
use crate::neighbour::NeighbourState;
use crate::state::{Particles, BONDS_PER_PARTICLE, INDEX_MASK, NO_BOND};

/// A simulation's state between two steps ([`Simulation::save_state`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SimState {
    particles: Particles,
    neighbours: NeighbourState,
    since_build_s: f64,
    step: u64,
    steps_taken: u64,
    stride: u64,
    largest_stride: u64,
    stride_limits: StrideLimits,
    stride_calm: u32,
    last_min_r2: f64,
    vel_at_build: Vec<DVec3>,
    #[serde(default)]
    speed_refreshes: u64,
    bonds_broken: u64,
    coast_velocity: Vec<DVec3>,
    coast_from_step: Option<u64>,
    coast_energy: Option<Energy>,
    broken_energy: f64,
    #[serde(default)]
    absorbed_energy: f64,
    energy_initial: Energy,
    momentum_initial: DVec3,
    timing: Timing,
}

impl SimState {
    /// The base step it was saved at.
    pub fn step(&self) -> u64 {
        self.step
    }

    /// Its particle count.
    pub fn particles(&self) -> usize {
        self.particles.len()
    }

    /// Whether it can be restored into a simulation of `n` particles: every array of the
    /// right length and every index in range (a damaged or foreign state is refused, never
    /// half restored).
    fn fits(&self, n: usize) -> std::result::Result<(), String> {
        let p = &self.particles;
        let lengths = [
            p.pos.len(),
            p.vel.len(),
            p.force.len(),
            p.mass.len(),
            p.inv_mass.len(),
            p.body.len(),
            p.id.len(),
        ];
        if lengths.iter().any(|&l| l != n) || p.bonds.len() != n * BONDS_PER_PARTICLE {
            return Err(format!(
                "it holds {} particles, the scene {n}",
                self.particles.len()
            ));
        }
        let mut seen = vec![false; n];
        for &id in &p.id {
            match seen.get_mut(id as usize) {
                Some(s) if !*s => *s = true,
                _ => return Err("its particle ids are not a permutation".into()),
            }
        }
        if p.bonds
            .iter()
            .any(|&b| b != NO_BOND && (b & INDEX_MASK) as usize >= n)
        {
            return Err("its bonds name particles beyond the count".into());
        }
        for (what, v) in [
            ("velocities at the last build", &self.vel_at_build),
            ("free-flight velocities", &self.coast_velocity),
        ] {
            if !v.is_empty() && v.len() != n {
                return Err(format!("its {what} are not of {n} particles"));
            }
        }
        if self.stride == 0 || self.steps_taken > self.step {
            return Err("its step counters are inconsistent".into());
        }
        self.neighbours.fits(n)
    }
}

impl Simulation {
    /// The state between two steps, to continue from later ([`Self::restore_state`]).
    pub fn save_state(&self) -> SimState {
        SimState {
            particles: self.particles.clone(),
            neighbours: self.neighbours.save_state(),
            since_build_s: self.since_build_s,
            step: self.step,
            steps_taken: self.steps_taken,
            stride: self.stride,
            largest_stride: self.largest_stride,
            stride_limits: self.stride_limits,
            stride_calm: self.stride_calm,
            last_min_r2: self.last_min_r2,
            vel_at_build: self.vel_at_build.clone(),
            speed_refreshes: self.speed_refreshes,
            bonds_broken: self.bonds_broken,
            coast_velocity: self.coast_velocity.clone(),
            coast_from_step: self.coast_from_step,
            coast_energy: self.coast_energy,
            broken_energy: self.broken_energy,
            absorbed_energy: self.absorbed_energy,
            energy_initial: self.energy_initial,
            momentum_initial: self.momentum_initial,
            timing: self.timing,
        }
    }

    /// Continues from a saved state: this simulation (built from the same scene) takes it over
    /// and then steps exactly as the one it was saved from would have. Refused, with the
    /// simulation unchanged, when the state is not of this scene's particle count or is not
    /// well formed.
    ///
    /// ```
    /// use hvi_engine::scene::SceneSpec;
    /// use hvi_engine::sim::Simulation;
    ///
    /// let spec = SceneSpec::calibration(500.0, 1e-7);
    /// let mut a = Simulation::new(spec.build()?)?;
    /// a.advance(10)?;
    /// let saved = a.save_state();
    /// a.advance(10)?;
    /// let mut b = Simulation::new(spec.build()?)?;
    /// b.restore_state(saved)?;
    /// b.advance(10)?;
    /// assert_eq!(a.particles.pos, b.particles.pos);
    /// # Ok::<(), hvi_engine::EngineError>(())
    /// ```
    pub fn restore_state(&mut self, s: SimState) -> Result<()> {
        s.fits(self.particles.len())
            .map_err(EngineError::StateMismatch)?;
        self.particles = s.particles;
        self.neighbours.restore_state(s.neighbours);
        self.since_build_s = s.since_build_s;
        self.step = s.step;
        self.steps_taken = s.steps_taken;
        self.stride = s.stride;
        self.largest_stride = s.largest_stride;
        self.stride_limits = s.stride_limits;
        self.stride_calm = s.stride_calm;
        self.last_min_r2 = s.last_min_r2;
        self.vel_at_build = s.vel_at_build;
        self.speed_refreshes = s.speed_refreshes;
        self.bonds_broken = s.bonds_broken;
        self.coast_velocity = s.coast_velocity;
        self.coast_from_step = s.coast_from_step;
        self.coast_energy = s.coast_energy;
        self.broken_energy = s.broken_energy;
        self.absorbed_energy = s.absorbed_energy;
        self.energy_initial = s.energy_initial;
        self.momentum_initial = s.momentum_initial;
        self.timing = s.timing;
        self.refresh_damping();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::cloud::label_fragments;
    use crate::scene::SceneSpec;
    use crate::sim::Simulation;

    fn bits(sim: &Simulation) -> Vec<u64> {
        let p = &sim.particles;
        p.pos
            .iter()
            .chain(&p.vel)
            .chain(&p.force)
            .flat_map(|v| v.to_array())
            .map(f64::to_bits)
            .collect()
    }

    /// Saved in the adaptive step's impact, in free flight and across a re-sort, a state
    /// restored into a fresh simulation of the scene steps bit for bit as the original; a state
    /// of another particle count is refused and leaves the simulation as it was.
    #[test]
    fn a_restored_state_steps_bit_identically_and_a_foreign_one_is_refused() {
        let mut spec = SceneSpec::calibration(800.0, 1e-6);
        spec.run.max_stride = 8;
        let setup = || Simulation::new(spec.build().expect("builds")).expect("starts");
        let mut a = setup();
        a.advance(150).expect("steps");
        let saved = a.save_state();
        let builds = a.neighbour_builds();
        a.advance(150).expect("steps");
        assert!(a.neighbour_builds() > builds, "no re-sort after the save");
        let labels = label_fragments(&a.particles);
        a.start_coasting(&labels);
        a.advance(40).expect("steps");
        let coasting = a.save_state();
        a.advance(40).expect("steps");

        let mut b = setup();
        b.restore_state(saved).expect("restores");
        b.advance(150).expect("steps");
        b.start_coasting(&label_fragments(&b.particles));
        // Free flight goes to each landing in one step: land where `a` landed.
        b.advance(40).expect("steps");
        b.advance(40).expect("steps");
        assert!(bits(&a) == bits(&b), "restored and original differ");
        assert_eq!((a.step, a.steps_taken), (b.step, b.steps_taken));
        assert_eq!(a.energy(), b.energy());

        let mut c = setup();
        c.restore_state(coasting).expect("restores");
        c.advance(40).expect("steps");
        assert!(
            bits(&a) == bits(&c),
            "restored in free flight and original differ"
        );
        assert_eq!(c.coasting_since(), a.coasting_since());

        let other = SceneSpec::calibration(500.0, 1e-6);
        let foreign = Simulation::new(other.build().expect("builds"))
            .expect("starts")
            .save_state();
        let mut d = setup();
        let before = bits(&d);
        let e = d.restore_state(foreign).expect_err("refused");
        assert!(e.to_string().contains("particles"), "{e}");
        assert!(bits(&d) == before, "a refused state changed the simulation");
    }
}
