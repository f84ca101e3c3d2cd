//! Iteration counts of the Hat under random effector motion (like `DiffCloth/Hat-v0` with
//! random actions): `cargo run --release --example hat_polish [TOL] [STEPS] [POLISH] [TRACE_STEP]`.
use diffcloth::{Polish, Simulator, SolverSettings, StepInput, Vec3};
fn main() {
    diffcloth::init_linear_algebra();
    let args: Vec<String> = std::env::args().collect();
    let tol: f64 = args.get(1).map_or(1e-10, |t| t.parse().unwrap());
    let steps: usize = args.get(2).map_or(60, |t| t.parse().unwrap());
    let polish = args
        .get(3)
        .map_or(Polish::None, |t| Polish::from_name(t).unwrap());
    let trace_step: Option<usize> = args.get(4).map(|t| t.parse().unwrap());
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../diffcloth_gym/configs/hat.toml");
    let mut sim = Simulator::from_toml_file(&path).unwrap();
    let s = sim.solver().clone();
    sim.set_solver(SolverSettings {
        tolerance: tol,
        max_iterations: 2000,
        parallel: false,
        polish,
        ..s
    })
    .unwrap();
    sim.set_trace(trace_step.is_some());
    let mut seed = 12345u64;
    let mut rand = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    // ERR=1: each step's distance to the same step solved by PD alone at 1e-13.
    let mut reference = std::env::var("ERR").is_ok().then(|| {
        let mut r = Simulator::from_toml_file(&path).unwrap();
        let s = r.solver().clone();
        r.set_solver(SolverSettings {
            tolerance: 1e-13,
            max_iterations: 20000,
            parallel: false,
            ..s
        })
        .unwrap();
        r
    });
    let (mut err_max, mut err_sum) = (0.0f64, 0.0);
    let mut errs: Vec<f64> = Vec::new();
    let mut targets: Vec<Vec3> = sim.attachment_targets().to_vec();
    let mut step_times = Vec::new();
    let t0 = std::time::Instant::now();
    for n in 0..steps {
        for t in targets.iter_mut() {
            *t += 0.1 * Vec3::new(rand(), rand(), rand());
        }
        let input = StepInput {
            attachment_targets: Some(&targets),
            ..Default::default()
        };
        let (x_prev, v_prev) = (sim.positions().to_vec(), sim.velocities().to_vec());
        let exact = reference.as_mut().map(|r| {
            r.reset(Some(sim.positions()), Some(sim.velocities()))
                .unwrap();
            r.step(input).unwrap();
            r.positions().to_vec()
        });
        let step_start = std::time::Instant::now();
        let st = sim.step(input).unwrap();
        step_times.push((
            step_start.elapsed().as_secs_f64(),
            st.iterations,
            st.contacts,
        ));
        if let Some(exact) = exact {
            let e = exact
                .iter()
                .zip(sim.positions())
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max);
            if e > 1e-4 {
                let r = reference.as_mut().unwrap();
                r.reset(Some(&x_prev), Some(&v_prev)).unwrap();
                r.prepare(input).unwrap();
                let (e_ref, _) = r.step_objective(&exact);
                let (e_sim, _) = r.step_objective(sim.positions());
                eprintln!("step {n}: one-step error {e:.2e}, E reference {e_ref:.12e} E this {e_sim:.12e}");
            }
            err_max = err_max.max(e);
            err_sum += e;
            errs.push(e);
        }
        if !st.converged {
            eprintln!("step {n} unconverged: {st:?}");
        }
        if Some(n) == trace_step {
            println!("step {n}: {st:?}");
            for (i, (e, r)) in sim.trace().unwrap().iter().enumerate() {
                eprintln!("{i:4} E {e:.12e} res {r:.3e}");
            }
        }
    }
    let p = sim.profile();
    let st = p.steps as f64;
    if reference.is_some() {
        errs.sort_by(f64::total_cmp);
        println!(
            "one-step error vs PD at 1e-13: max {err_max:.2e} mean {:.2e} median {:.2e}, steps above 1e-5: {}",
            err_sum / st,
            errs[errs.len() / 2],
            errs.iter().filter(|&&e| e > 1e-5).count()
        );
    }
    println!(
        "tol {tol:e}: {:.2} ms/step, it/step {:.1} escapes/step {:.2} rejections/step {:.2} unconverged {}",
        1e3 * t0.elapsed().as_secs_f64() / st,
        p.iterations as f64 / st,
        p.escape_steps as f64 / st,
        p.acceleration_rejections as f64 / st,
        p.unconverged_steps
    );
    // Where the time goes: the slowest tenth of the steps against the rest.
    step_times.sort_by(|a, b| b.0.total_cmp(&a.0));
    let total: f64 = step_times.iter().map(|s| s.0).sum();
    let tenth = (step_times.len() / 10).max(1);
    let slow: f64 = step_times[..tenth].iter().map(|s| s.0).sum();
    println!(
        "  slowest {tenth} steps: {:.0} % of the time; slowest: {:?}",
        100.0 * slow / total,
        &step_times[..3.min(step_times.len())]
    );
    let per = |d: std::time::Duration, n: u64| 1e3 * d.as_secs_f64() / n.max(1) as f64;
    println!(
        "  ms per PD iteration (local+global) {:.4}, per CG iteration (incl. linearize) {:.4}",
        per(p.local + p.global, p.iterations),
        per(p.newton, p.newton_cg_iterations)
    );
    for (k, v) in p.entries() {
        if v != 0.0 {
            println!("  {k}: {:.2}/step", v / st);
        }
    }
}
