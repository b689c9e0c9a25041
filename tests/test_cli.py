"""The command line, driven the way a user (or another tool) drives it. The run the module shares is trained by a
real ``python -m rlcore`` process, and the interrupts are signals to one; the other commands call the same ``main``
in this process (tests/commandline.py says why)."""

import json
import signal
import subprocess
import sys
import time

import pytest

from commandline import command
from rlcore.checkpoint import load_checkpoint


def rlcore(*args, check=True, process=False):
    return command("rlcore", *args, check=check, process=process)


@pytest.fixture(scope="module")
def frozenlake_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "fl"
    rlcore("train", "q-learning", "--env", "FrozenLake-v1", "--steps", 15000, "--seed", 0, "--out", out,
           "--env-kwargs", '{"is_slippery": false}', "--no-progress", process=True)
    return out


def test_train_writes_the_run_folder(frozenlake_run):
    for name in ("config.json", "meta.json", "progress.csv", "checkpoint.pt"):
        assert (frozenlake_run / name).is_file()
    meta = json.loads((frozenlake_run / "meta.json").read_text())
    assert meta["command"].startswith("python -m rlcore train q-learning") and meta["versions"]["gymnasium"]
    config = json.loads((frozenlake_run / "config.json").read_text())
    assert config["config"]["env_kwargs"] == {"is_slippery": False} and config["seed"] == 0


def test_evaluate_prints_json_last(frozenlake_run):
    out = rlcore("evaluate", frozenlake_run, "--episodes", 4, process=True).stdout
    result = json.loads(out.strip().splitlines()[-1])
    assert result["episodes"] == 4
    assert result["mean_return"] == 1.0 and result["std_return"] == 0.0
    assert result["env_id"] == "FrozenLake-v1"


def test_render_writes_a_gif(frozenlake_run, tmp_path):
    gif = tmp_path / "fl.gif"
    rlcore("render", frozenlake_run, "--out", gif, "--frames", 8, process=True)
    assert gif.read_bytes()[:6] == b"GIF89a"


def test_set_overrides_config_fields(tmp_path):
    rlcore("train", "sarsa", "--env", "CliffWalking-v1", "--steps", 500, "--out", tmp_path / "c",
           "--set", "alpha=0.5", "--set", "gamma=1", "--no-progress")
    config = json.loads((tmp_path / "c" / "config.json").read_text())["config"]
    assert config["method"] == "sarsa" and config["alpha"] == 0.5 and config["gamma"] == 1.0
    bad = rlcore("train", "sarsa", "--env", "CliffWalking-v1", "--steps", 5, "--out", tmp_path / "d",
                 "--set", "alpah=0.5", check=False)
    assert bad.returncode == 2 and "no field 'alpah'" in bad.stderr


def test_set_takes_a_network_shape_as_one_number_or_several():
    from rlcore import ddpg
    from rlcore.cli import overrides as _overrides

    for text, hidden in (("16", (16,)), ("64,64", (64, 64)), ("[32, 8]", (32, 8))):
        assert ddpg.Config(**_overrides(ddpg.Config, [f"hidden={text}"])).hidden == hidden
    assert _overrides(ddpg.Config, ["normalize_obs=true", "tau=1"]) == {"normalize_obs": True, "tau": 1.0}


def test_resuming_with_other_settings_is_one_clear_line(tmp_path):
    common = ["--env", "Pendulum-v1", "--out", tmp_path, "--set", "learning_starts=50", "--set", "hidden=8",
              "--no-progress"]
    rlcore("train", "ddpg", "--steps", 100, *common)
    bad = rlcore("train", "ddpg", "--steps", 200, *common, "--set", "normalize_obs=true", check=False)
    assert bad.returncode == 2 and "other settings (normalize_obs: False -> True)" in bad.stderr
    assert "Traceback" not in bad.stderr


