"""An experiment as a chapter page shows it: each run loaded once, from ``results/`` or from a short live
stand-in, with a legend label that says which, the provenance to print under a figure, and a check that what
``results/`` holds is what the experiment's registry entry claims.

    runs = PageRuns("dqn-cartpole", fallback_steps=20_000, fallback_seeds=[0, 1])
    dqn = runs["dqn"]                  # every seed results/ has, or a live stand-in if it has none
    runs.legend(dqn), runs.describe(dqn)

and a sentence's numbers checked at the precision they are printed (see :func:`check_printed`):

    check_printed("1,030 ± 21", final.mean(), final.std())   # passes for 1,029.6 ± 21.4, fails for ± 19.1
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rlbook.registry import RunSpec, get_experiment
from rlbook.results import RunResults, load_experiment, load_or_train, provenance_markdown


@dataclass
class PageRuns:
    """The runs of experiment ``name`` for one page.

    ``runs[run]`` loads run ``run`` on first use: every seed that ``results/`` holds, or, if it holds none, a
    short live stand-in of ``fallback_steps`` steps for each of ``fallback_seeds``, evaluated ``eval_points``
    times (see :func:`rlbook.load_or_train`). With ``live_fallback=False`` (for runs too long to
    train while a page builds) a run missing from ``results/`` stays empty, and :meth:`describe` says so.
    ``labels`` gives short legend labels by run name (default: the registry's label).
    """

    name: str
    fallback_steps: int
    fallback_seeds: list[int]
    eval_points: int = 10
    labels: dict[str, str] = field(default_factory=dict)
    live_fallback: bool = True
    _loaded: dict[str, RunResults] = field(default_factory=dict, repr=False)

    @property
    def command(self) -> str:
        """The command that makes the experiment's full-budget runs."""
        return f"python -m rlbook experiments run {self.name} --jobs 2"

    @property
    def specs(self) -> dict[str, RunSpec]:
        return {spec.name: spec for spec in get_experiment(self.name).runs}

    def __getitem__(self, run: str) -> RunResults:
        if run not in self._loaded:
            if self.live_fallback:
                self._loaded[run] = load_or_train(self.name, run, self.fallback_steps, self.fallback_seeds,
                                                  eval_points=self.eval_points)
            else:
                self._loaded[run] = load_experiment(self.name)[run]
        return self._loaded[run]

    def legend(self, run: RunResults) -> str:
        """A short label for legends and tables; it says when the run is a short live stand-in."""
        label = self.labels.get(run.name, run.label)
        return label + ("" if run.source == "results" else " (short live run)")

    def describe(self, *runs: RunResults) -> str:
        """What to show under a figure of ``runs``: their provenance, folded (see
        :func:`rlbook.provenance_markdown`); a live stand-in, missing seeds, or a run with no seed at
        all stay visible."""
        return "\n".join(self._missing(run) if not run.seeds and run.source == "results"
                         else provenance_markdown(self.name, run, self.command) for run in runs)

    def _missing(self, run: RunResults) -> str:
        return (f":::{{warning}}\n`results/{self.name}/{run.name}/` holds none of its {len(run.spec.seeds)} seeds, "
                f"so *{self.legend(run)}* is not shown in this build. Run `{self.command}` to make it.\n:::\n")

    def complete(self, *runs: str) -> bool:
        """Whether every named run comes from ``results/`` with all of its registry's seeds: the condition under
        which a page's prose, written about the full-budget runs, can be checked."""
        return all(self[r].source == "results" and not self[r].missing for r in runs)


def check_results(name: str, results: dict[str, RunResults] | None = None) -> None:
    """Raise ``ValueError`` unless every seed in ``results/`` for experiment ``name`` is what the registry says:
    one of its seeds, its environment, its budget (and finished: the last evaluation is at or past it), the
    registry's overrides of the algorithm's defaults, and every evaluation of the configured number of episodes.
    A snapshot of a seed still training (``in_progress``) is checked the same way, except that it is unfinished."""
    results = load_experiment(name) if results is None else results
    for spec in get_experiment(name).runs:
        run = results[spec.name]
        if sorted([s.seed for s in run.seeds] + run.missing) != sorted(spec.seeds):
            raise ValueError(f"{name}/{spec.name}: seeds {[s.seed for s in run.seeds]} + missing {run.missing} "
                             f"are not the registry's {list(spec.seeds)}")
        for s in run.seeds + run.in_progress:
            where = f"{name}/{spec.name}/seed-{s.seed}" + (" (snapshot)" if s.snapshot else "")
            config = s.config.get("config", {})
            found = {"seed": (s.config.get("seed"), s.meta.get("seed")), "env_id": s.config.get("env_id"),
                     "steps": s.config.get("steps")}
            wanted = {"seed": (s.seed, s.seed), "env_id": spec.env_id, "steps": spec.steps}
            for key, value in spec.overrides.items():
                found[key], wanted[key] = config.get(key), _as_json(value)
            wrong = {k: (found[k], wanted[k]) for k in wanted if found[k] != wanted[k]}
            if wrong:
                raise ValueError(f"{where}: (found, registry) differ: {wrong}")
            if s.snapshot and (s.snapshot["steps"] != spec.steps or int(s.progress["step"][-1]) != s.snapshot["step"]):
                raise ValueError(f"{where}: the snapshot says step {s.snapshot['step']:,} of {s.snapshot['steps']:,}, "
                                 f"its logs end at {int(s.progress['step'][-1]):,} and the budget is {spec.steps:,}")
            if not s.snapshot and s.evals and int(s.evals["step"][-1]) < spec.steps:  # (whole iterations may pass it)
                raise ValueError(f"{where}: the last evaluation is at step {int(s.evals['step'][-1])}, "
                                 f"before {spec.steps}: the run did not finish")
            if s.evals and "eval_episodes" in config and any(int(e) != config["eval_episodes"]
                                                             for e in s.evals["episodes"]):
                raise ValueError(f"{where}: an evaluation has other than {config['eval_episodes']} episodes")


def finished_runs(name: str, results: dict[str, RunResults] | None = None) -> dict[str, RunResults]:
    """Every run of experiment ``name`` with all of its seeds, from ``results/``, checked against the registry
    (:func:`check_results`): for a page that reads a stored experiment and trains nothing. A seed still missing is
    one line that names the command that trains it."""
    results = load_experiment(name) if results is None else results
    check_results(name, results)
    missing = {run: r.missing for run, r in results.items() if r.missing}
    if missing:
        raise ValueError(f"results/{name} lacks seeds {missing}: run `python -m rlbook experiments run {name}`")
    return results


def _as_json(value: Any) -> Any:
    """A registry value as config.json stores it (tuples become lists)."""
    if isinstance(value, (tuple, list)):
        return [_as_json(v) for v in value]
    if isinstance(value, dict):
        return {k: _as_json(v) for k, v in value.items()}
    return value


# [check-printed]
# A number as prose prints it: an optional sign (ASCII or the typographic minus), digits with optional thousands
# commas, optional decimals. "1,030", "−1,081", "+224", "0.55", "2.1" (of "2.1 %"). A number glued to a letter
# before it ("PPO-v1", "Hopper-v5") is a name, not a number. A range is written with an en dash ("0.55–0.80"):
# an ASCII hyphen between two numbers reads as a minus sign.
_NUMBER = re.compile(r"(?<![\w.,])([+\-\u2212]?)(\d{1,3}(?:,\d{3})+|\d+)(?:\.(\d+))?(?!\d)")


def printed_numbers(text: str) -> list[tuple[str, float, int]]:
    """Each number in ``text`` as ``(as printed, value, decimals)``, in order. A comma or point that ends a
    sentence or a clause ("720, the", "is 41.") is not part of the number."""
    found = []
    for m in _NUMBER.finditer(text):
        sign, whole, decimals = m.group(1), m.group(2), m.group(3) or ""
        value = float(whole.replace(",", "") + ("." + decimals if decimals else ""))
        found.append((m.group(0), -value if sign in ("-", "\u2212") else value, len(decimals)))
    return found


def check_printed(text: str, *values: Any, page: str | Path | None = None) -> str:
    """Check that every number printed in ``text`` is the matching value of ``values``, rounded as it is printed,
    and return ``text`` (so a page can display what it checked).

    The i-th number of ``text`` is compared with ``values[i]`` at the number of decimals it is printed with:
    "1,030 ± 21" passes for (1,029.6, 21.4) and fails for (1,029.9, 19.1), since 19.1 prints as 19. ``...`` (Ellipsis)
    skips a number that is not computed (a year, a setting the sentence names, the report's own figure). Raises
    ``AssertionError``, naming each number that differs, if one does or if ``text`` holds another count of numbers
    than ``values``. No tolerance is wider than the printed rounding: a page that means "about" a number and accepts
    more says why and checks it with its own assert.

    With ``page`` (the chapter's ``.md`` file), ``text`` must also occur in that page as written (line breaks and
    runs of spaces count as one space), so that a sentence edited in the prose but not in its check fails too.
    """
    if page is not None and _spaces(text) not in _spaces(Path(page).read_text(encoding="utf-8")):
        raise AssertionError(f"{text!r} is not in {page}: the prose changed; check the sentence as it is now")
    numbers = printed_numbers(text)
    if len(numbers) != len(values):
        raise AssertionError(f"{text!r} prints {len(numbers)} numbers {[n for n, _, _ in numbers]}, "
                             f"but {len(values)} values were given")
    wrong = []
    for (as_printed, number, decimals), value in zip(numbers, values):
        if value is ...:
            continue
        rounded = round(float(value), decimals)
        if rounded == 0:
            rounded = 0.0                                      # -0.0 prints as 0
        if rounded != number:
            wrong.append(f"{as_printed} (the value {float(value):,.{decimals + 2}f} prints as {rounded:,.{decimals}f})")
    if wrong:
        raise AssertionError(f"stale numbers in {text!r}: " + "; ".join(wrong))
    return text


def _spaces(text: str) -> str:
    return " ".join(text.split())
# [check-printed]
