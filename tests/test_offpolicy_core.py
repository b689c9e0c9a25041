"""rlcore.offpolicy, the core DDPG, TD3 and SAC share: what holds for all three."""

import pytest
import torch

from rlcore import crossq, ddpg, sac, td3

SMALL = dict(hidden=(32, 32), learning_starts=100, batch_size=32, buffer_size=5_000)


@pytest.mark.parametrize("algo", [ddpg, td3, sac, crossq], ids=["ddpg", "td3", "sac", "crossq"])
def test_evaluating_leaves_training_untouched(algo):
    # Evaluation runs its own environment and draws no random number that training draws: a run that evaluates
    # every 150 steps trains exactly as one that never evaluates. So two runs that differ only in their evaluation
    # cadence (td3-ablation's "td3" arm and td3-sac-1m's td3-hopper, same seed) are the same run, step for step.
    torch.set_num_threads(1)
    small = {**SMALL, "critic_hidden": (32, 32)} if algo is crossq else SMALL
    quiet = algo.train("Pendulum-v1", algo.Config(**small, eval_every=0), steps=500, seed=4)
    watched = algo.train("Pendulum-v1", algo.Config(**small, eval_every=150, eval_episodes=2), steps=500, seed=4)
    assert len(watched.eval_returns) == 3 and len(quiet.eval_returns) == 0
    assert quiet.episode_returns.tolist() == watched.episode_returns.tolist()
    for a, b in zip(quiet.actor.parameters(), watched.actor.parameters()):
        assert torch.equal(a, b)
    for a, b in zip(quiet.critic.parameters(), watched.critic.parameters()):
        assert torch.equal(a, b)
