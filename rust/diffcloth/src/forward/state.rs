//! Setting the state, the physical parameters, friction and the solver settings. Each setter
//! validates first: on error nothing changes.

use super::Simulator;
use crate::anderson::Anderson;
use crate::error::{Error, Result};
use crate::params::{
    check_mu, check_nodes, validate_params, validate_solver, Params, SolverSettings,
};
use crate::Vec3;
use std::sync::Arc;
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
        self.state
            .x
            .copy_from_slice(x.unwrap_or(&self.model.mesh.positions));
        match v {
            Some(v) => self.state.v.copy_from_slice(v),
            None => self.state.v.iter_mut().for_each(|vi| *vi = Vec3::zeros()),
        }
        let nodes = self.model.attachment_nodes();
        for (t, &j) in self.state.targets.iter_mut().zip(nodes) {
            *t = self.state.x[j];
        }
        self.state.time = 0.0;
        self.state.step_count = 0;
        if let Some(rec) = self.recording.as_mut() {
            rec.tape.clear();
        }
        Ok(())
    }

    /// Sets the simulated time (the wind's phase and moving obstacles depend on it).
    pub fn set_time(&mut self, t: f64) -> Result<()> {
        if !t.is_finite() {
            return Err(Error::Input(format!("time must be finite, got {t}")));
        }
        self.state.time = t;
        Ok(())
    }

    /// Replaces the physical parameters; refactors the system matrix only if h, density or a
    /// stiffness changed. On error nothing is changed. A model shared with other simulators
    /// or a tape is copied first (they keep theirs).
    pub fn set_params(&mut self, params: Params) -> Result<()> {
        validate_params(&params)?;
        if params == self.model.params {
            return Ok(());
        }
        let start = Instant::now();
        // Copies the model only if another simulator or a tape shares it.
        if Arc::make_mut(&mut self.model).set_params(params)? {
            self.profile.refactorizations += 1;
            self.profile.refactor += start.elapsed();
        }
        Ok(())
    }

    /// Sets the friction coefficient of obstacle `index`.
    pub fn set_obstacle_mu(&mut self, index: usize, mu: f64) -> Result<()> {
        check_mu("mu", mu, Error::Param)?;
        let count = self.model.obstacles.len();
        if index >= count {
            return Err(Error::Param(format!(
                "obstacle {index} does not exist ({count} obstacles)"
            )));
        }
        Arc::make_mut(&mut self.model).obstacles[index].mu = mu;
        Ok(())
    }

    /// Sets the self-contact friction coefficient.
    pub fn set_self_mu(&mut self, mu: f64) -> Result<()> {
        check_mu("mu", mu, Error::Param)?;
        if self.model.self_collision.is_none() {
            return Err(Error::Param("the scene has no self-collision".into()));
        }
        if let Some(sc) = Arc::make_mut(&mut self.model).self_collision.as_mut() {
            sc.mu = mu;
        }
        Ok(())
    }

    pub fn set_solver(&mut self, solver: SolverSettings) -> Result<()> {
        validate_solver(&solver)?;
        if solver.history != self.solver.history {
            self.work.anderson = Anderson::new(solver.history, self.num_nodes());
        }
        if self.trace.is_some() {
            self.trace = Some(Vec::with_capacity(solver.trace_capacity()));
        }
        self.solver = solver;
        Ok(())
    }
}
