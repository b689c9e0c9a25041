"""rlcore: the small, tested reinforcement-learning library a student of the course book studies and reuses.

One idea per module. The book's own machinery (its named experiments, ``results/``, the pages' helpers) is a
separate package, ``rlbook``, which imports this one; nothing here imports it (``tests/test_layering.py``).

The algorithms, each a ``Config``, the math as small functions, and a ``train`` that follows its algorithm box:

- :mod:`rlcore.tabular`     tabular Q-learning and SARSA, value iteration
- :mod:`rlcore.dqn`         DQN with Double, Dueling and Prioritized switches
- :mod:`rlcore.reinforce`   REINFORCE, the policy gradient with Monte-Carlo returns and no critic
- :mod:`rlcore.a2c`         A2C, synchronous advantage actor-critic
- :mod:`rlcore.ppo`         PPO, clipped and adaptive-KL
- :mod:`rlcore.dppo`        PPO on N data-parallel workers (torchrun)
- :mod:`rlcore.ddpg`        DDPG
- :mod:`rlcore.td3`         TD3: clipped double Q, target-policy smoothing, delayed updates
- :mod:`rlcore.sac`         SAC: maximum entropy, a squashed Gaussian policy, automatic temperature
- :mod:`rlcore.crossq`      CrossQ: SAC with no target networks, batch renorm and one joint critic pass

What they share:

- :mod:`rlcore.onpolicy`    the on-policy core of A2C, PPO, DPPO and REINFORCE: their shared Config, actor-critic,
                            rollouts, GAE
- :mod:`rlcore.offpolicy`   the off-policy core of DDPG, TD3, SAC and CrossQ: the loop and its per-update hook, actor, critics
- :mod:`rlcore.harness`     everything around a training loop: resume, checkpoints, logs, evaluation, best policy
- :mod:`rlcore.batchrenorm` batch renormalization (Ioffe 2017): batch norm that corrects toward running statistics
- :mod:`rlcore.nets`        ``mlp()`` and the Q-network, dueling, actor and critic heads
- :mod:`rlcore.buffers`     replay buffer, sum tree, prioritized replay
- :mod:`rlcore.noise`       Gaussian, Ornstein-Uhlenbeck and adaptive parameter noise
- :mod:`rlcore.schedules`   how a hyperparameter moves over a run (epsilon's decay)
- :mod:`rlcore.config`      checks of every Config's values; a Config to and from a dict
- :mod:`rlcore.envs`        environment construction and seeding on Gymnasium
- :mod:`rlcore.wrappers`    environment wrappers that package a mistake (a time-out reported as termination)
- :mod:`rlcore.distributed` ``torch.distributed`` pieces for DPPO
- :mod:`rlcore.launch`      the torchrun command line that starts DPPO's workers, and finding them again

Around a run:

- :mod:`rlcore.evaluate`    evaluation episodes and statistics over seeds
- :mod:`rlcore.checkpoint`  atomic save, ``weights_only=True`` load
- :mod:`rlcore.runs`        a run's output folder: opening it, new or to resume
- :mod:`rlcore.provenance`  what a run records about itself: command, versions, commit and uncommitted changes
- :mod:`rlcore.machine`     the processor and its kernels; torch's thread count for training
- :mod:`rlcore.signals`     Ctrl-C and ``kill`` end a run with a checkpoint, written whole
- :mod:`rlcore.logger`      CSV progress logs
- :mod:`rlcore.plots`       learning curves with a band over seeds, and per-seed scores
- :mod:`rlcore.render`      offscreen rollouts to frames and GIFs
- :mod:`rlcore.gl`          which headless OpenGL backend MuJoCo renders with
- :mod:`rlcore.profile`     the quick/book budget switch (``RLBOOK_PROFILE``)

The command line, ``python -m rlcore train | evaluate | render``:

- :mod:`rlcore.algos`       the algorithms it knows, by name
- :mod:`rlcore.cli`         what its command lines share: argument types, ``--set`` parsing, exit statuses
- :mod:`rlcore.__main__`    the commands themselves

Modules are imported on demand (``import rlcore.envs``) so that ``import rlcore`` stays cheap.
"""

__version__ = "0.1.0"

from rlcore.gl import set_aside_unknown_backend as _set_aside_unknown_backend  # noqa: E402

# A MUJOCO_GL that MuJoCo does not know would stop every MuJoCo task, not only rendering (see rlcore.gl).
_set_aside_unknown_backend()
