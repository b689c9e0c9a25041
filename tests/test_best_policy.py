"""A run keeps its best-evaluated policy (policy_best.pt) beside its last, as Stable-Baselines3's EvalCallback keeps
best_model; evaluate and render take either."""

import json

import pytest
import torch

from commandline import command
from rlcore import dqn
from rlcore.checkpoint import load_checkpoint

SCORES = [10.0, 50.0, 20.0, 5.0]
"""The evaluations at steps 100, 200, 300 and 400: up, then down."""


@pytest.fixture
def scripted_evaluations(monkeypatch):
    """DQN's evaluations return :data:`SCORES` in turn; the Q-network's weights at each are kept."""
    seen = []

    def evaluate_q(q, env, episodes, seed, gamma):
        seen.append({k: v.clone() for k, v in q.state_dict().items()})
        return {"mean_return": SCORES[len(seen) - 1], "std_return": 0.0, "episodes": episodes, "q_start": 0.0,
                "discounted_return_start": 0.0}

    monkeypatch.setattr(dqn, "evaluate_q", evaluate_q)
    return seen


CONFIG = dict(hidden=(16,), learning_starts=50, train_freq=4, gradient_steps=1, eval_every=100, eval_episodes=1)


def assert_best_is_the_second_evaluation(folder, seen):
    best = load_checkpoint(folder / "policy_best.pt")
    assert best["evaluation"]["step"] == best["step"] == 200 and best["evaluation"]["mean_return"] == 50.0
    assert all(torch.equal(best["q"][k], seen[1][k]) for k in seen[1])
    last = load_checkpoint(folder / "checkpoint.pt")
    assert last["step"] == 400 and not torch.equal(last["q"]["net.0.weight"], best["q"]["net.0.weight"])


def test_a_run_whose_evaluations_go_up_then_down_keeps_the_best(tmp_path, scripted_evaluations):
    dqn.train("CartPole-v1", dqn.Config(**CONFIG), steps=400, seed=0, out=tmp_path)
    assert_best_is_the_second_evaluation(tmp_path, scripted_evaluations)
    assert dqn.load_policy(load_checkpoint(tmp_path / "policy_best.pt"))([0.0, 0.0, 0.0, 0.0]) in (0, 1)


def test_a_resumed_run_keeps_the_best_of_the_evaluations_before_and_after(tmp_path, scripted_evaluations,
                                                                          interrupt_at_first_checkpoint):
    interrupt_at_first_checkpoint(dqn)
    config = dqn.Config(**CONFIG, checkpoint_every=300)
    with pytest.raises(KeyboardInterrupt):
        dqn.train("CartPole-v1", config, steps=400, seed=0, out=tmp_path)
    assert load_checkpoint(tmp_path / "checkpoint.pt")["step"] == 300
    dqn.train("CartPole-v1", config, steps=400, seed=0, out=tmp_path)  # its evaluation at 400 scores less
    assert_best_is_the_second_evaluation(tmp_path, scripted_evaluations)


def test_evaluate_takes_the_last_or_the_best_policy(tmp_path, scripted_evaluations):
    dqn.train("CartPole-v1", dqn.Config(**CONFIG), steps=400, seed=0, out=tmp_path / "run")

    def evaluate(folder, *which):
        return command("rlcore", "evaluate", folder, "--episodes", "1", *which, check=False)

    last, best = (json.loads(evaluate(tmp_path / "run", *w).stdout.splitlines()[-1]) for w in ((), ("--which", "best")))
    assert (last["policy"], last["train_steps"]) == ("last", 400) and "training_evaluation" not in last
    assert (best["policy"], best["train_steps"]) == ("best", 200)
    assert best["training_evaluation"]["mean_return"] == 50.0
    (tmp_path / "results").mkdir()  # a results folder keeps only the last policy
    (tmp_path / "run" / "checkpoint.pt").rename(tmp_path / "results" / "policy.pt")
    proc = evaluate(tmp_path / "results", "--which", "best")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "keeps only the last" in lines[0], proc.stderr
