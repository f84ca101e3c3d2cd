//! The simulator and its forward step (paper Sec. 3.1): implicit Euler solved by PD
//! local-global iterations on the prefactored scalar matrix
//! `P_s = M / h^2 + sum_i w_i A_i^T A_i`, accelerated by energy-guarded Anderson.

use crate::anderson::Anderson;
use crate::collision::{Obstacle, SelfCollision};
use crate::config::SceneConfig;
use crate::contact::{BranchCounts, Contact, ContactSet, ContactSettings};
use crate::delassus::Delassus;
use crate::effects::Effects;
use crate::energy::{bending, Attachments, PdConstraints, Stretch};
use crate::error::Result;
use crate::forces::Wind;
use crate::linalg::SpdFactor;
use crate::mesh::TriMesh;
use crate::params::{Params, SolverSettings};
use crate::profile::Profile;
use crate::scene::{
    attachment_nodes, build_mesh, build_obstacles, build_self_collision, contact_settings,
    params_from_config, solver_from_config, strain_limits,
};
use crate::tape::Tape;
use crate::Vec3;

mod detection;
mod diagnostics;
mod pd;
mod state;
mod step;

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

pub struct Simulator {
    config: SceneConfig,
    mesh: TriMesh,
    handles: Vec<usize>,
    effects: Effects,
    params: Params,
    solver: SolverSettings,
    node_area: Vec<f64>,
    mass: Vec<f64>,
    stretch: Option<Stretch>,
    /// The bending model the scene selects (see `energy::bending`).
    bend: Option<Box<dyn PdConstraints>>,
    attachments: Option<Attachments>,
    wind: Option<Wind>,
    obstacles: Vec<Obstacle>,
    self_collision: Option<SelfCollision>,
    contact_settings: ContactSettings,
    contacts: ContactSet,
    /// The step's Delassus operator (contact response `delassus` only).
    delassus: Delassus,
    /// Scratch of the contact detection: velocities that set each node's reach, and which
    /// nodes have a contact with the obstacle being checked.
    detect_velocity: Vec<Vec3>,
    covered: Vec<bool>,
    factor: SpdFactor,
    // State.
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    time: f64,
    step_count: u64,
    // Work buffers, allocated once.
    y: Vec<Vec3>,
    inertia_rhs: Vec<Vec3>,
    iterate: Vec<Vec3>,
    mapped: Vec<Vec3>,
    /// `G(x_k)` kept while a safeguarded extrapolation is tried.
    previous_mapped: Vec<Vec3>,
    update: Vec<Vec3>,
    extrapolated: Vec<Vec3>,
    anderson: Anderson,
    trace: Option<Vec<(f64, f64)>>,
    tape: Option<Tape>,
    profile: Profile,
    last: StepStats,
}

impl Simulator {
    pub fn new(config: &SceneConfig) -> Result<Self> {
        let effects = Effects::from_config(config)?;
        let placed = build_mesh(config)?;
        let mesh = placed.mesh.clone();
        let n = mesh.num_vertices();
        let params = params_from_config(config)?;
        let solver = solver_from_config(&config.solver)?;
        let [lo, hi] = strain_limits(&config.material)?;
        let node_area = mesh.vertex_areas();
        let stretch = effects
            .stretch
            .then(|| Stretch::new(&mesh, params.k_stretch, lo, hi));
        let bend = effects.bend.then(|| bending(&mesh, params.k_bend));
        let attachments = match (&config.attachments, effects.attachments) {
            (Some(a), true) => {
                let nodes = attachment_nodes(a, &placed)?;
                let targets = nodes.iter().map(|&j| mesh.positions[j]).collect();
                Some(Attachments::new(nodes, params.k_attach, targets))
            }
            _ => None,
        };
        let wind = match (&config.wind, effects.wind) {
            (Some(w), true) => Some(Wind::new(w, &mesh.positions, &node_area)?),
            _ => None,
        };
        let obstacles = if effects.obstacle_contact {
            build_obstacles(&config.obstacles)?
        } else {
            Vec::new()
        };
        let self_collision = match (&config.self_collision, effects.self_collision) {
            (Some(sc), true) => Some(build_self_collision(sc, &mesh)?),
            _ => None,
        };
        let contact_settings = contact_settings(config, &effects)?;
        let mass: Vec<f64> = node_area.iter().map(|a| params.density * a).collect();
        let mut sim = Self {
            config: config.clone(),
            handles: placed.handles,
            effects,
            solver,
            mass,
            stretch,
            bend,
            attachments,
            wind,
            obstacles,
            self_collision,
            contact_settings,
            contacts: ContactSet::default(),
            delassus: Delassus::default(),
            detect_velocity: Vec::with_capacity(n),
            covered: Vec::with_capacity(n),
            factor: SpdFactor::new(1, &[(0, 0, 1.0)])?,
            x: mesh.positions.clone(),
            v: vec![Vec3::zeros(); n],
            time: 0.0,
            step_count: 0,
            y: vec![Vec3::zeros(); n],
            inertia_rhs: vec![Vec3::zeros(); n],
            iterate: vec![Vec3::zeros(); n],
            mapped: vec![Vec3::zeros(); n],
            previous_mapped: vec![Vec3::zeros(); n],
            update: vec![Vec3::zeros(); n],
            extrapolated: vec![Vec3::zeros(); n],
            anderson: Anderson::new(config.solver.history, n),
            trace: None,
            tape: None,
            profile: Profile::default(),
            last: StepStats::default(),
            node_area,
            params,
            mesh,
        };
        sim.factor = SpdFactor::new(n, &sim.system_triplets())?;
        Ok(sim)
    }

