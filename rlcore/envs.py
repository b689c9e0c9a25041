"""Environment construction and seeding, on Gymnasium and its own wrappers.

Every environment in the book is made here, so that every chapter and every algorithm gets the
same things: a checked environment id (with suggestions when it is misspelled), episode statistics
from :class:`gymnasium.wrappers.RecordEpisodeStatistics`, and seeded action/observation spaces.
"""

from __future__ import annotations

import difflib
from typing import Any

import gymnasium as gym
import numpy as np
import torch


class UnknownEnvironmentError(ValueError):
    """Raised for an environment id that Gymnasium does not know."""


def registered_env_ids() -> list[str]:
    """All environment ids registered with Gymnasium (including ``-v5`` MuJoCo tasks)."""
    return sorted(gym.envs.registry.keys())


def suggest_env_ids(env_id: str, n: int = 3) -> list[str]:
    """Registered ids closest to ``env_id`` (case-insensitive), best first."""
    ids = registered_env_ids()
    by_lower = {i.lower(): i for i in ids}
    close = difflib.get_close_matches(env_id.lower(), list(by_lower), n=n, cutoff=0.6)
    return [by_lower[c] for c in close]


def check_env_id(env_id: str) -> None:
    """Raise :class:`UnknownEnvironmentError` if ``env_id`` is not registered, suggesting close ids."""
    if env_id in gym.envs.registry:
        return
    suggestions = suggest_env_ids(env_id)
    hint = f" Did you mean {' or '.join(repr(s) for s in suggestions)}?" if suggestions else ""
    raise UnknownEnvironmentError(
        f"Unknown environment id {env_id!r}.{hint} "
        "Ids are case-sensitive and carry a version, e.g. 'Hopper-v5' or 'CartPole-v1'; "
        "`python -c \"import gymnasium; print(*gymnasium.envs.registry, sep=chr(10))\"` lists them all."
    )


def is_mujoco(env_id: str) -> bool:
    """True for a task simulated (and drawn) by MuJoCo."""
    return "mujoco" in str(gym.spec(env_id).entry_point)


SHADOW_SIZE = 1024
"""The side of the shadow map, in texels, of a MuJoCo task rendered offscreen (MuJoCo's default is 4096). The book
renders 320 x 240 frames with a software OpenGL (Mesa) on the CPU, where drawing the 4096 x 4096 shadow map is most
of a frame's cost: at 1024 a Humanoid-v5 frame costs about 40 % less CPU time and the shadows look the same at
that size (``benchmarks/render_cost.py``, ``results/benchmarks/render-cost.json``)."""


def make_env(
    env_id: str,
    seed: int | None = None,
    render_mode: str | None = None,
    record_stats: bool = True,
    **gym_kwargs: Any,
) -> gym.Env:
    """Make one Gymnasium environment, the way every chapter does.

    The id is checked first (a typo gets suggestions, not a registry traceback). Rendering to
    ``rgb_array`` picks a headless OpenGL backend for a MuJoCo task (other tasks draw without OpenGL).
    Its shadows are drawn from a smaller map than MuJoCo's own (:data:`SHADOW_SIZE`). ``RecordEpisodeStatistics``
    puts the episode's return and length into ``info["episode"]`` when it ends. The
    action and observation spaces are seeded with ``seed``; seed the first ``reset`` with the same number:
    ``obs, info = env.reset(seed=seed)``.
    """
    check_env_id(env_id)
    if render_mode == "rgb_array" and is_mujoco(env_id):
        from rlcore.gl import select_gl_backend

        select_gl_backend()
    env = gym.make(env_id, render_mode=render_mode, **gym_kwargs)
    if render_mode == "rgb_array" and is_mujoco(env_id):
        env.unwrapped.model.vis.quality.shadowsize = SHADOW_SIZE  # read when the first render makes the GL context
    if record_stats:
        env = gym.wrappers.RecordEpisodeStatistics(env)
    if seed is not None:
        env.action_space.seed(seed)
        env.observation_space.seed(seed)
    return env


def make_vec_env(
    env_id: str,
    num_envs: int,
    seed: int = 0,
    vectorization_mode: str = "sync",
    **gym_kwargs: Any,
) -> gym.vector.VectorEnv:
    """Make ``num_envs`` copies of an environment as a Gymnasium vector environment.

    Each copy records its episode statistics. Seed the first reset with ``envs.reset(seed=seed)``:
    Gymnasium then gives copy ``i`` the seed ``seed + i``.
    """
    check_env_id(env_id)
    envs = gym.make_vec(
        env_id,
        num_envs=num_envs,
        vectorization_mode=vectorization_mode,
        wrappers=[gym.wrappers.RecordEpisodeStatistics],
        **gym_kwargs,
    )
    envs.action_space.seed(seed)
    envs.observation_space.seed(seed)
    return envs


def episode_seed(seed: int, episode: int) -> int:
    """The reset seed of episode ``episode`` of a run seeded ``seed`` (independent of interruptions)."""
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


def is_discrete(space: gym.Space) -> bool:
    """True for a ``Discrete`` space."""
    return isinstance(space, gym.spaces.Discrete)


