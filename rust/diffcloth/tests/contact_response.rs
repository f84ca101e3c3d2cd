//! The contact responses (inertia splitting, Delassus operator, and `auto`, the splitting that
//! switches a stalling stiff step to the Delassus operator) solve the same step, the
//! Delassus operator keeps stiff cloth at large steps outside the obstacle, and `auto` builds
//! it only for steps with few enough contact nodes.
use crate::common::*;
use diffcloth::forward::MAX_CONTACT_NODES;
use diffcloth::{Simulator, StepInput};

/// A `rows` x `rows` napkin dropped onto a sphere (radius 0.5) with the given response.
fn napkin_on_sphere(
    rows: usize,
    k_stretch: f64,
    h: f64,
    response: &str,
    max_iterations: usize,
) -> Simulator {
    napkin_on_dome(rows, k_stretch, h, response, max_iterations, 0.5)
}

/// A 1.6 m `rows` x `rows` napkin dropped from 0.2 m above the top of a sphere of the given
/// radius (a flatter dome for a larger one, so more of the napkin lands on it).
fn napkin_on_dome(
    rows: usize,
    k_stretch: f64,
    h: f64,
    response: &str,
    max_iterations: usize,
    radius: f64,
) -> Simulator {
    let center = 0.5 - radius;
    sim_from_toml(&format!(
        r#"
h = {h}
effects = ["gravity", "stretch", "bend", "obstacle_contact", "friction"]
[mesh]
kind = "grid"
rows = {rows}
cols = {rows}
width = 1.6
height = 1.6
plane = "xz"
[placement]
translate = [0.1, 0.7, 0.0]
[material]
density = 0.2
k_stretch = {k_stretch}
k_bend = 0.001
[contact]
thickness = 0.01
response = "{response}"
[[obstacles]]
mu = 0.3
shape = {{ kind = "sphere", center = [0.0, {center}, 0.0], radius = {radius} }}
[solver]
# Two solves of one step converged to the same tolerance lie up to ~100x it apart (PD's slow
# contraction), and `both_responses_solve_the_same_step` allows 1e-8 of the motion: at 1e-12
# the two responses came within 0.9-1.9e-10 of each other, at 1e-13 within 0.5-1.5e-11.
tolerance = 1e-13
max_iterations = {max_iterations}
"#
    ))
}

#[test]
fn both_responses_solve_the_same_step() {
    // From the same states along a drop (take-off, stick and slip all occur), one converged
    // step with each response lands on the same state: the law holds at the fixed point
    // whichever prediction the iteration uses.
    let mut inertia = napkin_on_sphere(9, 200.0, 0.01, "inertia", 20000);
    let mut delassus = napkin_on_sphere(9, 200.0, 0.01, "delassus", 20000);
    let mut compared = 0;
    for step in 0..60 {
        let (x, v) = (inertia.positions().to_vec(), inertia.velocities().to_vec());
        let a = inertia.step(StepInput::default()).unwrap();
        if step % 6 == 5 {
            delassus.reset(Some(&x), Some(&v)).unwrap();
            let b = delassus.step(StepInput::default()).unwrap();
            assert!(a.converged && b.converged, "{a:?} {b:?}");
            let moved = max_distance(inertia.positions(), &x);
            let apart = max_distance(inertia.positions(), delassus.positions());
            assert!(
                apart <= 1e-7 * moved.max(1e-3),
                "step {step}: responses differ by {apart:e} (moved {moved:e}; {a:?} vs {b:?})"
            );
            compared += (b.contacts.stick + b.contacts.slip > 0) as usize;
        }
    }
    assert!(
        compared >= 5,
        "only {compared} compared steps had active contacts"
    );
    assert_eq!(inertia.profile().delassus_builds, 0);
    assert!(delassus.profile().delassus_builds as usize >= compared);
}

