//! 2-thread scaling of the batch on the FlyingNapkin env's scene (issue 12): N members of the
//! 10x10 napkin (`napkin.toml`, the env's solver: tolerance 1e-10, cap 2000) driven by fixed
//! pseudo-random per-node forces, timed on 1 and 2 threads interleaved in one process.
//!
//! `cargo run --release --example batch_scaling -- [options]`
//!   --sizes 8,32      batch sizes
//!   --scales 0.1,1,10 force scale, in units of the env's full-scale force (max_accel 20 x mean
//!                     node mass = 0.16 N per component; the env's random actions are scale 1)
//!   --repeats 7       timed episodes per (size, scale, threads)
//!   --steps 100       steps per episode (the env's horizon)
//!   --threads 1,2     thread counts, interleaved (order alternates between repeats)
//!   --seconds S       instead: run 1-thread episodes for S seconds and print the rate (for the
//!                     two-independent-processes ceiling: start two such processes at once)
//!   --spin            instead: a trivially parallel pure-compute loop on 1 and 2 threads
//!   --processes       instead: the machine's ceiling, one 1-thread process of the workload
//!                     alone vs two at once (aggregate rate), alternating, `--repeats` times
//!   --forkjoin        instead: the fixed cost of one parallel call (a step) on 1 and 2 threads
//!   --gap US          busy-wait US microseconds on the calling thread between steps (an env's
//!                     serial Python part; idle workers fall asleep meanwhile), not timed
//!   --install         also time, interleaved, the members stepped the way `Batch::step` did
//!                     before the caller took part (`pool.install` + `par_iter_mut`); the
//!                     thread list's entries then read 1, 2 (Batch) and 1, 2 (install)
//!   --quiet C         also summarize only pairs during which the other processes (the other
//!                     agents, steal included) used less than C cores (default 0.15)
//!
//! Every timed run is labelled with the other processes' CPU use while it ran (`sched.rs`):
//! with 2 cores shared with other agents, only runs they left alone measure our scaling.
//! A counting global allocator reports allocations per step inside the timed loop.
mod episode;
mod forkjoin;
mod imbalance;
mod sched;

use episode::{episode, episode_with, Stepper};

use diffcloth::{Model, Simulator, SolverSettings, Vec3};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

struct Counting;
static ALLOCS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The env's full-scale force per component: max_accel 20 x total mass 0.8 kg / 100 nodes.
const FULL_SCALE: f64 = 20.0 * 0.8 / 100.0;

struct Opts {
    sizes: Vec<usize>,
    scales: Vec<f64>,
    repeats: usize,
    steps: usize,
    threads: Vec<usize>,
    seconds: Option<f64>,
    spin: bool,
    processes: bool,
    forkjoin: bool,
    quiet: f64,
    gap_us: u64,
    install: bool,
}

fn parse() -> Opts {
    let mut o = Opts {
        sizes: vec![8, 32],
        scales: vec![0.1, 1.0, 10.0],
        repeats: 7,
        steps: 100,
        threads: vec![1, 2],
        seconds: None,
        spin: false,
        processes: false,
        forkjoin: false,
        quiet: 0.15,
        gap_us: 0,
        install: false,
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let list = |s: &str| -> Vec<f64> { s.split(',').map(|v| v.parse().unwrap()).collect() };
    let mut i = 0;
    while i < args.len() {
        let v = args.get(i + 1).cloned().unwrap_or_default();
        match args[i].as_str() {
            "--sizes" => o.sizes = list(&v).iter().map(|&x| x as usize).collect(),
            "--scales" => o.scales = list(&v),
            "--repeats" => o.repeats = v.parse().unwrap(),
            "--steps" => o.steps = v.parse().unwrap(),
            "--threads" => o.threads = list(&v).iter().map(|&x| x as usize).collect(),
            "--seconds" => o.seconds = Some(v.parse().unwrap()),
            "--spin" => {
                o.spin = true;
                i -= 1;
            }
            "--processes" => {
                o.processes = true;
                i -= 1;
            }
            "--forkjoin" => {
                o.forkjoin = true;
                i -= 1;
            }
            "--quiet" => o.quiet = v.parse().unwrap(),
            "--gap" => o.gap_us = v.parse().unwrap(),
            "--install" => {
                o.install = true;
                i -= 1;
            }
            a => panic!("unknown argument {a}"),
        }
        i += 2;
    }
    o
}

/// Forces of every step and member, made before timing: `forces[k][i]` (splitmix64 stream).
fn make_forces(n_nodes: usize, size: usize, steps: usize, scale: f64) -> Vec<Vec<Vec<Vec3>>> {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut uniform = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        2.0 * (z >> 11) as f64 / (1u64 << 53) as f64 - 1.0
    };
    let amp = scale * FULL_SCALE;
    (0..steps)
        .map(|_| {
            (0..size)
                .map(|_| {
                    (0..n_nodes)
                        .map(|_| amp * Vec3::new(uniform(), uniform(), uniform()))
                        .collect()
                })
                .collect()
        })
        .collect()
}

