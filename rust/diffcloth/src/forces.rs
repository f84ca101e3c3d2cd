//! Explicit external forces that enter the inertial prediction `y = x + h v + h^2 M^{-1} f`:
//! gravity, wind, and per-node forces given to each step.

use crate::config::{WindConfig, WindProfile};
use crate::params::Params;
use crate::Vec3;

/// Wind after the paper's Appendix B: `f_a(t) = 0.5 (sin(omega t + phi) + 1) k_a d`. The
/// amplitude d, omega and phi are parameters (`Params::wind_*`, their one home); the wind
/// itself keeps only the per-node factor fixed by the rest shape.
#[derive(Debug, Clone)]
pub struct Wind {
    /// Per-node coefficient `k_a` (times the node's area when the amplitude is per area).
    coefficient: Vec<f64>,
}

impl Wind {
    pub fn new(cfg: &WindConfig, rest: &[Vec3], node_area: &[f64]) -> Self {
        let mut coefficient = match cfg.profile {
            WindProfile::Uniform => vec![1.0; rest.len()],
            WindProfile::InverseDistance => {
                let centroid = rest.iter().sum::<Vec3>() / rest.len() as f64;
                let scale = rest
                    .iter()
                    .map(|p| (p - centroid).norm())
                    .fold(0.0, f64::max);
                // Floor the distance at 1 % of the extent so a node at the centre stays finite.
                rest.iter()
                    .map(|p| 1.0 / (p - centroid).norm().max(1e-2 * scale))
                    .collect()
            }
        };
        if cfg.per_area {
            coefficient
                .iter_mut()
                .zip(node_area)
                .for_each(|(k, a)| *k *= a);
        }
        Self { coefficient }
    }

    /// Per-node coefficient `k_a` (including the node area when per area).
    pub fn coefficient(&self) -> &[f64] {
        &self.coefficient
    }

    /// Temporal factor `0.5 (sin(omega t + phi) + 1)`.
    pub fn modulation(p: &Params, t: f64) -> f64 {
        0.5 * ((p.wind_omega * t + p.wind_phi).sin() + 1.0)
    }

    /// Adds the wind force at time `t` to `f`.
    pub fn add_forces(&self, p: &Params, t: f64, f: &mut [Vec3]) {
        let d = Self::modulation(p, t) * p.wind_direction;
        for (fa, k) in f.iter_mut().zip(&self.coefficient) {
            *fa += *k * d;
        }
    }
}
