//! Procedural garment meshes with curved rest shapes: the default meshes of the Hat and Sock
//! dressing scenes (after DiffCloth, Li et al. 2022). Units are the scenes' units (gravity
//! 9.8), the y axis points up.
//!
//! Both garments are built the same way: a sequence of vertex rings swept along a profile,
//! starting with a single pole vertex (crown top / toe tip) and ending with the open boundary
//! (brim edge / sock opening). A ring of radius `rho` gets `round(2 pi rho / h)` vertices (at
//! least 6; the boundary ring a multiple of 4, for the handles), consecutive rings are about
//! `h sqrt(3)/2` apart and staggered by half a step, and neighbouring rings are stitched by
//! merging their vertices in angular order. Triangles are thus close to equilateral and the pole
//! is surrounded by a regular ring of 6 (no slivers). The result is a topological disc:
//! connected, oriented counter-clockwise seen from outside, with exactly one boundary loop.

use std::f64::consts::{FRAC_PI_2, TAU};

/// A generated garment: vertex positions, triangles (counter-clockwise seen from outside), and
/// named handle vertices.
#[derive(Debug, Clone, PartialEq)]
pub struct Garment {
    /// Rest positions of the vertices.
    pub positions: Vec<[f64; 3]>,
    /// Vertex indices, counter-clockwise seen from outside.
    pub triangles: Vec<[usize; 3]>,
    /// Suggested end-effector vertices (attachment points), in the order documented by the
    /// generator ([`hat`], [`sock`]).
    pub handles: Vec<usize>,
}

/// Shape of the hat: a crown (half-ellipsoid of revolution) plus a drooping brim.
#[derive(Debug, Clone, PartialEq)]
pub struct HatParams {
    /// Radius of the crown at its rim (y = 0). Default 2.2 (fits a head sphere of radius 2.1).
    pub crown_radius: f64,
    /// Height of the crown top above the rim. Default 2.2; keep it above the head radius (2.1)
    /// so the crown clears a head centred at the origin.
    pub crown_height: f64,
    /// Outer radius of the brim, measured from the hat axis. Default 3.0 (hat 6 wide).
    pub brim_radius: f64,
    /// How far the brim's outer edge hangs below the crown rim (the brim follows a parabola
    /// that leaves the crown horizontally). Default 0.3.
    pub brim_droop: f64,
    /// Target edge length (the brim edge gets a multiple of 4 vertices).
    /// Default 0.295 (about 600 vertices).
    pub edge_length: f64,
}

impl Default for HatParams {
    fn default() -> Self {
        Self {
            crown_radius: 2.2,
            crown_height: 2.2,
            brim_radius: 3.0,
            brim_droop: 0.3,
            edge_length: 0.295,
        }
    }
}

/// Shape of the sock: leg tube, heel bend, foot tube and toe cap (see [`sock`] for the frame).
#[derive(Debug, Clone, PartialEq)]
pub struct SockParams {
    /// Tube radius of leg and foot. Default 0.9 (fits capsules of radius 0.8).
    pub radius: f64,
    /// Length of the straight vertical leg tube, from the top of the heel bend to the opening.
    /// Default 4.0.
    pub leg_length: f64,
    /// Length of the straight horizontal foot tube, from the end of the heel bend to the start
    /// of the toe cap. Default 3.5.
    pub foot_length: f64,
    /// Radius of the heel bend's centre line (90 degrees, in the y-z plane). Must exceed
    /// `radius`. Default 1.4.
    pub bend_radius: f64,
    /// Extra room at the heel: at mid-bend the cross-section radius grows by this much and its
    /// centre moves outwards by as much (the inner side of the bend stays put). Default 0.3.
    pub heel_bulge: f64,
    /// Target edge length (the opening gets a multiple of 4 vertices).
    /// Default 0.26 (about 1000 vertices).
    pub edge_length: f64,
}

impl Default for SockParams {
    fn default() -> Self {
        Self {
            radius: 0.9,
            leg_length: 4.0,
            foot_length: 3.5,
            bend_radius: 1.4,
            heel_bulge: 0.3,
            edge_length: 0.26,
        }
    }
}

/// A circular cross-section: points `center + rho (cos a * e1 + sin a * e2)`.
struct Section {
    center: [f64; 3],
    e1: [f64; 3],
    e2: [f64; 3],
    rho: f64,
}

