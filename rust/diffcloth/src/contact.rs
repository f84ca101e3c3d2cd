//! Dry frictional contact (Ly et al. 2020 as used by the paper, Eqns. 8-12).
//!
//! Contacts are detected once per step from the state entering it, with frames fixed during
//! the step. Each PD iteration then predicts every contact node's free velocity from the
//! splitting `P = M/h^2 + K` (paper Eqn. 12: the node's own inertia against the iterate's
//! internal forces), picks the Signorini-Coulomb branch per contact, and feeds the resulting
//! forces into the global solve. At a fixed point the prediction equals the solved velocity,
//! so the contact law holds exactly.

use crate::collision::{HashScratch, Obstacle, SelfCollision};
use crate::Vec3;
use faer::sparse::SparseColMat;

/// Which of the three Signorini-Coulomb cases holds (paper Eqn. 8).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Branch {
    /// Separating: no force.
    TakeOff,
    /// Inside the friction cone: the node moves with the obstacle.
    Stick,
    /// On the cone's boundary: sliding, friction opposing the tangential motion.
    Slip,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactKind {
    /// Node `node` against obstacle `obstacle`.
    Obstacle { node: usize, obstacle: usize },
    /// Nodes `a` and `b` of the cloth (the impulse acts on `a`, its opposite on `b`).
    SelfPair { a: usize, b: usize },
}

/// One contact of the current step, with everything its backward pass needs.
#[derive(Debug, Clone, Copy)]
pub struct Contact {
    pub kind: ContactKind,
    /// Unit normal at the state entering the step, pointing into free space (for a pair:
    /// from `b` to `a`).
    pub normal: Vec3,
    /// Distance the contact may still close this step: the signed distance minus the
    /// thickness (obstacle) or minus the radius (pair). Negative means penetrating.
    pub gap: f64,
    pub mu: f64,
    /// Obstacle velocity at the node (zero for pairs).
    pub obstacle_velocity: Vec3,
    /// Node mass, or the pair's reduced mass `m_a m_b / (m_a + m_b)`.
    pub mass: f64,
    pub branch: Branch,
    /// Impulse on the node (on `a` for a pair) over the step, N s.
    pub impulse: Vec3,
}

/// The per-contact law in momentum form. `d` is the free relative momentum
/// `m (v_free - v_obstacle)`, `n` the normal, `gap` the closable distance. The normal
/// velocity may not fall below `-gap / h` (gap-aware Signorini condition).
///
/// - take off: `d.n + m gap / h >= 0` -> `J = 0`;
/// - stick: `|d_T| <= mu lambda` with `lambda = -(d.n + m gap / h)` -> `J = lambda n - d_T`;
/// - slip: otherwise `J = lambda n - mu lambda d_T / |d_T|`.
pub fn signorini_coulomb(d: Vec3, n: Vec3, gap: f64, mass: f64, h: f64, mu: f64) -> (Branch, Vec3) {
    let dn = d.dot(&n);
    let closing = dn + mass * gap / h;
    if closing >= 0.0 {
        return (Branch::TakeOff, Vec3::zeros());
    }
    let lambda = -closing;
    let d_t = d - dn * n;
    let t = d_t.norm();
    if t <= mu * lambda {
        (Branch::Stick, lambda * n - d_t)
    } else {
        (Branch::Slip, lambda * n - (mu * lambda / t) * d_t)
    }
}

/// Contact settings of a scene.
#[derive(Debug, Clone)]
pub struct ContactSettings {
    /// Distance kept between a node and an obstacle surface (m).
    pub thickness: f64,
    pub response: crate::config::ContactResponse,
    /// Extra detection distance beyond what the step's motion can close (m).
    pub margin: f64,
    /// Friction on (else every mu is treated as 0).
    pub friction: bool,
}

/// Counts of the current contacts by branch.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BranchCounts {
    pub take_off: usize,
    pub stick: usize,
    pub slip: usize,
}

impl BranchCounts {
    pub fn total(&self) -> usize {
        self.take_off + self.stick + self.slip
    }
}

/// Sweeps of projected Gauss-Seidel per PD iteration at most, for nodes in several contacts.
const MAX_SWEEPS: usize = 50;

/// The contact set of the current step and the per-iteration solve.
#[derive(Default)]
pub struct ContactSet {
    pub contacts: Vec<Contact>,
    pairs: Vec<(usize, usize, f64)>,
    hash: HashScratch,
    /// Nodes in at least one contact (each once) and whether any is in several.
    nodes: Vec<usize>,
    shared_nodes: bool,
    /// Per node: contact count (detection) and velocity during the contact sweeps; sized to
    /// the mesh on first use.
    per_node_count: Vec<u32>,
    velocity: Vec<Vec3>,
}

impl ContactSet {
    pub fn is_empty(&self) -> bool {
        self.contacts.is_empty()
    }

    /// No contact exerts a force at the last solve (true without contacts).
    pub fn all_take_off(&self) -> bool {
        self.contacts.iter().all(|c| c.branch == Branch::TakeOff)
    }

