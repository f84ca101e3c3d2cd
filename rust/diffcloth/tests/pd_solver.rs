//! The PD local-global solve: convergence, agreement with Newton, acceleration, determinism.
use crate::common::*;
use diffcloth::{SolverSettings, StepInput, Vec3};
use nalgebra::{DMatrix, DVector};

/// A small deformed step: stretch with limits, bending, a pin, gravity and random initial
/// velocities (1 m/s) that excite every constraint.
fn small_scene(acceleration: &str, iterations: usize, tolerance: f64) -> diffcloth::Simulator {
    let mut sim = sim_from_toml(&format!(
        r#"
h = 0.01
effects = ["gravity", "stretch", "bend", "attachments"]
[mesh]
kind = "grid"
rows = 4
cols = 4
width = 1.0
height = 1.0
plane = "xz"
[material]
density = 0.2
k_stretch = 300.0
k_bend = 0.05
strain_limits = [0.95, 1.05]
[attachments]
stiffness = 1000.0
nodes = [0]
[solver]
acceleration = "{acceleration}"
max_iterations = {iterations}
tolerance = {tolerance}
"#
    ));
    let v0 = random_vectors(sim.num_nodes(), 1.0, 11);
    sim.reset(None, Some(&v0)).unwrap();
    sim
}

fn flatten(x: &[Vec3]) -> DVector<f64> {
    DVector::from_iterator(3 * x.len(), x.iter().flat_map(|p| [p.x, p.y, p.z]))
}

fn unflatten(v: &DVector<f64>) -> Vec<Vec3> {
    (0..v.len() / 3)
        .map(|i| Vec3::new(v[3 * i], v[3 * i + 1], v[3 * i + 2]))
        .collect()
}

/// Newton's method on the same implicit-Euler objective, with a dense Hessian obtained by
/// central differences of the exact gradient and a backtracking line search.
fn newton_solve(sim: &mut diffcloth::Simulator, start: &[Vec3]) -> Vec<Vec3> {
    let mut x = flatten(start);
    let dim = x.len();
    for _ in 0..100 {
        let (e, g) = sim.step_objective(&unflatten(&x));
        let g = flatten(&g);
        if g.norm() < 1e-11 {
            break;
        }
        let eps = 1e-6;
        let mut hess = DMatrix::zeros(dim, dim);
        for k in 0..dim {
            let mut xp = x.clone();
            xp[k] += eps;
            let gp = flatten(&sim.step_objective(&unflatten(&xp)).1);
            xp[k] -= 2.0 * eps;
            let gm = flatten(&sim.step_objective(&unflatten(&xp)).1);
            hess.set_column(k, &((gp - gm) / (2.0 * eps)));
        }
        let hess = (&hess + hess.transpose()) * 0.5;
        let dir = hess.lu().solve(&(-&g)).expect("Hessian is invertible");
        let mut t = 1.0;
        while t > 1e-8 && sim.step_objective(&unflatten(&(&x + t * &dir))).0 > e {
            t *= 0.5;
        }
        x += t * dir;
    }
    unflatten(&x)
}

#[test]
fn two_hundred_plain_pd_iterations_agree_with_newton() {
    let mut sim = small_scene("none", 200, 0.0);
    sim.prepare(StepInput::default()).unwrap();
    sim.set_trace(true);
    let (x_pd, stats) = sim.solve_prepared();
    assert_eq!(stats.iterations, 200);
    let start = sim.positions().to_vec();
    let x_newton = newton_solve(&mut sim, &start);
    let (_, g) = sim.step_objective(&x_newton);
    assert!(flatten(&g).norm() < 1e-9, "Newton converged");
    let err = max_distance(&x_pd, &x_newton);
    assert!(err < 1e-6, "PD vs Newton: {err}");
}

#[test]
fn residual_decreases_and_energy_never_increases() {
    for accel in ["none", "anderson"] {
        let mut sim = small_scene(accel, 200, 0.0);
        sim.set_trace(true);
        sim.step(StepInput::default()).unwrap();
        let trace = sim.trace().unwrap().to_vec();
        // The loop ends early only if the update is exactly zero (a bitwise fixed point).
        assert!(
            trace.len() == 200 || trace.last().unwrap().1 == 0.0,
            "{accel}: {} iterations",
            trace.len()
        );
        for w in trace.windows(2) {
            assert!(
                w[1].0 <= w[0].0 + 1e-12 * w[0].0.abs(),
                "{accel}: energy rose {} -> {}",
                w[0].0,
                w[1].0
            );
        }
        let (first, last) = (trace[0].1, trace.last().unwrap().1);
        assert!(last < 1e-8 * first, "{accel}: residual {first} -> {last}");
        if accel == "none" {
            // Plain PD: the residual also decreases over every 10-iteration window.
            for k in (10..trace.len()).step_by(10) {
                assert!(
                    trace[k].1 < trace[k - 10].1 || trace[k].1 < 1e-13,
                    "{accel}: iteration {k}"
                );
            }
        }
    }
}

