//! `diffcloth_gym._core.Renderer`: the software renderer (`diffcloth-render`) holding its
//! buffers across frames; converts the camera dict and the frame, releases the GIL while
//! rasterizing. Renderer errors are bad input (`InputError`, naming the argument).

use crate::batch::PyBatch;
use crate::conv::usize_arg;
use crate::errors::{guarded, to_py_err, InputError};
use crate::simulator::PySimulator;
use diffcloth::Vec3;
use diffcloth_render::{Camera, Renderer, SceneView};
use numpy::{PyArray1, PyArray3, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

#[pyclass(name = "Renderer", module = "diffcloth_gym._core")]
pub(crate) struct PyRenderer {
    inner: Renderer,
}

/// Keys of a camera dict.
const CAMERA_KEYS: [&str; 4] = ["eye", "target", "up", "fov"];

fn render_error(e: diffcloth_render::RenderError) -> diffcloth::Error {
    diffcloth::Error::Input(e.to_string())
}

/// The default framing with the entries of `camera` (a dict: eye, target, up, fov) in place
/// of its own.
fn read_camera(default: Camera, camera: Option<&Bound<'_, PyDict>>) -> PyResult<Camera> {
    let mut cam = default;
    let Some(dict) = camera else {
        return Ok(cam);
    };
    for (key, value) in dict.iter() {
        let key: String = key
            .extract()
            .map_err(|_| InputError::new_err("camera keys must be strings"))?;
        if !CAMERA_KEYS.contains(&key.as_str()) {
            return Err(InputError::new_err(format!(
                "unknown camera key {key:?} (expected one of {CAMERA_KEYS:?})"
            )));
        }
        if key == "fov" {
            cam.fov_y = value.extract::<f64>().map_err(|_| {
                InputError::new_err(format!(
                    "camera.fov must be a number of degrees, got {value}"
                ))
            })?;
            continue;
        }
        let v: Vec<f64> = value
            .extract()
            .ok()
            .filter(|v: &Vec<f64>| v.len() == 3)
            .ok_or_else(|| {
                InputError::new_err(format!("camera.{key} must be 3 numbers, got {value}"))
            })?;
        let v = Vec3::new(v[0], v[1], v[2]);
        match key.as_str() {
            "eye" => cam.eye = v,
            "target" => cam.target = v,
            _ => cam.up = v,
        }
    }
    cam.validate()
        .map_err(|e| InputError::new_err(format!("invalid input: {e}")))?;
    Ok(cam)
}

impl PyRenderer {
    /// One frame of `core`'s current state (GIL released while rasterizing).
    fn frame<'py>(
        &mut self,
        py: Python<'py>,
        core: &diffcloth::Simulator,
        camera: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let cam = read_camera(self.inner.framing(&SceneView::of(core)).camera, camera)?;
        let renderer = &mut self.inner;
        let frame = guarded(py, || {
            renderer
                .render_to_vec(&SceneView::of(core), Some(&cam))
                .map_err(render_error)
        })?;
        let (w, h) = (self.inner.width(), self.inner.height());
        PyArray1::from_vec(py, frame).reshape([h, w, 3])
    }
}

#[pymethods]
impl PyRenderer {
    /// A renderer of width x height pixels (each 1..=4096), reused across frames.
    #[new]
    fn new(width: &Bound<'_, PyAny>, height: &Bound<'_, PyAny>) -> PyResult<Self> {
        let (w, h) = (usize_arg("width", width)?, usize_arg("height", height)?);
        let inner =
            Renderer::new(w, h).map_err(|e| InputError::new_err(format!("invalid input: {e}")))?;
        Ok(Self { inner })
    }

    #[getter]
    fn width(&self) -> usize {
        self.inner.width()
    }
    #[getter]
    fn height(&self) -> usize {
        self.inner.height()
    }

    /// The simulator's current state as an (height, width, 3) uint8 RGB frame.
    #[pyo3(signature = (sim, camera=None))]
    fn render<'py>(
        &mut self,
        py: Python<'py>,
        sim: PyRef<'_, PySimulator>,
        camera: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let core = &sim.inner;
        self.frame(py, core, camera)
    }

    /// Member `index` of a batch as an (height, width, 3) uint8 RGB frame (the envs' frames).
    #[pyo3(signature = (batch, index, camera=None))]
    fn render_member<'py>(
        &mut self,
        py: Python<'py>,
        batch: PyRef<'_, PyBatch>,
        index: &Bound<'_, PyAny>,
        camera: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let index = usize_arg("index", index)?;
        let core = batch.inner.member(index).map_err(to_py_err)?;
        self.frame(py, core, camera)
    }

    /// The default camera for a simulator's scene: {"eye", "target", "up", "fov"}.
    fn default_camera<'py>(
        &self,
        py: Python<'py>,
        sim: PyRef<'_, PySimulator>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let cam = self.inner.framing(&SceneView::of(&sim.inner)).camera;
        let d = PyDict::new(py);
        d.set_item("eye", cam.eye.as_slice().to_vec())?;
        d.set_item("target", cam.target.as_slice().to_vec())?;
        d.set_item("up", cam.up.as_slice().to_vec())?;
        d.set_item("fov", cam.fov_y)?;
        Ok(d)
    }
}
