"""The course report's DDPG settings and scores as it prints them, in its own names.

The experiments in :mod:`rlbook.registry` encode these tables in ``rlcore``'s names;
``tests/test_course_report.py`` checks that the two agree, so a chapter can print the report's tables and our runs'
settings side by side, and quote the report's scores, from one place.
"""

from __future__ import annotations

from typing import Any

# The report's name for each setting of its tables, and rlcore.ddpg.Config's field for it.
REPORT_NAMES: dict[str, tuple[str, str]] = {
    "memory": ("memory-size", "buffer_size"), "hidden": ("hidden-size", "hidden"), "lr_a": ("LR-A", "actor_lr"),
    "lr_c": ("LR-C", "critic_lr"), "gamma": ("GAMMA", "gamma"), "tau": ("TAU", "tau"),
    "batch": ("batch-size", "batch_size"), "start": ("start-step", "learning_starts"),
    "decay": ("explore-decay", "explore_decay"), "reward_factor": ("reward-factor", "reward_scale"),
}

# Tables 1-3 (Ant, HalfCheetah, Hopper) as printed, with the score the report gives for each task: its own metric,
# the mean training reward per epoch of `epoch_steps` steps over the last 20 epochs. On Ant that is its run without
# exploration noise (2232.8; with noise 2085.4); on HalfCheetah and Hopper its best of three configurations ("v2").
REPORT_DDPG_TABLES: dict[str, dict[str, Any]] = {
    "ant": dict(table=1, memory=100_000, hidden=256, lr_a=1e-4, lr_c=1e-3, gamma=0.99, tau=0.005, batch=256,
                epochs=100, start=25_000, epoch_steps=2500, decay=0.999995, reward_factor=10, score=2232.8),
    "halfcheetah": dict(table=2, memory=1_000_000, hidden=256, lr_a=1e-4, lr_c=1e-3, gamma=0.99, tau=0.001,
                        batch=64, epochs=200, start=5_000, epoch_steps=1000, decay=0.99998, reward_factor=1,
                        score=3848.4),
    "hopper": dict(table=3, memory=100_000, hidden=512, lr_a=1e-4, lr_c=1e-3, gamma=0.99, tau=0.001, batch=64,
                   epochs=400, start=10_000, epoch_steps=1000, decay=0.99998, reward_factor=0.5, score=2532.2),
}

# Table 4 (Humanoid) as printed, and what the report's text changes for its "large-scale" variant. The report
# prints no score for either: it says both "perform bad".
REPORT_DDPG_HUMANOID_TABLES: dict[str, dict[str, Any]] = {
    "small": dict(table=4, memory=100_000, hidden=512, lr_a=1e-4, lr_c=1e-3, gamma=0.99, tau=0.005, batch=256,
                  epochs=100, start=25_000, epoch_steps=5000, decay=0.999995, reward_factor=50),
}
REPORT_DDPG_HUMANOID_TABLES["large"] = {**REPORT_DDPG_HUMANOID_TABLES["small"], "hidden": (1024, 1024),
                                        "memory": 1_000_000, "epochs": 500, "decay": 0.999998}

# What the report measured for the arms of its comparisons (section 4.2; its metric), in its words.
REPORT_DDPG_ARMS: dict[str, str] = {
    "ant": "DDPG without noise 2232.8, DDPG-explore 2085.4",
    "halfcheetah": "v2 3848.4, v3 3510.5, v1 (\"inappropriate batch size\") 1245.3; batch sizes not given",
    "hopper": "v2 2532.2, v3 2011.6, v1 2380.1; network sizes not given",
}


def report_overrides(table: dict[str, Any]) -> dict[str, Any]:
    """A table's settings in rlcore.ddpg.Config's names (``hidden`` as a tuple of layer sizes)."""
    out = {}
    for key, (_, field) in REPORT_NAMES.items():
        value = table[key]
        out[field] = (tuple(value) if isinstance(value, (tuple, list)) else (value,)) if key == "hidden" else value
    return out


def report_steps(table: dict[str, Any]) -> int:
    """A table's training budget: epochs x step-per-epoch."""
    return int(table["epochs"] * table["epoch_steps"])
