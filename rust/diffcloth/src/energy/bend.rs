//! Bending with (possibly non-zero) rest curvature, one constraint per interior vertex.
//!
//! `A_i x = sum_j c_ij (x_j - x_i)` is the cotangent Laplacian at vertex `i` (the mean-curvature
//! normal, `c_ij = (cot a_ij + cot b_ij) / (2 area_i)` from the rest shape). The projection keeps
//! its direction and sets its length to the rest value `|A_i X_rest|` (zero on a flat rest
//! shape: then `p_i = 0`), so a curved rest shape (hat, sock) is force-free at rest.
//! `w_i = k_bend * area_i`, with `area_i` the mixed Voronoi area of the rest shape
//! (Meyer et al. 2003), which makes `A_i x` the mean-curvature normal `2 H n` on any valence.
//! Boundary vertices carry no constraint: their Laplacian is not a curvature.

use super::{
    project_vec3_each, rescale_jacobian, rescale_to_rest_length, PdConstraints, Projections,
    Stiffness,
};
use crate::mesh::TriMesh;
use crate::Vec3;
use nalgebra::Matrix3;
use std::collections::BTreeMap;

#[derive(Debug, Clone)]
pub struct Bend {
    center: Vec<usize>,
    /// CSR over constraints: neighbours `j` and coefficients `c_ij`.
    offsets: Vec<usize>,
    neighbor: Vec<usize>,
    coef: Vec<f64>,
    /// Per constraint: `sum_j c_ij` (minus the center's coefficient; the adjoint's hot loop).
    coef_sum: Vec<f64>,
    area: Vec<f64>,
    weight: Vec<f64>,
    rest_length: Vec<f64>,
    /// Direction used only when the current curvature vector vanishes exactly.
    rest_vector: Vec<Vec3>,
}

impl Bend {
    pub fn new(mesh: &TriMesh, k_bend: f64) -> Self {
        let x = &mesh.positions;
        // Symmetric edge weights (cot a + cot b) / 2, accumulated over the two adjacent triangles.
        let mut edge_weight: BTreeMap<(usize, usize), f64> = BTreeMap::new();
        for tri in &mesh.triangles {
            for k in 0..3 {
                let (o, i, j) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
                let (e1, e2) = (x[i] - x[o], x[j] - x[o]);
                let cot = e1.dot(&e2) / e1.cross(&e2).norm();
                *edge_weight.entry((i.min(j), i.max(j))).or_default() += 0.5 * cot;
            }
        }
        let n = mesh.num_vertices();
        let mut adjacency: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
        for (&(i, j), &w) in &edge_weight {
            adjacency[i].push((j, w));
            adjacency[j].push((i, w));
        }
        let vertex_area = mixed_voronoi_areas(mesh);
        let on_boundary = mesh.boundary_vertices();
        let mean_edge = mean_edge_length(mesh);

        let mut b = Self {
            center: Vec::new(),
            offsets: vec![0],
            neighbor: Vec::new(),
            coef: Vec::new(),
            coef_sum: Vec::new(),
            area: Vec::new(),
            weight: Vec::new(),
            rest_length: Vec::new(),
            rest_vector: Vec::new(),
        };
        for i in (0..n).filter(|&i| !on_boundary[i] && !adjacency[i].is_empty()) {
            let area = vertex_area[i];
            let mut lap = Vec3::zeros();
            for &(j, w) in &adjacency[i] {
                b.neighbor.push(j);
                // c_ij = (cot a + cot b) / (2 area_i); `w` already holds (cot a + cot b) / 2.
                b.coef.push(w / area);
                lap += *b.coef.last().unwrap() * (x[j] - x[i]);
            }
            b.coef_sum
                .push(b.coef[b.offsets[b.offsets.len() - 1]..].iter().sum());
            b.offsets.push(b.neighbor.len());
            b.center.push(i);
            b.area.push(area);
            // A flat rest shape gives a Laplacian that is zero up to round-off: make it exact.
            let length = if lap.norm() * mean_edge < 1e-9 {
                0.0
            } else {
                lap.norm()
            };
            b.rest_length.push(length);
            b.rest_vector
                .push(if length > 0.0 { lap } else { Vec3::zeros() });
        }
        b.weight = vec![0.0; b.center.len()];
        b.set_stiffness(k_bend);
        b
    }

