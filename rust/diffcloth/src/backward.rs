//! Adjoint of the recorded steps (paper Sec. 4, Eqns. 13-30), contact included (Sec. 4.2).
//!
//! Step n solves `g(x_{n+1}) = M (x_{n+1} - y) / h^2 + grad W(x_{n+1}) = 0` with
//! `y = x_n + h v_n + h^2 M^{-1} f` and `v_{n+1} = (x_{n+1} - x_n) / h`. Its Jacobian is
//! `H = P - dP`, `dP = sum_i w_i A_i^T (dp_i/d(A_i x)) A_i` (paper Eqn. 29 with dR = 0), and
//! the adjoint `z` solves `H z = dL/dx_{n+1} + dL/dv_{n+1} / h`. Then
//! `dL/dx_n = M z / h^2 - dL/dv_{n+1} / h`, `dL/dv_n = M z / h`, `dL/df_n = z`, and every
//! parameter theta gets `-z . dg/dtheta`.

use crate::contact::{Branch, ContactKind};
use crate::energy::Stiffness;
use crate::error::{Error, Result};
use crate::forward::Simulator;
use crate::linalg::SpdFactor;
use crate::tape::{StepRecord, Tape};
use crate::Vec3;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::matrix_free::bicgstab::{bicgstab, bicgstab_scratch, BicgParams};
use faer::matrix_free::{IdentityPrecond, InitialGuessStatus, LinOp, Precond};
use faer::prelude::*;
use faer::reborrow::ReborrowMut;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, MatMut, MatRef, Par};
use nalgebra::Matrix3;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How the adjoint system `H z = g` is solved (selectable per call).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdjointSolver {
    /// Sparse LU of the assembled `H` (the reference).
    Direct,
    /// Preconditioned by the PD factorization of `P` (the default): conjugate gradients when
    /// `H` is symmetric (no active contact), else BiCGStab.
    Krylov,
    /// The paper's Eqn. 30: `P z_{k+1} = dP z_k + g`, reusing the PD factorization.
    FixedPoint,
}

#[derive(Debug, Clone)]
pub struct BackwardOptions {
    pub solver: AdjointSolver,
    /// Relative residual `|g - H z| / |g|` at which an iterative solve stops.
    pub tolerance: f64,
    /// Iteration cap of the iterative solvers (then: fall back to `Direct`).
    pub max_iterations: usize,
}

impl Default for BackwardOptions {
    fn default() -> Self {
        Self {
            solver: AdjointSolver::Krylov,
            tolerance: 1e-10,
            max_iterations: 500,
        }
    }
}

/// What the adjoint solve of one step did.
#[derive(Debug, Clone, Copy, Default)]
pub struct AdjointStepStats {
    /// Iterations of the iterative solver, also when it then fell back (the cap when a
    /// Krylov solve stopped there).
    pub iterations: usize,
    /// The iterative solver stalled or diverged and the direct solve was used.
    pub fell_back: bool,
    /// Final relative residual.
    pub residual: f64,
}

/// How an iterative adjoint solve ended.
#[derive(Debug, Clone, Copy)]
struct Attempt {
    iterations: usize,
    converged: bool,
}

impl Attempt {
    fn converged(iterations: usize) -> Self {
        Self {
            iterations,
            converged: true,
        }
    }
    fn failed(iterations: usize) -> Self {
        Self {
            iterations,
            converged: false,
        }
    }
}

/// Time per backward stage (the columns of the paper's Table 1).
#[derive(Debug, Clone, Copy, Default)]
pub struct BackwardProfile {
    /// Projection Jacobians (dP).
    pub dp: Duration,
    /// Contact linearization (dR).
    pub dr: Duration,
    pub solve: Duration,
    pub other: Duration,
}

/// Gradients of the loss with respect to everything the rollout depends on.
#[derive(Debug, Clone, Default)]
pub struct Gradients {
    pub x0: Vec<Vec3>,
    pub v0: Vec<Vec3>,
    /// Per recorded step: attachment targets (the actions) and external forces.
    pub attachment_targets: Vec<Vec<Vec3>>,
    pub external_forces: Vec<Vec<Vec3>>,
    pub k_stretch: f64,
    pub k_bend: f64,
    pub k_attach: f64,
    pub density: f64,
    pub gravity: Vec3,
    pub wind_direction: Vec3,
    pub wind_omega: f64,
    pub wind_phi: f64,
    /// Friction coefficient of each obstacle, and of self-contact.
    pub mu_obstacles: Vec<f64>,
    pub mu_self: f64,
    pub steps: Vec<AdjointStepStats>,
    pub profile: BackwardProfile,
    /// Why these gradients may be untrustworthy (empty when there is no known reason).
    pub warnings: Vec<String>,
    /// Recorded steps whose forward residual was above [`TRUSTED_FORWARD_RESIDUAL`].
    pub loose_steps: Vec<(usize, f64)>,
}

/// Where a segment's backward pass continues from (checkpointed tapes).
struct Resume {
    grads: Gradients,
    carry_x: Vec<Vec3>,
    carry_v: Vec<Vec3>,
    /// The last two adjoints, the warm start of the next solve.
    z: Vec<Vec3>,
    z_previous: Option<Vec<Vec3>>,
}

/// Recorded steps whose PD residual is above this are flagged: the adjoint assumes the step is
/// the converged implicit-Euler solution (measured on the Hat, 400 steps: 1e-8 gives 29 % error
/// in the target gradients, 1e-10 gives 0.02 %).
pub const TRUSTED_FORWARD_RESIDUAL: f64 = 1e-9;

