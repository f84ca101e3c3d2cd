//! The PD solve of one step (paper Sec. 3.1): local step (projections), global step (the
//! prefactored solve), and the safeguarded accelerated iteration between them.

use super::safeguards::{Accepted, AndersonOutcome, Progress};
use super::{Simulator, StepStats};
use crate::params::{Acceleration, Polish};
use crate::profile::timed;
use crate::Vec3;
use std::time::Instant;

impl Simulator {
    /// Local step at `x`: projects every constraint, writes `M y / h^2 + sum_i w_i A_i^T p_i`
    /// into `rhs` and returns the implicit-Euler objective
    /// `E(x) = |x - y|_M^2 / (2 h^2) + sum_i w_i / 2 |A_i x - p_i|^2`.
    pub(super) fn local_step(&mut self, which: Buffer) -> f64 {
        let start = Instant::now();
        let parallel = self.solver.parallel && self.split_work;
        let x = std::mem::take(self.buffer(which));
        let mut rhs = std::mem::take(&mut self.work.update);
        rhs.copy_from_slice(&self.work.inertia_rhs);
        let inv_2h2 = 0.5 / (self.model.params.h * self.model.params.h);
        let mut energy: f64 = x
            .iter()
            .zip(&self.work.y)
            .zip(&self.model.mass)
            .map(|((xi, yi), m)| m * (xi - yi).norm_squared())
            .sum::<f64>()
            * inv_2h2;
        let model = &*self.model;
        for (c, proj) in model.constraint_sets().zip(&mut self.work.projections) {
            energy += c.project(&x, parallel, proj);
            c.add_rhs(proj, &mut rhs);
        }
        if let Some(a) = &model.attachments {
            energy += a.energy(&x, &self.state.targets);
            a.add_rhs(&self.state.targets, &mut rhs);
        }
        *self.buffer(which) = x;
        self.work.update = rhs;
        self.profile.local += start.elapsed();
        energy
    }

    pub(super) fn buffer(&mut self, which: Buffer) -> &mut Vec<Vec3> {
        match which {
            Buffer::Iterate => &mut self.work.iterate,
            Buffer::Extrapolated => &mut self.work.extrapolated,
        }
    }

