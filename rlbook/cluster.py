"""The experiment runner on a Ray cluster: ``experiments run NAME --ray ADDRESS`` and ``experiments snapshot NAME
--ray ADDRESS``. Ray is optional (``pip install ray==2.60.0``); without ``--ray`` nothing here is imported. The
command line picks this backend (:func:`ray_backend`, :func:`ray_snapshots`) and hands it to the runner's
``run_experiment`` and ``snapshot_experiment``; this module uses :mod:`rlbook.runner`, which never imports it.

The code travels the Ray way: the job's and every task's ``runtime_env`` has the checkout as ``working_dir``
(:func:`shipped_env`; not :data:`NOT_SHIPPED`: ``runs/``, ``results/``, builds, ``.venv/``, ``.git/``; nor what
running code writes in it, :data:`GENERATED`, such as ``__pycache__/``), which Ray uploads once and unpacks on each
node, where the task imports ``rlcore`` and ``rlbook`` from that copy; no node needs a checkout. The copy has no
``.git``, so the submitting machine passes its commit (``RLCORE_COMMIT``, which the runs record) and a hash of its
``rlcore``/``rlbook`` sources (:func:`driver_code`); before it trains, each task hashes the sources it imported and
refuses, in one line, where they differ (:func:`check_code`).

Each missing (experiment, run, seed) becomes one Ray task that asks for one CPU (a DPPO run for one per worker) and
the memory its replay memory needs (:func:`task_memory`), and runs :func:`rlbook.runner.train_one`, the function
the local process pool runs, on whichever node Ray picks. It trains in the run folder
``WORK/<experiment>/<run>/seed-<s>/`` *on that node* (:func:`node_work`) and writes its small outputs to a temporary
results folder there; the task hands those files back, and the submitting machine writes them to its ``results/``:
the same files, with the same provenance, as a local run (``meta.json`` records the command typed on the submitting
machine, and the node's machine, versions and commit).

While the tasks run, each running seed reports its step and latest evaluation to a small actor (:class:`Board`)
that the submitting machine polls for its progress bars. Ctrl-C there cancels the tasks: each running seed gets a
KeyboardInterrupt, writes its checkpoint and stops, as under the local pool, and the same command resumes it.

A seed that fails (its own error) is reported as it fails and the others go on; at the end :class:`SeedsFailed`
lists the failed ones. A task whose worker process or node dies is retried by Ray (:data:`RETRIES` times), and
resumes from the seed's last checkpoint, whose step the submitting machine names. No shared disk is needed for it: a
node trains in its own folder (``--work``, alias ``--runs-dir``, as a path on that node, or the node's
:data:`NODE_RUNS`), and where some node does not see the submitting machine's (:func:`keeper_node`), each task sends
every new checkpoint of its seed, with its logs, back to the submitting machine (:class:`Watcher`,
:func:`send_folder`), which keeps the latest in its own ``--work`` (:class:`Board`); a task that starts a seed (a
retry, or the same command again after Ctrl-C), or a run that continues it, on any node first takes that copy where
it is further on than the node's own (:func:`fetch_folder`). With ``--work`` on storage every node sees, nothing is
sent. An address where nothing answers is one line (:func:`check_answers`), not Ray's minutes of waiting.

``experiments status NAME --ray ADDRESS`` reads the same boards (:func:`in_flight_lines`): each seed in flight,
its machine and node, its step and its last checkpoint's step, which the task reads from the checkpoint when it
changes. No shared disk is needed: the boards live in the cluster while their commands run.

``experiments snapshot --ray`` asks the boards of the ``experiments run --ray`` commands in progress where each seed
trains, and runs :func:`rlbook.runner.snapshot_one` on that node; seeds no board knows are snapshot here, from the
run folders this machine sees.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import socket
import sys
import tempfile
import threading
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rlbook.registry import RunSpec, run_paths
from rlbook.runner import LOGS, SNAPSHOT, SNAPSHOT_POLICY, snapshot_one, train_one

RAY_VERSION = "2.60.0"
"""The Ray release the book is tested with (``requirements.txt``)."""
INSTALL = f"pip install ray=={RAY_VERSION}"

RETRIES = 3
"""How many times Ray starts a seed again whose worker process (or node) died."""
NAMESPACE = "rlbook"
"""The Ray namespace of the boards, so that ``experiments snapshot --ray`` finds them from another driver."""
BOARD_PREFIX = "rlbook-board-"
POLL_SECONDS = 1.0
"""How often a task reads its seed's logs for the board, and the submitting machine reads the board."""
STOP_SECONDS = 300.0
"""How long, after Ctrl-C, the submitting machine waits for the cancelled seeds to write their checkpoints."""
RESULT_FILES = (*LOGS, "policy.pt", SNAPSHOT, SNAPSHOT_POLICY)
"""The files of a seed's results folder that the runner writes, and a node hands back."""


def import_ray():
    """Ray, or a one-line error that says how to install it."""
    try:
        import ray
    except ImportError:
        raise ValueError(f"--ray needs Ray, which is not installed here: {INSTALL}") from None
    return ray


PROBE_SECONDS = 10.0
"""How long the submitting machine waits for ``HOST:PORT`` to answer before it says no cluster is there (Ray itself
would wait minutes, printing its own log lines)."""


