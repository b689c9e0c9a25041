import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

import pytest

import rlbook as ex
from rlcore.checkpoint import load_checkpoint
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy


@pytest.fixture
def tiny(monkeypatch):
    exp = ex.Experiment("tiny", "a test experiment", (
        ex.RunSpec("ql", "q-learning", "FrozenLake-v1", 3_000, (0, 1), {"env_kwargs": {"is_slippery": False}}),
        ex.RunSpec("dqn", "dqn", "CartPole-v1", 600, (0,), {"learning_starts": 100, "train_freq": 4,
                                                            "gradient_steps": 1, "eval_every": 300, "hidden": [16]}),
    ))
    monkeypatch.setitem(ex.EXPERIMENTS, "tiny", lambda: exp)
    return exp


def _mark_or_fail(folder, i):
    """A stand-in for one seed's training, in a pool worker: call 0 fails at once, the others leave a mark."""
    if i == 0:
        raise RuntimeError("seed 0 failed")
    (Path(folder) / f"ran-{i}").touch()
    return i


def test_pool_starts_nothing_new_after_a_failure(tmp_path):
    # one worker, so the order is fixed: call 0 fails, and calls 1 and 2 must never start
    with pytest.raises(RuntimeError, match="seed 0 failed"):
        list(ex.run_in_pool(_mark_or_fail, [(str(tmp_path), i) for i in range(3)], jobs=1))
    assert list(tmp_path.iterdir()) == []
    assert list(ex.run_in_pool(_mark_or_fail, [(str(tmp_path), i) for i in (3, 2)], jobs=2)) in ([3, 2], [2, 3])
    assert sorted(f.name for f in tmp_path.iterdir()) == ["ran-2", "ran-3"]


class ControlledPool:
    """An executor whose calls finish when the test says so: calls in ``at_once`` finish as they are submitted,
    the others when the test calls ``finish(i)``; call 0 fails."""

    def __init__(self, at_once=()):
        self.at_once, self.submitted, self.futures = set(at_once), [], {}

    def submit(self, fn, folder, i):
        from concurrent.futures import Future

        self.submitted.append(i)
        self.futures[i] = Future()
        if i in self.at_once:
            self.finish(i)
        return self.futures[i]

    def finish(self, i):
        if i == 0:
            self.futures[i].set_exception(RuntimeError("seed 0 failed"))
        else:
            self.futures[i].set_result(i)


def test_schedule_submits_nothing_after_a_failure():
    # call 0 fails while call 1 runs: nothing new is submitted, and the error comes out
    pool = ControlledPool(at_once=[0])
    with pytest.raises(RuntimeError, match="seed 0 failed"):
        list(ex.schedule(pool, None, [("x", i) for i in range(4)], jobs=2))
    assert pool.submitted == [0, 1]


def test_schedule_starts_nothing_for_a_call_that_finished_alongside_a_failure():
    # call 1 succeeds first and call 2 takes its place; then call 0 fails in the same round as call 2 succeeds:
    # call 3 must not start, although call 2 freed a worker
    pool = ControlledPool(at_once=[1])
    gen = ex.schedule(pool, None, [("x", i) for i in range(4)], jobs=2)
    assert next(gen) == 1 and pool.submitted == [0, 1, 2]
    pool.finish(2)
    pool.finish(0)
    with pytest.raises(RuntimeError, match="seed 0 failed"):
        next(gen)
    assert pool.submitted == [0, 1, 2]


def _signal_self(sig):
    """In a pool worker: a signal to itself must interrupt (as Ctrl-C does), and a second one be ignored."""
    try:
        os.kill(os.getpid(), sig)
        time.sleep(5)
        return "not interrupted"
    except KeyboardInterrupt:
        os.kill(os.getpid(), sig)  # ignored: a checkpoint in progress is not cut short
        time.sleep(0.2)
        return "interrupted once"


def test_pool_workers_turn_sigterm_into_an_interrupt():
    # without the workers' handler, SIGTERM would kill the worker (BrokenProcessPool) before any checkpoint
    calls = [(signal.SIGTERM,), (signal.SIGINT,)]
    assert list(ex.run_in_pool(_signal_self, calls, jobs=2)) == ["interrupted once"] * 2


def _train_until_interrupted(folder, i):
    """A stand-in for a long training run that checkpoints when interrupted."""
    (Path(folder) / f"started-{i}").touch()
    try:
        time.sleep(120)
    except KeyboardInterrupt:
        (Path(folder) / f"checkpointed-{i}").touch()
        raise


