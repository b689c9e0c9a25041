"""rlcore.sac: the squashing correction three ways, action boxes, the soft target and the temperature by hand,
resume."""

import math

import numpy as np
import pytest
import torch

from rlcore import sac
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy

SMALL = dict(hidden=(32, 32), learning_starts=100, batch_size=32, buffer_size=5_000, eval_every=0)


def test_the_squashed_log_prob_is_torch_s_tanh_transformed_gaussian():
    torch.manual_seed(0)
    mean, log_std = torch.randn(1000, 3) * 3, torch.randn(1000, 3).clamp(-3, 1)
    base = torch.distributions.Normal(mean, log_std.exp())
    tanh = torch.distributions.transforms.TanhTransform(cache_size=1)  # keeps u: atanh(tanh(u)) is lossy near +-1
    squashed = torch.distributions.TransformedDistribution(base, [tanh])
    u = base.sample()
    x = tanh(u)
    torch.testing.assert_close(sac.squashed_log_prob(u, mean, log_std), squashed.log_prob(x).sum(-1))


def test_the_squashed_density_integrates_to_one():
    """Independent of torch's transforms: p(x) = N(atanh x; m, s) / (1 - x^2) over (-1, 1), by quadrature in u
    (x = tanh u, dx = (1 - tanh(u)^2) du), for a wide and a narrow Gaussian, centred and far out."""
    u = torch.linspace(-40, 40, 400_001, dtype=torch.float64)
    for m, s in ((0.0, 1.0), (3.0, 0.3), (-8.0, 2.0), (0.5, 7.0)):
        logp = sac.squashed_log_prob(u[:, None], torch.full((1, 1), m, dtype=torch.float64),
                                     torch.full((1, 1), math.log(s), dtype=torch.float64))
        dx_du = torch.exp(sac.tanh_log_det_jacobian(u))
        mass = torch.trapezoid(torch.exp(logp) * dx_du, u)
        assert float(mass) == pytest.approx(1.0, abs=1e-6), (m, s)


def test_the_naive_correction_is_wrong_where_tanh_saturates():
    u = torch.tensor([0.5, 5.0, 12.0])
    exact = sac.tanh_log_det_jacobian(u)
    naive = torch.log(1 - torch.tanh(u) ** 2 + 1e-6)
    assert float(exact[0]) == pytest.approx(math.log(1 - math.tanh(0.5) ** 2), rel=1e-6)
    assert float(exact[2]) == pytest.approx(2 * (math.log(2) - 12.0), rel=1e-6)  # log(4 e^{-2u}) for large u
    assert abs(float(naive[2] - exact[2])) > 5  # log(1e-6) = -13.8 instead of -22.6


@pytest.mark.parametrize("low,high", [([-0.4] * 3, [0.4] * 3), ([-1.0] * 3, [1.0] * 3),
                                     ([0.0, -2.0, 1.0], [2.0, 2.0, 1.5])])
def test_actions_fill_the_task_s_box_and_the_mean_action_is_its_centre_plus_half_width_tanh_m(low, high):
    torch.manual_seed(0)
    actor = sac.SquashedGaussianActor(4, 3, (16,), low, high)
    with torch.no_grad():
        actor.log_std.bias.fill_(1.5)  # wide: samples reach the box's edges
        obs = torch.randn(5_000, 4)
        a, logp = actor(obs)
    lo, hi = torch.tensor(low), torch.tensor(high)
    assert bool(((a >= lo) & (a <= hi)).all())
    span = (a.max(0).values - a.min(0).values) / (hi - lo)
    assert bool((span > 0.95).all()), span  # the whole box, not [-1, 1] nor a part of it
    with torch.no_grad():
        mean, _ = actor.gaussian(obs)
        torch.testing.assert_close(actor.deterministic(obs), (lo + hi) / 2 + (hi - lo) / 2 * torch.tanh(mean))
    # the log-probability is that of x = tanh(u) in (-1, 1)^d: the same for every box
    torch.manual_seed(1)
    unit = sac.SquashedGaussianActor(4, 3, (16,), [-1.0] * 3, [1.0] * 3)
    unit.load_state_dict({k: v for k, v in actor.state_dict().items() if k not in ("scale", "center")}, strict=False)
    torch.manual_seed(2)
    _, lp_box = actor(obs[:10])
    torch.manual_seed(2)
    _, lp_unit = unit(obs[:10])
    torch.testing.assert_close(lp_box, lp_unit)


