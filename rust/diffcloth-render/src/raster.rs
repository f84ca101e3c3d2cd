//! The z-buffer rasterizer: triangles with per-vertex colours (Gouraud) and screen-space
//! discs, written into an RGB8 frame, plus clipping at the near plane.
//!
//! A pixel is covered when its centre is inside the triangle by the three edge functions
//! `E_ab(p) = (b - a) x (p - a)`; a centre exactly on an edge belongs to the triangle for
//! which that edge is a top or left edge, so two triangles sharing an edge never both draw
//! it nor leave a gap. The depth value is the inverse view depth (affine in screen space,
//! larger is nearer); colours are interpolated affinely in screen space (triangles are
//! small; the error of skipping perspective correction is invisible at cloth resolution).

use crate::camera::Vec3f;

/// A projected vertex: pixel position, inverse depth, colour (0..255 per channel).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vertex {
    pub x: f32,
    pub y: f32,
    pub z: f32,
    pub color: [f32; 3],
}

/// A vertex in view space (before projection), as clipping needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewVertex {
    pub position: Vec3f,
    pub color: [f32; 3],
}

/// The frame being drawn: `height` rows of `width` RGB pixels and a depth per pixel.
pub struct Target<'a> {
    pub color: &'a mut [u8],
    pub depth: &'a mut [f32],
    pub width: usize,
    pub height: usize,
}

#[inline]
fn edge(ax: f32, ay: f32, bx: f32, by: f32, px: f32, py: f32) -> f32 {
    (bx - ax) * (py - ay) - (by - ay) * (px - ax)
}

/// Whether the edge a -> b of a triangle with positive `edge` area (y down) is a top or a
/// left edge: it owns the pixel centres lying exactly on it.
#[inline]
fn owns_ties(ax: f32, ay: f32, bx: f32, by: f32) -> bool {
    // Positive area with y down is clockwise on screen; a top edge runs right, a left edge up.
    (ay == by && bx > ax) || by < ay
}

