"""The training harness: everything around an algorithm's loop, written once.

Every ``train`` in rlcore builds its networks from its ``Config``, hands them to a :class:`Run`, and then runs
its loop, which reads like the algorithm box in its module's docstring. The :class:`Run` owns the rest:

- the run folder (``config.json``, ``meta.json``, the CSV logs) and the check that a folder being resumed
  holds the same run (:func:`rlcore.runs.open_run`);
- what a checkpoint saves and a resume restores, registered once by the algorithm: :meth:`Run.restores` lists
  what a resume puts back (networks, optimizers, replay memories, random generators, normalizer statistics),
  :meth:`Run.records` what a checkpoint only says (the spaces a saved policy is rebuilt for);
- the progress bar, the per-episode log, periodic evaluation of the deterministic policy (:class:`Evaluation`),
  periodic checkpoints, a checkpoint at the end, and one on Ctrl-C or SIGTERM
  (see :func:`rlcore.signals.stop_on_signals`), which stop the loop between two steps, not in the middle of one;
- the episode in progress (:meth:`Run.resume_episode`): a checkpoint taken between two steps holds it, and a run
  resumed from it goes on with that episode, so that it is the uninterrupted run.

A loop tells the run where it is with :meth:`Run.record_episode` (an episode ended) and :meth:`Run.step_done`
(the step counter moved on; here is the observation to act on next); the run decides what is due. A typical
``train``::

    run = Run("ddpg", env_id, config, steps, seed, out, progress, evaluation=Evaluation(...), close=(env, eval_env))
    run.restores(actor=actor, critic=critic, actor_opt=actor_opt, rng=rng, torch_rng=torch_rng())
    run.records(spaces=spaces)
    step, episode = run.resume(step=0, episode=0)
    obs = run.resume_episode(env, reset_seed=seed)
    with run:                      # progress bar; checkpoint at the end, or on Ctrl-C
        while step < steps:
            ...                    # the algorithm
            run.step_done(step, step - 1, obs, episode=episode)
    return Result(..., run.episode_returns, run.eval_steps, ...)
"""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from rlcore.checkpoint import (Saved, load_checkpoint, load_running_stats, running_stats_state,  # noqa: F401
                               save_checkpoint)
from rlcore.envs import episode_state, restore_episode
from rlcore.logger import CSVLogger
from rlcore.config import config_dict
from rlcore.runs import RunDir, open_run
from rlcore.signals import signals_held

EPISODE_COLUMNS = ["episode", "step", "episode_return", "episode_length"]
"""The columns of ``progress.csv`` for an algorithm that logs one row per episode (before its own ones)."""
EVAL_COLUMNS = ["step", "mean_return", "std_return", "episodes"]
"""The columns of ``eval.csv`` (before an algorithm's own ones)."""


def saved_entries(key: str, value: Any) -> dict[str, Any]:
    """What a checkpoint holds of one restored object (see :meth:`Run.restores`), by checkpoint key."""
    if isinstance(value, Saved):
        return value.save()
    if isinstance(value, np.random.Generator):
        return {key: value.bit_generator.state}
    return {key: value.state_dict()}


def torch_rng() -> Saved:
    """torch's global random generator, under ``torch_rng``."""
    return Saved(lambda: {"torch_rng": torch.get_rng_state()}, lambda c: torch.set_rng_state(c["torch_rng"]))


def running_stats(rms: Any, prefix: str, loaded: Callable[[], None] | None = None) -> Saved:
    """A Gymnasium ``RunningMeanStd`` under ``{prefix}_mean``, ``{prefix}_var``, ``{prefix}_count``; with no
    statistics (``rms`` None), ``{prefix}_mean`` and ``{prefix}_var`` are None, as a saved policy expects.
    ``loaded`` is called after a restore (a cache built on the statistics, say)."""
    def save() -> dict[str, Any]:
        return {f"{prefix}_mean": None, f"{prefix}_var": None} if rms is None else running_stats_state(rms, prefix)

    def load(ckpt: dict[str, Any]) -> None:
        if rms is not None:
            load_running_stats(rms, ckpt, prefix)
            if loaded is not None:
                loaded()

    return Saved(save, load)


def crossed(every: int, now: int, before: int) -> bool:
    """Whether a counter that went from ``before`` to ``now`` passed a multiple of ``every`` (never if 0)."""
    return bool(every) and now // every > before // every


