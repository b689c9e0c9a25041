"""Measuring how the max in Q-learning's target overestimates, and how much of it Double DQN removes.

- a controlled experiment: "networks" whose errors we choose (:class:`LookupQ`), fed to the library's own target
  functions (:func:`mean_targets`), against the theory (:func:`expected_max`);
- a bound for real runs: the most that exact backups from Q = 0 could give after the bursts of updates a DQN has
  done by a given step (:func:`backup_bound`), for CartPole's reward of +1 per step.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from rlcore.dqn import Config, double_dqn_target, dqn_target


# [lookup-q]
class LookupQ(torch.nn.Module):
    """A stand-in Q-network that looks its answers up in a table (row = first observation entry)."""

    def __init__(self, table):
        super().__init__()
        self.table = torch.as_tensor(table, dtype=torch.float32)

    def forward(self, obs):
        return self.table[obs[:, 0].long()]
# [/lookup-q]


def expected_max(m: int) -> float:
    """E[max of m independent standard normals], by numerical integration of x * m * pdf(x) * cdf(x)^(m-1)."""
    x = np.linspace(-8, 8, 4001)
    pdf = np.exp(-x ** 2 / 2) / math.sqrt(2 * math.pi)
    cdf = 0.5 * (1 + np.vectorize(math.erf)(x / math.sqrt(2)))
    return float(np.trapezoid(x * m * pdf * cdf ** (m - 1), x))


# [mean-targets]
def mean_targets(m: int, rho: float, n: int = 20_000, seed: int = 0) -> tuple[float, float]:
    """Mean DQN and Double DQN targets when every true value is 0 and estimates have N(0, 1) errors.

    ``m`` actions; the online and target networks' errors have correlation ``rho``. With r = 0 and gamma = 1
    the correct target is 0, so the mean target over ``n`` next states is the bias.
    """
    gen = np.random.default_rng(seed)
    err_online = gen.standard_normal((n, m))
    err_target = rho * err_online + math.sqrt(1 - rho ** 2) * gen.standard_normal((n, m))
    rows, zeros = torch.arange(n, dtype=torch.float32).unsqueeze(1), torch.zeros(n)
    dqn = dqn_target(LookupQ(err_target), rows, zeros, zeros, gamma=1.0).mean().item()
    double = double_dqn_target(LookupQ(err_online), LookupQ(err_target), rows, zeros, zeros, 1.0).mean().item()
    return dqn, double
# [/mean-targets]


# [backup-bound]
def backup_bound(step, config: Config | None = None):
    """B_j after the bursts of updates done by ``step``: the most exact backups from 0 could give, with r <= 1.

    Burst j (``gradient_steps`` updates every ``train_freq`` steps, from ``learning_starts`` on) regresses onto
    targets of the network after burst j - 1, so after j bursts no value exceeds 1 + gamma + ... + gamma^(j-1).
    """
    config = config or Config()
    assert config.target_update_interval < config.train_freq  # the target is refreshed between bursts
    first = -(-config.learning_starts // config.train_freq)      # the first burst: ceil(starts / freq)
    bursts = np.maximum(0, np.floor_divide(step, config.train_freq) - first + 1)
    return (1 - config.gamma ** bursts) / (1 - config.gamma)
# [/backup-bound]
