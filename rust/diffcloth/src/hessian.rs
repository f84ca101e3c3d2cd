//! The step objective's Hessian `H = P (x) I_3 - dP` (3m x 3m, node-major), assembled and
//! factored by sparse Cholesky. Its pattern is fixed by the mesh (P's node pattern, every node
//! pair a dense 3x3 block), so the fill-reducing ordering, the symbolic factorization and the
//! map from each energy's blocks to their slots are built once per model
//! ([`HessianPattern`], kept in the `Model`); new values (a new linearization) cost an
//! assembly and a numeric factorization ([`StepHessian`]). A failed factorization is how an
//! indefinite `H` shows (a step away from a minimum; the caller falls back).
//!
//! The adjoint preconditions each step's solve with the factor of that step's own
//! contact-free `H` where P does badly (`backward/factored.rs`).

use crate::error::{Error, Result};
use crate::forward::Model;
use crate::Vec3;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
    SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use nalgebra::Matrix3;
use std::sync::Arc;

/// Where one 3x3 block lives in the (both-triangle, column-major) value array: entry `(r, s)`
/// at `base + s * stride + r` (each of a node's three columns holds `stride` rows).
#[derive(Clone, Copy)]
struct Slot {
    base: u32,
    stride: u32,
}

/// What a model's step Hessians share (built once per model, `Model::hessian_pattern`): the
/// pattern, the slot of every contribution and the symbolic Cholesky analysis.
pub(crate) struct HessianPattern {
    /// The 3m x 3m pattern, both triangles (faer reads the lower one).
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Per entry of P (its CSC order), the block it adds to; per `-dP` block the constraint
    /// sets emit (their fixed order), its slot.
    p_slots: Vec<Slot>,
    dp_slots: Vec<Slot>,
    /// P's pattern when this was built (a model with another pattern needs a rebuild).
    p_col_ptr: Vec<usize>,
    p_row_idx: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
}

/// One Hessian's values and Cholesky factor; every buffer allocated at construction.
pub(crate) struct StepHessian {
    pattern: Arc<HessianPattern>,
    values: Vec<f64>,
    l_values: Vec<f64>,
    /// Whether `l_values` holds the factor of the current values.
    factored: bool,
    stack: MemBuffer,
    /// A right-hand side / solution as one 3m column.
    column: Vec<f64>,
    /// Per node: its index in the constraints of `factor_constrained` (u32::MAX: none).
    constrained: Vec<u32>,
}

impl HessianPattern {
    /// The pattern and symbolic analysis for `model`.
    pub(crate) fn new(model: &Model) -> Result<Self> {
        // Only the blocks' positions are read, never their values.
        let lin: Vec<Vec<f64>> = model
            .constraint_sets()
            .map(|c| vec![0.0; c.linearization_len()])
            .collect();
        let m = model.num_nodes();
        let p = model.factor.matrix().as_ref();
        // Node pattern: P's, plus every pair the constraint sets emit (the same pairs, as
        // dP = A^T (w dp) A shares A with P; taken as a union to rely on neither).
        let mut nodes: Vec<Vec<usize>> = (0..m).map(|j| p.row_idx_of_col(j).collect()).collect();
        let mut pairs = Vec::new();
        for (c, l) in model.constraint_sets().zip(&lin) {
            c.for_each_neg_dp_block(l, &mut |a, b, _| pairs.push((a, b)));
        }
        for &(a, b) in &pairs {
            nodes[b].push(a);
        }
        for col in &mut nodes {
            col.sort_unstable();
            col.dedup();
        }
        let mut col_ptr = Vec::with_capacity(3 * m + 1);
        col_ptr.push(0);
        let mut row_idx = Vec::new();
        for col in &nodes {
            for _ in 0..3 {
                row_idx.extend(col.iter().flat_map(|&i| [3 * i, 3 * i + 1, 3 * i + 2]));
                col_ptr.push(row_idx.len());
            }
        }
        if row_idx.len() > u32::MAX as usize {
            return Err(Error::Solver("step Hessian too large to assemble".into()));
        }
        let slot = |a: usize, b: usize| {
            let pos = nodes[b].binary_search(&a).expect("pair in the pattern");
            Slot {
                base: (col_ptr[3 * b] + 3 * pos) as u32,
                stride: (3 * nodes[b].len()) as u32,
            }
        };
        let mut p_slots = Vec::with_capacity(p.compute_nnz());
        for j in 0..m {
            p_slots.extend(p.row_idx_of_col(j).map(|i| slot(i, j)));
        }
        let dp_slots = pairs.iter().map(|&(a, b)| slot(a, b)).collect();
        let n = 3 * m;
        let pattern = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let symbolic = factorize_symbolic_cholesky(
            pattern,
            Side::Lower,
            SymmetricOrdering::Amd,
            // faer's choice (supernodal here): forced simplicial was measured 3.5x slower
            // on the Hat (3m = 1854, 265k factor entries).
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| Error::Solver(format!("symbolic Cholesky of the step Hessian: {e:?}")))?;
        Ok(Self {
            symbolic,
            p_slots,
            dp_slots,
            p_col_ptr: p.col_ptr().to_vec(),
            p_row_idx: p.row_idx().to_vec(),
            col_ptr,
            row_idx,
        })
    }

