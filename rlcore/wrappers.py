"""Environment wrappers that package a mistake, so that a chapter can measure what it does with the library's own,
correct training loops.

- :class:`TimeoutAsTermination`: a time-out (truncation) reported as the end of the task (termination), the bug
  ``done = terminated or truncated`` in a TD target.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym


# [timeout-as-termination]
class TimeoutAsTermination(gym.Wrapper):
    """The bug, packaged as a wrapper: report a time-out (truncation) as termination."""

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated or truncated, False, info
# [/timeout-as-termination]


def register_timeout_as_termination(env_id: str, **make_kwargs: Any) -> str:
    """Register ``env_id`` (made with ``make_kwargs``, e.g. ``max_episode_steps=15``) wrapped in
    :class:`TimeoutAsTermination` with Gymnasium, in this process, and return the new id.

    The id says what it is: ``CliffWalking-v1`` with a 15-step limit becomes ``CliffWalking-TimeoutAsEnd15-v1``.
    Registering the same thing twice is harmless.
    """
    name, _, version = env_id.rpartition("-")
    limit = make_kwargs.get("max_episode_steps")
    new_id = f"{name}-TimeoutAsEnd{limit or ''}-{version}"
    if new_id not in gym.envs.registry:
        gym.register(new_id, entry_point=lambda **kwargs: TimeoutAsTermination(
            gym.make(env_id, **make_kwargs, **kwargs)))
    return new_id
