//! The adjoint's factored preconditioner: the sparse Cholesky factor of the step's own
//! `H = P - dP` ([`StepHessian`]), for scenes where P preconditions badly.
//!
//! Where the step objective has soft or non-convex directions (the Hat's curved-rest edge
//! bending), PCG preconditioned by P needs 110-270 iterations per step at tolerance 1e-10;
//! with the factor of the step's own `H` it needs one. A factorization costs about 25
//! P-preconditioned iterations on the Hat, so it is used only once a P-preconditioned solve
//! of this pass took more than [`SWITCH_ITERATIONS`] (a count, not a timing: the choice, and
//! so every bit of the gradient, is the same on every run). The factor of a neighbouring step
//! does not do: consecutive steps' `H` differ along exactly the soft directions (measured:
//! 100-270 iterations with the previous step's factor).
//!
//! On a contact step the adjoint operator is `dF^T`, `dF = H - dR`, and `dR` is not of low
//! rank where many nodes touch (the Hat on its head: up to 150 slipping contacts, 100-450
//! BiCGStab iterations with `H^{-1}`). There the factor is that of `Q H Q` with the
//! directions the contact law pins eliminated (`pinned_directions`; `Q` projects them out),
//! and the preconditioner is the transpose of the forward contact Newton's: exact (`dF^{-T}`,
//! one iteration) where every contact sticks to an obstacle alone, 10-40 iterations there
//! with slipping ones. Eliminating the pinned directions also lets steps factor whose `H` is
//! indefinite only along them.

use super::contact::{pinned_directions, ContactLin};
use crate::forward::Model;
use crate::hessian::StepHessian;
use crate::Vec3;
use faer::dyn_stack::{MemStack, StackReq};
use faer::matrix_free::{LinOp, Precond};
use faer::{MatMut, MatRef, Par};
use nalgebra::Matrix3;
use std::sync::Mutex;

use super::operator::apply_per_column;

/// P-preconditioned iterations of one solve above which the pass factors each step's `H`.
pub(super) const SWITCH_ITERATIONS: usize = 50;

/// Consecutive indefinite factorizations after which the pass stops trying (a recorded step
/// that is not a minimum, e.g. stopped early, has an indefinite `H`).
const MAX_FAILURES: usize = 3;

/// The factored preconditioner's state during one backward pass.
#[derive(Default)]
pub(super) struct Factored {
    /// Built on first use (its pattern and symbolic analysis: once per model).
    hessian: Option<StepHessian>,
    /// The analysis failed, or `MAX_FAILURES` factorizations in a row found `H` indefinite:
    /// never again this pass.
    unavailable: bool,
    failures: usize,
    /// Whether the current step's solve used the factor.
    pub(super) used: bool,
    /// A P-preconditioned solve took more than `SWITCH_ITERATIONS`.
    enabled: bool,
    /// The pinned directions of the factored step, `(node, projector, m / h^2)`.
    constraints: Vec<(usize, Matrix3<f64>, f64)>,
    /// Scratch: contacts per node (zeroed), and two node vectors.
    per_node: Vec<u32>,
    t: Vec<Vec3>,
    s: Vec<Vec3>,
}

impl Factored {
    /// Continues a pass (a checkpointed segment, or one-step adjoints in sequence) that had
    /// already switched to the factor or not.
    pub(super) fn new(enabled: bool) -> Self {
        Self {
            enabled,
            ..Default::default()
        }
    }

    /// Whether the pass has switched to the factor (carried to the next segment).
    pub(super) fn enabled(&self) -> bool {
        self.enabled
    }

    /// Whether this step should try the factor.
    pub(super) fn wanted(&self) -> bool {
        self.enabled && !self.unavailable
    }

    /// Counts a P-preconditioned solve.
    pub(super) fn observe(&mut self, iterations: usize) {
        self.enabled |= iterations > SWITCH_ITERATIONS;
    }

