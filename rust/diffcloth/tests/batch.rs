//! The batch: members step in parallel on one factorization and each gives bitwise the
//! trajectory of a standalone simulator, whatever the thread count; chaining the one-step
//! adjoint over a recording gives the gradients of the whole-tape backward.
use crate::common::{configs_dir, random_vectors};
use diffcloth::{BackwardOptions, Batch, MemberInput, SceneConfig, Simulator, StepInput, Vec3};

fn hat() -> Simulator {
    diffcloth::init_linear_algebra();
    Simulator::new(&SceneConfig::from_toml_file(&configs_dir().join("hat.toml")).unwrap()).unwrap()
}

/// The hat lowered to 2 cm above the head (the scene starts it 87 cm above), so it lands at
/// once: 139 contacts by step 8.
const DROP: f64 = 2.08;

fn start(sim: &Simulator) -> Vec<Vec3> {
    sim.mesh()
        .positions
        .iter()
        .map(|p| p - Vec3::y() * DROP)
        .collect()
}

/// Member i's targets at step k: the brim handles pulled down along a member-specific
/// direction.
fn targets(sim: &Simulator, i: usize, k: usize) -> Vec<Vec3> {
    let dir = Vec3::new(0.001 * i as f64, -0.003, 0.001 * (3 - i as i64) as f64);
    let x = start(sim);
    sim.model()
        .attachment_nodes()
        .iter()
        .map(|&j| x[j] + dir * k as f64)
        .collect()
}

fn run_batch(batch: &mut Batch, template: &Simulator, steps: usize) -> Vec<Vec<Vec3>> {
    let x0 = start(template);
    batch.for_each_mut(|s| s.reset(Some(&x0), None).unwrap());
    for k in 0..steps {
        let t: Vec<Vec<Vec3>> = (0..batch.len()).map(|i| targets(template, i, k)).collect();
        let inputs: Vec<MemberInput> = t
            .iter()
            .map(|t| MemberInput {
                attachment_targets: Some(t),
                external_forces: None,
            })
            .collect();
        for r in batch.step(&inputs).unwrap() {
            r.unwrap();
        }
    }
    batch.members().map(|s| s.positions().to_vec()).collect()
}

#[test]
fn batch_members_match_standalone_simulators_bitwise_on_one_and_two_threads() {
    let template = hat();
    let (model, solver) = (template.model().clone(), template.solver().clone());
    let steps = 12;
    let expected: Vec<Vec<Vec3>> = (0..4)
        .map(|i| {
            let mut sim = Simulator::from_model(model.clone(), solver.clone());
            sim.reset(Some(&start(&template)), None).unwrap();
            for k in 0..steps {
                let t = targets(&template, i, k);
                sim.step(StepInput {
                    attachment_targets: Some(&t),
                    ..Default::default()
                })
                .unwrap();
            }
            sim.positions().to_vec()
        })
        .collect();
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let got = pool.install(|| {
            let mut batch = Batch::new(model.clone(), solver.clone(), 4).unwrap();
            run_batch(&mut batch, &template, steps)
        });
        assert_eq!(got, expected, "{threads} thread(s)");
        // The same with the batch's own pool, called from the global pool.
        let mut own = Batch::with_threads(model.clone(), solver.clone(), 4, threads).unwrap();
        assert_eq!(own.threads(), threads);
        assert_eq!(
            run_batch(&mut own, &template, steps),
            expected,
            "own pool, {threads} thread(s)"
        );
    }
    for bad in [0, diffcloth::batch::MAX_THREADS + 1] {
        let err = Batch::with_threads(model.clone(), solver.clone(), 2, bad)
            .err()
            .unwrap();
        assert!(err.to_string().contains("threads"), "{err}");
    }
    // One factorization for the template and every member of both batches.
    assert_eq!(model.factorizations(), 1);
}

