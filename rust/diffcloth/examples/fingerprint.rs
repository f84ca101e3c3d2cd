//! Behaviour fingerprint of every scene in a config folder: PD iterations, contact counts and
//! a bit-exact checksum of the trajectory, plus the adjoint's iteration counts and gradient
//! checksum, recorded and plain. Two builds that print the same lines simulate the same thing
//! (used to prove that a refactor changed no behaviour):
//! `cargo run --release --example fingerprint [CONFIG_DIR] [STEPS] [POLISH]`.
use diffcloth::{BackwardOptions, SceneConfig, Simulator, StepInput, Vec3};

/// Order-sensitive checksum of the exact bits of a sequence of vectors.
fn checksum<'a>(values: impl Iterator<Item = &'a Vec3>) -> u64 {
    values
        .flat_map(|v| v.iter())
        .fold(0xcbf29ce484222325, |h, c| {
            (h ^ c.to_bits()).wrapping_mul(0x100000001b3)
        })
}

fn main() {
    diffcloth::init_linear_algebra();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../diffcloth_gym/configs");
    let dir = std::env::args().nth(1).map_or(root, Into::into);
    let steps: usize = std::env::args().nth(2).map_or(30, |s| s.parse().unwrap());
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    for path in paths {
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        let mut cfg = SceneConfig::from_toml_file(&path).unwrap();
        cfg.solver.parallel = false;
        if let Some(polish) = std::env::args().nth(3) {
            cfg.solver.polish =
                diffcloth::Polish::from_name(&polish).expect("polish: none or newton");
        }
        for recorded in [false, true] {
            let mut sim = Simulator::new(&cfg).unwrap();
            sim.set_recording(recorded);
            let mut trajectory = 0u64;
            for _ in 0..steps {
                sim.step(StepInput::default()).unwrap();
                trajectory ^= checksum(sim.positions().iter()).rotate_left(7);
            }
            let p = sim.profile();
            let mut line = format!(
                "{name} recorded={recorded}: it {} escape {} rejections {} stalls {} redetect {} contacts {}/{}/{} x {trajectory:016x}",
                p.iterations, p.escape_steps, p.acceleration_rejections,
                p.acceleration_stalls, p.redetections, p.contacts_take_off, p.contacts_stick,
                p.contacts_slip
            );
            if cfg.solver.polish != diffcloth::Polish::None {
                line += &format!(
                    " newton {} rejected {} cg {}",
                    p.newton_steps, p.newton_rejections, p.newton_cg_iterations
                );
            }
            if recorded {
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
                let g = sim
                    .backward(&dl_dx, &[], &BackwardOptions::default())
                    .unwrap();
                let it: usize = g.steps.iter().map(|s| s.iterations).sum();
                let scalars = [g.k_stretch, g.k_bend, g.k_attach, g.density];
                line += &format!(
                    " | adjoint it {it} fell_back {} v0 {:016x} k {:?}",
                    g.steps.iter().filter(|s| s.fell_back).count(),
                    checksum(g.v0.iter()),
                    scalars.map(|s| s.to_bits() % 1_000_000)
                );
            }
            println!("{line}");
        }
    }
}
