//! Semi-smooth Newton on contact steps (`solver.polish = "semismooth"`).
//!
//! Where contacts push, the PD iteration converges slowly (a sticking node's error contracts
//! only through the inertia splitting) and the trust-region polish (`newton.rs`) does not
//! apply: with contact forces there is no objective. The step's fixed point solves
//! `F(x) = P x - b(x) - R(x) = 0`, with `b` the local step's right-hand side and `R` the
//! contact forces of the inertia splitting (`contact.rs`); the Delassus response has the same
//! fixed point (its law holds on the same velocities and impulses). With each contact's law
//! linearized at its current branch, `dF = H - dR`: `H = P - dP` the step Hessian and `dR`
//! the adjoint's contact Jacobian (`backward/contact.rs`, `dR = E Phi' S (dP - K)`).
//!
//! A sticking node's row of `dF` is `m/h^2 I` (the law pins it) and a slipping node's normal
//! row is `m/h^2 n^T`. The preconditioner eliminates exactly those directions: it solves the
//! pinned ones directly and the rest with the Cholesky factor of `Q H Q` (`Q` projects them
//! out; `StepHessian::factor_constrained`), so right-preconditioned GMRES only sees friction
//! and contacts between cloth nodes (and nodes in several contacts).
//!
//! Safeguards: tried once the PD update is below [`START`]; the trial `x + a d` (`a` = 1, 1/2,
//! 1/4) is evaluated as any iterate (local step, contact response, global step: the same
//! stopping measure) and kept only if its PD update is smaller. A rejected step, or an
//! indefinite `Q H Q` (a saddle), sends the step back to PD until its update has fallen by
//! another [`RETRY`]. The fixed point is unchanged: only the path to it. Sequential and
//! deterministic (the factor is reused within a step only, by iteration counts).

use super::pd::Buffer;
use super::safeguards::Progress;
use super::{Model, Simulator};
use crate::backward::contact::{
    linearize_contacts_at, pinned_directions, ContactCoupling, ContactLin,
};
use crate::contact::{Branch, ContactKind};
use crate::gmres::Gmres;
use crate::hessian::StepHessian;
use crate::Vec3;
use nalgebra::{DMatrix, DVector, Matrix3};
use std::time::Instant;

/// Try contact Newton once the RMS PD update (metres) is below this.
pub(super) const START: f64 = 1e-4;
/// Halvings of a rejected step before it is given up.
const MAX_HALVINGS: usize = 2;
/// After a rejected trial, retry once the update has fallen by this factor.
const RETRY: f64 = 0.5;
/// GMRES iterations per Newton step, and its relative residual target.
const MAX_KRYLOV: usize = 40;
const FORCING: f64 = 1e-4;
/// Within a step, the factor is reused by later Newton steps until a solve with it took more
/// GMRES iterations than this or missed its target: a factorization costs far more than an
/// iteration, and a lagged one still preconditions well while the contacts change little.
/// Never across steps: a step's result must not depend on the steps before it (a replayed
/// checkpoint segment, a reset env must reproduce it bitwise).
const REFACTOR_KRYLOV: usize = 10;

/// The contact Newton's buffers, allocated once per simulator (the factor on first use).
#[derive(Default)]
pub(crate) struct ContactNewtonWork {
    hessian: Option<StepHessian>,
    /// The model has no Hessian pattern (never try).
    unavailable: bool,
    /// The response's branches and impulses, kept while the splitting is evaluated.
    saved: Vec<(Branch, Vec3)>,
    contacts: Vec<ContactLin>,
    /// Per group of contacts sharing nodes: members and `(I - B T)^{-1}`.
    groups: Vec<(Vec<usize>, DMatrix<f64>)>,
    /// Eliminated directions: `(node, projector, m / h^2)`, at the iterate and in the factor.
    constraints: Vec<(usize, Matrix3<f64>, f64)>,
    factored_constraints: Vec<(usize, Matrix3<f64>, f64)>,
    /// Whether the factor may be reused (see [`REFACTOR_KRYLOV`]).
    reuse: bool,
    /// Active contacts per node (scratch).
    per_node: Vec<u32>,
    /// `-F(x)`, the step `d`, and scratch.
    f: Vec<Vec3>,
    d: Vec<Vec3>,
    t: Vec<Vec3>,
    s: Vec<Vec3>,
    impulses: Vec<Vec3>,
    gmres: Gmres,
}

