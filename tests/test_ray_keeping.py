"""benchmarks/ray_keeping.py's account of a seed's checkpoint traffic: one checkpoint every checkpoint_every steps
and the last, each the fixed bytes and the replay memory filled so far; and a transition's bytes in a checkpoint."""

import sys
from pathlib import Path

import pytest

import rlbook as ex

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from ray_keeping import seed_traffic, transition_bytes  # noqa: E402


def test_a_seeds_traffic_is_the_sum_of_its_checkpoints():
    spec = ex.RunSpec("t", "td3", "Pendulum-v1", 2_500, (0,), {"checkpoint_every": 1_000, "buffer_size": 1_500})
    row = seed_traffic(spec, per_transition=10.0, fixed=100)
    # checkpoints at 1,000, 2,000 and the last at 2,500; the memory holds at most 1,500
    assert row["checkpoints"] == 3
    assert row["sent_gib"] * 2**30 == pytest.approx(3 * 100 + 10.0 * (1_000 + 1_500 + 1_500))
    assert row["largest_mib"] * 2**20 == pytest.approx(100 + 10.0 * 1_500)


def test_a_transition_takes_about_one_observation_in_a_checkpoint():
    # Pendulum: 3 float32 observations, 1 float32 action, reward and end flag; a checkpoint keeps next_obs apart only
    # where it is not the next slot's obs (episode ends), so a transition is about 4 * (3 + 1 + 1 + 1) bytes
    per = transition_bytes("Pendulum-v1", continuous=True, steps=2_000)
    assert 4 * 6 <= per < 4 * 6 + 4 * 3
