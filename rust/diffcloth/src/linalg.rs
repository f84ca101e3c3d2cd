//! Factorizations as explicit objects: the PD system matrix `P_s` (m x m, scalar) is analysed
//! once (fill-reducing ordering + symbolic Cholesky), factored numerically when its values
//! change, and solved for the three coordinate columns together every PD iteration.

use crate::error::{Error, Result};
use crate::Vec3;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Par, Side};
use std::sync::Arc;

/// A symmetric positive-definite sparse matrix, kept factored as `L L^T`.
///
/// Solves take the caller's work rows, so one factor serves many simulators (a shared model)
/// and [`SpdFactor::solve_xyz`] allocates nothing.
pub struct SpdFactor {
    n: usize,
    /// Shared by copies (the pattern never changes with the values).
    symbolic: Arc<SymbolicCholesky<usize>>,
    l_values: Vec<f64>,
    matrix: SparseColMat<usize, f64>,
    scratch: MemBuffer,
    /// The same factor laid out for node-major gather solves (rebuilt on every numeric
    /// factorization, which is rare: the PD matrix is constant between parameter changes).
    nodes: NodeSolve,
    /// Numeric factorizations done for this factor (and the one it was copied from).
    factorizations: u64,
}

impl Clone for SpdFactor {
    fn clone(&self) -> Self {
        Self {
            n: self.n,
            symbolic: self.symbolic.clone(),
            l_values: self.l_values.clone(),
            matrix: self.matrix.clone(),
            scratch: MemBuffer::new(
                self.symbolic
                    .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            ),
            nodes: self.nodes.clone(),
            factorizations: self.factorizations,
        }
    }
}

/// `L` stored twice, strictly-lower rows (CSR, for `L y = b`) and strictly-lower columns (CSC,
/// for `L^T x = y`), with the fill-reducing permutation and the inverse diagonal.
///
/// Why not faer's solve: its column-oriented forward substitution scatters into the right-hand
/// side (three stores per factor entry), which bounds it by the store port. Both gather forms
/// here accumulate in registers, on `Vec3` rows, so the node-major PD state is solved without
/// transposing it into columns.
#[derive(Clone, Default)]
struct NodeSolve {
    perm: Vec<usize>,
    perm_inv: Vec<usize>,
    inv_diag: Vec<f64>,
    row_ptr: Vec<usize>,
    row_col: Vec<u32>,
    row_val: Vec<f64>,
    col_ptr: Vec<usize>,
    col_row: Vec<u32>,
    col_val: Vec<f64>,
}

impl NodeSolve {
    fn new(symbolic: &SymbolicCholesky<usize>, l_values: &[f64]) -> Option<Self> {
        let SymbolicCholeskyRaw::Simplicial(l) = symbolic.raw() else {
            return None;
        };
        let n = l.nrows();
        let (l_ptr, l_idx) = (l.col_ptr(), l.row_idx());
        let (perm, perm_inv) = match symbolic.perm() {
            Some(p) => (p.arrays().0.to_vec(), p.arrays().1.to_vec()),
            None => ((0..n).collect(), (0..n).collect()),
        };
        let mut s = Self {
            perm,
            perm_inv,
            inv_diag: vec![0.0; n],
            col_ptr: vec![0; n + 1],
            row_ptr: vec![0; n + 1],
            ..Default::default()
        };
        // Columns: the diagonal entry comes first in each of faer's simplicial columns.
        for j in 0..n {
            let (start, end) = (l_ptr[j], l_ptr[j + 1]);
            debug_assert_eq!(l_idx[start], j);
            s.inv_diag[j] = 1.0 / l_values[start];
            for k in start + 1..end {
                s.col_row.push(l_idx[k] as u32);
                s.col_val.push(l_values[k]);
                s.row_ptr[l_idx[k] + 1] += 1;
            }
            s.col_ptr[j + 1] = s.col_row.len();
        }
        // Rows: a counting-sort transpose of the strictly-lower part.
        for i in 0..n {
            s.row_ptr[i + 1] += s.row_ptr[i];
        }
        let mut next = s.row_ptr.clone();
        s.row_col = vec![0; s.col_row.len()];
        s.row_val = vec![0.0; s.col_row.len()];
        for j in 0..n {
            for k in s.col_ptr[j]..s.col_ptr[j + 1] {
                let i = s.col_row[k] as usize;
                s.row_col[next[i]] = j as u32;
                s.row_val[next[i]] = s.col_val[k];
                next[i] += 1;
            }
        }
        Some(s)
    }

    /// `out = P^{-1} b` through `y` (n work rows).
    fn solve(&self, b: &[Vec3], out: &mut [Vec3], y: &mut [Vec3]) {
        self.solve_permuted(b, y);
        for (o, &p) in out.iter_mut().zip(&self.perm_inv) {
            *o = y[p];
        }
    }

