"""Evaluating saved policies again, on the page that shows them: a run's final policies on the start states its
training evaluated them on, which seeds were trained before PPO's evaluation-clipping fix, and one PPO policy's
return three ways (mean action clipped to the motors' range, unclipped, sampled).

    finals = final_policy_returns(run)            # per seed: stored in results/, or evaluated now
    episodes = final_policy_episodes(run)         # per seed: (returns, lengths) of each episode
    before = trained_before_clipping_fix(run)     # per seed, True where eval.csv counted unclipped actions

A policy's return is a chaotic function of the last bits of its actions, and those differ between processors
(MKL takes other kernels on AMD than on Intel): a Hopper evaluated on one machine can fall where on another it
hops. So the final policies' returns that the book quotes are evaluated once, by

    python -m rlbook experiments reevaluate NAME            # writes seed-<s>/final-policy-returns.json

and stored beside each policy with the command, the commit and the processor; :func:`final_policy_returns`
reads them (a stored record whose ``policy.pt`` has changed since is ignored), and evaluates now only where none
is stored. Other re-evaluations a page quotes go through :func:`stored` the same way; a build with
``RLCORE_STORE_REEVALUATIONS=1`` writes those it computes.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rlbook.results import RunResults, SeedResult

_FINALS: dict[tuple, Any] = {}
FINAL = "final-policy-returns"
"""The name of the stored final-policy re-evaluation (``seed-<s>/final-policy-returns.json``)."""
STORE = "RLCORE_STORE_REEVALUATIONS"
"""Set to 1, :func:`stored` writes what it computes (``RLCORE_STORE_REEVALUATIONS=1 jupyter-book build .``)."""


def _policy_sha256(s: SeedResult) -> str:
    return hashlib.sha256(s.policy_path.read_bytes()).hexdigest()


def stored(s: SeedResult, name: str, params: dict[str, Any], compute: Callable[[], dict[str, Any]],
           write: bool | None = None) -> dict[str, Any]:
    """A re-evaluation of seed ``s``'s final policy that a page quotes: read from ``seed-<s>/<name>.json`` where it
    was stored with the same ``params`` for the same ``policy.pt``; otherwise ``compute()`` now, and, with ``write``
    (default: the environment variable ``RLCORE_STORE_REEVALUATIONS=1``), store it there with the command, the commit
    and the processor (one record per ``params``). ``compute`` returns a dict of numbers and lists of numbers."""
    from rlcore.provenance import run_metadata

    path = s.folder / f"{name}.json"
    sha = _policy_sha256(s)
    records = json.loads(path.read_text())["records"] if path.exists() else []
    for record in records:
        if record["params"] == params and record["policy_sha256"] == sha:
            return record["value"]
    value = compute()
    from_a_page = write is None and os.environ.get(STORE) == "1"
    if write or from_a_page:
        meta = run_metadata()  # names the processor (machine.cpu)
        if from_a_page:  # inside a page's kernel the process's own command line says nothing
            meta["command"] = f"{STORE}=1 jupyter-book build .  # computed by the page that quotes it"
        records = [r for r in records if r["params"] != params]
        records.append({"params": params, "value": value, "policy_sha256": sha, **meta})
        path.write_text(json.dumps({"name": name, "records": records}, indent=1) + "\n")
    return value


def _episodes(s: SeedResult, env_id: str, episodes: int, first_reset_seed: int,
              env_kwargs: dict[str, Any] | None = None) -> dict[str, list]:
    """Per-episode returns and lengths of ``s``'s final policy, episode ``i`` from ``reset(seed=first_reset_seed + i)``,
    evaluated now."""
    from rlcore.envs import make_env
    from rlcore.evaluate import episode_rewards

    env = make_env(env_id, **(env_kwargs or {}))
    try:
        rewards = episode_rewards(s.policy, env, episodes=episodes, seed=first_reset_seed)
    finally:
        env.close()
    return {"returns": [float(r.sum()) for r in rewards], "lengths": [len(r) for r in rewards]}


def stored_returns(s: SeedResult, env_id: str, episodes: int, first_reset_seed: int) -> np.ndarray:
    """Per-episode returns of ``s``'s final policy, episode ``i`` from ``reset(seed=first_reset_seed + i)``:
    :func:`stored` as ``returns``, else evaluated now."""
    params = {"env_id": env_id, "episodes": episodes, "first_reset_seed": first_reset_seed}
    value = stored(s, "returns", params,
                   lambda: {"returns": _episodes(s, env_id, episodes, first_reset_seed)["returns"]})
    return np.asarray(value["returns"], dtype=float)


def stored_reward_anatomy(s: SeedResult, env_id: str, episodes: int, first_reset_seed: int) -> dict[str, float]:
    """:func:`rlbook.mujoco_analysis.reward_anatomy` of ``s``'s final policy: :func:`stored` as ``reward-anatomy``,
    else computed now."""
    from rlbook.mujoco_analysis import reward_anatomy

    params = {"env_id": env_id, "episodes": episodes, "first_reset_seed": first_reset_seed}
    return stored(s, "reward-anatomy", params,
                  lambda: reward_anatomy(s.policy, env_id, episodes, seed=first_reset_seed))


def fresh_seed_scores(run: RunResults, episodes: int = 10, first_reset_seed: int = 20_000) -> np.ndarray:
    """Each finished seed's score, in the order of ``run.seeds``: the mean return of its final policy on ``episodes``
    fresh episodes (:func:`stored_returns`, seed ``s`` from ``reset(seed=first_reset_seed + s + i)``)."""
    return np.array([stored_returns(s, run.spec.env_id, episodes, first_reset_seed + s.seed).mean()
                     for s in run.seeds])


def fresh_iqm_rows(arms: dict[str, RunResults], episodes: int = 10, first_reset_seed: int = 20_000,
                   min_seeds: int = 3) -> list[dict[str, str]]:
    """One table row per algorithm (label -> run): each finished seed's final policy on ``episodes`` fresh episodes
    (:func:`fresh_seed_scores`), its mean as the seed's score, and the interquartile mean over seeds with its 95 %
    bootstrap interval (:func:`rlbook.analysis.iqm_ci`) and the lowest seed. An arm with fewer than ``min_seeds``
    finished seeds is listed without a summary, saying how many it has: no IQM is drawn from fewer."""
    from rlbook.analysis import iqm_ci

    rows = []
    for label, run in arms.items():
        scores = fresh_seed_scores(run, episodes, first_reset_seed)
        row = {"algorithm": label, "task": run.spec.env_id, "steps": f"{run.spec.steps:,}",
               "finished seeds": f"{len(scores)} of {len(run.spec.seeds)}"}
        if len(scores) >= min_seeds:
            iqm, low, high = iqm_ci({label: scores})[label]
            row |= {f"IQM over seeds (mean of {episodes} fresh episodes each)": f"{iqm:,.0f}",
                    "95 % interval": f"{low:,.0f} to {high:,.0f}", "lowest seed": f"{scores.min():,.0f}"}
        else:
            row |= {f"IQM over seeds (mean of {episodes} fresh episodes each)": f"waits for {min_seeds} seeds",
                    "95 % interval": "—", "lowest seed": "—"}
        rows.append(row)
    return rows


def _final_episodes(s: SeedResult, env_id: str, env_kwargs: dict[str, Any], episodes: int,
                    write: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
    params = {"episodes": episodes, "first_reset_seed": s.seed + 10_000,
              "what": "per-episode return and length of the final deterministic policy (policy.pt), episode i "
                      "from reset(seed=first_reset_seed + i)"}
    value = stored(s, FINAL, params, lambda: _episodes(s, env_id, episodes, s.seed + 10_000, env_kwargs), write)
    return np.asarray(value["returns"], dtype=float), np.asarray(value["lengths"])


def final_policy_episodes(run: RunResults, episodes: int = 5) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per seed of ``run`` (in order), the per-episode returns and lengths of its final deterministic policy
    (``policy.pt``) over ``episodes`` episodes from the start states of the evaluations logged during training
    (episode ``i`` from ``reset(seed=seed + 10_000 + i)``): as stored (:func:`stored`), or, where none is stored,
    evaluated now. Computed once per run and number of episodes."""
    key = (tuple(str(s.folder) for s in run.seeds), episodes)
    if key not in _FINALS:
        kwargs = run.spec.overrides.get("env_kwargs", {})
        _FINALS[key] = [_final_episodes(s, run.spec.env_id, kwargs, episodes) for s in run.seeds]
    return _FINALS[key]


