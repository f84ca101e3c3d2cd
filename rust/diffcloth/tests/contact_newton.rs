//! The semi-smooth contact Newton (`solver.polish = "semismooth"`): from the same states it
//! lands where plain PD lands (either contact response), the contact law holds at its
//! solution, it takes fewer PD iterations, threads and recording change no bit, and gradients
//! through its steps match finite differences.
use crate::common::*;
use crate::gradient_check::*;
use diffcloth::{AdjointSolver, Branch, ContactKind, Simulator, StepInput, Vec3};

/// A `rows` x `rows` napkin dropped onto a sphere (radius 0.5), friction 0.3 (take-off,
/// stick and slip all occur), with the given response and polish.
fn napkin_on_sphere(rows: usize, response: &str, polish: &str, tolerance: f64) -> Simulator {
    sim_from_toml(&format!(
        r#"
h = 0.01
effects = ["gravity", "stretch", "bend", "obstacle_contact", "friction"]
[mesh]
kind = "grid"
rows = {rows}
cols = {rows}
width = 1.6
height = 1.6
plane = "xz"
[placement]
translate = [0.1, 0.55, 0.0]
[material]
density = 0.2
k_stretch = 200.0
k_bend = 0.001
[contact]
thickness = 0.01
response = "{response}"
[[obstacles]]
mu = 0.3
shape = {{ kind = "sphere", center = [0.0, 0.0, 0.0], radius = 0.5 }}
[solver]
tolerance = {tolerance:e}
max_iterations = 20000
polish = "{polish}"
parallel = false
"#
    ))
}

/// The contact law at the step just taken (static obstacle): no node closer than the
/// thickness, sticking nodes at rest tangentially, slipping impulses on the cone's boundary
/// opposing the motion, separating contacts without impulse.
fn assert_contact_law(sim: &Simulator, slack: f64) {
    let h = sim.params().h;
    let o = &sim.obstacles()[0];
    for p in sim.positions() {
        let d = o.query(p, sim.time()).0;
        assert!(
            d >= 0.01 - slack,
            "node at {d:e} from the sphere (thickness 0.01)"
        );
    }
    let scale = sim
        .contacts()
        .iter()
        .map(|c| c.impulse.norm())
        .fold(1e-12, f64::max);
    for c in sim.contacts() {
        let ContactKind::Obstacle { node, .. } = c.kind else {
            continue;
        };
        let v = sim.velocities()[node];
        let vt = v - v.dot(&c.normal) * c.normal;
        let jn = c.impulse.dot(&c.normal);
        let jt = c.impulse - jn * c.normal;
        match c.branch {
            Branch::TakeOff => assert_eq!(c.impulse, Vec3::zeros()),
            Branch::Stick => {
                assert!(vt.norm() * h < slack, "stick node slides {:e}", vt.norm());
                assert!(
                    jt.norm() <= c.mu * jn + 1e-9 * scale,
                    "stick outside the cone"
                );
            }
            Branch::Slip => {
                assert!(
                    (jt.norm() - c.mu * jn).abs() <= 1e-9 * scale,
                    "slip off the cone"
                );
                assert!(jt.dot(&vt) <= 0.0, "friction does not oppose the slip");
            }
        }
    }
}

