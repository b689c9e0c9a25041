"""Atomic checkpoint save and safe load.

A checkpoint is a plain dict of tensors, numbers, strings, lists and dicts, written with
``torch.save`` and read back with ``torch.load(weights_only=True)``: loading never runs pickled code.
Saving goes to a temporary file in the same folder and then ``os.replace``-s it over the target, so an
interrupted save (Ctrl-C, a full disk, a killed job) leaves the previous checkpoint intact.
"""

from __future__ import annotations

import os
import tempfile
import zipfile
from pathlib import Path
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

FORMAT = "rlcore-checkpoint"
FORMAT_VERSION = 1
_PRIMITIVES = (str, int, float, bool, type(None))

META_KEYS = ("algo", "env_id", "seed", "config", "step", "episode", "total_steps", "complete")
"""What every training checkpoint says about itself (:meth:`rlcore.harness.Run.state`); a policy-only copy keeps
these and its algorithm's ``POLICY_KEYS``."""


class CheckpointError(RuntimeError):
    """A file that is missing, truncated, or not an rlcore checkpoint."""


def _plain(obj: Any, where: str = "payload") -> Any:
    """Return ``obj`` with NumPy arrays turned into tensors; reject what ``weights_only`` can't load."""
    if isinstance(obj, np.generic):  # before the primitives: np.float64 is a subclass of float
        return obj.item()
    if isinstance(obj, torch.Tensor) or isinstance(obj, _PRIMITIVES):
        return obj
    if isinstance(obj, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(obj))
    if isinstance(obj, dict):
        return {k: _plain(v, f"{where}[{k!r}]") for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_plain(v, f"{where}[{i}]") for i, v in enumerate(obj))
    raise TypeError(
        f"{where} is a {type(obj).__name__}; a checkpoint holds only tensors, arrays, numbers, "
        "strings, lists and dicts (use module.state_dict() for networks)"
    )


def save_checkpoint(path: str | os.PathLike, payload: dict[str, Any]) -> Path:
    """Write ``payload`` to ``path`` atomically and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {"format": FORMAT, "format_version": FORMAT_VERSION, **_plain(dict(payload))}
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(data, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_checkpoint(path: str | os.PathLike) -> dict[str, Any]:
    """Load a checkpoint written by :func:`save_checkpoint` with ``weights_only=True``.

    Raises :class:`CheckpointError` with a plain explanation for a missing, truncated, foreign or
    unsafe file.
    """
    path = Path(path)
    if path.is_dir():
        raise CheckpointError(f"{path} is a folder; pass the checkpoint file inside it (e.g. {path / 'checkpoint.pt'})")
    if not path.exists():
        raise CheckpointError(f"No checkpoint at {path}: train first, or check the path.")
    if not zipfile.is_zipfile(path):
        raise CheckpointError(
            f"{path} is not an rlcore checkpoint: it is not a PyTorch zip archive (truncated by an "
            "interrupted copy, or another kind of file). Re-copy it or re-run training."
        )
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises pickle/zip/runtime errors of many kinds
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
        # torch's refusal explains itself on its "Unsupported global" line; otherwise the first line
        first = next((ln for ln in lines if "GLOBAL" in ln), lines[0] if lines else type(exc).__name__)
        raise CheckpointError(
            f"{path} could not be loaded safely as an rlcore checkpoint ({type(exc).__name__}: {first}). "
            "It may be truncated or corrupt, or hold Python objects that weights_only loading refuses; "
            "re-run training to write a fresh one."
        ) from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CheckpointError(
            f"{path} is a PyTorch file but not an rlcore checkpoint (no format marker {FORMAT!r}). "
            "Pass a file written by `python -m rlcore train`."
        )
    return data


class Saved:
    """Checkpoint state that is not one ``state_dict`` under one key: ``save()`` returns checkpoint entries,
    ``load(ckpt)`` restores them from a checkpoint."""

    def __init__(self, save: Callable[[], dict[str, Any]], load: Callable[[dict[str, Any]], None]):
        self.save, self.load = save, load


def running_stats_state(rms: Any, prefix: str) -> dict[str, Any]:
    """Gymnasium's ``RunningMeanStd`` as checkpoint entries ``{prefix}_mean``, ``{prefix}_var``, ``{prefix}_count``."""
    return {f"{prefix}_mean": rms.mean, f"{prefix}_var": rms.var, f"{prefix}_count": float(rms.count)}


def load_running_stats(rms: Any, ckpt: dict[str, Any], prefix: str) -> None:
    """Restore into ``rms`` what :func:`running_stats_state` saved under ``prefix``, in ``rms``'s own dtype."""
    rms.mean = np.asarray(ckpt[f"{prefix}_mean"]).astype(rms.mean.dtype)
    rms.var = np.asarray(ckpt[f"{prefix}_var"]).astype(rms.var.dtype)
    rms.count = float(ckpt[f"{prefix}_count"])
