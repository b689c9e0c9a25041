"""Returns of a peer library on one task, as `benchmarks/ppo_returns_vs_sb3.py` records them in
``results/benchmarks/ppo-returns-sb3-<task>.json``: per seed, the deterministic policy's evaluations during training
and its returns on fresh episodes at the end, with the command, versions and machine that made them.

A page reads a record with :func:`load_peer` and shows it beside rlcore's runs of the same settings."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rlbook import paths
from rlbook.results import commit_text


def peer_path(env_id: str, results_dir: Path | None = None) -> Path:
    """Where the returns benchmark writes its record for ``env_id`` (``HalfCheetah-v5`` -> ``...-halfcheetah.json``)."""
    results_dir = paths.results_dir() if results_dir is None else results_dir
    return Path(results_dir) / "benchmarks" / f"ppo-returns-sb3-{env_id.split('-')[0].lower()}.json"


def commits(runs: list[dict[str, Any]]) -> str:
    """The distinct commits that made ``runs``, in order, as a page prints them."""
    return ", ".join(dict.fromkeys(commit_text(str(r["commit"])) for r in runs))


def dropdown(title: str, text: str) -> str:
    """A collapsed MyST dropdown holding ``text`` in italics."""
    return f"::::{{dropdown}} {title}\n*{text}*\n::::\n"


def final_episode_count(runs: list[dict[str, Any]], what: str) -> int:
    """The number of episodes in every run's ``final_returns``; a ValueError if ``what`` (the runs) differ."""
    counts = {len(r["final_returns"]) for r in runs}
    if len(counts) != 1:
        raise ValueError(f"{what} have different final-evaluation lengths {sorted(counts)}")
    return counts.pop()


@dataclass(frozen=True)
class PeerRuns:
    """One task's record of the returns benchmark."""

    record: dict[str, Any]

    @property
    def env_id(self) -> str:
        return self.record["env_id"]

    @property
    def seeds(self) -> list[int]:
        return [r["seed"] for r in self.record["seeds"]]

    def curves(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per seed: (environment steps, mean evaluation return) during training, for `plot_learning_curves`."""
        return [(np.asarray(r["evals"]["step"]), np.asarray(r["evals"]["mean_return"])) for r in self.record["seeds"]]

    def final_returns(self) -> np.ndarray:
        """Per seed: the mean return of the final policy's fresh evaluation episodes."""
        return np.array([np.mean(r["final_returns"]) for r in self.record["seeds"]])

    @property
    def final_episodes(self) -> int:
        """Episodes in each seed's final evaluation (the same for every seed of a record)."""
        return final_episode_count(self.record["seeds"], f"{self.env_id}: seeds")

    def provenance_markdown(self) -> str:
        """A collapsed MyST dropdown: library version, seeds, steps, command, commits, versions, machine, evaluation."""
        r, v = self.record, self.record["versions"]
        return dropdown(f"Provenance: Stable-Baselines3 on {self.env_id}",
                        f"Stable-Baselines3 {v['stable_baselines3']}, seeds {', '.join(map(str, self.seeds))}, "
                        f"{r['steps']:,} steps each: `{r['command']}` at commit {commits(r['seeds'])}; PyTorch "
                        f"{v['torch']}, Gymnasium {v['gymnasium']}, {r['machine']['cpu_count']} CPUs. Its evaluation: "
                        f"{r['evaluation']}.")


def load_peer(env_id: str, results_dir: Path | None = None) -> PeerRuns | None:
    """The record for ``env_id``, or None when there is none or it holds no finished seed yet."""
    path = peer_path(env_id, results_dir)
    if not path.exists():
        return None
    record = json.loads(path.read_text())
    if record.get("env_id") != env_id:
        raise ValueError(f"{path} records {record.get('env_id')!r}, not {env_id!r}")
    return PeerRuns(record) if record.get("seeds") else None


# --- DQN on CartPole: does it forget, or does rlcore's? -------------------------------------------------------


def forgetting_path(results_dir: Path | None = None) -> Path:
    """Where `benchmarks/dqn_forgetting_vs_sb3.py` writes its record."""
    results_dir = paths.results_dir() if results_dir is None else results_dir
    return Path(results_dir) / "benchmarks" / "dqn-forgetting-vs-sb3.json"


@dataclass(frozen=True)
class ForgettingRecord:
    """rlcore's DQN and SB3's DQN on CartPole-v1 with the same RL-Zoo settings: each seed's final greedy policy on
    fresh episodes (``benchmarks/dqn_forgetting_vs_sb3.py``)."""

    record: dict[str, Any]

    @property
    def seeds(self) -> list[int]:
        """The seeds both libraries finished, so that every comparison is over the same seeds."""
        done = [{r["seed"] for r in self.record["runs"] if r["impl"] == impl} for impl in ("rlcore", "sb3")]
        return sorted(done[0] & done[1])

    def finals(self, impl: str) -> np.ndarray:
        """Per seed (in :attr:`seeds` order): the mean return of ``impl``'s final policy on the fresh episodes."""
        by_seed = {r["seed"]: np.mean(r["final_returns"]) for r in self.record["runs"] if r["impl"] == impl}
        return np.array([by_seed[s] for s in self.seeds])

    def holds(self, impl: str) -> np.ndarray:
        """Per seed: whether ``impl``'s final policy averages at least the record's ``solved`` threshold."""
        return self.finals(impl) >= self.record["solved"]

    @property
    def final_episodes(self) -> int:
        """Episodes in each run's final evaluation (the same for every run of the record)."""
        return final_episode_count(self.record["runs"], "runs")

    def provenance_markdown(self) -> str:
        """A collapsed MyST dropdown: seeds, steps, command, commits, versions, machine, evaluation."""
        r, v = self.record, self.record["versions"]
        return dropdown(f"Provenance: rlcore's and Stable-Baselines3's DQN on {r['env_id']}",
                        f"rlcore {v['rlcore']} and Stable-Baselines3 {v['stable_baselines3']}, seeds "
                        f"{self.seeds[0]}–{self.seeds[-1]} ({len(self.seeds)} each), {r['steps']:,} steps each, the "
                        f"same settings (rlcore's `dqn.Config()` defaults, the RL Zoo's): `{r['command']}` at commit "
                        f"{commits(r['runs'])}; PyTorch {v['torch']}, Gymnasium {v['gymnasium']}, "
                        f"{r['machine']['cpu_model']}, one torch thread per run. Evaluation: {r['evaluation']}.")


def load_forgetting(results_dir: Path | None = None) -> ForgettingRecord | None:
    """The record, or None when there is none or no seed that both libraries finished."""
    path = forgetting_path(results_dir)
    if not path.exists():
        return None
    record = ForgettingRecord(json.loads(path.read_text()))
    return record if record.seeds else None