def pool_main(folder):  # run in a subprocess by the test below, as `experiments run --jobs 2` would
    from rlcore.signals import stop_on_signals

    stop_on_signals()
    try:
        list(ex.run_in_pool(_train_until_interrupted, [(folder, i) for i in range(3)], jobs=2))
    except KeyboardInterrupt:
        print("interrupted", flush=True)


def test_killing_the_parent_stops_and_checkpoints_the_workers(tmp_path):
    # `kill PID` of `experiments run --jobs 2` (its workers not signalled): both running seeds checkpoint and stop
    # at once, and the third never starts; before, the parent waited for the running seeds to train to the end
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import test_experiments as t; "
            f"t.pool_main({str(tmp_path)!r})")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300  # a bound, not a wait: a loaded machine starts the two workers slowly
    while len(list(tmp_path.glob("started-*"))) < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert len(list(tmp_path.glob("started-*"))) == 2, "the two workers did not start within 300 s"
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=120)
    assert out.strip() == "interrupted" and proc.returncode == 0
    assert sorted(f.name for f in tmp_path.iterdir()) == ["checkpointed-0", "checkpointed-1", "started-0", "started-1"]


def test_run_writes_small_results_and_is_resumable(tiny, tmp_path):
    results, work = tmp_path / "results", tmp_path / "runs"
    assert ex.status_lines("tiny", results, work) == ["tiny/ql: 0/2 seeds (missing [0, 1])",
                                                      "tiny/dqn: 0/1 seeds (missing [0])"]
    # a seed that has trained part of the way (a checkpoint and a progress log in the work folder) says how far
    part = work / "tiny" / "dqn" / "seed-0"
    part.mkdir(parents=True)
    (part / "progress.csv").write_text("episode,step,episode_return\n1,20,20.0\n2,45,25.0\n")
    (part / "checkpoint.pt").write_bytes(b"")
    assert ex.status_lines("tiny", results, work)[2].startswith("  seed 0: trained to step 45 of 600 in ")
    shutil.rmtree(part)
    ex.run_experiment("tiny", only=["ql"], seeds=[0], results=results, work=work)
    loaded = ex.load_experiment("tiny", results)
    assert [s.seed for s in loaded["ql"].seeds] == [0] and loaded["ql"].missing == [1]
    assert loaded["ql"].finished(0) is loaded["ql"].seeds[0]
    with pytest.raises(KeyError, match=r"ql: seed 1 has not finished \(finished: \[0\]\)"):
        loaded["ql"].finished(1)
    lines = ex.run_experiment("tiny", jobs=2, results=results, work=work)
    assert any("already in" in line for line in lines)  # seed 0 is not trained twice
    loaded = ex.load_experiment("tiny", results)
    assert all(not r.missing for r in loaded.values())
    folder = results / "tiny" / "dqn" / "seed-0"
    assert sorted(p.name for p in folder.iterdir()) == ["config.json", "eval.csv", "meta.json", "policy.pt",
                                                         "progress.csv"]
    policy = load_checkpoint(folder / "policy.pt")
    assert "replay" not in policy and "optimizer" not in policy and policy["step"] == 600
    assert json.loads((folder / "meta.json").read_text())["versions"]["torch"]
    # the exported policy is what evaluate/render load
    from rlcore.dqn import load_policy

    evaluate_policy(load_policy(policy), make_env("CartPole-v1"), episodes=1)
    assert loaded["dqn"].seeds[0].evals["step"].tolist() == [300, 600]


