#!/usr/bin/env python3
"""Check a finished `jupyter-book build .`: every page in _toc.yml was written, no chapter failed.

`jupyter-book build . -W -n --keep-going` already exits non-zero on any Sphinx warning, including a
notebook that fails to execute. This check does not rely on that alone: it fails if

- a page listed in _toc.yml has no HTML file in _build/html/, or
- _build/html/reports/ holds any execution report (myst-nb writes one per notebook that raised;
  the traceback is inside), or
- a page of _toc.yml shows a GIF larger than 1.5 MB (a page should load light; rlcore.render.render_gif's
  size, frame_skip and colors options trade length and detail for bytes), or
- a page of _toc.yml has more than 4,000 words of prose (.ci/prose_words.py counts them; split it into sections).

Run from the repository root after the build:  python3 .ci/check_book.py
Reports from an earlier build are not deleted by a later one: remove _build/html/reports/ before
building (.ci/run does) or delete _build/ altogether.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
HTML = ROOT / "_build" / "html"
MAX_GIF_BYTES = 1_500_000


def toc_pages(node: object) -> list[str]:
    """Every `root:` and `file:` entry of a jupyter-book _toc.yml, in order."""
    found: list[str] = []
    if isinstance(node, dict):
        for key, value in node.items():
            if key in ("root", "file") and isinstance(value, str):
                found.append(value)
            else:
                found.extend(toc_pages(value))
    elif isinstance(node, list):
        for item in node:
            found.extend(toc_pages(item))
    return found


def main() -> int:
    problems: list[str] = []
    if not HTML.is_dir():
        problems.append(f"{HTML.relative_to(ROOT)}/ does not exist: the book was not built")
    else:
        toc = yaml.safe_load((ROOT / "_toc.yml").read_text(encoding="utf-8"))
        for page in toc_pages(toc):
            html = HTML / Path(page).with_suffix(".html")
            if not html.is_file():
                problems.append(f"page {page!r} from _toc.yml is missing: no {html.relative_to(ROOT)}")
        reports = HTML / "reports"
        if reports.is_dir():
            for report in sorted(p for p in reports.rglob("*") if p.is_file()):
                lines = report.read_text(encoding="utf-8", errors="replace").strip().splitlines()
                tail = "\n      ".join(lines[-15:])
                problems.append(f"execution failed, report {report.relative_to(ROOT)}:\n      {tail}")
        for page in toc_pages(toc):
            html = HTML / Path(page).with_suffix(".html")
            if not html.is_file():
                continue
            for src in dict.fromkeys(re.findall(r'<img[^>]*\ssrc="([^"]+\.gif)"', html.read_text(encoding="utf-8"))):
                gif = (html.parent / src).resolve()
                if gif.is_file() and gif.stat().st_size > MAX_GIF_BYTES:
                    problems.append(f"page {page!r} shows {gif.relative_to(ROOT)}: {gif.stat().st_size / 1e6:.2f} MB, "
                                    f"over the {MAX_GIF_BYTES / 1e6:.1f} MB a GIF may take")
        from prose_words import MAX_PROSE_WORDS, count_words

        for page in toc_pages(toc):
            source = ROOT / f"{page}.md"
            if source.is_file() and (n := count_words(source.read_text(encoding="utf-8"))) > MAX_PROSE_WORDS:
                problems.append(f"page {page!r} has {n:,} words of prose, over {MAX_PROSE_WORDS:,}: split it into "
                                "sections (_toc.yml `sections:`); `python3 .ci/prose_words.py` counts them")

    if problems:
        print("Book check FAILED:", file=sys.stderr)
        for problem in problems:
            print(f"  - {problem}", file=sys.stderr)
        return 1
    print(f"Book check passed: every page of _toc.yml is in {HTML.relative_to(ROOT)}/, no execution reports, "
          f"no GIF over {MAX_GIF_BYTES / 1e6:.1f} MB, no page over 4,000 words of prose.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