#[test]
fn contact_newton_solves_the_same_step_as_pd() {
    // From the same states along a drop, one step with each polish at tolerance 1e-12 lands
    // on the same state, for both responses.
    for response in ["inertia", "delassus"] {
        let mut pd = napkin_on_sphere(9, response, "none", 1e-12);
        let mut newton = napkin_on_sphere(9, response, "semismooth", 1e-12);
        let (mut compared, mut pd_iterations, mut newton_iterations) = (0, 0, 0);
        for step in 0..40 {
            let (x, v, t) = (pd.positions().to_vec(), pd.velocities().to_vec(), pd.time());
            let a = pd.step(StepInput::default()).unwrap();
            newton.reset(Some(&x), Some(&v)).unwrap();
            newton.set_time(t).unwrap();
            let b = newton.step(StepInput::default()).unwrap();
            assert!(a.converged && b.converged, "{a:?} {b:?}");
            let apart = max_distance(pd.positions(), newton.positions());
            // Measured: up to about 1e-10 (PD's own error at this tolerance).
            assert!(
                apart <= 1e-8,
                "{response} step {step}: polishes differ by {apart:e} ({a:?} vs {b:?})"
            );
            assert_contact_law(&newton, 1e-9);
            if b.contacts.stick + b.contacts.slip > 0 {
                compared += 1;
                pd_iterations += a.iterations;
                newton_iterations += b.iterations;
            }
        }
        assert!(compared >= 10, "{response}: only {compared} contact steps");
        let p = newton.profile();
        assert!(
            p.contact_newton_steps > 0,
            "{response}: contact Newton never ran"
        );
        assert!(
            2 * newton_iterations < pd_iterations,
            "{response}: {newton_iterations} PD iterations with contact Newton vs {pd_iterations}"
        );
    }
}

#[test]
fn contact_newton_is_one_trajectory_recorded_or_not_on_one_or_two_threads() {
    let run = |record: bool, threads: usize| {
        let mut sim = napkin_on_sphere(12, "inertia", "semismooth", 1e-10);
        let mut solver = sim.solver().clone();
        solver.parallel = true;
        sim.set_solver(solver).unwrap();
        sim.set_recording(record);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let bits: Vec<u64> = pool.install(|| {
            (0..30)
                .flat_map(|_| {
                    sim.step(StepInput::default()).unwrap();
                    sim.positions()
                        .iter()
                        .flat_map(|p| p.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
                        .collect::<Vec<_>>()
                })
                .collect()
        });
        assert!(
            sim.profile().contact_newton_steps > 0,
            "contact Newton never ran"
        );
        bits
    };
    let plain = run(false, 1);
    assert!(
        plain == run(true, 1),
        "recorded steps differ from plain ones"
    );
    assert!(plain == run(false, 2), "two threads differ from one");
}

/// A 4x4 patch sliding (mu 0.2) on a sphere of radius 1, as in `contact_gradients.rs`, with
/// contact Newton.
fn patch_on_sphere(response: &str) -> Simulator {
    let sphere = r#"{ kind = "sphere", center = [0.0, 0.0, 0.0], radius = 1.0 }"#;
    patch_on_obstacle(
        sphere,
        0.2,
        "translate = [0.2, 1.01, 0.1]",
        response,
        "semismooth",
    )
}

/// Gradients through contact Newton steps, slipping and sticking, match central differences.
#[test]
fn gradients_through_contact_newton_steps_match_finite_differences() {
    for response in ["inertia", "delassus"] {
        for (mu, v) in [
            (0.2, Vec3::new(0.8, -0.1, 0.3)),
            (1.0, Vec3::new(0.05, -0.1, 0.0)),
        ] {
            let mut sim = patch_on_sphere(response);
            let steps = 3;
            let n = sim.num_nodes();
            let base = Rollout {
                x0: sim.positions().to_vec(),
                v0: random_vectors(n, 0.02, 4).iter().map(|d| v + d).collect(),
                targets: vec![Vec::new(); steps],
                forces: (0..steps)
                    .map(|k| random_vectors(n, 1e-3, 60 + k as u64))
                    .collect(),
                params: sim.params().clone(),
                mu: Some(mu),
            };
            check_all_gradients(&mut sim, &base, steps, &[AdjointSolver::Krylov], 1.0);
            let p = sim.profile();
            assert!(
                p.contact_newton_steps > 0,
                "{response} mu {mu}: contact Newton never ran ({p:?})"
            );
            let active = sim
                .contacts()
                .iter()
                .filter(|c| c.branch != Branch::TakeOff);
            assert!(
                active.count() >= 2,
                "{response} mu {mu}: no active contacts"
            );
        }
    }
}
