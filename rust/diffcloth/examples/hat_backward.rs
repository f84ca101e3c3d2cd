//! Times the contact-free Hat's backward pass (controller style: a loss on every step) for
//! profiling, e.g. under `perf record`:
//! `cargo run --release --example hat_backward [STEPS] [EPS] [REPEATS]`.
use diffcloth::{AdjointSolver, BackwardOptions, Effect, SceneConfig, Simulator, StepInput, Vec3};
use std::time::Instant;

fn main() {
    diffcloth::init_linear_algebra();
    let arg = |i: usize, default: f64| {
        std::env::args()
            .nth(i)
            .map_or(default, |a| a.parse().unwrap())
    };
    let (steps, eps, repeats) = (arg(1, 50.0) as usize, arg(2, 1e-4), arg(3, 5.0) as usize);
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../diffcloth_gym/configs/hat.toml");
    let mut cfg = SceneConfig::from_toml_file(&path).unwrap();
    cfg.effects.retain(|e| {
        !matches!(
            e,
            Effect::ObstacleContact | Effect::Friction | Effect::SelfCollision
        )
    });
    cfg.obstacles.clear();
    cfg.self_collision = None;
    cfg.contact = None;
    cfg.solver.parallel = false;
    let mut sim = Simulator::new(&cfg).unwrap();
    sim.set_recording(true);
    for _ in 0..steps {
        sim.step(StepInput::default()).unwrap();
    }
    let n = sim.num_nodes();
    // A fixed pseudo-random linear loss on every step's positions.
    let dl_dx: Vec<Vec<Vec3>> = (0..steps)
        .map(|s| {
            (0..n)
                .map(|i| {
                    let t = (s * n + i) as f64;
                    Vec3::new(t.sin(), (1.3 * t).cos(), (0.7 * t).sin()) / n as f64
                })
                .collect()
        })
        .collect();
    let options = BackwardOptions {
        solver: AdjointSolver::Krylov,
        tolerance: eps,
        ..Default::default()
    };
    let mut best = f64::INFINITY;
    for _ in 0..repeats {
        let start = Instant::now();
        let g = sim.backward(&dl_dx, &[], &options).unwrap();
        let ms = 1e3 * start.elapsed().as_secs_f64() / steps as f64;
        best = best.min(ms);
        let it: usize = g.steps.iter().map(|s| s.iterations).sum();
        println!(
            "{ms:.3} ms/step, {:.1} it/step, {:.4} ms/it (solve share {:.0} %)",
            it as f64 / steps as f64,
            ms / (it as f64 / steps as f64),
            100.0 * g.profile.solve.as_secs_f64() / (1e-3 * ms * steps as f64)
        );
    }
    println!("best of {repeats}: {best:.3} ms/step");
}
