//! In-plane stretch with strain limiting, one constraint per triangle.
//!
//! `A_i x = F = D_s D_m^{-1}` (3x2), `D_s = [x_1 - x_0, x_2 - x_0]`, `D_m` the rest edges in the
//! triangle's own 2D frame. The projection is `U clamp(Sigma, s_min, s_max) V^T`
//! (as-rigid-as-possible for `s_min = s_max = 1`), and `w_i = k_stretch * rest area`.

use super::{PdConstraints, Projections, Stiffness, PARALLEL_MIN_CONSTRAINTS};
use crate::mesh::TriMesh;
use crate::Vec3;
use nalgebra::{Matrix2, Matrix3, Matrix3x2, Vector2};
use rayon::prelude::*;

pub type Mat32 = Matrix3x2<f64>;

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
        let (lo, hi) = (self.strain_min, self.strain_max);
        // Triangles go in groups of LANES: their independent sqrt/div chains overlap and
        // vectorize, instead of one latency-bound chain after another.
        let work = |(group, (p, e)): (usize, (&mut [f64], &mut [f64]))| {
            let base = group * LANES;
            let mut f = [Mat32::zeros(); LANES];
            for (l, fl) in f.iter_mut().enumerate().take(e.len()) {
                *fl = self.deformation_gradient(base + l, x);
            }
            let projected = project_singular_values_lanes(&f, lo, hi);
            for l in 0..e.len() {
                p[6 * l..6 * l + 6].copy_from_slice(projected[l].as_slice());
                e[l] = 0.5 * self.weight[base + l] * (f[l] - projected[l]).norm_squared();
            }
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

/// Singular values `s1 >= s2 >= 0` and right singular vectors of a 3x2 matrix, in closed form
/// from the 2x2 eigenproblem of `F^T F = [[a, b], [b, c]]` (no trigonometry: this runs once per
/// triangle per PD iteration).
fn singular_2d(f: &Mat32) -> (f64, f64, Vector2<f64>, Vector2<f64>) {
    let (c0, c1) = (f.column(0), f.column(1));
    let (a, b, c) = (c0.dot(&c0), c0.dot(&c1), c1.dot(&c1));
    let half_trace = 0.5 * (a + c);
    let disc = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let (l1, l2) = (half_trace + disc, (half_trace - disc).max(0.0));
    // Eigenvector of l1: (l1 - c, b) or (b, l1 - a); take the better conditioned one.
    let (p, q) = (Vector2::new(l1 - c, b), Vector2::new(b, l1 - a));
    let v = if p.norm_squared() >= q.norm_squared() {
        p
    } else {
        q
    };
    let norm = v.norm();
    // An isotropic F^T F (norm = 0) has every direction as eigenvector.
    let v1 = if norm > 1e-300 {
        v / norm
    } else {
        Vector2::new(1.0, 0.0)
    };
    (l1.sqrt(), l2.sqrt(), v1, Vector2::new(-v1.y, v1.x))
}

/// Triangles projected together by [`project_singular_values_lanes`].
const LANES: usize = 4;

/// [`project_singular_values`] for `LANES` matrices at once, written lane by lane without
/// branches so the compiler vectorizes it; rank-deficient lanes fall back to the scalar path.
fn project_singular_values_lanes(f: &[Mat32; LANES], lo: f64, hi: f64) -> [Mat32; LANES] {
    let mut out = [Mat32::zeros(); LANES];
    let mut regular = [false; LANES];
    let (mut r1, mut r2, mut v1x, mut v1y) =
        ([0.0; LANES], [0.0; LANES], [0.0; LANES], [0.0; LANES]);
    for l in 0..LANES {
        let (c0, c1) = (f[l].column(0), f[l].column(1));
        let (a, b, c) = (c0.dot(&c0), c0.dot(&c1), c1.dot(&c1));
        let half_trace = 0.5 * (a + c);
        let disc = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        let (l1, l2) = (half_trace + disc, (half_trace - disc).max(0.0));
        let (px, py, qx, qy) = (l1 - c, b, b, l1 - a);
        let take_p = px * px + py * py >= qx * qx + qy * qy;
        let (vx, vy) = if take_p { (px, py) } else { (qx, qy) };
        let norm2 = vx * vx + vy * vy;
        let inv = if norm2 > 1e-300 {
            1.0 / norm2.sqrt()
        } else {
            0.0
        };
        let isotropic = norm2 <= 1e-300;
        v1x[l] = if isotropic { 1.0 } else { vx * inv };
        v1y[l] = if isotropic { 0.0 } else { vy * inv };
        let (s1, s2) = (l1.sqrt(), l2.sqrt());
        regular[l] = s2 > 1e-8 * s1;
        r1[l] = s1.clamp(lo, hi) / s1;
        r2[l] = s2.clamp(lo, hi) / s2;
    }
    for l in 0..LANES {
        if regular[l] {
            let v1 = Vector2::new(v1x[l], v1y[l]);
            out[l] = f[l] * r2[l] + (f[l] * v1) * ((r1[l] - r2[l]) * v1.transpose());
        } else {
            out[l] = project_singular_values(&f[l], lo, hi);
        }
    }
    out
}

/// Closest matrix to `f` (Frobenius) whose singular values lie in `[lo, hi]`:
/// `U clamp(Sigma, lo, hi) V^T`.
pub fn project_singular_values(f: &Mat32, lo: f64, hi: f64) -> Mat32 {
    let (s1, s2, v1, v2) = singular_2d(f);
    let (t1, t2) = (s1.clamp(lo, hi), s2.clamp(lo, hi));
    if s2 > 1e-8 * s1 {
        // F V diag(t / s) V^T = U diag(t) V^T without forming U; with V = [v1 v2] orthonormal,
        // V diag(r1, r2) V^T = r2 I + (r1 - r2) v1 v1^T.
        let (r1, r2) = (t1 / s1, t2 / s2);
        return f * r2 + (f * v1) * ((r1 - r2) * v1.transpose());
    }
    // Rank-deficient F (collapsed triangle): U's columns are not unique; complete them.
    let u1 = if s1 > 0.0 { f * v1 / s1 } else { Vec3::x() };
    let mut u2 = f * v2;
    u2 -= u1 * u1.dot(&u2);
    if u2.norm() <= 1e-12 * s1.max(1e-300) {
        let axis = u1.iamin();
        let mut e = Vec3::zeros();
        e[axis] = 1.0;
        u2 = e - u1 * u1[axis];
    }
    let u2 = u2.normalize();
    t1 * u1 * v1.transpose() + t2 * u2 * v2.transpose()
}

/// Jacobian of [`project_singular_values`] with respect to F, as a 6x6 matrix acting on F
/// flattened column by column (`[F[:,0]; F[:,1]]`). From the derivative of a singular-value
/// function of a 3x2 matrix: in the frame `dF^ = U^T dF V` (U completed to 3x3),
/// `dP^_ii = f'(s_i) dF^_ii`, the 2x2 off-diagonal block mixes the symmetric and
/// antisymmetric parts with `(f1 - f2) / (s1 - s2)` and `(f1 + f2) / (s1 + s2)`, and the third
/// row scales by `f_j / s_j`. Symmetric (a nearest-point projection).
pub fn projection_jacobian(f: &Mat32, lo: f64, hi: f64) -> [[f64; 6]; 6] {
    let (s1, s2, v1, v2) = singular_2d(f);
    let tiny = 1e-12 * s1.max(1e-300);
    let (s1c, s2c) = (s1.max(tiny), s2.max(tiny));
    let u1 = f * v1 / s1c;
    let mut u2 = f * v2;
    u2 -= u1 * u1.dot(&u2);
    let u2 = if u2.norm() > tiny {
        u2.normalize()
    } else {
        complete(&u1)
    };
    let u3 = u1.cross(&u2);
    let (f1, f2) = (s1.clamp(lo, hi), s2.clamp(lo, hi));
    let slope = |s: f64| if s > lo && s < hi { 1.0 } else { 0.0 };
    let (d1, d2) = (slope(s1), slope(s2));
    let diff = if (s1 - s2).abs() > 1e-10 * s1.max(1e-300) {
        (f1 - f2) / (s1 - s2)
    } else {
        0.5 * (d1 + d2)
    };
    let sum = (f1 + f2) / (s1c + s2c);
    let u = nalgebra::Matrix3::from_columns(&[u1, u2, u3]);
    let v = Matrix2::from_columns(&[v1, v2]);
    let mut jac = [[0.0; 6]; 6];
    for k in 0..6 {
        let mut df = Mat32::zeros();
        df[(k % 3, k / 3)] = 1.0;
        let h = u.transpose() * df * v;
        let mut dp = Mat32::zeros();
        dp[(0, 0)] = d1 * h[(0, 0)];
        dp[(1, 1)] = d2 * h[(1, 1)];
        let (a, b) = (h[(0, 1)], h[(1, 0)]);
        dp[(0, 1)] = 0.5 * sum * (a - b) + 0.5 * diff * (a + b);
        dp[(1, 0)] = -0.5 * sum * (a - b) + 0.5 * diff * (a + b);
        dp[(2, 0)] = f1 / s1c * h[(2, 0)];
        dp[(2, 1)] = f2 / s2c * h[(2, 1)];
        let out = u * dp * v.transpose();
        for r in 0..6 {
            jac[r][k] = out[(r % 3, r / 3)];
        }
    }
    jac
}

/// A unit vector orthogonal to `u`.
fn complete(u: &Vec3) -> Vec3 {
    let axis = u.iamin();
    let mut e = Vec3::zeros();
    e[axis] = 1.0;
    (e - u * u[axis]).normalize()
}

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
    fn projection_jacobian_matches_finite_differences() {
        for (seed, (lo, hi)) in (0..40).zip([(1.0, 1.0), (0.9, 1.1), (0.95, 1.3)].iter().cycle()) {
            let f = random_f(seed);
            let jac = projection_jacobian(&f, *lo, *hi);
            let eps = 1e-6;
            for k in 0..6 {
                let mut df = Mat32::zeros();
                df[(k % 3, k / 3)] = eps;
                let fd = (project_singular_values(&(f + df), *lo, *hi)
                    - project_singular_values(&(f - df), *lo, *hi))
                    / (2.0 * eps);
                for r in 0..6 {
                    assert!(
                        (fd[(r % 3, r / 3)] - jac[r][k]).abs() < 1e-6,
                        "seed {seed} [{r}][{k}]: {} vs {}",
                        jac[r][k],
                        fd[(r % 3, r / 3)]
                    );
                }
            }
            for r in 0..6 {
                for k in 0..6 {
                    assert!((jac[r][k] - jac[k][r]).abs() < 1e-10, "symmetric");
                }
            }
        }
    }

    fn random_f(seed: u64) -> Mat32 {
        let v = jitter(&[Vec3::zeros(), Vec3::zeros()], 1.5, seed);
        Mat32::from_columns(&[v[0], v[1]])
    }

    #[test]
    fn projection_matches_svd_and_is_closest() {
        for seed in 0..200 {
            let f = random_f(seed);
            let p = project_singular_values(&f, 0.9, 1.1);
            let svd = f.svd(true, true);
            let clamped = svd.singular_values.map(|s| s.clamp(0.9, 1.1));
            let expected = svd.u.unwrap() * Matrix2::from_diagonal(&clamped) * svd.v_t.unwrap();
            assert!(
                (p - expected).norm() < 1e-10 * (1.0 + f.norm()),
                "seed {seed}"
            );
            // Its singular values are inside the limits ...
            let sv = p.svd(false, false).singular_values;
            assert!(sv.iter().all(|&s| (0.9 - 1e-12..=1.1 + 1e-12).contains(&s)));
            // ... and no other member of the set we sample is closer.
            for k in 0..20 {
                let q = random_f(1000 + 20 * seed + k);
                let qs = q.svd(true, true);
                let member = qs.u.unwrap()
                    * Matrix2::from_diagonal(&qs.singular_values.map(|s| s.clamp(0.9, 1.1)))
                    * qs.v_t.unwrap();
                assert!((f - p).norm() <= (f - member).norm() + 1e-12);
            }
        }
    }

    #[test]
    fn lane_projection_matches_the_scalar_one() {
        for seed in 0..50 {
            let mut f = [0; LANES].map(|_| Mat32::zeros());
            for (l, fl) in f.iter_mut().enumerate() {
                *fl = random_f(7 * seed + l as u64);
            }
            // A collapsed lane and a zero lane take the fallback path.
            f[1] = Mat32::from_columns(&[Vec3::new(1.0, 2.0, 0.0), Vec3::new(2.0, 4.0, 0.0)]);
            f[2] = Mat32::zeros();
            let lanes = project_singular_values_lanes(&f, 0.9, 1.1);
            for l in 0..LANES {
                let scalar = project_singular_values(&f[l], 0.9, 1.1);
                assert!(
                    (lanes[l] - scalar).norm() < 1e-12 * (1.0 + scalar.norm()),
                    "seed {seed} lane {l}"
                );
            }
        }
    }

    #[test]
    fn projection_handles_collapsed_triangles() {
        let f = Mat32::from_columns(&[Vec3::new(1.0, 2.0, 0.0), Vec3::new(2.0, 4.0, 0.0)]);
        let p = project_singular_values(&f, 1.0, 1.0);
        assert!(p.iter().all(|v| v.is_finite()));
        let sv = p.svd(false, false).singular_values;
        assert!((sv[0] - 1.0).abs() < 1e-12 && (sv[1] - 1.0).abs() < 1e-12);
        let p0 = project_singular_values(&Mat32::zeros(), 1.0, 1.0);
        assert!((p0.transpose() * p0 - Matrix2::identity()).norm() < 1e-12);
    }

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
