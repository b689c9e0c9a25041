"""Reading what the experiments wrote: a run's seeds from ``results/`` (or a short live stand-in), their
provenance for the page, and the status of an experiment's seeds.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import tempfile
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rlbook import paths
from rlbook.registry import RunSpec, get_experiment, run_paths, seed_folder
from rlbook.runner import SNAPSHOT, SNAPSHOT_POLICY, config_class, train_all
from rlcore.logger import read_csv


class TemporaryFolder:
    """A new temporary folder (``path``), removed with everything in it when this object is garbage-collected or
    the process ends, whichever comes first (quietly, unlike ``tempfile.TemporaryDirectory``)."""

    def __init__(self, prefix: str):
        self.path = Path(tempfile.mkdtemp(prefix=prefix))
        weakref.finalize(self, shutil.rmtree, self.path, ignore_errors=True)


@dataclass
class SeedResult:
    """One finished seed: its logs, its config and metadata, and (loaded on first use) its policy; or, with
    ``snapshot`` set, a seed still training: its logs so far (:func:`rlbook.runner.snapshot_one`)."""

    seed: int
    folder: Path
    progress: dict[str, np.ndarray]
    evals: dict[str, np.ndarray]
    config: dict[str, Any]
    meta: dict[str, Any]
    snapshot: dict[str, Any] | None = None
    """For a seed still training: the step its logs reach, its budget, and who took the snapshot when."""
    _policy: Any = field(default=None, repr=False)
    _keep: Any = field(default=None, repr=False, compare=False)
    """A live stand-in's :class:`TemporaryFolder`: the folder goes when the last seed holding it does."""

    @property
    def episode_end_steps(self) -> np.ndarray:
        return self.progress["step"]

    @property
    def episode_returns(self) -> np.ndarray:
        """Training episodes' returns (of the exploring behaviour policy)."""
        return self.progress["episode_return"]

    @property
    def policy_path(self) -> Path:
        """``policy.pt``; for a snapshot, the policy of the run's checkpoint at ``snapshot["policy_step"]``
        (``snapshot-policy.pt``, written by ``experiments snapshot --policy``)."""
        return self.folder / (SNAPSHOT_POLICY if self.snapshot else "policy.pt")

    @property
    def policy(self):
        """The final deterministic policy, from ``policy.pt`` (a snapshot's policy so far: :attr:`policy_path`)."""
        if self._policy is None:
            from rlcore.algos import get_algorithm
            from rlcore.checkpoint import load_checkpoint

            ckpt = load_checkpoint(self.policy_path)
            self._policy = get_algorithm(ckpt["algo"]).load_policy(ckpt)
        return self._policy


@dataclass
class RunResults:
    """The seeds of one configuration: from ``results/``, or from a short live stand-in (``source="live"``).

    ``in_progress`` holds the snapshots of missing seeds that are still training (each is also in ``missing``)."""

    spec: RunSpec
    seeds: list[SeedResult]
    missing: list[int]
    source: str = "results"
    in_progress: list[SeedResult] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def label(self) -> str:
        return self.spec.label or self.spec.name

    @property
    def steps(self) -> int:
        """Training steps per seed of what is shown (the live budget for a live stand-in)."""
        return self.spec.steps

    def finished(self, seed: int) -> SeedResult:
        """The finished seed ``seed`` (a seed in training is not one)."""
        for s in self.seeds:
            if s.seed == seed:
                return s
        raise KeyError(f"{self.name}: seed {seed} has not finished (finished: {[s.seed for s in self.seeds]})")


def _read_seed(seed: int, folder: Path, snapshot: dict[str, Any] | None = None) -> SeedResult:
    return SeedResult(
        seed, folder, read_csv(folder / "progress.csv"),
        read_csv(folder / "eval.csv") if (folder / "eval.csv").exists() else {},
        json.loads((folder / "config.json").read_text()), json.loads((folder / "meta.json").read_text()), snapshot,
    )