    /// `y = Q P^{-1} b` (the solution in the factor's ordering `Q`).
    fn solve_permuted(&self, b: &[Vec3], y: &mut [Vec3]) {
        for (yi, &p) in y.iter_mut().zip(&self.perm) {
            *yi = b[p];
        }
        // L y = b: row i gathers the solved y_j, j < i. Two accumulators halve the FMA chain.
        for i in 0..y.len() {
            let (cols, vals) = (
                &self.row_col[self.row_ptr[i]..self.row_ptr[i + 1]],
                &self.row_val[self.row_ptr[i]..self.row_ptr[i + 1]],
            );
            let (acc0, acc1) = gather(cols, vals, y);
            y[i] = (y[i] - acc0 - acc1) * self.inv_diag[i];
        }
        // L^T x = y: row j of L^T is column j of L (rows i > j, already solved).
        for j in (0..y.len()).rev() {
            let (rows, vals) = (
                &self.col_row[self.col_ptr[j]..self.col_ptr[j + 1]],
                &self.col_val[self.col_ptr[j]..self.col_ptr[j + 1]],
            );
            let (acc0, acc1) = gather(rows, vals, y);
            y[j] = (y[j] - acc0 - acc1) * self.inv_diag[j];
        }
    }
}

/// `(sum over even k, sum over odd k)` of `vals[k] * y[idx[k]]`.
#[inline(always)]
fn gather(idx: &[u32], vals: &[f64], y: &[Vec3]) -> (Vec3, Vec3) {
    let (mut a0, mut a1) = (Vec3::zeros(), Vec3::zeros());
    for (i, v) in idx.chunks_exact(2).zip(vals.chunks_exact(2)) {
        a0 += v[0] * y[i[0] as usize];
        a1 += v[1] * y[i[1] as usize];
    }
    if idx.len() % 2 == 1 {
        a0 += vals[idx.len() - 1] * y[idx[idx.len() - 1] as usize];
    }
    (a0, a1)
}

impl SpdFactor {
    /// Analyses and factors the matrix given by triplets (duplicates are summed; both
    /// triangles may be given, only the lower one is read).
    pub fn new(n: usize, triplets: &[(usize, usize, f64)]) -> Result<Self> {
        let matrix = assemble(n, triplets)?;
        let symbolic = factorize_symbolic_cholesky(
            matrix.symbolic(),
            Side::Lower,
            SymmetricOrdering::Amd,
            // Simplicial: at cloth sizes faer's supernodal solve was measured slower (Hat: 68
            // vs 51 us per 3-column solve), and the node-major gather solve below (34 us)
            // reads the simplicial columns.
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SIMPLICIAL,
                ..Default::default()
            },
        )
        .map_err(|e| Error::Solver(format!("symbolic Cholesky: {e:?}")))?;
        let scratch = MemBuffer::new(
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
        );
        let mut factor = Self {
            n,
            l_values: vec![0.0; symbolic.len_val()],
            symbolic: Arc::new(symbolic),
            matrix,
            scratch,
            nodes: NodeSolve::default(),
            factorizations: 0,
        };
        factor.factor_numeric()?;
        Ok(factor)
    }

    /// Replaces the values (same sparsity pattern expected) and refactors numerically,
    /// reusing the symbolic analysis when the pattern is unchanged.
    pub fn refactor(&mut self, triplets: &[(usize, usize, f64)]) -> Result<()> {
        let matrix = assemble(self.n, triplets)?;
        let same_pattern = matrix.symbolic().col_ptr() == self.matrix.symbolic().col_ptr()
            && matrix.symbolic().row_idx() == self.matrix.symbolic().row_idx();
        if !same_pattern {
            *self = Self::new(self.n, triplets)?;
            return Ok(());
        }
        self.matrix = matrix;
        self.factor_numeric()
    }

    fn factor_numeric(&mut self) -> Result<()> {
        self.symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.l_values,
                self.matrix.as_ref(),
                Side::Lower,
                Default::default(),
                Par::Seq,
                MemStack::new(&mut self.scratch),
                Default::default(),
            )
            .map_err(|e| Error::Solver(format!("system matrix is not positive definite: {e:?}")))?;
        self.nodes = NodeSolve::new(&self.symbolic, &self.l_values)
            .ok_or_else(|| Error::Solver("expected a simplicial Cholesky factor".into()))?;
        self.factorizations += 1;
        Ok(())
    }

    /// Stored values of the Cholesky factor and whether it is supernodal (for reports).
    pub fn factor_stats(&self) -> (usize, bool) {
        (
            self.symbolic.len_val(),
            matches!(self.symbolic.raw(), SymbolicCholeskyRaw::Supernodal(_)),
        )
    }

    /// Numeric factorizations so far (copies count their original's).
    pub fn factorizations(&self) -> u64 {
        self.factorizations
    }

    pub fn dim(&self) -> usize {
        self.n
    }

    /// The assembled matrix (both triangles as given).
    pub fn matrix(&self) -> &SparseColMat<usize, f64> {
        &self.matrix
    }

    /// Solves `P_s X = B` in place for the n x 3 right-hand side stored as one `Vec3` per node.
    /// `work` holds n rows.
    pub fn solve_xyz(&self, rhs: &mut [Vec3], work: &mut [Vec3]) {
        debug_assert_eq!(rhs.len(), self.n);
        self.nodes.solve_permuted(rhs, work);
        for (r, &p) in rhs.iter_mut().zip(&self.nodes.perm_inv) {
            *r = work[p];
        }
    }

    /// `out = P_s^{-1} b` per coordinate, node-major, without touching internal buffers (so
    /// one factor can precondition several solves); `work` holds n rows. No allocation.
    pub fn solve_nodes_into(&self, b: &[Vec3], out: &mut [Vec3], work: &mut [Vec3]) {
        self.nodes.solve(b, out, work);
    }

    /// `out = P_s x` (per coordinate). The matrix is stored with both triangles, so column i
    /// is row i: gathering along it keeps the sums in registers.
    pub fn mul_xyz(&self, x: &[Vec3], out: &mut [Vec3]) {
        let m = self.matrix.as_ref();
        for (i, o) in out.iter_mut().enumerate() {
            *o = m
                .row_idx_of_col(i)
                .zip(m.val_of_col(i))
                .map(|(j, &val)| val * x[j])
                .sum();
        }
    }
}

