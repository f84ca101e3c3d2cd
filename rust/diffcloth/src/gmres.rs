//! Right-preconditioned GMRES on node-major vectors (no restart), for the forward's contact
//! Newton (`forward/contact_newton.rs`): its operator is non-symmetric (friction, contacts
//! between cloth nodes). Sequential and deterministic; the basis lives in [`Gmres`] and is
//! allocated once per size.

use crate::Vec3;

fn dot(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

/// The Krylov basis and the preconditioned vector (reused across solves).
#[derive(Default)]
pub(crate) struct Gmres {
    basis: Vec<Vec<Vec3>>,
    z: Vec<Vec3>,
}

impl Gmres {
    /// Solves `A x = b` from `x = 0` with `A` applied by `apply(v, out)` and the preconditioner
    /// `M^{-1}` by `precondition(r, out)`, until the residual `|b - A x|` is below
    /// `relative |b|` or after `max_iterations`. Returns the iterations taken and the
    /// relative residual reached (GMRES minimizes it, so `x` is never worse than 0).
    pub(crate) fn solve(
        &mut self,
        b: &[Vec3],
        x: &mut [Vec3],
        relative: f64,
        max_iterations: usize,
        mut apply: impl FnMut(&[Vec3], &mut [Vec3]),
        mut precondition: impl FnMut(&[Vec3], &mut [Vec3]),
    ) -> (usize, f64) {
        let n = b.len();
        x.iter_mut().for_each(|v| *v = Vec3::zeros());
        let beta = dot(b, b).sqrt();
        if !(beta > 0.0 && beta.is_finite()) {
            return (0, 0.0);
        }
        while self.basis.len() < max_iterations + 1 {
            self.basis.push(Vec::new());
        }
        for v in &mut self.basis[..=max_iterations] {
            v.resize(n, Vec3::zeros());
        }
        self.z.resize(n, Vec3::zeros());
        for (v, bi) in self.basis[0].iter_mut().zip(b) {
            *v = bi / beta;
        }
        // Hessenberg columns, Givens rotations and the rotated right-hand side.
        let mut hess: Vec<Vec<f64>> = Vec::with_capacity(max_iterations);
        let (mut cs, mut sn): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
        let mut g = vec![0.0; max_iterations + 1];
        g[0] = beta;
        let mut k = 0;
        let mut residual = beta;
        while k < max_iterations && residual > relative * beta {
            precondition(&self.basis[k], &mut self.z);
            let (head, tail) = self.basis.split_at_mut(k + 1);
            let w = &mut tail[0];
            apply(&self.z, w);
            let mut col = vec![0.0; k + 2];
            // Modified Gram-Schmidt.
            for (i, v) in head.iter().enumerate() {
                col[i] = dot(w, v);
                for (wi, vi) in w.iter_mut().zip(v) {
                    *wi -= col[i] * vi;
                }
            }
            col[k + 1] = dot(w, w).sqrt();
            if col[k + 1] > 0.0 {
                let inv = 1.0 / col[k + 1];
                w.iter_mut().for_each(|wi| *wi *= inv);
            }
            for i in 0..k {
                let t = cs[i] * col[i] + sn[i] * col[i + 1];
                col[i + 1] = -sn[i] * col[i] + cs[i] * col[i + 1];
                col[i] = t;
            }
            let r = col[k].hypot(col[k + 1]);
            let (c, s) = if r > 0.0 {
                (col[k] / r, col[k + 1] / r)
            } else {
                (1.0, 0.0)
            };
            cs.push(c);
            sn.push(s);
            col[k] = r;
            col[k + 1] = 0.0;
            g[k + 1] = -s * g[k];
            g[k] *= c;
            residual = g[k + 1].abs();
            hess.push(col);
            k += 1;
            if hess[k - 1][k - 1] == 0.0 {
                break;
            }
        }
        // y = R^{-1} g, then x = M^{-1} (V y).
        let mut y = vec![0.0; k];
        for i in (0..k).rev() {
            let mut s = g[i];
            for (j, yj) in y.iter().enumerate().skip(i + 1) {
                s -= hess[j][i] * yj;
            }
            y[i] = if hess[i][i] != 0.0 {
                s / hess[i][i]
            } else {
                0.0
            };
        }
        let u = &mut self.z;
        u.iter_mut().for_each(|v| *v = Vec3::zeros());
        for (yi, v) in y.iter().zip(&self.basis) {
            for (ui, vi) in u.iter_mut().zip(v) {
                *ui += *yi * vi;
            }
        }
        precondition(u, x);
        (k, residual / beta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_nonsymmetric_system() {
        // A tridiagonal non-symmetric matrix, Jacobi-preconditioned.
        let n = 20;
        let apply = |v: &[Vec3], out: &mut [Vec3]| {
            for i in 0..n {
                let mut s = 4.0 * v[i];
                if i > 0 {
                    s -= 1.5 * v[i - 1];
                }
                if i + 1 < n {
                    s -= 0.5 * v[i + 1];
                }
                out[i] = s;
            }
        };
        let b: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(i as f64, 1.0, (i as f64).sin()))
            .collect();
        let mut x = vec![Vec3::zeros(); n];
        let mut gm = Gmres::default();
        let (it, rel) = gm.solve(&b, &mut x, 1e-12, 30, apply, |r, o| {
            o.iter_mut().zip(r).for_each(|(o, r)| *o = r / 4.0)
        });
        assert!(it <= 30 && rel <= 1e-12, "{it} {rel}");
        let mut ax = vec![Vec3::zeros(); n];
        apply(&x, &mut ax);
        let err: f64 = ax
            .iter()
            .zip(&b)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-10, "{err}");
    }
}
