//! The renderer: owns every buffer a frame needs (depth, vertex cache, obstacle meshes),
//! so that rendering allocates nothing once the first frame has sized them.
//!
//! How a frame is made:
//! 1. framing: the scene's bounds (rest cloth, markers, bounded obstacles) extended down to
//!    the floor give the default camera, the floor patch and the depth-cue range;
//! 2. obstacles at the frame's time and the floor are tessellated into [`Surfaces`];
//! 3. vertex stage: cloth normals (area-weighted), every vertex to view space, lit on both
//!    sides ([`Light::two_sided`]) and depth-cued, projected if in front of the near plane;
//! 4. background gradient and depth cleared, then every triangle drawn with the colours of
//!    the side it shows (clipped at the near plane where it crosses it);
//! 5. the markers as discs on top of the surfaces at their depth.

use crate::camera::{scene_basis, Camera, Vec3f, View};
use crate::error::RenderError;
use crate::raster::{clip_near, Target, Vertex, ViewVertex};
use crate::scene::SceneView;
use crate::shading::{scale, sky_rows, DepthCue, Light, Palette};
use crate::tessellate::Surfaces;
use diffcloth::Vec3;

/// Largest width or height accepted, pixels.
pub const MAX_SIZE: usize = 4096;
/// The floor and the cut planes reach this many scene radii from the scene's centre.
const FLOOR_EXTENT: f64 = 1.6;

/// A vertex after the vertex stage.
#[derive(Debug, Clone, Copy)]
struct Shaded {
    view: Vec3f,
    /// Screen position and inverse depth (meaningful when `visible`).
    screen: [f32; 3],
    visible: bool,
    front: [f32; 3],
    back: [f32; 3],
}

/// A software renderer of a fixed frame size. Reuse one across frames.
pub struct Renderer {
    width: usize,
    height: usize,
    pub palette: Palette,
    pub light: Light,
    depth: Vec<f32>,
    sky: Vec<[u8; 3]>,
    normals: Vec<Vec3>,
    surfaces: Surfaces,
    shaded: Vec<Shaded>,
}

/// What the framing of a scene decides: the default camera and where the floor goes.
#[derive(Debug, Clone, Copy)]
pub struct Framing {
    pub camera: Camera,
    pub center: Vec3,
    pub radius: f64,
    /// Centre of the floor patch (below everything, and never above the origin's level).
    pub floor: Vec3,
}

impl Renderer {
    /// A renderer of `width` x `height` pixels (each in `1..=MAX_SIZE`).
    pub fn new(width: usize, height: usize) -> Result<Self, RenderError> {
        for (name, value) in [("width", width), ("height", height)] {
            if !(1..=MAX_SIZE).contains(&value) {
                return Err(RenderError::Size {
                    name,
                    value,
                    max: MAX_SIZE,
                });
            }
        }
        Ok(Self {
            width,
            height,
            palette: Palette::default(),
            light: Light::default(),
            depth: vec![0.0; width * height],
            sky: Vec::with_capacity(height),
            normals: Vec::new(),
            surfaces: Surfaces::default(),
            shaded: Vec::new(),
        })
    }

    pub fn width(&self) -> usize {
        self.width
    }
    pub fn height(&self) -> usize {
        self.height
    }