def learning_starts_on_resume(step: int, memory: Any, learning_starts: int) -> int:
    """The step from which a replay-memory run that has just resumed at ``step`` learns: ``learning_starts``, as
    ever, unless it resumed without its memory (``replay_in_checkpoint=False``: ``memory`` is empty past step 0).
    Then it acts as it would have, without learning, for ``learning_starts`` more steps to fill the memory again,
    so that its first minibatches are not drawn from a handful of transitions; one line on stderr says so."""
    if step == 0 or len(memory) > 0 or learning_starts == 0:
        return learning_starts
    until = step + learning_starts
    tqdm.write(f"resumed at step {step:,} without the replay memory (replay_in_checkpoint=False): refilling it for "
               f"{learning_starts:,} steps, learning again from step {until:,}", file=sys.stderr)
    return until


@dataclass
class Evaluation:
    """How a run evaluates its deterministic policy: ``evaluate()`` returns one row of ``eval.csv`` (without
    ``step``), with ``columns``; it runs every ``config.eval_every`` steps, and at the end of the run too with
    ``at_end``."""

    evaluate: Callable[[], dict[str, float]]
    columns: list[str] = field(default_factory=lambda: list(EVAL_COLUMNS))
    at_end: bool = False
    keep_best: tuple[str, ...] = ()
    """The checkpoint keys of the policy (its algorithm's ``POLICY_KEYS``): the run keeps the best-evaluated policy
    so far in ``policy_best.pt``, beside the last one in ``checkpoint.pt`` (none where empty)."""


@dataclass
class Workers:
    """A data-parallel worker's run (DPPO): ``opened`` is the ``(run folder, checkpoint)`` rank 0 opened (None, None
    on the other ranks); a checkpoint is written every ``checkpoint_every`` iterations, none on an interrupt, and an
    interrupt stops a worker at once (the workers must stop together)."""

    opened: tuple[RunDir | None, dict[str, Any] | None]
    checkpoint_every: int


