"""Schedules: how a hyperparameter moves over a run (epsilon in Q-learning and DQN).

A schedule is a plain function of the step, so the loop that uses it shows which step it is read at.
"""

from __future__ import annotations


def linear_schedule(start: float, end: float, duration: int, t: int) -> float:
    """Linear interpolation from ``start`` (t=0) to ``end`` (t >= duration)."""
    if duration <= 0:
        return end
    return start + (end - start) * min(t / duration, 1.0)
