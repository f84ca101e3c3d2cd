//! Projective-dynamics constraints (paper Sec. 3.1, Eqn. 2-4). Each constraint `i` has a weight
//! `w_i`, a linear selector `A_i` acting identically on x, y, z, and a projection `p_i` onto
//! its constraint set; its energy is `w_i / 2 |A_i x - p_i(A_i x)|^2`.
//!
//! A constraint set contributes `sum_i w_i A_i^T A_i` to the scalar system matrix once, and
//! each local step contributes `sum_i w_i A_i^T p_i` to the right-hand side.

mod attachment;
mod bend;
mod stretch;

pub use attachment::Attachments;
pub use bend::Bend;
pub use stretch::{
    project_singular_values, projection_jacobian as stretch_projection_jacobian, Stretch,
};

use crate::Vec3;

/// Constraint sets below this size are projected on one thread: rayon's fork/join overhead
/// (a few microseconds) exceeds the work.
pub(crate) const PARALLEL_MIN_CONSTRAINTS: usize = 2048;

/// One family of PD constraints (all stretch triangles, all bending vertices, ...).
pub trait PdConstraints: Send + Sync {
    /// Appends `w_i A_i^T A_i` as scalar (node, node, value) triplets.
    fn add_system_triplets(&self, out: &mut Vec<(usize, usize, f64)>);
    /// Local step: projects every constraint at `x`, keeping the projections for
    /// [`PdConstraints::add_rhs`] (and later for the backward pass). Returns the constraint
    /// energy `sum_i w_i / 2 |A_i x - p_i|^2` at `x`.
    fn project(&mut self, x: &[Vec3], parallel: bool) -> f64;
    /// Adds `sum_i w_i A_i^T p_i` of the stored projections to `rhs`.
    fn add_rhs(&self, rhs: &mut [Vec3]);
}

#[cfg(test)]
pub(crate) mod testing {
    //! Shared checks: a constraint set's energy, gradient (`K x - rhs`) and finite differences.
    use super::PdConstraints;
    use crate::Vec3;

    /// `K x` with `K = sum_i w_i A_i^T A_i` from the constraint's own triplets.
    pub fn apply_system(c: &dyn PdConstraints, x: &[Vec3]) -> Vec<Vec3> {
        let mut t = Vec::new();
        c.add_system_triplets(&mut t);
        let mut out = vec![Vec3::zeros(); x.len()];
        for (r, col, v) in t {
            out[r] += v * x[col];
        }
        out
    }

    /// Gradient of the constraint energy at `x`: `K x - sum_i w_i A_i^T p_i(x)`.
    pub fn gradient(c: &mut dyn PdConstraints, x: &[Vec3]) -> (f64, Vec<Vec3>) {
        let e = c.project(x, false);
        let mut g = apply_system(c, x);
        let mut rhs = vec![Vec3::zeros(); x.len()];
        c.add_rhs(&mut rhs);
        for (gi, ri) in g.iter_mut().zip(&rhs) {
            *gi -= ri;
        }
        (e, g)
    }

    /// Asserts that the analytic gradient matches central differences of the energy.
    pub fn check_gradient_fd(c: &mut dyn PdConstraints, x: &[Vec3], tol: f64) {
        let (_, g) = gradient(c, x);
        let eps = 1e-6;
        let mut xp = x.to_vec();
        let scale = g.iter().map(|v| v.amax()).fold(1e-8, f64::max);
        for i in 0..x.len() {
            for d in 0..3 {
                xp[i][d] = x[i][d] + eps;
                let ep = c.project(&xp, false);
                xp[i][d] = x[i][d] - eps;
                let em = c.project(&xp, false);
                xp[i][d] = x[i][d];
                let fd = (ep - em) / (2.0 * eps);
                assert!(
                    (fd - g[i][d]).abs() <= tol * scale,
                    "node {i} dim {d}: analytic {} vs fd {fd}",
                    g[i][d]
                );
            }
        }
    }

    /// A deterministic pseudo-random perturbation in [-amp, amp].
    pub fn jitter(x: &[Vec3], amp: f64, seed: u64) -> Vec<Vec3> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        x.iter()
            .map(|p| p + Vec3::new(next(), next(), next()) * amp)
            .collect()
    }
}
