//! Anderson acceleration (type II, Walker & Ni 2011) of the PD fixed-point map `x -> G(x)`,
//! as used for projective dynamics by Peng et al. 2018. Combined with an energy guard in the
//! forward solver (reject an extrapolation that does not lower the energy), it keeps PD's
//! monotone convergence while cutting the iteration count several-fold.

use crate::Vec3;

/// Longest history supported; the small normal equations live on the stack.
pub const MAX_HISTORY: usize = 8;

pub struct Anderson {
    history: usize,
    /// Ring buffers of residual differences `dF_j = f_{j+1} - f_j` and map differences `dG_j`.
    d_f: Vec<Vec<Vec3>>,
    d_g: Vec<Vec<Vec3>>,
    /// `gram[i][j] = dF_i . dF_j`, updated one column at a time.
    gram: [[f64; MAX_HISTORY]; MAX_HISTORY],
    columns: usize,
    next: usize,
    f_prev: Vec<Vec3>,
    g_prev: Vec<Vec3>,
    has_prev: bool,
}

impl Anderson {
    /// `history` is clamped to `1..=MAX_HISTORY`; buffers for `n` nodes are allocated here once.
    pub fn new(history: usize, n: usize) -> Self {
        let history = history.clamp(1, MAX_HISTORY);
        Self {
            history,
            d_f: vec![vec![Vec3::zeros(); n]; history],
            d_g: vec![vec![Vec3::zeros(); n]; history],
            gram: [[0.0; MAX_HISTORY]; MAX_HISTORY],
            columns: 0,
            next: 0,
            f_prev: vec![Vec3::zeros(); n],
            g_prev: vec![Vec3::zeros(); n],
            has_prev: false,
        }
    }

    /// Number of past iterates kept.
    pub fn history(&self) -> usize {
        self.history
    }

    pub fn reset(&mut self) {
        self.columns = 0;
        self.next = 0;
        self.has_prev = false;
    }

    /// Records the iterate's residual `f = G(x) - x` and map value `g = G(x)`.
    pub fn push(&mut self, f: &[Vec3], g: &[Vec3]) {
        if self.has_prev {
            let slot = self.next;
            for (((df, dg), (fi, gi)), (fp, gp)) in self.d_f[slot]
                .iter_mut()
                .zip(self.d_g[slot].iter_mut())
                .zip(f.iter().zip(g))
                .zip(self.f_prev.iter_mut().zip(self.g_prev.iter_mut()))
            {
                *df = fi - *fp;
                *dg = gi - *gp;
                (*fp, *gp) = (*fi, *gi);
            }
            self.columns = (self.columns + 1).min(self.history);
            self.next = (slot + 1) % self.history;
            let m = self.columns;
            let mut dots = [0.0; MAX_HISTORY];
            let cols: [&[Vec3]; MAX_HISTORY] = std::array::from_fn(|j| &self.d_f[j.min(m - 1)][..]);
            multi_dot(&self.d_f[slot], &cols[..m], &mut dots);
            for (j, &dot) in dots.iter().enumerate().take(m) {
                self.gram[slot][j] = dot;
                self.gram[j][slot] = dot;
            }
        } else {
            self.f_prev.copy_from_slice(f);
            self.g_prev.copy_from_slice(g);
        }
        self.has_prev = true;
    }

    /// Writes the extrapolated iterate `g - dG theta`, `theta = argmin |f - dF theta|`, into
    /// `out`. Returns false (and leaves `out` alone) when there is no usable history.
    pub fn extrapolate(&self, f: &[Vec3], g: &[Vec3], out: &mut [Vec3]) -> bool {
        let m = self.columns;
        if m == 0 {
            return false;
        }
        let mut a = [[0.0; MAX_HISTORY]; MAX_HISTORY];
        let mut theta = [0.0; MAX_HISTORY];
        let mut trace = 0.0;
        for i in 0..m {
            trace += self.gram[i][i];
        }
        // Tikhonov term: keeps the normal equations solvable when differences are collinear.
        let reg = 1e-12 * trace / m as f64 + f64::MIN_POSITIVE;
        for i in 0..m {
            a[i][..m].copy_from_slice(&self.gram[i][..m]);
            a[i][i] += reg;
        }
        let d_f: [&[Vec3]; MAX_HISTORY] = std::array::from_fn(|j| &self.d_f[j.min(m - 1)][..]);
        multi_dot(f, &d_f[..m], &mut theta);
        if !cholesky_solve(&mut a, &mut theta, m) {
            return false;
        }
        let d_g: [&[Vec3]; MAX_HISTORY] = std::array::from_fn(|j| &self.d_g[j.min(m - 1)][..]);
        sub_combination(g, &theta[..m], &d_g[..m], out);
        true
    }
}

