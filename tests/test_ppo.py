import numpy as np
import pytest
import torch

from rlcore import ppo
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy
from rlcore.onpolicy import evaluated_unclipped
from rlcore.ppo import (
    ActorCritic, Config, adaptive_kl_coef, approx_kl, clipped_surrogate, kl_penalty_surrogate, load_policy, train,
)


def _grad_of_ratio(loss_fn, ratio_value, advantage):
    ratio = torch.tensor([ratio_value], requires_grad=True)
    loss_fn(ratio, torch.tensor([advantage])).backward()
    return ratio.grad.item()


@pytest.mark.parametrize("ratio, adv, zero", [
    (1.5, +1.0, True),    # good action already made much more likely: no further push
    (0.5, -1.0, True),    # bad action already made much less likely: no further push
    (1.5, -1.0, False),   # bad action made MORE likely: the gradient still pulls it back
    (0.5, +1.0, False),   # good action made LESS likely: still pushed up
    (1.1, +1.0, False),   # inside the clip range: ordinary policy gradient
])
def test_clipped_surrogate_gradient_is_zero_only_outside_the_range_in_the_improving_direction(ratio, adv, zero):
    g = _grad_of_ratio(lambda r, a: clipped_surrogate(r, a, 0.2), ratio, adv)
    if zero:
        assert g == 0.0
    else:
        assert g == pytest.approx(-adv)  # d(-r A)/dr


def test_clipped_surrogate_value_by_hand():
    ratio = torch.tensor([0.5, 1.0, 1.5])
    adv = torch.tensor([1.0, 2.0, 1.0])
    # min(r A, clip(r) A) = [0.5*1 vs 0.8*1 -> 0.5, 2, 1.5 vs 1.2 -> 1.2]
    assert clipped_surrogate(ratio, adv, 0.2).item() == pytest.approx(-(0.5 + 2.0 + 1.2) / 3)


def test_kl_penalty_surrogate_by_hand():
    loss = kl_penalty_surrogate(torch.tensor([1.0, 2.0]), torch.tensor([1.0, 1.0]), torch.tensor(0.3), beta=2.0)
    assert loss.item() == pytest.approx(-1.5 + 0.6)


def test_adaptive_kl_coefficient_follows_the_reports_rule():
    # report, Table 5: beta-low 1/1.5, beta-high 1.5, alpha 2, kl-target 0.01
    rule = dict(kl_target=0.01, beta_low=1 / 1.5, beta_high=1.5, alpha=2.0)
    assert adaptive_kl_coef(1.0, 0.02, **rule) == 2.0     # KL above 1.5 x target: penalty doubles
    assert adaptive_kl_coef(1.0, 0.005, **rule) == 0.5    # KL below target / 1.5: penalty halves
    assert adaptive_kl_coef(1.0, 0.01, **rule) == 1.0     # in between: unchanged
    assert adaptive_kl_coef(1.0, 0.015, **rule) == 1.0    # the boundaries themselves do not move it


def test_approx_kl_is_zero_for_the_same_policy_and_positive_otherwise():
    lp = torch.log(torch.tensor([0.2, 0.5, 0.3]))
    assert approx_kl(lp, lp).item() == pytest.approx(0.0)
    assert approx_kl(lp, lp + torch.tensor([0.1, -0.2, 0.3])).item() > 0
    # the estimator is unbiased: compare with the exact KL of two Gaussians from samples of the old one
    torch.manual_seed(0)
    old, new = torch.distributions.Normal(0.0, 1.0), torch.distributions.Normal(0.3, 1.2)
    x = old.sample((200_000,))
    exact = torch.distributions.kl_divergence(old, new).item()
    assert approx_kl(old.log_prob(x), new.log_prob(x)).item() == pytest.approx(exact, rel=0.03)


def test_actor_critic_heads():
    torch.manual_seed(0)
    cont = ActorCritic(3, 2, discrete=False)
    d = cont.distribution(torch.zeros(4, 3))
    assert d.sample().shape == (4, 2) and cont.value(torch.zeros(4, 3)).shape == (4,)
    assert cont.log_prob(d, torch.zeros(4, 2)).shape == (4,)
    disc = ActorCritic(3, 5, discrete=True)
    assert disc.deterministic(torch.zeros(4, 3)).shape == (4,)


