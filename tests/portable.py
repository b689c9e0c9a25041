"""What a test does when this machine lacks something it needs (a browser, a headless OpenGL, its CPU's pins).

On a reader's machine such a test skips with one line that says what to install or set; on continuous integration
(``CI=true``, as ``.ci/run`` and most CI services set it) the same test fails, so that CI still proves the browser
test, the rendering and the pins run. Every test that may skip for the machine's sake goes through
:func:`skip_or_fail`. (Chapters do not skip: without OpenGL their MuJoCo clips become stills that say why, see
:func:`rlcore.render.realtime_gif`; ``tests/test_render.py`` is what fails on CI then.)
"""

from __future__ import annotations

import os

import pytest


def in_ci() -> bool:
    """Whether this is a continuous-integration run: ``CI`` is ``true`` (or ``1``, ``yes``), in any case."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def skip_or_fail(reason: str) -> None:
    """Skip the calling test with ``reason`` (one line: what is missing and how to get it); fail it under
    ``CI=true``."""
    if in_ci():
        pytest.fail(f"{reason} (CI=true: a missing requirement fails here instead of skipping)", pytrace=False)
    pytest.skip(reason)
