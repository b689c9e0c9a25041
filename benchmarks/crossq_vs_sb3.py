"""rlcore's CrossQ against sb3-contrib's (``sb3_contrib.CrossQ``, its PyTorch reference), same task, networks,
hyperparameters and budget: throughput, and with ``--returns`` the return both reach.

    pip install -r requirements.txt -r benchmarks/requirements.txt
    python benchmarks/crossq_vs_sb3.py --env HalfCheetah-v5 --steps 1500 --learning-starts 500 --repeats 2
    python benchmarks/crossq_vs_sb3.py --returns --env Pendulum-v1 --critic-width 256 --steps 4000 \\
        --learning-starts 500 --seeds 0,1

**Throughput** (the default) follows ``benchmarks/offpolicy_vs_sb3.py`` and uses its pieces: both train from
scratch in this one process, interleaved (rlcore, sb3-contrib, rlcore, sb3-contrib over ``--repeats``), one torch
thread, no evaluation, checkpoints or logging during training; environment steps per second of wall time from
building the model to the end of training, and the same in CPU time of the process (``cpu_time``, the steadier figure
on a shared machine); the verdict is the ratio of medians. Where the time goes, by timers around each side's pieces:
for rlcore ``networks`` (each step's ``learn``: the joint pass, critic and actor updates, backward and Adam),
``acting`` (the actor's forward pass for the behaviour action), ``simulator`` (``env.step``) and
``replay_sampling``; for sb3-contrib ``networks`` (its ``train``, with its replay sampling) and ``simulator``. The
rest is the loop, storing transitions, episodes and building the model. ``learning_starts`` is small so that most of
the budget is spent learning; the critics' width is ``--critic-width`` (sb3-contrib's default 1024; the paper's
2048). Before anything is timed the settings are read back from both built models (:func:`sb3_read_back`,
:func:`rlcore_read_back`) and must agree; the record keeps them.

**Returns** (``--returns``): for each seed of ``--seeds``, rlcore then sb3-contrib train ``--steps`` steps on one
body with the same settings and seed, and each final deterministic policy (the squashed Gaussian's mean, the batch
renorm layers on their running statistics) plays ``--episodes`` fresh episodes, the same reset seeds for both
(``1_000_000 + 1000 * seed + i``, none a training episode's). A check of the implementation, not a ranking: the two
draw different random numbers from the same seed, so a seed's two runs are not the same run. At a budget short of
``--bn-warmup`` (100,000 batches) the layers never leave the warm-up: the check covers batch norm, not renorm's
corrections (a smaller ``--bn-warmup`` reaches them, on both sides alike).

What is the same in both (the settings of :func:`settings`, and sb3-contrib 2.9.2's code read for the rest):

- critics Q_1, Q_2 of two hidden layers of ``--critic-width``, ReLU, reading the concatenated observation and action,
  each layer batch renorm -> linear (-> ReLU): BR, L, ReLU, BR, L, ReLU, BR, L; the actor's body BR, L(256), ReLU, BR,
  L(256), ReLU, BR, then a linear mean head and a linear log-std head, log std clamped to [-20, 2], a tanh-squashed
  Gaussian scaled to the action box; every linear layer initialized as ``nn.Linear`` is (U(+-1/sqrt(fan_in)));
  no target networks (sb3-contrib passes tau = 1 and keeps no copies);
- batch renormalization: momentum 0.01, eps 1e-3, r_max 3, d_max 5, running mean 0 and variance 1 at the start,
  the running variance following the batches' unbiased variance, a warm-up of 100,000 training batches of plain
  batch norm, the running statistics in evaluation mode; one joint pass of [s; s'], [a; a'] through the critics in
  training mode (one set of batch statistics), a' ~ pi(.|s') drawn with the actor on its running statistics; the
  actor's update on batch statistics, the critic scoring the actor's actions on its running statistics;
- the soft target y = r + gamma (1 - terminated) (min_j Q_j(s', a') - alpha log pi(a'|s')), no gradient through it,
  gamma 0.99, time-limit truncations bootstrapped; the actor's loss mean(alpha log pi - min_j Q_j(s, a~)); automatic
  temperature from alpha = 1, target entropy -dim(A), alpha taken before the step's temperature update in both the
  target and the actor's loss;
- Adam with step size 1e-3 for critics, actor and temperature; beta_1 0.5 for critics and actor, Adam's default
  betas for the temperature; the actor and the temperature updated every 3rd step, the critics every step; batch
  256, one gradient step per environment step, a replay memory of 1,000,000 transitions sampled uniformly, uniform
  random actions for the first ``learning_starts`` steps, then actions sampled from the policy (no added noise);
  no observation normalization, rewards unscaled.

What differs (none of it changes what an update computes by more than rounding, except where said):

- the critic's loss: sb3-contrib's is 0.5 sum_j mean (q_j - y)^2, rlcore's sum_j mean (q_j - y)^2 (twice the
  gradient; Adam divides the scale out but for its eps of 1e-8);
- the temperature's loss: sb3-contrib's -log(alpha) mean(log pi + H_target), rlcore's -alpha mean(log pi +
  H_target) (the same fixed point; a gradient alpha times smaller in log alpha, which Adam's normalization mostly
  removes); sb3-contrib updates the temperature before the actor, rlcore after (both losses use the same alpha);
- batch renormalization in a training pass: sb3-contrib normalizes with the batch's *unbiased* variance (``x.var``,
  divisor m - 1), rlcore with the biased one (divisor m, as ``torch.nn.BatchNorm1d``): during the warm-up
  sb3-contrib's normalized features are rlcore's times sqrt(1 - 1/m), 0.999 in the critics' joint batch of 512 and
  0.998 in the actor's 256 (checked: 0.99902 against sqrt(511/512) = 0.99902 on one batch). After the warm-up
  sb3-contrib folds r and d into a mean and variance, (x - (mu_B - d s_B / r)) / sqrt(s_B^2 / r^2 + eps), where
  rlcore computes (x - mu_B) / sigma_B * r + d with eps inside sigma_B: with r and d unclipped both come to
  (x - mu) / sigma on the running statistics, apart from where eps enters (0.9996 on the same batch). sb3-contrib
  renormalizes once it has seen more than ``warmup`` batches, rlcore once it has seen ``warmup`` (one batch apart);
  neither relaxes r_max and d_max over time as Ioffe does (both: clipped at 3 and 5 from the end of the warm-up);
  the running statistics are the same (both follow the unbiased variance);
- the squashing's log-determinant: sb3-contrib's log(1 - tanh(u)^2 + 1e-6), rlcore's exact
  2 (log 2 - u - softplus(-2u)) (they part where |u| > ~7, i.e. a saturated action);
- sb3-contrib's actor has ``log_std_init = -3``, but it is only used with gSDE (``use_sde``, off here): without it
  the log-std head is a plain ``nn.Linear`` in both, as is its ``clip_mean``;
- sb3-contrib works in actions scaled to [-1, 1] (stored, and fed to the critics, scaled; unscaled to the box for
  the environment), rlcore in the box's units (the critics see box actions; the log-probability is of the squashed
  action in [-1, 1] in both). The same on HalfCheetah (box +-1); a factor 2 on Pendulum's +-2, which the critics'
  first batch renorm layer removes;
- the policy delay: sb3-contrib counts its gradient steps (the actor at the 3rd, 6th, ...), rlcore the environment
  step (``step % 3 == 0``); rlcore learns from step ``learning_starts`` on, sb3-contrib from the step after (one
  gradient step fewer);
- the arithmetic: rlcore runs both critics as one module (:class:`rlcore.crossq.NormalizedTwinCritic`: one batched
  matrix product per layer for both, one renorm per layer with two groups of statistics) with PyTorch's fused Adam,
  and freezes the critics while the actor's loss is backpropagated through them; sb3-contrib runs its two critics
  one after the other, uses the default (per-tensor) Adam, and computes the critics' weight gradients in the actor's
  backward pass too (every 3rd step), then zeroes them: more arithmetic per update;
- random numbers: the same seed gives each side its own draws (networks, actions, minibatches), so a seed's runs
  differ; sb3-contrib seeds its environment's first reset only, rlcore every episode's.
"""