/// `dF = H - dR` at the iterate, and the preconditioner.
struct Linearized<'a> {
    model: &'a Model,
    lin: &'a [Vec<f64>],
    contacts: &'a [ContactLin],
    groups: &'a [(Vec<usize>, DMatrix<f64>)],
    constraints: &'a [(usize, Matrix3<f64>, f64)],
    h: f64,
}

impl Linearized<'_> {
    fn apply_h(&self, v: &[Vec3], out: &mut [Vec3]) {
        self.model.factor.mul_xyz(v, out);
        for (c, l) in self.model.constraint_sets().zip(self.lin) {
            c.sub_dp(l, v, out);
        }
    }

    /// `out = (H - dR) v`; `(dP - K) v = M v / h^2 - H v` at the contact nodes.
    fn apply(&self, v: &[Vec3], out: &mut [Vec3], impulses: &mut Vec<Vec3>) {
        self.apply_h(v, out);
        if self.contacts.is_empty() {
            return;
        }
        let inv_h2 = 1.0 / (self.h * self.h);
        let mass = &self.model.mass;
        impulses.clear();
        impulses.extend(self.contacts.iter().map(|c| {
            let dd: Vec3 =
                c.s.iter()
                    .map(|&(k, s)| s * (mass[k] * inv_h2 * v[k] - out[k]))
                    .sum();
            c.phi * dd
        }));
        for (group, inverse) in self.groups {
            let mut rhs = DVector::<f64>::zeros(3 * group.len());
            for (b, &c) in group.iter().enumerate() {
                rhs.fixed_rows_mut::<3>(3 * b).copy_from(&impulses[c]);
            }
            let y = inverse * rhs;
            for (b, &c) in group.iter().enumerate() {
                impulses[c] = y.fixed_rows::<3>(3 * b).into_owned();
            }
        }
        for (c, j) in self.contacts.iter().zip(impulses.iter()) {
            for &(k, e) in &c.e {
                out[k] -= e * j;
            }
        }
    }

    /// `out = M^{-1} r`: the pinned directions `z_c = Pi r h^2 / m`, the rest
    /// `(Q H Q)^{-1} Q (r - H z_c)`.
    fn precondition(
        &self,
        hessian: &mut StepHessian,
        r: &[Vec3],
        out: &mut [Vec3],
        t: &mut [Vec3],
        s: &mut [Vec3],
    ) {
        out.iter_mut().for_each(|o| *o = Vec3::zeros());
        for &(j, pi, w) in self.constraints {
            out[j] = pi * r[j] / w;
        }
        self.apply_h(out, t);
        for (ti, ri) in t.iter_mut().zip(r) {
            *ti = ri - *ti;
        }
        for &(j, pi, _) in self.constraints {
            t[j] -= pi * t[j];
        }
        hessian.solve(t, s);
        for (o, si) in out.iter_mut().zip(s.iter()) {
            *o += si;
        }
    }
}

impl ContactNewtonWork {
    /// A new step: its first Newton step factors afresh.
    pub(super) fn start_step(&mut self) {
        self.reuse = false;
    }
}

impl Simulator {
    /// One contact Newton trial from the accepted iterate (its update in `update`, its map in
    /// `mapped`): true if it was kept (the iterate moved and its map is evaluated), false if
    /// the iterate and its update are as they were (the step goes on with PD).
    pub(super) fn try_contact_newton(&mut self, p: &mut Progress) -> bool {
        let start = Instant::now();
        let direction = self.contact_newton_direction();
        self.profile.newton += start.elapsed();
        if !direction {
            // (An indefinite Q H Q far from the solution can turn definite nearer to it.)
            p.contact_newton_below = RETRY * p.residual;
            return false;
        }
        // Backtracking: the elastic energy's curvature changes along the step (the Hat's
        // bending is not convex), so a full step can overshoot where a shorter one gains.
        let mut scale = 1.0;
        for _ in 0..=MAX_HALVINGS {
            let w = &mut self.work;
            for ((e, x), d) in w
                .extrapolated
                .iter_mut()
                .zip(&w.iterate)
                .zip(&w.contact_newton.d)
            {
                *e = x + scale * d;
            }
            let energy = self.local_step(Buffer::Extrapolated);
            if self.evaluate_trial(p, energy, false) {
                self.profile.contact_newton_steps += 1;
                return true;
            }
            scale *= 0.5;
        }
        self.profile.contact_newton_rejections += 1;
        self.restore_update();
        p.contact_newton_below = RETRY * p.residual;
        false
    }