def host_port(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of an address ``HOST:PORT`` (or ``ray://HOST:PORT``), else None (``auto``, ``local``)."""
    host, _, port = address.removeprefix("ray://").rpartition(":")
    return (host.strip("[]"), int(port)) if host and port.isdigit() else None


def check_answers(address: str) -> None:
    """A one-line ValueError unless something answers at ``address`` (``HOST:PORT``) within :data:`PROBE_SECONDS`:
    no Ray cluster is there, and the line says how to start one."""
    import socket

    where = host_port(address)
    if where is None:
        return
    try:
        socket.create_connection(where, timeout=PROBE_SECONDS).close()
    except OSError as exc:
        why = "no answer" if isinstance(exc, TimeoutError) else (exc.strerror or type(exc).__name__).lower()
        raise ValueError(f"no Ray cluster answers at {address} ({why}); start one there with `ray start --head "
                         f"--port {where[1]}` on {where[0]}, or train on this machine alone with --ray local") from None


def connect(address: str, cpus: int | None = None, env: dict[str, Any] | None = None):
    """Join the Ray cluster at ``address`` (``auto``: the one ``ray start`` runs on this machine; ``HOST:PORT``), or
    with ``local`` start one on this machine with ``cpus`` CPUs (default: all); a connected driver stays. Returns
    the ``ray`` module. ``env``: the job's ``runtime_env`` (:func:`shipped_env`): with a ``working_dir``, Ray puts
    no folder of this machine (such as the current one) on the workers' import path before the shipped copy.

    Ray starts its worker processes at nice 15; a cluster of this machine alone starts them at this process's
    niceness instead (unless ``RAY_worker_niceness`` says otherwise), as the local pool's workers run, so that on a
    shared machine the seeds are not pushed behind everything else."""
    import logging

    ray = import_ray()
    if ray.is_initialized():
        return ray
    check_answers(address)
    with contextlib.suppress(ImportError, AttributeError):  # its note that .git and .venv are left out: they are ours
        from ray._private.runtime_env.working_dir import _LOG_ONCE_DEFAULT_EXCLUDE_PREFIX
        from ray.util.debug import log_once

        for folder in NOT_SHIPPED:
            log_once(f"{_LOG_ONCE_DEFAULT_EXCLUDE_PREFIX}{folder}")
    try:
        if address == "local":
            os.environ.setdefault("RAY_worker_niceness", str(os.nice(0)))
            ray.init(address="local", num_cpus=cpus, include_dashboard=False, namespace=NAMESPACE,
                     logging_level=logging.WARNING, runtime_env=env)
        else:
            ray.init(address=address, namespace=NAMESPACE, logging_level=logging.WARNING, runtime_env=env)
    except ConnectionError as exc:
        raise ValueError(f"no Ray cluster at {address!r} ({str(exc).splitlines()[0]}); start one with "
                         "`ray start --head`, or train on a cluster of this machine alone with --ray local") from None
    return ray


def seed_key(exp: str, run: str, seed: int) -> str:
    return f"{exp}/{run}/seed-{seed}"


# --- the code, shipped the Ray way -------------------------------------------------------------------------------

NOT_SHIPPED = ("runs", "results", "_build", ".venv", ".git", "tests/_nbval")
"""The checkout's folders that stay on the submitting machine: outputs, builds, the environment, history."""
GENERATED = ("__pycache__", "*.pyc", ".pytest_cache", ".ipynb_checkpoints", "*.egg-info", ".jupyter_cache",
             "MUJOCO_LOG.TXT")
"""What Python, pytest, Jupyter, pip and MuJoCo write anywhere in the checkout whenever code runs there: never
shipped, and never part of the package's hash. Ray's hash of a ``working_dir`` takes in every folder's *name*, even
where ``.gitignore`` (``__pycache__/``) leaves out all its files: without these, the first import of a module
(another test, another command) creates a ``__pycache__`` folder and changes the package under a running
submission. The ``.gitignore``'s own folders (``name/``) are left out by name as well (:func:`shipped_excludes`)."""


def checkout_root() -> Path:
    """The checkout this ``rlbook`` was imported from (it holds ``rlcore/`` and ``rlbook/``)."""
    return Path(__file__).resolve().parents[1]


def source_hash(root: Path) -> str:
    """SHA-256 of the Python sources of ``rlcore/`` and ``rlbook/`` under ``root`` (each file's path and bytes, in
    order): the same on the submitting machine and in the copy shipped to a node, which has no ``.git``."""
    digest = hashlib.sha256()
    for package in ("rlcore", "rlbook"):
        for path in sorted((root / package).rglob("*.py")):
            digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def driver_code() -> dict[str, str | None]:
    """What the submitting machine runs: its checkout's ``commit`` (``+dirty`` with uncommitted changes), the hash
    of those ``changes`` (None where clean) and its ``sources`` (:func:`source_hash`), which each task checks."""
    from rlcore.provenance import git_commit, uncommitted_changes

    root = checkout_root()
    changes = None if os.environ.get("RLCORE_COMMIT") else uncommitted_changes(root)
    return {"commit": git_commit(root), "changes": changes and changes["diff_sha256"], "sources": source_hash(root)}


def shipped_excludes(root: Path) -> list[str]:
    """Ray's ``excludes`` (gitignore patterns) for the checkout ``root``: :data:`NOT_SHIPPED` at its top,
    :data:`GENERATED` anywhere, and each folder its ``.gitignore`` names (``name/``) by its name too, which Ray's own
    reading of ``.gitignore`` leaves in the hash (only the files in it out)."""
    ignored = (root / ".gitignore").read_text().splitlines() if (root / ".gitignore").is_file() else []
    folders = [line.strip().rstrip("/") for line in ignored
               if line.strip().endswith("/") and not line.lstrip().startswith(("#", "!"))]
    return [f"/{d}" for d in NOT_SHIPPED] + [g for g in GENERATED if g not in folders] + folders


def shipped_env(code: dict[str, str | None], root: Path | None = None) -> dict[str, Any]:
    """The ``runtime_env`` of every task and actor: the checkout (``root``, default :func:`checkout_root`) as
    ``working_dir`` but :func:`shipped_excludes`, which Ray uploads once and unpacks on each node, where the task
    imports ``rlcore`` and ``rlbook`` from it; and the submitting machine's commit as ``RLCORE_COMMIT``, which the
    runs record (the copy has no ``.git``)."""
    root = root or checkout_root()
    env: dict[str, Any] = {"working_dir": str(root), "excludes": shipped_excludes(root)}
    if code["commit"]:
        env["env_vars"] = {"RLCORE_COMMIT": code["commit"]}
    return env


def ship(ray, env: dict[str, Any]) -> dict[str, Any]:
    """``env`` (:func:`shipped_env`) with its ``working_dir`` uploaded to the cluster (once for each content: Ray
    keeps the package under a hash of it) and named by its URI, as a task's or actor's ``runtime_env`` must (Ray
    uploads a local folder itself only for the ``runtime_env`` of ``ray.init``, and this driver may be connected
    already)."""
    import logging

    from ray._private.runtime_env.working_dir import upload_working_dir_if_needed

    node = ray._private.worker.global_worker.node
    scratch = node.get_runtime_env_dir_path() if node is not None else tempfile.gettempdir()
    quiet = logging.getLogger("rlbook.cluster.ship")  # not Ray's note that .git and .venv are left out by default
    quiet.setLevel(logging.ERROR)
    env = upload_working_dir_if_needed(dict(env), include_gitignore=True, scratch_dir=scratch, logger=quiet)
    env.pop("excludes", None)
    return env


class OtherCode(ValueError):
    """A task on a node that runs other code than the submitting machine's."""


def check_code(code: dict[str, str | None]) -> None:
    """Before a seed trains: :class:`OtherCode` (one line) unless this process runs the submitting machine's code
    ``code`` (:func:`driver_code`): the ``rlcore`` and ``rlbook`` it imported lie in one folder whose sources hash
    as the submitting machine's, and, where that folder is a git checkout, at the same commit."""
    import rlcore

    here, core = checkout_root(), Path(rlcore.__file__).resolve().parents[1]
    where = f"node {socket.gethostname()}"
    commit = code["commit"] or "unknown"
    if core != here:
        raise OtherCode(f"refused on {where}: it imports rlcore from {core} and rlbook from {here}, not the "
                        f"submitting machine's code (commit {commit}) shipped to it")
    sources = source_hash(here)
    if sources != code["sources"]:
        raise OtherCode(f"refused on {where}: its rlcore/rlbook in {here} are not the submitting machine's (commit "
                        f"{commit}; sources {sources[:12]}, there {str(code['sources'])[:12]})")
    from rlcore.provenance import _git

    head = (_git(["rev-parse", "HEAD"], here) or "").strip()
    if head and code["commit"] and len(code["commit"].split("+")[0]) == 40 and head != code["commit"].split("+")[0]:
        raise OtherCode(f"refused on {where}: its checkout {here} is at commit {head}, the submitting machine's at "
                        f"{commit}")


# --- a seed's results folder, moved between machines ----------------------------------------------------------


def pack(folder: Path) -> dict[str, bytes]:
    """The :data:`RESULT_FILES` that ``folder`` holds, by name."""
    return {name: (folder / name).read_bytes() for name in RESULT_FILES if (folder / name).is_file()}


def unpack(files: dict[str, bytes], folder: Path) -> None:
    """Make ``folder``'s :data:`RESULT_FILES` those of ``files``: write each, remove the others (files the runner
    does not write, such as stored re-evaluations, stay)."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in RESULT_FILES:
        if name in files:
            tmp = folder / f".{name}.tmp"
            tmp.write_bytes(files[name])
            os.replace(tmp, folder / name)
        else:
            (folder / name).unlink(missing_ok=True)


@contextlib.contextmanager
def command_typed(command: str | None):
    """Inside: :func:`rlcore.provenance.command_line` is ``command`` (``RLCORE_COMMAND``), the one typed on the
    submitting machine; afterwards the environment is as it was (a Ray worker process runs task after task)."""
    before = os.environ.get("RLCORE_COMMAND")
    if command:
        os.environ["RLCORE_COMMAND"] = command
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("RLCORE_COMMAND", None)
        else:
            os.environ["RLCORE_COMMAND"] = before


def source_results(spec: RunSpec, seed: int, results: Path, work: Path) -> dict[str, bytes]:
    """For a seed that continues another run's (``spec.continues``), the submitting machine's results of that
    run's seed (its ``policy.pt`` says it is finished), which the node's temporary results folder must hold too."""
    if not spec.continues:
        return {}
    exp, run = spec.continues.split("/")
    return pack(run_paths(exp, run, seed, results, work)[1])


def on_node(fn, exp: str, spec: RunSpec, seed: int, current: dict[str, bytes], work: str, command: str | None,
            source: dict[str, bytes] | None = None, **kwargs: Any) -> tuple[str, dict[str, bytes], str]:
    """Run ``fn`` (:func:`~rlbook.runner.train_one` or :func:`~rlbook.runner.snapshot_one`) for one seed on this
    node, in its work folder (:func:`node_work`), with a temporary results folder that starts as the submitting
    machine's (``current``, and ``source``, the results of the seed it continues, :func:`source_results`): returns
    its status line, the folder's files afterwards, and the folder's path (which the line names)."""
    work = str(node_work(work))
    with tempfile.TemporaryDirectory(prefix="rlbook-results-") as tmp, command_typed(command):
        _, result_dir = run_paths(exp, spec.name, seed, tmp, work)
        unpack(current, result_dir)
        if source:
            unpack(source, run_paths(*spec.continues.split("/"), seed, tmp, work)[1])
        line = fn(exp, spec, seed, Path(tmp), Path(work), **kwargs)
        return line, pack(result_dir), str(result_dir)


# --- checkpoints kept by the submitting machine ----------------------------------------------------------------

NODE_RUNS = "RLBOOK_RUNS_DIR"
"""Set for a node's Ray processes (``RLBOOK_RUNS_DIR=/scratch/runs ray start --address ...``): the folder where that
node trains its seeds, instead of the path the submitting machine gives as ``--runs-dir``."""
CHUNK_BYTES = 64 * 2**20
"""A checkpoint travels between a node and the submitting machine in pieces of this size, so that neither side holds
a second copy of a replay memory of gigabytes."""


def node_work(work: str | os.PathLike) -> Path:
    """Where this node trains: :data:`NODE_RUNS` where its Ray processes were started with it, else ``work``, the
    submitting machine's ``--runs-dir``."""
    return Path(os.environ.get(NODE_RUNS) or work)


def small_files(folder: Path) -> dict[str, bytes]:
    """A seed's run folder as it stands, but its checkpoint: every file but the temporary ones of a save in progress
    (``.name``), each CSV log up to its last whole line (a row being written is left for the next copy)."""
    files = {}
    for path in sorted(folder.iterdir()) if folder.is_dir() else []:
        if path.is_file() and not path.name.startswith(".") and path.name != "checkpoint.pt":
            data = path.read_bytes()
            files[path.name] = data[:data.rfind(b"\n") + 1] if path.suffix == ".csv" else data
    return files


def chunks(path: Path):
    """The file ``path`` in pieces of :data:`CHUNK_BYTES`, read from one open file (a save that replaces it meanwhile
    does not mix two checkpoints)."""
    with open(path, "rb") as f:
        while piece := f.read(CHUNK_BYTES):
            yield piece


def send_folder(board, key: str, folder: Path) -> None:
    """Send the seed ``key``'s run folder ``folder`` (its checkpoint, logs and records) to the submitting machine
    through ``board`` (:meth:`Board.receive`, :meth:`Board.keep`), which replaces its copy once all has arrived."""
    import ray

    logs = small_files(folder)  # the logs first: they reach at least as far as the checkpoint read after them
    offset = 0
    for piece in chunks(folder / "checkpoint.pt"):
        ray.get(board.receive.remote(key, offset, piece))
        offset += len(piece)
    ray.get(board.keep.remote(key, logs))


def fetch_folder(board, key: str, folder: Path) -> int | None:
    """Make ``folder`` the submitting machine's copy of the seed ``key``'s run folder (:meth:`Board.kept`) where that
    copy's checkpoint is later than the one ``folder`` holds (or ``folder`` has none); returns the step of the
    checkpoint ``folder`` then holds (None: none)."""
    import ray

    here = checkpoint_step(folder / "checkpoint.pt")
    kept = ray.get(board.kept.remote(key))
    if kept is None or (here is not None and kept["step"] <= here):
        return here
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.iterdir():
        if old.is_file():
            old.unlink()
    tmp = folder / ".checkpoint.pt.fetching"
    with open(tmp, "wb") as f:
        for offset in range(0, kept["size"], CHUNK_BYTES):
            f.write(ray.get(board.piece.remote(key, offset)))
    for name, data in kept["files"].items():
        (folder / name).write_bytes(data)
    os.replace(tmp, folder / "checkpoint.pt")
    return kept["step"]


# --- the tasks ---------------------------------------------------------------------------------------------------


def last_value(path: Path, column: str) -> float | None:
    """``column`` of the last row of the CSV log ``path`` (read from its end), or None if there is none yet."""
    try:
        with open(path, "rb") as f:
            header = f.readline().decode().strip().split(",")
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - 4096))
            rows = f.read().decode(errors="replace").strip().splitlines()
        if len(rows) < 2 and rows and rows[-1].split(",") == header:
            return None
        return float(rows[-1].split(",")[header.index(column)])
    except (OSError, ValueError, IndexError):
        return None


