"""The experiment runner on a Ray cluster (rlbook.cluster), on a local cluster of two CPUs: the results are the local
runner's bit for bit; a killed worker's seed is retried and resumes from its checkpoint; Ctrl-C on the submitting
side cancels the tasks and leaves the seeds resumable; snapshots through Ray; the checkout shipped to the tasks (its
heavy folders and what running code writes left out), a task running other code refused; the seeds in flight in
`experiments status`; without Ray, one line that says what to install, and the local pool as before."""

import json
import os
import re
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
from rlbook.cluster import (BOARD_PREFIX, GENERATED, INSTALL, NAMESPACE, NOT_SHIPPED, PROCESS_BYTES, RAY_VERSION,
                            RESERVED_FROM, Board, OtherCode, SeedsFailed, check_code, check_memory, driver_code,
                            in_flight_lines, last_value, nodes_not_seeing, on_node, ray_backend, ray_snapshots,
                            replay_bytes, shipped_env, source_results, task_memory)
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
    """A Ray cluster of this machine with two CPUs, and this process its driver, whose job ships the checkout as
    :func:`rlbook.cluster.connect` does; yields its address. Its workers get :data:`PINNED` (they inherit this
    process's environment, and the driver's job says so again)."""
    try:
        import ray
    except ImportError:
        skip_or_fail(f"the Ray backend's tests need Ray: {INSTALL}")
    register()
    shipped = shipped_env(driver_code())  # as the backend's own connection ships the checkout
    info = ray.init(address="local", num_cpus=2, include_dashboard=False, namespace=NAMESPACE,
                    runtime_env={**shipped, "env_vars": {**shipped["env_vars"], **PINNED}})
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
    assert replay_bytes(dqn) < RESERVED_FROM and task_memory(dqn) is None  # 4.8 MB: a small cluster schedules it
    assert task_memory(TINY.runs[0]) is None  # q-learning keeps no replay memory
    assert task_memory(BAD.runs[0]) is None  # a bad setting: the seed's own task fails with it, as the local pool's


class Nodes:
    """What check_memory asks of Ray: its nodes, one alive with ``memory`` bytes for tasks, one dead."""

    def __init__(self, memory: int):
        self.memory = memory

    def nodes(self) -> list[dict]:
        return [{"Alive": True, "Resources": {"CPU": 2.0, "memory": float(self.memory)}},
                {"Alive": False, "Resources": {"CPU": 64.0, "memory": float(2**40)}}]


def test_a_reservation_no_node_can_hold_is_one_line_before_anything_starts():
    humanoid = ex.RunSpec("td3", "td3", "Humanoid-v5", 1_000_000, (0,), {})
    tasks = [(humanoid, 0), (TINY.runs[1], 0), (TINY.runs[0], 0)]
    assert check_memory(Nodes(8 * 2**30), "e", tasks) == {"td3": task_memory(humanoid), "dqn": None, "ql": None}
    assert check_memory(Nodes(0), "e", tasks[1:]) == {"dqn": None, "ql": None}  # nothing reserved: nothing to fit
    need = task_memory(humanoid) / 2**30
    with pytest.raises(ValueError) as refused:
        check_memory(Nodes(4 * 2**30), "e", tasks)  # Ray would keep the task waiting for ever
    assert str(refused.value) == (f"e/td3: each seed reserves {need:.1f} GiB for its replay memory and process, more "
                                  "than any node of the cluster has for tasks (4.0 GiB): add a machine with more "
                                  "memory, or lower its buffer_size")


