//! Conversions between numpy arrays / dicts and the core's types. Everything returned to
//! Python is a fresh copy: callers may keep or mutate it without touching the simulator.

use crate::errors::{InputError, ParameterError};
use diffcloth::{
    AdjointSolver, BackwardOptions, Branch, Contact, ContactKind, Gradients, Param, ParamValue,
    Profile, StepStats, Vec3,
};
use numpy::ndarray::{Array2, Array3};
use numpy::{Element, PyArray2, PyArray3, PyReadonlyArray2, PyReadonlyArray3, ToPyArray};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Copies an (n, 3) float64 array into nodes, naming the argument in errors.
pub(crate) fn read_nodes(name: &str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<Vec3>> {
    let view = a.as_array();
    let shape = view.shape();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(InputError::new_err(format!(
            "{name} must have shape (n, 3), got {shape:?}"
        )));
    }
    Ok(view
        .outer_iter()
        .map(|r| Vec3::new(r[0], r[1], r[2]))
        .collect())
}

/// Copies a (steps, n, 3) float64 array into per-step nodes; `None` is no steps.
pub(crate) fn read_steps(
    name: &str,
    a: Option<PyReadonlyArray3<'_, f64>>,
) -> PyResult<Vec<Vec<Vec3>>> {
    let Some(a) = a else { return Ok(Vec::new()) };
    let view = a.as_array();
    if view.shape()[2] != 3 {
        return Err(InputError::new_err(format!(
            "{name} must have shape (steps, n, 3), got {:?}",
            view.shape()
        )));
    }
    Ok(view
        .outer_iter()
        .map(|step| {
            step.outer_iter()
                .map(|r| Vec3::new(r[0], r[1], r[2]))
                .collect()
        })
        .collect())
}

/// A (len / cols, cols) array from row-major values. Copied so numpy owns the result
/// (`flags.owndata`, resizable) like every other array the binding returns.
pub(crate) fn array2<T: Element>(
    py: Python<'_>,
    cols: usize,
    flat: Vec<T>,
) -> Bound<'_, PyArray2<T>> {
    Array2::from_shape_vec((flat.len() / cols, cols), flat)
        .expect("row-major values fill whole rows")
        .to_pyarray(py)
}

/// Nodes as an (n, 3) float64 array.
pub(crate) fn nodes_to_py<'py>(py: Python<'py>, nodes: &[Vec3]) -> Bound<'py, PyArray2<f64>> {
    array2(py, 3, nodes.iter().flat_map(|p| [p.x, p.y, p.z]).collect())
}

/// Pairs as an (k, 2) float64 array (convergence traces, principal stretches).
pub(crate) fn pairs_to_py<'py>(py: Python<'py>, pairs: &[(f64, f64)]) -> Bound<'py, PyArray2<f64>> {
    array2(py, 2, pairs.iter().flat_map(|&(a, b)| [a, b]).collect())
}

/// Triangles as a (t, 3) int64 array (numpy's default integer, unlike usize).
pub(crate) fn triangles_to_py<'py>(py: Python<'py>, t: &[[usize; 3]]) -> Bound<'py, PyArray2<i64>> {
    array2(py, 3, t.iter().flat_map(|t| t.map(|i| i as i64)).collect())
}

/// One step's solver stats: iterations, residual, converged, contacts {take_off, stick, slip}.
pub(crate) fn stats_dict(py: Python<'_>, s: StepStats) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("iterations", s.iterations)?;
    d.set_item("residual", s.residual)?;
    d.set_item("converged", s.converged)?;
    let c = PyDict::new(py);
    c.set_item("take_off", s.contacts.take_off)?;
    c.set_item("stick", s.contacts.stick)?;
    c.set_item("slip", s.contacts.slip)?;
    d.set_item("contacts", c)?;
    Ok(d)
}

/// The forward profile: stage times in seconds and counters, all as floats.
pub(crate) fn profile_dict<'py>(py: Python<'py>, p: &Profile) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in p.entries() {
        d.set_item(k, v)?;
    }
    Ok(d)
}

/// Contacts as arrays with one entry per contact (columns, not a list of records, so a
/// caller can mask and plot them directly); -1 marks "no such node / obstacle".
pub(crate) fn contacts_dict<'py>(py: Python<'py>, cs: &[Contact]) -> PyResult<Bound<'py, PyDict>> {
    let (mut a, mut b, mut o, mut gap, mut mu, mut branch) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    let (mut normal, mut impulse) = (vec![], vec![]);
    for c in cs {
        match c.kind {
            ContactKind::Obstacle { node, obstacle } => {
                a.push(node as i64);
                b.push(-1i64);
                o.push(obstacle as i64);
            }
            ContactKind::SelfPair { a: na, b: nb } => {
                a.push(na as i64);
                b.push(nb as i64);
                o.push(-1i64);
            }
        }
        gap.push(c.gap);
        mu.push(c.mu);
        branch.push(match c.branch {
            Branch::TakeOff => 0i64,
            Branch::Stick => 1,
            Branch::Slip => 2,
        });
        normal.push(c.normal);
        impulse.push(c.impulse);
    }
    let d = PyDict::new(py);
    d.set_item("node_a", a.to_pyarray(py))?;
    d.set_item("node_b", b.to_pyarray(py))?;
    d.set_item("obstacle", o.to_pyarray(py))?;
    d.set_item("normal", nodes_to_py(py, &normal))?;
    d.set_item("gap", gap.to_pyarray(py))?;
    d.set_item("mu", mu.to_pyarray(py))?;
    d.set_item("branch", branch.to_pyarray(py))?;
    d.set_item("impulse", nodes_to_py(py, &impulse))?;
    Ok(d)
}

