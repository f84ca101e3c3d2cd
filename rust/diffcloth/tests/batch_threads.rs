//! A batch on `t` threads starts exactly `t - 1` OS threads: the calling thread is the t-th
//! (a spare pool worker would be woken by rayon every step and compete for a core). Its own
//! test binary, so no other test starts threads meanwhile.
#![cfg(target_os = "linux")]

use diffcloth::{Batch, SceneConfig, Simulator};
use std::path::Path;

fn os_threads() -> usize {
    std::fs::read_dir("/proc/self/task").unwrap().count()
}

#[test]
fn a_batch_on_t_threads_adds_t_minus_one_threads() {
    diffcloth::init_linear_algebra();
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../diffcloth_gym/configs/napkin.toml");
    let template = Simulator::new(&SceneConfig::from_toml_file(&path).unwrap()).unwrap();
    let (model, solver) = (template.model().clone(), template.solver().clone());
    // Kept alive: a dropped pool's workers exit asynchronously.
    let mut batches = Vec::new();
    for threads in [1, 2, 3] {
        let before = os_threads();
        let batch = Batch::with_threads(model.clone(), solver.clone(), 4, threads).unwrap();
        assert_eq!(batch.threads(), threads);
        assert_eq!(os_threads() - before, threads - 1, "{threads} thread(s)");
        batches.push(batch);
    }
}