impl Target<'_> {
    /// Draws a triangle where it is nearer than what is drawn (either winding).
    pub fn triangle(&mut self, v: &[Vertex; 3]) {
        let [a, mut b, mut c] = *v;
        let mut area = edge(a.x, a.y, b.x, b.y, c.x, c.y);
        if area < 0.0 {
            std::mem::swap(&mut b, &mut c);
            area = -area;
        }
        // Also rejects NaN coordinates (every comparison fails).
        if !(area > 0.0 && area.is_finite()) {
            return;
        }
        let (w, h) = (self.width as f32, self.height as f32);
        let min_x = a.x.min(b.x).min(c.x);
        let max_x = a.x.max(b.x).max(c.x);
        let min_y = a.y.min(b.y).min(c.y);
        let max_y = a.y.max(b.y).max(c.y);
        if !(max_x >= 0.0 && max_y >= 0.0 && min_x <= w && min_y <= h) {
            return;
        }
        // Pixel columns/rows whose centres (i + 0.5) can lie inside the box.
        let x0 = (min_x - 0.5).ceil().max(0.0) as usize;
        let x1 = ((max_x - 0.5).floor().min(w - 1.0)) as isize;
        let y0 = (min_y - 0.5).ceil().max(0.0) as usize;
        let y1 = ((max_y - 0.5).floor().min(h - 1.0)) as isize;
        if x1 < x0 as isize || y1 < y0 as isize {
            return;
        }
        let (x1, y1) = (x1 as usize, y1 as usize);
        // Barycentric weights: w_a = E_bc / area etc. Stepping one pixel right changes E_ab
        // by -(b.y - a.y).
        let (ta, tb, tc) = (
            owns_ties(b.x, b.y, c.x, c.y),
            owns_ties(c.x, c.y, a.x, a.y),
            owns_ties(a.x, a.y, b.x, b.y),
        );
        let (da, db, dc) = (-(c.y - b.y), -(a.y - c.y), -(b.y - a.y));
        let inv_area = 1.0 / area;
        // An attribute with values fa, fb, fc at the vertices is (ea fa + eb fb + ec fc) /
        // area at a pixel: start value per row, constant step per pixel.
        let plane = |fa: f32, fb: f32, fc: f32| {
            let (fa, fb, fc) = (fa * inv_area, fb * inv_area, fc * inv_area);
            ([fa, fb, fc], da * fa + db * fb + dc * fc)
        };
        let attributes = [
            plane(a.z, b.z, c.z),
            plane(a.color[0], b.color[0], c.color[0]),
            plane(a.color[1], b.color[1], c.color[1]),
            plane(a.color[2], b.color[2], c.color[2]),
        ];
        let steps = attributes.map(|(_, step)| step);
        // `e >= threshold` is `e >= 0` for an edge owning its ties, else `e > 0` (nothing
        // lies between 0 and the smallest positive float).
        let threshold = |ties: bool| if ties { 0.0 } else { f32::from_bits(1) };
        let (ta, tb, tc) = (threshold(ta), threshold(tb), threshold(tc));
        let (x0f, x1f) = (x0 as f32, x1 as f32);
        for py in y0..=y1 {
            let fy = py as f32 + 0.5;
            // Edge values at column x0; each edge bounds the row's span on one side, where
            // it crosses zero (widened by a pixel: the exact test below decides).
            let ea0 = edge(b.x, b.y, c.x, c.y, x0f + 0.5, fy);
            let eb0 = edge(c.x, c.y, a.x, a.y, x0f + 0.5, fy);
            let ec0 = edge(a.x, a.y, b.x, b.y, x0f + 0.5, fy);
            let (mut lo, mut hi) = (x0f, x1f);
            let mut empty = false;
            for (e, d) in [(ea0, da), (eb0, db), (ec0, dc)] {
                let cross = (x0f - e / d).clamp(x0f - 2.0, x1f + 2.0);
                if d > 0.0 {
                    lo = lo.max(floor(cross) - 1.0);
                } else if d < 0.0 {
                    hi = hi.min(floor(cross) + 2.0);
                } else {
                    empty |= e < 0.0;
                }
            }
            if empty || lo > hi {
                continue;
            }
            let (xs, xe) = (lo as usize, hi as usize);
            let fx = xs as f32 + 0.5;
            let mut ea = edge(b.x, b.y, c.x, c.y, fx, fy);
            let mut eb = edge(c.x, c.y, a.x, a.y, fx, fy);
            let mut ec = edge(a.x, a.y, b.x, b.y, fx, fy);
            let [mut z, mut r, mut g, mut bl] =
                attributes.map(|(f, _)| ea * f[0] + eb * f[1] + ec * f[2]);
            let row = py * self.width;
            let depth_row = &mut self.depth[row + xs..=row + xe];
            let color_row = &mut self.color[3 * (row + xs)..3 * (row + xe + 1)];
            for (d, rgb) in depth_row.iter_mut().zip(color_row.chunks_exact_mut(3)) {
                if (ea >= ta) & (eb >= tb) & (ec >= tc) & (z > *d) {
                    *d = z;
                    rgb[0] = to_u8(r);
                    rgb[1] = to_u8(g);
                    rgb[2] = to_u8(bl);
                }
                ea += da;
                eb += db;
                ec += dc;
                z += steps[0];
                r += steps[1];
                g += steps[2];
                bl += steps[3];
            }
        }
    }

    /// A filled disc of `radius` pixels around (x, y) at inverse depth `z`, with a one-pixel
    /// `outline` ring, drawn where it is nearer than the scene.
    pub fn disc(&mut self, x: f32, y: f32, z: f32, radius: f32, fill: [u8; 3], outline: [u8; 3]) {
        if !(x.is_finite() && y.is_finite() && z.is_finite() && radius > 0.0) {
            return;
        }
        let outer = radius + 1.0;
        let (w, h) = (self.width as f32, self.height as f32);
        let x0 = (x - outer - 0.5).ceil().max(0.0);
        let x1 = (x + outer - 0.5).floor().min(w - 1.0);
        let y0 = (y - outer - 0.5).ceil().max(0.0);
        let y1 = (y + outer - 0.5).floor().min(h - 1.0);
        if x1 < x0 || y1 < y0 {
            return;
        }
        for py in y0 as usize..=y1 as usize {
            for px in x0 as usize..=x1 as usize {
                let (dx, dy) = (px as f32 + 0.5 - x, py as f32 + 0.5 - y);
                let r2 = dx * dx + dy * dy;
                let i = py * self.width + px;
                if r2 <= outer * outer && z >= self.depth[i] {
                    let rgb = if r2 <= radius * radius { fill } else { outline };
                    self.color[3 * i..3 * i + 3].copy_from_slice(&rgb);
                }
            }
        }
    }
}