def test_snapshot_shows_a_seed_in_training_until_it_finishes(tiny, tmp_path):
    from rlcore import dqn

    results, work = tmp_path / "results", tmp_path / "runs"
    spec = next(r for r in tiny.runs if r.name == "dqn")
    work_dir, result_dir = ex.run_paths("tiny", "dqn", 0, results, work)
    assert ex.snapshot_experiment("tiny", only=["dqn"], results=results, work=work) == [
        f"tiny/dqn/seed-0: nothing to snapshot, no training episode in {work_dir} yet"]
    assert not result_dir.exists()
    # a seed trained in its work folder (as a long run is between sessions), not yet copied to results/
    dqn.train(spec.env_id, dqn.make_config("dqn", **spec.overrides), steps=spec.steps, seed=0, out=work_dir)
    last = int(np.loadtxt(work_dir / "progress.csv", delimiter=",", skiprows=1, ndmin=2)[-1, 1])
    (line,) = ex.snapshot_experiment("tiny", only=["dqn"], results=results, work=work)
    assert line == f"tiny/dqn/seed-0: snapshot at step {last:,} of 600 -> {result_dir}"
    run = ex.load_experiment("tiny", results)["dqn"]
    assert run.seeds == [] and run.missing == [0] and [s.seed for s in run.in_progress] == [0]
    snap = run.in_progress[0]
    assert snap.snapshot["step"] == last and snap.snapshot["steps"] == 600
    assert snap.evals["step"].tolist() == [300, 600] and snap.config["config"]["hidden"] == [16]
    assert f"holds a snapshot of its logs at step {last:,}" in ex.status_lines("tiny", results, work)[-1]
    assert ex.snapshot_one("tiny", spec, 0, results, tmp_path / "elsewhere", policy=True) == (
        f"tiny/dqn/seed-0: nothing to snapshot, no training episode in "
        f"{tmp_path / 'elsewhere' / 'tiny' / 'dqn' / 'seed-0'} yet")
    text = ex.snapshot_markdown("tiny", run)
    assert text.startswith(f"Seed 0 had not finished when its snapshot was taken: `results/tiny/dqn/seed-0/` "
                           f"holds a snapshot of its logs at "
                           f"step {last:,} of 600")
    assert "its last evaluation, at step 600, returns" in text and "::::{dropdown} Provenance: dqn, in training" in text
    ex.check_results("tiny", ex.load_experiment("tiny", results))
    assert not (result_dir / ex.SNAPSHOT_POLICY).exists()   # logs only, unless asked for
    # with --policy, the policy of the last checkpoint too: what the seed does part of the way
    assert ex.snapshot_one("tiny", spec, 0, results, work, policy=True).endswith(
        f"snapshot at step {last:,} of 600, policy at step 600 -> {result_dir}")
    snap = ex.load_experiment("tiny", results)["dqn"].in_progress[0]
    assert snap.snapshot["policy_step"] == 600 and snap.policy_path == result_dir / ex.SNAPSHOT_POLICY
    assert "replay" not in load_checkpoint(snap.policy_path)
    assert "It holds the policy of its checkpoint at step 600 too" in ex.snapshot_markdown(
        "tiny", ex.load_experiment("tiny", results)["dqn"])
    evaluate_policy(snap.policy, make_env("CartPole-v1"), episodes=1)
    ex.snapshot_one("tiny", spec, 0, results, work)    # a later snapshot of the logs alone drops the older policy
    assert not (result_dir / ex.SNAPSHOT_POLICY).exists()
    ex.snapshot_one("tiny", spec, 0, results, work, policy=True)
    record = json.loads((result_dir / ex.SNAPSHOT).read_text())
    (result_dir / ex.SNAPSHOT).write_text(json.dumps({**record, "steps": 900}))
    with pytest.raises(ValueError, match="snapshot says step"):
        ex.check_results("tiny", ex.load_experiment("tiny", results))
    # finishing the seed writes its final files over the snapshot and removes the record
    assert ex.train_one("tiny", spec, 0, results, work).endswith(f"done -> {result_dir}")
    assert sorted(p.name for p in result_dir.iterdir()) == ["config.json", "eval.csv", "meta.json", "policy.pt",
                                                            "progress.csv"]
    run = ex.load_experiment("tiny", results)["dqn"]
    assert [s.seed for s in run.seeds] == [0] and run.in_progress == [] and run.missing == []
    assert ex.snapshot_markdown("tiny", run) == ""
    assert ex.snapshot_one("tiny", spec, 0, results, work) == f"tiny/dqn/seed-0: finished, already in {result_dir}"


def test_unknown_experiment():
    with pytest.raises(ValueError, match="Unknown experiment"):
        ex.get_experiment("nope")


