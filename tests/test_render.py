import io
import os
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest

from portable import skip_or_fail
from rlcore import gl, render
from rlcore.render import (HeadlessGLError, env_dt, frames_to_gif, realtime_gif, render_gif, rollout_frames,
                           select_gl_backend, simulated_seconds)


@pytest.fixture
def fake_system(monkeypatch):
    """``fake_system("Darwin")``: rlcore.gl sees that system, no backend chosen yet, ``MUJOCO_GL`` unset; returns
    the list of backends probed (each probe fails)."""
    def fake(system: str) -> list[str]:
        probed: list[str] = []
        monkeypatch.setattr(gl.platform, "system", lambda: system)
        monkeypatch.setattr(gl, "_selected", None)
        monkeypatch.setattr(gl, "_set_aside", None)
        monkeypatch.delenv("MUJOCO_GL", raising=False)
        monkeypatch.setattr(gl, "probe_gl_backend", lambda b: (probed.append(b), (False, "cannot open display"))[1])
        return probed

    return fake


def test_no_working_backend_names_what_to_install(monkeypatch, fake_system):
    fake_system("Linux")
    with pytest.raises(HeadlessGLError) as err:
        select_gl_backend(["egl", "osmesa"])
    msg = str(err.value)
    for needed in ("MUJOCO_GL=egl", "MUJOCO_GL=osmesa", "libegl1", "libgl1-mesa-dri", "libosmesa6", "apt-get install"):
        assert needed in msg
    assert "cannot open display" in msg


def test_the_probe_opens_a_context_with_that_backend_in_a_child_process_and_reports_its_last_error_line(
        monkeypatch):
    # rlcore's part of a probe, with the child process faked: what it runs, with which environment, and how it
    # reads the outcome (whether MuJoCo itself refuses a backend is MuJoCo's business, not tested here)
    runs = []

    def fake_run(cmd, env, capture_output, text, timeout):
        runs.append((cmd, env, timeout))
        return outcome

    monkeypatch.setattr(gl.subprocess, "run", fake_run)
    monkeypatch.setenv("MUJOCO_GL", "glfw")
    monkeypatch.setenv("PYOPENGL_PLATFORM", "osmesa")
    outcome = subprocess.CompletedProcess([], 1, stdout="", stderr="Traceback\n  ...\nImportError: no libEGL\n")
    assert gl.probe_gl_backend("egl", timeout=7) == (False, "ImportError: no libEGL")
    (cmd, env, timeout), = runs
    assert cmd[0] == sys.executable and "mujoco.GLContext" in cmd[-1] and "MjrContext" in cmd[-1]
    assert (env["MUJOCO_GL"], env["PYOPENGL_PLATFORM"], timeout) == ("egl", "egl", 7)
    assert os.environ["MUJOCO_GL"] == "glfw"   # this process's choice is left alone
    outcome = subprocess.CompletedProcess([], 0, stdout="", stderr="")
    assert gl.probe_gl_backend("glfw") == (True, "exit code 0")
    assert runs[-1][1]["MUJOCO_GL"] == "glfw" and "PYOPENGL_PLATFORM" not in runs[-1][1]   # GLFW picks its own
    outcome = subprocess.CompletedProcess([], -11, stdout="only stdout\n", stderr="")
    assert gl.probe_gl_backend("osmesa") == (False, "only stdout")
    assert runs[-1][1]["PYOPENGL_PLATFORM"] == "osmesa"

    def hang(cmd, env, capture_output, text, timeout):
        raise subprocess.TimeoutExpired(cmd, timeout)

    monkeypatch.setattr(gl.subprocess, "run", hang)
    assert gl.probe_gl_backend("egl", timeout=3) == (False, "timed out after 3 s")


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


@pytest.mark.parametrize("system, backends", [("Linux", ["egl", "osmesa"]), ("Darwin", ["glfw"]),
                                             ("Windows", ["glfw"])])
def test_each_system_tries_the_backends_mujoco_and_gymnasium_open_there(fake_system, system, backends):
    probed = fake_system(system)
    assert list(gl.platform_backends()) == backends
    with pytest.raises(HeadlessGLError) as err:
        select_gl_backend()
    assert probed == backends
    if system == "Linux":
        assert "apt-get install" in str(err.value)
    else:  # no apt-get on a Mac: GLFW needs a desktop session
        assert "desktop session" in str(err.value) and "apt-get" not in str(err.value)


def test_on_macos_glfw_is_chosen_and_cgl_is_refused_for_gymnasium(fake_system, monkeypatch):
    fake_system("Darwin")
    monkeypatch.setattr(gl, "probe_gl_backend", lambda b: (b == "glfw", "nope"))
    monkeypatch.setattr(gl, "_use_backend", lambda b: None)
    assert select_gl_backend() == "glfw"
    monkeypatch.setenv("MUJOCO_GL", "cgl")  # MuJoCo's own macOS backend, which Gymnasium's renderer cannot open
    with pytest.raises(HeadlessGLError, match="MUJOCO_GL=cgl: Gymnasium's renderer opens only egl, osmesa, glfw"):
        select_gl_backend()


