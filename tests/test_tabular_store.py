"""rlbook.tabular_seeds' stored runs: a stored run is the run trained now, read back exactly; its key changes with
anything the run depends on (settings, budget, seed, code); nothing is written unless RLBOOK_STORE_TABULAR=1."""
import hashlib
import json

import numpy as np
import pytest

from rlbook import tabular_seeds
from rlbook.tabular_seeds import SeedPool, run_key, stored_run, train_seeds
from rlcore.tabular import Config, train

CONFIG = Config(env_kwargs={"is_slippery": False})


def same(a, b):
    return (np.array_equal(a.Q, b.Q) and np.array_equal(a.episode_returns, b.episode_returns)
            and np.array_equal(a.episode_lengths, b.episode_lengths)
            and np.array_equal(a.episode_end_steps, b.episode_end_steps) and a.steps == b.steps)


def test_a_stored_run_is_read_back_as_the_run_trained_now(tmp_path, monkeypatch):
    monkeypatch.setenv("RLBOOK_STORE_TABULAR", "1")
    first = train_seeds("FrozenLake-v1", CONFIG, 600, [0, 1], SeedPool(workers=1), folder=tmp_path)
    files = sorted(tmp_path.glob("*.npz"))
    assert len(files) == 2                                   # one file per seed
    monkeypatch.setattr(tabular_seeds, "train", lambda *a, **k: pytest.fail("trained again instead of read"))
    again = train_seeds("FrozenLake-v1", CONFIG, 600, [0, 1], folder=tmp_path)
    assert all(same(a, b) for a, b in zip(first, again))
    assert same(again[1], train("FrozenLake-v1", CONFIG, 600, 1))
    with np.load(files[0]) as data:                          # what it stands for and who trained it, inside
        meta = json.loads(str(data["meta"]))
    assert meta["params"]["env_id"] == "FrozenLake-v1" and meta["params"]["steps"] == 600 and "commit" in meta


def test_the_key_changes_with_anything_the_run_depends_on(monkeypatch):
    key = run_key("FrozenLake-v1", CONFIG, 600, 0)[0]
    assert key == run_key("FrozenLake-v1", Config(env_kwargs={"is_slippery": False}), 600, 0)[0]
    others = {run_key("FrozenLake-v1", Config(env_kwargs={"is_slippery": True}), 600, 0)[0],
              run_key("FrozenLake-v1", Config(env_kwargs={"is_slippery": False}, alpha=0.2), 600, 0)[0],
              run_key("FrozenLake-v1", CONFIG, 601, 0)[0], run_key("FrozenLake-v1", CONFIG, 600, 1)[0],
              run_key("CliffWalking-v1", CONFIG, 600, 0)[0]}
    assert key not in others and len(others) == 5
    monkeypatch.setattr(tabular_seeds, "code_sha256", lambda: "other code")
    assert run_key("FrozenLake-v1", CONFIG, 600, 0)[0] != key   # changed code: the stored run is stale


def test_without_the_switch_nothing_is_written(tmp_path, monkeypatch):
    monkeypatch.delenv("RLBOOK_STORE_TABULAR", raising=False)
    result = stored_run("FrozenLake-v1", CONFIG, 300, 0, folder=tmp_path)
    assert result.steps == 300 and list(tmp_path.iterdir()) == []


def test_the_stored_runs_are_the_current_codes():
    """A change to the code that trains them makes every stored run stale (the pages then train them again, minutes
    longer): store them again, and remove the stale ones. (Other versions of Gymnasium or NumPy on a reader's machine
    only mean that the pages train them there.)"""
    stored = sorted(tabular_seeds.stored_runs_dir().glob("*.npz"))
    assert stored, "results/tabular-runs/ is empty"
    current = tabular_seeds.code_sha256()
    stale = []
    for path in stored:
        with np.load(path) as data:
            params = json.loads(str(data["meta"]))["params"]
        named = hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:24]
        if params["code_sha256"] != current or named != path.stem:
            stale.append(path.name)
    assert not stale, (f"{len(stale)} of {len(stored)} stored tabular runs are stale (the code changed): delete "
                       "results/tabular-runs/ and run RLBOOK_STORE_TABULAR=1 RLBOOK_PROFILE=book pytest --nbval "
                       "chapters/01a_tabular_experiments.md chapters/01b_tabular_pitfalls.md, then the same with "
                       "RLBOOK_PROFILE=quick")
