"""Offscreen rollouts of a policy to frames and to a GIF.

MuJoCo tasks render through a headless OpenGL backend that :mod:`rlcore.gl` selects (``select_gl_backend`` and
``HeadlessGLError`` are re-exported here, where the chapters and the command line have always found them). Where
none works, :func:`render_gif` raises ``HeadlessGLError``, and :func:`realtime_gif`, the chapters' clips, shows a
still that says why (:attr:`Clip.missing`), so that a page still builds on such a machine.
"""

from __future__ import annotations

import io
import os
import sys
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rlcore.gl import GL_BACKENDS, GL_PACKAGES, HeadlessGLError, probe_gl_backend, select_gl_backend  # noqa: F401

# A camera that follows the humanoid's torso from the side (passed as default_camera_config).
HUMANOID_CAMERA = {"trackbodyid": 1, "distance": 4.0, "elevation": -15.0, "lookat": np.array([0.0, 0.0, 1.0])}



Policy = Callable[[Any], Any]


def rollout_frames(
    env_id: str,
    policy: Policy | None = None,
    max_frames: int = 200,
    seed: int = 0,
    width: int = 320,
    height: int = 240,
    env_kwargs: dict[str, Any] | None = None,
    frame_skip: int = 1,
) -> list[np.ndarray]:
    """Run ``policy`` in a fresh ``env_id`` and return up to ``max_frames`` RGB frames.

    ``policy`` maps an observation to an action; ``None`` means uniformly random actions (seeded).
    When an episode ends before ``max_frames``, a new one starts, so short-lived bodies still fill
    the GIF. MuJoCo tasks render at ``width`` x ``height``; other tasks at their own size.
    ``frame_skip=k`` keeps every k-th step's frame (a smaller GIF of a longer stretch of motion).
    """
    if frame_skip < 1:
        raise ValueError(f"frame_skip must be >= 1, got {frame_skip}")
    from rlcore.envs import check_env_id, is_mujoco, make_env

    check_env_id(env_id)
    kwargs = dict(env_kwargs or {})
    if is_mujoco(env_id):
        kwargs.setdefault("width", width)
        kwargs.setdefault("height", height)
        if env_id.startswith("Humanoid"):  # Gymnasium's default camera aims above the humanoid's head
            kwargs.setdefault("default_camera_config", dict(HUMANOID_CAMERA))
    else:
        # pygame draws the grid worlds and classic-control tasks; without a screen it needs no video device
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    env = make_env(env_id, seed=seed, render_mode="rgb_array", **kwargs)
    try:
        obs, _ = env.reset(seed=seed)
        frames = [np.asarray(env.render())]
        step = 0
        while len(frames) < max_frames:
            action = env.action_space.sample() if policy is None else policy(obs)
            obs, _, terminated, truncated, _ = env.step(action)
            step += 1
            if step % frame_skip == 0:
                frames.append(np.asarray(env.render()))
            if terminated or truncated:
                obs, _ = env.reset()
        return frames
    finally:
        env.close()


