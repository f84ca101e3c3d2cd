//! Projective-dynamics constraints (paper Sec. 3.1, Eqn. 2-4). Each constraint `i` has a weight
//! `w_i`, a linear selector `A_i` acting identically on x, y, z, and a projection `p_i` onto
//! its constraint set; its energy is `w_i / 2 |A_i x - p_i(A_i x)|^2`.
//!
//! A constraint set contributes `sum_i w_i A_i^T A_i` to the scalar system matrix once, and
//! each local step contributes `sum_i w_i A_i^T p_i` to the right-hand side.
//!
//! Each set also owns its backward half (paper Eqn. 29): the Jacobian of its elastic force is
//! `K - dP` with `dP = sum_i A_i^T (w_i dp_i/d(A_i x)) A_i`, and its weights scale with one
//! stiffness parameter, so the adjoint needs no per-energy code.

mod attachment;
mod bend;
mod bend_edge;
mod polar;
mod stretch;

pub use attachment::Attachments;
pub use bend::Bend;
pub use bend_edge::BendEdge;
pub use stretch::Stretch;

use crate::config::BendModel;
use crate::mesh::TriMesh;
use crate::Vec3;
use nalgebra::Matrix3;

/// The bending constraints of a mesh in the scene's model: per interior edge ([`BendEdge`],
/// the reference code's) or per interior vertex ([`Bend`]).
pub fn bending(mesh: &TriMesh, k_bend: f64, model: BendModel) -> Box<dyn PdConstraints> {
    match model {
        BendModel::Edge => Box::new(BendEdge::new(mesh, k_bend)),
        BendModel::Vertex => Box::new(Bend::new(mesh, k_bend)),
    }
}

/// Constraint sets below this size are projected on one thread: rayon's fork/join overhead
/// (a few microseconds) exceeds the work.
pub(crate) const PARALLEL_MIN_CONSTRAINTS: usize = 2048;

/// One family of PD constraints (all stretch triangles, all bending vertices, ...).
pub trait PdConstraints: Send + Sync {
    /// Appends `w_i A_i^T A_i` as scalar (node, node, value) triplets.
    fn add_system_triplets(&self, out: &mut Vec<(usize, usize, f64)>);
    /// Buffers for [`PdConstraints::project`], sized for this set. They live in each
    /// simulator's workspace: the set itself is read-only and shared by every simulator of a
    /// model.
    fn new_projections(&self) -> Projections;
    /// Local step: projects every constraint at `x` into `out`, for
    /// [`PdConstraints::add_rhs`]. Returns the constraint energy
    /// `sum_i w_i / 2 |A_i x - p_i(A_i x)|^2` at `x`.
    fn project(&self, x: &[Vec3], parallel: bool, out: &mut Projections) -> f64;
    /// Adds `sum_i w_i A_i^T p_i` of the projections to `rhs`.
    fn add_rhs(&self, projections: &Projections, rhs: &mut [Vec3]);
    /// A copy behind a new box (a model is copied on write when a parameter changes).
    fn boxed_clone(&self) -> Box<dyn PdConstraints>;

    /// The stiffness parameter the weights are proportional to.
    fn stiffness(&self) -> Stiffness;
    /// Sets that stiffness (the weights scale with it; the caller refactors).
    fn set_stiffness(&mut self, k: f64);

    // ---- backward half ----------------------------------------------------------------

