"""Named physical parameters with bounds: any entry of the simulator's parameter registry
(``Simulator.PARAM_NAMES``: k_stretch, k_bend, density, gravity, wind_*, mu_obstacles,
mu_self, ...), a component of a vector one written ``name[i]`` (``mu_obstacles[0]``,
``wind_direction[2]``)."""

from __future__ import annotations

import re

import numpy as np

from diffcloth_gym.errors import InputError, ParameterError
from diffcloth_gym.optim.parameterization import Inputs, check_bounds

_ITEM = re.compile(r"^([a-z_]+)(?:\[(\d+)\])?$")


def parse_name(name: str, registry) -> tuple[str, int | None]:
    """``"mu_obstacles[0]"`` -> ``("mu_obstacles", 0)``; unknown names raise ParameterError."""
    m = _ITEM.match(name)
    if not m or m.group(1) not in registry:
        raise ParameterError(f"unknown parameter {name!r}; known: {', '.join(registry)} (a component: name[i])")
    return m.group(1), None if m.group(2) is None else int(m.group(2))


class PhysicalParams:
    """Physical parameters by registry name, each with bounds: ``PhysicalParams(sim,
    {"k_stretch": (100, 2000), "mu_obstacles[0]": (0, 1)})``. ``theta`` holds the values in
    their own units, in the order given; the gradient is the backward's entry of the same name.
    """

    def __init__(self, sim, spec: dict):
        if not spec:
            raise InputError("spec must name at least one parameter")
        registry = sim.PARAM_NAMES
        current = sim.params()
        self.items = []
        for name in spec:
            base, index = parse_name(name, registry)
            value = current.get(base)
            if value is None:
                raise ParameterError(f"{name}: this scene has no such parameter (e.g. mu_self without self-collision)")
            if isinstance(value, list):
                if index is None or not 0 <= index < len(value):
                    raise ParameterError(f"{name}: {base} has {len(value)} entries; name one as {base}[i]")
            elif index is not None:
                raise ParameterError(f"{name}: {base} is a scalar")
            self.items.append((name, base, index))
        self.names = list(spec)
        self.size = len(self.items)
        self._base = current
        lo, hi = zip(*(spec[n] for n in self.names))
        self._bounds = check_bounds("PhysicalParams", lo, hi, self.size)

    @property
    def bounds(self):
        return self._bounds

    def inputs(self, theta, steps: int) -> Inputs:
        params = {}
        for (name, base, index), value in zip(self.items, np.asarray(theta, dtype=np.float64)):
            if index is None:
                params[base] = float(value)
            else:
                vec = list(params.get(base, self._base[base]))
                vec[index] = float(value)
                params[base] = vec
        return Inputs(params=params)

    def chain(self, theta, grads: dict, steps: int) -> np.ndarray:
        return np.array([grads[base] if index is None else grads[base][index] for _, base, index in self.items],
                        dtype=np.float64)