    pub fn len(&self) -> usize {
        self.center.len()
    }

    pub fn is_empty(&self) -> bool {
        self.center.is_empty()
    }

    /// `A_i x`: the curvature vector of constraint `i`.
    pub fn curvature(&self, i: usize, x: &[Vec3]) -> Vec3 {
        let xi = x[self.center[i]];
        let range = self.offsets[i]..self.offsets[i + 1];
        self.neighbor[range.clone()]
            .iter()
            .zip(&self.coef[range])
            .map(|(&j, &c)| c * (x[j] - xi))
            .sum()
    }

    /// The projection of constraint `i` at `x`.
    pub fn projection(&self, i: usize, x: &[Vec3]) -> Vec3 {
        self.project_one(i, x).0
    }

    // Inlined into the local step's loop (a call per constraint returns through memory).
    #[inline(always)]
    fn project_one(&self, i: usize, x: &[Vec3]) -> (Vec3, f64) {
        let (target, fallback) = (self.rest_length[i], self.rest_vector[i]);
        rescale_to_rest_length(self.curvature(i, x), target, fallback, self.weight[i])
    }
}

impl Bend {
    pub fn centers(&self) -> &[usize] {
        &self.center
    }
    /// Neighbours and coefficients of constraint `i` (`A_i x = sum_j c_ij (x_j - x_i)`).
    pub fn stencil(&self, i: usize) -> (&[usize], &[f64]) {
        let r = self.offsets[i]..self.offsets[i + 1];
        (&self.neighbor[r.clone()], &self.coef[r])
    }
    pub fn weight(&self, i: usize) -> f64 {
        self.weight[i]
    }
    pub fn area(&self, i: usize) -> f64 {
        self.area[i]
    }
    /// Jacobian of the projection `p = r v / |v|` at `v = A_i x`: `(r / |v|)(I - v^ v^T)`
    /// (zero on a flat rest shape, where `p = 0`).
    pub fn projection_jacobian(&self, i: usize, x: &[Vec3]) -> nalgebra::Matrix3<f64> {
        rescale_jacobian(self.curvature(i, x), self.rest_length[i])
    }
}