def checkpoint_step(path: Path) -> int | None:
    """The step the checkpoint ``path`` was written at, the one a resume goes on from (None: none there, or not
    readable). Memory-mapped: its replay memory is not read."""
    import torch

    try:
        return int(torch.load(path, map_location="cpu", weights_only=True, mmap=True)["step"])
    except Exception:  # missing, half-written, or of another kind: not resumable from here
        return None


class Watcher:
    """On a node, beside a training seed: reports its step (``progress.csv``), latest evaluation (``eval.csv``) and
    the step of its last checkpoint (read again when the file changes) to the ``board`` when they change; with
    ``keep``, sends each new checkpoint, with the seed's logs, to the submitting machine (:meth:`Board.keep`), which
    keeps the latest one."""

    def __init__(self, work_dir: Path, key: str, board, keep: bool):
        self.work_dir, self.key, self.board, self.keep = work_dir, key, board, keep
        self.seen: tuple | None = None
        self.written: int | None = None
        self.saved: int | None = None
        self.sent: int | None = None

    def poll(self) -> None:
        """One look at the run folder: report what changed; send a checkpoint not sent yet."""
        with contextlib.suppress(OSError):
            if (stamp := (self.work_dir / "checkpoint.pt").stat().st_mtime_ns) != self.written:
                self.written, self.saved = stamp, checkpoint_step(self.work_dir / "checkpoint.pt")
        now = (last_value(self.work_dir / "progress.csv", "step"),
               last_value(self.work_dir / "eval.csv", "mean_return"), self.saved)
        if now != self.seen:
            self.board.report.remote(self.key, *now)
            self.seen = now
        if self.keep and self.saved is not None and self.written != self.sent:
            send_folder(self.board, self.key, self.work_dir)
            self.sent = self.written

    def run(self, stop: threading.Event) -> None:
        """:meth:`poll` every :data:`POLL_SECONDS` until ``stop`` is set."""
        while not stop.wait(POLL_SECONDS):
            self.poll()


