//! Scene configuration as read from the scene TOMLs (`diffcloth_gym/configs/*.toml`) or a
//! Python dict. Unknown keys are errors that name the key: a typo must never silently fall
//! back to a default.

use crate::error::{Error, Result};
use crate::mesh::GridPlane;
use crate::params::SolverSettings;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A whole scene: mesh, material, time step, the effects it simulates and their parameters.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneConfig {
    /// Scene name (informational).
    #[serde(default)]
    pub name: String,
    /// Time step h in seconds.
    pub h: f64,
    /// Default episode length in steps (used by environments and benchmarks).
    #[serde(default = "default_steps")]
    pub steps: usize,
    /// The effects this scene simulates; anything not listed is not computed.
    pub effects: Vec<Effect>,
    pub mesh: MeshConfig,
    /// Rigid placement of the mesh applied after loading/generation.
    #[serde(default)]
    pub placement: Placement,
    pub material: MaterialConfig,
    /// Gravitational acceleration in m/s^2 (default `[0, -9.8, 0]`). Used if `gravity` is on.
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    pub attachments: Option<AttachmentConfig>,
    pub wind: Option<WindConfig>,
    /// Contact tolerances (defaults apply when a contact effect is on and this is absent).
    pub contact: Option<ContactConfig>,
    /// Analytic obstacles (needs the `obstacle_contact` effect).
    #[serde(default)]
    pub obstacles: Vec<ObstacleConfig>,
    pub self_collision: Option<SelfCollisionConfig>,
    #[serde(default)]
    pub solver: SolverSettings,
}

/// A physical effect a scene can switch on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    Gravity,
    Stretch,
    Bend,
    Attachments,
    Wind,
    /// Per-node forces passed to each step.
    ExternalForces,
    /// Non-penetration against the scene's obstacles.
    ObstacleContact,
    /// Coulomb friction in every contact (else contacts are frictionless).
    Friction,
    /// Node-node contact between non-adjacent cloth nodes.
    SelfCollision,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum MeshConfig {
    /// A rectangular `rows x cols` node grid of `width x height` metres.
    Grid {
        rows: usize,
        cols: usize,
        width: f64,
        height: f64,
        plane: GridPlane,
    },
    /// The procedural hat (crown + brim, ~600 nodes) sized for a head sphere of radius 2.1.
    Hat {},
    /// The procedural sock (tube with a heel bend, closed toe, ~1000 nodes).
    Sock {},
    /// A user mesh; a relative `path` is resolved against the config file's folder.
    Obj { path: PathBuf },
}

/// `p -> rotation(rotate_deg, applied x then y then z) * (scale * p) + translate`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    #[serde(default = "one")]
    pub scale: f64,
    /// Rotation about x, y, z in degrees.
    #[serde(default)]
    pub rotate_deg: [f64; 3],
    #[serde(default)]
    pub translate: [f64; 3],
}

