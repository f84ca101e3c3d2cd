"""Env throughput: what an RL or gradient user gets per second from each env.

Per env, with random actions in the action box:
- ``single``: a single env's steps/s;
- ``vector``: env steps/s of the Gymnasium vector env at N = 1, 2, 8, 32, on 1 and 2 threads
  (``RAYON_NUM_THREADS``, one subprocess per thread count so the pool is fresh), and the
  2-thread speed-up (target: >= 1.8x at the larger N);
- ``step_grad``: forward + backward steps/s of a closed-loop differentiable rollout, and its
  cost relative to a plain step at the same accuracy (the env's steps are gradient-grade by
  construction; target <= 2.5x), plus the tape memory of the episode per member;
- ``render``: ``rgb_array`` frames/s at 480x480 (when the renderer is installed).

Every ratio is measured within one run (the machine is shared and noisy); each figure is the
best of ``--repeats`` timings. Writes benchmarks/results/env_throughput.{json,md}.

Run: python -m benchmarks env_throughput [--quick] [--envs Hat-v0 ...]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

from benchmarks import results_io

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


def vector_rate(env_id: str, n: int, steps: int, repeats: int) -> float:
    """Env steps/s of the vector env with ``n`` members (in this process's thread pool)."""
    import gymnasium as gym

    import diffcloth_gym  # noqa: F401

    venv = gym.make_vec(env_id, num_envs=n)
    rng = np.random.default_rng(0)
    space = venv.single_action_space
    actions = rng.uniform(space.low, space.high, (steps, n, space.shape[0]))

    def run():
        venv.reset(seed=0)
        for k in range(steps):
            venv.step(actions[k])

    return n * steps / best_of(repeats, run)


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


def _child(argv: list[str]) -> int:
    """Runs one vector measurement in this process and prints it as JSON (see ``vector_rows``)."""
    env_id, n, steps, repeats = argv[0], int(argv[1]), int(argv[2]), int(argv[3])
    print(json.dumps(vector_rate(env_id, n, steps, repeats)))
    return 0


def vector_rows(env_id: str, steps: int, repeats: int, sizes: list[int]) -> list[dict]:
    rows = []
    for n in sizes:
        rates = {}
        for threads in (1, 2):
            env = {**os.environ, "RAYON_NUM_THREADS": str(threads)}
            out = subprocess.run([sys.executable, "-m", "benchmarks.env_throughput", "--child", env_id, str(n),
                                  str(steps), str(repeats)], env=env, capture_output=True, text=True, check=True)
            rates[threads] = json.loads(out.stdout.strip().splitlines()[-1])
        rows.append({"env": env_id, "measure": f"vector N={n}", "steps_per_s_1t": rates[1],
                     "steps_per_s_2t": rates[2], "speedup_2t": rates[2] / rates[1]})
    return rows


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "--child":
        return _child(argv[1:])
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer steps and sizes (a smoke run)")
    parser.add_argument("--envs", nargs="*", default=ENV_IDS, help="env ids (default: all three)")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args(argv)
    steps = 3 if args.quick else 10
    sizes = [1, 2] if args.quick else SIZES
    rows = []
    for env_id in args.envs:
        rows.append({"env": env_id, "measure": "single", "steps_per_s_1t": single_rate(env_id, steps, args.repeats)})
        rows += vector_rows(env_id, steps, args.repeats, sizes)
        rows.append({"env": env_id, "measure": "step_grad", **step_grad_costs(env_id, steps, args.repeats)})
        fps = render_rate(env_id, 10 if args.quick else 50, args.repeats)
        if fps is not None:
            rows.append({"env": env_id, "measure": "render 480x480", "frames_per_s": fps})
    notes = ("Env steps per second with random actions (single env in this process's default pool; vector "
             "envs on 1 and 2 rayon threads, each in a fresh subprocess). step_grad: a closed-loop "
             "differentiable rollout's forward and backward time per step, and (forward + backward) / plain "
             "step at the same accuracy (the env's plain and recorded steps share one tolerance). Tape memory "
             "is what a member's recording holds for a full episode (freed at reset).")
    results_io.write("env_throughput", rows, results_io.meta({"steps": steps, "repeats": args.repeats}),
                     "Env throughput", notes)
    print(results_io.markdown_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
