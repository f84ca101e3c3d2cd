//! The Newton polish of a step (`solver.polish = "newton"`): near the solution, trust-region
//! Newton steps on the step's objective `E` replace the last stretch of PD iterations.
//!
//! PD converges linearly, and slowest where `E` is nearly flat or not convex: stiff bending
//! with a curved rest shape (`|A x| - n` is not convex when the curvature is below its rest
//! value) gives the Hat saddles, where PD and Anderson linger for hundreds of iterations. At an
//! accepted iterate `x` with PD update `u = G(x) - x = -P^{-1} grad E(x)`, the step `d`
//! minimizes the quadratic model `m(d) = -d^T P u + d^T H d / 2` with the exact Hessian
//! `H = P - dP` of `E` (the projection Jacobians the adjoint uses: `d(grad W)/dx = K - dP`)
//! inside the trust region `|d|_P <= radius`, by Steihaug's conjugate gradients
//! preconditioned by the PD factor (Nocedal & Wright, Alg. 7.2). PCG starts at `d = 0` with
//! preconditioned residual `P^{-1} (P u) = u`: the PD update is its first direction, so no
//! extra solve. Negative curvature (a saddle) sends the step to the region's boundary along
//! that direction, which is how the polish leaves a saddle. Inside, PCG stops once its
//! preconditioned residual `P^{-1}(P u - H d)`, to first order the PD update at `x + d` (the
//! quantity the step's tolerance bounds), is below a fraction of the tolerance or a forcing
//! fraction of the current update.
//!
//! Safeguards, so the result is still a point where the PD update is below the tolerance:
//! - only where no contact pushes (every contact taking off at the iterate): there `E` is the
//!   exact objective; with active contacts the step finishes with PD;
//! - the trial `x + d` is kept only if `E` falls by at least a tenth of the model's predicted
//!   decrease (below round-off, where `E` cannot tell: if its PD update is smaller); the
//!   radius shrinks after a poor prediction and grows after a good one on the boundary;
//! - every accepted point is evaluated like any iterate (local step, contacts, global step),
//!   so the step stops on the same measure as without polish; after repeated rejections the
//!   step finishes with PD.
//!
//! Plain and recorded steps run this identically; everything is sequential (bitwise the same
//! on any thread count) and every buffer lives in [`NewtonWork`].

use super::pd::Buffer;
use super::safeguards::Progress;
use super::{Model, Simulator};
use crate::Vec3;
use std::time::Instant;

/// Try Newton only once the RMS PD update (metres) is below this.
pub(super) const POLISH_START: f64 = 1e-5;
/// PCG stops at `FORCING x` the current update (inexact Newton), or at
/// `TOLERANCE_FRACTION x tolerance`, whichever is larger.
const FORCING: f64 = 0.1;
const TOLERANCE_FRACTION: f64 = 0.25;
/// PCG iterations per Newton step.
const MAX_CG_ITERATIONS: usize = 100;
/// First trust radius, in units of the PD update's P-norm.
const FIRST_RADIUS: f64 = 100.0;
/// Rejected trials (radius shrinking) after which the step finishes with PD.
const MAX_REJECTIONS: usize = 4;
/// Relative round-off of `E`: a predicted decrease below this is not measurable.
const ENERGY_SLACK: f64 = 1e-12;

/// The polish's buffers, allocated once per simulator.
pub(crate) struct NewtonWork {
    /// Each constraint set's weighted projection Jacobians at the iterate.
    pub(super) lin: Vec<Vec<f64>>,
    /// The step `d`, `H d`, and PCG's residual, preconditioned residual, direction and `H p`.
    d: Vec<Vec3>,
    hd: Vec<Vec3>,
    r: Vec<Vec3>,
    s: Vec<Vec3>,
    p: Vec<Vec3>,
    hp: Vec<Vec3>,
    rows: Vec<Vec3>,
}

impl NewtonWork {
    pub(super) fn new(model: &Model) -> Self {
        let zeros = vec![Vec3::zeros(); model.num_nodes()];
        Self {
            lin: model
                .constraint_sets()
                .map(|c| vec![0.0; c.linearization_len()])
                .collect(),
            d: zeros.clone(),
            hd: zeros.clone(),
            r: zeros.clone(),
            s: zeros.clone(),
            p: zeros.clone(),
            hp: zeros.clone(),
            rows: zeros,
        }
    }
}