// The history's passes over the nodes, one pass for all columns: a dot product is a chain
// of dependent additions (latency-bound, about 4 cycles a node), so `m` of them side by side
// cost about what one does. Each sum still runs in node order, and each output subtracts the
// columns in order: the same bits as one pass per column. `K` is a constant so the
// accumulators live in registers.

/// Calls `run::<K>(args)` with `K` the column count (1..=MAX_HISTORY).
macro_rules! by_columns {
    ($m:expr, $run:ident($($arg:expr),*)) => {
        match $m {
            1 => $run::<1>($($arg),*),
            2 => $run::<2>($($arg),*),
            3 => $run::<3>($($arg),*),
            4 => $run::<4>($($arg),*),
            5 => $run::<5>($($arg),*),
            6 => $run::<6>($($arg),*),
            7 => $run::<7>($($arg),*),
            8 => $run::<8>($($arg),*),
            m => unreachable!("{m} history columns"),
        }
    };
}

/// `out[j] = a . cols[j]` for every column.
fn multi_dot(a: &[Vec3], cols: &[&[Vec3]], out: &mut [f64; MAX_HISTORY]) {
    fn run<const K: usize>(a: &[Vec3], cols: &[&[Vec3]], out: &mut [f64; MAX_HISTORY]) {
        let cols: [&[Vec3]; K] = std::array::from_fn(|k| &cols[k][..a.len()]);
        let mut acc = [0.0; K];
        for (i, ai) in a.iter().enumerate() {
            for k in 0..K {
                acc[k] += cols[k][i].dot(ai);
            }
        }
        out[..K].copy_from_slice(&acc);
    }
    by_columns!(cols.len(), run(a, cols, out));
}

/// `out = g - sum_j theta_j cols[j]`.
fn sub_combination(g: &[Vec3], theta: &[f64], cols: &[&[Vec3]], out: &mut [Vec3]) {
    fn run<const K: usize>(g: &[Vec3], theta: &[f64], cols: &[&[Vec3]], out: &mut [Vec3]) {
        let cols: [&[Vec3]; K] = std::array::from_fn(|k| &cols[k][..g.len()]);
        for (i, (o, gi)) in out.iter_mut().zip(g).enumerate() {
            let mut v = *gi;
            for k in 0..K {
                v -= theta[k] * cols[k][i];
            }
            *o = v;
        }
    }
    by_columns!(cols.len(), run(g, theta, cols, out));
}

/// In-place Cholesky solve of the leading `m x m` block; false if not positive definite.
fn cholesky_solve(
    a: &mut [[f64; MAX_HISTORY]; MAX_HISTORY],
    b: &mut [f64; MAX_HISTORY],
    m: usize,
) -> bool {
    for j in 0..m {
        let mut d = a[j][j];
        for k in 0..j {
            d -= a[j][k] * a[j][k];
        }
        if !(d > 0.0) {
            return false;
        }
        let d = d.sqrt();
        a[j][j] = d;
        for i in j + 1..m {
            let mut s = a[i][j];
            for k in 0..j {
                s -= a[i][k] * a[j][k];
            }
            a[i][j] = s / d;
        }
    }
    for i in 0..m {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i][k] * b[k];
        }
        b[i] = s / a[i][i];
    }
    for i in (0..m).rev() {
        let mut s = b[i];
        for k in i + 1..m {
            s -= a[k][i] * b[k];
        }
        b[i] = s / a[i][i];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a linear contraction `G(x) = M x + c`, Anderson with enough history converges far
    /// faster than the plain iteration.
    #[test]
    fn accelerates_a_linear_fixed_point() {
        let n = 6;
        let rate = |i: usize| 0.5 + 0.49 * i as f64 / n as f64;
        let map = |x: &[Vec3], out: &mut [Vec3]| {
            for i in 0..n {
                out[i] = x[i] * rate(i) + Vec3::new(1.0, 2.0, 3.0);
            }
        };
        let solve = |accel: bool| {
            let mut aa = Anderson::new(6, n);
            let (mut x, mut g, mut f) = (
                vec![Vec3::zeros(); n],
                vec![Vec3::zeros(); n],
                vec![Vec3::zeros(); n],
            );
            for it in 0..2000 {
                map(&x, &mut g);
                for i in 0..n {
                    f[i] = g[i] - x[i];
                }
                if f.iter().map(|v| v.norm()).fold(0.0, f64::max) < 1e-10 {
                    return it;
                }
                aa.push(&f, &g);
                if !(accel && aa.extrapolate(&f, &g, &mut x)) {
                    x.copy_from_slice(&g);
                }
            }
            2000
        };
        let (plain, fast) = (solve(false), solve(true));
        assert!(fast * 10 < plain, "anderson {fast} vs plain {plain}");
    }
}
