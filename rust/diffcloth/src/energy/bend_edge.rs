//! Bending with (possibly non-zero) rest curvature, one constraint per interior edge: the
//! reference DiffCloth code's model (`TriangleBending.cpp`, after the quadratic bending model of
//! Bergou et al. 2006, "A Quadratic Bending Model for Inextensible Surfaces").
//!
//! An interior edge `(x0, x1)` with opposite vertices `x2` (triangle `T0 = (x0, x1, x2)`, rest
//! area `A0`) and `x3` (`T1 = (x0, x1, x3)`, `A1`) has the stencil `A_i x = e = sum_j w_j x_j`
//! with, from the rest lengths `l_jk` (each `cot` is that of the angle opposite the named edge):
//!
//! ```text
//! cot02 = (l01^2 - l02^2 + l12^2) / (4 A0)    cot12 = (l01^2 + l02^2 - l12^2) / (4 A0)
//! cot03 = (l01^2 - l03^2 + l13^2) / (4 A1)    cot13 = (l01^2 + l03^2 - l13^2) / (4 A1)
//! w0 = cot02 + cot03,  w1 = cot12 + cot13,  w2 = -(cot02 + cot12),  w3 = -(cot03 + cot13)
//! ```
//!
//! `sum_j w_j = 0` (translations are free) and `e(X_rest) = 0` on a planar rest hinge. The
//! projection rescales `e` to its rest length `n = |e(X_rest)|` (`p = n e / |e|`; `p = 0` when
//! `n <= 1e-6` m, as the reference, so a flat rest shape gives the quadratic model
//! `E = w/2 |e|^2`), so a curved rest shape is force-free at rest.
//!
//! Weight: the reference writes each constraint as `(1/2) |W (A x - p)|^2` with
//! `W = sqrt(3 k_bend / (A0 + A1))` (its selector rows and projections both carry `W`, so its
//! global step sees `W^2 A^T A` and `W^2 A^T p`). In our convention `w/2 |A x - p|^2` that is
//! the PD weight `w = W^2 = 3 k_bend / (A0 + A1)` (Bergou's `Q = 3 / (A0 + A1) K^T K`).
//! Boundary and non-manifold edges carry no constraint.

use super::{
    project_vec3_each, rescale_jacobian, rescale_to_rest_length, PdConstraints, Projections,
    Stiffness,
};
use crate::mesh::TriMesh;
use crate::Vec3;
use nalgebra::Matrix3;
use std::collections::BTreeMap;

/// Rest stencil lengths at or below this (metres) count as flat, as in the reference.
const FLAT_REST_LENGTH: f64 = 1e-6;

/// Largest cotangent a hinge's stencil may carry; a hinge beyond it has its whole stencil
/// scaled down to it. The stiffness of a hinge grows like `cot^2 / (A0 + A1)`, without bound on
/// a sliver: with one of aspect 1e-5 (cot 1e5; the system's condition number, estimated from
/// the weights, near 1e14) converged steps gained energy (E(t)/E(0) up to 235 falling onto a
/// sphere, 18 hanging from a corner without contact; stability case `obj_sliver_1e-5`). Scaling the stencil, not clamping single cotangents,
/// keeps `sum_j w_j = 0` and `e(X_rest) = 0` on a planar hinge (clamping made a planar sliver
/// hinge a curved one, and the napkin blew up). 1e3 is an angle of 0.057 degrees: no shipped
/// or reference mesh comes near it (their thinnest triangles have aspect 3e-2), so only
/// degenerate imports are affected, where the sliver's bending is meaningless anyway.
const MAX_COT: f64 = 1e3;

#[derive(Debug, Clone)]
pub struct BendEdge {
    /// Per constraint: the edge `x0, x1`, then the opposite vertices `x2, x3`.
    nodes: Vec<[usize; 4]>,
    /// Per constraint: the stencil weights `w_0..w_3`.
    coef: Vec<[f64; 4]>,
    /// `3 / (A0 + A1)`: the PD weight per unit `k_bend`.
    weight_per_k: Vec<f64>,
    weight: Vec<f64>,
    rest_length: Vec<f64>,
    /// Direction used only when the current stencil vector vanishes exactly.
    rest_vector: Vec<Vec3>,
}