def test_first_step_reaching_and_tables():
    import numpy as np

    evals = {"step": np.array([10, 20, 30]), "mean_return": np.array([100.0, 480.0, 400.0]),
             "episodes": np.array([5, 5, 5])}
    assert ex.first_step_reaching(evals, 475) == 20
    assert ex.first_step_reaching(evals, 500) is None
    assert ex.first_step_reaching({}, 1) is None
    spec = ex.RunSpec("dqn", "dqn", "CartPole-v1", 30, (0,))
    run = ex.RunResults(spec, [ex.SeedResult(0, None, {}, evals, {}, {})], [])
    rows = ex.seeds_table(run, 475)
    assert rows == [{"seed": 0, "final_step": 30, "final_mean_return": 400.0, "eval_episodes": 5,
                     "first_step_reaching": 20}]
    md = ex.markdown_table(rows, {"seed": "seed", "first_step_reaching": "first step ≥ 475"})
    assert md.splitlines() == ["| seed | first step ≥ 475 |", "|---|---|", "| 0 | 20 |"]
    assert "—" in ex.markdown_table([{"a": None}])
    small = ex.markdown_table([{"lr": 3e-4, "gamma": 0.99, "ret": 2315.84, "low": 1 / 3}])
    assert small.splitlines()[-1] == "| 0.0003 | 0.99 | 2,315.8 | 0.3333 |"


def test_load_or_train_falls_back_to_a_live_run_and_says_so(tiny, tmp_path):
    results = tmp_path / "results"
    live = ex.load_or_train("tiny", "dqn", fallback_steps=400, fallback_seeds=[5], jobs=1, eval_points=2,
                            results=results)
    assert live.source == "live" and live.steps == 400 and live.missing == [0]
    assert [s.seed for s in live.seeds] == [5]
    assert live.seeds[0].evals["step"].tolist() == [200, 400]
    assert live.seeds[0].policy(np.zeros(4)) in (0, 1)  # the policy loads from the live run's policy.pt
    text = ex.provenance_markdown("tiny", live)
    assert "{warning}" in text and "short live run" in text and "400 steps" in text
    # once results/ has the run, it is used as is
    ex.run_experiment("tiny", only=["dqn"], results=results, work=tmp_path / "runs")
    stored = ex.load_or_train("tiny", "dqn", fallback_steps=400, fallback_seeds=[5], results=results)
    assert stored.source == "results" and [s.seed for s in stored.seeds] == [0] and stored.steps == 600
    text = ex.provenance_markdown("tiny", stored)
    assert "seeds [0] (1 of 1), 600 steps" in text and "python -m rlbook experiments run tiny" in text
    assert "{warning}" not in text and "loaded its code earlier" not in text
    # the record is folded under the figure, in a dropdown named after the run
    assert text.startswith(f"::::{{dropdown}} Provenance: {stored.label}\n") and text.rstrip().endswith("::::")
    stored.seeds[0].meta.update(checkout_at_start="fedcba9876", provenance_note="Trained before the fix.")
    text = ex.provenance_markdown("tiny", stored)
    assert "seed 0 (the checkout was already at fedcba9)" in text and "Seed 0: Trained before the fix." in text
    assert len(stored.seeds[0].episode_returns) == len(stored.seeds[0].episode_end_steps) > 0


def test_report_metric_sums_rewards_per_epoch_over_the_last_epochs():
    from rlbook import report_metric

    # four 1000-step episodes in 2000-step epochs: each epoch collects two episodes' returns
    log = {"step": np.array([1000, 2000, 3000, 4000, 4500]), "episode_return": np.array([1.0, 2.0, 10.0, 20.0, 99.0])}
    assert report_metric(log, epoch_steps=2000, last=1) == 30.0   # the unfinished third epoch is left out
    assert report_metric(log, epoch_steps=2000, last=20) == 16.5  # only two epochs exist: (3 + 30) / 2
    with pytest.raises(ValueError, match="less than one epoch"):
        report_metric(log, epoch_steps=10_000)


