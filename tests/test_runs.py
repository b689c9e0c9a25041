"""rlcore.provenance and rlcore.runs: what a run records about the code that trained it; its folder."""

import json
import os
import subprocess
import sys
from dataclasses import dataclass

import pytest

from commandline import command
from rlcore import machine, provenance, runs


def test_a_process_records_the_commit_it_loaded_not_the_checkouts_later_one():
    # a long experiment process keeps the code it imported while the checkout moves on to new commits
    # (the command lines ask for loaded_commit() as they start; a library user's first run_metadata() does)
    code = ("import os, rlcore.provenance as r; r.loaded_commit(); os.environ['RLCORE_COMMIT'] = 'later'; "
            "m = r.run_metadata(); print(m['commit'], m['checkout_at_start'])")
    out = subprocess.run([sys.executable, "-c", code], env={**os.environ, "RLCORE_COMMIT": "loaded"},
                         capture_output=True, text=True, check=True).stdout.split()
    assert out == ["loaded", "later"]


def test_importing_the_library_runs_no_git():
    code = ("import subprocess; calls = []; run = subprocess.run\n"
            "subprocess.run = lambda *a, **k: calls.append(a) or run(*a, **k)\n"
            "import rlcore.runs, rlcore.provenance, rlcore.harness, rlcore.ddpg, rlcore.__main__\n"
            "print(len(calls))")
    env = {k: v for k, v in os.environ.items() if k != "RLCORE_COMMIT"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split()[-1] == "0"


def test_no_checkout_field_while_the_checkout_is_what_was_loaded(tmp_path, monkeypatch):
    @dataclass
    class Tiny:
        lr: float = 0.1

    monkeypatch.setattr(provenance, "loaded_commit", lambda: "abc")
    monkeypatch.setattr(provenance, "git_commit", lambda cwd=None: "abc")
    run, ckpt = runs.open_run(tmp_path / "run", "q-learning", "FrozenLake-v1", 0, 10, Tiny())
    meta = json.loads(run.meta.read_text())
    assert ckpt is None and meta["commit"] == "abc" and "checkout_at_start" not in meta
    monkeypatch.setattr(provenance, "git_commit", lambda cwd=None: "def+dirty")
    assert provenance.run_metadata()["checkout_at_start"] == "def+dirty"


def test_changes_under_results_do_not_make_a_checkout_dirty(tmp_path, monkeypatch):
    monkeypatch.delenv("RLCORE_COMMIT", raising=False)

    def git(*args):
        subprocess.run(["git", *args], cwd=tmp_path, check=True, capture_output=True)

    git("init", "-q")
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "eval.csv").write_text("1\n")
    (tmp_path / "code.py").write_text("x = 1\n")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@example.org", "commit", "-qm", "start")
    clean = provenance.git_commit(tmp_path)
    assert clean is not None and len(clean) == 40
    (tmp_path / "results" / "eval.csv").write_text("2\n")  # a run's outputs being copied in
    assert provenance.git_commit(tmp_path) == clean
    (tmp_path / "code.py").write_text("x = 2\n")
    assert provenance.git_commit(tmp_path) == clean + "+dirty"


def test_a_dirty_checkout_records_which_files_were_uncommitted_and_a_hash_of_their_changes(tmp_path, monkeypatch):
    monkeypatch.delenv("RLCORE_COMMIT", raising=False)

    def git(*args):
        subprocess.run(["git", *args], cwd=tmp_path, check=True, capture_output=True)

    git("init", "-q")
    (tmp_path / "code.py").write_text("x = 1\n")
    (tmp_path / "other.py").write_text("y = 1\n")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@example.org", "commit", "-qm", "start")
    assert provenance.uncommitted_changes(tmp_path) is None
    (tmp_path / "code.py").write_text("x = 2\n")
    first = provenance.uncommitted_changes(tmp_path)
    assert first["files"] == [" M code.py"] and len(first["diff_sha256"]) == 64
    (tmp_path / "code.py").write_text("x = 3\n")  # the same file, other changes: another hash
    second = provenance.uncommitted_changes(tmp_path)
    assert second["files"] == first["files"] and second["diff_sha256"] != first["diff_sha256"]


