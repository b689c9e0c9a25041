"""(Run from the repository root: python scripts/hopper_extra_seeds.py.) Seeds 3 and 4 of ddpg-report-sweeps/hopper-hidden2048, which the registry does not list yet (its Hopper arms
list seeds 0-2 until this arm has five): train_one with the arm's own spec, into the usual work and results
folders. Resumable: run it again after an interruption. When both are in results/, set
REPORT_DDPG_SEEDS["Hopper-v5"] to (0, 1, 2, 3, 4) and update section 5.2's Hopper verdict."""
from rlcore.experiments.registry import get_experiment
from rlcore.experiments.runner import train_one
from rlcore.runs import stop_on_signals

stop_on_signals()
spec = next(r for r in get_experiment("ddpg-report-sweeps").runs if r.name == "hopper-hidden2048")
for seed in (3, 4):
    print(train_one("ddpg-report-sweeps", spec, seed), flush=True)
