#!/usr/bin/env python3
"""Writes the procedural meshes of the shipped task scenes (package data):
diffcloth_gym/configs/dress_skirt.obj (diffcloth_gym.optim.shapes.skirt) and
diffcloth_gym/configs/tshirt_tube.obj (flat_tube), with the generators' default arguments.
tests/test_optim_tasks.py checks that the shipped files equal what this writes."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from diffcloth_gym.optim.tasks_meshes import write_all  # noqa: E402

for path in write_all():
    print("wrote", path)
