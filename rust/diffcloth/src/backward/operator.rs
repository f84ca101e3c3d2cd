//! The adjoint operator `H^T` (matrix-free: each energy's dP plus the contact term) and the PD
//! factorization as its preconditioner, both as faer linear operators on node-major columns.

use super::contact::{ContactCoupling, ContactLin};
use crate::forward::Simulator;
use crate::linalg::SpdFactor;
use crate::Vec3;
use faer::dyn_stack::{MemStack, StackReq};
use faer::matrix_free::{LinOp, Precond};
use faer::reborrow::ReborrowMut;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, MatMut, MatRef, Par};
use std::sync::Mutex;

/// The linearization of one step at its end state: each constraint set's weighted projection
/// Jacobians, in the set's own layout (see [`PdConstraints::linearize`]).
pub(super) struct Linearization {
    pub(super) per_set: Vec<Vec<f64>>,
}

impl Linearization {
    pub(super) fn new(sim: &Simulator) -> Self {
        Self {
            per_set: sim
                .constraint_sets()
                .map(|c| vec![0.0; c.linearization_len()])
                .collect(),
        }
    }

    pub(super) fn update(&mut self, sim: &Simulator, x: &[Vec3]) {
        for (c, lin) in sim.constraint_sets().zip(&mut self.per_set) {
            c.linearize(x, lin);
        }
    }

    /// `out -= dP v`, constraint by constraint (never assembled for the iterative solvers).
    pub(super) fn sub_dp(&self, sim: &Simulator, v: &[Vec3], out: &mut [Vec3]) {
        for (c, lin) in sim.constraint_sets().zip(&self.per_set) {
            c.sub_dp(lin, v, out);
        }
    }

    /// Triplets of `H = P_s (x) I_3 - dP` (3m x 3m) for the direct solver.
    pub(super) fn assemble(
        &self,
        sim: &Simulator,
        p: &SparseColMat<usize, f64>,
    ) -> Vec<Triplet<usize, usize, f64>> {
        let mut t = Vec::new();
        let pr = p.as_ref();
        for col in 0..pr.ncols() {
            for (row, &val) in pr.row_idx_of_col(col).zip(pr.val_of_col(col)) {
                for d in 0..3 {
                    t.push(Triplet::new(3 * row + d, 3 * col + d, val));
                }
            }
        }
        let mut neg_dp = Vec::new();
        for (c, lin) in sim.constraint_sets().zip(&self.per_set) {
            c.add_neg_dp_triplets(lin, &mut neg_dp);
        }
        t.extend(neg_dp.into_iter().map(|(r, c, v)| Triplet::new(r, c, v)));
        t
    }
}

/// `H` as a faer linear operator on node-major 3m vectors.
pub(super) struct AdjointOperator<'a> {
    pub(super) sim: &'a Simulator,
    pub(super) lin: Linearization,
    pub(super) contacts: Vec<ContactLin>,
    pub(super) coupling: ContactCoupling,
    /// Scratch of the contact term (kept across applications: no allocation per iteration).
    pub(super) contact_scratch: Mutex<ContactScratch>,
}

#[derive(Default)]
pub(super) struct ContactScratch {
    /// Per contact: the impulse adjoints.
    pub(super) y: Vec<Vec3>,
    /// Per node: `u`, `-dP u` and `P u`.
    pub(super) u: Vec<Vec3>,
    pub(super) t: Vec<Vec3>,
    pub(super) pu: Vec<Vec3>,
}

impl std::fmt::Debug for AdjointOperator<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("AdjointOperator")
    }
}

impl AdjointOperator<'_> {
    /// `out = H^T v` with `H^T = P - dP - (dP - K) sum_c S_c^T Phi_c'^T E_c^T` (the adjoint
    /// system is transposed: contact makes H non-symmetric).
    pub(super) fn apply_nodes(&self, v: &[Vec3], out: &mut [Vec3]) {
        self.sim.factor().mul_xyz(v, out);
        self.lin.sub_dp(self.sim, v, out);
        if self.contacts.is_empty() {
            return;
        }
        let n = v.len();
        let h = self.sim.params().h;
        let mut guard = self.contact_scratch.lock().expect("contact scratch");
        let ContactScratch { y, u, t, pu } = &mut *guard;
        y.clear();
        y.extend(self.contacts.iter().map(|c| c.impulse_adjoint(v, h) * h));
        self.coupling.solve(y);
        u.clear();
        u.resize(n, Vec3::zeros());
        for (c, yc) in self.contacts.iter().zip(y.iter()) {
            let w = c.phi.transpose() * yc;
            for &(k, s) in &c.s {
                u[k] += s * w;
            }
        }
        // out -= (dP - K) u, with K u = P u - M u / h^2.
        t.clear();
        t.resize(n, Vec3::zeros());
        self.lin.sub_dp(self.sim, u, t); // t = -dP u
        pu.resize(n, Vec3::zeros());
        self.sim.factor().mul_xyz(u, pu);
        let mass = self.sim.masses();
        for i in 0..n {
            let ku = pu[i] - mass[i] / (h * h) * u[i];
            // (dP - K) u = -t - K u
            out[i] += t[i] + ku;
        }
    }
}