    /// Factors this step's contact-free `H` from its linearization, with the directions its
    /// `contacts` pin eliminated; false if that is not positive definite (or cannot be
    /// analysed), and then there is no factor to use.
    pub(super) fn factor(
        &mut self,
        model: &Model,
        lin: &[Vec<f64>],
        contacts: &[ContactLin],
    ) -> bool {
        if self.unavailable {
            return false;
        }
        if !self.hessian.as_ref().is_some_and(|h| h.fits(model)) {
            match model.hessian_pattern().filter(|p| p.fits(model)) {
                Some(p) => self.hessian = Some(StepHessian::new(p)),
                None => {
                    self.unavailable = true;
                    return false;
                }
            }
        }
        let n = model.num_nodes();
        self.per_node.resize(n, 0);
        self.t.resize(n, Vec3::zeros());
        self.s.resize(n, Vec3::zeros());
        pinned_directions(
            contacts,
            &model.mass,
            model.params.h,
            &mut self.per_node,
            &mut self.constraints,
        );
        let ok = self
            .hessian
            .as_mut()
            .is_some_and(|h| h.factor_constrained(model, lin, &self.constraints));
        self.failures = if ok { 0 } else { self.failures + 1 };
        self.unavailable = self.failures >= MAX_FAILURES;
        ok
    }

    /// `out = H^{-1} b` with the last successful [`Factored::factor`] (of a contact-free step:
    /// nothing pinned).
    pub(super) fn solve(&mut self, b: &[Vec3], out: &mut [Vec3]) {
        debug_assert!(self.constraints.is_empty());
        self.hessian
            .as_mut()
            .expect("factored before solving")
            .solve(b, out);
    }

    /// `out = M^T r`, `M` the forward contact Newton's preconditioner with this factor:
    /// `M^T r = K r + Z (r - H K r)`, `K = Q (Q H Q)^{-1} Q`, `Z` the pinned directions over
    /// `m / h^2` (`M = Z + K (I - H Z)`, and `Z`, `K` are symmetric).
    fn precondition_transposed(
        &mut self,
        model: &Model,
        lin: &[Vec<f64>],
        r: &[Vec3],
        out: &mut [Vec3],
    ) {
        let (t, s) = (&mut self.t, &mut self.s);
        t.copy_from_slice(r);
        for &(j, pi, _) in &self.constraints {
            let tj = t[j];
            t[j] = tj - pi * tj;
        }
        self.hessian
            .as_mut()
            .expect("factored before solving")
            .solve(t, s);
        model.factor.mul_xyz(s, t);
        for (c, l) in model.constraint_sets().zip(lin) {
            c.sub_dp(l, s, t);
        }
        out.copy_from_slice(s);
        for &(j, pi, w) in &self.constraints {
            out[j] += pi * (r[j] - t[j]) / w;
        }
    }

    /// The preconditioner of a contact step's BiCGStab (`precondition_transposed`).
    pub(super) fn as_precond<'a>(
        &'a mut self,
        model: &'a Model,
        lin: &'a [Vec<f64>],
    ) -> FactorPrecond<'a> {
        FactorPrecond {
            factored: Mutex::new(self),
            model,
            lin,
        }
    }
}

/// `M^T` (`Factored::precondition_transposed`) as a faer preconditioner on node-major 3m
/// columns.
pub(super) struct FactorPrecond<'a> {
    /// (faer's `LinOp::apply` takes `&self`; the solve needs its work buffers.)
    factored: Mutex<&'a mut Factored>,
    model: &'a Model,
    lin: &'a [Vec<f64>],
}

impl std::fmt::Debug for FactorPrecond<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("FactorPrecond")
    }
}

impl LinOp<f64> for FactorPrecond<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }
    fn nrows(&self) -> usize {
        self.ncols()
    }
    fn ncols(&self) -> usize {
        let f = self.factored.lock().expect("factor");
        f.hessian.as_ref().map_or(0, |h| h.dim())
    }
    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _stack: &mut MemStack) {
        let mut f = self.factored.lock().expect("factor");
        apply_per_column(out, rhs, |b, o| {
            f.precondition_transposed(self.model, self.lin, b, o)
        });
    }
    fn conj_apply(
        &self,
        out: MatMut<'_, f64>,
        rhs: MatRef<'_, f64>,
        par: Par,
        stack: &mut MemStack,
    ) {
        self.apply(out, rhs, par, stack);
    }
}

impl Precond<f64> for FactorPrecond<'_> {}
