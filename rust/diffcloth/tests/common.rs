use diffcloth::{Effect, SceneConfig, Simulator, Vec3};
use std::path::PathBuf;

pub fn configs_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../diffcloth_gym/configs")
}

pub fn sim_from_toml(text: &str) -> Simulator {
    diffcloth::init_linear_algebra();
    Simulator::new(&SceneConfig::from_toml_str(text).unwrap()).unwrap()
}

pub fn load_config(name: &str) -> SceneConfig {
    SceneConfig::from_toml_file(&configs_dir().join(format!("{name}.toml"))).unwrap()
}

/// A shipped scene without its contact effects (obstacles, friction, self-collision).
pub fn contact_free_config(name: &str) -> SceneConfig {
    let mut cfg = load_config(name);
    cfg.effects.retain(|e| {
        !matches!(
            e,
            Effect::ObstacleContact | Effect::Friction | Effect::SelfCollision
        )
    });
    cfg.obstacles.clear();
    cfg.self_collision = None;
    cfg.contact = None;
    cfg
}

/// Deterministic pseudo-random vectors in [-amp, amp]^3.
pub fn random_vectors(n: usize, amp: f64, seed: u64) -> Vec<Vec3> {
    let mut s = seed.wrapping_add(0x9E3779B97F4A7C15);
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    (0..n)
        .map(|_| Vec3::new(next(), next(), next()) * amp)
        .collect()
}

pub fn momentum(sim: &Simulator) -> Vec3 {
    sim.velocities()
        .iter()
        .zip(sim.masses())
        .map(|(v, m)| *m * v)
        .sum()
}

pub fn max_distance(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max)
}

/// Smallest signed distance of a node to obstacle 0 at the simulator's time.
pub fn min_obstacle_distance(sim: &Simulator) -> f64 {
    let o = &sim.obstacles()[0];
    sim.positions()
        .iter()
        .map(|p| o.query(p, sim.time()).0)
        .fold(f64::INFINITY, f64::min)
}

/// A 4x4 patch (0.3 m square, k_stretch 60, external forces on) against `obstacle` with
/// friction `mu`. `response`: how the forward solves the contact law; `polish`: what finishes a
/// step. Tolerance 0 with a cap of 300: no stopping test, so a rollout is a smooth function of
/// its inputs (finite differences see no jumps).
pub fn patch_on_obstacle(
    obstacle: &str,
    mu: f64,
    placement: &str,
    response: &str,
    polish: &str,
) -> Simulator {
    sim_from_toml(&format!(
        r#"
h = 0.01
effects = ["gravity", "stretch", "obstacle_contact", "friction", "external_forces"]
[mesh]
kind = "grid"
rows = 4
cols = 4
width = 0.3
height = 0.3
plane = "xz"
[placement]
{placement}
[material]
density = 0.2
k_stretch = 60.0
[contact]
thickness = 0.01
response = "{response}"
[[obstacles]]
mu = {mu}
shape = {obstacle}
[solver]
tolerance = 0.0
max_iterations = 300
polish = "{polish}"
"#
    ))
}
