//! `diffcloth_gym._core.Batch`: N simulators on one shared model, stepped in parallel (GIL
//! released) with one call. Arrays carry the member index first: (N, n, 3) states, (N, k, 3)
//! attachment targets.

use crate::conv::{backward_options, read_nodes, read_steps, stats_dict, usize_arg};
use crate::errors::{guarded, to_py_err, InputError};
use crate::simulator::PySimulator;
use diffcloth::{Batch, MemberInput, Vec3};
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray3, PyReadonlyArray2, PyReadonlyArray3, ToPyArray};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

#[pyclass(name = "Batch", module = "diffcloth_gym._core")]
pub(crate) struct PyBatch {
    pub(crate) inner: Batch,
}

/// Rows of equal length as an (N, rows, 3) float64 array (one buffer, handed to numpy
/// without a second copy: an env reads positions and velocities every step, serially).
fn members_to_py<'py>(py: Python<'py>, rows: &[&[Vec3]]) -> Bound<'py, PyArray3<f64>> {
    let per = rows.first().map_or(0, |r| r.len());
    let mut flat = Vec::with_capacity(rows.len() * per * 3);
    for r in rows {
        for p in r.iter() {
            flat.extend_from_slice(&[p.x, p.y, p.z]);
        }
    }
    Array3::from_shape_vec((rows.len(), per, 3), flat)
        .expect("members have equal row counts")
        .into_pyarray(py)
}

impl PyBatch {
    fn check_members(&self, name: &str, rows: &[Vec<Vec3>]) -> PyResult<()> {
        if rows.len() != self.inner.len() {
            return Err(InputError::new_err(format!(
                "{name} must have one entry per member ({}), got {}",
                self.inner.len(),
                rows.len()
            )));
        }
        Ok(())
    }
}

#[pymethods]
impl PyBatch {
    /// `size` simulators sharing `sim`'s model (its factorization) and solver settings, each
    /// at the rest state, not recording. `threads`: run on a thread pool of the batch's own
    /// with that many threads (default: rayon's global pool, sized by `RAYON_NUM_THREADS`).
    #[new]
    #[pyo3(signature = (sim, size, threads=None))]
    fn new(
        py: Python<'_>,
        sim: &PySimulator,
        size: &Bound<'_, PyAny>,
        threads: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let size = usize_arg("size", size)?;
        let threads = threads.map(|t| usize_arg("threads", t)).transpose()?;
        let (model, solver) = (sim.inner.model().clone(), sim.inner.solver().clone());
        let inner = guarded(py, || match threads {
            Some(t) => Batch::with_threads(model, solver, size, t),
            None => Batch::new(model, solver, size),
        })?;
        Ok(Self { inner })
    }

