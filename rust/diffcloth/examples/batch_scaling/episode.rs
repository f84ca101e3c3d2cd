//! One timed episode of the batch (or of the members stepped the old way, for an A/B):
//! per-step member costs and iterations, allocations, the scheduler's view, final state.

use crate::{sched, ALLOCS};
use diffcloth::{Batch, MemberInput, Model, Simulator, SolverSettings, Vec3};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Instant;

pub struct Episode {
    pub seconds: f64,
    pub usage: sched::Usage,
    pub costs: Vec<Vec<f64>>,
    pub step_iterations: Vec<Vec<f64>>,
    /// PD iterations of each member over the episode.
    pub iterations: Vec<u64>,
    pub first_step_allocs: u64,
    /// Allocations per step after the first (the whole batch's step call).
    pub allocs_per_step: f64,
    pub final_x: Vec<Vec<Vec3>>,
}

/// How an episode's steps are run: the batch, or `pool.install` over the members (the old
/// `Batch::step`; `solver.parallel` off, as the batch turned member splitting off).
#[derive(Clone, Copy)]
pub enum Stepper {
    Batch,
    Install,
}

/// Members stepped by `pool.install(par_iter_mut)`.
struct Installed {
    pool: rayon::ThreadPool,
    sims: Vec<Simulator>,
}

impl Installed {
    fn step(&mut self, inputs: &[MemberInput<'_>]) -> Vec<diffcloth::Result<diffcloth::StepStats>> {
        use rayon::prelude::*;
        let sims = &mut self.sims;
        self.pool.install(|| {
            sims.par_iter_mut()
                .zip(inputs)
                .map(|(s, i)| {
                    s.step(diffcloth::StepInput {
                        attachment_targets: i.attachment_targets,
                        external_forces: i.external_forces,
                    })
                })
                .collect()
        })
    }
}

fn busy(us: u64) {
    let t = Instant::now();
    while t.elapsed().as_micros() < us as u128 {
        std::hint::spin_loop();
    }
}

pub fn episode(
    model: &Arc<Model>,
    solver: &SolverSettings,
    threads: usize,
    forces: &[Vec<Vec<Vec3>>],
) -> Episode {
    episode_with(model, solver, threads, forces, Stepper::Batch, 0)
}

pub fn episode_with(
    model: &Arc<Model>,
    solver: &SolverSettings,
    threads: usize,
    forces: &[Vec<Vec<Vec3>>],
    stepper: Stepper,
    gap_us: u64,
) -> Episode {
    let size = forces[0].len();
    let mut batch = Batch::with_threads(model.clone(), solver.clone(), size, threads).unwrap();
    let mut installed = matches!(stepper, Stepper::Install).then(|| Installed {
        pool: rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap(),
        sims: (0..size)
            .map(|_| {
                let serial = SolverSettings {
                    parallel: false,
                    ..solver.clone()
                };
                Simulator::from_model(model.clone(), serial)
            })
            .collect(),
    });
    let mut gap = std::time::Duration::ZERO;
    let mut iterations = vec![0u64; size];
    let mut inputs: Vec<MemberInput> = Vec::with_capacity(size);
    // Per step and member: time in `step` (profile) and PD iterations (filled in place).
    let mut costs = vec![vec![0.0; size]; forces.len()];
    let mut step_iterations = vec![vec![0.0; size]; forces.len()];
    let t0 = sched::snapshot();
    let a0 = ALLOCS.load(Ordering::Relaxed);
    // Allocations after the first step: a new pool's first call sets up rayon's queues.
    let mut a1 = a0;
    let start = Instant::now();
    for (k, f) in forces.iter().enumerate() {
        if k == 1 {
            a1 = ALLOCS.load(Ordering::Relaxed);
        }
        inputs.clear();
        inputs.extend(f.iter().map(|f| MemberInput {
            attachment_targets: None,
            external_forces: Some(f),
        }));
        let results = match installed.as_mut() {
            Some(inst) => inst.step(&inputs),
            None => batch.step(&inputs).unwrap(),
        };
        for (i, r) in results.into_iter().enumerate() {
            let n = r.unwrap().iterations;
            iterations[i] += n as u64;
            step_iterations[k][i] = n as f64;
        }
        let members: Vec<&Simulator> = match installed.as_ref() {
            Some(inst) => inst.sims.iter().collect(),
            None => batch.members().collect(),
        };
        for (c, s) in costs[k].iter_mut().zip(members) {
            *c = s.profile().total.as_secs_f64();
        }
        if gap_us > 0 {
            let g = Instant::now();
            busy(gap_us);
            gap += g.elapsed();
        }
    }
    let seconds = (start.elapsed() - gap).as_secs_f64();
    let allocs = ALLOCS.load(Ordering::Relaxed) - a1;
    let usage = sched::between(&t0, &sched::snapshot());
    // Cumulative profile times to per-step costs.
    for k in (1..costs.len()).rev() {
        let (a, b) = costs.split_at_mut(k);
        for (c, p) in b[0].iter_mut().zip(&a[k - 1]) {
            *c -= p;
        }
    }
    Episode {
        costs,
        step_iterations,
        seconds,
        usage,
        iterations,
        first_step_allocs: a1 - a0,
        allocs_per_step: allocs as f64 / (forces.len() - 1).max(1) as f64,
        final_x: match installed.as_ref() {
            Some(inst) => inst.sims.iter().map(|s| s.positions().to_vec()).collect(),
            None => batch.members().map(|s| s.positions().to_vec()).collect(),
        },
    }
}
