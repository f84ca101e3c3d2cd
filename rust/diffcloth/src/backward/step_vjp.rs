//! The backward pass of one recorded step on its own: given dL/dx_{k+1} and dL/dv_{k+1}, the
//! gradients with respect to the step's inputs (x_k, v_k, its attachment targets and forces)
//! and the parameters' share of this step. This is what a closed-loop autograd graph needs
//! (`step_grad`): each step is recorded once and differentiated from its record, with no
//! second forward. Chaining it over every step in reverse gives the same gradients as
//! `backward` over the whole tape (up to the adjoint tolerance).

use super::replay::Resume;
use super::{BackwardOptions, Gradients};
use crate::cancel::Cancel;
use crate::error::{Error, Result};
use crate::forward::Simulator;
use crate::tape::Tape;
use crate::Vec3;

/// The last adjoints of a chain of one-step products, to warm-start the next (earlier) step:
/// consecutive steps' adjoints vary smoothly, so this saves iterations.
#[derive(Debug, Clone, Default)]
pub struct AdjointWarmStart {
    /// The step these adjoints belong to (a warm start is used for step `step - 1` only).
    step: usize,
    z: Vec<Vec3>,
    z_previous: Option<Vec<Vec3>>,
    /// Whether the chain's adjoint solves have switched to the factored Hessian.
    factored: bool,
}

impl Simulator {
    /// dL/d(inputs of recorded step `k`) from `dl_dx` and `dl_dv` on its outputs (each n
    /// rows). The result's `x0`/`v0` are dL/dx_k and dL/dv_k, `attachment_targets[k]` and
    /// `external_forces[k]` this step's input gradients, the parameter fields this step's
    /// share. Needs a full (not checkpointed) tape recorded with one model. `warm` carries
    /// the adjoint from the previous call: it is used when that call was step `k + 1`, and is
    /// replaced by this step's.
    pub fn backward_step(
        &self,
        k: usize,
        dl_dx: &[Vec3],
        dl_dv: &[Vec3],
        options: &BackwardOptions,
        warm: &mut Option<AdjointWarmStart>,
    ) -> Result<Gradients> {
        let rec = self.recording().ok_or_else(|| {
            Error::Input("no tape: call set_recording(true) before the rollout".into())
        })?;
        let Tape::Full { records } = &rec.tape else {
            return Err(Error::Input(
                "backward_step needs a full tape (set_recording without checkpoint_every)".into(),
            ));
        };
        if k >= records.len() {
            return Err(Error::Input(format!(
                "step {k} is not recorded (the tape has {} steps)",
                records.len()
            )));
        }
        if rec.changed_at.is_some_and(|c| k >= c) {
            return Err(Error::Input(format!(
                "recorded step {k} was taken after the parameters changed (at step {}): its \
                 model is not kept; call set_recording(true) again after changing them",
                rec.changed_at.unwrap_or(0)
            )));
        }
        let n = self.num_nodes();
        for (name, g) in [("dl_dx", dl_dx), ("dl_dv", dl_dv)] {
            if g.len() != n || !g.iter().all(|p| p.iter().all(|c| c.is_finite())) {
                return Err(Error::Input(format!("{name} must be {n} finite rows")));
            }
        }
        super::replay::validate_options(options)?;
        let steps = records.len();
        let (z, z_previous, factored) = match warm.take() {
            Some(w) if w.step == k + 1 && w.z.len() == n => (w.z, w.z_previous, w.factored),
            _ => (vec![Vec3::zeros(); n], None, false),
        };
        // The loss gradients enter as the carry from "later steps", so the step's own slot in
        // dl_dx/dl_dv stays empty and nothing is sized by the horizon but empty rows.
        let resume = Resume {
            grads: Gradients::zeros(steps, self.obstacles().len()),
            carry_x: dl_dx.to_vec(),
            carry_v: dl_dv.to_vec(),
            z,
            z_previous,
            factored,
        };
        let replay = Simulator::from_model(rec.model.clone(), rec.solver.clone());
        let mut carry = None;
        let grads = replay.backward_segments(
            &rec.tape,
            &[(k, &records[k..=k])],
            &[],
            &[],
            options,
            // One step: short enough that Ctrl-C waits for it (the caller checks between steps).
            &Cancel::never(),
            Some(resume),
            &mut carry,
        )?;
        if let Some((_, _, z, z_previous, factored)) = carry {
            *warm = Some(AdjointWarmStart {
                step: k,
                z,
                z_previous,
                factored,
            });
        }
        Ok(grads)
    }
}
