//! The tape: what each recorded forward step keeps for its backward pass. Projections and
//! their Jacobians are recomputed from the end state in the backward pass (cheaper than
//! storing them); the contact set is stored as detected (frames are explicit in the state
//! entering the step).

use crate::contact::Contact;
use crate::Vec3;

#[derive(Debug, Clone)]
pub struct StepRecord {
    /// State entering the step.
    pub x_prev: Vec<Vec3>,
    pub v_prev: Vec<Vec3>,
    /// Positions at the end of the step (the converged implicit-Euler solution).
    pub x_next: Vec<Vec3>,
    /// Attachment targets in effect during the step.
    pub targets: Vec<Vec3>,
    /// Time at the start of the step.
    pub time: f64,
    /// Contacts of the step with their frames, branches and impulses.
    pub contacts: Vec<Contact>,
    /// Final PD residual of the step (the linearization assumes convergence).
    pub residual: f64,
}

impl StepRecord {
    pub fn bytes(&self) -> usize {
        let v = std::mem::size_of::<Vec3>();
        std::mem::size_of::<Self>()
            + v * (self.x_prev.len() + self.v_prev.len() + self.x_next.len() + self.targets.len())
            + std::mem::size_of::<Contact>() * self.contacts.len()
    }
}

/// A state the backward pass re-simulates from (checkpointed recording).
#[derive(Debug, Clone)]
pub struct Checkpoint {
    /// Index of the first step this state enters.
    pub step: usize,
    pub x: Vec<Vec3>,
    pub v: Vec<Vec3>,
    pub time: f64,
}

/// The inputs of one step, kept so a checkpointed segment can be re-simulated exactly.
#[derive(Debug, Clone)]
pub struct StepInputs {
    pub targets: Option<Vec<Vec3>>,
    pub forces: Option<Vec<Vec3>>,
}

/// Recorded steps. Either every step's full record, or (checkpointed) one state every
/// `every` steps plus each step's inputs: memory then grows with the horizon only through the
/// inputs (a few values per step for end effectors), and backward re-simulates one segment
/// at a time.
#[derive(Debug, Clone, Default)]
pub struct Tape {
    pub records: Vec<StepRecord>,
    /// `Some(every)` for a checkpointed tape.
    pub checkpoint_every: Option<usize>,
    pub checkpoints: Vec<Checkpoint>,
    pub inputs: Vec<StepInputs>,
}

impl Tape {
    pub fn checkpointed(every: usize) -> Self {
        Self {
            checkpoint_every: Some(every.max(1)),
            ..Default::default()
        }
    }

    /// Recorded steps.
    pub fn len(&self) -> usize {
        if self.checkpoint_every.is_some() {
            self.inputs.len()
        } else {
            self.records.len()
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Memory held by the tape in bytes.
    pub fn bytes(&self) -> usize {
        let v = std::mem::size_of::<Vec3>();
        let checkpoints: usize = self
            .checkpoints
            .iter()
            .map(|c| std::mem::size_of::<Checkpoint>() + v * (c.x.len() + c.v.len()))
            .sum();
        let inputs: usize = self
            .inputs
            .iter()
            .map(|i| {
                std::mem::size_of::<StepInputs>()
                    + v * (i.targets.as_ref().map_or(0, Vec::len)
                        + i.forces.as_ref().map_or(0, Vec::len))
            })
            .sum();
        self.records.iter().map(StepRecord::bytes).sum::<usize>() + checkpoints + inputs
    }
}
