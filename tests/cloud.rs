//! Tests of the debris-cloud observables (`hvi_engine::cloud`, docs/model.md section 5): synthetic
//! configurations with known answers (fragments, F, sizes, La, Lr, R, va, outliers), a small
//! real impact (consistency, plausibility, thread independence), and `hvi-study run --render`
//! end to end.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::process::Command;

use glam::DVec3;
use hvi_engine::cloud::{
    extent, find_cloud, label_fragments, measure, size_distribution, CloudObserver, CloudReference,
    CloudResult,
};
use hvi_engine::potential::{ContactForm, Interaction};
use hvi_engine::scene::{Analysis, Derived, RunSettings, SceneSpec, Width};
use hvi_engine::sim::Simulation;
use hvi_engine::state::{Body, Particles, BONDS_PER_PARTICLE, BROKEN_FLAG, NO_BOND};

const SIGMA: f64 = 1e-3;

fn interaction() -> Interaction {
    Interaction::new(SIGMA, 1e-3, 1e4, 1.5 * SIGMA, ContactForm::Printed)
}

/// Hand-made particle sets: particles in insertion order (their id), bonds owned along an axis.
#[derive(Default)]
struct Builder {
    pos: Vec<DVec3>,
    body: Vec<Body>,
    mass: Vec<f64>,
    vel: Vec<DVec3>,
    /// (owner, partner, axis 0/1/2, broken)
    bonds: Vec<(usize, usize, usize, bool)>,
}

impl Builder {
    fn add(&mut self, p: DVec3, body: Body, mass: f64) -> usize {
        self.pos.push(p);
        self.body.push(body);
        self.mass.push(mass);
        self.vel.push(DVec3::ZERO);
        self.pos.len() - 1
    }

    fn bond(&mut self, owner: usize, partner: usize, axis: usize) {
        self.bonds.push((owner, partner, axis, false));
    }

    fn broken_bond(&mut self, owner: usize, partner: usize, axis: usize) {
        self.bonds.push((owner, partner, axis, true));
    }

    /// A lattice block of nx x ny x nz sites at spacing `a` from `origin`, fully bonded.
    fn block(&mut self, origin: DVec3, n: [usize; 3], a: f64, body: Body, mass: f64) -> Vec<usize> {
        let mut ids = Vec::new();
        let at = |i: usize, j: usize, k: usize| (k * n[1] + j) * n[0] + i;
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let p = origin + DVec3::new(i as f64, j as f64, k as f64) * a;
                    ids.push(self.add(p, body, mass));
                }
            }
        }
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let me = ids[at(i, j, k)];
                    if i + 1 < n[0] {
                        self.bond(me, ids[at(i + 1, j, k)], 0);
                    }
                    if j + 1 < n[1] {
                        self.bond(me, ids[at(i, j + 1, k)], 1);
                    }
                    if k + 1 < n[2] {
                        self.bond(me, ids[at(i, j, k + 1)], 2);
                    }
                }
            }
        }
        ids
    }

    /// The particles stored in the order `storage` (storage[k] = id at index k).
    fn build(&self, storage: &[usize]) -> Particles {
        let n = self.pos.len();
        assert_eq!(storage.len(), n);
        let mut index = vec![0usize; n];
        for (k, &id) in storage.iter().enumerate() {
            index[id] = k;
        }
        let mut bonds = vec![NO_BOND; n * BONDS_PER_PARTICLE];
        for &(o, p, axis, broken) in &self.bonds {
            let (i, j) = (index[o], index[p]);
            let owned = &mut bonds[i * BONDS_PER_PARTICLE + 2 * axis];
            assert_eq!(
                *owned, NO_BOND,
                "particle {o} owns two bonds along axis {axis}"
            );
            *owned = j as u32 | if broken { BROKEN_FLAG } else { 0 };
            bonds[j * BONDS_PER_PARTICLE + 2 * axis + 1] = i as u32;
        }
        let mut p = Particles::new(
            storage.iter().map(|&id| self.pos[id]).collect(),
            storage.iter().map(|&id| self.vel[id]).collect(),
            storage.iter().map(|&id| self.mass[id]).collect(),
            storage.iter().map(|&id| self.body[id]).collect(),
            bonds,
        );
        p.id = storage.iter().map(|&id| id as u32).collect();
        p
    }

    fn in_order(&self) -> Particles {
        self.build(&(0..self.pos.len()).collect::<Vec<_>>())
    }
}

