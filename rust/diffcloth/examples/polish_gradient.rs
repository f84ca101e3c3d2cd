//! Gradient error of a Hat rollout driven like `DiffCloth/Hat-v0` with random actions (loss on
//! every step) against a PD rollout converged to 1e-13, per forward tolerance and polish:
//! `cargo run --release --example polish_gradient [STEPS] [REFERENCE_POLISH] [POLISH:TOL ...]`
//! (the reference is solved to 1e-13 with that polish, default none; the cases default to
//! both polishes at 1e-8 .. 1e-11). Also prints the backward's cost; `PER_STEP=1` lists each
//! step's adjoint iterations.
use diffcloth::{BackwardOptions, Polish, Simulator, SolverSettings, StepInput, Vec3};

type Rollout = (Vec<Vec3>, Vec<Vec<Vec3>>, u64, u64, f64, (f64, f64, usize));

fn rollout(tol: f64, polish: Polish, steps: usize) -> Rollout {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../diffcloth_gym/configs/hat.toml");
    let mut sim = Simulator::from_toml_file(&path).unwrap();
    let s = sim.solver().clone();
    sim.set_solver(SolverSettings {
        tolerance: tol,
        max_iterations: 20000,
        parallel: false,
        polish,
        ..s
    })
    .unwrap();
    sim.set_recording(true);
    let mut seed = 12345u64;
    let mut rand = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    let mut targets: Vec<Vec3> = sim.attachment_targets().to_vec();
    let t0 = std::time::Instant::now();
    for _ in 0..steps {
        for t in targets.iter_mut() {
            *t += 0.1 * Vec3::new(rand(), rand(), rand());
        }
        sim.step(StepInput {
            attachment_targets: Some(&targets),
            ..Default::default()
        })
        .unwrap();
    }
    let forward = t0.elapsed().as_secs_f64();
    let n = sim.num_nodes();
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
    let t1 = std::time::Instant::now();
    let g = sim
        .backward(&dl_dx, &[], &BackwardOptions::default())
        .unwrap();
    let backward = 1e3 * t1.elapsed().as_secs_f64() / steps as f64;
    let adjoint_iterations =
        g.steps.iter().map(|s| s.iterations).sum::<usize>() as f64 / steps as f64;
    let fell_back = g.steps.iter().filter(|s| s.fell_back).count();
    if std::env::var("PER_STEP").is_ok() {
        let its: Vec<usize> = g.steps.iter().map(|s| s.iterations).collect();
        eprintln!("adjoint iterations per step: {its:?}");
    }
    let p = sim.profile();
    (
        g.v0,
        g.attachment_targets,
        p.iterations,
        p.newton_cg_iterations,
        1e3 * forward / steps as f64,
        (backward, adjoint_iterations, fell_back),
    )
}

fn main() {
    diffcloth::init_linear_algebra();
    let steps: usize = std::env::args().nth(1).map_or(60, |t| t.parse().unwrap());
    let reference_polish = std::env::args()
        .nth(2)
        .map_or(Polish::None, |p| Polish::from_name(&p).unwrap());
    let (rv, rt, ..) = rollout(1e-13, reference_polish, steps);
    let flat = |v: &[Vec3], t: &[Vec<Vec3>]| -> Vec<f64> {
        v.iter()
            .chain(t.iter().flatten())
            .flat_map(|x| x.iter().copied().collect::<Vec<_>>())
            .collect()
    };
    let reference = flat(&rv, &rt);
    let norm = reference.iter().map(|x| x * x).sum::<f64>().sqrt();
    // Optional cases after the two arguments, e.g. `newton:1e-10` (default: every polish at
    // 1e-8 .. 1e-11).
    let mut cases: Vec<(Polish, f64)> = std::env::args()
        .skip(3)
        .map(|c| {
            let (p, t) = c.split_once(':').expect("case POLISH:TOL");
            (
                Polish::from_name(p).expect("polish"),
                t.parse().expect("tolerance"),
            )
        })
        .collect();
    if cases.is_empty() {
        for polish in [Polish::None, Polish::Newton] {
            for tol in [1e-8, 1e-9, 1e-10, 1e-11] {
                cases.push((polish, tol));
            }
        }
    }
    {
        for (polish, tol) in cases {
            let (v, t, it, cg, ms, (back, adj, fell)) = rollout(tol, polish, steps);
            let g = flat(&v, &t);
            let err = g
                .iter()
                .zip(&reference)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt()
                / norm;
            println!(
                "{:6} tol {tol:.0e}: gradient rel. error {err:.2e}, PD it/step {:.1}, CG it/step {:.1}, forward {ms:.1} ms/step, backward {back:.2} ms/step ({adj:.1} adjoint it/step, {fell} fell back)",
                polish.name(), it as f64 / steps as f64, cg as f64 / steps as f64
            );
        }
    }
}
