//! Analytic gradients against central finite differences of the whole rollout.
use crate::common::*;
use diffcloth::{AdjointSolver, BackwardOptions, Params, Simulator, StepInput, Vec3};

/// Inputs of a rollout that the gradients are taken with respect to.
#[derive(Clone)]
struct Rollout {
    x0: Vec<Vec3>,
    v0: Vec<Vec3>,
    targets: Vec<Vec<Vec3>>,
    forces: Vec<Vec<Vec3>>,
    params: Params,
    /// Friction of obstacle 0 (contact scenes).
    mu: Option<f64>,
}

/// Loss weights: L = sum_n a_n . x_n + b_n . v_n (linear, so FD truncation error is small).
struct Loss {
    a: Vec<Vec<Vec3>>,
    b: Vec<Vec<Vec3>>,
}

thread_local! {
    static BRANCHES: std::cell::RefCell<Vec<Vec<diffcloth::Branch>>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Set for a loop of redundant contacts: their load split is not unique (the Gauss-Seidel
    /// order decides it), so branch labels may change while no node's motion does; and x0 is
    /// perturbed horizontally only (see the loop test).
    static REDUNDANT_CONTACTS: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// Step of the attachment-target difference (before `eps_factor`); a scene whose loss
    /// curves strongly in the targets sets a smaller one.
    static TARGETS_EPS: std::cell::Cell<f64> = const { std::cell::Cell::new(1e-4) };
}

fn run(sim: &mut Simulator, r: &Rollout, loss: &Loss, record: bool) -> f64 {
    sim.set_params(r.params.clone()).unwrap();
    if let Some(mu) = r.mu {
        sim.set_obstacle_mu(0, mu).unwrap();
    }
    sim.set_recording(record);
    sim.reset(Some(&r.x0), Some(&r.v0)).unwrap();
    let mut total = 0.0;
    for n in 0..r.targets.len() {
        let input = StepInput {
            attachment_targets: (!r.targets[n].is_empty()).then_some(&r.targets[n][..]),
            external_forces: (!r.forces[n].is_empty()).then_some(&r.forces[n][..]),
        };
        let stats = sim.step(input).unwrap();
        assert!(
            stats.residual < 1e-11,
            "forward must converge for the check: {stats:?}"
        );
        // Every perturbed rollout must keep the base rollout's contact branches.
        let branches: Vec<diffcloth::Branch> = sim.contacts().iter().map(|c| c.branch).collect();
        BRANCHES.with(|b| {
            let mut b = b.borrow_mut();
            if record {
                b.push(branches);
            } else if !REDUNDANT_CONTACTS.with(|c| c.get()) {
                assert_eq!(
                    b[n], branches,
                    "a perturbation switched a contact branch at step {n}"
                );
            }
        });
        total += sim
            .positions()
            .iter()
            .zip(&loss.a[n])
            .map(|(x, a)| x.dot(a))
            .sum::<f64>();
        total += sim
            .velocities()
            .iter()
            .zip(&loss.b[n])
            .map(|(v, b)| v.dot(b))
            .sum::<f64>();
    }
    total
}

fn dot(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

/// Relative agreement, with an absolute floor for gradients that vanish (e.g. everything but
/// x0 when every node sticks: the positions are then fixed by x_n and the obstacle).
fn check(name: &str, analytic: f64, fd: f64) {
    let err = (analytic - fd).abs() / fd.abs().max(analytic.abs()).max(1e-3);
    assert!(
        err < 1e-5,
        "{name}: analytic {analytic:.10e} vs fd {fd:.10e} (rel {err:.1e})"
    );
}

/// Checks every gradient group by a directional central difference.
fn check_all_gradients(
    sim: &mut Simulator,
    base: &Rollout,
    steps: usize,
    solvers: &[AdjointSolver],
    eps_factor: f64,
) {
    let strict_fixed_point = base.mu.is_none();
    let n = sim.num_nodes();
    let loss = Loss {
        a: (0..steps)
            .map(|k| random_vectors(n, 1.0, 100 + k as u64))
            .collect(),
        b: (0..steps)
            .map(|k| random_vectors(n, 0.1, 200 + k as u64))
            .collect(),
    };
    BRANCHES.with(|b| b.borrow_mut().clear());
    run(sim, base, &loss, true);
    let mut reference = None;
    for &solver in solvers {
        let g = sim
            .backward(
                &loss.a,
                &loss.b,
                &BackwardOptions {
                    solver,
                    tolerance: 1e-10,
                    max_iterations: 2000,
                },
            )
            .unwrap();
        // The paper's fixed-point iteration may legitimately diverge (spectral radius >= 1,
        // e.g. with sticking contact) and fall back; the other solvers must not.
        if solver != AdjointSolver::FixedPoint || !strict_fixed_point {
            assert!(
                solver == AdjointSolver::FixedPoint || g.steps.iter().all(|s| !s.fell_back),
                "{solver:?} fell back: {:?}",
                g.steps
            );
        } else {
            assert!(
                g.steps.iter().all(|s| !s.fell_back),
                "{solver:?} fell back: {:?}",
                g.steps
            );
        }
        match &reference {
            None => reference = Some(g),
            Some(r) => {
                let rel = |a: &[Vec3], b: &[Vec3]| {
                    a.iter()
                        .zip(b)
                        .map(|(x, y)| (x - y).norm_squared())
                        .sum::<f64>()
                        .sqrt()
                        / b.iter()
                            .map(|y| y.norm_squared())
                            .sum::<f64>()
                            .sqrt()
                            .max(1e-3)
                };
                assert!(
                    rel(&g.v0, &r.v0) < 1e-6,
                    "{solver:?} vs first solver: {} (residuals {:?} vs {:?})",
                    rel(&g.v0, &r.v0),
                    g.steps.iter().map(|s| s.residual).collect::<Vec<_>>(),
                    r.steps.iter().map(|s| s.residual).collect::<Vec<_>>()
                );
                assert!(rel(&g.x0, &r.x0) < 1e-6);
            }
        }
    }
    let g = reference.unwrap();
    let effects = sim.effects();
    let masses = sim.masses().to_vec();
    // Step sizes: large enough that the forward solve's remaining error (the FD noise floor)
    // is negligible, small enough that curvature does not matter (checked by sweeping eps).
    let mut fd = |eps: f64, perturb: &dyn Fn(&mut Rollout, f64)| {
        let eps = eps * eps_factor;
        let (mut p, mut m) = (base.clone(), base.clone());
        perturb(&mut p, eps);
        perturb(&mut m, -eps);
        (run(sim, &p, &loss, false) - run(sim, &m, &loss, false)) / (2.0 * eps)
    };
    let mut dx = random_vectors(n, 1.0, 7);
    if REDUNDANT_CONTACTS.with(|c| c.get()) {
        dx.iter_mut().for_each(|d| d.y = 0.0);
    }
    check(
        "x0",
        dot(&g.x0, &dx),
        fd(1e-5, &|r, e| {
            r.x0.iter_mut().zip(&dx).for_each(|(x, d)| *x += e * d)
        }),
    );
    check(
        "v0",
        dot(&g.v0, &dx),
        fd(1e-3, &|r, e| {
            r.v0.iter_mut().zip(&dx).for_each(|(v, d)| *v += e * d)
        }),
    );
    if !base.targets[0].is_empty() {
        let dt: Vec<Vec<Vec3>> = (0..steps)
            .map(|k| random_vectors(base.targets[0].len(), 1.0, 300 + k as u64))
            .collect();
        let analytic: f64 = (0..steps)
            .map(|k| dot(&g.attachment_targets[k], &dt[k]))
            .sum();
        check(
            "attachment targets",
            analytic,
            fd(TARGETS_EPS.with(|e| e.get()), &|r, e| {
                for (t, d) in r.targets.iter_mut().zip(&dt) {
                    t.iter_mut().zip(d).for_each(|(x, dd)| *x += e * dd);
                }
            }),
        );
        let ka = base.params.k_attach;
        check(
            "k_attach",
            g.k_attach * ka,
            // 1e-3: at 1e-4 the forward's 1e-13 m stopping error (loss noise ~5e-8) already
            // costs 1e-5 here; the truncation error at 1e-3 is ~1e-6 (swept 1e-2..1e-6).
            fd(1e-3, &|r, e| r.params.k_attach += e * ka),
        );
    }
    if !base.forces[0].is_empty() {
        // Force directions scaled by the node masses: equal accelerations on every node.
        let df: Vec<Vec<Vec3>> = (0..steps)
            .map(|k| {
                random_vectors(n, 1.0, 400 + k as u64)
                    .iter()
                    .zip(&masses)
                    .map(|(d, m)| d * (*m / 0.01))
                    .collect()
            })
            .collect();
        let analytic: f64 = (0..steps).map(|k| dot(&g.external_forces[k], &df[k])).sum();
        check(
            "external forces",
            analytic,
            fd(1e-4, &|r, e| {
                for (f, d) in r.forces.iter_mut().zip(&df) {
                    f.iter_mut().zip(d).for_each(|(x, dd)| *x += e * dd);
                }
            }),
        );
    }
    let scale = |v: f64| v.abs().max(1.0);
    // k_bend is perturbed relative to itself, as k_attach and density are: scenes use values
    // far below 1 (0.005 here), where a unit scale made a 1e-4 step a 2 % change and the
    // check measured the loss's curvature in k_bend (rel 1.3e-3), not the gradient.
    let (ks, kb, rho) = (
        scale(base.params.k_stretch),
        base.params.k_bend,
        base.params.density,
    );
    check(
        "k_stretch",
        g.k_stretch * ks,
        fd(1e-4, &|r, e| r.params.k_stretch += e * ks),
    );
    if effects.bend {
        check(
            "k_bend",
            g.k_bend * kb,
            fd(1e-4, &|r, e| r.params.k_bend += e * kb),
        );
    }
    check(
        "density",
        g.density * rho,
        fd(1e-4, &|r, e| r.params.density += e * rho),
    );
    if effects.gravity {
        let dg = Vec3::new(0.3, -1.0, 0.2);
        check(
            "gravity",
            g.gravity.dot(&dg),
            fd(1e-3, &|r, e| r.params.gravity += e * dg),
        );
    }
    if let Some(mu) = base.mu {
        check(
            "mu",
            g.mu_obstacles[0] * mu,
            fd(1e-4, &|r, e| r.mu = Some(mu * (1.0 + e))),
        );
    }
    if effects.wind {
        let dd = Vec3::new(0.5, 0.1, -0.7);
        let om = scale(base.params.wind_omega);
        check(
            "wind direction",
            g.wind_direction.dot(&dd),
            fd(1e-3, &|r, e| r.params.wind_direction += e * dd),
        );
        check(
            "wind omega",
            g.wind_omega * om,
            fd(1e-4, &|r, e| r.params.wind_omega += e * om),
        );
        check(
            "wind phi",
            g.wind_phi,
            fd(1e-3, &|r, e| r.params.wind_phi += e),
        );
    }
}

#[test]
fn gradients_match_finite_differences_without_contact() {
    let mut sim = sim_from_toml(
        r#"
h = 0.01
effects = ["gravity", "stretch", "bend", "attachments", "wind", "external_forces"]
[mesh]
kind = "grid"
rows = 5
cols = 5
width = 1.0
height = 1.0
plane = "xy"
[material]
density = 0.2
k_stretch = 80.0
# A quarter of the 0.02 this test used with the per-vertex model (the edge model stores
# 3-4.5x its energy in the same bend).
k_bend = 0.005
strain_limits = [1.0, 1.0]
[attachments]
stiffness = 500.0
select = "top_corners"
[wind]
direction = [0.1, 0.0, 0.4]
omega = 5.0
phi = 0.3
# A fixed iteration count (no stopping test), as for the garments below: a tolerance of 1e-13
# let the +eps and -eps rollouts stop at different iterations, loss noise ~1e-10, which cost
# the small wind-omega gradient 1.6e-4 (3.5e-4 at eps/3, 1.9e-3 at eps/10: noise). 150
# Anderson iterations reach machine precision (the stopping test needed ~33); errors < 1e-6.
[solver]
tolerance = 0.0
max_iterations = 150
"#,
    );
    let steps = 12;
    let n = sim.num_nodes();
    let t0 = sim.attachment_targets().to_vec();
    let base = Rollout {
        x0: sim
            .positions()
            .iter()
            .zip(random_vectors(n, 0.02, 1))
            .map(|(x, d)| x + d)
            .collect(),
        v0: random_vectors(n, 0.5, 2),
        targets: (0..steps)
            .map(|k| {
                t0.iter()
                    .map(|t| t + Vec3::new(0.01, 0.02, 0.03) * k as f64)
                    .collect()
            })
            .collect(),
        forces: (0..steps)
            .map(|k| random_vectors(n, 0.01, 50 + k as u64))
            .collect(),
        params: sim.params().clone(),
        mu: None,
    };
    check_all_gradients(
        &mut sim,
        &base,
        steps,
        &[
            AdjointSolver::Direct,
            AdjointSolver::Krylov,
            AdjointSolver::FixedPoint,
        ],
        1.0,
    );
}

/// A shipped garment scene without its contact effects, solved with a fixed iteration count.
fn contact_free_garment(name: &str, iterations: usize) -> Simulator {
    let mut cfg = contact_free_config(name);
    // A fixed iteration count (no stopping test): the solution is then a smooth function of
    // the inputs, which keeps the finite differences free of stopping-rule noise.
    cfg.solver.tolerance = 0.0;
    cfg.solver.max_iterations = iterations;
    Simulator::new(&cfg).unwrap()
}

/// A garment rollout from random initial velocities (0.3 m/s, `seed`) with the handles moving
/// by `drift` per step.
fn garment_rollout(sim: &Simulator, steps: usize, seed: u64, drift: Vec3) -> Rollout {
    let t0 = sim.attachment_targets().to_vec();
    Rollout {
        x0: sim.positions().to_vec(),
        v0: random_vectors(sim.num_nodes(), 0.3, seed),
        targets: (0..steps)
            .map(|k| t0.iter().map(|t| t + drift * k as f64).collect())
            .collect(),
        forces: vec![Vec::new(); steps],
        params: sim.params().clone(),
        mu: None,
    }
}

/// The hat's curved rest shape makes the bending projection Jacobian non-zero.
#[test]
fn gradients_match_finite_differences_on_the_hat() {
    // 2000 iterations: with the paper's k_bend 120 in the edge model, 600 stop at updates of
    // 1e-14..3e-14 in the last steps, and that remaining error alone cost density 1.4e-4 and
    // gravity 2.8e-5 (growing as eps shrinks: noise, not truncation); at 2000 both are < 1e-6.
    let mut sim = contact_free_garment("hat", 2000);
    // The loss curves in the targets (the stiff hat pulled by two handles): at eps 1e-4 the
    // central difference is off by 2.4e-4, falling as eps^2 (3.5e-3 at 3e-4, 1.8e-5 at 3e-5);
    // at 1e-5 the error is 2e-8.
    TARGETS_EPS.with(|e| e.set(1e-5));
    let steps = 6;
    let base = garment_rollout(&sim, steps, 5, Vec3::new(0.0, 0.02, 0.0));
    check_all_gradients(
        &mut sim,
        &base,
        steps,
        &[AdjointSolver::Direct, AdjointSolver::Krylov],
        1.0,
    );
}

/// A 4x4 cloth on an obstacle with friction; `v0` chosen so one branch holds everywhere.
/// A 4x4 patch against `obstacle`. `response`: how the forward solves the contact law; the
/// adjoint is the same for both (it linearizes the law at the converged step).
fn contact_scene(obstacle: &str, mu: f64, placement: &str, response: &str) -> Simulator {
    sim_from_toml(&format!(
        r#"
h = 0.01
effects = ["gravity", "stretch", "obstacle_contact", "friction", "external_forces"]
[mesh]
kind = "grid"
rows = 4
cols = 4
width = 0.3
height = 0.3
plane = "xz"
[placement]
{placement}
[material]
density = 0.2
k_stretch = 60.0
[contact]
thickness = 0.01
response = "{response}"
[[obstacles]]
mu = {mu}
shape = {obstacle}
[solver]
tolerance = 0.0
max_iterations = 300
"#
    ))
}

fn contact_rollout(sim: &Simulator, v0: Vec<Vec3>, steps: usize, mu: f64, force: f64) -> Rollout {
    let n = sim.num_nodes();
    Rollout {
        x0: sim.positions().to_vec(),
        v0,
        targets: vec![Vec::new(); steps],
        forces: (0..steps)
            .map(|k| random_vectors(n, force, 60 + k as u64))
            .collect(),
        params: sim.params().clone(),
        mu: Some(mu),
    }
}

fn incline(theta_deg: f64) -> (String, String, Vec3, Vec3) {
    let t = theta_deg.to_radians();
    let n = Vec3::new(-t.sin(), t.cos(), 0.0);
    let downhill = Vec3::new(-t.cos(), -t.sin(), 0.0);
    let shape = format!(
        r#"{{ kind = "plane", point = [0.0, 0.0, 0.0], normal = [{}, {}, 0.0] }}"#,
        n.x, n.y
    );
    let placement = format!(
        "rotate_deg = [0.0, 0.0, {theta_deg}]\ntranslate = [{}, {}, 0.0]",
        0.01 * n.x,
        0.01 * n.y
    );
    (shape, placement, n, downhill)
}

#[test]
fn gradients_through_sticking_contact_match_finite_differences() {
    for response in ["inertia", "delassus"] {
        let (shape, placement, _, _) = incline(20.0);
        let mut sim = contact_scene(&shape, 0.6, &placement, response);
        let steps = 10;
        let base = contact_rollout(&sim, vec![Vec3::zeros(); sim.num_nodes()], steps, 0.6, 1e-4);
        check_all_gradients(
            &mut sim,
            &base,
            steps,
            &[
                AdjointSolver::Direct,
                AdjointSolver::Krylov,
                AdjointSolver::FixedPoint,
            ],
            1.0,
        );
        assert!(sim
            .contacts()
            .iter()
            .all(|c| c.branch == diffcloth::Branch::Stick));
    }
}

#[test]
fn gradients_through_slipping_contact_match_finite_differences() {
    for response in ["inertia", "delassus"] {
        let (shape, placement, _, downhill) = incline(40.0);
        let mut sim = contact_scene(&shape, 0.3, &placement, response);
        let steps = 10;
        let n = sim.num_nodes();
        // Sliding downhill and slightly sideways, with some spread between nodes.
        let v0: Vec<Vec3> = random_vectors(n, 0.05, 9)
            .iter()
            .map(|d| {
                1.0 * downhill
                    + Vec3::new(0.0, 0.0, 0.3)
                    + Vec3::new(d.x, d.y, d.z) * 0.0
                    + Vec3::new(0.0, 0.0, d.z)
            })
            .collect();
        let base = contact_rollout(&sim, v0, steps, 0.3, 1e-3);
        check_all_gradients(
            &mut sim,
            &base,
            steps,
            &[
                AdjointSolver::Direct,
                AdjointSolver::Krylov,
                AdjointSolver::FixedPoint,
            ],
            1.0,
        );
        assert!(sim
            .contacts()
            .iter()
            .all(|c| c.branch == diffcloth::Branch::Slip));
    }
}

/// On a sphere the contact frame depends on x_n (normal and gap): the frame terms.
#[test]
fn gradients_through_slipping_contact_on_a_sphere_match_finite_differences() {
    for response in ["inertia", "delassus"] {
        let shape = r#"{ kind = "sphere", center = [0.0, 0.0, 0.0], radius = 1.0 }"#;
        let mut sim = contact_scene(shape, 0.2, "translate = [0.2, 1.01, 0.1]", response);
        let steps = 3;
        let n = sim.num_nodes();
        let v0: Vec<Vec3> = random_vectors(n, 0.05, 4)
            .iter()
            .map(|d| Vec3::new(0.8, -0.1, 0.3) + d)
            .collect();
        let base = contact_rollout(&sim, v0, steps, 0.2, 1e-3);
        check_all_gradients(
            &mut sim,
            &base,
            steps,
            &[
                AdjointSolver::Direct,
                AdjointSolver::Krylov,
                AdjointSolver::FixedPoint,
            ],
            1.0,
        );
        let active = sim
            .contacts()
            .iter()
            .filter(|c| c.branch == diffcloth::Branch::Slip)
            .count();
        assert!(active >= 2, "nodes slide over the sphere: {active}");
    }
}

/// Writes two separate 0.3 m squares (nodes 0-3 at `bottom`, 4-7 at `top`) as an OBJ file in
/// a fresh temporary folder; returns (folder, file).
fn two_squares_obj(tag: &str, bottom: f64, top: f64) -> (std::path::PathBuf, std::path::PathBuf) {
    squares_obj(tag, [Vec3::new(0.0, bottom, 0.0), Vec3::new(0.0, top, 0.0)])
}

/// Two separate 0.3 m squares (two triangles each) in the xz plane, shifted by `offsets`.
fn squares_obj(tag: &str, offsets: [Vec3; 2]) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("diffcloth_{tag}_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let obj = dir.join("two_squares.obj");
    let mut text = String::new();
    for o in offsets {
        for (x, z) in [(0.0, 0.0), (0.3, 0.0), (0.3, 0.3), (0.0, 0.3)] {
            text += &format!("v {} {} {}\n", x + o.x, o.y, z + o.z);
        }
    }
    text += "f 1 2 3\nf 1 3 4\nf 5 6 7\nf 5 7 8\n";
    std::fs::write(&obj, text).unwrap();
    (dir, obj)
}

/// Self-contact: a square sliding over another square held by springs. Each top node touches
/// the node below it (pair normal from their separation) and slips.
#[test]
fn gradients_through_self_contact_match_finite_differences() {
    // Bottom square at y = 0, top square at y = 0.062 (contact radius 0.06).
    let (dir, obj) = two_squares_obj("pairs", 0.0, 0.062);
    let mut sim = sim_from_toml(&format!(
        r#"
h = 0.01
effects = ["stretch", "attachments", "self_collision", "friction", "external_forces"]
[mesh]
kind = "obj"
path = "{}"
[material]
density = 0.2
k_stretch = 30.0
[attachments]
stiffness = 2000.0
nodes = [0, 1, 2, 3]
[self_collision]
radius = 0.06
mu = 0.1
[contact]
margin = 0.01
[solver]
tolerance = 0.0
max_iterations = 300
"#,
        obj.display()
    ));
    let steps = 4;
    let n = sim.num_nodes();
    let v0: Vec<Vec3> = (0..n)
        .map(|i| {
            if i >= 4 {
                Vec3::new(0.5, -0.8, 0.2)
            } else {
                Vec3::zeros()
            }
        })
        .collect();
    let mut base = contact_rollout(&sim, v0, steps, 0.1, 1e-4);
    base.mu = None; // no obstacle: the self mu is checked below
                    // Targets given explicitly (reset() would move them with a perturbed x0).
    base.targets = vec![sim.attachment_targets().to_vec(); steps];
    check_all_gradients(
        &mut sim,
        &base,
        steps,
        &[AdjointSolver::Direct, AdjointSolver::Krylov],
        1.0,
    );
    // The self-contact friction gradient against a finite difference.
    let loss = Loss {
        a: (0..steps)
            .map(|k| random_vectors(n, 1.0, 100 + k as u64))
            .collect(),
        b: (0..steps)
            .map(|k| random_vectors(n, 0.1, 200 + k as u64))
            .collect(),
    };
    run(&mut sim, &base, &loss, true);
    let slips: usize = sim
        .tape()
        .unwrap()
        .records()
        .iter()
        .map(|r| {
            r.contacts
                .iter()
                .filter(|c| c.branch == diffcloth::Branch::Slip)
                .count()
        })
        .sum();
    assert!(
        slips >= 4,
        "the top nodes slip on the nodes below: {slips} slip contacts"
    );
    let g = sim
        .backward(
            &loss.a,
            &loss.b,
            &BackwardOptions {
                solver: AdjointSolver::Direct,
                tolerance: 1e-10,
                max_iterations: 500,
            },
        )
        .unwrap();
    let eps = 1e-4;
    let mut at = |mu: f64| {
        sim.set_self_mu(mu).unwrap();
        let l = run(&mut sim, &base, &loss, false);
        sim.set_self_mu(0.1).unwrap();
        l
    };
    let fd = (at(0.1 * (1.0 + eps)) - at(0.1 * (1.0 - eps))) / (2.0 * eps);
    check("self mu", g.mu_self * 0.1, fd);
    std::fs::remove_dir_all(&dir).ok();
}

/// The sock: a closed tube with a heel bend (curved rest shape), held at its four rim handles.
#[test]
fn gradients_match_finite_differences_on_the_sock() {
    let mut sim = contact_free_garment("sock", 400);
    let steps = 4;
    let base = garment_rollout(&sim, steps, 15, Vec3::new(0.0, 0.01, 0.02));
    check_all_gradients(
        &mut sim,
        &base,
        steps,
        &[AdjointSolver::Direct, AdjointSolver::Krylov],
        1.0,
    );
}

/// The squares of `obj` over a floor (friction `floor_mu`) with self-contact (radius 0.06,
/// friction `self_mu`), gravity and external forces; fixed iteration count.
fn squares_on_a_floor(obj: &std::path::Path, floor_mu: f64, self_mu: f64) -> Simulator {
    sim_from_toml(&format!(
        r#"
h = 0.01
effects = ["gravity", "stretch", "obstacle_contact", "self_collision", "friction", "external_forces"]
[mesh]
kind = "obj"
path = "{}"
[material]
density = 0.2
k_stretch = 30.0
[[obstacles]]
mu = {floor_mu}
shape = {{ kind = "plane", point = [0.0, 0.0, 0.0], normal = [0.0, 1.0, 0.0] }}
[self_collision]
radius = 0.06
mu = {self_mu}
[contact]
thickness = 0.01
margin = 0.01
[solver]
tolerance = 0.0
max_iterations = 300
"#,
        obj.display()
    ))
}

/// Nodes in two contacts at once: the bottom square rests on a sticky plane while the top one
/// slides over it, so each bottom node has an obstacle contact and a self-contact pair, solved
/// jointly (projected Gauss-Seidel) and linearized jointly in the adjoint.
#[test]
fn gradients_through_coupled_contacts_match_finite_differences() {
    let (dir, obj) = two_squares_obj("coupled", 0.01, 0.072);
    let mut sim = squares_on_a_floor(&obj, 1.0, 0.1);
    let steps = 3;
    let n = sim.num_nodes();
    let v0: Vec<Vec3> = (0..n)
        .map(|i| {
            if i >= 4 {
                Vec3::new(0.5, -0.8, 0.2)
            } else {
                Vec3::zeros()
            }
        })
        .collect();
    let base = contact_rollout(&sim, v0, steps, 1.0, 1e-5);
    check_all_gradients(
        &mut sim,
        &base,
        steps,
        &[AdjointSolver::Direct, AdjointSolver::Krylov],
        1.0,
    );
    // Some node really had two active contacts in one recorded step.
    let loss = Loss {
        a: vec![vec![Vec3::zeros(); n]; steps],
        b: vec![vec![Vec3::zeros(); n]; steps],
    };
    run(&mut sim, &base, &loss, true);
    let coupled = sim.tape().unwrap().records().iter().any(|r| {
        let mut count = vec![0; n];
        for c in r
            .contacts
            .iter()
            .filter(|c| c.branch != diffcloth::Branch::TakeOff)
        {
            match c.kind {
                diffcloth::ContactKind::Obstacle { node, .. } => count[node] += 1,
                diffcloth::ContactKind::SelfPair { a, b } => {
                    count[a] += 1;
                    count[b] += 1;
                }
            }
        }
        count.iter().any(|&k| k >= 2)
    });
    assert!(
        coupled,
        "no node had two active contacts: the test would not exercise the coupling"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A closed loop of contacts: two squares side by side on a frictionless floor slide into
/// each other and their facing nodes stick together. The floor's normals and the sticking pair
/// both fix the facing nodes' vertical motion, so those impulses are redundant (not unique;
/// only each node's total is) and the contact group's linearization is singular. The
/// gradients still match finite differences.
#[test]
fn gradients_through_a_loop_of_sticking_contacts_match_finite_differences() {
    // Facing edges 0.06 apart (the contact radius), both squares on the floor (gap 0).
    let (dir, obj) = squares_obj(
        "loop",
        [Vec3::new(0.0, 0.01, 0.0), Vec3::new(0.36, 0.01, 0.0)],
    );
    let mut sim = squares_on_a_floor(&obj, 0.0, 5.0);
    let steps = 2;
    let n = sim.num_nodes();
    let v0: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(if i < 4 { 0.05 } else { -0.05 }, -0.1, 0.0))
        .collect();
    let base = contact_rollout(&sim, v0, steps, 0.0, 1e-5);
    // Perturbations move the facing nodes' vertical load between floor and pair (a floor
    // contact may even read "take off"): labels change, forces on the nodes do not. Raising
    // one facing node above the other is a kink, though: the pair (sticking) then lifts it off
    // the floor on one side and presses it on the other, and x0 has no derivative in that
    // direction here. Hence x0 is perturbed horizontally; every gradient must match to 1e-5.
    REDUNDANT_CONTACTS.with(|c| c.set(true));
    check_all_gradients(
        &mut sim,
        &base,
        steps,
        &[AdjointSolver::Direct, AdjointSolver::Krylov],
        1.0,
    );
    let loss = Loss {
        a: vec![vec![Vec3::zeros(); n]; steps],
        b: vec![vec![Vec3::zeros(); n]; steps],
    };
    REDUNDANT_CONTACTS.with(|c| c.set(false));
    run(&mut sim, &base, &loss, true);
    let pushing = |c: &&diffcloth::Contact| c.branch != diffcloth::Branch::TakeOff;
    let looped = sim.tape().unwrap().records().iter().any(|r| {
        let floor: Vec<usize> = r
            .contacts
            .iter()
            .filter(pushing)
            .filter_map(|c| match c.kind {
                diffcloth::ContactKind::Obstacle { node, .. } => Some(node),
                _ => None,
            })
            .collect();
        r.contacts.iter().any(|c| {
            c.branch == diffcloth::Branch::Stick
                && matches!(c.kind, diffcloth::ContactKind::SelfPair { a, b } if floor.contains(&a) && floor.contains(&b))
        })
    });
    assert!(
        looped,
        "no pair stuck with both nodes stuck to the floor: no loop to test"
    );
    std::fs::remove_dir_all(&dir).ok();
}