    /// A contact node's velocity after the last [`ContactSet::solve`] (every impulse applied).
    pub(crate) fn solved_velocity(&self, node: usize) -> Vec3 {
        self.velocity[node]
    }

    pub fn counts(&self) -> BranchCounts {
        let mut c = BranchCounts::default();
        for k in &self.contacts {
            match k.branch {
                Branch::TakeOff => c.take_off += 1,
                Branch::Stick => c.stick += 1,
                Branch::Slip => c.slip += 1,
            }
        }
        c
    }

    /// Finds this step's contacts from the entering state `(x, v)` at time `t`. A candidate is
    /// anything the step's motion could bring into contact: within the contact distance plus
    /// the margin plus twice the distance the nodes' current velocity covers in one step
    /// (for a self-contact pair, their velocity relative to each other).
    #[allow(clippy::too_many_arguments)]
    pub fn detect(
        &mut self,
        x: &[Vec3],
        v: &[Vec3],
        mass: &[f64],
        t: f64,
        h: f64,
        obstacles: &[Obstacle],
        self_collision: Option<&SelfCollision>,
        settings: &ContactSettings,
    ) {
        self.contacts.clear();
        let friction = |mu: f64| if settings.friction { mu } else { 0.0 };
        for (o, obstacle) in obstacles.iter().enumerate() {
            // The obstacle's placement and velocity are evaluated once per step. Its reach
            // covers its travel over the step (a path may start moving inside the step).
            let (offset, end, velocity) = obstacle.motion.over_step(t, h);
            let travel = (h * velocity.norm()).max((end - offset).norm());
            let obstacle_reach = settings.thickness + settings.margin + 2.0 * travel;
            for (j, (p, vj)) in x.iter().zip(v).enumerate() {
                let reach = obstacle_reach + 2.0 * h * vj.norm();
                let contacts = &mut self.contacts;
                obstacle
                    .shape
                    .for_each_contact(&(p - offset), reach, |distance, normal| {
                        contacts.push(Contact {
                            kind: ContactKind::Obstacle {
                                node: j,
                                obstacle: o,
                            },
                            normal,
                            gap: distance - settings.thickness,
                            mu: friction(obstacle.mu),
                            obstacle_velocity: velocity,
                            mass: mass[j],
                            branch: Branch::TakeOff,
                            impulse: Vec3::zeros(),
                        });
                    });
            }
        }
        if let Some(sc) = self_collision {
            // A pair's distance changes with its relative velocity only, so the reach is
            // Galilean invariant: a cloth carried fast keeps the candidates of a cloth at rest.
            // Cells are sized for the fastest pair (|v_a - v_b| <= 2 max |v_i - v_mean|), each
            // pair then kept only within its own reach.
            let v_mean = v.iter().fold(Vec3::zeros(), |s, vi| s + vi) / v.len().max(1) as f64;
            let spread = v.iter().map(|vi| (vi - v_mean).norm()).fold(0.0, f64::max);
            let base = sc.radius + settings.margin;
            self.pairs.clear();
            sc.find_pairs(x, base + 4.0 * h * spread, &mut self.hash, &mut self.pairs);
            for &(a, b, distance) in &self.pairs {
                if distance >= base + 2.0 * h * (v[a] - v[b]).norm() {
                    continue;
                }
                let normal = if distance > 0.0 {
                    (x[a] - x[b]) / distance
                } else {
                    Vec3::y()
                };
                self.contacts.push(Contact {
                    kind: ContactKind::SelfPair { a, b },
                    normal,
                    gap: distance - sc.radius,
                    mu: friction(sc.mu),
                    obstacle_velocity: Vec3::zeros(),
                    mass: mass[a] * mass[b] / (mass[a] + mass[b]),
                    branch: Branch::TakeOff,
                    impulse: Vec3::zeros(),
                });
            }
        }
        self.index_nodes(x.len());
    }

    fn index_nodes(&mut self, n: usize) {
        if self.per_node_count.len() != n {
            self.per_node_count = vec![0; n];
            self.velocity = vec![Vec3::zeros(); n];
        }
        self.nodes.clear();
        let add = |j: usize, nodes: &mut Vec<usize>, count: &mut [u32]| {
            if count[j] == 0 {
                nodes.push(j);
            }
            count[j] += 1;
        };
        for c in &self.contacts {
            match c.kind {
                ContactKind::Obstacle { node, .. } => {
                    add(node, &mut self.nodes, &mut self.per_node_count)
                }
                ContactKind::SelfPair { a, b } => {
                    add(a, &mut self.nodes, &mut self.per_node_count);
                    add(b, &mut self.nodes, &mut self.per_node_count);
                }
            }
        }
        self.shared_nodes = self.nodes.iter().any(|&j| self.per_node_count[j] > 1);
        for &j in &self.nodes {
            self.per_node_count[j] = 0;
        }
    }

