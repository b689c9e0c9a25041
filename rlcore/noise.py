"""Exploration noise for deterministic policies (chapter 5).

- :class:`GaussianNoise`: independent N(0, sigma^2) per action dimension, sigma multiplied by ``decay``
  every step (the course report's ``explore-decay``).
- :class:`OrnsteinUhlenbeckNoise`: temporally correlated noise, dx = theta (mu - x) dt + sigma sqrt(dt) N(0, 1)
  (Lillicrap et al. 2016).
- :class:`AdaptiveParamNoise`: perturb the actor's *weights* instead of its actions, with a scale adapted
  so that the perturbed actor's actions stay about ``target_distance`` away from the unperturbed ones
  (Plappert et al. 2018). The distance is measured on a fresh perturbation of the *current* actor, as in
  OpenAI Baselines' ``adapt_param_noise``: the behaviour policy of the episode that just ended was perturbed from
  an older actor, and its distance would also count the training in between.

  What DDPG runs with it is not Baselines' parameter noise (``baselines/ddpg/main.py``, the paper's script, by default
  ``--noise-type adaptive-param_0.2``): sigma adapts once per episode, at its end (Baselines: once per cycle of 100
  environment steps, ``param_noise_adaption_interval=50`` within each cycle's 50 training steps); the distance and its
  target are in the environment's action units, the actor's output scaled to the box (Baselines: the tanh output in
  [-1, 1], i.e. half-ranges, the unit of the other noises here; the same on a [-1, 1] box); the actor has no layer
  normalization and every parameter is perturbed (that script: layer norm after every hidden layer, on by default, its
  gains and biases unperturbed); sigma starts at ``initial_sigma`` (Baselines: at the target).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch
from torch import nn

from rlcore.checkpoint import Saved


# [gaussian-noise]
class GaussianNoise:
    """a + N(0, sigma^2), sigma <- sigma * decay after every sample."""

    def __init__(self, size: int, sigma: float = 0.1, decay: float = 1.0, seed: int | None = None):
        self.size, self.sigma, self.decay = size, sigma, decay
        self.rng = np.random.default_rng(seed)

    def __call__(self) -> np.ndarray:
        x = self.rng.normal(0.0, self.sigma, self.size)
        self.sigma *= self.decay
        return x

    def reset(self) -> None:
        pass

    # [/gaussian-noise]
    def state_dict(self) -> dict:
        """What a checkpoint needs to continue the same noise sequence: sigma and the generator's state."""
        return {"sigma": self.sigma, "rng": self.rng.bit_generator.state}

    def load_state_dict(self, state: dict) -> None:
        self.sigma = float(state["sigma"])
        self.rng.bit_generator.state = state["rng"]


# [ou-noise]
class OrnsteinUhlenbeckNoise:
    """x_{t+1} = x_t + theta (mu - x_t) dt + sigma sqrt(dt) eps_t: mean-reverting, temporally correlated.

    Its stationary distribution is N(mu, sigma^2 / (2 theta)) (for small dt).
    """

    def __init__(self, size: int, mu: float = 0.0, theta: float = 0.15, sigma: float = 0.2, dt: float = 1e-2,
                 seed: int | None = None):
        self.mu, self.theta, self.sigma, self.dt = mu, theta, sigma, dt
        self.rng = np.random.default_rng(seed)
        self.x = np.full(size, mu, dtype=float)

    def __call__(self) -> np.ndarray:
        self.x = (self.x + self.theta * (self.mu - self.x) * self.dt
                  + self.sigma * np.sqrt(self.dt) * self.rng.normal(size=self.x.shape))
        return self.x.copy()

    def reset(self) -> None:
        self.x[:] = self.mu

    # [/ou-noise]
    def state_dict(self) -> dict:
        """The process's current value and the generator's state."""
        return {"x": self.x.tolist(), "rng": self.rng.bit_generator.state}

    def load_state_dict(self, state: dict) -> None:
        self.x = np.asarray(state["x"], dtype=float)
        self.rng.bit_generator.state = state["rng"]


def action_distance(actor_a: torch.nn.Module, actor_b: torch.nn.Module, obs: torch.Tensor) -> float:
    """d = sqrt(mean over states and action dimensions of (mu_a(s) - mu_b(s))^2)."""
    with torch.no_grad():
        return float(torch.sqrt(((actor_a(obs) - actor_b(obs)) ** 2).mean()).item())