    /// Global step: `mapped = P_s^{-1} rhs` (rhs in `update`), then `update = mapped - iterate`.
    /// Returns the RMS of the update.
    pub(super) fn global_step(&mut self) -> f64 {
        let factor = &self.model.factor;
        let work = &mut self.work;
        timed(&mut self.profile.global, || {
            factor.solve_xyz(&mut work.update, &mut work.solve_rows)
        });
        if self.delassus_response() {
            let start = Instant::now();
            self.work.delassus.respond(
                &mut self.work.update,
                &self.state.x,
                self.model.params.h,
                &mut self.work.contacts.contacts,
            );
            self.profile.contact_solve += start.elapsed();
        }
        let mut sum = 0.0;
        for ((u, g), x) in self
            .work
            .update
            .iter_mut()
            .zip(self.work.mapped.iter_mut())
            .zip(&self.work.iterate)
        {
            *g = *u;
            *u -= x;
            sum += u.norm_squared();
        }
        let update = (sum / (3 * self.work.iterate.len()) as f64).sqrt();
        self.work.delassus.set_last_update(update);
        update
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
    /// `a` doubling up to `ESCAPE_MAX_SCALE` while E keeps falling. Every accepted point
    /// still lowers E, so the safeguard is the same; the first shrinking update ends it. Contact
    /// steps escape the same way (the Hat sliding off the head: 9 % -> 3 % of steps at the
    /// iteration cap); there E leaves out the contact forces, which only the fixed point
    /// must satisfy.
    ///
    /// Polish (`solver.polish = "newton"`): once the update is below `newton::POLISH_START`
    /// and no contact pushes, trust-region Newton steps take over (`newton.rs`); the stopping
    /// test is unchanged. With `"semismooth"`, where contacts push, semi-smooth Newton steps
    /// are tried once the update is below `contact_newton::START` (`contact_newton.rs`).
    ///
    /// Contact response (`response.rs`): with `auto`, a step whose contacts are stiff and whose
    /// rate would not reach the tolerance within the cap switches to the Delassus response.
    pub(super) fn solve_pd(&mut self) -> StepStats {
        self.work.iterate.copy_from_slice(&self.work.y);
        self.work.anderson.reset();
        self.work.contact_newton.start_step();
        self.start_response();
        if let Some(t) = self.trace.as_mut() {
            t.clear();
        }
        // Recorded or not, every step converges to the same tolerance: recording never
        // changes the trajectory (backward warns when the steps are too loose for it).
        let (tol, max_it) = (self.solver.tolerance, self.solver.max_iterations);
        let energy = self.local_step(Buffer::Iterate);
        self.solve_contacts(Buffer::Iterate);
        let residual = self.global_step();
        self.record(energy, residual);
        let history = self.work.anderson.history();
        let accelerate = self.solver.acceleration == Acceleration::Anderson;
        let polish = self.solver.polish != Polish::None;
        let contact_newton = self.solver.polish == Polish::Semismooth;
        let mut p = Progress::new(energy, residual, accelerate, history);
        while p.residual > tol && p.iterations < max_it {
            if self.escalate_response(p.iterations, p.residual) {
                // The map changed: its history no longer describes it.
                self.work.anderson.reset();
            }
            // While no contact pushes (all take off at the iterate), E is the exact objective
            // and the energy guard applies; the residual guard only where contact forces act.
            let energy_guard = self.work.contacts.all_take_off();
            if polish && energy_guard && p.escape_scale == 1.0 && p.residual <= p.newton_below {
                if self.try_newton(&mut p) {
                    self.record(p.energy, p.residual);
                }
                continue;
            }
            if contact_newton
                && !energy_guard
                && p.escape_scale == 1.0
                && p.residual <= p.contact_newton_below
                && self.try_contact_newton(&mut p)
            {
                self.record(p.energy, p.residual);
                continue;
            }
            let previous = (p.residual, p.energy);
            let mut accepted = None;
            if p.escape_scale > 1.0 {
                accepted = self.try_escape(&mut p).then_some(Accepted::Escape);
            } else if p.accelerate {
                match self.try_anderson(&mut p, energy_guard) {
                    AndersonOutcome::Accepted => accepted = Some(Accepted::Anderson),
                    // The extrapolation's G is already evaluated: that was the iteration.
                    AndersonOutcome::AcceptedWithMap => continue,
                    AndersonOutcome::Rejected | AndersonOutcome::Unavailable => {}
                }
            }
            if accepted.is_none() {
                self.work.iterate.copy_from_slice(&self.work.mapped);
                p.energy = self.local_step(Buffer::Iterate);
            }
            self.solve_contacts(Buffer::Iterate);
            let residual = self.global_step();
            p.iterated(residual);
            self.record(p.energy, p.residual);
            if !energy_guard {
                self.watch_stall(&mut p);
            }
            self.watch_saddle(&mut p, previous, accepted == Some(Accepted::Anderson));
        }
        StepStats {
            iterations: p.iterations,
            residual: p.residual,
            converged: p.residual <= tol,
            contacts: self.work.contacts.counts(),
        }
    }

    /// Adds this iteration's contact forces at the iterate to the right-hand side in `update`.
    pub(super) fn solve_contacts(&mut self, which: Buffer) {
        // (The Delassus response acts after the global solve instead.)
        if self.work.contacts.is_empty() || self.delassus_response() {
            return;
        }
        let start = Instant::now();
        let x = std::mem::take(self.buffer(which));
        self.work.contacts.solve(
            &x,
            &self.state.x,
            &self.model.mass,
            self.model.params.h,
            self.model.factor.matrix(),
            &mut self.work.update,
        );
        *self.buffer(which) = x;
        self.profile.contact_solve += start.elapsed();
    }
}

#[derive(Clone, Copy)]
pub(super) enum Buffer {
    Iterate,
    Extrapolated,
}
