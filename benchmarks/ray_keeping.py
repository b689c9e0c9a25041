"""What a Ray cluster of machines that share no disk costs the experiment runner: its start-up, and the traffic of
the checkpoints that come back to the submitting machine (rlbook.cluster, issue 57).

    python benchmarks/ray_keeping.py --sizes 64,512 --repeats 3

On a local cluster of three nodes, as ``tests/test_cluster_nodes.py`` starts it (the submitting machine's node, and
two nodes with one CPU each and a work folder of their own, ``RLBOOK_RUNS_DIR``), it measures:

- **start-up**: the cluster's three nodes and the driver joining it; the check of whether every node sees the
  submitting machine's ``--runs-dir`` (:func:`rlbook.cluster.keeper_node`), which a submission runs once;
- **a checkpoint's trip**, for each size of ``--sizes`` (MiB; a checkpoint file that ``torch.load`` reads): sent from
  a node to the submitting machine (:func:`rlbook.cluster.send_folder`, run on node A) and taken back to the other
  node (:func:`rlbook.cluster.fetch_folder`, on node B), seconds and MiB/s, medians over ``--repeats``. Over one
  machine this is what the object store and the board cost; between two machines the network's bandwidth bounds it
  too (a 1 Gbit/s link carries about 112 MiB/s);
- **each seed's traffic** in the book's experiments with a replay memory: the sum of the checkpoints a seed writes
  (one every ``checkpoint_every`` steps, and its last; each holds the replay memory filled so far), from the bytes a
  transition takes in a checkpoint of that task, measured on a memory filled by random actions, plus the networks'
  and optimizers' bytes, read from one checkpoint of a few steps of that run's settings. This is computed from
  sizes, not timed; at the rate measured for the largest size it is seconds per seed.

Writes ``results/benchmarks/ray-keeping.json``.
"""

from __future__ import annotations

import argparse
import os
import shlex
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import provenance, write_record  # noqa: E402

NAME = "ray-keeping"
SEEDS_OF = {  # the book's experiments with a replay memory whose seeds are longest: (experiment, run)
    "td3-sac-1m": ("td3-humanoid", "td3-hopper"),
    "crossq-humanoid": ("crossq-1024",),
    "td3-sac-ant": ("td3-ant",),
    "crossq-ablation": ("crossq-1024",),
    "dqn-lunarlander": ("dqn",),
}


