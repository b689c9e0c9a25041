"""rlcore: the small, tested reinforcement-learning library behind the course book.

One idea per module (see the design card in the README):

- :mod:`rlcore.envs`       environment construction and seeding on Gymnasium
- :mod:`rlcore.render`     offscreen rollouts to frames and GIFs, headless GL selection
- :mod:`rlcore.evaluate`   evaluation episodes and statistics over seeds
- :mod:`rlcore.logger`     CSV progress logs
- :mod:`rlcore.checkpoint` atomic save, ``weights_only=True`` load
- :mod:`rlcore.plots`      learning curves with a band over seeds
- :mod:`rlcore.runs`       the output directory of one training run
- :mod:`rlcore.profile`    the quick/book budget switch the chapters read
- :mod:`rlcore.nets`       ``mlp()`` and the Q-network, dueling, actor and critic heads
- :mod:`rlcore.buffers`    replay buffer, sum tree, prioritized replay, GAE
- :mod:`rlcore.noise`      Gaussian, Ornstein-Uhlenbeck and adaptive parameter noise
- :mod:`rlcore.tabular`    tabular Q-learning and SARSA, value iteration
- :mod:`rlcore.dqn`        DQN with Double, Dueling and Prioritized switches
- :mod:`rlcore.a2c`        A2C, synchronous advantage actor-critic
- :mod:`rlcore.offpolicy`  the off-policy core DDPG, TD3 and SAC share
- :mod:`rlcore.ddpg`       DDPG
- :mod:`rlcore.td3`        TD3: clipped double Q, target-policy smoothing, delayed updates
- :mod:`rlcore.sac`        SAC: maximum entropy, a squashed Gaussian policy, automatic temperature
- :mod:`rlcore.ppo`        PPO, clipped and adaptive-KL
- :mod:`rlbook` the book's named, resumable full-budget experiments
- :mod:`rlcore.algos`      the registry of algorithms the command line knows

Modules are imported on demand (``import rlcore.envs``) so that ``import rlcore`` stays cheap.
"""

__version__ = "0.1.0"

from rlcore.gl import set_aside_unknown_backend as _set_aside_unknown_backend  # noqa: E402

# A MUJOCO_GL that MuJoCo does not know would stop every MuJoCo task, not only rendering (see rlcore.gl).
_set_aside_unknown_backend()
