//! A look-at pinhole camera and its default framing of a scene.
//!
//! View space is right-handed with the camera at the origin, x right, y up, looking down -z
//! (OpenGL's convention); a point's depth is `-z`. Screen space is pixels, x right, y down,
//! pixel centres at half-integers.

use crate::error::RenderError;
use diffcloth::Vec3;
use nalgebra::{Matrix3, Vector3};

/// Single-precision 3-vector: view-space positions and normals (rasterizing needs no more).
pub type Vec3f = Vector3<f32>;

/// A perspective camera looking from `eye` at `target`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Camera position in scene units.
    pub eye: Vec3,
    /// The point at the centre of the frame.
    pub target: Vec3,
    /// The direction that points up in the frame (need not be orthogonal to the view).
    pub up: Vec3,
    /// Vertical field of view in degrees, in (0, 180) (default framing: 40).
    pub fov_y: f64,
}

/// Field of view of the default framing, degrees.
pub const DEFAULT_FOV_Y: f64 = 40.0;
/// Direction of the default eye from the target: azimuth from the scene's "front" (+z when y
/// is up) towards +x, and elevation above the horizon, degrees.
const DEFAULT_AZIMUTH: f64 = 30.0;
const DEFAULT_ELEVATION: f64 = 22.0;

impl Camera {
    /// Checks the camera defines a view; the error names the field at fault.
    pub fn validate(&self) -> Result<(), RenderError> {
        let err = |field, message: &str| {
            Err(RenderError::Camera {
                field,
                message: message.to_string(),
            })
        };
        for (field, v) in [("eye", self.eye), ("target", self.target), ("up", self.up)] {
            if !v.iter().all(|c| c.is_finite()) {
                return err(
                    field,
                    &format!("must be 3 finite numbers, got {:?}", v.as_slice()),
                );
            }
        }
        if !(self.fov_y > 0.0 && self.fov_y < 180.0) {
            return err(
                "fov",
                &format!("must be in (0, 180) degrees, got {}", self.fov_y),
            );
        }
        let forward = self.target - self.eye;
        if forward.norm() == 0.0 {
            return err("eye", "must differ from the target");
        }
        if self.up.cross(&forward).norm() <= 1e-9 * self.up.norm() * forward.norm() {
            return err(
                "up",
                "must be non-zero and not parallel to the viewing direction",
            );
        }
        Ok(())
    }

    /// The default view of a scene whose interesting part lies in the box `lo`-`hi`, with `up`
    /// pointing up: the box's bounding sphere fills the frame (of aspect width / height), seen
    /// from the front-right and above.
    pub fn framing(lo: Vec3, hi: Vec3, up: Vec3, aspect: f64) -> Self {
        let center = (lo + hi) / 2.0;
        let radius = ((hi - lo).norm() / 2.0).max(1e-6);
        let (right, up, front) = scene_basis(up);
        let (az, el) = (DEFAULT_AZIMUTH.to_radians(), DEFAULT_ELEVATION.to_radians());
        let dir = (front * az.cos() + right * az.sin()) * el.cos() + up * el.sin();
        // Fit the sphere in the narrower of the two fields of view.
        let half_y = (DEFAULT_FOV_Y / 2.0).to_radians();
        let half_x = (half_y.tan() * aspect).atan();
        let distance = radius / half_y.min(half_x).sin() * 1.02;
        Self {
            eye: center + dir * distance,
            target: center,
            up,
            fov_y: DEFAULT_FOV_Y,
        }
    }

    /// The projection of this camera onto a `width` x `height` frame, clipping at depth
    /// `near`. The camera must be valid.
    pub(crate) fn view(&self, width: usize, height: usize, near: f64) -> View {
        let back = (self.eye - self.target).normalize();
        let right = self.up.cross(&back).normalize();
        let up = back.cross(&right);
        let rotation = Matrix3::from_rows(&[right.transpose(), up.transpose(), back.transpose()]);
        let focal = 1.0 / (self.fov_y.to_radians() / 2.0).tan();
        let (w, h) = (width as f64, height as f64);
        View {
            rotation,
            eye: self.eye,
            // ndc_y = focal * y / depth; pixels: half the height per ndc unit (square pixels).
            scale: (focal * h / 2.0) as f32,
            cx: (w / 2.0) as f32,
            cy: (h / 2.0) as f32,
            near: near as f32,
        }
    }
}