def test_bad_spaces_are_clear_errors():
    with pytest.raises(ValueError, match="flat vector observations"):
        train("FrozenLake-v1", steps=10)
    with pytest.raises(ValueError, match="objective"):
        Config(objective="trpo")


SMALL = dict(num_envs=2, n_steps=256, batch_size=64, n_epochs=4, learning_rate=1e-3, eval_every=0)


@pytest.mark.parametrize("objective", ["clip", "kl"])
def test_short_run_on_cartpole_beats_random(objective):
    torch.set_num_threads(1)
    result = train("CartPole-v1", Config(objective=objective, **SMALL), steps=15_000, seed=0)
    returns = evaluate_policy(result.policy, make_env("CartPole-v1"), episodes=5, seed=7)
    assert returns.mean() > 100, returns  # a random policy averages about 22


def test_checkpoint_policy_matches_and_carries_observation_scaling(tmp_path):
    torch.set_num_threads(1)
    from rlcore.checkpoint import load_checkpoint

    result = train("Pendulum-v1", Config(**SMALL), steps=1_024, seed=0, out=tmp_path)
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    policy = load_policy(ckpt)
    np.testing.assert_allclose(policy.obs_mean, result.policy.obs_mean)
    obs = np.array([0.5, -0.5, 1.0])
    np.testing.assert_allclose(policy(obs), result.policy(obs))
    assert np.all(np.abs(policy(obs)) <= 2.0)  # within Pendulum's action bounds
    assert (tmp_path / "updates.csv").exists()


def test_resume_restores_iteration_and_observation_statistics(tmp_path):
    torch.set_num_threads(1)
    from rlcore.checkpoint import load_checkpoint

    train("Pendulum-v1", Config(**SMALL, anneal_lr=False), steps=512, seed=0, out=tmp_path)
    first = load_checkpoint(tmp_path / "checkpoint.pt")
    resumed = train("Pendulum-v1", Config(**SMALL, anneal_lr=False), steps=1_024, seed=0, out=tmp_path)
    second = load_checkpoint(tmp_path / "checkpoint.pt")
    assert (first["iteration"], second["iteration"], resumed.steps) == (1, 2, 1_024)
    assert second["obs_count"] > first["obs_count"]  # statistics continued, not restarted


def test_resume_drops_log_rows_written_after_the_checkpoint_and_records_itself(tmp_path):
    """A run killed between two checkpoints redoes those steps; its logs must not show them twice."""
    import json

    from rlcore.logger import read_csv

    torch.set_num_threads(1)
    train("Pendulum-v1", Config(**SMALL, anneal_lr=False), steps=512, seed=0, out=tmp_path)
    with (tmp_path / "progress.csv").open() as f:
        header = f.readline().strip().split(",")
    with (tmp_path / "progress.csv").open("a") as f:  # a row from after the checkpoint, then the crash
        f.write(",".join("777" if h == "step" else "-12345" for h in header) + "\n")
    train("Pendulum-v1", Config(**SMALL, anneal_lr=False), steps=1_024, seed=0, out=tmp_path)
    steps = read_csv(tmp_path / "progress.csv")["step"]
    assert 777 not in steps.tolist() and -12345 not in read_csv(tmp_path / "progress.csv")["episode_return"].tolist()
    assert np.all(np.diff(steps) >= 0)  # (parallel environments can finish episodes at the same step)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert [r["step"] for r in meta["resumes"]] == [512]


