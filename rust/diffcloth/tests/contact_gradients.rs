//! Analytic gradients through contact against central finite differences: sticking and
//! slipping on planes and a sphere, self-contact, coupled contacts and a closed loop.
use crate::common::*;
use crate::gradient_check::*;
use diffcloth::{AdjointSolver, BackwardOptions, Simulator, Vec3};

/// The shared 4x4 patch against `obstacle` (`common::patch_on_obstacle`), without a polish;
/// the adjoint is the same for both responses (it linearizes the law at the converged step).
fn contact_scene(obstacle: &str, mu: f64, placement: &str, response: &str) -> Simulator {
    patch_on_obstacle(obstacle, mu, placement, response, "none")
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
        check_all_gradients(&mut sim, &base, steps, &ALL_ADJOINT_SOLVERS, 1.0);
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
            .map(|d| 1.0 * downhill + Vec3::new(0.0, 0.0, 0.3) + Vec3::new(0.0, 0.0, d.z))
            .collect();
        let base = contact_rollout(&sim, v0, steps, 0.3, 1e-3);
        check_all_gradients(&mut sim, &base, steps, &ALL_ADJOINT_SOLVERS, 1.0);
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
        check_all_gradients(&mut sim, &base, steps, &ALL_ADJOINT_SOLVERS, 1.0);
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