/// The linearization of one step at its end state: each constraint set's weighted projection
/// Jacobians, in the set's own layout (see [`PdConstraints::linearize`]).
struct Linearization {
    per_set: Vec<Vec<f64>>,
}

impl Linearization {
    fn new(sim: &Simulator) -> Self {
        Self {
            per_set: sim
                .constraint_sets()
                .map(|c| vec![0.0; c.linearization_len()])
                .collect(),
        }
    }

    fn update(&mut self, sim: &Simulator, x: &[Vec3]) {
        for (c, lin) in sim.constraint_sets().zip(&mut self.per_set) {
            c.linearize(x, lin);
        }
    }

    /// `out -= dP v`, constraint by constraint (never assembled for the iterative solvers).
    fn sub_dp(&self, sim: &Simulator, v: &[Vec3], out: &mut [Vec3]) {
        for (c, lin) in sim.constraint_sets().zip(&self.per_set) {
            c.sub_dp(lin, v, out);
        }
    }

    /// Triplets of `H = P_s (x) I_3 - dP` (3m x 3m) for the direct solver.
    fn assemble(
        &self,
        sim: &Simulator,
        p: &SparseColMat<usize, f64>,
    ) -> Vec<Triplet<usize, usize, f64>> {
        let mut t = Vec::new();
        let pr = p.as_ref();
        for col in 0..pr.ncols() {
            for (row, &val) in pr.row_idx_of_col(col).zip(pr.val_of_col(col)) {
                for d in 0..3 {
                    t.push(Triplet::new(3 * row + d, 3 * col + d, val));
                }
            }
        }
        let mut neg_dp = Vec::new();
        for (c, lin) in sim.constraint_sets().zip(&self.per_set) {
            c.add_neg_dp_triplets(lin, &mut neg_dp);
        }
        t.extend(neg_dp.into_iter().map(|(r, c, v)| Triplet::new(r, c, v)));
        t
    }
}

/// One active contact linearized at the converged step (paper Sec. 4.2, Eqns. 19-28, in
/// momentum form). The contact's free momentum is `d = sum_k s_k D_k - m v_obs` with
/// `D = M v_n + h f + h (b(x) - K x)` per node, its impulse `J = Phi(d; n, gap, mu)` acts as
/// the force `e_k J / h` on its nodes, so `dR/dx = sum_c E_c Phi' S_c (dP - K)`.
struct ContactLin {
    /// `(node, s_k)`: how the nodes' momenta combine into d.
    s: Vec<(usize, f64)>,
    /// `(node, e_k)`: where the impulse acts (+1 on the node / on a, -1 on b).
    e: Vec<(usize, f64)>,
    /// `dJ/dd`.
    phi: Matrix3<f64>,
    /// `dJ/dlambda` with `lambda = -(d.n + m gap / h)` the normal impulse.
    dj_dlambda: Vec3,
    /// `dJ/dn` (the frame's dependence on x_n) and `dJ/dmu`.
    dj_dn: Matrix3<f64>,
    dj_dmu: Vec3,
    /// Per node of the frame: `(node, d gap/dx, dn/dx)`.
    frame: Vec<(usize, Vec3, Matrix3<f64>)>,
    mass: f64,
    gap: f64,
    obstacle: Option<usize>,
    obstacle_velocity: Vec3,
}

impl ContactLin {
    /// `E^T v / h`: the adjoint of the contact force.
    fn impulse_adjoint(&self, v: &[Vec3], h: f64) -> Vec3 {
        self.e.iter().map(|&(k, e)| e * v[k]).sum::<Vec3>() / h
    }
}

