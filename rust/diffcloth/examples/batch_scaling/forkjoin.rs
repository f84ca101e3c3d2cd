//! The fixed cost of one batch step's parallel call on this machine: `install` on the batch's
//! pool wakes its workers and, at the end, the caller; in a VM a wake-up is an inter-processor
//! interrupt and can take tens of microseconds, paid once per step whatever the batch size.
//! Timed as calls (like steps) of `threads` busy-waits of `work_us` each, one per thread,
//! separated by `gap_us` of busy work on the calling thread (an env's Python between steps;
//! long enough for idle workers to fall asleep): the time over `work_us` is the call's
//! overhead on the critical path. `caller_works`: the calling thread takes one of the shares
//! itself and the pool has one worker fewer (what `Batch::step` does when members fill the
//! threads).

use std::time::{Duration, Instant};

fn busy(d: Duration) {
    let t = Instant::now();
    while t.elapsed() < d {
        std::hint::spin_loop();
    }
}

/// Median and 90th percentile overhead (us) of `calls` calls on `threads` threads.
pub fn overhead(
    threads: usize,
    work_us: u64,
    gap_us: u64,
    caller_works: bool,
    calls: usize,
) -> (f64, f64) {
    use rayon::prelude::*;
    let workers = if caller_works { threads - 1 } else { threads };
    let pool = (workers > 0).then(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(workers)
            .build()
            .unwrap()
    });
    let work = Duration::from_micros(work_us);
    let gap = Duration::from_micros(gap_us);
    let mut over: Vec<f64> = (0..calls)
        .map(|_| {
            busy(gap);
            let start = Instant::now();
            match (&pool, caller_works) {
                (Some(pool), false) => {
                    pool.install(|| (0..threads).into_par_iter().for_each(|_| busy(work)))
                }
                (Some(pool), true) => pool.in_place_scope(|s| {
                    for _ in 1..threads {
                        s.spawn(|_| busy(work));
                    }
                    busy(work);
                }),
                (None, _) => busy(work),
            }
            start.elapsed().as_secs_f64() * 1e6 - work_us as f64
        })
        .collect();
    over.sort_by(f64::total_cmp);
    (over[calls / 2], over[calls * 9 / 10])
}
