//! Active contacts linearized at a converged step (paper Sec. 4.2), and the coupling of
//! contacts that share nodes (solved jointly in the forward pass).

use crate::contact::{Branch, ContactKind};
use crate::error::{Error, Result};
use crate::forward::Simulator;
use crate::tape::StepRecord;
use crate::Vec3;
use nalgebra::Matrix3;

/// One active contact linearized at the converged step (paper Sec. 4.2, Eqns. 19-28, in
/// momentum form). The contact's free momentum is `d = sum_k s_k D_k - m v_obs` with
/// `D = M v_n + h f + h (b(x) - K x)` per node, its impulse `J = Phi(d; n, gap, mu)` acts as
/// the force `e_k J / h` on its nodes, so `dR/dx = sum_c E_c Phi' S_c (dP - K)`.
pub(crate) struct ContactLin {
    /// `(node, s_k)`: how the nodes' momenta combine into d.
    pub(crate) s: Vec<(usize, f64)>,
    /// `(node, e_k)`: where the impulse acts (+1 on the node / on a, -1 on b).
    pub(crate) e: Vec<(usize, f64)>,
    /// `dJ/dd`.
    pub(crate) phi: Matrix3<f64>,
    /// `dJ/dlambda` with `lambda = -(d.n + m gap / h)` the normal impulse.
    pub(super) dj_dlambda: Vec3,
    /// `dJ/dn` (the frame's dependence on x_n) and `dJ/dmu`.
    pub(super) dj_dn: Matrix3<f64>,
    pub(super) dj_dmu: Vec3,
    /// Per node of the frame: `(node, d gap/dx, dn/dx)`.
    pub(super) frame: Vec<(usize, Vec3, Matrix3<f64>)>,
    pub(super) mass: f64,
    pub(super) gap: f64,
    pub(super) obstacle: Option<usize>,
    pub(super) obstacle_velocity: Vec3,
    /// The branch and the contact normal (what the law pins: `pinned_directions`).
    pub(crate) branch: Branch,
    pub(crate) normal: Vec3,
}

impl ContactLin {
    /// `E^T v / h`: the adjoint of the contact force.
    pub(super) fn impulse_adjoint(&self, v: &[Vec3], h: f64) -> Vec3 {
        self.e.iter().map(|&(k, e)| e * v[k]).sum::<Vec3>() / h
    }
}

/// Linearizes every active contact of a recorded step at its converged state.
pub(super) fn linearize_contacts(sim: &Simulator, rec: &StepRecord) -> Result<Vec<ContactLin>> {
    let h = sim.params().h;
    let velocity = |k: usize| (rec.x_next[k] - rec.x_prev[k]) / h;
    linearize_contacts_at(sim, &rec.x_prev, rec.time, &rec.contacts, velocity)
}