/// Linearizes every active contact of a recorded step at its converged state.
fn linearize_contacts(sim: &Simulator, rec: &StepRecord) -> Result<Vec<ContactLin>> {
    let h = sim.params().h;
    let mass = sim.masses();
    let mut out = Vec::new();
    for c in rec.contacts.iter().filter(|c| c.branch != Branch::TakeOff) {
        let velocity = |k: usize| (rec.x_next[k] - rec.x_prev[k]) / h;
        let (s, e, frame, relative, obstacle) = match c.kind {
            ContactKind::Obstacle { node, obstacle } => {
                let o = &sim.obstacles()[obstacle];
                let (offset, _) = o.motion.at(rec.time);
                let jac = o
                    .shape
                    .normal_jacobian_of(&(rec.x_prev[node] - offset), &c.normal);
                (
                    vec![(node, 1.0)],
                    vec![(node, 1.0)],
                    vec![(node, c.normal, jac)],
                    velocity(node) - c.obstacle_velocity,
                    Some(obstacle),
                )
            }
            ContactKind::SelfPair { a, b } => {
                let dist = (rec.x_prev[a] - rec.x_prev[b]).norm();
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
        });
    }
    Ok(out)
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
struct ContactCoupling {
    groups: Vec<(Vec<usize>, nalgebra::DMatrix<f64>)>,
}

/// Singular values below this fraction of the largest are treated as zero (redundant loops).
const COUPLING_RANK_TOLERANCE: f64 = 1e-10;

impl ContactCoupling {
    fn new(contacts: &[ContactLin], nodes: usize) -> Result<Self> {
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
    fn inverse_groups(&self, contacts: usize) -> Vec<(Vec<usize>, nalgebra::DMatrix<f64>)> {
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
    fn solve(&self, zhat: &mut [Vec3]) {
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

/// `H` as a faer linear operator on node-major 3m vectors.
struct AdjointOperator<'a> {
    sim: &'a Simulator,
    lin: Linearization,
    contacts: Vec<ContactLin>,
    coupling: ContactCoupling,
    /// Scratch of the contact term (kept across applications: no allocation per iteration).
    contact_scratch: Mutex<ContactScratch>,
}

#[derive(Default)]
struct ContactScratch {
    /// Per contact: the impulse adjoints.
    y: Vec<Vec3>,
    /// Per node: `u`, `-dP u` and `P u`.
    u: Vec<Vec3>,
    t: Vec<Vec3>,
    pu: Vec<Vec3>,
}

impl std::fmt::Debug for AdjointOperator<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("AdjointOperator")
    }
}

impl AdjointOperator<'_> {
    /// `out = H^T v` with `H^T = P - dP - (dP - K) sum_c S_c^T Phi_c'^T E_c^T` (the adjoint
    /// system is transposed: contact makes H non-symmetric).
    fn apply_nodes(&self, v: &[Vec3], out: &mut [Vec3]) {
        self.sim.factor().mul_xyz(v, out);
        self.lin.sub_dp(self.sim, v, out);
        if self.contacts.is_empty() {
            return;
        }
        let n = v.len();
        let h = self.sim.params().h;
        let mut guard = self.contact_scratch.lock().expect("contact scratch");
        let ContactScratch { y, u, t, pu } = &mut *guard;
        y.clear();
        y.extend(self.contacts.iter().map(|c| c.impulse_adjoint(v, h) * h));
        self.coupling.solve(y);
        u.clear();
        u.resize(n, Vec3::zeros());
        for (c, yc) in self.contacts.iter().zip(y.iter()) {
            let w = c.phi.transpose() * yc;
            for &(k, s) in &c.s {
                u[k] += s * w;
            }
        }
        // out -= (dP - K) u, with K u = P u - M u / h^2.
        t.clear();
        t.resize(n, Vec3::zeros());
        self.lin.sub_dp(self.sim, u, t); // t = -dP u
        pu.resize(n, Vec3::zeros());
        self.sim.factor().mul_xyz(u, pu);
        let mass = self.sim.masses();
        for i in 0..n {
            let ku = pu[i] - mass[i] / (h * h) * u[i];
            // (dP - K) u = -t - K u
            out[i] += t[i] + ku;
        }
    }
}

// A node-major 3m column and a slice of `Vec3` share one layout: nalgebra's `Vector3<f64>` is
// `repr(C)` over `[f64; 3]`. Viewing in place avoids two copies per Krylov iteration.
const _: () = assert!(std::mem::size_of::<Vec3>() == 24 && std::mem::align_of::<Vec3>() == 8);

fn col_as_nodes(c: faer::ColRef<'_, f64>) -> Option<&[Vec3]> {
    let s = c.try_as_col_major()?.as_slice();
    // SAFETY: same size and alignment (checked above); the length is a multiple of 3.
    (s.len() % 3 == 0)
        .then(|| unsafe { std::slice::from_raw_parts(s.as_ptr() as *const Vec3, s.len() / 3) })
}

fn col_as_nodes_mut(c: faer::ColMut<'_, f64>) -> Option<&mut [Vec3]> {
    let s = c.try_as_col_major_mut()?.as_slice_mut();
    // SAFETY: as in `col_as_nodes`; the mutable borrow is unique.
    (s.len() % 3 == 0).then(|| unsafe {
        std::slice::from_raw_parts_mut(s.as_mut_ptr() as *mut Vec3, s.len() / 3)
    })
}

/// Applies the node-major map `f(input, output)` to every column of `rhs`: in place on
/// contiguous columns (what faer's solvers pass), through node copies otherwise.
fn apply_per_column(
    mut out: MatMut<'_, f64>,
    rhs: MatRef<'_, f64>,
    mut f: impl FnMut(&[Vec3], &mut [Vec3]),
) {
    let n = rhs.nrows() / 3;
    for k in 0..rhs.ncols() {
        if let (Some(v), Some(o)) = (
            col_as_nodes(rhs.col(k)),
            col_as_nodes_mut(out.rb_mut().col_mut(k)),
        ) {
            f(v, o);
            continue;
        }
        let v: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new(rhs[(3 * i, k)], rhs[(3 * i + 1, k)], rhs[(3 * i + 2, k)]))
            .collect();
        let mut o = vec![Vec3::zeros(); n];
        f(&v, &mut o);
        for (i, x) in o.iter().enumerate() {
            for d in 0..3 {
                out[(3 * i + d, k)] = x[d];
            }
        }
    }
}

impl LinOp<f64> for AdjointOperator<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }
    fn nrows(&self) -> usize {
        3 * self.sim.num_nodes()
    }
    fn ncols(&self) -> usize {
        3 * self.sim.num_nodes()
    }
    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _stack: &mut MemStack) {
        apply_per_column(out, rhs, |v, o| self.apply_nodes(v, o));
    }
    fn conj_apply(
        &self,
        out: MatMut<'_, f64>,
        rhs: MatRef<'_, f64>,
        par: Par,
        stack: &mut MemStack,
    ) {
        self.apply(out, rhs, par, stack);
    }
}

/// `P^{-1}` (the PD factorization, per coordinate) as a faer preconditioner.
struct PdPreconditioner<'a> {
    factor: &'a SpdFactor,
    /// The solve's work rows (faer's `LinOp::apply` takes `&self`).
    work: Mutex<Vec<Vec3>>,
}

impl<'a> PdPreconditioner<'a> {
    fn new(factor: &'a SpdFactor) -> Self {
        Self {
            factor,
            work: Mutex::new(vec![Vec3::zeros(); factor.dim()]),
        }
    }
}