    /// Loads a TOML scene file.
    pub fn from_toml_file(path: &std::path::Path) -> Result<Self> {
        Self::new(&SceneConfig::from_toml_file(path)?)
    }

    /// Every constraint set the scene simulates, in a fixed order.
    pub(crate) fn constraint_sets(&self) -> impl Iterator<Item = &dyn PdConstraints> {
        let s = self.stretch.as_ref().map(|c| c as &dyn PdConstraints);
        let b = self.bend.as_deref();
        let a = self.attachments.as_ref().map(|c| c as &dyn PdConstraints);
        [s, b, a].into_iter().flatten()
    }

    fn constraint_sets_mut(&mut self) -> impl Iterator<Item = &mut dyn PdConstraints> {
        let s = self.stretch.as_mut().map(|c| c as &mut dyn PdConstraints);
        let b = self
            .bend
            .as_deref_mut()
            .map(|c| c as &mut dyn PdConstraints);
        let a = self
            .attachments
            .as_mut()
            .map(|c| c as &mut dyn PdConstraints);
        [s, b, a].into_iter().flatten()
    }

    /// Triplets of `P_s = M / h^2 + sum_i w_i A_i^T A_i`.
    fn system_triplets(&mut self) -> Vec<(usize, usize, f64)> {
        let inv_h2 = 1.0 / (self.params.h * self.params.h);
        let mut t: Vec<(usize, usize, f64)> = self
            .mass
            .iter()
            .enumerate()
            .map(|(i, m)| (i, i, m * inv_h2))
            .collect();
        for c in self.constraint_sets() {
            c.add_system_triplets(&mut t);
        }
        t
    }

    // ---- accessors -------------------------------------------------------------------------

    pub fn config(&self) -> &SceneConfig {
        &self.config
    }
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }
    pub fn handles(&self) -> &[usize] {
        &self.handles
    }
    pub fn effects(&self) -> Effects {
        self.effects
    }
    pub fn params(&self) -> &Params {
        &self.params
    }
    pub fn solver(&self) -> &SolverSettings {
        &self.solver
    }
    pub fn num_nodes(&self) -> usize {
        self.mesh.num_vertices()
    }
    pub fn positions(&self) -> &[Vec3] {
        &self.x
    }
    pub fn velocities(&self) -> &[Vec3] {
        &self.v
    }
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }
    pub fn time(&self) -> f64 {
        self.time
    }
    pub fn step_count(&self) -> u64 {
        self.step_count
    }
    /// `(stored values of the Cholesky factor, supernodal?)` of the system matrix.
    pub fn factor_stats(&self) -> (usize, bool) {
        self.factor.factor_stats()
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
        self.stretch.as_ref()
    }
    pub fn bend(&self) -> Option<&dyn PdConstraints> {
        self.bend.as_deref()
    }
    pub fn wind(&self) -> Option<&Wind> {
        self.wind.as_ref()
    }
    /// Each node's share of the rest area (m^2); mass = density x area.
    pub fn node_areas(&self) -> &[f64] {
        &self.node_area
    }
    pub(crate) fn factor(&self) -> &SpdFactor {
        &self.factor
    }
    /// Starts (clearing any previous tape) or stops recording steps for `backward`.
    pub fn set_recording(&mut self, on: bool) {
        self.tape = on.then(Tape::default);
    }

    /// Starts a checkpointed recording: one state every `every` steps plus each step's inputs;
    /// `backward` re-simulates one segment at a time (same gradients, bounded memory).
    pub fn set_recording_checkpointed(&mut self, every: usize) {
        self.tape = Some(Tape::checkpointed(every));
    }

    pub(crate) fn attachments_mut(&mut self) -> Option<&mut Attachments> {
        self.attachments.as_mut()
    }

    pub(crate) fn take_tape(&mut self) -> Option<Tape> {
        self.tape.take()
    }

    pub(crate) fn put_tape(&mut self, tape: Option<Tape>) {
        self.tape = tape;
    }
    pub fn tape(&self) -> Option<&Tape> {
        self.tape.as_ref()
    }
    /// The current step's contacts (frames, branches and impulses of the last step).
    pub fn contacts(&self) -> &[Contact] {
        &self.contacts.contacts
    }
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }
    pub fn contact_settings(&self) -> &ContactSettings {
        &self.contact_settings
    }
    pub fn self_collision(&self) -> Option<&SelfCollision> {
        self.self_collision.as_ref()
    }
    pub fn attachment_nodes(&self) -> &[usize] {
        self.attachments.as_ref().map_or(&[], |a| a.nodes())
    }
    pub fn attachment_targets(&self) -> &[Vec3] {
        self.attachments.as_ref().map_or(&[], |a| a.targets())
    }
}