    /// Threads a batched step runs on.
    #[getter]
    fn threads(&self) -> usize {
        self.inner.threads()
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// Resets member `index` (x, v: (n, 3); defaults: rest positions, zero velocity); its
    /// tape, if recording, is cleared.
    #[pyo3(signature = (index, x=None, v=None))]
    fn reset(
        &mut self,
        py: Python<'_>,
        index: &Bound<'_, PyAny>,
        x: Option<PyReadonlyArray2<'_, f64>>,
        v: Option<PyReadonlyArray2<'_, f64>>,
    ) -> PyResult<()> {
        let index = usize_arg("index", index)?;
        let x = x.map(|a| read_nodes("x", &a)).transpose()?;
        let v = v.map(|a| read_nodes("v", &a)).transpose()?;
        let batch = &mut self.inner;
        guarded(py, || {
            batch.member_mut(index)?.reset(x.as_deref(), v.as_deref())
        })
    }

    /// Starts (clearing the tapes) or stops recording on every member.
    fn set_recording(&mut self, py: Python<'_>, on: bool) -> PyResult<()> {
        let batch = &mut self.inner;
        guarded(py, || {
            batch.for_each_mut(|s| s.set_recording(on));
            Ok(())
        })
    }

    /// One step of every member in parallel. `attachment_targets` (N, k, 3) and
    /// `external_forces` (N, n, 3) give each member's inputs (None: keep the targets / no
    /// force). Returns one entry per member: None when it stepped, else the exception (not
    /// raised) that its step raised; a failed member stays at its previous step.
    #[pyo3(signature = (attachment_targets=None, external_forces=None))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        attachment_targets: Option<PyReadonlyArray3<'_, f64>>,
        external_forces: Option<PyReadonlyArray3<'_, f64>>,
    ) -> PyResult<Bound<'py, PyList>> {
        let has_targets = attachment_targets.is_some();
        let has_forces = external_forces.is_some();
        let targets = read_steps("attachment_targets", attachment_targets)?;
        let forces = read_steps("external_forces", external_forces)?;
        if has_targets {
            self.check_members("attachment_targets", &targets)?;
        }
        if has_forces {
            self.check_members("external_forces", &forces)?;
        }
        let size = self.inner.len();
        let batch = &mut self.inner;
        let results = guarded(py, || {
            let inputs: Vec<MemberInput> = (0..size)
                .map(|i| MemberInput {
                    attachment_targets: targets.get(i).map(Vec::as_slice),
                    external_forces: forces.get(i).map(Vec::as_slice),
                })
                .collect();
            batch.step(&inputs)
        })?;
        let out = PyList::empty(py);
        for r in results {
            match r {
                Ok(_) => out.append(py.None())?,
                Err(e) => out.append(to_py_err(e).into_value(py))?,
            }
        }
        py.check_signals()?;
        Ok(out)
    }

    /// Positions of every member, (N, n, 3).
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        let rows: Vec<&[Vec3]> = self.inner.members().map(|s| s.positions()).collect();
        members_to_py(py, &rows)
    }

    /// Velocities of every member, (N, n, 3).
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        let rows: Vec<&[Vec3]> = self.inner.members().map(|s| s.velocities()).collect();
        members_to_py(py, &rows)
    }

    /// Attachment targets in effect of every member, (N, k, 3).
    fn attachment_targets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        let rows: Vec<&[Vec3]> = self
            .inner
            .members()
            .map(|s| s.attachment_targets())
            .collect();
        members_to_py(py, &rows)
    }

    /// Steps taken since each member's reset.
    fn step_counts(&self) -> Vec<u64> {
        self.inner.members().map(|s| s.step_count()).collect()
    }

    /// `(recorded steps, bytes held)` of each member's tape ((0, 0) when not recording).
    fn tape_info(&self) -> Vec<(usize, usize)> {
        self.inner
            .members()
            .map(|s| s.tape().map_or((0, 0), |t| (t.len(), t.bytes())))
            .collect()
    }

    /// The last step's solver stats of each member.
    fn last_steps<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .members()
            .map(|s| stats_dict(py, s.last_step()))
            .collect()
    }

    /// The last step's solver stats of every member as arrays (what an env reads every
    /// step, without a dict per member): `iterations` (N,) int64, `residual` (N,) float64,
    /// `converged` (N,) bool.
    fn last_stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let stats: Vec<_> = self.inner.members().map(|s| s.last_step()).collect();
        let d = PyDict::new(py);
        let iterations: Vec<i64> = stats.iter().map(|s| s.iterations as i64).collect();
        let residual: Vec<f64> = stats.iter().map(|s| s.residual).collect();
        let converged: Vec<bool> = stats.iter().map(|s| s.converged).collect();
        d.set_item("iterations", iterations.to_pyarray(py))?;
        d.set_item("residual", residual.to_pyarray(py))?;
        d.set_item("converged", converged.to_pyarray(py))?;
        Ok(d)
    }

    /// The profile (times, iteration and contact counts) of member `index`.
    fn profile<'py>(
        &self,
        py: Python<'py>,
        index: &Bound<'_, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let index = usize_arg("index", index)?;
        let sim = self.inner.member(index).map_err(to_py_err)?;
        crate::conv::profile_dict(py, sim.profile())
    }

    /// The one-step adjoint of recorded step `step` on every member in parallel: from the
    /// loss gradients on the step's outputs, `dl_dx`/`dl_dv` (N, n, 3), returns a dict of
    /// the gradients on its inputs: `x`, `v`, `external_forces` (N, n, 3),
    /// `attachment_targets` (N, k, 3), and `warnings` (per member, a list of strings). Each
    /// member's chain of calls in decreasing `step` order is warm-started.
    #[pyo3(signature = (step, dl_dx, dl_dv, solver=None, tolerance=None, max_iterations=None))]
    #[allow(clippy::too_many_arguments)]
    fn backward_step<'py>(
        &mut self,
        py: Python<'py>,
        step: &Bound<'_, PyAny>,
        dl_dx: PyReadonlyArray3<'_, f64>,
        dl_dv: PyReadonlyArray3<'_, f64>,
        solver: Option<&str>,
        tolerance: Option<f64>,
        max_iterations: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let k = usize_arg("step", step)?;
        let options = backward_options(solver, tolerance, max_iterations)?;
        let (gx, gv) = (
            read_steps("dl_dx", Some(dl_dx))?,
            read_steps("dl_dv", Some(dl_dv))?,
        );
        self.check_members("dl_dx", &gx)?;
        self.check_members("dl_dv", &gv)?;
        let batch = &mut self.inner;
        let results = guarded(py, || batch.backward_step(k, &gx, &gv, &options))?;
        let grads = results
            .into_iter()
            .collect::<diffcloth::Result<Vec<_>>>()
            .map_err(to_py_err)?;
        let field = |f: fn(&diffcloth::Gradients, usize) -> &[Vec3]| {
            let rows: Vec<&[Vec3]> = grads.iter().map(|g| f(g, k)).collect();
            members_to_py(py, &rows)
        };
        let d = PyDict::new(py);
        d.set_item("x", field(|g, _| &g.x0))?;
        d.set_item("v", field(|g, _| &g.v0))?;
        d.set_item("attachment_targets", field(|g, k| &g.attachment_targets[k]))?;
        d.set_item("external_forces", field(|g, k| &g.external_forces[k]))?;
        let warnings: Vec<Vec<String>> = grads.iter().map(|g| g.warnings.clone()).collect();
        d.set_item("warnings", warnings)?;
        Ok(d)
    }
}