def _read_run(name: str, spec: RunSpec, results: Path) -> RunResults:
    found, missing, in_progress = [], [], []
    for s in spec.seeds:
        folder = seed_folder(results, name, spec.name, s)
        if (folder / "policy.pt").exists():
            found.append(_read_seed(s, folder))
            continue
        missing.append(s)
        if (folder / SNAPSHOT).exists():
            in_progress.append(_read_seed(s, folder, json.loads((folder / SNAPSHOT).read_text())))
    return RunResults(spec, found, missing, in_progress=in_progress)


def load_experiment(name: str, results: Path | None = None) -> dict[str, RunResults]:
    """Everything ``results`` (default: the book's ``results/``, :mod:`rlbook.paths`) holds for an experiment, with
    the seeds still missing listed per run."""
    results = paths.results_dir() if results is None else results
    return {spec.name: _read_run(name, spec, results) for spec in get_experiment(name).runs}


def load_or_train(name: str, run: str, fallback_steps: int, fallback_seeds: list[int], jobs: int = 2,
                  eval_points: int = 10, results: Path | None = None) -> RunResults:
    """Run ``run`` of experiment ``name`` from ``results/``; if it has no seed there, a short live stand-in.

    The stand-in has the same settings with ``fallback_steps`` steps per seed (evaluated ``eval_points``
    times), trains ``fallback_seeds`` in ``jobs`` processes into a temporary folder, and is returned
    with ``source="live"`` so that a page can say what it shows. The folder's run checkpoints are removed at once;
    its results (policies, logs) go when no seed of the stand-in is referenced any more, or when the process ends.
    """
    found = _read_run(name, next(r for r in get_experiment(name).runs if r.name == run),
                      paths.results_dir() if results is None else results)
    if found.seeds:
        return found
    spec = found.spec
    overrides = dict(spec.overrides)
    if "eval_every" in config_class(spec.algo).__dataclass_fields__:
        overrides["eval_every"] = max(fallback_steps // eval_points, 1)
    live = dataclasses.replace(spec, steps=fallback_steps, seeds=tuple(fallback_seeds), overrides=overrides)
    keep = TemporaryFolder(f"rlbook-live-{name}-")
    tmp = keep.path
    try:
        train_all(name, [(live, s) for s in live.seeds], jobs, tmp / "results", tmp / "runs", progress=False)
    finally:
        shutil.rmtree(tmp / "runs", ignore_errors=True)
    out = _read_run(name, live, tmp / "results")
    for seed in out.seeds:
        seed._keep = keep
    return RunResults(live, out.seeds, list(spec.seeds), source="live")


def provenance_markdown(name: str, run: RunResults, command: str | None = None) -> str:
    """What to print under a figure: which seeds, how many steps, made by which command, commit, versions, in a
    collapsed dropdown ("Provenance: <run>").

    A live stand-in, or seeds still missing from ``results/``, get a visible warning.
    """
    command = command or f"python -m rlbook experiments run {name} --jobs 2"
    full = next(r for r in get_experiment(name).runs if r.name == run.name)
    folder = f"results/{name}/{run.name}/"
    seeds = [s.seed for s in run.seeds]
    if run.source == "live":
        return (f":::{{warning}}\n**{run.label}**: `{folder}` holds none of its seeds {run.missing}, so this "
                f"page trained a short live run instead: seed(s) {seeds}, {run.steps:,} steps each (the full "
                f"budget is {full.steps:,}). Run `{command}` to fill in `results/`.\n:::\n")
    commits = sorted({s.meta.get("commit") or "unknown" for s in run.seeds})
    commits_text = ", ".join(commit_text(c) for c in commits)
    meta = run.seeds[0].meta if run.seeds else {}
    v = meta.get("versions", {})
    text = (f"*{run.label}*: `{folder}`, seeds {seeds} ({len(seeds)} of {len(full.seeds)}), {run.steps:,} steps "
            f"each; made by `{command}` at commit {commits_text}; Gymnasium {v.get('gymnasium')}, PyTorch "
            f"{v.get('torch')}, NumPy {v.get('numpy')}, Python {v.get('python')}, "
            f"{meta.get('machine', {}).get('cpus', '?')} CPUs.")
    resumes = [(s.seed, r) for s in run.seeds for r in s.meta.get("resumes", [])]
    if resumes:
        text += " Resumed from a checkpoint: " + "; ".join(
            f"seed {seed} at step {r['step']:,} ({r.get('machine', {}).get('cpus', '?')} CPUs, commit "
            f"{str(r.get('commit'))[:7]}, PyTorch {r.get('versions', {}).get('torch')})" for seed, r in resumes) + "."
    moved = [(s.seed, s.meta["checkout_at_start"]) for s in run.seeds if s.meta.get("checkout_at_start")]
    if moved:  # a long-lived process ran code it had loaded before the checkout moved on (see rlcore.provenance)
        text += " Trained by a process that had loaded its code earlier: " + "; ".join(
            f"seed {seed} (the checkout was already at {str(c)[:7]})" for seed, c in moved) + "."
    notes: dict[str, list[int]] = {}
    for s in run.seeds:
        if s.meta.get("provenance_note"):
            notes.setdefault(s.meta["provenance_note"], []).append(s.seed)
    text += "".join(f" Seed{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))}: {note}"
                    for note, seeds in notes.items())
    # the record a reader may want, folded under the figure; what a reader must see stays visible
    text = f"::::{{dropdown}} Provenance: {run.label}\n{text}\n::::\n"
    if run.missing:
        text += (f"\n:::{{warning}}\nSeeds {run.missing} of *{run.label}* are not in `{folder}` yet; this page "
                 f"shows the {len(seeds)} that are. Run `{command}` to finish them.\n:::\n")
    return text


def snapshot_markdown(name: str, run: RunResults) -> str:
    """What a page says of the seeds of ``run`` that are still training (``run.in_progress``): how far each has
    come and its last evaluation (visible), and who trained it and took the snapshot (folded)."""
    lines, prov = [], []
    for s in run.in_progress:
        snap = s.snapshot
        last = (f"; its last evaluation, at step {int(s.evals['step'][-1]):,}, returns "
                f"{float(s.evals['mean_return'][-1]):,.0f} (mean over {int(s.evals['episodes'][-1])} episodes of the "
                "deterministic policy)" if s.evals else "; it has not been evaluated yet")
        lines.append(f"Seed {s.seed} had not finished when its snapshot was taken: "
                     f"`results/{name}/{run.name}/seed-{s.seed}/` holds a "
                     f"snapshot of its logs at step {snap['step']:,} of {snap['steps']:,} "
                     f"({100 * snap['step'] / snap['steps']:.0f}%, taken {snap['provenance']['started'][:10]}){last}."
                     + (f" It holds the policy of its checkpoint at step {snap['policy_step']:,} too "
                        f"(`{SNAPSHOT_POLICY}`)." if "policy_step" in snap else ""))
        trained = [(s.meta.get("started", "?")[:10], s.meta.get("commit") or "unknown", 0)] + [
            (r.get("started", "?")[:10], r.get("commit") or "unknown", r["step"]) for r in s.meta.get("resumes", [])]
        v = s.meta.get("versions", {})
        prov.append(f"Seed {s.seed}: `{s.meta.get('command')}`, started at commit {commit_text(trained[0][1])} "
                    f"on {trained[0][0]}"
                    + "".join(f", resumed at step {step:,} at commit {commit_text(c)} on {day}"
                              for day, c, step in trained[1:])
                    + f" (PyTorch {v.get('torch')}, Gymnasium {v.get('gymnasium')}, "
                    f"{s.meta.get('machine', {}).get('torch_threads', '?')} torch thread(s)); snapshot by "
                    f"`{snap['provenance']['command']}` at commit "
                    f"{commit_text(snap['provenance'].get('commit') or 'unknown')}.")
    if not lines:
        return ""
    return ("\n\n".join(lines) + f"\n\n::::{{dropdown}} Provenance: {run.label}, in training\n"
            + " ".join(prov) + "\n::::\n")


def commit_text(commit: str) -> str:
    """A recorded commit as provenance prints it: its short hash, and whether the checkout had uncommitted changes."""
    return commit[:7] + (" (with uncommitted changes)" if commit.endswith("+dirty") else "")


def live_provenance_markdown(label: str, what: str, command: str | None = None) -> str:
    """The provenance of a run a page trained itself while the book was built, in a collapsed dropdown
    ("Provenance: <label>"): ``what`` it was (seed, steps, settings), the command line that repeats it, and the
    commit, versions and machine of the process that trained it (this one: :func:`rlcore.provenance.run_metadata`)."""
    from rlcore.provenance import run_metadata

    meta = run_metadata()
    v, commit = meta["versions"], meta.get("commit") or "unknown"
    text = (f"*{label}*: trained on this page while the book was built, not read from `results/`: {what}. "
            + (f"The same run from the command line: `{command}`. " if command else "")
            + f"Code at commit {commit_text(commit)}; "
            f"Gymnasium {v.get('gymnasium')}, PyTorch {v.get('torch')}, NumPy {v.get('numpy')}, "
            f"Python {v.get('python')}, {meta['machine'].get('cpus', '?')} CPUs.")
    return f"::::{{dropdown}} Provenance: {label}\n{text}\n::::\n"


def record_provenance_markdown(label: str, path: str, record: dict[str, Any], what: str) -> str:
    """The provenance of a derived record in ``results/`` (a comparison, a diagnostic) in a collapsed dropdown
    ("Provenance: <label>"): its file, the command that wrote it, the commit, time and versions of the process that
    did (``record["provenance"]``, :func:`rlcore.provenance.run_metadata`), and ``what`` it measures."""
    prov = record["provenance"]
    v = prov["versions"]
    return (f"::::{{dropdown}} Provenance: {label}\n"
            f"`{path}`, written by `{prov['command']}` at commit {commit_text(prov.get('commit') or 'unknown')} "
            f"({prov['started']}; Python {v.get('python')}, torch {v.get('torch')}, Gymnasium {v.get('gymnasium')}, "
            f"MuJoCo {v.get('mujoco')}, {prov['machine'].get('torch_threads', '?')} torch thread(s)). {what}\n::::\n")


def status_lines(name: str, results: Path | None = None, work: Path | None = None) -> list[str]:
    """One line per run: seeds finished in ``results``, and how far each unfinished one has trained in ``work``
    (default: the book's ``results/`` and ``runs/``, :mod:`rlbook.paths`)."""
    results, work = results or paths.results_dir(), work or paths.work_dir()
    lines = []
    for run, res in load_experiment(name, results).items():
        have = len(res.seeds)
        total = have + len(res.missing)
        lines.append(f"{name}/{run}: {have}/{total} seeds" + (f" (missing {res.missing})" if res.missing else ""))
        for seed in res.missing:
            folder, _ = run_paths(name, run, seed, results, work)
            progress = read_csv(folder / "progress.csv") if (folder / "progress.csv").exists() else {}
            if (folder / "checkpoint.pt").exists() and len(progress.get("step", [])):
                lines.append(f"  seed {seed}: trained to step {int(progress['step'][-1]):,} of {res.spec.steps:,} in "
                             f"{folder}; `experiments run` resumes it from its last checkpoint")
        for snap in res.in_progress:
            lines.append(f"  seed {snap.seed}: {snap.folder} holds a snapshot of its logs at step "
                         f"{snap.snapshot['step']:,} (taken {snap.snapshot['provenance']['started']})")
    return lines
