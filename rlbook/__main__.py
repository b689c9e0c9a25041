"""The book's command line: ``python -m rlbook experiments list | run | status | reevaluate | snapshot``.

    python -m rlbook experiments list
    python -m rlbook experiments run dqn-cartpole --jobs 2        # resumable: run it again after Ctrl-C
    python -m rlbook experiments status dqn-cartpole
    python -m rlbook experiments snapshot ddpg-report-humanoid --only large   # logs so far of a seed in training
    python -m rlbook experiments run td3-sac-1m --ray auto --runs-dir ~/runs   # on a Ray cluster
    python -m rlbook experiments run td3-sac-1m --ray auto --runs-dir ~/runs --detach   # and close the terminal
    python -m rlbook experiments status td3-sac-1m --ray auto     # and its seeds in flight there

Training one agent, evaluating and rendering it are the library's: ``python -m rlcore train | evaluate | render``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from rlcore.cli import EXIT_INTERRUPTED, Parser, count, run_command, seed_list


def cmd_experiments(args: argparse.Namespace) -> int:
    import rlbook as ex
    from rlbook import paths

    if args.detach and args.action != "run":
        raise ValueError(f"--detach is for `experiments run`, not `experiments {args.action}`")
    if args.action == "list":
        for name in sorted(ex.EXPERIMENTS):
            exp = ex.get_experiment(name)
            runs = sum(len(r.seeds) for r in exp.runs)
            print(f"{name}: {exp.description} ({len(exp.runs)} configurations, {runs} runs)")
        return 0
    if not args.name:
        raise ValueError(f"experiments {args.action} needs an experiment name; see `python -m rlbook experiments list`")
    results = Path(args.results) if args.results else None
    work = Path(args.work) if args.work else None
    if args.root:  # else each step finds the book's folders itself (rlbook.paths), after checking its arguments
        results, work = results or paths.results_dir(args.root), work or paths.work_dir(args.root)
    if args.action == "reevaluate":
        from rlbook.reevaluation import store_final_policy_returns

        chosen = {spec.name for spec in ex.chosen_runs(args.name, args.only)}
        for run_name, run in ex.load_experiment(args.name, results).items():
            if run.seeds and run_name in chosen:
                for path in store_final_policy_returns(run, episodes=args.episodes, seeds=args.seeds):
                    print(f"Wrote {path}")
        return 0
    if args.action == "snapshot":
        take = None
        if args.ray:  # each seed's snapshot on the node where it trains
            from rlbook.cluster import ray_snapshots

            take = ray_snapshots(args.ray)
        for line in ex.snapshot_experiment(args.name, only=args.only, seeds=args.seeds, results=results,
                                           work=work, policy=args.policy, take=take):
            print(line)
        return 0
    if args.action == "run":
        if args.detach:
            return detach(args, work)
        return run_and_report(args, results, work)
    print("\n".join(ex.status_lines(args.name, results, work)))
    if args.ray:  # and the seeds in flight on the cluster: where, step, last checkpoint
        from rlbook.cluster import in_flight_lines

        print("\n".join(in_flight_lines(args.name, args.ray)))
    return 0


def run_and_report(args: argparse.Namespace, results: Path | None, work: Path | None) -> int:
    """``experiments run``: train the missing seeds, print their status lines and the experiment's status. Seeds
    that failed on a cluster, while the others went on, are listed last, and the exit status is 1."""
    import rlbook as ex

    train, failed = ex.train_all, ()  # the backend; what it raises when seeds failed while the others went on
    if args.ray:
        from rlbook.cluster import SeedsFailed, ray_backend

        train, failed = ray_backend(args.ray), (SeedsFailed,)
    failures = []
    try:
        lines = ex.run_experiment(args.name, jobs=args.jobs, only=args.only, seeds=args.seeds,
                                  results=results, work=work, train=train)
    except KeyboardInterrupt:
        print("\nInterrupted. Finished runs are in results/; the others resume from their checkpoints "
              "when you run the same command again.", file=sys.stderr)
        return EXIT_INTERRUPTED
    except failed as exc:
        lines, failures = exc.lines, exc.failures
    print("\n".join(lines))
    print("\n".join(ex.status_lines(args.name, results, work)))
    if failures:
        print(f"error: {len(failures)} seed(s) failed: " + ", ".join(key for key, _ in failures) +
              "; the others went on (their lines above say why)", file=sys.stderr)
    return 1 if failures else 0


def detach(args: argparse.Namespace, work: Path | None) -> int:
    """``experiments run ... --detach``: the same command without ``--detach``, started in a session of its own (no
    terminal: closing this one sends it no hangup), its input from nothing and its output to a log in the work folder;
    prints where, and returns at once. ``kill PID`` stops it as Ctrl-C would: its seeds checkpoint, and the same
    command resumes them."""
    from rlbook import paths
    from rlbook.runner import chosen_tasks

    chosen_tasks(args.name, args.only, args.seeds)  # what the command would refuse, refused here, in one line
    log = (work or paths.work_dir()) / args.name / f"driver-{time.strftime('%Y%m%d-%H%M%S')}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    argv = [a for a in args.argv if a != "--detach"]
    with open(os.devnull, "rb") as nothing, log.open("ab") as out:
        child = subprocess.Popen([sys.executable, "-m", "rlbook", *argv], stdin=nothing, stdout=out,
                                 stderr=subprocess.STDOUT, start_new_session=True, close_fds=True)
    print(f"experiments run {args.name}: running in the background as process {child.pid}, in a session of its own "
          f"(closing this terminal does not stop it); output: {log}; `kill {child.pid}` stops it (its seeds "
          "checkpoint, and the same command resumes them); `python -m rlbook experiments status "
          f"{args.name}` shows where it is")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="python -m rlbook", description="The book's full-budget experiments (resumable).")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    x = sub.add_parser("experiments", help="the book's full-budget experiments (resumable)")
    x.add_argument("action", choices=["list", "run", "status", "reevaluate", "snapshot"],
                   help="reevaluate: evaluate each finished seed's (each of --seeds') final policy and store its "
                        "returns in results/; snapshot: copy the logs so far of seeds still training to results/ "
                        "(with --policy, the policy of their last checkpoint too)")
    x.add_argument("name", nargs="?", help="experiment name (see `experiments list`)")
    x.add_argument("--jobs", type=count(1), help="runs in parallel, one process each (one per core; default 1); "
                                                  "with --ray local, the CPUs of the local cluster (default all)")
    x.add_argument("--ray", metavar="ADDRESS",
                   help="run: each seed as a task on a Ray cluster (auto: the one `ray start` joined this machine "
                        "to; HOST:PORT; local: start one on this machine), results written here; snapshot: take "
                        "each seed's snapshot on the node where it trains; status: also the seeds in flight on the "
                        "cluster (node, step, last checkpoint). Needs `pip install ray==2.60.0`")
    x.add_argument("--only", action="append", metavar="RUN", help="only this configuration (repeatable)")
    x.add_argument("--seeds", type=seed_list, help="comma-separated subset of the seeds, e.g. 0,1")
    x.add_argument("--episodes", type=count(1), default=5, help="reevaluate: episodes per seed")
    x.add_argument("--policy", action="store_true",
                   help="snapshot: also the policy of each seed's last checkpoint (snapshot-policy.pt)")
    x.add_argument("--root", help="the book's folder (default: RLBOOK_ROOT, else the checkout holding the current "
                                  "folder); --results and --work default to its results/ and runs/")
    x.add_argument("--results", help="where finished runs' small outputs go (default: ROOT/results)")
    x.add_argument("--work", "--runs-dir", dest="work",
                   help="where runs train and keep full checkpoints (default: ROOT/runs); with --ray, each node "
                        "trains in this path on its own disk (or its RLBOOK_RUNS_DIR) and, unless every node sees "
                        "this machine's, sends each checkpoint here, from where a seed goes on on any node")
    x.add_argument("--detach", action="store_true",
                   help="run: start it in the background, in a session of its own, and return at once: closing the "
                        "terminal does not stop it; its output goes to a log in the work folder, whose path is "
                        "printed with the process ID (`kill PID` stops it as Ctrl-C does)")
    x.set_defaults(func=cmd_experiments)
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    args.argv = argv  # what --detach starts again, without itself
    return run_command(args)


if __name__ == "__main__":
    sys.exit(main())
