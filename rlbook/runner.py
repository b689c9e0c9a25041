"""Training the named experiments: one seed at a time or one process per core, resumable, with the small
outputs copied to ``results/`` when a seed finishes.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Any

from rlbook import paths
from rlbook.registry import RunSpec, get_experiment, run_paths


def export_policy(checkpoint: str | os.PathLike, dest: str | os.PathLike) -> int:
    """Write only what :func:`load_policy` needs from ``checkpoint`` (no replay memory, no optimizer); returns the
    step the checkpoint was written at."""
    from rlcore.algos import get_algorithm
    from rlcore.checkpoint import META_KEYS, load_checkpoint, save_checkpoint

    ckpt = load_checkpoint(checkpoint)
    keys = (*META_KEYS, *get_algorithm(ckpt["algo"]).POLICY_KEYS)
    save_checkpoint(dest, {k: ckpt[k] for k in keys if k in ckpt and k not in ("format", "format_version")})
    return int(ckpt["step"])


def config_class(algo: str) -> type:
    """The Config dataclass of ``algo``, an algorithm of :mod:`rlcore.algos`."""
    from rlcore.algos import get_algorithm

    return get_algorithm(algo).Config


def distributed_command(spec: RunSpec, seed: int, out: str | os.PathLike) -> list[str]:
    """The torchrun command line that trains one seed of a ``dppo`` spec with ``spec.workers`` workers in ``out``.

    ``python -m torch.distributed.run`` is ``torchrun``; ``--standalone`` picks a free port, so that several runs
    can train side by side. Running it again resumes from the run's checkpoint, as every ``train`` does.
    """
    if spec.algo != "dppo":
        raise ValueError(f"{spec.name}: only dppo runs are started by torchrun, not {spec.algo!r}")
    from rlcore.launch import torchrun_command

    return torchrun_command(spec.workers, spec.env_id, spec.steps, seed, out, spec.overrides)


def train_one(exp: str, spec: RunSpec, seed: int, results: Path | None = None, work: Path | None = None) -> str:
    """Train (or resume) one seed in ``work`` and copy its small outputs to ``results`` (default: the book's
    ``runs/`` and ``results/``, :mod:`rlbook.paths`); returns a status line."""
    from rlcore.algos import get_algorithm
    from rlcore.machine import torch_threads

    torch_threads()  # one per process unless RLCORE_TORCH_THREADS says more (one long run on an idle machine)
    results, work = results or paths.results_dir(), work or paths.work_dir()
    work_dir, result_dir = run_paths(exp, spec.name, seed, results, work)
    if (result_dir / "policy.pt").exists():
        return f"{exp}/{spec.name}/seed-{seed}: already in {result_dir}"
    if spec.continues and not (work_dir / "checkpoint.pt").exists():
        start_from(spec, seed, work_dir, results, work)
    started = (time.perf_counter(), cpu_seconds())
    if spec.algo == "dppo":  # one process per worker, started by torchrun; each worker with one torch thread
        run_torchrun(distributed_command(spec, seed, work_dir), {**os.environ, "OMP_NUM_THREADS": "1"})
    else:
        module = get_algorithm(spec.algo)
        config = module.make_config(spec.algo, **spec.overrides)
        module.train(spec.env_id, config, steps=spec.steps, seed=seed, out=work_dir, progress=False)
    copy_logs(work_dir, result_dir)
    record_timing(result_dir / "meta.json", time.perf_counter() - started[0], cpu_seconds() - started[1])
    export_policy(work_dir / "checkpoint.pt", result_dir / "policy.pt")
    for name in (SNAPSHOT, SNAPSHOT_POLICY):  # the finished seed replaces its in-progress snapshot
        (result_dir / name).unlink(missing_ok=True)
    return f"{exp}/{spec.name}/seed-{seed}: done -> {result_dir}"


def start_from(spec: RunSpec, seed: int, work_dir: Path, results: Path, work: Path) -> None:
    """Copy the finished seed that ``spec`` continues (``spec.continues``, its checkpoint and logs) into
    ``work_dir``, from where ``train`` resumes it with ``spec``'s larger budget; its record says so."""
    exp, run = spec.continues.split("/")
    (source,) = chosen_runs(exp, [run])
    source_work, source_results = run_paths(exp, run, seed, results, work)
    if not (source_results / "policy.pt").exists():
        raise ValueError(f"{spec.name} seed {seed} continues {exp}/{run} seed {seed}, which is not finished: finish "
                         f"it first with `python -m rlbook experiments run {exp} --only {run} --seeds {seed}`")
    if not (source_work / "checkpoint.pt").exists():
        raise ValueError(f"{spec.name} seed {seed} continues {exp}/{run} seed {seed}, which is finished but whose "
                         f"checkpoint is not in {source_work} (on a cluster: nor in the submitting machine's "
                         "--runs-dir, which keeps a finished seed's last checkpoint)")
    if source.overrides != spec.overrides or source.algo != spec.algo or source.env_id != spec.env_id:
        raise ValueError(f"{spec.name} continues {exp}/{run} with other settings; a continued run keeps them all")
    work_dir.mkdir(parents=True, exist_ok=True)
    for f in source_work.iterdir():
        if f.is_file():
            shutil.copy2(f, work_dir / f.name)
    (work_dir / CONTINUED).write_text(json.dumps({"continues": spec.continues, "seed": seed,
                                                 "from_step": source.steps}, indent=2) + "\n")


