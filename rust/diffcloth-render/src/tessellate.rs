//! Obstacles and the floor as triangles: each analytic [`Shape`] becomes a triangle mesh
//! with smooth normals on curved parts (spheres, capsules, the bowl's cavity) and flat ones on
//! planar parts (boxes, the pyramid pit, planes). Unbounded solids are cut to a finite patch
//! of half-size `extent` around the scene: a plane becomes a checkered square, the bowl's and
//! the pit's rim planes a ring around their opening.
//!
//! Every triangle is wound so that its geometric normal agrees with its vertex normals: the
//! shading's "front" side is then the side the normals point to.

use diffcloth::collision::Shape;
use diffcloth::Vec3;
use std::f64::consts::PI;

/// Segments around a surface of revolution.
const SEGMENTS: usize = 32;
/// Rings from pole to pole of a sphere (a capsule's hemispheres get half each).
const RINGS: usize = 16;
/// Tiles along each side of a checkered plane or floor.
const TILES: usize = 10;

/// Triangles with per-vertex normals and colours, in scene coordinates; cleared and refilled
/// every frame without giving back its memory.
#[derive(Debug, Default, Clone)]
pub struct Surfaces {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub colors: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Per triangle: whether it bounds a closed solid (sphere, capsule, box), so that its
    /// back side can never be seen from outside and need not be drawn.
    pub closed: Vec<bool>,
    /// `closed` for the triangles being added.
    adding_closed: bool,
}

impl Surfaces {
    pub fn clear(&mut self) {
        self.positions.clear();
        self.normals.clear();
        self.colors.clear();
        self.triangles.clear();
        self.closed.clear();
    }

    fn vertex(&mut self, p: Vec3, n: Vec3, color: [f32; 3]) -> u32 {
        self.positions.push(p);
        self.normals.push(n);
        self.colors.push(color);
        (self.positions.len() - 1) as u32
    }

    /// Adds a triangle wound to agree with its vertex normals; skips degenerate ones (poles).
    fn triangle(&mut self, a: u32, b: u32, c: u32) {
        let p = |i: u32| self.positions[i as usize];
        let face = (p(b) - p(a)).cross(&(p(c) - p(a)));
        if face.norm_squared() == 0.0 {
            return;
        }
        let n = |i: u32| self.normals[i as usize];
        if face.dot(&(n(a) + n(b) + n(c))) >= 0.0 {
            self.triangles.push([a, b, c]);
        } else {
            self.triangles.push([a, c, b]);
        }
        self.closed.push(self.adding_closed);
    }

    /// A flat quad p0-p1-p2-p3 (in order around it).
    fn flat_quad(&mut self, q: [Vec3; 4], color: [f32; 3]) {
        let n = (q[1] - q[0]).cross(&(q[2] - q[0])).normalize();
        let [a, b, c, d] = q.map(|p| self.vertex(p, n, color));
        self.triangle(a, b, c);
        self.triangle(a, c, d);
    }

    /// A surface of revolution about the axis through `origin` along unit `axis`: ring `i`
    /// of `rings + 1` has radius, height along the axis and normal components `(radial,
    /// axial)` given by `profile(i)`.
    fn lathe(
        &mut self,
        origin: Vec3,
        axis: Vec3,
        rings: usize,
        color: [f32; 3],
        profile: impl Fn(usize) -> (f64, f64, f64, f64),
    ) {
        let (e1, e2) = perpendiculars(axis);
        let first = self.positions.len() as u32;
        for i in 0..=rings {
            let (r, h, nr, nh) = profile(i);
            for j in 0..SEGMENTS {
                let phi = 2.0 * PI * j as f64 / SEGMENTS as f64;
                let radial = e1 * phi.cos() + e2 * phi.sin();
                self.vertex(
                    origin + axis * h + radial * r,
                    radial * nr + axis * nh,
                    color,
                );
            }
        }
        let at = |i: usize, j: usize| first + (i * SEGMENTS + j % SEGMENTS) as u32;
        for i in 0..rings {
            for j in 0..SEGMENTS {
                self.triangle(at(i, j), at(i, j + 1), at(i + 1, j + 1));
                self.triangle(at(i, j), at(i + 1, j + 1), at(i + 1, j));
            }
        }
    }