impl BendEdge {
    pub fn new(mesh: &TriMesh, k_bend: f64) -> Self {
        let x = &mesh.positions;
        // Opposite vertices of every edge, in triangle order (a BTreeMap: deterministic order).
        let mut opposite: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
        for tri in &mesh.triangles {
            for k in 0..3 {
                let (i, j) = (tri[k], tri[(k + 1) % 3]);
                opposite
                    .entry((i.min(j), i.max(j)))
                    .or_default()
                    .push(tri[(k + 2) % 3]);
            }
        }
        let mut b = Self {
            nodes: Vec::new(),
            coef: Vec::new(),
            weight_per_k: Vec::new(),
            weight: Vec::new(),
            rest_length: Vec::new(),
            rest_vector: Vec::new(),
        };
        for (&(i0, i1), opp) in &opposite {
            // Boundary (one triangle) and non-manifold (three or more) edges: no hinge.
            if opp.len() != 2 {
                continue;
            }
            let ids = [i0, i1, opp[0], opp[1]];
            let p = ids.map(|i| x[i]);
            let sq = |a: usize, b: usize| (p[a] - p[b]).norm_squared();
            let (l01, l02, l12, l03, l13) = (sq(0, 1), sq(0, 2), sq(1, 2), sq(0, 3), sq(1, 3));
            // The areas from cross products (the reference uses Heron's formula: same value,
            // less round-off on thin triangles).
            let a0 = 0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm();
            let a1 = 0.5 * (p[1] - p[0]).cross(&(p[3] - p[0])).norm();
            let cot02 = (l01 - l02 + l12) / (4.0 * a0);
            let cot12 = (l01 + l02 - l12) / (4.0 * a0);
            let cot03 = (l01 - l03 + l13) / (4.0 * a1);
            let cot13 = (l01 + l03 - l13) / (4.0 * a1);
            let mut c = [
                cot02 + cot03,
                cot12 + cot13,
                -(cot02 + cot12),
                -(cot03 + cot13),
            ];
            let largest = [cot02, cot12, cot03, cot13]
                .iter()
                .fold(0.0f64, |m, c| m.max(c.abs()));
            if largest > MAX_COT {
                c.iter_mut().for_each(|w| *w *= MAX_COT / largest);
            }
            let e: Vec3 = (0..4).map(|j| c[j] * p[j]).sum();
            let length = if e.norm() <= FLAT_REST_LENGTH {
                0.0
            } else {
                e.norm()
            };
            b.nodes.push(ids);
            b.coef.push(c);
            b.weight_per_k.push(3.0 / (a0 + a1));
            b.rest_length.push(length);
            b.rest_vector
                .push(if length > 0.0 { e } else { Vec3::zeros() });
        }
        b.weight = vec![0.0; b.nodes.len()];
        b.set_stiffness(k_bend);
        b
    }

    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Nodes `[x0, x1, x2, x3]` and stencil weights of constraint `i`.
    pub fn stencil(&self, i: usize) -> ([usize; 4], [f64; 4]) {
        (self.nodes[i], self.coef[i])
    }

    pub fn weight(&self, i: usize) -> f64 {
        self.weight[i]
    }

    pub fn rest_length(&self, i: usize) -> f64 {
        self.rest_length[i]
    }

    /// `A_i x = sum_j w_j x_j`.
    #[inline]
    pub fn edge_vector(&self, i: usize, x: &[Vec3]) -> Vec3 {
        let (n, c) = (&self.nodes[i], &self.coef[i]);
        c[0] * x[n[0]] + c[1] * x[n[1]] + c[2] * x[n[2]] + c[3] * x[n[3]]
    }

    /// The projection of constraint `i` at `x`.
    pub fn projection(&self, i: usize, x: &[Vec3]) -> Vec3 {
        self.project_one(i, x).0
    }

    // Inlined into the local step's loop (a call per constraint returns through memory).
    #[inline(always)]
    fn project_one(&self, i: usize, x: &[Vec3]) -> (Vec3, f64) {
        let (target, fallback) = (self.rest_length[i], self.rest_vector[i]);
        rescale_to_rest_length(self.edge_vector(i, x), target, fallback, self.weight[i])
    }

    /// Jacobian of `p = n e / |e|` at `e = A_i x`: `(n / |e|)(I - e^ e^T)` (zero when `n = 0`
    /// or `|e| = 0`).
    pub fn projection_jacobian(&self, i: usize, x: &[Vec3]) -> Matrix3<f64> {
        rescale_jacobian(self.edge_vector(i, x), self.rest_length[i])
    }
}

impl PdConstraints for BendEdge {
    fn add_system_triplets(&self, out: &mut Vec<(usize, usize, f64)>) {
        for ((n, c), &w) in self.nodes.iter().zip(&self.coef).zip(&self.weight) {
            for a in 0..4 {
                for b in 0..4 {
                    out.push((n[a], n[b], w * c[a] * c[b]));
                }
            }
        }
    }

