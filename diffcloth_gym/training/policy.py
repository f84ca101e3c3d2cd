"""The paper's controller network (Sec. 6.5; the reference ``hatController.py``): an MLP
obs -> 64 -> 64 -> action with tanh activations, the output squashed by tanh into the action
bound, in float64 (the simulator's gradients are float64).

``forward(obs, member_deltas)`` runs the same network with a zero perturbation per batch
member added to every weight: the perturbations change no value (adding exact zeros), but
their gradients are the per-member gradients dL_i/dtheta (member i's trajectory depends on
theta + delta_i only), which gives the spread of the gradient across the batch without a
second backward pass. The product with a perturbation is taken as ``delta_i @ h_i`` so that
autograd saves the small activations, never a per-member copy of the weights.
"""

from __future__ import annotations

from typing import Sequence

import torch
from torch import nn


class MLPPolicy(nn.Module):
    """``obs_dim -> hidden... -> act_dim``, tanh between layers and at the output (times
    ``bound``). Initialised by torch's default Linear init from a seeded generator, with the
    last layer scaled by ``last_layer_scale`` so that the first actions are small."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: Sequence[int] = (64, 64), bound: float = 1.0,
                 seed: int = 0, last_layer_scale: float = 0.01):
        super().__init__()
        sizes = [obs_dim, *hidden, act_dim]
        g = torch.random.fork_rng(devices=[])
        with g:
            torch.manual_seed(seed)
            self.layers = nn.ModuleList(nn.Linear(a, b, dtype=torch.float64) for a, b in zip(sizes[:-1], sizes[1:]))
            with torch.no_grad():
                self.layers[-1].weight.mul_(last_layer_scale)
                self.layers[-1].bias.mul_(last_layer_scale)
        self.bound = float(bound)
        self.obs_dim, self.act_dim, self.hidden = obs_dim, act_dim, list(hidden)

    def member_deltas(self, members: int) -> list[torch.Tensor]:
        """Zero perturbations, one per member and parameter, as leaves that require grad."""
        return [torch.zeros((members, *p.shape), dtype=p.dtype, requires_grad=True) for p in self.parameters()]

    def forward(self, obs: torch.Tensor, deltas: list[torch.Tensor] | None = None) -> torch.Tensor:
        h = obs
        for k, layer in enumerate(self.layers):
            z = layer(h)
            if deltas is not None:
                dw, db = deltas[2 * k], deltas[2 * k + 1]
                z = z + torch.einsum("noi,ni->no", dw, h) + db
            h = torch.tanh(z)
        return self.bound * h

    def config(self) -> dict:
        return {"obs_dim": self.obs_dim, "act_dim": self.act_dim, "hidden": self.hidden, "bound": self.bound}
