//! Setting the state, the physical parameters, friction and the solver settings. Each setter
//! validates first: on error nothing changes.

use super::Simulator;
use crate::anderson::Anderson;
use crate::energy::Stiffness;
use crate::error::{Error, Result};
use crate::params::{
    check_mu, check_nodes, validate_params, validate_solver, Params, SolverSettings,
};
use crate::Vec3;
use std::time::Instant;

impl Simulator {
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

    pub(super) fn apply_matrix_params(&mut self) {
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
        check_mu("mu", mu, Error::Param)?;
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
        check_mu("mu", mu, Error::Param)?;
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
}
