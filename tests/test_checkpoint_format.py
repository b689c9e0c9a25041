"""Checkpoints written by earlier code still resume: DDPG, TD3 and SAC runs stopped at step 317 by the code of
commit e1e7014 (tests/data/checkpoints/), resumed to 600 steps by this code. On the CPU that wrote them the resumed
run is, bit for bit, the uninterrupted run of that commit; elsewhere the bits may differ (other kernels), but the
resume must still load everything it needs and finish, writing a checkpoint with the same entries.

Long-running experiments (the Humanoid runs of chapter 8) resume such checkpoints: a change to the checkpoint's
entries or to what a resume restores fails here first."""

import hashlib
import json
import shutil
from pathlib import Path

import pytest
import torch

from rlcore.algos import get_algorithm
from rlcore.checkpoint import load_checkpoint
from rlcore.config import config_from_dict
from rlcore.machine import cpu_model

DATA = Path(__file__).parent / "data" / "checkpoints"
RECORD = json.loads((DATA / "resumed.json").read_text())


def sha256(module: torch.nn.Module) -> str:
    return hashlib.sha256(b"".join(p.detach().numpy().tobytes() for p in module.state_dict().values())).hexdigest()


@pytest.mark.parametrize("algo", sorted(RECORD["runs"]))
def test_a_checkpoint_of_earlier_code_resumes(tmp_path, algo):
    record = RECORD["runs"][algo]
    (tmp_path / "run").mkdir()
    shutil.copy(DATA / record["file"], tmp_path / "run" / "checkpoint.pt")
    ckpt = load_checkpoint(tmp_path / "run" / "checkpoint.pt")
    module = get_algorithm(algo)
    config = config_from_dict(module.Config, ckpt["config"])
    torch.set_num_threads(1)
    result = module.train(ckpt["env_id"], config, steps=RECORD["steps"], seed=ckpt["seed"], out=tmp_path / "run")
    assert result.steps == RECORD["steps"] and result.episode_end_steps.min() > record["stopped_at"]
    assert sorted(load_checkpoint(tmp_path / "run" / "checkpoint.pt")) == record["keys"]
    if cpu_model() == RECORD["cpu"]:  # the bits of the CPU and kernels that wrote the checkpoints
        assert (sha256(result.actor), sha256(result.critic)) == (record["actor_sha256"], record["critic_sha256"])
