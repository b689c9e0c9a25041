"""rlbook.crossq_demo: a memory-like batch holds the random steps, then the policy's, as consecutive transitions."""

import numpy as np
import torch

from rlbook.crossq_demo import memory_like_batch
from rlcore import crossq


def test_a_memory_like_batch_is_random_steps_then_the_policy_s():
    torch.manual_seed(0)
    actor = crossq.NormalizedActor(3, 1, (8,), [-2.0], [2.0], crossq.Config().renorm())
    with torch.no_grad():
        actor.log_std.bias.fill_(-20.0)  # a near-deterministic policy: its actions are tanh of its mean, scaled
        actor.log_std.weight.zero_()
    b = memory_like_batch(actor, "Pendulum-v1", random_steps=50, policy_steps=30, seed=2)
    assert len(b.obs) == 80 and b.actions.shape == (80, 1)
    np.testing.assert_array_equal(b.obs[1:].numpy(), b.next_obs[:-1].numpy())  # Pendulum's 200 steps: no reset
    with torch.no_grad():
        mean_action = actor.deterministic(b.obs[50:])
    torch.testing.assert_close(b.actions[50:], mean_action, atol=1e-5, rtol=0)
    assert float(b.actions[:50].std()) > 0.5  # uniform on [-2, 2]: std 1.15
