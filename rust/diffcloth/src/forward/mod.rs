//! The simulator and its forward step (paper Sec. 3.1): implicit Euler solved by PD
//! local-global iterations on the prefactored scalar matrix
//! `P_s = M / h^2 + sum_i w_i A_i^T A_i`, accelerated by energy-guarded Anderson.

use crate::anderson::Anderson;
use crate::collision::{Obstacle, SelfCollision};
use crate::config::SceneConfig;
use crate::contact::{BranchCounts, Contact, ContactSet, ContactSettings};
use crate::delassus::Delassus;
use crate::effects::Effects;
use crate::energy::{PdConstraints, Projections, Stretch};
use crate::error::Result;
use crate::forces::Wind;
use crate::mesh::TriMesh;
use crate::params::{Params, SolverSettings};
use crate::profile::Profile;
use crate::scene::solver_from_config;
use crate::tape::Tape;
use crate::Vec3;
use std::sync::Arc;

mod contact_newton;
mod detection;
mod diagnostics;
mod model;
mod newton;
mod overlap;
mod pd;
mod registry;
mod response;
mod safeguards;
mod state;
mod step;

pub use model::Model;
pub use overlap::Overlaps;
pub use response::MAX_CONTACT_NODES;

/// What one forward step did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepStats {
    pub iterations: usize,
    /// Final RMS PD update (metres).
    pub residual: f64,
    pub converged: bool,
    /// The step's contacts by branch at the last iteration.
    pub contacts: BranchCounts,
}

/// Inputs of one step; `None` keeps the previous attachment targets / applies no force.
#[derive(Debug, Clone, Copy, Default)]
pub struct StepInput<'a> {
    pub attachment_targets: Option<&'a [Vec3]>,
    pub external_forces: Option<&'a [Vec3]>,
}

/// A simulator: a shared [`Model`], its own [`State`] and [`Workspace`], and what it records.
pub struct Simulator {
    model: Arc<Model>,
    state: State,
    work: Workspace,
    solver: SolverSettings,
    trace: Option<Vec<(f64, f64)>>,
    recording: Option<Recording>,
    profile: Profile,
    last: StepStats,
    /// The last completed step's contacts: the workspace's are overwritten by a step that
    /// then fails, and `contacts()` must agree with `last_step()` after a rollback.
    last_contacts: Vec<Contact>,
    /// Whether this simulator's own step may split its work across threads (with
    /// `solver.parallel`). A batch with at least as many members as threads turns it off:
    /// the members already fill the threads, and splitting each small step again only adds
    /// scheduling. The results are bitwise the same either way.
    pub(crate) split_work: bool,
}

/// What changes every step: positions, velocities, time and the attachment targets.
#[derive(Debug, Clone)]
pub(crate) struct State {
    pub(crate) x: Vec<Vec3>,
    pub(crate) v: Vec<Vec3>,
    pub(crate) time: f64,
    pub(crate) step_count: u64,
    /// Attachment targets in effect (one per attached node).
    pub(crate) targets: Vec<Vec3>,
}

/// Every per-step and per-iteration buffer, allocated once per simulator.
pub(crate) struct Workspace {
    pub(crate) contacts: ContactSet,
    /// The step's Delassus operator (contact response `delassus`, or `auto` once a step
    /// switched), and whether the solve uses it now (`response.rs`).
    pub(crate) delassus: Delassus,
    pub(crate) exact_response: bool,
    /// `auto`'s progress within the solve.
    pub(crate) auto_switch: response::AutoSwitch,
    /// Scratch of the contact detection: velocities that set each node's reach, and node
    /// marks (which nodes have a contact with the obstacle being checked).
    pub(crate) detect_velocity: Vec<Vec3>,
    pub(crate) covered: Vec<bool>,
    pub(crate) y: Vec<Vec3>,
    pub(crate) inertia_rhs: Vec<Vec3>,
    pub(crate) iterate: Vec<Vec3>,
    pub(crate) mapped: Vec<Vec3>,
    /// `G(x_k)` kept while a safeguarded extrapolation is tried.
    pub(crate) previous_mapped: Vec<Vec3>,
    pub(crate) update: Vec<Vec3>,
    pub(crate) extrapolated: Vec<Vec3>,
    pub(crate) anderson: Anderson,
    pub(crate) newton: newton::NewtonWork,
    pub(crate) contact_newton: contact_newton::ContactNewtonWork,
    /// Each constraint set's projections (in `Model::constraint_sets` order).
    pub(crate) projections: Vec<Projections>,
    /// Work rows of the factor's solve.
    pub(crate) solve_rows: Vec<Vec3>,
    /// The targets before this step's inputs (restored if the step diverges).
    pub(crate) previous_targets: Vec<Vec3>,
}

impl Workspace {
    fn new(model: &Model, history: usize) -> Self {
        let n = model.num_nodes();
        let zeros = vec![Vec3::zeros(); n];
        Self {
            contacts: ContactSet::default(),
            delassus: Delassus::default(),
            exact_response: false,
            auto_switch: Default::default(),
            detect_velocity: Vec::with_capacity(n),
            covered: Vec::with_capacity(n),
            y: zeros.clone(),
            inertia_rhs: zeros.clone(),
            iterate: zeros.clone(),
            mapped: zeros.clone(),
            previous_mapped: zeros.clone(),
            update: zeros.clone(),
            extrapolated: zeros.clone(),
            anderson: Anderson::new(history, n),
            newton: newton::NewtonWork::new(model),
            contact_newton: Default::default(),
            projections: model
                .constraint_sets()
                .map(|c| c.new_projections())
                .collect(),
            solve_rows: zeros,
            previous_targets: Vec::new(),
        }
    }
}

