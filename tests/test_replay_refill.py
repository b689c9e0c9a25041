"""A run resumed without its replay memory (``replay_in_checkpoint=False``) refills the memory for
``learning_starts`` steps before it learns again, and says so in one line; one resumed with its memory learns on at
once, saying nothing. A DDPG checkpoint without its noise's state is refused, as rlcore.noise says."""

import pytest
import torch

from rlcore import ddpg, dqn, sac, td3
from rlcore.buffers import ReplayBuffer
from rlcore.checkpoint import load_checkpoint, save_checkpoint

OFF_POLICY = dict(hidden=(16, 16), learning_starts=100, batch_size=16, buffer_size=5_000, eval_every=0,
                  checkpoint_every=100_000)


@pytest.fixture
def memory_sizes(monkeypatch):
    """The memory's size at every minibatch drawn from it (every learning step's), in order."""
    sizes: list[int] = []
    real = ReplayBuffer.sample

    def sample(self, *args, **kwargs):
        sizes.append(len(self))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(ReplayBuffer, "sample", sample)
    return sizes


@pytest.mark.parametrize("module", [td3, sac], ids=["td3", "sac"])
@pytest.mark.parametrize("in_checkpoint", [False, True])
def test_an_off_policy_resume_without_the_memory_refills_it_before_learning(tmp_path, module, in_checkpoint,
                                                                          memory_sizes, capsys):
    torch.set_num_threads(1)
    cfg = module.Config(**OFF_POLICY, replay_in_checkpoint=in_checkpoint)
    module.train("Pendulum-v1", cfg, steps=317, seed=3, out=tmp_path)
    assert len(memory_sizes) == 317 - 100 + 1  # learning from step 100 on, one minibatch a step
    capsys.readouterr()
    memory_sizes.clear()
    module.train("Pendulum-v1", cfg, steps=600, seed=3, out=tmp_path)
    err = capsys.readouterr().err
    if in_checkpoint:  # learning goes on at once, from the restored memory
        assert memory_sizes[0] == 318 and len(memory_sizes) == 600 - 317 and "refilling" not in err
    else:  # 100 steps to refill the memory, then one minibatch a step from step 417 on
        assert memory_sizes[0] == 100 and len(memory_sizes) == 600 - 417 + 1
        assert err.strip().splitlines() == ["resumed at step 317 without the replay memory "
                                            "(replay_in_checkpoint=False): refilling it for 100 steps, learning "
                                            "again from step 417"]


def test_a_dqn_resume_without_the_memory_refills_it_before_learning(tmp_path, memory_sizes, capsys,
                                                                    interrupt_at_first_checkpoint):
    torch.set_num_threads(1)
    cfg = dqn.Config(train_freq=4, gradient_steps=2, hidden=(16,), learning_starts=200, eval_every=0,
                     checkpoint_every=800, replay_in_checkpoint=False)
    interrupt_at_first_checkpoint(dqn)
    with pytest.raises(KeyboardInterrupt):  # the budget shapes epsilon's schedule: stopped, not extended
        dqn.train("CartPole-v1", cfg, steps=1_500, seed=1, out=tmp_path)
    assert load_checkpoint(tmp_path / "checkpoint.pt")["step"] == 800
    capsys.readouterr()
    memory_sizes.clear()
    dqn.train("CartPole-v1", cfg, steps=1_500, seed=1, out=tmp_path)
    assert "learning again from step 1,000" in capsys.readouterr().err
    assert memory_sizes[0] == 200 and len(memory_sizes) == 2 * len(range(1_000, 1_501, 4))


def test_a_ddpg_checkpoint_without_the_noise_state_is_refused_in_one_line(tmp_path):
    cfg = ddpg.Config(**OFF_POLICY)
    ddpg.train("Pendulum-v1", cfg, steps=150, seed=0, out=tmp_path)
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    del ckpt["noise"]  # as a checkpoint from before rlcore saved it
    save_checkpoint(tmp_path / "checkpoint.pt", {k: v for k, v in ckpt.items() if k not in ("format",
                                                                                            "format_version")})
    with pytest.raises(ValueError, match=r"holds a checkpoint without 'noise', which this run needs") as refused:
        ddpg.train("Pendulum-v1", cfg, steps=300, seed=0, out=tmp_path)
    assert "\n" not in str(refused.value)