// A node-major 3m column and a slice of `Vec3` share one layout: nalgebra's `Vector3<f64>` is
// `repr(C)` over `[f64; 3]`. Viewing in place avoids two copies per Krylov iteration.
const _: () = assert!(std::mem::size_of::<Vec3>() == 24 && std::mem::align_of::<Vec3>() == 8);

pub(super) fn col_as_nodes(c: faer::ColRef<'_, f64>) -> Option<&[Vec3]> {
    let s = c.try_as_col_major()?.as_slice();
    // SAFETY: same size and alignment (checked above); the length is a multiple of 3.
    (s.len() % 3 == 0)
        .then(|| unsafe { std::slice::from_raw_parts(s.as_ptr() as *const Vec3, s.len() / 3) })
}

pub(super) fn col_as_nodes_mut(c: faer::ColMut<'_, f64>) -> Option<&mut [Vec3]> {
    let s = c.try_as_col_major_mut()?.as_slice_mut();
    // SAFETY: as in `col_as_nodes`; the mutable borrow is unique.
    (s.len() % 3 == 0).then(|| unsafe {
        std::slice::from_raw_parts_mut(s.as_mut_ptr() as *mut Vec3, s.len() / 3)
    })
}

/// Applies the node-major map `f(input, output)` to every column of `rhs`: in place on
/// contiguous columns (what faer's solvers pass), through node copies otherwise.
pub(super) fn apply_per_column(
    mut out: MatMut<'_, f64>,
    rhs: MatRef<'_, f64>,
    mut f: impl FnMut(&[Vec3], &mut [Vec3]),
) {
    let n = rhs.nrows() / 3;
    for k in 0..rhs.ncols() {
        if let (Some(v), Some(o)) = (
            col_as_nodes(rhs.col(k)),
            col_as_nodes_mut(out.rb_mut().col_mut(k)),
        ) {
            f(v, o);
            continue;
        }
        let v: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(rhs[(3 * i, k)], rhs[(3 * i + 1, k)], rhs[(3 * i + 2, k)]))
            .collect();
        let mut o = vec![Vec3::zeros(); n];
        f(&v, &mut o);
        for (i, x) in o.iter().enumerate() {
            for d in 0..3 {
                out[(3 * i + d, k)] = x[d];
            }
        }
    }
}

impl LinOp<f64> for AdjointOperator<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }
    fn nrows(&self) -> usize {
        3 * self.sim.num_nodes()
    }
    fn ncols(&self) -> usize {
        3 * self.sim.num_nodes()
    }
    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _stack: &mut MemStack) {
        apply_per_column(out, rhs, |v, o| self.apply_nodes(v, o));
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

/// `P^{-1}` (the PD factorization, per coordinate) as a faer preconditioner.
pub(super) struct PdPreconditioner<'a> {
    pub(super) factor: &'a SpdFactor,
    /// The solve's work rows (faer's `LinOp::apply` takes `&self`).
    pub(super) work: Mutex<Vec<Vec3>>,
}

impl<'a> PdPreconditioner<'a> {
    pub(super) fn new(factor: &'a SpdFactor) -> Self {
        Self {
            factor,
            work: Mutex::new(vec![Vec3::zeros(); factor.dim()]),
        }
    }
}

impl std::fmt::Debug for PdPreconditioner<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PdPreconditioner")
    }
}

impl LinOp<f64> for PdPreconditioner<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }
    fn nrows(&self) -> usize {
        3 * self.factor.dim()
    }
    fn ncols(&self) -> usize {
        3 * self.factor.dim()
    }
    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _stack: &mut MemStack) {
        let mut work = self.work.lock().expect("preconditioner work");
        apply_per_column(out, rhs, |b, o| {
            self.factor.solve_nodes_into(b, o, &mut work)
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

impl Precond<f64> for PdPreconditioner<'_> {}

/// Nodes as one node-major 3m column.
pub(super) fn nodes_to_col(v: &[Vec3]) -> Mat<f64> {
    Mat::from_fn(3 * v.len(), 1, |r, _| v[r / 3][r % 3])
}

/// A node-major 3m column back into nodes.
pub(super) fn col_to_nodes(c: &Mat<f64>, out: &mut [Vec3]) {
    for (i, o) in out.iter_mut().enumerate() {
        *o = Vec3::new(c[(3 * i, 0)], c[(3 * i + 1, 0)], c[(3 * i + 2, 0)]);
    }
}
