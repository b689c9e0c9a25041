"""rlbook.reevaluation: a run's final policies evaluated again, the clipping-fix check, and one policy
run three ways."""

import numpy as np
import pytest
import torch

import rlbook as ex
from rlcore.checkpoint import load_checkpoint, save_checkpoint
from rlbook.reevaluation import (action_clipping_returns, final_policy_returns,
                                 trained_before_clipping_fix)
from rlcore.evaluate import evaluate_policy
from rlcore.ppo import Config, train
from rlcore.machine import cpu_model


@pytest.fixture(scope="module")
def tiny_ppo(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("reeval")
    exp = ex.Experiment("tiny-ppo", "two seeds of a tiny PPO on Pendulum", (
        ex.RunSpec("ppo", "ppo", "Pendulum-v1", 256, (0, 1),
                   {"num_envs": 1, "n_steps": 128, "batch_size": 64, "n_epochs": 1, "eval_every": 128,
                    "eval_episodes": 2}),))
    mp = pytest.MonkeyPatch()
    mp.setitem(ex.EXPERIMENTS, "tiny-ppo", lambda: exp)
    ex.run_experiment("tiny-ppo", results=tmp / "results", work=tmp / "runs")
    yield ex.load_experiment("tiny-ppo", tmp / "results")["ppo"]
    mp.undo()


def test_final_policies_evaluated_again_reproduce_the_last_logged_evaluation(tiny_ppo):
    finals = final_policy_returns(tiny_ppo, episodes=2)
    assert finals.shape == (2,)
    # same policy, same start states (seed + 10,000 + i): the returns of eval.csv's last row. Under other kernels
    # (ATEN_CPU_CAPABILITY=default) the two evaluations round apart in the 9th digit (1.9e-9 seen), hence 1e-6
    np.testing.assert_allclose(finals, ex.final_returns(tiny_ppo), rtol=1e-6)
    assert final_policy_returns(tiny_ppo, episodes=2) is finals           # computed once
    assert not np.array_equal(final_policy_returns(tiny_ppo, episodes=1), finals)


def test_a_policy_saved_with_infinite_action_bounds_was_trained_before_the_fix(tiny_ppo):
    assert not trained_before_clipping_fix(tiny_ppo).any()
    path = tiny_ppo.seeds[1].folder / "policy.pt"
    ckpt = load_checkpoint(path)
    ckpt["spaces"]["low"] = np.full_like(ckpt["spaces"]["low"], -np.inf)
    ckpt["spaces"]["high"] = np.full_like(ckpt["spaces"]["high"], np.inf)
    save_checkpoint(path, {k: v for k, v in ckpt.items() if k not in ("format", "format_version")})
    assert trained_before_clipping_fix(tiny_ppo).tolist() == [False, True]


def _policy(env_id, scale):
    """An untrained PPO policy on env_id whose mean actions are the network's times ``scale``."""
    policy = train(env_id, Config(num_envs=1, n_steps=64, batch_size=64, n_epochs=1, eval_every=0), 64,
                   seed=0).policy
    with torch.no_grad():
        for p in policy.agent.actor[-1].parameters():
            p.mul_(scale)
    return policy


def test_three_ways_on_pendulum_which_clips_the_torque_before_its_cost():
    policy = _policy("Pendulum-v1", 1_000.0)
    out = action_clipping_returns(policy, "Pendulum-v1", episodes=1)
    assert 0 < out["outside"] <= 1                             # the scaled means leave [-2, 2]
    assert out["clipped"] == pytest.approx(out["unclipped"], rel=1e-6)   # Pendulum clips before charging
    from rlcore.envs import make_env
    from rlcore.evaluate import evaluate_policy

    assert out["clipped"] == evaluate_policy(policy, make_env("Pendulum-v1"), 1, seed=20_000)[0]
    assert out["sampled"] != out["clipped"]


def test_three_ways_on_halfcheetah_which_charges_the_unclipped_action():
    out = action_clipping_returns(_policy("HalfCheetah-v5", 1_000.0), "HalfCheetah-v5", episodes=1)
    assert out["outside"] > 0.5
    assert out["unclipped"] < out["clipped"] - 1_000            # 0.1 sum a^2 on huge actions, 1,000 steps
    small = action_clipping_returns(_policy("HalfCheetah-v5", 1e-3), "HalfCheetah-v5", episodes=1)
    assert small["outside"] == 0 and small["clipped"] == pytest.approx(small["unclipped"], rel=1e-6)


def test_stored_final_returns_are_read_back_with_provenance_and_ignored_once_the_policy_changes(tiny_ppo, tmp_path,
                                                                                                   capsys):
    import json
    import shutil

    from rlbook import reevaluation
    from rlbook.__main__ import main

    shutil.copytree(tiny_ppo.seeds[0].folder.parents[2], tmp_path / "results")  # a copy: the other tests' stays
    assert main(["experiments", "reevaluate", "tiny-ppo", "--episodes", "2", "--results",
                 str(tmp_path / "results")]) == 0
    run = ex.load_experiment("tiny-ppo", tmp_path / "results")["ppo"]
    assert capsys.readouterr().out.count((reevaluation.FINAL + '.json')) == 2
    path = run.seeds[0].folder / (reevaluation.FINAL + '.json')
    record = json.loads(path.read_text())
    (record,) = record["records"]
    value = record["value"]
    assert len(value["returns"]) == 2 and value["lengths"] == [200, 200]
    assert record["params"]["first_reset_seed"] == 10_000
    assert {"command", "commit", "versions", "machine"} <= set(record) and record["machine"]["cpu"] == cpu_model()
    reevaluation._FINALS.clear()
    live = np.array([evaluate_policy(s.policy, _pendulum(), 2, seed=s.seed + 10_000).mean() for s in run.seeds])
    np.testing.assert_array_equal(final_policy_returns(run, episodes=2), live)  # stored on this processor

    record["value"]["returns"] = [1.0, 3.0]  # what another processor might have stored
    path.write_text(json.dumps({"records": [record]}))
    reevaluation._FINALS.clear()
    assert final_policy_returns(run, episodes=2)[0] == 2.0                   # read, not evaluated
    assert final_policy_returns(run, episodes=1)[0] != 1.0                   # another number of episodes: evaluated
    ckpt = load_checkpoint(run.seeds[0].folder / "policy.pt")
    save_checkpoint(run.seeds[0].folder / "policy.pt", {**ckpt, "obs_clip": 9.0})  # a policy trained again
    reevaluation._FINALS.clear()
    assert final_policy_returns(run, episodes=2)[0] != 2.0                   # stale: evaluated again

    assert main(["experiments", "reevaluate", "tiny-ppo", "--only", "nope", "--results",
                 str(tmp_path / "results")]) == 2
    assert "tiny-ppo has no run 'nope'; its runs: ppo." in capsys.readouterr().err

    # --seeds: only the chosen seed's file is written again; the other seed's stays byte for byte
    other = run.seeds[1].folder / (reevaluation.FINAL + '.json')
    before = other.read_bytes()
    assert main(["experiments", "reevaluate", "tiny-ppo", "--seeds", str(run.seeds[0].seed), "--episodes", "2",
                 "--results", str(tmp_path / "results")]) == 0
    assert capsys.readouterr().out.count(reevaluation.FINAL + '.json') == 1
    assert other.read_bytes() == before
    assert json.loads(path.read_text())["records"][0]["params"]["episodes"] == 2


def test_stored_computes_once_writes_only_when_asked_and_reads_back_the_same_params(tiny_ppo, tmp_path, monkeypatch):
    import json
    import shutil

    from rlbook import reevaluation

    shutil.copytree(tiny_ppo.seeds[0].folder.parents[2], tmp_path / "results")
    seed = ex.load_experiment("tiny-ppo", tmp_path / "results")["ppo"].seeds[0]
    calls = []

    def compute():
        calls.append(1)
        return {"x": float(len(calls))}

    monkeypatch.delenv(reevaluation.STORE, raising=False)
    assert reevaluation.stored(seed, "probe", {"k": 1}, compute) == {"x": 1.0}
    assert not (seed.folder / "probe.json").exists()                    # not asked to store
    monkeypatch.setenv(reevaluation.STORE, "1")
    assert reevaluation.stored(seed, "probe", {"k": 1}, compute) == {"x": 2.0}
    assert "jupyter-book build" in json.loads((seed.folder / "probe.json").read_text())["records"][0]["command"]
    assert reevaluation.stored(seed, "probe", {"k": 1}, compute) == {"x": 2.0} and len(calls) == 2  # read back
    assert reevaluation.stored(seed, "probe", {"k": 2}, compute) == {"x": 3.0}  # other params: computed again
    assert reevaluation.stored(seed, "probe", {"k": 1}, compute) == {"x": 2.0} and len(calls) == 3  # both kept


def _pendulum():
    from rlcore.envs import make_env

    return make_env("Pendulum-v1")


def test_fresh_iqm_rows_summarize_seeds_only_when_there_are_enough(tiny_ppo):
    from rlbook.analysis import iqm_ci
    from rlbook.reevaluation import fresh_iqm_rows, stored_returns

    (row,) = fresh_iqm_rows({"PPO": tiny_ppo}, episodes=2, min_seeds=2)
    scores = np.array([stored_returns(s, "Pendulum-v1", 2, 20_000 + s.seed).mean() for s in tiny_ppo.seeds])
    assert not np.isclose(scores[0], scores[1])                   # two seeds, two scores
    iqm, low, high = iqm_ci({"PPO": scores})["PPO"]
    assert row["finished seeds"] == "2 of 2" and row["steps"] == "256" and row["task"] == "Pendulum-v1"
    assert row["IQM over seeds (mean of 2 fresh episodes each)"] == f"{iqm:,.0f}"
    assert row["95 % interval"] == f"{low:,.0f} to {high:,.0f}" and row["lowest seed"] == f"{scores.min():,.0f}"
    (waiting,) = fresh_iqm_rows({"PPO": tiny_ppo}, episodes=2, min_seeds=3)
    assert waiting["IQM over seeds (mean of 2 fresh episodes each)"] == "waits for 3 seeds"
    assert waiting["lowest seed"] == "—"
