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
use std::sync::Arc;

/// Largest batch (a bound on the memory one call may ask for).
pub const MAX_BATCH: usize = 4096;

/// Most threads a batch may own (a bound on what one call may spawn).
pub const MAX_THREADS: usize = 1024;

pub struct Batch {
    members: Vec<Member>,
    /// Threads a parallel call runs on: the calling thread and `threads - 1` helpers.
    threads: usize,
    /// The helpers' pool: `threads - 1` workers (none on one thread), owned so that a
    /// process can run batches at different thread counts side by side. The caller works
    /// too (`batch_shared.rs`), so a pool of `threads` workers would hold a spare one: rayon
    /// wakes a sleeping worker whenever another finds work (`Sleep::work_found`), and the
    /// spare spun for a core every step (32-member FlyingNapkin on 2 threads: a thread
    /// waiting for a core 33 % of the time, 1.87 cores obtained; with the smaller pool 0.2 %
    /// and 1.96).
    helpers: Option<rayon::ThreadPool>,
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
    /// `size` simulators on `model`, each at the rest state with `solver`, stepped on as
    /// many threads as the current rayon pool has (the global pool outside any).
    pub fn new(model: Arc<Model>, solver: SolverSettings, size: usize) -> Result<Self> {
        Self::build(model, solver, size, rayon::current_num_threads())
    }

    /// As [`Batch::new`], stepped on `threads` threads.
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
        Self::build(model, solver, size, threads)
    }

    fn build(
        model: Arc<Model>,
        solver: SolverSettings,
        size: usize,
        threads: usize,
    ) -> Result<Self> {
        if size == 0 || size > MAX_BATCH {
            return Err(Error::Input(format!(
                "batch size must be in 1..={MAX_BATCH}, got {size}"
            )));
        }
        let helpers = (threads > 1)
            .then(|| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads - 1)
                    .build()
                    .map_err(|e| {
                        Error::Input(format!("threads: cannot start {threads} threads: {e}"))
                    })
            })
            .transpose()?;
        let members = (0..size)
            .map(|_| {
                let mut sim = Simulator::from_model(model.clone(), solver.clone());
                // A member's step runs whole on one thread: the members fill the threads.
                // Splitting a member's own step never paid (2 threads, one member: Hat 0.97x,
                // Sock 0.98x, FlyingNapkin 0.89x of one thread; env_throughput.md).
                sim.split_work = false;
                Member { sim, warm: None }
            })
            .collect();
        Ok(Self {
            members,
            threads,
            helpers,
        })
    }

    /// Threads a parallel call of this batch runs on.
    pub fn threads(&self) -> usize {
        self.threads
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
        let helpers = self.helpers.as_ref();
        let tasks: Vec<&mut Member> = self.members.iter_mut().collect();
        shared::run(helpers, tasks, |m| {
            m.warm = None;
            f(&mut m.sim)
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
        let helpers = self.helpers.as_ref();
        let tasks: Vec<_> = self.members.iter_mut().zip(inputs).collect();
        Ok(shared::run(helpers, tasks, |(m, input)| {
            m.sim.step(StepInput {
                attachment_targets: input.attachment_targets,
                external_forces: input.external_forces,
            })
        }))
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
        let helpers = self.helpers.as_ref();
        let tasks: Vec<_> = self
            .members
            .iter_mut()
            .zip(dl_dx.iter().zip(dl_dv))
            .collect();
        Ok(shared::run(helpers, tasks, |(m, (gx, gv))| {
            m.sim.backward_step(k, gx, gv, options, &mut m.warm)
        }))
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
