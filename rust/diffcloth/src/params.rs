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
/// `diffcloth_gym.torch` (through `_core.PARAM_NAMES`) and the gradients all use. The friction
/// coefficients belong to the obstacles and the self-collision set, not to [`Params`]; the
/// simulator's `param` / `set_param_values` reach them by the same names.
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
    /// Coulomb friction coefficient of each obstacle, in config order (a list).
    MuObstacles,
    /// Coulomb friction coefficient of self-contact (scenes with self-collision).
    MuSelf,
}

/// A parameter's value: a scalar, a 3-vector, or one number per obstacle.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamValue {
    Scalar(f64),
    Vector(Vec3),
    List(Vec<f64>),
}

/// What kind of value a parameter takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamKind {
    Scalar,
    Vector,
    List,
}

impl Param {
    pub const ALL: [Param; 11] = [
        Param::H,
        Param::Density,
        Param::KStretch,
        Param::KBend,
        Param::KAttach,
        Param::Gravity,
        Param::WindDirection,
        Param::WindOmega,
        Param::WindPhi,
        Param::MuObstacles,
        Param::MuSelf,
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
            Param::MuObstacles => "mu_obstacles",
            Param::MuSelf => "mu_self",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    pub fn kind(self) -> ParamKind {
        match self {
            Param::Gravity | Param::WindDirection => ParamKind::Vector,
            Param::MuObstacles => ParamKind::List,
            _ => ParamKind::Scalar,
        }
    }

    pub fn is_vector(self) -> bool {
        self.kind() == ParamKind::Vector
    }

    /// Whether the parameter lives in [`Params`] (the friction coefficients do not).
    pub fn in_params(self) -> bool {
        !matches!(self, Param::MuObstacles | Param::MuSelf)
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
    /// A parameter held by `Params` (None for the friction coefficients: see [`Param`]).
    pub fn get(&self, p: Param) -> Option<ParamValue> {
        use ParamValue::{Scalar, Vector};
        Some(match p {
            Param::H => Scalar(self.h),
            Param::Density => Scalar(self.density),
            Param::KStretch => Scalar(self.k_stretch),
            Param::KBend => Scalar(self.k_bend),
            Param::KAttach => Scalar(self.k_attach),
            Param::Gravity => Vector(self.gravity),
            Param::WindDirection => Vector(self.wind_direction),
            Param::WindOmega => Scalar(self.wind_omega),
            Param::WindPhi => Scalar(self.wind_phi),
            Param::MuObstacles | Param::MuSelf => return None,
        })
    }

    /// Sets one parameter (not validated: see [`validate_params`]); a value of the wrong kind,
    /// or a friction coefficient (set through the simulator), is an error naming the parameter.
    pub fn set(&mut self, p: Param, value: ParamValue) -> Result<()> {
        match (p, value) {
            (Param::Gravity, ParamValue::Vector(v)) => self.gravity = v,
            (Param::WindDirection, ParamValue::Vector(v)) => self.wind_direction = v,
            (_, ParamValue::Scalar(x)) if p.kind() == ParamKind::Scalar && p.in_params() => {
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
            _ if !p.in_params() => {
                return Err(Error::Param(format!(
                    "{} is not held by Params (set it through the simulator)",
                    p.name()
                )))
            }
            _ => {
                return Err(Error::Param(format!(
                    "{} must be {}",
                    p.name(),
                    p.kind().what()
                )))
            }
        }
        Ok(())
    }
}

impl ParamKind {
    /// What a value of this kind is, for error messages.
    pub fn what(self) -> &'static str {
        match self {
            ParamKind::Scalar => "a number",
            ParamKind::Vector => "3 numbers",
            ParamKind::List => "one number per obstacle",
        }
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

/// `solver.polish`: what finishes a step once PD is near its solution.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Polish {
    /// PD (and its acceleration) all the way to the tolerance.
    #[default]
    None,
    /// Newton steps on the step's objective (PCG preconditioned by the PD factor, safeguarded),
    /// where no contact pushes: see `forward/newton.rs`.
    Newton,
    /// `Newton`, plus semi-smooth Newton steps where contacts push (the contact law
    /// linearized at its current branches; GMRES preconditioned by the factored Hessian with
    /// the contact-constrained directions eliminated): see `forward/contact_newton.rs`. Same
    /// fixed point, same stopping test.
    Semismooth,
}

impl Polish {
    /// The name used in configs and by the Python binding.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Newton => "newton",
            Self::Semismooth => "semismooth",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        [Self::None, Self::Newton, Self::Semismooth]
            .into_iter()
            .find(|a| a.name() == name)
    }
}

/// Largest iteration cap a step may have: caps size the per-iteration trace, and a step
/// that needs more iterations than this is not going to converge anyway.
pub const MAX_ITERATIONS: usize = 1_000_000;

/// A named set of accuracy knobs (`solver.preset` in a config, `set_solver(preset=...)`):
/// the tolerance and iteration cap of *every* step, recorded for backward or not, so a loss
/// and its gradient always come from one trajectory. Explicit settings override the preset's.
///
/// Costs measured by `python -m benchmarks accuracy` (benchmarks/results/accuracy_time.md,
/// Anderson, one thread):
/// - `Simulation` (tolerance 1e-8, cap 300; the default): Hat with contact 16 ms/step,
///   trajectory error 7e-4 against a 1e-12 run; contact-free Hat 3.2 ms/step. Gradients taken
///   from such steps are 0.3-6 % off on the contact-free Hat (400 steps) and 50 % off on
///   Wind 24x24, so `backward` warns (its steps are above [`crate::backward::TRUSTED_FORWARD_RESIDUAL`]).
/// - `Gradient` (tolerance 1e-11, cap 10000): contact-free Hat 7.2 ms/step (2.3x), gradients
///   within 2e-5 of the converged ones (Wind 24x24, which
///   has no bending and amplifies per-step differences: 3e-3); the contact Hat's 400-step gradients agree with a
///   1e-12 rollout to 3e-3 (at 1e-10 its trajectory parts from the converged one at the
///   buckling against the head, gradients 0.56 apart). The backward pass is unchanged
///   (contact-free Hat: 2.7 ms/step Krylov at eps 1e-6, 32 ms/step direct), so a loss with its
///   gradient costs 1.1x (direct) to 1.7x (Krylov) what it costs at `Simulation`. The cap is
///   the envs' (`engine.DEFAULT_MAX_ITERATIONS`): a Hat step with slipping contacts can sit near
///   a saddle for thousands of iterations, and at a cap of 2000 two of the contact Hat's 400
///   recorded steps stopped at 7e-9, above what the adjoint trusts (`test_gradient_consistency`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    #[default]
    Simulation,
    Gradient,
}

impl Preset {
    pub const ALL: [Preset; 2] = [Preset::Simulation, Preset::Gradient];