def cpu_seconds() -> float:
    """CPU time of this process and of its children that have ended (torchrun and its workers)."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def record_timing(meta: Path, wall: float, cpu: float) -> None:
    """Add to a seed's results ``meta.json`` what its last session took: ``timing`` = wall and CPU seconds (the
    process's and its workers'), and the step that session started from (0, or its last resume's)."""
    from rlcore.runs import write_json

    record = json.loads(meta.read_text())
    record["timing"] = {"wall_seconds": round(wall, 3), "cpu_seconds": round(cpu, 3),
                        "from_step": int(record["resumes"][-1]["step"]) if record.get("resumes") else 0}
    write_json(meta, record)


def run_torchrun(cmd: list[str], env: dict[str, str]) -> None:
    """Run a torchrun job to its end; an interrupt of this process (Ctrl-C, a pool's or Ray's cancel) is passed
    to torchrun as SIGINT, which stops its workers (they checkpoint every update), and waited for, so that no
    worker is left behind."""
    job = subprocess.Popen(cmd, env=env)
    try:
        code = job.wait()
    except KeyboardInterrupt:
        job.send_signal(signal.SIGINT)
        job.wait()
        raise
    if code:
        raise subprocess.CalledProcessError(code, cmd)


CONTINUED = "continued.json"
"""Beside a seed that continues another run's: which run, and the step it started from."""

LOGS = ("config.json", "meta.json", "progress.csv", "eval.csv", "alpha.csv", CONTINUED)
"""What a seed's results folder holds besides ``policy.pt``: settings, provenance and the logs (SAC's temperature in
``alpha.csv``; for a seed that continues another run's, :data:`CONTINUED`)."""

SNAPSHOT = "snapshot.json"
"""In a results folder without ``policy.pt``: the seed is still training, and these are its logs so far."""

SNAPSHOT_POLICY = "snapshot-policy.pt"
"""Beside a :data:`SNAPSHOT`, where it was asked for: the policy of the seed's last checkpoint."""


def copy_logs(work_dir: Path, result_dir: Path) -> None:
    """Copy a run's small files (:data:`LOGS`) from its work folder to its results folder."""
    result_dir.mkdir(parents=True, exist_ok=True)
    for name in LOGS:
        if (work_dir / name).exists():
            shutil.copy2(work_dir / name, result_dir / name)


def snapshot_one(exp: str, spec: RunSpec, seed: int, results: Path | None = None, work: Path | None = None,
                 policy: bool = False) -> str:
    """Copy the logs of a seed that is still training to ``results`` with a :data:`SNAPSHOT` record, so that a
    page can show how far a run of many sessions has come; returns a status line. With ``policy``, also the policy
    of its last checkpoint (:data:`SNAPSHOT_POLICY`, its step in the record as ``policy_step``): what the policy
    does part of the way, e.g. at 1M steps of a longer budget.

    A snapshot holds no final ``policy.pt``: the seed still counts as missing, and when it finishes :func:`train_one`
    writes its final files over the snapshot and removes the record. Taking one while the seed trains is safe: the
    logs only grow, and their rows up to any step are what the resumed run writes again.
    """
    from rlcore.logger import read_csv
    from rlcore.provenance import run_metadata

    work_dir, result_dir = run_paths(exp, spec.name, seed, results or paths.results_dir(), work or paths.work_dir())
    where = f"{exp}/{spec.name}/seed-{seed}"
    if (result_dir / "policy.pt").exists():
        return f"{where}: finished, already in {result_dir}"
    progress = read_csv(work_dir / "progress.csv") if (work_dir / "progress.csv").exists() else {}
    if not len(progress.get("step", [])):
        return f"{where}: nothing to snapshot, no training episode in {work_dir} yet"
    if policy and not (work_dir / "checkpoint.pt").exists():
        return f"{where}: no checkpoint in {work_dir} yet to take a policy from; run it again without --policy"
    copy_logs(work_dir, result_dir)
    step = int(progress["step"][-1])
    record = {"step": step, "steps": spec.steps, "provenance": run_metadata()}
    if policy:
        record["policy_step"] = export_policy(work_dir / "checkpoint.pt", result_dir / SNAPSHOT_POLICY)
    else:  # a policy from an earlier snapshot would not match these logs
        (result_dir / SNAPSHOT_POLICY).unlink(missing_ok=True)
    (result_dir / SNAPSHOT).write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
    return (f"{where}: snapshot at step {step:,} of {spec.steps:,}"
            + (f", policy at step {record['policy_step']:,}" if policy else "") + f" -> {result_dir}")


def snapshot_experiment(name: str, only: list[str] | None = None, seeds: list[int] | None = None,
                        results: Path | None = None, work: Path | None = None, policy: bool = False,
                        take: Callable[..., list[str]] | None = None) -> list[str]:
    """:func:`snapshot_one` for every chosen seed of an experiment, here; or with ``take`` (another backend's, such as
    :func:`rlbook.cluster.ray_snapshots`, which the command line picks), ``take(name, picks, results, work, policy)``
    for the chosen ``(spec, seed)`` picks."""
    picks = [(spec, s) for spec in chosen_runs(name, only) for s in spec.seeds if seeds is None or s in seeds]
    results, work = results or paths.results_dir(), work or paths.work_dir()
    if take is not None:
        return take(name, picks, results, work, policy)
    return [snapshot_one(name, spec, s, results, work, policy) for spec, s in picks]


def train_all(name: str, tasks: list[tuple[RunSpec, int]], jobs: int | None, results: Path, work: Path,
              progress: bool = True) -> list[str]:
    """Train each ``(spec, seed)`` of ``tasks`` of experiment ``name`` with :func:`train_one`, ``jobs`` processes at a
    time (:func:`run_in_pool`; default 1), with a progress bar over runs; returns their status lines. The local
    backend of :func:`run_experiment`."""
    from tqdm import tqdm

    lines: list[str] = []
    jobs = jobs or 1
    with tqdm(total=len(tasks), desc=name, unit="run", disable=not progress) as bar:
        if jobs <= 1:
            for spec, s in tasks:
                lines.append(train_one(name, spec, s, results, work))
                bar.update(1)
        else:
            for line in run_in_pool(train_one, [(name, spec, s, results, work) for spec, s in tasks], jobs):
                lines.append(line)
                bar.update(1)
    return lines


def run_in_pool(fn: Callable[..., Any], calls: list[tuple], jobs: int):
    """Yield ``fn(*args)`` for each of ``calls``, ``jobs`` processes at a time, as each finishes.

    A call is handed to a worker only when one is free, so that when one fails, or the run is interrupted, no
    further call starts: the error is raised once the calls already running have returned. (Submitting
    everything at once would queue calls that a pool runs even after an interrupt.) An interrupt of this
    process (Ctrl-C, or SIGTERM with :func:`rlcore.signals.stop_on_signals`) is passed on to the workers as SIGINT:
    each running ``train`` saves a checkpoint and stops, instead of training on to the end of its seed.
    """
    from rlcore.signals import stop_on_signals

    # spawn, not fork: safe from a Jupyter kernel, whose threads a fork would copy half-way
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=stop_on_signals, initargs=(True,)) as pool:
        yield from schedule(pool, fn, calls, jobs)