def space_shape(space: gym.Space) -> tuple[int, ...]:
    """Shape of a space for a table: ``(n,)`` for ``Discrete(n)``, ``space.shape`` otherwise."""
    if isinstance(space, gym.spaces.Discrete):
        return (int(space.n),)
    return tuple(space.shape)


def normalize_observation(obs, mean, var, clip: float = 10.0) -> np.ndarray:
    """(obs - mean) / sqrt(var + 1e-8), clipped to +-clip: Gymnasium's NormalizeObservation with given statistics
    (and the clipping of SB3's VecNormalize). Policies apply their training's statistics with it."""
    return np.clip((np.asarray(obs, dtype=np.float64) - mean) / np.sqrt(var + 1e-8), -clip, clip)


class ObservationScaler:
    """Running observation statistics and the scaling :func:`normalize_observation` does, for a training loop.

    ``update(obs)`` adds one observation to the statistics (Gymnasium's ``RunningMeanStd`` in float64, updated
    incrementally: Chan et al.'s parallel rule with a batch of one). ``scale(x)`` scales a batch of raw observations
    in float32 torch, with the statistics as they are now; the float32 mean and 1/std are cached between updates,
    so scaling a minibatch costs two tensor operations. ``rms`` is what a checkpoint and the saved policy keep.
    """

    def __init__(self, obs_dim: int, clip: float = 10.0):
        from gymnasium.wrappers.utils import RunningMeanStd

        self.rms = RunningMeanStd(shape=(obs_dim,))
        self.clip = clip
        self._cached: tuple[torch.Tensor, torch.Tensor] | None = None

    def update(self, obs: np.ndarray) -> None:
        rms, x = self.rms, np.asarray(obs, dtype=np.float64)
        total = rms.count + 1.0
        delta = x - rms.mean
        rms.var = (rms.var * rms.count + delta**2 * rms.count / total) / total
        rms.mean = rms.mean + delta / total
        rms.count = total
        self._cached = None

    def scale(self, x: np.ndarray) -> torch.Tensor:
        if self._cached is None:
            self._cached = (torch.as_tensor(self.rms.mean, dtype=torch.float32),
                            torch.as_tensor(1.0 / np.sqrt(self.rms.var + 1e-8), dtype=torch.float32))
        mean, inv_std = self._cached
        return ((torch.as_tensor(x, dtype=torch.float32) - mean) * inv_std).clamp_(-self.clip, self.clip)

    def loaded(self) -> None:
        """Call after the statistics in ``rms`` were replaced (a checkpoint was loaded)."""
        self._cached = None


def find_wrapper(env: Any, cls: type) -> Any:
    """The wrapper of type ``cls`` in ``env``'s chain of wrappers (``env`` itself included), or None."""
    while not isinstance(env, cls):
        if not hasattr(env, "env"):
            return None
        env = env.env
    return env


def env_setting(env_id: str, name: str) -> Any:
    """A setting of a registered environment, as ``gymnasium.make(env_id)`` would use it: the registration's keyword
    argument if it gives one, else the default of the environment class's constructor (``healthy_z_range``, say),
    read through public APIs only."""
    import inspect

    check_env_id(env_id)
    spec = gym.spec(env_id)
    if name in spec.kwargs:
        return spec.kwargs[name]
    entry = spec.entry_point
    cls = gym.envs.registration.load_env_creator(entry) if isinstance(entry, str) else entry
    params = inspect.signature(cls).parameters
    if name not in params or params[name].default is inspect.Parameter.empty:
        raise ValueError(f"{env_id} has no setting {name!r} with a default; its settings: "
                         f"{', '.join(p for p in params if p not in ('self', 'kwargs'))}")
    return params[name].default


# --- an episode in progress, in a checkpoint ------------------------------------------------------

EPISODE_COUNTERS = ("_elapsed_steps", "episode_returns", "episode_lengths")
"""What a wrapper counts within an episode (TimeLimit; RecordEpisodeStatistics's return and length so far)."""
CLASSIC_STATE = ("state", "steps_beyond_terminated", "last_u")
"""What a classic-control task keeps between steps (CartPole, Pendulum, MountainCar, Acrobot)."""
VECTOR_COUNTERS = ("accumulated_reward", "_prev_dones", "episode_returns", "episode_lengths", "prev_dones")
"""What a vector wrapper keeps between steps (NormalizeReward's discounted return so far; RecordEpisodeStatistics's)."""


def _chain(env: Any) -> list[Any]:
    """``env``'s wrappers, outermost first, and the environment itself last."""
    chain = [env]
    while isinstance(chain[-1], (gym.Wrapper, gym.vector.VectorWrapper)):
        chain.append(chain[-1].env)
    return chain


