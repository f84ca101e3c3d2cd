//! Load-independent check of the per-step tail: a batch step is one parallel call (every
//! member must finish before the next step starts), so members whose step costs more than
//! the others' leave the second thread idle at the end. From each member's measured step time
//! on one thread (`Profile::total`), this computes the 2-thread makespan of each step under
//! greedy list scheduling (a free thread takes the next member: what rayon's stealing does at
//! best) in index order and in longest-predicted-first order (predicted: the member's
//! previous step), and the speed-up those makespans allow.

/// `costs[k][i]`: member i's time in step k. Returns (ideal, in-order, longest-first)
/// speed-ups: sum of costs over the sum of the steps' 2-thread makespans.
pub fn speedups(costs: &[Vec<f64>]) -> (f64, f64, f64) {
    let total: f64 = costs.iter().flatten().sum();
    let (mut ideal, mut in_order, mut longest) = (0.0, 0.0, 0.0);
    let mut order: Vec<usize> = (0..costs[0].len()).collect();
    for (k, c) in costs.iter().enumerate() {
        let sum: f64 = c.iter().sum();
        let max = c.iter().cloned().fold(0.0, f64::max);
        ideal += (sum / 2.0).max(max);
        in_order += makespan(c, 0..c.len());
        if k > 0 {
            let prev = &costs[k - 1];
            order.sort_by(|&a, &b| prev[b].total_cmp(&prev[a]).then(a.cmp(&b)));
        }
        longest += makespan(c, order.iter().copied());
    }
    (total / ideal, total / in_order, total / longest)
}

/// Two threads, each taking the next member of `order` when free.
fn makespan(cost: &[f64], order: impl Iterator<Item = usize>) -> f64 {
    let mut free = [0.0f64; 2];
    for i in order {
        let t = if free[0] <= free[1] { 0 } else { 1 };
        free[t] += cost[i];
    }
    free[0].max(free[1])
}

/// Per step: the largest member cost over the median, summarized (median, max over steps).
pub fn spread(costs: &[Vec<f64>]) -> (f64, f64) {
    let mut r: Vec<f64> = costs
        .iter()
        .map(|c| {
            let mut s = c.clone();
            s.sort_by(f64::total_cmp);
            s[s.len() - 1] / s[s.len() / 2]
        })
        .collect();
    r.sort_by(f64::total_cmp);
    (r[r.len() / 2], r[r.len() - 1])
}
