"""Training harness: analytic policy gradients (APG, through ``step_grad``) and PPO
(stable-baselines3) on one cloth task, evaluated by one function on the env's fixed
``TEST_STARTS``, with every simulated time step counted.

- ``config.py``: the training configs (``configs/*.toml``, package data; hyperparameters only,
  the physics stays in the scene configs).
- ``policy.py``: the paper's controller network (MLP 64-64 tanh) in float64.
- ``accounting.py``: time steps counted from the engine's own step counters, wall clock, threads.
- ``apg.py``: the paper's controller trained by Adam on batched ``step_grad`` rollouts.
- ``ppo.py``: SB3's PPO on the batched ``ClothSB3VecEnv``.
- ``evaluate.py``: any policy on ``TEST_STARTS`` (loss terms, success, final frames).
- ``runlog.py``: CSV logs, atomic checkpoints, RNG states.
- ``media.py``: frames and the GIF.
- ``compare.py``: every method and seed under one budget; the JSON, Markdown, plot and GIF.

Heavy imports (torch, stable-baselines3, matplotlib) are inside the modules that need them.
"""
