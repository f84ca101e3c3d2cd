//! Builds the simulated objects a config describes: the mesh in its placement, node masses and
//! the attached nodes. (The simulator then builds only the effects the scene declares.)

use crate::config::{AttachmentConfig, MeshConfig, SceneConfig};
use crate::error::{Error, Result};
use crate::mesh::{garment, grid, read_obj, TriMesh};
use crate::Vec3;
use nalgebra::Rotation3;

/// A mesh with the named node sets its generator provides.
pub struct PlacedMesh {
    pub mesh: TriMesh,
    /// Garment handles (suggested end-effector nodes); empty for grids and OBJ files.
    pub handles: Vec<usize>,
}

pub fn build_mesh(cfg: &SceneConfig) -> Result<PlacedMesh> {
    let from_garment = |g: garment::Garment| -> Result<PlacedMesh> {
        let mesh = TriMesh::new(
            g.positions.iter().map(|&p| Vec3::from(p)).collect(),
            g.triangles,
        )?;
        Ok(PlacedMesh {
            mesh,
            handles: g.handles,
        })
    };
    let mut placed = match &cfg.mesh {
        MeshConfig::Grid {
            rows,
            cols,
            width,
            height,
            plane,
        } => PlacedMesh {
            mesh: grid(*rows, *cols, *width, *height, *plane)?,
            handles: Vec::new(),
        },
        MeshConfig::Hat {} => from_garment(garment::hat(&garment::HatParams::default()))?,
        MeshConfig::Sock {} => from_garment(garment::sock(&garment::SockParams::default()))?,
        MeshConfig::Obj { path } => PlacedMesh {
            mesh: read_obj(path)?,
            handles: Vec::new(),
        },
    };
    let p = &cfg.placement;
    if !(p.scale > 0.0 && p.scale.is_finite()) {
        return Err(Error::Config(format!(
            "placement.scale must be positive, got {}",
            p.scale
        )));
    }
    let [rx, ry, rz] = p.rotate_deg.map(f64::to_radians);
    let rotation = Rotation3::from_euler_angles(rx, ry, rz);
    placed
        .mesh
        .transform(p.scale, &rotation, Vec3::from(p.translate));
    Ok(placed)
}

/// Resolves the attached nodes: explicit indices, or a named selection.
pub fn attachment_nodes(cfg: &AttachmentConfig, placed: &PlacedMesh) -> Result<Vec<usize>> {
    let n = placed.mesh.num_vertices();
    let nodes = match (&cfg.select, cfg.nodes.is_empty()) {
        (Some(_), false) => {
            return Err(Error::Config("attachments: give either `nodes` or `select`, not both".into()))
        }
        (None, true) => return Err(Error::Config("attachments: `nodes` or `select` is required".into())),
        (None, false) => cfg.nodes.clone(),
        (Some(name), true) => match name.as_str() {
            "top_corners" => top_corners(&placed.mesh),
            "handles" if !placed.handles.is_empty() => placed.handles.clone(),
            "handles" => return Err(Error::Config("attachments.select = \"handles\" needs a garment mesh".into())),
            other => {
                return Err(Error::Config(format!(
                    "attachments.select: unknown selection {other:?} (known: \"top_corners\", \"handles\")"
                )))
            }
        },
    };
    if let Some(&bad) = nodes.iter().find(|&&i| i >= n) {
        return Err(Error::Config(format!(
            "attachments: node {bad} is out of range (mesh has {n} nodes)"
        )));
    }
    let mut sorted = nodes.clone();
    sorted.sort_unstable();
    sorted.dedup();
    if sorted.len() != nodes.len() {
        return Err(Error::Config("attachments: a node is listed twice".into()));
    }
    Ok(nodes)
}

/// The two highest nodes at the left and right ends of the top edge (a hanging cloth's corners).
fn top_corners(mesh: &TriMesh) -> Vec<usize> {
    let top = mesh
        .positions
        .iter()
        .map(|p| p.y)
        .fold(f64::NEG_INFINITY, f64::max);
    let tol = 1e-9 * mesh.bounding_box_diagonal();
    let on_top: Vec<usize> = (0..mesh.num_vertices())
        .filter(|&i| mesh.positions[i].y >= top - tol)
        .collect();
    let by_x = |a: &&usize, b: &&usize| mesh.positions[**a].x.total_cmp(&mesh.positions[**b].x);
    let left = *on_top.iter().min_by(by_x).expect("mesh is not empty");
    let right = *on_top.iter().max_by(by_x).expect("mesh is not empty");
    vec![left, right]
}
