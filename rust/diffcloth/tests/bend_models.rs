//! The edge-based bending model (`material.bend_model = "edge"`) through the whole simulator:
//! gradients against finite differences of the rollout, and a physical fact.
use crate::common::*;
use diffcloth::mesh::{grid, write_obj, GridPlane};
use diffcloth::{AdjointSolver, BackwardOptions, Simulator, StepInput, Vec3};

const ROWS: usize = 5;
const COLS: usize = 5;

/// A 5x5-node, 0.5 m napkin lying in the xz plane, held at its two far corners (row
/// `ROWS - 1`), with gravity, stretch and edge bending; `mesh` is the TOML `[mesh]` body.
/// Converged to 1e-13 m so that finite differences see the implicit-Euler solution.
fn napkin(mesh: &str, k_bend: f64) -> Simulator {
    sim_from_toml(&format!(
        r#"
h = 0.01
effects = ["gravity", "stretch", "bend", "attachments"]
[mesh]
{mesh}
[material]
density = 0.2
k_stretch = 60.0
k_bend = {k_bend}
bend_model = "edge"
[attachments]
stiffness = 500.0
nodes = [{a}, {b}]
[solver]
tolerance = 1e-13
max_iterations = 20000
"#,
        a = (ROWS - 1) * COLS,
        b = ROWS * COLS - 1,
    ))
}

const GRID: &str = r#"kind = "grid"
rows = 5
cols = 5
width = 0.5
height = 0.5
plane = "xz""#;

