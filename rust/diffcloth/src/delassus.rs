//! Contact response through the Delassus operator of the step's contact nodes.
//!
//! The inertia splitting of [`crate::contact::ContactSet::solve`] predicts each contact node as
//! if it moved alone with its mass. With stiff cloth at large steps (`k h^2 / m` >> 1) the
//! neighbours' response dominates instead, and the PD iteration's error on a sticking node
//! contracts only by `1 - m / (h^2 P_jj)` per iteration: the stiff sphere drop stalled with
//! nodes 0.16 m inside the obstacle. (Splitting off the full diagonal of `P` instead
//! diverges: that needs `diag(P) < 2 P`, and rigid translations have no stiffness.)
//!
//! Here the response is exact for the current local step instead. `P` and the contact set are
//! fixed during a step, so once per step the columns `G = P^{-1} C^T` of the contact nodes are
//! solved for and `W = C G` (scalar, the same for x, y and z) is kept. Every PD iteration
//! solves the contact law on `x = x^ + G r`, `x^ = P^{-1} rhs`, by projected Gauss-Seidel on
//! `W` (which converges for SPD `W`; it stops once a sweep moves no node by more than
//! [`SWEEP_FRACTION`] of the iteration's update), then applies `G r`. The fixed point is the
//! same as the inertia splitting's (the law holds for the solved velocities), so the adjoint,
//! which linearizes the inertia-split law at that point, is unchanged.

use crate::contact::{signorini_coulomb, Contact, ContactKind};
use crate::linalg::SpdFactor;
use crate::Vec3;

/// Gauss-Seidel sweeps over the contacts per PD iteration at most.
const MAX_SWEEPS: usize = 100;
/// The sweeps also stop once the last one moved no contact node by more than this fraction
/// of the PD iteration's last update (RMS): a contact solve far below the error of the
/// iterate it responds to only costs, and the outer iteration's stopping test still bounds
/// the step's error (at its fixed point a sweep moves nothing). On the Hat carried onto the
/// head (5 test starts, 400 steps) the sweeps had hit the cap in 93-99 % of calls; with
/// this, 2.3x less time per rollout at the same PD iterations (+4 %) and as many steps at
/// the iteration cap (35 vs 39 of 2000).
const SWEEP_FRACTION: f64 = 0.1;

/// The step's Delassus operator and the per-iteration contact solve on it.
#[derive(Default)]
pub struct Delassus {
    n: usize,
    /// Contact nodes (each once) and, per mesh node, its slot among them (`usize::MAX`: none).
    nodes: Vec<usize>,
    slot: Vec<usize>,
    /// Per contact: its node slots (`b` is `usize::MAX` for an obstacle contact).
    slots: Vec<(usize, usize)>,
    /// `G`, column k (n values) at `k * n`: the response of every node to a unit force on
    /// contact node k.
    columns: Vec<f64>,
    /// `W = C G`, c x c row-major, and its transpose (column-major `W`): a Gauss-Seidel
    /// update reads one column of `W` over every contact node, which the row-major copy
    /// strides through a cache line per entry (the Hat on the head: 68 % of a rollout's time
    /// in `respond`). `W` is symmetric only up to round-off, so the copy keeps the values.
    w: Vec<f64>,
    w_columns: Vec<f64>,
    /// Per contact node during the sweeps: position `x^ + W r` and total force `r`.
    x: Vec<Vec3>,
    force: Vec<Vec3>,
    /// Solve buffers (n rows each).
    rhs: Vec<Vec3>,
    out: Vec<Vec3>,
    work: Vec<Vec3>,
    /// The PD iteration's last update (RMS); infinite at a step's start, so that a step
    /// never depends on the steps before it.
    last_update: f64,
}

impl Delassus {
    /// Gives each distinct contact node a slot and returns their number (the operator's size),
    /// without allocating once warm. `build` starts with this; `auto` calls it alone to see
    /// whether a step is small enough to build for, so `respond` must not run before `build`.
    pub fn assign_nodes(&mut self, n: usize, contacts: &[Contact]) -> usize {
        if self.slot.len() != n {
            self.slot = vec![usize::MAX; n];
        }
        for &j in &self.nodes {
            self.slot[j] = usize::MAX;
        }
        self.nodes.clear();
        self.slots.clear();
        let mut slot_of = |j: usize, nodes: &mut Vec<usize>| {
            if self.slot[j] == usize::MAX {
                self.slot[j] = nodes.len();
                nodes.push(j);
            }
            self.slot[j]
        };
        for c in contacts {
            let s = match c.kind {
                ContactKind::Obstacle { node, .. } => (slot_of(node, &mut self.nodes), usize::MAX),
                ContactKind::SelfPair { a, b } => {
                    (slot_of(a, &mut self.nodes), slot_of(b, &mut self.nodes))
                }
            };
            self.slots.push(s);
        }
        self.nodes.len()
    }