fn napkin() -> (Arc<Model>, SolverSettings) {
    diffcloth::init_linear_algebra();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../diffcloth_gym/configs/napkin.toml");
    let sim = Simulator::from_toml_file(&path).unwrap();
    // The env's accuracy rule (engine.py build_scene): tolerance 1e-10, cap 2000.
    let solver = SolverSettings {
        tolerance: 1e-10,
        max_iterations: 2000,
        ..sim.solver().clone()
    };
    (sim.model().clone(), solver)
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)))
}

/// One repeat of the interleaved comparison: each thread count's rate (member-steps/s), CPU
/// us per member-step, waiting fraction, and the most cores other processes took in any of
/// its runs.
struct Repeat {
    rate: Vec<f64>,
    cpu_us: Vec<f64>,
    wait: Vec<f64>,
    /// Cores the process obtained (CPU seconds over wall seconds).
    cores: Vec<f64>,
    /// Times the process's threads went to sleep, per step (a load-independent count).
    sleeps: Vec<f64>,
    others: f64,
}

/// Prints the spread of `repeats` (all, then only those the other processes left alone).
fn summarize(threads: &[usize], repeats: &[Repeat], quiet: f64) {
    let last = threads.len() - 1;
    for (label, set) in [
        ("all", repeats.iter().collect::<Vec<_>>()),
        (
            "quiet",
            repeats.iter().filter(|r| r.others < quiet).collect(),
        ),
    ] {
        if set.is_empty() {
            println!("    {label:5}: none (others' use min {:.2} cores)", {
                min_max(&repeats.iter().map(|r| r.others).collect::<Vec<_>>()).0
            });
            continue;
        }
        for (k, t) in threads.iter().enumerate() {
            let rate: Vec<f64> = set.iter().map(|r| r.rate[k]).collect();
            let cpu: Vec<f64> = set.iter().map(|r| r.cpu_us[k]).collect();
            let wait: Vec<f64> = set.iter().map(|r| r.wait[k]).collect();
            let cores: Vec<f64> = set.iter().map(|r| r.cores[k]).collect();
            let sleeps: Vec<f64> = set.iter().map(|r| r.sleeps[k]).collect();
            let (lo, hi) = min_max(&rate);
            println!(
                "    {label:5} {t} thr: member-steps/s best {hi:7.0} median {:7.0} worst {lo:7.0}; \
                 CPU us/member-step median {:6.1}; cores obtained median {:.2}; waiting for a \
                 core {:4.1} %; thread sleeps per step median {:.2}",
                median(&rate),
                median(&cpu),
                median(&cores),
                100.0 * median(&wait),
                median(&sleeps)
            );
        }
        let ratios: Vec<f64> = set.iter().map(|r| r.rate[last] / r.rate[0]).collect();
        let best = |k: usize| set.iter().map(|r| r.rate[k]).fold(0.0, f64::max);
        let (lo, hi) = min_max(&ratios);
        let inflation: Vec<f64> = set.iter().map(|r| r.cpu_us[last] / r.cpu_us[0]).collect();
        let others: Vec<f64> = set.iter().map(|r| r.others).collect();
        println!(
            "    {label:5} speed-up {}t/{}t over {} repeats: best/best {:.2}x, median {:.2}x \
             [min {lo:.2}, max {hi:.2}]; CPU per member-step {}t/{}t median {:.3} (so \
             {:.2}x had every thread its own core); others' use median {:.2} cores",
            threads[last],
            threads[0],
            set.len(),
            best(last) / best(0),
            median(&ratios),
            threads[last],
            threads[0],
            median(&inflation),
            threads[last] as f64 / threads[0] as f64 / median(&inflation),
            median(&others)
        );
    }
}