def train_task(exp: str, spec: RunSpec, seed: int, current: dict[str, bytes], work: str, command: str | None,
               board, source: dict[str, bytes] | None = None, code: dict[str, str | None] | None = None,
               keeper: str | None = None) -> tuple[str, dict[str, bytes], str]:
    """One seed, on a Ray worker: :func:`~rlbook.runner.train_one` (:func:`on_node`), its progress on ``board``;
    ``source``: the results of the seed it continues; ``code``: the submitting machine's (:func:`driver_code`),
    which this process must run (:func:`check_code`), else it refuses before training. ``keeper``: the submitting
    machine's node, where the nodes do not all see ``work``: unless this task trains in that very folder, it first
    takes the submitting machine's copy of the seed's run folder where that is further on (and of the seed it
    continues, :func:`fetch_folder`), and sends each new checkpoint there as it is written (:class:`Watcher`), the
    last one too (a finished seed's, which a run that continues it starts from; or the one a stop writes)."""
    import ray

    if code is not None:
        check_code(code)
    key, node, here = seed_key(exp, spec.name, seed), ray.get_runtime_context().get_node_id(), node_work(work)
    keep = keeper is not None and not (node == keeper and here.resolve() == Path(work).resolve())
    work_dir, _ = run_paths(exp, spec.name, seed, tempfile.gettempdir(), here)
    if keep and spec.continues:
        source_exp, source_run = spec.continues.split("/")
        fetch_folder(board, seed_key(source_exp, source_run, seed),
                     run_paths(source_exp, source_run, seed, tempfile.gettempdir(), here)[0])
    resumable = fetch_folder(board, key, work_dir) if keep else checkpoint_step(work_dir / "checkpoint.pt")
    note = ray.get(board.attempt.remote(key, node, os.getpid(), resumable, socket.gethostname(),
                                        str(checkout_root())))
    if note:
        print(note, file=sys.stderr, flush=True)
    stop, watcher = threading.Event(), Watcher(work_dir, key, board, keep)
    thread = threading.Thread(target=watcher.run, args=(stop,), daemon=True)
    thread.start()
    try:
        return on_node(train_one, exp, spec, seed, current, work, command, source)
    finally:  # finished, stopped (Ctrl-C there) or failed: its last checkpoint goes to the submitting machine too
        stop.set()
        thread.join()
        try:
            watcher.poll()
        except Exception as exc:  # the checkpoint stays on this node; a seed's own error is the one to raise
            print(f"{key}: its last checkpoint could not be sent to the submitting machine ({one_line(exc)})",
                  file=sys.stderr, flush=True)


