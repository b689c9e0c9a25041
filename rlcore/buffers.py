"""Replay memories: a preallocated ring buffer, a sum tree, and prioritized replay.

All storage is NumPy, preallocated at construction: adding a transition is a few array writes,
sampling a batch is one fancy-indexing gather per field.

Every transition keeps ``terminated`` (the episode really ended: no future value) separate from a
time-limit truncation, which is *not* stored as an end: the target still bootstraps from ``next_obs``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class Batch:
    """A minibatch of transitions; ``indices`` and ``weights`` matter for prioritized replay."""

    obs: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_obs: np.ndarray
    terminated: np.ndarray
    indices: np.ndarray
    weights: np.ndarray


class ReplayBuffer:
    """A fixed-size FIFO of transitions ``(s, a, r, s', terminated)``, sampled uniformly."""

    def __init__(self, capacity: int, obs_shape: tuple[int, ...], action_shape: tuple[int, ...] = (),
                 action_dtype: Any = np.int64, seed: int | None = None):
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self.obs = np.zeros((capacity, *obs_shape), dtype=np.float32)
        self.next_obs = np.zeros((capacity, *obs_shape), dtype=np.float32)
        self.actions = np.zeros((capacity, *action_shape), dtype=action_dtype)
        self.rewards = np.zeros(capacity, dtype=np.float32)
        self.terminated = np.zeros(capacity, dtype=np.float32)
        self.pos = 0
        self.size = 0
        self.rng = np.random.default_rng(seed)

    def __len__(self) -> int:
        return self.size

    def add(self, obs, action, reward: float, next_obs, terminated: bool) -> int:
        """Store one transition, overwriting the oldest when full; returns its slot."""
        i = self.pos
        self.obs[i] = obs
        self.actions[i] = action
        self.rewards[i] = reward
        self.next_obs[i] = next_obs
        self.terminated[i] = terminated
        self.pos = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)
        return i

    def _gather(self, idx: np.ndarray, weights: np.ndarray) -> Batch:
        return Batch(self.obs[idx], self.actions[idx], self.rewards[idx], self.next_obs[idx],
                     self.terminated[idx], idx, weights)

    def sample(self, batch_size: int) -> Batch:
        """A uniformly random minibatch (with replacement); all weights are 1."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        idx = self.rng.integers(0, self.size, size=batch_size)
        return self._gather(idx, np.ones(batch_size, dtype=np.float32))

    def state_dict(self) -> dict[str, Any]:
        """The memory as a checkpoint keeps it. Within an episode a transition's next observation is the next slot's
        observation, so ``next_obs`` is kept only for the slots where it is not, bit for bit (episode ends, the
        newest slot, the seam of a full circular memory): about half the bytes of storing both arrays."""
        n = self.size
        rows = self._next_obs_rows()
        return {"obs": self.obs[:n], "next_obs_rows": rows, "next_obs_at_rows": self.next_obs[rows],
                "actions": self.actions[:n], "rewards": self.rewards[:n], "terminated": self.terminated[:n],
                "pos": self.pos, "size": self.size, "rng": self.rng.bit_generator.state}

    def _next_obs_rows(self, block: int = 65_536) -> np.ndarray:
        """Slots i < size whose next_obs differs in any bit from obs[i + 1] (the last slot always counts)."""
        n = self.size
        if n == 0:
            return np.zeros(0, dtype=np.int64)
        # observations are float32: compare their bits, so that -0.0 and 0.0 differ and NaN equals itself
        bits, next_bits = self.obs[:n].reshape(n, -1).view(np.uint32), self.next_obs[:n].reshape(n, -1).view(np.uint32)
        rows = [np.flatnonzero(np.any(next_bits[i:min(i + block, n - 1)] != bits[i + 1:min(i + block, n - 1) + 1],
                                      axis=1)) + i
                for i in range(0, n - 1, block)]
        return np.concatenate([*rows, [n - 1]]).astype(np.int64)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        n = int(state["size"])
        for name in ("obs", "actions", "rewards", "terminated"):
            getattr(self, name)[:n] = np.asarray(state[name])
        if "next_obs" in state:                      # checkpoints written before next_obs was stored once
            self.next_obs[:n] = np.asarray(state["next_obs"])
        elif n > 0:
            self.next_obs[:n - 1] = self.obs[1:n]
            self.next_obs[np.asarray(state["next_obs_rows"])] = np.asarray(state["next_obs_at_rows"])
        self.pos, self.size = int(state["pos"]), n
        self.rng.bit_generator.state = state["rng"]


class SumTree:
    """A binary tree whose leaves hold priorities and whose inner nodes hold the sums below them.

    ``total`` is the root; ``find(mass)`` walks down to the leaf where the running sum passes
    ``mass``: drawing ``mass`` uniformly in ``[0, total)`` picks leaf ``i`` with probability
    ``p_i / total``. Both updates and lookups cost O(log n).
    """

    def __init__(self, capacity: int):
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self.leaves = 1 << (self.capacity - 1).bit_length()  # a power of two >= capacity
        self.tree = np.zeros(2 * self.leaves)  # node k has children 2k and 2k+1; the root is node 1

    @property
    def total(self) -> float:
        return float(self.tree[1])

    def __getitem__(self, idx):
        return self.tree[np.asarray(idx) + self.leaves]

    def update(self, idx, priority) -> None:
        """Set the priority of leaves ``idx`` (ints or an array) and fix the sums above them."""
        idx = np.atleast_1d(np.asarray(idx, dtype=np.int64))
        priority = np.broadcast_to(np.asarray(priority, dtype=float), idx.shape)
        if np.any(priority < 0) or not np.all(np.isfinite(priority)):
            raise ValueError("priorities must be finite and non-negative")
        if np.any((idx < 0) | (idx >= self.capacity)):
            raise IndexError(f"leaf index out of range [0, {self.capacity})")
        if idx.size == 1:  # one leaf (each new transition): its path alone, without array bookkeeping
            tree, node = self.tree, int(idx[0]) + self.leaves
            tree[node] = priority[0]
            node //= 2
            while node >= 1:
                tree[node] = tree[2 * node] + tree[2 * node + 1]
                node //= 2
            return
        nodes = idx + self.leaves
        self.tree[nodes] = priority
        nodes = np.unique(nodes // 2)  # sorted, and halving keeps them sorted: a repeat is next to its twin
        while nodes[0] >= 1:
            self.tree[nodes] = self.tree[2 * nodes] + self.tree[2 * nodes + 1]
            if nodes[0] == 1:
                break
            nodes = nodes // 2
            nodes = nodes[np.concatenate(([True], nodes[1:] != nodes[:-1]))]

    def find(self, mass) -> np.ndarray:
        """Leaf indices where the prefix sum of priorities first exceeds ``mass`` (vectorized)."""
        mass = np.array(mass, dtype=float, ndmin=1)
        node = np.ones(mass.shape, dtype=np.int64)
        while node[0] < self.leaves:  # every path has the same depth
            left = 2 * node
            go_right = mass >= self.tree[left]
            mass = np.where(go_right, mass - self.tree[left], mass)
            node = np.where(go_right, left + 1, left)
        return np.minimum(node - self.leaves, self.capacity - 1)


def importance_weights(probabilities: np.ndarray, size: int, beta: float) -> np.ndarray:
    """w_i = (N * P(i))^-beta / max_j w_j  (Schaul et al. 2016): corrects the bias of non-uniform sampling.

    Normalized by the largest weight in the batch so that updates are only ever scaled down.
    """
    w = (size * np.asarray(probabilities, dtype=float)) ** (-beta)
    return (w / w.max()).astype(np.float32)


class PrioritizedReplayBuffer(ReplayBuffer):
    """Proportional prioritized replay: P(i) = p_i^alpha / sum_k p_k^alpha, with p_i = |delta_i| + eps.

    New transitions get the largest priority seen so far, so each is replayed at least once soon.
    """

    def __init__(self, capacity: int, obs_shape: tuple[int, ...], action_shape: tuple[int, ...] = (),
                 action_dtype: Any = np.int64, seed: int | None = None, alpha: float = 0.6,
                 eps: float = 1e-6):
        super().__init__(capacity, obs_shape, action_shape, action_dtype, seed)
        self.alpha = alpha
        self.eps = eps
        self.tree = SumTree(capacity)
        self.max_priority = 1.0

    def add(self, obs, action, reward: float, next_obs, terminated: bool) -> int:
        i = super().add(obs, action, reward, next_obs, terminated)
        self.tree.update(i, self.max_priority ** self.alpha)
        return i

    def sample(self, batch_size: int, beta: float = 0.4) -> Batch:
        """Sample proportionally to priority (stratified: one draw per equal slice of the total mass)."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        total = self.tree.total
        bounds = np.linspace(0.0, total, batch_size + 1)
        mass = self.rng.uniform(bounds[:-1], bounds[1:])
        idx = np.minimum(self.tree.find(mass), self.size - 1)
        probs = self.tree[idx] / total
        return self._gather(idx, importance_weights(probs, self.size, beta))

    def update_priorities(self, indices: np.ndarray, td_errors: np.ndarray) -> None:
        """p_i <- |delta_i| + eps for the transitions just learned from."""
        priority = np.abs(np.asarray(td_errors, dtype=float)) + self.eps
        self.max_priority = max(self.max_priority, float(priority.max()))
        self.tree.update(indices, priority ** self.alpha)

    def state_dict(self) -> dict[str, Any]:
        return {**super().state_dict(), "priorities": self.tree[np.arange(self.size)],
                "max_priority": self.max_priority}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        self.tree.update(np.arange(self.size), np.asarray(state["priorities"]))
        self.max_priority = float(state["max_priority"])
