//! What studies and tests look at beyond the state: the per-iteration trace, the step
//! objective and its gradient, an unadvanced solve, and the mechanical energy.

use super::pd::Buffer;
use super::{Simulator, StepStats};
use crate::Vec3;

impl Simulator {
    pub(super) fn record(&mut self, energy: f64, residual: f64) {
        if let Some(t) = self.trace.as_mut() {
            if t.len() < t.capacity() {
                t.push((energy, residual));
            }
        }
    }

    /// Objective `E(x)` of the implicit step prepared by [`Simulator::prepare`] and its exact
    /// gradient `P x - rhs(x)` (what PD minimizes; used by tests and studies).
    pub fn step_objective(&mut self, x: &[Vec3]) -> (f64, Vec<Vec3>) {
        self.work.iterate.copy_from_slice(x);
        let e = self.local_step(Buffer::Iterate);
        let mut grad = vec![Vec3::zeros(); x.len()];
        self.model.factor.mul_xyz(x, &mut grad);
        for (g, r) in grad.iter_mut().zip(&self.work.update) {
            *g -= r;
        }
        (e, grad)
    }

    /// Solves the prepared step and returns its positions without advancing the state.
    pub fn solve_prepared(&mut self) -> (Vec<Vec3>, StepStats) {
        let stats = self.solve_pd();
        (self.work.mapped.clone(), stats)
    }

    /// Total mechanical energy: kinetic + gravitational + elastic at the current state.
    pub fn mechanical_energy(&mut self) -> f64 {
        let kinetic: f64 = self
            .state
            .v
            .iter()
            .zip(&self.model.mass)
            .map(|(v, m)| 0.5 * m * v.norm_squared())
            .sum();
        let potential: f64 = if self.model.effects.gravity {
            -self
                .state
                .x
                .iter()
                .zip(&self.model.mass)
                .map(|(x, m)| m * self.model.params.gravity.dot(x))
                .sum::<f64>()
        } else {
            0.0
        };
        let (model, x) = (&*self.model, &self.state.x);
        let sets = model.constraint_sets().zip(&mut self.work.projections);
        let elastic: f64 = sets.map(|(c, proj)| c.project(x, false, proj)).sum::<f64>()
            + model
                .attachments
                .as_ref()
                .map_or(0.0, |a| a.energy(x, &self.state.targets));
        kinetic + potential + elastic
    }

    /// Records `(energy, residual)` of every PD iteration of the next steps (for studies).
    pub fn set_trace(&mut self, on: bool) {
        self.trace = on.then(|| Vec::with_capacity(self.solver.trace_capacity()));
    }

    /// The `(energy, residual)` per iteration of the last step, if tracing.
    pub fn trace(&self) -> Option<&[(f64, f64)]> {
        self.trace.as_deref()
    }
}
