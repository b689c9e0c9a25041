"""rlbook.cluster_time: each seed's cost from the records, and the wall time of all seeds on N machines."""

import json

import pytest

from rlbook import paths
from rlbook.cluster_time import left_out, makespan, scaling_rows, seed_costs
from rlbook.registry import EXPERIMENTS, get_experiment


def rows(*seeds):
    return [{"hours": h, "cores": c, "seeds": n} for h, c, n in seeds]


def test_makespan_packs_seeds_onto_machines_longest_first():
    assert makespan(rows((1.0, 1, 4)), nodes=1) == 2.0   # four one-hour seeds, two cores: two rounds
    assert makespan(rows((1.0, 1, 4)), nodes=2) == 1.0
    assert makespan(rows((1.0, 1, 4)), nodes=8) == 1.0   # more machines than seeds: one seed's time
    # a two-core seed takes a whole machine; longest first: 3 h alone beside the others' 1 + 1 + 1 ... on one core
    assert makespan(rows((3.0, 2, 1), (1.0, 1, 2)), nodes=1) == 4.0
    assert makespan(rows((3.0, 2, 1), (1.0, 1, 2)), nodes=2) == 3.0
    assert makespan(rows((1.0, 1, 2)), nodes=1, overhead_seconds=36) == pytest.approx(1.01)
    with pytest.raises(ValueError, match="needs 3 cores"):
        makespan(rows((1.0, 3, 1)), nodes=4)


def test_scaling_rows_stop_at_the_longest_seed():
    table = scaling_rows(rows((4.0, 1, 1), (1.0, 1, 8)), node_counts=(1, 2, 8))
    assert [r["hours"] for r in table] == [6.0, 4.0, 4.0] and [r["cores"] for r in table] == [2, 4, 16]
    assert table[1]["speedup"] == 1.5


def test_seed_costs_of_the_stored_records():
    costs = seed_costs(paths.results_dir(paths.book_root(__file__)))
    assert {r["experiment"] for r in costs} | set(left_out(costs)) == set(EXPERIMENTS)
    for r in costs:
        spec = next(s for s in get_experiment(r["experiment"]).runs if s.name == r["run"])
        assert (r["seeds"], r["cores"], r["steps"]) == (len(spec.seeds), spec.workers, spec.steps)
        # a benchmark record's estimate, or the seeds' own wall time where they recorded it
        assert 0 < r["hours"] < 100 and (r["source"].split(" ")[0].endswith(".json")
                                         or r["source"].startswith("its "))
    longest = max(costs, key=lambda r: r["hours"])
    assert (longest["experiment"], longest["run"]) == ("ddpg-report-humanoid", "large")


def test_a_runs_own_timing_replaces_the_records_estimate(tmp_path):
    from rlbook.cluster_time import measured

    row = {"experiment": "dqn-cartpole", "run": "dqn", "hours": 0.5, "seeds": 5, "cores": 1, "source": "a record"}
    folder = tmp_path / "dqn-cartpole" / "dqn"
    for seed, wall, since in ((0, 360.0, 0), (1, 720.0, 0), (2, 1_800.0, 0)):
        (folder / f"seed-{seed}").mkdir(parents=True)
        (folder / f"seed-{seed}" / "policy.pt").write_bytes(b"")
        (folder / f"seed-{seed}" / "meta.json").write_text(
            json.dumps({"timing": {"wall_seconds": wall, "cpu_seconds": wall, "from_step": since}}))
    (new,) = measured([row], tmp_path)
    assert new["hours"] == 0.2 and new["source"].startswith("its 3 seed(s)' own wall time")
    # a seed timed over its last session only (resumed) leaves the record's estimate in place
    (folder / "seed-2" / "meta.json").write_text(
        json.dumps({"timing": {"wall_seconds": 10.0, "cpu_seconds": 10.0, "from_step": 500}}))
    assert measured([row], tmp_path) == [row]
