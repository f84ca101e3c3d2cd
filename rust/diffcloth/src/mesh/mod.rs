//! Triangle meshes: the mesh type, generators (grid, procedural garments) and OBJ i/o.

pub mod garment;
mod grid;
mod obj;

pub use grid::{grid, GridPlane};
pub use obj::{read_obj, write_obj};

use crate::error::{Error, Result};
use crate::Vec3;
use std::collections::HashMap;

/// An indexed triangle mesh. Its vertex positions at construction are the rest shape.
/// Smallest accepted [`TriMesh::triangle_aspect`]. Measured: a free-falling grid with one
/// sliver of aspect 1e-8 gains 1000x its energy in 20 steps (bending), 1e-7 3.7x in 100, and
/// 3e-7 and above stay stable; the reference meshes' smallest is 3e-2.
pub const MIN_ASPECT: f64 = 1e-6;

/// Largest accepted vertex coordinate magnitude in metres. Far beyond any cloth, and far
/// enough below overflow that squared areas and their products stay finite (at 1e150 a
/// triangle's normal overflows and its rest shape is lost).
pub const MAX_COORDINATE: f64 = 1e15;

#[derive(Debug, Clone)]
pub struct TriMesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[usize; 3]>,
}

impl TriMesh {
    /// Builds a mesh and validates it: finite positions, indices in range, no repeated vertex
    /// in a triangle, and no degenerate triangle (area below `1e-12` times the squared
    /// bounding-box diagonal), so every triangle has a well-defined rest shape, and every
    /// vertex in some triangle (else it has no mass), no coordinate beyond [`MAX_COORDINATE`].
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[usize; 3]>) -> Result<Self> {
        if positions.is_empty() {
            return Err(Error::Mesh("mesh has no vertices".into()));
        }
        if triangles.is_empty() {
            return Err(Error::Mesh("mesh has no triangles".into()));
        }
        if let Some(i) = positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(Error::Mesh(format!(
                "vertex {i} has a non-finite coordinate"
            )));
        }
        if let Some(i) = positions.iter().position(|p| p.amax() > MAX_COORDINATE) {
            return Err(Error::Mesh(format!(
                "vertex {i} is {:.1e} m from the origin, beyond the {MAX_COORDINATE:.0e} m allowed",
                positions[i].amax()
            )));
        }
        let mesh = Self {
            positions,
            triangles,
        };
        let mut used = vec![false; mesh.positions.len()];
        let diag2 = mesh.bounding_box_diagonal().powi(2);
        let n = mesh.positions.len();
        for (t, tri) in mesh.triangles.iter().enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i >= n) {
                return Err(Error::Mesh(format!(
                    "triangle {t} references vertex {i} but the mesh has {n} vertices"
                )));
            }
            tri.iter().for_each(|&i| used[i] = true);
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(Error::Mesh(format!(
                    "triangle {t} repeats a vertex: {tri:?}"
                )));
            }
            let area = mesh.triangle_area(t);
            if !(area > 1e-12 * diag2) {
                return Err(Error::Mesh(format!(
                    "triangle {t} {tri:?} is degenerate (area {area:.3e}); remove it or repair the mesh"
                )));
            }
            let aspect = mesh.triangle_aspect(t);
            if aspect < MIN_ASPECT {
                return Err(Error::Mesh(format!(
                    "triangle {t} {tri:?} is a sliver (2 area / longest edge^2 = {aspect:.1e}, below {MIN_ASPECT:.0e}): \
                     its bending weights (cotangents, ~1/aspect) make the step unstable; remove it or repair the mesh"
                )));
            }
        }
        // A vertex of no triangle has no mass: the system matrix would be singular.
        if let Some(i) = used.iter().position(|&u| !u) {
            return Err(Error::Mesh(format!(
                "vertex {i} is used by no triangle (it would have no mass)"
            )));
        }
        Ok(mesh)
    }

    /// `2 area / (longest edge)^2`: about 0.87 for an equilateral triangle, 0 for a sliver.
    pub fn triangle_aspect(&self, t: usize) -> f64 {
        let [a, b, c] = self.triangles[t].map(|i| self.positions[i]);
        let longest = (b - a)
            .norm_squared()
            .max((c - b).norm_squared())
            .max((a - c).norm_squared());
        2.0 * self.triangle_area(t) / longest
    }

    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    pub fn triangle_area(&self, t: usize) -> f64 {
        let [a, b, c] = self.triangles[t];
        let (pa, pb, pc) = (self.positions[a], self.positions[b], self.positions[c]);
        0.5 * (pb - pa).cross(&(pc - pa)).norm()
    }

    pub fn bounding_box(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        for p in &self.positions {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        (lo, hi)
    }

    pub fn bounding_box_diagonal(&self) -> f64 {
        let (lo, hi) = self.bounding_box();
        (hi - lo).norm()
    }

    /// Each vertex's share of the surface: one third of its incident triangles' areas.
    pub fn vertex_areas(&self) -> Vec<f64> {
        let mut area = vec![0.0; self.num_vertices()];
        for (t, tri) in self.triangles.iter().enumerate() {
            let a = self.triangle_area(t) / 3.0;
            for &i in tri {
                area[i] += a;
            }
        }
        area
    }

    /// Vertices on a boundary edge (an edge used by exactly one triangle).
    pub fn boundary_vertices(&self) -> Vec<bool> {
        let mut edge_count: HashMap<(usize, usize), u32> = HashMap::new();
        for tri in &self.triangles {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                *edge_count.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let mut on_boundary = vec![false; self.num_vertices()];
        for (&(a, b), &count) in &edge_count {
            if count == 1 {
                on_boundary[a] = true;
                on_boundary[b] = true;
            }
        }
        on_boundary
    }

    /// Applies `p -> rotation * (scale * p) + translation` to every vertex.
    pub fn transform(
        &mut self,
        scale: f64,
        rotation: &nalgebra::Rotation3<f64>,
        translation: Vec3,
    ) {
        for p in &mut self.positions {
            *p = rotation * (*p * scale) + translation;
        }
    }
}