#[test]
fn a_failing_member_stays_at_its_step_and_the_others_advance() {
    let template = hat();
    let mut batch = Batch::new(template.model().clone(), template.solver().clone(), 2).unwrap();
    let good = targets(&template, 0, 1);
    let bad = vec![Vec3::repeat(1e150); good.len()];
    let before = batch.member(1).unwrap().positions().to_vec();
    let results = batch
        .step(&[
            MemberInput {
                attachment_targets: Some(&good),
                external_forces: None,
            },
            MemberInput {
                attachment_targets: Some(&bad),
                external_forces: None,
            },
        ])
        .unwrap();
    assert!(results[0].is_ok());
    assert!(results[1].is_err());
    assert_eq!(batch.member(0).unwrap().step_count(), 1);
    assert_eq!(batch.member(1).unwrap().step_count(), 0);
    assert_eq!(batch.member(1).unwrap().positions(), &before[..]);
    assert!(batch.step(&[]).is_err(), "wrong input count is refused");
    assert!(Batch::new(template.model().clone(), template.solver().clone(), 0).is_err());
}

#[test]
fn chained_one_step_adjoints_equal_the_whole_tape_backward_with_contact() {
    let template = hat();
    let mut batch = Batch::new(template.model().clone(), template.solver().clone(), 2).unwrap();
    let steps = 8;
    batch.for_each_mut(|s| s.set_recording(true));
    run_batch(&mut batch, &template, steps);
    let n = template.num_nodes();
    let dl_dx: Vec<Vec<Vec3>> = (0..steps)
        .map(|k| random_vectors(n, 1.0, k as u64))
        .collect();
    let dl_dv: Vec<Vec<Vec3>> = (0..steps)
        .map(|k| random_vectors(n, 0.1, 99 + k as u64))
        .collect();
    let options = BackwardOptions {
        tolerance: 1e-12,
        ..Default::default()
    };
    let mut whole = Vec::new();
    for sim in batch.members() {
        assert!(sim.contacts().len() > 0, "the test needs contact");
        whole.push(sim.backward(&dl_dx, &dl_dv, &options).unwrap());
    }
    // Reverse chain: the carry into step k is dL/d(outputs of k) from later steps plus the
    // loss's own gradient on them.
    let mut carry_x = vec![vec![Vec3::zeros(); n]; 2];
    let mut carry_v = carry_x.clone();
    let mut targets_grad = vec![vec![Vec::new(); steps]; 2];
    for k in (0..steps).rev() {
        let gx: Vec<Vec<Vec3>> = carry_x
            .iter()
            .map(|c| c.iter().zip(&dl_dx[k]).map(|(a, b)| a + b).collect())
            .collect();
        let gv: Vec<Vec<Vec3>> = carry_v
            .iter()
            .map(|c| c.iter().zip(&dl_dv[k]).map(|(a, b)| a + b).collect())
            .collect();
        let results = batch.backward_step(k, &gx, &gv, &options).unwrap();
        for (i, r) in results.into_iter().enumerate() {
            let g = r.unwrap();
            carry_x[i] = g.x0;
            carry_v[i] = g.v0;
            targets_grad[i][k] = g.attachment_targets[k].clone();
        }
    }
    let rel = |a: &[Vec3], b: &[Vec3]| {
        let scale = b.iter().map(|p| p.amax()).fold(0.0, f64::max);
        a.iter()
            .zip(b)
            .map(|(p, q)| (p - q).amax())
            .fold(0.0, f64::max)
            / scale
    };
    for i in 0..2 {
        assert!(
            rel(&carry_x[i], &whole[i].x0) < 1e-8,
            "x0: {}",
            rel(&carry_x[i], &whole[i].x0)
        );
        assert!(rel(&carry_v[i], &whole[i].v0) < 1e-8);
        for k in 0..steps {
            let e = rel(&targets_grad[i][k], &whole[i].attachment_targets[k]);
            assert!(e < 1e-8, "targets step {k}: {e}");
        }
    }
    // Errors: a step beyond the tape, wrong shapes.
    let zeros = vec![vec![Vec3::zeros(); n]; 2];
    for r in batch
        .backward_step(steps, &zeros, &zeros, &options)
        .unwrap()
    {
        assert!(r.is_err());
    }
    assert!(batch
        .backward_step(0, &zeros[..1], &zeros, &options)
        .is_err());
}
