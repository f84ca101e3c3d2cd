//! In-plane stretch with strain limiting, one constraint per triangle.
//!
//! `A_i x = F = D_s D_m^{-1}` (3x2), `D_s = [x_1 - x_0, x_2 - x_0]`, `D_m` the rest edges in the
//! triangle's own 2D frame. The projection is `U clamp(Sigma, s_min, s_max) V^T`
//! (as-rigid-as-possible for `s_min = s_max = 1`), and `w_i = k_stretch * rest area`.

use super::polar::{
    lane, project_rigid_group, project_singular_values, project_singular_values_lanes,
    projection_jacobian, set_lane, singular_2d, Group, Mat32, LANES,
};
use super::{PdConstraints, Projections, Stiffness, PARALLEL_MIN_CONSTRAINTS};
use crate::mesh::TriMesh;
use crate::Vec3;
use nalgebra::{Matrix2, Matrix3, Vector2};
use rayon::prelude::*;

#[derive(Debug, Clone)]
pub struct Stretch {
    triangles: Vec<[usize; 3]>,
    /// `F = sum_l x_l b_l^T`: row `l` of `[[-1,-1],[1,0],[0,1]] D_m^{-1}`.
    shape: Vec<[Vector2<f64>; 3]>,
    rest_area: Vec<f64>,
    weight: Vec<f64>,
    strain_min: f64,
    strain_max: f64,
}

impl Stretch {
    pub fn new(mesh: &TriMesh, k_stretch: f64, strain_min: f64, strain_max: f64) -> Self {
        let mut shape = Vec::with_capacity(mesh.triangles.len());
        let mut rest_area = Vec::with_capacity(mesh.triangles.len());
        for tri in &mesh.triangles {
            let [x0, x1, x2] = tri.map(|i| mesh.positions[i]);
            let (e1, e2) = (x1 - x0, x2 - x0);
            let u = e1.normalize();
            let normal = e1.cross(&e2).normalize();
            let w = normal.cross(&u);
            // Rest edges in the triangle's own orthonormal frame (u, w).
            let dm = Matrix2::new(e1.norm(), e2.dot(&u), 0.0, e2.dot(&w));
            let dm_inv = dm
                .try_inverse()
                .expect("TriMesh::new rejects degenerate triangles");
            let b = |r: Vector2<f64>| (r.transpose() * dm_inv).transpose();
            shape.push([
                b(Vector2::new(-1.0, -1.0)),
                b(Vector2::new(1.0, 0.0)),
                b(Vector2::new(0.0, 1.0)),
            ]);
            rest_area.push(0.5 * dm[(0, 0)] * dm[(1, 1)].abs());
        }
        let n = mesh.triangles.len();
        let mut s = Self {
            triangles: mesh.triangles.clone(),
            shape,
            weight: vec![0.0; n],
            rest_area,
            strain_min,
            strain_max,
        };
        s.set_stiffness(k_stretch);
        s
    }

    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Deformation gradient of triangle `t` at `x`.
    pub fn deformation_gradient(&self, t: usize, x: &[Vec3]) -> Mat32 {
        let tri = &self.triangles[t];
        let b = &self.shape[t];
        let mut f = Mat32::zeros();
        for l in 0..3 {
            f += x[tri[l]] * b[l].transpose();
        }
        f
    }

    /// Deformation gradients of triangles `base..base + n` (`n <= LANES`; the other lanes
    /// zero), each as [`Stretch::deformation_gradient`] computes it.
    fn deformation_gradients(&self, base: usize, n: usize, x: &[Vec3]) -> Group {
        let mut f: Group = [[0.0; LANES]; 6];
        let tris = self.triangles[base..base + n]
            .iter()
            .zip(&self.shape[base..base + n]);
        for (l, (tri, b)) in tris.enumerate() {
            let [p0, p1, p2] = tri.map(|i| x[i]);
            for k in 0..2 {
                for r in 0..3 {
                    f[3 * k + r][l] = p0[r] * b[0][k] + p1[r] * b[1][k] + p2[r] * b[2][k];
                }
            }
        }
        f
    }

    /// Projects one group of triangles (`base..base + n`) at `x` into `p` (6 floats each,
    /// column-major) and their energies into `e`.
    fn project_group(&self, base: usize, x: &[Vec3], p: &mut [f64], e: &mut [f64]) {
        let (lo, hi) = (self.strain_min, self.strain_max);
        let n = e.len();
        let f = self.deformation_gradients(base, n, x);
        let mut q: Group = [[0.0; LANES]; 6];
        if lo == hi {
            let regular = project_rigid_group(&f, lo, &mut q);
            for l in (0..n).filter(|&l| !regular[l]) {
                set_lane(&mut q, l, &project_singular_values(&lane(&f, l), lo, hi));
            }
        } else {
            let projected =
                project_singular_values_lanes(&std::array::from_fn(|l| lane(&f, l)), lo, hi);
            for (l, m) in projected.iter().enumerate() {
                set_lane(&mut q, l, m);
            }
        }
        let mut sq = [0.0; LANES];
        for k in 0..6 {
            for l in 0..LANES {
                let r = f[k][l] - q[k][l];
                sq[l] += r * r;
            }
        }
        for l in 0..n {
            for k in 0..6 {
                p[6 * l + k] = q[k][l];
            }
            e[l] = 0.5 * self.weight[base + l] * sq[l];
        }
    }