/// `x.floor()` for |x| < 2^31 without a libm call (no SSE4.1 rounding in the baseline).
#[inline]
fn floor(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

#[inline]
fn to_u8(c: f32) -> u8 {
    (c + 0.5).clamp(0.0, 255.0) as u8
}

/// Clips a view-space triangle to depth >= `near` (the part in front of the camera):
/// writes 0, 3 or 4 vertices of a convex polygon into `out` and returns how many.
pub fn clip_near(tri: &[ViewVertex; 3], near: f32, out: &mut [ViewVertex; 4]) -> usize {
    let depth = |v: &ViewVertex| -v.position.z - near;
    let mut n = 0;
    for i in 0..3 {
        let (p, q) = (&tri[i], &tri[(i + 1) % 3]);
        let (dp, dq) = (depth(p), depth(q));
        if dp >= 0.0 {
            out[n] = *p;
            n += 1;
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            let t = dp / (dp - dq);
            let lerp = |a: f32, b: f32| a + (b - a) * t;
            out[n] = ViewVertex {
                position: p.position + (q.position - p.position) * t,
                color: [0, 1, 2].map(|k| lerp(p.color[k], q.color[k])),
            };
            n += 1;
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: usize, h: usize) -> (Vec<u8>, Vec<f32>) {
        (vec![0; w * h * 3], vec![0.0; w * h])
    }

    fn vertex(x: f32, y: f32, z: f32, c: f32) -> Vertex {
        Vertex {
            x,
            y,
            z,
            color: [c; 3],
        }
    }

    #[test]
    fn a_triangle_covers_the_pixel_centres_inside_it() {
        let (w, h) = (8, 8);
        let (mut color, mut depth) = frame(w, h);
        let mut t = Target {
            color: &mut color,
            depth: &mut depth,
            width: w,
            height: h,
        };
        // Lower-left half of the square [0, 8]^2 below the diagonal from (0, 0) to (8, 8):
        // centres with y > x, plus the diagonal's own centres if it is a top/left edge.
        t.triangle(&[
            vertex(0.0, 0.0, 1.0, 200.0),
            vertex(8.0, 8.0, 1.0, 200.0),
            vertex(0.0, 8.0, 1.0, 200.0),
        ]);
        for py in 0..h {
            for px in 0..w {
                let drawn = color[3 * (py * w + px)] == 200;
                if py > px {
                    assert!(drawn, "({px}, {py}) is inside");
                } else if py < px {
                    assert!(!drawn, "({px}, {py}) is outside");
                }
            }
        }
    }

    #[test]
    fn two_triangles_sharing_an_edge_cover_each_pixel_once() {
        let (w, h) = (16, 16);
        let (p, q, r, s) = ((1.0, 1.0), (15.0, 1.0), (15.0, 15.0), (1.0, 15.0));
        let tris = [[p, q, r], [p, r, s], [r, p, s]];
        let covered: Vec<Vec<bool>> = tris
            .iter()
            .map(|tri| {
                let (mut color, mut depth) = frame(w, h);
                let mut t = Target {
                    color: &mut color,
                    depth: &mut depth,
                    width: w,
                    height: h,
                };
                t.triangle(&tri.map(|(x, y)| vertex(x, y, 1.0, 1.0)));
                (0..w * h).map(|i| color[3 * i] == 1).collect()
            })
            .collect();
        assert_eq!(covered[1], covered[2], "winding does not change coverage");
        for py in 0..h {
            for px in 0..w {
                let i = py * w + px;
                let inside = (1..15).contains(&px) && (1..15).contains(&py);
                let count = covered[0][i] as u8 + covered[1][i] as u8;
                assert_eq!(count, inside as u8, "({px}, {py}) drawn {count} times");
            }
        }
    }

    #[test]
    fn the_nearer_triangle_wins_in_either_order() {
        let (w, h) = (10, 10);
        for order in [[0, 1], [1, 0]] {
            let (mut color, mut depth) = frame(w, h);
            let mut t = Target {
                color: &mut color,
                depth: &mut depth,
                width: w,
                height: h,
            };
            // Inverse depth: 0.5 (depth 2) is nearer than 0.25 (depth 4).
            let tris = [
                [
                    vertex(0.0, 0.0, 0.25, 10.0),
                    vertex(10.0, 0.0, 0.25, 10.0),
                    vertex(0.0, 10.0, 0.25, 10.0),
                ],
                [
                    vertex(0.0, 0.0, 0.5, 90.0),
                    vertex(10.0, 0.0, 0.5, 90.0),
                    vertex(0.0, 10.0, 0.5, 90.0),
                ],
            ];
            for k in order {
                t.triangle(&tris[k]);
            }
            assert_eq!(color[3 * (2 * w + 2)], 90, "order {order:?}");
            assert_eq!(depth[2 * w + 2], 0.5);
        }
    }

    #[test]
    fn depth_is_interpolated_across_a_slanted_triangle() {
        let (w, h) = (10, 10);
        let (mut color, mut depth) = frame(w, h);
        let mut t = Target {
            color: &mut color,
            depth: &mut depth,
            width: w,
            height: h,
        };
        t.triangle(&[
            vertex(0.0, 0.0, 1.0, 0.0),
            vertex(20.0, 0.0, 0.0, 0.0),
            vertex(0.0, 20.0, 1.0, 0.0),
        ]);
        // z = 1 - x / 20 at the pixel centre x = 4.5.
        assert!((t.depth[3 * w + 4] - (1.0 - 4.5 / 20.0)).abs() < 1e-6);
        // A second triangle in front on the right half only: it wins there and nowhere else.
        t.triangle(&[
            vertex(5.0, 0.0, 0.9, 255.0),
            vertex(10.0, 0.0, 0.9, 255.0),
            vertex(5.0, 10.0, 0.9, 255.0),
        ]);
        assert_eq!(color[3 * (1 * w + 6)], 255, "in front of z = 0.675");
    }

    #[test]
    fn degenerate_and_offscreen_triangles_draw_nothing() {
        let (w, h) = (4, 4);
        let (mut color, mut depth) = frame(w, h);
        let mut t = Target {
            color: &mut color,
            depth: &mut depth,
            width: w,
            height: h,
        };
        t.triangle(&[
            vertex(0.0, 0.0, 1.0, 9.0),
            vertex(4.0, 4.0, 1.0, 9.0),
            vertex(2.0, 2.0, 1.0, 9.0),
        ]);
        t.triangle(&[
            vertex(10.0, 0.0, 1.0, 9.0),
            vertex(14.0, 0.0, 1.0, 9.0),
            vertex(10.0, 4.0, 1.0, 9.0),
        ]);
        t.triangle(&[
            vertex(f32::NAN, 0.0, 1.0, 9.0),
            vertex(4.0, 0.0, 1.0, 9.0),
            vertex(0.0, 4.0, 1.0, 9.0),
        ]);
        assert!(color.iter().all(|&c| c == 0));
    }

    #[test]
    fn clipping_keeps_the_part_in_front() {
        let v = |z: f32| ViewVertex {
            position: Vec3f::new(0.0, 0.0, z),
            color: [z; 3],
        };
        let mut out = [v(0.0); 4];
        assert_eq!(clip_near(&[v(-2.0), v(-3.0), v(-4.0)], 1.0, &mut out), 3);
        assert_eq!(clip_near(&[v(2.0), v(3.0), v(0.5)], 1.0, &mut out), 0);
        // One vertex behind: a quad; two behind: a triangle; every kept depth >= near.
        assert_eq!(clip_near(&[v(-2.0), v(-3.0), v(0.0)], 1.0, &mut out), 4);
        assert!(out.iter().all(|p| -p.position.z >= 1.0 - 1e-6));
        assert_eq!(clip_near(&[v(-2.0), v(0.0), v(0.0)], 1.0, &mut out), 3);
        assert!(out[..3].iter().all(|p| -p.position.z >= 1.0 - 1e-6));
    }
}