    /// The name used in configs and by the Python binding.
    pub fn name(self) -> &'static str {
        match self {
            Self::Simulation => "simulation",
            Self::Gradient => "gradient",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// `(tolerance, max_iterations)` of the preset.
    pub fn accuracy(self) -> (f64, usize) {
        match self {
            Self::Simulation => (1e-8, 300),
            Self::Gradient => (1e-11, 10000),
        }
    }

    /// Sets the knobs the preset decides (tolerance and iteration cap).
    pub fn apply(self, s: &mut SolverSettings) {
        (s.tolerance, s.max_iterations) = self.accuracy();
    }
}

/// The accuracy knobs of the PD solve (`[solver]` in a scene config, `set_solver` at run
/// time): their one home, with their defaults. Every step, recorded for backward or not,
/// converges to the same `tolerance` within the same `max_iterations`: recording never
/// changes the trajectory.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "SolverTable")]
pub struct SolverSettings {
    /// Iteration cap per step (default 300, the `simulation` preset; at most [`MAX_ITERATIONS`]).
    pub max_iterations: usize,
    /// Stop when the RMS per-coordinate PD update `|G(x) - x|` falls below this, in metres
    /// (default 1e-8, the `simulation` preset; use the `gradient` preset, 1e-11, for steps
    /// recorded for backward: see [`Preset`] for the measured costs).
    /// `G(x) - x = -P^{-1} grad E(x)`: a preconditioned gradient norm.
    pub tolerance: f64,
    /// Acceleration of the local-global iterations (default: anderson).
    pub acceleration: Acceleration,
    /// Anderson history length (default 5).
    pub history: usize,
    /// Parallel local step for large meshes (default true).
    pub parallel: bool,
    /// What finishes a step near its solution (default: none). `newton` is measured in the
    /// README (Hat: far smaller one-step error at equal tolerance, about equal time);
    /// `semismooth` also takes Newton steps on contact steps (opt-in).
    pub polish: Polish,
}

impl Default for SolverSettings {
    fn default() -> Self {
        let (tolerance, max_iterations) = Preset::default().accuracy();
        Self {
            max_iterations,
            tolerance,
            acceleration: Acceleration::default(),
            history: 5,
            parallel: true,
            polish: Polish::default(),
        }
    }
}

/// `[solver]` as written in a config: an optional preset, then explicit settings over it.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SolverTable {
    preset: Option<Preset>,
    max_iterations: Option<usize>,
    tolerance: Option<f64>,
    acceleration: Option<Acceleration>,
    history: Option<usize>,
    parallel: Option<bool>,
    polish: Option<Polish>,
    /// Retired (recorded steps converge like the others): accepted only equal to `tolerance`.
    record_tolerance: Option<f64>,
    /// Retired: accepted only equal to `max_iterations`.
    record_max_iterations: Option<usize>,
}

impl TryFrom<SolverTable> for SolverSettings {
    type Error = String;

