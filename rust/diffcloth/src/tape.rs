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

#[derive(Debug, Clone, Default)]
pub struct Tape {
    pub records: Vec<StepRecord>,
}

impl Tape {
    /// Memory held by the tape in bytes.
    pub fn bytes(&self) -> usize {
        self.records.iter().map(StepRecord::bytes).sum()
    }
}