fn scaling(o: &Opts) {
    let (model, solver) = napkin();
    println!(
        "napkin: {} nodes; solver tol {:e} cap {}; {} steps/episode; {} repeats; threads {:?}",
        model.num_nodes(),
        solver.tolerance,
        solver.max_iterations,
        o.steps,
        o.repeats,
        o.threads
    );
    for &size in &o.sizes {
        for &scale in &o.scales {
            let forces = make_forces(model.num_nodes(), size, o.steps, scale);
            // Warm-up (first touches, thread start), and the reference for the bitwise check.
            let reference = episode(&model, &solver, 1, &forces);
            let steppers: &[(&str, Stepper)] = if o.install {
                &[("batch", Stepper::Batch), ("install", Stepper::Install)]
            } else {
                &[("batch", Stepper::Batch)]
            };
            let mut all_repeats: Vec<Vec<Repeat>> = steppers.iter().map(|_| Vec::new()).collect();
            let (mut allocs, mut first) = (0.0f64, 0u64);
            for rep in 0..o.repeats {
                for (si, &(label, stepper)) in steppers.iter().enumerate() {
                    let repeats = &mut all_repeats[si];
                    let mut order: Vec<usize> = (0..o.threads.len()).collect();
                    if rep % 2 == 1 {
                        order.reverse();
                    }
                    let n = o.threads.len();
                    let mut r = Repeat {
                        rate: vec![0.0; n],
                        cpu_us: vec![0.0; n],
                        wait: vec![0.0; n],
                        cores: vec![0.0; n],
                        sleeps: vec![0.0; n],
                        others: 0.0,
                    };
                    for &t in &order {
                        let e =
                            episode_with(&model, &solver, o.threads[t], &forces, stepper, o.gap_us);
                        assert!(e.final_x == reference.final_x, "not bitwise identical");
                        allocs = allocs.max(e.allocs_per_step);
                        first = first.max(e.first_step_allocs);
                        let u = &e.usage;
                        r.rate[t] = (size * o.steps) as f64 / e.seconds;
                        r.cpu_us[t] = 1e6 * u.cpu / (size * o.steps) as f64;
                        r.wait[t] = u.wait / (u.wait + u.cpu);
                        r.cores[t] = u.cpu / e.seconds;
                        r.sleeps[t] = u.sleeps as f64 / o.steps as f64;
                        r.others = r.others.max(u.others / e.seconds);
                    }
                    println!(
                    "  rep N={size} scale={scale} {label}: rate {:?} CPU us {:?} cores obtained {:?} \
                     others {:.2} cores",
                    r.rate.iter().map(|x| x.round()).collect::<Vec<_>>(),
                    r.cpu_us.iter().map(|x| x.round()).collect::<Vec<_>>(),
                    r.cores
                        .iter()
                        .map(|x| (x * 100.0).round() / 100.0)
                        .collect::<Vec<_>>(),
                    r.others
                );
                    repeats.push(r);
                }
            }
            let mut its = reference.iterations.clone();
            its.sort();
            let per_step = |x: u64| x as f64 / o.steps as f64;
            println!(
                "N={size:3} scale={scale:5}: PD it/step per member min {:.1} median {:.1} max {:.1} \
                 (mean {:.1}); allocations per whole-batch step after the first {allocs:.2} (first \
                 step {first}; max over runs)",
                per_step(its[0]),
                per_step(its[its.len() / 2]),
                per_step(its[its.len() - 1]),
                its.iter().sum::<u64>() as f64 / (size * o.steps) as f64,
            );
            for (what, c) in [
                ("step time (1 thread)", &reference.costs),
                ("PD iterations", &reference.step_iterations),
            ] {
                let (ideal, in_order, longest) = imbalance::speedups(c);
                let (med, max) = imbalance::spread(c);
                println!(
                    "    tail by {what}: per step max/median member median {med:.2}, worst \
                     {max:.2}; 2-thread bound {ideal:.3}x, list scheduling in order {in_order:.3}x, \
                     longest-predicted-first {longest:.3}x"
                );
            }
            for ((label, _), repeats) in steppers.iter().zip(&all_repeats) {
                println!("  {label} (gap {} us between steps):", o.gap_us);
                summarize(&o.threads, repeats, o.quiet);
            }
        }
    }
}

