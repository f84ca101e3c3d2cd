//! Explicit external forces that enter the inertial prediction `y = x + h v + h^2 M^{-1} f`:
//! gravity, wind, and per-node forces given to each step.

use crate::config::{WindConfig, WindProfile};
use crate::error::{Error, Result};
use crate::Vec3;

/// Wind after the paper's Appendix B: `f_a(t) = 0.5 (sin(omega t + phi) + 1) k_a d`.
#[derive(Debug, Clone)]
pub struct Wind {
    pub direction: Vec3,
    pub omega: f64,
    pub phi: f64,
    /// Per-node coefficient `k_a` (times the node's area when the amplitude is per area).
    coefficient: Vec<f64>,
}

impl Wind {
    pub fn new(cfg: &WindConfig, rest: &[Vec3], node_area: &[f64]) -> Result<Self> {
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
        let wind = Self {
            direction: Vec3::from(cfg.direction),
            omega: cfg.omega,
            phi: cfg.phi,
            coefficient,
        };
        wind.validate()?;
        Ok(wind)
    }

    pub fn validate(&self) -> Result<()> {
        if !(self.direction.iter().all(|c| c.is_finite())
            && self.omega.is_finite()
            && self.phi.is_finite())
        {
            return Err(Error::Param(
                "wind direction, omega and phi must be finite".into(),
            ));
        }
        Ok(())
    }

    /// Per-node coefficient `k_a` (including the node area when per area).
    pub fn coefficient(&self) -> &[f64] {
        &self.coefficient
    }

    /// Temporal factor `0.5 (sin(omega t + phi) + 1)`.
    pub fn modulation(&self, t: f64) -> f64 {
        0.5 * ((self.omega * t + self.phi).sin() + 1.0)
    }

    /// Adds the wind force at time `t` to `f`.
    pub fn add_forces(&self, t: f64, f: &mut [Vec3]) {
        let d = self.modulation(t) * self.direction;
        for (fa, k) in f.iter_mut().zip(&self.coefficient) {
            *fa += *k * d;
        }
    }
}
