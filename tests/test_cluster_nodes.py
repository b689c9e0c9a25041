"""The experiment runner on a Ray cluster of machines that share nothing but a network (issue 57, item 9), as a local
cluster of three nodes: the submitting machine's (no CPU for seeds) and two nodes A and B of one CPU, each with its
own temporary folder and its own work folder (``RLBOOK_RUNS_DIR``), so that no node sees another's run folders.
The code is shipped to the nodes; each seed's checkpoints come back to the submitting machine as they are written;
a node killed mid-seed has its seed resumed on the other from the checkpoint kept there; a re-run after Ctrl-C
resumes with the nodes' folders gone; a run that continues another starts on a node from the source's checkpoint
kept there; status lists the seeds in flight on both nodes. Every result is the local runner's, bit for bit."""

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest
import torch

import rlbook as ex
from portable import skip_or_fail
from rlbook.cluster import (BOARD_PREFIX, INSTALL, NAMESPACE, NODE_RUNS, driver_code, in_flight_lines, ray_backend,
                            shipped_env)
from test_cluster import PINNED, board_state, pinned_environment, same, wait_for  # noqa: F401 (a fixture)

HERE = Path(__file__).parent
LONG = {"learning_starts": 100, "train_freq": 4, "gradient_steps": 1, "eval_every": 1_000, "hidden": [16],
        "checkpoint_every": 250}
SHORT = {"learning_starts": 100, "hidden": (16,), "batch_size": 32, "eval_every": 200, "eval_episodes": 1,
         "checkpoint_every": 200}
NODES = ex.Experiment("nodes-cluster", "a test experiment for a cluster of machines that share nothing", (
    ex.RunSpec("long", "dqn", "CartPole-v1", 4_000, (0, 1), LONG),
    # long enough to be stopped part of the way: a node sends its first checkpoint within a second, at about a
    # seventh of the way
    ex.RunSpec("longest", "dqn", "CartPole-v1", 16_000, (0,), LONG),
    # a run that continues another (as td3-sac-humanoid-2m does): TD3, whose budget sets no schedule
    ex.RunSpec("short", "td3", "Pendulum-v1", 400, (0,), SHORT),
    ex.RunSpec("longer", "td3", "Pendulum-v1", 800, (0,), SHORT, continues="nodes-cluster/short"),
))


def register() -> None:
    ex.EXPERIMENTS[NODES.name] = lambda: NODES


# pinned_environment (autouse, imported): test_cluster.PINNED set and test_cluster.UNSET unset for these tests too;
# the nodes' processes get PINNED from their start (Nodes.add)


def driver_main(argv: list[str]) -> int:  # a submitting process, run by a test below: `python -m rlbook ...`
    from rlbook.__main__ import main

    register()
    return main(argv)


class Nodes:
    """The cluster (``cluster``), and for each of the nodes ``"a"`` and ``"b"`` its node and work folder; the nodes'
    object stores of ``object_store_mib`` (default: Ray's for a test cluster, 150 MiB). Also
    ``benchmarks/ray_keeping.py``'s cluster."""

    def __init__(self, top: Path, object_store_mib: int | None = None):
        from ray.cluster_utils import Cluster

        self.top, self.cluster, self.nodes = top, Cluster(), {}
        self.store = {} if object_store_mib is None else {"object_store_memory": object_store_mib * 2**20}
        # the submitting machine: no CPU, so that every seed trains on A or B; the driver joins it (Ray prefers the
        # head among the nodes of one host)
        self.cluster.add_node(num_cpus=0, temp_dir=str(top / "tmp-head"), **self.store)
        for name in ("a", "b"):
            self.add(name)

    def add(self, name: str) -> None:
        """Start node ``name`` (again): one CPU, its own temporary folder and work folder."""
        work = self.top / f"runs-{name}"
        node = self.cluster.add_node(num_cpus=1, temp_dir=str(self.top / f"tmp-{name}"),
                                     env_vars={NODE_RUNS: str(work), **PINNED}, **self.store)
        self.nodes[name] = (node, work)

    def work(self, name: str) -> Path:
        return self.nodes[name][1]

    def clear(self) -> None:
        """The nodes' work folders emptied (an earlier test's seeds gone from them)."""
        for name in ("a", "b"):
            shutil.rmtree(self.top / f"runs-{name}", ignore_errors=True)

    def named(self, node_id: str) -> str:
        """``"a"`` or ``"b"``: the node of id ``node_id``."""
        return next(n for n, (node, _) in self.nodes.items() if node.node_id == node_id)

    def kill(self, name: str) -> None:
        self.cluster.remove_node(self.nodes.pop(name)[0], allow_graceful=False)