    fn new_projections(&self) -> Projections {
        Projections::new(self.len(), 3)
    }

    fn project(&self, x: &[Vec3], parallel: bool, out: &mut Projections) -> f64 {
        project_vec3_each(out, parallel, |i| self.project_one(i, x))
    }

    fn add_rhs(&self, projections: &Projections, rhs: &mut [Vec3]) {
        let p = projections.values.chunks_exact(3);
        for (i, ((n, c), p)) in self.nodes.iter().zip(&self.coef).zip(p).enumerate() {
            let wp = self.weight[i] * Vec3::from_column_slice(p);
            for a in 0..4 {
                rhs[n[a]] += c[a] * wp;
            }
        }
    }

    fn boxed_clone(&self) -> Box<dyn PdConstraints> {
        Box::new(self.clone())
    }

    fn stiffness(&self) -> Stiffness {
        Stiffness::Bend
    }

    fn set_stiffness(&mut self, k_bend: f64) {
        for (w, f) in self.weight.iter_mut().zip(&self.weight_per_k) {
            *w = k_bend * f;
        }
    }

    fn linearization_len(&self) -> usize {
        9 * self.len()
    }

    /// Per constraint, `w dp/de` (3x3, column-major as nalgebra stores it).
    fn linearize(&self, x: &[Vec3], lin: &mut [f64]) {
        for (i, out) in lin.chunks_exact_mut(9).enumerate() {
            let j = self.weight[i] * self.projection_jacobian(i, x);
            out.copy_from_slice(j.as_slice());
        }
    }

    fn sub_dp(&self, lin: &[f64], v: &[Vec3], out: &mut [Vec3]) {
        for ((j, n), c) in lin.chunks_exact(9).zip(&self.nodes).zip(&self.coef) {
            let dv = c[0] * v[n[0]] + c[1] * v[n[1]] + c[2] * v[n[2]] + c[3] * v[n[3]];
            let q = Matrix3::from_column_slice(j) * dv;
            for a in 0..4 {
                out[n[a]] -= c[a] * q;
            }
        }
    }