#[test]
fn stiff_cloth_at_large_steps_stays_outside_the_obstacle() {
    // k h^2 / m ~ 1e3: the inertia splitting's error on a sticking node contracts by
    // 1 - 1e-3 per iteration, so steps stopped at the cap with nodes inside the sphere
    // (1.7 cm at step 5). Through the Delassus operator every iterate respects the contact
    // law: no node goes through, and no energy is created. `auto` (the default) gets there by
    // switching the stalling steps.
    for response in ["delassus", "auto"] {
        let mut sim = napkin_on_sphere(9, 1e5, 1.0 / 30.0, response, 300);
        let thickness = 0.01;
        let e0 = sim.mechanical_energy();
        let mut touched = false;
        for step in 0..30 {
            let stats = sim.step(StepInput::default()).unwrap();
            touched |= stats.contacts.stick + stats.contacts.slip > 0;
            // These steps stop at the cap (PD itself converges slowly here: residual ~1e-4),
            // and a node found late by re-detection may end a little inside the layer: 1 % of
            // it is allowed (the inertia response ended 0.17 m inside the sphere).
            let d = min_obstacle_distance(&sim);
            assert!(
                d >= 0.99 * thickness,
                "{response}, step {step}: a node is {d} from the sphere (thickness {thickness}): {stats:?}"
            );
            let e = sim.mechanical_energy();
            assert!(
                e <= e0 * (1.0 + 1e-6),
                "{response}, step {step}: energy {e} > initial {e0}"
            );
        }
        assert!(touched, "the napkin reached the sphere");
        if response == "auto" {
            assert!(sim.profile().response_switches > 0);
        }
    }
}

#[test]
fn auto_response_is_the_splitting_where_it_converges() {
    // The stiff napkin on the sphere at a small step, and a soft one at a large step: the
    // splitting converges well within the cap, so `auto` never switches and its trajectory is
    // the inertia response's, bit for bit.
    for (k_stretch, h) in [(1e5, 1e-3), (200.0, 0.01)] {
        let mut inertia = napkin_on_sphere(9, k_stretch, h, "inertia", 300);
        let mut auto = napkin_on_sphere(9, k_stretch, h, "auto", 300);
        let mut active = 0;
        for _ in 0..(0.4 / h) as usize {
            let a = inertia.step(StepInput::default()).unwrap();
            let b = auto.step(StepInput::default()).unwrap();
            assert_eq!(a, b);
            active += a.contacts.stick + a.contacts.slip;
        }
        assert!(active > 0, "k {k_stretch}, h {h}: no contact");
        assert_eq!(inertia.positions(), auto.positions());
        assert_eq!(auto.profile().response_switches, 0);
    }
}

#[test]
fn a_switched_step_reaches_the_delassus_fixed_point() {
    // Stiff cloth (k h^2 / m ~ 300) converged tightly: the steps `auto` switched land where the
    // Delassus response does from the same state (the law at the fixed point is one law). At
    // k 1e5 and h 1/30 neither response converges within 20000 iterations. The bound: stiff
    // modes contract by about 1 - 1/300 per iteration, so a solve stopped at an update of 1e-13
    // is up to ~1e-9 from the fixed point (measured apart: 8e-10 in 4 cm of motion).
    let (k_stretch, h) = (3e3, 0.01);
    let mut auto = napkin_on_sphere(9, k_stretch, h, "auto", 20000);
    let mut delassus = napkin_on_sphere(9, k_stretch, h, "delassus", 20000);
    let mut compared = 0;
    for step in 0..60 {
        let (x, v) = (auto.positions().to_vec(), auto.velocities().to_vec());
        let switches = auto.profile().response_switches;
        let a = auto.step(StepInput::default()).unwrap();
        if auto.profile().response_switches == switches || !a.converged {
            continue;
        }
        delassus.reset(Some(&x), Some(&v)).unwrap();
        let b = delassus.step(StepInput::default()).unwrap();
        assert!(b.converged, "{b:?}");
        let moved = max_distance(auto.positions(), &x);
        let apart = max_distance(auto.positions(), delassus.positions());
        assert!(
            apart <= 1e-7 * moved.max(1e-3),
            "step {step}: auto and delassus differ by {apart:e} (moved {moved:e}; {a:?} vs {b:?})"
        );
        compared += 1;
    }
    assert!(compared >= 3, "only {compared} switched, converged steps");
}