def transition_bytes(env_id: str, continuous: bool, steps: int = 5_000, seed: int = 0) -> float:
    """Bytes one transition takes in a checkpoint (:meth:`rlcore.buffers.ReplayBuffer.state_dict`, as
    ``torch.save`` writes it) of a memory of ``env_id`` filled by ``steps`` random actions (episodes end as they
    do, so the next observations a checkpoint keeps apart are there too)."""
    import io

    import numpy as np
    import torch

    from rlcore.buffers import ReplayBuffer
    from rlcore.envs import make_env

    env = make_env(env_id)
    obs_shape, act = env.observation_space.shape, env.action_space
    memory = ReplayBuffer(steps, obs_shape, act.shape if continuous else (), np.float32 if continuous else np.int64,
                          seed=seed)
    obs, _ = env.reset(seed=seed)
    act.seed(seed)
    for _ in range(steps):
        action = act.sample()
        nxt, reward, terminated, truncated, _ = env.step(action)
        memory.add(obs, action, float(reward), nxt, terminated)
        obs = env.reset()[0] if terminated or truncated else nxt
    env.close()
    sizes = []
    for n in (steps // 2, steps):  # the slope: what one more transition adds
        memory.size = n
        buf = io.BytesIO()
        torch.save(memory.state_dict(), buf)
        sizes.append(buf.tell())
    return (sizes[1] - sizes[0]) / (steps - steps // 2)


def fixed_bytes(spec, folder: Path) -> int:
    """Bytes of a checkpoint of ``spec``'s settings without its replay memory (networks, optimizers, counters): one
    written after a few steps with ``replay_in_checkpoint=False``."""
    from rlcore.algos import get_algorithm

    module = get_algorithm(spec.algo)
    overrides = {**spec.overrides, "replay_in_checkpoint": False, "learning_starts": 10, "eval_every": 0,
                 "checkpoint_every": 1_000_000}
    config = module.make_config(spec.algo, **overrides)
    module.train(spec.env_id, config, steps=20, seed=0, out=folder, progress=False)
    return (folder / "checkpoint.pt").stat().st_size


def seed_traffic(spec, per_transition: float, fixed: int) -> dict[str, float]:
    """What one seed of ``spec`` sends to the submitting machine: one checkpoint every ``checkpoint_every`` steps and
    its last, each ``fixed`` bytes and ``per_transition`` for each transition its memory holds by then."""
    from rlcore.algos import get_algorithm

    config = get_algorithm(spec.algo).make_config(spec.algo, **spec.overrides)
    every, buffer = config.checkpoint_every, config.buffer_size
    steps = sorted({*range(every, spec.steps + 1, every), spec.steps})
    sent = sum(fixed + per_transition * min(k, buffer) for k in steps)
    return {"checkpoints": len(steps), "checkpoint_every": every, "buffer_size": buffer,
            "largest_mib": (fixed + per_transition * min(spec.steps, buffer)) / 2**20, "sent_gib": sent / 2**30}


def make_checkpoint(folder: str, mib: int) -> None:
    """On a node: a checkpoint of about ``mib`` MiB (a step and random bytes) in ``folder``."""
    import torch

    Path(folder).mkdir(parents=True, exist_ok=True)
    torch.save({"step": 1, "memory": torch.randint(0, 255, (mib * 2**20,), dtype=torch.uint8)},
               Path(folder) / "checkpoint.pt")


def timed(fn, *args) -> float:
    start = time.perf_counter()
    fn(*args)
    return time.perf_counter() - start


def trips(ray, board, nodes, sizes: list[int], repeats: int) -> dict[str, dict[str, float]]:
    """Median seconds and MiB/s of a checkpoint of each size sent from node A to the board and taken to node B."""
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    from rlbook.cluster import fetch_folder, send_folder

    def on(node, fn):
        return ray.remote(num_cpus=0)(fn).options(scheduling_strategy=NodeAffinitySchedulingStrategy(node, soft=False))

    a, b = (nodes.nodes[n][0].node_id for n in ("a", "b"))
    out = {}
    for mib in sizes:
        sent, fetched = [], []
        for r in range(repeats):
            key = f"{NAME}/trip/seed-{mib}-{r}"
            ray.get(on(a, make_checkpoint).remote(str(nodes.work("a") / key), mib))
            sent.append(ray.get(on(a, timed).remote(send_folder, board, key, nodes.work("a") / key)))
            fetched.append(ray.get(on(b, timed).remote(fetch_folder, board, key, nodes.work("b") / key)))
        size = (nodes.work("b") / key / "checkpoint.pt").stat().st_size / 2**20
        s, f = statistics.median(sent), statistics.median(fetched)
        out[str(mib)] = {"mib": size, "send_seconds": s, "fetch_seconds": f, "send_mib_per_s": size / s,
                         "fetch_mib_per_s": size / f}
        print(f"{size:,.0f} MiB: sent in {s:.2f} s ({size / s:,.0f} MiB/s), taken back in {f:.2f} s "
              f"({size / f:,.0f} MiB/s)", flush=True)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", default="64,512", help="checkpoint sizes in MiB, comma-separated")
    p.add_argument("--repeats", type=int, default=3, help="trips of each size; the medians are kept")
    p.add_argument("--out", default="results/benchmarks/ray-keeping.json")
    args = p.parse_args()
    try:
        sizes = [int(s) for s in args.sizes.split(",")]
    except ValueError:
        sizes = []
    if not sizes or min(sizes) < 1 or args.repeats < 1:
        raise SystemExit("--sizes takes whole numbers of MiB (1 or more), comma-separated; --repeats 1 or more")
    import ray

    import rlbook as ex
    from rlbook.cluster import NAMESPACE, driver_code, keeper_node, new_board, shipped_env

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_cluster_nodes import Nodes

    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="rk-", dir="/tmp") as tmp:
        top = Path(tmp)
        (top / "ray").mkdir()
        os.environ["RAY_TMPDIR"] = str(top)
        start = time.perf_counter()
        nodes = Nodes(top, object_store_mib=2 * max(sizes) + 256)
        ray.init(address=nodes.cluster.address, namespace=NAMESPACE, runtime_env=shipped_env(driver_code()))
        cluster_seconds = time.perf_counter() - start
        work = top / "runs"
        check = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            assert keeper_node(ray, work) is not None  # the nodes do not see it: checkpoints come back
            check.append(time.perf_counter() - start)
        board = new_board(ray, None, work)
        trip = trips(ray, board, nodes, sizes, args.repeats)
        ray.shutdown()
        nodes.cluster.shutdown()
    rate = trip[str(max(sizes))]["send_mib_per_s"]  # a replay memory's checkpoint is the largest kind
    seeds = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, runs in SEEDS_OF.items():
            for spec in ex.get_experiment(name).runs:
                if spec.name not in runs:
                    continue
                continuous = spec.algo != "dqn"
                row = seed_traffic(spec, transition_bytes(spec.env_id, continuous),
                                   fixed_bytes(spec, Path(tmp) / name / spec.name))
                row.update(env_id=spec.env_id, steps=spec.steps,
                           seconds_at_measured_rate=row["sent_gib"] * 1024 / rate,
                           seconds_at_1_gbit=row["sent_gib"] * 1024 / 112)
                seeds[f"{name}/{spec.name}"] = row
                print(f"{name}/{spec.name}: {row['checkpoints']} checkpoints, the last {row['largest_mib']:,.0f} MiB, "
                      f"{row['sent_gib']:,.1f} GiB a seed", flush=True)
    record = {"benchmark": NAME, "sizes_mib": sizes, "repeats": args.repeats,
              "startup": {"cluster_seconds": cluster_seconds, "check_seconds": statistics.median(check)},
              "trips": trip, "rate_mib_per_s": rate, "seeds": seeds,
              **provenance(shlex.join(["python", "benchmarks/ray_keeping.py", *sys.argv[1:]]), load_start=load,
                           peers=("ray",))}
    write_record(record, args.out, f"cluster start-up {cluster_seconds:.1f} s, check "
                                   f"{record['startup']['check_seconds']:.2f} s; a checkpoint comes back at "
                                   f"{rate:,.0f} MiB/s on this machine")


if __name__ == "__main__":
    main()
