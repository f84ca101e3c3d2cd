//! diffcloth: a differentiable projective-dynamics cloth simulator (after DiffCloth, Li et al.
//! 2022). Data flows one way: config -> [`Model`] (mesh, material, effects, the factored PD
//! matrix; shared by `Arc`) -> [`Simulator`]s (each its own state and workspace) stepping
//! forward, recording a tape, and running the adjoint backward. See `DESIGN.md` for the
//! physics.

pub mod anderson;
pub mod backward;
pub mod batch;
mod batch_shared;
pub mod cancel;
pub mod collision;
pub mod config;
pub mod contact;
pub mod delassus;
pub mod effects;
pub mod energy;
pub mod error;
pub mod forces;
pub mod forward;
pub(crate) mod gmres;
pub(crate) mod hessian;
pub mod linalg;
pub mod mesh;
pub mod params;
pub mod profile;
pub mod scene;
pub mod tape;

/// 3-vectors are nalgebra's (node positions, velocities, forces).
pub type Vec3 = nalgebra::Vector3<f64>;

pub use backward::{AdjointSolver, AdjointWarmStart, BackwardOptions, Gradients};
pub use batch::{Batch, MemberInput};
pub use cancel::Cancel;
pub use config::{BendModel, Effect, SceneConfig};
pub use contact::{Branch, BranchCounts, Contact, ContactKind};
pub use error::{Error, Result};
pub use forward::{Model, Overlaps, Simulator, StepInput, StepStats};
pub use params::{
    Acceleration, Param, ParamKind, ParamValue, Params, Polish, Preset, SolverSettings,
};
pub use profile::Profile;

/// Use one thread inside faer: its parallel sparse kernels are slower than sequential at cloth
/// sizes (STACK.md); parallelism comes from the local step and from batched environments.
pub fn init_linear_algebra() {
    faer::set_global_parallelism(faer::Par::Seq);
}