    /// Singular values of every triangle's deformation gradient at `x` (principal stretches).
    pub fn principal_stretches(&self, x: &[Vec3]) -> Vec<(f64, f64)> {
        (0..self.len())
            .map(|t| {
                let (s1, s2, _, _) = singular_2d(&self.deformation_gradient(t, x));
                (s1, s2)
            })
            .collect()
    }
}

impl PdConstraints for Stretch {
    fn add_system_triplets(&self, out: &mut Vec<(usize, usize, f64)>) {
        for ((tri, b), &w) in self.triangles.iter().zip(&self.shape).zip(&self.weight) {
            for a in 0..3 {
                for c in 0..3 {
                    out.push((tri[a], tri[c], w * b[a].dot(&b[c])));
                }
            }
        }
    }

    fn new_projections(&self) -> Projections {
        Projections::new(self.len(), 6)
    }

    fn project(&self, x: &[Vec3], parallel: bool, out: &mut Projections) -> f64 {
        let work = |(group, (p, e)): (usize, (&mut [f64], &mut [f64]))| {
            self.project_group(group * LANES, x, p, e)
        };
        let Projections { values, energy } = out;
        if parallel && energy.len() >= PARALLEL_MIN_CONSTRAINTS {
            values
                .par_chunks_mut(6 * LANES)
                .zip(energy.par_chunks_mut(LANES))
                .enumerate()
                .for_each(work);
        } else {
            values
                .chunks_mut(6 * LANES)
                .zip(energy.chunks_mut(LANES))
                .enumerate()
                .for_each(work);
        }
        // Serial sum: bitwise identical whatever the thread count.
        energy.iter().sum()
    }

    fn add_rhs(&self, projections: &Projections, rhs: &mut [Vec3]) {
        let p = projections.values.chunks_exact(6);
        for ((t, tri), p) in self.triangles.iter().enumerate().zip(p) {
            let wp = self.weight[t] * Mat32::from_column_slice(p);
            for l in 0..3 {
                rhs[tri[l]] += wp * self.shape[t][l];
            }
        }
    }

    fn boxed_clone(&self) -> Box<dyn PdConstraints> {
        Box::new(self.clone())
    }

    fn stiffness(&self) -> Stiffness {
        Stiffness::Stretch
    }

    fn set_stiffness(&mut self, k_stretch: f64) {
        for (w, a) in self.weight.iter_mut().zip(&self.rest_area) {
            *w = k_stretch * a;
        }
    }

    fn linearization_len(&self) -> usize {
        JACOBIAN_LEN * self.len()
    }

    /// Per triangle, `w dP/dF` (6x6, row-major, on F flattened column by column).
    fn linearize(&self, x: &[Vec3], lin: &mut [f64]) {
        let (lo, hi) = (self.strain_min, self.strain_max);
        for (t, out) in lin.chunks_exact_mut(JACOBIAN_LEN).enumerate() {
            let j = projection_jacobian(&self.deformation_gradient(t, x), lo, hi);
            let w = self.weight[t];
            for (o, e) in out.iter_mut().zip(j.iter().flatten()) {
                *o = w * e;
            }
        }
    }

    fn sub_dp(&self, lin: &[f64], v: &[Vec3], out: &mut [Vec3]) {
        let rows = self.triangles.iter().zip(&self.shape);
        for ((tri, b), j) in rows.zip(lin.chunks_exact(JACOBIAN_LEN)) {
            // dF = [v] B (3x2, columns f0 and f1); q = (w J) vec(dF); out -= q B^T.
            let [va, vb, vc] = tri.map(|k| v[k]);
            let f0 = va * b[0][0] + vb * b[1][0] + vc * b[2][0];
            let f1 = va * b[0][1] + vb * b[1][1] + vc * b[2][1];
            let df = [f0.x, f0.y, f0.z, f1.x, f1.y, f1.z];
            let q: [f64; 6] = std::array::from_fn(|r| (0..6).map(|k| j[6 * r + k] * df[k]).sum());
            let (q0, q1) = (Vec3::new(q[0], q[1], q[2]), Vec3::new(q[3], q[4], q[5]));
            for (l, &k) in tri.iter().enumerate() {
                out[k] -= q0 * b[l][0] + q1 * b[l][1];
            }
        }
    }