from __future__ import annotations

import argparse
import os
import shlex
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))  # this checkout's rlcore, not an installed one
import offpolicy_vs_sb3 as shared  # noqa: E402
from record import provenance, throughput_summary, time_side_by_side, write_record  # noqa: E402

PEERS = ("stable_baselines3", "sb3_contrib")
EVAL_SEED = 1_000_000
"""Fresh episodes for the returns check: episode i of seed s resets with EVAL_SEED + 1000 s + i."""


def settings(learning_starts: int, critic_width: int = 1024, bn_warmup: int = 100_000) -> dict[str, object]:
    """The hyperparameters both sides are given (see the docstring): sb3-contrib's defaults, ``learning_starts`` and
    the critics' width as given."""
    return {"algo": "crossq", "hidden": [256, 256], "critic_hidden": [critic_width, critic_width], "batch_size": 256,
            "gamma": 0.99, "buffer_size": 1_000_000, "learning_starts": learning_starts, "train_freq": 1,
            "gradient_steps": 1, "actor_lr": 1e-3, "critic_lr": 1e-3, "alpha_lr": 1e-3, "adam_beta1": 0.5,
            "policy_delay": 3, "alpha": 1.0, "autotune": True, "target_entropy": "-dim(A)", "bn_momentum": 0.01,
            "bn_eps": 1e-3, "bn_warmup": bn_warmup, "r_max": 3.0, "d_max": 5.0, "normalize_obs": False,
            "reward_scale": 1.0}


