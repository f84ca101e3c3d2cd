//! The knobs that can change between steps, and their validation (one place: the scene
//! builder, the setters and the binding all call these).

use crate::error::{Error, Result};
use crate::Vec3;
use serde::Deserialize;

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

/// The physical parameters by name: the one table the binding (`params`, `set_params`),
/// `diffcloth_gym.torch` (through `_core.PARAM_NAMES`) and the gradients all use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Param {
    H,
    Density,
    KStretch,
    KBend,
    KAttach,
    Gravity,
    WindDirection,
    WindOmega,
    WindPhi,
}

/// A parameter's value: a scalar or a 3-vector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamValue {
    Scalar(f64),
    Vector(Vec3),
}

impl Param {
    pub const ALL: [Param; 9] = [
        Param::H,
        Param::Density,
        Param::KStretch,
        Param::KBend,
        Param::KAttach,
        Param::Gravity,
        Param::WindDirection,
        Param::WindOmega,
        Param::WindPhi,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Param::H => "h",
            Param::Density => "density",
            Param::KStretch => "k_stretch",
            Param::KBend => "k_bend",
            Param::KAttach => "k_attach",
            Param::Gravity => "gravity",
            Param::WindDirection => "wind_direction",
            Param::WindOmega => "wind_omega",
            Param::WindPhi => "wind_phi",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    pub fn is_vector(self) -> bool {
        matches!(self, Param::Gravity | Param::WindDirection)
    }

    /// Whether backward gives its gradient (not the time step: it sets the discretization).
    pub fn differentiable(self) -> bool {
        self != Param::H
    }

    /// Every name, comma-separated (for error messages).
    pub fn names() -> String {
        Self::ALL.map(Param::name).join(", ")
    }
}

impl Params {
    pub fn get(&self, p: Param) -> ParamValue {
        use ParamValue::{Scalar, Vector};
        match p {
            Param::H => Scalar(self.h),
            Param::Density => Scalar(self.density),
            Param::KStretch => Scalar(self.k_stretch),
            Param::KBend => Scalar(self.k_bend),
            Param::KAttach => Scalar(self.k_attach),
            Param::Gravity => Vector(self.gravity),
            Param::WindDirection => Vector(self.wind_direction),
            Param::WindOmega => Scalar(self.wind_omega),
            Param::WindPhi => Scalar(self.wind_phi),
        }
    }

    /// Sets one parameter (not validated: see [`validate_params`]); a value of the wrong kind
    /// is an error naming the parameter.
    pub fn set(&mut self, p: Param, value: ParamValue) -> Result<()> {
        match (p, value) {
            (Param::Gravity, ParamValue::Vector(v)) => self.gravity = v,
            (Param::WindDirection, ParamValue::Vector(v)) => self.wind_direction = v,
            (_, ParamValue::Scalar(x)) if !p.is_vector() => {
                *match p {
                    Param::H => &mut self.h,
                    Param::Density => &mut self.density,
                    Param::KStretch => &mut self.k_stretch,
                    Param::KBend => &mut self.k_bend,
                    Param::KAttach => &mut self.k_attach,
                    Param::WindOmega => &mut self.wind_omega,
                    _ => &mut self.wind_phi,
                } = x
            }
            _ => {
                let kind = if p.is_vector() {
                    "3 numbers"
                } else {
                    "a number"
                };
                return Err(Error::Param(format!("{} must be {kind}", p.name())));
            }
        }
        Ok(())
    }
}

/// `solver.acceleration`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Acceleration {
    /// Energy-guarded Anderson acceleration (default).
    #[default]
    Anderson,
    /// Plain local-global iterations.
    None,
}

impl Acceleration {
    /// The name used in configs and by the Python binding.
    pub fn name(self) -> &'static str {
        match self {
            Self::Anderson => "anderson",
            Self::None => "none",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        [Self::Anderson, Self::None]
            .into_iter()
            .find(|a| a.name() == name)
    }
}

/// Largest iteration cap a step may have: caps size the per-iteration trace, and a step
/// that needs more iterations than this is not going to converge anyway.
pub const MAX_ITERATIONS: usize = 1_000_000;