/// Runs 1-thread episodes for `seconds` and prints "member-steps done, busy seconds, CPU
/// seconds" (one line, for `processes`).
fn solo(o: &Opts, seconds: f64) {
    let (model, solver) = napkin();
    let size = o.sizes[0];
    let forces = make_forces(model.num_nodes(), size, o.steps, o.scales[0]);
    let start = Instant::now();
    let (mut done, mut busy, mut cpu) = (0usize, 0.0, 0.0);
    while start.elapsed().as_secs_f64() < seconds {
        let e = episode(&model, &solver, 1, &forces);
        busy += e.seconds;
        cpu += e.usage.cpu;
        done += size * o.steps;
    }
    println!("{done} {busy} {cpu}");
}

/// The machine's own ceiling: `k` = 1 or 2 independent 1-thread processes of the workload at
/// once, alternating; the aggregate rate of two over one is what two cores give two
/// unrelated processes (no shared memory, no rayon).
fn processes(o: &Opts) {
    let exe = std::env::current_exe().unwrap();
    let seconds = 6.0;
    let run = |k: usize| {
        let before = sched::snapshot();
        let start = Instant::now();
        let children: Vec<_> = (0..k)
            .map(|_| {
                std::process::Command::new(&exe)
                    .args(["--seconds", &seconds.to_string()])
                    .args(["--sizes", &o.sizes[0].to_string()])
                    .args(["--scales", &o.scales[0].to_string()])
                    .stdout(std::process::Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        let (mut rate, mut cpu, mut done) = (0.0, 0.0, 0.0);
        for c in children {
            let out = String::from_utf8(c.wait_with_output().unwrap().stdout).unwrap();
            let f: Vec<f64> = out.split_whitespace().map(|v| v.parse().unwrap()).collect();
            rate += f[0] / f[1];
            done += f[0];
            cpu += f[2];
        }
        let wall = start.elapsed().as_secs_f64();
        // Others: the machine's busy time less our children's CPU (their start-up included
        // in neither, so a small overestimate).
        let others = (sched::between(&before, &sched::snapshot()).others - cpu).max(0.0) / wall;
        (rate, 1e6 * cpu / done, others)
    };
    println!(
        "processes: N={} scale={}, {seconds} s per run, 1 vs 2 independent 1-thread processes",
        o.sizes[0], o.scales[0]
    );
    let mut repeats = Vec::new();
    for rep in 0..o.repeats {
        let mut r = Repeat {
            rate: vec![0.0; 2],
            cpu_us: vec![0.0; 2],
            wait: vec![0.0; 2],
            cores: vec![0.0; 2],
            sleeps: vec![0.0; 2],
            others: 0.0,
        };
        let order = if rep % 2 == 0 { [1, 2] } else { [2, 1] };
        for k in order {
            let (rate, cpu_us, others) = run(k);
            println!("  rep {rep}: {k} process(es): {rate:7.0} member-steps/s, CPU us/member-step {cpu_us:6.1}, others {others:.2} cores");
            r.rate[k - 1] = rate;
            r.cpu_us[k - 1] = cpu_us;
            r.cores[k - 1] = rate * cpu_us * 1e-6;
            r.others = r.others.max(others);
        }
        repeats.push(r);
    }
    summarize(&[1, 2], &repeats, o.quiet);
}

/// `CHAINS` independent multiply-add chains for `iters` rounds: 4 chains are latency-bound
/// (a core's FP ports mostly idle), 16 keep the ports busy; if the 2 vCPUs were hyperthreads
/// of one host core, the second would scale far worse than the first.
fn chains<const CHAINS: usize>(seed: f64, iters: u64) -> f64 {
    let mut a = [0.0; CHAINS];
    for (k, v) in a.iter_mut().enumerate() {
        *v = seed + k as f64;
    }
    for _ in 0..iters {
        for (k, v) in a.iter_mut().enumerate() {
            *v = *v * (0.999_999 - 1e-7 * k as f64) + 1e-7;
        }
    }
    a.iter().sum()
}

/// A trivially parallel pure-compute loop (no memory traffic) on 1 and 2 threads, both chain
/// counts: the cores' own 2-thread ceiling.
fn spin(o: &Opts) {
    type Work = fn(f64) -> f64;
    let kinds: [(&str, Work); 2] = [
        ("latency-bound, 4 chains", |s| chains::<4>(s, 50_000_000)),
        ("port-bound, 16 chains", |s| chains::<16>(s, 12_500_000)),
    ];
    for (name, work) in kinds {
        let mut repeats = Vec::new();
        for rep in 0..o.repeats {
            let mut r = Repeat {
                rate: vec![0.0; 2],
                cpu_us: vec![0.0; 2],
                wait: vec![0.0; 2],
                cores: vec![0.0; 2],
                sleeps: vec![0.0; 2],
                others: 0.0,
            };
            let order = if rep % 2 == 0 { [0, 1] } else { [1, 0] };
            for k in order {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(k + 1)
                    .build()
                    .unwrap();
                let before = sched::snapshot();
                let start = Instant::now();
                let s: f64 = pool.install(|| {
                    use rayon::prelude::*;
                    (0..8).into_par_iter().map(|i| work(i as f64)).sum()
                });
                let wall = start.elapsed().as_secs_f64();
                let u = sched::between(&before, &sched::snapshot());
                std::hint::black_box(s);
                r.rate[k] = 8.0 / wall;
                r.cpu_us[k] = 1e6 * u.cpu / 8.0;
                r.wait[k] = u.wait / (u.wait + u.cpu);
                r.cores[k] = u.cpu / wall;
                r.others = r.others.max(u.others / wall);
            }
            println!(
                "  rep spin {name}: rate {:.2} {:.2} tasks/s, others {:.2} cores",
                r.rate[0], r.rate[1], r.others
            );
            repeats.push(r);
        }
        println!("spin {name}: 8 tasks (rates in tasks/s, 'CPU us' per task)");
        summarize(&[1, 2], &repeats, o.quiet);
    }
}

fn main() {
    let o = parse();
    if o.forkjoin {
        for rep in 0..o.repeats {
            for (work, gap) in [(100, 0), (1000, 0), (1000, 1700)] {
                for caller in [false, true] {
                    let before = sched::snapshot();
                    let start = Instant::now();
                    let one = forkjoin::overhead(1, work, gap, caller, 300);
                    let two = forkjoin::overhead(2, work, gap, caller, 300);
                    let others = sched::between(&before, &sched::snapshot()).others
                        / start.elapsed().as_secs_f64();
                    println!(
                        "  rep {rep} forkjoin work {work} us gap {gap} us caller works {caller}: \
                         overhead per call (median, p90) 1 thread {:.0} {:.0} us, 2 threads {:.0} \
                         {:.0} us; others {others:.2} cores",
                        one.0, one.1, two.0, two.1
                    );
                }
            }
        }
    } else if o.spin {
        spin(&o);
    } else if o.processes {
        processes(&o);
    } else if let Some(s) = o.seconds {
        solo(&o, s);
    } else {
        scaling(&o);
    }
}
