//! Colours and lighting: two-sided Lambert shading at the vertices, a depth cue (distant
//! surfaces fade towards the haze colour), and the background gradient.
//!
//! The light is fixed to the camera (up-left, behind the viewer), so every view is lit the
//! same way. A vertex gets a colour for each side of its surface: `ambient + diffuse
//! max(0, s n.l) + head max(0, s n.z)` times the side's base colour, with `s = +1` for the
//! side the normal points to and `-1` for the other; the rasterizer picks the side each
//! triangle shows.

use crate::camera::Vec3f;

/// Colours of everything drawn (RGB, 0..255).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Palette {
    /// The cloth side its triangles' normals point to (default: brick red).
    pub cloth_front: [f32; 3],
    /// The cloth's other side (default: ochre).
    pub cloth_back: [f32; 3],
    /// Obstacles (default: slate grey).
    pub obstacle: [f32; 3],
    /// The floor's two checker tiles (default: light greys).
    pub floor: [[f32; 3]; 2],
    /// Background at the top and bottom of the frame (default: pale blue to near white).
    pub sky: [[f32; 3]; 2],
    /// Effector / attachment target marks and their outline (default: green, near black).
    pub marker: [u8; 3],
    pub marker_outline: [u8; 3],
}

impl Default for Palette {
    fn default() -> Self {
        Self {
            cloth_front: [200.0, 70.0, 58.0],
            cloth_back: [232.0, 178.0, 82.0],
            obstacle: [140.0, 156.0, 178.0],
            floor: [[206.0, 206.0, 200.0], [178.0, 178.0, 172.0]],
            sky: [[170.0, 190.0, 214.0], [236.0, 238.0, 242.0]],
            marker: [30, 200, 110],
            marker_outline: [15, 25, 20],
        }
    }
}

/// Light fixed to the camera, in view space.
#[derive(Debug, Clone, Copy)]
pub struct Light {
    /// Unit direction from a surface towards the light.
    pub direction: Vec3f,
    pub ambient: f32,
    pub diffuse: f32,
    /// Weight of a headlight term (light from the eye) that keeps faces seen edge-on from
    /// the key light readable.
    pub head: f32,
}

impl Default for Light {
    fn default() -> Self {
        Self {
            direction: Vec3f::new(-0.45, 0.65, 0.6).normalize(),
            ambient: 0.28,
            diffuse: 0.62,
            head: 0.18,
        }
    }
}

impl Light {
    /// Brightness of the side of a surface its unit view-space normal `n` points to, and of
    /// the other side.
    #[inline]
    pub fn two_sided(&self, n: &Vec3f) -> (f32, f32) {
        let (l, z) = (n.dot(&self.direction), n.z);
        let side =
            |s: f32| self.ambient + self.diffuse * (s * l).max(0.0) + self.head * (s * z).max(0.0);
        (side(1.0), side(-1.0))
    }
}

/// Depth cue: fades colours towards `haze` over the depth range of the scene.
#[derive(Debug, Clone, Copy)]
pub struct DepthCue {
    pub near: f32,
    pub far: f32,
    /// Fraction of the haze colour at the far depth.
    pub strength: f32,
    pub haze: [f32; 3],
}

impl DepthCue {
    /// `color` (already lit) seen at `depth`.
    #[inline]
    pub fn apply(&self, color: [f32; 3], depth: f32) -> [f32; 3] {
        let t = ((depth - self.near) / (self.far - self.near).max(1e-12)).clamp(0.0, 1.0)
            * self.strength;
        [0, 1, 2].map(|k| color[k] + (self.haze[k] - color[k]) * t)
    }
}

#[inline]
pub(crate) fn scale(c: [f32; 3], s: f32) -> [f32; 3] {
    [c[0] * s, c[1] * s, c[2] * s]
}

/// Fills `rows` (one RGB colour per row) with the vertical background gradient.
pub(crate) fn sky_rows(palette: &Palette, rows: &mut Vec<[u8; 3]>, height: usize) {
    rows.clear();
    let [top, bottom] = palette.sky;
    rows.extend((0..height).map(|y| {
        let t = (y as f32 + 0.5) / height as f32;
        [0, 1, 2].map(|k| (top[k] + (bottom[k] - top[k]) * t + 0.5) as u8)
    }));
}
