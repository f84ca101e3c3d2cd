"""Env throughput: what an RL or gradient user gets per second from each env.

Per env, with random actions in the action box:
- ``single``: a single env's steps/s;
- ``vector``: env steps/s of the Gymnasium vector env at N = 1, 2, 8, 32, on 1 and 2 threads
  (two vector envs in one process, each on a thread pool of its own: ``threads=1`` and
  ``threads=2``, timed alternately so both see the same machine load), the 2-thread speed-up
  (target: >= 1.8x at the larger N), and the same for the Rust batch step alone (the time
  inside ``Batch.step``; the rest is Python: actions, observations, rewards);
- ``step_grad``: forward + backward steps/s of a closed-loop differentiable rollout, and its
  cost relative to a plain step at the same accuracy (the env's steps are gradient-grade by
  construction; target <= 2.5x), plus the tape memory of the episode per member;
- ``render``: ``rgb_array`` frames/s at 480x480 (when the renderer is installed).

Every ratio is measured within one run (the machine is shared and noisy); each figure is the
best of ``--repeats`` timings. The vector rows' 1/2-thread pairs are labelled with the other
processes' CPU use (``machine_load``: the scheduler shares the cores between sessions, so a
2-thread speed-up is only ours when the others leave the cores idle); ``--quiet-wait S`` keeps
timing pairs for up to S seconds per size until ``--repeats`` quiet ones are found. Writes
benchmarks/results/env_throughput.{json,md} (or ``--out-dir``).

Run: python -m benchmarks env_throughput [--quick] [--envs Hat-v0 ...] [--measures vector]
     [--sizes 8 32] [--steps 100] [--quiet-wait 300] [--out-dir DIR]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from benchmarks import machine_load, results_io

ENV_IDS = ["DiffCloth/Hat-v0", "DiffCloth/Sock-v0", "DiffCloth/FlyingNapkin-v0"]
SIZES = [1, 2, 8, 32]


def best_of(repeats: int, fn) -> float:
    """The smallest wall time of ``repeats`` calls of ``fn`` (seconds)."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


class _TimedBatch:
    """Forwards to a ``_core.Batch`` and adds up the wall time of its ``step`` calls."""

    def __init__(self, batch):
        self._batch, self.seconds = batch, 0.0

    def __getattr__(self, name):
        return getattr(self._batch, name)

    def step(self, **kwargs):
        t = time.perf_counter()
        try:
            return self._batch.step(**kwargs)
        finally:
            self.seconds += time.perf_counter() - t