impl Default for Placement {
    fn default() -> Self {
        Self {
            scale: 1.0,
            rotate_deg: [0.0; 3],
            translate: [0.0; 3],
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialConfig {
    /// Area density in kg/m^2 (lumped mass = density x one third of incident areas).
    pub density: f64,
    /// Stretch stiffness in N/m (weight = k_stretch x rest area). Default 0.
    #[serde(default)]
    pub k_stretch: f64,
    /// Bending stiffness in N m (weights per [`BendModel`]). Default 0.
    #[serde(default)]
    pub k_bend: f64,
    /// Which bending model `k_bend` drives (default: edge, the reference DiffCloth model, so
    /// that the paper's k_bend values mean what they mean there).
    #[serde(default)]
    pub bend_model: BendModel,
    /// Principal-stretch limits `[s_min, s_max]`; `[1, 1]` (default) is as-rigid-as-possible.
    #[serde(default = "unit_limits")]
    pub strain_limits: [f64; 2],
}

/// The bending model (`material.bend_model`); both keep a curved rest shape force-free.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BendModel {
    /// One constraint per interior edge (default; the reference DiffCloth code's model): the
    /// cotangent stencil of the edge's two triangles, weight `3 k_bend / (A0 + A1)`.
    #[default]
    Edge,
    /// One constraint per interior vertex: the cotangent-Laplacian mean-curvature vector,
    /// weight `k_bend x` mixed Voronoi area (the default before the edge model existed).
    Vertex,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttachmentConfig {
    /// Spring stiffness of each attachment in N/m (default 1e4, as the reference code).
    #[serde(default = "default_attach_stiffness")]
    pub stiffness: f64,
    /// Attached node indices, or
    #[serde(default)]
    pub nodes: Vec<usize>,
    /// a named selection.
    #[serde(default)]
    pub select: Option<Selection>,
}

/// `attachments.select`: a named set of nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Selection {
    /// The two highest nodes at the left and right ends of the top edge (grids).
    TopCorners,
    /// The garment's handles (its suggested end-effector nodes).
    Handles,
}

/// Wind after the paper's Appendix B (Eqn. 35 and the T-shirt sinusoid):
/// `f_a(t) = 0.5 (sin(omega t + phi) + 1) k_a d`, scaled by the node's area if
/// `per_area` (default: then `d` is a force per unit area and the scene's response does not
/// depend on the mesh resolution), else applied per node as in the paper.
/// `wind.profile`: the per-node factor `k_a`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WindProfile {
    /// `k_a = 1` (default).
    #[default]
    Uniform,
    /// `k_a = 1 /` the node's distance to the mesh centroid at rest (the paper's Flag).
    InverseDistance,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindConfig {
    /// Amplitude vector d (N/m^2 if `per_area`, else N per node).
    pub direction: [f64; 3],
    /// Angular frequency omega in rad/s.
    #[serde(default)]
    pub omega: f64,
    /// Phase phi in rad.
    #[serde(default)]
    pub phi: f64,
    /// How the wind's strength varies over the cloth (default: uniform).
    #[serde(default)]
    pub profile: WindProfile,
    #[serde(default = "yes")]
    pub per_area: bool,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactConfig {
    /// Distance kept between nodes and obstacle surfaces in m (default 0.01).
    #[serde(default = "default_thickness")]
    pub thickness: f64,
    /// Extra detection distance in m (default 0.01).
    #[serde(default = "default_margin")]
    pub margin: f64,
    /// How a PD iteration predicts the contact nodes' response (see [`ContactResponse`]).
    #[serde(default)]
    pub response: ContactResponse,
}

/// How each PD iteration solves the contact law (both reach the same solution).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ContactResponse {
    /// `Inertia`, switching a step to `Delassus` when it stalls on stiff contacts (see
    /// `forward/response.rs`): stiff cloth at large steps stays out of the obstacles, and
    /// every other step is solved exactly as with `Inertia`.
    #[default]
    Auto,
    /// Each contact node moves with its own inertia against the iterate (paper Eqn. 12):
    /// free per iteration, but slow for stiff cloth at large steps (`k h^2 / m` >> 1), where
    /// unconverged steps can leave nodes inside obstacles.
    Inertia,
    /// Exact for the current local step via the Delassus operator `C P^{-1} C^T`, formed
    /// once per step (`c / 3` extra solves for c contact nodes): every iterate respects the
    /// contact law. For stiff cloth with few contact nodes (the Hat on its head, stiff cloth
    /// draped at large steps). Its per-iteration Gauss-Seidel on `W` is slow when many stiff,
    /// strongly coupled nodes are all in contact (a stiff ribbon sliding on a slope).
    Delassus,
}

impl Default for ContactConfig {
    fn default() -> Self {
        Self {
            thickness: default_thickness(),
            margin: default_margin(),
            response: ContactResponse::default(),
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleConfig {
    pub shape: ShapeConfig,
    /// Coulomb friction coefficient (default 0).
    #[serde(default)]
    pub mu: f64,
    /// Constant velocity in m/s (default: static).
    pub velocity: Option<[f64; 3]>,
    /// Piecewise-linear path: rows `[t, dx, dy, dz]` of offsets from the placement.
    pub path: Option<Vec<[f64; 4]>>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeConfig {
    Plane {
        point: [f64; 3],
        normal: [f64; 3],
    },
    Sphere {
        center: [f64; 3],
        radius: f64,
    },
    Capsule {
        a: [f64; 3],
        b: [f64; 3],
        radius: f64,
    },
    Box {
        center: [f64; 3],
        half_extents: [f64; 3],
        #[serde(default)]
        rotate_deg: [f64; 3],
    },
    /// Spherical cavity of `radius` around `center`, open above `y = rim_height`.
    Bowl {
        center: [f64; 3],
        radius: f64,
        rim_height: f64,
    },
    /// Upside-down square pyramid pit: walls from `apex` to a square of `half_width` at
    /// `apex.y + height`, solid around it below that rim.
    PyramidPit {
        apex: [f64; 3],
        half_width: f64,
        height: f64,
    },
    Union {
        parts: Vec<ShapeConfig>,
    },
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SelfCollisionConfig {
    /// Contact distance between two nodes in m.
    pub radius: f64,
    /// Friction coefficient between cloth layers (default 0.1, as the reference).
    #[serde(default = "default_self_mu")]
    pub mu: f64,
}

fn default_thickness() -> f64 {
    0.01
}
fn default_margin() -> f64 {
    0.01
}
fn default_self_mu() -> f64 {
    0.1
}
fn default_steps() -> usize {
    100
}
fn default_gravity() -> [f64; 3] {
    [0.0, -9.8, 0.0]
}
fn one() -> f64 {
    1.0
}
fn yes() -> bool {
    true
}
fn unit_limits() -> [f64; 2] {
    [1.0, 1.0]
}
fn default_attach_stiffness() -> f64 {
    1e4
}

impl SceneConfig {
    /// Parses a TOML scene file; relative mesh paths are resolved against its folder.
    pub fn from_toml_file(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        let mut cfg: Self = Self::from_toml_str(&text)
            .map_err(|e| Error::Config(format!("{}: {e}", path.display())))?;
        cfg.resolve_paths(path.parent().unwrap_or(Path::new(".")));
        Ok(cfg)
    }

    pub fn from_toml_str(text: &str) -> Result<Self> {
        // A byte-order mark (some Windows editors write one) is not part of TOML.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        toml::from_str(text).map_err(|e| Error::Config(e.to_string()))
    }

    /// Parses JSON (what the Python layer sends); relative paths resolve against `base_dir`.
    pub fn from_json_str(text: &str, base_dir: &Path) -> Result<Self> {
        let mut cfg: Self = serde_json::from_str(text).map_err(|e| Error::Config(e.to_string()))?;
        cfg.resolve_paths(base_dir);
        Ok(cfg)
    }

    fn resolve_paths(&mut self, base: &Path) {
        if let MeshConfig::Obj { path } = &mut self.mesh {
            if path.is_relative() {
                *path = base.join(&*path);
            }
        }
    }

    pub fn has(&self, effect: Effect) -> bool {
        self.effects.contains(&effect)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material(extra: &str) -> Result<SceneConfig> {
        SceneConfig::from_toml_str(&format!(
            "h = 0.01\neffects = []\n[mesh]\nkind = \"hat\"\n[material]\ndensity = 0.1\n{extra}"
        ))
    }

    #[test]
    fn bend_model_defaults_to_edge_and_parses_vertex() {
        assert_eq!(material("").unwrap().material.bend_model, BendModel::Edge);
        let vertex = material("bend_model = \"vertex\"").unwrap();
        assert_eq!(vertex.material.bend_model, BendModel::Vertex);
        let err = material("bend_model = \"hinge\"").unwrap_err().to_string();
        assert!(err.contains("hinge"), "{err}");
    }
}