    fn add_neg_dp_triplets(&self, lin: &[f64], out: &mut Vec<(usize, usize, f64)>) {
        let rows = self.triangles.iter().zip(&self.shape);
        for ((tri, b), j) in rows.zip(lin.chunks_exact(JACOBIAN_LEN)) {
            for l in 0..3 {
                for m in 0..3 {
                    for c in 0..3 {
                        for e in 0..3 {
                            let mut val = 0.0;
                            for kk in 0..2 {
                                for mm in 0..2 {
                                    val += b[l][kk] * j[6 * (c + 3 * kk) + e + 3 * mm] * b[m][mm];
                                }
                            }
                            out.push((3 * tri[l] + c, 3 * tri[m] + e, -val));
                        }
                    }
                }
            }
        }
    }

    fn for_each_neg_dp_block(
        &self,
        lin: &[f64],
        emit: &mut dyn FnMut(usize, usize, &Matrix3<f64>),
    ) {
        let rows = self.triangles.iter().zip(&self.shape);
        for ((tri, b), j) in rows.zip(lin.chunks_exact(JACOBIAN_LEN)) {
            // (w J) in 3x3 blocks J_km (row block k, column block m of the 6x6 on vec F).
            let jb = |k: usize, m: usize| Matrix3::from_fn(|c, e| j[6 * (c + 3 * k) + e + 3 * m]);
            let blocks = [jb(0, 0), jb(0, 1), jb(1, 0), jb(1, 1)];
            for l in 0..3 {
                for m in 0..3 {
                    let (bl, bm) = (b[l], b[m]);
                    let block = blocks[0] * (bl[0] * bm[0])
                        + blocks[1] * (bl[0] * bm[1])
                        + blocks[2] * (bl[1] * bm[0])
                        + blocks[3] * (bl[1] * bm[1]);
                    emit(tri[l], tri[m], &-block);
                }
            }
        }
    }

    /// `grad W = sum_t k a_t (F - P(F)) b_l` per corner, so d/dk drops the k.
    fn stiffness_dot(&self, x: &[Vec3], z: &[Vec3]) -> f64 {
        let (lo, hi) = (self.strain_min, self.strain_max);
        let mut dot = 0.0;
        for (t, tri) in self.triangles.iter().enumerate() {
            let f = self.deformation_gradient(t, x);
            let r = (f - project_singular_values(&f, lo, hi)) * self.rest_area[t];
            for l in 0..3 {
                dot += z[tri[l]].dot(&(r * self.shape[t][l]));
            }
        }
        dot
    }
}

/// Floats of one triangle's weighted projection Jacobian (6x6).
const JACOBIAN_LEN: usize = 36;

impl Stretch {
    pub fn triangles(&self) -> &[[usize; 3]] {
        &self.triangles
    }
    /// The selector rows `b_l` of triangle `t` (`F = sum_l x_l b_l^T`).
    pub fn shape(&self, t: usize) -> &[Vector2<f64>; 3] {
        &self.shape[t]
    }
    /// Every triangle's [`Stretch::shape`].
    pub fn shapes(&self) -> &[[Vector2<f64>; 3]] {
        &self.shape
    }
    pub fn weight(&self, t: usize) -> f64 {
        self.weight[t]
    }
    pub fn rest_area(&self, t: usize) -> f64 {
        self.rest_area[t]
    }
    pub fn strain_limits(&self) -> (f64, f64) {
        (self.strain_min, self.strain_max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::testing::*;
    use crate::mesh::{grid, GridPlane};

    #[test]
    fn rest_shape_has_identity_stretch_and_zero_energy() {
        let mesh = grid(4, 5, 2.0, 1.0, GridPlane::Xy).unwrap();
        let s = Stretch::new(&mesh, 100.0, 1.0, 1.0);
        assert!(energy(&s, &mesh.positions) < 1e-20);
        for (s1, s2) in s.principal_stretches(&mesh.positions) {
            assert!((s1 - 1.0).abs() < 1e-12 && (s2 - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn energy_gradient_matches_finite_differences() {
        let mesh = grid(4, 4, 1.0, 1.0, GridPlane::Xz).unwrap();
        let x = jitter(&mesh.positions, 0.15, 7);
        let mut arap = Stretch::new(&mesh, 30.0, 1.0, 1.0);
        check_gradient_fd(&mut arap, &x, 1e-6);
        let mut limited = Stretch::new(&mesh, 30.0, 0.95, 1.05);
        check_gradient_fd(&mut limited, &x, 1e-6);
        check_backward_fd(&mut arap, 100.0, &x, 1e-5);
        check_backward_fd(&mut limited, 100.0, &x, 1e-5);
        // Translation invariance: the selector rows sum to zero (momentum conservation).
        let shifted: Vec<Vec3> = x.iter().map(|p| p + Vec3::new(3.0, -1.0, 2.0)).collect();
        let (e0, _) = gradient(&mut arap, &x);
        let (e1, _) = gradient(&mut arap, &shifted);
        assert!((e0 - e1).abs() < 1e-10 * e0.max(1.0));
    }
}