impl std::fmt::Debug for PdPreconditioner<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PdPreconditioner")
    }
}

impl LinOp<f64> for PdPreconditioner<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }
    fn nrows(&self) -> usize {
        3 * self.factor.dim()
    }
    fn ncols(&self) -> usize {
        3 * self.factor.dim()
    }
    fn apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _stack: &mut MemStack) {
        let mut work = self.work.lock().expect("preconditioner work");
        apply_per_column(out, rhs, |b, o| {
            self.factor.solve_nodes_into(b, o, &mut work)
        });
    }
    fn conj_apply(
        &self,
        out: MatMut<'_, f64>,
        rhs: MatRef<'_, f64>,
        par: Par,
        stack: &mut MemStack,
    ) {
        self.apply(out, rhs, par, stack);
    }
}

impl Precond<f64> for PdPreconditioner<'_> {}

/// Nodes as one node-major 3m column.
fn nodes_to_col(v: &[Vec3]) -> Mat<f64> {
    Mat::from_fn(3 * v.len(), 1, |r, _| v[r / 3][r % 3])
}

/// A node-major 3m column back into nodes.
fn col_to_nodes(c: &Mat<f64>, out: &mut [Vec3]) {
    for (i, o) in out.iter_mut().enumerate() {
        *o = Vec3::new(c[(3 * i, 0)], c[(3 * i + 1, 0)], c[(3 * i + 2, 0)]);
    }
}

fn norm(v: &[Vec3]) -> f64 {
    v.iter().map(|x| x.norm_squared()).sum::<f64>().sqrt()
}

fn dot(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

/// Work space of the iterative adjoint solves, allocated once per backward pass.
struct SolveWork<'a> {
    precond: PdPreconditioner<'a>,
    /// faer's BiCGStab scratch.
    stack: MemBuffer,
    /// Node vectors of PCG and the fixed-point iteration, and the P-solve's work rows.
    r: Vec<Vec3>,
    s: Vec<Vec3>,
    p: Vec<Vec3>,
    ap: Vec<Vec3>,
    y: Vec<Vec3>,
}

impl<'a> SolveWork<'a> {
    fn new(factor: &'a SpdFactor, op: &AdjointOperator<'_>) -> Self {
        let precond = PdPreconditioner::new(factor);
        let n = factor.dim();
        let stack = MemBuffer::new(bicgstab_scratch(
            IdentityPrecond { dim: 3 * n },
            &precond,
            op,
            1,
            Par::Seq,
        ));
        let zeros = vec![Vec3::zeros(); n];
        Self {
            precond,
            stack,
            r: zeros.clone(),
            s: zeros.clone(),
            p: zeros.clone(),
            ap: zeros.clone(),
            y: zeros,
        }
    }
}

impl Simulator {
    /// Backpropagates a loss through the recorded steps. `dl_dx[n]` and `dl_dv[n]` are the
    /// loss gradients with respect to the positions and velocities after recorded step n
    /// (empty slices mean zero). Requires a tape (`set_recording(true)` before the rollout).
    pub fn backward(
        &mut self,
        dl_dx: &[Vec<Vec3>],
        dl_dv: &[Vec<Vec3>],
        options: &BackwardOptions,
    ) -> Result<Gradients> {
        let start = Instant::now();
        let tape = self.take_tape().ok_or_else(|| {
            Error::Input("no tape: call set_recording(true) before the rollout".into())
        })?;
        let result = if let Tape::Checkpointed { .. } = tape {
            self.backward_checkpointed(&tape, dl_dx, dl_dv, options)
        } else {
            self.backward_segments(
                &tape,
                &[(0, tape.records())],
                dl_dx,
                dl_dv,
                options,
                None,
                &mut None,
            )
        };
        self.put_tape(Some(tape));
        result.map(|mut g| {
            // "other" includes re-simulation of checkpointed segments.
            let p = &mut g.profile;
            p.other = start.elapsed().saturating_sub(p.dp + p.dr + p.solve);
            g
        })
    }

    /// Re-simulates each checkpointed segment (last first) and backpropagates through it;
    /// the simulator's state is restored afterwards.
    fn backward_checkpointed(
        &mut self,
        tape: &Tape,
        dl_dx: &[Vec<Vec3>],
        dl_dv: &[Vec<Vec3>],
        options: &BackwardOptions,
    ) -> Result<Gradients> {
        let saved = (
            self.positions().to_vec(),
            self.velocities().to_vec(),
            self.time(),
            self.attachment_targets().to_vec(),
        );
        let Tape::Checkpointed {
            checkpoints,
            inputs,
            ..
        } = tape
        else {
            unreachable!("called for checkpointed tapes only")
        };
        let steps = tape.len();
        let mut state: Option<Resume> = None;
        let mut outcome = Ok(());
        for (s, cp) in checkpoints.iter().enumerate().rev() {
            let end = checkpoints.get(s + 1).map_or(steps, |c| c.step);
            let records = match self.resimulate(cp, &inputs[cp.step..end]) {
                Ok(r) => r,
                Err(e) => {
                    outcome = Err(e);
                    break;
                }
            };
            let mut carry = None;
            match self.backward_segments(
                tape,
                &[(cp.step, &records[..])],
                dl_dx,
                dl_dv,
                options,
                state.take(),
                &mut carry,
            ) {
                Ok(g) => {
                    let (carry_x, carry_v, z, z_previous) = carry.expect("set on success");
                    state = Some(Resume {
                        grads: g,
                        carry_x,
                        carry_v,
                        z,
                        z_previous,
                    });
                }
                Err(e) => {
                    outcome = Err(e);
                    break;
                }
            }
        }
        // Back to the state before backward.
        self.put_tape(None);
        let restored = self
            .reset(Some(&saved.0), Some(&saved.1))
            .and_then(|_| self.set_time(saved.2));
        if let Some(a) = self.attachments_mut() {
            a.set_targets(&saved.3);
        }
        outcome?;
        restored?;
        Ok(state.map(|r| r.grads).unwrap_or_default())
    }