def test_explore_noise_widens_the_stored_actions_and_stores_their_log_probability():
    torch.manual_seed(0)
    config = Config(n_steps=400, batch_size=400, normalize_obs=False, normalize_reward=False)
    envs = ppo.make_envs("Pendulum-v1", config, seed=0)
    spaces = ppo.check_spaces(envs, "Pendulum-v1")
    agent = ppo.make_agent(spaces, config)
    with torch.no_grad():
        agent.log_std.fill_(-5.0)  # the policy itself barely explores: std 0.007
    spread = {}
    for noise in (0.0, 0.5):
        buf = ppo.Rollout(spaces, config.n_steps, config.num_envs)
        obs, _ = envs.reset(seed=0)
        ppo.collect_rollout(agent, envs, obs, buf, explore_noise=noise)
        x = torch.as_tensor(buf.obs.reshape(400, -1))
        with torch.no_grad():
            mean = agent.actor(x)
            logp = agent.log_prob(agent.distribution(x), torch.as_tensor(buf.actions.reshape(400, -1)))
        spread[noise] = float((torch.as_tensor(buf.actions.reshape(400, -1)) - mean).std())
        np.testing.assert_allclose(buf.log_probs.reshape(-1), logp.numpy(), rtol=1e-4, atol=1e-3)
    assert spread[0.0] < 0.02 and 0.4 < spread[0.5] < 0.6, spread
    with pytest.raises(ValueError, match="discrete"):
        train("CartPole-v1", Config(explore_noise=0.1, n_steps=64, batch_size=64), steps=64)


def test_the_deterministic_policy_clips_to_the_environments_own_action_bounds(tmp_path):
    import gymnasium as gym

    from rlcore.checkpoint import load_checkpoint, save_checkpoint

    config = Config(n_steps=64, batch_size=64, n_epochs=1, eval_every=0)
    result = train("Pendulum-v1", config, steps=64, seed=0, out=tmp_path / "run")
    assert list(result.policy.low) == [-2.0] and list(result.policy.high) == [2.0]  # not ClipAction's +-inf
    ckpt = load_checkpoint(tmp_path / "run" / "checkpoint.pt")
    assert ckpt["spaces"]["low"] == [-2.0] and not evaluated_unclipped(ckpt)
    with torch.no_grad():
        result.agent.actor[-1].bias.fill_(50.0)  # a mean far outside the bounds
    assert result.policy(np.zeros(3)).tolist() == [2.0]
    # a checkpoint from before the fix, with infinite bounds, gets the environment's
    ckpt["spaces"] = {**ckpt["spaces"], "low": [-np.inf], "high": [np.inf]}
    save_checkpoint(tmp_path / "old.pt", ckpt)
    assert evaluated_unclipped(load_checkpoint(tmp_path / "old.pt"))
    policy = load_policy(load_checkpoint(tmp_path / "old.pt"))
    assert policy.low.tolist() == gym.make("Pendulum-v1").action_space.low.tolist() == [-2.0]


def test_normalize_by_hand_and_a_single_element_is_not_nan():
    from rlcore.ppo import normalize

    x = torch.tensor([1.0, 2.0, 3.0])
    torch.testing.assert_close(normalize(x), (x - 2.0) / (1.0 + 1e-8))
    one = normalize(torch.tensor([5.0]))
    assert not torch.isnan(one).any() and one.item() == 5.0  # left as it is, as A2C does


