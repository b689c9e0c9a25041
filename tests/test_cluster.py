"""The experiment runner on a Ray cluster (rlbook.cluster), on a local cluster of two CPUs: the results are the local
runner's bit for bit; a killed worker's seed is retried and resumes from its checkpoint; Ctrl-C on the submitting
side cancels the tasks and leaves the seeds resumable; snapshots through Ray; without Ray, one line that says what to
install, and the local pool as before."""

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import torch

import rlbook as ex
from portable import skip_or_fail
from rlbook.cluster import (BOARD_PREFIX, INSTALL, NAMESPACE, PROCESS_BYTES, RAY_VERSION, Board, SeedsFailed,
                            last_value, on_node, ray_backend, ray_snapshots, replay_bytes, source_results,
                            task_memory)
from rlbook.runner import train_one

TINY = ex.Experiment("tiny-cluster", "a test experiment for the Ray backend", (
    ex.RunSpec("ql", "q-learning", "FrozenLake-v1", 3_000, (0, 1), {"env_kwargs": {"is_slippery": False}}),
    ex.RunSpec("dqn", "dqn", "CartPole-v1", 600, (0,), {"learning_starts": 100, "train_freq": 4, "gradient_steps": 1,
                                                        "eval_every": 300, "hidden": [16]}),
    # long enough to be stopped part of the way: a checkpoint every 250 steps
    ex.RunSpec("long", "dqn", "CartPole-v1", 4_000, (0,), {"learning_starts": 100, "train_freq": 4,
                                                           "gradient_steps": 1, "eval_every": 1_000, "hidden": [16],
                                                           "checkpoint_every": 250}),
))
BAD = ex.Experiment("bad-cluster", "a seed that cannot start, beside one that can", (
    ex.RunSpec("dqn", "dqn", "CartPole-v1", 600, (0,), {"hidden": [16], "gamma": 2.0}),
    ex.RunSpec("ql", "q-learning", "FrozenLake-v1", 3_000, (0,), {"env_kwargs": {"is_slippery": False}}),
))
HERE = Path(__file__).parent
PINNED = {"RLCORE_TORCH_THREADS": "1", "OMP_NUM_THREADS": "1", "RLCORE_COMMIT": "test-cluster"}
"""The environment the tests assert on (one torch thread a seed, as ``meta.json`` records; one commit, whatever
the checkout's files do while the tests run), whatever the reader's shell says: set here, in the workers of the
cluster (started from this process) and in the drivers started below."""
UNSET = ("RLCORE_COMMAND",)
"""Unset for the tests: the command the runs record is the one of the test."""


def register() -> None:
    ex.EXPERIMENTS[TINY.name] = lambda: TINY
    ex.EXPERIMENTS[BAD.name] = lambda: BAD


def driver_main(argv: list[str]) -> int:  # a submitting process, run by the tests below: `python -m rlbook ...`
    from rlbook.__main__ import main

    register()
    return main(argv)


def driver(argv: list[str], blocked: str = "") -> list[str]:
    """The command line of a process that runs ``python -m rlbook`` with the test experiment (and ``blocked`` made
    unimportable)."""
    code = (f"import sys; sys.modules.update(dict.fromkeys({blocked.split()!r})); sys.path.insert(0, {str(HERE)!r}); "
            f"import test_cluster as t; sys.exit(t.driver_main({argv!r}))")
    return [sys.executable, "-c", code]


@pytest.fixture(scope="module", autouse=True)
def pinned_environment():
    """:data:`PINNED` set and :data:`UNSET` unset for this module's tests, the reader's values back afterwards. The
    commit this process records is asked again under them (and after them): an earlier test in the same process may
    have cached the checkout's own (:func:`rlcore.provenance.loaded_commit`)."""
    from rlcore import provenance

    with pytest.MonkeyPatch.context() as mp:
        for name, value in PINNED.items():
            mp.setenv(name, value)
        for name in UNSET:
            mp.delenv(name, raising=False)
        provenance.loaded_commit.cache_clear()
        provenance.loaded_changes.cache_clear()
        yield
    provenance.loaded_commit.cache_clear()
    provenance.loaded_changes.cache_clear()


