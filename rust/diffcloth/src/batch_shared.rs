//! Member-level parallelism of a batch call that the calling thread shares in.
//!
//! A plain `pool.install(par_iter)` hands the whole call to the pool and puts the caller to
//! sleep: per call the caller wakes a worker, that worker wakes the next, and the last one
//! wakes the caller again. Between an env's steps the workers fall asleep (the Python part
//! takes ~1-2 ms), and in this VM every such wake-up is on the critical path. Here the
//! caller works too: it spawns one job per worker of the helpers' pool (which has one worker
//! fewer than the call's threads) and starts on the members at once; every participant takes
//! the next member from a shared counter (greedy list scheduling, one member at a time, so a
//! member with more solver iterations than the others cannot leave a chunk of members stuck
//! behind it on one thread). On one thread nothing is
//! spawned: the call runs on the caller alone.
//!
//! Which thread runs a member does not change its arithmetic (members share only the
//! read-only model), so results are bitwise those of any other schedule.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Applies `f` to every task on the calling thread and one job per worker of `helpers`
/// (none: the caller alone); returns the results in task order.
pub(crate) fn run<T: Send, R: Send>(
    helpers: Option<&rayon::ThreadPool>,
    tasks: Vec<T>,
    f: impl Fn(T) -> R + Sync,
) -> Vec<R> {
    let n = tasks.len();
    let (Some(pool), jobs @ 1..) = (
        helpers,
        helpers.map_or(0, |p| p.current_num_threads().min(n.saturating_sub(1))),
    ) else {
        return tasks.into_iter().map(f).collect();
    };
    // Each slot is taken by exactly one participant (the counter hands out each index
    // once), so the locks are never contended; they only make the hand-over safe.
    let slots: Vec<Mutex<Option<T>>> = tasks.into_iter().map(|t| Mutex::new(Some(t))).collect();
    let results: Vec<Mutex<Option<R>>> = (0..n).map(|_| Mutex::new(None)).collect();
    let next = AtomicUsize::new(0);
    let work = || loop {
        let i = next.fetch_add(1, Ordering::Relaxed);
        if i >= n {
            break;
        }
        let task = lock(&slots[i]).take().expect("each task is taken once");
        let r = f(task);
        *lock(&results[i]) = Some(r);
    };
    pool.in_place_scope(|s| participate(s, jobs, &work));
    results
        .into_iter()
        .map(|r| {
            r.into_inner()
                .unwrap_or_else(|e| e.into_inner())
                .expect("every task ran")
        })
        .collect()
}

/// Spawns `jobs` jobs running `work` and runs it on the calling thread too.
fn participate<'s>(s: &rayon::Scope<'s>, jobs: usize, work: &'s (impl Fn() + Sync)) {
    for _ in 0..jobs {
        s.spawn(move |_| work());
    }
    work();
}

/// The lock's content, also after a panic elsewhere (the scope re-raises that panic).
fn lock<V>(m: &Mutex<V>) -> std::sync::MutexGuard<'_, V> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