def rlcore_config(cfg: dict[str, object]):
    """rlcore's :class:`rlcore.crossq.Config` for ``cfg``, evaluation and checkpoints off."""
    return shared.rlcore_config(cfg)


def sb3_model(env, cfg: dict[str, object], seed: int):
    """sb3-contrib's CrossQ for ``cfg`` (:func:`settings`) on ``env``. It has one step size for all three optimizers
    and fixes r_max = 3, d_max = 5: other values are refused."""
    from sb3_contrib import CrossQ

    if not cfg["actor_lr"] == cfg["critic_lr"] == cfg["alpha_lr"] or (cfg["r_max"], cfg["d_max"]) != (3.0, 5.0):
        raise ValueError("sb3-contrib's CrossQ has one step size for all and r_max = 3, d_max = 5")
    if not cfg["autotune"] or cfg["target_entropy"] != "-dim(A)" or cfg["normalize_obs"] or cfg["reward_scale"] != 1:
        raise ValueError("this benchmark compares automatic temperature, target entropy -dim(A), raw observations and "
                         "rewards only")
    policy_kwargs = {"net_arch": {"pi": list(cfg["hidden"]), "qf": list(cfg["critic_hidden"])},
                     "activation_fn": torch.nn.ReLU, "n_critics": 2, "batch_norm": True,
                     "batch_norm_momentum": cfg["bn_momentum"], "batch_norm_eps": cfg["bn_eps"],
                     "renorm_warmup_steps": cfg["bn_warmup"],
                     "optimizer_kwargs": {"betas": (cfg["adam_beta1"], 0.999)}}
    return CrossQ("MlpPolicy", env, learning_rate=cfg["actor_lr"], buffer_size=cfg["buffer_size"],
                  learning_starts=cfg["learning_starts"], batch_size=cfg["batch_size"], gamma=cfg["gamma"],
                  train_freq=cfg["train_freq"], gradient_steps=cfg["gradient_steps"], policy_delay=cfg["policy_delay"],
                  ent_coef=f"auto_{cfg['alpha']}", target_entropy="auto", policy_kwargs=policy_kwargs, seed=seed,
                  verbose=0, device="cpu")


def _widths(linears) -> list[int]:
    return [layer.out_features for layer in linears]


