"""Checks shared by every algorithm's ``Config`` and by the command line: a value outside its meaningful range is
refused with one line that says what is accepted, before any work starts.

A field is checked by its name, so that ``gamma`` means the same in every algorithm: :data:`RANGES` lists each
named field's accepted interval (a Config whose field means something else at a bound, such as DQN's
``max_grad_norm = 0`` for "no clipping", says so in a class attribute ``RANGES`` of its own), and
:func:`check_config` also checks that a number is a number (``--set actor_lr=abc`` is refused, not trained with).
Fields not listed are checked only for their type.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import typing
from typing import Any

# (low, high, low inclusive, high inclusive); None is unbounded
Interval = tuple[float | None, float | None, bool, bool]
POSITIVE: Interval = (0, None, False, False)
NON_NEGATIVE: Interval = (0, None, True, False)
AT_LEAST_ONE: Interval = (1, None, True, False)
UNIT: Interval = (0, 1, True, True)
HALF_OPEN_UNIT: Interval = (0, 1, False, True)

RANGES: dict[str, Interval] = {
    # step sizes and scales
    "actor_lr": POSITIVE, "critic_lr": POSITIVE, "learning_rate": POSITIVE, "optimizer_eps": POSITIVE,
    "clip_range": POSITIVE, "max_grad_norm": POSITIVE, "reward_scale": POSITIVE, "param_noise_target": POSITIVE,
    "kl_target": POSITIVE, "kl_alpha": POSITIVE, "kl_beta_high": POSITIVE, "kl_beta_low": POSITIVE,
    "ent_coef": NON_NEGATIVE, "vf_coef": NON_NEGATIVE, "noise_sigma": NON_NEGATIVE, "explore_noise": NON_NEGATIVE,
    "kl_coef": NON_NEGATIVE, "exploration_noise": NON_NEGATIVE, "alpha_lr": POSITIVE,
    # probabilities, discounts and rates
    "gamma": UNIT, "gae_lambda": UNIT, "epsilon_start": UNIT, "epsilon_end": UNIT, "exploration_fraction": UNIT,
    "per_alpha": UNIT, "per_beta_start": UNIT, "rms_alpha": UNIT,
    "tau": HALF_OPEN_UNIT, "alpha": HALF_OPEN_UNIT, "explore_decay": HALF_OPEN_UNIT,
    # sizes and counts
    "batch_size": AT_LEAST_ONE, "buffer_size": AT_LEAST_ONE, "n_steps": AT_LEAST_ONE, "num_envs": AT_LEAST_ONE,
    "n_epochs": AT_LEAST_ONE, "gradient_steps": AT_LEAST_ONE, "train_freq": AT_LEAST_ONE,
    "target_update_interval": AT_LEAST_ONE, "checkpoint_every": AT_LEAST_ONE, "checkpoint_updates": AT_LEAST_ONE,
    "eval_episodes": AT_LEAST_ONE, "log_every": AT_LEAST_ONE, "policy_delay": AT_LEAST_ONE,
    "eval_every": NON_NEGATIVE, "learning_starts": NON_NEGATIVE, "epsilon_decay_steps": NON_NEGATIVE,
}
"""The accepted interval of every named Config field, whichever algorithm has it."""


def describe(interval: Interval) -> str:
    """``"> 0"``, ``"in [0, 1]"``, ``">= 1"``..."""
    low, high, low_in, high_in = interval
    if high is None:
        return f"{'>=' if low_in else '>'} {low:g}"
    return f"in {'[' if low_in else '('}{low:g}, {high:g}{']' if high_in else ')'}"


def in_interval(value: float, interval: Interval) -> bool:
    low, high, low_in, high_in = interval
    if math.isnan(value):
        return False
    if low is not None and (value < low or (value == low and not low_in)):
        return False
    return high is None or value < high or (value == high and high_in)


def _number(name: str, value: Any, integer: bool) -> float:
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be {kind}, got {value!r}")
    if integer and not float(value).is_integer():
        raise ValueError(f"{name} must be {kind}, got {value!r}")
    return value


def check_config(config: Any) -> None:
    """Raise ValueError (one line: the field, what is accepted, what was given) for the first bad field.

    Integer fields given as whole floats (``64.0``) become ints; ``hidden`` becomes a tuple of ints >= 1.
    """
    owner = type(config).__module__.rsplit(".", 1)[-1] + ".Config"
    hints = typing.get_type_hints(type(config))
    ranges = {**RANGES, **getattr(type(config), "RANGES", {})}
    for f in dataclasses.fields(config):
        value, hint, name = getattr(config, f.name), hints.get(f.name), f"{owner}.{f.name}"
        if f.name == "hidden" or f.name.endswith("_hidden"):
            if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)):
                raise ValueError(f"{name} must be a list of layer sizes such as 64,64, got {value!r}")
            sizes = tuple(int(_number(name, h, integer=True)) for h in value)
            if any(h < 1 for h in sizes):
                raise ValueError(f"{name}: every layer size must be >= 1, got {value!r}")
            setattr(config, f.name, sizes)
            continue
        if hint is bool:
            if not isinstance(value, bool):
                raise ValueError(f"{name} must be true or false, got {value!r}")
            continue
        if hint in (int, float):
            number = _number(name, value, integer=hint is int)
            if hint is int:
                setattr(config, f.name, int(number))
            interval = ranges.get(f.name)
            if interval is not None and not in_interval(float(number), interval):
                raise ValueError(f"{name} must be {describe(interval)}, got {value!r}")
            if interval is None and not math.isfinite(number):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        elif hint is str and not isinstance(value, str):
            raise ValueError(f"{name} must be a string, got {value!r}")
        elif typing.get_origin(hint) is dict and not isinstance(value, dict):
            raise ValueError(f"{name} must be a JSON object such as {{\"is_slippery\": false}}, got {value!r}")


def check_budget(steps: Any, seed: Any) -> None:
    """A training call's step budget (an integer >= 1) and seed (an integer >= 0)."""
    if isinstance(steps, bool) or not isinstance(steps, numbers.Integral) or steps < 1:
        raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")


def config_dict(config: Any) -> dict[str, Any]:
    """A dataclass Config as a JSON-ready dict."""
    return dataclasses.asdict(config)


def config_from_dict(cls: type, values: dict[str, Any]) -> Any:
    """Rebuild a Config dataclass from :func:`config_dict`'s output, ignoring unknown keys."""
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in values.items() if k in names})