@pytest.mark.parametrize(
    "args, message",
    [
        (["train", "q-learning", "--env", "Frozenlake-v1", "--steps", 5], "Did you mean 'FrozenLake-v1'"),
        (["train", "q-lerning", "--env", "FrozenLake-v1", "--steps", 5], "Did you mean 'q-learning'"),
        (["train", "q-learning", "--env", "Hopper-v5", "--steps", 5], "discrete states and actions"),
    ],
)
def test_bad_training_input_is_one_clear_line(args, message, tmp_path):
    proc = rlcore(*args, "--out", tmp_path / "x", check=False)
    assert proc.returncode == 2
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_corrupt_checkpoint_is_a_clear_error(frozenlake_run, tmp_path):
    broken = tmp_path / "broken"
    broken.mkdir()
    data = (frozenlake_run / "checkpoint.pt").read_bytes()
    (broken / "checkpoint.pt").write_bytes(data[: len(data) // 3])
    for cmd in (["evaluate", broken], ["render", broken, "--out", tmp_path / "x.gif"]):
        proc = rlcore(*cmd, check=False)
        assert proc.returncode == 2
        assert "not an rlcore checkpoint" in proc.stderr or "could not be loaded" in proc.stderr
        assert "Traceback" not in proc.stderr and "pickle" not in proc.stderr.lower().split("error:")[0]
    proc = rlcore("evaluate", tmp_path / "empty-folder-that-does-not-exist", check=False)
    assert proc.returncode == 2 and "No checkpoint" in proc.stderr


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_interrupt_leaves_a_usable_checkpoint_and_resumes(tmp_path, sig):
    out = tmp_path / "long"
    cmd = [sys.executable, "-m", "rlcore", "train", "q-learning", "--env", "Taxi-v4", "--steps", "50000000",
           "--out", str(out), "--no-progress", "--set", "checkpoint_every=100000000"]
    # started with SIGINT ignored, as a shell starts a background job (`cmd &`): the run must still stop on it
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        deadline = time.monotonic() + 120
        progress = out / "progress.csv"
        # wait for the event "it has trained a little": two episodes logged (polled, not a fixed sleep)
        while time.monotonic() < deadline and proc.poll() is None and \
                not (progress.exists() and len(progress.read_text().splitlines()) >= 3):
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()[1]
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:  # it ignored the signal: do not leave it training after the test
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    assert "Checkpoint saved" in err
    ckpt = load_checkpoint(out / "checkpoint.pt")
    assert 0 < ckpt["step"] < 50_000_000 and not ckpt["complete"]
    result = json.loads(rlcore("evaluate", out, "--episodes", 2, "--max-steps", 50).stdout.splitlines()[-1])
    assert result["train_steps"] == ckpt["step"]
    # the same command with a budget already reached finishes at once from the checkpoint
    rlcore("train", "q-learning", "--env", "Taxi-v4", "--steps", ckpt["step"], "--out", out, "--no-progress")
    assert load_checkpoint(out / "checkpoint.pt")["step"] == ckpt["step"]


def test_dqn_through_the_command_line(tmp_path):
    out = tmp_path / "dqn"
    rlcore("train", "dqn", "--env", "CartPole-v1", "--steps", 1500, "--out", out, "--no-progress",
           "--set", "double=true", "--set", "dueling=true", "--set", "hidden=[32]", "--set", "eval_every=500")
    assert json.loads((out / "config.json").read_text())["config"]["hidden"] == [32]
    assert (out / "eval.csv").read_text().count("\n") == 4  # header + evaluations at 500, 1000, 1500
    result = json.loads(rlcore("evaluate", out, "--episodes", 2).stdout.splitlines()[-1])
    assert result["algo"] == "dqn" and result["episodes"] == 2
    proc = rlcore("train", "dqn", "--env", "Pendulum-v1", "--steps", 10, "--out", tmp_path / "p", check=False)
    assert proc.returncode == 2 and "discrete action space" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("env_id", ["Pendulum-v1", "CartPole-v1"])
def test_ppo_through_the_command_line_on_continuous_and_discrete_tasks(env_id, tmp_path):
    out = tmp_path / "ppo"
    rlcore("train", "ppo", "--env", env_id, "--steps", 512, "--out", out, "--no-progress",
           "--set", "n_steps=256", "--set", "objective=kl", "--set", "eval_every=512")
    assert json.loads((out / "config.json").read_text())["config"]["objective"] == "kl"
    result = json.loads(rlcore("evaluate", out, "--episodes", 1).stdout.splitlines()[-1])
    assert result["algo"] == "ppo" and result["train_steps"] == 512


def test_ddpg_through_the_command_line(tmp_path):
    out = tmp_path / "ddpg"
    rlcore("train", "ddpg", "--env", "Pendulum-v1", "--steps", 400, "--out", out, "--no-progress",
           "--set", "learning_starts=200", "--set", "hidden=[32]", "--set", "exploration=ou", "--set", "eval_every=400")
    result = json.loads(rlcore("evaluate", out, "--episodes", 1).stdout.splitlines()[-1])
    assert result["algo"] == "ddpg" and result["train_steps"] == 400
    proc = rlcore("train", "ddpg", "--env", "CartPole-v1", "--steps", 10, "--out", tmp_path / "c", check=False)
    assert proc.returncode == 2 and "continuous" in proc.stderr and "Traceback" not in proc.stderr


BAD_INPUT = [
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "-5"], "--steps: expected an integer >= 1, got -5"),
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "ten"], "--steps: expected an integer >= 1, got 'ten'"),
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "10", "--seed", "-1"], "--seed: expected an integer >= 0"),
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "10", "--set", "actor_lr=-1"], "actor_lr must be > 0"),
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "10", "--set", "actor_lr=fast"], "actor_lr must be a number"),
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "10", "--set", "batch_size=0"], "batch_size must be >= 1"),
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "10", "--set", "batch_size=2.5"], "must be an integer"),
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "10", "--set", "tau=0"], "tau must be in (0, 1]"),
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "10", "--set", "hidden=0"], "layer size must be >= 1"),
    (["train", "ddpg", "--env", "Pendulum-v1", "--steps", "10", "--set", "normalize_obs=maybe"], "true or false"),
    (["train", "dqn", "--env", "CartPole-v1", "--steps", "10", "--set", "gamma=1.5"], "gamma must be in [0, 1]"),
    (["train", "ppo", "--env", "CartPole-v1", "--steps", "10", "--set", "n_epochs=0"], "n_epochs must be >= 1"),
    (["train", "ppo", "--env", "CartPole-v1", "--steps", "10", "--set", "learning_rate=nan"], "learning_rate must be"),
    (["train", "a2c", "--env", "CartPole-v1", "--steps", "10", "--set", "num_envs=-2"], "num_envs must be >= 1"),
    (["train", "q-learning", "--env", "FrozenLake-v1", "--steps", "10", "--set", "alpha=0"], "alpha must be in (0, 1]"),
    (["train", "q-learning", "--env", "FrozenLake-v1", "--steps", "10", "--env-kwargs", "slippery"], "a JSON object"),
    (["train", "q-learning", "--env", "FrozenLake-v1", "--steps", "10", "--set", "env_kwargs=5"], "a JSON object"),
    (["train", "dqn", "--env", "CartPole-v1", "--steps", "10", "--set", "hidden=[]", "--set", "dueling=true"],
     "at least one hidden layer"),
    (["evaluate", "runs/none", "--episodes", "0"], "--episodes: expected an integer >= 1, got 0"),
    (["render", "runs/none", "--out", "x.gif", "--frames", "0"], "--frames: expected an integer >= 1"),
    (["render", "runs/none", "--out", "x.gif", "--fps", "-3"], "--fps: expected an integer >= 1"),
]
BAD_EXPERIMENTS_INPUT = [  # python -m rlbook, the book's command line
    (["experiments", "run", "dqn-cartpole", "--jobs", "0"], "--jobs: expected an integer >= 1"),
    (["experiments", "run", "dqn-cartpole", "--seeds", "one"], "--seeds: expected comma-separated integers"),
    (["experiments", "run", "dqn-cartpole", "--only", "nope"], "dqn-cartpole has no run 'nope'"),
    (["experiments", "run", "dqn-cartpole", "--seeds", "99"], "dqn-cartpole has no seed [99]"),
]