    /// One contact solve inside a PD iteration at the iterate `x`: `rhs` holds the global
    /// step's right-hand side without contact; on return it includes the contact forces
    /// `J / h`. `x_n` is the state entering the step, `system` the matrix `P_s`.
    ///
    /// A node in several contacts (an obstacle and self-contacts, or several self-contacts)
    /// is solved by projected Gauss-Seidel: each contact's law is applied given the other
    /// contacts' current impulses, warm-started from the previous iteration's, until the
    /// impulses stop changing. With one contact per node a single sweep is exact.
    pub fn solve(
        &mut self,
        x: &[Vec3],
        x_n: &[Vec3],
        mass: &[f64],
        h: f64,
        system: &SparseColMat<usize, f64>,
        rhs: &mut [Vec3],
    ) {
        let inv_h2 = 1.0 / (h * h);
        let m = system.as_ref();
        // Free velocity of each contact node from the splitting (paper Eqn. 12):
        // (m_j / h^2) x_j = rhs_j - (K x)_j with K = P_s - M / h^2.
        for &j in &self.nodes {
            let mut px = Vec3::zeros();
            for (i, &val) in m.row_idx_of_col(j).zip(m.val_of_col(j)) {
                px += val * x[i];
            }
            let kx = px - mass[j] * inv_h2 * x[j];
            let x_free = (rhs[j] - kx) * (h * h / mass[j]);
            self.velocity[j] = (x_free - x_n[j]) / h;
        }
        let velocity = &mut self.velocity;
        let apply = |c: &Contact, impulse: Vec3, velocity: &mut [Vec3]| match c.kind {
            ContactKind::Obstacle { node, .. } => velocity[node] += impulse / mass[node],
            ContactKind::SelfPair { a, b } => {
                velocity[a] += impulse / mass[a];
                velocity[b] -= impulse / mass[b];
            }
        };
        if self.shared_nodes {
            // Warm start: the previous iteration's impulses.
            for c in &self.contacts {
                apply(c, c.impulse, velocity);
            }
        } else {
            for c in &mut self.contacts {
                c.impulse = Vec3::zeros();
            }
        }
        let sweeps = if self.shared_nodes { MAX_SWEEPS } else { 1 };
        for _ in 0..sweeps {
            let mut change: f64 = 0.0;
            let mut scale: f64 = 0.0;
            for c in &mut self.contacts {
                let own = c.impulse;
                apply(c, -own, velocity);
                let relative = match c.kind {
                    ContactKind::Obstacle { node, .. } => velocity[node] - c.obstacle_velocity,
                    ContactKind::SelfPair { a, b } => velocity[a] - velocity[b],
                };
                (c.branch, c.impulse) =
                    signorini_coulomb(c.mass * relative, c.normal, c.gap, c.mass, h, c.mu);
                apply(c, c.impulse, velocity);
                change = change.max((c.impulse - own).amax());
                scale = scale.max(c.impulse.amax());
            }
            if change <= 1e-12 * scale {
                break;
            }
        }
        for c in &self.contacts {
            let force = c.impulse / h;
            match c.kind {
                ContactKind::Obstacle { node, .. } => rhs[node] += force,
                ContactKind::SelfPair { a, b } => {
                    rhs[a] += force;
                    rhs[b] -= force;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn branches_satisfy_the_signorini_coulomb_law() {
        let n = Vec3::y();
        let (m, h, mu) = (2.0, 0.01, 0.5);
        // Separating: no impulse.
        let (b, j) = signorini_coulomb(Vec3::new(1.0, 0.5, 0.0), n, 0.0, m, h, mu);
        assert_eq!((b, j), (Branch::TakeOff, Vec3::zeros()));
        // Approaching slowly from above a positive gap: still free.
        assert_eq!(
            signorini_coulomb(Vec3::new(0.0, -1.0, 0.0), n, 0.01, m, h, mu).0,
            Branch::TakeOff
        );
        // Inside the cone: the resulting relative velocity is zero (gap zero).
        let d = Vec3::new(0.3, -1.0, 0.1);
        let (b, j) = signorini_coulomb(d, n, 0.0, m, h, mu);
        assert_eq!(b, Branch::Stick);
        assert!((d + j).norm() < 1e-15);
        assert!(
            Vec3::new(j.x, 0.0, j.z).norm() <= mu * j.y + 1e-15,
            "force in the cone"
        );
        // Outside the cone: normal velocity zero, friction on the cone boundary, opposing.
        let d = Vec3::new(2.0, -1.0, 0.0);
        let (b, j) = signorini_coulomb(d, n, 0.0, m, h, mu);
        assert_eq!(b, Branch::Slip);
        let u = d + j;
        assert!(u.y.abs() < 1e-15);
        let jt = Vec3::new(j.x, 0.0, j.z);
        assert!((jt.norm() - mu * j.y).abs() < 1e-15);
        assert!(jt.dot(&u) < 0.0);
        // Gap-aware: a node 1 cm above may approach by exactly 1 cm this step.
        let (b, j) = signorini_coulomb(Vec3::new(0.0, -5.0, 0.0), n, 0.01, m, h, mu);
        assert_eq!(b, Branch::Stick);
        assert!(((Vec3::new(0.0, -5.0, 0.0) + j).y / m * h + 0.01).abs() < 1e-15);
    }
}