/// A fixed shuffle of 0..n (a multiplicative permutation, gcd(step, n) = 1).
fn shuffled(n: usize) -> Vec<usize> {
    let step = (1..n.max(2))
        .rev()
        .find(|s| gcd(*s, n) == 1 && *s > n / 3)
        .unwrap_or(1);
    (0..n).map(|k| (k * step + 7) % n).collect()
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

fn derived_with(rear_z: f64, density: f64, v0: f64) -> Derived {
    let mut d = Derived::for_interaction(&interaction(), 1e-9, 1e-6, 1000);
    d.plate_rear_z_m = rear_z;
    d.density_kg_m3 = density;
    d.v0_m_s = v0;
    d
}

fn by_id(p: &Particles, per_index: &[u32]) -> Vec<u32> {
    let idx = p.index_of_id();
    (0..p.len()).map(|id| per_index[idx[id] as usize]).collect()
}

/// The scene of the cluster tests: a bonded plate with a rim and a bent-back lip, and beyond
/// its rear face clusters of known size. Returns the builder, rim ids and the expected groups.
struct Clusters {
    b: Builder,
    rim: Vec<u32>,
    rear_z: f64,
    cube: Vec<usize>,
    chain: Vec<usize>,
    straddler: Vec<usize>,
    loners: Vec<usize>,
    impactor_mass: f64,
}

const A: f64 = 1e-3;
const M_IMPACTOR: f64 = 2.0e-6;
const M_TARGET: f64 = 3.0e-6;
const DENSITY: f64 = 2700.0;

/// A plate of 6 x 6 x 2 sites, z = 0.5a and 1.5a (rear face at 2a): its sites' ids and its
/// rim's (what holds the residual plate).
fn plate_with_rim(b: &mut Builder) -> (Vec<usize>, Vec<u32>) {
    let plate = b.block(
        DVec3::new(-2.5 * A, -2.5 * A, 0.5 * A),
        [6, 6, 2],
        A,
        Body::Target,
        M_TARGET,
    );
    let rim: Vec<u32> = plate
        .iter()
        .filter(|&&id| {
            let p = b.pos[id];
            p.x.abs().max(p.y.abs()) > 2.0 * A
        })
        .map(|&id| id as u32)
        .collect();
    (plate, rim)
}

fn clusters() -> Clusters {
    let mut b = Builder::default();
    let (plate, rim) = plate_with_rim(&mut b);
    // A lip bent back beyond the rear face, still bonded to the plate: not cloud.
    let anchor = plate[6 * 6 + 2 * 6 + 2]; // rear layer, inner site
    let lip1 = b.add(b.pos[anchor] + DVec3::Z * A, Body::Target, M_TARGET);
    let lip2 = b.add(b.pos[anchor] + DVec3::Z * 2.0 * A, Body::Target, M_TARGET);
    b.bond(anchor, lip1, 2);
    b.bond(lip1, lip2, 2);
    // Beyond the face: a bonded 3x3x3 impactor cube, a 5-chain of plate material, two
    // particles whose bond broke, ten impactor loners.
    let cube = b.block(
        DVec3::new(-A, -A, 10.0 * A),
        [3, 3, 3],
        A,
        Body::Impactor,
        M_IMPACTOR,
    );
    let chain = b.block(
        DVec3::new(5.0 * A, 0.0, 6.0 * A),
        [5, 1, 1],
        A,
        Body::Target,
        M_TARGET,
    );
    let p1 = b.add(DVec3::new(0.0, 6.0 * A, 8.0 * A), Body::Target, M_TARGET);
    let p2 = b.add(DVec3::new(0.0, 7.0 * A, 8.0 * A), Body::Target, M_TARGET);
    b.broken_bond(p1, p2, 1);
    let mut loners = vec![p1, p2];
    for k in 0..10 {
        loners.push(b.add(
            DVec3::new(-6.0 * A, (k as f64 - 5.0) * 1.5 * A, 15.0 * A),
            Body::Impactor,
            M_IMPACTOR,
        ));
    }
    // A chain across the rear face, beside the plate: one site before it, two beyond.
    let straddler = b.block(
        DVec3::new(9.0 * A, 0.0, 1.5 * A),
        [1, 1, 3],
        A,
        Body::Target,
        M_TARGET,
    );
    let impactor_mass = 37.0 * M_IMPACTOR;
    Clusters {
        b,
        rim,
        rear_z: 2.0 * A,
        cube,
        chain,
        straddler,
        loners,
        impactor_mass,
    }
}

fn d_eq(m: f64) -> f64 {
    (6.0 * m / (std::f64::consts::PI * DENSITY)).cbrt()
}

#[test]
fn clusters_of_known_size_give_known_fragments_and_fragmentation() {
    let c = clusters();
    let n = c.b.pos.len();
    let derived = derived_with(c.rear_z, DENSITY, 1000.0);
    let p = c.b.in_order();
    let reference = CloudReference::new(&p, &derived, &c.rim);
    assert!((reference.impactor_mass_kg - c.impactor_mass).abs() < 1e-18);
    let members = find_cloud(&p, &reference);
    let a = measure(&p, &members, &reference, 0.995, Width::Side, 1.0, 1.0);
    let m = &a.measurement;
    // Cloud: cube 27 + chain 5 + 2 broken + 10 loners + 2 of the straddler.
    assert_eq!(m.n_part, 46);
    assert_eq!(m.n_frag, 1 + 1 + 12 + 1);
    assert_eq!(m.fragmentation, Some(15.0 / 46.0));
    assert_eq!(m.fragments_crossing_rear_face, 1);
    // The plate and its lip are the residual plate, never cloud.
    let idx = p.index_of_id();
    for (id, &i) in idx.iter().enumerate().take(72 + 2) {
        let i = i as usize;
        assert!(
            members.in_residual_plate[i] && !members.in_cloud[i],
            "id {id}"
        );
    }
    // Labels are the smallest id of each group.
    let labels = by_id(&p, &label_fragments(&p));
    for group in [&c.cube, &c.chain, &c.straddler] {
        let min = *group.iter().min().expect("group") as u32;
        assert!(group.iter().all(|&id| labels[id] == min));
    }
    for &id in &c.loners {
        assert_eq!(labels[id], id as u32);
    }
    // Sizes, masses, diameters; the largest is the cube.
    let big = &a.fragments[0];
    assert_eq!(big.label, c.cube[0] as u32);
    assert_eq!((big.particles, big.impactor_particles), (27, 27));
    assert!((big.mass_kg - 27.0 * M_IMPACTOR).abs() < 1e-18);
    assert!((big.diameter_m - d_eq(27.0 * M_IMPACTOR)).abs() < 1e-15);
    let share = m.largest_fragment_mass_fraction.expect("largest");
    assert!((share - 27.0 / 37.0).abs() < 1e-12, "{share}");
    assert_eq!(m.largest_fragment_particles, 27);
    // Its centre of mass is the cube's centre.
    let centre = DVec3::new(0.0, 0.0, 11.0 * A);
    assert!((DVec3::from_array(big.centroid_m) - centre).length() < 1e-15);
    let sizes: Vec<usize> = a.fragments.iter().map(|f| f.particles).collect();
    assert_eq!(sizes[..3], [27, 5, 2]);
    assert!(sizes[3..].iter().all(|&s| s == 1));
    // Cloud mass and the mass-weighted mean diameter by hand.
    let groups: Vec<f64> = [27.0 * M_IMPACTOR, 5.0 * M_TARGET, 2.0 * M_TARGET]
        .into_iter()
        .chain([M_TARGET; 2])
        .chain([M_IMPACTOR; 10])
        .collect();
    let mass: f64 = groups.iter().sum();
    assert!((m.mass_kg - mass).abs() < 1e-15 * mass / 1e-6);
    let mean = groups.iter().map(|&g| g * d_eq(g)).sum::<f64>() / mass;
    let got = m.mean_fragment_diameter_m.expect("mean");
    assert!((got - mean).abs() < 1e-12 * mean, "{got} vs {mean}");
    assert!(
        (m.impactor_mass_fraction_in_cloud - 1.0).abs() < 1e-12,
        "all impactor particles are in the cloud"
    );
    // The size distribution.
    let dist = size_distribution(&a.fragments);
    let classes: Vec<(usize, usize)> = dist.iter().map(|c| (c.particles, c.fragments)).collect();
    assert_eq!(classes, vec![(1, 12), (2, 1), (5, 1), (27, 1)]);
    assert!((dist[0].mass_fraction_at_least - 1.0).abs() < 1e-12);
    assert!((dist[3].mass_fraction - 27.0 * M_IMPACTOR / mass).abs() < 1e-12);
    let total: f64 = dist.iter().map(|c| c.mass_fraction).sum();
    assert!((total - 1.0).abs() < 1e-12);
    assert_eq!(n, 72 + 2 + 27 + 5 + 12 + 3);
}

#[test]
fn results_do_not_depend_on_storage_order() {
    let c = clusters();
    let n = c.b.pos.len();
    let derived = derived_with(c.rear_z, DENSITY, 1000.0);
    let orders = [
        (0..n).collect::<Vec<_>>(),
        (0..n).rev().collect(),
        shuffled(n),
    ];
    let mut results = Vec::new();
    for order in &orders {
        let p = c.b.build(order);
        let reference = CloudReference::new(&p, &derived, &c.rim);
        let members = find_cloud(&p, &reference);
        let a = measure(&p, &members, &reference, 0.995, Width::Side, 1.0, 1.0);
        results.push((by_id(&p, &members.labels), a));
    }
    for r in &results[1..] {
        assert_eq!(r.0, results[0].0, "labels by id");
        // Sums run in id order: bit-identical, not merely close.
        assert_eq!(r.1, results[0].1);
    }
}

/// `n` particles beyond `rear`: z spread evenly over (rear, rear + length], distances from the
/// axis evenly over [0, radius] (in another order), at the golden angle around it.
fn known_cloud(b: &mut Builder, n: usize, rear: f64, length: f64, radius: f64) {
    for k in 0..n {
        let z = rear + length * (k + 1) as f64 / n as f64;
        let r = radius * ((k * 7919) % n) as f64 / (n - 1) as f64;
        let phi = 2.399_963_229_728_653 * k as f64;
        b.add(
            DVec3::new(r * phi.cos(), r * phi.sin(), z),
            Body::Target,
            M_TARGET,
        );
    }
}

#[test]
fn cloud_of_known_extent_gives_la_lr_and_r() {
    let (n, rear, length, radius) = (10_000, 4e-3, 0.2, 0.06);
    let mut b = Builder::default();
    known_cloud(&mut b, n, rear, length, radius);
    // Particles before the rear face never count, however far out.
    for k in 0..200 {
        b.add(
            DVec3::new(0.5, 0.0, rear - 1e-3 * (k as f64 + 1.0)),
            Body::Target,
            M_TARGET,
        );
    }
    let p = b.in_order();
    let derived = derived_with(rear, DENSITY, 1000.0);
    let reference = CloudReference::new(&p, &derived, &[]);
    let members = find_cloud(&p, &reference);
    for q in [0.995, 0.9, 0.5] {
        // Distances from the axis are spread evenly: the cylindrical reading has a closed form.
        let e = extent(&p, &members.in_cloud, rear, q, Width::Cylindrical);
        assert_eq!(e.n_part, n);
        // z = rear + length (k + 1) / n: the q-quantile is at h = (n - 1) q.
        let la = length * (1.0 + (n - 1) as f64 * q) / n as f64;
        let lr = 2.0 * radius * q;
        let got_la = e.length_axial_m.expect("La");
        let got_lr = e.length_radial_m.expect("Lr");
        assert!((got_la - la).abs() < 1e-12, "q {q}: La {got_la} vs {la}");
        assert!((got_lr - lr).abs() < 1e-12, "q {q}: Lr {got_lr} vs {lr}");
        let r = e.length_ratio.expect("R");
        assert!((r - la / lr).abs() < 1e-9, "R {r}");
        assert!((e.length_axial_max_m.expect("max") - length).abs() < 1e-12);
        assert!((e.length_radial_max_m.expect("max") - 2.0 * radius).abs() < 1e-12);
    }
}

#[test]
fn a_ring_seen_side_on_is_narrower_than_its_radius_by_the_projection() {
    // A thin ring of radius r, evenly around the axis: every particle is r from the axis, and
    // seen side-on (along y or along x) at |x| = r |cos phi|, whose q-quantile is
    // r cos(pi (1 - q) / 2) for phi uniform.
    let (n, rear, radius) = (40_000, 4e-3, 0.05);
    let mut b = Builder::default();
    for k in 0..n {
        let phi = std::f64::consts::TAU * (k as f64 + 0.5) / n as f64;
        b.add(
            DVec3::new(radius * phi.cos(), radius * phi.sin(), rear + 0.1),
            Body::Target,
            M_TARGET,
        );
    }
    let p = b.in_order();
    let derived = derived_with(rear, DENSITY, 1000.0);
    let reference = CloudReference::new(&p, &derived, &[]);
    let members = find_cloud(&p, &reference);
    assert_eq!(
        Analysis::default().width,
        Width::Side,
        "R is read side-on by default"
    );
    for q in [0.9, 0.5] {
        let e = extent(&p, &members.in_cloud, rear, q, Width::Side);
        let cylindrical = e.length_radial_cylindrical_m.expect("cylindrical Lr");
        assert!((cylindrical - 2.0 * radius).abs() < 1e-12, "{cylindrical}");
        let side = e.length_radial_side_m.expect("side Lr");
        let expected = 2.0 * radius * (std::f64::consts::PI * (1.0 - q) / 2.0).cos();
        assert!(
            (side - expected).abs() < 1e-4 * expected,
            "q {q}: side Lr {side} vs {expected}"
        );
        let la = e.length_axial_m.expect("La");
        assert!((e.length_ratio_side.expect("side R") - la / side).abs() < 1e-12);
        assert!((e.length_ratio_cylindrical.expect("cyl R") - la / cylindrical).abs() < 1e-12);
        // The chosen reading is the side view's, its maximum too (the ring's |x| reaches r).
        assert_eq!(e.length_radial_m, e.length_radial_side_m);
        assert_eq!(e.length_ratio, e.length_ratio_side);
        assert!((e.length_radial_max_m.expect("max") - 2.0 * radius).abs() < 1e-6 * radius);
        // Read cylindrically, the same cloud gives the cylindrical numbers as Lr and R.
        let c = extent(&p, &members.in_cloud, rear, q, Width::Cylindrical);
        assert_eq!(c.length_radial_m, e.length_radial_cylindrical_m);
        assert_eq!(c.length_ratio, e.length_ratio_cylindrical);
        assert_eq!(
            (c.length_radial_side_m, c.length_radial_cylindrical_m),
            (e.length_radial_side_m, e.length_radial_cylindrical_m)
        );
    }
}

#[test]
fn stray_particles_do_not_move_the_quantile_extents() {
    let (n, rear, length, radius) = (10_000, 4e-3, 0.2, 0.06);
    let mut clean = Builder::default();
    known_cloud(&mut clean, n, rear, length, radius);
    let mut strays = Builder::default();
    known_cloud(&mut strays, n, rear, length, radius);
    // 20 strays (0.2 %, below the 0.5 % the quantile leaves out) 50 times further out.
    for k in 0..20 {
        let phi = k as f64;
        strays.add(
            DVec3::new(
                50.0 * radius * phi.cos(),
                50.0 * radius * phi.sin(),
                rear + 50.0 * length,
            ),
            Body::Target,
            M_TARGET,
        );
    }
    let derived = derived_with(rear, DENSITY, 1000.0);
    let ext = |b: &Builder| {
        let p = b.in_order();
        let reference = CloudReference::new(&p, &derived, &[]);
        let members = find_cloud(&p, &reference);
        extent(&p, &members.in_cloud, rear, 0.995, Width::Side)
    };
    let (a, b) = (ext(&clean), ext(&strays));
    let rel = |x: Option<f64>, y: Option<f64>| {
        let (x, y) = (x.expect("value"), y.expect("value"));
        (x - y).abs() / x
    };
    // The quantile extents move by the rank shift of 20 in 10000 at most: by less than 0.5 %
    // where the samples are evenly spread (z, the distance from the axis).
    assert!(rel(a.length_axial_m, b.length_axial_m) < 0.005);
    assert!(rel(a.length_radial_cylindrical_m, b.length_radial_cylindrical_m) < 0.005);
    assert!(rel(a.length_ratio_cylindrical, b.length_ratio_cylindrical) < 0.005);
    // Seen side-on, |x| = r |cos phi| thins out towards its largest value, so the same rank
    // shift (40 of 20000 pooled samples) moves the quantile more: 1.2 % here.
    assert!(rel(a.length_radial_m, b.length_radial_m) < 0.02);
    assert!(rel(a.length_ratio, b.length_ratio) < 0.02);
    // The maxima follow the strays.
    assert!((b.length_axial_max_m.expect("max") - 50.0 * length).abs() < 1e-9);
    assert!(b.length_radial_max_m.expect("max") > 40.0 * 2.0 * radius);
}

#[test]
fn front_moving_at_a_known_speed_gives_va() {
    // 400 free particles, each in its own column (5 sigma apart: no contacts), flying along +z
    // at speeds evenly spread over [0.5, 1] U, starting at positions ordered like their speeds:
    // z_k(t) = rear + u_k (c + U t), so the front's quantile moves at U u_(q).
    let (side, u_max) = (20usize, 5000.0);
    let n = side * side;
    let ia = interaction();
    let rear = 2e-3;
    let mut b = Builder::default();
    let mut speeds = Vec::new();
    for k in 0..n {
        let (i, j) = (k % side, k / side);
        let u = 0.5 + 0.5 * ((k * 37) % n) as f64 / (n - 1) as f64;
        let x = DVec3::new(
            (i as f64 - 9.5) * 5.0 * SIGMA,
            (j as f64 - 9.5) * 5.0 * SIGMA,
            rear + u * 0.02,
        );
        let id = b.add(x, Body::Target, 1e-6);
        b.vel[id] = DVec3::Z * u * u_max;
        speeds.push(u);
    }
    let p = b.in_order();
    let dt = 2e-9;
    let steps = 2000;
    let mut derived = Derived::for_interaction(&ia, dt, 1e-6, steps);
    derived.plate_rear_z_m = rear;
    derived.v0_m_s = u_max;
    let mut sim = Simulation::from_parts(p, ia, derived, &RunSettings::default()).expect("starts");
    let end = steps as f64 * dt;
    let analysis = Analysis {
        front_times_s: Some([0.5 * end, end]),
        track_every: 50,
        ..Analysis::default()
    };
    let mut observer = CloudObserver::new(&sim, &analysis, end);
    observer.observe(&sim);
    while sim.step < steps {
        sim.advance(1).expect("free flight is stable");
        observer.observe(&sim);
    }
    assert!(
        sim.neighbour_builds() > 2,
        "storage order changed along the way"
    );
    let result = observer.finish(&sim).expect("cloud asked for");
    let q = analysis.quantile;
    let mut u = speeds.clone();
    u.sort_by(f64::total_cmp);
    let h = (n - 1) as f64 * q;
    let uq =
        u[h.floor() as usize] + h.fract() * (u[h.floor() as usize + 1] - u[h.floor() as usize]);
    let va = result.report.front_velocity_m_s.expect("va");
    assert!(
        (va - uq * u_max).abs() < 1e-6 * u_max,
        "va {va} vs {}",
        uq * u_max
    );
    let ratio = result.report.front_velocity_ratio.expect("va/v0");
    assert!((ratio - uq).abs() < 1e-6);
    let [t1, t2] = result.report.front_velocity_times_s;
    assert!((t1.expect("t1") - 0.5 * end).abs() <= 0.5 * dt);
    assert!((t2.expect("t2") - end).abs() <= 0.5 * dt);
    // The track sees the same constant speed between any two samples.
    let track = &observer.track;
    assert_eq!(track.len(), steps as usize / 50 + 1);
    for r in &track[1..] {
        let v = r.front_velocity_m_s.expect("speed between samples");
        assert!((v - uq * u_max).abs() < 1e-6 * u_max, "track speed {v}");
    }
    // Everything is a lone particle.
    assert_eq!(result.report.measurement.fragmentation, Some(1.0));
}

fn sphere_scene(particles: f64, end_time_s: f64) -> SceneSpec {
    SceneSpec::calibration(particles, end_time_s)
}

/// Runs a scene with a cloud observer as `hvi-study run` does.
fn observed_run(spec: &SceneSpec) -> (Simulation, CloudResult) {
    let mut sim = Simulation::new(spec.build().expect("valid scene")).expect("starts");
    assert!(
        !sim.rim_ids.is_empty(),
        "Simulation::new keeps the plate's rim"
    );
    let mut observer = CloudObserver::new(&sim, &spec.analysis, spec.run.end_time_s);
    observer.observe(&sim);
    while sim.step < sim.derived.steps {
        sim.advance(1).expect("stable");
        observer.observe(&sim);
    }
    let result = observer.finish(&sim).expect("cloud asked for");
    (sim, result)
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool")
}

/// Connected components by breadth-first search over intact bonds (an independent check of
/// the union-find): component of each particle by id, named by its smallest id.
fn components_by_bfs(p: &Particles) -> Vec<u32> {
    let n = p.len();
    let mut adj = vec![Vec::new(); n];
    for (i, j) in p.intact_bond_pairs() {
        adj[i].push(j);
        adj[j].push(i);
    }
    let mut comp = vec![u32::MAX; n];
    for start in 0..n {
        if comp[start] != u32::MAX {
            continue;
        }
        let mut members = vec![start];
        let mut queue = VecDeque::from([start]);
        comp[start] = 0;
        while let Some(i) = queue.pop_front() {
            for &j in &adj[i] {
                if comp[j] == u32::MAX {
                    comp[j] = 0;
                    members.push(j);
                    queue.push_back(j);
                }
            }
        }
        let label = members.iter().map(|&i| p.id[i]).min().expect("member");
        for i in members {
            comp[i] = label;
        }
    }
    by_id(p, &comp)
}

#[test]
fn small_impact_cloud_is_consistent_plausible_and_thread_independent() {
    let spec = sphere_scene(3000.0, 4e-6);
    let (sim, a) = pool(1).install(|| observed_run(&spec));
    let (_, b) = pool(2).install(|| observed_run(&spec));
    assert_eq!(a.labels_by_id, b.labels_by_id, "labels at 1 and 2 threads");
    assert_eq!(a.report, b.report, "measurement at 1 and 2 threads");
    assert_eq!(a.fragments, b.fragments);

    let m = &a.report.measurement;
    let f = m.fragmentation.expect("a cloud formed");
    assert!(f > 0.0 && f <= 1.0, "F = {f}");
    assert!(m.n_part > 100, "cloud of {} particles", m.n_part);
    // Some fragments hold several particles at this resolution, and many are alone.
    assert!(m.n_frag < m.n_part && m.n_frag > m.n_part / 4);

    // The cloud's mass is the sum of its fragments', and of its particles'.
    let p = &sim.particles;
    let reference = CloudReference::of(&sim);
    let members = find_cloud(p, &reference);
    let by_particles: f64 = (0..p.len())
        .filter(|&i| members.in_cloud[i])
        .map(|i| p.mass[i])
        .sum();
    let by_fragments: f64 = a.fragments.iter().map(|f| f.mass_kg).sum();
    assert!((m.mass_kg - by_fragments).abs() <= 1e-12 * m.mass_kg);
    assert!((m.mass_kg - by_particles).abs() <= 1e-12 * m.mass_kg);
    assert_eq!(
        a.fragments.iter().map(|f| f.particles).sum::<usize>(),
        m.n_part
    );

    // The union-find agrees with a breadth-first search.
    assert_eq!(a.labels_by_id, components_by_bfs(p));

    // The residual plate holds every rim particle and most of the plate.
    let idx = p.index_of_id();
    assert!(!sim.rim_ids.is_empty());
    for &id in &sim.rim_ids {
        let i = idx[id as usize] as usize;
        assert!(members.in_residual_plate[i] && !members.in_cloud[i]);
    }
    let plate_mass: f64 = (0..p.len())
        .filter(|&i| p.body[i] == Body::Target)
        .map(|i| p.mass[i])
        .sum();
    let residual: f64 = (0..p.len())
        .filter(|&i| members.in_residual_plate[i])
        .map(|i| p.mass[i])
        .sum();
    assert!(residual > 0.5 * plate_mass && residual < plate_mass);

    // va / v0 near the 1-D shock estimate of the rear free surface (about 1.03, docs/model.md
    // section 6).
    let ratio = a.report.front_velocity_ratio.expect("va");
    assert!(ratio > 0.8 && ratio < 1.3, "va/v0 = {ratio}");
    let r = m.length_ratio.expect("R");
    assert!(r > 0.3 && r < 3.0, "R = {r}");
    let share = m.largest_fragment_mass_fraction.expect("largest");
    assert!(share > 0.0 && share <= 1.0);

    // The camera sees the cloud: a silhouette at least as long as the quantile's La (it ends at
    // the farthest dark pixel), with a front speed of the same order.
    let sil = a.report.silhouette.expect("silhouette measured");
    let la = sil.length_axial_m.expect("silhouette La");
    assert!(la > 0.5 * m.length_axial_m.expect("La"), "{sil:?}");
    let r_sil = sil.length_ratio.expect("silhouette R");
    assert!(r_sil > 0.3 && r_sil < 3.0, "R (silhouette) = {r_sil}");
    let va_sil = sil.front_velocity_ratio.expect("silhouette va");
    assert!(
        va_sil > 0.8 && va_sil < 2.0,
        "va/v0 (silhouette) = {va_sil}"
    );
    // Every fragment moving downstream leaves one crater on the witness plate.
    let wit = a.report.witness_plate.expect("witness plate");
    let downstream = a
        .fragments
        .iter()
        .filter(|f| f.velocity_m_s[2] > 0.0)
        .count();
    assert_eq!(wit.crater_count, downstream);
    assert_eq!(a.craters.len(), downstream);
    let median = wit.crater_diameter_median_m.expect("craters");
    assert!(median > 0.0 && median <= wit.crater_diameter_max_m.expect("largest"));
}

#[test]
fn analysis_keys_are_validated_by_name() {
    type Edit = Box<dyn Fn(&mut Analysis)>;
    let cases: [(&str, Edit); 4] = [
        ("analysis.quantile", Box::new(|a| a.quantile = 0.3)),
        ("analysis.quantile", Box::new(|a| a.quantile = f64::NAN)),
        (
            "analysis.front_times_s",
            Box::new(|a| a.front_times_s = Some([3e-6, 1e-6])),
        ),
        (
            "analysis.render_times_s",
            Box::new(|a| a.render_times_s = vec![-1e-6]),
        ),
    ];
    for (key, set) in cases {
        let mut spec = sphere_scene(2000.0, 2e-6);
        set(&mut spec.analysis);
        let e = spec.build().expect_err("invalid").to_string();
        assert!(e.contains(key), "{e}");
    }
    // Front times past the end of the run are refused; the defaults adapt to a short run.
    let mut spec = sphere_scene(2000.0, 2e-6);
    spec.analysis.front_times_s = Some([28e-6, 32e-6]);
    let e = spec.build().expect_err("beyond the end").to_string();
    assert!(
        e.contains("analysis.front_times_s") && e.contains("run.end_time_s"),
        "{e}"
    );
    let d = Analysis::default();
    assert_eq!(d.front_times_s(40e-6), [28e-6, 32e-6]);
    let [t1, t2] = d.front_times_s(4e-6);
    assert!((t1 - 3.5e-6).abs() < 1e-18 && t2 == 4e-6, "{t1} {t2}");
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `hvi-study run` on the default scene into `out`, with `args` after it.
fn run_default_scene(out: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_hvi-study"))
        .arg("run")
        .arg(repo().join("studies/scenes/default.toml"))
        .arg("--out")
        .arg(out)
        .args(args)
        .output()
        .expect("runs")
}

/// The `summary.json` a run wrote into `out`.
fn read_summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
        .expect("json")
}

fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(
        &bytes[..8],
        b"\x89PNG\r\n\x1a\n",
        "{} is a PNG",
        path.display()
    );
    let be = |o: usize| u32::from_be_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    (be(16), be(20))
}

