//! Analytic obstacle shapes. Each gives the signed distance of a point to the solid (positive
//! in free space) and the outward unit normal (the distance's gradient). Analytic rather than
//! triangulated surfaces: triangulated normals jump across edges (paper Sec. 5.1).

use crate::Vec3;
use nalgebra::{Matrix3, Rotation3};

#[derive(Debug, Clone)]
pub enum Shape {
    /// Half-space below the plane through `point` with unit `normal` (free side: the normal's).
    Plane {
        point: Vec3,
        normal: Vec3,
    },
    Sphere {
        center: Vec3,
        radius: f64,
    },
    /// All points within `radius` of the segment `a`-`b`.
    Capsule {
        a: Vec3,
        b: Vec3,
        radius: f64,
    },
    /// An oriented box: `half_extents` along the axes of `rotation`.
    Box {
        center: Vec3,
        half_extents: Vec3,
        rotation: Rotation3<f64>,
    },
    /// A bowl: solid below the rim plane `y = rim_height` except a spherical cavity; the free
    /// space is the cavity (radius `radius` around `center`) plus everything above the rim.
    Bowl {
        center: Vec3,
        radius: f64,
        rim_height: f64,
    },
    /// An upside-down square pyramid cut into a solid (the crumpling scene of Liang et al. 2019,
    /// Fig. 3.2): solid below the rim plane `y = apex.y + height` except a pit whose four
    /// planar walls meet at `apex` and open to a square of `half_width` (axis-aligned) at the rim.
    PyramidPit {
        apex: Vec3,
        half_width: f64,
        height: f64,
    },
    /// Several solids together (a head on a neck, a foot and a leg).
    Union(Vec<Shape>),
}

