"""Headless OpenGL for MuJoCo: which backend renders offscreen on this machine.

MuJoCo draws with OpenGL. On a laptop or server with no screen it needs a *headless* backend, chosen
with the ``MUJOCO_GL`` environment variable before MuJoCo is first imported: ``egl`` (Mesa's or
NVIDIA's EGL) or ``osmesa`` (pure software). :func:`select_gl_backend` tries them in that order, each
in a throw-away subprocess (a broken GL stack can crash the process that tries it), and keeps the
first that works. When none works it raises :class:`HeadlessGLError` saying what to install.

Both :mod:`rlcore.envs` (which selects a backend before making a MuJoCo environment that renders) and
:mod:`rlcore.render` use this module; it imports neither.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence

GL_BACKENDS = ("egl", "osmesa")

# What each backend needs on Debian/Ubuntu.
GL_PACKAGES = {
    "egl": "libegl1 libegl-mesa0 libgl1-mesa-dri",
    "osmesa": "libosmesa6",
}

_PROBE = """
import mujoco
ctx = mujoco.GLContext(64, 64)
ctx.make_current()
model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='1'/></worldbody></mujoco>")
mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
ctx.free()
"""

_selected: str | None = None

class HeadlessGLError(RuntimeError):
    """No headless OpenGL backend works, so MuJoCo cannot render offscreen."""


def probe_gl_backend(backend: str, timeout: float = 120.0) -> tuple[bool, str]:
    """Try to open a MuJoCo GL context with ``MUJOCO_GL=backend`` in a subprocess.

    Returns ``(works, last line of the error)``.
    """
    env = dict(os.environ, MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend)
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        return False, f"timed out after {timeout:.0f} s"
    lines = (proc.stderr or proc.stdout).strip().splitlines()
    return proc.returncode == 0, (lines[-1] if lines else f"exit code {proc.returncode}")


def _no_backend_message(tried: dict[str, str]) -> str:
    reasons = "\n".join(f"  MUJOCO_GL={b}: {why}" for b, why in tried.items())
    return (
        "MuJoCo cannot render offscreen: no headless OpenGL backend works on this machine.\n"
        f"Tried:\n{reasons}\n"
        "To fix it, install one of them and try again:\n"
        f"  EGL (recommended):  sudo apt-get install {GL_PACKAGES['egl']}   then MUJOCO_GL=egl\n"
        f"  OSMesa (software):  sudo apt-get install {GL_PACKAGES['osmesa']}   then MUJOCO_GL=osmesa\n"
        "On a machine with a screen you may also set MUJOCO_GL=glfw."
    )


def select_gl_backend(candidates: Sequence[str] | None = None) -> str:
    """Pick a headless OpenGL backend for MuJoCo and put it in ``MUJOCO_GL``.

    A ``MUJOCO_GL`` already set by the user is the only candidate tried. Otherwise ``egl`` then
    ``osmesa``. The choice is remembered for the rest of the process (and inherited by child
    processes through the environment). Call it before MuJoCo is imported; :func:`rlcore.envs.make_env`
    does so whenever ``render_mode="rgb_array"``.
    """
    global _selected
    if candidates is None:
        if _selected is not None:
            return _selected
        user_choice = os.environ.get("MUJOCO_GL", "").strip().lower()
        candidates = (user_choice,) if user_choice else GL_BACKENDS
    tried: dict[str, str] = {}
    for backend in candidates:
        works, why = probe_gl_backend(backend)
        if works:
            _use_backend(backend)
            return backend
        tried[backend] = why
    raise HeadlessGLError(_no_backend_message(tried))


def _use_backend(backend: str) -> None:
    # Gymnasium reads MUJOCO_GL when it opens its offscreen viewer, so setting it here reaches
    # Gymnasium even if MuJoCo itself was imported earlier.
    global _selected
    os.environ["MUJOCO_GL"] = backend
    os.environ.setdefault("PYOPENGL_PLATFORM", backend)
    _selected = backend