    /// The default camera and floor of a scene for this frame's aspect ratio.
    pub fn framing(&self, scene: &SceneView) -> Framing {
        let (mut lo, mut hi) = scene.bounds();
        let (_, up, _) = scene_basis(scene.up);
        let center = (lo + hi) / 2.0;
        let radius = ((hi - lo).norm() / 2.0).max(1e-6);
        // The floor: just below the lowest corner of the bounds, at most at the origin's level.
        let lowest = (0..8)
            .map(|i| {
                let corner = Vec3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                );
                up.dot(&corner)
            })
            .fold(0.0_f64, f64::min);
        let level = lowest - 0.01 * radius;
        let floor = center - up * (up.dot(&center) - level);
        if !scene.has_plane() {
            lo = lo.inf(&floor);
            hi = hi.sup(&floor);
        }
        let aspect = self.width as f64 / self.height as f64;
        Framing {
            camera: Camera::framing(lo, hi, up, aspect),
            center: (lo + hi) / 2.0,
            radius: ((hi - lo).norm() / 2.0).max(1e-6),
            floor,
        }
    }

    /// Renders `scene` seen by `camera` (None: the default framing) into `out`, `height`
    /// rows of `width` RGB pixels.
    pub fn render(
        &mut self,
        scene: &SceneView,
        camera: Option<&Camera>,
        out: &mut [u8],
    ) -> Result<(), RenderError> {
        let expected = self.width * self.height * 3;
        if out.len() != expected {
            return Err(RenderError::Output {
                got: out.len(),
                expected,
            });
        }
        let framing = self.framing(scene);
        let camera = camera.copied().unwrap_or(framing.camera);
        camera.validate()?;
        let view = camera.view(self.width, self.height, 1e-3 * framing.radius);
        let distance = (camera.eye - framing.center).norm() as f32;
        let cue = DepthCue {
            near: distance - framing.radius as f32,
            far: distance + framing.radius as f32,
            strength: 0.4,
            haze: self.palette.sky[1],
        };

        let extent = FLOOR_EXTENT * framing.radius;
        self.surfaces.clear();
        for obstacle in scene.obstacles {
            let (offset, _) = obstacle.motion.at(scene.time);
            self.surfaces.shape(
                &obstacle.shape,
                offset,
                framing.center,
                extent,
                self.palette.obstacle,
            );
        }
        if !scene.has_plane() {
            self.surfaces.checker(
                framing.floor,
                scene_basis(scene.up).1,
                extent,
                self.palette.floor,
            );
        }

        self.vertex_stage(scene, &view, &cue);
        sky_rows(&self.palette, &mut self.sky, self.height);
        for (row, rgb) in out.chunks_exact_mut(3 * self.width).zip(&self.sky) {
            // One pixel, then the filled part copied onto the rest (memcpy, doubling).
            row[..3].copy_from_slice(rgb);
            let mut filled = 3;
            while filled < row.len() {
                let n = filled.min(row.len() - filled);
                row.copy_within(..n, filled);
                filled += n;
            }
        }
        self.depth.fill(0.0);
        let mut target = Target {
            color: out,
            depth: &mut self.depth,
            width: self.width,
            height: self.height,
        };
        let n = scene.positions.len();
        for t in scene.triangles {
            draw(
                &mut target,
                &view,
                [t[0], t[1], t[2]].map(|i| &self.shaded[i]),
                false,
            );
        }
        for (t, &closed) in self.surfaces.triangles.iter().zip(&self.surfaces.closed) {
            draw(
                &mut target,
                &view,
                t.map(|i| &self.shaded[n + i as usize]),
                closed,
            );
        }

        let radius = (self.width.min(self.height) as f32 / 110.0).max(2.5);
        for m in scene.markers {
            let v = view.point(m);
            if -v.z >= view.near {
                let [x, y, z] = view.project(&v);
                // Drawn over the cloth it holds (same depth): a few percent nearer.
                target.disc(
                    x,
                    y,
                    z * 1.03,
                    radius,
                    self.palette.marker,
                    self.palette.marker_outline,
                );
            }
        }
        Ok(())
    }

    /// Renders into a new `height * width * 3` vector.
    pub fn render_to_vec(
        &mut self,
        scene: &SceneView,
        camera: Option<&Camera>,
    ) -> Result<Vec<u8>, RenderError> {
        let mut out = vec![0; self.width * self.height * 3];
        self.render(scene, camera, &mut out)?;
        Ok(out)
    }

    /// Cloth normals, then every cloth and surface vertex to view space, lit and projected.
    fn vertex_stage(&mut self, scene: &SceneView, view: &View, cue: &DepthCue) {
        let n = scene.positions.len();
        self.normals.clear();
        self.normals.resize(n, Vec3::zeros());
        for t in scene.triangles {
            let [a, b, c] = t.map(|i| scene.positions[i]);
            // Area-weighted: the cross product's length is twice the area.
            let face = (b - a).cross(&(c - a));
            for &i in t {
                self.normals[i] += face;
            }
        }
        self.shaded.clear();
        let (light, palette) = (&self.light, &self.palette);
        let shade = |p: &Vec3, normal: &Vec3, front: [f32; 3], back: [f32; 3]| {
            let v = view.point(p);
            let nv = view
                .direction(normal)
                .try_normalize(1e-30)
                .unwrap_or_else(Vec3f::zeros);
            let (lf, lb) = light.two_sided(&nv);
            let depth = -v.z;
            let visible = depth >= view.near;
            Shaded {
                view: v,
                screen: if visible { view.project(&v) } else { [0.0; 3] },
                visible,
                front: cue.apply(scale(front, lf), depth),
                back: cue.apply(scale(back, lb), depth),
            }
        };
        for (p, normal) in scene.positions.iter().zip(&self.normals) {
            self.shaded
                .push(shade(p, normal, palette.cloth_front, palette.cloth_back));
        }
        let s = &self.surfaces;
        for ((p, normal), color) in s.positions.iter().zip(&s.normals).zip(&s.colors) {
            self.shaded.push(shade(p, normal, *color, *color));
        }
    }
}

