"""What every benchmark record in ``results/benchmarks/`` carries beside its numbers, and how it is written: one
place for the scripts in this folder (they put it on ``sys.path`` as the folder they run from)."""

from __future__ import annotations

import importlib
import json
import os
import platform
import statistics
from collections.abc import Callable, Sequence
from pathlib import Path


def cpu_model() -> str:
    """The processor's model name as the operating system reports it (Linux's ``/proc/cpuinfo``; elsewhere
    :func:`platform.processor`), with the vector extensions a float32 matrix product can use (AVX2, AVX-512)."""
    name, flags = "", set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and not name:
                name = value.strip()
            elif key.strip() == "flags" and not flags:
                flags = set(value.split())
    except OSError:
        pass
    name = name or platform.processor() or platform.machine()
    vector = [label for flag, label in (("avx2", "AVX2"), ("avx512f", "AVX-512")) if flag in flags]
    return f"{name} ({', '.join(vector)})" if vector else name


def provenance(command: str, load_start: Sequence[float] | None = None,
               peers: Sequence[str] = ()) -> dict[str, object]:
    """The command, the versions of what the numbers depend on (:func:`rlcore.provenance.versions`, and of each package
    in ``peers``, e.g. ``stable_baselines3``), the machine (its CPU model, :func:`cpu_model`) with torch's thread count and, from ``load_start`` on,
    the load average before and now, and the commit."""
    import torch

    from rlcore.provenance import git_commit, versions

    machine = {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
               "cpu_model": cpu_model(), "cpu_count": os.cpu_count(), "torch_threads": torch.get_num_threads()}
    if load_start is not None:
        machine |= {"loadavg_start": list(load_start), "loadavg_end": list(os.getloadavg())}
    return {"command": command,
            "versions": {**versions(), **{name: importlib.import_module(name).__version__ for name in peers}},
            "machine": machine, "commit": git_commit()}


def write_record(record: dict[str, object], out: str | os.PathLike, summary: str = "") -> None:
    """Write ``record`` as JSON to ``out`` (making its folder) and print where, after ``summary``."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(record, indent=2) + "\n")
    print(f"{summary}  -> {out}" if summary else f"-> {out}")


def time_side_by_side(runners: dict[str, Callable[..., float]], env_id: str, steps: int, seed: int, repeats: int,
                      cfg: dict[str, object]) -> dict[str, list[float]]:
    """Seconds of each of ``runners`` (name -> ``fn(env_id, steps, seed, cfg)`` returning its seconds), repeated
    ``repeats`` times with the seed ``seed + r``, interleaved (one of each per round), so that a change in the
    machine's load falls on all of them alike; prints each run as it finishes."""
    times: dict[str, list[float]] = {name: [] for name in runners}
    for r in range(repeats):
        for name, fn in runners.items():
            t = fn(env_id, steps, seed + r, cfg)
            times[name].append(t)
            print(f"repeat {r + 1}/{repeats}  {name:6s}  {steps / t:8.0f} env-steps/s  ({t:.1f} s)  "
                  f"load {os.getloadavg()[0]:.2f}", flush=True)
    return times


def throughput(times: dict[str, list[float]], steps: int) -> dict[str, object]:
    """A side-by-side timing (:func:`time_side_by_side` of ``rlcore`` and ``sb3``) as a record holds it: the seconds,
    the env-steps per second of each repeat and of the median one, and rlcore's ratio over SB3."""
    sps = {k: steps / statistics.median(v) for k, v in times.items()}
    return {"seconds": times, "env_steps_per_second_per_repeat": {k: [steps / t for t in v] for k, v in times.items()},
            "env_steps_per_second": sps, "ratio_rlcore_over_sb3": sps["rlcore"] / sps["sb3"]}


def throughput_summary(record: dict[str, object]) -> str:
    """The line a throughput benchmark prints at the end."""
    sps = record["env_steps_per_second"]
    return (f"rlcore {sps['rlcore']:.0f} env-steps/s, SB3 {sps['sb3']:.0f} env-steps/s: ratio "
            f"{record['ratio_rlcore_over_sb3']:.2f}x")
