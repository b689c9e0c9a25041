"""TD3, SAC and CrossQ through the command line: train, evaluate, the logs each writes, and bad settings refused in one line."""

import json

import pytest

from commandline import command

REFUSALS = {
    "td3": ((("--env", "CartPole-v1"), "TD3 needs a continuous (Box) action space"),
            (("--env", "Pendulum-v1", "--set", "policy_delay=0"), "policy_delay must be >= 1"),
            (("--env", "Pendulum-v1", "--set", "target_policy_noise=-1"), "must be >= 0")),
    "sac": ((("--env", "CartPole-v1"), "SAC needs a continuous (Box) action space"),
            (("--env", "Pendulum-v1", "--set", "alpha=-1"), "alpha must be > 0")),
    "crossq": ((("--env", "CartPole-v1"), "CrossQ needs a continuous (Box) action space"),
               (("--env", "Pendulum-v1", "--set", "r_max=0.5"), "r_max must be >= 1"),
               (("--env", "Pendulum-v1", "--set", "critic_hidden=0"), "every layer size must be >= 1")),
}
LOGS = {"td3": ("progress.csv", "eval.csv"), "sac": ("progress.csv", "eval.csv", "alpha.csv"),
        "crossq": ("progress.csv", "eval.csv", "alpha.csv")}


def rlcore(*args):
    return command("rlcore", *args, check=False)  # in this process: tests/commandline.py


@pytest.mark.parametrize("algo", ["td3", "sac", "crossq"])
def test_through_the_command_line(tmp_path, algo):
    out = tmp_path / algo
    proc = rlcore("train", algo, "--env", "Pendulum-v1", "--steps", 300, "--out", out, "--no-progress",
                  "--set", "learning_starts=100", "--set", "hidden=[32]", "--set", "eval_every=300",
                  *(("--set", "critic_hidden=[32]") if algo == "crossq" else ()))
    assert proc.returncode == 0, proc.stderr
    result = json.loads(rlcore("evaluate", out, "--episodes", 1).stdout.splitlines()[-1])
    assert result["algo"] == algo and result["train_steps"] == 300
    assert all((out / name).is_file() for name in LOGS[algo])
    if algo != "td3":
        assert (out / "alpha.csv").read_text().splitlines()[0] == "step,alpha,entropy"
    for args, message in REFUSALS[algo]:
        proc = rlcore("train", algo, *args, "--steps", 10, "--out", tmp_path / "bad")
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and message in lines[0], proc.stderr