def final_policy_returns(run: RunResults, episodes: int = 5) -> np.ndarray:
    """Every seed's final deterministic policy: the mean return of its :func:`final_policy_episodes`. On the
    processor that trained it, a policy evaluated after the fix reproduces its last logged evaluation."""
    key = ("mean", tuple(str(s.folder) for s in run.seeds), episodes)
    if key not in _FINALS:
        _FINALS[key] = np.array([returns.mean() for returns, _ in final_policy_episodes(run, episodes)])
    return _FINALS[key]


def store_final_policy_returns(run: RunResults, episodes: int = 5,
                               seeds: Sequence[int] | None = None) -> list[Path]:
    """Evaluate the final policy of every finished seed (of ``seeds`` only, if given) now as
    :func:`final_policy_episodes` does and store it (``seed-<s>/final-policy-returns.json``); the paths written.
    Other seeds' stored files are left as they are."""
    if run.source != "results":
        raise ValueError(f"{run.spec.name}: only finished runs in results/ have stored re-evaluations")
    chosen = [s for s in run.seeds if seeds is None or s.seed in seeds]
    for s in chosen:
        path = s.folder / f"{FINAL}.json"
        path.unlink(missing_ok=True)
        _final_episodes(s, run.spec.env_id, run.spec.overrides.get("env_kwargs", {}), episodes, write=True)
    _FINALS.clear()
    return [s.folder / f"{FINAL}.json" for s in chosen]