/// One ring of built vertices: vertex `j` lies at angle `2 pi (j + phase) / count`.
struct Ring {
    start: usize,
    count: usize,
    phase: f64,
}

fn axpy(a: f64, x: [f64; 3], y: [f64; 3]) -> [f64; 3] {
    [y[0] + a * x[0], y[1] + a * x[1], y[2] + a * x[2]]
}

/// Builds the mesh from `sections` (the first one is the pole, a single vertex), with target
/// edge length `h`. The surface's outside is on the side of `e_angle x d`, where `e_angle` is
/// the direction of increasing angle and `d` points from one ring to the next.
/// Returns the garment (without handles) and the last ring.
fn build(sections: &[Section], h: f64) -> (Garment, Ring) {
    let mut g = Garment {
        positions: Vec::new(),
        triangles: Vec::new(),
        handles: Vec::new(),
    };
    let last = sections.len() - 1;
    let mut prev: Option<Ring> = None;
    for (k, s) in sections.iter().enumerate() {
        let count = match k {
            0 => 1,
            _ if k == last => 4 * ((TAU * s.rho / (4.0 * h)).round() as usize).max(2),
            _ => ((TAU * s.rho / h).round() as usize).max(6),
        };
        let phase = if k == 0 {
            0.0
        } else {
            0.5 * ((last - k) % 2) as f64
        };
        let ring = Ring {
            start: g.positions.len(),
            count,
            phase,
        };
        for j in 0..count {
            let a = TAU * (j as f64 + phase) / count as f64;
            g.positions.push(axpy(
                s.rho * a.cos(),
                s.e1,
                axpy(s.rho * a.sin(), s.e2, s.center),
            ));
        }
        if let Some(p) = prev {
            stitch(&mut g.triangles, &p, &ring);
        }
        prev = Some(ring);
    }
    (g, prev.expect("at least one section"))
}

/// Triangulates the band between rings `a` and `b` by merging their vertices in angular order.
/// A single-vertex ring (pole) is never advanced, which yields a fan.
fn stitch(tris: &mut Vec<[usize; 3]>, a: &Ring, b: &Ring) {
    let turn = |r: &Ring, i: usize| (i as f64 + r.phase) / r.count as f64;
    let idx = |r: &Ring, i: usize| r.start + i % r.count;
    let end = |r: &Ring| if r.count == 1 { 0 } else { r.count };
    let (a_end, b_end) = (end(a), end(b));
    let (mut i, mut j) = (0, 0);
    while i < a_end || j < b_end {
        if j == b_end || (i < a_end && turn(a, i + 1) <= turn(b, j + 1)) {
            tris.push([idx(a, i), idx(a, i + 1), idx(b, j)]);
            i += 1;
        } else {
            tris.push([idx(a, i), idx(b, j + 1), idx(b, j)]);
            j += 1;
        }
    }
}

/// `n + 1` points of the plane curve `f: [0, 1] -> R^2`, equally spaced in arc length, with
/// `n` the number of steps of length about `step`.
fn resample(f: impl Fn(f64) -> [f64; 2], step: f64) -> Vec<[f64; 2]> {
    const N: usize = 2000;
    let pts: Vec<[f64; 2]> = (0..=N).map(|i| f(i as f64 / N as f64)).collect();
    let mut cum = vec![0.0];
    for w in pts.windows(2) {
        cum.push(cum.last().unwrap() + (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]));
    }
    let total = cum[N];
    let n = ((total / step).round() as usize).max(1);
    let mut seg = 0;
    (0..=n)
        .map(|k| {
            let target = total * k as f64 / n as f64;
            while seg < N - 1 && cum[seg + 1] < target {
                seg += 1;
            }
            let t = ((target - cum[seg]) / (cum[seg + 1] - cum[seg])).clamp(0.0, 1.0);
            let (p, q) = (pts[seg], pts[seg + 1]);
            [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]
        })
        .collect()
}

