//! Solving the adjoint system of one step: the paper's fixed point, PCG / BiCGStab
//! preconditioned by the PD factorization, sparse LU, and the policy that falls back to LU
//! when an iterative solve stalls, diverges or hits its cap.

use super::factored::Factored;
use super::operator::{col_to_nodes, nodes_to_col, AdjointOperator, PdPreconditioner};
use super::{AdjointSolver, AdjointStepStats, BackwardOptions};
use crate::cancel::Cancel;
use crate::error::{Error, Result};
use crate::forward::Simulator;
use crate::linalg::SpdFactor;
use crate::Vec3;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::matrix_free::bicgstab::{bicgstab, bicgstab_scratch, BicgParams};
use faer::matrix_free::{IdentityPrecond, InitialGuessStatus};
use faer::prelude::*;
use faer::reborrow::ReborrowMut;
use faer::sparse::{SparseColMat, Triplet};
use faer::Par;
use nalgebra::Matrix3;

/// How an iterative adjoint solve ended.
#[derive(Debug, Clone, Copy)]
pub(super) struct Attempt {
    pub(super) iterations: usize,
    pub(super) converged: bool,
}

impl Attempt {
    pub(super) fn converged(iterations: usize) -> Self {
        Self {
            iterations,
            converged: true,
        }
    }
    pub(super) fn failed(iterations: usize) -> Self {
        Self {
            iterations,
            converged: false,
        }
    }
}

/// Work space of the iterative adjoint solves, allocated once per backward pass.
pub(super) struct SolveWork<'a> {
    pub(super) precond: PdPreconditioner<'a>,
    /// Polled once per iteration of the hand-written solves (rate-limited by `Cancel`).
    pub(super) cancel: &'a Cancel<'a>,
    /// faer's BiCGStab scratch.
    pub(super) stack: MemBuffer,
    /// Node vectors of PCG and the fixed-point iteration, and the P-solve's work rows.
    pub(super) r: Vec<Vec3>,
    pub(super) s: Vec<Vec3>,
    pub(super) p: Vec<Vec3>,
    pub(super) ap: Vec<Vec3>,
    pub(super) y: Vec<Vec3>,
    /// The factor of the step's own `H`, where P preconditions badly.
    pub(super) factored: Factored,
}

impl<'a> SolveWork<'a> {
    pub(super) fn new(
        factor: &'a SpdFactor,
        op: &AdjointOperator<'_>,
        cancel: &'a Cancel<'a>,
    ) -> Self {
        let precond = PdPreconditioner::new(factor);
        let n = factor.dim();
        let stack = MemBuffer::new(bicgstab_scratch(
            IdentityPrecond { dim: 3 * n },
            &precond,
            op,
            1,
            Par::Seq,
        ));
        let zeros = vec![Vec3::zeros(); n];
        Self {
            precond,
            cancel,
            stack,
            r: zeros.clone(),
            s: zeros.clone(),
            p: zeros.clone(),
            ap: zeros.clone(),
            y: zeros,
            factored: Factored::default(),
        }
    }
}

pub(super) fn norm(v: &[Vec3]) -> f64 {
    v.iter().map(|x| x.norm_squared()).sum::<f64>().sqrt()
}