def test_ddpg_sweep_arms_change_one_setting_of_the_report_table_and_modern_runs_only_their_budget():
    """Each arm of ddpg-report-sweeps is its ddpg-report run with only the setting its name says."""
    from rlcore.ddpg import Config

    base = {spec.env_id: spec for spec in ex.get_experiment("ddpg-report").runs}
    expected = {"ant-no-explore": {"exploration"}, "halfcheetah-no-explore": {"exploration"},
                "halfcheetah-param-noise": {"exploration", "noise_sigma"}, "halfcheetah-batch16": {"batch_size"},
                "halfcheetah-batch256": {"batch_size"}, "hopper-hidden128": {"hidden"},
                "hopper-hidden2048": {"hidden"}}
    arms = ex.get_experiment("ddpg-report-sweeps").runs
    assert {arm.name for arm in arms} == set(expected)
    for arm in arms:
        ref = base[arm.env_id]
        a, b = Config(**arm.overrides), Config(**ref.overrides)
        changed = {f for f in Config.__dataclass_fields__ if getattr(a, f) != getattr(b, f)}
        assert changed == expected[arm.name], (arm.name, changed)
        assert (arm.steps, arm.seeds, arm.algo) == (ref.steps, ref.seeds, "ddpg")
    modern_runs = ex.get_experiment("ddpg-modern").runs
    # the report's tasks and budgets, with Config's defaults: only the settings differ from ddpg-report
    assert [r.name for r in modern_runs] == ["halfcheetah", "hopper", "ant"]
    for run in modern_runs:
        assert (run.env_id, run.steps, run.seeds) == (base[run.env_id].env_id, base[run.env_id].steps, (0, 1, 2))
        cfg = Config(**run.overrides)
        assert {f for f in Config.__dataclass_fields__ if getattr(cfg, f) != getattr(Config(), f)} <= {
            "eval_every", "eval_episodes", "checkpoint_every"}
    modern = modern_runs[0]
    long = {r.name: r for r in ex.get_experiment("ddpg-modern-1m").runs}  # the same settings, trained to 1M steps
    assert sorted(long) == ["halfcheetah", "humanoid"] and long["humanoid"].env_id == "Humanoid-v5"
    for run in long.values():
        a, b = Config(**run.overrides), Config(**modern.overrides)
        changed = {f for f in Config.__dataclass_fields__ if getattr(a, f) != getattr(b, f)}
        # Humanoid adds observation normalization, and only that
        assert changed <= {"eval_every", "checkpoint_every"} | ({"normalize_obs"} if run.name == "humanoid" else set())
        assert (run.steps, run.seeds) == (1_000_000, modern.seeds)
    assert Config(**long["humanoid"].overrides).normalize_obs
    assert not Config(**long["halfcheetah"].overrides).normalize_obs
    assert long["halfcheetah"].env_id == modern.env_id


def test_scaling_rows_split_each_update_into_rollout_and_the_rest(scaling_record):
    rows = ex.scaling_rows(scaling_record)
    assert [(r["workers"], r["sharing"], r["ratio to 1 worker"]) for r in rows] == [
        (1, "(nothing)", "1.00×"), (2, "gradients", "1.40×"), (2, "rollouts", "1.90×")]
    assert rows[1]["learning + sync s / update"] == "0.400" and rows[2]["rollout s / update"] == "0.300"
    by = ex.scaling_runs(scaling_record)
    assert sorted(by) == [(1, "gradients"), (2, "gradients"), (2, "rollouts")]
    assert ex.learning_seconds(by[2, "rollouts"]) == pytest.approx(0.22)


def test_ppo_report_halfcheetah_is_the_two_by_two_of_memory_batch_and_update_steps():
    runs = ex.get_experiment("ppo-report-halfcheetah").runs
    combos = set()
    for run in runs:
        changed = {k for k, v in run.overrides.items() if ex.REPORT_PPO_HALFCHEETAH[k] != v}
        assert changed <= {"n_steps", "batch_size", "n_epochs"}, (run.name, changed)
        assert run.overrides["n_steps"] == run.overrides["batch_size"]  # one full-batch step per update step
        combos.add((run.overrides["n_steps"], run.overrides["n_epochs"]))
    assert combos == {(128, 20), (1024, 20), (128, 5), (1024, 5)}
    assert all(r.steps == 50 * 5_000 and len(r.seeds) >= 3 for r in runs)  # the report's 50 epochs of 5000 steps


def test_gap_and_spread_names_the_best_and_worst_arm_and_the_widest_spread():
    import numpy as np

    best, worst, gap, spread = ex.gap_and_spread({"a": np.array([1.0, 3.0]), "b": np.array([10.0, 10.0]),
                                                  "c": np.array([4.0, 8.0])})
    assert (best, worst, gap, spread) == ("b", "a", 8.0, 2.0)


