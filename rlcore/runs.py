"""The output folder of one training run, and what it records about itself.

``python -m rlcore train ... --out DIR`` writes::

    DIR/config.json     the algorithm's Config, the environment id, seed and step budget
    DIR/meta.json       the command, versions (Python, torch, Gymnasium, MuJoCo, NumPy, rlcore), git commit
    DIR/progress.csv    one row per episode (or update), appended to on resume (rows past the
                        checkpoint's step are dropped first, so none appears twice)
    DIR/checkpoint.pt   the latest checkpoint: the trained policy plus what a resume needs

Every number the book shows can be traced back to these files.
"""

from __future__ import annotations

import functools
import json
import os
import platform
import shlex
import signal
import subprocess
import sys
import tempfile
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from rlcore.config import config_dict


class RunDir:
    """Paths inside a run's output folder."""

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)

    @property
    def config(self) -> Path:
        return self.root / "config.json"

    @property
    def meta(self) -> Path:
        return self.root / "meta.json"

    @property
    def progress(self) -> Path:
        return self.root / "progress.csv"

    @property
    def checkpoint(self) -> Path:
        return self.root / "checkpoint.pt"


def stop_on_signals(once: bool = False) -> None:
    """Make SIGTERM (a ``kill``, a job scheduler) and SIGINT end a run as Ctrl-C does: a KeyboardInterrupt, on
    which every ``train`` saves a checkpoint before it stops.

    SIGINT is set too, even where it arrives ignored: a shell starts background jobs (``cmd &``) with SIGINT
    ignored, and Python then keeps it ignored, so ``kill -INT`` would do nothing to such a run. With ``once``
    (pool workers, which may receive Ctrl-C from the terminal and the parent's forwarded signal both), the first
    signal interrupts and later ones are ignored, so that the checkpoint it triggers is not cut short.
    """
    def interrupt(signum: int, frame: Any) -> None:
        if once:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, interrupt if once else signal.default_int_handler)


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as indented JSON, atomically (temporary file, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    with os.fdopen(fd, "w") as f:
        json.dump(obj, f, indent=2, sort_keys=True, default=str)
        f.write("\n")
    os.replace(tmp, path)


def git_commit(cwd: str | os.PathLike | None = None) -> str | None:
    """The current git commit of the rlcore checkout (``+dirty`` if it has changes), or None.

    Changes under ``results/`` do not count: those are outputs (a run being copied in), not code.

    A copy of the tree without ``.git`` (a remote machine, say) can name its commit in ``RLCORE_COMMIT``.
    """
    cwd = cwd or Path(__file__).resolve().parent
    if os.environ.get("RLCORE_COMMIT"):
        return os.environ["RLCORE_COMMIT"]
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True, timeout=10
        )
        if sha.returncode != 0:
            return None
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", ":(top)", ":(top,exclude)results"],
            cwd=cwd, capture_output=True, text=True, timeout=10,
        )
        return sha.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


@functools.cache
def loaded_commit() -> str | None:
    """The checkout's commit when this process first recorded a run (its first :func:`run_metadata`), taken as the
    code it runs; asked once, so importing :mod:`rlcore.runs` runs no ``git``.

    A long-lived process (``experiments run`` training seed after seed) keeps running the code it loaded, even
    when the checkout moves on to new commits meanwhile. So a run records this commit, not the checkout's
    current one; where the two differ, :func:`run_metadata` records the latter as ``checkout_at_start``.
    """
    return git_commit()


def versions() -> dict[str, str]:
    """Versions of the pieces a result depends on."""
    import gymnasium
    import torch

    import rlcore

    out = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "torch": torch.__version__,
        "gymnasium": gymnasium.__version__,
        "rlcore": rlcore.__version__,
    }
    try:
        import mujoco

        out["mujoco"] = mujoco.__version__
    except ImportError:
        pass
    return out


def torch_threads() -> int:
    """Set and return torch's thread count for training: ``RLCORE_TORCH_THREADS``, 1 if unset.

    The book's networks are small: one thread each is fastest per core, and several runs share the cores. A
    single long run on an otherwise idle machine may take more (``RLCORE_TORCH_THREADS=2``); the count is recorded
    in each run's ``meta.json``.
    """
    import torch

    raw = os.environ.get("RLCORE_TORCH_THREADS", "1")
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"RLCORE_TORCH_THREADS={raw!r}: give a whole number of threads, 1 or more")
    torch.set_num_threads(n)
    return n


def command_line() -> str | None:
    """How this process was started, as a user would type it: ``python -m rlcore ...`` for a module of a package
    (``python -m rlcore train ...``, ``python -m rlbook experiments run ...``), else the script's name.

    A process that trains for a command typed elsewhere (a Ray task of ``experiments run --ray``, on another
    machine) records that command, which it finds in ``RLCORE_COMMAND``."""
    if os.environ.get("RLCORE_COMMAND"):
        return os.environ["RLCORE_COMMAND"]
    if not sys.argv or not sys.argv[0]:
        return None
    prog = Path(sys.argv[0]).resolve()
    package = [prog.stem] if prog.suffix == ".py" else []
    folder = prog.parent
    while (folder / "__init__.py").is_file():  # a module inside a package: its dotted name
        package.insert(0, folder.name)
        folder = folder.parent
    if len(package) > 1:
        head = ["python", "-m", ".".join(package).removesuffix(".__main__")]
    else:
        head = [prog.name]
    return shlex.join([*head, *sys.argv[1:]])


