"""Command line: ``python -m rlcore train | evaluate | render``.

    python -m rlcore train q-learning --env FrozenLake-v1 --steps 20000 --seed 0 --out runs/fl
    python -m rlcore evaluate runs/fl --episodes 10      # last line: one JSON object
    python -m rlcore evaluate runs/cp --which best       # a run's best-evaluated policy (policy_best.pt)
    python -m rlcore render runs/fl --out fl.gif

``train`` shows a progress bar; Ctrl-C saves a checkpoint, and running the same command again resumes.
Errors a user can fix (an unknown environment or algorithm, a corrupt checkpoint, no headless GL)
are printed as one clear message with exit code 2, not a traceback.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from rlcore.cli import EXIT_INTERRUPTED, EXIT_USAGE, Parser, count, json_object, run_command
from rlcore.cli import overrides as overrides_of


POLICY_FILES = ("policy.pt", "snapshot-policy.pt")
"""What a results folder holds instead of ``checkpoint.pt``: a finished seed's policy, or a snapshot's."""


WHICH = ("last", "best")
"""Which policy of a run ``evaluate`` and ``render`` take: the last one trained, or the best-evaluated one."""


def run_file(run_dir: str | Path, which: str = "last") -> Path:
    """The file to load from ``run_dir``: itself if a file; in a folder, for the ``best`` policy its
    ``policy_best.pt``, for the ``last`` its ``checkpoint.pt`` (a run folder), else its ``policy.pt`` or
    ``snapshot-policy.pt`` (a seed's folder in ``results/``). A folder with none of them gets the checkpoint's path,
    whose absence load_checkpoint reports."""
    from rlcore.runs import RunDir

    path = Path(run_dir)
    if not path.is_dir():
        return path
    if which == "best":
        return RunDir(path).best_policy
    checkpoint = RunDir(path).checkpoint
    return next((f for f in (checkpoint, *(path / n for n in POLICY_FILES)) if f.is_file()), checkpoint)


def _load_run(run_dir: str, which: str = "last"):
    """(checkpoint, algorithm module, policy) of a run folder, a results folder or a checkpoint file; ``which``
    policy of a folder's (:data:`WHICH`)."""
    from rlcore.algos import get_algorithm
    from rlcore.checkpoint import CheckpointError, load_checkpoint

    path = run_file(run_dir, which)
    try:
        ckpt = load_checkpoint(path)
    except CheckpointError as err:
        if which == "best" and not path.exists():
            raise CheckpointError(f"No {path.name} in {run_dir}: a run keeps its best-evaluated policy once it has "
                                  "evaluated one (eval_every > 0); results/ keeps only the last (--which last)."
                                  ) from None
        if Path(run_dir).is_dir() and not path.exists():
            raise CheckpointError(f"No checkpoint at {path} and no {' or '.join(POLICY_FILES)} in {run_dir}: "
                                  "train first, or check the path.") from None
        raise err
    module = get_algorithm(ckpt["algo"])
    return ckpt, module, module.load_policy(ckpt)


def cmd_train(args: argparse.Namespace) -> int:
    from rlcore.algos import get_algorithm
    from rlcore.envs import check_env_id

    module = get_algorithm(args.algo)
    check_env_id(args.env)
    overrides = overrides_of(module.Config, args.set or [])
    if args.env_kwargs is not None:
        overrides["env_kwargs"] = args.env_kwargs
    config = module.make_config(args.algo, **overrides)
    from rlcore.machine import torch_threads

    torch_threads()  # one unless RLCORE_TORCH_THREADS says more
    try:
        module.train(args.env, config, steps=args.steps, seed=args.seed, out=args.out,
                     progress=not args.no_progress)
    except KeyboardInterrupt:
        print(f"\nInterrupted. Checkpoint saved in {args.out}; run the same command again to resume.",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f"Done: {args.algo} on {args.env}, {args.steps} steps, seed {args.seed} -> {args.out}")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from rlcore.envs import make_env
    from rlcore.evaluate import evaluate_policy, summarize

    ckpt, _, policy = _load_run(args.run, args.which)
    env = make_env(ckpt["env_id"], seed=args.seed, **ckpt["config"].get("env_kwargs", {}))
    returns = evaluate_policy(policy, env, episodes=args.episodes, seed=args.seed, max_steps=args.max_steps)
    env.close()
    result = {"algo": ckpt["algo"], "env_id": ckpt["env_id"], "train_seed": ckpt["seed"],
              "train_steps": ckpt["step"], "policy": args.which, "eval_seed": args.seed, **summarize(returns),
              "returns": [float(r) for r in returns]}
    if "evaluation" in ckpt:  # the best-evaluated policy: the evaluation it was kept for
        result["training_evaluation"] = ckpt["evaluation"]
    print(json.dumps(result))
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    from rlcore.render import render_gif

    ckpt, _, policy = _load_run(args.run, args.which)
    data = render_gif(ckpt["env_id"], policy, max_frames=args.frames, seed=args.seed, fps=args.fps,
                      path=args.out, env_kwargs=ckpt["config"].get("env_kwargs", {}))
    print(f"Wrote {args.out} ({len(data) / 1e6:.2f} MB, {ckpt['algo']} on {ckpt['env_id']}, the {args.which} policy, "
          f"step {ckpt['step']:,})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    from rlcore.algos import ALGORITHMS

    p = Parser(prog="python -m rlcore", description="Train, evaluate and render rlcore agents.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)

    t = sub.add_parser("train", help="train an agent and write its run folder")
    t.add_argument("algo", help=f"one of: {', '.join(sorted(ALGORITHMS))}")
    t.add_argument("--env", required=True, help="Gymnasium environment id, e.g. FrozenLake-v1")
    t.add_argument("--steps", type=count(1), required=True, help="environment steps to train for")
    t.add_argument("--seed", type=count(0), default=0)
    t.add_argument("--out", required=True, help="run folder (config, progress.csv, checkpoint.pt)")
    t.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a Config field (repeatable)")
    t.add_argument("--env-kwargs", type=json_object,
                   help='JSON keyword arguments for gymnasium.make, e.g. \'{"is_slippery": false}\'')
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.set_defaults(func=cmd_train)

    e = sub.add_parser("evaluate", help="evaluate the deterministic policy of a run")
    e.add_argument("run", help="run folder (or its checkpoint.pt)")
    e.add_argument("--episodes", type=count(1), default=10)
    e.add_argument("--seed", type=count(0), default=10_000, help="seed of the first evaluation episode")
    e.add_argument("--max-steps", type=count(1), default=None, help="cap on steps per episode")
    e.add_argument("--which", choices=WHICH, default="last",
                   help="the last policy trained (default) or the best-evaluated one (policy_best.pt)")
    e.set_defaults(func=cmd_evaluate)

    r = sub.add_parser("render", help="render the deterministic policy of a run to a GIF")
    r.add_argument("run", help="run folder (or its checkpoint.pt)")
    r.add_argument("--out", required=True, help="GIF file to write")
    r.add_argument("--frames", type=count(1), default=300)
    r.add_argument("--fps", type=count(1), default=30)
    r.add_argument("--seed", type=count(0), default=0)
    r.add_argument("--which", choices=WHICH, default="last",
                   help="the last policy trained (default) or the best-evaluated one (policy_best.pt)")
    r.set_defaults(func=cmd_render)

    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["experiments"]:  # the book's experiments moved out of the library, into the book's package
        print(f"error: the book's experiments are run by `python -m rlbook {shlex.join(argv)}`", file=sys.stderr)
        return EXIT_USAGE
    return run_command(build_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
