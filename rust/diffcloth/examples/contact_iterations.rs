//! PD iterations per step with and without contact, per solver polish (issue 15 item 2):
//! `cargo run --release --example contact_iterations -- SCENE STEPS TOL POLISH...` with SCENE
//! `sphere:N` (the sphere drop on N x N nodes, same 6 m cloth), `hatdown:D` (the Hat with its
//! head, both handles lowered by D per step for 60 steps and then held: the hat comes to rest
//! on the head, as under a trained controller) or a shipped scene name (`hat`),
//! POLISH among none / newton / semismooth. Each polish runs the same rollout; the report has
//! contact steps (some contact pushes at the end) and contact-free steps apart, ms per step,
//! the contact Newton's counters, and the largest position difference to the first polish.
//! With `ONE_STEP=1`, every step of the later polishes also starts from the first polish's
//! state: `one-step max|dx|` is then the difference of single steps (same start, same
//! tolerance), which separates the solvers' fixed points from the rollout's sensitivity.
use diffcloth::{Polish, SceneConfig, Simulator, SolverSettings, StepInput, Vec3};
use std::time::Instant;

fn config(scene: &str) -> SceneConfig {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../diffcloth_gym/configs");
    if let Some(n) = scene.strip_prefix("sphere:") {
        let text = std::fs::read_to_string(dir.join("sphere.toml")).unwrap();
        let text = text
            .replace("rows = 25", &format!("rows = {n}"))
            .replace("cols = 25", &format!("cols = {n}"));
        return SceneConfig::from_toml_str(&text).unwrap();
    }
    let name = scene.split(':').next().unwrap();
    let name = if name.starts_with("hatdown") {
        "hat"
    } else {
        name
    };
    let mut cfg = SceneConfig::from_toml_file(&dir.join(format!("{name}.toml"))).unwrap();
    if scene.starts_with("hatdown_inertia") {
        cfg.contact.as_mut().unwrap().response = diffcloth::config::ContactResponse::Inertia;
    }
    cfg
}