/// `(right, up, front)` of a scene with `up` pointing up: front is +z made orthogonal to up
/// (+x if up is along z), so that y-up scenes are seen from +z with +x to the right.
pub(crate) fn scene_basis(up: Vec3) -> (Vec3, Vec3, Vec3) {
    let up = up.try_normalize(1e-12).unwrap_or_else(Vec3::y);
    let mut front = Vec3::z() - up * up.z;
    if front.norm() < 1e-6 {
        front = Vec3::x() - up * up.x;
    }
    let front = front.normalize();
    (up.cross(&front), up, front)
}

/// A camera's transform to view space and its projection to pixels.
#[derive(Debug, Clone, Copy)]
pub(crate) struct View {
    /// Rows: the camera's right, up and backward axes in scene coordinates.
    rotation: Matrix3<f64>,
    eye: Vec3,
    /// Pixels per unit of `y / depth`.
    scale: f32,
    cx: f32,
    cy: f32,
    /// Geometry nearer than this depth is clipped away.
    pub(crate) near: f32,
}

impl View {
    /// A scene point in view space.
    #[inline]
    pub(crate) fn point(&self, p: &Vec3) -> Vec3f {
        (self.rotation * (p - self.eye)).cast()
    }

    /// A scene direction in view space.
    #[inline]
    pub(crate) fn direction(&self, d: &Vec3) -> Vec3f {
        (self.rotation * d).cast()
    }

    /// Screen position (pixels) and inverse depth of a view-space point in front of the
    /// camera (depth >= near). Inverse depth is affine in screen space, so the z-buffer
    /// interpolates it linearly; larger is nearer.
    #[inline]
    pub(crate) fn project(&self, v: &Vec3f) -> [f32; 3] {
        let inv = 1.0 / -v.z;
        [
            self.cx + self.scale * v.x * inv,
            self.cy - self.scale * v.y * inv,
            inv,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_projects_to_the_centre_and_up_is_up() {
        let cam = Camera {
            eye: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::zeros(),
            up: Vec3::y(),
            fov_y: 90.0,
        };
        cam.validate().unwrap();
        let view = cam.view(200, 100, 0.01);
        let [x, y, inv] = view.project(&view.point(&Vec3::zeros()));
        assert_eq!((x, y), (100.0, 50.0));
        assert!((inv - 0.2).abs() < 1e-7);
        // fov 90: a point at height = depth sits on the top edge.
        let [_, top, _] = view.project(&view.point(&Vec3::new(0.0, 5.0, 0.0)));
        assert!(top.abs() < 1e-4, "{top}");
        let [right, _, _] = view.project(&view.point(&Vec3::new(1.0, 0.0, 0.0)));
        assert!(right > 100.0);
    }

    #[test]
    fn framing_sees_the_whole_box() {
        let (lo, hi) = (Vec3::new(-1.0, 0.0, -2.0), Vec3::new(3.0, 1.0, 0.5));
        let cam = Camera::framing(lo, hi, Vec3::y(), 1.5);
        cam.validate().unwrap();
        let view = cam.view(300, 200, 0.01);
        for i in 0..8 {
            let corner = Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            let [x, y, _] = view.project(&view.point(&corner));
            assert!(
                (0.0..300.0).contains(&x) && (0.0..200.0).contains(&y),
                "{corner:?}"
            );
        }
    }

    #[test]
    fn bad_cameras_name_the_field() {
        let good = Camera::framing(Vec3::zeros(), Vec3::repeat(1.0), Vec3::y(), 1.0);
        let field = |c: Camera| match c.validate() {
            Err(RenderError::Camera { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            field(Camera {
                eye: Vec3::new(f64::NAN, 0.0, 0.0),
                ..good
            }),
            "eye"
        );
        assert_eq!(
            field(Camera {
                eye: good.target,
                ..good
            }),
            "eye"
        );
        assert_eq!(
            field(Camera {
                fov_y: 180.0,
                ..good
            }),
            "fov"
        );
        assert_eq!(
            field(Camera {
                up: Vec3::zeros(),
                ..good
            }),
            "up"
        );
        assert_eq!(
            field(Camera {
                up: good.target - good.eye,
                ..good
            }),
            "up"
        );
    }
}
