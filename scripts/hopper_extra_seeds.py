"""(Run from the repository root: python scripts/hopper_extra_seeds.py.) How seeds 3 and 4 of
ddpg-report-sweeps/hopper-hidden2048 were trained (their meta.json names this command), while the registry listed
Hopper seeds 0-2 only: train_one with the arm's own spec, into the usual work and results folders; resumable.
Now that REPORT_DDPG_SEEDS["Hopper-v5"] lists all five, `python -m rlbook experiments run ddpg-report-sweeps
--only hopper-hidden2048` does the same; this script stays as the provenance of those two seeds."""
from rlbook.registry import get_experiment
from rlbook.runner import train_one
from rlcore.signals import stop_on_signals

stop_on_signals()
spec = next(r for r in get_experiment("ddpg-report-sweeps").runs if r.name == "hopper-hidden2048")
for seed in (3, 4):
    print(train_one("ddpg-report-sweeps", spec, seed), flush=True)