    /// Floats [`PdConstraints::linearize`] writes (per-constraint weighted projection
    /// Jacobians).
    fn linearization_len(&self) -> usize;
    /// Writes `w_i dp_i/d(A_i x)` of every constraint at `x` into `lin`.
    fn linearize(&self, x: &[Vec3], lin: &mut [f64]);
    /// `out -= dP v` from a linearization (matrix-free: never assembled for Krylov solves).
    fn sub_dp(&self, lin: &[f64], v: &[Vec3], out: &mut [Vec3]);
    /// Appends `-dP` as triplets of the 3m x 3m node-major matrix (row `3 node + coordinate`),
    /// for the direct adjoint solve.
    fn add_neg_dp_triplets(&self, lin: &[f64], out: &mut Vec<(usize, usize, f64)>);
    /// Calls `emit(a, b, block)` with each 3x3 block of `-dP` (entry `(r, s)` at row `3a + r`,
    /// column `3b + s`; blocks of one node pair add up), for the assembled Hessian
    /// ([`crate::hessian::StepHessian`]). Which pairs, in which order, depends on the mesh alone (never on `lin`): the
    /// assembly maps each call to its matrix slot once.
    fn for_each_neg_dp_block(&self, lin: &[f64], emit: &mut dyn FnMut(usize, usize, &Matrix3<f64>));
    /// `z . d(grad W)/dk` at `x`: the stiffness gradient is `-` this summed over steps.
    fn stiffness_dot(&self, x: &[Vec3], z: &[Vec3]) -> f64;
}

/// One local step's output: each constraint's projection (in the set's own layout) and its
/// energy (summed serially afterwards, so the total is bitwise the same on any thread count).
#[derive(Debug, Clone, Default)]
pub struct Projections {
    pub values: Vec<f64>,
    pub energy: Vec<f64>,
}

impl Projections {
    /// `constraints` projections of `width` floats each.
    pub fn new(constraints: usize, width: usize) -> Self {
        Self {
            values: vec![0.0; constraints * width],
            energy: vec![0.0; constraints],
        }
    }
}

/// Projects a set whose constraints each give one 3-vector (`project_one(i) -> (p_i,
/// energy_i)`) into `out`, on all threads for large sets; the energies are summed serially so
/// the total has the same bits whatever the thread count. (Shared by the bending models.)
pub(crate) fn project_vec3_each(
    out: &mut Projections,
    parallel: bool,
    project_one: impl Fn(usize) -> (Vec3, f64) + Sync,
) -> f64 {
    let work = |(i, (p, e)): (usize, (&mut [f64], &mut f64))| {
        let (projection, energy) = project_one(i);
        // Element-wise: `copy_from_slice` on a chunk of unknown length calls memcpy.
        (p[0], p[1], p[2]) = (projection.x, projection.y, projection.z);
        *e = energy;
    };
    let Projections { values, energy } = out;
    if parallel && energy.len() >= PARALLEL_MIN_CONSTRAINTS {
        use rayon::prelude::*;
        values
            .par_chunks_exact_mut(3)
            .zip(energy.par_iter_mut())
            .enumerate()
            .for_each(work);
    } else {
        values
            .chunks_exact_mut(3)
            .zip(energy.iter_mut())
            .enumerate()
            .for_each(work);
    }
    energy.iter().sum()
}

/// The bending models' projection: `v` rescaled to its rest length `target` (`0` on a flat
/// rest shape; `fallback`, the rest vector, when `v` vanishes exactly), and the energy
/// `w / 2 |v - p|^2`.
#[inline(always)]
pub(crate) fn rescale_to_rest_length(v: Vec3, target: f64, fallback: Vec3, w: f64) -> (Vec3, f64) {
    let len = v.norm();
    let p = if target == 0.0 {
        Vec3::zeros()
    } else if len > 0.0 {
        v * (target / len)
    } else {
        fallback
    };
    (p, 0.5 * w * (v - p).norm_squared())
}

/// Jacobian of [`rescale_to_rest_length`]: `(target / |v|)(I - v^ v^T)`, zero when
/// `target = 0` or `|v| = 0`.
pub(crate) fn rescale_jacobian(v: Vec3, target: f64) -> nalgebra::Matrix3<f64> {
    let len = v.norm();
    if target == 0.0 || len == 0.0 {
        return nalgebra::Matrix3::zeros();
    }
    let u = v / len;
    (target / len) * (nalgebra::Matrix3::identity() - u * u.transpose())
}

