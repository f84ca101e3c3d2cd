//! Core errors to Python exceptions: one `match` from `diffcloth::Error` to the exception
//! tree in `diffcloth_gym.errors`, and the panic guard every long call goes through.

use diffcloth::Error;
use pyo3::prelude::*;
use std::panic::{catch_unwind, AssertUnwindSafe};

// Checked handles on the Python classes (imported once, on first use). `_core` is only ever
// loaded as part of the `diffcloth_gym` package, whose `__init__` imports `errors` first.
pyo3::import_exception!(diffcloth_gym.errors, DiffClothError);
pyo3::import_exception!(diffcloth_gym.errors, ConfigError);
pyo3::import_exception!(diffcloth_gym.errors, MeshError);
pyo3::import_exception!(diffcloth_gym.errors, InputError);
pyo3::import_exception!(diffcloth_gym.errors, ParameterError);
pyo3::import_exception!(diffcloth_gym.errors, SolverError);
pyo3::import_exception!(diffcloth_gym.errors, DivergedError);
pyo3::import_exception!(diffcloth_gym.errors, ContactError);
pyo3::import_exception!(diffcloth_gym.errors, UnsupportedError);
pyo3::import_exception!(diffcloth_gym.errors, InternalError);

/// The Python exception for a core error: the one place a core error's message is made.
pub(crate) fn to_py_err(err: Error) -> PyErr {
    // The full Display text, thiserror's prefix included ("invalid parameter: ..."):
    // callers and tests match on it.
    let message = err.to_string();
    match err {
        // An unreadable scene or mesh file is a config problem to the caller.
        Error::Config(_) | Error::Io { .. } => ConfigError::new_err(message),
        Error::Mesh(_) => MeshError::new_err(message),
        Error::Input(_) => InputError::new_err(message),
        Error::Param(_) => ParameterError::new_err(message),
        Error::Solver(_) => SolverError::new_err(message),
        Error::Diverged(_) => DivergedError::new_err(message),
        Error::Contact(_) => ContactError::new_err(message),
        Error::Unsupported(_) => UnsupportedError::new_err(message),
        // Only reached when a cancellation had no exception of its own to re-raise.
        Error::Cancelled(_) => pyo3::exceptions::PyKeyboardInterrupt::new_err(message),
        // `Error` is non_exhaustive: a variant added later still reaches the base class.
        _ => DiffClothError::new_err(message),
    }
}

/// Runs core code without the GIL; a panic (a bug, never bad input) becomes `InternalError`
/// instead of tearing down the interpreter.
pub(crate) fn guarded<T: Send>(
    py: Python<'_>,
    f: impl FnOnce() -> diffcloth::Result<T> + Send,
) -> PyResult<T> {
    match py.detach(|| catch_unwind(AssertUnwindSafe(f))) {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_py_err(e)),
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            Err(InternalError::new_err(format!(
                "internal error in the simulator (please report): {msg}"
            )))
        }
    }
}