/// Draws one triangle with the colours of the side it shows (nothing if that is the inside
/// of a `closed` solid); clips it at the near plane if it crosses it.
#[inline]
fn draw(target: &mut Target, view: &View, v: [&Shaded; 3], closed: bool) {
    // The side seen: the one its geometric normal points to if the eye (the origin) is there.
    let face = (v[1].view - v[0].view).cross(&(v[2].view - v[0].view));
    let front = face.dot(&v[0].view) < 0.0;
    if closed && !front {
        return;
    }
    let color = |s: &Shaded| if front { s.front } else { s.back };
    if v.iter().all(|s| s.visible) {
        target.triangle(&v.map(|s| Vertex {
            x: s.screen[0],
            y: s.screen[1],
            z: s.screen[2],
            color: color(s),
        }));
        return;
    }
    if v.iter().all(|s| !s.visible) {
        return;
    }
    let tri = v.map(|s| ViewVertex {
        position: s.view,
        color: color(s),
    });
    let mut poly = [tri[0]; 4];
    let count = clip_near(&tri, view.near, &mut poly);
    let project = |p: &ViewVertex| {
        let [x, y, z] = view.project(&p.position);
        Vertex {
            x,
            y,
            z,
            color: p.color,
        }
    };
    for k in 1..count.saturating_sub(1) {
        target.triangle(&[project(&poly[0]), project(&poly[k]), project(&poly[k + 1])]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use diffcloth::collision::{Motion, Obstacle, Shape};

    /// A view of a scene: the cloth is also its own rest shape.
    fn scene<'a>(
        positions: &'a [Vec3],
        triangles: &'a [[usize; 3]],
        obstacles: &'a [Obstacle],
        markers: &'a [Vec3],
    ) -> SceneView<'a> {
        SceneView {
            positions,
            triangles,
            rest_positions: positions,
            obstacles,
            time: 0.0,
            markers,
            up: Vec3::y(),
        }
    }

    fn square() -> (Vec<Vec3>, Vec<[usize; 3]>) {
        let p =
            [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)].map(|(x, z)| Vec3::new(x, 3.0, z));
        // (At height 3: the floor is at 0, below everything and below the cameras.)
        // Counter-clockwise seen from above: normals point up.
        (p.to_vec(), vec![[0, 2, 1], [0, 3, 2]])
    }

    fn pixel(frame: &[u8], width: usize, x: usize, y: usize) -> [u8; 3] {
        let i = 3 * (y * width + x);
        [frame[i], frame[i + 1], frame[i + 2]]
    }

    fn camera(eye: Vec3) -> Camera {
        Camera {
            eye,
            target: Vec3::new(0.0, 3.0, 0.0),
            up: Vec3::z(),
            fov_y: 60.0,
        }
    }

    #[test]
    fn each_side_of_the_cloth_has_its_colour() {
        let (x, t) = square();
        let view = scene(&x, &t, &[], &[]);
        let mut r = Renderer::new(64, 64).unwrap();
        let above = r
            .render_to_vec(&view, Some(&camera(Vec3::new(0.0, 6.0, 0.0))))
            .unwrap();
        let below = r
            .render_to_vec(&view, Some(&camera(Vec3::new(0.0, 1.0, 0.0))))
            .unwrap();
        let (front, back) = (pixel(&above, 64, 32, 32), pixel(&below, 64, 32, 32));
        // Red front (red well above green), ochre back (green well above blue).
        assert!(front[0] as i32 - front[1] as i32 > 60, "{front:?}");
        assert!(back[1] as i32 - back[2] as i32 > 40, "{back:?}");
        // The corner of the frame is background.
        assert_eq!(pixel(&above, 64, 0, 0), pixel(&below, 64, 0, 0));
    }

    #[test]
    fn nearer_surfaces_hide_farther_ones_and_markers_show() {
        let (x, t) = square();
        let ball = [Obstacle {
            shape: Shape::Sphere {
                center: Vec3::new(0.0, 2.0, 0.0),
                radius: 0.3,
            },
            mu: 0.0,
            motion: Motion::Static,
        }];
        let marker = [Vec3::new(0.5, 3.0, 0.5)];
        let mut r = Renderer::new(64, 64).unwrap();
        // From above the cloth hides the ball; from below the ball hides the cloth's centre.
        let above = r
            .render_to_vec(
                &scene(&x, &t, &ball, &marker),
                Some(&camera(Vec3::new(0.0, 6.0, 0.0))),
            )
            .unwrap();
        let bare = r
            .render_to_vec(
                &scene(&x, &t, &[], &[]),
                Some(&camera(Vec3::new(0.0, 6.0, 0.0))),
            )
            .unwrap();
        let (c, b) = (pixel(&above, 64, 32, 32), pixel(&bare, 64, 32, 32));
        assert!(
            c[0] as i32 - c[1] as i32 > 60 && b[0] as i32 - b[1] as i32 > 60,
            "red cloth: {c:?} {b:?}"
        );
        let below = r
            .render_to_vec(
                &scene(&x, &t, &ball, &[]),
                Some(&camera(Vec3::new(0.0, 1.0, 0.0))),
            )
            .unwrap();
        let c = pixel(&below, 64, 32, 32);
        assert!(c[2] > c[0], "slate ball in front of the ochre cloth: {c:?}");
        assert!(
            above.chunks_exact(3).any(|p| p == r.palette.marker),
            "the marker is drawn"
        );
    }

    #[test]
    fn frames_reuse_the_buffers_and_repeat_exactly() {
        let (x, t) = square();
        let ball = [Obstacle {
            shape: Shape::Sphere {
                center: Vec3::zeros(),
                radius: 0.3,
            },
            mu: 0.0,
            motion: Motion::Static,
        }];
        let view = scene(&x, &t, &ball, &[]);
        let mut r = Renderer::new(48, 32).unwrap();
        let mut out = vec![0; 48 * 32 * 3];
        r.render(&view, None, &mut out).unwrap();
        let first = out.clone();
        let buffers = |r: &Renderer| {
            (
                r.shaded.as_ptr(),
                r.surfaces.positions.as_ptr(),
                r.normals.as_ptr(),
                r.depth.as_ptr(),
            )
        };
        let before = buffers(&r);
        r.render(&view, None, &mut out).unwrap();
        assert_eq!(before, buffers(&r), "no buffer was reallocated");
        assert_eq!(first, out);
        assert!(matches!(
            r.render(&view, None, &mut out[1..]),
            Err(RenderError::Output { .. })
        ));
        assert!(matches!(
            Renderer::new(0, 5),
            Err(RenderError::Size { name: "width", .. })
        ));
        assert!(matches!(
            Renderer::new(5, MAX_SIZE + 1),
            Err(RenderError::Size { name: "height", .. })
        ));
    }
}