@pytest.fixture(scope="module")
def nodes(pinned_environment):
    try:
        import ray
    except ImportError:
        skip_or_fail(f"the Ray backend's tests need Ray: {INSTALL}")
    register()
    top = Path(tempfile.mkdtemp(prefix="rln-", dir="/tmp"))  # short: Ray's socket paths are bounded
    (top / "ray").mkdir()
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RAY_TMPDIR", str(top))  # where Ray notes the cluster's address: not the reader's /tmp/ray
        cluster = Nodes(top)
        shipped = shipped_env(driver_code())
        # the nodes' workers know the test experiment too (a continued run looks its source up by name): the hook
        # that registers it travels by value, this module being none of the shipped code's
        ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
        ray.init(address=cluster.cluster.address, namespace=NAMESPACE,
                 runtime_env={**shipped, "env_vars": {**shipped["env_vars"], **PINNED},
                              "worker_process_setup_hook": register})
        try:
            yield cluster
        finally:
            ray.shutdown()
            cluster.cluster.shutdown()
            shutil.rmtree(top, ignore_errors=True)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The local runner's results of the whole test experiment (one process, one torch thread)."""
    register()
    results = tmp_path_factory.mktemp("local") / "results"
    ex.run_experiment(NODES.name, results=results, work=results.parent / "runs", progress=False)
    return results


def assert_same(ours: Path, theirs: Path, run: str, seed: int = 0, aside: tuple[str, ...] = ()) -> None:
    """The seed's files are the local runner's: the same names, the same bytes (``meta.json`` but its start, its
    timing, its resumes and ``aside``), the policy's tensors equal."""
    a, b = (ex.run_paths(NODES.name, run, seed, r, r)[1] for r in (ours, theirs))
    assert sorted(p.name for p in a.iterdir()) == sorted(p.name for p in b.iterdir())
    for path in a.iterdir():
        other = b / path.name
        if path.name == "meta.json":
            x, y = json.loads(path.read_text()), json.loads(other.read_text())
            unlike = dict.fromkeys(("started", "timing", "resumes", *aside))
            assert {**x, **unlike} == {**y, **unlike}
        elif path.name != "policy.pt":
            assert path.read_bytes() == other.read_bytes(), (run, seed, path.name)
    x, y = (torch.load(d / "policy.pt", weights_only=True) for d in (a, b))
    assert same(x, y), (run, seed)


def in_thread(fn, *args, **kwargs) -> tuple[threading.Thread, dict]:
    """``fn`` running in a thread; its return value (``"lines"``) or error (``"error"``) lands in the dict."""
    out: dict = {}

    def run() -> None:
        try:
            out["lines"] = fn(*args, **kwargs)
        except BaseException as exc:  # said by the assertions, which would otherwise see no lines
            out["error"] = exc

    thread = threading.Thread(target=run)
    thread.start()
    return thread, out


def boards(ray) -> set[str]:
    """The names of the boards on the cluster now (each ``experiments run --ray`` in progress has one)."""
    return {a["name"] for a in ray.util.list_named_actors(all_namespaces=True) if a["name"].startswith(BOARD_PREFIX)}