def schedule(pool: Any, fn: Callable[..., Any], calls: list[tuple], jobs: int):
    """:func:`run_in_pool`'s rule, for any executor: at most ``jobs`` calls running, a new one submitted only when
    one has finished, and none after a failure or an interrupt (which is passed on to the pool's workers)."""
    todo = list(calls)
    running = {pool.submit(fn, *todo.pop(0)) for _ in range(min(jobs, len(todo)))}
    try:
        while running:
            done, running = wait(running, return_when=FIRST_COMPLETED)
            # every call that finished is looked at before any new one starts: a failure among them raises
            # here, nothing new is submitted, and the executor waits for the calls still running
            results = [fut.result() for fut in done]
            for result in results:
                if todo:
                    running.add(pool.submit(fn, *todo.pop(0)))
                yield result
    except (KeyboardInterrupt, GeneratorExit):  # interrupted, or the caller stopped asking for results
        for child in multiprocessing.active_children():  # the pool's workers
            os.kill(child.pid, signal.SIGINT)
        raise


def chosen_runs(name: str, only: list[str] | None = None) -> list[RunSpec]:
    """The runs of experiment ``name`` that ``--only`` names (all without it); an unknown name is an error."""
    exp = get_experiment(name)
    names = [spec.name for spec in exp.runs]
    unknown = sorted(set(only or ()) - set(names))
    if unknown:
        raise ValueError(f"{name} has no run {', '.join(map(repr, unknown))}; its runs: {', '.join(names)}.")
    return [spec for spec in exp.runs if not only or spec.name in only]