/// Which physical parameter scales a constraint set's weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stiffness {
    Stretch,
    Bend,
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

    /// The constraint energy at `x`.
    pub fn energy(c: &dyn PdConstraints, x: &[Vec3]) -> f64 {
        c.project(x, false, &mut c.new_projections())
    }

    /// Gradient of the constraint energy at `x`: `K x - sum_i w_i A_i^T p_i(x)`.
    pub fn gradient(c: &mut dyn PdConstraints, x: &[Vec3]) -> (f64, Vec<Vec3>) {
        let mut proj = c.new_projections();
        let e = c.project(x, false, &mut proj);
        let mut g = apply_system(c, x);
        let mut rhs = vec![Vec3::zeros(); x.len()];
        c.add_rhs(&proj, &mut rhs);
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
                let ep = energy(c, &xp);
                xp[i][d] = x[i][d] - eps;
                let em = energy(c, &xp);
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

    /// Checks the backward half against finite differences of the elastic force: along `v`,
    /// `d(grad W)/dx v = K v - dP v`; the triplets of `-dP` give the same product as
    /// `sub_dp`; and `stiffness_dot` is `z . d(grad W)/dk` (central differences in k).
    pub fn check_backward_fd(c: &mut dyn PdConstraints, k: f64, x: &[Vec3], tol: f64) {
        let n = x.len();
        let v = jitter(&vec![Vec3::zeros(); n], 1.0, 77);
        let mut lin = vec![0.0; c.linearization_len()];
        c.linearize(x, &mut lin);
        let mut analytic = apply_system(c, &v);
        c.sub_dp(&lin, &v, &mut analytic);
        let eps = 1e-6;
        let shifted = |c: &mut dyn PdConstraints, s: f64| {
            let xs: Vec<Vec3> = x.iter().zip(&v).map(|(a, b)| a + s * b).collect();
            gradient(c, &xs).1
        };
        let (gp, gm) = (shifted(c, eps), shifted(c, -eps));
        let scale = analytic.iter().map(|a| a.amax()).fold(1e-8, f64::max);
        for i in 0..n {
            let fd = (gp[i] - gm[i]) / (2.0 * eps);
            assert!(
                (fd - analytic[i]).amax() <= tol * scale,
                "d(grad W) v at node {i}: analytic {analytic:?} vs fd {fd:?}",
                analytic = analytic[i]
            );
        }
        // The assembled -dP agrees with the matrix-free product.
        let mut t = Vec::new();
        c.add_neg_dp_triplets(&lin, &mut t);
        let mut assembled = vec![Vec3::zeros(); n];
        for (r, col, val) in t {
            assembled[r / 3][r % 3] -= val * v[col / 3][col % 3];
        }
        let mut blocks = vec![Vec3::zeros(); n];
        c.for_each_neg_dp_block(&lin, &mut |a, b, m| blocks[a] += m * v[b]);
        let mut free = vec![Vec3::zeros(); n];
        c.sub_dp(&lin, &v, &mut free);
        for i in 0..n {
            assert!(
                (blocks[i] - free[i]).amax() <= 1e-12 * scale.max(1.0),
                "dP blocks differ from sub_dp at node {i}"
            );
        }
        for i in 0..n {
            assert!(
                (assembled[i] + free[i]).amax() <= 1e-12 * scale.max(1.0),
                "assembled dP differs from sub_dp at node {i}"
            );
        }
        // Stiffness: d(grad W)/dk by central differences.
        let z = jitter(&vec![Vec3::zeros(); n], 1.0, 78);
        let dot = c.stiffness_dot(x, &z);
        let dk = 1e-6 * k.abs().max(1.0);
        c.set_stiffness(k + dk);
        let gp = gradient(c, x).1;
        c.set_stiffness(k - dk);
        let gm = gradient(c, x).1;
        c.set_stiffness(k);
        let fd: f64 = (0..n).map(|i| z[i].dot(&(gp[i] - gm[i]))).sum::<f64>() / (2.0 * dk);
        assert!(
            (fd - dot).abs() <= tol * dot.abs().max(1e-8),
            "stiffness_dot {dot} vs fd {fd}"
        );
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