def test_an_unknown_mujoco_gl_is_set_aside_before_mujoco_is_imported(fake_system, monkeypatch):
    fake_system("Darwin")
    monkeypatch.setenv("MUJOCO_GL", "egl")  # Linux only: `import mujoco` would raise on a Mac
    monkeypatch.delitem(sys.modules, "mujoco", raising=False)
    assert gl.set_aside_unknown_backend() == "egl"
    assert os.environ["MUJOCO_GL"] == "disable"
    with pytest.raises(HeadlessGLError,
                       match=r"(?s)MUJOCO_GL=egl: not a backend MuJoCo knows on Darwin.*unset MUJOCO_GL"):
        select_gl_backend()
    for known in ("glfw", "cgl", "", "disable"):
        monkeypatch.setenv("MUJOCO_GL", known)
        assert gl.set_aside_unknown_backend() is None and os.environ["MUJOCO_GL"] == known


def test_with_an_unknown_mujoco_gl_mujoco_still_simulates_and_a_clip_says_why_it_is_a_still():
    code = ("from rlcore.envs import make_env; from rlcore.render import realtime_gif\n"
            "env = make_env('Hopper-v5', seed=0); env.reset(seed=0); env.step(env.action_space.sample())\n"
            "clip = realtime_gif('Hopper-v5', seconds=0.1)\n"
            "assert clip.gif[:6] == b'GIF89a' and clip.missing, clip\n"
            "print(clip.caption())")
    proc = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, MUJOCO_GL="no-such-backend"),
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "not rendered on this machine" in proc.stdout and "unset MUJOCO_GL" in proc.stdout, proc.stdout


def test_without_opengl_a_clip_is_a_still_that_says_why(monkeypatch):
    def no_gl(*args, **kwargs):
        raise HeadlessGLError(gl._no_backend_message({"egl": "no libEGL", "osmesa": "no libOSMesa"}, "Linux"))

    monkeypatch.setattr(render, "render_gif", no_gl)
    clip = realtime_gif("Hopper-v5", seconds=0.5, width=160, height=120)
    assert clip.gif[:6] == b"GIF89a" and len(clip.gif) < 50_000
    assert iio.imread(io.BytesIO(clip.gif), extension=".gif", index=None).shape[1:3] == (120, 160)
    assert clip.missing == ("no OpenGL backend works (MUJOCO_GL=egl: no libEGL; MUJOCO_GL=osmesa: no libOSMesa). "
                            "To fix it: sudo apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri then MUJOCO_GL=egl")
    assert clip.caption().startswith("not rendered on this machine") and clip.missing in clip.caption()
    assert abs(clip.seconds - 0.5) <= clip.frame_skip * clip.step_seconds / 2 + 1e-9  # what the clip would have shown
    with pytest.raises(HeadlessGLError):  # the command line's render says so rather than write a still
        render.render_gif("Hopper-v5")


def test_mujoco_renders_offscreen_to_a_gif(tmp_path):
    try:
        select_gl_backend()  # a real backend must work on CI (which installs Mesa EGL)
    except HeadlessGLError as err:
        skip_or_fail(f"MuJoCo cannot render here ({render.no_gl_reason(err)})")
    out = tmp_path / "hopper.gif"
    data = render_gif("Hopper-v5", max_frames=6, width=96, height=64, path=out, frame_skip=2)
    assert out.read_bytes() == data
    decoded = iio.imread(io.BytesIO(data), extension=".gif", index=None)
    assert decoded.shape[:3] == (6, 64, 96)
    assert decoded.std() > 0  # not a blank image
    with pytest.raises(ValueError):
        rollout_frames("Hopper-v5", max_frames=2, frame_skip=0)


def test_offscreen_mujoco_draws_its_shadows_from_the_smaller_map_and_looks_the_same():
    try:
        select_gl_backend()
    except HeadlessGLError as err:
        skip_or_fail(f"MuJoCo cannot render here ({render.no_gl_reason(err)})")
    from rlcore.envs import SHADOW_SIZE, make_env

    frames = {}
    for name, size, shadows in (("book", SHADOW_SIZE, True), ("mujoco", 4096, True), ("none", SHADOW_SIZE, False)):
        env = make_env("Hopper-v5", seed=0, render_mode="rgb_array", width=160, height=120)
        assert env.unwrapped.model.vis.quality.shadowsize == SHADOW_SIZE < 4096  # the book's size, not MuJoCo's
        env.unwrapped.model.vis.quality.shadowsize = size
        if not shadows:
            env.unwrapped.model.light_castshadow[:] = 0
        env.reset(seed=0)
        frames[name] = env.render().astype(float)
        env.close()
    assert frames["book"].std() > 0
    assert np.abs(frames["book"] - frames["mujoco"]).mean() < 1.0   # the same picture as MuJoCo's own map draws
    assert np.abs(frames["book"] - frames["none"]).mean() > 1.0     # and it has its shadows
