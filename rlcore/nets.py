"""Networks: ``mlp()`` and the few heads the chapters use.

Kept deliberately small: a network here is a plain ``torch.nn.Module`` whose ``forward`` reads like
the equation it computes.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn


def mlp(sizes: Sequence[int], activation: type[nn.Module] = nn.ReLU, output_activation: type[nn.Module] | None = None) -> nn.Sequential:
    """A multilayer perceptron: ``sizes = [in, hidden..., out]``, ``activation`` between layers."""
    if len(sizes) < 2:
        raise ValueError(f"mlp needs at least an input and an output size, got {list(sizes)}")
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        last = i == len(sizes) - 2
        if not last:
            layers.append(activation())
        elif output_activation is not None:
            layers.append(output_activation())
    return nn.Sequential(*layers)


class QNetwork(nn.Module):
    """Q(s, ·): one output per discrete action."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: Sequence[int] = (64, 64)):
        super().__init__()
        self.net = mlp([obs_dim, *hidden, n_actions])

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs)


def dueling_aggregate(value: torch.Tensor, advantages: torch.Tensor) -> torch.Tensor:
    """Q(s,a) = V(s) + A(s,a) - mean_a' A(s,a')  (Wang et al. 2016, eq. 9)."""
    return value + advantages - advantages.mean(dim=-1, keepdim=True)


class DuelingQNetwork(nn.Module):
    """Q(s, ·) from a shared body and two streams: a state value V(s) and advantages A(s, ·)."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: Sequence[int] = (64, 64)):
        super().__init__()
        *body, last = [obs_dim, *hidden]
        self.body = mlp([*body, last], output_activation=nn.ReLU) if body else nn.Identity()
        self.value = mlp([last, last, 1])
        self.advantage = mlp([last, last, n_actions])

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        h = self.body(obs)
        return dueling_aggregate(self.value(h), self.advantage(h))