    fn resimulate(
        &mut self,
        cp: &crate::tape::Checkpoint,
        inputs: &[crate::tape::StepInputs],
    ) -> Result<Vec<StepRecord>> {
        self.set_recording(true);
        self.reset(Some(&cp.x), Some(&cp.v))?;
        self.set_time(cp.time)?;
        for input in inputs {
            self.step(crate::forward::StepInput {
                attachment_targets: input.targets.as_deref(),
                external_forces: input.forces.as_deref(),
            })?;
        }
        Ok(match self.take_tape() {
            Some(Tape::Full { records }) => records,
            _ => Vec::new(),
        })
    }

    /// Backpropagates through `segments` (each `(first step index, records)`, in increasing
    /// order), continuing from `resume` (the gradients and carries of later segments).
    fn backward_segments(
        &self,
        tape: &Tape,
        segments: &[(usize, &[StepRecord])],
        dl_dx: &[Vec<Vec3>],
        dl_dv: &[Vec<Vec3>],
        options: &BackwardOptions,
        resume: Option<Resume>,
        carry_out: &mut Option<(Vec<Vec3>, Vec<Vec3>, Vec<Vec3>, Option<Vec<Vec3>>)>,
    ) -> Result<Gradients> {
        let steps = tape.len();
        let n = self.num_nodes();
        for (name, g) in [("dl_dx", dl_dx), ("dl_dv", dl_dv)] {
            if !g.is_empty() && g.len() != steps {
                return Err(Error::Input(format!(
                    "{name} must have one entry per recorded step ({steps}), got {}",
                    g.len()
                )));
            }
            for (k, a) in g.iter().enumerate() {
                if a.len() != n || !a.iter().all(|p| p.iter().all(|c| c.is_finite())) {
                    return Err(Error::Input(format!("{name}[{k}] must be {n} finite rows")));
                }
            }
        }
        if !(options.tolerance > 0.0 && options.tolerance.is_finite())
            || options.max_iterations == 0
        {
            return Err(Error::Param(
                "backward tolerance must be positive and max_iterations at least 1".into(),
            ));
        }
        let h = self.params().h;
        let mass = self.masses();
        let Resume {
            mut grads,
            mut carry_x,
            mut carry_v,
            mut z,
            z_previous,
        } = resume.unwrap_or_else(|| Resume {
            grads: Gradients {
                mu_obstacles: vec![0.0; self.obstacles().len()],
                attachment_targets: vec![Vec::new(); steps],
                external_forces: vec![Vec::new(); steps],
                steps: vec![AdjointStepStats::default(); steps],
                ..Default::default()
            },
            carry_x: vec![Vec3::zeros(); n],
            carry_v: vec![Vec3::zeros(); n],
            z: vec![Vec3::zeros(); n],
            z_previous: None,
        });
        let mut rhs = vec![Vec3::zeros(); n];
        let mut have_previous = z_previous.is_some();
        let mut z_previous = z_previous.unwrap_or_else(|| z.clone());
        let mut op = AdjointOperator {
            sim: self,
            lin: Linearization::new(self),
            contacts: Vec::new(),
            coupling: ContactCoupling::default(),
            contact_scratch: Mutex::default(),
        };
        let mut work = SolveWork::new(self.factor(), &op);
        for &(first, records) in segments.iter().rev() {
            for (offset, rec) in records.iter().enumerate().rev() {
                let k = first + offset;
                // The loss gradient on this step's output plus what later steps sent back.
                let mut a_v = vec![Vec3::zeros(); n];
                for i in 0..n {
                    let ax = carry_x[i] + dl_dx.get(k).map_or(Vec3::zeros(), |g| g[i]);
                    a_v[i] = carry_v[i] + dl_dv.get(k).map_or(Vec3::zeros(), |g| g[i]);
                    rhs[i] = ax + a_v[i] / h;
                }
                let t_dp = Instant::now();
                op.lin.update(self, &rec.x_next);
                grads.profile.dp += t_dp.elapsed();
                let t_dr = Instant::now();
                op.contacts = linearize_contacts(self, rec).map_err(|e| match e {
                    Error::Unsupported(m) => Error::Unsupported(format!("recorded step {k}: {m}")),
                    other => other,
                })?;
                op.coupling = ContactCoupling::new(&op.contacts, n)?;
                grads.profile.dr += t_dr.elapsed();
                let t_solve = Instant::now();
                // Warm start: extrapolate the last two adjoints (consecutive steps vary smoothly).
                if have_previous {
                    for i in 0..n {
                        let zi = z[i];
                        z[i] = 2.0 * zi - z_previous[i];
                        z_previous[i] = zi;
                    }
                } else {
                    z_previous.copy_from_slice(&z);
                }
                have_previous = true;
                grads.steps[k] = self.solve_adjoint(&op, &rhs, &mut z, options, &mut work)?;
                grads.profile.solve += t_solve.elapsed();
                let (zeta, frame_x) =
                    self.accumulate(rec, &op.contacts, &op.coupling, &z, &mut grads, k);
                for i in 0..n {
                    carry_x[i] = mass[i] / (h * h) * z[i] - a_v[i] / h + frame_x[i];
                    carry_v[i] = mass[i] / h * z[i] + mass[i] * zeta[i];
                }
                if rec.residual > TRUSTED_FORWARD_RESIDUAL {
                    grads.loose_steps.push((k, rec.residual));
                }
            }
        }
        grads.x0 = carry_x.clone();
        grads.v0 = carry_v.clone();
        *carry_out = Some((carry_x, carry_v, z, have_previous.then_some(z_previous)));
        grads.warnings.clear();
        if !grads.loose_steps.is_empty() {
            let worst = grads
                .loose_steps
                .iter()
                .map(|&(_, r)| r)
                .fold(0.0, f64::max);
            let first = grads.loose_steps.iter().map(|&(k, _)| k).min().unwrap_or(0);
            grads.warnings.push(format!(
                "{} of {steps} recorded steps stopped above the residual {TRUSTED_FORWARD_RESIDUAL:e} (worst {worst:.1e}, first at step {first}): \
                 the adjoint linearizes unconverged steps and the gradient may be inaccurate; lower \
                 solver.record_tolerance or raise record_max_iterations",
                grads.loose_steps.len()
            ));
        }
        let fell_back = grads.steps.iter().filter(|s| s.fell_back).count();
        if fell_back > 0 && options.solver != AdjointSolver::Direct {
            grads.warnings.push(format!(
                "{fell_back} of {steps} adjoint solves fell back to the direct solver"
            ));
        }
        Ok(grads)
    }