def frames_to_gif(frames: Sequence[np.ndarray], fps: float = 30, palette_samples: int = 8, colors: int = 256) -> bytes:
    """Encode RGB frames as an endlessly looping GIF and return its bytes.

    One palette of ``colors`` colours (2 to 256) is built for the whole clip from ``palette_samples``
    frames spread over it (median cut, no dithering), and every frame is mapped to it. A shared palette
    without dithering noise is what keeps a few hundred 320x240 MuJoCo frames near 1 MB instead of
    several. Fewer colours make a smaller file: a tracking camera over MuJoCo's checkered floor changes
    most pixels of every frame, and 128 colours then take about a quarter less than 256 with the
    bodies' colours intact (64 turn them grey). ``fps`` sets each frame's duration, which GIF stores
    in hundredths of a second. Consecutive identical frames are merged into one longer frame.
    """
    from PIL import Image

    if len(frames) == 0:
        raise ValueError("frames_to_gif needs at least one frame")
    if not 2 <= colors <= 256:
        raise ValueError(f"colors must be between 2 and 256, got {colors}")
    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)[..., :3]) for f in frames]
    picks = np.unique(np.linspace(0, len(images) - 1, min(palette_samples, len(images))).astype(int))
    w, h = images[0].size
    sheet = Image.new("RGB", (w, h * len(picks)))
    for k, i in enumerate(picks):
        sheet.paste(images[i], (0, h * k))
    palette = sheet.quantize(colors=colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    quantized = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    buf = io.BytesIO()
    quantized[0].save(buf, format="GIF", save_all=True, append_images=quantized[1:],
                      duration=round(1000 / fps), loop=0, optimize=False)
    return buf.getvalue()


def render_gif(
    env_id: str,
    policy: Policy | None = None,
    max_frames: int = 200,
    seed: int = 0,
    fps: float = 30,
    width: int = 320,
    height: int = 240,
    path: str | os.PathLike | None = None,
    env_kwargs: dict[str, Any] | None = None,
    frame_skip: int = 1,
    colors: int = 256,
) -> bytes:
    """Roll out ``policy`` offscreen and return the GIF's bytes (also written to ``path`` if given).

    The GIF shows ``max_frames * frame_skip`` environment steps, i.e. that many times the
    environment's ``dt`` seconds of simulation (see :func:`simulated_seconds`); it plays in real time
    when ``fps = 1 / (frame_skip * dt)``. ``colors`` is the palette size (see :func:`frames_to_gif`).
    """
    frames = rollout_frames(env_id, policy, max_frames, seed, width, height, env_kwargs, frame_skip)
    data = frames_to_gif(frames, fps=fps, colors=colors)
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_bytes(data)
    return data


def env_dt(env_id: str, env_kwargs: dict[str, Any] | None = None) -> float:
    """Seconds of simulated time per environment step, e.g. 0.008 for Hopper-v5.

    ``env.unwrapped.dt`` (the MuJoCo tasks, Pendulum) or ``tau`` (CartPole); a task without either
    (the grid worlds, which have no simulated time) raises ``ValueError``.
    """
    from rlcore.envs import make_env

    env = make_env(env_id, **dict(env_kwargs or {}))
    try:
        dt = getattr(env.unwrapped, "dt", None) or getattr(env.unwrapped, "tau", None)
    finally:
        env.close()
    if dt is None:
        raise ValueError(f"{env_id} has no simulation time step (env.unwrapped.dt or .tau)")
    return float(dt)


def simulated_seconds(env_id: str, frames: int, frame_skip: int = 1, env_kwargs: dict[str, Any] | None = None) -> float:
    """How many seconds of simulation a GIF of ``frames`` frames, one every ``frame_skip`` steps, shows."""
    return frames * frame_skip * env_dt(env_id, env_kwargs)


@dataclass(frozen=True)
class Clip:
    """A GIF of a rollout that plays in real time, with what it shows (for its caption and its checks)."""

    gif: bytes
    env_id: str
    frames: int
    frame_skip: int
    """Environment steps per frame."""
    step_seconds: float
    """Simulated seconds per environment step (:func:`env_dt`)."""
    missing: str = ""
    """Why the clip is a still instead (no OpenGL backend renders here), or empty."""

    @property
    def fps(self) -> float:
        """Frames per second that make the clip play in real time."""
        return 1.0 / (self.frame_skip * self.step_seconds)

    @property
    def seconds(self) -> float:
        """Seconds of simulation the clip shows (:func:`simulated_seconds`)."""
        return self.frames * self.frame_skip * self.step_seconds

    def caption(self) -> str:
        """E.g. "6 s of simulation in real time: 120 frames at 20 per second, one every step of 0.05 s (0.83 MB)"."""
        if self.missing:
            return f"not rendered on this machine, a still says why: {self.missing}"
        every = f"{self.frame_skip} steps" if self.frame_skip > 1 else "step"
        return (f"{self.seconds:.3g} s of simulation in real time: {self.frames} frames at {self.fps:.3g} per "
                f"second, one every {every} of {self.step_seconds:g} s ({len(self.gif) / 1e6:.2f} MB)")


def realtime_frame_skip(dt: float, fps: float = 25.0) -> int:
    """Environment steps per frame for a GIF of a task with ``dt`` seconds a step that plays in real time at close
    to ``fps`` frames per second.

    A GIF stores each frame's duration in hundredths of a second, so a frame of 45 ms would play as 40 ms or
    50 ms. Among the step counts from half to twice ``1 / (fps * dt)``, the nearest one whose frames last a whole
    number of hundredths is taken (Humanoid's 0.015 s: 2 steps, 30 ms, rather than 3 steps, 45 ms); if there is
    none, the nearest one.
    """
    ideal = 1 / (fps * dt)
    nearest = max(1, round(ideal))
    exact = [k for k in range(max(1, int(ideal / 2)), max(2, int(2 * ideal) + 1))
             if abs(k * dt * 100 - round(k * dt * 100)) < 1e-6]
    return min(exact, key=lambda k: (abs(k - ideal), k)) if exact else nearest


def realtime_gif(
    env_id: str,
    policy: Policy | None = None,
    seconds: float = 5.0,
    fps: float = 25.0,
    seed: int = 0,
    width: int = 320,
    height: int = 240,
    env_kwargs: dict[str, Any] | None = None,
    colors: int = 256,
) -> Clip:
    """About ``seconds`` of simulation of ``policy`` in ``env_id`` as a GIF that plays in real time.

    A frame is kept every ``frame_skip`` steps (:func:`realtime_frame_skip`), so that the GIF runs at close to
    ``fps`` frames per second, and each frame is shown for exactly the simulated time it stands for,
    ``frame_skip * dt``. The clip is as many whole frames as come closest to ``seconds``; ``Clip.seconds``
    says exactly how long it is. The rest is :func:`render_gif`.
    """
    if seconds <= 0 or fps <= 0:
        raise ValueError(f"seconds and fps must be positive, got {seconds} and {fps}")
    dt = env_dt(env_id, env_kwargs)
    frame_skip = realtime_frame_skip(dt, fps)
    frames = max(1, round(seconds / (frame_skip * dt)))
    try:
        gif = render_gif(env_id, policy, max_frames=frames, seed=seed, fps=1 / (frame_skip * dt), width=width,
                         height=height, env_kwargs=env_kwargs, frame_skip=frame_skip, colors=colors)
    except HeadlessGLError as err:
        missing = no_gl_reason(err)
        print(f"{env_id} is not rendered: {missing}", file=sys.stderr)
        return Clip(still_gif(f"{env_id} is not rendered here: {missing}", width, height), env_id, frames,
                    frame_skip, dt, missing=missing)
    return Clip(gif, env_id, frames, frame_skip, dt)


def gl_status() -> str:
    """One line for a page: the backend MuJoCo renders with here, or why it cannot (its clips are then stills)."""
    try:
        return f"MuJoCo renders with MUJOCO_GL = {select_gl_backend()}"
    except HeadlessGLError as err:
        return f"MuJoCo cannot render on this machine, so its clips below are stills: {no_gl_reason(err)}"


def no_gl_reason(err: HeadlessGLError) -> str:
    """One line from a :class:`HeadlessGLError`: what was tried and what fixes it (its first fix)."""
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    tried = [line for line in lines if line.startswith("MUJOCO_GL=")]
    fixes = [line for line in lines if line.startswith(("To fix", "EGL"))]
    fix = " ".join((fixes[-1] if fixes else lines[-1]).removeprefix("EGL (recommended):").split())
    return f"no OpenGL backend works ({'; '.join(tried)}). {fix if fix.startswith('To fix') else 'To fix it: ' + fix}"


def still_gif(text: str, width: int = 320, height: int = 240) -> bytes:
    """A one-frame GIF, ``width`` x ``height``, that shows ``text`` (wrapped) on grey: what stands in for a clip that
    could not be rendered."""
    from PIL import Image, ImageDraw

    image = Image.new("RGB", (width, height), (225, 225, 225))
    draw = ImageDraw.Draw(image)
    chars = max(10, width // 7)
    draw.multiline_text((8, 8), "\n".join(textwrap.wrap(text, chars)), fill=(40, 40, 40))
    return frames_to_gif([np.asarray(image)], fps=1)
