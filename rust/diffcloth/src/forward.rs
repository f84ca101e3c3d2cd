//! The simulator and its forward step (paper Sec. 3.1): implicit Euler solved by PD
//! local-global iterations on the prefactored scalar matrix
//! `P_s = M / h^2 + sum_i w_i A_i^T A_i`, accelerated by energy-guarded Anderson.

use crate::anderson::Anderson;
use crate::collision::{Motion, Obstacle, SelfCollision, Shape};
use crate::config::{ContactResponse, SceneConfig, ShapeConfig};
use crate::delassus::Delassus;

use crate::contact::{BranchCounts, Contact, ContactSet, ContactSettings};
use crate::effects::Effects;
use crate::energy::{bending, Attachments, PdConstraints, Stiffness, Stretch};
use crate::error::{Error, Result};
use crate::forces::Wind;
use crate::linalg::SpdFactor;
use crate::mesh::TriMesh;
use crate::profile::{timed, Profile};
use crate::scene::{attachment_nodes, build_mesh};
use crate::tape::{CompletedStep, Tape};
use crate::Vec3;
use std::time::Instant;

/// Physical parameters that can change between steps. Changing any of the first five
/// refactors the system matrix (once); the others only change right-hand sides.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// Time step h in s.
    pub h: f64,
    /// Area density in kg/m^2.
    pub density: f64,
    /// Stretch stiffness in N/m.
    pub k_stretch: f64,
    /// Bending stiffness in N m.
    pub k_bend: f64,
    /// Attachment spring stiffness in N/m.
    pub k_attach: f64,
    /// Gravitational acceleration in m/s^2.
    pub gravity: Vec3,
    /// Wind amplitude vector d, angular frequency omega (rad/s), phase phi (rad).
    pub wind_direction: Vec3,
    pub wind_omega: f64,
    pub wind_phi: f64,
}

/// Accuracy knobs of the PD solve.
#[derive(Debug, Clone, PartialEq)]
pub struct SolverSettings {
    /// Iteration cap per step.
    pub max_iterations: usize,
    /// Stop when the RMS per-coordinate PD update `|G(x) - x|` is below this (metres).
    pub tolerance: f64,
    /// Tolerance of steps recorded on a tape (see `SolverConfig::record_tolerance`).
    pub record_tolerance: f64,
    /// Iteration cap of recorded steps (the larger of this and `max_iterations`).
    pub record_max_iterations: usize,
    /// Energy-guarded Anderson acceleration on/off.
    pub anderson: bool,
    /// Anderson history length (1..=8).
    pub history: usize,
    /// Project constraints on all threads (for large meshes).
    pub parallel: bool,
}

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