impl PdConstraints for Bend {
    fn add_system_triplets(&self, out: &mut Vec<(usize, usize, f64)>) {
        for i in 0..self.len() {
            let range = self.offsets[i]..self.offsets[i + 1];
            let center_coef: f64 = -self.coef[range.clone()].iter().sum::<f64>();
            let nodes = std::iter::once((self.center[i], center_coef)).chain(
                self.neighbor[range.clone()]
                    .iter()
                    .copied()
                    .zip(self.coef[range].iter().copied()),
            );
            let nodes: Vec<(usize, f64)> = nodes.collect();
            for &(a, ca) in &nodes {
                for &(b, cb) in &nodes {
                    out.push((a, b, self.weight[i] * ca * cb));
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
        for (i, p) in projections.values.chunks_exact(3).enumerate() {
            let wp = self.weight[i] * Vec3::from_column_slice(p);
            let range = self.offsets[i]..self.offsets[i + 1];
            let mut center = Vec3::zeros();
            for (&j, &c) in self.neighbor[range.clone()].iter().zip(&self.coef[range]) {
                rhs[j] += c * wp;
                center -= c * wp;
            }
            rhs[self.center[i]] += center;
        }
    }

    fn boxed_clone(&self) -> Box<dyn PdConstraints> {
        Box::new(self.clone())
    }

    fn stiffness(&self) -> Stiffness {
        Stiffness::Bend
    }

    fn set_stiffness(&mut self, k_bend: f64) {
        for (w, a) in self.weight.iter_mut().zip(&self.area) {
            *w = k_bend * a;
        }
    }

    fn linearization_len(&self) -> usize {
        9 * self.len()
    }

    /// Per constraint, `w dp/dv` (3x3, column-major as nalgebra stores it).
    fn linearize(&self, x: &[Vec3], lin: &mut [f64]) {
        for (i, out) in lin.chunks_exact_mut(9).enumerate() {
            let j = self.weight[i] * self.projection_jacobian(i, x);
            out.copy_from_slice(j.as_slice());
        }
    }

    fn sub_dp(&self, lin: &[f64], v: &[Vec3], out: &mut [Vec3]) {
        for (i, j) in lin.chunks_exact(9).enumerate() {
            let (nbrs, coefs) = self.stencil(i);
            let center = self.center[i];
            let coef_sum = self.coef_sum[i];
            let mut dv = -coef_sum * v[center];
            for (&k, &c) in nbrs.iter().zip(coefs) {
                dv += c * v[k];
            }
            let q = Matrix3::from_column_slice(j) * dv;
            for (&k, &c) in nbrs.iter().zip(coefs) {
                out[k] -= c * q;
            }
            out[center] += coef_sum * q;
        }
    }

    fn add_neg_dp_triplets(&self, lin: &[f64], out: &mut Vec<(usize, usize, f64)>) {
        for (i, j) in lin.chunks_exact(9).enumerate() {
            let (nbrs, coefs) = self.stencil(i);
            let center_coef: f64 = -coefs.iter().sum::<f64>();
            let nodes: Vec<(usize, f64)> = std::iter::once((self.center[i], center_coef))
                .chain(nbrs.iter().copied().zip(coefs.iter().copied()))
                .collect();
            let jw = Matrix3::from_column_slice(j);
            for &(a, ca) in &nodes {
                for &(b, cb) in &nodes {
                    for c in 0..3 {
                        for e in 0..3 {
                            out.push((3 * a + c, 3 * b + e, -ca * cb * jw[(c, e)]));
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
        for (i, j) in lin.chunks_exact(9).enumerate() {
            let (nbrs, coefs) = self.stencil(i);
            let center_coef: f64 = -coefs.iter().sum::<f64>();
            let node = |k: usize| match k {
                0 => (self.center[i], center_coef),
                _ => (nbrs[k - 1], coefs[k - 1]),
            };
            let jw = Matrix3::from_column_slice(j);
            for a in 0..=nbrs.len() {
                for b in 0..=nbrs.len() {
                    let ((na, ca), (nb, cb)) = (node(a), node(b));
                    emit(na, nb, &(-ca * cb * jw));
                }
            }
        }
    }

    /// `grad W` on neighbour j is `k a_i c_ij (A_i x - p_i)` (minus their sum on the center).
    fn stiffness_dot(&self, x: &[Vec3], z: &[Vec3]) -> f64 {
        let mut dot = 0.0;
        for (i, &center) in self.center.iter().enumerate() {
            let r = (self.curvature(i, x) - self.projection(i, x)) * self.area[i];
            let (nbrs, coefs) = self.stencil(i);
            for (&j, &c) in nbrs.iter().zip(coefs) {
                dot += c * (z[j] - z[center]).dot(&r);
            }
        }
        dot
    }
}

/// Mixed Voronoi area per vertex (Meyer et al. 2003): the Voronoi region inside non-obtuse
/// triangles, and half / a quarter of an obtuse triangle's area at / beside its obtuse corner.
fn mixed_voronoi_areas(mesh: &TriMesh) -> Vec<f64> {
    let x = &mesh.positions;
    let mut area = vec![0.0; mesh.num_vertices()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let tri_area = mesh.triangle_area(t);
        let corner = |k: usize| {
            let (o, i, j) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
            let (e1, e2) = (x[i] - x[o], x[j] - x[o]);
            (e1.dot(&e2) / e1.cross(&e2).norm(), e1.dot(&e2) < 0.0)
        };
        let corners = [corner(0), corner(1), corner(2)];
        let obtuse = corners.iter().position(|c| c.1);
        for k in 0..3 {
            area[tri[k]] += match obtuse {
                Some(o) if o == k => 0.5 * tri_area,
                Some(_) => 0.25 * tri_area,
                None => {
                    // (|e_ki|^2 cot(angle at j) + |e_kj|^2 cot(angle at i)) / 8
                    let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                    let (pi, pj, pk) = (x[tri[i]], x[tri[j]], x[tri[k]]);
                    ((pi - pk).norm_squared() * corners[j].0
                        + (pj - pk).norm_squared() * corners[i].0)
                        / 8.0
                }
            };
        }
    }
    area
}

fn mean_edge_length(mesh: &TriMesh) -> f64 {
    let total: f64 = mesh
        .triangles
        .iter()
        .map(|t| {
            (0..3)
                .map(|k| (mesh.positions[t[k]] - mesh.positions[t[(k + 1) % 3]]).norm())
                .sum::<f64>()
        })
        .sum();
    total / (3 * mesh.triangles.len()) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::testing::*;
    use crate::mesh::{grid, GridPlane};

    /// A grid bent into a cylinder section: curved rest shape.
    fn curved_mesh() -> TriMesh {
        let mut m = grid(6, 6, 2.0, 1.5, GridPlane::Xy).unwrap();
        for p in &mut m.positions {
            let angle = p.x / 1.5;
            *p = Vec3::new(1.5 * angle.sin(), p.y, 1.5 * angle.cos());
        }
        m
    }

    #[test]
    fn flat_rest_shape_has_zero_rest_curvature() {
        let m = grid(5, 5, 1.0, 1.0, GridPlane::Xz).unwrap();
        let b = Bend::new(&m, 1.0);
        assert_eq!(b.len(), 9, "interior vertices only");
        assert!(b.rest_length.iter().all(|&l| l == 0.0));
    }

    #[test]
    fn curved_rest_shape_is_force_free() {
        let m = curved_mesh();
        let mut b = Bend::new(&m, 5.0);
        assert!(b.rest_length.iter().all(|&l| l > 0.1));
        let (e, g) = gradient(&mut b, &m.positions);
        assert!(e < 1e-24);
        assert!(
            g.iter().all(|v| v.norm() < 1e-10),
            "{:?}",
            g.iter().map(|v| v.norm()).fold(0.0, f64::max)
        );
        // The curvature of a cylinder of radius R is 1/R along the inward normal.
        for i in 0..b.len() {
            let k = b.curvature(i, &m.positions).norm();
            assert!((k - 1.0 / 1.5).abs() < 0.02, "vertex {}: {k}", b.center[i]);
        }
    }

    #[test]
    fn projection_jacobian_matches_finite_differences() {
        let m = curved_mesh();
        let b = Bend::new(&m, 1.0);
        let x = jitter(&m.positions, 0.05, 9);
        for i in 0..b.len() {
            let jac = b.projection_jacobian(i, &x);
            // Perturb the curvature vector through one neighbour (A_i is linear).
            // (via the neighbour with the largest coefficient: right angles give zero weights).
            let (nbrs, coefs) = b.stencil(i);
            let k = (0..nbrs.len())
                .max_by(|&a, &b| coefs[a].abs().total_cmp(&coefs[b].abs()))
                .unwrap();
            let (j, c) = (nbrs[k], coefs[k]);
            for d in 0..3 {
                let eps = 1e-6;
                let mut xp = x.clone();
                xp[j][d] += eps;
                let mut xm = x.clone();
                xm[j][d] -= eps;
                let fd = (b.project_one(i, &xp).0 - b.project_one(i, &xm).0) / (2.0 * eps * c);
                assert!((fd - jac.column(d)).norm() < 1e-5, "constraint {i} dim {d}");
            }
        }
    }

    #[test]
    fn energy_gradient_matches_finite_differences() {
        let m = curved_mesh();
        let x = jitter(&m.positions, 0.05, 3);
        check_gradient_fd(&mut Bend::new(&m, 2.0), &x, 1e-6);
        let flat = grid(5, 5, 1.0, 1.0, GridPlane::Xz).unwrap();
        let xf = jitter(&flat.positions, 0.05, 4);
        check_gradient_fd(&mut Bend::new(&flat, 2.0), &xf, 1e-6);
        check_backward_fd(&mut Bend::new(&m, 2.0), 2.0, &x, 1e-5);
        check_backward_fd(&mut Bend::new(&flat, 2.0), 2.0, &xf, 1e-5);
    }
}
