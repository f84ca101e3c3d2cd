//! Per-stage wall time and counters, readable after any run (like the paper's Table 1 columns).

use std::time::{Duration, Instant};

/// Accumulated wall time per forward stage and the counts that go with it.
#[derive(Debug, Clone, Default)]
pub struct Profile {
    /// Forward steps taken.
    pub steps: u64,
    /// PD (local-global) iterations over all steps.
    pub iterations: u64,
    /// Steps that stopped at the iteration cap before reaching the tolerance.
    pub unconverged_steps: u64,
    /// Accelerated iterates rejected by the energy guard (the plain PD step was taken).
    pub acceleration_rejections: u64,
    /// Contact steps whose residual-guarded acceleration stalled and finished with plain PD.
    pub acceleration_stalls: u64,
    /// Iterations that took a scaled step `x + a (G(x) - x)`, `a > 1`, to leave a saddle.
    pub escape_steps: u64,
    /// Newton polish (`solver.polish = "newton"`): accepted steps, rejected attempts, their
    /// PCG iterations, and the time spent linearizing and in PCG (the trial's evaluation is
    /// in local and global).
    pub newton_steps: u64,
    pub newton_rejections: u64,
    pub newton_cg_iterations: u64,
    pub newton: Duration,
    /// Semi-smooth contact Newton (`solver.polish = "semismooth"`): accepted steps, rejected
    /// trials and their GMRES iterations (its time is in `newton`).
    pub contact_newton_steps: u64,
    pub contact_newton_rejections: u64,
    pub contact_newton_krylov_iterations: u64,
    pub contact_newton_factorizations: u64,
    /// Local step: projections onto each constraint set and the right-hand side gather.
    pub local: Duration,
    /// Global step: the prefactored sparse solve.
    pub global: Duration,
    /// Numeric refactorizations of the system matrix (only when h, mass or stiffness change).
    pub refactorizations: u64,
    pub refactor: Duration,
    /// Steps solved twice because a node ended inside an obstacle it had no contact with.
    pub redetections: u64,
    /// Collision detection (obstacle queries and the self-collision spatial hash).
    pub detection: Duration,
    /// Per-iteration Signorini-Coulomb contact solves (and forming the Delassus operators).
    pub contact_solve: Duration,
    /// Contact sets that responded through the Delassus operator (see `ContactResponse`).
    pub delassus_builds: u64,
    /// Steps `contact.response = "auto"` switched to the Delassus response.
    pub response_switches: u64,
    /// Contacts at the end of each step, summed over steps, by branch.
    pub contacts_take_off: u64,
    pub contacts_stick: u64,
    pub contacts_slip: u64,
    /// Everything else inside `step` (prediction, acceleration, residuals, bookkeeping).
    pub other: Duration,
    /// Total time inside `step`.
    pub total: Duration,
}

impl Profile {
    /// Named stage times in seconds and counters, for reporting.
    pub fn entries(&self) -> Vec<(&'static str, f64)> {
        vec![
            ("steps", self.steps as f64),
            ("iterations", self.iterations as f64),
            ("unconverged_steps", self.unconverged_steps as f64),
            (
                "acceleration_rejections",
                self.acceleration_rejections as f64,
            ),
            ("acceleration_stalls", self.acceleration_stalls as f64),
            ("escape_steps", self.escape_steps as f64),
            ("newton_steps", self.newton_steps as f64),
            ("newton_rejections", self.newton_rejections as f64),
            ("newton_cg_iterations", self.newton_cg_iterations as f64),
            ("newton_s", self.newton.as_secs_f64()),
            ("contact_newton_steps", self.contact_newton_steps as f64),
            (
                "contact_newton_rejections",
                self.contact_newton_rejections as f64,
            ),
            (
                "contact_newton_krylov_iterations",
                self.contact_newton_krylov_iterations as f64,
            ),
            (
                "contact_newton_factorizations",
                self.contact_newton_factorizations as f64,
            ),
            ("refactorizations", self.refactorizations as f64),
            ("redetections", self.redetections as f64),
            ("local_s", self.local.as_secs_f64()),
            ("global_s", self.global.as_secs_f64()),
            ("refactor_s", self.refactor.as_secs_f64()),
            ("detection_s", self.detection.as_secs_f64()),
            ("contact_s", self.contact_solve.as_secs_f64()),
            ("delassus_builds", self.delassus_builds as f64),
            ("response_switches", self.response_switches as f64),
            ("contacts_take_off", self.contacts_take_off as f64),
            ("contacts_stick", self.contacts_stick as f64),
            ("contacts_slip", self.contacts_slip as f64),
            ("other_s", self.other.as_secs_f64()),
            ("total_s", self.total.as_secs_f64()),
        ]
    }
}

/// Times a closure into a stage accumulator.
#[inline]
pub fn timed<T>(acc: &mut Duration, f: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let out = f();
    *acc += start.elapsed();
    out
}