fn assemble(n: usize, triplets: &[(usize, usize, f64)]) -> Result<SparseColMat<usize, f64>> {
    let entries: Vec<Triplet<usize, usize, f64>> = triplets
        .iter()
        .map(|&(r, c, v)| Triplet::new(r, c, v))
        .collect();
    SparseColMat::try_new_from_triplets(n, n, &entries)
        .map_err(|e| Error::Solver(format!("cannot assemble system matrix: {e:?}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::linalg::cholesky::LltRef;
    use faer::{Conj, Mat};

    #[test]
    fn gather_solve_matches_faer_on_a_reordered_grid() {
        // A 2-ring grid stencil (like bending) on 9x9 nodes: AMD reorders it and L fills in.
        let (w, n) = (9usize, 81usize);
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, 30.0));
            for j in 0..n {
                let (dx, dy) = ((i % w).abs_diff(j % w), (i / w).abs_diff(j / w));
                if i != j && dx <= 2 && dy <= 2 {
                    t.push((i, j, -1.0 / (1 + dx + dy) as f64));
                }
            }
        }
        let f = SpdFactor::new(n, &t).unwrap();
        assert!(f.nodes.perm.iter().enumerate().any(|(i, &p)| i != p));
        let b: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new((i as f64).sin(), (0.3 * i as f64).cos(), 1.0))
            .collect();
        let (mut x, mut work) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
        f.solve_nodes_into(&b, &mut x, &mut work);
        let mut cols = Mat::<f64>::from_fn(n, 3, |i, c| b[i][c]);
        let mut stack = MemBuffer::new(f.symbolic.solve_in_place_scratch::<f64>(3, Par::Seq));
        LltRef::new(&f.symbolic, &f.l_values).solve_in_place_with_conj(
            Conj::No,
            cols.as_mut(),
            Par::Seq,
            MemStack::new(&mut stack),
        );
        for (i, xi) in x.iter().enumerate() {
            for c in 0..3 {
                assert!((xi[c] - cols[(i, c)]).abs() < 1e-14 * (1.0 + cols[(i, c)].abs()));
            }
        }
    }

    #[test]
    fn solves_a_small_spd_system() {
        // 1D Laplacian + identity, 5 nodes.
        let n = 5;
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, 3.0));
            if i + 1 < n {
                t.push((i, i + 1, -1.0));
                t.push((i + 1, i, -1.0));
            }
        }
        let mut f = SpdFactor::new(n, &t).unwrap();
        let x: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(i as f64, 1.0, -(i as f64).powi(2)))
            .collect();
        let mut b = vec![Vec3::zeros(); n];
        f.mul_xyz(&x, &mut b);
        f.solve_xyz(&mut b, &mut vec![Vec3::zeros(); f.dim()]);
        for (a, e) in b.iter().zip(&x) {
            assert!((a - e).norm() < 1e-12);
        }
        // Non-SPD values are reported, not panicked on.
        let bad: Vec<_> = t
            .iter()
            .map(|&(r, c, v)| (r, c, if r == c { -v } else { v }))
            .collect();
        assert!(f.refactor(&bad).is_err());
    }
}
