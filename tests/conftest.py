"""Shared test fixtures."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True, scope="session")
def one_torch_thread():
    """The book's networks are small: one torch thread is fastest, and it leaves the other core to the rest."""
    import torch

    torch.set_num_threads(1)


@pytest.fixture
def scaling_record():
    """A small record in the format of benchmarks/dppo_scaling.py."""
    return {"results": [
        {"workers": 1, "share": "gradients", "ratio_to_1_worker": 1.0, "env_steps_per_second": 100.0,
         "env_steps_per_second_wall": 80.0, "rollout_seconds_per_update": 0.3, "update_seconds_per_update": 0.5,
         "curve": {"step": [10, 20], "episode_return": [1.0, 2.0]}},
        {"workers": 2, "share": "gradients", "ratio_to_1_worker": 1.4, "env_steps_per_second": 140.0,
         "env_steps_per_second_wall": 100.0, "rollout_seconds_per_update": 0.3, "update_seconds_per_update": 0.7,
         "curve": {"step": [20, 40], "episode_return": [1.0, 3.0]}},
        {"workers": 2, "share": "rollouts", "ratio_to_1_worker": 1.9, "env_steps_per_second": 190.0,
         "env_steps_per_second_wall": 120.0, "rollout_seconds_per_update": 0.3, "update_seconds_per_update": 0.52,
         "curve": {"step": [], "episode_return": []}},
    ]}


@pytest.fixture
def interrupt_at_first_checkpoint(monkeypatch):
    """``interrupt_at_first_checkpoint(module)``: the next ``module.train`` (every one runs in
    :class:`rlcore.harness.Run`, which writes the checkpoints) stops right after its first periodic
    checkpoint with a KeyboardInterrupt, as Ctrl-C would there, so that a test can resume it with the same budget
    (a run whose budget shapes its schedules cannot be resumed with another one). Checkpoints written by any other
    code (another module's ``train``) are written as usual. Returns the steps of ``module.train``'s checkpoints."""

    def arm(module):
        import inspect
        import sys

        import rlcore.harness

        train = getattr(module, "train", None)
        if not callable(train):
            raise TypeError(f"interrupt_at_first_checkpoint: {module.__name__} has no train function")
        train_code = inspect.unwrap(train).__code__
        real = rlcore.harness.save_checkpoint
        calls = []

        def inside_train() -> bool:
            frame = sys._getframe(2)
            while frame is not None:
                if frame.f_code is train_code:
                    return True
                frame = frame.f_back
            return False

        def save_then_interrupt(path, state):
            real(path, state)
            if Path(path).name != "checkpoint.pt" or not inside_train():  # policy_best.pt is no checkpoint
                return
            calls.append(int(state["step"]))
            if len(calls) == 1:
                raise KeyboardInterrupt

        monkeypatch.setattr(rlcore.harness, "save_checkpoint", save_then_interrupt)
        return calls

    return arm


@pytest.fixture
def script_module():
    """Load a script that is not part of a package (``benchmarks/checkpoint_cost.py``) as a module, fresh each call:
    ``script_module("benchmarks/checkpoint_cost.py").main()``."""
    def load(relative_path: str):
        path = ROOT / relative_path
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load
