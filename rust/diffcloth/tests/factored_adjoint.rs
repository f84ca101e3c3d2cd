//! The adjoint preconditioned by each step's own factored Hessian (`backward/factored.rs`):
//! used where P preconditions badly (the Hat), it gives the sparse-LU gradient; where P does
//! well (Wind) it is never used.
use crate::common::*;
use diffcloth::{AdjointSolver, BackwardOptions, Polish, Simulator, StepInput, Vec3};

/// A loss on every step's positions, and the gradients of it.
fn gradients(sim: &Simulator, steps: usize, solver: AdjointSolver) -> diffcloth::Gradients {
    let n = sim.num_nodes();
    let dl_dx: Vec<Vec<Vec3>> = (0..steps)
        .map(|k| random_vectors(n, 1.0 / n as f64, 100 + k as u64))
        .collect();
    let options = BackwardOptions {
        solver,
        ..Default::default()
    };
    sim.backward(&dl_dx, &[], &options).unwrap()
}

fn flat(g: &diffcloth::Gradients) -> Vec<f64> {
    g.v0.iter()
        .chain(g.attachment_targets.iter().flatten())
        .flat_map(|v| v.iter().copied().collect::<Vec<_>>())
        .collect()
}

/// The Hat on its head, polished to 1e-10 and driven like the env for `steps` steps.
fn driven_hat(steps: usize) -> Simulator {
    diffcloth::init_linear_algebra();
    let mut cfg = load_config("hat");
    cfg.solver.parallel = false;
    cfg.solver.polish = Polish::Newton;
    cfg.solver.tolerance = 1e-10;
    cfg.solver.max_iterations = 2000;
    let mut sim = Simulator::new(&cfg).unwrap();
    sim.set_recording(true);
    let mut targets = sim.attachment_targets().to_vec();
    for k in 0..steps {
        let moves = random_vectors(targets.len(), 0.1, 31 + k as u64);
        targets.iter_mut().zip(&moves).for_each(|(t, m)| *t += m);
        sim.step(StepInput {
            attachment_targets: Some(&targets),
            ..Default::default()
        })
        .unwrap();
    }
    sim
}

/// The Hat on its head, polished and driven like the env: P-preconditioned CG needs over a
/// hundred iterations per step there, so the pass factors each step's H; the gradient is the
/// sparse-LU one, and the same bits on a rerun.
#[test]
fn factored_adjoint_on_the_hat_matches_the_direct_solve() {
    let steps = 12;
    let sim = driven_hat(steps);
    let krylov = gradients(&sim, steps, AdjointSolver::Krylov);
    let factored = krylov.steps.iter().filter(|s| s.factored).count();
    assert!(
        factored > 0,
        "no step used the factored Hessian: {:?}",
        krylov.steps
    );
    assert!(krylov.steps.iter().all(|s| !s.fell_back));
    // Measured: one iteration per factored step.
    for s in krylov.steps.iter().filter(|s| s.factored) {
        assert!(s.iterations <= 6, "{s:?}");
    }
    let direct = flat(&gradients(&sim, steps, AdjointSolver::Direct));
    let (a, norm) = (
        flat(&krylov),
        direct.iter().map(|x| x * x).sum::<f64>().sqrt(),
    );
    let err = a
        .iter()
        .zip(&direct)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
        / norm;
    assert!(
        err < 1e-8,
        "factored vs direct gradient: relative error {err:.2e}"
    );
    let again = flat(&gradients(&sim, steps, AdjointSolver::Krylov));
    assert!(
        a.iter()
            .zip(&again)
            .all(|(x, y)| x.to_bits() == y.to_bits()),
        "a rerun changed the gradient"
    );
}

/// One-step adjoints chained in reverse (`backward_step`, what `step_grad` runs) carry the
/// switch along the chain, and the chain's dL/dv0 is the full backward's.
#[test]
fn chained_one_step_adjoints_use_the_factor_too() {
    let steps = 8;
    let sim = driven_hat(steps);
    let full = gradients(&sim, steps, AdjointSolver::Krylov);
    let n = sim.num_nodes();
    let options = BackwardOptions::default();
    let loss = |k: usize| random_vectors(n, 1.0 / n as f64, 100 + k as u64);
    let (mut warm, mut dl_x, mut dl_v) = (None, loss(steps - 1), vec![Vec3::zeros(); n]);
    let mut factored = 0;
    for k in (0..steps).rev() {
        let g = sim
            .backward_step(k, &dl_x, &dl_v, &options, &mut warm)
            .unwrap();
        factored += usize::from(g.steps[k].factored);
        (dl_x, dl_v) = (g.x0, g.v0);
        if k > 0 {
            dl_x.iter_mut().zip(&loss(k - 1)).for_each(|(a, b)| *a += b);
        }
    }
    assert!(factored > 0, "the chain never used the factored Hessian");
    let norm = |v: &[Vec3]| v.iter().map(|x| x.norm_squared()).sum::<f64>().sqrt();
    let diff: Vec<Vec3> = dl_v.iter().zip(&full.v0).map(|(a, b)| a - b).collect();
    let err = norm(&diff) / norm(&full.v0);
    assert!(err < 1e-7, "chained dL/dv0 vs the full backward: {err:.2e}");
}

/// Wind (the scene file's 12x12 cloth): P-preconditioned CG converges in about 26
/// iterations, so no step pays for a factorization.
#[test]
fn factored_adjoint_is_not_used_where_p_preconditions_well() {
    diffcloth::init_linear_algebra();
    let mut cfg = load_config("wind");
    cfg.solver.parallel = false;
    cfg.solver.tolerance = 1e-10;
    cfg.solver.max_iterations = 2000;
    let mut sim = Simulator::new(&cfg).unwrap();
    sim.set_recording(true);
    let steps = 10;
    for _ in 0..steps {
        sim.step(StepInput::default()).unwrap();
    }
    let g = gradients(&sim, steps, AdjointSolver::Krylov);
    assert!(g.steps.iter().all(|s| !s.factored), "{:?}", g.steps);
}