def sb3_read_back(model) -> dict[str, object]:
    """The settings a built sb3-contrib CrossQ holds, read from its attributes, optimizers and layers, in the keys of
    :func:`settings` (``target_entropy`` as the number it resolved to)."""
    from sb3_contrib.common.torch_layers import BatchRenorm1d

    critic, actor = model.critic, model.actor
    norms = [m for net in (critic, actor) for m in net.modules() if isinstance(m, BatchRenorm1d)]
    per_critic = [_widths(m for m in q if isinstance(m, torch.nn.Linear)) for q in critic.q_networks]
    if any(w != per_critic[0] for w in per_critic) or len({(m.momentum, m.eps, m.warmup_steps, m.rmax, m.dmax)
                                                              for m in norms}) != 1:
        raise ValueError("sb3-contrib's critics or renorm layers differ among themselves")
    opt = {name: o.param_groups[0] for name, o in (("actor", actor.optimizer), ("critic", critic.optimizer),
                                                    ("alpha", model.ent_coef_optimizer))}
    n = norms[0]
    return {"hidden": _widths(m for m in actor.latent_pi if isinstance(m, torch.nn.Linear)),
            "critic_hidden": per_critic[0][:-1], "n_critics": len(per_critic), "batch_size": model.batch_size,
            "gamma": model.gamma, "buffer_size": model.buffer_size, "learning_starts": model.learning_starts,
            "train_freq": model.train_freq.frequency, "gradient_steps": model.gradient_steps,
            "actor_lr": opt["actor"]["lr"], "critic_lr": opt["critic"]["lr"], "alpha_lr": opt["alpha"]["lr"],
            "adam_beta1": opt["actor"]["betas"][0], "critic_adam_beta1": opt["critic"]["betas"][0],
            "alpha_adam_betas": list(opt["alpha"]["betas"]), "policy_delay": model.policy_delay,
            "alpha": float(model.log_ent_coef.detach().exp()), "target_entropy": model.target_entropy,
            "bn_momentum": n.momentum, "bn_eps": n.eps, "bn_warmup": n.warmup_steps, "r_max": n.rmax,
            "d_max": n.dmax, "renorm_layers_critic": sum(isinstance(m, BatchRenorm1d) for m in critic.q_networks[0]),
            "renorm_layers_actor": sum(isinstance(m, BatchRenorm1d) for m in actor.latent_pi)}


def rlcore_read_back(config, env_id: str) -> dict[str, object]:
    """The same settings of rlcore's CrossQ: its Config, and the networks :func:`rlcore.crossq.make_networks` builds
    from it on ``env_id`` (the optimizers' settings are the Config's: ``train`` builds them from it; the
    temperature's Adam has the default betas, which sb3-contrib's read-back shows and this one leaves out)."""
    from rlcore import crossq
    from rlcore.batchrenorm import BatchRenorm
    from rlcore.envs import make_env
    from rlcore.offpolicy import check_spaces

    env = make_env(env_id)
    sp = check_spaces(env, env_id, "CrossQ")
    env.close()
    actor, critic = crossq.make_networks(sp, config)
    norms = [m for net in (critic, actor) for m in net.modules() if isinstance(m, BatchRenorm)]
    if len({(m.momentum, m.eps, m.warmup, m.r_max, m.d_max) for m in norms}) != 1:
        raise ValueError("rlcore's renorm layers differ among themselves")
    n = norms[0]
    c = config
    return {"hidden": _widths(m for m in actor.body if isinstance(m, torch.nn.Linear)),
            "critic_hidden": [w.shape[-1] for w in critic.weights][:-1], "n_critics": critic.weights[0].shape[0],
            "batch_size": c.batch_size, "gamma": c.gamma, "buffer_size": c.buffer_size,
            "learning_starts": c.learning_starts, "train_freq": 1, "gradient_steps": 1, "actor_lr": c.actor_lr,
            "critic_lr": c.critic_lr, "alpha_lr": c.alpha_lr, "adam_beta1": c.adam_beta1,
            "critic_adam_beta1": c.adam_beta1, "policy_delay": c.policy_delay,
            "alpha": c.alpha, "target_entropy": -float(sp["act_dim"]) if c.target_entropy is None else c.target_entropy,
            "bn_momentum": n.momentum, "bn_eps": n.eps, "bn_warmup": n.warmup, "r_max": n.r_max, "d_max": n.d_max,
            "renorm_layers_critic": sum(isinstance(m, BatchRenorm) for m in critic.norms),
            "renorm_layers_actor": sum(isinstance(m, BatchRenorm) for m in actor.body)}