def snapshot_task(exp: str, spec: RunSpec, seed: int, current: dict[str, bytes], work: str, command: str | None,
                  policy: bool) -> tuple[str, dict[str, bytes], str]:
    """:func:`~rlbook.runner.snapshot_one` on the node where the seed trains (:func:`on_node`)."""
    return on_node(snapshot_one, exp, spec, seed, current, work, command, policy=policy)


class Board:
    """Where each seed of one ``experiments run --ray`` trains and how far it is: the tasks report, the submitting
    machine (and ``experiments snapshot --ray``) read. A Ray actor with no CPU of its own, on the submitting
    machine's node. With ``work`` (the submitting machine's ``--runs-dir``, where the nodes do not all see it), it
    also keeps each seed's latest checkpoint there, as the tasks send it (:func:`send_folder`), and hands it to the
    task that goes on with the seed, on any node (:func:`fetch_folder`)."""

    def __init__(self, work: str | None = None) -> None:
        self.seeds: dict[str, dict[str, Any]] = {}
        self.work = work

    def attempt(self, key: str, node: str, pid: int, resumable: float | None, host: str | None = None,
                code: str | None = None) -> str | None:
        """A task starts ``key`` on ``node`` (machine ``host``) in process ``pid``, running the code in folder
        ``code``, with a checkpoint written at step ``resumable`` (None: no checkpoint there). Returns what to say if
        this is a retry."""
        seed = self._seed(key)
        note = None
        if seed["attempts"]:
            died = seed["attempts"][-1]
            reached = f"step {int(seed['step']):,}" if seed["step"] is not None else "its start"
            how = (f"resuming from its checkpoint at step {int(resumable):,}" if resumable is not None else
                   "restarting from step 0: it had written no checkpoint")
            note = (f"{key}: its worker (pid {died['pid']}, node {died['node'][:8]}) died at {reached}; "
                    f"retried on node {node[:8]}, {how}")
            seed["notes"].append(note)
        seed["attempts"].append({"node": node, "pid": pid, "host": host, "code": code})
        seed.update(checkpoint=resumable, running=True)
        return note

    def _seed(self, key: str) -> dict[str, Any]:
        """The seed ``key``'s entry, made empty where it has none yet."""
        return self.seeds.setdefault(key, {"attempts": [], "step": None, "eval": None, "notes": []})

    def _folder(self, key: str) -> Path:
        return Path(self.work) / key

    def receive(self, key: str, offset: int, piece: bytes) -> None:
        """A piece of the seed ``key``'s new checkpoint, at byte ``offset`` (0: a new one begins)."""
        incoming = self._folder(key) / ".checkpoint.pt.incoming"
        incoming.parent.mkdir(parents=True, exist_ok=True)
        with open(incoming, "wb" if offset == 0 else "r+b") as f:
            f.seek(offset)
            f.write(piece)

    def keep(self, key: str, files: dict[str, bytes]) -> None:
        """The seed ``key``'s new checkpoint has all arrived (:meth:`receive`), with the folder's other ``files``:
        make them this machine's copy of its run folder, the checkpoint last (a copy read meanwhile is whole)."""
        folder = self._folder(key)
        for name, data in files.items():
            tmp = folder / f".{name}.tmp"
            tmp.write_bytes(data)
            os.replace(tmp, folder / name)
        incoming = folder / ".checkpoint.pt.incoming"
        size = incoming.stat().st_size
        os.replace(incoming, folder / "checkpoint.pt")
        seed = self._seed(key)
        seed["kept"] = seed.get("kept", 0) + 1
        seed["kept_bytes"] = seed.get("kept_bytes", 0) + size + sum(map(len, files.values()))

    def kept(self, key: str) -> dict[str, Any] | None:
        """This machine's copy of the seed ``key``'s run folder: its checkpoint's ``step`` and ``size`` and the other
        ``files``; None without a checkpoint (or without keeping)."""
        if self.work is None:
            return None
        folder = self._folder(key)
        step = checkpoint_step(folder / "checkpoint.pt")
        if step is None:
            return None
        return {"step": step, "size": (folder / "checkpoint.pt").stat().st_size, "files": small_files(folder)}

    def piece(self, key: str, offset: int) -> bytes:
        """:data:`CHUNK_BYTES` of the seed ``key``'s kept checkpoint from byte ``offset``."""
        with open(self._folder(key) / "checkpoint.pt", "rb") as f:
            f.seek(offset)
            return f.read(CHUNK_BYTES)

    def report(self, key: str, step: float | None, evaluation: float | None, checkpoint: float | None = None) -> None:
        """The seed ``key`` has logged step ``step``, its latest evaluation is ``evaluation`` and its last checkpoint
        was written at step ``checkpoint``."""
        self.seeds[key].update(step=step, eval=evaluation)
        if checkpoint is not None:
            self.seeds[key]["checkpoint"] = checkpoint

    def end(self, key: str) -> None:
        """The seed ``key``'s task has ended (finished, failed or stopped): no longer in flight."""
        if key in self.seeds:
            self.seeds[key]["running"] = False

    def state(self) -> dict[str, dict[str, Any]]:
        return self.seeds


