//! Rectangular cloth grids (napkin, Wind, Slope, Bowl).

use super::TriMesh;
use crate::error::{Error, Result};
use crate::Vec3;

/// The plane a grid lies in; the first named axis runs along the columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GridPlane {
    /// Hanging cloth: columns along x, rows along y (up).
    Xy,
    /// Lying cloth: columns along x, rows along z.
    Xz,
}

/// Largest generated grid (nodes): its buffers would take several GB beyond this.
pub const MAX_GRID_NODES: usize = 1_000_000;

/// A `rows x cols` node grid of size `width x height`, centred at the origin, split into
/// `2 (rows-1)(cols-1)` triangles with alternating diagonals (no shear bias).
/// Node `(r, c)` has index `r * cols + c`; row 0 is at the low end of the second axis.
/// At most [`MAX_GRID_NODES`] nodes.
pub fn grid(
    rows: usize,
    cols: usize,
    width: f64,
    height: f64,
    plane: GridPlane,
) -> Result<TriMesh> {
    if rows < 2 || cols < 2 {
        return Err(Error::Mesh(format!(
            "grid needs at least 2x2 nodes, got {rows}x{cols}"
        )));
    }
    if rows.checked_mul(cols).is_none_or(|n| n > MAX_GRID_NODES) {
        return Err(Error::Mesh(format!(
            "grid of {rows}x{cols} nodes is larger than the {MAX_GRID_NODES} nodes allowed"
        )));
    }
    if !(width > 0.0 && height > 0.0) {
        return Err(Error::Mesh(format!(
            "grid size must be positive, got {width} x {height}"
        )));
    }
    let mut positions = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            let u = (c as f64 / (cols - 1) as f64 - 0.5) * width;
            let v = (r as f64 / (rows - 1) as f64 - 0.5) * height;
            positions.push(match plane {
                GridPlane::Xy => Vec3::new(u, v, 0.0),
                // Counter-clockwise seen from +y (the normal points up).
                GridPlane::Xz => Vec3::new(u, 0.0, -v),
            });
        }
    }
    let mut triangles = Vec::with_capacity(2 * (rows - 1) * (cols - 1));
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let (a, b) = (r * cols + c, r * cols + c + 1);
            let (d, e) = (a + cols, b + cols);
            if (r + c) % 2 == 0 {
                triangles.push([a, b, e]);
                triangles.push([a, e, d]);
            } else {
                triangles.push([a, b, d]);
                triangles.push([b, e, d]);
            }
        }
    }
    TriMesh::new(positions, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huge_grids_are_refused_before_allocating() {
        for (r, c) in [(100_000, 100_000), (usize::MAX, 3), (1001, 1000)] {
            let err = grid(r, c, 1.0, 1.0, GridPlane::Xy).unwrap_err().to_string();
            assert!(err.contains("larger than"), "{err}");
        }
        assert!(grid(1000, 1000, 1.0, 1.0, GridPlane::Xy).is_ok());
    }

    #[test]
    fn grid_counts_and_area() {
        let m = grid(4, 5, 2.0, 3.0, GridPlane::Xz).unwrap();
        assert_eq!(m.num_vertices(), 20);
        assert_eq!(m.triangles.len(), 2 * 3 * 4);
        let area: f64 = (0..m.triangles.len()).map(|t| m.triangle_area(t)).sum();
        assert!((area - 6.0).abs() < 1e-12);
        // Normals of the xz grid point up.
        let [a, b, c] = m.triangles[0];
        let n = (m.positions[b] - m.positions[a]).cross(&(m.positions[c] - m.positions[a]));
        assert!(n.y > 0.0);
    }

    #[test]
    fn grid_rejects_bad_sizes() {
        assert!(grid(1, 5, 1.0, 1.0, GridPlane::Xy).is_err());
        assert!(grid(3, 3, -1.0, 1.0, GridPlane::Xy).is_err());
    }
}
