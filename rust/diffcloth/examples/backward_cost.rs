//! Forward and backward cost of a falling scene (default inputs, a loss on every step), one
//! thread: `cargo run --release --example backward_cost SCENE [STEPS] [TOL] [POLISH]`
//! (SCENE names a file in diffcloth_gym/configs; defaults 40 steps, tolerance 1e-10, polish
//! none). Prints ms/step forward and backward and the adjoint's iterations per step.
use diffcloth::{BackwardOptions, Polish, SceneConfig, Simulator, StepInput, Vec3};
use std::time::Instant;

fn main() {
    diffcloth::init_linear_algebra();
    let args: Vec<String> = std::env::args().collect();
    let scene = args.get(1).expect("SCENE");
    let steps: usize = args.get(2).map_or(40, |s| s.parse().unwrap());
    let tol: f64 = args.get(3).map_or(1e-10, |s| s.parse().unwrap());
    let polish = args
        .get(4)
        .map_or(Polish::None, |p| Polish::from_name(p).expect("polish"));
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../diffcloth_gym/configs")
        .join(format!("{scene}.toml"));
    let mut cfg = SceneConfig::from_toml_file(&path).unwrap();
    cfg.solver.parallel = false;
    cfg.solver.polish = polish;
    cfg.solver.tolerance = tol;
    cfg.solver.max_iterations = 5000;
    let mut sim = Simulator::new(&cfg).unwrap();
    sim.set_recording(true);
    let start = Instant::now();
    for _ in 0..steps {
        sim.step(StepInput::default()).unwrap();
    }
    let forward = 1e3 * start.elapsed().as_secs_f64() / steps as f64;
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
    let start = Instant::now();
    let g = sim
        .backward(&dl_dx, &[], &BackwardOptions::default())
        .unwrap();
    let backward = 1e3 * start.elapsed().as_secs_f64() / steps as f64;
    let iterations: usize = g.steps.iter().map(|s| s.iterations).sum();
    let checksum =
        g.v0.iter()
            .flat_map(|v| v.iter())
            .fold(0u64, |h, c| (h ^ c.to_bits()).rotate_left(5));
    println!(
        "{scene} ({n} nodes) tol {tol:.0e} polish {}: forward {forward:.2} ms/step ({:.1} PD it/step), backward {backward:.2} ms/step ({:.1} adjoint it/step, {} fell back), |dL/dv0| {:.6e} bits {checksum:016x}",
        polish.name(),
        sim.profile().iterations as f64 / steps as f64,
        iterations as f64 / steps as f64,
        g.steps.iter().filter(|s| s.fell_back).count(),
        g.v0.iter().map(|v| v.norm_squared()).sum::<f64>().sqrt(),
    );
    let per = |d: std::time::Duration| 1e3 * d.as_secs_f64() / steps as f64;
    println!(
        "  backward stages ms/step: dP {:.2}, dR {:.2}, solve {:.2}, other {:.2}; factored steps {}",
        per(g.profile.dp),
        per(g.profile.dr),
        per(g.profile.solve),
        per(g.profile.other),
        g.steps.iter().filter(|s| s.factored).count()
    );
    // The same loss through chained one-step adjoints (what `step_grad` runs).
    let options = BackwardOptions::default();
    let (mut warm, mut ax, mut av) = (None, dl_dx[steps - 1].clone(), vec![Vec3::zeros(); n]);
    let (mut iterations, mut factored) = (0, 0);
    let start = Instant::now();
    for k in (0..steps).rev() {
        let gk = sim.backward_step(k, &ax, &av, &options, &mut warm).unwrap();
        iterations += gk.steps[k].iterations;
        factored += usize::from(gk.steps[k].factored);
        (ax, av) = (gk.x0, gk.v0);
        if k > 0 {
            ax.iter_mut().zip(&dl_dx[k - 1]).for_each(|(a, b)| *a += b);
        }
    }
    println!(
        "  one-step chain: {:.2} ms/step ({:.1} adjoint it/step, factored steps {factored})",
        1e3 * start.elapsed().as_secs_f64() / steps as f64,
        iterations as f64 / steps as f64
    );
}
