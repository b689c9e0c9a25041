"""Synchronous data-parallel PPO ("DPPO") on ``torch.distributed``: N workers, one PPO.

Every worker (one process per rank) steps its own environments, computes GAE on its own rollout and runs
PPO's minibatch updates (:func:`rlcore.ppo.ppo_update`, the same code as :func:`rlcore.ppo.train`) on it;
the actor-critic is wrapped in ``DistributedDataParallel``, so every minibatch's gradient is averaged over
the workers (gloo, on the CPU) before the optimizer step, and all workers hold the same weights throughout.
After each rollout the workers merge their observation (and return) normalization statistics, and the
adaptive-KL coefficient reads the KL averaged over the workers: the workers, and the saved policy, agree.

``--set share=rollouts`` exchanges data instead of gradients: once per update the workers all-gather their
rollouts and each takes the same minibatch steps on all of them, with no communication per gradient step
(:attr:`Config.share`). The learning is the same in distribution; the communication is one message per
update instead of one per minibatch, paid for by computing every gradient step on every worker.

The loop of every worker, in lockstep with the others (:func:`_train`)::

    for each update:
        run the policy in this worker's num_envs environments for n_steps steps
        merge the observation and return statistics of all workers
        GAE(lambda) advantages on this worker's rollout
        for n_epochs epochs, over minibatches (the same number on every worker):
            one Adam step on the PPO loss, its gradient averaged over the workers
        (kl) adapt beta from the KL averaged over the workers

One machine, 2 workers (``--steps`` is the total over all workers)::

    torchrun --nproc_per_node 2 -m rlcore.dppo --env HalfCheetah-v5 --steps 1000000 --out runs/dppo-hc

Several machines (run the same line on each; the run folder lives on rank 0's machine, ``--out`` is
only written there)::

    torchrun --nnodes 2 --nproc_per_node 8 --rdzv-backend c10d --rdzv-endpoint HOST0:29400 --rdzv-id hc1 \\
        --max-restarts 3 -m rlcore.dppo --env HalfCheetah-v5 --steps 10000000 --out runs/dppo-hc
    # or a static rendezvous: --nnodes 2 --node_rank 0|1 --master_addr HOST0 --master_port 29500

Without torchrun (no ``RANK``/``WORLD_SIZE`` in the environment), ``python -m rlcore.dppo ...`` trains
with a single worker; one worker draws the same random numbers as :func:`rlcore.ppo.train` and
computes the same run.

What each worker does with the seed: worker r's environments are seeded ``seed + 1000 r`` (copy i:
``seed + 1000 r + i``; keep ``num_envs`` below 1000), its minibatch shuffling ``seed + 1000 r``, its action
sampling ``seed`` on rank 0 (continuing the weight-initialization stream, as ppo does) and ``seed + 1000 r``
on the others. A resumed run reseeds every worker from ``(seed, rank, iteration)``. ``num_envs``,
``n_steps`` and ``batch_size`` are per worker: an update learns from ``world_size * num_envs * n_steps``
transitions, in minibatches of ``world_size * batch_size``.

Rank 0 writes the run folder (:func:`rlcore.runs.open_run`): ``progress.csv`` (one row per update, with
env-steps per second), ``eval.csv`` and ``checkpoint.pt`` every ``checkpoint_updates`` updates (default:
every update). The checkpoint is a ``ppo`` checkpoint, so ``python -m rlcore evaluate|render DIR`` and
:func:`rlcore.ppo.load_policy` read it; its ``distributed`` entry marks it as DPPO's.

When a worker dies (killed, out of memory, a lost machine), torchrun stops the others; with
``--max-restarts K`` it then starts all workers again (up to K times), they rendezvous, rank 0 reads the
checkpoint and hands it to every worker, and training resumes from the last completed update (at most
``checkpoint_updates`` updates are redone; the logs drop the rows written after the checkpoint). Without
restarts, run the same command again to resume. Environments are reset on resume, so a resumed run is not
bit-identical to an uninterrupted one. The number of workers may change between restarts (an elastic
``--nnodes 1:4``): the step budget, the learning-rate schedule and the statistics carry over.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from torch.nn.parallel import DistributedDataParallel

from rlcore import ppo
from rlcore.checkpoint import CheckpointError, save_checkpoint
from rlcore.config import check_budget, config_dict
from rlcore.distributed import (LAUNCH_HELP, broadcast_object, broadcast_weights, gather_rollouts,  # noqa: F401
                                init_distributed, merge_contributions, snapshot, stats_contribution,
                                sync_running_stats)
from rlcore.envs import make_env
from rlcore.harness import Evaluation, Run, Workers, evaluation, running_stats
from rlcore.launch import build_parser, launch_command  # noqa: F401 (python -m rlcore.dppo's command line)
from rlcore.onpolicy import (OBS_CLIP, Rollout, annealing, check_spaces, collect_rollout, deterministic_policy,
                             make_agent, make_envs, set_learning_rate, training_statistics)
from rlcore.ppo import load_policy  # noqa: F401 (what the command line loads a policy with)
from rlcore.ppo import ppo_update, rollout_batch
from rlcore.runs import open_run

ALGO = "ppo"
"""The checkpoint's ``algo``: DPPO's checkpoints are PPO's, plus a ``distributed`` entry."""
POLICY_KEYS = ppo.POLICY_KEYS
"""Checkpoint keys :func:`load_policy` needs: PPO's."""