def same_settings(env_id: str, cfg: dict[str, object]) -> dict[str, object]:
    """Both sides' settings read back (:func:`rlcore_read_back`, :func:`sb3_read_back`); ValueError, naming them,
    where they differ."""
    import gymnasium as gym

    env = gym.make(env_id)
    sb3 = sb3_read_back(sb3_model(env, cfg, seed=0))
    env.close()
    rl = rlcore_read_back(rlcore_config(cfg), env_id)
    differ = {k: (rl[k], sb3[k]) for k in rl if rl[k] != sb3[k]}
    if differ:
        raise ValueError(f"rlcore and sb3-contrib are set up differently (rlcore, sb3-contrib): {differ}")
    return sb3


def rlcore_run(env_id: str, steps: int, seed: int, cfg: dict[str, object]) -> float:
    """One timed rlcore CrossQ run (:func:`offpolicy_vs_sb3.rlcore_run`): its seconds; the split goes to
    ``shared.SPLITS['rlcore']``."""
    return shared.rlcore_run(env_id, steps, seed, cfg)


def sb3_run(env_id: str, steps: int, seed: int, cfg: dict[str, object]) -> float:
    """One timed sb3-contrib CrossQ run (:func:`offpolicy_vs_sb3.sb3_run`): its seconds; the split goes to
    ``shared.SPLITS['sb3']``."""
    return shared.sb3_run(env_id, steps, seed, cfg, make_model=sb3_model)


def final_returns(side: str, env_id: str, steps: int, seed: int, cfg: dict[str, object],
                  episodes: int) -> dict[str, object]:
    """Train one side (``rlcore`` or ``sb3``) for ``steps`` steps from ``seed``; the deterministic policy's returns on
    ``episodes`` fresh episodes (:data:`EVAL_SEED`), the training episodes' returns and the seconds it took."""
    import gymnasium as gym

    from rlcore.evaluate import evaluate_policy

    start, cpu_start = time.perf_counter(), time.process_time()
    if side == "rlcore":
        from rlcore import crossq

        result = crossq.train(env_id, rlcore_config(cfg), steps=steps, seed=seed)
        policy, training = result.policy, [float(r) for r in result.episode_returns]
    else:
        model = sb3_model(gym.make(env_id), cfg, seed)
        model.learn(total_timesteps=steps)

        def policy(obs):
            return model.predict(obs, deterministic=True)[0]
        training = [float(info["r"]) for info in model.ep_info_buffer]  # its last 100 episodes
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    env = gym.make(env_id)
    returns = evaluate_policy(policy, env, episodes, EVAL_SEED + 1000 * seed).tolist()
    env.close()
    return {"seed": seed, "final_returns": returns, "final_mean": statistics.fmean(returns),
            "training_episode_returns": training, "seconds": seconds, "cpu_seconds": cpu}


