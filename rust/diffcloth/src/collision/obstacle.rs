//! An obstacle: a shape, its friction coefficient and an optional prescribed motion.

use super::Shape;
use crate::Vec3;

/// Prescribed rigid translation of an obstacle over time.
#[derive(Debug, Clone)]
pub enum Motion {
    Static,
    /// Constant velocity (m/s) from its configured placement at t = 0.
    Linear {
        velocity: Vec3,
    },
    /// Piecewise-linear offsets `(t, offset)` with increasing t; held constant outside.
    Path(Vec<(f64, Vec3)>),
}

impl Motion {
    /// Offset from the configured placement and velocity at time `t`.
    pub fn at(&self, t: f64) -> (Vec3, Vec3) {
        match self {
            Motion::Static => (Vec3::zeros(), Vec3::zeros()),
            Motion::Linear { velocity } => (velocity * t, *velocity),
            Motion::Path(keys) => {
                let (first, last) = (keys[0], keys[keys.len() - 1]);
                if t <= first.0 {
                    return (first.1, Vec3::zeros());
                }
                if t >= last.0 {
                    return (last.1, Vec3::zeros());
                }
                let k = keys.partition_point(|(tk, _)| *tk <= t) - 1;
                let ((t0, p0), (t1, p1)) = (keys[k], keys[k + 1]);
                let velocity = (p1 - p0) / (t1 - t0);
                (p0 + velocity * (t - t0), velocity)
            }
        }
    }

    /// The placement at the start `t` and end `t + h` of a step and the velocity contacts use
    /// over it. A path's velocity is its mean over the step: at a key inside the step (a path
    /// that starts moving at `t`) the velocity at `t` alone would call a rising obstacle still.
    pub fn over_step(&self, t: f64, h: f64) -> (Vec3, Vec3, Vec3) {
        let (start, velocity) = self.at(t);
        let (end, _) = self.at(t + h);
        match self {
            Motion::Static | Motion::Linear { .. } => (start, end, velocity),
            Motion::Path(_) => (start, end, (end - start) / h),
        }
    }
}

#[derive(Debug, Clone)]
pub struct Obstacle {
    pub shape: Shape,
    /// Coulomb friction coefficient between the cloth and this obstacle.
    pub mu: f64,
    pub motion: Motion,
}

impl Obstacle {
    /// Signed distance, outward normal and the obstacle's velocity at `p` and time `t`.
    pub fn query(&self, p: &Vec3, t: f64) -> (f64, Vec3, Vec3) {
        let (offset, velocity) = self.motion.at(t);
        let (d, n) = self.shape.distance(&(p - offset));
        (d, n, velocity)
    }
}
