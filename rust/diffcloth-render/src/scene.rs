//! What a frame shows, borrowed from a simulator: the cloth now, its rest shape (for a
//! framing that does not follow the cloth around), the obstacles at the current time and the
//! attachment targets.

use diffcloth::collision::{Obstacle, Shape};
use diffcloth::{Simulator, Vec3};

/// A borrowed view of one simulator state.
#[derive(Debug, Clone, Copy)]
pub struct SceneView<'a> {
    pub positions: &'a [Vec3],
    pub triangles: &'a [[usize; 3]],
    /// The rest shape: with the obstacles it sets the default framing and the floor.
    pub rest_positions: &'a [Vec3],
    pub obstacles: &'a [Obstacle],
    /// Simulated time (moving obstacles are drawn where they are at this time).
    pub time: f64,
    /// Marked points: the attachment targets (where the end effectors hold the cloth).
    pub markers: &'a [Vec3],
    /// Up in the scene: against gravity, +y without gravity.
    pub up: Vec3,
}

impl<'a> SceneView<'a> {
    pub fn of(sim: &'a Simulator) -> Self {
        let gravity = sim.params().gravity;
        Self {
            positions: sim.positions(),
            triangles: &sim.mesh().triangles,
            rest_positions: &sim.mesh().positions,
            obstacles: sim.obstacles(),
            time: sim.time(),
            markers: sim.attachment_targets(),
            up: (Vec3::zeros() - gravity)
                .try_normalize(1e-12)
                .unwrap_or_else(Vec3::y),
        }
    }

    /// Whether an obstacle is an infinite plane (it is then the floor).
    pub fn has_plane(&self) -> bool {
        fn plane(s: &Shape) -> bool {
            match s {
                Shape::Plane { .. } => true,
                Shape::Union(parts) => parts.iter().any(plane),
                _ => false,
            }
        }
        self.obstacles.iter().any(|o| plane(&o.shape))
    }

    /// Bounding box of the rest shape, the markers and the bounded obstacles at their
    /// configured placement: the same for every frame of a run.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        let mut add = |p: Vec3, r: f64| {
            if p.iter().all(|c| c.is_finite()) {
                lo = lo.inf(&(p - Vec3::repeat(r)));
                hi = hi.sup(&(p + Vec3::repeat(r)));
            }
        };
        for p in self.rest_positions.iter().chain(self.markers) {
            add(*p, 0.0);
        }
        for o in self.obstacles {
            shape_bounds(&o.shape, &mut add);
        }
        if lo.x > hi.x {
            return (Vec3::repeat(-1.0), Vec3::repeat(1.0));
        }
        (lo, hi)
    }
}

/// Calls `add(point, radius)` with balls covering the bounded part of a shape (planes add
/// nothing; bowls and pits their opening).
fn shape_bounds(shape: &Shape, add: &mut impl FnMut(Vec3, f64)) {
    match shape {
        Shape::Plane { .. } => {}
        Shape::Sphere { center, radius } => add(*center, *radius),
        Shape::Capsule { a, b, radius } => {
            add(*a, *radius);
            add(*b, *radius);
        }
        Shape::Box {
            center,
            half_extents,
            ..
        } => add(*center, half_extents.norm()),
        Shape::Bowl { center, radius, .. } => add(*center, *radius),
        Shape::PyramidPit {
            apex,
            half_width,
            height,
        } => {
            add(*apex, 0.0);
            add(apex + Vec3::y() * *height, *half_width);
        }
        Shape::Union(parts) => {
            for part in parts {
                shape_bounds(part, add);
            }
        }
    }
}
