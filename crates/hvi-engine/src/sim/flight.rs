//! Per-fragment free flight (`run.free_flight_every_s`): fragments that have separated for good
//! move rigidly and cost no force evaluation, while the rest of the scene is integrated as
//! before.
//!
//! # The rule
//!
//! Every `run.free_flight_every_s` after first contact the fragments are labelled
//! ([`crate::cloud::Labeller`]) and a fragment starts free flight when
//! - it is not the residual plate (it holds no particle of the plate's outer rim);
//! - none of its particles is in contact (closer than r_eq) with a particle of another
//!   fragment, and every such pair of the neighbour list (and of broken bonds since the last
//!   build) recedes, judged by the two fragments' centre-of-mass velocities;
//! - its internal energy (kinetic energy relative to its centre of mass, plus the energy of its
//!   bonds and of its own pairs in contact) is below the energy that breaks one bond: such a
//!   fragment can never break, whatever its internal motion does.
//!
//! Each of its particles then takes the fragment's centre-of-mass velocity: momentum is
//! unchanged, and the internal kinetic energy (vibration and rotation) leaves the kinetic term
//! of the ledger for a term of its own, `frozen_j`, so the ledger stays closed. A lone particle
//! has none: its free flight is exact. The fragment's internal distances, hence its bond and
//! contact energies, stay as they were; its force is not computed and its bonds are not checked
//! (they cannot break).
//!
//! # Exactness towards the rest
//!
//! A particle in free flight stays in the neighbour list and in its rebuild rule, so every pair
//! that comes within the contact radius is listed first. Before each force evaluation the pairs
//! of a particle in free flight with a particle of another fragment that can still meet it
//! (the watch: every listed pair and broken bond with an active particle, or with a particle in
//! free flight of another fragment that is closing in) are checked, and a fragment with such a
//! pair closer than r_eq is woken, with the other fragment if that one flies too, before the
//! forces are computed. So no force ever acts on one side of a pair only: momentum is conserved
//! to round-off. A woken fragment carries on from its rigid position with the centre-of-mass
//! velocity; its frozen energy stays booked.
//!
//! The adaptive step leaves out the pairs that can never meet (one fragment in free flight, or
//! two receding ones, [`crate::state::never_meet`]), which is where the stride gains: the
//! separated debris no longer holds it down.

use std::collections::HashSet;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::Simulation;
use crate::cloud::Labeller;
use crate::state::{never_meet, ACTIVE, BONDS_PER_PARTICLE, BROKEN_FLAG, INDEX_MASK, NO_BOND};

/// What per-fragment free flight did in a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FreeFlightStats {
    /// Checks made (labelling the fragments each time).
    pub checks: u64,
    /// Fragments that started free flight.
    pub started: u64,
    /// Fragments woken by a contact.
    pub woken: u64,
    /// Particles in free flight now (of the simulated scene).
    pub particles_now: u64,
}

/// Per-fragment sums of a check, indexed by fragment label.
#[derive(Default)]
struct FragmentSums {
    mass: Vec<f64>,
    momentum: Vec<DVec3>,
    internal: Vec<f64>,
    kinetic_internal: Vec<f64>,
    held: Vec<bool>,
}

impl Simulation {
    /// Whether per-fragment free flight is on for this run.
    pub fn has_free_flight(&self) -> bool {
        self.free_flight_every > 0
    }

    /// What per-fragment free flight did so far.
    pub fn free_flight_stats(&self) -> FreeFlightStats {
        let mut s = self.free_flight_stats;
        s.particles_now = self
            .particles
            .free_flight
            .iter()
            .filter(|&&f| f != ACTIVE)
            .count() as u64;
        s
    }

    /// Whether the step that just ended at `self.step` after `m` base steps crossed a check time
    /// (a multiple of the check interval after first contact).
    pub(super) fn free_flight_due(&self, m: u64) -> bool {
        let every = self.free_flight_every;
        if every == 0 {
            return false;
        }
        let contact = self.contact_step;
        let (now, before) = (self.step, self.step.saturating_sub(m));
        now > contact && (now - contact) / every > before.saturating_sub(contact) / every
    }

    /// Starts free flight for every fragment that qualifies (see the module's rule). Returns
    /// whether any did.
    pub(super) fn start_free_flight(&mut self) -> bool {
        let t = Instant::now();
        self.free_flight_stats.checks += 1;
        let mut labels = Vec::new();
        Labeller::default().label(&self.particles, &mut labels);
        let sums = self.fragment_sums(&labels);
        let break_energy = self.interaction.break_energy_at_rcut();
        let flies = |l: u32| {
            let l = l as usize;
            !sums.held[l] && sums.internal[l] < break_energy
        };
        let p = &mut self.particles;
        let mut started: HashSet<u32> = HashSet::new();
        let mut frozen = 0.0;
        for i in 0..p.len() {
            let l = labels[i];
            if p.free_flight[i] != ACTIVE || !flies(l) {
                continue;
            }
            if started.insert(l) {
                frozen += sums.kinetic_internal[l as usize];
            }
            p.free_flight[i] = l;
            p.vel[i] = sums.momentum[l as usize] / sums.mass[l as usize];
        }
        self.frozen_energy += frozen;
        self.free_flight_stats.started += started.len() as u64;
        let any = !started.is_empty();
        if any {
            self.refresh_watch();
        }
        self.timing.integrate += t.elapsed();
        any
    }

