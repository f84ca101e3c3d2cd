//! The safeguards of the accelerated PD iteration ([`Simulator::solve_pd`] explains why each
//! exists), one function each: the saddle escape, the energy- or residual-guarded Anderson
//! step, the stall watch that falls back to plain PD, and the saddle detector.

use super::pd::Buffer;
use super::Simulator;

/// Largest step scale `a` of the saddle escape.
const ESCAPE_MAX_SCALE: f64 = 64.0;

/// Where one step's PD iteration stands, and what the safeguards remember.
pub(super) struct Progress {
    pub(super) iterations: usize,
    pub(super) residual: f64,
    /// E at the accepted iterate.
    pub(super) energy: f64,
    /// Saddle escape: consecutive growing plain updates, and the step scale (1: off).
    growing: usize,
    pub(super) escape_scale: f64,
    /// Residual guard: whether Anderson is still on, and the lowest residual and when.
    pub(super) accelerate: bool,
    best_residual: f64,
    best_at: usize,
    stall_window: usize,
    /// Newton polish: tried while the update is below this (lowered after a rejection).
    pub(super) newton_below: f64,
    pub(super) trust: super::newton::TrustRegion,
    /// Contact Newton (`polish = "semismooth"`): tried while the update is below this.
    pub(super) contact_newton_below: f64,
}

impl Progress {
    /// After the first (plain) iteration.
    pub(super) fn new(energy: f64, residual: f64, accelerate: bool, history: usize) -> Self {
        Self {
            iterations: 1,
            residual,
            energy,
            growing: 0,
            escape_scale: 1.0,
            accelerate,
            best_residual: residual,
            best_at: 1,
            stall_window: 2 * history + 4,
            newton_below: super::newton::POLISH_START,
            trust: Default::default(),
            contact_newton_below: super::contact_newton::START,
        }
    }

    /// Counts one more map evaluation that ended at `residual`.
    pub(super) fn iterated(&mut self, residual: f64) {
        self.iterations += 1;
        self.residual = residual;
    }
}

/// How this iteration's point was accepted (None in the driver: the plain step).
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Accepted {
    Escape,
    Anderson,
}

pub(super) enum AndersonOutcome {
    /// The extrapolation lowered E (energy guard): it is the iterate.
    Accepted,
    /// The extrapolation's own map lowered the residual (residual guard): the iteration is
    /// complete.
    AcceptedWithMap,
    Rejected,
    /// No extrapolation yet (too little history).
    Unavailable,
}

impl Simulator {
    /// Saddle escape: tries `x + a (G(x) - x)`; kept (and `a` doubled) while E falls, else
    /// the escape ends.
    pub(super) fn try_escape(&mut self, p: &mut Progress) -> bool {
        let scale = p.escape_scale;
        let w = &mut self.work;
        for ((e, x), u) in w.extrapolated.iter_mut().zip(&w.iterate).zip(&w.update) {
            *e = x + scale * u;
        }
        let trial = self.local_step(Buffer::Extrapolated);
        if trial < p.energy {
            std::mem::swap(&mut self.work.iterate, &mut self.work.extrapolated);
            p.energy = trial;
            p.escape_scale = (2.0 * scale).min(ESCAPE_MAX_SCALE);
            self.profile.escape_steps += 1;
            true
        } else {
            p.escape_scale = 1.0;
            false
        }
    }

    /// Anderson extrapolation, safeguarded: by E where no contact pushes (`energy_guard`),
    /// else by the residual of its own map. A rejection restarts the history.
    pub(super) fn try_anderson(&mut self, p: &mut Progress, energy_guard: bool) -> AndersonOutcome {
        let w = &mut self.work;
        w.anderson.push(&w.update, &w.mapped);
        if !w
            .anderson
            .extrapolate(&w.update, &w.mapped, &mut w.extrapolated)
        {
            return AndersonOutcome::Unavailable;
        }
        let trial = self.local_step(Buffer::Extrapolated);
        if energy_guard {
            if trial < p.energy {
                std::mem::swap(&mut self.work.iterate, &mut self.work.extrapolated);
                p.energy = trial;
                return AndersonOutcome::Accepted;
            }
        } else if self.residual_guard(p, trial) {
            return AndersonOutcome::AcceptedWithMap;
        }
        self.profile.acceleration_rejections += 1;
        self.work.anderson.reset();
        AndersonOutcome::Rejected
    }

    /// Evaluates G at the extrapolation (energy `trial`) and keeps it if its update is smaller
    /// than the last iterate's; otherwise restores `x_k` and `G(x_k)`. The evaluation counts as
    /// an iteration either way.
    fn residual_guard(&mut self, p: &mut Progress, trial: f64) -> bool {
        self.solve_contacts(Buffer::Extrapolated);
        std::mem::swap(&mut self.work.iterate, &mut self.work.extrapolated);
        std::mem::swap(&mut self.work.mapped, &mut self.work.previous_mapped);
        let trial_residual = self.global_step();
        let residual = p.residual;
        if trial_residual < residual {
            p.energy = trial;
            p.iterated(trial_residual);
            self.record(p.energy, p.residual);
            if p.residual < p.best_residual {
                (p.best_residual, p.best_at) = (p.residual, p.iterations);
            }
            return true;
        }
        p.iterations += 1;
        std::mem::swap(&mut self.work.iterate, &mut self.work.extrapolated);
        std::mem::swap(&mut self.work.mapped, &mut self.work.previous_mapped);
        false
    }

    /// Residual-guarded steps: without a new lowest residual for `stall_window` iterations,
    /// finish the step with plain PD (accepted extrapolations and plain steps can cycle).
    pub(super) fn watch_stall(&mut self, p: &mut Progress) {
        if !p.accelerate || p.escape_scale != 1.0 {
            return;
        }
        if p.residual < p.best_residual {
            (p.best_residual, p.best_at) = (p.residual, p.iterations);
        } else if p.iterations - p.best_at > p.stall_window {
            p.accelerate = false;
            self.profile.acceleration_stalls += 1;
        }
    }

    /// Two plain updates in a row that grow while E falls: a saddle; start the escape. The
    /// first update that does not grow ends it.
    pub(super) fn watch_saddle(
        &mut self,
        p: &mut Progress,
        (previous_residual, previous_energy): (f64, f64),
        extrapolated_by_anderson: bool,
    ) {
        let grew = !extrapolated_by_anderson
            && p.residual > previous_residual
            && p.energy < previous_energy;
        p.growing = if grew { p.growing + 1 } else { 0 };
        if p.growing == 0 {
            if p.escape_scale > 1.0 {
                // Out of the saddle: the stall test starts afresh.
                (p.best_residual, p.best_at) = (p.residual, p.iterations);
            }
            p.escape_scale = 1.0;
        } else if p.growing >= 2 && p.escape_scale == 1.0 {
            p.escape_scale = 2.0;
            self.work.anderson.reset();
        }
    }
}