    /// Forms `G` and `W` for this step's contacts: `ceil(c / 3)` solves with `P` (three unit
    /// columns per node-major solve, one per coordinate).
    pub fn build(&mut self, factor: &SpdFactor, contacts: &[Contact]) {
        let n = factor.dim();
        if self.rhs.len() != n {
            self.rhs = vec![Vec3::zeros(); n];
            self.out = vec![Vec3::zeros(); n];
            self.work = vec![Vec3::zeros(); n];
        }
        self.n = n;
        self.last_update = f64::INFINITY;
        self.assign_nodes(n, contacts);
        let c = self.nodes.len();
        self.columns.resize(c * n, 0.0);
        for (chunk, group) in self.nodes.chunks(3).enumerate() {
            self.rhs.iter_mut().for_each(|r| *r = Vec3::zeros());
            for (d, &j) in group.iter().enumerate() {
                self.rhs[j][d] = 1.0;
            }
            factor.solve_nodes_into(&self.rhs, &mut self.out, &mut self.work);
            for d in 0..group.len() {
                let column = &mut self.columns[(3 * chunk + d) * n..(3 * chunk + d + 1) * n];
                for (g, o) in column.iter_mut().zip(&self.out) {
                    *g = o[d];
                }
            }
        }
        self.w.resize(c * c, 0.0);
        self.w_columns.resize(c * c, 0.0);
        for k in 0..c {
            for l in 0..c {
                self.w[k * c + l] = self.columns[l * n + self.nodes[k]];
            }
        }
        for l in 0..c {
            let column = &self.columns[l * n..(l + 1) * n];
            for (w, &j) in self.w_columns[l * c..(l + 1) * c]
                .iter_mut()
                .zip(&self.nodes)
            {
                *w = column[j];
            }
        }
        self.x.resize(c, Vec3::zeros());
        self.force.resize(c, Vec3::zeros());
    }

    /// Notes the RMS update of the PD iteration `respond` just served (the next call's sweep
    /// tolerance).
    pub fn set_last_update(&mut self, update: f64) {
        self.last_update = update;
    }

    /// Given `x^ = P^{-1} rhs` in `mapped`, solves every contact's law for the positions
    /// `x^ + G r` and writes those into `mapped`. `x_n` is the state entering the step; the
    /// contacts' impulses (warm start and result) and branches are updated in place.
    pub fn respond(&mut self, mapped: &mut [Vec3], x_n: &[Vec3], h: f64, contacts: &mut [Contact]) {
        let (c, n) = (self.nodes.len(), self.n);
        debug_assert_eq!(
            self.w.len(),
            c * c,
            "respond on contact nodes not built for"
        );
        // Warm start: the previous iteration's impulses.
        self.force.iter_mut().for_each(|f| *f = Vec3::zeros());
        for (contact, &(a, b)) in contacts.iter().zip(&self.slots) {
            self.force[a] += contact.impulse / h;
            if b != usize::MAX {
                self.force[b] -= contact.impulse / h;
            }
        }
        for k in 0..c {
            let row = &self.w[k * c..(k + 1) * c];
            self.x[k] = mapped[self.nodes[k]]
                + row
                    .iter()
                    .zip(&self.force)
                    .map(|(w, f)| *w * f)
                    .sum::<Vec3>();
        }
        let h2 = h * h;
        let sweep_tolerance = SWEEP_FRACTION * self.last_update;
        for _ in 0..MAX_SWEEPS {
            let (mut change, mut scale, mut moved): (f64, f64, f64) = (0.0, 0.0, 0.0);
            for (i, contact) in contacts.iter_mut().enumerate() {
                let (a, b) = self.slots[i];
                let own = contact.impulse;
                let velocity = |k: usize| (self.x[k] - x_n[self.nodes[k]]) / h;
                let (relative, compliance) = if b == usize::MAX {
                    (velocity(a) - contact.obstacle_velocity, self.w[a * c + a])
                } else {
                    (
                        velocity(a) - velocity(b),
                        self.w[a * c + a] + self.w[b * c + b] - 2.0 * self.w[a * c + b],
                    )
                };
                // A unit impulse changes the relative velocity by compliance / h^2; the law
                // sees the velocity without this contact's own impulse.
                let mass = h2 / compliance;
                (contact.branch, contact.impulse) = signorini_coulomb(
                    mass * relative - own,
                    contact.normal,
                    contact.gap,
                    mass,
                    h,
                    contact.mu,
                );
                if contact.impulse != own {
                    self.push(a, b, (contact.impulse - own) / h);
                }
                let step = (contact.impulse - own).amax();
                change = change.max(step);
                scale = scale.max(contact.impulse.amax());
                // The force change step / h moves the contact's node(s) by compliance times it.
                moved = moved.max(compliance * step / h);
            }
            if change <= 1e-12 * scale || moved <= sweep_tolerance {
                break;
            }
        }
        for (k, f) in self.force.iter().enumerate() {
            if *f == Vec3::zeros() {
                continue;
            }
            let column = &self.columns[k * n..(k + 1) * n];
            for (m, g) in mapped.iter_mut().zip(column) {
                *m += *g * f;
            }
        }
    }