/// Linearizes the active `contacts` of a step entering at `x_prev` (time `time`), given each
/// contact node's velocity after the contact solve (all impulses applied). At a converged
/// step that is the step's velocity; the forward's contact Newton (`forward/contact_newton.rs`)
/// passes the splitting's velocities at an iterate.
pub(crate) fn linearize_contacts_at(
    sim: &Simulator,
    x_prev: &[Vec3],
    time: f64,
    contacts: &[crate::contact::Contact],
    velocity: impl Fn(usize) -> Vec3,
) -> Result<Vec<ContactLin>> {
    let h = sim.params().h;
    let mass = sim.masses();
    let mut out = Vec::new();
    for c in contacts.iter().filter(|c| c.branch != Branch::TakeOff) {
        let (s, e, frame, relative, obstacle) = match c.kind {
            ContactKind::Obstacle { node, obstacle } => {
                let o = &sim.obstacles()[obstacle];
                let (offset, _) = o.motion.at(time);
                let jac = o
                    .shape
                    .normal_jacobian_of(&(x_prev[node] - offset), &c.normal);
                (
                    vec![(node, 1.0)],
                    vec![(node, 1.0)],
                    vec![(node, c.normal, jac)],
                    velocity(node) - c.obstacle_velocity,
                    Some(obstacle),
                )
            }
            ContactKind::SelfPair { a, b } => {
                let dist = (x_prev[a] - x_prev[b]).norm();
                let jac = (Matrix3::identity() - c.normal * c.normal.transpose())
                    / dist.max(f64::MIN_POSITIVE);
                (
                    vec![(a, c.mass / mass[a]), (b, -c.mass / mass[b])],
                    vec![(a, 1.0), (b, -1.0)],
                    vec![(a, c.normal, jac), (b, -c.normal, -jac)],
                    velocity(a) - velocity(b),
                    None,
                )
            }
        };
        // The converged momentum balance m u = d + J gives back the free momentum d.
        let (n, m, mu) = (c.normal, c.mass, c.mu);
        let d = m * relative - c.impulse;
        let lambda = -(d.dot(&n) + m * c.gap / h);
        let (phi, dj_dlambda, dj_dn, dj_dmu) = match c.branch {
            Branch::Stick => (
                -Matrix3::identity(),
                n,
                -(m * c.gap / h) * Matrix3::identity(),
                Vec3::zeros(),
            ),
            Branch::Slip => {
                let d_t = d - d.dot(&n) * n;
                let t = d_t.norm().max(f64::MIN_POSITIVE);
                let a = d_t / t;
                let proj_a = Matrix3::identity() - a * a.transpose();
                let proj_n = Matrix3::identity() - n * n.transpose();
                let phi = -n * n.transpose() + mu * a * n.transpose()
                    - (mu * lambda / t) * proj_a * proj_n;
                let da_dn = proj_a * (-(n * d.transpose()) - d.dot(&n) * Matrix3::identity()) / t;
                let dj_dn =
                    (n - mu * a) * (-d.transpose()) + lambda * (Matrix3::identity() - mu * da_dn);
                (phi, n - mu * a, dj_dn, -lambda * a)
            }
            Branch::TakeOff => unreachable!("filtered above"),
        };
        out.push(ContactLin {
            s,
            e,
            phi,
            dj_dlambda,
            dj_dn,
            dj_dmu,
            frame,
            mass: m,
            gap: c.gap,
            obstacle,
            obstacle_velocity: c.obstacle_velocity,
            branch: c.branch,
            normal: n,
        });
    }
    Ok(out)
}

/// The directions the contact law pins at a step, as `(node, projector, m / h^2)` into `out`:
/// every direction of a node sticking to an obstacle, the normal of one slipping, for nodes in
/// exactly one active contact (`per_node`: scratch, one zero per node, left zeroed). There the
/// row of `dF = H - dR` is `m / h^2` times the projector, so a preconditioner can solve those
/// directions exactly (the forward's contact Newton and the adjoint's factored solve). Nodes
/// in several contacts, and cloth pairs, are left to the Krylov solver.
pub(crate) fn pinned_directions(
    contacts: &[ContactLin],
    mass: &[f64],
    h: f64,
    per_node: &mut [u32],
    out: &mut Vec<(usize, Matrix3<f64>, f64)>,
) {
    for c in contacts {
        for &(k, _) in &c.e {
            per_node[k] += if c.obstacle.is_some() { 1 } else { 2 };
        }
    }
    out.clear();
    for c in contacts.iter().filter(|c| c.obstacle.is_some()) {
        let node = c.e[0].0;
        if per_node[node] == 1 {
            let pi = match c.branch {
                Branch::Stick => Matrix3::identity(),
                _ => c.normal * c.normal.transpose(),
            };
            out.push((node, pi, mass[node] / (h * h)));
        }
    }
    for c in contacts {
        for &(k, _) in &c.e {
            per_node[k] = 0;
        }
    }
}

/// Contacts that share nodes are solved jointly by projected Gauss-Seidel in the forward pass:
/// each contact's law sees the others' impulses, `d_c = S_c D + sum_{c'} T_cc' J_c' - m v_obs`
/// with `T_cc' = sum_{k in c and c'} s_ck e_c'k`. Linearized, `dJ = (I - B T)^{-1} B S dD` with
/// `B = diag(Phi'_c)`, so the adjoint of the impulses is `y = (I - T^T B^T)^{-1} zhat`, solved
/// per group of coupled contacts (a dense inverse per group, formed once per step).
///
/// A closed loop of sticking contacts (two nodes each stuck to the floor and to each other)
/// is redundant: the impulses are not unique, only their sum on each node is, and
/// `I - T^T B^T` is singular. Its adjoint system is consistent (the loss sees only the nodes'
/// motion), so the minimum-norm solution, from the pseudo-inverse, gives the unique `u`.
#[derive(Default)]
pub(crate) struct ContactCoupling {
    pub(crate) groups: Vec<(Vec<usize>, nalgebra::DMatrix<f64>)>,
}

