//! Issue 11 item 3: backward could not be interrupted (Ctrl-C ran on for minutes). A
//! cancellation check stops it with `Error::Cancelled` at every stage it is polled in, and a
//! check that never fires changes nothing, bit for bit.
use crate::common::*;
use diffcloth::{AdjointSolver, BackwardOptions, Cancel, Error, Simulator, StepInput, Vec3};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

fn recorded(checkpoint_every: Option<usize>) -> (Simulator, Vec<Vec<Vec3>>) {
    let mut sim = Simulator::from_toml_file(&configs_dir().join("slope.toml")).unwrap();
    match checkpoint_every {
        Some(k) => sim.set_recording_checkpointed(k),
        None => sim.set_recording(true),
    }
    let steps = 12;
    for _ in 0..steps {
        sim.step(StepInput::default()).unwrap();
    }
    let n = sim.num_nodes();
    let w = (0..steps).map(|k| random_vectors(n, 1.0, 70 + k)).collect();
    (sim, w)
}

#[test]
fn a_check_that_never_fires_changes_nothing() {
    for every in [None, Some(5)] {
        let (sim, w) = recorded(every);
        for solver in [
            AdjointSolver::Krylov,
            AdjointSolver::FixedPoint,
            AdjointSolver::Direct,
        ] {
            let options = BackwardOptions {
                solver,
                ..Default::default()
            };
            let plain = sim.backward(&w, &[], &options).unwrap();
            let check = || false;
            let polled = Cancel::with_interval(&check, Duration::ZERO);
            let g = sim
                .backward_cancellable(&w, &[], &options, &polled)
                .unwrap();
            assert_eq!(plain.x0, g.x0, "{solver:?} {every:?}");
            assert_eq!(plain.v0, g.v0);
            assert_eq!(plain.attachment_targets, g.attachment_targets);
        }
    }
}

/// The n-th poll cancels: every stage (re-simulation, each replayed step, the iterative
/// solves) gives `Error::Cancelled` and the simulator is left as it was.
#[test]
fn cancelling_at_any_poll_stops_with_a_typed_error_and_leaves_the_simulator() {
    for every in [None, Some(5)] {
        let (sim, w) = recorded(every);
        let x = sim.positions().to_vec();
        let tape_len = sim.tape().unwrap().len();
        for solver in [AdjointSolver::Krylov, AdjointSolver::FixedPoint] {
            let options = BackwardOptions {
                solver,
                ..Default::default()
            };
            // Count the polls of a whole pass, then cancel at a spread of them.
            let polls = AtomicUsize::new(0);
            let count = || {
                polls.fetch_add(1, Ordering::Relaxed);
                false
            };
            sim.backward_cancellable(
                &w,
                &[],
                &options,
                &Cancel::with_interval(&count, Duration::ZERO),
            )
            .unwrap();
            let total = polls.load(Ordering::Relaxed);
            // One poll per replayed (and re-simulated) step; the fixed-point solves are
            // polled per iteration too (Krylov with contact is faer's BiCGStab: per step only).
            let per_step = if every.is_some() { 24 } else { 12 };
            match solver {
                AdjointSolver::FixedPoint => assert!(total > per_step, "{total} polls"),
                _ => assert!(total >= per_step, "{total} polls"),
            }
            for at in [1, 2, total / 3, total / 2, total] {
                let seen = AtomicUsize::new(0);
                let check = || seen.fetch_add(1, Ordering::Relaxed) + 1 >= at;
                let err = sim
                    .backward_cancellable(
                        &w,
                        &[],
                        &options,
                        &Cancel::with_interval(&check, Duration::ZERO),
                    )
                    .unwrap_err();
                assert!(matches!(err, Error::Cancelled(_)), "{err}");
                assert_eq!(seen.load(Ordering::Relaxed), at, "stopped at the first yes");
            }
            assert_eq!(sim.positions(), &x[..]);
            assert_eq!(sim.tape().unwrap().len(), tape_len);
        }
    }
}
