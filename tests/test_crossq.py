"""rlcore.crossq: the joint pass against separate passes, the target from the live critics, no target network,
the networks' modes, resume bit for bit across the end of the warm-up, render, and a short run that learns."""

import json

import pytest
import torch

from commandline import command
from rlcore import crossq
from rlcore.batchrenorm import BatchRenorm, batch_stats
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy

SMALL = dict(hidden=(32, 32), critic_hidden=(64, 64), learning_starts=100, batch_size=32, buffer_size=5_000,
             eval_every=0, bn_warmup=150)


def critic_and_batch(renorm, seed=0, n=16):
    torch.manual_seed(seed)
    critic = crossq.NormalizedTwinCritic(3, 2, (16, 16), renorm)
    g = torch.Generator().manual_seed(seed + 1)
    s, a, s2, a2 = (torch.randn(n, d, generator=g) * 3 + 1 for d in (3, 2, 3, 2))
    return critic, (s, a, s2 * 4 - 5, a2)


def test_without_batch_norm_the_joint_pass_is_two_separate_passes():
    critic, batch = critic_and_batch(None)
    for x, y in zip(crossq.joint_q(critic, *batch), crossq.separate_q(critic, *batch)):
        torch.testing.assert_close(x, y)
    torch.manual_seed(0)  # the same draws: chapter 8's twin critic, with no norm layers
    base = crossq.TwinCritic(3, 2, (16, 16))
    torch.testing.assert_close(base(*batch[:2]), critic(*batch[:2]))


def test_with_batch_norm_the_joint_pass_normalizes_both_halves_by_the_same_statistics():
    renorm = crossq.Config().renorm()
    critic, (s, a, s2, a2) = critic_and_batch(renorm)
    # the same batch twice has the batch's own mean and (biased) variance: joint = separate
    q_joint, _ = crossq.joint_q(critic, s, a, s, a, track=False)
    q_apart, _ = crossq.separate_q(critic, s, a, s, a, track=False)
    torch.testing.assert_close(q_joint, q_apart)
    # a next batch from elsewhere: apart, each half is centred on its own; jointly, on the mixture
    joint = crossq.joint_q(critic, s, a, s2, a2, track=False)
    apart = crossq.separate_q(critic, s, a, s2, a2, track=False)
    assert (joint[0] - apart[0]).abs().max() > 1e-2 and (joint[1] - apart[1]).abs().max() > 1e-2
    with batch_stats(critic, track=False):
        both = critic(torch.cat([s, s2]), torch.cat([a, a2]))
    torch.testing.assert_close(torch.cat(joint, dim=-1), both)
    assert joint[0].requires_grad and not joint[1].requires_grad  # the target half carries no gradient


def test_a_pass_updates_running_statistics_only_when_asked_and_acting_uses_them():
    critic, batch = critic_and_batch(crossq.Config().renorm())
    norms = [m for m in critic.modules() if isinstance(m, BatchRenorm)]
    assert len(norms) == 3 and all(not m.training for m in norms)
    crossq.joint_q(critic, *batch, track=False)
    assert all(int(m.batches) == 0 for m in norms)
    crossq.joint_q(critic, *batch)
    assert all(int(m.batches) == 1 and not m.training for m in norms)
    # evaluation mode: one state at a time gives the same value as inside a batch (no batch statistics)
    s, a = batch[0], batch[1]
    torch.testing.assert_close(critic(s[:1], a[:1]), critic(s, a)[:, :1])


def test_the_target_is_sac_s_soft_target_from_the_live_critics():
    q_next = torch.tensor([[1.0, 5.0, -2.0], [3.0, 4.0, -1.0]])
    logp, r, done = torch.tensor([0.5, -1.0, 2.0]), torch.tensor([1.0, 0.0, 2.0]), torch.tensor([0.0, 0.0, 1.0])
    y = crossq.crossq_target(q_next, logp, r, done, gamma=0.9, alpha=0.2)
    torch.testing.assert_close(y, torch.tensor([1 + 0.9 * (1 - 0.1), 0.9 * (4 + 0.2), 2.0]))


def test_a_stopped_and_resumed_run_is_the_uninterrupted_run_across_the_warm_up(tmp_path):
    torch.set_num_threads(1)
    cfg = crossq.Config(**{**SMALL, "checkpoint_every": 100_000, "eval_every": 100})
    whole = crossq.train("Pendulum-v1", cfg, steps=500, seed=3, out=tmp_path / "whole")
    crossq.train("Pendulum-v1", cfg, steps=203, seed=3, out=tmp_path / "parts")  # inside the warm-up
    resumed = crossq.train("Pendulum-v1", cfg, steps=500, seed=3, out=tmp_path / "parts")
    for a, b in ((whole.actor, resumed.actor), (whole.critic, resumed.critic)):
        state_a, state_b = a.state_dict(), b.state_dict()
        assert all(torch.equal(state_a[k], state_b[k]) for k in state_a)
    counts = [int(m.batches) for m in resumed.critic.modules() if isinstance(m, BatchRenorm)]
    assert counts == [401] * 3  # one training pass a step from step 100: past the warm-up of 150
    assert whole.alphas[-1] == resumed.alphas[-1] and whole.alphas[0] != whole.alphas[-1]
    assert not any(k.startswith("critic_target") for k in torch.load(tmp_path / "parts" / "checkpoint.pt",
                                                                     weights_only=True))


def test_a_short_run_on_pendulum_clearly_beats_random():
    torch.set_num_threads(1)
    cfg = crossq.Config(hidden=(64, 64), critic_hidden=(128, 128), learning_starts=500, batch_size=64,
                        buffer_size=10_000, eval_every=0, bn_warmup=1000)
    # at 3,000 steps seeds 0, 1 and 2 score about -170, -140 and -270 here (a random policy: about -1,200)
    result = crossq.train("Pendulum-v1", cfg, steps=3_000, seed=0)
    returns = evaluate_policy(result.policy, make_env("Pendulum-v1"), episodes=5, seed=3)
    assert returns.mean() > -600, returns


def test_render_through_the_command_line(tmp_path):
    pytest.importorskip("imageio")
    out = tmp_path / "run"
    train = command("rlcore", "train", "crossq", "--env", "Pendulum-v1", "--steps", "150", "--out", out,
                    "--no-progress", "--set", "learning_starts=100", "--set", "hidden=[16]",
                    "--set", "critic_hidden=[16]", check=False)
    assert train.returncode == 0, train.stderr
    gif = tmp_path / "p.gif"
    proc = command("rlcore", "render", out, "--out", gif, "--frames", "20", check=False)
    if proc.returncode != 0 and "OpenGL" in proc.stderr:
        pytest.skip(proc.stderr.strip().splitlines()[-1])
    assert proc.returncode == 0, proc.stderr
    assert gif.stat().st_size > 1000
    assert json.loads(command("rlcore", "evaluate", out, "--episodes", "1").stdout.splitlines()[-1])["algo"] == "crossq"
