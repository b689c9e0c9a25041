"""rlbook: the machinery that makes the book, beside the library. At its heart the full-budget experiments: the
named, resumable runs whose outputs the book shows.

    python -m rlbook experiments list
    python -m rlbook experiments run dqn-cartpole --jobs 2        # resumable: run it again after Ctrl-C
    python -m rlbook experiments status dqn-cartpole
    python -m rlbook experiments snapshot ddpg-report-humanoid --only large   # logs so far of a seed in training

Each run trains in a work folder (``runs/<experiment>/<run>/seed-<s>/``, not committed: it holds
full checkpoints with replay memories) and, when it finishes, its small outputs are copied to
``results/<experiment>/<run>/seed-<s>/``:

    config.json  meta.json     what ran: algorithm, environment, Config, seed, steps; command, versions, commit;
                               the wall and CPU seconds of the session that finished it (timing)
    progress.csv eval.csv      per-episode training returns; periodic evaluations of the deterministic policy
    policy.pt                  the final policy's weights only (loads with weights_only=True)

A seed that trains over many sessions can be shown before it finishes: ``experiments snapshot`` copies its logs
so far to its results folder with a ``snapshot.json`` (and no ``policy.pt``, so it still counts as missing);
:func:`load_experiment` lists it in ``RunResults.in_progress``.

Chapters read ``results/`` with :func:`load_experiment`; a run that is missing there is reported so
that the chapter can say so and fall back to a short live run.

The package, one idea a module. It imports :mod:`rlcore`; :mod:`rlcore` never imports it.

- :mod:`rlbook.paths`: where the book is (``RLBOOK_ROOT``, or the checkout around the working directory);
- :mod:`rlbook.registry`: the named experiments (``RunSpec``, ``Experiment``, ``EXPERIMENTS``);
- :mod:`rlbook.runner`: training them, one process per core, resumable; snapshots of seeds still training;
- :mod:`rlbook.cluster`: the same on a Ray cluster (``experiments run --ray``; Ray is optional);
  :mod:`rlbook.cluster_time`: how the experiments' wall time would scale with machines;
- :mod:`rlbook.results`: reading ``results/`` (or a short live stand-in) and its provenance;
- :mod:`rlbook.analysis`: the statistics and tables the chapters quote;
- :mod:`rlbook.pages`: an experiment's runs as a page loads, labels and describes them; ``check_printed``;
- :mod:`rlbook.reevaluation`: stored policies evaluated again, and the records that keep those numbers;
- :mod:`rlbook.critic_trace`: a stored DDPG or TD3 seed re-trained with a read-only probe on its critic;
- :mod:`rlbook.versus`: two algorithms' stored runs measured the same way;
- :mod:`rlbook.peers`: the records of the returns benchmark against Stable-Baselines3;
- :mod:`rlbook.course_report`: the course report's tables, as printed;
- :mod:`rlbook.record_plots`: plots of the book's records (DPPO's scaling, a critic trace);
- :mod:`rlbook.scoreboard`: every Humanoid-v5 setting's return at 100k, 300k and 1M steps beside the CPU-hours;
- chapter helpers: :mod:`rlbook.tabular_seeds` (tabular seeds in a reused process pool),
  :mod:`rlbook.tabular_plots`, :mod:`rlbook.mujoco_analysis`, :mod:`rlbook.overestimation`,
  :mod:`rlbook.crossq_demo` (a batch like a replay memory's, for chapter 9's batch-norm demonstration);
- :mod:`rlbook.__main__`: ``python -m rlbook experiments ...``.

Everything is importable from ``rlbook`` itself.
"""

from __future__ import annotations

from rlbook.paths import BookRootError, book_root, results_dir, work_dir  # noqa: F401
from rlbook.registry import (  # noqa: F401
    RunSpec,
    Experiment,
    ZOO_PPO,
    REPORT_DDPG,
    REPORT_DDPG_SEEDS,
    REPORT_DDPG_SWEEPS,
    REPORT_DDPG_HUMANOID,
    MODERN_DDPG,
    REPORT_PPO_HOPPER,
    REPORT_PPO_HALFCHEETAH,
    REPORT_PPO_HALFCHEETAH_RUNS,
    EXPERIMENTS,
    get_experiment,
    run_paths,
    seed_folder,
)
from rlbook.runner import (  # noqa: F401
    chosen_runs,
    config_class,
    distributed_command,
    export_policy,
    train_one,
    snapshot_one,
    snapshot_experiment,
    SNAPSHOT,
    SNAPSHOT_POLICY,
    run_in_pool,
    schedule,
    train_all,
    run_experiment,
)
from rlbook.results import (  # noqa: F401
    SeedResult,
    RunResults,
    load_experiment,
    load_or_train,
    provenance_markdown,
    live_provenance_markdown,
    record_provenance_markdown,
    snapshot_markdown,
    status_lines,
)
from rlbook.analysis import (  # noqa: F401
    first_step_reaching,
    reward_per_epoch,
    covers_epochs,
    report_metric,
    final_returns,
    last_evals,
    mean_std,
    seeds_table,
    gap_and_spread,
    gap_rows,
    scaling_runs,
    learning_seconds,
    scaling_rows,
    markdown_table,
    eval_curves,
    second_half_means,
    iqm_ci,
    iqm_difference_ci,
    ablation_rows,
)
from rlbook.pages import PageRuns, check_printed, check_results, finished_runs, printed_numbers  # noqa: F401
