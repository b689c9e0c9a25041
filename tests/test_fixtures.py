"""The shared fixtures of conftest.py do what they say."""

import pytest

import rlcore.dqn
import rlcore.tabular as tab
from rlcore.checkpoint import load_checkpoint


def _tabular(out, steps=300):
    return tab.train("FrozenLake-v1", tab.Config(checkpoint_every=100), steps=steps, seed=0, out=out)


def test_interrupt_at_first_checkpoint_interrupts_only_the_module_it_is_given(tmp_path, interrupt_at_first_checkpoint):
    calls = interrupt_at_first_checkpoint(rlcore.dqn)
    try:                                    # another module's train writes its checkpoints and is not stopped
        _tabular(tmp_path / "other")
    except KeyboardInterrupt:               # (a KeyboardInterrupt escaping a test would stop the whole session)
        pytest.fail("armed for rlcore.dqn, the fixture interrupted rlcore.tabular's train")
    assert calls == [] and load_checkpoint(tmp_path / "other" / "checkpoint.pt")["step"] == 300
    calls = interrupt_at_first_checkpoint(tab)
    with pytest.raises(KeyboardInterrupt):
        _tabular(tmp_path / "armed")
    assert calls == [100] and load_checkpoint(tmp_path / "armed" / "checkpoint.pt")["step"] == 100


def test_interrupt_at_first_checkpoint_refuses_a_module_without_train(interrupt_at_first_checkpoint):
    import rlcore.checkpoint

    with pytest.raises(TypeError, match="rlcore.checkpoint has no train function"):
        interrupt_at_first_checkpoint(rlcore.checkpoint)
