//! The model: everything fixed for a scene between parameter changes (mesh, masses, the
//! energies' rest data, obstacles, the factorization of the PD matrix). Simulators share one
//! by `Arc`, so a batch of N environments factors the matrix once. Changing a parameter the
//! factorization depends on copies the model first (copy on write): simulators and tapes that
//! still hold the old one keep it unchanged.

use crate::collision::{Obstacle, SelfCollision};
use crate::config::SceneConfig;
use crate::contact::ContactSettings;
use crate::effects::Effects;
use crate::energy::{bending, Attachments, PdConstraints, Stiffness, Stretch};
use crate::error::{Error, Result};
use crate::forces::Wind;
use crate::hessian::HessianPattern;
use crate::linalg::SpdFactor;
use crate::mesh::TriMesh;
use crate::params::{validate_params, Params};
use crate::scene::{
    attachment_nodes, build_mesh, build_obstacles, build_self_collision, contact_settings,
    params_from_config, strain_limits,
};
use crate::Vec3;
use std::sync::{Arc, OnceLock};

pub struct Model {
    pub(crate) config: SceneConfig,
    pub(crate) mesh: TriMesh,
    pub(crate) handles: Vec<usize>,
    pub(crate) effects: Effects,
    pub(crate) params: Params,
    pub(crate) node_area: Vec<f64>,
    pub(crate) mass: Vec<f64>,
    pub(crate) stretch: Option<Stretch>,
    /// The bending model the scene selects (see `energy::bending`).
    pub(crate) bend: Option<Box<dyn PdConstraints>>,
    pub(crate) attachments: Option<Attachments>,
    pub(crate) wind: Option<Wind>,
    pub(crate) obstacles: Vec<Obstacle>,
    pub(crate) self_collision: Option<SelfCollision>,
    pub(crate) contact_settings: ContactSettings,
    pub(crate) factor: SpdFactor,
    /// The step Hessian's pattern and symbolic analysis (`hessian.rs`), built on first use
    /// (None: it could not be analysed). Values never enter it, so a copy keeps it.
    pub(crate) hessian: OnceLock<Option<Arc<HessianPattern>>>,
}

impl Clone for Model {
    fn clone(&self) -> Self {
        Self {
            config: self.config.clone(),
            mesh: self.mesh.clone(),
            handles: self.handles.clone(),
            effects: self.effects,
            params: self.params.clone(),
            node_area: self.node_area.clone(),
            mass: self.mass.clone(),
            stretch: self.stretch.clone(),
            bend: self.bend.as_ref().map(|b| b.boxed_clone()),
            attachments: self.attachments.clone(),
            wind: self.wind.clone(),
            obstacles: self.obstacles.clone(),
            self_collision: self.self_collision.clone(),
            contact_settings: self.contact_settings.clone(),
            factor: self.factor.clone(),
            hessian: self.hessian.clone(),
        }
    }
}

/// A scene whose system matrix cannot be factored is singular in floating point: the
/// stiffness over the mass term, ~ k h^2 / (density edge^2), is beyond double precision.
fn explain_singular(e: Error) -> Error {
    match e {
        Error::Solver(m) => Error::Solver(format!(
            "{m}: the scene is numerically singular (stiffness x h^2 / (density x edge length^2) \
             too large): a mesh scaled too small (placement.scale), a tiny h or density, or a huge \
             stiffness"
        )),
        other => other,
    }
}