#[test]
fn auto_switches_identically_recorded_in_a_batch_and_on_any_thread_count() {
    // One simulation, one answer: the switch depends only on the step's own iterations, so
    // a recorded simulator and batch members on one or two threads give the standalone
    // trajectory bit for bit, switched steps included.
    let template = napkin_on_sphere(9, 1e5, 1.0 / 30.0, "auto", 300);
    let (model, solver) = (template.model().clone(), template.solver().clone());
    let starts: Vec<Vec<diffcloth::Vec3>> = (0..2)
        .map(|i| {
            let shift = diffcloth::Vec3::new(0.02 * i as f64, 0.0, -0.01 * i as f64);
            template.positions().iter().map(|p| p + shift).collect()
        })
        .collect();
    let steps = 12;
    let expected: Vec<Vec<diffcloth::Vec3>> = starts
        .iter()
        .enumerate()
        .map(|(i, x0)| {
            let mut sim = Simulator::from_model(model.clone(), solver.clone());
            sim.set_recording(i == 1);
            sim.reset(Some(x0), None).unwrap();
            for _ in 0..steps {
                sim.step(StepInput::default()).unwrap();
            }
            assert!(
                sim.profile().response_switches > 0,
                "member {i} never switched"
            );
            sim.positions().to_vec()
        })
        .collect();
    let mut plain = Simulator::from_model(model.clone(), solver.clone());
    plain.reset(Some(&starts[1]), None).unwrap();
    for _ in 0..steps {
        plain.step(StepInput::default()).unwrap();
    }
    assert_eq!(plain.positions(), &expected[1][..], "recorded vs plain");
    for threads in [1, 2] {
        let mut batch =
            diffcloth::Batch::with_threads(model.clone(), solver.clone(), 2, threads).unwrap();
        for (i, x0) in starts.iter().enumerate() {
            batch.member_mut(i).unwrap().reset(Some(x0), None).unwrap();
        }
        let inputs = vec![diffcloth::MemberInput::default(); 2];
        for _ in 0..steps {
            for r in batch.step(&inputs).unwrap() {
                r.unwrap();
            }
        }
        let got: Vec<Vec<diffcloth::Vec3>> =
            batch.members().map(|s| s.positions().to_vec()).collect();
        assert_eq!(got, expected, "{threads} thread(s)");
    }
}

#[test]
fn auto_keeps_the_splitting_where_a_step_has_too_many_contact_nodes() {
    // A 40 x 40 stiff napkin (k h^2 / m ~ 1e3, every contacting step stalls at the cap) on a
    // flat dome: up to ~1500 of its 1600 nodes touch at once. `auto` may only build the
    // Delassus operator for at most MAX_CONTACT_NODES contact nodes (one obstacle and no
    // self-contact here, so a step's contacts are its contact nodes). The 10 % margins allow
    // for contacts that re-detection adds after the switch's check.
    let mut sim = napkin_on_dome(40, 1e5, 1.0 / 30.0, "auto", 300, 3.0);
    let (mut kept_large, mut switched_small) = (0, 0);
    for step in 0..30 {
        let before = sim.profile().response_switches;
        let stats = sim.step(StepInput::default()).unwrap();
        let switched = sim.profile().response_switches > before;
        let c = &stats.contacts;
        let nodes = (c.take_off + c.stick + c.slip) as f64;
        let limit = MAX_CONTACT_NODES as f64;
        if nodes > 1.1 * limit {
            assert!(
                !switched,
                "step {step}: switched with {nodes} contact nodes: {stats:?}"
            );
            kept_large += !stats.converged as usize;
        } else if nodes > 0.0 && nodes < 0.9 * limit && switched {
            switched_small += 1;
        }
    }
    assert!(
        kept_large >= 5,
        "only {kept_large} stalled steps over the limit"
    );
    assert!(
        switched_small >= 3,
        "only {switched_small} switched steps under it"
    );
}
