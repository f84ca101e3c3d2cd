//! Overlaps in the current state: nodes inside an obstacle and self-contact pairs closer than
//! their radius. The contact law closes an overlap within one step, so the first step throws
//! such nodes out at up to depth / h (issue 11: a cloth 10 m below a plane was launched to
//! 1,480 m; a cloth folded exactly onto itself gained 48 % energy). A simulated state never
//! has them; a state set by `reset` (or a scene's rest shape) may, and is warned about.

use super::Simulator;
use crate::collision::HashScratch;

/// A pair counts as overlapping below this fraction of the self-contact radius: a simulated
/// state keeps pairs at the radius up to the solver tolerance, well inside 1 %.
pub const PAIR_OVERLAP_FRACTION: f64 = 0.99;

/// What [`Simulator::overlaps`] found.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Overlaps {
    /// Nodes inside an obstacle (negative signed distance at the current time).
    pub nodes_inside: usize,
    /// The deepest of them: `(node, obstacle, depth)`, depth in m below the surface.
    pub deepest: Option<(usize, usize, f64)>,
    /// Non-adjacent node pairs closer than `PAIR_OVERLAP_FRACTION` x the self-contact radius.
    pub close_pairs: usize,
    /// The closest of them: `(a, b, distance)` in m.
    pub closest_pair: Option<(usize, usize, f64)>,
    /// The self-contact radius (m; 0 without self-collision).
    pub radius: f64,
}

impl Overlaps {
    pub fn any(&self) -> bool {
        self.nodes_inside > 0 || self.close_pairs > 0
    }
}

impl Simulator {
    /// A warning for the user if the current state overlaps (see [`Simulator::overlaps`]):
    /// what, where, how deep, and the speed the first step will throw it out at.
    pub fn overlap_warning(&self) -> Option<String> {
        let found = self.overlaps();
        let h = self.model.params.h;
        let thickness = self.model.contact_settings.thickness;
        let mut parts = Vec::new();
        if let Some((node, obstacle, depth)) = found.deepest {
            parts.push(format!(
                "{} node(s) start inside an obstacle, the deepest (node {node}) {depth:.3e} m \
                 inside obstacle {obstacle}; the first step throws it out at {:.3e} m/s \
                 ((depth + thickness) / h)",
                found.nodes_inside,
                (depth + thickness) / h
            ));
        }
        if let Some((a, b, d)) = found.closest_pair {
            let coincident = if d == 0.0 {
                " (coincident: no separation direction, pushed apart along +y)"
            } else {
                ""
            };
            parts.push(format!(
                "{} self-contact pair(s) start closer than the contact radius {} m, the closest \
                 (nodes {a} and {b}) {d:.3e} m apart{coincident}; the first step pushes them \
                 apart at {:.3e} m/s ((radius - distance) / h)",
                found.close_pairs,
                found.radius,
                (found.radius - d) / h
            ));
        }
        (!parts.is_empty()).then(|| {
            format!(
                "{}: this adds kinetic energy the scene never had. Start the cloth outside the \
                 obstacles and its layers at least the self-contact radius apart.",
                parts.join("; ")
            )
        })
    }

    /// Nodes of the current state inside an obstacle, and self-contact pairs closer than the
    /// contact radius (only for the effects the scene has). Not for per-step use: it
    /// allocates the self-collision search's buffers.
    pub fn overlaps(&self) -> Overlaps {
        let mut found = Overlaps::default();
        if self.model.effects.obstacle_contact {
            for (o, obstacle) in self.model.obstacles.iter().enumerate() {
                for (j, p) in self.state.x.iter().enumerate() {
                    let depth = -obstacle.query(p, self.state.time).0;
                    if depth > 0.0 {
                        found.nodes_inside += 1;
                        if found.deepest.is_none_or(|(_, _, d)| depth > d) {
                            found.deepest = Some((j, o, depth));
                        }
                    }
                }
            }
        }
        if let Some(sc) = self.model.self_collision.as_ref() {
            found.radius = sc.radius;
            let mut pairs = Vec::new();
            let reach = PAIR_OVERLAP_FRACTION * sc.radius;
            sc.find_pairs(
                &self.state.x,
                reach,
                &mut HashScratch::default(),
                &mut pairs,
            );
            found.close_pairs = pairs.len();
            found.closest_pair = pairs.into_iter().min_by(|p, q| p.2.total_cmp(&q.2));
        }
        found
    }
}
