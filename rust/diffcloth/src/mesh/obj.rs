//! Wavefront OBJ import/export (vertices and faces; polygons are fan-triangulated).

use super::TriMesh;
use crate::error::{Error, Result};
use crate::Vec3;
use std::fmt::Write as _;

/// Largest OBJ file read (bytes).
pub const MAX_OBJ_BYTES: u64 = 512 << 20;

/// Reads an OBJ file's `v` and `f` records. Face entries may be `i`, `i/t`, `i//n` or `i/t/n`,
/// with negative (relative) indices allowed; other records are ignored. Only a regular file
/// of at most [`MAX_OBJ_BYTES`] is read. A vertex no face uses is an error naming it (it
/// would have no mass and make the system singular; dropping it silently would renumber the
/// vertices after it, which `attachments.nodes` refer to).
pub fn read_obj(path: &std::path::Path) -> Result<TriMesh> {
    let io = |message: String| Error::Io {
        path: path.display().to_string(),
        message,
    };
    // A device or pipe (/dev/zero, /dev/urandom) would be read forever or until memory runs
    // out: only regular files, up to a size limit.
    let meta = std::fs::metadata(path).map_err(|e| io(e.to_string()))?;
    if !meta.is_file() {
        return Err(io("not a regular file".into()));
    }
    if meta.len() > MAX_OBJ_BYTES {
        return Err(io(format!(
            "{} bytes is larger than the {MAX_OBJ_BYTES} bytes allowed for a mesh file",
            meta.len()
        )));
    }
    let text = std::fs::read_to_string(path).map_err(|e| io(e.to_string()))?;
    parse_obj(&text).map_err(|e| match e {
        Error::Mesh(msg) => Error::Mesh(format!("{}: {msg}", path.display())),
        other => other,
    })
}

/// Parses OBJ text (see [`read_obj`]).
pub fn parse_obj(text: &str) -> Result<TriMesh> {
    // A UTF-8 byte-order mark (some Windows tools write one) would hide the first record.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut positions = Vec::new();
    let mut vertex_lines = Vec::new();
    let mut triangles = Vec::new();
    for (lineno, line) in text.lines().enumerate() {
        let mut fields = line.split_whitespace();
        match fields.next() {
            Some("v") => {
                let coords: Vec<f64> = fields
                    .take(3)
                    .map(|s| s.parse::<f64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|e| Error::Mesh(format!("line {}: bad vertex: {e}", lineno + 1)))?;
                if coords.len() != 3 {
                    return Err(Error::Mesh(format!(
                        "line {}: vertex needs 3 coordinates",
                        lineno + 1
                    )));
                }
                positions.push(Vec3::new(coords[0], coords[1], coords[2]));
                vertex_lines.push(lineno + 1);
            }
            Some("f") => {
                let mut face = Vec::with_capacity(4);
                for entry in fields {
                    let index: i64 =
                        entry.split('/').next().unwrap_or("").parse().map_err(|e| {
                            Error::Mesh(format!(
                                "line {}: bad face index {entry:?}: {e}",
                                lineno + 1
                            ))
                        })?;
                    let resolved = if index > 0 {
                        index - 1
                    } else {
                        positions.len() as i64 + index
                    };
                    if index == 0 || resolved < 0 {
                        return Err(Error::Mesh(format!(
                            "line {}: face index {index} is out of range",
                            lineno + 1
                        )));
                    }
                    face.push(resolved as usize);
                }
                if face.len() < 3 {
                    return Err(Error::Mesh(format!(
                        "line {}: face has fewer than 3 vertices",
                        lineno + 1
                    )));
                }
                for k in 1..face.len() - 1 {
                    triangles.push([face[0], face[k], face[k + 1]]);
                }
            }
            _ => {}
        }
    }
    // (An index out of range is reported first, by TriMesh::new.)
    let mut used = vec![false; positions.len()];
    let in_range = triangles.iter().flatten().all(|&i| i < used.len());
    triangles.iter().flatten().for_each(|&i| {
        if let Some(u) = used.get_mut(i) {
            *u = true;
        }
    });
    let unused: Vec<usize> = (0..used.len()).filter(|&i| in_range && !used[i]).collect();
    if let Some(&first) = unused.first() {
        return Err(Error::Mesh(format!(
            "line {}: vertex {} is used by no face ({} unused vertices in all); it would have \
             no mass: remove unused vertices from the file",
            vertex_lines[first],
            first + 1,
            unused.len()
        )));
    }
    TriMesh::new(positions, triangles)
}

/// Writes the mesh with the given vertex positions (e.g. a simulated state) as OBJ.
pub fn write_obj(path: &std::path::Path, mesh: &TriMesh, positions: &[Vec3]) -> Result<()> {
    let mut out = String::with_capacity(40 * (positions.len() + mesh.triangles.len()));
    for p in positions {
        let _ = writeln!(out, "v {:.17e} {:.17e} {:.17e}", p.x, p.y, p.z);
    }
    for t in &mesh.triangles {
        let _ = writeln!(out, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(path, out).map_err(|e| Error::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_regular_files_are_read() {
        for path in ["/dev/zero", "/dev/urandom", "/"] {
            let err = read_obj(std::path::Path::new(path))
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(path) && err.contains("not a regular file"),
                "{err}"
            );
        }
    }

    #[test]
    fn parses_polygons_and_slashes() {
        let text = "# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n";
        let m = parse_obj(text).unwrap();
        assert_eq!(m.num_vertices(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        let rel = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n").unwrap();
        assert_eq!(rel.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn rejects_degenerate_and_out_of_range() {
        let err = parse_obj("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n").unwrap_err();
        assert!(err.to_string().contains("degenerate"), "{err}");
        let err = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").unwrap_err();
        assert!(err.to_string().contains("references vertex 3"), "{err}");
        // A sliver: 1 m long, 1e-7 m high (aspect 2e-7), next to a normal triangle.
        let sliver = "v 0 0 0\nv 1 0 0\nv 0.5 1e-7 0\nv 0.5 -1 0\nf 1 2 3\nf 1 4 2\n";
        let err = parse_obj(sliver).unwrap_err();
        assert!(err.to_string().contains("sliver"), "{err}");
        assert!(parse_obj(&sliver.replace("1e-7", "1e-5")).is_ok());
    }

    /// Issue 11: a BOM dropped the first vertex; an unused vertex failed later as "system
    /// matrix is not positive definite".
    #[test]
    fn a_byte_order_mark_is_skipped_and_unused_vertices_are_named() {
        let m = parse_obj("\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(m.num_vertices(), 3);
        let err = parse_obj("v 0 0 0\nv 1 0 0\nv 9 9 9\nv 0 1 0\nf 1 2 4\n").unwrap_err();
        assert!(
            err.to_string()
                .contains("line 3: vertex 3 is used by no face"),
            "{err}"
        );
    }

    #[test]
    fn write_then_read_round_trips() {
        let m = super::super::grid(3, 4, 1.0, 2.0, super::super::GridPlane::Xy).unwrap();
        let path = std::env::temp_dir().join(format!("diffcloth_rt_{}.obj", std::process::id()));
        write_obj(&path, &m, &m.positions).unwrap();
        let back = read_obj(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(back.triangles, m.triangles);
        for (a, b) in back.positions.iter().zip(&m.positions) {
            assert_eq!(a, b);
        }
    }
}
