//! The backward driver: walks the tape from the last step to the first (re-simulating
//! checkpointed segments), carrying dL/dx and dL/dv back through each step's adjoint solve.

use super::contact::{linearize_contacts, ContactCoupling};
use super::factored::Factored;
use super::operator::{AdjointOperator, Linearization};
use super::solvers::SolveWork;
use super::{AdjointSolver, BackwardOptions, Gradients, TRUSTED_FORWARD_RESIDUAL};
use crate::cancel::Cancel;
use crate::error::{Error, Result};
use crate::forward::Simulator;
use crate::params::Preset;
use crate::tape::{StepRecord, Tape};
use crate::Vec3;
use std::sync::Mutex;
use std::time::Instant;

/// Where a segment's backward pass continues from (checkpointed tapes).
pub(super) struct Resume {
    pub(super) grads: Gradients,
    pub(super) carry_x: Vec<Vec3>,
    pub(super) carry_v: Vec<Vec3>,
    /// The last two adjoints, the warm start of the next solve.
    pub(super) z: Vec<Vec3>,
    pub(super) z_previous: Option<Vec<Vec3>>,
    /// Whether the adjoint solves had switched to the factored Hessian (`factored.rs`).
    pub(super) factored: bool,
}

/// What a segment hands to the next: `Resume` without the gradients.
pub(super) type Carry = (Vec<Vec3>, Vec<Vec3>, Vec<Vec3>, Option<Vec<Vec3>>, bool);

impl Simulator {
    /// Backpropagates a loss through the recorded steps. `dl_dx[n]` and `dl_dv[n]` are the
    /// loss gradients with respect to the positions and velocities after recorded step n
    /// (empty slices mean zero). Requires a tape (`set_recording(true)` before the rollout).
    ///
    /// The steps are linearized with the model they were recorded with, and checkpointed
    /// segments are replayed on a simulator of their own: this simulator (state, step count,
    /// profile, tape) is left exactly as it was.
    pub fn backward(
        &self,
        dl_dx: &[Vec<Vec3>],
        dl_dv: &[Vec<Vec3>],
        options: &BackwardOptions,
    ) -> Result<Gradients> {
        self.backward_cancellable(dl_dx, dl_dv, options, &Cancel::never())
    }

    /// [`Simulator::backward`] that stops with [`Error::Cancelled`] when `cancel` says so. It
    /// is polled before each replayed step, each re-simulated step of a checkpointed tape and
    /// in every iteration of the CG and fixed-point adjoint solves (not inside one BiCGStab or
    /// direct solve, which are faer's: they bound the latency to one step's solve). A
    /// cancelled backward leaves this simulator as untouched as a finished one.
    pub fn backward_cancellable(
        &self,
        dl_dx: &[Vec<Vec3>],
        dl_dv: &[Vec<Vec3>],
        options: &BackwardOptions,
        cancel: &Cancel<'_>,
    ) -> Result<Gradients> {
        let start = Instant::now();
        let rec = self.recording().ok_or_else(|| {
            Error::Input("no tape: call set_recording(true) before the rollout".into())
        })?;
        let tape = &rec.tape;
        validate(tape.len(), self.num_nodes(), dl_dx, dl_dv, options)?;
        if let Some(k) = rec.changed_at {
            return Err(Error::Input(format!(
                "the parameters (or, for a checkpointed tape, the solver settings) changed at \
                 recorded step {k}: the tape holds steps of two different models and has no \
                 single linearization; call set_recording(true) again after changing them"
            )));
        }
        let mut replay = Simulator::from_model(rec.model.clone(), rec.solver.clone());
        let result = if let Tape::Checkpointed { .. } = tape {
            replay.backward_checkpointed(tape, dl_dx, dl_dv, options, cancel)
        } else {
            replay.backward_segments(
                tape,
                &[(0, tape.records())],
                dl_dx,
                dl_dv,
                options,
                cancel,
                None,
                &mut None,
            )
        };
        result.map(|mut g| {
            // "other" includes re-simulation of checkpointed segments.
            let p = &mut g.profile;
            p.other = start.elapsed().saturating_sub(p.dp + p.dr + p.solve);
            g
        })
    }

