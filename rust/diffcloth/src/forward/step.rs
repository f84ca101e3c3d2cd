//! One implicit-Euler step: validate and apply the inputs, predict, detect contacts, solve,
//! record, advance. A step that fails leaves the state (and the tape) as it was.

use super::{Simulator, StepInput, StepStats};
use crate::error::{Error, Result};
use crate::params::check_nodes;
use crate::tape::CompletedStep;
use crate::Vec3;
use std::time::Instant;

impl Simulator {
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
}
