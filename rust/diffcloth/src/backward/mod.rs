//! Adjoint of the recorded steps (paper Sec. 4, Eqns. 13-30), contact included (Sec. 4.2).
//!
//! Step n solves `g(x_{n+1}) = M (x_{n+1} - y) / h^2 + grad W(x_{n+1}) = 0` with
//! `y = x_n + h v_n + h^2 M^{-1} f` and `v_{n+1} = (x_{n+1} - x_n) / h`. Its Jacobian is
//! `H = P - dP`, `dP = sum_i w_i A_i^T (dp_i/d(A_i x)) A_i` (paper Eqn. 29 with dR = 0), and
//! the adjoint `z` solves `H z = dL/dx_{n+1} + dL/dv_{n+1} / h`. Then
//! `dL/dx_n = M z / h^2 - dL/dv_{n+1} / h`, `dL/dv_n = M z / h`, `dL/df_n = z`, and every
//! parameter theta gets `-z . dg/dtheta`.

pub(crate) mod contact;
mod factored;
mod gradients;
mod operator;
mod replay;
mod solvers;
mod step_vjp;

pub use gradients::Gradients;
pub use step_vjp::AdjointWarmStart;

use std::time::Duration;

/// How the adjoint system `H z = g` is solved (selectable per call).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdjointSolver {
    /// Sparse LU of the assembled `H` (the reference).
    Direct,
    /// Preconditioned by the PD factorization of `P` (the default): conjugate gradients when
    /// `H` is symmetric (no active contact), else BiCGStab.
    Krylov,
    /// The paper's Eqn. 30: `P z_{k+1} = dP z_k + g`, reusing the PD factorization.
    FixedPoint,
}

#[derive(Debug, Clone)]
pub struct BackwardOptions {
    pub solver: AdjointSolver,
    /// Relative residual `|g - H z| / |g|` at which an iterative solve stops.
    pub tolerance: f64,
    /// Iteration cap of the iterative solvers (then: fall back to `Direct`).
    pub max_iterations: usize,
}

impl Default for BackwardOptions {
    fn default() -> Self {
        Self {
            solver: AdjointSolver::Krylov,
            tolerance: 1e-10,
            max_iterations: 500,
        }
    }
}

/// What the adjoint solve of one step did.
#[derive(Debug, Clone, Copy, Default)]
pub struct AdjointStepStats {
    /// Iterations of the iterative solver, also when it then fell back (the cap when a
    /// Krylov solve stopped there).
    pub iterations: usize,
    /// The iterative solver stalled or diverged and the direct solve was used.
    pub fell_back: bool,
    /// The Krylov solve was preconditioned by this step's own factored `H` rather than by P
    /// (`factored.rs`: once P-preconditioned solves take many iterations).
    pub factored: bool,
    /// Final relative residual.
    pub residual: f64,
}

/// Time per backward stage (the columns of the paper's Table 1).
#[derive(Debug, Clone, Copy, Default)]
pub struct BackwardProfile {
    /// Projection Jacobians (dP).
    pub dp: Duration,
    /// Contact linearization (dR).
    pub dr: Duration,
    pub solve: Duration,
    pub other: Duration,
}

/// Recorded steps whose PD residual is above this are flagged: the adjoint assumes the step is
/// the converged implicit-Euler solution (measured on the Hat, 400 steps: 1e-8 gives 29 % error
/// in the target gradients, 1e-10 gives 0.02 %).
pub const TRUSTED_FORWARD_RESIDUAL: f64 = 1e-9;