def board_state(ray, seen: dict | None = None) -> dict:
    """Every seed on the boards of this cluster that are alive; ``seen``, if given, gets each board's name and what
    asking it gave (its seeds, or the error: a board that has gone away), for a failure to say."""
    seeds = {}
    for actor in ray.util.list_named_actors(all_namespaces=True):
        if actor["name"].startswith(BOARD_PREFIX):
            try:
                state = ray.get(ray.get_actor(actor["name"], namespace=NAMESPACE).state.remote(), timeout=60)
            except (ValueError, ray.exceptions.RayActorError, ray.exceptions.GetTimeoutError) as exc:
                state = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"  # a finished command's
            if seen is not None:
                seen[actor["name"]] = sorted(state) if isinstance(state, dict) else state
            if isinstance(state, dict):
                seeds.update(state)
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

    def submit() -> None:
        try:
            out["lines"] = ex.run_experiment(TINY.name, only=["long"], results=results, work=work,
                                             train=ray_backend("auto"), progress=False)
        except BaseException as exc:  # said by the assertions below, which would otherwise only see no lines
            out["error"] = exc
            raise

    thread = threading.Thread(target=submit)
    thread.start()
    wait_for(work_dir / "checkpoint.pt")
    key, deadline, seen = f"{TINY.name}/long/seed-0", time.monotonic() + 300, {}
    while key not in (seeds := board_state(ray, seen)) and time.monotonic() < deadline:
        time.sleep(0.05)  # the cluster's list of named actors can lag behind (a bound, as wait_for's)
    assert key in seeds, (f"{key} did not reach the run's board within 300 s; boards: {seen}; the submitting "
                          f"thread: {'alive' if thread.is_alive() else 'ended'}, {out.get('error')!r}")
    # a snapshot through Ray of the seed in training: taken on its node (which the board names), written here. The
    # seed is stopped meanwhile (its files stay), so that it cannot finish before it is killed, however slow the
    # snapshot's new worker is to start on a loaded machine
    pid = seeds[key]["attempts"][-1]["pid"]
    os.kill(pid, signal.SIGSTOP)
    try:
        assert thread.is_alive() and not (result_dir / "policy.pt").exists(), "the seed finished before it stopped"
        (line,) = ex.snapshot_experiment(TINY.name, only=["long"], results=results, work=work,
                                         take=ray_snapshots("auto"))
        assert line.startswith(f"{TINY.name}/long/seed-0: snapshot at step ") and line.endswith(")"), line
        assert line.endswith(f" (from node {seeds[key]['attempts'][-1]['node'][:8]})"), line
        assert json.loads((result_dir / ex.SNAPSHOT).read_text())["steps"] == 4_000
    finally:  # never leave a stopped worker to the cluster: killed, Ray starts another
        os.kill(pid, signal.SIGKILL)
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
                    "restarting from step 0: it had written no checkpoint")
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


def test_the_checkout_is_shipped_without_its_heavy_folders(cluster, tmp_path, monkeypatch):
    import zipfile

    from ray._private.ray_constants import get_runtime_env_default_excludes
    from ray._private.runtime_env.packaging import create_package, get_uri_for_directory
    from ray.remote_function import RemoteFunction

    env = shipped_env(driver_code())
    assert env["working_dir"] == str(HERE.parent) and env["env_vars"] == {"RLCORE_COMMIT": "test-cluster"}
    create_package(env["working_dir"], tmp_path / "shipped.zip", include_gitignore=True, excludes=env["excludes"])
    names = zipfile.ZipFile(tmp_path / "shipped.zip").namelist()
    assert "rlcore/__init__.py" in names and "rlbook/cluster.py" in names and "tests/test_cluster.py" in names
    assert (HERE.parent / "results").is_dir()  # there, and left out
    assert not [n for n in names if n.split("/")[0] in ("runs", "results", "_build", ".venv", ".git")
                or n.startswith("tests/_nbval/")]
    assert set(NOT_SHIPPED) == {"runs", "results", "_build", ".venv", ".git", "tests/_nbval"}
    # what running code writes there (this module's __pycache__, written when pytest imported it) is left out too
    assert not [n for n in names if "__pycache__" in n.split("/") or n.endswith(".pyc")]
    # what the backend passes to its tasks: that package, uploaded, and the submitting machine's commit
    passed, options = [], RemoteFunction.options
    monkeypatch.setattr(RemoteFunction, "options", lambda self, **kw: passed.append(kw) or options(self, **kw))
    results = tmp_path / "results"
    (line,) = ex.run_experiment(TINY.name, only=["ql"], seeds=[0], results=results, work=tmp_path / "runs",
                                train=ray_backend("auto"), progress=False)
    assert line == f"{TINY.name}/ql/seed-0: done -> {results / TINY.name / 'ql' / 'seed-0'}"
    ((task,),) = [[kw["runtime_env"]] for kw in passed]
    uri = get_uri_for_directory(env["working_dir"], include_gitignore=True,
                                excludes=get_runtime_env_default_excludes() + env["excludes"])
    assert task == {"working_dir": uri, "env_vars": {"RLCORE_COMMIT": "test-cluster"}}
    assert json.loads((results / TINY.name / "ql" / "seed-0" / "meta.json").read_text())["commit"] == "test-cluster"


