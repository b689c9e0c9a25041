import io

import imageio.v3 as iio
import numpy as np
import pytest

from rlcore import render
from rlcore.render import HeadlessGLError, frames_to_gif, render_gif, rollout_frames, select_gl_backend


def test_no_working_backend_names_what_to_install(monkeypatch):
    monkeypatch.setattr(render, "probe_gl_backend", lambda backend: (False, "cannot open display"))
    with pytest.raises(HeadlessGLError) as err:
        select_gl_backend(["egl", "osmesa"])
    msg = str(err.value)
    for needed in ("MUJOCO_GL=egl", "MUJOCO_GL=osmesa", "libegl1", "libgl1-mesa-dri", "libosmesa6", "apt-get install"):
        assert needed in msg
    assert "cannot open display" in msg


def test_a_bogus_backend_really_fails_in_the_probe():
    works, why = render.probe_gl_backend("not-a-backend")
    assert not works
    assert why  # the reason is reported


def test_first_working_backend_is_chosen(monkeypatch):
    monkeypatch.setattr(render, "probe_gl_backend", lambda b: (b == "osmesa", "nope"))
    monkeypatch.setattr(render, "_selected", None)
    monkeypatch.setenv("MUJOCO_GL", "egl")
    monkeypatch.setenv("PYOPENGL_PLATFORM", "egl")
    assert select_gl_backend(["egl", "osmesa"]) == "osmesa"
    import os

    assert os.environ["MUJOCO_GL"] == "osmesa"


def test_frames_to_gif_round_trips():
    frames = [np.full((12, 16, 3), c, dtype=np.uint8) for c in (0, 128, 255)]
    data = frames_to_gif(frames, fps=10)
    assert data[:6] == b"GIF89a"
    decoded = iio.imread(io.BytesIO(data), extension=".gif", index=None)
    assert decoded.shape[0] == 3 and decoded.shape[1:3] == (12, 16)
    with pytest.raises(ValueError):
        frames_to_gif([])


def test_toy_text_rollout_follows_the_policy():
    frames = rollout_frames("FrozenLake-v1", policy=lambda obs: 2, max_frames=5, env_kwargs={"is_slippery": False})
    assert len(frames) == 5
    assert frames[0].ndim == 3 and frames[0].shape[2] == 3
    assert not np.array_equal(frames[0], frames[1])  # the elf moved right


def test_mujoco_renders_offscreen_to_a_gif(tmp_path):
    select_gl_backend()  # a real backend must work on the test machine (CI installs Mesa EGL)
    out = tmp_path / "hopper.gif"
    data = render_gif("Hopper-v5", max_frames=6, width=96, height=64, path=out, frame_skip=2)
    assert out.read_bytes() == data
    decoded = iio.imread(io.BytesIO(data), extension=".gif", index=None)
    assert decoded.shape[:3] == (6, 64, 96)
    assert decoded.std() > 0  # not a blank image
    with pytest.raises(ValueError):
        rollout_frames("Hopper-v5", max_frames=2, frame_skip=0)