def test_gap_rows_give_one_row_per_measure_with_its_best_and_worst_arm():
    rows = ex.gap_rows({"final": {"a": [1.0, 3.0], "b": [10.0, 10.0], "c": [4.0, 8.0]},
                        "metric": {"a": [4.0, 4.0], "b": [4.0, 6.0], "c": [6.0, 6.0]}}, labels={"b": "arm B"})
    assert rows == [
        {"measure": "final", "best (mean)": "arm B (10)", "worst (mean)": "a (2)", "gap between their means": "8",
         "largest std within one arm": "2", "gap above twice that std": "yes"},
        {"measure": "metric", "best (mean)": "c (6)", "worst (mean)": "a (4)", "gap between their means": "2",
         "largest std within one arm": "1", "gap above twice that std": "no"}]


def test_a_live_stand_in_leaves_no_temporary_folder_behind(tiny, tmp_path, monkeypatch):
    import gc
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    live = ex.load_or_train("tiny", "ql", fallback_steps=300, fallback_seeds=[5, 6], jobs=1, eval_points=2,
                            results=tmp_path / "results")
    assert live.source == "live" and len(live.seeds) == 2
    [folder] = list((tmp_path / "tmp").iterdir())
    assert not (folder / "runs").exists()  # the checkpoints (a replay memory, say) go at once
    assert live.seeds[0].policy(0) in range(4) and (live.seeds[1].folder / "policy.pt").exists()  # still usable
    seed = live.seeds[1]
    del live
    gc.collect()
    assert (seed.folder / "policy.pt").exists()  # a seed kept by the page keeps its files
    del seed
    gc.collect()
    assert list((tmp_path / "tmp").iterdir()) == []  # and the folder goes with the last of them


def test_td3_and_sac_experiments_compare_like_with_like():
    from rlbook import get_experiment

    runs = {r.name: r for r in get_experiment("td3-sac-1m").runs}
    assert set(runs) == {f"{a}-{t}" for a in ("td3", "sac") for t in ("humanoid", "hopper", "halfcheetah")}
    ddpg_humanoid = get_experiment("ddpg-modern-1m").runs[1]
    for name, run in runs.items():
        assert run.steps == 1_000_000 and run.seeds == (0, 1, 2)
        assert run.overrides["hidden"] == (256, 256) and run.overrides["batch_size"] == 256
        assert run.overrides.get("normalize_obs", False) == (run.env_id == "Humanoid-v5")  # as DDPG's Humanoid run
        assert run.overrides["eval_every"] == ddpg_humanoid.overrides["eval_every"]       # the same evaluations
    ablation = {r.name: r for r in get_experiment("td3-ablation").runs}
    assert {r.env_id for r in ablation.values()} == {"Hopper-v5"} and all(len(r.seeds) == 5 for r in ablation.values())
    assert ablation["none"].overrides["policy_delay"] == 1 and not ablation["none"].overrides["clipped_double_q"]
    for longer in get_experiment("td3-sac-humanoid-2m").runs:  # the same seeds, trained on with the same settings
        source = runs[longer.continues.split("/")[1]]
        assert longer.continues.startswith("td3-sac-1m/") and longer.steps == 2 * source.steps
        assert (longer.algo, longer.env_id, longer.overrides, longer.seeds) == (source.algo, source.env_id,
                                                                                source.overrides, source.seeds)


def test_an_interrupt_stops_the_torchrun_job_and_waits_for_it(tmp_path):
    # a stand-in for torchrun: it says when it has started, and on SIGINT it stops (as torchrun stops its workers)
    from rlbook.runner import run_torchrun

    started, stopped = tmp_path / "started", tmp_path / "stopped"
    code = (f"import pathlib, signal, sys, time; signal.signal(signal.SIGINT, lambda *a: (pathlib.Path("
            f"{str(stopped)!r}).touch(), sys.exit(3))); pathlib.Path({str(started)!r}).touch(); time.sleep(120)")

    def interrupt_once_started():  # Ctrl-C of this process, or Ray's cancel of its task
        deadline = time.monotonic() + 120
        while not started.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGINT)

    import threading

    # Python's own Ctrl-C handler, whatever an earlier test in this process left installed (Ray's driver sets its own)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    threading.Thread(target=interrupt_once_started, daemon=True).start()
    try:
        with pytest.raises(KeyboardInterrupt):
            run_torchrun([sys.executable, "-c", code], dict(os.environ))
    finally:
        signal.signal(signal.SIGINT, previous)
    assert stopped.exists()  # the job got the SIGINT and had ended when the interrupt came out
    with pytest.raises(subprocess.CalledProcessError):
        run_torchrun([sys.executable, "-c", "raise SystemExit(5)"], dict(os.environ))