def held(ray, keys: list[str], before: set[str], seconds: float = 300) -> dict:
    """Stop (SIGSTOP) the worker of each seed of ``keys`` as soon as it is on a board not among ``before`` (the
    submission's, not a board of an earlier command that is going away), when its task has started and before it
    trains on, so that none finishes while a test looks; returns that board's state once all are (a bound, not a
    pause)."""
    deadline, stopped = time.monotonic() + seconds, set()
    while time.monotonic() < deadline:
        state: dict = {}
        for name in boards(ray) - before:
            with contextlib.suppress(ValueError, ray.exceptions.RayActorError):
                state.update(ray.get(ray.get_actor(name, namespace=NAMESPACE).state.remote(), timeout=60))
        for key in keys:
            if key not in stopped and state.get(key, {}).get("running"):
                os.kill(state[key]["attempts"][-1]["pid"], signal.SIGSTOP)
                stopped.add(key)
        if stopped == set(keys):
            return state
        time.sleep(0.05)
    raise AssertionError(f"{keys} did not all start within {seconds} s: {board_state(ray)}")


def test_seeds_train_on_both_nodes_with_shipped_code_and_their_checkpoints_come_back(nodes, reference, tmp_path):
    import ray

    results, work = tmp_path / "results", tmp_path / "runs"
    nodes.clear()
    keys, before = [f"{NODES.name}/long/seed-{s}" for s in (0, 1)], boards(ray)
    thread, out = in_thread(ex.run_experiment, NODES.name, only=["long"], results=results, work=work,
                            train=ray_backend("auto"), progress=False)
    state = held(ray, keys, before)  # neither finishes while status is read
    pids = [state[k]["attempts"][-1]["pid"] for k in keys]
    try:
        lines = in_flight_lines(NODES.name, "auto")
    finally:
        for pid in pids:
            os.kill(pid, signal.SIGCONT)
    where = {k: state[k]["attempts"][-1] for k in keys}
    assert sorted(nodes.named(w["node"]) for w in where.values()) == ["a", "b"]  # one seed on each node
    assert [line.split(": in flight on ")[0] for line in lines] == keys, lines
    for line, k in zip(lines, keys):
        assert f"(node {where[k]['node'][:8]}, pid {where[k]['pid']}), " in line, line
    for w in where.values():  # the code each imports: the copy shipped to its node, not this checkout
        assert Path(w["code"]).is_relative_to(nodes.top / f"tmp-{nodes.named(w['node'])}"), w["code"]
    thread.join(timeout=600)
    assert not thread.is_alive() and "error" not in out, out.get("error")
    for s, line in enumerate(sorted(out["lines"])):  # in the order they finished
        result_dir = ex.run_paths(NODES.name, "long", s, results, work)[1]
        assert line.startswith(f"{NODES.name}/long/seed-{s}: done -> {result_dir} (") and "kept here)" in line, line
        assert_same(results, reference, "long", s)
        node = nodes.named(where[keys[s]]["node"])
        trained = ex.run_paths(NODES.name, "long", s, results, nodes.work(node))[0]
        kept = ex.run_paths(NODES.name, "long", s, results, work)[0]
        other = ex.run_paths(NODES.name, "long", s, results, nodes.work("b" if node == "a" else "a"))[0]
        assert not other.exists()  # nothing is shared: the other node never saw this seed
        # the submitting machine keeps the seed's last checkpoint (the finished one: a run may continue it)
        assert (kept / "checkpoint.pt").read_bytes() == (trained / "checkpoint.pt").read_bytes()


def test_a_continued_run_starts_on_a_node_from_the_source_kept_by_the_submitting_machine(nodes, reference,
                                                                                         tmp_path):
    results, work = tmp_path / "results", tmp_path / "runs"
    nodes.clear()
    ex.run_experiment(NODES.name, only=["short"], results=results, work=work, train=ray_backend("auto"),
                      progress=False)
    nodes.clear()  # the source's checkpoint is now on the submitting machine alone
    (line,) = ex.run_experiment(NODES.name, only=["longer"], results=results, work=work, train=ray_backend("auto"),
                                progress=False)
    assert line.startswith(f"{NODES.name}/longer/seed-0: done -> "), line
    assert_same(results, reference, "longer")
    assert json.loads((ex.run_paths(NODES.name, "longer", 0, results, work)[1] / "continued.json").read_text()) == {
        "continues": f"{NODES.name}/short", "seed": 0, "from_step": 400}