    /// Solves `H z = g` with the chosen solver; an iterative solver that stalls, diverges or
    /// hits its cap falls back to the direct solve (counted in the stats).
    fn solve_adjoint(
        &self,
        op: &AdjointOperator<'_>,
        g: &[Vec3],
        z: &mut [Vec3],
        options: &BackwardOptions,
        work: &mut SolveWork<'_>,
    ) -> Result<AdjointStepStats> {
        let g_norm = norm(g);
        if g_norm == 0.0 {
            z.iter_mut().for_each(|v| *v = Vec3::zeros());
            return Ok(AdjointStepStats::default());
        }
        // |g - H z| / |g|, into the work rows (no allocation per step).
        let residual_of = |z: &[Vec3], hz: &mut [Vec3]| {
            op.apply_nodes(z, hz);
            let r2: f64 = hz.iter().zip(g).map(|(a, b)| (b - a).norm_squared()).sum();
            r2.sqrt() / g_norm
        };
        let iterative = match options.solver {
            AdjointSolver::Direct => None,
            AdjointSolver::FixedPoint => Some(self.fixed_point(op, g, z, options, work)),
            AdjointSolver::Krylov => Some(self.krylov(op, g, z, options, work)),
        };
        if let Some(Attempt {
            iterations,
            converged: true,
        }) = iterative
        {
            let residual = residual_of(z, &mut work.ap);
            if residual <= options.tolerance * 10.0
                && z.iter().all(|v| v.iter().all(|c| c.is_finite()))
            {
                return Ok(AdjointStepStats {
                    iterations,
                    fell_back: false,
                    residual,
                });
            }
        }
        self.direct(op, g, z)?;
        Ok(AdjointStepStats {
            iterations: iterative.map_or(0, |a| a.iterations),
            fell_back: iterative.is_some(),
            residual: residual_of(z, &mut work.ap),
        })
    }

    /// Paper Eqn. 30: `P z_{k+1} = (P - H^T) z_k + g` (dP and, with contact, the dR term),
    /// reusing the PD factorization. Stops on the true relative residual `|g - H^T z| / |g|`
    /// (free: `H^T z` is needed for the update anyway), not on the update size, which
    /// understates the error when the iteration converges slowly. Returns the iteration count,
    /// or None on divergence or at the cap.
    fn fixed_point(
        &self,
        op: &AdjointOperator<'_>,
        g: &[Vec3],
        z: &mut [Vec3],
        options: &BackwardOptions,
        work: &mut SolveWork<'_>,
    ) -> Attempt {
        let g_norm = norm(g);
        let SolveWork { r, s, ap, y, .. } = work;
        // Warm start from the previous step's adjoint (kept in z), unless it is unusable.
        if !z.iter().all(|v| v.iter().all(|c| c.is_finite())) {
            z.iter_mut().for_each(|v| *v = Vec3::zeros());
        }
        let mut previous = f64::INFINITY;
        let mut growing = 0;
        for it in 0..=options.max_iterations {
            op.apply_nodes(z, ap);
            let residual = g
                .iter()
                .zip(ap.iter())
                .map(|(a, b)| (a - b).norm_squared())
                .sum::<f64>()
                .sqrt()
                / g_norm;
            if !residual.is_finite() {
                return Attempt::failed(it);
            }
            if residual <= options.tolerance {
                return Attempt::converged(it);
            }
            growing = if residual > previous { growing + 1 } else { 0 };
            if growing >= 5 || it == options.max_iterations {
                return Attempt::failed(it);
            }
            previous = residual;
            // z <- P^{-1} (g + P z - H^T z)
            self.factor().mul_xyz(z, s);
            for ((ri, gi), (si, ai)) in r.iter_mut().zip(g).zip(s.iter().zip(ap.iter())) {
                *ri = gi + si - ai;
            }
            self.factor().solve_nodes_into(r, z, y);
        }
        Attempt::failed(options.max_iterations)
    }

