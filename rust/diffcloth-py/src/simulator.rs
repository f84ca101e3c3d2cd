//! `diffcloth_gym._core.Simulator`: one method per core call; each converts its arguments,
//! runs the core through `guarded` (GIL released, panics caught) and converts the result.

use crate::conv::{
    backward_options, contacts_dict, f64_arg, gradients_dict, nodes_to_py, pairs_to_py,
    profile_dict, read_nodes, read_steps, set_param_item, stats_dict, triangles_to_py, usize_arg,
};
use crate::errors::{guarded, InputError, ParameterError};
use diffcloth::{
    Acceleration, Cancel, Param, ParamKind, ParamValue, Polish, Preset, SceneConfig, Simulator,
    SolverSettings, StepInput, StepStats, Vec3,
};
use numpy::{PyArray2, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::Path;
use std::sync::Mutex;

#[pyclass(name = "Simulator", module = "diffcloth_gym._core")]
pub(crate) struct PySimulator {
    pub(crate) inner: Simulator,
}

#[pymethods]
impl PySimulator {
    /// Builds a simulator from a scene config in JSON; relative paths resolve against base_dir.
    #[staticmethod]
    fn from_json(py: Python<'_>, config_json: &str, base_dir: &str) -> PyResult<Self> {
        let inner = guarded(py, || {
            diffcloth::init_linear_algebra();
            Simulator::new(&SceneConfig::from_json_str(
                config_json,
                Path::new(base_dir),
            )?)
        })?;
        Ok(Self { inner })
    }

    #[pyo3(signature = (x=None, v=None))]
    fn reset(
        &mut self,
        py: Python<'_>,
        x: Option<PyReadonlyArray2<'_, f64>>,
        v: Option<PyReadonlyArray2<'_, f64>>,
    ) -> PyResult<()> {
        let x = x.map(|a| read_nodes("x", &a)).transpose()?;
        let v = v.map(|a| read_nodes("v", &a)).transpose()?;
        let sim = &mut self.inner;
        guarded(py, || sim.reset(x.as_deref(), v.as_deref()))
    }

    /// Advances `steps` steps (None: 1) with the same inputs; returns the last step's stats.
    #[pyo3(signature = (attachment_targets=None, external_forces=None, steps=None))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        attachment_targets: Option<PyReadonlyArray2<'_, f64>>,
        external_forces: Option<PyReadonlyArray2<'_, f64>>,
        steps: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let steps = steps.map_or(Ok(1), |s| usize_arg("steps", s))?;
        let targets = attachment_targets
            .map(|a| read_nodes("attachment_targets", &a))
            .transpose()?;
        let forces = external_forces
            .map(|a| read_nodes("external_forces", &a))
            .transpose()?;
        let mut last = StepStats::default();
        for _ in 0..steps {
            let sim = &mut self.inner;
            last = guarded(py, || {
                sim.step(StepInput {
                    attachment_targets: targets.as_deref(),
                    external_forces: forces.as_deref(),
                })
            })?;
            // Ctrl-C between steps raises KeyboardInterrupt with the simulator at the last
            // completed step (the GIL is taken back once per step: microseconds).
            py.check_signals()?;
        }
        stats_dict(py, last)
    }

    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        nodes_to_py(py, self.inner.positions())
    }
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        nodes_to_py(py, self.inner.velocities())
    }
    #[getter]
    fn rest_positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        nodes_to_py(py, &self.inner.mesh().positions)
    }
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        triangles_to_py(py, &self.inner.mesh().triangles)
    }
    #[getter]
    fn masses(&self) -> Vec<f64> {
        self.inner.masses().to_vec()
    }
    #[getter]
    fn attachment_nodes(&self) -> Vec<usize> {
        self.inner.attachment_nodes().to_vec()
    }
    #[getter]
    fn attachment_targets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        nodes_to_py(py, self.inner.attachment_targets())
    }
    #[getter]
    fn handles(&self) -> Vec<usize> {
        self.inner.handles().to_vec()
    }
    #[getter]
    fn effects(&self) -> Vec<&'static str> {
        self.inner.effects().names()
    }
    #[getter]
    fn time(&self) -> f64 {
        self.inner.time()
    }
    #[setter]
    fn set_time(&mut self, py: Python<'_>, t: f64) -> PyResult<()> {
        let sim = &mut self.inner;
        guarded(py, || sim.set_time(t))
    }
    #[getter]
    fn step_count(&self) -> u64 {
        self.inner.step_count()
    }
    #[getter]
    fn num_nodes(&self) -> usize {
        self.inner.num_nodes()
    }

    /// Every physical parameter by its registry name (`mu_self` only with self-collision).
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for name in Param::ALL {
            if let Some(value) = self.inner.param(name) {
                set_param_item(&d, name, value)?;
            }
        }
        Ok(d)
    }

    /// Updates physical parameters by name (friction coefficients included); unknown names
    /// and bad values raise and change nothing.
    #[pyo3(signature = (**kwargs))]
    fn set_params(&mut self, py: Python<'_>, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<()> {
        let mut values = Vec::new();
        if let Some(kwargs) = kwargs {
            for (key, value) in kwargs.iter() {
                let key: String = key.extract()?;
                let name = Param::from_name(&key).ok_or_else(|| {
                    ParameterError::new_err(format!(
                        "unknown parameter {key:?}; known: {}",
                        Param::names()
                    ))
                })?;
                let bad =
                    || ParameterError::new_err(format!("{key} must be {}", name.kind().what()));
                let value = match name.kind() {
                    ParamKind::Vector => {
                        let a: [f64; 3] = value.extract().map_err(|_| bad())?;
                        ParamValue::Vector(Vec3::from(a))
                    }
                    ParamKind::List => ParamValue::List(value.extract().map_err(|_| bad())?),
                    ParamKind::Scalar => ParamValue::Scalar(value.extract().map_err(|_| bad())?),
                };
                values.push((name, value));
            }
        }
        let sim = &mut self.inner;
        guarded(py, || sim.set_param_values(&values))
    }

    fn solver<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.inner.solver();
        let d = PyDict::new(py);
        d.set_item("max_iterations", s.max_iterations)?;
        d.set_item("tolerance", s.tolerance)?;
        d.set_item("acceleration", s.acceleration.name())?;
        d.set_item("history", s.history)?;
        d.set_item("parallel", s.parallel)?;
        d.set_item("polish", s.polish.name())?;
        Ok(d)
    }

    /// Updates solver settings by name (preset, max_iterations, tolerance, acceleration,
    /// history, parallel, polish). A preset is applied first, explicit settings over it. Recorded and
    /// plain steps share every setting: the retired `record_tolerance` and
    /// `record_max_iterations` are accepted only equal to `tolerance` and `max_iterations`.
    #[pyo3(signature = (**kwargs))]
    fn set_solver(&mut self, py: Python<'_>, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<()> {
        let mut s: SolverSettings = self.inner.solver().clone();
        let mut retired: Vec<(String, f64)> = Vec::new();
        if let Some(kwargs) = kwargs {
            let preset_names = || Preset::ALL.map(|p| format!("{:?}", p.name())).join(" or ");
            if let Some(value) = kwargs.get_item("preset")? {
                let name: String = value.extract().map_err(|_| {
                    ParameterError::new_err(format!("preset must be {}", preset_names()))
                })?;
                let preset = Preset::from_name(&name).ok_or_else(|| {
                    ParameterError::new_err(format!(
                        "preset must be {}, got {name:?}",
                        preset_names()
                    ))
                })?;
                preset.apply(&mut s);
            }
            for (key, value) in kwargs.iter() {
                let key: String = key.extract()?;
                let bad = |what: &str| ParameterError::new_err(format!("{key} must be {what}"));
                match key.as_str() {
                    "preset" => {}
                    "max_iterations" => s.max_iterations = value.extract().map_err(|_| bad("a positive integer"))?,
                    "tolerance" => s.tolerance = value.extract().map_err(|_| bad("a number"))?,
                    "record_tolerance" | "record_max_iterations" => {
                        retired.push((key.clone(), value.extract().map_err(|_| bad("a number"))?))
                    }
                    "history" => s.history = value.extract().map_err(|_| bad("an integer"))?,
                    "parallel" => s.parallel = value.extract().map_err(|_| bad("a bool"))?,
                    "acceleration" => {
                        let a: String = value.extract().map_err(|_| bad("\"anderson\" or \"none\""))?;
                        let a = Acceleration::from_name(&a).ok_or_else(|| bad("\"anderson\" or \"none\""))?;
                        s.acceleration = a;
                    }
                    "polish" => {
                        let a: String = value
                            .extract()
                            .map_err(|_| bad("\"newton\", \"semismooth\" or \"none\""))?;
                        s.polish = Polish::from_name(&a)
                            .ok_or_else(|| bad("\"newton\", \"semismooth\" or \"none\""))?;
                    }
                    other => {
                        return Err(ParameterError::new_err(format!(
                            "unknown solver setting {other:?}; known: preset, max_iterations, tolerance, \
                             acceleration, history, parallel, polish"
                        )))
                    }
                }
            }
        }
        for (key, value) in retired {
            let (shared, current) = if key == "record_tolerance" {
                ("tolerance", s.tolerance)
            } else {
                ("max_iterations", s.max_iterations as f64)
            };
            if value != current {
                return Err(ParameterError::new_err(format!(
                    "{key} is retired: recorded steps converge like every other step (one \
                     trajectory whether recorded or not); set {shared} (now {current:e}), or \
                     preset=\"gradient\" for gradient work"
                )));
            }
        }
        let sim = &mut self.inner;
        guarded(py, || sim.set_solver(s))
    }

    /// Per-stage wall time (seconds) and counters accumulated since the last reset_profile().
    fn profile<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        profile_dict(py, self.inner.profile())
    }

    fn reset_profile(&mut self) {
        self.inner.reset_profile();
    }

    fn last_step<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        stats_dict(py, self.inner.last_step())
    }

    /// The last step's contacts as arrays: node_a, node_b (-1 for obstacle contacts),
    /// obstacle (-1 for self-contacts), normal (k, 3), gap, mu, branch (0 take off, 1 stick,
    /// 2 slip), impulse (k, 3) on node_a in N s.
    fn contacts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        contacts_dict(py, self.inner.contacts())
    }

    /// A message if the current state has nodes inside an obstacle or self-contact pairs
    /// closer than the radius (the first step throws them out), else None.
    fn overlap_warning(&self) -> Option<String> {
        self.inner.overlap_warning()
    }

    /// Signed distance of every node to obstacle `index` at the current time, shape (n,).
    fn obstacle_distance(&self, index: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
        let index = usize_arg("index", index)?;
        let obstacles = self.inner.obstacles();
        let Some(o) = obstacles.get(index) else {
            return Err(InputError::new_err(format!(
                "obstacle {index} does not exist ({} obstacles)",
                obstacles.len()
            )));
        };
        Ok(self
            .inner
            .positions()
            .iter()
            .map(|p| o.query(p, self.inner.time()).0)
            .collect())
    }

    /// Sets the friction coefficient of obstacle `index`.
    fn set_obstacle_mu(
        &mut self,
        py: Python<'_>,
        index: &Bound<'_, PyAny>,
        mu: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let (index, mu) = (usize_arg("index", index)?, f64_arg("mu", mu)?);
        let sim = &mut self.inner;
        guarded(py, || sim.set_obstacle_mu(index, mu))
    }

    /// Sets the self-contact friction coefficient.
    fn set_self_mu(&mut self, py: Python<'_>, mu: &Bound<'_, PyAny>) -> PyResult<()> {
        let mu = f64_arg("mu", mu)?;
        let sim = &mut self.inner;
        guarded(py, || sim.set_self_mu(mu))
    }

    /// Starts (clearing the tape) or stops recording steps for backward(); with
    /// checkpoint_every = K only every K-th state (plus each step's inputs) is kept and
    /// backward re-simulates segments.
    #[pyo3(signature = (on, checkpoint_every=None))]
    fn set_recording(
        &mut self,
        on: bool,
        checkpoint_every: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let checkpoint_every = checkpoint_every
            .map(|k| usize_arg("checkpoint_every", k))
            .transpose()?;
        match (on, checkpoint_every) {
            (true, Some(0)) => Err(ParameterError::new_err(
                "checkpoint_every must be at least 1",
            )),
            (true, Some(k)) => {
                self.inner.set_recording_checkpointed(k);
                Ok(())
            }
            _ => {
                self.inner.set_recording(on);
                Ok(())
            }
        }
    }

    /// (recorded steps, bytes held by the tape).
    fn tape_info(&self) -> (usize, usize) {
        self.inner.tape().map_or((0, 0), |t| (t.len(), t.bytes()))
    }

    /// Backpropagates dL/dx and dL/dv of every recorded step's output (arrays (N, n, 3) or
    /// None) and returns the gradients as a dict. Options left None take the core's defaults
    /// (`BackwardOptions::default()`, their one home).
    #[pyo3(signature = (dl_dx=None, dl_dv=None, solver=None, tolerance=None, max_iterations=None))]
    fn backward<'py>(
        &mut self,
        py: Python<'py>,
        dl_dx: Option<PyReadonlyArray3<'_, f64>>,
        dl_dv: Option<PyReadonlyArray3<'_, f64>>,
        solver: Option<&str>,
        tolerance: Option<f64>,
        max_iterations: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let options = backward_options(solver, tolerance, max_iterations)?;
        let (gx, gv) = (read_steps("dl_dx", dl_dx)?, read_steps("dl_dv", dl_dv)?);
        let sim = &mut self.inner;
        // Ctrl-C: the core polls this check (at most every 50 ms, between and inside adjoint
        // solves); it takes the GIL back for a moment and keeps the signal handler's exception
        // (KeyboardInterrupt, or whatever a custom handler raised) to re-raise as it was.
        let interrupt: Mutex<Option<PyErr>> = Mutex::new(None);
        let check = || match Python::attach(|py| py.check_signals()) {
            Ok(()) => false,
            Err(e) => {
                *interrupt.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
                true
            }
        };
        let result = guarded(py, || {
            sim.backward_cancellable(&gx, &gv, &options, &Cancel::new(&check))
        });
        if let Some(e) = interrupt.into_inner().unwrap_or_else(|p| p.into_inner()) {
            return Err(e);
        }
        gradients_dict(py, &result?)
    }

    /// Records (on) or stops recording (off) the PD convergence trace of each step.
    fn set_trace(&mut self, on: bool) {
        self.inner.set_trace(on);
    }

    /// The last step's convergence trace, shape (iterations, 2): the step objective E and
    /// the RMS PD update after each iteration (empty when tracing is off).
    fn trace<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        pairs_to_py(py, self.inner.trace().unwrap_or_default())
    }

    /// Kinetic + gravitational + elastic energy of the current state.
    fn mechanical_energy(&mut self) -> f64 {
        self.inner.mechanical_energy()
    }

    /// Principal stretches (s1 >= s2) of every triangle at the current state, shape (t, 2).
    fn principal_stretches<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let s = self
            .inner
            .stretch()
            .map(|s| s.principal_stretches(self.inner.positions()))
            .unwrap_or_default();
        pairs_to_py(py, &s)
    }

    /// Writes the current state as an OBJ file.
    fn write_obj(&self, py: Python<'_>, path: &str) -> PyResult<()> {
        let sim = &self.inner;
        guarded(py, || {
            diffcloth::mesh::write_obj(Path::new(path), sim.mesh(), sim.positions())
        })
    }
}