def trained_before_clipping_fix(run: RunResults) -> np.ndarray:
    """Per seed: whether its saved policy was written before PPO's deterministic policy clipped its actions
    (:func:`rlcore.onpolicy.evaluated_unclipped`), so that the evaluations in its ``eval.csv`` paid the control cost
    on unclipped actions."""
    from rlcore.checkpoint import load_checkpoint
    from rlcore.onpolicy import evaluated_unclipped

    return np.array([evaluated_unclipped(load_checkpoint(s.folder / "policy.pt")) for s in run.seeds], dtype=bool)


def action_clipping_returns(policy: Any, env_id: str, episodes: int = 2, seed: int = 20_000,
                            sample_seed: int = 0) -> dict[str, float]:
    """A PPO policy (:class:`rlcore.onpolicy.ActorCriticPolicy`) run three ways on the same ``episodes`` start states:

    - ``"clipped"``: the Gaussian's mean action clipped to the action space (what every evaluation does);
    - ``"unclipped"``: the mean action as the network gives it (what evaluations did before the fix);
    - ``"sampled"``: actions sampled from the Gaussian and clipped (what training ran), torch seeded ``sample_seed``;

    each the mean return over the episodes, and ``"outside"``: the share of the mean action's components outside
    the action space along the clipped episodes.
    """
    import torch

    from rlcore.envs import make_env
    from rlcore.evaluate import evaluate_policy

    agent, low, high = policy.agent, policy.low, policy.high
    means: list[np.ndarray] = []

    def mean_action(obs):
        with torch.no_grad():
            means.append(agent.actor(policy.observation(obs))[0].numpy())
        return means[-1]

    def sampled(obs):
        with torch.no_grad():
            return np.clip(agent.distribution(policy.observation(obs)).sample()[0].numpy(), low, high)

    env = make_env(env_id)
    try:
        clipped = evaluate_policy(lambda o: np.clip(mean_action(o), low, high), env, episodes=episodes, seed=seed)
        m = np.array(means)
        outside = float(np.mean((m < low) | (m > high)))
        unclipped = evaluate_policy(mean_action, env, episodes=episodes, seed=seed)
        torch.manual_seed(sample_seed)
        sample = evaluate_policy(sampled, env, episodes=episodes, seed=seed)
    finally:
        env.close()
    return {"clipped": float(clipped.mean()), "unclipped": float(unclipped.mean()), "sampled": float(sample.mean()),
            "outside": outside}
