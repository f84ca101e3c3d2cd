//! A batch of simulators on one shared [`Model`] (one factorization), stepped in parallel with
//! rayon: what vector environments and batched rollouts stand on. Each member has its own
//! state, workspace and tape; a member's trajectory is bitwise the one a standalone
//! simulator gives from the same inputs (members never read each other's data, and a step's
//! arithmetic does not depend on which thread runs it).

use crate::backward::{AdjointWarmStart, BackwardOptions, Gradients};
use crate::batch_shared as shared;
use crate::error::{Error, Result};
use crate::forward::{Model, Simulator, StepInput, StepStats};
use crate::params::SolverSettings;
use crate::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

/// Largest batch (a bound on the memory one call may ask for).
pub const MAX_BATCH: usize = 4096;

/// Most threads a batch may own (a bound on what one call may spawn).
pub const MAX_THREADS: usize = 1024;

pub struct Batch {
    members: Vec<Member>,
    /// The batch's own thread pool, when it was given a thread count; else rayon's global
    /// pool. Owning one lets a process run batches at different thread counts side by side
    /// (and a benchmark compare them in one run).
    pool: Option<rayon::ThreadPool>,
}

/// One simulator of the batch and the warm start of its chained one-step adjoints.
struct Member {
    sim: Simulator,
    warm: Option<AdjointWarmStart>,
}

/// One member's inputs for a batched step.
#[derive(Debug, Clone, Copy, Default)]
pub struct MemberInput<'a> {
    pub attachment_targets: Option<&'a [Vec3]>,
    pub external_forces: Option<&'a [Vec3]>,
}

impl Batch {
    /// `size` simulators on `model`, each at the rest state with `solver`.
    pub fn new(model: Arc<Model>, solver: SolverSettings, size: usize) -> Result<Self> {
        if size == 0 || size > MAX_BATCH {
            return Err(Error::Input(format!(
                "batch size must be in 1..={MAX_BATCH}, got {size}"
            )));
        }
        let members = (0..size)
            .map(|_| Member {
                sim: Simulator::from_model(model.clone(), solver.clone()),
                warm: None,
            })
            .collect();
        Ok(Self {
            members,
            pool: None,
        })
    }

    /// As [`Batch::new`], stepped on a pool of its own with `threads` threads.
    pub fn with_threads(
        model: Arc<Model>,
        solver: SolverSettings,
        size: usize,
        threads: usize,
    ) -> Result<Self> {
        if threads == 0 || threads > MAX_THREADS {
            return Err(Error::Input(format!(
                "threads must be in 1..={MAX_THREADS}, got {threads}"
            )));
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| Error::Input(format!("threads: cannot start {threads} threads: {e}")))?;
        let mut batch = Self::new(model, solver, size)?;
        batch.pool = Some(pool);
        Ok(batch)
    }

    /// Threads a parallel call of this batch runs on.
    pub fn threads(&self) -> usize {
        match &self.pool {
            Some(pool) => pool.current_num_threads(),
            None => rayon::current_num_threads(),
        }
    }

    /// Whether members split their own steps across threads: only when there are fewer
    /// members than threads (otherwise the members fill the threads; measured on the 32-member
    /// FlyingNapkin: 2-thread speed-up 1.65x with nested splitting, 1.84x without).
    fn splits_member_work(&self) -> bool {
        self.members.len() < self.threads()
    }

    /// Runs `f` on the members inside the batch's pool (nested rayon work of the members
    /// included), or in the caller's pool when the batch has none.
    fn in_pool<R: Send>(&mut self, f: impl FnOnce(&mut [Member]) -> R + Send) -> R {
        let members = &mut self.members;
        match &self.pool {
            Some(pool) => pool.install(|| f(members)),
            None => f(members),
        }
    }

    pub fn len(&self) -> usize {
        self.members.len()
    }

    pub fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// Member `i` (error if out of range).
    pub fn member(&self, i: usize) -> Result<&Simulator> {
        self.members
            .get(i)
            .map(|m| &m.sim)
            .ok_or_else(|| self.index_error(i))
    }

    /// Member `i`, mutably; its adjoint warm start is dropped (its state may change).
    pub fn member_mut(&mut self, i: usize) -> Result<&mut Simulator> {
        let size = self.len();
        let m = self
            .members
            .get_mut(i)
            .ok_or_else(|| index_error(i, size))?;
        m.warm = None;
        Ok(&mut m.sim)
    }

    pub fn members(&self) -> impl Iterator<Item = &Simulator> {
        self.members.iter().map(|m| &m.sim)
    }

    /// Applies `f` to every member in parallel.
    pub fn for_each_mut(&mut self, f: impl Fn(&mut Simulator) + Sync) {
        self.in_pool(|members| {
            members.par_iter_mut().for_each(|m| {
                m.warm = None;
                f(&mut m.sim)
            })
        });
    }

    /// One step of every member in parallel (`inputs`: one per member). Each member's result
    /// is its own: a member that fails is left at its previous step, the others advance.
    pub fn step(&mut self, inputs: &[MemberInput<'_>]) -> Result<Vec<Result<StepStats>>> {
        if inputs.len() != self.len() {
            return Err(Error::Input(format!(
                "inputs: one per member ({}), got {}",
                self.len(),
                inputs.len()
            )));
        }
        let step = |m: &mut Member, input: &MemberInput<'_>, split_work: bool| {
            m.sim.split_work = split_work;
            m.sim.step(StepInput {
                attachment_targets: input.attachment_targets,
                external_forces: input.external_forces,
            })
        };
        if self.splits_member_work() {
            // Fewer members than threads: the members' own steps spread over the pool.
            return Ok(self.in_pool(|members| {
                members
                    .par_iter_mut()
                    .zip(inputs)
                    .map(|(m, input)| step(m, input, true))
                    .collect()
            }));
        }
        let threads = self.threads();
        let tasks: Vec<_> = self.members.iter_mut().zip(inputs).collect();
        Ok(shared::run(
            self.pool.as_ref(),
            threads,
            tasks,
            |(m, input)| step(m, input, false),
        ))
    }

    /// The one-step adjoint ([`Simulator::backward_step`]) of recorded step `k` of every
    /// member in parallel; `dl_dx[i]`, `dl_dv[i]` are member i's loss gradients on the
    /// step's outputs.
    pub fn backward_step(
        &mut self,
        k: usize,
        dl_dx: &[Vec<Vec3>],
        dl_dv: &[Vec<Vec3>],
        options: &BackwardOptions,
    ) -> Result<Vec<Result<Gradients>>> {
        for (name, g) in [("dl_dx", dl_dx), ("dl_dv", dl_dv)] {
            if g.len() != self.len() {
                return Err(Error::Input(format!(
                    "{name}: one per member ({}), got {}",
                    self.len(),
                    g.len()
                )));
            }
        }
        // A member's adjoint runs on one thread (no nested splitting), so the caller shares
        // in the work whatever the batch size.
        let threads = self.threads();
        let tasks: Vec<_> = self
            .members
            .iter_mut()
            .zip(dl_dx.iter().zip(dl_dv))
            .collect();
        Ok(shared::run(
            self.pool.as_ref(),
            threads,
            tasks,
            |(m, (gx, gv))| m.sim.backward_step(k, gx, gv, options, &mut m.warm),
        ))
    }

    fn index_error(&self, i: usize) -> Error {
        index_error(i, self.len())
    }
}

fn index_error(i: usize, size: usize) -> Error {
    Error::Input(format!(
        "member index {i} out of range for a batch of {size}"
    ))
}
