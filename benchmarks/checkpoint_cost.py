"""What a DDPG checkpoint with its replay memory costs on Humanoid-v5, against the learning steps between two.

    python benchmarks/checkpoint_cost.py --sizes 100000,500000,1000000

A DDPG checkpoint (``replay_in_checkpoint``, the default) holds the whole replay memory, so that a resumed run is
the uninterrupted one. On Humanoid-v5 a transition is two observations of 348 float32 numbers plus an action of 17:
about 2.9 KB, so a full memory of 1,000,000 transitions is about 2.9 GB in memory. A checkpoint stores each
observation once (``ReplayBuffer.state_dict``), about 1.5 GB, rewritten (atomically, with fsync) at every
periodic checkpoint. This measures, for memories of the given sizes filled with Humanoid-shaped transitions:
the file's size, the seconds :func:`rlcore.checkpoint.save_checkpoint` takes to write it (networks, optimizers
and memory, as DDPG's checkpoint holds them) and :func:`rlcore.checkpoint.load_checkpoint` to read it back; and,
in the same process, the seconds of one learning step of the modern settings (critic and actor update on a batch
of 256 through two 256-unit layers). The verdict is the ratio: a checkpoint costs as much as how many learning
steps, and what share of the run that is at ``checkpoint_every`` steps between checkpoints. Since a checkpoint
keeps ``next_obs`` only where it is not the next slot's observation (episode ends), the memory is filled in
episodes of ``--episode-length`` steps. Writes
``results/benchmarks/checkpoint-cost.json``; one torch thread.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import provenance, write_record  # noqa: E402

OBS_DIM, ACT_DIM = 348, 17           # Humanoid-v5


def learning_step_seconds(steps: int = 200, config=None) -> tuple[float, dict[str, object]]:
    """Median seconds of one DDPG learning step (critic, actor, both soft updates) with ``config`` (the modern
    settings, ``rlcore.ddpg.Config()``, if None) on Humanoid-shaped minibatches, and the networks and optimizers it
    trained (what a checkpoint saves besides the memory)."""
    from rlcore.ddpg import Config, make_networks, make_optimizers, update_actor, update_critic
    from rlcore.nets import soft_update

    config = Config() if config is None else config
    sp = {"obs_dim": OBS_DIM, "act_dim": ACT_DIM, "low": -0.4 * np.ones(ACT_DIM), "high": 0.4 * np.ones(ACT_DIM)}
    actor, critic, actor_t, critic_t = make_networks(sp, config)
    actor_opt, critic_opt = make_optimizers(actor, critic, config)
    b = config.batch_size
    obs, next_obs = torch.randn(b, OBS_DIM), torch.randn(b, OBS_DIM)
    act, rew, term = torch.rand(b, ACT_DIM) * 0.8 - 0.4, torch.randn(b), torch.zeros(b)
    times, per_round = [], max(steps // 5, 1)
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(per_round):
            update_critic(critic, critic_opt, actor_t, critic_t, obs, act, rew, next_obs, term, config.gamma)
            update_actor(actor, actor_opt, critic, obs)
            soft_update(actor_t, actor, config.tau)
            soft_update(critic_t, critic, config.tau)
        times.append((time.perf_counter() - start) / per_round)
    return float(np.median(times)), {"actor": actor, "critic": critic, "actor_opt": actor_opt, "critic_opt": critic_opt}


def checkpoint_seconds(size: int, nets: dict, folder: Path, episode_length: int) -> dict[str, float]:
    """Fill a memory of ``size`` Humanoid-shaped transitions in episodes of ``episode_length`` steps (at an end,
    the next observation is not the next slot's, as after a fall and a reset); time writing and reading the
    checkpoint."""
    from rlcore.buffers import ReplayBuffer
    from rlcore.checkpoint import load_checkpoint, save_checkpoint

    memory = ReplayBuffer(size, (OBS_DIM,), (ACT_DIM,), np.float32, seed=0)
    rng = np.random.default_rng(0)
    rows = rng.standard_normal((1_000, OBS_DIM)).astype(np.float32)
    for i in range(size):
        ended = (i + 1) % episode_length == 0
        next_obs = rows[(i + 500) % 1_000] if ended else rows[(i + 1) % 1_000]
        memory.add(rows[i % 1_000], rows[i % 1_000, :ACT_DIM], 1.0, next_obs, ended)
    payload = {name: value.state_dict() for name, value in nets.items()} | {"replay": memory.state_dict()}
    path = folder / "checkpoint.pt"
    start = time.perf_counter()
    save_checkpoint(path, payload)
    written = time.perf_counter() - start
    start = time.perf_counter()
    load_checkpoint(path)
    read = time.perf_counter() - start
    gigabytes = path.stat().st_size / 1e9
    path.unlink()
    return {"transitions": size, "gigabytes": gigabytes, "write_seconds": written, "read_seconds": read}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", default="100000,500000,1000000", help="replay memory sizes, comma-separated")
    p.add_argument("--checkpoint-every", type=int, default=25_000, help="steps between checkpoints, for the share")
    p.add_argument("--episode-length", type=int, default=100,
                   help="steps per episode in the filled memory (Humanoid's early episodes are shorter, good ones 1,000)")
    p.add_argument("--dir", default="runs", help="folder for the temporary checkpoint (the disk runs/ is on)")
    p.add_argument("--out", default="results/benchmarks/checkpoint-cost.json")
    args = p.parse_args()
    try:
        sizes = [int(s) for s in args.sizes.split(",")]
    except ValueError:
        raise SystemExit(f"--sizes takes comma-separated whole numbers, got {args.sizes!r}") from None
    torch.set_num_threads(1)
    step, nets = learning_step_seconds()
    Path(args.dir).mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory(dir=args.dir) as folder:
        for size in sizes:
            row = checkpoint_seconds(size, nets, Path(folder), args.episode_length)
            row["learning_steps"] = row["write_seconds"] / step
            row["share_of_run"] = row["write_seconds"] / (row["write_seconds"] + args.checkpoint_every * step)
            rows.append(row)
            print(f"{size:>9,} transitions: {row['gigabytes']:.2f} GB, written in {row['write_seconds']:.1f} s "
                  f"(= {row['learning_steps']:,.0f} learning steps), read in {row['read_seconds']:.1f} s; "
                  f"{100 * row['share_of_run']:.1f} % of a run checkpointed every {args.checkpoint_every:,} steps",
                  flush=True)
    record = {
        "benchmark": "checkpoint-cost", "env_id": "Humanoid-v5", "learning_step_seconds": step,
        "checkpoint_every": args.checkpoint_every, "episode_length": args.episode_length, "rows": rows,
        **provenance(f"python benchmarks/checkpoint_cost.py --sizes {args.sizes} --episode-length "
                     f"{args.episode_length}"),
    }
    write_record(record, args.out)


if __name__ == "__main__":
    main()
