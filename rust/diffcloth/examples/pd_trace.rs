//! Prints the PD convergence trace (energy, residual per iteration) of one step of a scene:
//! `cargo run --release --example pd_trace CONFIG.toml STEP [TOL]`.
use diffcloth::{Simulator, SolverSettings, StepInput};
fn main() {
    diffcloth::init_linear_algebra();
    let args: Vec<String> = std::env::args().collect();
    let mut sim = Simulator::from_toml_file(std::path::Path::new(&args[1])).unwrap();
    let step: usize = args[2].parse().unwrap();
    let tol: f64 = args.get(3).map_or(1e-7, |t| t.parse().unwrap());
    let s = sim.solver().clone();
    sim.set_solver(SolverSettings {
        tolerance: tol,
        max_iterations: 300,
        parallel: false,
        ..s
    })
    .unwrap();
    sim.set_trace(true);
    for n in 0..=step {
        let st = sim.step(StepInput::default()).unwrap();
        if n == step {
            println!("step {n}: {st:?}");
            let t = sim.trace().unwrap();
            let e0 = t.last().unwrap().0;
            for (i, (e, r)) in t.iter().enumerate() {
                println!("{i:4} dE {:+.3e} res {r:.3e}", e - e0);
            }
        }
    }
}
