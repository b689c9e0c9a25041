import numpy as np
import pytest
import torch

from rlcore.noise import AdaptiveParamNoise, GaussianNoise, OrnsteinUhlenbeckNoise, action_distance


def test_gaussian_noise_decays_multiplicatively():
    n = GaussianNoise(3, sigma=1.0, decay=0.5, seed=0)
    n(), n()
    assert n.sigma == 0.25
    big = GaussianNoise(1, sigma=2.0, seed=1)
    samples = np.array([big() for _ in range(20_000)])
    assert samples.std() == pytest.approx(2.0, rel=0.03)


def test_ou_reverts_to_the_mean():
    n = OrnsteinUhlenbeckNoise(1, mu=0.0, theta=0.5, sigma=0.0, dt=0.1, seed=0)
    n.x[:] = 10.0
    xs = [n()[0] for _ in range(50)]
    np.testing.assert_allclose(xs[0], 10 * (1 - 0.05))  # x + theta (mu - x) dt, no noise
    assert abs(xs[-1]) < abs(xs[0]) * 0.2
    n.reset()
    assert n.x[0] == 0.0


def test_ou_stationary_variance_and_correlation():
    theta, sigma, dt = 0.15, 0.2, 1e-2
    n = OrnsteinUhlenbeckNoise(200, theta=theta, sigma=sigma, dt=dt, seed=0)  # 200 independent processes
    for _ in range(3_000):  # burn in (time constant 1 / (theta dt) ~ 667 steps)
        n()
    xs = np.array([n() for _ in range(2_000)])  # (time, process)
    # the exact stationary variance of the discretized process: sigma^2 dt / (1 - (1 - theta dt)^2)
    var = sigma**2 * dt / (1 - (1 - theta * dt) ** 2)
    assert xs.var() == pytest.approx(var, rel=0.1)
    assert abs(xs.mean()) < 0.02
    lag1 = np.mean([np.corrcoef(xs[:-1, i], xs[1:, i])[0, 1] for i in range(xs.shape[1])])
    assert lag1 > 0.99  # temporally correlated, unlike Gaussian noise


def test_param_noise_adapts_its_scale_toward_the_target_distance():
    torch.manual_seed(0)
    actor = torch.nn.Sequential(torch.nn.Linear(3, 16), torch.nn.Tanh(), torch.nn.Linear(16, 2), torch.nn.Tanh())
    obs = torch.randn(256, 3)
    for start in (1.0, 0.001):  # far too large, far too small
        noise = AdaptiveParamNoise(initial_sigma=start, target_distance=0.1, alpha=1.1, seed=0)
        for _ in range(120):
            d = action_distance(actor, noise.perturb(actor), obs)
            noise.adapt(d)
        dists = [action_distance(actor, noise.perturb(actor), obs) for _ in range(20)]
        assert np.mean(dists) == pytest.approx(0.1, rel=0.5)
    sigma = noise.sigma
    assert noise.adapt(1.0) == pytest.approx(sigma / 1.1)  # farther than the target: sigma shrinks by alpha
    assert noise.adapt(0.0) == pytest.approx(sigma)  # nearer: it grows by alpha


def _adapt_while_training(rule: str, rounds: int = 150):
    """An actor that keeps training between adaptations (a new regression target each 'episode'), with parameter
    noise adapted by ``rule``: ``fixed`` (a fresh perturbation of the current actor) or ``stale`` (the old rule:
    the behaviour policy perturbed at the episode's start, measured against the trained actor)."""
    torch.manual_seed(0)
    actor = torch.nn.Sequential(torch.nn.Linear(3, 32), torch.nn.Tanh(), torch.nn.Linear(32, 2), torch.nn.Tanh())
    opt = torch.optim.SGD(actor.parameters(), lr=0.5)
    obs = torch.randn(256, 3)
    noise = AdaptiveParamNoise(initial_sigma=0.05, target_distance=0.1, alpha=1.05, seed=0)
    behaviour = noise.perturb(actor)
    for _ in range(rounds):
        goal = torch.tanh(torch.randn(256, 2))
        for _ in range(5):  # an episode of training moves the actor
            opt.zero_grad()
            ((actor(obs) - goal) ** 2).mean().backward()
            opt.step()
        if rule == "fixed":
            noise.adapt_to(actor, obs)
        else:
            noise.adapt(action_distance(actor, behaviour, obs))
        behaviour = noise.perturb(actor)
    fresh = [action_distance(actor, noise.perturbed_copy(actor), obs) for _ in range(20)]
    return noise.sigma, float(np.mean(fresh))


def test_param_noise_holds_its_distance_while_the_actor_trains():
    sigma_fixed, distance_fixed = _adapt_while_training("fixed")
    sigma_stale, distance_stale = _adapt_while_training("stale")
    # the stale rule counts the training drift as perturbation and pushes sigma down, episode after episode
    assert sigma_stale < 0.05 / 20 and distance_stale < 0.1 / 5
    # the fixed rule keeps a fresh perturbation about target_distance away
    assert distance_fixed == pytest.approx(0.1, rel=0.3)
    assert sigma_fixed > 10 * sigma_stale


def test_adapt_to_leaves_the_behaviour_policy_alone():
    actor = torch.nn.Linear(3, 2)
    noise = AdaptiveParamNoise(0.1, target_distance=0.05, seed=0)
    behaviour = noise.perturb(actor)
    weights = behaviour.weight.detach().clone()
    before = noise.sigma
    d = noise.adapt_to(actor, torch.randn(64, 3))
    assert noise.perturbed is behaviour and torch.equal(behaviour.weight, weights)
    assert noise.sigma == pytest.approx(before / noise.alpha if d > 0.05 else before * noise.alpha)


def test_perturbation_changes_weights_but_not_the_original():
    actor = torch.nn.Linear(2, 2)
    before = actor.weight.detach().clone()
    p = AdaptiveParamNoise(0.5, seed=0).perturb(actor)
    assert torch.equal(actor.weight, before)
    assert not torch.equal(p.weight, before)