    /// A checkered square of half-size `half` centred at `center` in the plane with unit
    /// normal `normal`.
    pub fn checker(&mut self, center: Vec3, normal: Vec3, half: f64, colors: [[f32; 3]; 2]) {
        let (u, v) = perpendiculars(normal);
        let step = 2.0 * half / TILES as f64;
        for i in 0..TILES {
            for j in 0..TILES {
                let corner = |di: usize, dj: usize| {
                    center
                        + u * (-half + (i + di) as f64 * step)
                        + v * (-half + (j + dj) as f64 * step)
                };
                let q = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
                let n = normal;
                let color = colors[(i + j) % 2];
                let [a, b, c, d] = q.map(|p| self.vertex(p, n, color));
                self.triangle(a, b, c);
                self.triangle(a, c, d);
            }
        }
    }

    /// Adds `shape` translated by `offset` (its motion at the frame's time). Unbounded parts
    /// are cut `extent` around `center` (the scene's centre).
    pub fn shape(
        &mut self,
        shape: &Shape,
        offset: Vec3,
        center: Vec3,
        extent: f64,
        color: [f32; 3],
    ) {
        self.adding_closed = matches!(
            shape,
            Shape::Sphere { .. } | Shape::Capsule { .. } | Shape::Box { .. }
        );
        match shape {
            Shape::Plane { point, normal } => {
                let n = normal.normalize();
                let p = point + offset;
                // The square sits under the scene: its centre is the scene centre's foot.
                let foot = center - n * (center - p).dot(&n);
                self.checker(foot, n, extent, [color, crate::shading::scale(color, 0.85)]);
            }
            Shape::Sphere { center: c, radius } => {
                let (c, r) = (c + offset, *radius);
                self.lathe(c, Vec3::y(), RINGS, color, |i| {
                    let t = PI * i as f64 / RINGS as f64;
                    (r * t.sin(), -r * t.cos(), t.sin(), -t.cos())
                });
            }
            Shape::Capsule { a, b, radius } => {
                let ab = b - a;
                let (a, r, length) = (a + offset, *radius, ab.norm());
                let axis = ab.try_normalize(1e-12).unwrap_or_else(Vec3::y);
                let half = RINGS / 2;
                // Rings 0..=half: the hemisphere around a; half+1..: the one around b.
                self.lathe(a, axis, 2 * half + 1, color, |i| {
                    let (k, h0) = if i <= half { (i, 0.0) } else { (i - 1, length) };
                    let t = PI * k as f64 / (2 * half) as f64;
                    (r * t.sin(), h0 - r * t.cos(), t.sin(), -t.cos())
                });
            }
            Shape::Box {
                center: c,
                half_extents: he,
                rotation,
            } => {
                let c = c + offset;
                let corner = |sx: f64, sy: f64, sz: f64| {
                    c + rotation * Vec3::new(sx * he.x, sy * he.y, sz * he.z)
                };
                for axis in 0..3 {
                    for s in [-1.0, 1.0] {
                        // The face at local coordinate `axis` = s, its corners in order around it.
                        let q =
                            [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].map(|(u, v)| {
                                match axis {
                                    0 => corner(s, u, v),
                                    1 => corner(v, s, u),
                                    _ => corner(u, v, s),
                                }
                            });
                        self.flat_quad(q, color);
                    }
                }
            }
            Shape::Bowl {
                center: c,
                radius,
                rim_height,
            } => {
                let (c, r) = (c + offset, *radius);
                let rim = rim_height + offset.y;
                // The cavity from its bottom up to the rim, normals into the free space.
                let top = ((c.y - rim) / r).clamp(-1.0, 1.0).acos();
                self.lathe(c, Vec3::y(), RINGS, color, |i| {
                    let t = top * i as f64 / RINGS as f64;
                    (r * t.sin(), -r * t.cos(), -t.sin(), t.cos())
                });
                // The rim plane: a ring from the opening outwards.
                let opening = r * top.sin();
                let base = Vec3::new(c.x, rim, c.z);
                let outer = (2.0 * r).max(opening * 1.5);
                self.lathe(base, Vec3::y(), 1, color, |i| {
                    ([opening, outer][i], 0.0, 0.0, 1.0)
                });
            }
            Shape::PyramidPit {
                apex,
                half_width,
                height,
            } => {
                let (apex, w) = (apex + offset, *half_width);
                let rim = apex + Vec3::y() * *height;
                let square = |s: f64| {
                    [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                        .map(|(x, z)| rim + Vec3::new(x * s, 0.0, z * s))
                };
                let (inner, outer) = (square(w), square(2.0 * w));
                for k in 0..4 {
                    let (p, q) = (inner[k], inner[(k + 1) % 4]);
                    // The wall, normal into the pit (towards the axis and up).
                    let mut n = (q - p).cross(&(apex - p)).normalize();
                    if n.dot(&(rim - (p + q) / 2.0)) < 0.0 {
                        n = -n;
                    }
                    let [a, b, c] = [apex, p, q].map(|v| self.vertex(v, n, color));
                    self.triangle(a, b, c);
                    self.flat_quad([p, q, outer[(k + 1) % 4], outer[k]], color);
                }
            }
            Shape::Union(parts) => {
                for part in parts {
                    self.shape(part, offset, center, extent, color);
                }
            }
        }
    }
}

/// Two unit vectors completing unit `n` to an orthonormal basis.
fn perpendiculars(n: Vec3) -> (Vec3, Vec3) {
    let helper = if n.x.abs() < 0.9 {
        Vec3::x()
    } else {
        Vec3::y()
    };
    let u = n.cross(&helper).normalize();
    (u, n.cross(&u))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Vertices lie on the shape's surface (signed distance ~0) and normals agree with it.
    fn on_surface(shape: &Shape) {
        let mut s = Surfaces::default();
        s.shape(shape, Vec3::zeros(), Vec3::zeros(), 3.0, [1.0; 3]);
        assert!(!s.triangles.is_empty());
        for (p, n) in s.positions.iter().zip(&s.normals) {
            let (mut d, normal) = shape.distance(p);
            if let Shape::Union(parts) = shape {
                // On some part's surface (parts overlap, so maybe inside the union).
                d = parts
                    .iter()
                    .map(|s| s.distance(p).0.abs())
                    .fold(f64::INFINITY, f64::min);
            }
            assert!(d.abs() < 1e-9, "{shape:?}: {p:?} at distance {d}");
            assert!((n.norm() - 1.0).abs() < 1e-9);
            // Edges, corners, rims and junctions have no single normal: check smooth shapes.
            if matches!(
                shape,
                Shape::Sphere { .. } | Shape::Capsule { .. } | Shape::Plane { .. }
            ) {
                assert!(
                    n.dot(&normal) > 0.99,
                    "{shape:?}: normal {n:?} vs {normal:?} at {p:?}"
                );
            }
        }
        for t in &s.triangles {
            let p = |k: usize| s.positions[t[k] as usize];
            let face = (p(1) - p(0)).cross(&(p(2) - p(0)));
            assert!(
                face.dot(&s.normals[t[0] as usize]) > 0.0,
                "winding agrees with the normals"
            );
        }
    }

    #[test]
    fn tessellations_lie_on_their_shapes() {
        on_surface(&Shape::Sphere {
            center: Vec3::new(1.0, 2.0, 3.0),
            radius: 0.5,
        });
        on_surface(&Shape::Capsule {
            a: Vec3::new(0.0, -1.0, 0.0),
            b: Vec3::new(1.0, 1.0, 0.5),
            radius: 0.3,
        });
        on_surface(&Shape::Box {
            center: Vec3::new(0.0, 1.0, 0.0),
            half_extents: Vec3::new(1.0, 0.5, 0.25),
            rotation: nalgebra::Rotation3::from_euler_angles(0.2, 0.4, 0.1),
        });
        on_surface(&Shape::Plane {
            point: Vec3::new(0.0, -1.0, 0.0),
            normal: Vec3::new(0.0, 0.8, 0.6),
        });
        on_surface(&Shape::Bowl {
            center: Vec3::new(0.0, 1.0, 0.0),
            radius: 1.0,
            rim_height: 1.5,
        });
        on_surface(&Shape::PyramidPit {
            apex: Vec3::zeros(),
            half_width: 0.5,
            height: 0.6,
        });
        on_surface(&Shape::Union(vec![
            Shape::Sphere {
                center: Vec3::zeros(),
                radius: 2.0,
            },
            Shape::Capsule {
                a: Vec3::new(0.0, -4.0, 0.0),
                b: Vec3::new(0.0, -1.5, 0.0),
                radius: 0.8,
            },
        ]));
    }

    #[test]
    fn the_motion_offset_moves_the_mesh() {
        let sphere = Shape::Sphere {
            center: Vec3::zeros(),
            radius: 1.0,
        };
        let (mut a, mut b) = (Surfaces::default(), Surfaces::default());
        a.shape(&sphere, Vec3::zeros(), Vec3::zeros(), 1.0, [1.0; 3]);
        b.shape(
            &sphere,
            Vec3::new(0.0, 2.0, 0.0),
            Vec3::zeros(),
            1.0,
            [1.0; 3],
        );
        for (p, q) in a.positions.iter().zip(&b.positions) {
            assert!((q - p - Vec3::new(0.0, 2.0, 0.0)).norm() < 1e-12);
        }
    }
}
