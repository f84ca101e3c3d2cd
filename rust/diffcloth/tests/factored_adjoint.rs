//! The adjoint preconditioned by each step's own factored Hessian (`backward/factored.rs`):
//! used where P preconditions badly (the Hat), it gives the sparse-LU gradient; where P does
//! well (Wind) it is never used. On contact steps the directions the contact law pins are
//! eliminated from the factor, which makes the preconditioner exact where every contact
//! sticks to the obstacle.
use crate::common::*;
use diffcloth::{AdjointSolver, BackwardOptions, Polish, Simulator, StepInput, StepStats, Vec3};

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

/// The Hat lowered onto its head like `make_target` (both handles 0.03 down per step for
/// `steps` steps; contact from step 46), semismooth polish at 1e-10, head friction `mu`.
/// Returns the simulator (recorded) and each step's stats.
fn hat_onto_head(mu: f64, steps: usize) -> (Simulator, Vec<StepStats>) {
    diffcloth::init_linear_algebra();
    let mut cfg = load_config("hat");
    cfg.solver.parallel = false;
    cfg.solver.polish = Polish::Semismooth;
    cfg.solver.tolerance = 1e-10;
    cfg.solver.max_iterations = 2000;
    cfg.obstacles.iter_mut().for_each(|o| o.mu = mu);
    let mut sim = Simulator::new(&cfg).unwrap();
    sim.set_recording(true);
    let mut targets = sim.attachment_targets().to_vec();
    let stats = (0..steps)
        .map(|_| {
            targets.iter_mut().for_each(|t| t.y -= 0.03);
            sim.step(StepInput {
                attachment_targets: Some(&targets),
                ..Default::default()
            })
            .unwrap()
        })
        .collect();
    (sim, stats)
}

/// The Krylov gradient equals the sparse-LU one to 1e-8 (relative).
fn assert_matches_direct(sim: &Simulator, steps: usize, krylov: &diffcloth::Gradients) {
    let direct = gradients(sim, steps, AdjointSolver::Direct);
    let err = relative_error(&flat(krylov), &flat(&direct));
    assert!(err < 1e-8, "vs the direct solve: relative error {err:.2e}");
}

fn relative_error(a: &[f64], b: &[f64]) -> f64 {
    let norm = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
        / norm
}

/// Head friction 5: the hat's contacts with the head stick. Where every active contact sticks
/// (steps 46-48, 53 and 55 here) the preconditioner is the exact inverse of the adjoint
/// operator: one BiCGStab iteration (with the contact-free H's factor: 4-72). The gradient is
/// the sparse-LU one. (The pass factors once a P-preconditioned solve has needed many
/// iterations: here from the last step, 55, on.)
#[test]
fn sticking_contact_steps_take_one_adjoint_iteration() {
    let steps = 56;
    let (sim, stats) = hat_onto_head(5.0, steps);
    let krylov = gradients(&sim, steps, AdjointSolver::Krylov);
    let sticking: Vec<_> = stats
        .iter()
        .zip(&krylov.steps)
        .filter(|(s, a)| s.contacts.stick > 0 && s.contacts.slip == 0 && a.factored)
        .collect();
    assert!(
        sticking.len() >= 3,
        "too few factored sticking steps: {:?}",
        krylov.steps
    );
    for (s, a) in &sticking {
        assert!(a.iterations <= 1, "{s:?}: {a:?}");
    }
    assert_matches_direct(&sim, steps, &krylov);
}

/// The shipped head friction (0.1): up to 150 slipping contacts a step. Measured 10-42
/// iterations on steps with 50 or more slipping contacts (166-453 with the contact-free H's
/// factor); the gradient is the sparse-LU one.
#[test]
fn slipping_contact_steps_converge_in_few_adjoint_iterations() {
    let steps = 58;
    let (sim, stats) = hat_onto_head(0.1, steps);
    let krylov = gradients(&sim, steps, AdjointSolver::Krylov);
    let slipping: Vec<_> = stats
        .iter()
        .zip(&krylov.steps)
        .filter(|(s, _)| s.contacts.slip >= 50)
        .collect();
    assert!(slipping.len() >= 5, "too few slipping steps: {stats:?}");
    for (s, a) in &slipping {
        assert!(
            a.factored && !a.fell_back && a.iterations <= 60,
            "{s:?}: {a:?}"
        );
    }
    assert_matches_direct(&sim, steps, &krylov);
}