/// Largest step scale `a` of the saddle escape in [`Simulator::solve_pd`].
const ESCAPE_MAX_SCALE: f64 = 64.0;

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
        let m = &config.material;
        let s = &config.solver;
        let wind_cfg = config.wind.as_ref();
        let params = Params {
            h: config.h,
            density: m.density,
            k_stretch: m.k_stretch,
            k_bend: m.k_bend,
            k_attach: config.attachments.as_ref().map_or(0.0, |a| a.stiffness),
            gravity: Vec3::from(config.gravity),
            wind_direction: wind_cfg.map_or(Vec3::zeros(), |w| Vec3::from(w.direction)),
            wind_omega: wind_cfg.map_or(0.0, |w| w.omega),
            wind_phi: wind_cfg.map_or(0.0, |w| w.phi),
        };
        validate_params(&params)?;
        let [lo, hi] = m.strain_limits;
        if !(lo > 0.0 && lo <= hi && hi.is_finite()) {
            return Err(Error::Config(format!(
                "material.strain_limits must satisfy 0 < min <= max, got [{lo}, {hi}]"
            )));
        }
        let solver = SolverSettings {
            max_iterations: s.max_iterations,
            tolerance: s.tolerance,
            record_tolerance: s.record_tolerance,
            record_max_iterations: s.record_max_iterations,
            anderson: match s.acceleration.as_str() {
                "anderson" => true,
                "none" => false,
                other => {
                    return Err(Error::Config(format!(
                        "solver.acceleration must be \"anderson\" or \"none\", got {other:?}"
                    )))
                }
            },
            history: s.history,
            parallel: s.parallel,
        };
        validate_solver(&solver)?;

        let node_area = mesh.vertex_areas();
        let stretch = effects
            .stretch
            .then(|| Stretch::new(&mesh, params.k_stretch, lo, hi));
        let bend = effects.bend.then(|| bending(&mesh, params.k_bend, config.material.bend_model));
        let attachments = match (&config.attachments, effects.attachments) {
            (Some(a), true) => {
                let nodes = attachment_nodes(a, &placed)?;
                let targets = nodes.iter().map(|&j| mesh.positions[j]).collect();
                Some(Attachments::new(nodes, params.k_attach, targets))
            }
            _ => None,
        };
        let wind = match (wind_cfg, effects.wind) {
            (Some(w), true) => Some(Wind::new(w, &mesh.positions, &node_area)?),
            _ => None,
        };
        let obstacles = if effects.obstacle_contact {
            config
                .obstacles
                .iter()
                .enumerate()
                .map(|(i, o)| build_obstacle(i, o))
                .collect::<Result<Vec<_>>>()?
        } else {
            Vec::new()
        };
        let self_collision = match (&config.self_collision, effects.self_collision) {
            (Some(sc), true) => {
                if !(sc.radius > 0.0 && sc.radius.is_finite()) {
                    return Err(Error::Config(format!(
                        "self_collision.radius must be positive, got {}",
                        sc.radius
                    )));
                }
                check_mu("self_collision.mu", sc.mu)?;
                Some(SelfCollision::new(&mesh, sc.radius, sc.mu))
            }
            _ => None,
        };
        let contact_cfg = config.contact.clone().unwrap_or_default();
        if !(contact_cfg.thickness >= 0.0
            && contact_cfg.margin >= 0.0
            && contact_cfg.thickness.is_finite()
            && contact_cfg.margin.is_finite())
        {
            return Err(Error::Config(
                "contact.thickness and contact.margin must be non-negative".into(),
            ));
        }
        let contact_settings = ContactSettings {
            thickness: contact_cfg.thickness,
            margin: contact_cfg.margin,
            friction: effects.friction,
            response: contact_cfg.response,
        };
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
        let b = self.bend.as_deref_mut().map(|c| c as &mut dyn PdConstraints);
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

    /// Records `(energy, residual)` of every PD iteration of the next steps (for studies).
    pub fn set_trace(&mut self, on: bool) {
        self.trace = on.then(|| Vec::with_capacity(self.solver.max_iterations + 1));
    }
    /// The `(energy, residual)` per iteration of the last step, if tracing.
    pub fn trace(&self) -> Option<&[(f64, f64)]> {
        self.trace.as_deref()
    }

    // ---- state and parameters --------------------------------------------------------------

    /// Sets the state (defaults: rest positions, zero velocity), time 0, attachment targets
    /// back to the attached nodes' positions.
    pub fn reset(&mut self, x: Option<&[Vec3]>, v: Option<&[Vec3]>) -> Result<()> {
        let n = self.num_nodes();
        if let Some(x) = x {
            check_nodes("x", x, n)?;
        }
        if let Some(v) = v {
            check_nodes("v", v, n)?;
        }
        self.x.copy_from_slice(x.unwrap_or(&self.mesh.positions));
        match v {
            Some(v) => self.v.copy_from_slice(v),
            None => self.v.iter_mut().for_each(|vi| *vi = Vec3::zeros()),
        }
        if let Some(a) = self.attachments.as_mut() {
            let targets: Vec<Vec3> = a.nodes().iter().map(|&j| self.x[j]).collect();
            a.set_targets(&targets);
        }
        self.time = 0.0;
        self.step_count = 0;
        if let Some(tape) = self.tape.as_mut() {
            tape.clear();
        }
        Ok(())
    }

    /// Sets the simulated time (the wind's phase and moving obstacles depend on it).
    pub fn set_time(&mut self, t: f64) -> Result<()> {
        if !t.is_finite() {
            return Err(Error::Input(format!("time must be finite, got {t}")));
        }
        self.time = t;
        Ok(())
    }

    /// Replaces the physical parameters; refactors the system matrix only if h, density or a
    /// stiffness changed. On error nothing is changed.
    pub fn set_params(&mut self, params: Params) -> Result<()> {
        validate_params(&params)?;
        let old = std::mem::replace(&mut self.params, params.clone());
        let refactor = old.h != params.h
            || old.density != params.density
            || old.k_stretch != params.k_stretch
            || old.k_bend != params.k_bend
            || old.k_attach != params.k_attach;
        if refactor {
            self.apply_matrix_params();
            let start = Instant::now();
            let triplets = self.system_triplets();
            if let Err(e) = self.factor.refactor(&triplets) {
                self.params = old;
                self.apply_matrix_params();
                return Err(e);
            }
            self.profile.refactorizations += 1;
            self.profile.refactor += start.elapsed();
        }
        if let Some(w) = self.wind.as_mut() {
            w.direction = params.wind_direction;
            w.omega = params.wind_omega;
            w.phi = params.wind_phi;
        }
        Ok(())
    }

    fn apply_matrix_params(&mut self) {
        let p = self.params.clone();
        self.mass
            .iter_mut()
            .zip(&self.node_area)
            .for_each(|(m, a)| *m = p.density * a);
        for c in self.constraint_sets_mut() {
            c.set_stiffness(match c.stiffness() {
                Stiffness::Stretch => p.k_stretch,
                Stiffness::Bend => p.k_bend,
                Stiffness::Attach => p.k_attach,
            });
        }
    }

    /// Sets the friction coefficient of obstacle `index`.
    pub fn set_obstacle_mu(&mut self, index: usize, mu: f64) -> Result<()> {
        check_mu("mu", mu).map_err(|e| Error::Param(e.to_string()))?;
        let count = self.obstacles.len();
        let o = self.obstacles.get_mut(index).ok_or_else(|| {
            Error::Param(format!(
                "obstacle {index} does not exist ({count} obstacles)"
            ))
        })?;
        o.mu = mu;
        Ok(())
    }

    /// Sets the self-contact friction coefficient.
    pub fn set_self_mu(&mut self, mu: f64) -> Result<()> {
        check_mu("mu", mu).map_err(|e| Error::Param(e.to_string()))?;
        let sc = self
            .self_collision
            .as_mut()
            .ok_or_else(|| Error::Param("the scene has no self-collision".into()))?;
        sc.mu = mu;
        Ok(())
    }

    pub fn set_solver(&mut self, solver: SolverSettings) -> Result<()> {
        validate_solver(&solver)?;
        if solver.history != self.solver.history {
            self.anderson = Anderson::new(solver.history, self.num_nodes());
        }
        if self.trace.is_some() {
            self.trace = Some(Vec::with_capacity(solver.max_iterations + 1));
        }
        self.solver = solver;
        Ok(())
    }

    // ---- the step --------------------------------------------------------------------------

    /// Advances one implicit-Euler step. On error the state is unchanged.
    pub fn step(&mut self, input: StepInput<'_>) -> Result<StepStats> {
        let start = Instant::now();
        let p0 = self.profile.clone();
        self.prepare(input)?;
        if self.effects.has_contact() {
            self.detect_contacts(false);
        }
        let mut stats = self.solve_pd();
        // Detection reaches as far as each node's entering velocity carries it. A node that
        // speeds up within the step (a snap-through) can end inside an obstacle it was never
        // a candidate for (the Hat: 3.6 cm in one step, 9.8 mm deep in the head); then detect
        // again with the step's own motion and solve the step once more.
        if self.effects.obstacle_contact && self.missed_obstacle_contact() {
            self.profile.redetections += 1;
            self.detect_contacts(true);
            stats = self.solve_pd();
        }
        // The PD result is in `mapped`.
        let h = self.params.h;
        if !self.mapped.iter().all(|p| p.iter().all(|c| c.is_finite())) {
            return Err(Error::Diverged(format!(
                "non-finite positions at step {}; state left at the previous step",
                self.step_count
            )));
        }
        if let Some(tape) = self.tape.as_mut() {
            tape.push(&CompletedStep {
                x_prev: &self.x,
                v_prev: &self.v,
                x_next: &self.mapped,
                targets: self.attachments.as_ref().map(|a| a.targets()),
                forces: input.external_forces,
                time: self.time,
                contacts: &self.contacts.contacts,
                residual: stats.residual,
            });
        }
        for ((x, v), xn) in self.x.iter_mut().zip(self.v.iter_mut()).zip(&self.mapped) {
            *v = (xn - *x) / h;
            *x = *xn;
        }
        self.time += h;
        self.step_count += 1;
        self.last = stats;
        let p = &mut self.profile;
        p.steps += 1;
        p.iterations += stats.iterations as u64;
        p.unconverged_steps += u64::from(!stats.converged);
        p.contacts_take_off += stats.contacts.take_off as u64;
        p.contacts_stick += stats.contacts.stick as u64;
        p.contacts_slip += stats.contacts.slip as u64;
        let total = start.elapsed();
        p.total += total;
        let staged = (p.local - p0.local)
            + (p.global - p0.global)
            + (p.detection - p0.detection)
            + (p.contact_solve - p0.contact_solve);
        p.other += total.saturating_sub(staged);
        Ok(stats)
    }

    /// Finds this step's contact candidates from the entering state; with `with_motion`, each
    /// node's reach also covers the motion of the step just solved (in `mapped`).
    fn detect_contacts(&mut self, with_motion: bool) {
        let detect_start = Instant::now();
        let h = self.params.h;
        let mut velocity = std::mem::take(&mut self.detect_velocity);
        velocity.clear();
        velocity.extend(
            self.v
                .iter()
                .zip(&self.x)
                .zip(&self.mapped)
                .map(|((v, x), xn)| {
                    let moved = (xn - x) / h;
                    if with_motion && moved.norm() > v.norm() {
                        moved
                    } else {
                        *v
                    }
                }),
        );
        self.contacts.detect(
            &self.x,
            &velocity,
            &self.mass,
            self.time,
            h,
            &self.obstacles,
            self.self_collision.as_mut(),
            &self.contact_settings,
        );
        self.detect_velocity = velocity;
        self.profile.detection += detect_start.elapsed();
        if self.delassus_response() {
            let start = Instant::now();
            self.delassus.build(&self.factor, &self.contacts.contacts);
            self.profile.contact_solve += start.elapsed();
            self.profile.delassus_builds += 1;
        }
    }

    /// Whether this step's contacts respond through the Delassus operator.
    fn delassus_response(&self) -> bool {
        !self.contacts.is_empty() && self.contact_settings.response == ContactResponse::Delassus
    }

    /// Whether the solved step (`mapped`) put a node that has no contact with an obstacle
    /// inside that obstacle's contact layer.
    fn missed_obstacle_contact(&mut self) -> bool {
        let detect_start = Instant::now();
        let mut covered = std::mem::take(&mut self.covered);
        let mut missed = false;
        for (o, obstacle) in self.obstacles.iter().enumerate() {
            covered.clear();
            covered.resize(self.x.len(), false);
            for c in &self.contacts.contacts {
                if let crate::contact::ContactKind::Obstacle { node, obstacle } = c.kind {
                    if obstacle == o {
                        covered[node] = true;
                    }
                }
            }
            let (offset, _) = obstacle.motion.at(self.time + self.params.h);
            let layer = self.contact_settings.thickness;
            missed |= self
                .mapped
                .iter()
                .zip(&covered)
                .any(|(p, &c)| !c && obstacle.shape.distance(&(p - offset)).0 < layer);
            if missed {
                break;
            }
        }
        self.covered = covered;
        self.profile.detection += detect_start.elapsed();
        missed
    }

    /// Validates the inputs and computes the inertial prediction
    /// `y = x + h v + h^2 M^{-1} f_ext` and `M y / h^2`.
    pub fn prepare(&mut self, input: StepInput<'_>) -> Result<()> {
        let n = self.num_nodes();
        if let Some(t) = input.attachment_targets {
            let Some(a) = self.attachments.as_mut() else {
                return Err(Error::Input(
                    "attachment targets given but the scene has no attachments".into(),
                ));
            };
            check_nodes("attachment_targets", t, a.nodes().len())?;
            a.set_targets(t);
        }
        if let Some(f) = input.external_forces {
            if !self.effects.external_forces {
                return Err(Error::Input(
                    "external forces given but 'external_forces' is not in the scene's effects"
                        .into(),
                ));
            }
            check_nodes("external_forces", f, n)?;
        }
        let h = self.params.h;
        // Accumulate forces in `y` first, then turn them into the prediction.
        let f = &mut self.y;
        match input.external_forces {
            Some(ext) => f.copy_from_slice(ext),
            None => f.iter_mut().for_each(|fi| *fi = Vec3::zeros()),
        }
        if self.effects.gravity {
            let g = self.params.gravity;
            f.iter_mut()
                .zip(&self.mass)
                .for_each(|(fi, m)| *fi += *m * g);
        }
        if let Some(w) = &self.wind {
            w.add_forces(self.time, f);
        }
        let inv_h2 = 1.0 / (h * h);
        for i in 0..n {
            let y = self.x[i] + h * self.v[i] + (h * h / self.mass[i]) * self.y[i];
            self.y[i] = y;
            self.inertia_rhs[i] = self.mass[i] * inv_h2 * y;
        }
        Ok(())
    }

    /// Local step at `x`: projects every constraint, writes `M y / h^2 + sum_i w_i A_i^T p_i`
    /// into `rhs` and returns the implicit-Euler objective
    /// `E(x) = |x - y|_M^2 / (2 h^2) + sum_i w_i / 2 |A_i x - p_i|^2`.
    fn local_step(&mut self, which: Buffer) -> f64 {
        let start = Instant::now();
        let parallel = self.solver.parallel;
        let x = std::mem::take(self.buffer(which));
        let mut rhs = std::mem::take(&mut self.update);
        rhs.copy_from_slice(&self.inertia_rhs);
        let inv_2h2 = 0.5 / (self.params.h * self.params.h);
        let mut energy: f64 = x
            .iter()
            .zip(&self.y)
            .zip(&self.mass)
            .map(|((xi, yi), m)| m * (xi - yi).norm_squared())
            .sum::<f64>()
            * inv_2h2;
        for c in self.constraint_sets_mut() {
            energy += c.project(&x, parallel);
            c.add_rhs(&mut rhs);
        }
        *self.buffer(which) = x;
        self.update = rhs;
        self.profile.local += start.elapsed();
        energy
    }

    fn buffer(&mut self, which: Buffer) -> &mut Vec<Vec3> {
        match which {
            Buffer::Iterate => &mut self.iterate,
            Buffer::Extrapolated => &mut self.extrapolated,
        }
    }

    /// Global step: `mapped = P_s^{-1} rhs` (rhs in `update`), then `update = mapped - iterate`.
    /// Returns the RMS of the update.
    fn global_step(&mut self) -> f64 {
        let factor = &mut self.factor;
        timed(&mut self.profile.global, || {
            factor.solve_xyz(&mut self.update)
        });
        if self.delassus_response() {
            let start = Instant::now();
            self.delassus.respond(
                &mut self.update,
                &self.x,
                self.params.h,
                &mut self.contacts.contacts,
            );
            self.profile.contact_solve += start.elapsed();
        }
        let mut sum = 0.0;
        for ((u, g), x) in self
            .update
            .iter_mut()
            .zip(self.mapped.iter_mut())
            .zip(&self.iterate)
        {
            *g = *u;
            *u -= x;
            sum += u.norm_squared();
        }
        (sum / (3 * self.iterate.len()) as f64).sqrt()
    }

    /// PD iterations from the initial guess `y`. Each iteration maps the iterate x to
    /// `G(x) = P^{-1}(M y / h^2 + sum w A^T p(x) + r(x))` with contact forces `r`.
    ///
    /// Anderson acceleration is safeguarded two ways. Without contact, G never raises the
    /// energy E, and an extrapolation is kept only if it lowers E below the last accepted
    /// iterate's (Peng et al. 2018). Contact forces are not conservative, so with contacts an
    /// extrapolation is kept only if its PD update `|G(x) - x|` is smaller than the last
    /// iterate's; otherwise the plain step `G(x_k)` (already computed) is taken. Either way a
    /// rejection restarts the history.
    ///
    /// Leaving a saddle. When the cloth buckles or snaps through, the iterates can first
    /// approach a saddle of E; Anderson, a secant method for fixed points, is drawn to the
    /// saddle (its extrapolations raise E and are rejected) and plain PD leaves it only at the
    /// slow geometric rate of the unstable direction (Hat: hundreds of iterations with the
    /// update growing about 3 % per iteration while E falls). Two plain updates in a row that
    /// grow while E falls mark that regime; there the step `x + a (G(x) - x)` is tried with
    /// `a` doubling up to [`ESCAPE_MAX_SCALE`] while E keeps falling. Every accepted point
    /// still lowers E, so the safeguard is the same; the first shrinking update ends it. Contact
    /// steps escape the same way (the Hat sliding off the head: 9 % -> 3 % of steps at the
    /// iteration cap); there E leaves out the contact forces, which only the fixed point
    /// must satisfy.
    fn solve_pd(&mut self) -> StepStats {
        self.iterate.copy_from_slice(&self.y);
        self.anderson.reset();
        if let Some(t) = self.trace.as_mut() {
            t.clear();
        }
        // Recorded steps converge further: the adjoint needs the converged solution.
        let user_tol = self.solver.tolerance;
        let tol = if self.tape.is_some() {
            user_tol.min(self.solver.record_tolerance)
        } else {
            user_tol
        };
        let mut reached_user_tol: Option<usize> = None;
        let max_it = if self.tape.is_some() {
            self.solver
                .max_iterations
                .max(self.solver.record_max_iterations)
        } else {
            self.solver.max_iterations
        };
        let mut energy = self.local_step(Buffer::Iterate);
        self.solve_contacts(Buffer::Iterate);
        let mut residual = self.global_step();
        let mut iterations = 1;
        self.record(energy, residual);
        // Saddle escape (see above): consecutive growing plain updates, and the step scale.
        let mut growing = 0;
        let mut escape_scale = 1.0;
        // Residual guard (contact steps): the residual is not monotone under G, so accepted
        // extrapolations and plain steps can cycle (measured on the Sock: a 14-iteration
        // cycle, 3000 iterations without converging, where plain PD takes 101). Without a new
        // lowest residual for `stall_window` iterations, the step finishes with plain PD.
        let mut accelerate = self.solver.anderson;
        let mut best_residual = residual;
        let mut best_at = iterations;
        let stall_window = 2 * self.anderson.history() + 4;
        while residual > tol && iterations < max_it {
            // While no contact pushes (all take off at the iterate), E is the exact objective
            // and the energy guard applies; the residual guard only where contact forces act.
            let energy_guard = self.contacts.all_take_off();
            let mut accepted = false;
            let mut extrapolated_by_anderson = false;
            let (previous_residual, previous_energy) = (residual, energy);
            if escape_scale > 1.0 {
                for ((e, x), u) in self
                    .extrapolated
                    .iter_mut()
                    .zip(&self.iterate)
                    .zip(&self.update)
                {
                    *e = x + escape_scale * u;
                }
                let trial = self.local_step(Buffer::Extrapolated);
                if trial < energy {
                    std::mem::swap(&mut self.iterate, &mut self.extrapolated);
                    energy = trial;
                    accepted = true;
                    escape_scale = (2.0 * escape_scale).min(ESCAPE_MAX_SCALE);
                    self.profile.escape_steps += 1;
                } else {
                    escape_scale = 1.0;
                }
            } else if accelerate {
                self.anderson.push(&self.update, &self.mapped);
                if self
                    .anderson
                    .extrapolate(&self.update, &self.mapped, &mut self.extrapolated)
                {
                    let trial = self.local_step(Buffer::Extrapolated);
                    if energy_guard {
                        if trial < energy {
                            std::mem::swap(&mut self.iterate, &mut self.extrapolated);
                            energy = trial;
                            accepted = true;
                            extrapolated_by_anderson = true;
                        }
                    } else {
                        // Residual guard: evaluate G at the extrapolation, keep it if better.
                        self.solve_contacts(Buffer::Extrapolated);
                        std::mem::swap(&mut self.iterate, &mut self.extrapolated);
                        std::mem::swap(&mut self.mapped, &mut self.previous_mapped);
                        let trial_residual = self.global_step();
                        iterations += 1;
                        if trial_residual < residual {
                            energy = trial;
                            residual = trial_residual;
                            self.record(energy, residual);
                            if residual < best_residual {
                                (best_residual, best_at) = (residual, iterations);
                            }
                            if reached_user_tol.is_none() && residual <= user_tol {
                                reached_user_tol = Some(iterations);
                            }
                            continue;
                        }
                        // Undo: back to x_k and G(x_k).
                        std::mem::swap(&mut self.iterate, &mut self.extrapolated);
                        std::mem::swap(&mut self.mapped, &mut self.previous_mapped);
                    }
                    if !accepted {
                        self.profile.acceleration_rejections += 1;
                        self.anderson.reset();
                    }
                }
            }
            if !accepted {
                self.iterate.copy_from_slice(&self.mapped);
                energy = self.local_step(Buffer::Iterate);
            }
            self.solve_contacts(Buffer::Iterate);
            residual = self.global_step();
            iterations += 1;
            self.record(energy, residual);
            if reached_user_tol.is_none() && residual <= user_tol {
                reached_user_tol = Some(iterations);
            }
            if !energy_guard && accelerate && escape_scale == 1.0 {
                if residual < best_residual {
                    (best_residual, best_at) = (residual, iterations);
                } else if iterations - best_at > stall_window {
                    accelerate = false;
                    self.profile.acceleration_stalls += 1;
                }
            }
            let grew = !extrapolated_by_anderson
                && residual > previous_residual
                && energy < previous_energy;
            growing = if grew { growing + 1 } else { 0 };
            if growing == 0 {
                if escape_scale > 1.0 {
                    // Out of the saddle: the stall test starts afresh.
                    (best_residual, best_at) = (residual, iterations);
                }
                escape_scale = 1.0;
            } else if growing >= 2 && escape_scale == 1.0 {
                escape_scale = 2.0;
                self.anderson.reset();
            }
        }
        if let Some(at) = reached_user_tol {
            self.profile.polish_iterations += (iterations - at) as u64;
        }
        StepStats {
            iterations,
            residual,
            converged: residual <= tol,
            contacts: self.contacts.counts(),
        }
    }

    /// Adds this iteration's contact forces at the iterate to the right-hand side in `update`.
    fn solve_contacts(&mut self, which: Buffer) {
        // (The Delassus response acts after the global solve instead.)
        if self.contacts.is_empty() || self.delassus_response() {
            return;
        }
        let start = Instant::now();
        let x = std::mem::take(self.buffer(which));
        self.contacts.solve(
            &x,
            &self.x,
            &self.mass,
            self.params.h,
            self.factor.matrix(),
            &mut self.update,
        );
        *self.buffer(which) = x;
        self.profile.contact_solve += start.elapsed();
    }

    fn record(&mut self, energy: f64, residual: f64) {
        if let Some(t) = self.trace.as_mut() {
            if t.len() < t.capacity() {
                t.push((energy, residual));
            }
        }
    }

    /// Objective `E(x)` of the implicit step prepared by [`Simulator::prepare`] and its exact
    /// gradient `P x - rhs(x)` (what PD minimizes; used by tests and studies).
    pub fn step_objective(&mut self, x: &[Vec3]) -> (f64, Vec<Vec3>) {
        self.iterate.copy_from_slice(x);
        let e = self.local_step(Buffer::Iterate);
        let mut grad = vec![Vec3::zeros(); x.len()];
        self.factor.mul_xyz(x, &mut grad);
        for (g, r) in grad.iter_mut().zip(&self.update) {
            *g -= r;
        }
        (e, grad)
    }

    /// Solves the prepared step and returns its positions without advancing the state.
    pub fn solve_prepared(&mut self) -> (Vec<Vec3>, StepStats) {
        let stats = self.solve_pd();
        (self.mapped.clone(), stats)
    }

    /// Total mechanical energy: kinetic + gravitational + elastic at the current state.
    pub fn mechanical_energy(&mut self) -> f64 {
        let kinetic: f64 = self
            .v
            .iter()
            .zip(&self.mass)
            .map(|(v, m)| 0.5 * m * v.norm_squared())
            .sum();
        let potential: f64 = if self.effects.gravity {
            -self
                .x
                .iter()
                .zip(&self.mass)
                .map(|(x, m)| m * self.params.gravity.dot(x))
                .sum::<f64>()
        } else {
            0.0
        };
        let x = self.x.clone();
        let elastic: f64 = self.constraint_sets_mut().map(|c| c.project(&x, false)).sum();
        kinetic + potential + elastic
    }
}

