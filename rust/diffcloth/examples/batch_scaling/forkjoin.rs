//! The fixed cost of one batch step's parallel call on this machine: `install` on the batch's
//! pool wakes its workers and, at the end, the caller; in a VM a wake-up is an inter-processor
//! interrupt and can take tens of microseconds, paid once per step whatever the batch size.
//! Timed as back-to-back calls (like steps) of `threads` busy-waits of `work_us` each, one
//! per thread: the time over `work_us` is the call's overhead on the critical path.

use std::time::{Duration, Instant};

/// Median and 90th percentile overhead (us) of `calls` calls on a `threads`-thread pool.
pub fn overhead(threads: usize, work_us: u64, calls: usize) -> (f64, f64) {
    use rayon::prelude::*;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let work = Duration::from_micros(work_us);
    let mut over: Vec<f64> = (0..calls)
        .map(|_| {
            let start = Instant::now();
            pool.install(|| {
                (0..threads).into_par_iter().for_each(|_| {
                    let t = Instant::now();
                    while t.elapsed() < work {
                        std::hint::spin_loop();
                    }
                })
            });
            start.elapsed().as_secs_f64() * 1e6 - work_us as f64
        })
        .collect();
    over.sort_by(f64::total_cmp);
    (over[calls / 2], over[calls * 9 / 10])
}