/// The trust region of one step's polish.
#[derive(Debug, Clone, Copy)]
pub(super) struct TrustRegion {
    /// Radius in the P-norm (0: not yet set).
    radius: f64,
    /// Consecutive rejected trials.
    rejections: usize,
}

impl Default for TrustRegion {
    fn default() -> Self {
        Self {
            radius: 0.0,
            rejections: 0,
        }
    }
}

/// What Steihaug-CG returned: the model's predicted decrease, `|d|_P`, and whether `d`
/// ends on the boundary.
struct Direction {
    predicted: f64,
    norm: f64,
    on_boundary: bool,
}

fn dot(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

fn rms(v: &[Vec3]) -> f64 {
    (dot(v, v) / (3 * v.len()).max(1) as f64).sqrt()
}

impl Simulator {
    /// Newton trials from the accepted iterate (its update in `update`, its map in `mapped`)
    /// until one is accepted (true: the iterate moved and its map is evaluated) or the radius
    /// has shrunk too often (false: the iterate and its update are as they were, and the step
    /// goes on with PD). Called only where every contact takes off.
    pub(super) fn try_newton(&mut self, p: &mut Progress) -> bool {
        let start = Instant::now();
        self.linearize_at_iterate();
        self.profile.newton += start.elapsed();
        let rs0 = {
            let w = &mut self.work;
            self.model.factor.mul_xyz(&w.update, &mut w.newton.r);
            dot(&w.newton.r, &w.update)
        };
        let tr = &mut p.trust;
        if tr.radius == 0.0 {
            tr.radius = FIRST_RADIUS * rs0.sqrt();
        }
        let target = (TOLERANCE_FRACTION * self.solver.tolerance).max(FORCING * p.residual);
        loop {
            let start = Instant::now();
            let dir = self.newton_direction(target, p.trust.radius, rs0);
            self.profile.newton += start.elapsed();
            let w = &mut self.work;
            for ((e, x), d) in w.extrapolated.iter_mut().zip(&w.iterate).zip(&w.newton.d) {
                *e = x + d;
            }
            let trial_energy = self.local_step(Buffer::Extrapolated);
            let actual = p.energy - trial_energy;
            let measurable = dir.predicted > ENERGY_SLACK * p.energy.abs();
            let ratio = actual / dir.predicted;
            let tr = &mut p.trust;
            if measurable && ratio < 0.25 {
                tr.radius = 0.25 * dir.norm;
            } else if measurable && ratio > 0.75 && dir.on_boundary {
                tr.radius *= 2.0;
            }
            if (!measurable || ratio > 0.1) && self.evaluate_trial(p, trial_energy, measurable) {
                p.trust.rejections = 0;
                self.profile.newton_steps += 1;
                return true;
            }
            self.profile.newton_rejections += 1;
            p.trust.rejections += 1;
            self.restore_update();
            if !measurable || p.trust.rejections >= MAX_REJECTIONS {
                p.newton_below = 0.0;
                return false;
            }
        }
    }

    /// Evaluates the map at the trial (`extrapolated`, energy `trial_energy`): kept if E fell
    /// measurably, or else if its update is smaller; otherwise `x` and `G(x)` are restored.
    pub(super) fn evaluate_trial(
        &mut self,
        p: &mut Progress,
        trial_energy: f64,
        measurable: bool,
    ) -> bool {
        self.solve_contacts(Buffer::Extrapolated);
        std::mem::swap(&mut self.work.iterate, &mut self.work.extrapolated);
        std::mem::swap(&mut self.work.mapped, &mut self.work.previous_mapped);
        let trial_residual = self.global_step();
        p.iterations += 1;
        if measurable || trial_residual < p.residual {
            p.energy = trial_energy;
            p.residual = trial_residual;
            self.work.anderson.reset();
            return true;
        }
        std::mem::swap(&mut self.work.iterate, &mut self.work.extrapolated);
        std::mem::swap(&mut self.work.mapped, &mut self.work.previous_mapped);
        false
    }

    /// `update = G(x) - x` again (a trial's local step overwrote it).
    pub(super) fn restore_update(&mut self) {
        let w = &mut self.work;
        for ((u, g), x) in w.update.iter_mut().zip(&w.mapped).zip(&w.iterate) {
            *u = g - x;
        }
    }

    pub(super) fn linearize_at_iterate(&mut self) {
        let w = &mut self.work;
        for (c, lin) in self.model.constraint_sets().zip(&mut w.newton.lin) {
            c.linearize(&w.iterate, lin);
        }
    }

    /// Steihaug-CG on `H d = P u` from `d = 0` (`newton.r` holds `P u`, `rs0 = u^T P u`),
    /// within `|d|_P <= radius`, into `newton.d`; stops inside when the RMS preconditioned
    /// residual is below `target`.
    fn newton_direction(&mut self, target: f64, radius: f64, rs0: f64) -> Direction {
        let model = &*self.model;
        let factor = &model.factor;
        let w = &mut self.work;
        let nw = &mut w.newton;
        let apply_h = |lin: &[Vec<f64>], v: &[Vec3], out: &mut [Vec3]| {
            factor.mul_xyz(v, out);
            for (c, l) in model.constraint_sets().zip(lin) {
                c.sub_dp(l, v, out);
            }
        };
        nw.d.iter_mut().for_each(|d| *d = Vec3::zeros());
        nw.hd.iter_mut().for_each(|d| *d = Vec3::zeros());
        factor.mul_xyz(&w.update, &mut nw.r);
        nw.s.copy_from_slice(&w.update);
        nw.p.copy_from_slice(&w.update);
        let mut rs = rs0;
        // P-norm products of the iterate d and the direction p, by recurrence.
        let (mut dd, mut dp, mut pp) = (0.0, 0.0, rs0);
        let mut iterations = 0;
        let mut on_boundary = false;
        while iterations < MAX_CG_ITERATIONS {
            iterations += 1;
            apply_h(&nw.lin, &nw.p, &mut nw.hp);
            let curvature = dot(&nw.p, &nw.hp);
            let alpha = rs / curvature;
            let leaves = |a: f64| dd + 2.0 * a * dp + a * a * pp >= radius * radius;
            if !(curvature.is_finite() && curvature > 0.0) || leaves(alpha) {
                // To the boundary along p: the positive root of |d + tau p|_P = radius.
                let disc = (dp * dp + pp * (radius * radius - dd)).max(0.0);
                let tau = (-dp + disc.sqrt()) / pp;
                for ((d, hd), (pi, hpi)) in
                    nw.d.iter_mut()
                        .zip(nw.hd.iter_mut())
                        .zip(nw.p.iter().zip(&nw.hp))
                {
                    *d += tau * pi;
                    *hd += tau * hpi;
                }
                on_boundary = true;
                break;
            }
            for ((d, hd), (pi, hpi)) in
                nw.d.iter_mut()
                    .zip(nw.hd.iter_mut())
                    .zip(nw.p.iter().zip(&nw.hp))
            {
                *d += alpha * pi;
                *hd += alpha * hpi;
            }
            dd += 2.0 * alpha * dp + alpha * alpha * pp;
            for (r, hp) in nw.r.iter_mut().zip(&nw.hp) {
                *r -= alpha * hp;
            }
            factor.solve_nodes_into(&nw.r, &mut nw.s, &mut nw.rows);
            if rms(&nw.s) <= target {
                break;
            }
            let rs_next = dot(&nw.r, &nw.s);
            let beta = rs_next / rs;
            rs = rs_next;
            dp = beta * (dp + alpha * pp);
            pp = rs + beta * beta * pp;
            for (pi, si) in nw.p.iter_mut().zip(&nw.s) {
                *pi = si + beta * *pi;
            }
        }
        self.profile.newton_cg_iterations += iterations as u64;
        // m(0) - m(d) = d^T P u - d^T H d / 2, with P u = grad-free right-hand side.
        factor.mul_xyz(&w.update, &mut nw.r);
        let predicted = dot(&nw.d, &nw.r) - 0.5 * dot(&nw.d, &nw.hd);
        Direction {
            predicted,
            norm: if on_boundary {
                radius
            } else {
                dd.max(0.0).sqrt()
            },
            on_boundary,
        }
    }
}
