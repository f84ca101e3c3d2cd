//! Node-node self-collision candidates from a spatial hash (paper Sec. 4.2, Extensions).
//!
//! Nodes are binned into cubic cells of the search reach; sorting the cell keys once per step
//! lets each node visit its 27 neighbouring cells by binary search: O(n log n), no O(n^2) pass,
//! and no allocation after the first step.

use crate::mesh::TriMesh;
use crate::Vec3;

#[derive(Debug, Clone)]
pub struct SelfCollision {
    /// Contact distance between two nodes (m).
    pub radius: f64,
    /// Coulomb friction coefficient between cloth layers.
    pub mu: f64,
    /// Per node, the sorted nodes it shares a triangle with (never a contact pair).
    excluded_offsets: Vec<usize>,
    excluded: Vec<usize>,
}

/// The spatial hash's buffers (per simulator: the collision settings above are shared).
#[derive(Debug, Default)]
pub struct HashScratch {
    sorted: Vec<(u64, usize)>,
    cells: Vec<[i64; 3]>,
}

impl SelfCollision {
    pub fn new(mesh: &TriMesh, radius: f64, mu: f64) -> Self {
        let n = mesh.num_vertices();
        let mut neighbours: Vec<Vec<usize>> = vec![Vec::new(); n];
        for t in &mesh.triangles {
            for &a in t {
                for &b in t {
                    if a != b {
                        neighbours[a].push(b);
                    }
                }
            }
        }
        let mut excluded_offsets = vec![0];
        let mut excluded = Vec::new();
        for mut list in neighbours {
            list.sort_unstable();
            list.dedup();
            excluded.extend(list);
            excluded_offsets.push(excluded.len());
        }
        Self {
            radius,
            mu,
            excluded_offsets,
            excluded,
        }
    }

    /// Whether `a` and `b` share a triangle.
    pub fn adjacent(&self, a: usize, b: usize) -> bool {
        self.excluded[self.excluded_offsets[a]..self.excluded_offsets[a + 1]]
            .binary_search(&b)
            .is_ok()
    }

    /// Appends every non-adjacent pair `(i, j, distance)`, `i < j`, closer than `reach`.
    pub fn find_pairs(
        &self,
        x: &[Vec3],
        reach: f64,
        hash: &mut HashScratch,
        out: &mut Vec<(usize, usize, f64)>,
    ) {
        let inv = 1.0 / reach;
        hash.cells.resize(x.len(), [0; 3]);
        hash.sorted.clear();
        for (i, p) in x.iter().enumerate() {
            let cell = [
                (p.x * inv).floor() as i64,
                (p.y * inv).floor() as i64,
                (p.z * inv).floor() as i64,
            ];
            hash.cells[i] = cell;
            hash.sorted.push((cell_key(cell), i));
        }
        hash.sorted.sort_unstable();
        let reach2 = reach * reach;
        for i in 0..x.len() {
            let c = hash.cells[i];
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let cell = [c[0] + dx, c[1] + dy, c[2] + dz];
                        let key = cell_key(cell);
                        let start = hash.sorted.partition_point(|&(k, _)| k < key);
                        for &(k, j) in &hash.sorted[start..] {
                            if k != key {
                                break;
                            }
                            // A hash collision of two cells must not report a pair twice.
                            if j <= i || hash.cells[j] != cell {
                                continue;
                            }
                            let d2 = (x[i] - x[j]).norm_squared();
                            if d2 < reach2 && !self.adjacent(i, j) {
                                out.push((i, j, d2.sqrt()));
                            }
                        }
                    }
                }
            }
        }
    }
}

fn cell_key(c: [i64; 3]) -> u64 {
    (c[0].wrapping_mul(73_856_093) ^ c[1].wrapping_mul(19_349_663) ^ c[2].wrapping_mul(83_492_791))
        as u64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{grid, GridPlane};

    #[test]
    fn finds_exactly_the_brute_force_pairs() {
        let mesh = grid(9, 9, 1.0, 1.0, GridPlane::Xz).unwrap();
        // Fold the sheet: the right half is mirrored 3 cm above the left half.
        let x: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|p| {
                if p.x > 0.0 {
                    Vec3::new(-p.x, 0.03 + 0.001 * p.z, p.z)
                } else {
                    *p
                }
            })
            .collect();
        let sc = SelfCollision::new(&mesh, 0.05, 0.1);
        let mut pairs = Vec::new();
        sc.find_pairs(&x, 0.08, &mut HashScratch::default(), &mut pairs);
        let mut brute = Vec::new();
        for i in 0..x.len() {
            for j in i + 1..x.len() {
                let d = (x[i] - x[j]).norm();
                if d < 0.08 && !sc.adjacent(i, j) {
                    brute.push((i, j));
                }
            }
        }
        let mut found: Vec<(usize, usize)> = pairs.iter().map(|&(i, j, _)| (i, j)).collect();
        found.sort_unstable();
        assert_eq!(found, brute);
        assert!(!found.is_empty());
    }
}
