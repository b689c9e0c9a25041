"""The output folder of one training run.

``python -m rlcore train ... --out DIR`` writes::

    DIR/config.json     the algorithm's Config, the environment id, seed and step budget
    DIR/meta.json       what the run records about itself (:mod:`rlcore.provenance`): the command, versions,
                        git commit (and what was uncommitted), machine
    DIR/progress.csv    one row per episode (or update), appended to on resume (rows past the
                        checkpoint's step are dropped first, so none appears twice)
    DIR/eval.csv        one row per evaluation of the deterministic policy
    DIR/checkpoint.pt   the latest checkpoint: the trained policy plus what a resume needs
    DIR/policy_best.pt  the best-evaluated policy so far, with the evaluation it scored (:mod:`rlcore.harness`)

Every number the book shows can be traced back to these files. :func:`open_run` opens such a folder, new or to
resume.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from rlcore.config import config_dict
from rlcore.provenance import run_metadata


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

    @property
    def best_policy(self) -> Path:
        return self.root / "policy_best.pt"


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as indented JSON, atomically (temporary file, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    with os.fdopen(fd, "w") as f:
        json.dump(obj, f, indent=2, sort_keys=True, default=str)
        f.write("\n")
    os.replace(tmp, path)


def open_run(out: str | os.PathLike | None, algo: str, env_id: str, seed: int, steps: int, config: Any,
             schedules: str | None = None, data_parallel: bool = False,
             **meta: Any) -> tuple[RunDir | None, dict[str, Any] | None]:
    """Open a run's output folder: ``(run folder, checkpoint to resume from or None)``.

    No ``out``: ``(None, None)``. A folder with a checkpoint of the same algorithm, environment and seed
    is resumed: its CSV logs lose the rows past the checkpoint's step and ``meta.json`` records the resume
    (step, time, machine, versions, commit) under ``resumes``. One of another run is an error. A new folder
    gets ``config.json`` and ``meta.json`` (``meta`` adds fields to the latter); a folder without a checkpoint is a
    new one, and the CSV logs and best policy of an attempt stopped there before its first checkpoint are removed,
    so that the run's logs hold each step once.

    ``schedules`` names what the step budget shapes in this run (``"epsilon's decay"``), if anything. Such a
    run resumes only with the budget it started with: another ``steps`` would bend the schedule mid-run. A run
    whose budget shapes nothing (DDPG, tabular) may be resumed with a larger budget, which extends it.

    ``data_parallel``: the run is trained by data-parallel workers (:mod:`rlcore.dppo`), whose checkpoints say so
    (``distributed``); neither kind resumes the other's run.
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
        if bool(ckpt.get("distributed")) != data_parallel:
            raise ValueError(other_kind(run.root, algo, data_parallel=not data_parallel))
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
            record.setdefault("resumes", []).append({k: resume[k] for k in RESUME_FIELDS if k in resume})
            write_json(run.meta, record)
        return run, ckpt
    for stale in (*run.root.glob("*.csv"), run.best_policy):  # an attempt stopped before its first checkpoint:
        stale.unlink(missing_ok=True)                          # this run starts over, so do its logs
    write_json(run.config, {"algo": algo, "env_id": env_id, "seed": seed, "steps": steps,
                            "config": config_dict(config)})
    write_json(run.meta, run_metadata(algo=algo, env_id=env_id, seed=seed, steps=steps, **meta))
    return run, None


def other_kind(root: Path, algo: str, data_parallel: bool) -> str:
    """The one-line refusal of a folder that holds a run of the other kind, and how to resume that one."""
    if data_parallel:
        return (f"{root} holds a data-parallel {algo.upper()} run; resume it with `torchrun --nproc_per_node N -m "
                "rlcore.dppo ...` (see rlcore.dppo), or choose another --out folder.")
    return (f"{root} holds a single-process {algo.upper()} run; resume it with `python -m rlcore train {algo}`, "
            "or choose another --out folder.")


RESUME_FIELDS = ("step", "started", "command", "commit", "uncommitted", "checkout_at_start", "machine", "versions")
"""What ``meta.json`` records of each resume, under ``resumes``."""

RESUMABLE_CHANGES = frozenset({"eval_every", "eval_episodes", "checkpoint_every"})
"""Config fields a resumed run may change: they decide what is logged and saved, not what is learned."""


def changed_settings(saved: dict[str, Any], current: dict[str, Any]) -> list[str]:
    """``"name: saved -> current"`` for every setting both configs have and that differs (JSON-wise, so a tuple
    equals the list it was saved as), except :data:`RESUMABLE_CHANGES`. Settings newer than a checkpoint are
    not compared."""
    norm = lambda v: json.dumps(v, sort_keys=True, default=str)  # noqa: E731
    return [f"{k}: {saved[k]!r} -> {current[k]!r}" for k in sorted(saved.keys() & current.keys())
            if k not in RESUMABLE_CHANGES and norm(saved[k]) != norm(current[k])]