def test_a_work_folder_some_node_does_not_see_is_found(cluster, tmp_path):
    import ray

    # the check that decides whether checkpoints must come back to the submitting machine: each node reads a file this
    # machine wrote there; this cluster's one node sees it, and does not where it holds other content
    assert nodes_not_seeing(ray, tmp_path / "runs") == []
    node = ray.get_runtime_context().get_node_id()
    assert nodes_not_seeing(ray, tmp_path / "runs", token="not what was written") == [
        f"{ray.nodes()[0]['NodeManagerHostname']} ({node[:8]})"]
    assert list((tmp_path / "runs").iterdir()) == []  # the marker is gone


def test_what_running_code_writes_in_the_checkout_changes_neither_package_nor_hash(tmp_path):
    # a fresh clone has no __pycache__ yet: the first import (another test, another command) writes one, and Ray's hash
    # of a working_dir takes in a folder's name even where .gitignore leaves out its files (issue 57's fresh clones)
    from ray._private.ray_constants import get_runtime_env_default_excludes
    from ray._private.runtime_env.packaging import get_uri_for_directory

    root = tmp_path / "checkout"
    for folder in ("rlcore", "tests", "chapters"):
        (root / folder).mkdir(parents=True)
        (root / folder / "__init__.py").write_text("x = 1\n")
    (root / ".gitignore").write_text((HERE.parent / ".gitignore").read_text())

    def uri() -> str:
        env = shipped_env({"commit": "c", "changes": None, "sources": "s"}, root)
        return get_uri_for_directory(str(root), include_gitignore=True,
                                     excludes=get_runtime_env_default_excludes() + env["excludes"])

    before = uri()
    for folder in ("rlcore/__pycache__", "__pycache__", ".pytest_cache/v", "rlcore.egg-info", "tests/_nbval", "runs",
                   "chapters/.ipynb_checkpoints", "_build/.jupyter_cache"):
        (root / folder).mkdir(parents=True)
        (root / folder / "f.pyc").write_bytes(b"generated")
    (root / "MUJOCO_LOG.TXT").write_text("a warning")
    assert uri() == before
    (root / "rlcore" / "__init__.py").write_text("x = 2\n")  # the code itself: another package
    assert uri() != before
    assert {"__pycache__", "*.pyc", ".pytest_cache"} <= set(GENERATED)