def test_a_run_from_a_dirty_checkout_records_its_changes_and_a_command_warns_in_one_line(monkeypatch):
    changes = {"files": [" M rlcore/ppo.py", " M rlcore/dqn.py"], "diff_sha256": "ab" * 32}
    monkeypatch.setattr(provenance, "loaded_commit", lambda: "abc+dirty")
    monkeypatch.setattr(provenance, "loaded_changes", lambda: changes)
    monkeypatch.setattr(provenance, "git_commit", lambda cwd=None: "abc+dirty")
    assert provenance.run_metadata()["uncommitted"] == changes
    warning = provenance.dirty_warning()
    assert "\n" not in warning and "rlcore/ppo.py, rlcore/dqn.py" in warning
    monkeypatch.setattr(provenance, "loaded_commit", lambda: "abc")
    monkeypatch.setattr(provenance, "loaded_changes", lambda: None)
    monkeypatch.setattr(provenance, "git_commit", lambda cwd=None: "abc")
    assert "uncommitted" not in provenance.run_metadata() and provenance.dirty_warning() is None


def test_a_run_does_not_resume_a_checkpoint_of_other_settings(tmp_path):
    import pytest
    import torch

    from rlcore.ddpg import Config, train

    torch.set_num_threads(1)
    small = dict(hidden=(16,), batch_size=16, learning_starts=50, eval_every=0, checkpoint_every=100)
    train("Pendulum-v1", Config(**small), steps=100, seed=0, out=tmp_path)
    with pytest.raises(ValueError, match=r"other settings \(normalize_obs: False -> True\)"):
        train("Pendulum-v1", Config(normalize_obs=True, **small), steps=200, seed=0, out=tmp_path)
    # what is only logged or saved may change, and settings a checkpoint predates are not compared
    assert train("Pendulum-v1", Config(**{**small, "eval_every": 50}), steps=200, seed=0, out=tmp_path).steps == 200
    assert runs.changed_settings({"hidden": [16], "tau": 0.005}, {"hidden": (16,), "tau": 0.005, "new": 1}) == []


def test_a_budget_that_shapes_schedules_cannot_change_on_resume(tmp_path):
    """DQN's epsilon is annealed over a fraction of --steps: resuming with more or fewer steps would bend it."""
    import pytest

    from rlcore.dqn import Config, train

    cfg = Config(learning_starts=50, train_freq=50, gradient_steps=1, batch_size=16, hidden=(8,), eval_every=0)
    train("CartPole-v1", cfg, steps=200, seed=0, out=tmp_path)
    for other in (400, 100):  # both directions
        with pytest.raises(ValueError, match=r"was started with --steps 200, which sets its epsilon schedule"):
            train("CartPole-v1", cfg, steps=other, seed=0, out=tmp_path)
    assert train("CartPole-v1", cfg, steps=200, seed=0, out=tmp_path).steps == 200  # the same budget resumes


@pytest.mark.parametrize("anneal_lr", [True, False])
def test_ppo_resumes_with_another_budget_only_without_annealing(tmp_path, anneal_lr):
    from rlcore.ppo import Config, train

    cfg = Config(num_envs=1, n_steps=64, batch_size=32, n_epochs=1, hidden=(8,), eval_every=0, anneal_lr=anneal_lr)
    train("CartPole-v1", cfg, steps=64, seed=0, out=tmp_path)
    if anneal_lr:
        with pytest.raises(ValueError, match="learning-rate annealing; resume it with --steps 64"):
            train("CartPole-v1", cfg, steps=128, seed=0, out=tmp_path)
    else:  # nothing depends on the budget: a larger one extends the run
        assert train("CartPole-v1", cfg, steps=128, seed=0, out=tmp_path).steps == 128


def test_budget_and_seed_are_checked_before_anything_is_written(tmp_path):
    from rlcore.ddpg import train

    for steps, seed, message in ((-5, 0, "steps must be an integer >= 1"), (0, 0, "steps must be"),
                                 (10, -1, "seed must be an integer >= 0")):
        with pytest.raises(ValueError, match=message):
            train("Pendulum-v1", steps=steps, seed=seed, out=tmp_path / "x")
    assert not (tmp_path / "x").exists()