# --- the submitting machine -----------------------------------------------------------------------------------


class SeedBars:
    """On the submitting machine: a bar over the seeds, and one per running seed with its step and latest
    evaluation (from the board); the notes of retried seeds are printed as they come."""

    def __init__(self, steps: dict[str, int], desc: str, enabled: bool):
        from tqdm import tqdm

        self.tqdm, self.steps, self.enabled, self.bars, self.said = tqdm, steps, enabled, {}, set()
        self.total = tqdm(total=len(steps), desc=desc, unit="run", disable=not enabled)

    def show(self, state: dict[str, dict[str, Any]]) -> None:
        for key, seed in state.items():
            for note in seed["notes"]:
                if note not in self.said:
                    self.said.add(note)
                    self.tqdm.write(note, file=sys.stderr)
            if key not in self.steps or not self.enabled:
                continue
            if key not in self.bars:
                self.bars[key] = self.tqdm(total=self.steps[key], desc=key, unit="step", leave=False)
            bar = self.bars[key]
            bar.n = int(seed["step"] or 0)
            if seed["eval"] is not None:
                bar.set_postfix(eval=f"{seed['eval']:.1f}", refresh=False)
            bar.refresh()

    def done(self, key: str) -> None:
        self.total.update(1)
        if key in self.bars:
            self.bars.pop(key).close()

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
        self.total.close()


def new_board(ray, env: dict[str, Any] | None = None, work: Path | None = None):
    """A :class:`Board` actor for one submission on this machine's node, named so that another driver finds it, alive
    while this one is; ``env``: its ``runtime_env`` (:func:`shipped_env`); ``work``: the folder where it keeps the
    seeds' checkpoints (None: it keeps none)."""
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
    return ray.remote(num_cpus=0)(Board).options(name=f"{BOARD_PREFIX}{uuid.uuid4().hex[:12]}", namespace=NAMESPACE,
                                                 runtime_env=env, scheduling_strategy=here).remote(
        None if work is None else str(work))


def ray_backend(address: str) -> Callable[..., list[str]]:
    """The Ray cluster at ``address`` as :func:`rlbook.runner.run_experiment`'s ``train``: each task a seed on the
    cluster (:func:`run_on_ray`; ``jobs``, for ``local`` alone, its CPUs)."""

    def train(name: str, tasks: list[tuple[RunSpec, int]], jobs: int | None, results: Path, work: Path,
              progress: bool = True) -> list[str]:
        return run_on_ray(name, tasks, results, work.resolve(), address, cpus=jobs, progress=progress)

    return train


def ray_snapshots(address: str) -> Callable[..., list[str]]:
    """The Ray cluster at ``address`` as :func:`rlbook.runner.snapshot_experiment`'s ``take``: each seed's snapshot
    on the node where it trains (:func:`snapshot_on_ray`)."""

    def take(name: str, picks: list[tuple[RunSpec, int]], results: Path, work: Path, policy: bool) -> list[str]:
        return snapshot_on_ray(name, picks, results, work.resolve(), address, policy)

    return take


def sees(work: str, name: str, token: str) -> bool:
    """On a node: whether the file ``name`` in the folder where it trains (:func:`node_work` of ``work``) holds
    ``token`` (the one the submitting machine wrote)."""
    try:
        return (node_work(work) / name).read_text() == token
    except OSError:
        return False


def nodes_not_seeing(ray, work: Path, token: str | None = None) -> list[str]:
    """The live nodes (``host (node id)``) that do not train in the work folder ``work`` this machine sees: each is
    asked, by a task of no CPU pinned to it, for a file that this machine writes there (holding ``token``)."""
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    work.mkdir(parents=True, exist_ok=True)
    marker, written = work / f".rlbook-shared-{uuid.uuid4().hex[:12]}", uuid.uuid4().hex
    marker.write_text(written)
    try:
        nodes = [node for node in ray.nodes() if node.get("Alive")]
        remote = ray.remote(num_cpus=0)(sees)
        seen = ray.get([remote.options(scheduling_strategy=NodeAffinitySchedulingStrategy(node["NodeID"], soft=False))
                        .remote(str(work), marker.name, token or written) for node in nodes])
    finally:
        marker.unlink(missing_ok=True)
    return [f"{node.get('NodeManagerHostname', '?')} ({node['NodeID'][:8]})" for node, ok in zip(nodes, seen) if not ok]


def keeper_node(ray, work: Path) -> str | None:
    """This machine's node, where the checkpoints must be kept here (:class:`Board`): on a cluster of several nodes
    some of which do not see the work folder ``work`` as this machine does, so that a retried seed, or one run again
    after Ctrl-C, that lands on another node resumes from its last checkpoint instead of step 0; says so in one line.
    None on one node, or where every node sees ``work`` (storage they all mount): nothing to send."""
    if sum(1 for node in ray.nodes() if node.get("Alive")) < 2 or not (unseen := nodes_not_seeing(ray, work)):
        return None
    print(f"--runs-dir {work} is not this machine's folder on {', '.join(unseen)}: each seed's checkpoints come back "
          f"here as they are written, kept in {work}, and a seed that goes on elsewhere resumes from them",
          file=sys.stderr, flush=True)
    return ray.get_runtime_context().get_node_id()


class SeedsFailed(Exception):
    """Seeds that failed on the cluster while the others went on: ``lines``, the status line of every seed (a failed
    one's says why), and ``failures``, each failed seed's key and error."""

    def __init__(self, lines: list[str], failures: list[tuple[str, BaseException]]):
        super().__init__(f"{len(failures)} seed(s) failed: " + "; ".join(k for k, _ in failures))
        self.lines, self.failures = lines, failures