# [param-noise]
class AdaptiveParamNoise:
    """A perturbed copy of the actor, w~ = w + N(0, sigma^2) on its weights w, with sigma adapted to a target distance.

    At each episode's end: :meth:`adapt_to` perturbs a separate copy of the current actor with the current sigma,
    measures d = distance(mu(s), mu~(s)) on a minibatch of states, and moves sigma (``adapt``: sigma <- sigma / alpha
    if d is above the target, sigma * alpha otherwise); then :meth:`perturb` makes the next episode's behaviour
    policy from the current actor with the new sigma.
    """

    def __init__(self, initial_sigma: float = 0.1, target_distance: float = 0.2, alpha: float = 1.01,
                 seed: int | None = None):
        self.sigma, self.target_distance, self.alpha = initial_sigma, target_distance, alpha
        self.generator = torch.Generator().manual_seed(0 if seed is None else seed)
        self.perturbed: torch.nn.Module | None = None

    def perturb(self, actor: torch.nn.Module) -> torch.nn.Module:
        """A fresh perturbed copy of ``actor`` (call at the start of each episode)."""
        self.perturbed = self.perturbed_copy(actor)
        return self.perturbed

    def perturbed_copy(self, actor: torch.nn.Module) -> torch.nn.Module:
        """w + N(0, sigma^2 I) on the weights w of a copy of ``actor`` (the behaviour policy is left as it is)."""
        copy_ = copy.deepcopy(actor)
        with torch.no_grad():
            for p in copy_.parameters():
                p.add_(torch.randn(p.shape, generator=self.generator) * self.sigma)
        return copy_

    # [param-noise-adapt]
    def adapt_to(self, actor: torch.nn.Module, states: torch.Tensor) -> float:
        """Adapt sigma to the distance a perturbation of the *current* actor makes on ``states``; returns it."""
        distance = action_distance(actor, self.perturbed_copy(actor), states)
        self.adapt(distance)
        return distance
    # [/param-noise-adapt]

    def adapt(self, distance: float) -> float:
        """Move sigma toward the target action distance; returns the new sigma."""
        self.sigma = self.sigma / self.alpha if distance > self.target_distance else self.sigma * self.alpha
        return self.sigma

    # [/param-noise]
    def state_dict(self) -> dict:
        """sigma, the generator's state and the current perturbed actor's weights."""
        return {"sigma": self.sigma, "generator": self.generator.get_state(),
                "perturbed": None if self.perturbed is None else self.perturbed.state_dict()}

    def load_state_dict(self, state: dict, actor: torch.nn.Module) -> None:
        """Restore; ``perturbed`` becomes a copy of ``actor`` with the saved perturbed weights (if any)."""
        self.sigma = float(state["sigma"])
        self.generator.set_state(state["generator"])
        self.perturbed = None
        if state["perturbed"] is not None:
            self.perturbed = copy.deepcopy(actor)
            self.perturbed.load_state_dict(state["perturbed"])


# --- choosing and keeping the exploration of a DDPG run ----------------------------------------


def make_exploration(config: Any, act_dim: int, seed: int) -> tuple[Any, AdaptiveParamNoise | None]:
    """``(action noise or None, parameter noise or None)`` for a DDPG Config's ``exploration`` (``gaussian``, ``ou``,
    ``param`` or ``none``), with its ``noise_sigma``, ``explore_decay`` and ``param_noise_target``."""
    if config.exploration == "gaussian":
        return GaussianNoise(act_dim, config.noise_sigma, config.explore_decay, seed=seed), None
    if config.exploration == "ou":
        return OrnsteinUhlenbeckNoise(act_dim, sigma=config.noise_sigma, seed=seed), None
    if config.exploration == "param":
        return None, AdaptiveParamNoise(config.noise_sigma, config.param_noise_target, seed=seed)
    return None, None


def noise_sigma(noise: Any, param_noise: AdaptiveParamNoise | None) -> float:
    """The exploration's current scale (0 without noise)."""
    return float(getattr(param_noise if param_noise is not None else noise, "sigma", 0.0))


def exploration_state(noise: Any, param_noise: AdaptiveParamNoise | None, actor: nn.Module) -> Saved:
    """The noise's generator and state in a checkpoint (``noise``, beside its scale ``noise_sigma``), so that a
    resumed run continues as if never stopped. A checkpoint without ``noise`` (from before rlcore saved it) cannot
    resume the run: :meth:`rlcore.harness.Run.resume` refuses it in one line, as any checkpoint that lacks what the
    run restores."""
    source = param_noise if param_noise is not None else noise

    def save() -> dict[str, Any]:
        return {"noise_sigma": noise_sigma(noise, param_noise),
                **({"noise": source.state_dict()} if source is not None else {})}

    def load(ckpt: dict[str, Any]) -> None:
        if param_noise is not None:
            param_noise.load_state_dict(ckpt["noise"], actor)
        elif noise is not None:
            noise.load_state_dict(ckpt["noise"])

    return Saved(save, load)


def first_behaviour(actor: nn.Module, param_noise: AdaptiveParamNoise | None) -> nn.Module:
    """The network that acts first: the actor, or with parameter noise the perturbed actor a checkpoint restored
    (or a fresh perturbation)."""
    if param_noise is None:
        return actor
    return param_noise.perturbed if param_noise.perturbed is not None else param_noise.perturb(actor)