/// The hanging hat buckles and snaps through (from about step 38): the iterates pass near
/// saddles of the step energy, where Anderson's extrapolations are rejected and plain PD
/// crawls along the unstable direction (before the saddle escape, steps took 100-300
/// iterations and two hit the cap of 300). With the escape every step converges, the energy
/// still never rises within a step, and no step needs more than 200 iterations.
#[test]
fn buckling_hat_leaves_saddles_with_falling_energy() {
    let mut cfg = contact_free_config("hat");
    cfg.solver.tolerance = 1e-7;
    cfg.solver.max_iterations = 300;
    cfg.solver.parallel = false;
    let mut sim = diffcloth::Simulator::new(&cfg).unwrap();
    sim.set_trace(true);
    let mut most = 0;
    for n in 0..80 {
        let stats = sim.step(StepInput::default()).unwrap();
        assert!(stats.converged, "step {n}: {stats:?}");
        most = most.max(stats.iterations);
        for w in sim.trace().unwrap().windows(2) {
            assert!(
                w[1].0 <= w[0].0 + 1e-12 * w[0].0.abs(),
                "step {n}: energy rose {} -> {}",
                w[0].0,
                w[1].0
            );
        }
    }
    assert!(
        sim.profile().escape_steps > 0,
        "the scene no longer buckles: pick another"
    );
    assert!(most <= 200, "a step took {most} iterations");
}

/// Anderson reaches the same trajectory as plain PD in several times fewer iterations.
/// (Per-step errors compound through v = (x_{n+1} - x_n) / h, hence the tight tolerance.)
#[test]
fn anderson_converges_to_the_same_solution_in_fewer_iterations() {
    let tol = 1e-12;
    let mut plain = small_scene("none", 5000, tol);
    let mut fast = small_scene("anderson", 5000, tol);
    let (mut it_plain, mut it_fast) = (0, 0);
    for _ in 0..10 {
        it_plain += plain.step(StepInput::default()).unwrap().iterations;
        it_fast += fast.step(StepInput::default()).unwrap().iterations;
    }
    let err = max_distance(plain.positions(), fast.positions());
    assert!(err < 1e-6, "trajectories differ by {err}");
    assert!(
        3 * it_fast < it_plain,
        "anderson {it_fast} vs plain {it_plain} iterations"
    );
}

/// The parallel local step gives bit-identical results to the serial one.
#[test]
fn parallel_and_serial_local_steps_are_bitwise_identical() {
    let mut cfg = load_config("wind");
    cfg.mesh = diffcloth::config::MeshConfig::Grid {
        rows: 40,
        cols: 40,
        width: 6.0,
        height: 6.0,
        plane: diffcloth::mesh::GridPlane::Xy,
    };
    cfg.solver.max_iterations = 30;
    let run = |parallel: bool| {
        let mut c = cfg.clone();
        c.solver.parallel = parallel;
        let mut sim = diffcloth::Simulator::new(&c).unwrap();
        for _ in 0..5 {
            sim.step(StepInput::default()).unwrap();
        }
        sim.positions().to_vec()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let parallel = pool.install(|| run(true));
    let serial = run(false);
    assert!(parallel.iter().zip(&serial).all(|(a, b)| a
        .iter()
        .zip(b.iter())
        .all(|(p, q)| p.to_bits() == q.to_bits())));
}

#[test]
fn solver_settings_are_validated() {
    let mut sim = small_scene("anderson", 10, 1e-8);
    let ok = sim.solver().clone();
    assert!(sim
        .set_solver(SolverSettings {
            max_iterations: 0,
            ..ok.clone()
        })
        .is_err());
    assert!(sim
        .set_solver(SolverSettings {
            tolerance: f64::NAN,
            ..ok.clone()
        })
        .is_err());
    assert!(sim
        .set_solver(SolverSettings {
            history: 99,
            ..ok.clone()
        })
        .is_err());
    assert_eq!(sim.solver(), &ok);
}