def run_on_ray(name: str, tasks: list[tuple[RunSpec, int]], results: Path, work: Path, address: str,
               cpus: int | None = None, progress: bool = True) -> list[str]:
    """Train each missing ``(spec, seed)`` of ``tasks`` of experiment ``name`` as a Ray task on the cluster at
    ``address`` (:func:`connect`) and write its results here; returns the status lines, as
    :func:`rlbook.runner.train_all` does. A seed that fails is reported and the others go on; at the end,
    :class:`SeedsFailed` if any did. Ctrl-C cancels them all (:func:`stop`): each running one checkpoints, so
    that the same command resumes them. ``cpus`` (``--jobs``) is for ``local`` alone: a cluster's CPUs are its own."""
    from rlcore.provenance import command_line

    if cpus is not None and address != "local":
        raise ValueError(f"--jobs with --ray {address}: the cluster's CPUs decide how many seeds train at once; "
                         "--jobs sets them only for a cluster of this machine alone (--ray local)")
    code = driver_code()
    ray = connect(address, cpus, shipped_env(code))
    env = ship(ray, shipped_env(code))
    folders = {(spec.name, s): run_paths(name, spec.name, s, results, work)[1] for spec, s in tasks}
    lines = [f"{seed_key(name, run, s)}: already in {folder}" for (run, s), folder in folders.items()
             if (folder / "policy.pt").exists()]
    tasks = [(spec, s) for spec, s in tasks if not (folders[spec.name, s] / "policy.pt").exists()]
    reserved = check_memory(ray, name, tasks)
    keeper = keeper_node(ray, work)
    board, command, refs = new_board(ray, env, work if keeper else None), command_line(), {}
    remote = ray.remote(train_task)
    for spec, s in tasks:
        result_dir = folders[spec.name, s]
        ref = remote.options(num_cpus=spec.workers, memory=reserved[spec.name], max_retries=RETRIES,
                             retry_exceptions=False, name=seed_key(name, spec.name, s), runtime_env=env).remote(
            name, spec, s, pack(result_dir), str(work), command, board, source_results(spec, s, results, work), code,
            keeper)
        refs[ref] = (seed_key(name, spec.name, s), spec.steps, result_dir)
    done, failures = collect(ray, refs, board, name, progress)
    if failures:
        raise SeedsFailed(lines + done, failures)
    return lines + done


PROCESS_BYTES = 512 * 2**20
"""What a seed's process needs besides its replay memory (Python, torch, the simulator), for :func:`task_memory`."""


def replay_bytes(spec: RunSpec) -> int:
    """The bytes of the replay memory a seed of ``spec`` fills (0 for an algorithm without one): ``buffer_size``
    transitions of two float32 observations, the action (float32 vector, or one int64), reward and end flag."""
    from rlcore.algos import get_algorithm
    from rlcore.envs import make_env

    config = get_algorithm(spec.algo).make_config(spec.algo, **spec.overrides)
    if not hasattr(config, "buffer_size"):
        return 0
    env = make_env(spec.env_id, **getattr(config, "env_kwargs", {}))
    obs, act = env.observation_space, env.action_space
    env.close()
    action = 4 * int(np.prod(act.shape)) if act.shape else 8
    return config.buffer_size * (2 * 4 * int(np.prod(obs.shape)) + action + 4 + 4)


RESERVED_FROM = 256 * 2**20
"""The smallest replay memory a task reserves memory for (:func:`task_memory`): a real run's (a 1M-step Humanoid
seed's is about 2.9 GB) reserves, a small one's (CartPole's 100,000 transitions: 4.8 MB; a test's) does not, so that
a small cluster, whose memory Ray counts as what the machine has free when it starts, schedules it as the local pool
would."""


def task_memory(spec: RunSpec) -> int | None:
    """The memory a seed's task reserves on its node (Ray's ``memory=``), so that Ray places no more seeds on a
    machine than its memory holds: its replay memory and half again (a resume holds the loaded checkpoint's copy,
    about half the memory, while it restores it), and :data:`PROCESS_BYTES`. None (no reservation) without a replay
    memory or with one under :data:`RESERVED_FROM`, or where its settings or task are bad (the seed's own task then
    fails with the one-line error)."""
    try:
        replay = replay_bytes(spec)
    except Exception:  # a bad setting or an unknown task: said by the seed's task, as any error of a seed
        return None
    return replay * 3 // 2 + PROCESS_BYTES if replay >= RESERVED_FROM else None


def node_memory(ray) -> int:
    """The memory (Ray's ``memory`` resource, bytes) of the cluster's roomiest live node: no task that reserves more
    can ever start."""
    return max((int(node["Resources"].get("memory", 0)) for node in ray.nodes() if node.get("Alive")), default=0)


def check_memory(ray, name: str, tasks: list[tuple[RunSpec, int]]) -> dict[str, int | None]:
    """Each run's reservation (:func:`task_memory`) by name; a one-line ValueError, before anything is submitted,
    where one is more than any node of the cluster has (Ray would keep its tasks waiting, silently, for ever)."""
    reserved = {spec.name: task_memory(spec) for spec, _ in tasks}
    roomiest = node_memory(ray) if any(reserved.values()) else 0
    for run, need in reserved.items():
        if need and need > roomiest:
            raise ValueError(f"{name}/{run}: each seed reserves {need / 2**30:.1f} GiB for its replay memory and "
                             f"process, more than any node of the cluster has for tasks ({roomiest / 2**30:.1f} "
                             "GiB): add a machine with more memory, or lower its buffer_size")
    return reserved


