//! Times plain PD iterations of a shipped scene for profiling (e.g. under `perf record`):
//! `cargo run --release --example hat_iterations [scene]`; set `PAR=1` for the parallel local step.
use diffcloth::{Simulator, SolverSettings, StepInput};
fn main() {
    diffcloth::init_linear_algebra();
    let scene = std::env::args().nth(1).unwrap_or_else(|| "hat".into());
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(format!("../../diffcloth_gym/configs/{scene}.toml"));
    let mut sim = Simulator::from_toml_file(&path).unwrap();
    let s = sim.solver().clone();
    sim.set_solver(SolverSettings {
        tolerance: 0.0,
        max_iterations: 200,
        acceleration: diffcloth::Acceleration::None,
        parallel: std::env::var("PAR").is_ok(),
        ..s
    })
    .unwrap();
    for _ in 0..100 {
        sim.step(StepInput::default()).unwrap();
    }
    println!(
        "nodes {} factor (nnz, supernodal) {:?}",
        sim.num_nodes(),
        sim.factor_stats()
    );
    let p = sim.profile();
    let it = p.iterations as f64;
    println!(
        "{scene}: {:.4} ms/iter (local {:.4}, global {:.4})",
        1e3 * p.total.as_secs_f64() / it,
        1e3 * p.local.as_secs_f64() / it,
        1e3 * p.global.as_secs_f64() / it
    );
}