def returns_check(env_id: str, steps: int, seeds: list[int], cfg: dict[str, object], episodes: int,
                  write=None) -> dict[str, object]:
    """:func:`final_returns` of rlcore then sb3-contrib for each seed, interleaved; ``write(partial record)``
    after each run (so that a stopped run keeps what it finished). The means over seeds of each side's mean."""
    runs: dict[str, list[dict[str, object]]] = {"rlcore": [], "sb3": []}
    out: dict[str, object] = {}
    for seed in seeds:
        for side in runs:
            runs[side].append(final_returns(side, env_id, steps, seed, cfg, episodes))
            r = runs[side][-1]
            print(f"seed {seed}  {side:6s}  final return {r['final_mean']:9.1f}  ({r['seconds']:.0f} s)  "
                  f"load {os.getloadavg()[0]:.2f}", flush=True)
            means = {s: [x["final_mean"] for x in v] for s, v in runs.items()}
            out = {"runs": runs, "mean_final_return": {s: statistics.fmean(v) if v else None
                                                       for s, v in means.items()}}
            if write is not None:
                write(out)
    return out


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env", default="HalfCheetah-v5")
    p.add_argument("--steps", type=int, default=1_500)
    p.add_argument("--learning-starts", type=int, default=500)
    p.add_argument("--critic-width", type=int, default=1024, help="the critics' hidden width (sb3-contrib: 1024)")
    p.add_argument("--bn-warmup", type=int, default=100_000, help="batch renorm's warm-up in batches")
    p.add_argument("--repeats", type=int, default=2, help="timing: rounds of (rlcore, sb3-contrib)")
    p.add_argument("--seed", type=int, default=0, help="timing: the first repeat's seed")
    p.add_argument("--returns", action="store_true", help="the returns check instead of the timing")
    p.add_argument("--seeds", default="0,1", help="--returns: the seeds, comma-separated")
    p.add_argument("--episodes", type=int, default=10, help="--returns: fresh episodes per final policy")
    p.add_argument("--out", default=None,
                   help="default: results/benchmarks/crossq-vs-sb3-<task>.json (--returns: crossq-returns-sb3-...)")
    args = p.parse_args(argv)
    if not 0 < args.learning_starts < args.steps:
        p.error("--learning-starts must be between 0 and --steps, exclusive")
    return args


def main(argv=None) -> None:
    args = parse(argv)
    task = args.env.split("-")[0].lower()
    out = args.out or f"results/benchmarks/crossq-{'returns' if args.returns else 'vs'}-sb3-{task}.json"
    command = "python benchmarks/crossq_vs_sb3.py " + " ".join(map(shlex.quote, sys.argv[1:] if argv is None
                                                                   else argv))
    torch.set_num_threads(1)
    load_start = os.getloadavg()
    import sb3_contrib  # noqa: F401  (imports outside the timed region)

    from rlcore import crossq  # noqa: F401

    shared.warm_up(args.env)
    cfg = settings(args.learning_starts, args.critic_width, args.bn_warmup)
    read_back = same_settings(args.env, cfg)
    head = {"peer": f"sb3-contrib {sb3_contrib.__version__} CrossQ", "critic_width": args.critic_width,
            "settings_read_back": read_back}
    if args.returns:
        seeds = [int(s) for s in args.seeds.split(",")]
        base = {"benchmark": "crossq-returns-sb3", "algo": "crossq", "env_id": args.env, "steps": args.steps,
                "seeds": seeds, "episodes": args.episodes, "eval_seed": EVAL_SEED, "hyperparameters": cfg, **head}

        def write(result, summary=""):
            write_record({**base, **result, **provenance(command, load_start, peers=PEERS)}, out, summary)

        result = returns_check(args.env, args.steps, seeds, cfg, args.episodes, write)
        m = result["mean_final_return"]
        write(result, f"final deterministic return, mean over seeds: rlcore {m['rlcore']:.1f}, sb3-contrib "
                      f"{m['sb3']:.1f}")
        return
    for splits in shared.SPLITS.values():  # this timing's alone (the module is shared with anything run before)
        splits.clear()
    times = time_side_by_side({"rlcore": rlcore_run, "sb3": sb3_run}, args.env, args.steps, args.seed, args.repeats,
                              cfg)
    record = shared.timing_record(cfg, args.env, args.steps, args.repeats, times,
                                  provenance(command, load_start, peers=PEERS), peer="sb3-contrib")
    write_record({**record, **head}, out, throughput_summary(record).replace("SB3", "sb3-contrib"))


if __name__ == "__main__":
    main()