#[test]
fn run_with_render_writes_cloud_files_and_pictures() {
    let out = std::env::temp_dir().join(format!("hvi-cloud-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let o = run_default_scene(
        &out,
        &[
            "--set",
            "resolution.particles=2000",
            "--set",
            "run.end_time_s=3e-6",
            "--set",
            "analysis.render_times_s=[0, 1.5e-6, 3e-6]",
            "--set",
            "analysis.track_every=20",
            "--render",
        ],
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stderr.contains("cloud at tau") && stderr.contains("Render"),
        "{stderr}"
    );
    let summary = read_summary(&out);
    let cloud = &summary["cloud"];
    for key in [
        "fragmentation",
        "n_part",
        "n_frag",
        "length_axial_m",
        "length_radial_m",
        "length_ratio",
        "front_velocity_m_s",
        "front_velocity_ratio",
        "largest_fragment_mass_fraction",
        "largest_fragment_diameter_m",
        "mean_fragment_diameter_m",
        "tau_s",
        "length_axial_max_m",
        "length_radial_max_m",
    ] {
        assert!(cloud[key].is_number(), "cloud.{key} = {}", cloud[key]);
    }
    assert!((cloud["tau_s"].as_f64().expect("tau") - 3e-6).abs() < 1e-8);
    let track = std::fs::read_to_string(out.join("cloud_track.csv")).expect("track");
    assert!(track.starts_with("step,time_s,tau_s,n_part,front_z_m,length_axial_m"));
    assert!(track.lines().count() > 10);
    let frags = std::fs::read_to_string(out.join("fragments.csv")).expect("fragments");
    assert!(frags.starts_with("particles,fragments,mass_kg,mass_fraction"));
    let counted: usize = frags
        .lines()
        .skip(1)
        .map(|l| {
            let mut f = l.split(',');
            let size: usize = f.next().and_then(|x| x.parse().ok()).expect("size");
            let count: usize = f.next().and_then(|x| x.parse().ok()).expect("count");
            size * count
        })
        .sum();
    assert_eq!(counted as u64, cloud["n_part"].as_u64().expect("n_part"));
    for key in [
        "length_axial_m",
        "length_radial_m",
        "length_ratio",
        "front_velocity_ratio",
    ] {
        let v = &cloud["silhouette"][key];
        assert!(v.is_number(), "cloud.silhouette.{key} = {v}");
    }
    let craters = std::fs::read_to_string(out.join("craters.csv")).expect("craters");
    assert!(craters.starts_with("x_m,y_m,diameter_m,depth_m,fragment_diameter_m,velocity_m_s"));
    assert_eq!(
        craters.lines().count() as u64 - 1,
        cloud["witness_plate"]["crater_count"]
            .as_u64()
            .expect("count")
    );
    for name in [
        "cloud_side.png",
        "cloud_series.png",
        "fragments.png",
        "cloud_track.png",
    ] {
        let (w, h) = png_size(&out.join(name));
        assert!(w >= 800 && h >= 600, "{name}: {w} x {h}");
    }
    // The series has three panels: two columns, two rows.
    let (w, h) = png_size(&out.join("cloud_series.png"));
    assert!(w > 1500 && h > 1200, "series {w} x {h}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn analysis_can_be_turned_off_and_bad_keys_are_named() {
    let out = std::env::temp_dir().join(format!("hvi-cloud-off-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let run = |extra: &[&str]| {
        let mut args = vec![
            "--quiet",
            "--set",
            "resolution.particles=2000",
            "--set",
            "run.end_time_s=5e-7",
        ];
        args.extend_from_slice(extra);
        run_default_scene(&out, &args)
    };
    let o = run(&[
        "--set",
        "analysis.cloud=false",
        "--set",
        "analysis.track_every=0",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = std::fs::read_to_string(out.join("summary.json")).expect("summary");
    assert!(summary.contains("\"cloud\": null"), "{summary}");
    assert!(!out.join("cloud_track.csv").exists() && !out.join("fragments.csv").exists());
    for (set, key) in [
        ("analysis.quantile=2", "analysis.quantile"),
        ("analysis.track_evry=5", "track_evry"),
        (
            "analysis.front_times_s=[1e-6, 2e-6]",
            "analysis.front_times_s",
        ),
    ] {
        let o = run(&["--set", set]);
        assert_eq!(o.status.code(), Some(2), "{set}");
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(e.contains(key), "{set}: {e}");
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// With the adaptive step, every sample still lands on its time: the front at both front
/// times, the track at every `track_every` base steps, the energy at every `energy_every`.
#[test]
fn adaptive_run_samples_on_schedule() {
    let out = std::env::temp_dir().join(format!("hvi-cloud-adaptive-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let o = run_default_scene(
        &out,
        &[
            "--quiet",
            "--set",
            "resolution.particles=2000",
            "--set",
            "run.end_time_s=8e-6",
            "--set",
            "run.max_stride=8",
            "--set",
            "analysis.track_every=30",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = read_summary(&out);
    let steps = summary["steps"].as_u64().expect("steps");
    let base = summary["base_steps"].as_u64().expect("base steps");
    let dt = summary["dt_s"].as_f64().expect("dt");
    assert_eq!(base, summary["derived"]["steps"].as_u64().expect("planned"));
    assert!(
        steps < base,
        "{steps} steps for {base} base steps: no stride"
    );
    assert!(summary["dt_largest_s"].as_f64().expect("largest") > 1.5 * dt);
    let times = summary["cloud"]["front_velocity_times_s"]
        .as_array()
        .expect("front times");
    for (t, want) in times.iter().zip([7e-6, 8e-6]) {
        let t = t.as_f64().expect("reached");
        assert!(
            (t - want).abs() <= 0.5 * dt,
            "front sampled at {t}, not {want}"
        );
    }
    let track = std::fs::read_to_string(out.join("cloud_track.csv")).expect("track");
    let rows: Vec<u64> = track
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .next()
                .and_then(|s| s.parse().ok())
                .expect("step")
        })
        .collect();
    let expected: Vec<u64> = (0..=base / 30).map(|k| k * 30).chain([base]).collect();
    let mut expected = expected;
    expected.dedup();
    assert_eq!(rows, expected);
    let energy = std::fs::read_to_string(out.join("energy.csv")).expect("energy");
    assert_eq!(energy.lines().count() - 1, base.div_ceil(200) as usize + 1);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn the_largest_piece_of_the_impactor_is_reported_beside_the_clouds_largest_fragment() {
    let mut b = Builder::default();
    let (_, rim) = plate_with_rim(&mut b);
    // Beyond the face: a 4 x 4 x 2 spall of plate material (the cloud's largest fragment), a
    // 2 x 2 x 1 piece of the impactor and six impactor loners; in front of the plate a
    // 3 x 3 x 1 piece of the impactor that never got through (impactor: 19 particles).
    b.block(
        DVec3::new(-A, -A, -8.0 * A),
        [3, 3, 1],
        A,
        Body::Impactor,
        M_IMPACTOR,
    );
    b.block(
        DVec3::new(-1.5 * A, -1.5 * A, 8.0 * A),
        [4, 4, 2],
        A,
        Body::Target,
        M_TARGET,
    );
    b.block(
        DVec3::new(6.0 * A, 6.0 * A, 12.0 * A),
        [2, 2, 1],
        A,
        Body::Impactor,
        M_IMPACTOR,
    );
    for k in 0..6 {
        b.add(
            DVec3::new(-6.0 * A, (k as f64 - 3.0) * 1.5 * A, 15.0 * A),
            Body::Impactor,
            M_IMPACTOR,
        );
    }
    let derived = derived_with(2.0 * A, DENSITY, 1000.0);
    let p = b.in_order();
    let reference = CloudReference::new(&p, &derived, &rim);
    let members = find_cloud(&p, &reference);
    let m = measure(&p, &members, &reference, 0.995, Width::Side, 1.0, 1.0).measurement;
    let impactor = 19.0 * M_IMPACTOR;
    let largest = m.largest_fragment_mass_fraction.expect("largest");
    assert!(
        (largest - 32.0 * M_TARGET / impactor).abs() < 1e-12,
        "{largest}"
    );
    let piece = m
        .impactor_largest_fragment_mass_fraction
        .expect("impactor's largest piece");
    assert!(
        (piece - 4.0 * M_IMPACTOR / impactor).abs() < 1e-12,
        "{piece}"
    );
    // The onset reads the largest piece anywhere: the one in front of the plate.
    let intact = m.impactor_intact_mass_fraction.expect("intact fraction");
    assert!((intact - 9.0 / 19.0).abs() < 1e-12, "{intact}");
}