impl Shape {
    /// Signed distance of `p` to the solid (negative inside) and the outward unit normal.
    pub fn distance(&self, p: &Vec3) -> (f64, Vec3) {
        match self {
            Shape::Plane { point, normal } => ((p - point).dot(normal), *normal),
            Shape::Sphere { center, radius } => {
                let (len, dir) = length_and_direction(p - center);
                (len - radius, dir)
            }
            Shape::Capsule { a, b, radius } => {
                let ab = b - a;
                let t =
                    ((p - a).dot(&ab) / ab.norm_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
                let (len, dir) = length_and_direction(p - (a + t * ab));
                (len - radius, dir)
            }
            Shape::Box {
                center,
                half_extents,
                rotation,
            } => {
                let local = rotation.inverse() * (p - center);
                let q = local.abs() - half_extents;
                let outside = q.sup(&Vec3::zeros());
                if outside.norm_squared() > 0.0 {
                    let dir = outside.component_mul(&local.map(f64::signum));
                    (outside.norm(), rotation * dir.normalize())
                } else {
                    let k = q.imax();
                    let mut dir = Vec3::zeros();
                    dir[k] = local[k].signum();
                    (q[k], rotation * dir)
                }
            }
            Shape::Bowl {
                center,
                radius,
                rim_height,
            } => {
                let (len, dir) = length_and_direction(p - center);
                let in_cavity = radius - len;
                let above_rim = p.y - rim_height;
                if in_cavity >= above_rim {
                    (in_cavity, -dir)
                } else {
                    (above_rim, Vec3::y())
                }
            }
            Shape::PyramidPit {
                apex,
                half_width,
                height,
            } => {
                // Inside a convex pit the distance to its boundary is the smallest distance to
                // a wall plane (exact), so the walls need no edge or corner cases.
                let d = p - apex;
                let best = pit_walls(&d, half_width / height)
                    .into_iter()
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .expect("four walls");
                let above_rim = d.y - height;
                if best.0 >= above_rim {
                    best
                } else {
                    (above_rim, Vec3::y())
                }
            }
            Shape::Union(parts) => parts
                .iter()
                .map(|s| s.distance(p))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap_or((f64::INFINITY, Vec3::y())),
        }
    }

    /// Calls `found(distance, normal)` for each surface patch of the solid within `reach` of
    /// `p`: the nearest one for smooth or convex shapes, and every wall within reach inside a
    /// pyramid pit, whose edges and apex are concave: a node there touches two or more walls
    /// at once, and one contact for the nearest wall would let it sink into the next.
    pub fn for_each_contact(&self, p: &Vec3, reach: f64, mut found: impl FnMut(f64, Vec3)) {
        self.for_each_contact_dyn(p, reach, &mut found);
    }

    fn for_each_contact_dyn(&self, p: &Vec3, reach: f64, found: &mut dyn FnMut(f64, Vec3)) {
        // A union: every part within reach (staying `reach` from the union means staying that
        // far from each part; the nearest part alone let a node near the head-neck junction
        // sink into the part it was not in contact with).
        if let Shape::Union(parts) = self {
            for part in parts {
                part.for_each_contact_dyn(p, reach, found);
            }
            return;
        }
        if let Shape::PyramidPit {
            apex,
            half_width,
            height,
        } = self
        {
            let d = p - apex;
            if d.y < *height {
                for (dist, normal) in pit_walls(&d, half_width / height) {
                    if dist < reach {
                        found(dist, normal);
                    }
                }
                return;
            }
        }
        let (dist, normal) = self.distance(p);
        if dist < reach {
            found(dist, normal);
        }
    }

    /// [`Shape::normal_jacobian`] of the surface patch whose normal at `p` is `normal` (the
    /// patch a contact was made with; unions and pits give one contact per patch).
    pub fn normal_jacobian_of(&self, p: &Vec3, normal: &Vec3) -> Matrix3<f64> {
        match self {
            Shape::Union(parts) => parts
                .iter()
                .min_by(|a, b| {
                    let miss = |s: &Shape| (s.distance(p).1 - normal).norm_squared();
                    miss(a).total_cmp(&miss(b))
                })
                .map_or(Matrix3::zeros(), |s| s.normal_jacobian_of(p, normal)),
            _ => self.normal_jacobian(p),
        }
    }

    /// Jacobian of the outward normal with respect to the point (the Hessian of the signed
    /// distance): zero on flat parts, `(I - n n^T) / r` on a sphere of radius r, the
    /// cylinder's `(I - n n^T - t t^T) / r` along a capsule, and the cavity's negative.
    pub fn normal_jacobian(&self, p: &Vec3) -> Matrix3<f64> {
        let curved = |v: Vec3| {
            let (len, n) = length_and_direction(v);
            if len > 0.0 {
                (Matrix3::identity() - n * n.transpose()) / len
            } else {
                Matrix3::zeros()
            }
        };
        match self {
            Shape::Plane { .. } | Shape::PyramidPit { .. } => Matrix3::zeros(),
            Shape::Sphere { center, .. } => curved(p - center),
            Shape::Capsule { a, b, .. } => {
                let ab = b - a;
                let t = (p - a).dot(&ab) / ab.norm_squared().max(f64::MIN_POSITIVE);
                if t <= 0.0 {
                    curved(p - a)
                } else if t >= 1.0 {
                    curved(p - b)
                } else {
                    let axis = ab.normalize();
                    let radial = p - (a + t * ab);
                    let (len, n) = length_and_direction(radial);
                    if len > 0.0 {
                        (Matrix3::identity() - n * n.transpose() - axis * axis.transpose()) / len
                    } else {
                        Matrix3::zeros()
                    }
                }
            }
            Shape::Box {
                center,
                half_extents,
                rotation,
            } => {
                let local = rotation.inverse() * (p - center);
                let q = local.abs() - half_extents;
                let outside = q.sup(&Vec3::zeros());
                let len = outside.norm();
                if len == 0.0 {
                    return Matrix3::zeros();
                }
                // Outside near an edge or corner: curvature across the active axes only.
                let mut active = Matrix3::zeros();
                for k in 0..3 {
                    if q[k] > 0.0 {
                        active[(k, k)] = 1.0;
                    }
                }
                let n = outside.component_mul(&local.map(f64::signum)) / len;
                let r = rotation.matrix();
                r * ((active - n * n.transpose()) / len) * r.transpose()
            }
            Shape::Bowl {
                center,
                radius,
                rim_height,
            } => {
                let (len, _) = length_and_direction(p - center);
                if radius - len >= p.y - rim_height {
                    -curved(p - center)
                } else {
                    Matrix3::zeros()
                }
            }
            Shape::Union(parts) => parts
                .iter()
                .min_by(|a, b| a.distance(p).0.total_cmp(&b.distance(p).0))
                .map_or(Matrix3::zeros(), |s| s.normal_jacobian(p)),
        }
    }

    /// Checks dimensions; returns a message naming the problem.
    pub fn validate(&self) -> Result<(), String> {
        let finite = |v: &Vec3| v.iter().all(|c| c.is_finite());
        match self {
            Shape::Plane { point, normal } => {
                if !finite(point) || !finite(normal) || normal.norm() == 0.0 {
                    return Err("plane needs a finite point and a non-zero normal".into());
                }
            }
            Shape::Sphere { center, radius } | Shape::Bowl { center, radius, .. } => {
                if !finite(center) || !(*radius > 0.0 && radius.is_finite()) {
                    return Err(format!(
                        "radius must be positive and the center finite, got {radius}"
                    ));
                }
            }
            Shape::Capsule { a, b, radius } => {
                if !finite(a) || !finite(b) || !(*radius > 0.0 && radius.is_finite()) {
                    return Err(format!(
                        "capsule needs finite end points and a positive radius, got {radius}"
                    ));
                }
            }
            Shape::Box {
                center,
                half_extents,
                ..
            } => {
                if !finite(center) || !half_extents.iter().all(|&h| h > 0.0 && h.is_finite()) {
                    return Err("box half_extents must be positive".into());
                }
            }
            Shape::PyramidPit {
                apex,
                half_width,
                height,
            } => {
                if !finite(apex)
                    || !(*half_width > 0.0 && half_width.is_finite())
                    || !(*height > 0.0 && height.is_finite())
                {
                    return Err(format!("pyramid_pit needs a finite apex and positive half_width and height, got {half_width}, {height}"));
                }
            }
            Shape::Union(parts) => {
                if parts.is_empty() {
                    return Err("union needs at least one part".into());
                }
                for p in parts {
                    p.validate()?;
                }
            }
        }
        Ok(())
    }
}

/// Signed distances and inward unit normals of a pyramid pit's four wall planes at `d` (the
/// point relative to the apex); walls rise `slope` horizontally per unit of height.
fn pit_walls(d: &Vec3, slope: f64) -> [(f64, Vec3); 4] {
    let scale = 1.0 / (1.0 + slope * slope).sqrt();
    [(0, 1.0), (0, -1.0), (2, 1.0), (2, -1.0)].map(|(axis, sign): (usize, f64)| {
        let mut normal = Vec3::new(0.0, slope * scale, 0.0);
        normal[axis] = -sign * scale;
        ((slope * d.y - sign * d[axis]) * scale, normal)
    })
}

/// `(|v|, v / |v|)`, with an arbitrary fixed direction (+y) at the degenerate point.
fn length_and_direction(v: Vec3) -> (f64, Vec3) {
    let len = v.norm();
    if len > 0.0 {
        (len, v / len)
    } else {
        (0.0, Vec3::y())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The normal is the gradient of the signed distance (central differences).
    fn check_gradient(s: &Shape, p: Vec3) {
        let (_, n) = s.distance(&p);
        let eps = 1e-6;
        for k in 0..3 {
            let mut e = Vec3::zeros();
            e[k] = eps;
            let fd = (s.distance(&(p + e)).0 - s.distance(&(p - e)).0) / (2.0 * eps);
            assert!(
                (fd - n[k]).abs() < 1e-6,
                "{s:?} at {p:?}: d/dx{k} {fd} vs normal {}",
                n[k]
            );
        }
        assert!((n.norm() - 1.0).abs() < 1e-12);
        let jac = s.normal_jacobian(&p);
        for k in 0..3 {
            let mut e = Vec3::zeros();
            e[k] = eps;
            let fd = (s.distance(&(p + e)).1 - s.distance(&(p - e)).1) / (2.0 * eps);
            assert!(
                (fd - jac.column(k)).norm() < 1e-5,
                "{s:?} at {p:?}: dn/dx{k} {fd:?} vs {:?}",
                jac.column(k)
            );
        }
    }

    #[test]
    fn distances_and_normals() {
        let plane = Shape::Plane {
            point: Vec3::new(0.0, 1.0, 0.0),
            normal: Vec3::y(),
        };
        assert_eq!(plane.distance(&Vec3::new(5.0, 3.0, 2.0)).0, 2.0);
        let sphere = Shape::Sphere {
            center: Vec3::zeros(),
            radius: 2.0,
        };
        assert!((sphere.distance(&Vec3::new(0.0, 0.0, 3.0)).0 - 1.0).abs() < 1e-15);
        let capsule = Shape::Capsule {
            a: Vec3::zeros(),
            b: Vec3::new(0.0, 4.0, 0.0),
            radius: 0.5,
        };
        assert!((capsule.distance(&Vec3::new(1.0, 2.0, 0.0)).0 - 0.5).abs() < 1e-15);
        assert!((capsule.distance(&Vec3::new(0.0, 5.0, 0.0)).0 - 0.5).abs() < 1e-15);
        let boxed = Shape::Box {
            center: Vec3::zeros(),
            half_extents: Vec3::new(1.0, 2.0, 3.0),
            rotation: Rotation3::from_euler_angles(0.0, 0.3, 0.0),
        };
        assert!((boxed.distance(&Vec3::new(0.0, 2.5, 0.0)).0 - 0.5).abs() < 1e-12);
        assert!((boxed.distance(&Vec3::zeros()).0 + 1.0).abs() < 1e-12);
        let bowl = Shape::Bowl {
            center: Vec3::zeros(),
            radius: 2.0,
            rim_height: 0.5,
        };
        assert!(
            (bowl.distance(&Vec3::new(0.0, -1.5, 0.0)).0 - 0.5).abs() < 1e-15,
            "inside the cavity"
        );
        assert!(
            bowl.distance(&Vec3::new(0.0, -2.5, 0.0)).0 < 0.0,
            "in the bowl's wall"
        );
        assert!(
            bowl.distance(&Vec3::new(5.0, 1.0, 0.0)).0 > 0.0,
            "above the rim"
        );
        let pit = Shape::PyramidPit {
            apex: Vec3::new(0.0, -2.0, 0.0),
            half_width: 2.0,
            height: 2.0,
        };
        let on_axis = pit.distance(&Vec3::new(0.0, -1.0, 0.0)).0;
        assert!(
            (on_axis - 2f64.sqrt() / 2.0).abs() < 1e-15,
            "1 m above the apex of 45-degree walls: {on_axis}"
        );
        assert!(
            pit.distance(&Vec3::new(1.5, -1.0, 0.0)).0 < 0.0,
            "in the pit's wall"
        );
        // Near an edge of the pit (x = z) two walls are within reach, on the axis only one.
        let mut walls = Vec::new();
        pit.for_each_contact(&Vec3::new(0.9, -1.0, 0.9), 0.1, |d, n| walls.push((d, n)));
        assert_eq!(walls.len(), 2, "{walls:?}");
        assert!(
            walls[0].1.x < 0.0 && walls[1].1.z < 0.0,
            "inward normals: {walls:?}"
        );
        // A union gives a contact per part within reach, each with its own curvature.
        let head = Shape::Union(vec![
            Shape::Sphere {
                center: Vec3::zeros(),
                radius: 2.0,
            },
            Shape::Capsule {
                a: Vec3::new(0.0, -4.0, 0.0),
                b: Vec3::new(0.0, -1.5, 0.0),
                radius: 0.8,
            },
        ]);
        let junction = Vec3::new(1.0, -1.85, 0.0);
        let mut parts = Vec::new();
        head.for_each_contact(&junction, 0.25, |d, n| parts.push((d, n)));
        assert_eq!(parts.len(), 2, "{parts:?}");
        for (_, n) in &parts {
            let sphere = Shape::Sphere {
                center: Vec3::zeros(),
                radius: 2.0,
            };
            let expect = if (sphere.distance(&junction).1 - n).norm() < 1e-12 {
                sphere.normal_jacobian(&junction)
            } else {
                Shape::Capsule {
                    a: Vec3::new(0.0, -4.0, 0.0),
                    b: Vec3::new(0.0, -1.5, 0.0),
                    radius: 0.8,
                }
                .normal_jacobian(&junction)
            };
            assert!((head.normal_jacobian_of(&junction, n) - expect).norm() < 1e-15);
        }
        let mut count = 0;
        pit.for_each_contact(&Vec3::new(0.9, -1.0, 0.0), 0.1, |_, _| count += 1);
        assert_eq!(count, 1);
        assert!(
            pit.distance(&Vec3::new(5.0, 0.5, 0.0)).0 > 0.0,
            "above the rim"
        );
        let union = Shape::Union(vec![sphere.clone(), capsule.clone()]);
        assert!((union.distance(&Vec3::new(0.0, 0.0, 3.0)).0 - 1.0).abs() < 1e-15);
        for p in [
            Vec3::new(0.3, 2.7, -0.4),
            Vec3::new(1.5, -0.2, 0.9),
            Vec3::new(-0.7, 0.1, 3.3),
            Vec3::new(1.4, 2.6, 0.1),
            Vec3::new(1.3, 2.4, 3.5),
        ] {
            for s in [&plane, &sphere, &capsule, &boxed, &bowl, &pit, &union] {
                check_gradient(s, p);
            }
        }
    }
}
