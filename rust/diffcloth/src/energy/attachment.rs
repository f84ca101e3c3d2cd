//! Attachments: stiff springs pulling selected nodes to targets that may change every step
//! (the end effectors). `A_i` selects node `j_i`; the projection is the target `t_i`;
//! `w_i = k_attach`. Targets enter only the right-hand side, so moving them never refactors.
//!
//! Unlike the elastic sets this is not a [`super::PdConstraints`]: its projections are the
//! targets, which are the simulator's state (the actions), not a function of x, so they are
//! passed in; and dP = 0, so the adjoint needs nothing from it but the targets' own gradient.

use crate::Vec3;

#[derive(Debug, Clone)]
pub struct Attachments {
    nodes: Vec<usize>,
    stiffness: f64,
}

impl Attachments {
    pub fn new(nodes: Vec<usize>, stiffness: f64) -> Self {
        Self { nodes, stiffness }
    }

    pub fn nodes(&self) -> &[usize] {
        &self.nodes
    }

    pub fn stiffness(&self) -> f64 {
        self.stiffness
    }

    pub fn set_stiffness(&mut self, k: f64) {
        self.stiffness = k;
    }

    /// Appends `w_i A_i^T A_i` (the stiffness on each attached node's diagonal).
    pub fn add_system_triplets(&self, out: &mut Vec<(usize, usize, f64)>) {
        out.extend(self.nodes.iter().map(|&j| (j, j, self.stiffness)));
    }

    /// `k / 2 sum_i |x_{j_i} - t_i|^2`.
    pub fn energy(&self, x: &[Vec3], targets: &[Vec3]) -> f64 {
        let e: f64 = self
            .nodes
            .iter()
            .zip(targets)
            .map(|(&j, t)| (x[j] - t).norm_squared())
            .sum();
        0.5 * self.stiffness * e
    }

    /// Adds `k t_i` to each attached node's right-hand side.
    pub fn add_rhs(&self, targets: &[Vec3], rhs: &mut [Vec3]) {
        for (&j, t) in self.nodes.iter().zip(targets) {
            rhs[j] += self.stiffness * t;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::testing::jitter;

    #[test]
    fn energy_gradient_matches_finite_differences() {
        let x = jitter(&vec![Vec3::zeros(); 4], 1.0, 1);
        let targets = [Vec3::new(1.0, 2.0, 3.0), Vec3::zeros()];
        let a = Attachments::new(vec![1, 3], 50.0);
        // Gradient K x - rhs from the system triplets and the right-hand side.
        let mut t = Vec::new();
        a.add_system_triplets(&mut t);
        let mut g = vec![Vec3::zeros(); 4];
        for (r, c, v) in t {
            g[r] += v * x[c];
        }
        let mut rhs = vec![Vec3::zeros(); 4];
        a.add_rhs(&targets, &mut rhs);
        let eps = 1e-6;
        for i in 0..4 {
            for d in 0..3 {
                let mut xp = x.clone();
                xp[i][d] += eps;
                let mut xm = x.clone();
                xm[i][d] -= eps;
                let fd = (a.energy(&xp, &targets) - a.energy(&xm, &targets)) / (2.0 * eps);
                assert!(
                    (fd - (g[i][d] - rhs[i][d])).abs() < 1e-6,
                    "node {i} dim {d}"
                );
            }
        }
        // The projection is the target: zero energy there.
        let mut at = x.clone();
        at[1] = targets[0];
        at[3] = targets[1];
        assert_eq!(a.energy(&at, &targets), 0.0);
    }
}