class Run:
    """One training run's folder, checkpoints, logs, progress bar and evaluations (see the module docstring).

    ``algo``, ``env_id``, ``config``, ``steps``, ``seed``, ``out`` and ``progress`` are ``train``'s; ``desc`` labels
    the progress bar (default: ``DDPG Hopper-v5``, say). ``target``: the step count at which the run is complete
    (default ``steps``; on-policy algorithms round it up to whole iterations). ``schedules``: what the budget
    shapes, so that a resume must keep it (see :func:`rlcore.runs.open_run`); ``meta``: extra fields for
    ``meta.json``. ``episode_log``: the columns of the per-episode ``progress.csv`` (None: no per-episode log);
    ``logs``: other CSV logs, file stem to columns. ``evaluation``: how the run evaluates (:class:`Evaluation`; none
    without it). ``close``: environments to close at the end. ``workers``: a data-parallel worker's run
    (:class:`Workers`).

    Inside ``with run``, a SIGINT or SIGTERM that would interrupt the process stops the loop at the end of its
    current step (:meth:`step_done`) instead of wherever it is, so that the checkpoint it writes is one between two
    steps; a second one stops at once and writes no checkpoint (the state may be half a step ahead of the counters;
    the last checkpoint stays). A signal that comes while a checkpoint is written waits for the write to end.
    """

    def __init__(self, algo: str, env_id: str, config: Any, steps: int, seed: int, out: str | os.PathLike | None = None,
                 progress: bool = False, *, desc: str | None = None, target: int | None = None,
                 schedules: str | None = None,
                 meta: dict[str, Any] | None = None, episode_log: list[str] | None = EPISODE_COLUMNS,
                 logs: dict[str, list[str]] | None = None, evaluation: Evaluation | None = None, close: tuple = (),
                 workers: Workers | None = None):
        self.algo, self.env_id, self.config, self.steps, self.seed = algo, env_id, config, steps, seed
        self.target = steps if target is None else target
        self.desc = desc or f"{algo.upper()} {env_id}"
        self.progress, self.evaluation = progress, evaluation
        self.eval_every = getattr(config, "eval_every", 0) if evaluation is not None else 0
        self.workers = workers
        self.checkpoint_on = "step" if workers is None else "iteration"
        self.checkpoint_every = config.checkpoint_every if workers is None else workers.checkpoint_every
        self.to_close = close
        opened = workers.opened if workers is not None else \
            open_run(out, algo, env_id, seed, steps, config, schedules=schedules, **(meta or {}))
        self.folder, self.ckpt = opened
        """The checkpoint being resumed, until :meth:`resume` has restored it (then None)."""
        self._resumed: dict[str, Any] | None = None
        self.restored: dict[str, Any] = {}
        self.recorded: dict[str, Any] = {}
        self.counters: dict[str, Any] = {}
        self.episode = 0
        """Episodes ended so far, over every resume (the ``episode`` column of the per-episode log)."""
        self.returns: list[float] = []
        self.lengths: list[int] = []
        self.end_steps: list[int] = []
        self.evals: list[dict[str, float]] = []
        self.best_return = -math.inf
        """The best evaluation's mean return so far (the one ``policy_best.pt`` holds)."""
        self._saved_at: dict[str, Any] | None = None
        self._episode_env: Any = None
        self._obs: Any = None
        self._stop_requested = False
        self._stopped_between_steps = False
        self._handlers: dict[int, Any] = {}
        self.bar: tqdm | None = None
        self.episode_log = "progress" if episode_log else None
        wanted = {**({"progress": episode_log} if episode_log else {}), **(logs or {})}
        if evaluation is not None:
            wanted["eval"] = evaluation.columns
        self.logs = {} if self.folder is None else \
            {name: CSVLogger(self.folder.root / f"{name}.csv", cols) for name, cols in wanted.items()}

    # --- what a checkpoint holds -----------------------------------------------------------------

    def restores(self, **state: Any) -> None:
        """Register what a checkpoint saves and a resume puts back, by checkpoint key: a module, an optimizer, a
        replay memory (anything with ``state_dict``/``load_state_dict``), a NumPy generator (its bit generator's
        state), or a :class:`Saved` pair (the key is only a label). None is skipped (a memory left out of
        checkpoints)."""
        for key, value in state.items():
            if value is None:
                continue
            if not (hasattr(value, "state_dict") or isinstance(value, (np.random.Generator, Saved))):
                raise TypeError(f"a resume cannot restore {key!r}, a {type(value).__name__}: pass what it only "
                                "records (the spaces, say) to Run.records")
            self.restored[key] = value

    def records(self, **facts: Any) -> None:
        """Register what a checkpoint also holds but a resume does not restore: what a policy loaded from it needs
        to know (the observation and action spaces, say), by checkpoint key."""
        self.recorded.update(facts)

    def resume(self, **counters: Any) -> Any:
        """Restore everything registered with :meth:`restores` from the checkpoint being resumed (if any) and return
        the counters (``step=0, episode=0``, say) as the checkpoint has them, or as given. A checkpoint that lacks
        one (a replay memory) cannot resume the run: ValueError, in one line. Once restored, the loaded checkpoint
        is let go (a resumed run would otherwise hold its replay memory twice); :meth:`resume_episode` keeps
        what it needs."""
        ckpt, self.ckpt = self.ckpt, None
        if ckpt is not None:
            self._check_complete(ckpt)
            for key, value in self.restored.items():
                if isinstance(value, Saved):
                    value.load(ckpt)
                elif isinstance(value, np.random.Generator):
                    value.bit_generator.state = ckpt[key]
                else:
                    value.load_state_dict(ckpt[key])
            counters = {k: type(v)(ckpt[k]) for k, v in counters.items()}
            self.episode = int(ckpt.get("episode", 0))
            # what resume_episode reads: the episode in progress and the Saved pairs' entries (small), not the
            # networks, optimizers and replay memories just restored
            restored = {k for k, v in self.restored.items() if not isinstance(v, Saved)}
            self._resumed = {k: v for k, v in ckpt.items() if k not in restored}
        self.counters = dict(counters)
        self.best_return = self._best_so_far()
        values = tuple(counters.values())
        return values[0] if len(values) == 1 else values

    def _best_so_far(self) -> float:
        """The mean return of the evaluation ``policy_best.pt`` holds, where it is one this run has made by its current
        step (-inf otherwise: one from past the checkpoint is deleted, its evaluation will be made again)."""
        path = None if self.folder is None else self.folder.best_policy
        if path is None or not path.exists():
            return -math.inf
        best = load_checkpoint(path)["evaluation"]
        if best["step"] > self.counters.get("step", 0):
            path.unlink()
            return -math.inf
        return float(best["mean_return"])

    def _check_complete(self, ckpt: dict[str, Any]) -> None:
        """ValueError (one line) if ``ckpt`` lacks a restored key, or an entry a Saved pair restores."""
        missing = [k for k, v in self.restored.items() if not isinstance(v, Saved) and k not in ckpt]
        for value in self.restored.values():
            if isinstance(value, Saved):
                missing += [k for k in value.save() if k not in ckpt]
        if missing:
            where = self.folder.root if self.folder is not None else "the checkpoint"
            raise ValueError(f"{where} holds a checkpoint without {', '.join(map(repr, missing))}, which this run "
                             "needs to resume exactly; train it in another --out folder, or delete this one.")

    def resume_episode(self, env: Any, reset_seed: int) -> Any:
        """The observation the loop acts on first: the checkpoint's episode in progress, put back into ``env``
        (:func:`rlcore.envs.restore_episode`), or where there is none, or it cannot be, a new episode
        (``env.reset(seed=reset_seed)``). From now on a checkpoint taken between two steps holds ``env``'s episode
        in progress and the observation the loop last passed to :meth:`step_done`, the one it is about to act on.
        What the reset changed in the restored statistics (a normalizer wrapper counts the first observation) goes
        back as the checkpoint has it."""
        obs, _ = env.reset(seed=reset_seed)
        self._episode_env = env
        resumed, self._resumed = self._resumed, None
        saved = None if resumed is None else resumed.get("episode_env")
        if saved is not None and restore_episode(env, saved):
            for value in self.restored.values():
                if isinstance(value, Saved):
                    value.load(resumed)
            obs = np.asarray(saved["obs"]).copy()
        self._obs = obs
        return obs

    def state(self, episode: bool = True) -> dict[str, Any]:
        """The checkpoint's contents now; with ``episode``, the episode in progress too (between two steps only:
        elsewhere the simulator may be a step ahead of the observation)."""
        state = {**self.about(), **self.recorded}
        for key, value in self.restored.items():
            state.update(saved_entries(key, value))
        if episode and self._episode_env is not None:
            ongoing = episode_state(self._episode_env)
            if ongoing is not None:
                state["episode_env"] = {**ongoing, "obs": np.array(self._obs)}
        return state

    def about(self) -> dict[str, Any]:
        """What every checkpoint says about its run: algorithm, task, seed, settings, budget and counters (the
        :data:`rlcore.checkpoint.META_KEYS`)."""
        return {"algo": self.algo, "env_id": self.env_id, "seed": self.seed, "config": config_dict(self.config),
                "total_steps": self.steps, "complete": self.counters.get("step", 0) >= self.target,
                "episode": self.episode, **self.counters}

    def policy_state(self, keys: tuple[str, ...]) -> dict[str, Any]:
        """The entries under ``keys`` that a checkpoint now would hold (a policy's: no optimizer, no memory), with
        :meth:`about`."""
        state = {**self.about(), **{k: v for k, v in self.recorded.items() if k in keys}}
        for key, value in self.restored.items():
            if key in keys or isinstance(value, Saved):
                state.update({k: v for k, v in saved_entries(key, value).items() if k in keys})
        return state

    def checkpoint(self, episode: bool = True) -> None:
        """Write ``checkpoint.pt`` (atomically) if the run has a folder; ``episode``: see :meth:`state`. A SIGINT or
        SIGTERM that comes while it is written waits for the write to end (:func:`rlcore.signals.signals_held`)."""
        if self.folder is None:
            return
        with signals_held():
            save_checkpoint(self.folder.checkpoint, self.state(episode))
            self._saved_at = dict(self.counters)

    # --- what the loop reports -------------------------------------------------------------------

    def record_episode(self, step: int, episode_return: float, length: int, **columns: Any) -> None:
        """An episode ended at ``step``: keep its return, log it (``episode`` counts from 1), show it."""
        self.episode += 1
        if "episode" in self.counters:
            self.counters["episode"] = self.episode
        self.returns.append(float(episode_return))
        self.lengths.append(int(length))
        self.end_steps.append(int(step))
        if self.episode_log is not None:
            self.log(self.episode_log, episode=self.episode, step=step,
                     episode_return=episode_return, episode_length=length, **columns)
        if self.bar is not None:
            self.bar.set_postfix(ret=f"{np.mean(self.returns[-10:]):.1f}", refresh=False)

    def log(self, name: str, **row: Any) -> None:
        """A row of the run's ``{name}.csv`` (nothing without a run folder)."""
        if name in self.logs:
            self.logs[name].log(**row)

    def step_done(self, step: int, before: int, obs: Any = None, **counters: Any) -> None:
        """The loop moved from ``before`` to ``step`` environment steps (and its other counters to ``counters``), and
        acts next on ``obs`` (what a checkpoint of the episode in progress holds): evaluate if an evaluation step was
        passed, checkpoint if a checkpoint step was passed, move the bar."""
        previous = before if self.checkpoint_on == "step" else self.counters.get(self.checkpoint_on, 0)
        self.counters.update(step=step, **counters)
        self._obs = obs
        at_end = self.evaluation is not None and self.evaluation.at_end and step >= self.target
        if crossed(self.eval_every, step, before) or (at_end and self.eval_every):
            self.evaluate_now(step)
        if crossed(self.checkpoint_every, self.counters[self.checkpoint_on], previous):
            self.checkpoint()
        if self.bar is not None:
            self.bar.update(step - before)
        if self._stop_requested:  # a deferred Ctrl-C or SIGTERM: stop here, between two steps
            self._stopped_between_steps = True
            raise KeyboardInterrupt

    def evaluate_now(self, step: int) -> dict[str, float]:
        """Evaluate now: a row of ``eval.csv``."""
        row = {"step": step, **self.evaluation.evaluate()}
        self.evals.append(row)
        self.log("eval", **row)
        if self.evaluation.keep_best and self.folder is not None and row["mean_return"] > self.best_return:
            self.keep_best(row)
        return row

    def keep_best(self, row: dict[str, float]) -> None:
        """Write the policy just evaluated to ``policy_best.pt`` (atomically), with its evaluation ``row``."""
        self.best_return = float(row["mean_return"])
        with signals_held():
            save_checkpoint(self.folder.best_policy,
                            {**self.policy_state(self.evaluation.keep_best), "evaluation": dict(row)})

    # --- the run's lifetime ----------------------------------------------------------------------

    def __enter__(self) -> Run:
        start = min(self.counters.get("step", 0), self.target)
        self.bar = tqdm(total=self.target, initial=start, disable=not self.progress, unit="step", desc=self.desc)
        if self.workers is None:
            self._defer_signals()
        return self

    def _defer_signals(self) -> None:
        """Turn SIGINT and SIGTERM, where they would raise KeyboardInterrupt (a Python handler), into a request
        that :meth:`step_done` honours; an ignored or default-handled signal is left as it is. Only the main
        thread can set handlers: elsewhere interrupts stay immediate."""
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous = signal.getsignal(sig)
            if callable(previous):
                self._handlers[sig] = previous
                signal.signal(sig, self._request_stop)

    def _request_stop(self, signum: int, frame: Any) -> None:
        if self._stop_requested:  # a second one: stop now, in the middle of the step
            raise KeyboardInterrupt
        self._stop_requested = True
        tqdm.write(f"{signal.Signals(signum).name}: stopping at the end of this step, with a checkpoint "
                   "(again to stop at once, keeping the last checkpoint)")

    def __exit__(self, kind: type | None, exc: BaseException | None, tb: Any) -> None:
        try:
            # at the end, or stopped between two steps: a checkpoint, unless the last one is of this step. A second
            # Ctrl-C in the middle of a step writes nothing: the networks and memories may be half a step ahead of
            # the counters, and the last checkpoint stays (so do a data-parallel worker's, stopped anywhere)
            between_steps = kind is None or (self._stopped_between_steps and self.workers is None)
            if between_steps and self._saved_at != self.counters:
                self.checkpoint()
        finally:
            for sig, handler in self._handlers.items():
                signal.signal(sig, handler)
            self._handlers.clear()
            if self.bar is not None:
                self.bar.close()
            for env in self.to_close:
                if env is not None:
                    env.close()
            for log in self.logs.values():
                log.close()
        if kind is None and self._stop_requested:  # the signal came as the loop ended: the caller stops too
            raise KeyboardInterrupt

    # --- what train returns ------------------------------------------------------------------------

    @property
    def episode_returns(self) -> np.ndarray:
        return np.array(self.returns)

    @property
    def episode_lengths(self) -> np.ndarray:
        return np.array(self.lengths, dtype=int)

    @property
    def episode_end_steps(self) -> np.ndarray:
        return np.array(self.end_steps, dtype=int)

    @property
    def eval_steps(self) -> np.ndarray:
        return self.eval_column("step").astype(int)

    @property
    def eval_returns(self) -> np.ndarray:
        return self.eval_column("mean_return")

    def eval_column(self, name: str) -> np.ndarray:
        return np.array([row[name] for row in self.evals])


def evaluation(policy: Any, env: Any, episodes: int, seed: int) -> dict[str, float]:
    """A row of ``eval.csv``: the mean and standard deviation of ``episodes`` returns of ``policy``."""
    from rlcore.evaluate import evaluate_policy

    returns = evaluate_policy(policy, env, episodes, seed=seed)
    return {"mean_return": float(returns.mean()), "std_return": float(returns.std()), "episodes": len(returns)}