def test_the_saved_policy_on_raw_observations_acts_as_the_training_wrapper_fed_the_network(tmp_path):
    """The policy saved with a run scales raw observations itself; it must give the same actions as the network
    fed through training's own Gymnasium wrappers (NormalizeObservation, then the clip) with the same statistics."""
    import gymnasium as gym

    from rlcore.checkpoint import load_checkpoint, load_running_stats
    from rlcore.envs import make_env
    from rlcore.envs import find_wrapper
    from rlcore.ppo import load_policy, make_envs

    config = Config(**SMALL)
    train("Pendulum-v1", config, steps=1_024, seed=0, out=tmp_path)
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    policy = load_policy(ckpt)

    envs = make_envs("Pendulum-v1", config, seed=0)  # training's wrapper chain, with the run's final statistics
    norm = find_wrapper(envs, gym.wrappers.vector.NormalizeObservation)
    clip = find_wrapper(envs, gym.wrappers.vector.TransformObservation)
    load_running_stats(norm.obs_rms, ckpt, "obs")
    norm.update_running_mean = False

    env = make_env("Pendulum-v1", seed=1)
    obs, _ = env.reset(seed=1)
    raw = []
    for _ in range(64):
        raw.append(obs)
        obs, *_ = env.step(env.action_space.sample())
    raw = np.array(raw, dtype=np.float32) * np.array([1.0, 1.0, 3.0], dtype=np.float32)  # reach the clip too
    fed = clip.func(norm.observations(raw))
    assert np.abs(fed).max() > 1.0  # the statistics really scale the observations
    with torch.no_grad():
        wanted = policy.agent.deterministic(torch.as_tensor(fed, dtype=torch.float32)).numpy()
    wanted = np.clip(wanted, -2.0, 2.0)
    got = np.array([policy(o) for o in raw])
    np.testing.assert_allclose(got, wanted, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("env_id", ["Pendulum-v1", "Hopper-v5"])
def test_a_run_stopped_between_two_iterations_and_resumed_is_the_uninterrupted_run(tmp_path, env_id):
    """The checkpoint holds each copy's episode in progress (and the reward normalizer's running return): the
    resumed run goes on with them, so it is the uninterrupted run, bit for bit."""
    from rlcore.checkpoint import load_checkpoint

    torch.set_num_threads(1)
    cfg = Config(**{**SMALL, "n_steps": 128}, anneal_lr=False)
    whole = train(env_id, cfg, steps=1_024, seed=2, out=tmp_path / "whole")
    train(env_id, cfg, steps=512, seed=2, out=tmp_path / "parts")
    assert "episode_env" in load_checkpoint(tmp_path / "parts" / "checkpoint.pt")
    resumed = train(env_id, cfg, steps=1_024, seed=2, out=tmp_path / "parts")
    for key, value in whole.agent.state_dict().items():
        assert torch.equal(value, resumed.agent.state_dict()[key]), key
    done = len(whole.episode_returns) - len(resumed.episode_returns)  # episodes ended before the stop
    assert len(resumed.episode_returns) > 0
    np.testing.assert_array_equal(whole.episode_returns[done:], resumed.episode_returns)


def _kl_read_by_the_rule(n_epochs: int, n_batches: int) -> tuple[float, float]:
    """(the KL ppo_update hands the adaptive rule, the KL of the whole batch after all the updates: the paper's d)."""
    torch.manual_seed(0)
    config = Config(objective="kl", n_steps=256, batch_size=256 // n_batches, n_epochs=n_epochs, learning_rate=1e-2,
                    normalize_obs=False, normalize_reward=False)
    envs = ppo.make_envs("Pendulum-v1", config, seed=0)
    spaces = ppo.check_spaces(envs, "Pendulum-v1")
    agent, buf = ppo.make_agent(spaces, config), ppo.Rollout(spaces, config.n_steps, config.num_envs)
    obs, _ = envs.reset(seed=0)
    ppo.collect_rollout(agent, envs, obs, buf)
    batch = ppo.rollout_batch(buf, config)
    _, read = ppo.ppo_update(agent, ppo.make_optimizer(agent, config), batch, config, 1.0, np.random.default_rng(0))
    with torch.no_grad():
        after = approx_kl(batch["logp"], agent(batch["obs"], batch["act"])[0]).item()
    return read, after


def test_the_adaptive_kl_rule_reads_the_kl_before_each_minibatch_step_not_the_papers_kl_after_the_update():
    """What rlcore's docstring and chapter 6 say: the rule reads the mean over the last epoch's minibatches of the KL
    each measured just before its own step, not the paper's d measured after all of the iteration's updates."""
    read, after = _kl_read_by_the_rule(n_epochs=1, n_batches=1)
    assert read == 0.0 and after > 1e-4, (read, after)   # one step: it reads KL(pi_old, pi_old); the step moved pi
    read, after = _kl_read_by_the_rule(n_epochs=4, n_batches=1)
    assert 0 < read < after, (read, after)                 # the KL after 3 of the 4 steps, below the one after all 4