@pytest.fixture(scope="module")
def cluster(pinned_environment):
    """A Ray cluster of this machine with two CPUs, and this process its driver; yields its address. Its workers
    get :data:`PINNED` (they inherit this process's environment, and the driver's job says so again)."""
    try:
        import ray
    except ImportError:
        skip_or_fail(f"the Ray backend's tests need Ray: {INSTALL}")
    register()
    info = ray.init(address="local", num_cpus=2, include_dashboard=False, namespace=NAMESPACE,
                    runtime_env={"env_vars": PINNED})
    yield info.address_info["gcs_address"]
    ray.shutdown()


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The local runner's results of the whole test experiment (one process, one torch thread)."""
    register()
    results = tmp_path_factory.mktemp("local") / "results"
    ex.run_experiment(TINY.name, results=results, work=results.parent / "runs", progress=False)
    return results


def seed_files(results: Path, run: str, seed: int = 0) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((results / TINY.name / run / f"seed-{seed}").iterdir())}


def assert_same_training(ours: Path, theirs: Path, run: str, meta: bool = True) -> None:
    """The same files with the same bytes, ``meta.json`` (provenance) but its start time too when ``meta``; the
    policies' tensors equal."""
    a, b = seed_files(ours, run), seed_files(theirs, run)
    assert sorted(a) == sorted(b)
    for name in a:
        if name == "meta.json":
            x, y = json.loads(a[name]), json.loads(b[name])
            assert x["timing"]["wall_seconds"] > 0 and x["timing"]["cpu_seconds"] > 0
            if meta:  # the same provenance; but when it started and how long it took
                assert {**x, "started": None, "timing": None} == {**y, "started": None, "timing": None}
        elif name != "policy.pt":
            assert a[name] == b[name], (run, name)
    x, y = (torch.load(d / TINY.name / run / "seed-0" / "policy.pt", weights_only=True) for d in (ours, theirs))
    assert same(x, y), run


def same(a, b) -> bool:
    """Equal, tensors bit for bit, at any depth of dicts and lists."""
    if isinstance(a, torch.Tensor):
        return isinstance(b, torch.Tensor) and torch.equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(u, v) for u, v in zip(a, b))
    return a == b


def test_results_are_the_local_runners_bit_for_bit(cluster, reference, tmp_path):
    results = tmp_path / "results"
    lines = ex.run_experiment(TINY.name, only=["ql", "dqn"], results=results, work=tmp_path / "runs",
                              train=ray_backend("auto"), progress=False)
    assert sorted(lines) == sorted(f"{TINY.name}/{run}/seed-{s}: done -> {results / TINY.name / run / f'seed-{s}'}"
                                   for run, s in (("ql", 0), ("ql", 1), ("dqn", 0)))
    for run in ("ql", "dqn"):
        assert_same_training(results, reference, run)
    meta = json.loads((results / TINY.name / "dqn" / "seed-0" / "meta.json").read_text())
    assert meta["machine"]["torch_threads"] == 1
    again = ex.run_experiment(TINY.name, only=["dqn"], results=results, work=tmp_path / "runs",
                              train=ray_backend("auto"), progress=False)
    assert again == [f"{TINY.name}/dqn/seed-0: already in {results / TINY.name / 'dqn' / 'seed-0'}"]


def test_a_seeds_own_error_comes_back_as_itself_and_the_other_seeds_go_on(cluster, tmp_path):
    # as from the local pool: a bad setting is the library's one-line error, not Ray's wrapper of a remote traceback
    with pytest.raises(ValueError) as local:
        ex.run_experiment(BAD.name, only=["dqn"], results=tmp_path / "local", work=tmp_path / "runs-local",
                          progress=False)
    results = tmp_path / "results"
    with pytest.raises(SeedsFailed) as remote:
        ex.run_experiment(BAD.name, results=results, work=tmp_path / "runs", train=ray_backend("auto"),
                          progress=False)
    ((key, error),) = remote.value.failures
    assert key == f"{BAD.name}/dqn/seed-0" and type(error) is type(local.value) and str(error) == str(local.value)
    assert sorted(remote.value.lines) == [f"{BAD.name}/dqn/seed-0: failed: {local.value}",
                                          f"{BAD.name}/ql/seed-0: done -> {results / BAD.name / 'ql' / 'seed-0'}"]
    assert (results / BAD.name / "ql" / "seed-0" / "policy.pt").exists()  # the other seed went on to its end


