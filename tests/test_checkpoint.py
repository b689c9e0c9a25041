import os
import pickle

import numpy as np
import pytest
import torch

from rlcore.checkpoint import CheckpointError, load_checkpoint, save_checkpoint


def test_round_trip_keeps_tensors_arrays_and_rng_state(tmp_path):
    rng = np.random.default_rng(7)
    net = torch.nn.Linear(3, 2)
    path = save_checkpoint(tmp_path / "c.pt", {
        "q": np.arange(6.0).reshape(3, 2), "net": net.state_dict(), "rng": rng.bit_generator.state,
        "step": 10, "name": "x", "nested": {"a": [1, 2.5, None]},
    })
    data = load_checkpoint(path)
    np.testing.assert_array_equal(data["q"].numpy(), np.arange(6.0).reshape(3, 2))
    torch.testing.assert_close(data["net"]["weight"], net.weight.detach())
    restored = np.random.default_rng()
    restored.bit_generator.state = data["rng"]
    assert restored.random() == rng.random()
    assert data["step"] == 10 and data["nested"] == {"a": [1, 2.5, None]}


def test_save_is_atomic_and_leaves_no_temporary_files(tmp_path):
    save_checkpoint(tmp_path / "c.pt", {"v": 1})
    save_checkpoint(tmp_path / "c.pt", {"v": 2})
    assert sorted(os.listdir(tmp_path)) == ["c.pt"]
    assert load_checkpoint(tmp_path / "c.pt")["v"] == 2


def test_failed_save_keeps_previous_checkpoint(tmp_path):
    save_checkpoint(tmp_path / "c.pt", {"v": 1})
    with pytest.raises(TypeError, match="only tensors"):
        save_checkpoint(tmp_path / "c.pt", {"v": object()})
    assert load_checkpoint(tmp_path / "c.pt")["v"] == 1
    assert sorted(os.listdir(tmp_path)) == ["c.pt"]


def test_truncated_file_is_a_clear_error(tmp_path):
    path = save_checkpoint(tmp_path / "c.pt", {"q": np.zeros((100, 4))})
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="not an rlcore checkpoint|could not be loaded"):
        load_checkpoint(path)


def test_text_file_is_a_clear_error(tmp_path):
    path = tmp_path / "notes.pt"
    path.write_text("hello")
    with pytest.raises(CheckpointError, match="not a PyTorch zip archive"):
        load_checkpoint(path)


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(CheckpointError, match="No checkpoint"):
        load_checkpoint(tmp_path / "nope.pt")
    with pytest.raises(CheckpointError, match="is a folder"):
        load_checkpoint(tmp_path)


class Evil:
    def __reduce__(self):
        return (os.system, ("echo pwned",))


def test_unsafe_pickle_is_refused(tmp_path):
    path = tmp_path / "evil.pt"
    torch.save({"format": "rlcore-checkpoint", "x": Evil()}, path)
    with pytest.raises(CheckpointError, match="could not be loaded safely") as err:
        load_checkpoint(path)
    assert "posix.system" in str(err.value)  # says what was refused


def test_foreign_torch_file_is_refused(tmp_path):
    path = tmp_path / "weights.pt"
    torch.save({"weight": torch.zeros(2)}, path)
    with pytest.raises(CheckpointError, match="not an rlcore checkpoint"):
        load_checkpoint(path)
    path.write_bytes(pickle.dumps({"a": 1}))
    with pytest.raises(CheckpointError):
        load_checkpoint(path)


def test_numpy_scalars_are_saved_as_python_numbers(tmp_path):
    save_checkpoint(tmp_path / "c.pt", {"a": np.float64(1.5), "b": np.int64(3), "c": [np.float32(2.0)]})
    data = load_checkpoint(tmp_path / "c.pt")
    assert data["a"] == 1.5 and data["b"] == 3 and data["c"] == [2.0]
    assert type(data["a"]) is float