impl Model {
    /// Builds and factors the scene a config describes (validating it).
    pub fn new(config: &SceneConfig) -> Result<Self> {
        let effects = Effects::from_config(config)?;
        let placed = build_mesh(config)?;
        let mesh = placed.mesh.clone();
        let params = params_from_config(config)?;
        let [lo, hi] = strain_limits(&config.material)?;
        let node_area = mesh.vertex_areas();
        let stretch = effects
            .stretch
            .then(|| Stretch::new(&mesh, params.k_stretch, lo, hi));
        let bend = effects
            .bend
            .then(|| bending(&mesh, params.k_bend, config.material.bend_model));
        let attachments = match (&config.attachments, effects.attachments) {
            (Some(a), true) => Some(Attachments::new(
                attachment_nodes(a, &placed)?,
                params.k_attach,
            )),
            _ => None,
        };
        let wind = match (&config.wind, effects.wind) {
            (Some(w), true) => Some(Wind::new(w, &mesh.positions, &node_area)),
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
        let n = mesh.num_vertices();
        let mut model = Self {
            config: config.clone(),
            handles: placed.handles,
            effects,
            params,
            node_area,
            mass,
            stretch,
            bend,
            attachments,
            wind,
            obstacles,
            self_collision,
            contact_settings,
            factor: SpdFactor::new(1, &[(0, 0, 1.0)])?,
            hessian: OnceLock::new(),
            mesh,
        };
        model.factor = SpdFactor::new(n, &model.system_triplets()).map_err(explain_singular)?;
        Ok(model)
    }

    /// The step Hessian's shared pattern and analysis, built on first call.
    pub(crate) fn hessian_pattern(&self) -> Option<Arc<HessianPattern>> {
        self.hessian
            .get_or_init(|| HessianPattern::new(self).ok().map(Arc::new))
            .clone()
    }

    /// Every elastic constraint set the scene simulates, in a fixed order.
    pub(crate) fn constraint_sets(&self) -> impl Iterator<Item = &dyn PdConstraints> {
        let s = self.stretch.as_ref().map(|c| c as &dyn PdConstraints);
        [s, self.bend.as_deref()].into_iter().flatten()
    }

    /// Triplets of `P_s = M / h^2 + sum_i w_i A_i^T A_i`.
    fn system_triplets(&self) -> Vec<(usize, usize, f64)> {
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
        if let Some(a) = &self.attachments {
            a.add_system_triplets(&mut t);
        }
        t
    }

    /// Replaces the physical parameters; refactors only if h, density or a stiffness changed
    /// (returns whether it did). On error nothing is changed.
    pub(crate) fn set_params(&mut self, params: Params) -> Result<bool> {
        validate_params(&params)?;
        let old = std::mem::replace(&mut self.params, params.clone());
        let refactor = old.h != params.h
            || old.density != params.density
            || old.k_stretch != params.k_stretch
            || old.k_bend != params.k_bend
            || old.k_attach != params.k_attach;
        if refactor {
            self.apply_matrix_params();
            let triplets = self.system_triplets();
            if let Err(e) = self.factor.refactor(&triplets) {
                // Back to the old matrix, which factored before: the model is unchanged.
                self.params = old;
                self.apply_matrix_params();
                let triplets = self.system_triplets();
                self.factor
                    .refactor(&triplets)
                    .expect("the previous matrix factored before");
                return Err(e);
            }
        }
        Ok(refactor)
    }

    fn apply_matrix_params(&mut self) {
        let p = self.params.clone();
        self.mass
            .iter_mut()
            .zip(&self.node_area)
            .for_each(|(m, a)| *m = p.density * a);
        let stretch = self.stretch.as_mut().map(|c| c as &mut dyn PdConstraints);
        for c in [stretch, self.bend.as_deref_mut()].into_iter().flatten() {
            c.set_stiffness(match c.stiffness() {
                Stiffness::Stretch => p.k_stretch,
                Stiffness::Bend => p.k_bend,
            });
        }
        if let Some(a) = self.attachments.as_mut() {
            a.set_stiffness(p.k_attach);
        }
    }

    // ---- accessors -------------------------------------------------------------------------

    pub fn config(&self) -> &SceneConfig {
        &self.config
    }
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }
    pub fn num_nodes(&self) -> usize {
        self.mesh.num_vertices()
    }
    pub fn params(&self) -> &Params {
        &self.params
    }
    pub fn effects(&self) -> Effects {
        self.effects
    }
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }
    /// Each node's share of the rest area (m^2); mass = density x area.
    pub fn node_areas(&self) -> &[f64] {
        &self.node_area
    }
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }
    pub fn attachment_nodes(&self) -> &[usize] {
        self.attachments.as_ref().map_or(&[], |a| a.nodes())
    }
    /// Numeric factorizations of the PD matrix this model (and any it was copied from) did.
    pub fn factorizations(&self) -> u64 {
        self.factor.factorizations()
    }
    /// The rest positions of the attached nodes (the targets after a reset).
    pub(crate) fn rest_targets(&self, x: &[Vec3]) -> Vec<Vec3> {
        self.attachment_nodes().iter().map(|&j| x[j]).collect()
    }
}
