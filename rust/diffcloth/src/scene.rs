//! Builds the simulated objects a config describes, validating as it goes: the mesh in its
//! placement, the attached nodes, obstacles, self-collision, contact tolerances, and the
//! initial parameters and solver settings. (The simulator builds only the effects the scene
//! declares.)

use crate::collision::{Motion, Obstacle, SelfCollision, Shape};
use crate::config::{
    AttachmentConfig, MaterialConfig, MeshConfig, ObstacleConfig, SceneConfig, Selection,
    SelfCollisionConfig, ShapeConfig,
};
use crate::contact::ContactSettings;
use crate::effects::Effects;
use crate::error::{Error, Result};
use crate::mesh::{garment, grid, read_obj, TriMesh};
use crate::params::{check_mu, validate_params, validate_solver, Params, SolverSettings};
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
    // The mesh was validated as loaded; placement can still ruin it (a huge scale overflows
    // the areas, a huge translation rounds a triangle's corners together), so validate again.
    placed.mesh = TriMesh::new(
        std::mem::take(&mut placed.mesh.positions),
        std::mem::take(&mut placed.mesh.triangles),
    )
    .map_err(|e| {
        Error::Config(format!(
            "placement (scale = {:e}, rotate_deg = {:?}, translate = {:?}) makes the mesh unusable: {}",
            p.scale, p.rotate_deg, p.translate,
            match e {
                Error::Mesh(m) => m,
                other => other.to_string(),
            }
        ))
    })?;
    Ok(placed)
}