def test_the_recorded_command_names_the_module_a_user_would_run(monkeypatch):
    from pathlib import Path

    import rlbook
    import rlcore
    from rlcore.provenance import command_line

    monkeypatch.delenv("RLCORE_COMMAND", raising=False)
    package = Path(rlcore.__file__).resolve().parent
    monkeypatch.setattr("sys.argv", [str(package / "__main__.py"), "train", "dqn"])
    assert command_line() == "python -m rlcore train dqn"
    book = Path(rlbook.__file__).resolve().parent
    monkeypatch.setattr("sys.argv", [str(book / "versus.py"), "--arm", "a b"])
    assert command_line() == "python -m rlbook.versus --arm 'a b'"
    monkeypatch.setattr("sys.argv", [str(book / "__main__.py"), "experiments", "run", "x"])
    assert command_line() == "python -m rlbook experiments run x"
    monkeypatch.setattr("sys.argv", ["/somewhere/benchmarks/ppo_vs_sb3.py", "--steps", "10"])
    assert command_line() == "ppo_vs_sb3.py --steps 10"
    # a process that trains for a command typed on another machine (a Ray task) records that command
    monkeypatch.setenv("RLCORE_COMMAND", "python -m rlbook experiments run x --ray auto")
    assert command_line() == "python -m rlbook experiments run x --ray auto"


@pytest.mark.parametrize("raw", ["0", "-1", "two", ""])
def test_a_bad_thread_count_is_refused_in_one_line(raw, monkeypatch):
    monkeypatch.setenv("RLCORE_TORCH_THREADS", raw)
    with pytest.raises(ValueError, match="RLCORE_TORCH_THREADS.*whole number"):
        machine.torch_threads()


def test_the_thread_count_is_set_and_recorded_in_the_metadata(monkeypatch):
    import torch

    before = torch.get_num_threads()
    try:
        monkeypatch.setenv("RLCORE_TORCH_THREADS", "2")
        assert machine.torch_threads() == 2
        assert torch.get_num_threads() == 2
        assert provenance.run_metadata()["machine"]["torch_threads"] == 2
        monkeypatch.delenv("RLCORE_TORCH_THREADS")
        assert machine.torch_threads() == 1
        assert provenance.run_metadata()["machine"]["torch_threads"] == 1
    finally:
        torch.set_num_threads(before)


def test_the_cli_refuses_a_bad_thread_count_without_a_traceback(tmp_path, monkeypatch):
    monkeypatch.setenv("RLCORE_TORCH_THREADS", "many")
    proc = command("rlcore", "train", "ddpg", "--env", "Pendulum-v1", "--steps", "10", "--out", tmp_path / "run",
                   check=False)
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == ["error: RLCORE_TORCH_THREADS='many': give a whole number of threads, 1 "
                                                "or more"]


def test_a_run_started_over_where_an_attempt_stopped_before_its_first_checkpoint_logs_each_step_once(tmp_path):
    import torch

    from rlcore.dqn import Config, train
    from rlcore.logger import read_csv

    torch.set_num_threads(1)
    small = dict(hidden=(16,), learning_starts=50, checkpoint_every=10 ** 6)
    train("CartPole-v1", Config(**small, eval_every=0), steps=300, seed=0, out=tmp_path / "whole")
    out = tmp_path / "again"
    train("CartPole-v1", Config(**small, eval_every=100), steps=300, seed=0, out=out)
    (out / "checkpoint.pt").unlink()  # as if stopped (SIGKILL) before its first checkpoint: logs, no checkpoint
    assert (out / "eval.csv").exists() and (out / "policy_best.pt").exists()
    train("CartPole-v1", Config(**small, eval_every=0), steps=300, seed=0, out=out)  # starts over
    whole, again = read_csv(tmp_path / "whole" / "progress.csv"), read_csv(out / "progress.csv")
    assert len(read_csv(out / "eval.csv").get("step", [])) == 0 and not (out / "policy_best.pt").exists()
    assert again.keys() == whole.keys() and len(again["step"]) == len(whole["step"]) > 0
    for column in ("step", "episode_return"):
        assert list(again[column]) == list(whole[column]), column
