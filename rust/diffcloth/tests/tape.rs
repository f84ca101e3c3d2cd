//! The tape: recording modes, reset, and what backward requires of a recording.
use crate::common::*;
use diffcloth::{AdjointSolver, BackwardOptions, Simulator, StepInput, Vec3};

#[test]
fn backward_without_a_tape_is_an_error() {
    let sim = Simulator::from_toml_file(&configs_dir().join("slope.toml")).unwrap();
    assert!(sim
        .backward(&[], &[], &BackwardOptions::default())
        .unwrap_err()
        .to_string()
        .contains("tape"));
}

/// A checkpointed tape (states every few steps, segments re-simulated in backward) gives the
/// same gradients as the full tape, with far less memory; the state is restored afterwards.
#[test]
fn checkpointed_and_full_tapes_give_identical_gradients() {
    let mut sim = Simulator::from_toml_file(&configs_dir().join("slope.toml")).unwrap();
    let steps = 23;
    let n = sim.num_nodes();
    let w: Vec<Vec<Vec3>> = (0..steps)
        .map(|k| random_vectors(n, 1.0, 500 + k as u64))
        .collect();
    let run = |sim: &mut Simulator, every: Option<usize>| {
        match every {
            Some(e) => sim.set_recording_checkpointed(e),
            None => sim.set_recording(true),
        }
        sim.reset(None, None).unwrap();
        for _ in 0..steps {
            sim.step(StepInput::default()).unwrap();
        }
        let bytes = sim.tape().unwrap().bytes();
        let end = (sim.positions().to_vec(), sim.time());
        let mut grads = Vec::new();
        for solver in [AdjointSolver::Direct, AdjointSolver::Krylov] {
            grads.push(
                sim.backward(
                    &w,
                    &[],
                    &BackwardOptions {
                        solver,
                        ..Default::default()
                    },
                )
                .unwrap(),
            );
        }
        assert_eq!(sim.positions(), &end.0[..], "state restored after backward");
        assert_eq!(sim.time(), end.1);
        (grads, bytes)
    };
    let (full, full_bytes) = run(&mut sim, None);
    let (ckpt, ckpt_bytes) = run(&mut sim, Some(5));
    for (a, b) in full.iter().zip(&ckpt) {
        assert_eq!(a.v0, b.v0);
        assert_eq!(a.x0, b.x0);
        assert_eq!(a.mu_obstacles, b.mu_obstacles);
        assert_eq!(a.k_stretch, b.k_stretch);
    }
    assert!(
        ckpt_bytes * 3 < full_bytes,
        "checkpointed {ckpt_bytes} B vs full {full_bytes} B"
    );
}

/// Regression (restructure issue): `reset()` cleared only a full tape's records, so a
/// checkpointed recording of 5 steps, `reset()`, then 3 steps left a tape of 8 steps and
/// backward asked for 8 rows of `dl_dx` and replayed the stale steps. Now both modes clear,
/// and the gradients equal those of a fresh 3-step recording.
#[test]
fn reset_clears_a_checkpointed_tape() {
    let mut sim = Simulator::from_toml_file(&configs_dir().join("slope.toml")).unwrap();
    let n = sim.num_nodes();
    let w: Vec<Vec<Vec3>> = (0..3).map(|k| random_vectors(n, 1.0, 900 + k)).collect();
    let three_steps = |sim: &mut Simulator| {
        for _ in 0..3 {
            sim.step(StepInput::default()).unwrap();
        }
        assert_eq!(sim.tape().unwrap().len(), 3);
        sim.backward(&w, &[], &BackwardOptions::default()).unwrap()
    };
    sim.set_recording_checkpointed(2);
    for _ in 0..5 {
        sim.step(StepInput::default()).unwrap();
    }
    sim.reset(None, None).unwrap();
    let after_reset = three_steps(&mut sim);
    sim.set_recording_checkpointed(2);
    sim.reset(None, None).unwrap();
    let fresh = three_steps(&mut sim);
    assert_eq!(after_reset.v0, fresh.v0);
    assert_eq!(after_reset.x0, fresh.x0);
}
