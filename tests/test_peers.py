"""rlbook.peers: reading the returns benchmark's records."""
import json

import numpy as np
import pytest

from rlbook.analysis import fisher_exact
from rlbook.peers import forgetting_path, load_forgetting, load_peer, peer_path


def _record(env_id="Hopper-v5", seeds=(0, 1), final=((1.0, 3.0), (5.0, 7.0))):
    return {"env_id": env_id, "steps": 40_000, "command": "python benchmarks/ppo_returns_vs_sb3.py --env Hopper-v5",
            "evaluation": "deterministic", "machine": {"cpu_count": 2},
            "versions": {"stable_baselines3": "2.9.2", "torch": "2.13.0+cpu", "gymnasium": "1.4.0"},
            "seeds": [{"seed": s, "evals": {"step": [20_000, 40_000], "mean_return": [10.0 * s, 20.0 * s]},
                       "final_returns": list(f), "commit": c}
                      for s, f, c in zip(seeds, final, ("abc1234def", "abc1234def+dirty"))]}


def test_path_is_named_after_the_task(tmp_path):
    assert peer_path("HalfCheetah-v5", tmp_path) == tmp_path / "benchmarks" / "ppo-returns-sb3-halfcheetah.json"


def test_missing_or_empty_record_is_none(tmp_path):
    assert load_peer("Hopper-v5", tmp_path) is None
    peer_path("Hopper-v5", tmp_path).parent.mkdir(parents=True)
    peer_path("Hopper-v5", tmp_path).write_text(json.dumps({**_record(), "seeds": []}))
    assert load_peer("Hopper-v5", tmp_path) is None


def test_reads_curves_finals_and_provenance(tmp_path):
    peer_path("Hopper-v5", tmp_path).parent.mkdir(parents=True)
    peer_path("Hopper-v5", tmp_path).write_text(json.dumps(_record()))
    peer = load_peer("Hopper-v5", tmp_path)
    assert peer.seeds == [0, 1] and peer.final_episodes == 2
    np.testing.assert_allclose(peer.final_returns(), [2.0, 6.0])
    (steps, returns), _ = peer.curves()
    np.testing.assert_array_equal(steps, [20_000, 40_000])
    np.testing.assert_array_equal(returns, [0.0, 0.0])
    text = peer.provenance_markdown()
    assert text.startswith("::::{dropdown} Provenance: Stable-Baselines3 on Hopper-v5")
    assert "seeds 0, 1, 40,000 steps" in text and "abc1234, abc1234 (with uncommitted changes)" in text


def test_a_record_of_another_task_is_refused(tmp_path):
    peer_path("Hopper-v5", tmp_path).parent.mkdir(parents=True)
    peer_path("Hopper-v5", tmp_path).write_text(json.dumps(_record(env_id="Walker2d-v5")))
    with pytest.raises(ValueError, match="not 'Hopper-v5'"):
        load_peer("Hopper-v5", tmp_path)


def test_unequal_final_evaluations_are_refused(tmp_path):
    peer_path("Hopper-v5", tmp_path).parent.mkdir(parents=True)
    peer_path("Hopper-v5", tmp_path).write_text(json.dumps(_record(final=((1.0,), (5.0, 7.0)))))
    with pytest.raises(ValueError, match="different final-evaluation lengths"):
        load_peer("Hopper-v5", tmp_path).final_episodes


def test_the_stored_halfcheetah_record_reads():
    peer = load_peer("HalfCheetah-v5")
    assert peer is not None and peer.seeds == [0, 1, 2] and peer.final_episodes == 10
    assert peer.final_returns().shape == (3,)


def _forgetting(runs):
    return {"env_id": "CartPole-v1", "steps": 50_000, "solved": 475, "command": "nice -n 10 python benchmarks/x.py",
            "evaluation": "greedy", "machine": {"cpu_model": "Some CPU (AVX2)"},
            "versions": {"rlcore": "0.1.0", "stable_baselines3": "2.9.2", "torch": "2.13.0+cpu", "gymnasium": "1.4.0"},
            "runs": [{"impl": impl, "seed": seed, "final_returns": list(f), "commit": "abc1234def"}
                     for impl, seed, f in runs]}


def test_the_forgetting_record_compares_the_seeds_both_libraries_finished(tmp_path):
    assert load_forgetting(tmp_path) is None
    forgetting_path(tmp_path).parent.mkdir(parents=True)
    forgetting_path(tmp_path).write_text(json.dumps(_forgetting([("sb3", 0, (500, 500))])))
    assert load_forgetting(tmp_path) is None                      # no seed of rlcore's yet: nothing to compare
    forgetting_path(tmp_path).write_text(json.dumps(_forgetting([
        ("rlcore", 0, (500, 460)), ("rlcore", 1, (100, 120)), ("rlcore", 2, (500, 500)),
        ("sb3", 1, (500, 500)), ("sb3", 0, (480, 480))])))
    record = load_forgetting(tmp_path)
    assert record.seeds == [0, 1] and record.final_episodes == 2  # rlcore's seed 2 has no SB3 partner yet
    np.testing.assert_array_equal(record.finals("rlcore"), [480, 110])
    np.testing.assert_array_equal(record.holds("rlcore"), [True, False])
    np.testing.assert_array_equal(record.holds("sb3"), [True, True])
    text = record.provenance_markdown()
    assert "seeds 0–1 (2 each)" in text and "`nice -n 10 python benchmarks/x.py`" in text and "Some CPU" in text


@pytest.mark.parametrize("table, p", [((4, 5, 2, 5), 11 / 21), ((10, 10, 3, 10), 0.0030959752321981),
                                      ((5, 10, 5, 10), 1.0), ((0, 4, 4, 4), 2 / 70)])
def test_fisher_exact_by_hand(table, p):
    """By hand: the hypergeometric probabilities of every split at most as likely as the one seen, summed
    (for 0 of 4 against 4 of 4: the two extreme splits, 1/70 each)."""
    assert fisher_exact(*table) == pytest.approx(p, rel=1e-12)