def test_ctrl_c_then_a_rerun_resumes_from_the_checkpoint_kept_by_the_submitting_machine(nodes, reference, tmp_path):
    results, work = tmp_path / "results", tmp_path / "runs"
    nodes.clear()
    kept, result_dir = ex.run_paths(NODES.name, "longest", 0, results, work)
    argv = ["experiments", "run", NODES.name, "--only", "longest", "--seeds", "0", "--ray",
            nodes.cluster.address, "--results", str(results), "--runs-dir", str(work)]
    code = (f"import sys; sys.path.insert(0, {str(HERE)!r}); import test_cluster_nodes as t; "
            f"sys.exit(t.driver_main({argv!r}))")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(kept / "checkpoint.pt")  # a checkpoint has come back from the node
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "is not this machine's folder on " in err and "come back here as they are written" in err, err
    stopped = torch.load(kept / "checkpoint.pt", weights_only=True, mmap=True)["step"]
    assert 0 < stopped < 16_000 and not (result_dir / "policy.pt").exists()
    nodes.clear()  # the re-run lands on a node that has nothing of the seed
    (line,) = ex.run_experiment(NODES.name, only=["longest"], seeds=[0], results=results, work=work,
                                train=ray_backend("auto"), progress=False)
    assert line.startswith(f"{NODES.name}/longest/seed-0: done -> {result_dir}"), line
    resumes = json.loads((result_dir / "meta.json").read_text())["resumes"]
    assert [r["step"] for r in resumes] == [stopped]  # resumed where Ctrl-C stopped it, on the submitting machine
    assert_same(results, reference, "longest", aside=("command",))  # it records the command that started it


def test_a_node_killed_mid_seed_has_its_seed_resumed_on_the_other_from_the_kept_checkpoint(nodes, reference,
                                                                                           tmp_path):
    import ray

    results, work = tmp_path / "results", tmp_path / "runs"
    nodes.clear()
    kept, result_dir = ex.run_paths(NODES.name, "longest", 0, results, work)
    key, before = f"{NODES.name}/longest/seed-0", boards(ray)
    thread, out = in_thread(ex.run_experiment, NODES.name, only=["longest"], seeds=[0], results=results, work=work,
                            train=ray_backend("auto"), progress=False)
    where = held(ray, [key], before)[key]["attempts"][-1]
    os.kill(where["pid"], signal.SIGCONT)
    wait_for(kept / "checkpoint.pt")  # a checkpoint has come back from the node
    os.kill(where["pid"], signal.SIGSTOP)  # it cannot finish before its node goes
    assert thread.is_alive() and not (result_dir / "policy.pt").exists(), f"the seed ended before its node went: {out}"
    died = nodes.named(where["node"])
    nodes.kill(died)
    os.kill(where["pid"], signal.SIGKILL)  # the machine is gone, and its processes with it
    try:
        thread.join(timeout=600)
        assert not thread.is_alive() and "error" not in out, out.get("error")
    finally:
        nodes.add(died)  # the cluster as it was, for any later test
    (line,) = out["lines"]
    assert line.startswith(f"{key}: done -> {result_dir} (its worker (pid {where['pid']}"), line
    assert "resuming from its checkpoint at step " in line, line
    resumes = json.loads((result_dir / "meta.json").read_text())["resumes"]
    assert len(resumes) == 1 and 0 < resumes[0]["step"] < 16_000
    assert f"resuming from its checkpoint at step {resumes[0]['step']:,})" in line
    assert_same(results, reference, "longest")
