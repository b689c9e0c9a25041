"""Networks: ``mlp()`` and the few heads the chapters use.

Kept deliberately small: a network here is a plain ``torch.nn.Module`` whose ``forward`` reads like
the equation it computes.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn


def mlp(sizes: Sequence[int], activation: type[nn.Module] = nn.ReLU,
        output_activation: type[nn.Module] | None = None) -> nn.Sequential:
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
    """Q(s, ·) from a shared body and two streams: a state value V(s) and advantages A(s, ·).

    As in Wang et al. (2016), the two streams *replace* the plain network's last hidden layer: the body is
    ``hidden[:-1]`` and each stream is one hidden layer of ``hidden[-1]`` units, so the network is as deep as
    :class:`QNetwork` with the same ``hidden``. It still holds more weights (two last layers instead of one).
    """

    def __init__(self, obs_dim: int, n_actions: int, hidden: Sequence[int] = (64, 64)):
        super().__init__()
        if len(hidden) < 1:
            raise ValueError("a dueling network needs at least one hidden layer (each stream is the last one)")
        *shared, last = hidden
        width = shared[-1] if shared else obs_dim
        self.body = mlp([obs_dim, *shared], output_activation=nn.ReLU) if shared else nn.Identity()
        self.value = mlp([width, last, 1])
        self.advantage = mlp([width, last, n_actions])

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        h = self.body(obs)
        return dueling_aggregate(self.value(h), self.advantage(h))


# --- target networks ---------------------------------------------------------------------------


def soft_update(target: torch.nn.Module, source: torch.nn.Module, tau: float) -> None:
    """theta' <- tau * theta + (1 - tau) * theta'  (tau = 1 copies)."""
    with torch.no_grad():
        for t, s in zip(target.parameters(), source.parameters()):
            t.lerp_(s, tau)
