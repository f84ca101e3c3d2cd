//! Attachments: stiff springs pulling selected nodes to targets that may change every step
//! (the end effectors). `A_i` selects node `j_i`; the projection is the target `t_i`;
//! `w_i = k_attach`. Targets enter only the right-hand side, so moving them never refactors.

use super::{PdConstraints, Stiffness};
use crate::Vec3;

pub struct Attachments {
    nodes: Vec<usize>,
    stiffness: f64,
    targets: Vec<Vec3>,
}

impl Attachments {
    pub fn new(nodes: Vec<usize>, stiffness: f64, targets: Vec<Vec3>) -> Self {
        assert_eq!(nodes.len(), targets.len());
        Self {
            nodes,
            stiffness,
            targets,
        }
    }

    pub fn nodes(&self) -> &[usize] {
        &self.nodes
    }

    pub fn targets(&self) -> &[Vec3] {
        &self.targets
    }

    pub fn set_targets(&mut self, targets: &[Vec3]) {
        self.targets.copy_from_slice(targets);
    }

    pub fn set_stiffness(&mut self, k: f64) {
        self.stiffness = k;
    }
}

impl PdConstraints for Attachments {
    fn add_system_triplets(&self, out: &mut Vec<(usize, usize, f64)>) {
        out.extend(self.nodes.iter().map(|&j| (j, j, self.stiffness)));
    }

    fn project(&mut self, x: &[Vec3], _parallel: bool) -> f64 {
        let e: f64 = self
            .nodes
            .iter()
            .zip(&self.targets)
            .map(|(&j, t)| (x[j] - t).norm_squared())
            .sum();
        0.5 * self.stiffness * e
    }

    fn add_rhs(&self, rhs: &mut [Vec3]) {
        for (&j, t) in self.nodes.iter().zip(&self.targets) {
            rhs[j] += self.stiffness * t;
        }
    }

    fn stiffness(&self) -> Stiffness {
        Stiffness::Attach
    }

    fn set_stiffness(&mut self, k: f64) {
        self.stiffness = k;
    }

    /// The projection (the target) does not depend on x: dP = 0.
    fn linearization_len(&self) -> usize {
        0
    }

    fn linearize(&self, _x: &[Vec3], _lin: &mut [f64]) {}

    fn sub_dp(&self, _lin: &[f64], _v: &[Vec3], _out: &mut [Vec3]) {}

    fn add_neg_dp_triplets(&self, _lin: &[f64], _out: &mut Vec<(usize, usize, f64)>) {}

    /// `grad W = k (x_j - t)` on each attached node, at the current targets.
    fn stiffness_dot(&self, x: &[Vec3], z: &[Vec3]) -> f64 {
        self.nodes
            .iter()
            .zip(&self.targets)
            .map(|(&j, t)| z[j].dot(&(x[j] - t)))
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::testing::*;

    #[test]
    fn energy_gradient_matches_finite_differences() {
        let x = jitter(&vec![Vec3::zeros(); 4], 1.0, 1);
        let mut a = Attachments::new(
            vec![1, 3],
            50.0,
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::zeros()],
        );
        check_gradient_fd(&mut a, &x, 1e-7);
        check_backward_fd(&mut a, 50.0, &x, 1e-6);
        // The projection is the target: zero energy there.
        let mut at = x.clone();
        at[1] = Vec3::new(1.0, 2.0, 3.0);
        at[3] = Vec3::zeros();
        assert_eq!(a.project(&at, false), 0.0);
    }
}