    /// Krylov solve preconditioned by `P`: CG while `H` is symmetric (no active contact),
    /// else (or when CG meets negative curvature) faer's BiCGStab.
    fn krylov(
        &self,
        op: &AdjointOperator<'_>,
        g: &[Vec3],
        z: &mut [Vec3],
        options: &BackwardOptions,
        work: &mut SolveWork<'_>,
    ) -> Attempt {
        let n = g.len();
        // Warm start from the previous (later) steps' adjoints: consecutive adjoints are close.
        if !z.iter().all(|v| v.iter().all(|c| c.is_finite())) {
            z.iter_mut().for_each(|v| *v = Vec3::zeros());
        }
        let mut spent = 0;
        if op.contacts.is_empty() {
            match self.pcg(op, g, z, options, work) {
                Ok(attempt) => return attempt,
                Err(iterations) => spent = iterations,
            }
        }
        let rhs = nodes_to_col(g);
        let mut out = nodes_to_col(z);
        let mut params = BicgParams::<f64>::default();
        // (Also: faer 0.24's BiCGStab leaves its residual vector uninitialized for
        // `InitialGuessStatus::Zero`; `MaybeNonZero` computes r = g - H z0.)
        params.initial_guess = InitialGuessStatus::MaybeNonZero;
        params.rel_tolerance = options.tolerance;
        params.max_iters = options.max_iterations;
        // Right preconditioning by P: H P^{-1} is close to the identity (dP is small next to P).
        let result = bicgstab(
            out.as_mut(),
            IdentityPrecond { dim: 3 * n },
            &work.precond,
            op,
            rhs.as_ref(),
            params,
            |_| {},
            Par::Seq,
            MemStack::new(&mut work.stack),
        );
        col_to_nodes(&out, z);
        match result {
            Ok(info) => Attempt::converged(spent + info.iter_count),
            Err(_) => Attempt::failed(spent + params.max_iters),
        }
    }

    /// Preconditioned conjugate gradients on `H z = g` (contact-free `H = P - dP` is
    /// symmetric), stopping at `|g - H z| <= tolerance |g|`. Hand-written rather than faer's
    /// CG, which is a block method: for one right-hand side its per-iteration k x k Cholesky,
    /// permutations and gemm calls cost about 5 % of an iteration, and here the vectors stay
    /// node-major. `Err(iterations)` when `H` shows non-positive curvature (possible away from
    /// a converged step); `z` then holds the last iterate.
    fn pcg(
        &self,
        op: &AdjointOperator<'_>,
        g: &[Vec3],
        z: &mut [Vec3],
        options: &BackwardOptions,
        work: &mut SolveWork<'_>,
    ) -> std::result::Result<Attempt, usize> {
        let SolveWork { r, s, p, ap, y, .. } = work;
        let threshold = options.tolerance * norm(g);
        op.apply_nodes(z, ap);
        for ((ri, gi), ai) in r.iter_mut().zip(g).zip(ap.iter()) {
            *ri = gi - ai;
        }
        if norm(r) <= threshold {
            return Ok(Attempt::converged(0));
        }
        self.factor().solve_nodes_into(r, s, y);
        p.copy_from_slice(s);
        let mut rs = dot(r, s);
        for it in 1..=options.max_iterations {
            op.apply_nodes(p, ap);
            let curvature = dot(p, ap);
            let positive = curvature.is_finite() && curvature > 0.0;
            if !positive {
                return Err(it);
            }
            let alpha = rs / curvature;
            for (zi, pi) in z.iter_mut().zip(p.iter()) {
                *zi += alpha * pi;
            }
            for (ri, ai) in r.iter_mut().zip(ap.iter()) {
                *ri -= alpha * ai;
            }
            if norm(r) <= threshold {
                return Ok(Attempt::converged(it));
            }
            self.factor().solve_nodes_into(r, s, y);
            let rs_next = dot(r, s);
            let beta = rs_next / rs;
            rs = rs_next;
            for (pi, si) in p.iter_mut().zip(s.iter()) {
                *pi = si + beta * *pi;
            }
        }
        Ok(Attempt::failed(options.max_iterations))
    }

    fn direct(&self, op: &AdjointOperator<'_>, g: &[Vec3], z: &mut [Vec3]) -> Result<()> {
        let n = g.len();
        let mut triplets = op.lin.assemble(self, self.factor().matrix());
        if !op.contacts.is_empty() {
            // H^T = H_nc - (dP - K) C with C = sum_c S^T Phi'^T E^T and dP - K = M/h^2 - H_nc.
            let h_nc = SparseColMat::<usize, f64>::try_new_from_triplets(3 * n, 3 * n, &triplets)
                .map_err(|e| {
                Error::Solver(format!("cannot assemble the adjoint matrix: {e:?}"))
            })?;
            let hr = h_nc.as_ref();
            let (mass, h) = (self.masses(), self.params().h);
            // C = S^T B^T (I - T^T B^T)^{-1} E^T in 3x3 blocks C[k, j].
            let mut blocks: std::collections::BTreeMap<(usize, usize), Matrix3<f64>> =
                Default::default();
            for (group, inv) in op.coupling.inverse_groups(op.contacts.len()) {
                for (bi, &c) in group.iter().enumerate() {
                    for (bj, &cp) in group.iter().enumerate() {
                        let sub: Matrix3<f64> = inv.fixed_view::<3, 3>(3 * bi, 3 * bj).into_owned();
                        let block = op.contacts[c].phi.transpose() * sub;
                        for &(k, s) in &op.contacts[c].s {
                            for &(j, e) in &op.contacts[cp].e {
                                *blocks.entry((k, j)).or_insert_with(Matrix3::zeros) +=
                                    (s * e) * block;
                            }
                        }
                    }
                }
            }
            for (&(k, j), block) in &blocks {
                for ep in 0..3 {
                    let col = 3 * k + ep;
                    for (row, &val) in hr.row_idx_of_col(col).zip(hr.val_of_col(col)) {
                        let a = if row == col {
                            mass[k] / (h * h) - val
                        } else {
                            -val
                        };
                        for cp in 0..3 {
                            triplets.push(Triplet::new(row, 3 * j + cp, -a * block[(ep, cp)]));
                        }
                    }
                }
            }
        }
        let h = SparseColMat::<usize, f64>::try_new_from_triplets(3 * n, 3 * n, &triplets)
            .map_err(|e| Error::Solver(format!("cannot assemble the adjoint matrix: {e:?}")))?;
        let lu = h
            .sp_lu()
            .map_err(|e| Error::Solver(format!("adjoint matrix is singular: {e:?}")))?;
        let mut rhs = nodes_to_col(g);
        lu.solve_in_place(rhs.as_mut());
        col_to_nodes(&rhs, z);
        Ok(())
    }