    /// The Newton step `d` (into `contact_newton.d`) solving `(H - dR) d = -F(x)`; false if
    /// there is none (no Hessian pattern, an indefinite `Q H Q`, a bad linearization).
    fn contact_newton_direction(&mut self) -> bool {
        if self.work.contact_newton.unavailable {
            return false;
        }
        let model = self.model.clone();
        let h = model.params.h;
        let n = model.num_nodes();
        self.linearize_at_iterate();
        // -F(x) = b(x) + R(x) - P x. The response's map is `P^{-1}(b + its forces)`, so
        // b = P G(x) - its forces; R is the splitting's at x (with the Delassus response too).
        let w = &mut self.work;
        let cn = &mut w.contact_newton;
        cn.f.resize(n, Vec3::zeros());
        cn.t.resize(n, Vec3::zeros());
        cn.s.resize(n, Vec3::zeros());
        cn.d.resize(n, Vec3::zeros());
        model.factor.mul_xyz(&w.mapped, &mut cn.f);
        for c in &w.contacts.contacts {
            let force = c.impulse / h;
            match c.kind {
                ContactKind::Obstacle { node, .. } => cn.f[node] -= force,
                ContactKind::SelfPair { a, b } => {
                    cn.f[a] -= force;
                    cn.f[b] += force;
                }
            }
        }
        cn.saved.clear();
        cn.saved
            .extend(w.contacts.contacts.iter().map(|c| (c.branch, c.impulse)));
        w.contacts.solve(
            &w.iterate,
            &self.state.x,
            &model.mass,
            h,
            model.factor.matrix(),
            &mut cn.f,
        );
        model.factor.mul_xyz(&w.iterate, &mut cn.t);
        for (f, t) in cn.f.iter_mut().zip(&cn.t) {
            *f -= t;
        }
        let contacts = &self.work.contacts;
        let lin = linearize_contacts_at(
            self,
            &self.state.x,
            self.state.time,
            &contacts.contacts,
            |k| contacts.solved_velocity(k),
        );
        let coupling = lin
            .as_ref()
            .ok()
            .and_then(|l| ContactCoupling::new(l, n).ok());
        let w = &mut self.work;
        for (c, &(branch, impulse)) in w.contacts.contacts.iter_mut().zip(&w.contact_newton.saved) {
            (c.branch, c.impulse) = (branch, impulse);
        }
        let (Ok(lin), Some(coupling)) = (lin, coupling) else {
            return false;
        };
        let cn = &mut w.contact_newton;
        cn.contacts = lin;
        if cn.per_node.len() != n {
            cn.per_node = vec![0; n];
        }
        pinned_directions(
            &cn.contacts,
            &model.mass,
            h,
            &mut cn.per_node,
            &mut cn.constraints,
        );
        cn.groups.clear();
        cn.groups.extend(
            coupling
                .groups
                .into_iter()
                .map(|(g, inverse)| (g, inverse.transpose())),
        );
        if !cn.hessian.as_ref().is_some_and(|hs| hs.fits(&model)) {
            match model.hessian_pattern().filter(|pat| pat.fits(&model)) {
                Some(pat) => {
                    cn.hessian = Some(StepHessian::new(pat));
                    cn.reuse = false;
                }
                None => {
                    cn.unavailable = true;
                    return false;
                }
            }
        }
        let hessian = cn.hessian.as_mut().expect("built above");
        if !cn.reuse {
            self.profile.contact_newton_factorizations += 1;
            if !hessian.factor_constrained(&model, &w.newton.lin, &cn.constraints) {
                return false;
            }
            cn.factored_constraints.clone_from(&cn.constraints);
        }
        let op = Linearized {
            model: &model,
            lin: &w.newton.lin,
            contacts: &cn.contacts,
            groups: &cn.groups,
            constraints: &cn.factored_constraints,
            h,
        };
        let (t, s, impulses) = (&mut cn.t, &mut cn.s, &mut cn.impulses);
        let (iterations, reached) = cn.gmres.solve(
            &cn.f,
            &mut cn.d,
            FORCING,
            MAX_KRYLOV,
            |v, out| op.apply(v, out, impulses),
            |r, out| op.precondition(hessian, r, out, t, s),
        );
        self.profile.contact_newton_krylov_iterations += iterations as u64;
        cn.reuse = iterations <= REFACTOR_KRYLOV && reached <= FORCING;
        cn.d.iter().all(|d| d.iter().all(|c| c.is_finite()))
    }
}