@pytest.mark.parametrize("args, message", BAD_INPUT + BAD_EXPERIMENTS_INPUT,
                         ids=[" ".join(a[:2] + a[-2:]) for a, _ in BAD_INPUT + BAD_EXPERIMENTS_INPUT])
def test_every_bad_value_is_one_line_before_any_work(args, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "run"
    argv = [*args, "--out", str(out)] if args[0] == "train" else args
    proc = command("rlbook" if args[0] == "experiments" else "rlcore", *argv, check=False)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert not out.exists() and not (tmp_path / "runs").exists()  # refused before any work


def test_the_library_points_to_the_book_for_experiments():
    proc = rlcore("experiments", "run", "dqn-cartpole", "--jobs", "2", check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip() == ("error: the book's experiments are run by "
                                   "`python -m rlbook experiments run dqn-cartpole --jobs 2`")


def test_dppo_refuses_bad_values_the_same_way(tmp_path):
    proc = command("rlcore.dppo", "--env", "Pendulum-v1", "--steps", "0", "--out", tmp_path / "d", check=False)
    assert proc.returncode == 2 and "--steps: expected an integer >= 1, got 0" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_evaluate_and_render_take_a_results_folder_with_its_policy(frozenlake_run, tmp_path):
    from rlbook.runner import export_policy

    seed_folder = tmp_path / "results" / "exp" / "variant" / "seed-0"  # as `experiments run` leaves it
    export_policy(frozenlake_run / "checkpoint.pt", seed_folder / "policy.pt")
    result = json.loads(rlcore("evaluate", seed_folder, "--episodes", "3").stdout.strip().splitlines()[-1])
    assert result["algo"] == "q-learning" and result["episodes"] == 3
    rlcore("render", seed_folder, "--out", tmp_path / "seed.gif", "--frames", "5")
    assert (tmp_path / "seed.gif").read_bytes()[:6] == b"GIF89a"
    proc = rlcore("evaluate", tmp_path, check=False)  # a folder with neither names both
    assert proc.returncode == 2 and "checkpoint.pt" in proc.stderr and "policy.pt" in proc.stderr