/// The napkin's grid rolled about z into an arch of radius 0.4 m (a curved rest shape, so
/// the projection Jacobians are not zero), written as an OBJ file; returns its path.
fn arch_obj() -> std::path::PathBuf {
    let m = grid(ROWS, COLS, 0.5, 0.5, GridPlane::Xz).unwrap();
    let r = 0.4;
    let x: Vec<Vec3> = m
        .positions
        .iter()
        .map(|p| Vec3::new(r * (p.x / r).sin(), r * (p.x / r).cos() - r, p.z))
        .collect();
    let dir = std::env::temp_dir().join(format!("diffcloth_bend_arch_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("arch.obj");
    write_obj(&path, &m, &x).unwrap();
    path
}

/// `L = sum_n a_n . x_n + b_n . v_n` of a rollout from rest with initial velocities `v0`.
fn rollout(sim: &mut Simulator, k_bend: f64, v0: &[Vec3], a: &[Vec<Vec3>], b: &[Vec<Vec3>]) -> f64 {
    let mut params = sim.params().clone();
    params.k_bend = k_bend;
    sim.set_params(params).unwrap();
    sim.reset(None, Some(v0)).unwrap();
    let mut loss = 0.0;
    for (an, bn) in a.iter().zip(b) {
        let stats = sim.step(StepInput::default()).unwrap();
        assert!(stats.residual < 1e-11, "forward must converge: {stats:?}");
        let dot = |u: &[Vec3], w: &[Vec3]| u.iter().zip(w).map(|(p, q)| p.dot(q)).sum::<f64>();
        loss += dot(sim.positions(), an) + dot(sim.velocities(), bn);
    }
    loss
}

fn check(name: &str, analytic: f64, fd: f64) {
    let err = (analytic - fd).abs() / fd.abs().max(analytic.abs()).max(1e-3);
    assert!(
        err < 1e-5,
        "{name}: analytic {analytic:.10e} vs fd {fd:.10e} (rel {err:.1e})"
    );
}

/// Checks the k_bend and v0 gradients of a 10-step rollout against central differences.
fn check_gradients(sim: &mut Simulator, k_bend: f64) {
    let (n, steps) = (sim.num_nodes(), 10);
    // The simulator runs the edge model: 9 floats per interior edge (40 on a 5x5 grid).
    assert_eq!(sim.bend().unwrap().linearization_len(), 9 * 40);
    let a: Vec<Vec<Vec3>> = (0..steps)
        .map(|k| random_vectors(n, 1.0, 100 + k))
        .collect();
    let b: Vec<Vec<Vec3>> = (0..steps)
        .map(|k| random_vectors(n, 0.1, 200 + k))
        .collect();
    let v0 = random_vectors(n, 0.5, 2);
    sim.set_recording(true);
    rollout(sim, k_bend, &v0, &a, &b);
    let mut grads = Vec::new();
    for solver in [AdjointSolver::Direct, AdjointSolver::Krylov] {
        let options = BackwardOptions {
            solver,
            tolerance: 1e-10,
            max_iterations: 2000,
        };
        let g = sim.backward(&a, &b, &options).unwrap();
        assert!(g.steps.iter().all(|s| !s.fell_back), "{solver:?} fell back");
        grads.push(g);
    }
    sim.set_recording(false);
    let g = &grads[0];
    assert!(
        (grads[1].k_bend - g.k_bend).abs() <= 1e-7 * g.k_bend.abs().max(1e-3),
        "Krylov {} vs Direct {}",
        grads[1].k_bend,
        g.k_bend
    );
    // Relative steps as tests/gradients.rs (1e-4 in k, 1e-3 in v0).
    let dk = 1e-4 * k_bend;
    let fd_k = (rollout(sim, k_bend + dk, &v0, &a, &b) - rollout(sim, k_bend - dk, &v0, &a, &b))
        / (2.0 * dk);
    check("k_bend", g.k_bend * k_bend, fd_k * k_bend);
    let dv = random_vectors(n, 1.0, 7);
    let eps = 1e-3;
    let shifted = |s: f64| -> Vec<Vec3> { v0.iter().zip(&dv).map(|(v, d)| v + s * d).collect() };
    let fd_v = (rollout(sim, k_bend, &shifted(eps), &a, &b)
        - rollout(sim, k_bend, &shifted(-eps), &a, &b))
        / (2.0 * eps);
    let analytic_v: f64 = g.v0.iter().zip(&dv).map(|(p, q)| p.dot(q)).sum();
    check("v0", analytic_v, fd_v);
}

/// Flat rest shape: bending acts through `K` alone (the projections are zero).
#[test]
fn edge_bending_gradients_match_finite_differences_on_a_flat_napkin() {
    let mut sim = napkin(GRID, 0.02);
    check_gradients(&mut sim, 0.02);
}

/// Curved rest shape: the projection Jacobians (`dP`) enter the adjoint.
#[test]
fn edge_bending_gradients_match_finite_differences_on_a_curved_napkin() {
    let path = arch_obj();
    let mut sim = napkin(&format!("kind = \"obj\"\npath = {:?}", path), 0.02);
    check_gradients(&mut sim, 0.02);
    let _ = std::fs::remove_dir_all(path.parent().unwrap());
}

/// A 0.6 m x 0.12 m strip (13 x 3 nodes) clamped at one end (its first two columns held)
/// sags under gravity; with the edge model its tip sags less for larger `k_bend`.
#[test]
fn a_stiffer_edge_bending_strip_sags_less() {
    let tip_sag = |k_bend: f64| {
        let mut sim = sim_from_toml(&format!(
            r#"
h = 0.01
effects = ["gravity", "stretch", "bend", "attachments"]
[mesh]
kind = "grid"
rows = 3
cols = 13
width = 0.6
height = 0.12
plane = "xz"
[material]
density = 0.2
k_stretch = 200.0
k_bend = {k_bend}
bend_model = "edge"
[attachments]
nodes = [0, 1, 13, 14, 26, 27]
"#
        ));
        for _ in 0..400 {
            sim.step(StepInput::default()).unwrap();
        }
        // The free end's nodes (column 12), relative to the clamp height y = 0.
        -[12, 25, 38]
            .iter()
            .map(|&i| sim.positions()[i].y)
            .sum::<f64>()
            / 3.0
    };
    let sags: Vec<f64> = [0.01, 0.1, 1.0].iter().map(|&k| tip_sag(k)).collect();
    assert!(sags[0] > 0.0, "{sags:?}");
    assert!(
        sags[0] > 1.5 * sags[1] && sags[1] > 1.5 * sags[2] && sags[2] > 0.0,
        "tip sag must fall with k_bend: {sags:?}"
    );
}
