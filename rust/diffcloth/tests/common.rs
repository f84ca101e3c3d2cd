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