    fn add_neg_dp_triplets(&self, lin: &[f64], out: &mut Vec<(usize, usize, f64)>) {
        for ((j, n), c) in lin.chunks_exact(9).zip(&self.nodes).zip(&self.coef) {
            let jw = Matrix3::from_column_slice(j);
            for a in 0..4 {
                for b in 0..4 {
                    for r in 0..3 {
                        for s in 0..3 {
                            out.push((3 * n[a] + r, 3 * n[b] + s, -c[a] * c[b] * jw[(r, s)]));
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
        for ((j, n), c) in lin.chunks_exact(9).zip(&self.nodes).zip(&self.coef) {
            let jw = Matrix3::from_column_slice(j);
            for a in 0..4 {
                for b in 0..4 {
                    emit(n[a], n[b], &(-c[a] * c[b] * jw));
                }
            }
        }
    }

    /// `grad W` on node `a` of constraint `i` is `k (3 / (A0 + A1)) w_a (e_i - p_i)`; `p_i`
    /// does not depend on `k`.
    fn stiffness_dot(&self, x: &[Vec3], z: &[Vec3]) -> f64 {
        let mut dot = 0.0;
        for (i, (n, c)) in self.nodes.iter().zip(&self.coef).enumerate() {
            let (p, _) = self.project_one(i, x);
            let r = self.weight_per_k[i] * (self.edge_vector(i, x) - p);
            let zc = c[0] * z[n[0]] + c[1] * z[n[1]] + c[2] * z[n[2]] + c[3] * z[n[3]];
            dot += zc.dot(&r);
        }
        dot
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::testing::*;
    use crate::energy::Bend;
    use crate::mesh::{grid, GridPlane};

    /// A grid bent into a cylinder section of radius 1.5: curved rest shape.
    fn curved_mesh() -> TriMesh {
        let mut m = grid(6, 6, 2.0, 1.5, GridPlane::Xy).unwrap();
        for p in &mut m.positions {
            let angle = p.x / 1.5;
            *p = Vec3::new(1.5 * angle.sin(), p.y, 1.5 * angle.cos());
        }
        m
    }

    /// Two flat triangles `T0 = (0, 1, 2)` and `T1 = (0, 3, 1)` in the xy plane, hinged on
    /// the edge (0, 1) along x. Rest areas 0.5 and 0.4.
    fn hinge() -> TriMesh {
        let x = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.3, 1.0, 0.0),
            Vec3::new(0.5, -0.8, 0.0),
        ];
        TriMesh::new(x, vec![[0, 1, 2], [0, 3, 1]]).unwrap()
    }

    #[test]
    fn a_sliver_hinge_has_a_bounded_stencil_still_zero_on_its_planar_rest_shape() {
        // T0 = (0, 1, 2) with x2 1e-6 off the hinge edge: the angles at x0 and x1 have
        // cot 5e5; T1 is a normal triangle.
        let x = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.5, 1e-6, 0.0),
            Vec3::new(0.5, -0.8, 0.0),
        ];
        let mesh = TriMesh::new(x.clone(), vec![[0, 1, 2], [0, 3, 1]]).unwrap();
        let b = BendEdge::new(&mesh, 1.0);
        let (_, c) = b.stencil(0);
        let largest = c.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        // Scaled so that the largest cotangent is MAX_COT; each weight sums at most two.
        assert!(largest <= 2.0 * MAX_COT && largest > 0.5 * MAX_COT, "{c:?}");
        assert!(c.iter().sum::<f64>().abs() <= 1e-12 * largest, "{c:?}");
        assert!(
            b.edge_vector(0, &x).norm() <= 1e-9,
            "planar rest hinge: e = 0"
        );
        assert_eq!(b.rest_length(0), 0.0);
    }

    #[test]
    fn hinge_stencil_is_the_cotangent_formula() {
        let b = BendEdge::new(&hinge(), 1.0);
        assert_eq!(b.len(), 1, "one interior edge");
        let (nodes, c) = b.stencil(0);
        assert_eq!(nodes, [0, 1, 2, 3]);
        // By hand: in T0 the angle at x1 (opposite edge 02) has cot 0.7, the angle at x0
        // (opposite 12) cot 0.3; in T1 both base angles have cot 0.5 / 0.8 = 0.625.
        let (cot02, cot12, cot03, cot13) = (0.7, 0.3, 0.625, 0.625);
        let expected = [
            cot02 + cot03,
            cot12 + cot13,
            -(cot02 + cot12),
            -(cot03 + cot13),
        ];
        for k in 0..4 {
            assert!((c[k] - expected[k]).abs() < 1e-14, "{c:?} vs {expected:?}");
        }
        assert!((b.weight(0) - 3.0 / 0.9).abs() < 1e-14);
        assert_eq!(b.rest_length(0), 0.0, "flat rest hinge");
    }

    /// Folding the flat hinge by `theta` (x3 rotated about the hinge line) gives
    /// `e = w3 (x3' - x3) = (0, cos theta - 1, sin theta)` (`w3 = -1.25`, `|x3| = 0.8`); the
    /// energy gradient on node `a` is `w w_a e` with `w = 3 k / (A0 + A1)` (the restoring force
    /// is its negative), linear in `k`.
    #[test]
    fn k_bend_scales_the_restoring_force_of_a_folded_hinge() {
        let m = hinge();
        let theta: f64 = 0.4;
        let mut x = m.positions.clone();
        x[3] = Vec3::new(0.5, -0.8 * theta.cos(), -0.8 * theta.sin());
        let e = Vec3::new(0.0, theta.cos() - 1.0, theta.sin());
        let c = [1.325, 0.925, -1.0, -1.25];
        let mut forces = Vec::new();
        for k in [0.7, 1.4] {
            let mut b = BendEdge::new(&m, k);
            assert!((b.edge_vector(0, &x) - e).norm() < 1e-14);
            let w = 3.0 * k / (0.5 + 0.4);
            let (energy, g) = gradient(&mut b, &x);
            // |e| = 2 sin(theta / 2).
            let expected_energy = 0.5 * w * 4.0 * (0.5 * theta).sin().powi(2);
            assert!((energy - expected_energy).abs() < 1e-13 * expected_energy);
            for a in 0..4 {
                let expected = w * c[a] * e;
                assert!(
                    (g[a] - expected).norm() < 1e-12,
                    "node {a}: {:?} vs {expected:?}",
                    g[a]
                );
            }
            forces.push(g);
        }
        for (g1, g2) in forces[0].iter().zip(&forces[1]) {
            assert!((g2 - 2.0 * g1).norm() < 1e-12);
            assert!(g1.norm() > 0.05, "the fold is resisted");
        }
    }

    #[test]
    fn boundary_edges_carry_no_constraint() {
        let m = grid(3, 3, 1.0, 1.0, GridPlane::Xz).unwrap();
        // 16 edges, 8 on the boundary.
        assert_eq!(BendEdge::new(&m, 1.0).len(), 8);
    }

    /// A planar cloth (here: irregular, tilted) is force-free at rest in both models.
    #[test]
    fn planar_cloth_is_force_free_at_rest_in_both_models() {
        let mut m = grid(6, 5, 1.2, 1.0, GridPlane::Xz).unwrap();
        let flat = jitter(&m.positions, 0.04, 11);
        let (s, c) = (0.3f64.sin(), 0.3f64.cos());
        // In-plane jitter, then a tilt about x: still one plane.
        m.positions = flat
            .iter()
            .map(|p| Vec3::new(p.x, -s * p.z, c * p.z))
            .collect();
        let models: [(&str, Box<dyn PdConstraints>); 2] = [
            ("edge", Box::new(BendEdge::new(&m, 3.0))),
            ("vertex", Box::new(Bend::new(&m, 3.0))),
        ];
        for (model, mut b) in models {
            let (e, g) = gradient(b.as_mut(), &m.positions);
            let worst = g.iter().map(|v| v.norm()).fold(0.0, f64::max);
            assert!(
                e < 1e-24 && worst < 1e-10,
                "{model}: energy {e}, force {worst}"
            );
        }
        let b = BendEdge::new(&m, 3.0);
        assert!((0..b.len()).all(|i| b.rest_length(i) == 0.0));
    }

    #[test]
    fn curved_rest_shape_is_force_free() {
        let m = curved_mesh();
        let mut b = BendEdge::new(&m, 5.0);
        // Only the hinges on the 4 interior generator lines (5 segments each) are curved: the
        // others join two triangles of one planar quad strip.
        let curved = (0..b.len()).filter(|&i| b.rest_length(i) > 0.0).count();
        assert_eq!(curved, 20);
        let (e, g) = gradient(&mut b, &m.positions);
        assert!(e < 1e-24);
        let worst = g.iter().map(|v| v.norm()).fold(0.0, f64::max);
        assert!(worst < 1e-10, "{worst}");
    }

    #[test]
    fn projection_jacobian_matches_finite_differences() {
        let m = curved_mesh();
        let b = BendEdge::new(&m, 1.0);
        let x = jitter(&m.positions, 0.05, 9);
        for i in 0..b.len() {
            let jac = b.projection_jacobian(i, &x);
            // Perturb e through node x2 (A_i is linear: de = w2 dx2).
            let (nodes, c) = b.stencil(i);
            for d in 0..3 {
                let eps = 1e-6;
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[nodes[2]][d] += eps;
                xm[nodes[2]][d] -= eps;
                let fd = (b.projection(i, &xp) - b.projection(i, &xm)) / (2.0 * eps * c[2]);
                assert!((fd - jac.column(d)).norm() < 1e-5, "constraint {i} dim {d}");
            }
        }
    }

    #[test]
    fn energy_gradient_and_backward_match_finite_differences() {
        let m = curved_mesh();
        let x = jitter(&m.positions, 0.05, 3);
        check_gradient_fd(&mut BendEdge::new(&m, 2.0), &x, 1e-6);
        check_backward_fd(&mut BendEdge::new(&m, 2.0), 2.0, &x, 1e-5);
        let flat = grid(5, 5, 1.0, 1.0, GridPlane::Xz).unwrap();
        let xf = jitter(&flat.positions, 0.05, 4);
        check_gradient_fd(&mut BendEdge::new(&flat, 2.0), &xf, 1e-6);
        check_backward_fd(&mut BendEdge::new(&flat, 2.0), 2.0, &xf, 1e-5);
    }

    /// Parallel and serial local steps give the same bits (above the parallel threshold).
    #[test]
    fn parallel_projection_is_bitwise_serial() {
        let mut m = grid(40, 40, 2.0, 1.0, GridPlane::Xy).unwrap();
        for p in &mut m.positions {
            *p = Vec3::new(p.x.sin(), p.y, p.x.cos());
        }
        let x = jitter(&m.positions, 0.01, 5);
        let b = BendEdge::new(&m, 1.0);
        assert!(b.len() >= crate::energy::PARALLEL_MIN_CONSTRAINTS);
        let (mut serial, mut parallel) = (b.new_projections(), b.new_projections());
        let e = b.project(&x, false, &mut serial);
        assert_eq!(b.project(&x, true, &mut parallel).to_bits(), e.to_bits());
        assert_eq!(serial.values, parallel.values);
    }
}