#[derive(Clone, Copy)]
enum Buffer {
    Iterate,
    Extrapolated,
}

fn check_mu(name: &str, mu: f64) -> Result<()> {
    if !(mu >= 0.0 && mu.is_finite()) {
        return Err(Error::Config(format!(
            "{name} must be non-negative and finite, got {mu}"
        )));
    }
    Ok(())
}

fn build_shape(cfg: &ShapeConfig) -> Shape {
    let v = Vec3::from;
    match cfg {
        ShapeConfig::Plane { point, normal } => {
            let n = v(*normal);
            Shape::Plane {
                point: v(*point),
                normal: if n.norm() > 0.0 { n.normalize() } else { n },
            }
        }
        ShapeConfig::Sphere { center, radius } => Shape::Sphere {
            center: v(*center),
            radius: *radius,
        },
        ShapeConfig::Capsule { a, b, radius } => Shape::Capsule {
            a: v(*a),
            b: v(*b),
            radius: *radius,
        },
        ShapeConfig::Box {
            center,
            half_extents,
            rotate_deg,
        } => {
            let [rx, ry, rz] = rotate_deg.map(f64::to_radians);
            Shape::Box {
                center: v(*center),
                half_extents: v(*half_extents),
                rotation: nalgebra::Rotation3::from_euler_angles(rx, ry, rz),
            }
        }
        ShapeConfig::Bowl {
            center,
            radius,
            rim_height,
        } => Shape::Bowl {
            center: v(*center),
            radius: *radius,
            rim_height: *rim_height,
        },
        ShapeConfig::PyramidPit {
            apex,
            half_width,
            height,
        } => Shape::PyramidPit {
            apex: v(*apex),
            half_width: *half_width,
            height: *height,
        },
        ShapeConfig::Union { parts } => Shape::Union(parts.iter().map(build_shape).collect()),
    }
}