def collect(ray, refs: dict, board, desc: str, progress: bool) -> tuple[list[str], list[tuple[str, BaseException]]]:
    """Wait for the tasks ``refs`` (ref: key, steps, results folder), showing their progress; write each one's
    results as it finishes. Returns their status lines, with the notes of retried seeds, and the seeds that failed
    (key, error), each reported as it fails while the others go on."""
    bars = SeedBars({key: steps for key, steps, _ in refs.values()}, desc, progress)
    pending, lines, failures = list(refs), [], []
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1, timeout=POLL_SECONDS)
            state = ray.get(board.state.remote())
            bars.show(state)
            for ref in done:
                key, _, result_dir = refs[ref]
                notes = "".join(f" ({n.split(': ', 1)[1]})" for n in state.get(key, {}).get("notes", []))
                if kept := state.get(key, {}).get("kept"):
                    notes += f" ({kept} checkpoint(s), {state[key]['kept_bytes'] / 2**20:,.1f} MiB, kept here)"
                try:
                    line = finished(ray, ref, result_dir)
                except Exception as exc:  # this seed's own error, or its worker died once too often
                    failures.append((key, exc))
                    line = f"{key}: failed: {one_line(exc)}"
                    bars.tqdm.write(line, file=sys.stderr)
                lines.append(line + notes)
                bars.done(key)
                board.end.remote(key)
    except BaseException:  # Ctrl-C
        stop(ray, pending)
        raise
    finally:
        bars.close()
    return lines, failures


def finished(ray, ref, result_dir: Path) -> str:
    """Write the results of the finished task ``ref`` to ``result_dir``; its status line, naming that folder."""
    line, files, there = outcome(ray, ref)
    unpack(files, result_dir)
    return line.replace(there, str(result_dir))


def one_line(exc: BaseException) -> str:
    """An error as one line: its message's first line (with its type where that is not a plain ValueError)."""
    first = (str(exc).strip().splitlines() or [""])[0]
    return first if isinstance(exc, ValueError) and first else f"{type(exc).__name__}: {first}".rstrip(": ")


def outcome(ray, ref):
    """What the task ``ref`` returned; an error of its own comes out as itself, as from the local pool (a bad setting
    is one line, not Ray's wrapper around a remote traceback)."""
    try:
        return ray.get(ref)
    except ray.exceptions.RayTaskError as exc:
        if isinstance(getattr(exc, "cause", None), Exception):
            raise exc.cause from None
        raise


def stop(ray, pending: list) -> None:
    """Cancel the tasks ``pending``: those not started never start, running ones get a KeyboardInterrupt and
    write their checkpoint; wait (up to :data:`STOP_SECONDS`) until they have."""
    if not pending:
        return
    print(f"Stopping {len(pending)} seed(s) on the cluster; each running one writes its checkpoint ...",
          file=sys.stderr, flush=True)
    for ref in pending:
        ray.cancel(ref)
    ray.wait(pending, num_returns=len(pending), timeout=STOP_SECONDS)


def boards(ray) -> dict[str, dict[str, Any]]:
    """Every seed on the boards (:class:`Board`) of the ``experiments run --ray`` commands in progress on the
    cluster."""
    seeds: dict[str, dict[str, Any]] = {}
    for actor in ray.util.list_named_actors(all_namespaces=True):
        if actor["namespace"] == NAMESPACE and actor["name"].startswith(BOARD_PREFIX):
            try:
                seeds.update(ray.get(ray.get_actor(actor["name"], namespace=NAMESPACE).state.remote()))
            except (ValueError, ray.exceptions.RayActorError):  # its command has just ended: the board goes away
                continue
    return seeds


def seed_nodes(ray) -> dict[str, str]:
    """Where each seed trains (its last attempt's node id), from the boards of every ``experiments run --ray`` in
    progress on the cluster."""
    return {key: seed["attempts"][-1]["node"] for key, seed in boards(ray).items()}


def in_flight_lines(name: str, address: str) -> list[str]:
    """``experiments status NAME --ray ADDRESS``: one line per seed of experiment ``name`` training on the cluster
    at ``address`` now (from the boards, :func:`boards`): the machine and node, its step, its last checkpoint's."""
    if address == "local":
        raise ValueError("experiments status --ray local: a new cluster has no seeds in flight; give the address of "
                         "the cluster they train on (auto, or HOST:PORT)")
    seeds = {key: seed for key, seed in boards(connect(address)).items()
             if key.startswith(f"{name}/") and seed.get("running", True)}
    if not seeds:
        return [f"{name}: no seed in flight on the Ray cluster at {address}"]
    lines = []
    for key, seed in sorted(seeds.items()):
        where = seed["attempts"][-1]
        step = "no step logged yet" if seed["step"] is None else f"step {int(seed['step']):,}"
        saved = seed.get("checkpoint")
        saved = "no checkpoint yet" if saved is None else f"last checkpoint at step {int(saved):,}"
        lines.append(f"{key}: in flight on {where.get('host') or 'node'} (node {where['node'][:8]}, pid "
                     f"{where['pid']}), {step}, {saved}")
    return lines


def snapshot_on_ray(name: str, picks: list[tuple[RunSpec, int]], results: Path, work: Path, address: str,
                    policy: bool = False) -> list[str]:
    """:func:`rlbook.runner.snapshot_one` for each ``(spec, seed)`` of ``picks`` on the node where it trains
    (:func:`seed_nodes`), its files written to ``results`` here; a seed no board knows is snapshot here."""
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy
    from rlcore.provenance import command_line

    env = shipped_env(driver_code())
    ray = connect(address, env=env)
    nodes, remote, lines, env = seed_nodes(ray), ray.remote(snapshot_task), [], ship(ray, env)
    for spec, s in picks:
        node = nodes.get(seed_key(name, spec.name, s))
        _, result_dir = run_paths(name, spec.name, s, results, work)
        if node is None or (result_dir / "policy.pt").exists():
            lines.append(snapshot_one(name, spec, s, results, work, policy))
            continue
        there = NodeAffinitySchedulingStrategy(node, soft=False)
        line, files, tmp = outcome(ray, remote.options(num_cpus=0, scheduling_strategy=there, runtime_env=env).remote(
            name, spec, s, pack(result_dir), str(work), command_line(), policy))
        unpack(files, result_dir)
        lines.append(line.replace(tmp, str(result_dir)) + f" (from node {node[:8]})")
    return lines
