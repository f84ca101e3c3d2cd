//! What the loss gradient is with respect to, and each step's contribution to it
//! (`-z . dF/dtheta` for every parameter, and the per-step actions and forces).

use super::contact::{ContactCoupling, ContactLin};
use super::{AdjointStepStats, BackwardProfile};
use crate::energy::Stiffness;
use crate::forces::Wind;
use crate::forward::Simulator;
use crate::params::{Param, ParamValue};
use crate::tape::StepRecord;
use crate::Vec3;

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

impl Gradients {
    /// Zero gradients for a tape of `steps` steps and `obstacles` obstacles.
    pub(super) fn zeros(steps: usize, obstacles: usize) -> Self {
        Self {
            mu_obstacles: vec![0.0; obstacles],
            attachment_targets: vec![Vec::new(); steps],
            external_forces: vec![Vec::new(); steps],
            steps: vec![AdjointStepStats::default(); steps],
            ..Default::default()
        }
    }

    /// The gradient with respect to a parameter, by the shared name table (None for `h`).
    pub fn param(&self, p: Param) -> Option<ParamValue> {
        use ParamValue::{List, Scalar, Vector};
        Some(match p {
            Param::H => return None,
            Param::Density => Scalar(self.density),
            Param::KStretch => Scalar(self.k_stretch),
            Param::KBend => Scalar(self.k_bend),
            Param::KAttach => Scalar(self.k_attach),
            Param::Gravity => Vector(self.gravity),
            Param::WindDirection => Vector(self.wind_direction),
            Param::WindOmega => Scalar(self.wind_omega),
            Param::WindPhi => Scalar(self.wind_phi),
            Param::MuObstacles => List(self.mu_obstacles.clone()),
            Param::MuSelf => Scalar(self.mu_self),
        })
    }
}

impl Simulator {
    /// Adds step k's contributions `-z . dF/dtheta` and the per-step action/force gradients.
    /// Returns `zeta` (the contact adjoint on the nodes' free momenta, for dL/dv_n) and the
    /// contact frames' contribution to dL/dx_n.
    pub(super) fn accumulate(
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
            let s = Wind::modulation(p, rec.time);
            let ds = 0.5 * (p.wind_omega * rec.time + p.wind_phi).cos();
            let kz: Vec3 = zf
                .iter()
                .zip(wind.coefficient())
                .map(|(zi, c)| *c * zi)
                .sum();
            grads.wind_direction += s * kz;
            grads.wind_omega += ds * rec.time * kz.dot(&p.wind_direction);
            grads.wind_phi += ds * kz.dot(&p.wind_direction);
        }
        (zeta, frame_x)
    }
}