fn build_obstacle(index: usize, cfg: &crate::config::ObstacleConfig) -> Result<Obstacle> {
    let shape = build_shape(&cfg.shape);
    shape
        .validate()
        .map_err(|e| Error::Config(format!("obstacles[{index}]: {e}")))?;
    check_mu(&format!("obstacles[{index}].mu"), cfg.mu)?;
    let motion = match (&cfg.velocity, &cfg.path) {
        (Some(_), Some(_)) => {
            return Err(Error::Config(format!(
                "obstacles[{index}]: give `velocity` or `path`, not both"
            )))
        }
        (Some(vel), None) => Motion::Linear {
            velocity: Vec3::from(*vel),
        },
        (None, Some(rows)) => {
            let ok = !rows.is_empty()
                && rows.iter().all(|r| r.iter().all(|c| c.is_finite()))
                && rows.windows(2).all(|w| w[1][0] > w[0][0]);
            if !ok {
                return Err(Error::Config(format!(
                    "obstacles[{index}].path needs finite rows [t, dx, dy, dz] with increasing t"
                )));
            }
            Motion::Path(
                rows.iter()
                    .map(|r| (r[0], Vec3::new(r[1], r[2], r[3])))
                    .collect(),
            )
        }
        (None, None) => Motion::Static,
    };
    Ok(Obstacle {
        shape,
        mu: cfg.mu,
        motion,
    })
}

