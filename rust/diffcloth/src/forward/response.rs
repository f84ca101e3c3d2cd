//! Which contact response a step's PD iterations use (`contact.response`).
//!
//! `inertia` predicts each contact node as if it moved alone with its mass: free per
//! iteration, but a sticking node's error contracts only by `1 - m / (h^2 P_jj)` per
//! iteration, so stiff cloth at large steps stalls at the iteration cap with nodes inside the
//! obstacle. `delassus` is exact for the current local step (every iterate respects the contact
//! law) but costs `c / 3` extra solves and a dense `c x c` operator per step, and its
//! Gauss-Seidel is slow where every node of a stiff sheet is in contact (a ribbon on a slope:
//! 300 iterations a step against 2 with `inertia`).
//!
//! `auto` (the default) starts every step with `inertia` and switches to `delassus` for the rest
//! of the step when the splitting is too slow for it: at iterations 20, 40, 80, ... the
//! residual's rate over the last window, continued, would not reach the tolerance within the
//! step's iteration cap (with tolerance 0, a fixed iteration count, never), and the step has
//! stiff contacts (a contact node whose splitting contracts by `1 - 1 / STIFF_RATIO` or
//! slower) but at most [`MAX_CONTACT_NODES`] contact nodes. Both responses have the same fixed
//! point (the contact law at the solved velocities), so the switch changes how the step
//! converges, not what it converges to, and the adjoint is the same.

use super::Simulator;
use crate::config::ContactResponse;
use crate::contact::ContactKind;
use std::time::Instant;

/// The first iteration at which `auto` checks a step's progress (then at twice each check).
/// The ribbon sliding on a stiff slope converges in 2 iterations a step; the napkin in the
/// bowl (`configs/bowl.toml`, stiff by the ratio below) in about 40, at a rate that reaches
/// the tolerance well within the cap, so it keeps the splitting. Switching it would only slow
/// it: without the rate test, the Gauss-Seidel over its up to ~2000 coupled contact nodes
/// took it from 30 to 400 ms/step.
pub const FIRST_CHECK: usize = 20;

/// `h^2 P_jj / m_j` at or above which a contact node makes the splitting too slow to rely on:
/// it gains a digit only every `~2.3 STIFF_RATIO` iterations (230 here, most of the default
/// preset's 300-iteration cap). Measured over all nodes: `configs/sphere.toml` 1.7 (median)
/// to 2.5 (max), `napkin.toml` 13, `sock.toml` 10 / 80, `bowl.toml` 150 / 300, `hat.toml`
/// 540 / 1400; the stability suite's stiff drops (k_stretch 1e5 for 150, h 1/30 for 1/180)
/// are thousands of times the sphere's.
pub const STIFF_RATIO: f64 = 100.0;

/// The most contact nodes `auto` builds the Delassus operator for: its Gauss-Seidel costs
/// `c^2` per sweep, and `G = P^{-1} C^T` holds `c n` values. A 25 x 25 sheet all in contact
/// fits. Past it the step keeps the splitting.
pub const MAX_CONTACT_NODES: usize = 640;

/// `auto`'s progress within one solve.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AutoSwitch {
    /// The next check's iteration, and the window's start `(iteration, residual)`.
    check_at: usize,
    window_start: Option<(usize, f64)>,
    /// Whether the step's contacts are stiff and few enough (computed at the first check
    /// that wants to switch).
    eligible: Option<bool>,
}

impl Default for AutoSwitch {
    fn default() -> Self {
        Self {
            check_at: FIRST_CHECK,
            window_start: None,
            eligible: None,
        }
    }
}

impl Simulator {
    /// Whether this step's contacts respond through the Delassus operator (now).
    pub(super) fn delassus_response(&self) -> bool {
        !self.work.contacts.is_empty() && self.work.exact_response
    }

    /// At detection: `delassus` builds its operator for the step's contacts.
    pub(super) fn prepare_response(&mut self) {
        let delassus = self.model.contact_settings.response == ContactResponse::Delassus;
        if delassus && !self.work.contacts.is_empty() {
            self.build_delassus();
        }
    }

    /// At the start of every solve of a step: `auto` starts with the splitting again, so a
    /// solve never depends on an earlier solve of the same step.
    pub(super) fn start_response(&mut self) {
        self.work.exact_response =
            self.model.contact_settings.response == ContactResponse::Delassus;
        self.work.auto_switch = AutoSwitch::default();
    }

    /// With `auto`, after an iteration that ended at `residual`: switches to the Delassus
    /// response if the step is too slow for its cap and its contacts are stiff (see the
    /// module's text). Returns true if it switched: the map changed, so the caller drops its
    /// acceleration history.
    pub(super) fn escalate_response(&mut self, iterations: usize, residual: f64) -> bool {
        if self.model.contact_settings.response != ContactResponse::Auto || self.work.exact_response
        {
            return false;
        }
        let s = &mut self.work.auto_switch;
        if iterations < s.check_at {
            if iterations >= s.check_at / 2 && s.window_start.is_none() {
                s.window_start = Some((iterations, residual));
            }
            return false;
        }
        let window = s.window_start.replace((iterations, residual));
        s.check_at = 2 * iterations;
        let Some((start, before)) = window else {
            return false;
        };
        // Iterations left at the window's rate (infinite if it did not fall).
        let rate = (residual / before).powf(1.0 / (iterations - start) as f64);
        let left = if rate < 1.0 {
            (self.solver.tolerance / residual).ln() / rate.ln()
        } else {
            f64::INFINITY
        };
        if iterations as f64 + left <= self.solver.max_iterations as f64 {
            return false;
        }
        let eligible = match self.work.auto_switch.eligible {
            Some(e) => e,
            None => {
                let e = !self.work.contacts.is_empty()
                    && self
                        .work
                        .delassus
                        .assign_nodes(self.model.num_nodes(), &self.work.contacts.contacts)
                        <= MAX_CONTACT_NODES
                    && self.max_contact_stiffness_ratio() >= STIFF_RATIO;
                self.work.auto_switch.eligible = Some(e);
                e
            }
        };
        if !eligible {
            return false;
        }
        self.work.exact_response = true;
        self.profile.response_switches += 1;
        self.build_delassus();
        true
    }

    fn build_delassus(&mut self) {
        let start = Instant::now();
        self.work
            .delassus
            .build(&self.model.factor, &self.work.contacts.contacts);
        self.profile.contact_solve += start.elapsed();
        self.profile.delassus_builds += 1;
    }

    /// The largest `h^2 P_jj / m_j` over the step's contact nodes.
    fn max_contact_stiffness_ratio(&self) -> f64 {
        let p = self.model.factor.matrix().as_ref();
        let h2 = self.model.params.h * self.model.params.h;
        let ratio = |j: usize| {
            let diagonal = p
                .row_idx_of_col(j)
                .zip(p.val_of_col(j))
                .find_map(|(i, &v)| (i == j).then_some(v))
                .unwrap_or(0.0);
            h2 * diagonal / self.model.mass[j]
        };
        self.work
            .contacts
            .contacts
            .iter()
            .map(|c| match c.kind {
                ContactKind::Obstacle { node, .. } => ratio(node),
                ContactKind::SelfPair { a, b } => ratio(a).max(ratio(b)),
            })
            .fold(0.0, f64::max)
    }
}