def vector_rates(env_id: str, n: int, steps: int, repeats: int, quiet_wait: float = 0.0) -> dict:
    """Env steps/s of the vector env with ``n`` members on 1 and 2 threads, and the same for
    the batch step alone. Timed in pairs (1 and 2 threads back to back, the order alternating;
    each after one untimed warm-up step), every timing labelled with the other processes' CPU
    use (``machine_load``). The figures are the best of the quiet pairs (others below
    ``QUIET_CORES`` in both timings) when there are any, else of all pairs; after ``repeats``
    pairs, more are timed for up to ``quiet_wait`` seconds until ``repeats`` are quiet."""
    import gymnasium as gym

    import diffcloth_gym  # noqa: F401

    venvs = {t: gym.make_vec(env_id, num_envs=n, threads=t) for t in (1, 2)}
    space = venvs[1].single_action_space
    actions = np.random.default_rng(0).uniform(space.low, space.high, (steps + 1, n, space.shape[0]))

    def run(t: int) -> tuple[float, float, float]:
        venv = venvs[t]
        engine = venv.unwrapped.engine
        venv.reset(seed=0)
        venv.step(actions[0])
        timed = engine.batch = _TimedBatch(getattr(engine.batch, "_batch", engine.batch))

        def episode():
            for k in range(1, steps + 1):
                venv.step(actions[k])

        total, others = machine_load.timed(episode)
        return total, timed.seconds, others

    pairs = []  # (env seconds, core seconds) per thread count, and the pair's others' use
    deadline = None
    while True:
        order = (1, 2) if len(pairs) % 2 == 0 else (2, 1)
        times = {t: run(t) for t in order}
        pairs.append(({t: times[t][:2] for t in times}, max(times[t][2] for t in times)))
        quiet = [p for p in pairs if p[1] < machine_load.QUIET_CORES]
        if len(pairs) >= repeats:
            deadline = deadline or time.perf_counter() + quiet_wait
            if len(quiet) >= repeats or time.perf_counter() >= deadline:
                break
    used = quiet or pairs
    best = {t: (min(p[0][t][0] for p in used), min(p[0][t][1] for p in used)) for t in venvs}
    env_rate = {t: n * steps / best[t][0] for t in venvs}
    core_rate = {t: n * steps / best[t][1] for t in venvs}
    # The speed-up within each pair (back to back, so the host's speed drifts least between
    # them), median over the pairs used: a check on best/best, which takes each thread
    # count's best moment separately.
    pair_speedup = float(np.median([p[0][1][0] / p[0][2][0] for p in used]))
    pair_core_speedup = float(np.median([p[0][1][1] / p[0][2][1] for p in used]))
    return {"steps_per_s_1t": env_rate[1], "steps_per_s_2t": env_rate[2], "speedup_2t": env_rate[2] / env_rate[1],
            "speedup_2t_pair_median": pair_speedup,
            "core_steps_per_s_1t": core_rate[1], "core_steps_per_s_2t": core_rate[2],
            "core_speedup_2t": core_rate[2] / core_rate[1], "core_speedup_2t_pair_median": pair_core_speedup,
            "pairs_quiet": f"{len(quiet)}/{len(pairs)}",
            "others_cores": float(np.median([p[1] for p in used]))}


def single_rate(env_id: str, steps: int, repeats: int) -> float:
    import gymnasium as gym

    import diffcloth_gym  # noqa: F401

    env = gym.make(env_id).unwrapped
    rng = np.random.default_rng(0)
    actions = rng.uniform(env.action_space.low, env.action_space.high, (steps, env.action_space.shape[0]))

    def run():
        env.reset(seed=0)
        for k in range(steps):
            env.step(actions[k])

    return steps / best_of(repeats, run)


def step_grad_costs(env_id: str, steps: int, repeats: int) -> dict:
    """Plain steps/s, step_grad forward and backward times per step, and tape bytes."""
    import gymnasium as gym
    import torch

    import diffcloth_gym  # noqa: F401

    env = gym.make(env_id).unwrapped
    rng = np.random.default_rng(0)
    actions = rng.uniform(env.action_space.low, env.action_space.high, (steps, env.action_space.shape[0]))

    def plain():
        env.reset(seed=0)
        for k in range(steps):
            env.step(actions[k])

    forward_times, backward_times, tape = [], [], 0
    for _ in range(repeats):
        a = torch.tensor(actions, requires_grad=True)
        env.reset(seed=0)
        t = time.perf_counter()
        total = sum(env.step_grad(a[k])[1] for k in range(steps))
        forward_times.append(time.perf_counter() - t)
        tape = env.engine.batch.tape_info()[0][1]
        t = time.perf_counter()
        total.backward()
        backward_times.append(time.perf_counter() - t)
    plain_s = best_of(repeats, plain) / steps
    fwd, bwd = min(forward_times) / steps, min(backward_times) / steps
    return {"plain_ms": 1e3 * plain_s, "grad_forward_ms": 1e3 * fwd, "grad_backward_ms": 1e3 * bwd,
            "grad_vs_plain": (fwd + bwd) / plain_s, "tape_bytes_per_step": tape / steps,
            "tape_mb_per_episode": tape / steps * env.task.horizon / 1e6}


