//! One model, many simulators: a shared model is factored once, each simulator on it gives
//! bitwise the trajectory of a standalone one, backward leaves its caller untouched, and a
//! tape linearizes with the model it was recorded with.
use crate::common::{configs_dir, random_vectors};
use diffcloth::{BackwardOptions, SceneConfig, Simulator, StepInput, Vec3};
use std::sync::Arc;

fn hat_config() -> SceneConfig {
    SceneConfig::from_toml_file(&configs_dir().join("hat.toml")).unwrap()
}

/// Attachment targets that move the hat's brim along a fixed path (step k).
fn targets(sim: &Simulator, k: usize) -> Vec<Vec3> {
    let lift = Vec3::new(0.0, 0.002, 0.001) * k as f64;
    sim.model()
        .attachment_nodes()
        .iter()
        .map(|&j| sim.mesh().positions[j] + lift)
        .collect()
}

fn run(sim: &mut Simulator, steps: usize) -> Vec<Vec<Vec3>> {
    (0..steps)
        .map(|k| {
            let t = targets(sim, k);
            sim.step(StepInput {
                attachment_targets: Some(&t),
                ..Default::default()
            })
            .unwrap();
            sim.positions().to_vec()
        })
        .collect()
}

#[test]
fn simulators_on_one_model_share_one_factorization_and_match_a_standalone_one() {
    diffcloth::init_linear_algebra();
    let cfg = hat_config();
    let mut standalone = Simulator::new(&cfg).unwrap();
    let expected = run(&mut standalone, 15);
    let model = standalone.model().clone();
    let solver = standalone.solver().clone();
    let mut batch: Vec<Simulator> = (0..4)
        .map(|_| Simulator::from_model(model.clone(), solver.clone()))
        .collect();
    for sim in &mut batch {
        // Bitwise the standalone trajectory, step by step.
        assert_eq!(run(sim, 15), expected);
        assert!(Arc::ptr_eq(sim.model(), &model));
        assert_eq!(sim.profile().refactorizations, 0);
    }
    // One numeric factorization for the five simulators.
    assert_eq!(model.factorizations(), 1);
    assert_eq!(Arc::strong_count(&model), 1 + 1 + batch.len());
}

#[test]
fn a_parameter_change_copies_a_shared_model_and_leaves_the_others_alone() {
    let cfg = hat_config();
    let mut a = Simulator::new(&cfg).unwrap();
    let mut b = Simulator::from_model(a.model().clone(), a.solver().clone());
    let original = a.model().clone();
    let mut params = a.params().clone();
    params.k_stretch *= 2.0;
    a.set_params(params).unwrap();
    assert!(!Arc::ptr_eq(a.model(), &original));
    assert!(Arc::ptr_eq(b.model(), &original));
    assert_eq!(original.factorizations(), 1);
    assert_eq!(a.model().factorizations(), 2);
    // b still simulates the original material.
    let mut fresh = Simulator::new(&cfg).unwrap();
    assert_eq!(run(&mut b, 5), run(&mut fresh, 5));
}

/// Profile, state and step count of the caller, compared exactly.
fn fingerprint(sim: &Simulator) -> (Vec<Vec3>, Vec<Vec3>, f64, u64, String, usize) {
    (
        sim.positions().to_vec(),
        sim.velocities().to_vec(),
        sim.time(),
        sim.step_count(),
        format!("{:?}", sim.profile()),
        sim.tape().map_or(0, |t| t.len()),
    )
}

#[test]
fn a_checkpointed_backward_leaves_the_caller_unchanged() {
    let mut sim = Simulator::new(&hat_config()).unwrap();
    sim.set_recording_checkpointed(4);
    run(&mut sim, 10);
    let before = fingerprint(&sim);
    let n = sim.num_nodes();
    let dl_dx: Vec<Vec<Vec3>> = (0..10).map(|k| random_vectors(n, 1.0, k)).collect();
    let g = sim
        .backward(&dl_dx, &[], &BackwardOptions::default())
        .unwrap();
    assert!(g.v0.iter().any(|v| v.norm() > 0.0));
    assert_eq!(fingerprint(&sim), before);
    // A rejected call does no work either (wrong number of rows).
    assert!(sim
        .backward(&dl_dx[..3], &[], &BackwardOptions::default())
        .is_err());
    assert_eq!(fingerprint(&sim), before);
}

/// The stale-tape bug: backward used the simulator's current parameters, so changing one
/// after recording silently gave wrong gradients (87 % off for k_stretch). The tape now
/// keeps its model: the gradient is bitwise the one taken before the change.
#[test]
fn a_tape_linearizes_with_the_model_it_was_recorded_with() {
    let mut sim = Simulator::new(&hat_config()).unwrap();
    sim.set_recording(true);
    run(&mut sim, 8);
    let n = sim.num_nodes();
    let dl_dx: Vec<Vec<Vec3>> = (0..8).map(|k| random_vectors(n, 1.0, 40 + k)).collect();
    let options = BackwardOptions::default();
    let before = sim.backward(&dl_dx, &[], &options).unwrap();
    let mut params = sim.params().clone();
    params.k_stretch *= 3.0;
    params.h *= 0.5;
    params.density *= 2.0;
    sim.set_params(params).unwrap();
    let after = sim.backward(&dl_dx, &[], &options).unwrap();
    assert_eq!(before.v0, after.v0);
    assert_eq!(before.attachment_targets, after.attachment_targets);
    assert_eq!(before.k_stretch, after.k_stretch);
    // A step taken with the new model cannot join the old tape's linearization.
    let t = targets(&sim, 8);
    sim.step(StepInput {
        attachment_targets: Some(&t),
        ..Default::default()
    })
    .unwrap();
    let dl_dx: Vec<Vec<Vec3>> = (0..9).map(|k| random_vectors(n, 1.0, 40 + k)).collect();
    let err = sim.backward(&dl_dx, &[], &options).unwrap_err().to_string();
    assert!(err.contains("changed at recorded step 8"), "{err}");
}

/// A diverged step rolls back everything it set, the attachment targets included, so the
/// next plain step works.
#[test]
fn a_diverged_step_rolls_back_its_targets() {
    let mut sim = Simulator::new(&hat_config()).unwrap();
    let before = sim.attachment_targets().to_vec();
    let huge: Vec<Vec3> = before.iter().map(|_| Vec3::repeat(1e150)).collect();
    let err = sim.step(StepInput {
        attachment_targets: Some(&huge),
        ..Default::default()
    });
    assert!(matches!(err, Err(diffcloth::Error::Diverged(_))), "{err:?}");
    assert_eq!(sim.attachment_targets(), &before[..]);
    sim.step(StepInput::default()).unwrap();
    assert!(sim
        .positions()
        .iter()
        .all(|p| p.iter().all(|c| c.is_finite())));
}
