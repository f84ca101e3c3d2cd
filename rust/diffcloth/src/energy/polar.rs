//! Closed-form projections of 3x2 matrices (triangle deformation gradients) onto sets of
//! singular values, and their Jacobian: the stretch constraint's local step
//! ([`super::Stretch`]) and backward half. Everything is in closed form from the 2x2
//! eigenproblem of `F^T F`: no iterative SVD, no trigonometry (this runs once per triangle per
//! PD iteration).

use crate::Vec3;
use nalgebra::{Matrix2, Matrix3x2, Vector2};

pub type Mat32 = Matrix3x2<f64>;

/// Triangles projected together: their independent sqrt/div chains overlap and vectorize,
/// instead of one latency-bound chain after another.
pub(crate) const LANES: usize = 8;

/// A group of `LANES` 3x2 matrices as structure of arrays: entry `k` (column-major) of lane
/// `l` at `[k][l]`.
pub(crate) type Group = [[f64; LANES]; 6];

/// Singular values `s1 >= s2 >= 0` and right singular vectors of a 3x2 matrix, in closed form
/// from the 2x2 eigenproblem of `F^T F = [[a, b], [b, c]]` (no trigonometry: this runs once per
/// triangle per PD iteration).
pub(crate) fn singular_2d(f: &Mat32) -> (f64, f64, Vector2<f64>, Vector2<f64>) {
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

/// [`project_singular_values`] for `LANES` matrices at once, written lane by lane without
/// branches so the compiler vectorizes it; rank-deficient lanes fall back to the scalar path.
pub(crate) fn project_singular_values_lanes(
    f: &[Mat32; LANES],
    lo: f64,
    hi: f64,
) -> [Mat32; LANES] {
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

/// [`project_singular_values`] with `lo = hi = s` for a group of matrices: `s U V^T =
/// s F (F^T F)^{-1/2}`, where the 2x2 inverse square root has a closed form with one division:
/// with `d = sqrt(det C) = s1 s2` and `t = sqrt(tr C + 2 d) = s1 + s2`,
/// `C^{-1/2} = adj(C + d I) / (d t)`. Two square roots per matrix instead of four, one
/// division instead of three, no eigenvector, no branch (so the lanes vectorize);
/// `d = |c0 x c1|` (Lagrange's identity) keeps `det C` free of cancellation on thin triangles.
/// Writes `p` and returns which lanes are regular: nearly rank-deficient ones (where `1/d`
/// loses digits) must take [`project_singular_values`] instead.
pub(crate) fn project_rigid_group(f: &Group, s: f64, p: &mut Group) -> [bool; LANES] {
    let mut regular = [false; LANES];
    for l in 0..LANES {
        let [x0, y0, z0, x1, y1, z1] = std::array::from_fn::<f64, 6, _>(|k| f[k][l]);
        let a = x0 * x0 + y0 * y0 + z0 * z0;
        let b = x0 * x1 + y0 * y1 + z0 * z1;
        let c = x1 * x1 + y1 * y1 + z1 * z1;
        let (nx, ny, nz) = (y0 * z1 - z0 * y1, z0 * x1 - x0 * z1, x0 * y1 - y0 * x1);
        let d = (nx * nx + ny * ny + nz * nz).sqrt();
        let t = (a + c + 2.0 * d).sqrt();
        regular[l] = d > 1e-8 * (a + c);
        let inv = s / (d * t);
        let (m00, m01, m11) = ((c + d) * inv, -b * inv, (a + d) * inv);
        p[0][l] = x0 * m00 + x1 * m01;
        p[1][l] = y0 * m00 + y1 * m01;
        p[2][l] = z0 * m00 + z1 * m01;
        p[3][l] = x0 * m01 + x1 * m11;
        p[4][l] = y0 * m01 + y1 * m11;
        p[5][l] = z0 * m01 + z1 * m11;
    }
    regular
}

/// Lane `l` of a group as a matrix.
pub(crate) fn lane(g: &Group, l: usize) -> Mat32 {
    Mat32::from_fn(|r, c| g[3 * c + r][l])
}

/// Sets lane `l` of a group.
pub(crate) fn set_lane(g: &mut Group, l: usize, m: &Mat32) {
    for (k, v) in m.iter().enumerate() {
        g[k][l] = *v;
    }
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
#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::testing::jitter;

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
    fn rigid_group_matches_the_scalar_projection() {
        let mut fallbacks = 0;
        for seed in 0..50 {
            let mut f: Group = [[0.0; LANES]; 6];
            for l in 0..LANES {
                set_lane(&mut f, l, &random_f(11 * seed + l as u64));
            }
            // Thin, nearly collapsed, collapsed, zero and tiny lanes.
            let thin = Mat32::from_columns(&[Vec3::new(1.0, 2.0, 0.0), Vec3::new(2.0, 4.0, 1e-5)]);
            set_lane(&mut f, 1, &thin);
            set_lane(
                &mut f,
                2,
                &Mat32::from_columns(&[thin.column(0).into(), Vec3::new(2.0, 4.0, 1e-9)]),
            );
            set_lane(
                &mut f,
                3,
                &Mat32::from_columns(&[thin.column(0).into(), Vec3::new(2.0, 4.0, 0.0)]),
            );
            set_lane(&mut f, 4, &Mat32::zeros());
            set_lane(&mut f, 5, &(random_f(seed) * 1e-3));
            for s in [1.0, 0.8] {
                let mut p: Group = [[0.0; LANES]; 6];
                let regular = project_rigid_group(&f, s, &mut p);
                assert!(regular[1] && !regular[2] && !regular[3] && !regular[4] && regular[5]);
                for l in (0..LANES).filter(|&l| regular[l]) {
                    let (fl, pl) = (lane(&f, l), lane(&p, l));
                    // The polar factor's defining properties: orthonormal columns (times s)
                    // and P^T F symmetric positive semi-definite. They hold to round-off even
                    // on the thin lane, where the eigenvector route of the scalar path loses
                    // digits (lane 1: 4e-8 there, 4e-11 here, against 50-digit arithmetic).
                    // Both lose digits in proportion to s1 / s2 (lane 1: 1.1e6).
                    let sv = fl.svd(false, false).singular_values;
                    let tol = 1e-13 + 1e-15 * sv[0] / sv[1];
                    let gram = pl.transpose() * pl - s * s * Matrix2::identity();
                    assert!(
                        gram.norm() < tol,
                        "seed {seed} lane {l}: P^T P - s^2 I = {gram}"
                    );
                    let h = pl.transpose() * fl;
                    let asym = (h[(0, 1)] - h[(1, 0)]).abs();
                    assert!(
                        asym < tol * fl.norm(),
                        "seed {seed} lane {l}: P^T F asymmetric"
                    );
                    assert!(h.trace() > 0.0 && h.determinant() >= -tol * fl.norm_squared());
                    if sv[0] < 100.0 * sv[1] {
                        let scalar = project_singular_values(&fl, s, s);
                        assert!(
                            (pl - scalar).norm() < 1e-12 * (1.0 + scalar.norm()),
                            "seed {seed} lane {l}: {pl} vs {scalar}"
                        );
                    }
                }
                fallbacks += regular.iter().filter(|r| !**r).count();
            }
        }
        assert_eq!(fallbacks, 300);
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
}