/// A tape and what it was recorded with: backward linearizes with this model (not whatever
/// the simulator holds by then) and replays checkpointed segments with these settings.
pub(crate) struct Recording {
    pub(crate) tape: Tape,
    pub(crate) model: Arc<Model>,
    pub(crate) solver: SolverSettings,
    /// The first recorded step taken with another model (a parameter changed) or, for a
    /// checkpointed tape, other solver settings: such a tape has no single linearization.
    pub(crate) changed_at: Option<usize>,
}

impl Simulator {
    pub fn new(config: &SceneConfig) -> Result<Self> {
        let solver = solver_from_config(&config.solver)?;
        Ok(Self::from_model(Arc::new(Model::new(config)?), solver))
    }

    /// A simulator on a shared model (no factorization: the model's is used), at the rest
    /// state.
    pub fn from_model(model: Arc<Model>, solver: SolverSettings) -> Self {
        let x = model.mesh.positions.clone();
        let state = State {
            targets: model.rest_targets(&x),
            v: vec![Vec3::zeros(); x.len()],
            x,
            time: 0.0,
            step_count: 0,
        };
        Self {
            work: Workspace::new(&model, solver.history),
            state,
            model,
            solver,
            trace: None,
            recording: None,
            profile: Profile::default(),
            last: StepStats::default(),
            last_contacts: Vec::new(),
            split_work: true,
        }
    }

    /// Loads a TOML scene file.
    pub fn from_toml_file(path: &std::path::Path) -> Result<Self> {
        Self::new(&SceneConfig::from_toml_file(path)?)
    }

    /// The model this simulator steps (share it with [`Simulator::from_model`]).
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    pub(crate) fn constraint_sets(&self) -> impl Iterator<Item = &dyn PdConstraints> {
        self.model.constraint_sets()
    }

    // ---- accessors -------------------------------------------------------------------------

    pub fn config(&self) -> &SceneConfig {
        &self.model.config
    }
    pub fn mesh(&self) -> &TriMesh {
        &self.model.mesh
    }
    pub fn handles(&self) -> &[usize] {
        &self.model.handles
    }
    pub fn effects(&self) -> Effects {
        self.model.effects
    }
    pub fn params(&self) -> &Params {
        &self.model.params
    }
    pub fn solver(&self) -> &SolverSettings {
        &self.solver
    }
    pub fn num_nodes(&self) -> usize {
        self.model.num_nodes()
    }
    pub fn positions(&self) -> &[Vec3] {
        &self.state.x
    }
    pub fn velocities(&self) -> &[Vec3] {
        &self.state.v
    }
    pub fn masses(&self) -> &[f64] {
        &self.model.mass
    }
    pub fn time(&self) -> f64 {
        self.state.time
    }
    pub fn step_count(&self) -> u64 {
        self.state.step_count
    }
    /// `(stored values of the Cholesky factor, supernodal?)` of the system matrix.
    pub fn factor_stats(&self) -> (usize, bool) {
        self.model.factor.factor_stats()
    }
    pub fn profile(&self) -> &Profile {
        &self.profile
    }
    pub fn reset_profile(&mut self) {
        self.profile = Profile::default();
    }
    pub fn last_step(&self) -> StepStats {
        self.last
    }
    pub fn stretch(&self) -> Option<&Stretch> {
        self.model.stretch.as_ref()
    }
    pub fn bend(&self) -> Option<&dyn PdConstraints> {
        self.model.bend.as_deref()
    }
    pub fn wind(&self) -> Option<&Wind> {
        self.model.wind.as_ref()
    }
    /// Each node's share of the rest area (m^2); mass = density x area.
    pub fn node_areas(&self) -> &[f64] {
        &self.model.node_area
    }
    pub(crate) fn factor(&self) -> &crate::linalg::SpdFactor {
        &self.model.factor
    }
    /// Starts (clearing any previous tape) or stops recording steps for `backward`.
    pub fn set_recording(&mut self, on: bool) {
        self.recording = on.then(|| self.new_recording(Tape::default()));
    }

    /// Starts a checkpointed recording: one state every `every` steps plus each step's inputs;
    /// `backward` re-simulates one segment at a time (same gradients, bounded memory).
    pub fn set_recording_checkpointed(&mut self, every: usize) {
        self.recording = Some(self.new_recording(Tape::checkpointed(every)));
    }

    fn new_recording(&self, tape: Tape) -> Recording {
        Recording {
            tape,
            model: self.model.clone(),
            solver: self.solver.clone(),
            changed_at: None,
        }
    }

    pub(crate) fn recording(&self) -> Option<&Recording> {
        self.recording.as_ref()
    }

    pub(crate) fn take_tape(&mut self) -> Option<Tape> {
        self.recording.take().map(|r| r.tape)
    }

    pub fn tape(&self) -> Option<&Tape> {
        self.recording.as_ref().map(|r| &r.tape)
    }
    /// The current step's contacts (frames, branches and impulses of the last step).
    pub fn contacts(&self) -> &[Contact] {
        &self.last_contacts
    }
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.model.obstacles
    }
    pub fn contact_settings(&self) -> &ContactSettings {
        &self.model.contact_settings
    }
    pub fn self_collision(&self) -> Option<&SelfCollision> {
        self.model.self_collision.as_ref()
    }
    pub fn attachment_nodes(&self) -> &[usize] {
        self.model.attachment_nodes()
    }
    pub fn attachment_targets(&self) -> &[Vec3] {
        &self.state.targets
    }
}