    fn try_from(t: SolverTable) -> std::result::Result<Self, String> {
        let mut s = SolverSettings::default();
        t.preset.unwrap_or_default().apply(&mut s);
        s.max_iterations = t.max_iterations.unwrap_or(s.max_iterations);
        s.tolerance = t.tolerance.unwrap_or(s.tolerance);
        s.acceleration = t.acceleration.unwrap_or(s.acceleration);
        s.history = t.history.unwrap_or(s.history);
        s.parallel = t.parallel.unwrap_or(s.parallel);
        s.polish = t.polish.unwrap_or(s.polish);
        let retired = [
            (
                "record_tolerance",
                t.record_tolerance,
                s.tolerance,
                "tolerance",
            ),
            (
                "record_max_iterations",
                t.record_max_iterations.map(|m| m as f64),
                s.max_iterations as f64,
                "max_iterations",
            ),
        ];
        for (key, value, current, shared) in retired {
            if value.is_some_and(|v| v != current) {
                return Err(format!(
                    "{key} is retired: recorded steps converge like every other step (one \
                     trajectory whether recorded or not); set {shared} (now {current:e}), or \
                     preset = \"gradient\" for gradient work"
                ));
            }
        }
        Ok(s)
    }
}

impl SolverSettings {
    /// Iterations a step can take, plus the first: the length of a full trace. Bounded by
    /// the validation's [`MAX_ITERATIONS`].
    pub(crate) fn trace_capacity(&self) -> usize {
        self.max_iterations + 1
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
    if s.max_iterations > MAX_ITERATIONS {
        return Err(Error::Param(format!(
            "solver max_iterations must be at most {MAX_ITERATIONS}, got {}",
            s.max_iterations
        )));
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
            if !name.in_params() {
                assert_eq!(p.get(name), None);
                assert!(p.set(name, ParamValue::Scalar(0.1)).is_err());
                continue;
            }
            let value = if name.is_vector() {
                ParamValue::Vector(Vec3::repeat(i as f64 + 0.5))
            } else {
                ParamValue::Scalar(i as f64 + 0.5)
            };
            p.set(name, value.clone()).unwrap();
            assert_eq!(p.get(name), Some(value));
        }
        // All fields changed: none is left at its sample value.
        let s = sample();
        assert!(Param::ALL
            .into_iter()
            .filter(|n| n.in_params())
            .all(|n| p.get(n) != s.get(n)));
        assert!(p.set(Param::Gravity, ParamValue::Scalar(1.0)).is_err());
        assert!(p.set(Param::H, ParamValue::Vector(Vec3::zeros())).is_err());
        assert_eq!(Param::from_name("mu"), None);
    }

    /// `[solver]`: a preset first, explicit settings over it; the retired record settings
    /// only when they change nothing (recording never changes the trajectory).
    #[test]
    fn solver_tables_apply_presets_and_refuse_a_separate_record_tolerance() {
        let parse = |t: &str| toml::from_str::<SolverSettings>(t);
        let s = parse("preset = \"gradient\"\nmax_iterations = 900").unwrap();
        assert_eq!((s.tolerance, s.max_iterations), (1e-11, 900));
        assert_eq!(parse("").unwrap(), SolverSettings::default());
        let same = parse("tolerance = 1e-9\nrecord_tolerance = 1e-9\nrecord_max_iterations = 300");
        assert_eq!(same.unwrap().tolerance, 1e-9);
        let err = parse("record_tolerance = 1e-11").unwrap_err().to_string();
        assert!(err.contains("record_tolerance is retired"), "{err}");
        assert!(parse("preset = \"fast\"").is_err());
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
                max_iterations: usize::MAX,
                ..ok.clone()
            },
        ] {
            let err = validate_solver(&bad).unwrap_err().to_string();
            assert!(err.contains("at most 1000000"), "{err}");
        }
    }
}
