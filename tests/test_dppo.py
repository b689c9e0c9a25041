"""Data-parallel PPO: workers agree, one worker is PPO, a killed worker's job resumes, one worker learns."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from gymnasium.wrappers.utils import RunningMeanStd

from rlcore import distributed, dppo, ppo
from rlcore.checkpoint import load_checkpoint
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy
from rlcore.logger import read_csv

SMALL = dict(num_envs=2, n_steps=256, batch_size=64, n_epochs=4, learning_rate=1e-3, eval_every=0)
TINY = ["--set", "num_envs=2", "--set", "n_steps=64", "--set", "batch_size=32", "--set", "n_epochs=2",
        "--set", "eval_every=0"]
PER_UPDATE = 2 * 2 * 64  # workers x num_envs x n_steps
BUDGET = 16 * PER_UPDATE


def _same(a, b) -> bool:
    if isinstance(a, torch.Tensor):
        return torch.equal(a, b)
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


@pytest.fixture(scope="module")
def killed_and_restarted(tmp_path_factory):
    """A 2-worker torchrun job on Pendulum whose rank 1 dies (SIGKILL) as it starts its third update (after two
    updates were logged and checkpointed); torchrun restarts the job once, and it resumes from the checkpoint."""
    out = tmp_path_factory.mktemp("dppo") / "run"
    marker = out.parent / "killed"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2", "--standalone",
           "--max-restarts", "1", "-m", "_dppo_dies_once", "--env", "Pendulum-v1", "--steps", str(BUDGET),
           "--seed", "3", "--out", str(out), "--no-progress", "--dump-params", str(out / "dump"), *TINY]
    env = {**os.environ, "RLCORE_TEST_DIE_ONCE": str(marker),
           "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stdout
    assert marker.exists(), "worker 1 never died:\n" + proc.stdout
    return out, proc.stdout


def test_workers_hold_identical_weights_optimizer_and_statistics(killed_and_restarted):
    out, _ = killed_and_restarted
    r0, r1 = load_checkpoint(out / "dump" / "rank0.pt"), load_checkpoint(out / "dump" / "rank1.pt")
    assert r0["step"] == BUDGET and r0["iteration"] == BUDGET // PER_UPDATE
    for key in ("agent", "optimizer", "kl_coef", "obs_mean", "obs_var", "obs_count", "ret_mean", "ret_var",
                "ret_count"):
        assert _same(r0[key], r1[key]), key
    assert r0["optimizer"]["state"], "the optimizer took steps"
    ckpt = load_checkpoint(out / "checkpoint.pt")
    assert _same(ckpt["agent"], r0["agent"]) and _same(ckpt["obs_mean"], r0["obs_mean"])


def test_checkpoint_is_a_ppo_checkpoint_for_load_policy_and_the_cli(killed_and_restarted, capsys, tmp_path):
    from rlcore.__main__ import main

    out, _ = killed_and_restarted
    ckpt = load_checkpoint(out / "checkpoint.pt")
    assert ckpt["algo"] == "ppo" and ckpt["distributed"] == {"world_size": 2, "backend": "gloo"}
    policy = ppo.load_policy(ckpt)
    np.testing.assert_array_equal(policy.obs_mean, ckpt["obs_mean"].numpy())
    assert np.all(np.abs(policy(np.array([0.5, -0.5, 1.0]))) <= 2.0)
    assert main(["evaluate", str(out), "--episodes", "1", "--max-steps", "20"]) == 0
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["train_steps"] == BUDGET
    shutil.copytree(out, tmp_path / "copy")
    with pytest.raises(ValueError, match="data-parallel"):  # single-process PPO refuses to resume it
        ppo.train("Pendulum-v1", ppo.Config(**SMALL), steps=BUDGET * 2, seed=3, out=tmp_path / "copy")


def test_killed_worker_job_resumes_from_the_checkpoint_without_duplicate_log_rows(killed_and_restarted):
    out, log = killed_and_restarted
    meta = json.loads((out / "meta.json").read_text())
    assert meta["distributed"]["world_size"] == 2 and meta["command"].startswith("torchrun --nproc_per_node 2")
    resumed = [r["step"] for r in meta["resumes"]]
    assert len(resumed) == 1 and 2 * PER_UPDATE <= resumed[0] < BUDGET, (resumed, log)
    rows = read_csv(out / "progress.csv")
    np.testing.assert_array_equal(rows["step"], np.arange(1, BUDGET // PER_UPDATE + 1) * PER_UPDATE)
    assert np.all(rows["env_steps_per_second"] > 0) and np.all(rows["world_size"] == 2)
    assert np.isfinite(rows["episode_return"]).any()


def test_one_worker_is_ppo_bit_for_bit(tmp_path):
    torch.set_num_threads(1)
    config = dict(SMALL, objective="kl")  # the KL rule and the learning-rate schedule too
    a = ppo.train("Pendulum-v1", ppo.Config(**config), steps=1_024, seed=5, out=tmp_path / "ppo")
    b = dppo.train("Pendulum-v1", dppo.Config(**config), steps=1_024, seed=5, out=tmp_path / "dppo")
    assert _same(a.agent.state_dict(), b.agent.state_dict())
    np.testing.assert_array_equal(a.episode_returns, b.episode_returns)
    np.testing.assert_array_equal(a.policy.obs_mean, b.policy.obs_mean)
    assert not torch.distributed.is_initialized()  # the one-worker group is gone again
    with pytest.raises(ValueError, match="single-process PPO run"):  # neither resumes the other's run
        dppo.train("Pendulum-v1", dppo.Config(**config), steps=2_048, seed=5, out=tmp_path / "ppo")


def test_resume_with_a_larger_budget_starts_from_the_checkpoint_step(tmp_path):
    torch.set_num_threads(1)
    dppo.train("Pendulum-v1", dppo.Config(**SMALL, anneal_lr=False), steps=512, seed=0, out=tmp_path)
    first = load_checkpoint(tmp_path / "checkpoint.pt")
    result = dppo.train("Pendulum-v1", dppo.Config(**SMALL, anneal_lr=False), steps=1_536, seed=0, out=tmp_path)
    second = load_checkpoint(tmp_path / "checkpoint.pt")
    assert (first["step"], first["iteration"], second["step"], second["iteration"]) == (512, 1, 1_536, 3)
    assert result.steps == 1_536 and second["obs_count"] > first["obs_count"]
    assert [r["step"] for r in json.loads((tmp_path / "meta.json").read_text())["resumes"]] == [512]
    assert read_csv(tmp_path / "progress.csv")["step"].tolist() == [512, 1_024, 1_536]


def test_one_worker_learns_cartpole(tmp_path):
    torch.set_num_threads(1)
    dppo.train("CartPole-v1", dppo.Config(**SMALL), steps=8_192, seed=0, out=tmp_path)
    policy = ppo.load_policy(load_checkpoint(tmp_path / "checkpoint.pt"))
    returns = evaluate_policy(policy, make_env("CartPole-v1"), episodes=5, seed=7)
    assert returns.mean() > 100, returns  # a random policy averages about 22


def test_merged_statistics_are_those_of_all_the_data():
    rng = np.random.default_rng(0)
    base = RunningMeanStd(shape=(3,))
    base.update(rng.normal(5.0, 2.0, (50, 3)))
    start = distributed.snapshot(base)
    data = [rng.normal(5.5, 3.0, (40, 3)), rng.normal(4.0, 1.0, (70, 3))]  # two workers' new observations
    contributions = []
    for x in data:
        w = RunningMeanStd(shape=(3,))
        w.mean, w.var, w.count = start[0].copy(), start[1].copy(), start[2]
        for chunk in np.array_split(x, 4):
            w.update(chunk)
        contributions.append(distributed.stats_contribution(w, start))
    mean, var, count = distributed.merge_contributions(start, np.sum(contributions, axis=0))
    one = RunningMeanStd(shape=(3,))
    one.mean, one.var, one.count = start[0].copy(), start[1].copy(), start[2]
    one.update(np.concatenate(data))
    np.testing.assert_allclose(mean, one.mean, rtol=1e-12)
    np.testing.assert_allclose(var, one.var, rtol=1e-10)
    assert count == pytest.approx(one.count)


def test_half_a_torchrun_environment_is_a_clear_error(monkeypatch):
    monkeypatch.setenv("RANK", "0")
    monkeypatch.setenv("WORLD_SIZE", "2")
    monkeypatch.delenv("MASTER_ADDR", raising=False)
    with pytest.raises(ValueError, match="MASTER_ADDR.*torchrun --nproc_per_node"):
        distributed.init_distributed()


def test_sharing_rollouts_keeps_the_workers_identical(tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2", "--standalone",
           "-m", "rlcore.dppo", "--env", "Pendulum-v1", "--steps", str(4 * PER_UPDATE), "--seed", "1",
           "--out", str(out), "--no-progress", "--dump-params", str(out / "dump"), *TINY, "--set", "share=rollouts"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stdout + done.stderr
    r0, r1 = load_checkpoint(out / "dump" / "rank0.pt"), load_checkpoint(out / "dump" / "rank1.pt")
    assert r0["step"] == 4 * PER_UPDATE and r0["iteration"] == 4
    for key in ("agent", "optimizer", "kl_coef", "obs_mean", "obs_var", "obs_count"):
        assert _same(r0[key], r1[key]), key
    assert r0["optimizer"]["state"], "the optimizer took steps"
    assert load_checkpoint(out / "checkpoint.pt")["config"]["share"] == "rollouts"


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


TINY_CONFIG = {"num_envs": 2, "n_steps": 64, "batch_size": 32, "n_epochs": 2, "eval_every": 0}
TIMING = {"env_steps_per_second", "update_seconds", "rollout_seconds"}


def test_two_nodes_of_one_worker_train_the_two_worker_run(tmp_path):
    # torchrun's multi-node rendezvous (c10d) with two agents on this machine as two "nodes" of one worker each:
    # the job is the single-node two-worker one, bit for bit (gloo's sum of two numbers does not depend on order)
    from rlcore.launch import torchrun_command

    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    runs = {}
    for name, nodes in (("one-node", 1), ("two-nodes", 2)):
        out = tmp_path / name
        cmd = torchrun_command(2 // nodes, "Pendulum-v1", 4 * PER_UPDATE, 1, out, TINY_CONFIG, nodes=nodes,
                               rendezvous=f"localhost:{_free_port()}", job_id=f"test-{os.getpid()}",
                               extra=["--dump-params", str(out / "dump")])
        agents = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
                  for _ in range(nodes)]
        logs = [a.communicate(timeout=300)[0] for a in agents]
        assert [a.returncode for a in agents] == [0] * nodes, logs
        runs[name] = out
    one, two = runs["one-node"], runs["two-nodes"]
    meta = json.loads((two / "meta.json").read_text())
    assert meta["distributed"]["world_size"] == 2
    assert meta["command"].startswith("torchrun --nnodes 2 --nproc_per_node 1")
    for rank in (0, 1):
        a, b = load_checkpoint(one / "dump" / f"rank{rank}.pt"), load_checkpoint(two / "dump" / f"rank{rank}.pt")
        assert a["iteration"] == 4 and _same(a, b), rank
    assert _same(load_checkpoint(one / "checkpoint.pt")["agent"], load_checkpoint(two / "checkpoint.pt")["agent"])
    x, y = read_csv(one / "progress.csv"), read_csv(two / "progress.csv")
    assert x.keys() == y.keys() and len(x["step"]) == 4
    for column in set(x) - TIMING:
        np.testing.assert_array_equal(x[column], y[column], err_msg=column)


def _gather_worker(rank: int, store_file: str, out_dir: str) -> None:
    torch.distributed.init_process_group("gloo", init_method=f"file://{store_file}", rank=rank, world_size=2)
    n = 3 + 2 * rank  # the workers' rollouts differ in length (reset steps are dropped)
    mine = {"obs": torch.full((n, 2), float(rank)), "adv": torch.arange(n, dtype=torch.float32) + 10 * rank}
    merged = distributed.gather_rollouts(mine)
    torch.save(merged, Path(out_dir) / f"rank{rank}.pt")
    torch.distributed.destroy_process_group()


def test_gather_rollouts_concatenates_every_worker_in_rank_order(tmp_path):
    torch.multiprocessing.spawn(_gather_worker, args=(str(tmp_path / "store"), str(tmp_path)), nprocs=2)
    for rank in (0, 1):
        merged = torch.load(tmp_path / f"rank{rank}.pt", weights_only=True)
        assert merged["obs"].shape == (8, 2)
        assert merged["obs"][:3].eq(0).all() and merged["obs"][3:].eq(1).all()
        assert merged["adv"].tolist() == [0, 1, 2, 10, 11, 12, 13, 14]


def test_an_unknown_way_of_sharing_is_a_clear_error():
    with pytest.raises(ValueError, match="share must be one of"):
        dppo.Config(share="weights")