    /// Mass, momentum and internal energy of each fragment, and whether it is held: the
    /// residual plate, in free flight already, or touching or closing in on another fragment.
    fn fragment_sums(&self, labels: &[u32]) -> FragmentSums {
        let p = &self.particles;
        let n = p.len();
        let mut s = FragmentSums {
            mass: vec![0.0; n],
            momentum: vec![DVec3::ZERO; n],
            internal: vec![0.0; n],
            kinetic_internal: vec![0.0; n],
            held: vec![false; n],
        };
        for i in 0..n {
            let l = labels[i] as usize;
            s.mass[l] += p.mass[i];
            s.momentum[l] += p.vel[i] * p.mass[i];
            if p.free_flight[i] != ACTIVE || self.rim_by_id[p.id[i] as usize] {
                s.held[l] = true;
            }
        }
        let cm = |l: u32| {
            let l = l as usize;
            s.momentum[l] / s.mass[l]
        };
        let ia = self.interaction;
        let r_eq2 = ia.r_eq2();
        let nl = &self.neighbours;
        let mut held_now: Vec<u32> = Vec::new();
        let (mut internal, mut kinetic) = (vec![0.0; n], vec![0.0; n]);
        for i in 0..n {
            let li = labels[i];
            let k = 0.5 * p.mass[i] * (p.vel[i] - cm(li)).length_squared();
            kinetic[li as usize] += k;
            internal[li as usize] += k;
            let pi = p.pos[i];
            let mut other = |j: usize| {
                let d = pi - p.pos[j];
                if d.length_squared() < r_eq2 || d.dot(cm(li) - cm(labels[j])) < 0.0 {
                    held_now.push(li);
                }
            };
            for &j in nl.of(i) {
                let j = j as usize;
                if labels[j] != li {
                    other(j);
                } else if j > i {
                    internal[li as usize] += ia.contact_energy((pi - p.pos[j]).length_squared());
                }
            }
            for m in 0..crate::state::OWNED_BONDS {
                for slot in [2 * m, 2 * m + 1] {
                    let s = p.bonds[i * BONDS_PER_PARTICLE + slot];
                    if s == NO_BOND {
                        continue;
                    }
                    let j = (s & INDEX_MASK) as usize;
                    if labels[j] != li {
                        other(j);
                    } else if slot % 2 == 0 {
                        let r2 = (pi - p.pos[j]).length_squared();
                        internal[li as usize] += if r2 < r_eq2 {
                            ia.contact_energy(r2)
                        } else if s & BROKEN_FLAG == 0 {
                            ia.spring_energy(r2.sqrt())
                        } else {
                            0.0
                        };
                    }
                }
            }
        }
        for l in held_now {
            s.held[l as usize] = true;
        }
        s.internal = internal;
        s.kinetic_internal = kinetic;
        s
    }

    /// The watch: pairs (i, j) of a particle i in free flight and a particle j of another
    /// fragment that can still meet it, from the neighbour list and the bonds broken since the
    /// last build. Recomputed after every build, start and wake.
    pub(super) fn refresh_watch(&mut self) {
        let p = &self.particles;
        let ff = &p.free_flight;
        let nl = &self.neighbours;
        let watch: Vec<Vec<(u32, u32)>> = (0..p.len())
            .into_par_iter()
            .with_min_len(1024)
            .filter(|&i| ff[i] != ACTIVE)
            .map(|i| {
                let mut out = Vec::new();
                let mut consider = |j: usize| {
                    if ff[j] != ff[i]
                        && !never_meet(ff, i, j, p.pos[i] - p.pos[j], p.vel[i] - p.vel[j])
                    {
                        out.push((i as u32, j as u32));
                    }
                };
                for &j in nl.of(i) {
                    consider(j as usize);
                }
                for &s in &p.bonds[i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE] {
                    if s != NO_BOND {
                        consider((s & INDEX_MASK) as usize);
                    }
                }
                out
            })
            .collect();
        self.free_flight_watch = watch.into_iter().flatten().collect();
    }

    /// Wakes every fragment in free flight that a watched pair brought within r_eq (and the
    /// other fragment of the pair when it flies too), before the forces are computed. Returns
    /// whether any woke.
    pub(super) fn wake_touching(&mut self) -> bool {
        let r_eq2 = self.interaction.r_eq2();
        let p = &self.particles;
        let ff = &p.free_flight;
        let mut woken: Vec<u32> = self
            .free_flight_watch
            .par_iter()
            .filter(|&&(i, j)| (p.pos[i as usize] - p.pos[j as usize]).length_squared() < r_eq2)
            .flat_map_iter(|&(i, j)| [ff[i as usize], ff[j as usize]])
            .filter(|&l| l != ACTIVE)
            .collect();
        if woken.is_empty() {
            return false;
        }
        woken.sort_unstable();
        woken.dedup();
        self.free_flight_stats.woken += woken.len() as u64;
        self.particles.free_flight.par_iter_mut().for_each(|f| {
            if *f != ACTIVE && woken.binary_search(f).is_ok() {
                *f = ACTIVE;
            }
        });
        self.refresh_watch();
        true
    }
}