def chosen_tasks(name: str, only: list[str] | None = None, seeds: list[int] | None = None) -> list[tuple[RunSpec, int]]:
    """The ``(spec, seed)`` pairs that ``--only`` and ``--seeds`` choose (all without them); none is an error."""
    chosen = chosen_runs(name, only)
    tasks = [(spec, s) for spec in chosen for s in spec.seeds if seeds is None or s in seeds]
    if not tasks:
        known = sorted({s for spec in chosen for s in spec.seeds})
        raise ValueError(f"{name} has no seed {seeds} in the runs chosen; their seeds: {known}.")
    return tasks


def run_experiment(name: str, jobs: int | None = None, only: list[str] | None = None, seeds: list[int] | None = None,
                   results: Path | None = None, work: Path | None = None, progress: bool = True,
                   train: Callable[..., list[str]] = train_all) -> list[str]:
    """Train every missing (run, seed) of an experiment, ``jobs`` processes at a time (default 1), in ``work`` with
    the small outputs copied to ``results`` (default: the book's ``runs/`` and ``results/``, :mod:`rlbook.paths`).

    ``train(name, tasks, jobs, results, work, progress)`` trains the chosen ``(spec, seed)`` tasks: this machine's
    processes (:func:`train_all`), or another backend that the command line picks, such as a Ray cluster's
    (:func:`rlbook.cluster.ray_backend`, which uses this module; this module never imports it)."""
    tasks = chosen_tasks(name, only, seeds)
    from rlcore.provenance import dirty_warning

    if warning := dirty_warning():  # the runs record what was uncommitted; a clean tree needs no record
        print(warning, file=sys.stderr)
    results, work = results or paths.results_dir(), work or paths.work_dir()
    return train(name, tasks, jobs, results, work, progress)