def test_the_command_lists_the_failed_seeds_at_the_end_and_exits_non_zero(cluster, tmp_path):
    argv = ["experiments", "run", BAD.name, "--ray", cluster, "--results", str(tmp_path / "results"),
            "--runs-dir", str(tmp_path / "runs")]
    done = subprocess.run(driver(argv), capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, done.stderr
    assert f"{BAD.name}/ql/seed-0: done -> " in done.stdout and f"{BAD.name}/dqn/seed-0: failed: " in done.stdout
    assert done.stderr.strip().splitlines()[-1] == (f"error: 1 seed(s) failed: {BAD.name}/dqn/seed-0; the others "
                                                    "went on (their lines above say why)")
    assert "Traceback" not in done.stderr


def free_port() -> int:
    """A TCP port of this machine where nothing listens (just now)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_address_where_no_cluster_answers_is_one_line_within_30_s(tmp_path):
    port = free_port()
    argv = ["experiments", "run", TINY.name, "--only", "ql", "--ray", f"127.0.0.1:{port}", "--results",
            str(tmp_path / "results"), "--runs-dir", str(tmp_path / "runs")]
    started = time.monotonic()
    done = subprocess.run(driver(argv), capture_output=True, text=True, timeout=120)
    assert time.monotonic() - started < 30
    errors = [line for line in done.stderr.splitlines() if not line.startswith("warning: ")]  # a dirty tree warns
    assert done.returncode == 2 and errors == [
        f"error: no Ray cluster answers at 127.0.0.1:{port} (connection refused); start one there with `ray start "
        f"--head --port {port}` on 127.0.0.1, or train on this machine alone with --ray local"], done.stderr
    assert not (tmp_path / "results").exists()


def test_jobs_with_a_clusters_address_is_one_line():
    register()
    with pytest.raises(ValueError, match=r"^--jobs with --ray 127.0.0.1:6379: the cluster's CPUs decide how many "
                                         r"seeds train at once; --jobs sets them only .* \(--ray local\)$"):
        ex.run_experiment(TINY.name, jobs=2, train=ray_backend("127.0.0.1:6379"), progress=False)


def test_a_task_reserves_memory_for_its_replay():
    humanoid = ex.RunSpec("td3", "td3", "Humanoid-v5", 1_000_000, (0,), {})
    # 1M transitions of Humanoid: two observations of 348 float32, 17 float32 actions, reward and end flag
    assert replay_bytes(humanoid) == 1_000_000 * (2 * 4 * 348 + 4 * 17 + 8)  # about 2.9 GB
    assert task_memory(humanoid) == replay_bytes(humanoid) * 3 // 2 + PROCESS_BYTES
    dqn = TINY.runs[1]  # CartPole: 4 float32 observations, one int64 action
    assert replay_bytes(dqn) == 100_000 * (2 * 4 * 4 + 8 + 8)
    assert task_memory(TINY.runs[0]) is None  # q-learning keeps no replay memory
    assert task_memory(BAD.runs[0]) is None  # a bad setting: the seed's own task fails with it, as the local pool's


def board_state(ray) -> dict:
    """Every seed on the boards of this cluster that are alive."""
    seeds = {}
    for actor in ray.util.list_named_actors(all_namespaces=True):
        if actor["name"].startswith(BOARD_PREFIX):
            try:
                seeds.update(ray.get(ray.get_actor(actor["name"], namespace=NAMESPACE).state.remote()))
            except (ValueError, ray.exceptions.RayActorError):  # the board of a finished command, going away
                continue
    return seeds


def wait_for(path: Path, seconds: float = 300) -> None:
    """Until ``path`` exists (a bound, not a pause: a loaded machine starts workers slowly)."""
    deadline = time.monotonic() + seconds
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert path.exists(), f"{path} did not appear within {seconds} s"


def test_a_killed_worker_is_retried_and_resumes_from_its_checkpoint(cluster, reference, tmp_path):
    import ray

    results, work = tmp_path / "results", tmp_path / "runs"
    work_dir, result_dir = ex.run_paths(TINY.name, "long", 0, results, work)
    out: dict = {}
    thread = threading.Thread(target=lambda: out.update(lines=ex.run_experiment(
        TINY.name, only=["long"], results=results, work=work, train=ray_backend("auto"), progress=False)))
    thread.start()
    wait_for(work_dir / "checkpoint.pt")
    # a snapshot through Ray while the seed trains: taken on its node, written here
    (line,) = ex.snapshot_experiment(TINY.name, only=["long"], results=results, work=work,
                                     take=ray_snapshots("auto"))
    assert line.startswith(f"{TINY.name}/long/seed-0: snapshot at step ") and line.endswith(")"), line
    assert json.loads((result_dir / ex.SNAPSHOT).read_text())["steps"] == 4_000
    key, deadline = f"{TINY.name}/long/seed-0", time.monotonic() + 300
    while key not in (seeds := board_state(ray)) and time.monotonic() < deadline:
        time.sleep(0.05)  # the cluster's list of named actors can lag behind (a bound, as wait_for's)
    assert key in seeds, f"{key} did not reach the run's board within 300 s; boards: {sorted(seeds)}"
    os.kill(seeds[key]["attempts"][-1]["pid"], signal.SIGKILL)
    thread.join(timeout=300)
    assert not thread.is_alive()
    (line,) = out["lines"]
    assert line.startswith(f"{TINY.name}/long/seed-0: done -> {result_dir} (its worker (pid ")
    assert "died at" in line and "resuming from its checkpoint at step " in line, line
    meta = json.loads((result_dir / "meta.json").read_text())
    assert len(meta["resumes"]) == 1 and 0 < meta["resumes"][0]["step"] < 4_000
    assert f"resuming from its checkpoint at step {meta['resumes'][0]['step']:,})" in line  # the step it resumed
    assert meta["timing"]["from_step"] == meta["resumes"][0]["step"]  # the session that finished it, timed
    assert not (result_dir / ex.SNAPSHOT).exists()  # the finished seed replaced its snapshot
    assert_same_training(results, reference, "long", meta=False)  # resumed between two steps: the same run


def test_ctrl_c_cancels_the_tasks_and_leaves_the_seeds_resumable(cluster, reference, tmp_path):
    results, work = tmp_path / "results", tmp_path / "runs"
    work_dir, result_dir = ex.run_paths(TINY.name, "long", 0, results, work)
    argv = ["experiments", "run", TINY.name, "--only", "long", "--ray", cluster, "--results", str(results),
            "--runs-dir", str(work)]
    proc = subprocess.Popen(driver(argv), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(work_dir / "checkpoint.pt")
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "Stopping 1 seed(s) on the cluster" in err and "resume from their checkpoints" in err
    assert (work_dir / "checkpoint.pt").exists() and not (result_dir / "policy.pt").exists()
    import ray

    # the interrupted task has ended: both of the cluster's CPUs are free again
    assert ray.get(ray.remote(num_cpus=2)(lambda: "free").remote(), timeout=120) == "free"
    (line,) = ex.run_experiment(TINY.name, only=["long"], results=results, work=work, train=ray_backend("auto"),
                                progress=False)
    assert line == f"{TINY.name}/long/seed-0: done -> {result_dir}"
    assert json.loads((result_dir / "meta.json").read_text())["resumes"]
    assert_same_training(results, reference, "long", meta=False)


def test_without_ray_one_line_says_what_to_install_and_the_local_pool_works(tmp_path):
    argv = ["experiments", "run", TINY.name, "--only", "ql", "--seeds", "0", "--results", str(tmp_path / "results"),
            "--work", str(tmp_path / "runs")]
    done = subprocess.run(driver([*argv, "--ray", "local"], blocked="ray"), capture_output=True, text=True,
                          timeout=300)
    errors = [line for line in done.stderr.splitlines() if not line.startswith("warning: ")]  # a dirty tree warns
    assert done.returncode == 2 and errors == [f"error: --ray needs Ray, which is not installed here: "
                                               f"pip install ray=={RAY_VERSION}"]
    done = subprocess.run(driver(argv, blocked="ray"), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "results" / TINY.name / "ql" / "seed-0" / "policy.pt").exists()


def test_the_board_says_how_a_retried_seed_goes_on():
    # no Ray needed: the board is a plain class, which Ray runs as an actor
    board = Board()
    assert board.attempt("e/r/seed-0", "a" * 20, 11, None) is None  # a first attempt says nothing
    board.report("e/r/seed-0", 1_500.0, -3.5)
    note = board.attempt("e/r/seed-0", "b" * 20, 12, None)
    assert note == ("e/r/seed-0: its worker (pid 11, node aaaaaaaa) died at step 1,500; retried on node bbbbbbbb, "
                    "restarting from step 0: no checkpoint in its run folder there (the last one is on node "
                    "aaaaaaaa; give --runs-dir on storage every node sees to resume instead)")
    board.report("e/r/seed-0", 2_000.0, None)
    assert board.attempt("e/r/seed-0", "b" * 20, 13, 1_750).endswith(
        "died at step 2,000; retried on node bbbbbbbb, resuming from its checkpoint at step 1,750")
    assert len(board.state()["e/r/seed-0"]["notes"]) == 2 and board.state()["e/r/seed-0"]["step"] == 2_000.0


def test_last_value_reads_the_last_row_of_a_log(tmp_path):
    log = tmp_path / "progress.csv"
    assert last_value(log, "step") is None
    log.write_text("episode,step,episode_return\n")
    assert last_value(log, "step") is None
    log.write_text("episode,step,episode_return\n" + "".join(f"{i},{20 * i},{i}.5\n" for i in range(1, 2_000)))
    assert last_value(log, "step") == 39_980 and last_value(log, "episode_return") == 1_999.5
    assert last_value(log, "no-such-column") is None


def test_a_continued_run_starts_on_a_node_from_the_submitting_machines_results(tmp_path, monkeypatch):
    # on a node, a seed trains with a temporary results folder: the source seed's results must come along (no Ray
    # needed: the function a task runs, here)
    from dataclasses import replace

    short = ex.RunSpec("short", "q-learning", "FrozenLake-v1", 1_000, (0,), {"env_kwargs": {"is_slippery": False}})
    longer = replace(short, name="long", steps=2_000, continues="tiny-continued/short")
    exp = ex.Experiment("tiny-continued", "a run that continues another", (short, longer))
    monkeypatch.setitem(ex.EXPERIMENTS, exp.name, lambda: exp)
    results, work = tmp_path / "results", tmp_path / "runs"
    with pytest.raises(ValueError, match=r"continues tiny-continued/short seed 0, which is not finished: finish it"):
        on_node(train_one, exp.name, longer, 0, {}, str(work), None, source_results(longer, 0, results, work))
    ex.run_experiment(exp.name, only=["short"], results=results, work=work, progress=False)
    line, files, there = on_node(train_one, exp.name, longer, 0, {}, str(work), None,
                                 source_results(longer, 0, results, work))
    assert line == f"{exp.name}/long/seed-0: done -> {there}"
    assert json.loads(files["continued.json"]) == {"continues": "tiny-continued/short", "seed": 0, "from_step": 1_000}
    (tmp_path / "elsewhere").mkdir()  # a node whose work folder lacks the source's checkpoint says where it looked
    with pytest.raises(ValueError, match=r"which is finished but whose checkpoint is not in .*elsewhere.* --runs-dir"):
        on_node(train_one, exp.name, longer, 0, {}, str(tmp_path / "elsewhere"), None,
                source_results(longer, 0, results, work))


def test_the_pinned_ray_is_the_one_requirements_install():
    pins = [line.split("#")[0].strip() for line in (HERE.parent / "requirements.txt").read_text().splitlines()]
    assert f"ray=={RAY_VERSION}" in pins