def test_a_continued_run_is_its_source_run_trained_on(monkeypatch, tmp_path):
    # td3-sac-humanoid-2m's mechanism on a tiny TD3: a seed that continues a finished run resumes it (checkpoint,
    # replay memory, logs) with a larger budget, and ends where one run with that budget from the start ends
    from dataclasses import replace

    from rlcore.checkpoint import load_checkpoint

    base = ex.RunSpec("short", "td3", "Pendulum-v1", 400, (0,), {"learning_starts": 100, "hidden": (16,),
                                                                 "batch_size": 32, "eval_every": 200,
                                                                 "eval_episodes": 1, "checkpoint_every": 200})
    exp = ex.Experiment("tiny-td3", "a test experiment", (
        base, replace(base, name="long", steps=800, continues="tiny-td3/short"),
        replace(base, name="direct", steps=800)))
    monkeypatch.setitem(ex.EXPERIMENTS, "tiny-td3", lambda: exp)
    results, work = tmp_path / "results", tmp_path / "runs"
    with pytest.raises(ValueError, match="not finished"):  # the source seed must be finished first
        ex.run_experiment("tiny-td3", only=["long"], results=results, work=work, progress=False)
    assert not (work / "tiny-td3" / "long").exists()
    ex.run_experiment("tiny-td3", only=["short"], results=results, work=work, progress=False)
    ex.run_experiment("tiny-td3", only=["long"], results=results, work=work, progress=False)
    ex.run_experiment("tiny-td3", only=["direct"], results=results, work=work, progress=False)
    seed = {name: results / "tiny-td3" / name / "seed-0" for name in ("short", "long", "direct")}
    assert json.loads((seed["long"] / "continued.json").read_text()) == {"continues": "tiny-td3/short", "seed": 0,
                                                                         "from_step": 400}
    evals = {name: (folder / "eval.csv").read_text().splitlines() for name, folder in seed.items()}
    assert evals["long"][:len(evals["short"])] == evals["short"]  # the source's curve, then more of it
    assert evals["long"] == evals["direct"] and len(evals["long"]) == 1 + 4
    long, direct = (load_checkpoint(seed[n] / "policy.pt") for n in ("long", "direct"))
    assert long["step"] == direct["step"] == 800
    for key, tensor in direct["actor"].items():
        assert torch.equal(long["actor"][key], tensor), key
    # a continued run keeps its source's settings
    other = replace(base, name="other", steps=800, continues="tiny-td3/short",
                    overrides={**base.overrides, "tau": 0.01})
    monkeypatch.setitem(ex.EXPERIMENTS, "tiny-td3", lambda: replace(exp, runs=(*exp.runs, other)))
    with pytest.raises(ValueError, match="other settings"):
        ex.run_experiment("tiny-td3", only=["other"], results=results, work=work, progress=False)


def test_chapter_9_experiments_change_one_thing_at_a_time():
    from rlbook import get_experiment
    from rlbook.registry import SAC_1M, TD3_1M

    ant = {r.name: r for r in get_experiment("td3-sac-ant").runs}
    td3_sac = {r.name: r for r in get_experiment("td3-sac-1m").runs}
    assert set(ant) == {"td3-ant", "sac-ant"}
    for algo, hp in (("td3", TD3_1M), ("sac", SAC_1M)):
        # Ant's runs are the Hopper runs' settings on another body
        assert ant[f"{algo}-ant"].overrides == td3_sac[f"{algo}-hopper"].overrides
        assert ant[f"{algo}-ant"].steps == 1_000_000 and ant[f"{algo}-ant"].seeds == (0, 1, 2)
    arms = {r.name: r.overrides for r in get_experiment("crossq-ablation").runs}
    base = {k: v for k, v in arms["crossq-256"].items()}
    assert {k: v for k, v in arms["no-target"].items() if k != "batch_norm"} == base
    assert {k: v for k, v in arms["bn-separate"].items() if k != "joint_pass"} == base
    assert {k: v for k, v in arms["crossq-1024"].items() if k != "critic_hidden"} == {
        k: v for k, v in base.items() if k != "critic_hidden"}
    humanoid = get_experiment("crossq-humanoid").runs[0]
    assert humanoid.overrides["critic_hidden"] == (1024, 1024) and humanoid.steps == 300_000