/// backward()'s result: gradients by parameter name, per-step solver stats, a stage profile
/// and the warnings.
pub(crate) fn gradients_dict<'py>(py: Python<'py>, g: &Gradients) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("x0", nodes_to_py(py, &g.x0))?;
    d.set_item("v0", nodes_to_py(py, &g.v0))?;
    d.set_item("attachment_targets", steps_to_py(py, &g.attachment_targets))?;
    d.set_item("external_forces", steps_to_py(py, &g.external_forces))?;
    for name in Param::ALL {
        if let Some(value) = g.param(name) {
            set_param_item(&d, name, value)?;
        }
    }
    let per_step = |v: Vec<f64>| v.to_pyarray(py);
    d.set_item(
        "iterations",
        g.steps
            .iter()
            .map(|s| s.iterations as i64)
            .collect::<Vec<_>>()
            .to_pyarray(py),
    )?;
    d.set_item(
        "fell_back",
        g.steps
            .iter()
            .map(|s| s.fell_back)
            .collect::<Vec<_>>()
            .to_pyarray(py),
    )?;
    d.set_item(
        "factored",
        g.steps
            .iter()
            .map(|s| s.factored)
            .collect::<Vec<_>>()
            .to_pyarray(py),
    )?;
    d.set_item(
        "residual",
        per_step(g.steps.iter().map(|s| s.residual).collect()),
    )?;
    let prof = PyDict::new(py);
    prof.set_item("dp_s", g.profile.dp.as_secs_f64())?;
    prof.set_item("dr_s", g.profile.dr.as_secs_f64())?;
    prof.set_item("solve_s", g.profile.solve.as_secs_f64())?;
    prof.set_item("other_s", g.profile.other.as_secs_f64())?;
    d.set_item("profile", prof)?;
    d.set_item("warnings", g.warnings.clone())?;
    Ok(d)
}

/// Per-step nodes as one (steps, k, 3) float64 array (k = 0 where a step has none: the
/// effect is off).
pub(crate) fn steps_to_py<'py>(py: Python<'py>, rows: &[Vec<Vec3>]) -> Bound<'py, PyArray3<f64>> {
    let k = rows.iter().map(Vec::len).max().unwrap_or(0);
    let mut flat = Vec::with_capacity(rows.len() * k * 3);
    for r in rows {
        // Steps without entries (none recorded for this input) are zero rows.
        flat.extend(r.iter().flat_map(|p| [p.x, p.y, p.z]));
        flat.extend(std::iter::repeat_n(0.0, (k - r.len()) * 3));
    }
    Array3::from_shape_vec((rows.len(), k, 3), flat)
        .expect("rows padded to k")
        .to_pyarray(py)
}

/// `d[name] = value`: a float, a list of 3 for vector parameters, a list per obstacle.
pub(crate) fn set_param_item(
    d: &Bound<'_, PyDict>,
    name: Param,
    value: ParamValue,
) -> PyResult<()> {
    match value {
        ParamValue::Scalar(x) => d.set_item(name.name(), x),
        ParamValue::Vector(v) => d.set_item(name.name(), v.as_slice().to_vec()),
        ParamValue::List(v) => d.set_item(name.name(), v),
    }
}

/// A non-negative integer argument (an index or a count). Anything else, negative or beyond
/// 64 bits included, is an `InputError` naming the argument, not pyo3's `OverflowError` or
/// `TypeError`.
pub(crate) fn usize_arg(name: &str, value: &Bound<'_, PyAny>) -> PyResult<usize> {
    value.extract::<usize>().map_err(|_| {
        let shown = value.repr().map_or_else(|_| "?".into(), |r| r.to_string());
        InputError::new_err(format!(
            "{name} must be a non-negative integer of at most 64 bits, got {shown}"
        ))
    })
}

/// A number argument; anything else is a `ParameterError` naming it.
pub(crate) fn f64_arg(name: &str, value: &Bound<'_, PyAny>) -> PyResult<f64> {
    value.extract::<f64>().map_err(|_| {
        let shown = value.repr().map_or_else(|_| "?".into(), |r| r.to_string());
        ParameterError::new_err(format!("{name} must be a number, got {shown}"))
    })
}

/// Adjoint options from the binding's keyword arguments (None: the core's defaults).
pub(crate) fn backward_options(
    solver: Option<&str>,
    tolerance: Option<f64>,
    max_iterations: Option<&Bound<'_, PyAny>>,
) -> PyResult<BackwardOptions> {
    let defaults = BackwardOptions::default();
    let solver = match solver {
        None => defaults.solver,
        Some("direct") => AdjointSolver::Direct,
        Some("krylov") => AdjointSolver::Krylov,
        Some("fixed_point") => AdjointSolver::FixedPoint,
        Some(other) => {
            return Err(ParameterError::new_err(format!(
                "solver must be \"direct\", \"krylov\" or \"fixed_point\", got {other:?}"
            )))
        }
    };
    Ok(BackwardOptions {
        solver,
        tolerance: tolerance.unwrap_or(defaults.tolerance),
        max_iterations: max_iterations
            .map(|m| usize_arg("max_iterations", m))
            .transpose()?
            .unwrap_or(defaults.max_iterations),
    })
}