/// A hat: crown plus brim, one surface of revolution about the +y axis.
///
/// Frame: the crown's rim (where crown meets brim) is the circle of radius `crown_radius` in
/// the plane y = 0, the crown top is at `(0, crown_height, 0)`, and the brim's outer edge is
/// at radius `brim_radius`, height `-brim_droop`. Placed as is, the hat sits on a head sphere
/// of radius 2.1 centred at the origin. The crown is the half-ellipsoid
/// `(r / crown_radius)^2 + (y / crown_height)^2 = 1, y >= 0`; the brim is
/// `y = -brim_droop ((r - crown_radius) / (brim_radius - crown_radius))^2`.
/// The outside is the crown's convex side and the brim's upper side. Vertex 0 is the crown
/// top; the brim edge (the only boundary) is the last ring.
///
/// Handles: `[+x brim edge vertex, -x brim edge vertex]`.
///
/// Panics unless `brim_radius > crown_radius` and `edge_length > 0`.
pub fn hat(p: &HatParams) -> Garment {
    assert!(
        p.brim_radius > p.crown_radius && p.edge_length > 0.0,
        "invalid hat parameters: {p:?}"
    );
    let h = p.edge_length;
    let step = h * 3f64.sqrt() / 2.0;
    let crown = |t: f64| {
        let a = t * FRAC_PI_2;
        [p.crown_radius * a.sin(), p.crown_height * a.cos()]
    };
    let dr = p.brim_radius - p.crown_radius;
    let brim = |t: f64| [p.crown_radius + t * dr, -p.brim_droop * t * t];
    let mut profile = resample(crown, step);
    profile.extend(resample(brim, step).into_iter().skip(1));
    let sections: Vec<Section> = profile
        .iter()
        .map(|&[r, y]| Section {
            center: [0.0, y, 0.0],
            e1: [1.0, 0.0, 0.0],
            e2: [0.0, 0.0, 1.0],
            rho: r,
        })
        .collect();
    let (mut g, rim) = build(&sections, h);
    g.handles = vec![rim.start, rim.start + rim.count / 2];
    g
}

