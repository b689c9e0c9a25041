"""The algorithms the command line knows, by their lower-case names.

Each name maps to a module that provides:

- ``make_config(algo, **overrides) -> Config``: the algorithm's documented Config dataclass;
- ``train(env_id, config, steps, seed, out, progress)``: a run that writes ``out`` (see :mod:`rlcore.runs`)
  and saves a checkpoint on Ctrl-C;
- ``load_policy(checkpoint) -> policy``: the deterministic policy, a callable from observation to action.

Later chapters add their algorithms here (``dqn``, ``a2c``, ``reinforce``, ``ppo``, ``dppo``, ``ddpg``, ``td3``,
``sac``, ``crossq``).
"""

from __future__ import annotations

import difflib
import importlib
from types import ModuleType

ALGORITHMS: dict[str, str] = {
    "q-learning": "rlcore.tabular",
    "sarsa": "rlcore.tabular",
    "dqn": "rlcore.dqn",
    "a2c": "rlcore.a2c",
    "reinforce": "rlcore.reinforce",
    "ppo": "rlcore.ppo",
    "dppo": "rlcore.dppo",   # one worker here; N workers with torchrun (python -m rlcore.dppo)
    "ddpg": "rlcore.ddpg",
    "td3": "rlcore.td3",
    "sac": "rlcore.sac",
    "crossq": "rlcore.crossq",
}


class UnknownAlgorithmError(ValueError):
    """Raised for an algorithm name the command line does not know."""


def get_algorithm(name: str) -> ModuleType:
    """The module implementing algorithm ``name``."""
    if name not in ALGORITHMS:
        close = difflib.get_close_matches(name.lower(), list(ALGORITHMS), n=1)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        raise UnknownAlgorithmError(
            f"Unknown algorithm {name!r}.{hint} Known: {', '.join(sorted(ALGORITHMS))}."
        )
    return importlib.import_module(ALGORITHMS[name])
