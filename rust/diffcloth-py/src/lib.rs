//! Thin Python binding (`diffcloth_gym._core`): converts arrays, maps errors to the exception
//! tree in `diffcloth_gym.errors`, releases the GIL for long calls. No physics here.
//!
//! - `simulator`: the `Simulator` class, one method per core call;
//! - `batch`: the `Batch` class, N simulators on one model stepped in parallel;
//! - `conv`: numpy arrays and dicts to and from the core's types;
//! - `errors`: core errors to Python exceptions, and the panic guard;
//! - `render`: the `Renderer` class (the software renderer of `diffcloth-render`).
//!
//! The Python-side type stub is `diffcloth_gym/_core.pyi` (kept in sync by
//! `tests/test_core_stub.py`).

mod batch;
mod conv;
mod errors;
mod render;
mod simulator;

use pyo3::prelude::*;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<simulator::PySimulator>()?;
    m.add_class::<batch::PyBatch>()?;
    m.add_class::<render::PyRenderer>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // The differentiable parameters, from the core's one name table.
    let names: Vec<&str> = diffcloth::Param::ALL
        .into_iter()
        .filter(|p| p.differentiable())
        .map(diffcloth::Param::name)
        .collect();
    m.add("PARAM_NAMES", names)?;
    Ok(())
}