/// A sock: vertical leg tube, 90-degree heel bend, horizontal foot tube along +z and a
/// hemispherical toe cap; open at the top.
///
/// Frame: the origin is the heel corner, where the leg axis (the y axis) meets the foot axis
/// (the z axis). With `R = bend_radius`, the leg tube runs from y = R up to the opening at
/// y = R + leg_length; the bend's centre line is the quarter circle of radius R about
/// `(0, R, R)` from `(0, R, 0)` to `(0, 0, R)`; the foot tube runs from z = R to
/// z = R + foot_length; the toe cap is a hemisphere of radius `radius` ending at
/// z = R + foot_length + radius. Defaults: opening at y = 5.4, toe tip at z = 5.8. It fits a
/// leg capsule on the y axis (from the origin upwards) and a foot capsule on the z axis (from
/// the origin to z = R + foot_length), both of radius 0.8. The outside is the tube's exterior.
/// Vertex 0 is the toe tip; the opening (the only boundary) is the last ring.
///
/// Handles: opening rim vertices at `[+x, +z, -x, -z]` from the leg axis, in that order.
///
/// Panics unless `bend_radius > radius` and `edge_length > 0`.
pub fn sock(p: &SockParams) -> Garment {
    assert!(
        p.bend_radius > p.radius && p.edge_length > 0.0,
        "invalid sock parameters: {p:?}"
    );
    let (r0, rb, b) = (p.radius, p.bend_radius, p.heel_bulge);
    let h = p.edge_length;
    let step = h * 3f64.sqrt() / 2.0;
    let steps = |len: f64| ((len / step).round() as usize).max(1);
    let x = [1.0, 0.0, 0.0];
    let sec = |center, e2, rho| Section {
        center,
        e1: x,
        e2,
        rho,
    };
    let toe_end = rb + p.foot_length;
    let down = [0.0, -1.0, 0.0];
    let mut sections = Vec::new();
    // Toe cap, from the tip (latitude 90 degrees) back to the foot tube.
    let n = steps(FRAC_PI_2 * r0);
    for k in 0..=n {
        let lat = FRAC_PI_2 * (1.0 - k as f64 / n as f64);
        sections.push(sec(
            [0.0, 0.0, toe_end + r0 * lat.sin()],
            down,
            r0 * lat.cos(),
        ));
    }
    // Foot tube, from the toe back to the heel bend.
    let n = steps(p.foot_length);
    for k in 1..=n {
        sections.push(sec(
            [0.0, 0.0, toe_end - p.foot_length * k as f64 / n as f64],
            down,
            r0,
        ));
    }
    // Heel bend: cross-sections in radial planes through the bend axis (the line through
    // (0, R, R) along x), theta from 90 degrees (foot) to 0 (leg).
    let n = steps(FRAC_PI_2 * ((rb - r0) * (rb + r0 + 2.0 * b)).sqrt());
    for k in 1..=n {
        let theta = FRAC_PI_2 * (1.0 - k as f64 / n as f64);
        let bulge = b * (2.0 * theta).sin().powi(2);
        let u = [0.0, -theta.sin(), -theta.cos()];
        sections.push(sec(axpy(rb + bulge, u, [0.0, rb, rb]), u, r0 + bulge));
    }
    // Leg tube, up to the opening.
    let n = steps(p.leg_length);
    for k in 1..=n {
        sections.push(sec(
            [0.0, rb + p.leg_length * k as f64 / n as f64, 0.0],
            [0.0, 0.0, -1.0],
            r0,
        ));
    }
    let (mut g, top) = build(&sections, h);
    // Angle a on the opening is at x = cos a, z = -sin a: +x, +z, -x, -z are at a = 0, 3/4,
    // 1/2, 1/4 turn.
    let q = top.count / 4;
    g.handles = vec![
        top.start,
        top.start + 3 * q,
        top.start + 2 * q,
        top.start + q,
    ];
    g
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::{HashMap, HashSet};

    fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
    }
    fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }
    fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    }
    fn norm(a: [f64; 3]) -> f64 {
        dot(a, a).sqrt()
    }

    /// Checks validity, quality and topology (a connected, consistently oriented disc); returns
    /// the vertices of the single boundary loop.
    fn check(g: &Garment, min_angle_deg: f64) -> HashSet<usize> {
        let (n, mut min_angle) = (g.positions.len(), 180.0f64);
        let (mut seen, mut directed) = (HashSet::new(), HashSet::new());
        for t in &g.triangles {
            assert!(t.iter().all(|&i| i < n), "index out of range: {t:?}");
            let mut s = *t;
            s.sort();
            assert!(seen.insert(s), "duplicate triangle {t:?}");
            let p = t.map(|i| g.positions[i]);
            assert!(
                norm(cross(sub(p[1], p[0]), sub(p[2], p[0]))) > 1e-8,
                "zero area {t:?}"
            );
            for k in 0..3 {
                let (u, v) = (sub(p[(k + 1) % 3], p[k]), sub(p[(k + 2) % 3], p[k]));
                min_angle = min_angle.min((dot(u, v) / (norm(u) * norm(v))).acos().to_degrees());
                assert!(
                    directed.insert((t[k], t[(k + 1) % 3])),
                    "edge traversed twice the same way"
                );
            }
        }
        println!("{n} vertices, min angle {min_angle:.1} degrees");
        assert!(min_angle > min_angle_deg);
        // Boundary edges (directed edges without a reverse twin) must form exactly one loop.
        let bnd: Vec<(usize, usize)> = directed
            .iter()
            .filter(|&&(a, b)| !directed.contains(&(b, a)))
            .copied()
            .collect();
        let next: HashMap<usize, usize> = bnd.iter().copied().collect();
        assert_eq!(next.len(), bnd.len(), "boundary vertex visited twice");
        let (mut v, mut len) = (bnd[0].1, 1);
        while v != bnd[0].0 {
            (v, len) = (next[&v], len + 1);
        }
        assert_eq!(len, bnd.len(), "boundary is not a single loop");
        // Connected (labels propagated along edges), with Euler characteristic 1: a disc.
        let mut label: Vec<usize> = (0..n).collect();
        let mut changed = true;
        while changed {
            changed = false;
            for &(a, b) in &directed {
                let m = label[a].min(label[b]);
                changed |= label[a] != m || label[b] != m;
                (label[a], label[b]) = (m, m);
            }
        }
        assert!(label.iter().all(|&l| l == 0), "not connected");
        let edges = (directed.len() + bnd.len()) / 2;
        assert_eq!(n + g.triangles.len(), edges + 1, "not a disc");
        next.into_keys().collect()
    }

    /// Handles are boundary vertices at the `expected` positions.
    fn check_handles(g: &Garment, boundary: &HashSet<usize>, expected: &[[f64; 3]]) {
        assert_eq!(g.handles.len(), expected.len());
        for (&h, &e) in g.handles.iter().zip(expected) {
            assert!(
                boundary.contains(&h) && norm(sub(g.positions[h], e)) < 1e-9,
                "handle {h}, expected {e:?}"
            );
        }
    }

    /// Every triangle's normal points away from `inside(centroid)`.
    fn check_outward(g: &Garment, inside: impl Fn([f64; 3]) -> [f64; 3]) {
        for t in &g.triangles {
            let p = t.map(|i| g.positions[i]);
            let c = [0, 1, 2].map(|k| (p[0][k] + p[1][k] + p[2][k]) / 3.0);
            assert!(
                dot(cross(sub(p[1], p[0]), sub(p[2], p[0])), sub(c, inside(c))) > 0.0,
                "{t:?}"
            );
        }
    }

    /// Distance from `q` to the segment `a`-`b`.
    fn seg_dist(q: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
        let d = sub(b, a);
        let t = (dot(sub(q, a), d) / dot(d, d)).clamp(0.0, 1.0);
        norm(sub(q, axpy(t, d, a)))
    }

    #[test]
    fn hat_default() {
        let g = hat(&HatParams::default());
        let (nv, nt) = (g.positions.len(), g.triangles.len());
        println!(
            "hat: {nv} vertices, {nt} triangles, handles {:?}",
            g.handles
        );
        assert!((550..=650).contains(&nv), "{nv} vertices");
        let boundary = check(&g, 15.0);
        assert!(boundary
            .iter()
            .all(|&i| (g.positions[i][0].hypot(g.positions[i][2]) - 3.0).abs() < 1e-9));
        // Clears the head sphere (radius 2.1 at the origin); about 6 wide.
        assert!(g.positions.iter().all(|&p| norm(p) > 2.15));
        let xs = g.positions.iter().map(|p| p[0]);
        let width = xs.clone().fold(f64::MIN, f64::max) - xs.fold(f64::MAX, f64::min);
        assert!((5.5..=6.5).contains(&width), "width {width}");
        // Crown normals point away from the origin, brim normals up.
        check_outward(&g, |c| {
            if c[1] > 0.0 {
                [0.0; 3]
            } else {
                [c[0], c[1] - 1.0, c[2]]
            }
        });
        check_handles(&g, &boundary, &[[3.0, -0.3, 0.0], [-3.0, -0.3, 0.0]]);
        assert_eq!(g, hat(&HatParams::default()), "deterministic");
    }

    #[test]
    fn sock_default() {
        let p = SockParams::default();
        let g = sock(&p);
        let (nv, nt) = (g.positions.len(), g.triangles.len());
        println!(
            "sock: {nv} vertices, {nt} triangles, handles {:?}",
            g.handles
        );
        assert!((900..=1100).contains(&nv), "{nv} vertices");
        let boundary = check(&g, 10.0);
        let top = p.bend_radius + p.leg_length;
        assert!(
            boundary
                .iter()
                .all(|&i| (g.positions[i][1] - top).abs() < 1e-9),
            "boundary is the opening"
        );
        // Leg capsule along y, foot capsule along z, radius 0.8, meeting at the heel corner.
        let o = [0.0; 3];
        let (leg_end, foot_end) = (
            [0.0, top + 1.0, 0.0],
            [0.0, 0.0, p.bend_radius + p.foot_length],
        );
        let clearance = |q| seg_dist(q, o, leg_end).min(seg_dist(q, o, foot_end)) - 0.8;
        let min = g
            .positions
            .iter()
            .map(|&q| clearance(q))
            .fold(f64::MAX, f64::min);
        println!("sock: min clearance {min:.3}");
        assert!(min >= 0.05, "min clearance {min}");
        // Normals point away from the nearest capsule axis.
        check_outward(&g, |c| {
            let leg = seg_dist(c, o, leg_end) < seg_dist(c, o, foot_end);
            if leg {
                [0.0, c[1].max(0.0), 0.0]
            } else {
                [0.0, 0.0, c[2].max(0.0)]
            }
        });
        let r = p.radius;
        check_handles(
            &g,
            &boundary,
            &[[r, top, 0.0], [0.0, top, r], [-r, top, 0.0], [0.0, top, -r]],
        );
        assert_eq!(g, sock(&p), "deterministic");
    }

    #[test]
    fn other_resolutions() {
        for h in [0.15, 0.2, 0.45, 0.6] {
            let g = hat(&HatParams {
                edge_length: h,
                ..Default::default()
            });
            check(&g, 15.0);
            assert_eq!(g.handles.len(), 2);
            let g = sock(&SockParams {
                edge_length: h,
                ..Default::default()
            });
            check(&g, 10.0);
            assert_eq!(g.handles.len(), 4);
        }
    }
}