def render_rate(env_id: str, frames: int, repeats: int) -> float | None:
    import gymnasium as gym

    import diffcloth_gym  # noqa: F401

    try:
        env = gym.make(env_id, render_mode="rgb_array").unwrapped
        env.reset(seed=0)
        env.render()
    except (ImportError, AttributeError, NotImplementedError):
        return None

    def run():
        for _ in range(frames):
            env.render()

    return frames / best_of(repeats, run)


def vector_rows(env_id: str, steps: int, repeats: int, sizes: list[int], quiet_wait: float = 0.0) -> list[dict]:
    return [{"env": env_id, "measure": f"vector N={n}", **vector_rates(env_id, n, steps, repeats, quiet_wait)}
            for n in sizes]


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer steps and sizes (a smoke run)")
    parser.add_argument("--envs", nargs="*", default=ENV_IDS, help="env ids (default: all three)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quiet-wait", type=float, default=0.0,
                        help="seconds per vector size to keep timing 1/2-thread pairs until --repeats of them "
                             "ran while other processes used under %.2f cores (default 0: just label them)"
                             % machine_load.QUIET_CORES)
    parser.add_argument("--measures", nargs="*", default=["single", "vector", "step_grad", "render"],
                        help="which measures (default: all)")
    parser.add_argument("--sizes", nargs="*", type=int, default=None, help="vector sizes (default 1 2 8 32)")
    parser.add_argument("--out-dir", default=None, help="write the results here instead of benchmarks/results")
    parser.add_argument("--steps", type=int, default=None,
                        help="steps per timing (default 20, 3 with --quick); longer timings label the others' "
                             "use more precisely (/proc/stat counts 10 ms ticks)")
    args = parser.parse_args(argv)
    steps = args.steps or (3 if args.quick else 20)
    sizes = args.sizes or ([1, 2] if args.quick else SIZES)
    rows = []
    for env_id in args.envs:
        if "single" in args.measures:
            rows.append({"env": env_id, "measure": "single", "steps_per_s_1t": single_rate(env_id, steps, args.repeats)})
        if "vector" in args.measures:
            rows += vector_rows(env_id, steps, args.repeats, sizes, args.quiet_wait)
            print(results_io.markdown_table(rows), flush=True)
        if "step_grad" in args.measures:
            rows.append({"env": env_id, "measure": "step_grad", **step_grad_costs(env_id, steps, args.repeats)})
        fps = render_rate(env_id, 10 if args.quick else 50, args.repeats) if "render" in args.measures else None
        if fps is not None:
            rows.append({"env": env_id, "measure": "render 480x480", "frames_per_s": fps})
    notes = ("Env steps per second with random actions (single env in this process's default pool; vector "
             "envs on pools of their own with 1 and 2 threads, timed alternately in one process; 'core' is the "
             "time inside the Rust batch step alone, the rest being Python). Each vector row's pairs of 1- and "
             "2-thread timings are labelled with the other processes' CPU use ('others_cores', median over "
             "the pairs used; Linux shares the cores between sessions, so a 2-thread run only gets 2 cores "
             "when the others leave them idle): the row is the best of its quiet pairs (others under "
             f"{machine_load.QUIET_CORES} cores; 'pairs_quiet' counts them) if any, else of all; '*_pair_median' is "
             "the median over those pairs of the speed-up within each pair (timed back to back, so the host's "
             "speed, which this VM cannot see, drifts least between the two). step_grad: a closed-loop "
             "differentiable rollout's forward and backward time per step, and (forward + backward) / plain "
             "step at the same accuracy (the env's plain and recorded steps share one tolerance). Tape memory "
             "is what a member's recording holds for a full episode (freed at reset).")
    results_io.write("env_throughput", rows,
                     results_io.meta({"steps": steps, "repeats": args.repeats, "quiet_wait": args.quiet_wait}),
                     "Env throughput", notes, out_dir=args.out_dir)
    print(results_io.markdown_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
