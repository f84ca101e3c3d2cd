//! The knobs that can change between steps, and their validation (one place: the scene
//! builder, the setters and the binding all call these).

use crate::error::{Error, Result};
use crate::Vec3;

/// Physical parameters that can change between steps. Changing any of the first five
/// refactors the system matrix (once); the others only change right-hand sides.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// Time step h in s.
    pub h: f64,
    /// Area density in kg/m^2.
    pub density: f64,
    /// Stretch stiffness in N/m.
    pub k_stretch: f64,
    /// Bending stiffness in N m.
    pub k_bend: f64,
    /// Attachment spring stiffness in N/m.
    pub k_attach: f64,
    /// Gravitational acceleration in m/s^2.
    pub gravity: Vec3,
    /// Wind amplitude vector d, angular frequency omega (rad/s), phase phi (rad).
    pub wind_direction: Vec3,
    pub wind_omega: f64,
    pub wind_phi: f64,
}

/// Accuracy knobs of the PD solve.
#[derive(Debug, Clone, PartialEq)]
pub struct SolverSettings {
    /// Iteration cap per step.
    pub max_iterations: usize,
    /// Stop when the RMS per-coordinate PD update `|G(x) - x|` is below this (metres).
    pub tolerance: f64,
    /// Tolerance of steps recorded on a tape (see `SolverConfig::record_tolerance`).
    pub record_tolerance: f64,
    /// Iteration cap of recorded steps (the larger of this and `max_iterations`).
    pub record_max_iterations: usize,
    /// Energy-guarded Anderson acceleration on/off.
    pub anderson: bool,
    /// Anderson history length (1..=8).
    pub history: usize,
    /// Project constraints on all threads (for large meshes).
    pub parallel: bool,
}

/// A friction coefficient; `as_error` says whether a bad value is a config or parameter error
/// (so the message is not wrapped twice).
pub(crate) fn check_mu(name: &str, mu: f64, as_error: fn(String) -> Error) -> Result<()> {
    if !(mu >= 0.0 && mu.is_finite()) {
        return Err(as_error(format!(
            "{name} must be non-negative and finite, got {mu}"
        )));
    }
    Ok(())
}

pub(crate) fn check_nodes(name: &str, values: &[Vec3], expected: usize) -> Result<()> {
    if values.len() != expected {
        return Err(Error::Input(format!(
            "{name} must have {expected} rows (one per node), got {}",
            values.len()
        )));
    }
    if let Some(i) = values.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::Input(format!(
            "{name} row {i} is not finite: {:?}",
            values[i].as_slice()
        )));
    }
    Ok(())
}

pub(crate) fn validate_params(p: &Params) -> Result<()> {
    let positive = [("h", p.h), ("density", p.density)];
    for (name, v) in positive {
        if !(v > 0.0 && v.is_finite()) {
            return Err(Error::Param(format!(
                "{name} must be positive and finite, got {v}"
            )));
        }
    }
    let non_negative = [
        ("k_stretch", p.k_stretch),
        ("k_bend", p.k_bend),
        ("k_attach", p.k_attach),
    ];
    for (name, v) in non_negative {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(Error::Param(format!(
                "{name} must be non-negative and finite, got {v}"
            )));
        }
    }
    let finite = p
        .gravity
        .iter()
        .chain(p.wind_direction.iter())
        .all(|c| c.is_finite())
        && p.wind_omega.is_finite()
        && p.wind_phi.is_finite();
    if !finite {
        return Err(Error::Param(
            "gravity and wind parameters must be finite".into(),
        ));
    }
    Ok(())
}

pub(crate) fn validate_solver(s: &SolverSettings) -> Result<()> {
    if s.max_iterations == 0 {
        return Err(Error::Param(
            "solver max_iterations must be at least 1".into(),
        ));
    }
    if !(s.tolerance >= 0.0 && s.tolerance.is_finite()) {
        return Err(Error::Param(format!(
            "solver tolerance must be non-negative and finite, got {}",
            s.tolerance
        )));
    }
    if !(s.record_tolerance >= 0.0 && s.record_tolerance.is_finite()) {
        return Err(Error::Param(format!(
            "solver record_tolerance must be non-negative and finite, got {}",
            s.record_tolerance
        )));
    }
    if !(1..=crate::anderson::MAX_HISTORY).contains(&s.history) {
        return Err(Error::Param(format!(
            "solver history must be in 1..={}, got {}",
            crate::anderson::MAX_HISTORY,
            s.history
        )));
    }
    Ok(())
}
