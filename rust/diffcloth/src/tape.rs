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

/// One completed step as the forward pass hands it to the tape (borrowed: the tape copies
/// what its mode keeps).
pub struct CompletedStep<'a> {
    pub x_prev: &'a [Vec3],
    pub v_prev: &'a [Vec3],
    pub x_next: &'a [Vec3],
    /// Attachment targets in effect (None: the scene has no attachments).
    pub targets: Option<&'a [Vec3]>,
    pub forces: Option<&'a [Vec3]>,
    pub time: f64,
    pub contacts: &'a [Contact],
    pub residual: f64,
}

/// Recorded steps, in one of two modes. Only completed steps are pushed, so a step that
/// fails leaves the tape as it was.
#[derive(Debug, Clone)]
pub enum Tape {
    /// Every step's full record.
    Full { records: Vec<StepRecord> },
    /// One state every `every` steps plus each step's inputs: memory grows with the horizon
    /// only through the inputs (a few values per step for end effectors), and backward
    /// re-simulates one segment at a time.
    Checkpointed {
        every: usize,
        checkpoints: Vec<Checkpoint>,
        inputs: Vec<StepInputs>,
    },
}

impl Default for Tape {
    fn default() -> Self {
        Self::Full {
            records: Vec::new(),
        }
    }
}

impl Tape {
    pub fn checkpointed(every: usize) -> Self {
        Self::Checkpointed {
            every: every.max(1),
            checkpoints: Vec::new(),
            inputs: Vec::new(),
        }
    }

    /// Forgets every recorded step (both modes), keeping the mode.
    pub fn clear(&mut self) {
        match self {
            Self::Full { records } => records.clear(),
            Self::Checkpointed {
                checkpoints,
                inputs,
                ..
            } => {
                checkpoints.clear();
                inputs.clear();
            }
        }
    }

    /// Recorded steps.
    pub fn len(&self) -> usize {
        match self {
            Self::Full { records } => records.len(),
            Self::Checkpointed { inputs, .. } => inputs.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Appends a completed step in this tape's mode.
    pub fn push(&mut self, step: &CompletedStep<'_>) {
        match self {
            Self::Full { records } => records.push(StepRecord {
                x_prev: step.x_prev.to_vec(),
                v_prev: step.v_prev.to_vec(),
                x_next: step.x_next.to_vec(),
                targets: step.targets.map_or_else(Vec::new, <[Vec3]>::to_vec),
                time: step.time,
                contacts: step.contacts.to_vec(),
                residual: step.residual,
            }),
            Self::Checkpointed {
                every,
                checkpoints,
                inputs,
            } => {
                let index = inputs.len();
                if index % *every == 0 {
                    checkpoints.push(Checkpoint {
                        step: index,
                        x: step.x_prev.to_vec(),
                        v: step.v_prev.to_vec(),
                        time: step.time,
                    });
                }
                inputs.push(StepInputs {
                    targets: step.targets.map(<[Vec3]>::to_vec),
                    forces: step.forces.map(<[Vec3]>::to_vec),
                });
            }
        }
    }

    /// The full records (empty for a checkpointed tape).
    pub fn records(&self) -> &[StepRecord] {
        match self {
            Self::Full { records } => records,
            Self::Checkpointed { .. } => &[],
        }
    }

    /// Memory held by the tape in bytes.
    pub fn bytes(&self) -> usize {
        let v = std::mem::size_of::<Vec3>();
        match self {
            Self::Full { records } => records.iter().map(StepRecord::bytes).sum(),
            Self::Checkpointed {
                checkpoints,
                inputs,
                ..
            } => {
                let states: usize = checkpoints
                    .iter()
                    .map(|c| std::mem::size_of::<Checkpoint>() + v * (c.x.len() + c.v.len()))
                    .sum();
                let inputs: usize = inputs
                    .iter()
                    .map(|i| {
                        std::mem::size_of::<StepInputs>()
                            + v * (i.targets.as_ref().map_or(0, Vec::len)
                                + i.forces.as_ref().map_or(0, Vec::len))
                    })
                    .sum();
                states + inputs
            }
        }
    }
}
