"""rlbook.pages: an experiment's runs as a chapter page loads, labels and describes them, and the check
that results/ holds what the registry says."""

import numpy as np
import pytest

import rlbook as ex
from rlbook import pages
from rlbook.pages import PageRuns, check_results

SPECS = (ex.RunSpec("base", "dqn", "CartPole-v1", 100, (0, 1), {}, "Baseline"),
         ex.RunSpec("wide", "dqn", "CartPole-v1", 100, (0, 1), {"hidden": (8, 8), "double": True}, "Wide"))


@pytest.fixture
def small(monkeypatch):
    monkeypatch.setitem(ex.EXPERIMENTS, "small", lambda: ex.Experiment("small", "a test experiment", SPECS))


def _seed(spec, seed, **changes):
    config = {"seed": seed, "env_id": spec.env_id, "steps": spec.steps,
              "config": {"eval_episodes": 5, **{k: list(v) if isinstance(v, tuple) else v
                                                for k, v in spec.overrides.items()}}}
    config.update({k: v for k, v in changes.items() if k in ("env_id", "steps")})
    config["config"].update(changes.get("config", {}))
    evals = {"step": np.array([50, changes.get("last_step", spec.steps)]), "episodes": np.array([5, 5]),
             "mean_return": np.array([10.0, 20.0])}
    return ex.SeedResult(seed, None, {}, evals, config, {"seed": seed})


def _results(**changes):
    return {spec.name: ex.RunResults(spec, [_seed(spec, s, **(changes if spec.name == "wide" and s == 1 else {}))
                                            for s in spec.seeds], []) for spec in SPECS}


def test_check_results_accepts_what_the_registry_says(small):
    check_results("small", _results())
    fewer = _results()
    fewer["base"] = ex.RunResults(SPECS[0], fewer["base"].seeds[:1], [1])    # a seed still missing is fine
    check_results("small", fewer)


@pytest.mark.parametrize("changes, message", [
    ({"steps": 50}, "steps"),
    ({"env_id": "Acrobot-v1"}, "env_id"),
    ({"config": {"double": False}}, "double"),
    ({"config": {"hidden": [8, 16]}}, "hidden"),
    ({"last_step": 60}, "did not finish"),
    ({"config": {"eval_episodes": 3}}, "other than 3 episodes"),
])
def test_check_results_refuses_a_seed_that_differs_from_the_registry(small, changes, message):
    with pytest.raises(ValueError, match=message):
        check_results("small", _results(**changes))


def test_every_experiment_in_results_is_what_the_registry_says():
    import rlbook as ex

    for name in sorted(ex.EXPERIMENTS):
        check_results(name)
    assert ex.load_experiment("ddpg-report")["hopper"].seeds  # it read the committed results/, not an empty folder


def test_check_results_refuses_seeds_the_registry_does_not_have(small):
    odd = _results()
    odd["base"] = ex.RunResults(SPECS[0], odd["base"].seeds + [_seed(SPECS[0], 7)], [])
    with pytest.raises(ValueError, match="registry's"):
        check_results("small", odd)


def test_page_runs_loads_each_run_once_and_says_where_it_comes_from(small, monkeypatch):
    calls = []

    def fake_load_or_train(name, run, fallback_steps, fallback_seeds, eval_points=10):
        calls.append((name, run, fallback_steps, tuple(fallback_seeds), eval_points))
        spec = next(s for s in SPECS if s.name == run)
        if run == "base":
            return ex.RunResults(spec, [_seed(spec, 0)], [1])
        return ex.RunResults(spec, [_seed(spec, 5)], list(spec.seeds), source="live")

    monkeypatch.setattr(pages, "load_or_train", fake_load_or_train)
    runs = PageRuns("small", fallback_steps=40, fallback_seeds=[5], eval_points=2, labels={"base": "B"})
    assert runs["base"] is runs["base"] and calls == [("small", "base", 40, (5,), 2)]   # loaded once
    assert runs.legend(runs["base"]) == "B" and runs.legend(runs["wide"]) == "Wide (short live run)"
    assert runs.command == "python -m rlbook experiments run small --jobs 2" and set(runs.specs) == {"base", "wide"}
    assert not runs.complete("base") and not runs.complete("wide")     # a seed missing; a live stand-in
    runs._loaded["base"] = _results()["base"]
    assert runs.complete("base") and not runs.complete("base", "wide")  # every seed, from results/
    text = runs.describe(runs["wide"])
    assert "{warning}" in text and "short live run" in text and runs.command in text