def test_the_soft_target_by_hand():
    torch.manual_seed(0)
    actor = sac.SquashedGaussianActor(2, 1, (8,), [-2.0], [2.0])
    critic_t = sac.TwinCritic(2, 1, (8,))
    next_obs, rewards, terminated = torch.randn(6, 2), torch.randn(6), torch.tensor([0.0, 0, 0, 1, 0, 1])
    with torch.random.fork_rng():
        y = sac.soft_target(actor, critic_t, next_obs, rewards, terminated, 0.9, alpha=0.3)
    with torch.no_grad():
        a, logp = actor(next_obs)  # the same draw
        q = critic_t(next_obs, a)
        by_hand = rewards + 0.9 * (1 - terminated) * (torch.minimum(q[0], q[1]) - 0.3 * logp)
    torch.testing.assert_close(y, by_hand)
    assert torch.equal(y[terminated == 1], rewards[terminated == 1])


@pytest.mark.parametrize("logp,direction", [(5.0, 1), (-5.0, -1)])
def test_the_temperature_rises_while_the_entropy_is_below_its_target(logp, direction):
    """Target entropy -1: log pi = 5 (entropy -5, too little) raises alpha; log pi = -5 (entropy 5) lowers it."""
    log_alpha = torch.nn.Parameter(torch.tensor(0.0))
    opt = torch.optim.SGD([log_alpha], lr=0.01)
    sac.temperature_loss(log_alpha, torch.full((4,), logp), target_entropy=-1.0).backward()
    opt.step()
    assert direction * float(log_alpha) > 0


def test_a_stopped_and_resumed_run_is_the_uninterrupted_run(tmp_path):
    torch.set_num_threads(1)
    cfg = sac.Config(**{**SMALL, "checkpoint_every": 100_000, "eval_every": 100})
    whole = sac.train("Pendulum-v1", cfg, steps=600, seed=3, out=tmp_path / "whole")
    sac.train("Pendulum-v1", cfg, steps=317, seed=3, out=tmp_path / "parts")
    resumed = sac.train("Pendulum-v1", cfg, steps=600, seed=3, out=tmp_path / "parts")
    for a, b in zip(whole.actor.parameters(), resumed.actor.parameters()):
        assert torch.equal(a, b)
    assert whole.alphas[-1] == resumed.alphas[-1] and whole.alphas[0] != whole.alphas[-1]
    from rlcore.logger import read_csv

    assert read_csv(tmp_path / "parts" / "alpha.csv")["step"].tolist() == list(range(100, 601, 100))


def test_a_short_run_on_pendulum_clearly_beats_random():
    torch.set_num_threads(1)
    # RL Zoo's Pendulum step sizes, 1e-3 (at the paper's 3e-4 it takes about twice as long)
    cfg = sac.Config(hidden=(64, 64), learning_starts=500, batch_size=64, buffer_size=10_000, eval_every=1000,
                     actor_lr=1e-3, critic_lr=1e-3, alpha_lr=1e-3)
    # at 4,000 steps seeds 0, 1 and 2 score about -180, -150 and -170 here, alpha near 0.22 (a random policy: -1,200)
    result = sac.train("Pendulum-v1", cfg, steps=4_000, seed=0)
    returns = evaluate_policy(result.policy, make_env("Pendulum-v1"), episodes=5, seed=3)
    assert returns.mean() > -600, returns
    assert result.alphas[-1] < 1.0  # Pendulum's policy got more certain than the target entropy asks: alpha fell


def test_fixed_temperature_stays_fixed_and_bad_input_is_one_line():
    result = sac.train("Pendulum-v1", sac.Config(**{**SMALL, "autotune": False, "alpha": 0.2, "eval_every": 100}),
                       steps=300, seed=0)
    assert result.alphas.tolist() == pytest.approx([0.2, 0.2, 0.2])  # at steps 100, 200, 300
    with pytest.raises(ValueError, match="alpha must be > 0"):
        sac.Config(alpha=0.0)
    with pytest.raises(ValueError, match="SAC needs a continuous"):
        sac.train("CartPole-v1", sac.Config(**SMALL), steps=10)