    /// Re-simulates each checkpointed segment (last first) and backpropagates through it
    /// (on a simulator of the backward's own).
    pub(super) fn backward_checkpointed(
        &mut self,
        tape: &Tape,
        dl_dx: &[Vec<Vec3>],
        dl_dv: &[Vec<Vec3>],
        options: &BackwardOptions,
        cancel: &Cancel<'_>,
    ) -> Result<Gradients> {
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
        for (s, cp) in checkpoints.iter().enumerate().rev() {
            let end = checkpoints.get(s + 1).map_or(steps, |c| c.step);
            let records = self.resimulate(cp, &inputs[cp.step..end], cancel)?;
            let mut carry = None;
            let g = self.backward_segments(
                tape,
                &[(cp.step, &records[..])],
                dl_dx,
                dl_dv,
                options,
                cancel,
                state.take(),
                &mut carry,
            )?;
            let (carry_x, carry_v, z, z_previous, factored) = carry.expect("set on success");
            state = Some(Resume {
                grads: g,
                carry_x,
                carry_v,
                z,
                z_previous,
                factored,
            });
        }
        Ok(state.map(|r| r.grads).unwrap_or_default())
    }

    pub(super) fn resimulate(
        &mut self,
        cp: &crate::tape::Checkpoint,
        inputs: &[crate::tape::StepInputs],
        cancel: &Cancel<'_>,
    ) -> Result<Vec<StepRecord>> {
        self.set_recording(true);
        self.reset(Some(&cp.x), Some(&cp.v))?;
        self.set_time(cp.time)?;
        for input in inputs {
            cancel.checkpoint("backward (re-simulating a checkpointed segment)")?;
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
    pub(super) fn backward_segments(
        &self,
        tape: &Tape,
        segments: &[(usize, &[StepRecord])],
        dl_dx: &[Vec<Vec3>],
        dl_dv: &[Vec<Vec3>],
        options: &BackwardOptions,
        cancel: &Cancel<'_>,
        resume: Option<Resume>,
        carry_out: &mut Option<Carry>,
    ) -> Result<Gradients> {
        let steps = tape.len();
        let n = self.num_nodes();
        let h = self.params().h;
        let mass = self.masses();
        let Resume {
            mut grads,
            mut carry_x,
            mut carry_v,
            mut z,
            z_previous,
            factored,
        } = resume.unwrap_or_else(|| Resume {
            grads: Gradients::zeros(steps, self.obstacles().len()),
            carry_x: vec![Vec3::zeros(); n],
            carry_v: vec![Vec3::zeros(); n],
            z: vec![Vec3::zeros(); n],
            z_previous: None,
            factored: false,
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
        let mut work = SolveWork::new(self.factor(), &op, cancel);
        work.factored = Factored::new(factored);
        for &(first, records) in segments.iter().rev() {
            for (offset, rec) in records.iter().enumerate().rev() {
                let k = first + offset;
                cancel.checkpoint("backward")?;
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
        *carry_out = Some((
            carry_x,
            carry_v,
            z,
            have_previous.then_some(z_previous),
            work.factored.enabled(),
        ));
        grads.warnings.clear();
        if !grads.loose_steps.is_empty() {
            let worst = grads
                .loose_steps
                .iter()
                .map(|&(_, r)| r)
                .fold(0.0, f64::max);
            let first = grads.loose_steps.iter().map(|&(k, _)| k).min().unwrap_or(0);
            let (tolerance, cap) = Preset::Gradient.accuracy();
            grads.warnings.push(format!(
                "{} of {steps} recorded steps stopped above the residual {TRUSTED_FORWARD_RESIDUAL:e} (worst {worst:.1e}, first at step {first}): \
                 the adjoint linearizes unconverged steps and the gradient may be inaccurate; record \
                 with solver preset \"gradient\" (tolerance {tolerance:e}, max_iterations {cap}), a lower \
                 solver.tolerance, or a higher solver.max_iterations if steps stopped at the cap",
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
}

/// Checks the loss gradients and options against the tape before any work is done (a
/// checkpointed backward must not replay a segment for a call it then rejects).
fn validate(
    steps: usize,
    n: usize,
    dl_dx: &[Vec<Vec3>],
    dl_dv: &[Vec<Vec3>],
    options: &BackwardOptions,
) -> Result<()> {
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
    validate_options(options)
}

/// Checks the adjoint solver options.
pub(super) fn validate_options(options: &BackwardOptions) -> Result<()> {
    if !(options.tolerance > 0.0 && options.tolerance.is_finite()) || options.max_iterations == 0 {
        return Err(Error::Param(
            "backward tolerance must be positive and max_iterations at least 1".into(),
        ));
    }
    Ok(())
}
