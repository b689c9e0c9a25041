"""Headless OpenGL for MuJoCo: which backend renders offscreen on this machine.

MuJoCo draws with OpenGL. Without a screen it needs a backend that renders offscreen, chosen with the
``MUJOCO_GL`` environment variable before MuJoCo is first imported. Which ones exist depends on the system
(:data:`PLATFORM_BACKENDS`): on Linux ``egl`` (Mesa's or NVIDIA's EGL) then ``osmesa`` (pure software); on macOS
and Windows ``glfw``, which draws into a hidden window of the desktop session (MuJoCo also knows ``cgl`` on macOS
and ``wgl`` on Windows, but Gymnasium's renderer opens only ``egl``, ``osmesa`` and ``glfw``).
:func:`select_gl_backend` tries this system's backends in order, each in a throw-away subprocess (a broken GL
stack can crash the process that tries it), and keeps the first that works. When none works it raises
:class:`HeadlessGLError` saying what to install.

A ``MUJOCO_GL`` that MuJoCo does not know on this system would stop ``import mujoco`` itself, and with it every
MuJoCo task, rendering or not; :func:`set_aside_unknown_backend` (run when :mod:`rlcore.envs` is imported) turns
rendering off for MuJoCo instead, so that only rendering fails, and says why.

Both :mod:`rlcore.envs` (which selects a backend before making a MuJoCo environment that renders) and
:mod:`rlcore.render` use this module; it imports neither.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from collections.abc import Sequence

PLATFORM_BACKENDS = {"Linux": ("egl", "osmesa"), "Darwin": ("glfw",), "Windows": ("glfw",)}
"""The backends tried on each system (``platform.system()``), in order; another system tries ``glfw``."""

MUJOCO_GL_NAMES = {"Linux": ("egl", "osmesa", "glx", "glfw"), "Darwin": ("cgl", "glfw"), "Windows": ("wgl", "glfw")}
"""The backend names MuJoCo accepts in ``MUJOCO_GL`` on each system (besides words that switch rendering on or
off); any other value makes ``import mujoco`` raise."""
_SWITCHES = ("", "enable", "enabled", "on", "true", "1", "disable", "disabled", "off", "false", "0")
_ON = ("", "enable", "enabled", "on", "true", "1")
GYMNASIUM_BACKENDS = ("egl", "osmesa", "glfw")
"""The backends Gymnasium's MuJoCo renderer opens (it refuses any other ``MUJOCO_GL``)."""

GL_BACKENDS = PLATFORM_BACKENDS["Linux"]
"""Linux's backends (the names this module has always exported); :func:`platform_backends` gives this system's."""

# What each backend needs: Debian/Ubuntu packages on Linux, a desktop session elsewhere.
GL_PACKAGES = {
    "egl": "libegl1 libegl-mesa0 libgl1-mesa-dri",
    "osmesa": "libosmesa6",
}

_PYOPENGL_PLATFORMS = {"egl": "egl", "osmesa": "osmesa"}
"""``PYOPENGL_PLATFORM`` for a backend that renders through PyOpenGL's platform of the same name."""

_set_aside: str | None = None
"""The unknown ``MUJOCO_GL`` that :func:`set_aside_unknown_backend` replaced, if any."""


def platform_backends(system: str | None = None) -> tuple[str, ...]:
    """The backends to try on ``system`` (default: this one), in order."""
    return PLATFORM_BACKENDS.get(system or platform.system(), ("glfw",))


def set_aside_unknown_backend(system: str | None = None) -> str | None:
    """If ``MUJOCO_GL`` names a backend MuJoCo does not know on this system, and MuJoCo is not imported yet, set it
    to ``disable`` (MuJoCo then simulates but does not render) and return the unknown name; :func:`select_gl_backend`
    will say it is unknown. Otherwise leave everything as it is and return None."""
    global _set_aside
    system = system or platform.system()
    value = os.environ.get("MUJOCO_GL", "").strip().lower()
    known = MUJOCO_GL_NAMES.get(system, ("glfw",))
    if value in _SWITCHES or value in known or "mujoco" in sys.modules:
        return None
    _set_aside = value
    os.environ["MUJOCO_GL"] = "disable"
    return value


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
    env = dict(os.environ, MUJOCO_GL=backend)
    env.pop("PYOPENGL_PLATFORM", None)
    if backend in _PYOPENGL_PLATFORMS:
        env["PYOPENGL_PLATFORM"] = _PYOPENGL_PLATFORMS[backend]
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        return False, f"timed out after {timeout:.0f} s"
    lines = (proc.stderr or proc.stdout).strip().splitlines()
    return proc.returncode == 0, (lines[-1] if lines else f"exit code {proc.returncode}")


def _no_backend_message(tried: dict[str, str], system: str | None = None, fix: str | None = None) -> str:
    reasons = "\n".join(f"  MUJOCO_GL={b}: {why}" for b, why in tried.items())
    system = system or platform.system()
    if fix is not None:
        pass
    elif system == "Linux":
        fix = ("To fix it, install one of them and try again:\n"
               f"  EGL (recommended):  sudo apt-get install {GL_PACKAGES['egl']}   then MUJOCO_GL=egl\n"
               f"  OSMesa (software):  sudo apt-get install {GL_PACKAGES['osmesa']}   then MUJOCO_GL=osmesa\n"
               "On a machine with a screen you may also set MUJOCO_GL=glfw.")
    else:
        fix = ("To fix it, run from a logged-in desktop session (GLFW opens a hidden window there; not over ssh) with "
               "the glfw package installed (pip install glfw), and MUJOCO_GL=glfw or unset.")
    return ("MuJoCo cannot render offscreen: no OpenGL backend works on this machine.\n"
            f"Tried:\n{reasons}\n{fix}")


def _unknown_backend_message(name: str, system: str | None = None) -> str:
    system = system or platform.system()
    known = ", ".join(MUJOCO_GL_NAMES.get(system, ("glfw",)))
    return _no_backend_message({name: f"not a backend MuJoCo knows on {system} (it knows {known})"}, system,
                               fix="To fix it, unset MUJOCO_GL or set it to one of "
                                   f"{', '.join(platform_backends(system))}.")


def select_gl_backend(candidates: Sequence[str] | None = None) -> str:
    """Pick a headless OpenGL backend for MuJoCo and put it in ``MUJOCO_GL``.

    A ``MUJOCO_GL`` already set by the user is the only candidate tried. Otherwise this system's backends
    (:func:`platform_backends`: ``egl`` then ``osmesa`` on Linux, ``glfw`` on macOS and Windows). The choice is
    remembered for the rest of the process (and inherited by child processes through the environment). Call it
    before MuJoCo is imported; :func:`rlcore.envs.make_env` does so whenever ``render_mode="rgb_array"``.
    """
    global _selected
    if candidates is None:
        if _selected is not None:
            return _selected
        if _set_aside is not None:
            raise HeadlessGLError(_unknown_backend_message(_set_aside))
        user_choice = os.environ.get("MUJOCO_GL", "").strip().lower()
        candidates = platform_backends() if user_choice in _ON else (user_choice,)
    tried: dict[str, str] = {}
    for backend in candidates:
        if backend not in GYMNASIUM_BACKENDS:
            tried[backend] = f"Gymnasium's renderer opens only {', '.join(GYMNASIUM_BACKENDS)}"
            continue
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
    if backend in _PYOPENGL_PLATFORMS:
        os.environ["PYOPENGL_PLATFORM"] = _PYOPENGL_PLATFORMS[backend]  # as in the probe that passed
    _selected = backend