fn check_nodes(name: &str, values: &[Vec3], expected: usize) -> Result<()> {
    if values.len() != expected {
        return Err(Error::Input(format!(
            "{name} must have {expected} rows (one per node), got {}",
            values.len()
        )));
    }
    if let Some(i) = values.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::Input(format!(
            "{name} row {i} is not finite: {:?}",
            values[i].as_slice()
        )));
    }
    Ok(())
}

fn validate_params(p: &Params) -> Result<()> {
    let positive = [("h", p.h), ("density", p.density)];
    for (name, v) in positive {
        if !(v > 0.0 && v.is_finite()) {
            return Err(Error::Param(format!(
                "{name} must be positive and finite, got {v}"
            )));
        }
    }
    let non_negative = [
        ("k_stretch", p.k_stretch),
        ("k_bend", p.k_bend),
        ("k_attach", p.k_attach),
    ];
    for (name, v) in non_negative {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(Error::Param(format!(
                "{name} must be non-negative and finite, got {v}"
            )));
        }
    }
    let finite = p
        .gravity
        .iter()
        .chain(p.wind_direction.iter())
        .all(|c| c.is_finite())
        && p.wind_omega.is_finite()
        && p.wind_phi.is_finite();
    if !finite {
        return Err(Error::Param(
            "gravity and wind parameters must be finite".into(),
        ));
    }
    Ok(())
}

fn validate_solver(s: &SolverSettings) -> Result<()> {
    if s.max_iterations == 0 {
        return Err(Error::Param(
            "solver max_iterations must be at least 1".into(),
        ));
    }
    if !(s.tolerance >= 0.0 && s.tolerance.is_finite()) {
        return Err(Error::Param(format!(
            "solver tolerance must be non-negative and finite, got {}",
            s.tolerance
        )));
    }
    if !(s.record_tolerance >= 0.0 && s.record_tolerance.is_finite()) {
        return Err(Error::Param(format!(
            "solver record_tolerance must be non-negative and finite, got {}",
            s.record_tolerance
        )));
    }
    if !(1..=crate::anderson::MAX_HISTORY).contains(&s.history) {
        return Err(Error::Param(format!(
            "solver history must be in 1..={}, got {}",
            crate::anderson::MAX_HISTORY,
            s.history
        )));
    }
    Ok(())
}
