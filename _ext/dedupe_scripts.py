"""Sphinx extension: load each script of a page once.

Jupyter Book 1.0 registers the inline scripts of sphinx-thebe and sphinx-togglebutton twice (once with the
builder, once more through Sphinx's registry, the second time with ``''`` for ``None`` as the file name), so
every page declared ``const THEBE_JS_URL`` twice and the browser logged "Identifier 'THEBE_JS_URL' has
already been declared". This drops exact duplicates (same file or inline body, same attributes) from each
page's scripts, keeping the first. Enabled in ``_config.yml`` under ``sphinx: local_extensions``.
"""

from __future__ import annotations

from typing import Any


def _key(script: Any) -> tuple:
    filename = getattr(script, "filename", script) or ""  # None and "" both mean an inline script
    attributes = getattr(script, "attributes", {}) or {}
    return str(filename), tuple(sorted((k, str(v)) for k, v in attributes.items()))


def drop_duplicate_scripts(app: Any, pagename: str, templatename: str, context: dict, doctree: Any) -> None:
    scripts = context.get("script_files")
    if not scripts:
        return
    seen: set[tuple] = set()
    unique = []
    for script in scripts:
        key = _key(script)
        if key not in seen:
            seen.add(key)
            unique.append(script)
    context["script_files"] = unique


def setup(app: Any) -> dict[str, Any]:
    app.connect("html-page-context", drop_duplicate_scripts)
    return {"version": "1.0", "parallel_read_safe": True, "parallel_write_safe": True}
