"""_ext/hide_markers.py: a listing of a whole function leaves out the marker comments of the excerpts inside it,
and an excerpt between two markers is still found by them. Built as a one-page Sphinx project (text builder)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SOURCE = '''\
def train(steps):
    total = 0
    # [demo-loop]
    for step in range(steps):
        total += step  # [not-a-marker] stays: code before it
    # [/demo-loop]
    return total
'''


def build(tmp_path: Path, extensions: list[str]) -> str:
    tmp_path.mkdir()
    (tmp_path / "demo.py").write_text(SOURCE)
    (tmp_path / "conf.py").write_text(f"import sys\nsys.path.insert(0, {str(ROOT / '_ext')!r})\n"
                                      f"extensions = {extensions!r}\n")
    (tmp_path / "index.rst").write_text(textwrap.dedent("""\
        Demo
        ====

        .. literalinclude:: demo.py
           :pyobject: train

        .. literalinclude:: demo.py
           :start-after: # [demo-loop]
           :end-before: # [/demo-loop]
           :dedent: 4
        """))
    subprocess.run([sys.executable, "-m", "sphinx", "-q", "-b", "text", str(tmp_path), str(tmp_path / "out")],
                   check=True, capture_output=True, text=True)
    return (tmp_path / "out" / "index.txt").read_text()


def test_markers_leave_the_listing_and_still_delimit_excerpts(tmp_path):
    text = build(tmp_path / "with", ["hide_markers"])
    assert "[demo-loop]" not in text and "[/demo-loop]" not in text
    assert text.count("for step in range(steps):") == 2  # the whole function, and the excerpt
    assert "return total" in text and "# [not-a-marker] stays" in text
    excerpt = text[text.rindex("for step in range(steps):"):]
    assert "return total" not in excerpt  # the excerpt stops at its end marker
    plain = build(tmp_path / "without", [])  # the check can fail: without the extension the markers show
    assert "# [demo-loop]" in plain
