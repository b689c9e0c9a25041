import io

import imageio.v3 as iio
import numpy as np
import pytest

from rlcore import gl
from rlcore.render import (HeadlessGLError, env_dt, frames_to_gif, render_gif, rollout_frames, select_gl_backend,
                           simulated_seconds)


def test_no_working_backend_names_what_to_install(monkeypatch):
    monkeypatch.setattr(gl, "probe_gl_backend", lambda backend: (False, "cannot open display"))
    with pytest.raises(HeadlessGLError) as err:
        select_gl_backend(["egl", "osmesa"])
    msg = str(err.value)
    for needed in ("MUJOCO_GL=egl", "MUJOCO_GL=osmesa", "libegl1", "libgl1-mesa-dri", "libosmesa6", "apt-get install"):
        assert needed in msg
    assert "cannot open display" in msg


def test_a_bogus_backend_really_fails_in_the_probe():
    works, why = gl.probe_gl_backend("not-a-backend")
    assert not works
    assert why  # the reason is reported


def test_first_working_backend_is_chosen(monkeypatch):
    monkeypatch.setattr(gl, "probe_gl_backend", lambda b: (b == "osmesa", "nope"))
    monkeypatch.setattr(gl, "_selected", None)
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


def test_frames_to_gif_palette_size_and_frame_duration():
    from PIL import Image

    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, size=(16, 16, 3), dtype=np.uint8) for _ in range(3)]
    small, full = frames_to_gif(frames, fps=25, colors=8), frames_to_gif(frames, fps=25)
    assert len(small) < len(full)
    gif = Image.open(io.BytesIO(small))
    assert gif.info["duration"] == 40  # 25 frames per second
    colours = set()
    for i in range(gif.n_frames):
        gif.seek(i)
        colours |= {tuple(c) for c in np.asarray(gif.convert("RGB")).reshape(-1, 3)}
    assert len(colours) <= 8
    for bad in (1, 257):
        with pytest.raises(ValueError):
            frames_to_gif(frames, colors=bad)


def test_simulated_seconds_of_a_gif():
    assert env_dt("Hopper-v5") == pytest.approx(0.008)  # frame_skip 4 x timestep 0.002
    assert simulated_seconds("Hopper-v5", frames=150, frame_skip=5) == pytest.approx(6.0)
    assert simulated_seconds("HalfCheetah-v5", frames=120) == pytest.approx(6.0)
    assert env_dt("CartPole-v1") == pytest.approx(0.02)  # CartPole calls its step tau
    with pytest.raises(ValueError):
        env_dt("FrozenLake-v1")


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