/// Singular values below this fraction of the largest are treated as zero (redundant loops).
pub(super) const COUPLING_RANK_TOLERANCE: f64 = 1e-10;

impl ContactCoupling {
    pub(crate) fn new(contacts: &[ContactLin], nodes: usize) -> Result<Self> {
        let mut touching: Vec<Vec<usize>> = vec![Vec::new(); nodes];
        for (c, lin) in contacts.iter().enumerate() {
            for &(k, _) in &lin.e {
                touching[k].push(c);
            }
        }
        // Groups: connected components of contacts through shared nodes (union-find).
        let mut parent: Vec<usize> = (0..contacts.len()).collect();
        fn root(p: &mut [usize], mut i: usize) -> usize {
            while p[i] != i {
                p[i] = p[p[i]];
                i = p[i];
            }
            i
        }
        for list in &touching {
            for w in list.windows(2) {
                let (a, b) = (root(&mut parent, w[0]), root(&mut parent, w[1]));
                parent[a] = b;
            }
        }
        let mut members: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
        for c in 0..contacts.len() {
            let r = root(&mut parent, c);
            members.entry(r).or_default().push(c);
        }
        let mut groups = Vec::new();
        for (_, group) in members.into_iter().filter(|(_, g)| g.len() > 1) {
            let size = 3 * group.len();
            let mut m = nalgebra::DMatrix::<f64>::identity(size, size);
            for (bi, &c) in group.iter().enumerate() {
                for (bj, &cp) in group.iter().enumerate() {
                    if c == cp {
                        continue;
                    }
                    // Block (c, c') = -T_{c'c} Phi'_{c'}^T.
                    let t: f64 = contacts[cp]
                        .s
                        .iter()
                        .filter_map(|&(k, s)| {
                            contacts[c]
                                .e
                                .iter()
                                .find(|&&(kk, _)| kk == k)
                                .map(|&(_, e)| s * e)
                        })
                        .sum();
                    if t != 0.0 {
                        let block = -t * contacts[cp].phi.transpose();
                        for r in 0..3 {
                            for q in 0..3 {
                                m[(3 * bi + r, 3 * bj + q)] += block[(r, q)];
                            }
                        }
                    }
                }
            }
            let svd = m.svd(true, true);
            let largest = svd.singular_values.max();
            let inverse = svd
                .pseudo_inverse(COUPLING_RANK_TOLERANCE * largest)
                .map_err(|e| Error::Solver(format!("coupled contact linearization: {e}")))?;
            groups.push((group, inverse));
        }
        Ok(Self { groups })
    }

    /// Every group (singletons included) with its `(I - T^T B^T)^{-1}`, for the assembly.
    pub(super) fn inverse_groups(
        &self,
        contacts: usize,
    ) -> Vec<(Vec<usize>, nalgebra::DMatrix<f64>)> {
        let mut grouped = vec![false; contacts];
        let mut out: Vec<(Vec<usize>, nalgebra::DMatrix<f64>)> = Vec::new();
        for (group, inverse) in &self.groups {
            for &c in group {
                grouped[c] = true;
            }
            out.push((group.clone(), inverse.clone()));
        }
        out.extend(
            (0..contacts)
                .filter(|&c| !grouped[c])
                .map(|c| (vec![c], nalgebra::DMatrix::identity(3, 3))),
        );
        out
    }

    /// Replaces each contact's impulse adjoint `zhat_c` by `y_c`.
    pub(super) fn solve(&self, zhat: &mut [Vec3]) {
        for (group, inverse) in &self.groups {
            let mut rhs = nalgebra::DVector::<f64>::zeros(3 * group.len());
            for (b, &c) in group.iter().enumerate() {
                for r in 0..3 {
                    rhs[3 * b + r] = zhat[c][r];
                }
            }
            let y = inverse * rhs;
            for (b, &c) in group.iter().enumerate() {
                zhat[c] = Vec3::new(y[3 * b], y[3 * b + 1], y[3 * b + 2]);
            }
        }
    }
}