def _vector_episode_state(chain: list[Any]) -> dict[str, Any] | None:
    """:func:`episode_state` of a :class:`gymnasium.vector.SyncVectorEnv` (with its vector wrappers): each copy's
    episode, which copies reset on their next step, and the wrappers' counters."""
    base = chain[-1]
    if not isinstance(base, gym.vector.SyncVectorEnv):
        return None  # an AsyncVectorEnv's copies live in other processes
    copies = [episode_state(env) for env in base.envs]
    if any(c is None for c in copies):
        return None
    return {"wrappers": [type(w).__name__ for w in chain[:-1]],
            "counters": [{k: np.array(v) for k, v in vars(w).items() if k in VECTOR_COUNTERS} for w in chain[:-1]],
            "autoreset": np.array(base._autoreset_envs), "copies": copies}


def _array(value: Any) -> np.ndarray:
    """A NumPy copy of an array that a checkpoint may have stored as a tensor."""
    return value.numpy().copy() if isinstance(value, torch.Tensor) else np.array(value)


def pending_resets(envs: gym.vector.VectorEnv) -> np.ndarray:
    """Which copies of ``envs`` ended an episode on the last step, and so reset on the next one (Gymnasium's
    next-step autoreset): False for all just after ``envs.reset``."""
    base = _chain(envs)[-1]
    return np.array(getattr(base, "_autoreset_envs", np.zeros(envs.num_envs, dtype=bool)), dtype=bool)


def episode_state(env: gym.Env) -> dict[str, Any] | None:
    """What it takes to go on with ``env``'s episode in progress, bit for bit, in a fresh copy of the environment
    (:func:`restore_episode`): the simulator's state, each wrapper's counters, the environment's generator. For
    a MuJoCo task the simulator's state is MuJoCo's whole ``MjData`` (about 0.7 MB: the next step reads some of
    its derived quantities, the centre of mass for one, as the last step left them); for a classic-control task,
    its state vector. None where the simulator cannot be saved (Box2D's LunarLander, say): a resumed run then
    starts a new episode. For a vector environment (synchronous), each copy's, with the vector wrappers' counters.
    """
    chain = _chain(env)
    base = chain[-1]
    if isinstance(base, gym.vector.VectorEnv):
        return _vector_episode_state(chain)
    if hasattr(base, "data") and type(base).__module__.startswith("gymnasium.envs.mujoco"):
        simulator = {"mujoco_data": np.frombuffer(base.data.__getstate__(), dtype=np.uint8).copy()}
    elif type(base).__module__.startswith("gymnasium.envs.classic_control"):
        simulator = {k: (None if v is None else np.array(v)) for k, v in vars(base).items() if k in CLASSIC_STATE}
    else:
        return None
    return {"wrappers": [type(w).__name__ for w in chain[:-1]],
            "counters": [{k: v for k, v in vars(w).items() if k in EPISODE_COUNTERS} for w in chain[:-1]],
            "np_random": base.np_random.bit_generator.state, **simulator}


def _saved_mujoco_data(state: dict[str, Any]) -> Any:
    import mujoco

    saved = mujoco.MjData.__new__(mujoco.MjData)
    saved.__setstate__(np.asarray(state["mujoco_data"], dtype=np.uint8).tobytes())
    return saved


def _fits(env: Any, state: dict[str, Any]) -> bool:
    """Whether :func:`episode_state`'s ``state`` can be put back into ``env``: the same wrappers, the same number of
    copies (vector), the same MuJoCo model sizes."""
    chain = _chain(env)
    base = chain[-1]
    if [type(w).__name__ for w in chain[:-1]] != list(state["wrappers"]):
        return False
    if "copies" in state:
        return (isinstance(base, gym.vector.SyncVectorEnv) and len(base.envs) == len(state["copies"])
                and all(_fits(copy, saved) for copy, saved in zip(base.envs, state["copies"])))
    if "mujoco_data" in state:
        if not hasattr(base, "data"):
            return False
        model = _saved_mujoco_data(state).model
        return all(getattr(model, s) == getattr(base.model, s) for s in ("nq", "nv", "nu", "na", "nbody", "ngeom"))
    return True


def restore_episode(env: gym.Env, state: dict[str, Any]) -> bool:
    """Put ``env``, just reset, into the episode in progress that :func:`episode_state` saved; False (and ``env``
    left as reset) where the state does not fit this environment: other wrappers, or another MuJoCo model."""
    if not _fits(env, state):
        return False
    chain = _chain(env)
    base = chain[-1]
    if "copies" in state:
        for copy, saved in zip(base.envs, state["copies"]):
            restore_episode(copy, saved)
        base._autoreset_envs = _array(state["autoreset"]).astype(bool)
        for wrapper, counters in zip(chain[:-1], state["counters"]):
            for key, value in counters.items():
                setattr(wrapper, key, _array(value))
        return True
    if "mujoco_data" in state:
        import mujoco

        mujoco.mj_copyData(base.data, base.model, _saved_mujoco_data(state))
    else:
        for key in CLASSIC_STATE:
            if key in state:
                value = state[key]
                setattr(base, key, None if value is None else np.asarray(value).copy() if np.ndim(value) else
                        np.asarray(value).item())
    for wrapper, counters in zip(chain[:-1], state["counters"]):
        for key, value in counters.items():
            setattr(wrapper, key, value)
    base.np_random.bit_generator.state = state["np_random"]
    return True
