//! Contact detection for a step: candidates from the entering state (reach set by each
//! node's velocity), and the check for contacts the first detection missed (any node whose
//! motion over the step crossed an obstacle it had no contact with).

use super::Simulator;
use std::time::Instant;

impl Simulator {
    /// Finds this step's contact candidates from the entering state; with `with_motion`, each
    /// node's reach also covers the motion of the step just solved (in `mapped`). Reaches only
    /// grow over a step's re-detections, so every contact found before is found again and
    /// each re-detection covers at least the nodes whose crossing caused it.
    pub(super) fn detect_contacts(&mut self, with_motion: bool) {
        let detect_start = Instant::now();
        let h = self.model.params.h;
        let mut velocity = std::mem::take(&mut self.work.detect_velocity);
        if with_motion {
            for ((reach, x), xn) in velocity
                .iter_mut()
                .zip(&self.state.x)
                .zip(&self.work.mapped)
            {
                let moved = (xn - x) / h;
                if moved.norm() > reach.norm() {
                    *reach = moved;
                }
            }
        } else {
            velocity.clear();
            velocity.extend_from_slice(&self.state.v);
        }
        self.work.contacts.detect(
            &self.state.x,
            &velocity,
            &self.model.mass,
            self.state.time,
            h,
            &self.model.obstacles,
            self.model.self_collision.as_ref(),
            &self.model.contact_settings,
        );
        self.work.detect_velocity = velocity;
        self.profile.detection += detect_start.elapsed();
        self.prepare_response();
    }

    /// Whether the solved step (`mapped`) moved a node that has no contact with an obstacle
    /// into that obstacle's contact layer at any point of its motion: the straight path from
    /// `x_n` to `x_{n+1}` in the obstacle's frame (which moves from its placement at `t` to
    /// the one at `t + h`). End points alone miss a node that passes through in one step.
    /// Returns the first such `(node, obstacle)`.
    pub(super) fn missed_obstacle_contact(&mut self) -> Option<(usize, usize)> {
        let detect_start = Instant::now();
        let mut covered = std::mem::take(&mut self.work.covered);
        let mut missed = None;
        let (t, h) = (self.state.time, self.model.params.h);
        let layer = self.model.contact_settings.thickness;
        for (o, obstacle) in self.model.obstacles.iter().enumerate() {
            covered.clear();
            covered.resize(self.state.x.len(), false);
            for c in &self.work.contacts.contacts {
                if let crate::contact::ContactKind::Obstacle { node, obstacle } = c.kind {
                    if obstacle == o {
                        covered[node] = true;
                    }
                }
            }
            let (start, end, _) = obstacle.motion.over_step(t, h);
            missed = self
                .state
                .x
                .iter()
                .zip(&self.work.mapped)
                .zip(&covered)
                .position(|((a, b), &c)| {
                    !c && obstacle
                        .shape
                        .segment_within(&(a - start), &(b - end), layer)
                })
                .map(|node| (node, o));
            if missed.is_some() {
                break;
            }
        }
        self.work.covered = covered;
        self.profile.detection += detect_start.elapsed();
        missed
    }
}
