"""rlcore.harness.Run: what every train's loop relies on, tested on a toy loop without an algorithm."""

from __future__ import annotations

import os
import signal
from dataclasses import dataclass, field

import numpy as np
import pytest
import torch

import rlcore.harness as harness
from rlcore.checkpoint import load_checkpoint
from rlcore.harness import Evaluation, Run, Saved, crossed, running_stats, torch_rng
from rlcore.logger import read_csv


@dataclass
class ToyConfig:
    lr: float = 0.1
    eval_every: int = 4
    checkpoint_every: int = 5
    env_kwargs: dict = field(default_factory=dict)


@pytest.fixture
def sigint():
    """SIGINT raises KeyboardInterrupt, as in a terminal or a notebook."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


class Closable:
    closed = False

    def close(self):
        self.closed = True


def toy_run(out, steps=10, interrupt_at=None, evaluate=True, at_end=False, **kw):
    """A loop that 'learns' one weight, ends an 'episode' every 3 steps and is evaluated and checkpointed; with
    ``interrupt_at``, Ctrl-C comes in the middle of that step."""
    torch.manual_seed(0)
    net = torch.nn.Linear(1, 1)
    opt = torch.optim.SGD(net.parameters(), lr=0.1)
    rng = np.random.default_rng(0)
    box = Closable()
    evaluation = Evaluation(lambda: {"mean_return": float(net.weight.item()), "std_return": 0.0, "episodes": 1},
                            at_end=at_end)
    run = Run("toy", "Toy-v0", ToyConfig(), steps, 0, out, close=(box,), desc="toy",
              evaluation=evaluation if evaluate else None, **kw)
    run.restores(net=net, opt=opt, rng=rng, torch_rng=torch_rng(), nothing=None)
    run.records(spaces={"n": 1})
    step, episode = run.resume(step=0, episode=0)
    with run:
        while step < steps:
            loss = (net(torch.ones(1)) - rng.normal()).pow(2).sum()
            opt.zero_grad()
            loss.backward()
            opt.step()
            step += 1
            if interrupt_at == step:
                os.kill(os.getpid(), signal.SIGINT)
            if step % 3 == 0:
                episode += 1
                run.record_episode(step, float(step), 3)
            run.step_done(step, step - 1, episode=episode)
    return run, net, box


def test_an_interrupted_run_resumes_to_exactly_the_uninterrupted_one(tmp_path, sigint):
    whole, net_whole, _ = toy_run(tmp_path / "whole")
    with pytest.raises(KeyboardInterrupt):
        toy_run(tmp_path / "cut", interrupt_at=8)
    ckpt = load_checkpoint(tmp_path / "cut" / "checkpoint.pt")
    # the eighth step ran to its end: the checkpoint counts it; what the run restores and what it only records are
    # in it, None is not
    assert ckpt["step"] == 8 and ckpt["episode"] == 2 and not ckpt["complete"]
    assert ckpt["spaces"] == {"n": 1} and "nothing" not in ckpt and {"net", "opt", "rng", "torch_rng"} <= set(ckpt)
    # the resumed run finishes the budget, its log has every episode once, and it is the uninterrupted run
    resumed, net_again, _ = toy_run(tmp_path / "cut")
    assert resumed.episode_end_steps.tolist() == [9] and load_checkpoint(tmp_path / "cut" / "checkpoint.pt")["complete"]
    assert read_csv(tmp_path / "cut" / "progress.csv")["step"].tolist() == [3, 6, 9]
    assert torch.equal(net_whole.weight, net_again.weight) and torch.equal(net_whole.bias, net_again.bias)
    # stopped at a step that ends an episode and crosses a checkpoint step
    with pytest.raises(KeyboardInterrupt):
        toy_run(tmp_path / "exact", interrupt_at=6)
    assert load_checkpoint(tmp_path / "exact" / "checkpoint.pt")["step"] == 6
    again, net_again, _ = toy_run(tmp_path / "exact")
    assert torch.equal(net_whole.weight, net_again.weight) and torch.equal(net_whole.bias, net_again.bias)
    log = read_csv(tmp_path / "exact" / "progress.csv")
    assert log["episode"].tolist() == [1, 2, 3] and log["step"].tolist() == [3, 6, 9]  # no row twice
    assert read_csv(tmp_path / "exact" / "eval.csv")["step"].tolist() == [4, 8]


def test_evaluations_checkpoints_and_the_end(tmp_path, monkeypatch):
    saved = []
    real = harness.save_checkpoint
    monkeypatch.setattr(harness, "save_checkpoint",
                        lambda path, state: (saved.append(state["step"]), real(path, state)))
    run, net, box = toy_run(tmp_path, steps=10)
    assert saved == [5, 10]  # every checkpoint_every steps, and at the end
    assert run.eval_steps.tolist() == [4, 8] and run.eval_returns.shape == (2,)
    assert run.episode_returns.tolist() == [3.0, 6.0, 9.0] and run.episode_end_steps.tolist() == [3, 6, 9]
    assert run.episode_lengths.tolist() == [3, 3, 3]
    assert box.closed and load_checkpoint(tmp_path / "checkpoint.pt")["complete"]
    saved.clear()
    toy_run(tmp_path / "twelve", steps=15)
    assert saved == [5, 10, 15]  # the end coincides with a periodic checkpoint: written once


def test_eval_at_end_and_a_target_beyond_the_budget(tmp_path):
    run, _, _ = toy_run(tmp_path, steps=10, target=10, at_end=True)
    assert run.eval_steps.tolist() == [4, 8, 10]


def test_without_a_folder_nothing_is_written_and_the_loop_still_runs(tmp_path):
    run, _, box = toy_run(None, steps=6)
    assert run.folder is None and run.ckpt is None and box.closed
    assert run.eval_steps.tolist() == [4] and list(tmp_path.iterdir()) == []


def test_another_run_in_the_folder_is_refused(tmp_path):
    toy_run(tmp_path, steps=4)
    with pytest.raises(ValueError, match="other settings"):
        Run("toy", "Toy-v0", ToyConfig(lr=0.5), 4, 0, tmp_path, desc="toy")


def test_saved_pairs_and_running_statistics_round_trip(tmp_path):
    from gymnasium.wrappers.utils import RunningMeanStd

    rms = RunningMeanStd(shape=(2,))
    rms.update(np.array([[1.0, 2.0], [3.0, 6.0]]))
    table = np.arange(4.0)
    loaded = []
    run = Run("toy", "Toy-v0", ToyConfig(), 3, 0, tmp_path, desc="toy")
    run.restores(table=Saved(lambda: {"table": table}, lambda c: table.__setitem__(..., c["table"].numpy())),
                 obs=running_stats(rms, "obs", lambda: loaded.append(True)), ret=running_stats(None, "ret"))
    run.resume(step=3)
    with run:
        pass
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    assert ckpt["ret_mean"] is None and ckpt["obs_count"] == pytest.approx(rms.count)
    table[:] = 0
    rms.mean[:] = 0
    again = Run("toy", "Toy-v0", ToyConfig(), 3, 0, tmp_path, desc="toy")
    again.restores(table=Saved(lambda: {"table": table}, lambda c: table.__setitem__(..., c["table"].numpy())),
                   obs=running_stats(rms, "obs", lambda: loaded.append(True)))
    assert again.resume(step=0) == 3
    assert table.tolist() == [0.0, 1.0, 2.0, 3.0] and rms.mean.tolist() == pytest.approx([2.0, 4.0], rel=1e-3)
    assert loaded == [True]


def test_what_a_resume_cannot_restore_is_refused_and_goes_to_records(tmp_path):
    run = Run("toy", "Toy-v0", ToyConfig(), 3, 0, tmp_path, desc="toy")
    with pytest.raises(TypeError, match="cannot restore 'spaces'.*Run.records"):
        run.restores(spaces={"n": 1})
    run.records(spaces={"n": 1})
    run.resume(step=3)
    with run:
        pass
    assert load_checkpoint(tmp_path / "checkpoint.pt")["spaces"] == {"n": 1}


def test_crossed():
    assert crossed(4, 4, 3) and crossed(4, 9, 7) and not crossed(4, 7, 4) and not crossed(0, 8, 0)


def test_policies_and_evaluations_leave_every_network_in_training_mode():
    from rlcore.dqn import GreedyPolicy
    from rlcore.offpolicy import DeterministicPolicy
    from rlcore.onpolicy import ActorCritic, ActorCriticPolicy

    q, actor, agent = torch.nn.Linear(2, 2), torch.nn.Linear(2, 1), ActorCritic(2, 1, False, (4,))
    policies = GreedyPolicy(q), DeterministicPolicy(actor), ActorCriticPolicy(agent, low=[-1.0], high=[1.0])
    for policy in policies:
        policy(np.zeros(2, dtype=np.float32))
    assert q.training and actor.training and agent.training  # nothing for the harness to put back


def test_deferred_ctrl_c_stops_at_the_end_of_the_step_and_a_second_one_stops_at_once(tmp_path):
    import os
    import signal

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal or a notebook
    try:
        for presses, stopped_at in ((1, 4), (2, 3)):
            run = Run("toy", "Toy-v0", ToyConfig(checkpoint_every=100), 10, 0, tmp_path / f"p{presses}",
                      desc="toy")
            step, where = run.resume(step=0), []
            with pytest.raises(KeyboardInterrupt):
                with run:
                    while step < 10:
                        where.append("start")
                        if step == 3:  # Ctrl-C in the middle of the fourth step
                            for _ in range(presses):
                                os.kill(os.getpid(), signal.SIGINT)
                        where.append("end")
                        step += 1
                        run.step_done(step, step - 1)
            assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
            # one press: the fourth step ran to its end, and its checkpoint was written; two: it stopped where it
            # was, and wrote nothing (there was no checkpoint yet)
            if presses == 1:
                assert load_checkpoint(tmp_path / "p1" / "checkpoint.pt")["step"] == stopped_at
                assert where == ["start", "end"] * 4
            else:
                assert where[-1] == "start" and not (tmp_path / "p2" / "checkpoint.pt").exists()
    finally:
        signal.signal(signal.SIGINT, previous)


def test_a_checkpoint_without_a_tracked_key_is_refused_in_one_line(tmp_path):
    from rlcore.checkpoint import save_checkpoint

    toy_run(tmp_path, steps=10, target=20)  # an unfinished run, as a resume finds it
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    del ckpt["opt"]  # say, a replay memory the checkpoint was written without
    save_checkpoint(tmp_path / "checkpoint.pt",
                    {k: v for k, v in ckpt.items() if k not in ("format", "format_version")})
    with pytest.raises(ValueError) as err:
        toy_run(tmp_path, steps=10, target=20)
    message = str(err.value)
    assert "\n" not in message and "'opt'" in message and "another --out folder" in message


def test_the_loaded_checkpoint_is_released_once_the_run_is_resumed(tmp_path):
    import gc
    import weakref

    toy_run(tmp_path, steps=5, target=10)
    run = Run("toy", "Toy-v0", ToyConfig(), 5, 0, tmp_path, desc="toy")
    net = torch.nn.Linear(1, 1)
    run.restores(net=net)
    weight = weakref.ref(run.ckpt["net"]["weight"])  # one of the checkpoint's tensors, copied into net on resume
    assert run.resume(step=0) == 5
    gc.collect()
    assert weight() is None, "the run still holds the loaded checkpoint"
    with run:
        pass


def test_a_second_ctrl_c_in_the_middle_of_a_step_leaves_no_checkpoint_that_mixes_two_steps(tmp_path):
    import os
    import signal

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        net = torch.nn.Linear(1, 1)
        run = Run("toy", "Toy-v0", ToyConfig(checkpoint_every=2), 10, 0, tmp_path, desc="toy")
        run.restores(net=net)
        step = run.resume(step=0)
        with pytest.raises(KeyboardInterrupt):
            with run:
                while step < 10:
                    with torch.no_grad():
                        net.weight.fill_(step + 1.0)  # the step's first half: the weight is the step's number
                    if step == 3:  # Ctrl-C twice in the middle of the fourth step: stop at once
                        os.kill(os.getpid(), signal.SIGINT)
                        os.kill(os.getpid(), signal.SIGINT)
                    step += 1
                    run.step_done(step, step - 1)
    finally:
        signal.signal(signal.SIGINT, previous)
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    assert ckpt["net"]["weight"].item() == ckpt["step"] == 2  # the last whole step's checkpoint, not a mix


def test_a_ctrl_c_during_a_checkpoint_write_waits_for_the_write(tmp_path, monkeypatch):
    import os
    import signal

    real = harness.save_checkpoint

    def interrupted_save(path, state):  # Ctrl-C (or SIGTERM) arrives while the file is being written
        os.kill(os.getpid(), signal.SIGINT)
        real(path, state)

    monkeypatch.setattr(harness, "save_checkpoint", interrupted_save)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            toy_run(tmp_path, steps=10)
    finally:
        signal.signal(signal.SIGINT, previous)
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    # the first periodic checkpoint was written whole, then it stopped
    assert ckpt["step"] == 5 and not ckpt["complete"]
    assert read_csv(tmp_path / "progress.csv")["step"].tolist() == [3]
