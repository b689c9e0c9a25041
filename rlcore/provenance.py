"""What a run records about itself, so that a result can be traced to the code and machine that made it: the
command line, the versions of what it depends on, the git commit of the code it ran (and, where the tree was not
clean, which files were uncommitted and a hash of their changes), the machine (:mod:`rlcore.machine`).

Nothing here runs ``git`` at import time: the commit is asked for when a process first records a run.
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import shlex
import subprocess
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from rlcore.machine import cpu_model


CODE = ("--", ":(top)", ":(top,exclude)results")
"""The paths whose changes count as changes of the code: the whole checkout but ``results/``, whose changes are
outputs (a run being copied in), not code."""


def _git(args: list[str], cwd: str | os.PathLike | None) -> str | None:
    """``git args`` in ``cwd`` (default: this package's folder): its output, or None where git or the checkout is
    missing."""
    try:
        done = subprocess.run(["git", *args], cwd=cwd or Path(__file__).resolve().parent, capture_output=True,
                              text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout if done.returncode == 0 else None


def git_commit(cwd: str | os.PathLike | None = None) -> str | None:
    """The current git commit of the rlcore checkout (``+dirty`` if it has uncommitted changes of tracked files
    outside ``results/``), or None.

    A copy of the tree without ``.git`` (a remote machine, say) can name its commit in ``RLCORE_COMMIT``.
    """
    if os.environ.get("RLCORE_COMMIT"):
        return os.environ["RLCORE_COMMIT"]
    sha = _git(["rev-parse", "HEAD"], cwd)
    if sha is None:
        return None
    return sha.strip() + ("+dirty" if uncommitted_changes(cwd) else "")


def uncommitted_changes(cwd: str | os.PathLike | None = None) -> dict[str, Any] | None:
    """What a dirty checkout holds beyond its commit: ``files``, the lines of ``git status --porcelain`` (tracked
    files outside ``results/``), and ``diff_sha256``, the SHA-256 of ``git diff HEAD`` over them, so that two runs
    made from the same uncommitted state can be told apart from two made from different ones. None where the
    checkout is clean (or git is missing)."""
    status = _git(["status", "--porcelain", "--untracked-files=no", *CODE], cwd)
    files = [line for line in (status or "").splitlines() if line.strip()]
    if not files:
        return None
    diff = _git(["diff", "HEAD", "--binary", *CODE], cwd) or ""
    return {"files": files, "diff_sha256": hashlib.sha256(diff.encode()).hexdigest()}


@functools.cache
def loaded_commit() -> str | None:
    """The checkout's commit when this process first recorded a run (its first :func:`run_metadata`), taken as the
    code it runs; asked once, so importing rlcore runs no ``git``. Its uncommitted changes are taken at the same
    moment (:func:`loaded_changes`).

    A long-lived process (``experiments run`` training seed after seed) keeps running the code it loaded, even
    when the checkout moves on to new commits meanwhile. So a run records this commit, not the checkout's
    current one; where the two differ, :func:`run_metadata` records the latter as ``checkout_at_start``.
    """
    loaded_changes()
    return git_commit()


@functools.cache
def loaded_changes() -> dict[str, Any] | None:
    """:func:`uncommitted_changes` of the checkout when this process first recorded a run (see :func:`loaded_commit`);
    None where it was clean, or named by ``RLCORE_COMMIT``."""
    return None if os.environ.get("RLCORE_COMMIT") else uncommitted_changes()


def dirty_warning() -> str | None:
    """One line for a command that makes results from a checkout with uncommitted changes (None where it is clean):
    they are recorded, but the commit alone no longer names the code."""
    changes = loaded_changes() if loaded_commit() else None
    if not changes:
        return None
    names = [line[3:] for line in changes["files"]]
    shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
    return (f"warning: the checkout has uncommitted changes ({shown}); each run records them in its meta.json "
            "under 'uncommitted', but commit them first to make results a commit names")


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


def run_metadata(**extra: Any) -> dict[str, Any]:
    """What a result needs next to it: command, versions, commit, machine, time, plus ``extra``.

    ``commit`` is :func:`loaded_commit`, the code this process runs, with ``uncommitted`` (:func:`loaded_changes`)
    where that checkout was dirty; ``checkout_at_start`` is added when the checkout has moved on since this process
    loaded it.
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
    if loaded is not None and loaded.endswith("+dirty"):
        meta["uncommitted"] = loaded_changes()
    now = git_commit()
    if now != loaded:
        meta["checkout_at_start"] = now
    return meta
