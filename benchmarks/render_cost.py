"""What one offscreen frame of a MuJoCo body costs, by the size of its shadow map.

    python benchmarks/render_cost.py [--envs Hopper-v5,Humanoid-v5] [--sizes 4096,2048,1024] [--frames 60]

For each task and shadow-map size (``model.vis.quality.shadowsize``; MuJoCo's default is 4096, the book's
:data:`rlcore.envs.SHADOW_SIZE`), renders ``--frames`` 320 x 240 frames of random actions from one seed through the
book's renderer (:func:`rlcore.envs.make_env` with ``render_mode="rgb_array"``, on whatever headless OpenGL
:mod:`rlcore.gl` picks: on a machine without a GPU, Mesa's software renderer) and records the CPU seconds of this
process per frame (the renderer's threads included), the wall seconds, and how far each size's last frame is from
the default's (mean absolute difference per channel, 0 to 255). Rounds are interleaved so that load falls alike.
Writes ``results/benchmarks/render-cost.json``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import provenance, write_record  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def frames_cost(env_id: str, size: int, frames: int) -> tuple[float, float, np.ndarray]:
    """CPU and wall seconds per frame at shadow-map size ``size``, and the last frame."""
    from rlcore.envs import make_env

    env = make_env(env_id, seed=0, render_mode="rgb_array", width=320, height=240)
    env.unwrapped.model.vis.quality.shadowsize = size  # before the first render, which makes the GL context
    env.reset(seed=0)
    frame = env.render()  # the context is made here: not timed
    cpu, wall = time.process_time(), time.perf_counter()
    for _ in range(frames):
        env.step(env.action_space.sample())
        frame = env.render()
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    env.close()
    return cpu / frames, wall / frames, np.asarray(frame)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", default="Hopper-v5,Humanoid-v5")
    parser.add_argument("--sizes", default="4096,2048,1024")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", default=str(ROOT / "results" / "benchmarks" / "render-cost.json"))
    args = parser.parse_args(argv)
    try:
        sizes = [int(s) for s in args.sizes.split(",")]
    except ValueError:
        raise SystemExit(f"--sizes takes comma-separated whole numbers of texels, not {args.sizes!r}") from None
    if args.frames < 1 or args.rounds < 1 or any(s < 1 for s in sizes):
        raise SystemExit("--frames, --rounds and every size must be at least 1")
    from rlcore.gl import HeadlessGLError, select_gl_backend

    try:
        backend = select_gl_backend()
    except HeadlessGLError as err:
        raise SystemExit(str(err).splitlines()[0]) from None
    load_start = os.getloadavg()
    rows = []
    for env_id in args.envs.split(","):
        cpu: dict[int, list[float]] = {s: [] for s in sizes}
        wall: dict[int, list[float]] = {s: [] for s in sizes}
        last: dict[int, np.ndarray] = {}
        for _ in range(args.rounds):
            for size in sizes:
                c, w, last[size] = frames_cost(env_id, size, args.frames)
                cpu[size].append(c)
                wall[size].append(w)
        reference = last[max(sizes)].astype(float)
        for size in sizes:
            rows.append({"env": env_id, "shadow_size": size, "cpu_seconds_per_frame": statistics.median(cpu[size]),
                         "wall_seconds_per_frame": statistics.median(wall[size]),
                         "cpu_ratio_to_largest": statistics.median(cpu[size]) / statistics.median(cpu[max(sizes)]),
                         "mean_abs_pixel_difference": float(np.abs(last[size] - reference).mean())})
            print(f"{env_id:14s} {size:5d}  {rows[-1]['cpu_seconds_per_frame'] * 1e3:6.1f} ms CPU a frame  "
                  f"({rows[-1]['cpu_ratio_to_largest']:.2f}x)  pixels {rows[-1]['mean_abs_pixel_difference']:.2f}",
                  flush=True)
    record = {"rows": rows, "frames": args.frames, "rounds": args.rounds, "gl_backend": backend,
              **provenance(f"python benchmarks/render_cost.py --envs {args.envs} --sizes {args.sizes} "
                           f"--frames {args.frames} --rounds {args.rounds}", load_start)}
    write_record(record, args.out)


if __name__ == "__main__":
    main()
