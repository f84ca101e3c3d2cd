//! One implicit-Euler step: validate and apply the inputs, predict, detect contacts, solve,
//! record, advance. A step that fails leaves the state (and the tape) as it was.

use super::{Simulator, StepInput, StepStats};
use crate::error::{Error, Result};
use crate::params::check_nodes;
use crate::tape::{CompletedStep, Tape};
use crate::Vec3;
use std::sync::Arc;
use std::time::Instant;

/// Re-detections of one step's contacts before the step is refused. Each covers every node
/// whose crossing caused it; more than a couple means a step far too long for the scene.
const MAX_REDETECTIONS: usize = 8;

impl Simulator {
    /// Advances one implicit-Euler step. On error the state is unchanged.
    pub fn step(&mut self, input: StepInput<'_>) -> Result<StepStats> {
        let start = Instant::now();
        let p0 = self.profile.clone();
        self.prepare(input)?;
        if self.model.effects.has_contact() {
            self.detect_contacts(false);
        }
        let mut stats = self.solve_pd();
        self.check_finite()?;
        // Detection reaches as far as each node's entering velocity carries it. A node that
        // speeds up within the step (a snap-through; the Hat: 3.6 cm in one step, 9.8 mm deep
        // in the head) or falls from rest in a long step (issue 11: 2.45 m through a sphere
        // in 0.5 s) can cross an obstacle it was never a candidate for; then detect again
        // with the step's own motion and solve the step once more. Each re-detection covers
        // the crossing nodes for good, so this ends; past the cap the step is refused.
        if self.model.effects.obstacle_contact {
            let mut redetections = 0;
            while let Some((node, obstacle)) = self.missed_obstacle_contact() {
                if redetections == MAX_REDETECTIONS {
                    self.roll_back_targets();
                    return Err(Error::Contact(format!(
                        "step {} refused: node {node} still crosses obstacle {obstacle} after \
                         {MAX_REDETECTIONS} re-detections of the step's contacts; state left at \
                         the previous step (a smaller time step h helps)",
                        self.state.step_count
                    )));
                }
                redetections += 1;
                self.profile.redetections += 1;
                self.detect_contacts(true);
                stats = self.solve_pd();
                self.check_finite()?;
            }
        }
        // The PD result is in `mapped`.
        let h = self.model.params.h;
        self.record_step(&input, &stats);
        let state = &mut self.state;
        for ((x, v), xn) in state
            .x
            .iter_mut()
            .zip(state.v.iter_mut())
            .zip(&self.work.mapped)
        {
            *v = (xn - *x) / h;
            *x = *xn;
        }
        self.state.time += h;
        self.state.step_count += 1;
        self.last = stats;
        self.last_contacts.clone_from(&self.work.contacts.contacts);
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
            + (p.contact_solve - p0.contact_solve)
            + (p.newton - p0.newton);
        p.other += total.saturating_sub(staged);
        Ok(stats)
    }

    /// Fails the step if the solve (`mapped`) is not finite: a divergence, checked before
    /// any crossing test (a non-finite path crosses nothing and everything).
    fn check_finite(&mut self) -> Result<()> {
        if self
            .work
            .mapped
            .iter()
            .all(|p| p.iter().all(|c| c.is_finite()))
        {
            return Ok(());
        }
        // Roll back everything the call set: the targets too, or the next plain step would
        // diverge again.
        self.roll_back_targets();
        Err(Error::Diverged(format!(
            "non-finite positions at step {}; state left at the previous step",
            self.state.step_count
        )))
    }

    /// Restores the targets in effect before this step's inputs (a failed step sets nothing).
    fn roll_back_targets(&mut self) {
        std::mem::swap(&mut self.state.targets, &mut self.work.previous_targets);
    }

    /// Validates the inputs and computes the inertial prediction
    /// `y = x + h v + h^2 M^{-1} f_ext` and `M y / h^2`.
    pub fn prepare(&mut self, input: StepInput<'_>) -> Result<()> {
        let n = self.num_nodes();
        if let Some(t) = input.attachment_targets {
            if self.model.attachments.is_none() {
                return Err(Error::Input(
                    "attachment targets given but the scene has no attachments".into(),
                ));
            }
            check_nodes("attachment_targets", t, self.state.targets.len())?;
        }
        if let Some(f) = input.external_forces {
            if !self.model.effects.external_forces {
                return Err(Error::Input(
                    "external forces given but 'external_forces' is not in the scene's effects"
                        .into(),
                ));
            }
            check_nodes("external_forces", f, n)?;
        }
        // Validated: apply the targets, keeping the old ones for a rollback.
        let previous = &mut self.work.previous_targets;
        previous.clear();
        previous.extend_from_slice(&self.state.targets);
        if let Some(t) = input.attachment_targets {
            self.state.targets.copy_from_slice(t);
        }
        let h = self.model.params.h;
        // Accumulate forces in `y` first, then turn them into the prediction.
        let f = &mut self.work.y;
        match input.external_forces {
            Some(ext) => f.copy_from_slice(ext),
            None => f.iter_mut().for_each(|fi| *fi = Vec3::zeros()),
        }
        if self.model.effects.gravity {
            let g = self.model.params.gravity;
            f.iter_mut()
                .zip(&self.model.mass)
                .for_each(|(fi, m)| *fi += *m * g);
        }
        if let Some(w) = &self.model.wind {
            w.add_forces(&self.model.params, self.state.time, f);
        }
        let inv_h2 = 1.0 / (h * h);
        for i in 0..n {
            let (x, v, m) = (self.state.x[i], self.state.v[i], self.model.mass[i]);
            let y = x + h * v + (h * h / m) * self.work.y[i];
            self.work.y[i] = y;
            self.work.inertia_rhs[i] = m * inv_h2 * y;
        }
        Ok(())
    }

    /// Hands the completed step to the tape, noting when it was taken with another model (or,
    /// checkpointed, other solver settings) than the recording's first steps.
    fn record_step(&mut self, input: &StepInput<'_>, stats: &StepStats) {
        let Some(rec) = self.recording.as_mut() else {
            return;
        };
        let checkpointed = matches!(rec.tape, Tape::Checkpointed { .. });
        if rec.tape.is_empty() {
            rec.model = self.model.clone();
            rec.solver = self.solver.clone();
            rec.changed_at = None;
        } else if rec.changed_at.is_none()
            && (!Arc::ptr_eq(&rec.model, &self.model)
                || (checkpointed && rec.solver != self.solver))
        {
            rec.changed_at = Some(rec.tape.len());
        }
        rec.tape.push(&CompletedStep {
            x_prev: &self.state.x,
            v_prev: &self.state.v,
            x_next: &self.work.mapped,
            targets: self
                .model
                .attachments
                .is_some()
                .then_some(&self.state.targets[..]),
            forces: input.external_forces,
            time: self.state.time,
            contacts: &self.work.contacts.contacts,
            residual: stats.residual,
        });
    }
}
