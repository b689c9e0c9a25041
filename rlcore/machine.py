"""The machine a run trains on: its processor and PyTorch's kernels on it (the same code and seed give other bits
elsewhere), and the number of threads torch trains with."""

from __future__ import annotations

import os
import platform
from pathlib import Path


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