def test_a_task_running_other_code_is_refused_in_one_line(cluster, tmp_path, monkeypatch):
    import rlbook.cluster

    here = driver_code()
    check_code(here)  # this process runs the checkout's code: nothing to say
    with pytest.raises(OtherCode, match=rf"^refused on node \S+: its checkout {re.escape(str(HERE.parent))} is at "
                                        rf"commit [0-9a-f]{{40}}, the submitting machine's at {'f' * 40}$"):
        check_code({**here, "commit": "f" * 40})
    # through the cluster: a submitting machine whose sources hash otherwise than the copy shipped to the node
    monkeypatch.setattr(rlbook.cluster, "driver_code", lambda: {**here, "sources": "0" * 64})
    results, work = tmp_path / "results", tmp_path / "runs"
    with pytest.raises(SeedsFailed) as failed:
        ex.run_experiment(TINY.name, only=["ql"], seeds=[0], results=results, work=work, train=ray_backend("auto"),
                          progress=False)
    ((key, error),) = failed.value.failures
    assert key == f"{TINY.name}/ql/seed-0" and isinstance(error, OtherCode)
    assert re.fullmatch(r"refused on node \S+: its rlcore/rlbook in (\S+) are not the submitting machine's "
                        r"\(commit test-cluster; sources [0-9a-f]{12}, there 000000000000\)", str(error)), str(error)
    shipped = Path(re.search(r" in (\S+) are not", str(error)).group(1))
    assert shipped != HERE.parent and not (shipped / "results").exists()  # the node's copy, not the checkout
    assert failed.value.lines == [f"{key}: failed: {error}"]
    assert not work.exists() and not results.exists()  # refused before it trained


def test_status_lists_the_seeds_in_flight_with_node_and_step(cluster, tmp_path, capsys):
    import ray

    from rlbook.__main__ import main

    with pytest.raises(ValueError, match=r"^experiments status --ray local: .* give the address of the cluster"):
        in_flight_lines(TINY.name, "local")
    results, work = tmp_path / "results", tmp_path / "runs"
    out: dict = {}
    thread = threading.Thread(target=lambda: out.update(lines=ex.run_experiment(
        TINY.name, only=["long"], results=results, work=work, train=ray_backend("auto"), progress=False)))
    thread.start()
    key, deadline = f"{TINY.name}/long/seed-0", time.monotonic() + 300
    while (board_state(ray).get(key) or {}).get("checkpoint") is None and time.monotonic() < deadline:
        time.sleep(0.05)  # until the seed has reported a checkpoint
    seed = board_state(ray)[key]
    (line,) = in_flight_lines(TINY.name, cluster)
    node = ray.get_runtime_context().get_node_id()  # the cluster's one node
    match = re.fullmatch(rf"{key}: in flight on {re.escape(socket.gethostname())} \(node {node[:8]}, pid "
                         rf"{seed['attempts'][-1]['pid']}\), step ([\d,]+), last checkpoint at step ([\d,]+)", line)
    assert match, line
    step, saved = (int(g.replace(",", "")) for g in match.groups())
    assert 0 < step <= 4_000 and 0 < saved <= 4_000 and saved % 250 == 0
    code = Path(seed["attempts"][-1]["code"])  # the task imports the copy shipped to the node
    assert code != HERE.parent and (code / "rlcore" / "__init__.py").exists() and not (code / "results").exists()
    register()
    assert main(["experiments", "status", TINY.name, "--ray", cluster, "--results", str(results), "--runs-dir",
                 str(work)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith(f"{TINY.name}/") and any(p.startswith(f"{key}: in flight on ") for p in printed)
    thread.join(timeout=300)
    assert not thread.is_alive() and out["lines"][0].startswith(f"{key}: done -> ")
    assert in_flight_lines(TINY.name, cluster) == [f"{TINY.name}: no seed in flight on the Ray cluster at {cluster}"]


def test_the_board_keeps_a_seeds_last_checkpoint_and_its_end():
    board = Board()
    board.attempt("e/r/seed-0", "a" * 20, 11, 500, "host-a", "/tmp/code")
    assert board.state()["e/r/seed-0"]["checkpoint"] == 500 and board.state()["e/r/seed-0"]["running"]
    board.report("e/r/seed-0", 800.0, None, 750)
    board.report("e/r/seed-0", 900.0, None)  # no checkpoint read this time: the last one stays
    assert board.state()["e/r/seed-0"]["checkpoint"] == 750
    assert board.state()["e/r/seed-0"]["attempts"] == [{"node": "a" * 20, "pid": 11, "host": "host-a",
                                                         "code": "/tmp/code"}]
    board.end("e/r/seed-0")
    assert not board.state()["e/r/seed-0"]["running"]
