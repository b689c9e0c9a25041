"""Command lines that repeat a run: ``--set`` arguments, ``python -m rlcore train`` for a page's live run, and
torchrun's for a distributed (dppo) run of an experiment, with a tiny two-worker run end to end."""

import json

import pytest

import rlbook as ex
from rlbook.runner import config_class, distributed_command
from rlcore.a2c import Config as A2CConfig
from rlcore.checkpoint import load_checkpoint
from rlcore.cli import overrides, set_args, train_command
from rlcore.dppo import Config


def test_set_args_are_read_back_as_the_same_overrides():
    values = {"hidden": (64, 64), "normalize_obs": True, "learning_rate": 0.001, "optimizer": "adam", "n_steps": 8,
              "env_kwargs": {"is_slippery": False}}
    args = set_args(values)
    assert args[:4] == ["--set", "hidden=[64, 64]", "--set", "normalize_obs=true"]
    back = overrides(A2CConfig, args[1::2])
    assert {**back, "hidden": tuple(back["hidden"])} == values
    assert set_args({}) == []


def test_train_command_sets_only_what_differs_from_the_defaults():
    config = A2CConfig(n_steps=8, gamma=0.9, normalize_obs=True)
    line = train_command("a2c", "Pendulum-v1", 300_000, 2, config)
    assert line == ("python -m rlcore train a2c --env Pendulum-v1 --steps 300000 --seed 2 --set gamma=0.9 "
                    "--set n_steps=8 --set normalize_obs=true")  # in the Config's field order
    assert train_command("a2c", "CartPole-v1", 40_000, 0, A2CConfig()).endswith("--seed 0")


def test_the_torchrun_command_sets_workers_budget_seed_and_every_override_readably():
    spec = ex.RunSpec("two", "dppo", "HalfCheetah-v5", 1_000, (0,),
                      {"eval_every": 500, "hidden": (32, 16), "share": "rollouts", "normalize_obs": False,
                       "learning_rate": 1e-3}, workers=3)
    cmd = distributed_command(spec, 7, "runs/x")
    assert cmd[1:5] == ["-m", "torch.distributed.run", "--standalone", "--nproc_per_node=3"]
    args = cmd[cmd.index("rlcore.dppo") + 1:]
    assert args[:9] == ["--env", "HalfCheetah-v5", "--steps", "1000", "--seed", "7", "--out", "runs/x",
                        "--no-progress"]
    sets = [a for i, a in enumerate(args) if i and args[i - 1] == "--set"]
    # what the workers' --set parser reads back is exactly the spec's overrides
    parsed = overrides(Config, sets)
    assert {**parsed, "hidden": tuple(parsed["hidden"])} == spec.overrides
    assert config_class("dppo") is Config and config_class("ppo") is not Config


def test_only_dppo_runs_go_through_torchrun():
    with pytest.raises(ValueError, match="only dppo"):
        distributed_command(ex.RunSpec("p", "ppo", "CartPole-v1", 100, (0,)), 0, "out")


def test_a_two_worker_run_lands_in_results_like_any_other(monkeypatch, tmp_path):
    exp = ex.Experiment("tiny-dppo", "two workers on CartPole", (
        ex.RunSpec("two", "dppo", "CartPole-v1", 512, (0,),
                   {"num_envs": 1, "n_steps": 128, "batch_size": 64, "n_epochs": 1, "eval_every": 256,
                    "eval_episodes": 1}, workers=2),))
    monkeypatch.setitem(ex.EXPERIMENTS, "tiny-dppo", lambda: exp)
    results, work = tmp_path / "results", tmp_path / "runs"
    ex.run_experiment("tiny-dppo", results=results, work=work)
    run = ex.load_experiment("tiny-dppo", results)["two"]
    assert [s.seed for s in run.seeds] == [0] and not run.missing
    seed = run.seeds[0]
    assert "torchrun --nproc_per_node 2 -m rlcore.dppo" in seed.meta["command"]
    assert load_checkpoint(seed.folder / "policy.pt")["step"] == 512   # 2 workers x 128 steps x 2 updates
    assert set(seed.evals["step"].tolist()) >= {512}
    assert seed.policy(__import__("numpy").zeros(4, dtype="float32")) in (0, 1)
    assert json.loads((seed.folder / "config.json").read_text())["env_id"] == "CartPole-v1"