    /// Adds the force `df` on slot `a` (and `-df` on `b`, if any) to the contact nodes'
    /// positions and forces.
    fn push(&mut self, a: usize, b: usize, df: Vec3) {
        let c = self.nodes.len();
        let column = |k: usize| &self.w_columns[k * c..(k + 1) * c];
        if b == usize::MAX {
            for (x, &w) in self.x.iter_mut().zip(column(a)) {
                *x += w * df;
            }
        } else {
            for ((x, &wa), &wb) in self.x.iter_mut().zip(column(a)).zip(column(b)) {
                *x += (wa - wb) * df;
            }
        }
        self.force[a] += df;
        if b != usize::MAX {
            self.force[b] -= df;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::Branch;

    fn contact(kind: ContactKind) -> Contact {
        Contact {
            kind,
            normal: Vec3::y(),
            gap: 0.0,
            mu: 0.5,
            obstacle_velocity: Vec3::zeros(),
            mass: 1.0,
            branch: Branch::TakeOff,
            impulse: Vec3::zeros(),
        }
    }

    fn obstacle(node: usize) -> Contact {
        contact(ContactKind::Obstacle { node, obstacle: 0 })
    }

    fn pair(a: usize, b: usize) -> Contact {
        contact(ContactKind::SelfPair { a, b })
    }

    /// Each contact's slots name its own nodes, in the order the contacts list them.
    fn assert_slots_match(d: &Delassus, contacts: &[Contact]) {
        assert_eq!(d.slots.len(), contacts.len());
        for (c, &(a, b)) in contacts.iter().zip(&d.slots) {
            match c.kind {
                ContactKind::Obstacle { node, .. } => {
                    assert_eq!((d.nodes[a], b), (node, usize::MAX));
                }
                ContactKind::SelfPair { a: na, b: nb } => {
                    assert_eq!((d.nodes[a], d.nodes[b]), (na, nb));
                }
            }
        }
    }

    #[test]
    fn assign_nodes_counts_each_contact_node_once_and_forgets_the_last_step() {
        let mut d = Delassus::default();
        // Node 3 in three contacts, 5 in two, 7 in one: two obstacles and two pairs.
        let step = [obstacle(3), pair(3, 5), obstacle(5), pair(7, 3)];
        assert_eq!(d.assign_nodes(10, &step), 3);
        assert_eq!(d.nodes, [3, 5, 7]);
        assert_slots_match(&d, &step);
        // The next step's contacts share only node 5: the old slots must not leak into it.
        let next = [pair(5, 9), obstacle(0), obstacle(9)];
        assert_eq!(d.assign_nodes(10, &next), 3);
        assert_eq!(d.nodes, [5, 9, 0]);
        assert_slots_match(&d, &next);
        assert_eq!(d.slot.iter().filter(|&&s| s != usize::MAX).count(), 3);
        assert_eq!(d.assign_nodes(10, &[]), 0);
        assert!(d.slot.iter().all(|&s| s == usize::MAX));
    }
}