    /// Whether this was built for P's pattern of `model` (a copied model keeps it).
    pub(crate) fn fits(&self, model: &Model) -> bool {
        let p = model.factor.matrix().symbolic();
        p.col_ptr() == self.p_col_ptr.as_slice() && p.row_idx() == self.p_row_idx.as_slice()
    }
}

impl StepHessian {
    pub(crate) fn new(pattern: Arc<HessianPattern>) -> Self {
        let symbolic = &pattern.symbolic;
        let stack = MemBuffer::new(StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]));
        Self {
            l_values: vec![0.0; symbolic.len_val()],
            values: vec![0.0; pattern.row_idx.len()],
            column: vec![0.0; pattern.col_ptr.len() - 1],
            factored: false,
            constrained: Vec::new(),
            stack,
            pattern,
        }
    }

    /// Whether this was built for P's pattern of `model`.
    pub(crate) fn fits(&self, model: &Model) -> bool {
        self.pattern.fits(model)
    }

    /// Assembles `H = P (x) I_3 - dP` from a linearization and factors `Q H Q + sum_j w_j Pi_j`
    /// (just `H` without constraints); false (and no usable factor) if that is not numerically
    /// positive definite. Per constrained node `(j, Pi_j, w_j)` the
    /// projector `Pi_j` onto its constrained directions (`Q = I - Pi` per node, identity
    /// elsewhere) and a weight. The constrained directions decouple from the rest, which is
    /// how the contact Newton eliminates stick and normal directions (`contact_newton.rs`).
    /// Each node at most once.
    pub(crate) fn factor_constrained(
        &mut self,
        model: &Model,
        lin: &[Vec<f64>],
        constraints: &[(usize, Matrix3<f64>, f64)],
    ) -> bool {
        self.assemble(model, lin);
        let m = self.column.len() / 3;
        if self.constrained.len() != m {
            self.constrained = vec![u32::MAX; m];
        }
        for (k, &(j, _, _)) in constraints.iter().enumerate() {
            self.constrained[j] = k as u32;
        }
        let pattern = &*self.pattern;
        let q = |k: u32| match k {
            u32::MAX => Matrix3::identity(),
            k => Matrix3::identity() - constraints[k as usize].1,
        };
        for b in 0..m {
            let (start, end) = (pattern.col_ptr[3 * b], pattern.col_ptr[3 * b + 1]);
            let stride = end - start;
            for pos in 0..stride / 3 {
                let a = pattern.row_idx[start + 3 * pos] / 3;
                let (ka, kb) = (self.constrained[a], self.constrained[b]);
                if ka == u32::MAX && kb == u32::MAX {
                    continue;
                }
                let base = start + 3 * pos;
                let block = Matrix3::from_fn(|r, c| self.values[base + c * stride + r]);
                let mut block = q(ka) * block * q(kb);
                if a == b {
                    let (_, pi, w) = constraints[ka as usize];
                    block += w * pi;
                }
                for c in 0..3 {
                    for r in 0..3 {
                        self.values[base + c * stride + r] = block[(r, c)];
                    }
                }
            }
        }
        for &(j, _, _) in constraints {
            self.constrained[j] = u32::MAX;
        }
        self.factorize()
    }

    fn assemble(&mut self, model: &Model, lin: &[Vec<f64>]) {
        let pattern = &*self.pattern;
        let values = &mut self.values;
        values.iter_mut().for_each(|v| *v = 0.0);
        for (s, &v) in pattern.p_slots.iter().zip(model.factor.matrix().val()) {
            let (base, stride) = (s.base as usize, s.stride as usize);
            for c in 0..3 {
                values[base + c * stride + c] += v;
            }
        }
        let mut slots = pattern.dp_slots.iter();
        for (c, l) in model.constraint_sets().zip(lin) {
            c.for_each_neg_dp_block(l, &mut |_, _, block| {
                let s = slots.next().expect("one slot per block");
                let (base, stride) = (s.base as usize, s.stride as usize);
                for e in 0..3 {
                    let col = &mut values[base + e * stride..base + e * stride + 3];
                    for (r, v) in col.iter_mut().enumerate() {
                        *v += block[(r, e)];
                    }
                }
            });
        }
    }

    fn factorize(&mut self) -> bool {
        let pattern = &*self.pattern;
        let n = self.column.len();
        let csc =
            SymbolicSparseColMatRef::new_checked(n, n, &pattern.col_ptr, None, &pattern.row_idx);
        self.factored = pattern
            .symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.l_values,
                SparseColMatRef::new(csc, &self.values),
                Side::Lower,
                Default::default(),
                Par::Seq,
                MemStack::new(&mut self.stack),
                Default::default(),
            )
            .is_ok();
        self.factored
    }

    /// Rows (3 per node).
    pub(crate) fn dim(&self) -> usize {
        self.column.len()
    }

    /// `out = H^{-1} b` with the last successful factorization.
    pub(crate) fn solve(&mut self, b: &[Vec3], out: &mut [Vec3]) {
        debug_assert!(self.factored);
        for (c, v) in self.column.chunks_exact_mut(3).zip(b) {
            c.copy_from_slice(v.as_slice());
        }
        let n = self.column.len();
        LltRef::new(&self.pattern.symbolic, &self.l_values).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut self.column, n, 1),
            Par::Seq,
            MemStack::new(&mut self.stack),
        );
        for (o, c) in out.iter_mut().zip(self.column.chunks_exact(3)) {
            *o = Vec3::new(c[0], c[1], c[2]);
        }
    }
}