/// Resolves the attached nodes: explicit indices, or a named selection.
pub fn attachment_nodes(cfg: &AttachmentConfig, placed: &PlacedMesh) -> Result<Vec<usize>> {
    let n = placed.mesh.num_vertices();
    let nodes = match (&cfg.select, cfg.nodes.is_empty()) {
        (Some(_), false) => {
            return Err(Error::Config(
                "attachments: give either `nodes` or `select`, not both".into(),
            ))
        }
        (None, true) => {
            return Err(Error::Config(
                "attachments: `nodes` or `select` is required".into(),
            ))
        }
        (None, false) => cfg.nodes.clone(),
        (Some(Selection::TopCorners), true) => top_corners(&placed.mesh),
        (Some(Selection::Handles), true) if !placed.handles.is_empty() => placed.handles.clone(),
        (Some(Selection::Handles), true) => {
            return Err(Error::Config(
                "attachments.select = \"handles\" needs a garment mesh".into(),
            ))
        }
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

fn build_shape(cfg: &ShapeConfig) -> Shape {
    let v = Vec3::from;
    match cfg {
        ShapeConfig::Plane { point, normal } => {
            let n = v(*normal);
            Shape::Plane {
                point: v(*point),
                normal: if n.norm() > 0.0 { n.normalize() } else { n },
            }
        }
        ShapeConfig::Sphere { center, radius } => Shape::Sphere {
            center: v(*center),
            radius: *radius,
        },
        ShapeConfig::Capsule { a, b, radius } => Shape::Capsule {
            a: v(*a),
            b: v(*b),
            radius: *radius,
        },
        ShapeConfig::Box {
            center,
            half_extents,
            rotate_deg,
        } => {
            let [rx, ry, rz] = rotate_deg.map(f64::to_radians);
            Shape::Box {
                center: v(*center),
                half_extents: v(*half_extents),
                rotation: nalgebra::Rotation3::from_euler_angles(rx, ry, rz),
            }
        }
        ShapeConfig::Bowl {
            center,
            radius,
            rim_height,
        } => Shape::Bowl {
            center: v(*center),
            radius: *radius,
            rim_height: *rim_height,
        },
        ShapeConfig::PyramidPit {
            apex,
            half_width,
            height,
        } => Shape::PyramidPit {
            apex: v(*apex),
            half_width: *half_width,
            height: *height,
        },
        ShapeConfig::Union { parts } => Shape::Union(parts.iter().map(build_shape).collect()),
    }
}

pub(crate) fn build_obstacle(index: usize, cfg: &ObstacleConfig) -> Result<Obstacle> {
    let shape = build_shape(&cfg.shape);
    shape
        .validate()
        .map_err(|e| Error::Config(format!("obstacles[{index}]: {e}")))?;
    check_mu(&format!("obstacles[{index}].mu"), cfg.mu, Error::Config)?;
    let motion = match (&cfg.velocity, &cfg.path) {
        (Some(_), Some(_)) => {
            return Err(Error::Config(format!(
                "obstacles[{index}]: give `velocity` or `path`, not both"
            )))
        }
        (Some(vel), None) => Motion::Linear {
            velocity: Vec3::from(*vel),
        },
        (None, Some(rows)) => {
            let ok = !rows.is_empty()
                && rows.iter().all(|r| r.iter().all(|c| c.is_finite()))
                && rows.windows(2).all(|w| w[1][0] > w[0][0]);
            if !ok {
                return Err(Error::Config(format!(
                    "obstacles[{index}].path needs finite rows [t, dx, dy, dz] with increasing t"
                )));
            }
            Motion::Path(
                rows.iter()
                    .map(|r| (r[0], Vec3::new(r[1], r[2], r[3])))
                    .collect(),
            )
        }
        (None, None) => Motion::Static,
    };
    Ok(Obstacle {
        shape,
        mu: cfg.mu,
        motion,
    })
}

/// Every obstacle of the scene, validated.
pub(crate) fn build_obstacles(cfgs: &[ObstacleConfig]) -> Result<Vec<Obstacle>> {
    cfgs.iter()
        .enumerate()
        .map(|(i, o)| build_obstacle(i, o))
        .collect()
}

pub(crate) fn build_self_collision(
    cfg: &SelfCollisionConfig,
    mesh: &TriMesh,
) -> Result<SelfCollision> {
    if !(cfg.radius > 0.0 && cfg.radius.is_finite()) {
        return Err(Error::Config(format!(
            "self_collision.radius must be positive, got {}",
            cfg.radius
        )));
    }
    check_mu("self_collision.mu", cfg.mu, Error::Config)?;
    Ok(SelfCollision::new(mesh, cfg.radius, cfg.mu))
}

/// The contact tolerances (defaults when the scene gives none).
pub(crate) fn contact_settings(cfg: &SceneConfig, effects: &Effects) -> Result<ContactSettings> {
    let c = cfg.contact.clone().unwrap_or_default();
    if !(c.thickness >= 0.0 && c.margin >= 0.0 && c.thickness.is_finite() && c.margin.is_finite()) {
        return Err(Error::Config(
            "contact.thickness and contact.margin must be non-negative".into(),
        ));
    }
    Ok(ContactSettings {
        thickness: c.thickness,
        margin: c.margin,
        friction: effects.friction,
        response: c.response,
    })
}

/// The scene's initial physical parameters, validated.
pub(crate) fn params_from_config(cfg: &SceneConfig) -> Result<Params> {
    let m = &cfg.material;
    let wind = cfg.wind.as_ref();
    let params = Params {
        h: cfg.h,
        density: m.density,
        k_stretch: m.k_stretch,
        k_bend: m.k_bend,
        k_attach: cfg.attachments.as_ref().map_or(0.0, |a| a.stiffness),
        gravity: Vec3::from(cfg.gravity),
        wind_direction: wind.map_or(Vec3::zeros(), |w| Vec3::from(w.direction)),
        wind_omega: wind.map_or(0.0, |w| w.omega),
        wind_phi: wind.map_or(0.0, |w| w.phi),
    };
    validate_params(&params)?;
    Ok(params)
}

/// The principal-stretch limits `[min, max]`, validated.
pub(crate) fn strain_limits(m: &MaterialConfig) -> Result<[f64; 2]> {
    let [lo, hi] = m.strain_limits;
    if !(lo > 0.0 && lo <= hi && hi.is_finite()) {
        return Err(Error::Config(format!(
            "material.strain_limits must satisfy 0 < min <= max, got [{lo}, {hi}]"
        )));
    }
    Ok([lo, hi])
}

/// The scene's solver settings, validated.
pub(crate) fn solver_from_config(s: &SolverSettings) -> Result<SolverSettings> {
    validate_solver(s)?;
    Ok(s.clone())
}