def cpu_model() -> str:
    """The processor: vendor and model name (from ``/proc/cpuinfo`` where there is one) and the kernels PyTorch
    runs on it: its CPU capability, and ``MKL_ENABLE_INSTRUCTIONS`` where that is set. The same code and seed give
    other bits on other processors (MKL takes other kernels on AMD than on Intel) and with other kernels on the
    same one, so a result that is reproduced bit for bit names it."""
    import torch

    info: dict[str, str] = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    vendor = info.get("vendor_id", platform.machine())
    model = info.get("model name", platform.processor() or "unknown model")
    kernels = torch.backends.cpu.get_cpu_capability()
    mkl = os.environ.get("MKL_ENABLE_INSTRUCTIONS", "").strip()
    if mkl:
        kernels += f", MKL_ENABLE_INSTRUCTIONS={mkl}"
    return f"{vendor} {model} ({kernels})"


def run_metadata(**extra: Any) -> dict[str, Any]:
    """What a result needs next to it: command, versions, commit, machine, time, plus ``extra``.

    ``commit`` is :func:`loaded_commit`, the code this process runs; ``checkout_at_start`` is added when the
    checkout has moved on since this process loaded it.
    """
    import torch

    loaded = loaded_commit()
    meta = {
        "command": command_line(),
        "versions": versions(),
        "commit": loaded,
        "machine": {"platform": platform.platform(), "processor": platform.machine(), "cpu": cpu_model(),
                    "cpus": os.cpu_count(), "torch_threads": torch.get_num_threads()},
        "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        **extra,
    }
    now = git_commit()
    if now != loaded:
        meta["checkout_at_start"] = now
    return meta


def open_run(out: str | os.PathLike | None, algo: str, env_id: str, seed: int, steps: int, config: Any,
             schedules: str | None = None, **meta: Any) -> tuple[RunDir | None, dict[str, Any] | None]:
    """Open a run's output folder: ``(run folder, checkpoint to resume from or None)``.

    No ``out``: ``(None, None)``. A folder with a checkpoint of the same algorithm, environment and seed
    is resumed: its CSV logs lose the rows past the checkpoint's step and ``meta.json`` records the resume
    (step, time, machine, versions, commit) under ``resumes``. One of another run is an error. A new folder
    gets ``config.json`` and ``meta.json`` (``meta`` adds fields to the latter).

    ``schedules`` names what the step budget shapes in this run (``"epsilon's decay"``), if anything. Such a
    run resumes only with the budget it started with: another ``steps`` would bend the schedule mid-run. A run
    whose budget shapes nothing (DDPG, tabular) may be resumed with a larger budget, which extends it.
    """
    if out is None:
        return None, None
    from rlcore.checkpoint import load_checkpoint

    run = RunDir(out)
    if run.checkpoint.exists():
        ckpt = load_checkpoint(run.checkpoint)
        if (ckpt.get("algo"), ckpt.get("env_id"), ckpt.get("seed")) != (algo, env_id, seed):
            raise ValueError(
                f"{run.root} holds a {ckpt.get('algo')} run on {ckpt.get('env_id')} (seed {ckpt.get('seed')}); "
                "choose another --out folder or delete it."
            )
        started = ckpt.get("total_steps")
        if schedules and started is not None and int(started) != steps:
            raise ValueError(
                f"{run.root} was started with --steps {started}, which sets its {schedules}; resume it with "
                f"--steps {started}, or train {steps} steps in a new --out folder."
            )
        changed = changed_settings(ckpt.get("config", {}), config_dict(config))
        if changed:
            raise ValueError(
                f"{run.root} holds a run with other settings ({'; '.join(changed)}), so resuming it would mix two "
                "configurations; choose another --out folder, delete it, or run with its settings."
            )
        from rlcore.logger import drop_rows_after

        for log in sorted(run.root.glob("*.csv")):
            drop_rows_after(log, int(ckpt.get("step", 0)))
        if run.meta.exists():
            record = json.loads(run.meta.read_text())
            resume = run_metadata(step=int(ckpt.get("step", 0)))
            record.setdefault("resumes", []).append({k: resume[k] for k in ("step", "started", "command", "commit",
                                                                             "checkout_at_start", "machine",
                                                                             "versions") if k in resume})
            write_json(run.meta, record)
        return run, ckpt
    write_json(run.config, {"algo": algo, "env_id": env_id, "seed": seed, "steps": steps, "config": config_dict(config)})
    write_json(run.meta, run_metadata(algo=algo, env_id=env_id, seed=seed, steps=steps, **meta))
    return run, None


RESUMABLE_CHANGES = frozenset({"eval_every", "eval_episodes", "checkpoint_every"})
"""Config fields a resumed run may change: they decide what is logged and saved, not what is learned."""


def changed_settings(saved: dict[str, Any], current: dict[str, Any]) -> list[str]:
    """``"name: saved -> current"`` for every setting both configs have and that differs (JSON-wise, so a tuple
    equals the list it was saved as), except :data:`RESUMABLE_CHANGES`. Settings newer than a checkpoint are
    not compared."""
    norm = lambda v: json.dumps(v, sort_keys=True, default=str)  # noqa: E731
    return [f"{k}: {saved[k]!r} -> {current[k]!r}" for k in sorted(saved.keys() & current.keys())
            if k not in RESUMABLE_CHANGES and norm(saved[k]) != norm(current[k])]
