"""Gymnasium environments on the simulator, registered on ``import diffcloth_gym``:
``gym.make("DiffCloth/Hat-v0")``, ``gym.make_vec("DiffCloth/Hat-v0", num_envs=N)`` (one
batched Rust core; autoreset NEXT_STEP) and ``envs.sb3.ClothSB3VecEnv("DiffCloth/Hat-v0", N)``
for stable-baselines3.

One file per env (``hat_v0.py``, ``sock_v0.py``, ``flying_napkin_v0.py``: the task and its
documentation), the task interface (``task.py``), the shared plumbing (``engine.py`` batched,
``base.py`` the single env, ``vector.py`` and ``sb3.py`` the vector adapters). Registration
uses entry-point strings, so importing the package does not import torch or gymnasium's
env modules until an env is made.
"""

import gymnasium as gym

#: Registered ids, their module and class prefix.
ENVS = {
    "DiffCloth/Hat-v0": ("hat_v0", "Hat"),
    "DiffCloth/Sock-v0": ("sock_v0", "Sock"),
    "DiffCloth/FlyingNapkin-v0": ("flying_napkin_v0", "FlyingNapkin"),
}


def register_envs() -> None:
    for env_id, (module, name) in ENVS.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point=f"diffcloth_gym.envs.{module}:{name}Env",
            vector_entry_point=f"diffcloth_gym.envs.{module}:{name}VectorEnv",
            # Episodes end by the task's own horizon (truncated), not by a TimeLimit wrapper.
            disable_env_checker=False,
        )
