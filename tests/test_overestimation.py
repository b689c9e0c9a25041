"""Chapter 3's measurement of the maximization bias: the stand-in network, the controlled experiment against the
theory, and the bound on what exact backups can give."""

import math

import numpy as np
import torch

from rlbook.overestimation import LookupQ, backup_bound, expected_max, mean_targets
from rlcore.dqn import Config


def test_lookup_q_answers_from_its_table_by_the_first_observation_entry():
    q = LookupQ([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    obs = torch.tensor([[2.0, 9.0], [0.0, -1.0]])
    assert q(obs).tolist() == [[5.0, 6.0], [1.0, 2.0]]


def test_expected_max_of_standard_normals():
    assert abs(expected_max(1)) < 1e-6
    assert math.isclose(expected_max(2), 1 / math.sqrt(math.pi), abs_tol=1e-4)    # E[max(Z1, Z2)] = 1/sqrt(pi)
    assert [round(expected_max(m), 2) for m in (8, 32)] == [1.42, 2.07]           # tables of normal order statistics


def test_dqn_target_has_the_bias_of_the_max_and_double_dqn_has_none_with_independent_errors():
    for m in (2, 8):
        dqn, double = mean_targets(m, rho=0.0)
        assert abs(dqn - expected_max(m)) < 0.04 and abs(double) < 0.04
    # the same errors for choosing and evaluating: Double DQN is DQN again
    dqn, double = mean_targets(4, rho=1.0, n=2_000)
    assert dqn == double
    # in between, Double DQN keeps about a fraction rho of the bias
    dqn, double = mean_targets(8, rho=0.5)
    assert abs(double - 0.5 * expected_max(8)) < 0.05


def test_backup_bound_counts_the_bursts_by_hand():
    # learning starts at 1,000 and trains every 256 steps: the first burst at step 1,024, then 1,280, ...
    assert backup_bound(999) == 0 and backup_bound(1_023) == 0 and backup_bound(1_024) == 1.0
    assert math.isclose(backup_bound(1_280), 1 + 0.99)
    assert math.isclose(backup_bound(5_000), (1 - 0.99 ** 16) / 0.01)       # 1024, 1280, ..., 4864: 16 bursts
    assert math.isclose(backup_bound(50_000), (1 - 0.99 ** 192) / 0.01)     # 192 bursts: at most 85.5
    assert round(float(backup_bound(50_000)), 1) == 85.5
    steps = np.array([0, 1_024, 50_000])
    assert np.allclose(backup_bound(steps), [0, 1, (1 - 0.99 ** 192) / 0.01])
    other = Config(learning_starts=0, train_freq=100, gamma=0.5)
    assert backup_bound(250, other) == 1 + 0.5 + 0.25                         # bursts at steps 0, 100, 200
