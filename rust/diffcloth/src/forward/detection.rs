//! Contact detection for a step: candidates from the entering state (reach set by each
//! node's velocity), the Delassus operator when that response is chosen, and the check for
//! contacts the first detection missed.

use super::Simulator;
use crate::config::ContactResponse;
use std::time::Instant;

impl Simulator {
    /// Finds this step's contact candidates from the entering state; with `with_motion`, each
    /// node's reach also covers the motion of the step just solved (in `mapped`).
    pub(super) fn detect_contacts(&mut self, with_motion: bool) {
        let detect_start = Instant::now();
        let h = self.model.params.h;
        let mut velocity = std::mem::take(&mut self.work.detect_velocity);
        velocity.clear();
        velocity.extend(
            self.state
                .v
                .iter()
                .zip(&self.state.x)
                .zip(&self.work.mapped)
                .map(|((v, x), xn)| {
                    let moved = (xn - x) / h;
                    if with_motion && moved.norm() > v.norm() {
                        moved
                    } else {
                        *v
                    }
                }),
        );
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
        if self.delassus_response() {
            let start = Instant::now();
            self.work
                .delassus
                .build(&self.model.factor, &self.work.contacts.contacts);
            self.profile.contact_solve += start.elapsed();
            self.profile.delassus_builds += 1;
        }
    }

    /// Whether this step's contacts respond through the Delassus operator.
    pub(super) fn delassus_response(&self) -> bool {
        !self.work.contacts.is_empty()
            && self.model.contact_settings.response == ContactResponse::Delassus
    }

    /// Whether the solved step (`mapped`) put a node that has no contact with an obstacle
    /// inside that obstacle's contact layer.
    pub(super) fn missed_obstacle_contact(&mut self) -> bool {
        let detect_start = Instant::now();
        let mut covered = std::mem::take(&mut self.work.covered);
        let mut missed = false;
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
            let (offset, _) = obstacle.motion.at(self.state.time + self.model.params.h);
            let layer = self.model.contact_settings.thickness;
            missed |= self
                .work
                .mapped
                .iter()
                .zip(&covered)
                .any(|(p, &c)| !c && obstacle.shape.distance(&(p - offset)).0 < layer);
            if missed {
                break;
            }
        }
        self.work.covered = covered;
        self.profile.detection += detect_start.elapsed();
        missed
    }
}
