//! What the scheduler saw during a timed run, from `/proc`: the CPU time of this process's
//! threads and their time runnable but waiting for a core (schedstat), and the whole
//! machine's busy time (`/proc/stat`, steal included), so that a run can be labelled with how
//! much of the 2 cores other processes (the other agents) took while it ran.

/// A snapshot: per thread (tid, run ns, wait ns, voluntary context switches), and the
/// machine's busy seconds.
pub struct Snapshot {
    threads: Vec<(u64, u64, u64, u64)>,
    busy: f64,
}

pub struct Usage {
    /// CPU seconds of this process's threads.
    pub cpu: f64,
    /// Seconds this process's threads were runnable but not running.
    pub wait: f64,
    /// CPU seconds all other processes (and the hypervisor's steal) took.
    pub others: f64,
    /// Times this process's threads went to sleep (blocked or parked: each one a wake-up
    /// later); unlike times, a count the other processes' load does not change.
    pub sleeps: u64,
}

pub fn snapshot() -> Snapshot {
    let mut threads = Vec::new();
    for e in std::fs::read_dir("/proc/self/task").unwrap().flatten() {
        let Ok(tid) = e.file_name().to_string_lossy().parse::<u64>() else {
            continue;
        };
        if let Ok(s) = std::fs::read_to_string(e.path().join("schedstat")) {
            let mut f = s.split_whitespace().map(|v| v.parse::<u64>().unwrap_or(0));
            let status = std::fs::read_to_string(e.path().join("status")).unwrap_or_default();
            let voluntary = status
                .lines()
                .find_map(|l| l.strip_prefix("voluntary_ctxt_switches:"))
                .and_then(|v| v.trim().parse().ok())
                .unwrap_or(0);
            threads.push((tid, f.next().unwrap_or(0), f.next().unwrap_or(0), voluntary));
        }
    }
    Snapshot {
        threads,
        busy: machine_busy(),
    }
}

/// Busy CPU seconds of the whole machine since boot: user, nice, system, irq, softirq, steal
/// (USER_HZ = 100 ticks per second; 10 ms resolution).
fn machine_busy() -> f64 {
    let stat = std::fs::read_to_string("/proc/stat").unwrap();
    let line = stat.lines().next().unwrap();
    let f: Vec<u64> = line
        .split_whitespace()
        .skip(1)
        .map(|v| v.parse().unwrap())
        .collect();
    // user nice system idle iowait irq softirq steal
    (f[0] + f[1] + f[2] + f[5] + f[6] + f[7]) as f64 / 100.0
}

/// Usage between two snapshots, over the threads present in both (pools come and go).
pub fn between(a: &Snapshot, b: &Snapshot) -> Usage {
    let (mut cpu, mut wait, mut sleeps) = (0u64, 0u64, 0u64);
    for &(tid, run1, wait1, vol1) in &b.threads {
        if let Some(&(_, run0, wait0, vol0)) = a.threads.iter().find(|t| t.0 == tid) {
            cpu += run1 - run0;
            wait += wait1 - wait0;
            sleeps += vol1 - vol0;
        }
    }
    let (cpu, wait) = (cpu as f64 * 1e-9, wait as f64 * 1e-9);
    Usage {
        cpu,
        wait,
        others: (b.busy - a.busy - cpu).max(0.0),
        sleeps,
    }
}