fn main() {
    diffcloth::init_linear_algebra();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = args.first().map_or("sphere:24", |s| s.as_str());
    let steps: usize = args.get(1).map_or(120, |s| s.parse().unwrap());
    let tol: f64 = args.get(2).map_or(1e-8, |s| s.parse().unwrap());
    let polishes: Vec<Polish> = if args.len() > 3 {
        args[3..]
            .iter()
            .map(|p| Polish::from_name(p).expect("polish"))
            .collect()
    } else {
        vec![Polish::None, Polish::Semismooth]
    };
    let cfg = config(scene);
    let lower: Option<f64> = scene
        .strip_prefix("hatdown:")
        .or(scene.strip_prefix("hatdown_inertia:"))
        .map(|d| d.parse().unwrap());
    let mut first: Option<Vec<Vec3>> = None;
    let mut states: Vec<(Vec<Vec3>, Vec<Vec3>, f64)> = Vec::new();
    let one_step = std::env::var("ONE_STEP").is_ok();
    for polish in polishes {
        let mut sim = Simulator::new(&cfg).unwrap();
        let s = sim.solver().clone();
        sim.set_solver(SolverSettings {
            tolerance: tol,
            max_iterations: 2000,
            parallel: false,
            polish,
            ..s
        })
        .unwrap();
        let (mut c_steps, mut c_it, mut f_steps, mut f_it, mut unconv) = (0, 0, 0, 0, 0);
        let (mut c_time, mut f_time) = (0.0, 0.0);
        let record = first.is_none();
        let t0 = sim.attachment_targets().to_vec();
        sim.set_trace(true);
        // Contact steps' iterations with the update above 1e-4 (before contact Newton starts).
        let mut above = 0;
        let (mut one_step_diff, mut unconverged_diff): (f64, f64) = (0.0, 0.0);
        for k in 0..steps {
            if record {
                let time = k as f64 * sim.params().h;
                states.push((sim.positions().to_vec(), sim.velocities().to_vec(), time));
            } else if one_step {
                let (x, v, t) = &states[2 * k];
                sim.reset(Some(x), Some(v)).unwrap();
                sim.set_time(*t).unwrap();
            }
            // Targets from the step index (a reset puts them back at rest).
            let mut targets = t0.clone();
            if let Some(d) = lower {
                let drop = d * (k + 1).min(60) as f64;
                targets.iter_mut().for_each(|t| t.y -= drop);
            }
            let input = StepInput {
                attachment_targets: lower.map(|_| &targets[..]),
                ..Default::default()
            };
            let t = Instant::now();
            let st = sim.step(input).unwrap();
            let dt = t.elapsed().as_secs_f64();
            if record {
                // (The velocity slot marks whether the first polish converged this step.)
                let flag = if st.converged {
                    Vec::new()
                } else {
                    vec![Vec3::zeros()]
                };
                states.push((sim.positions().to_vec(), flag, 0.0));
            } else if one_step {
                let x0 = &states[2 * k + 1].0;
                let d = x0
                    .iter()
                    .zip(sim.positions())
                    .map(|(a, b)| (a - b).amax())
                    .fold(0.0, f64::max);
                if d > 1e-6 && std::env::var("SHOW").is_ok() {
                    println!("  step {k}: one-step |dx| {d:.2e} ({st:?})");
                }
                if states[2 * k + 1].1.is_empty() && st.converged {
                    one_step_diff = one_step_diff.max(d);
                } else {
                    unconverged_diff = unconverged_diff.max(d);
                }
            }
            unconv += usize::from(!st.converged);
            if st.contacts.stick + st.contacts.slip > 0 {
                above += sim.trace().unwrap().iter().filter(|t| t.1 > 1e-4).count();
                (c_steps, c_it, c_time) = (c_steps + 1, c_it + st.iterations, c_time + dt);
            } else {
                (f_steps, f_it, f_time) = (f_steps + 1, f_it + st.iterations, f_time + dt);
            }
        }
        let diff = if one_step {
            0.0
        } else {
            first.as_ref().map_or(0.0, |x0| {
                x0.iter()
                    .zip(sim.positions())
                    .map(|(a, b)| (a - b).amax())
                    .fold(0.0, f64::max)
            })
        };
        if first.is_none() {
            first = Some(sim.positions().to_vec());
        }
        let p = sim.profile();
        let per = |a: f64, b: usize| if b > 0 { a / b as f64 } else { f64::NAN };
        println!(
            "{scene} nodes {} tol {tol:e} polish {:<10} contact steps {c_steps}: {:.1} it/step \
             {:.2} ms/step | free steps {f_steps}: {:.1} it/step {:.2} ms/step | unconverged \
             {unconv} | contact-step iterations above 1e-4 {:.1} | cnewton {} ok {} rej {} gmres {} factors | tr-newton {} | max|dx| vs first {diff:.2e} \
             one-step {one_step_diff:.2e} (steps either left unconverged: {unconverged_diff:.2e}) | contact solve {:.0} % of the time, {:.1} contacts \
             ({:.1} stick, {:.1} slip) per step",
            sim.num_nodes(),
            polish.name(),
            per(c_it as f64, c_steps),
            per(1e3 * c_time, c_steps),
            per(f_it as f64, f_steps),
            per(1e3 * f_time, f_steps),
            per(above as f64, c_steps),
            p.contact_newton_steps,
            p.contact_newton_rejections,
            p.contact_newton_krylov_iterations,
            p.contact_newton_factorizations,
            p.newton_steps,
            100.0 * p.contact_solve.as_secs_f64() / p.total.as_secs_f64(),
            (p.contacts_take_off + p.contacts_stick + p.contacts_slip) as f64 / steps as f64,
            p.contacts_stick as f64 / steps as f64,
            p.contacts_slip as f64 / steps as f64,
        );
    }
}
