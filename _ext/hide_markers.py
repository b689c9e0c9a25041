"""Sphinx extension: leave the named marker comments out of ``literalinclude`` listings.

The chapters show the library's code by ``:pyobject:`` or by marker comments (``# [dqn-act]`` ...
``# [/dqn-act]``) that delimit an excerpt. A listing of a whole function that holds excerpts of its own would
show those markers as stray comments, so every line that is only a marker is dropped from every listing, after
``start-after``/``end-before`` have used them. Enabled in ``_config.yml`` under ``sphinx: local_extensions``.
"""

from __future__ import annotations

import re
from typing import Any

from sphinx.directives.code import LiteralIncludeReader

MARKER = re.compile(r"^\s*# \[/?[a-z0-9-]+\]\s*$")


def without_markers(lines: list[str]) -> list[str]:
    return [line for line in lines if not MARKER.match(line)]


def setup(app: Any) -> dict[str, Any]:
    dedent = LiteralIncludeReader.dedent_filter
    if not getattr(dedent, "drops_markers", False):  # runs after the start, end and lines filters

        def dedent_filter(self, lines, location=None):
            return dedent(self, without_markers(lines), location)

        dedent_filter.drops_markers = True
        LiteralIncludeReader.dedent_filter = dedent_filter
    return {"version": "1.0", "parallel_read_safe": True, "parallel_write_safe": True}