    /// Adds step k's contributions `-z . dF/dtheta` and the per-step action/force gradients.
    /// Returns `zeta` (the contact adjoint on the nodes' free momenta, for dL/dv_n) and the
    /// contact frames' contribution to dL/dx_n.
    fn accumulate(
        &self,
        rec: &StepRecord,
        contacts: &[ContactLin],
        coupling: &ContactCoupling,
        z: &[Vec3],
        grads: &mut Gradients,
        k: usize,
    ) -> (Vec<Vec3>, Vec<Vec3>) {
        let p = self.params();
        let h = p.h;
        let x = &rec.x_next;
        let n = x.len();
        let effects = self.effects();
        // Contacts: the impulse adjoints, their pull on the free momenta (zeta), the frame.
        let mut zeta = vec![Vec3::zeros(); n];
        let mut frame_x = vec![Vec3::zeros(); n];
        let area = self.node_areas();
        let mut adjoints: Vec<Vec3> = contacts.iter().map(|c| c.impulse_adjoint(z, h)).collect();
        coupling.solve(&mut adjoints);
        for (c, &zhat) in contacts.iter().zip(&adjoints) {
            let w = c.phi.transpose() * zhat;
            for &(node, s) in &c.s {
                zeta[node] += s * w;
            }
            let dj_dgap = -(c.mass / h) * c.dj_dlambda;
            let pull_gap = zhat.dot(&dj_dgap);
            let pull_n = c.dj_dn.transpose() * zhat;
            for &(node, dgap, dn) in &c.frame {
                frame_x[node] += pull_gap * dgap + dn.transpose() * pull_n;
            }
            if effects.friction {
                match c.obstacle {
                    Some(o) => grads.mu_obstacles[o] += zhat.dot(&c.dj_dmu),
                    None => grads.mu_self += zhat.dot(&c.dj_dmu),
                }
            }
            // Density through the contact mass (the gap term) and the obstacle's momentum.
            let dm_drho = c.mass / p.density;
            grads.density += zhat.dot(&(c.dj_dlambda * (-c.gap / h))) * dm_drho;
            if let Some(&(node, _)) = c.s.first().filter(|_| c.obstacle.is_some()) {
                grads.density -= w.dot(&(area[node] * c.obstacle_velocity));
            }
        }
        // The sensitivity to every force on a node: directly (z) and through contacts (h zeta).
        let zf: Vec<Vec3> = z.iter().zip(&zeta).map(|(a, b)| a + h * b).collect();
        if effects.external_forces {
            grads.external_forces[k] = zf.clone();
        }
        if !self.attachment_nodes().is_empty() {
            let nodes = self.attachment_nodes();
            grads.attachment_targets[k] = nodes.iter().map(|&j| p.k_attach * zf[j]).collect();
            grads.k_attach -= nodes
                .iter()
                .zip(&rec.targets)
                .map(|(&j, t)| zf[j].dot(&(x[j] - t)))
                .sum::<f64>();
        }
        for c in self.constraint_sets() {
            let dot = c.stiffness_dot(x, &zf);
            match c.stiffness() {
                Stiffness::Stretch => grads.k_stretch -= dot,
                Stiffness::Bend => grads.k_bend -= dot,
                // k_attach goes with the actions above, at the recorded targets.
                Stiffness::Attach => {}
            }
        }
        let mass = self.masses();
        for i in 0..n {
            // dF/drho from the inertia term, and the momentum (M v_n + h M g) through contacts.
            let mut dg = area[i] * (x[i] - rec.x_prev[i] - h * rec.v_prev[i]) / (h * h);
            let mut dd = area[i] * rec.v_prev[i];
            if effects.gravity {
                dg -= area[i] * p.gravity;
                dd += h * area[i] * p.gravity;
                grads.gravity += mass[i] * zf[i];
            }
            grads.density += -z[i].dot(&dg) + zeta[i].dot(&dd);
        }
        if let Some(wind) = self.wind() {
            let s = wind.modulation(rec.time);
            let ds = 0.5 * (wind.omega * rec.time + wind.phi).cos();
            let kz: Vec3 = zf
                .iter()
                .zip(wind.coefficient())
                .map(|(zi, c)| *c * zi)
                .sum();
            grads.wind_direction += s * kz;
            grads.wind_omega += ds * rec.time * kz.dot(&wind.direction);
            grads.wind_phi += ds * kz.dot(&wind.direction);
        }
        (zeta, frame_x)
    }
}