/// The accuracy knobs of the PD solve (`[solver]` in a scene config, `set_solver` at run
/// time): their one home, with their defaults.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverSettings {
    /// Iteration cap per step (default 300; at most [`MAX_ITERATIONS`]).
    #[serde(default = "default_max_iterations")]
    pub max_iterations: usize,
    /// Stop when the RMS per-coordinate PD update `|G(x) - x|` falls below this, in metres
    /// (default 1e-8). `G(x) - x = -P^{-1} grad E(x)`: a preconditioned gradient norm.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Tolerance for steps recorded on a tape (default 1e-11): the adjoint linearizes each step
    /// at its end state, which must be the converged implicit-Euler solution (at 1e-8 the Hat's
    /// 400-step target gradients were 29 % off; at 1e-10, 0.04 %; Wind 24x24, which has no
    /// bending and amplifies per-step differences, 0.9 % at 1e-10 and 0.3 % at 1e-11, for
    /// about 10 % more time). Steps converge to
    /// `min(tolerance, record_tolerance)` while recording; the extra iterations are counted as
    /// polish in the profile.
    #[serde(default = "default_record_tolerance")]
    pub record_tolerance: f64,
    /// Iteration cap of recorded steps (default 2000; the larger of this and max_iterations;
    /// at most [`MAX_ITERATIONS`]).
    #[serde(default = "default_record_max_iterations")]
    pub record_max_iterations: usize,
    /// Acceleration of the local-global iterations (default: anderson).
    #[serde(default)]
    pub acceleration: Acceleration,
    /// Anderson history length (default 5).
    #[serde(default = "default_history")]
    pub history: usize,
    /// Parallel local step for large meshes (default true).
    #[serde(default = "yes")]
    pub parallel: bool,
}

impl Default for SolverSettings {
    fn default() -> Self {
        Self {
            max_iterations: default_max_iterations(),
            tolerance: default_tolerance(),
            record_tolerance: default_record_tolerance(),
            record_max_iterations: default_record_max_iterations(),
            acceleration: Acceleration::default(),
            history: default_history(),
            parallel: true,
        }
    }
}

fn default_max_iterations() -> usize {
    300
}
fn default_tolerance() -> f64 {
    1e-8
}
fn default_record_max_iterations() -> usize {
    2000
}
fn default_record_tolerance() -> f64 {
    1e-11
}
fn default_history() -> usize {
    5
}
fn yes() -> bool {
    true
}

impl SolverSettings {
    /// Iterations a step can take (recorded steps may take more), plus the first: the length
    /// of a full trace. Bounded by the validation's [`MAX_ITERATIONS`].
    pub(crate) fn trace_capacity(&self) -> usize {
        self.max_iterations.max(self.record_max_iterations) + 1
    }
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
    for (name, cap) in [
        ("max_iterations", s.max_iterations),
        ("record_max_iterations", s.record_max_iterations),
    ] {
        if cap > MAX_ITERATIONS {
            return Err(Error::Param(format!(
                "solver {name} must be at most {MAX_ITERATIONS}, got {cap}"
            )));
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Params {
        Params {
            h: 0.01,
            density: 0.2,
            k_stretch: 100.0,
            k_bend: 0.1,
            k_attach: 1e4,
            gravity: Vec3::new(0.0, -9.8, 0.0),
            wind_direction: Vec3::new(1.0, 0.0, 0.5),
            wind_omega: 2.0,
            wind_phi: 0.3,
        }
    }

    /// Every name parses back to its parameter, and set/get round-trip every field (so the
    /// table cannot miss one).
    #[test]
    fn the_name_table_covers_every_parameter() {
        let mut p = sample();
        for (i, name) in Param::ALL.into_iter().enumerate() {
            assert_eq!(Param::from_name(name.name()), Some(name));
            let value = if name.is_vector() {
                ParamValue::Vector(Vec3::repeat(i as f64 + 0.5))
            } else {
                ParamValue::Scalar(i as f64 + 0.5)
            };
            p.set(name, value).unwrap();
            assert_eq!(p.get(name), value);
        }
        // All fields changed: none is left at its sample value.
        let s = sample();
        assert!(Param::ALL.into_iter().all(|n| p.get(n) != s.get(n)));
        assert!(p.set(Param::Gravity, ParamValue::Scalar(1.0)).is_err());
        assert!(p.set(Param::H, ParamValue::Vector(Vec3::zeros())).is_err());
        assert_eq!(Param::from_name("mu"), None);
    }

    /// Iteration caps size the trace: a cap beyond MAX_ITERATIONS is refused by name.
    #[test]
    fn iteration_caps_are_bounded() {
        let ok = SolverSettings::default();
        assert!(validate_solver(&ok).is_ok());
        for bad in [
            SolverSettings {
                max_iterations: 1 << 40,
                ..ok.clone()
            },
            SolverSettings {
                record_max_iterations: usize::MAX,
                ..ok.clone()
            },
        ] {
            let err = validate_solver(&bad).unwrap_err().to_string();
            assert!(err.contains("at most 1000000"), "{err}");
        }
    }
}
