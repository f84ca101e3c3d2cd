#!/usr/bin/env python3
"""Regenerates Hat-v0's target shape, diffcloth_gym/configs/hat_target.npz, by simulation at the
hat scene's physics (the recipe: diffcloth_gym.envs.hat_v0.make_target). Run after any change
to the hat scene or the simulator's physics: .venv/bin/python scripts/make_hat_target.py"""
import sys
import time

from diffcloth_gym.envs.hat_v0 import write_target

t0 = time.perf_counter()
path = write_target()
print(f"wrote {path} ({time.perf_counter() - t0:.1f} s)")
sys.exit(0)