pub(super) fn dot(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

impl Simulator {
    /// Solves `H z = g` with the chosen solver; an iterative solver that stalls, diverges or
    /// hits its cap falls back to the direct solve (counted in the stats).
    pub(super) fn solve_adjoint(
        &self,
        op: &AdjointOperator<'_>,
        g: &[Vec3],
        z: &mut [Vec3],
        options: &BackwardOptions,
        work: &mut SolveWork<'_>,
    ) -> Result<AdjointStepStats> {
        let g_norm = norm(g);
        if g_norm == 0.0 {
            z.iter_mut().for_each(|v| *v = Vec3::zeros());
            return Ok(AdjointStepStats::default());
        }
        // |g - H z| / |g|, into the work rows (no allocation per step).
        let residual_of = |z: &[Vec3], hz: &mut [Vec3]| {
            op.apply_nodes(z, hz);
            let r2: f64 = hz.iter().zip(g).map(|(a, b)| (b - a).norm_squared()).sum();
            r2.sqrt() / g_norm
        };
        work.factored.used = false;
        let iterative = match options.solver {
            AdjointSolver::Direct => None,
            AdjointSolver::FixedPoint => Some(self.fixed_point(op, g, z, options, work)),
            AdjointSolver::Krylov => Some(self.krylov(op, g, z, options, work)),
        };
        // A solve stopped by the cancellation is not a failed one: no direct fallback.
        if work.cancel.was_cancelled() {
            return Err(Error::Cancelled("backward (adjoint solve)".into()));
        }
        if let Some(Attempt {
            iterations,
            converged: true,
        }) = iterative
        {
            let residual = residual_of(z, &mut work.ap);
            if residual <= options.tolerance * 10.0
                && z.iter().all(|v| v.iter().all(|c| c.is_finite()))
            {
                return Ok(AdjointStepStats {
                    iterations,
                    fell_back: false,
                    factored: work.factored.used,
                    residual,
                });
            }
        }
        self.direct(op, g, z)?;
        Ok(AdjointStepStats {
            iterations: iterative.map_or(0, |a| a.iterations),
            fell_back: iterative.is_some(),
            factored: work.factored.used,
            residual: residual_of(z, &mut work.ap),
        })
    }

    /// Paper Eqn. 30: `P z_{k+1} = (P - H^T) z_k + g` (dP and, with contact, the dR term),
    /// reusing the PD factorization. Stops on the true relative residual `|g - H^T z| / |g|`
    /// (free: `H^T z` is needed for the update anyway), not on the update size, which
    /// understates the error when the iteration converges slowly. Returns the iteration count,
    /// or None on divergence or at the cap.
    pub(super) fn fixed_point(
        &self,
        op: &AdjointOperator<'_>,
        g: &[Vec3],
        z: &mut [Vec3],
        options: &BackwardOptions,
        work: &mut SolveWork<'_>,
    ) -> Attempt {
        let g_norm = norm(g);
        let SolveWork {
            r,
            s,
            ap,
            y,
            cancel,
            ..
        } = work;
        // Warm start from the previous step's adjoint (kept in z), unless it is unusable.
        if !z.iter().all(|v| v.iter().all(|c| c.is_finite())) {
            z.iter_mut().for_each(|v| *v = Vec3::zeros());
        }
        let mut previous = f64::INFINITY;
        let mut growing = 0;
        for it in 0..=options.max_iterations {
            if cancel.poll() {
                return Attempt::failed(it);
            }
            op.apply_nodes(z, ap);
            let residual = g
                .iter()
                .zip(ap.iter())
                .map(|(a, b)| (a - b).norm_squared())
                .sum::<f64>()
                .sqrt()
                / g_norm;
            if !residual.is_finite() {
                return Attempt::failed(it);
            }
            if residual <= options.tolerance {
                return Attempt::converged(it);
            }
            growing = if residual > previous { growing + 1 } else { 0 };
            if growing >= 5 || it == options.max_iterations {
                return Attempt::failed(it);
            }
            previous = residual;
            // z <- P^{-1} (g + P z - H^T z)
            self.factor().mul_xyz(z, s);
            for ((ri, gi), (si, ai)) in r.iter_mut().zip(g).zip(s.iter().zip(ap.iter())) {
                *ri = gi + si - ai;
            }
            self.factor().solve_nodes_into(r, z, y);
        }
        Attempt::failed(options.max_iterations)
    }

    /// Krylov solve preconditioned by `P` (or, once P has done badly in this pass, by the
    /// step's factored `H`: `factored.rs`): CG while `H` is symmetric (no active contact),
    /// else (or when CG meets negative curvature) faer's BiCGStab.
    pub(super) fn krylov(
        &self,
        op: &AdjointOperator<'_>,
        g: &[Vec3],
        z: &mut [Vec3],
        options: &BackwardOptions,
        work: &mut SolveWork<'_>,
    ) -> Attempt {
        let n = g.len();
        // Warm start from the previous (later) steps' adjoints: consecutive adjoints are close.
        if !z.iter().all(|v| v.iter().all(|c| c.is_finite())) {
            z.iter_mut().for_each(|v| *v = Vec3::zeros());
        }
        let mut spent = 0;
        // The step's own H, factored where P preconditions badly (with the directions its
        // contacts pin eliminated: `factored.rs`).
        let factored = work.factored.wanted()
            && work
                .factored
                .factor(&**self.model(), &op.lin.per_set, &op.contacts);
        work.factored.used = factored;
        if op.contacts.is_empty() {
            match self.pcg(op, g, z, options, work, factored) {
                Ok(attempt) => {
                    if !factored {
                        work.factored.observe(attempt.iterations);
                    }
                    return attempt;
                }
                Err(iterations) => spent = iterations,
            }
        }
        let rhs = nodes_to_col(g);
        let mut out = nodes_to_col(z);
        let mut params = BicgParams::<f64>::default();
        // (Also: faer 0.24's BiCGStab leaves its residual vector uninitialized for
        // `InitialGuessStatus::Zero`; `MaybeNonZero` computes r = g - H z0.)
        params.initial_guess = InitialGuessStatus::MaybeNonZero;
        params.rel_tolerance = options.tolerance;
        params.max_iters = options.max_iterations;
        // Right preconditioning by P (H P^{-1} is close to the identity: dP is small next to
        // P), or by the factored H with the pinned directions eliminated (`factored.rs`).
        let SolveWork {
            precond,
            stack,
            factored: by_factor,
            ..
        } = work;
        let mut out_col = out.as_mut();
        let mut stack = MemStack::new(stack);
        let result = if factored {
            bicgstab(
                out_col.rb_mut(),
                IdentityPrecond { dim: 3 * n },
                by_factor.as_precond(self.model(), &op.lin.per_set),
                op,
                rhs.as_ref(),
                params,
                |_| {},
                Par::Seq,
                &mut stack,
            )
        } else {
            bicgstab(
                out_col.rb_mut(),
                IdentityPrecond { dim: 3 * n },
                &*precond,
                op,
                rhs.as_ref(),
                params,
                |_| {},
                Par::Seq,
                &mut stack,
            )
        };
        col_to_nodes(&out, z);
        match result {
            Ok(info) => {
                if !factored {
                    work.factored.observe(info.iter_count);
                }
                Attempt::converged(spent + info.iter_count)
            }
            Err(_) => Attempt::failed(spent + params.max_iters),
        }
    }

    /// Preconditioned conjugate gradients on `H z = g` (contact-free `H = P - dP` is
    /// symmetric), stopping at `|g - H z| <= tolerance |g|`; preconditioned by the step's
    /// factored H (`by_factor`, `factored.rs`) or by P. Hand-written rather than faer's
    /// CG, which is a block method: for one right-hand side its per-iteration k x k Cholesky,
    /// permutations and gemm calls cost about 5 % of an iteration, and here the vectors stay
    /// node-major. `Err(iterations)` when `H` shows non-positive curvature (possible away from
    /// a converged step); `z` then holds the last iterate.
    pub(super) fn pcg(
        &self,
        op: &AdjointOperator<'_>,
        g: &[Vec3],
        z: &mut [Vec3],
        options: &BackwardOptions,
        work: &mut SolveWork<'_>,
        by_factor: bool,
    ) -> std::result::Result<Attempt, usize> {
        let SolveWork {
            r,
            s,
            p,
            ap,
            y,
            cancel,
            factored,
            ..
        } = work;
        let factor = self.factor();
        let mut precondition = |r: &[Vec3], s: &mut [Vec3]| {
            if by_factor {
                factored.solve(r, s)
            } else {
                factor.solve_nodes_into(r, s, y)
            }
        };
        let threshold = options.tolerance * norm(g);
        op.apply_nodes(z, ap);
        for ((ri, gi), ai) in r.iter_mut().zip(g).zip(ap.iter()) {
            *ri = gi - ai;
        }
        if norm(r) <= threshold {
            return Ok(Attempt::converged(0));
        }
        precondition(r, s);
        p.copy_from_slice(s);
        let mut rs = dot(r, s);
        for it in 1..=options.max_iterations {
            if cancel.poll() {
                return Ok(Attempt::failed(it));
            }
            op.apply_nodes(p, ap);
            let curvature = dot(p, ap);
            let positive = curvature.is_finite() && curvature > 0.0;
            if !positive {
                return Err(it);
            }
            let alpha = rs / curvature;
            for (zi, pi) in z.iter_mut().zip(p.iter()) {
                *zi += alpha * pi;
            }
            for (ri, ai) in r.iter_mut().zip(ap.iter()) {
                *ri -= alpha * ai;
            }
            if norm(r) <= threshold {
                return Ok(Attempt::converged(it));
            }
            precondition(r, s);
            let rs_next = dot(r, s);
            let beta = rs_next / rs;
            rs = rs_next;
            for (pi, si) in p.iter_mut().zip(s.iter()) {
                *pi = si + beta * *pi;
            }
        }
        Ok(Attempt::failed(options.max_iterations))
    }

    pub(super) fn direct(
        &self,
        op: &AdjointOperator<'_>,
        g: &[Vec3],
        z: &mut [Vec3],
    ) -> Result<()> {
        let n = g.len();
        let mut triplets = op.lin.assemble(self, self.factor().matrix());
        if !op.contacts.is_empty() {
            // H^T = H_nc - (dP - K) C with C = sum_c S^T Phi'^T E^T and dP - K = M/h^2 - H_nc.
            let h_nc = SparseColMat::<usize, f64>::try_new_from_triplets(3 * n, 3 * n, &triplets)
                .map_err(|e| {
                Error::Solver(format!("cannot assemble the adjoint matrix: {e:?}"))
            })?;
            let hr = h_nc.as_ref();
            let (mass, h) = (self.masses(), self.params().h);
            // C = S^T B^T (I - T^T B^T)^{-1} E^T in 3x3 blocks C[k, j].
            let mut blocks: std::collections::BTreeMap<(usize, usize), Matrix3<f64>> =
                Default::default();
            for (group, inv) in op.coupling.inverse_groups(op.contacts.len()) {
                for (bi, &c) in group.iter().enumerate() {
                    for (bj, &cp) in group.iter().enumerate() {
                        let sub: Matrix3<f64> = inv.fixed_view::<3, 3>(3 * bi, 3 * bj).into_owned();
                        let block = op.contacts[c].phi.transpose() * sub;
                        for &(k, s) in &op.contacts[c].s {
                            for &(j, e) in &op.contacts[cp].e {
                                *blocks.entry((k, j)).or_insert_with(Matrix3::zeros) +=
                                    (s * e) * block;
                            }
                        }
                    }
                }
            }
            for (&(k, j), block) in &blocks {
                for ep in 0..3 {
                    let col = 3 * k + ep;
                    for (row, &val) in hr.row_idx_of_col(col).zip(hr.val_of_col(col)) {
                        let a = if row == col {
                            mass[k] / (h * h) - val
                        } else {
                            -val
                        };
                        for cp in 0..3 {
                            triplets.push(Triplet::new(row, 3 * j + cp, -a * block[(ep, cp)]));
                        }
                    }
                }
            }
        }
        let h = SparseColMat::<usize, f64>::try_new_from_triplets(3 * n, 3 * n, &triplets)
            .map_err(|e| Error::Solver(format!("cannot assemble the adjoint matrix: {e:?}")))?;
        let lu = h
            .sp_lu()
            .map_err(|e| Error::Solver(format!("adjoint matrix is singular: {e:?}")))?;
        let mut rhs = nodes_to_col(g);
        lu.solve_in_place(rhs.as_mut());
        col_to_nodes(&rhs, z);
        Ok(())
    }
}
