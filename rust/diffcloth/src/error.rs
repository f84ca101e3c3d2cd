//! Typed errors at the crate boundary. The binding crate maps each variant once to a Python
//! exception (all of them `ValueError` subclasses except `Solver`/`Diverged`).

/// Everything that can go wrong in the simulator, with a message naming the problem.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A scene configuration is malformed (unknown key, missing field, wrong type, bad value).
    #[error("invalid scene config: {0}")]
    Config(String),
    /// A mesh cannot be simulated (index out of range, degenerate triangle, non-finite vertex).
    #[error("invalid mesh: {0}")]
    Mesh(String),
    /// A per-step input has the wrong shape or contains non-finite values.
    #[error("invalid input: {0}")]
    Input(String),
    /// A physical parameter is out of its valid range (e.g. negative stiffness).
    #[error("invalid parameter: {0}")]
    Param(String),
    /// Reading or writing a file failed.
    #[error("I/O error on {path}: {message}")]
    Io { path: String, message: String },
    /// A factorization or linear solve failed (e.g. matrix not positive definite).
    #[error("linear solver failed: {0}")]
    Solver(String),
    /// A feature that is not available for this input yet (the message says which).
    #[error("not supported: {0}")]
    Unsupported(String),
    /// Contact could not be resolved (a node keeps crossing an obstacle); the step was
    /// rolled back.
    #[error("contact failed: {0}")]
    Contact(String),
    /// The state became non-finite; the step was rolled back.
    #[error("simulation diverged: {0}")]
    Diverged(String),
    /// The caller's cancellation check asked the call to stop (see [`crate::Cancel`]); the
    /// message names the stage. Nothing the call would have changed was changed.
    #[error("cancelled during {0}")]
    Cancelled(String),
}

pub type Result<T> = std::result::Result<T, Error>;
