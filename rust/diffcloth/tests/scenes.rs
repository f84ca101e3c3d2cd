//! Scene configs: every shipped config loads and simulates; garments rest at rest; bad
//! configs fail with a message naming the problem.
use crate::common::*;
use diffcloth::{Effect, SceneConfig, Simulator, StepInput};

#[test]
fn every_shipped_config_loads_and_steps() {
    for entry in std::fs::read_dir(configs_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let mut sim = Simulator::from_toml_file(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            for _ in 0..3 {
                sim.step(StepInput::default()).unwrap();
            }
            assert!(
                sim.positions()
                    .iter()
                    .all(|p| p.iter().all(|c| c.is_finite())),
                "{}",
                path.display()
            );
        }
    }
}

/// Bending with rest curvature and stretch produce no force at the rest shape: with gravity
/// and attachments off, the hat and the sock do not move.
#[test]
fn hat_and_sock_rest_shapes_stay_at_rest() {
    for name in ["hat", "sock"] {
        let mut cfg = load_config(name);
        cfg.effects = vec![Effect::Stretch, Effect::Bend];
        cfg.attachments = None;
        cfg.obstacles.clear();
        cfg.self_collision = None;
        cfg.contact = None;
        let mut sim = Simulator::new(&cfg).unwrap();
        let rest = sim.positions().to_vec();
        for _ in 0..50 {
            sim.step(StepInput::default()).unwrap();
        }
        let moved = max_distance(sim.positions(), &rest);
        assert!(moved < 1e-9, "{name} moved by {moved}");
    }
}

/// Curvature matters: the same hat without its rest curvature (bending towards flat) deforms.
#[test]
fn hat_moves_if_bending_targeted_a_flat_shape() {
    let mut cfg = load_config("hat");
    cfg.effects = vec![Effect::Stretch, Effect::Bend, Effect::Gravity];
    cfg.attachments = None;
    cfg.obstacles.clear();
    cfg.contact = None;
    cfg.self_collision = None;
    let mut sim = Simulator::new(&cfg).unwrap();
    let rest = sim.positions().to_vec();
    for _ in 0..20 {
        sim.step(StepInput::default()).unwrap();
    }
    // Free fall moves everything the same; the shape change is what we measure.
    let shift = sim.positions()[0] - rest[0];
    let deformation = sim
        .positions()
        .iter()
        .zip(&rest)
        .map(|(p, r)| (p - r - shift).norm())
        .fold(0.0, f64::max);
    assert!(
        deformation < 1e-6,
        "uniform free fall keeps the rest shape: {deformation}"
    );
}

#[test]
fn config_errors_name_the_problem() {
    let base = std::fs::read_to_string(configs_dir().join("wind.toml")).unwrap();
    let cases = [
        (
            base.replace("k_stretch = 100.0", "k_strech = 100.0"),
            "k_strech",
        ),
        (base.replace("\"wind\"]", "\"bogus\"]"), "bogus"),
        (
            base.replace(
                "[\"gravity\", \"stretch\", \"attachments\", \"wind\"]",
                "[\"gravity\", \"stretch\", \"attachments\"]",
            ),
            "[wind]",
        ),
        (
            base.replace("select = \"top_corners\"", "select = \"middle\""),
            "middle",
        ),
        (
            base.replace("k_stretch = 100.0", "k_stretch = -100.0"),
            "k_stretch",
        ),
        (base.replace("density = 0.054", "density = 0.0"), "density"),
        (base.replace("rows = 12", "rows = 1"), "2x2"),
    ];
    for (text, needle) in cases {
        let err = SceneConfig::from_toml_str(&text)
            .and_then(|c| Simulator::new(&c))
            .err();
        let msg = err.map(|e| e.to_string()).unwrap_or_default();
        assert!(
            msg.contains(needle),
            "expected an error naming {needle:?}, got {msg:?}"
        );
    }
}

#[test]
fn effects_not_declared_build_nothing() {
    let mut cfg = load_config("napkin");
    cfg.effects = vec![Effect::Gravity];
    let sim = Simulator::new(&cfg).unwrap();
    assert!(sim.stretch().is_none());
    assert!(sim.attachment_nodes().is_empty());
}
