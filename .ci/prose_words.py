#!/usr/bin/env python3
"""Words of prose on each page of _toc.yml: Markdown cells only, without code, math, directives' options and
comments. A page should read in one sitting: .ci/check_book.py fails a page over MAX_PROSE_WORDS.

    python3 .ci/prose_words.py            # one line per page, longest first
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MAX_PROSE_WORDS = 4_000
CODE_DIRECTIVES = ("code-cell", "literalinclude", "code-block", "code", "math", "raw", "mermaid")


def prose(text: str) -> str:
    """The prose of a MyST-markdown notebook: code cells, fenced code and math, directive options, front matter,
    comments and cell markers removed."""
    text = re.sub(r"\A---\n.*?\n---\n", "", text, flags=re.S)               # front matter
    text = re.sub(r"<!--.*?-->", "", text, flags=re.S)
    out: list[str] = []
    stack: list[tuple[str, bool]] = []                                      # open fences: (marker, is code)
    for line in text.splitlines():
        stripped = line.strip()
        m = re.match(r"^(`{3,}|~{3,}|:{3,})\s*(?:\{([\w-]+)\})?", stripped)
        if m and stack and stripped == m.group(1) and m.group(1) == stack[-1][0]:
            stack.pop()                                                     # a closing fence
            continue
        if m and not (stack and stack[-1][1]):
            name = m.group(2) or ""
            code = name in CODE_DIRECTIVES or (m.group(1)[0] in "`~" and not name)
            stack.append((m.group(1), code))
            continue
        if (stack and stack[-1][1]) or (stack and stripped.startswith(":")):
            continue                                                        # code, or a directive's option
        if stripped.startswith("+++") or re.fullmatch(r"\([\w-]+\)=", stripped):
            continue                                                        # cell markers, labels
        out.append(line)
    body = "\n".join(out)
    body = re.sub(r"\$\$.*?\$\$", " ", body, flags=re.S)                     # display math
    body = re.sub(r"\$[^$\n]+\$", " x ", body)                              # inline math: one word
    body = re.sub(r"\{[\w-]+\}`[^`]*`", " x ", body)                        # roles ({cite}`...`)
    return body


def count_words(text: str) -> int:
    return len(re.findall(r"[A-Za-z0-9][\w'’.,-]*", prose(text)))


def toc_chapters() -> list[Path]:
    sys.path.insert(0, str(ROOT / ".ci"))
    import yaml
    from check_book import toc_pages

    toc = yaml.safe_load((ROOT / "_toc.yml").read_text(encoding="utf-8"))
    return [p for page in toc_pages(toc) for p in [ROOT / f"{page}.md"] if p.exists()]


def main() -> int:
    rows = sorted(((count_words(p.read_text(encoding="utf-8")), p.relative_to(ROOT)) for p in toc_chapters()),
                  reverse=True)
    for n, p in rows:
        print(f"{n:6d}  {p}{'   over ' + str(MAX_PROSE_WORDS) if n > MAX_PROSE_WORDS else ''}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