def test_page_runs_without_live_fallback_shows_what_results_has_and_says_what_is_missing(small, monkeypatch):
    stored = _results()
    stored["wide"] = ex.RunResults(SPECS[1], [], [0, 1])
    monkeypatch.setattr(pages, "load_experiment", lambda name: stored)
    monkeypatch.setattr(pages, "load_or_train", lambda *a, **k: pytest.fail("no live run without the fallback"))
    runs = PageRuns("small", fallback_steps=40, fallback_seeds=[5], live_fallback=False)
    assert runs["base"] is stored["base"] and runs.complete("base") and not runs["wide"].seeds
    text = runs.describe(runs["wide"])
    assert text.startswith(":::{warning}") and "holds none of its 2 seeds" in text and "*Wide*" in text


# check_printed: a number is checked at the precision it is printed


def test_printed_numbers_reads_signs_commas_decimals_and_skips_names():
    from rlbook.pages import printed_numbers

    text = "PPO-v1 on Hopper-v5: 1,030 ± 21, −1,081 and +224; 2.1 % of 0.55–0.80. It is 41."
    assert [(n, v, d) for n, v, d in printed_numbers(text)] == [
        ("1,030", 1030.0, 0), ("21", 21.0, 0), ("−1,081", -1081.0, 0), ("+224", 224.0, 0), ("2.1", 2.1, 1),
        ("0.55", 0.55, 2), ("0.80", 0.8, 2), ("41", 41.0, 0)]


def test_check_printed_passes_values_that_round_to_the_printed_numbers_and_returns_the_text():
    from rlbook.pages import check_printed

    assert check_printed("1,030 ± 21", 1_029.6, 21.4) == "1,030 ± 21"
    check_printed("−1,081 against 2.1 %", -1_080.7, 2.14)
    check_printed("0 and 0.0", -0.3, -0.04)                        # -0.3 prints as 0, not -0
    check_printed("report 8,470.7, ours 3,461", ..., 3_460.9)   # ... skips a number the page does not compute


@pytest.mark.parametrize("text, values, stale", [
    ("1,030 ± 21", (1_029.9, 19.1), "21 (the value 19.10 prints as 19)"),     # the example
    ("707 ± 222", (708.3, 222.0), "707"),
    ("gap 164", (160.4,), "164"),
    ("within 2.1 %", (2.04,), "2.1"),
    ("δ₂ is −0.4", (-0.2,), "−0.4"),
    ("+224", (-224.0,), "+224"),
])
def test_check_printed_names_each_stale_number(text, values, stale):
    from rlbook.pages import check_printed

    with pytest.raises(AssertionError, match="stale numbers") as info:
        check_printed(text, *values)
    assert stale in str(info.value)


def test_check_printed_refuses_another_count_of_values():
    from rlbook.pages import check_printed

    with pytest.raises(AssertionError, match="prints 2 numbers"):
        check_printed("1,030 ± 21", 1_030.0)


def test_check_printed_with_a_page_also_finds_the_sentence_there(tmp_path):
    from rlbook.pages import check_printed

    page = tmp_path / "page.md"
    page.write_text("All three seeds end within 150 of\n1,000 (1,030 ±  21). More prose.\n", encoding="utf-8")
    check_printed("within 150 of 1,000 (1,030 ± 21)", 150, 1_000, 1_030.2, 20.8, page=page)   # across a line break
    with pytest.raises(AssertionError, match="is not in"):
        check_printed("within 150 of 1,000 (1,031 ± 21)", 150, 1_000, 1_031, 21, page=page)


def test_finished_runs_are_checked_and_a_missing_seed_names_the_command(small):
    assert pages.finished_runs("small", _results())["wide"].label == "Wide"
    fewer = _results()
    fewer["base"] = ex.RunResults(SPECS[0], fewer["base"].seeds[:1], [1])
    with pytest.raises(ValueError, match=r"results/small lacks seeds \{'base': \[1\]\}: run `python -m rlbook "
                                         r"experiments run small`"):
        pages.finished_runs("small", fewer)
    with pytest.raises(ValueError, match="differ"):                          # and what the registry says holds
        pages.finished_runs("small", _results(env_id="Pendulum-v1"))