PROGRESS_COLUMNS = ["iteration", "step", "episodes", "episode_return", "env_steps_per_second", "update_seconds",
                    "rollout_seconds", "policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction",
                    "kl_coef", "learning_rate", "world_size"]
"""``progress.csv``: one row per update, written by rank 0 (``episode_return``: the mean over the episodes
that ended during the update on any worker, empty if none; ``update_seconds``: rank 0's wall time of the
update, rollout to checkpoint; ``env_steps_per_second``: all workers' transitions over it)."""


@dataclass
class Config(ppo.Config):
    """PPO's :class:`rlcore.ppo.Config` (``num_envs``, ``n_steps``, ``batch_size`` per worker) plus DPPO's fields.

    PPO's step-based ``checkpoint_every`` is not used: DPPO checkpoints every ``checkpoint_updates`` updates.
    """

    checkpoint_updates: int = 1
    """Write checkpoint.pt every this many updates (and at the end); a restarted job redoes at most this many."""
    share: str = "gradients"
    """What the workers exchange. ``"gradients"``: every minibatch's gradient is averaged by
    ``DistributedDataParallel`` (one all-reduce per gradient step). ``"rollouts"``: the workers gather each
    other's rollouts once per update and every worker takes the same minibatch steps on all of them (one
    all-gather per update; rank 0's weights are broadcast after it). Both learn from minibatches of
    ``world_size * batch_size`` of all workers' transitions; the second computes every step on every worker."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.share not in SHARES:
            raise ValueError(f"share must be one of {SHARES}, got {self.share!r}")


SHARES = ("gradients", "rollouts")


def make_config(algo: str = "dppo", **overrides: Any) -> Config:
    return Config(**overrides)


# --- training -------------------------------------------------------------------------------------


def train(
    env_id: str,
    config: Config | None = None,
    steps: int = 1_000_000,
    seed: int = 0,
    out: str | Path | None = None,
    progress: bool = False,
    dump_params: str | Path | None = None,
    command: str | None = None,
) -> ppo.Result:
    """Train DPPO on this worker for (at least) ``steps`` environment steps over all workers, in whole updates.

    Call it on every rank (torchrun does, via ``python -m rlcore.dppo``); outside torchrun it is a one-worker
    run. ``out`` is rank 0's run folder (resumed if it holds a checkpoint). ``dump_params``: every rank writes
    its final weights, optimizer state, normalization statistics and KL coefficient to ``rank{r}.pt``
    there (to check that the workers agree). ``command``: how the job was launched, for ``meta.json``
    (default: this process's command line). Returns this worker's :class:`rlcore.ppo.Result`.
    """
    check_budget(steps, seed)
    config = config or Config()
    if not isinstance(config, Config):
        config = Config(**config_dict(config))
    made_group = init_distributed()
    try:
        return _train(env_id, config, steps, seed, out, progress, dump_params, command)
    finally:
        if made_group:
            dist.destroy_process_group()


def open_on_rank0(out, env_id: str, config: Config, steps: int, seed: int, meta: dict[str, Any]):
    """Rank 0 opens the run folder (:func:`rlcore.runs.open_run`) and hands its checkpoint, or its error, to every
    worker: ``(run folder or None, checkpoint or None)`` on each."""
    folder = ckpt = error = None
    if dist.get_rank() == 0:
        try:
            folder, ckpt = open_run(out, ALGO, env_id, seed, steps, config, schedules=annealing(config),
                                    data_parallel=True, **meta)
        except (ValueError, CheckpointError) as exc:
            error = str(exc)
    ckpt, error = broadcast_object((ckpt, error))
    if error is not None:
        raise ValueError(error)
    return folder, ckpt


def worker_streams(seed: int, rank: int, iteration: int, resumed: bool) -> tuple[np.random.Generator, int]:
    """This worker's minibatch-shuffling generator and environment reset seed; torch's generator is seeded too.

    A new run: ``seed + 1000 rank`` (rank 0 continues the initialization's torch stream, as ppo.train does, so
    that one worker is ppo.train). A resumed one: all three from ``(seed, rank, iteration)``."""
    worker_seed = seed + 1_000 * rank
    if not resumed:
        if rank:
            torch.manual_seed(worker_seed)
        return np.random.default_rng(worker_seed), worker_seed
    ss = np.random.SeedSequence([seed, rank, iteration])
    torch.manual_seed(int(ss.generate_state(1)[0]))
    return np.random.default_rng(ss), int(ss.generate_state(2)[1])


def distributed_update(model, agent, optimizer, buf: Rollout, config: Config, kl_coef: float,
                       rng: np.random.Generator, seed: int, iteration: int) -> tuple[np.ndarray, float]:
    """PPO's minibatch steps on this worker's rollout (the same number of them on every worker), either with the
    gradients averaged by DDP, or on all workers' rollouts, gathered, with the same shuffling everywhere."""
    batch = rollout_batch(buf, config)
    n_batches = torch.tensor(max(len(batch["obs"]) // config.batch_size, 1))
    dist.all_reduce(n_batches, op=dist.ReduceOp.MIN)
    if config.share == "gradients":
        return ppo_update(model, optimizer, batch, config, kl_coef, rng, int(n_batches))
    update_rng = np.random.default_rng([seed, iteration])
    stats, mean_kl = ppo_update(model, optimizer, gather_rollouts(batch), config, kl_coef, update_rng, int(n_batches))
    broadcast_weights(agent)  # identical already on identical machines; exact on mixed ones too
    return stats, mean_kl


def mean_over_workers(stats: np.ndarray, mean_kl: float, new_returns: list[float]) -> tuple[list[float], int, float]:
    """The workers' mean update statistics (:data:`rlcore.ppo.UPDATE_STATS`, then the KL the adaptive rule reads),
    and the number and mean return of the episodes that ended on any worker (NaN if none)."""
    summary = torch.tensor([*np.mean(stats, axis=0), mean_kl, sum(new_returns), len(new_returns)], dtype=torch.float64)
    dist.all_reduce(summary)
    episodes = int(summary[7])
    mean_return = float(summary[6]) / episodes if episodes else float("nan")
    return (summary[:6] / dist.get_world_size()).tolist(), episodes, mean_return


def dump_worker_state(folder, agent, optimizer, kl_coef: float, step: int, iteration: int, *stats) -> None:
    """(Testing) this worker's weights, optimizer, KL coefficient and statistics in ``folder/rank{r}.pt``."""
    state = {"agent": agent.state_dict(), "optimizer": optimizer.state_dict(), "kl_coef": kl_coef, "step": step,
             "iteration": iteration}
    for name, rms in zip(("obs", "ret"), stats):
        if rms is not None:
            state.update({f"{name}_mean": rms.mean, f"{name}_var": rms.var, f"{name}_count": float(rms.count)})
    save_checkpoint(Path(folder) / f"rank{dist.get_rank()}.pt", state)


def _train(env_id, config: Config, steps, seed, out, progress, dump_params, command) -> ppo.Result:
    rank, world = dist.get_rank(), dist.get_world_size()
    torch.manual_seed(seed)  # the same initial weights on every worker (DDP also broadcasts rank 0's)
    envs = make_envs(env_id, config, seed + 1_000 * rank)
    spaces = check_spaces(envs, env_id, "DPPO")
    agent = make_agent(spaces, config)
    optimizer = ppo.make_optimizer(agent, config)
    obs_rms, ret_rms = training_statistics(envs)
    eval_env = make_env(env_id, **config.env_kwargs) if rank == 0 and config.eval_every else None
    per_update = config.n_steps * config.num_envs * world
    target = -(-steps // per_update) * per_update
    distributed = {"world_size": world, "backend": dist.get_backend()}
    opened = open_on_rank0(out, env_id, config, steps, seed,
                           {"distributed": distributed, **({"command": command} if command else {})})
    evaluate = Evaluation(lambda: evaluation(deterministic_policy(agent, spaces, obs_rms), eval_env,
                                             config.eval_episodes, seed + 10_000), at_end=True,
                          keep_best=POLICY_KEYS)
    run = Run(ALGO, env_id, config, steps, seed, progress=progress and rank == 0, target=target,
              desc=f"DPPO-{config.objective} {env_id} x{world}", episode_log=None, logs={"progress": PROGRESS_COLUMNS},
              evaluation=evaluate if eval_env is not None else None, close=(envs, eval_env),
              workers=Workers(opened, config.checkpoint_updates))
    run.restores(agent=agent, optimizer=optimizer, obs=running_stats(obs_rms, "obs"), ret=running_stats(ret_rms, "ret"))
    run.records(spaces=spaces, obs_clip=OBS_CLIP, distributed=distributed)
    step, iteration, kl_coef = run.resume(step=0, iteration=0, kl_coef=config.kl_coef)
    rng, reset_seed = worker_streams(seed, rank, iteration, resumed=opened[1] is not None)
    del opened  # the checkpoint is restored: let it go
    model = DistributedDataParallel(agent) if config.share == "gradients" else agent
    normalizers = [rms for rms in (obs_rms, ret_rms) if rms is not None]
    bases = [snapshot(rms) for rms in normalizers]
    buf = Rollout(spaces, config.n_steps, config.num_envs)
    new_returns: list[float] = []

    def on_episode(t: int, episode_return: float, length: int) -> None:  # an episode ended at rollout step t
        run.record_episode(step + (t + 1) * config.num_envs * world, episode_return, length)
        new_returns.append(episode_return)

    obs, _ = envs.reset(seed=reset_seed)
    last = time.perf_counter()
    with run:
        while step < target:
            # [dppo-loop]
            lr = set_learning_rate(optimizer, config, step / target)
            # 1. every worker runs the policy in its own environments, then they merge their statistics
            obs = collect_rollout(agent, envs, obs, buf, on_episode)
            rollout_seconds = time.perf_counter() - last
            if world > 1:
                bases = [sync_running_stats(rms, base) for rms, base in zip(normalizers, bases)]
            step += per_update
            # 2. advantages; 3. the same number of minibatch steps on every worker, on everyone's data
            stats, mean_kl = distributed_update(model, agent, optimizer, buf, config, kl_coef, rng, seed, iteration)
            # the workers' means: the KL for beta's rule (so that beta stays the same everywhere), the logged numbers
            m, episodes, episode_return = mean_over_workers(stats, mean_kl, new_returns)
            new_returns.clear()
            if config.objective == "kl":
                kl_coef = ppo.adaptive_kl_coef(kl_coef, m[5], config.kl_target, config.kl_beta_low,
                                               config.kl_beta_high, config.kl_alpha)
            iteration += 1
            # [/dppo-loop]
            run.step_done(step, step - per_update, iteration=iteration, kl_coef=kl_coef)
            now = time.perf_counter()
            run.log("progress", iteration=iteration, step=step, episodes=episodes, episode_return=episode_return,
                    env_steps_per_second=per_update / (now - last), update_seconds=now - last,
                    rollout_seconds=rollout_seconds, policy_loss=m[0], value_loss=m[1], entropy=m[2], approx_kl=m[5],
                    clip_fraction=m[4], kl_coef=kl_coef, learning_rate=lr, world_size=world)
            last = time.perf_counter()
    if dump_params is not None:
        dump_worker_state(dump_params, agent, optimizer, kl_coef, step, iteration, obs_rms, ret_rms)
    return ppo.Result(agent, deterministic_policy(agent, spaces, obs_rms), run.episode_returns,
                      run.episode_end_steps, run.eval_steps, run.eval_returns, step)


# --- command line ---------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    from rlcore.cli import EXIT_USAGE, overrides as overrides_of
    from rlcore.envs import UnknownEnvironmentError, check_env_id

    args = build_parser().parse_args(argv)
    torch.set_num_threads(max(args.threads, 1))
    if "RANK" not in os.environ:
        print(f"rlcore.dppo: not started by torchrun, so training with a single worker; for N workers, {LAUNCH_HELP}.",
              file=sys.stderr)
    try:
        check_env_id(args.env)
        overrides = overrides_of(Config, args.set or [])
        if args.env_kwargs is not None:
            overrides["env_kwargs"] = args.env_kwargs
        train(args.env, make_config(**overrides), steps=args.steps, seed=args.seed, out=args.out,
              progress=not args.no_progress, dump_params=args.dump_params, command=launch_command(argv))
    except (UnknownEnvironmentError, CheckpointError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if int(os.environ.get("RANK", 0)) == 0:
        print(f"Done: DPPO on {args.env}, {args.steps} steps, seed {args.seed} -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
