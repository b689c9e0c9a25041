"""The browser check of the built book (.ci/browser_check.py), run on tiny generated sites.

Each site is checked in Debian's Chromium exactly as `.ci/run` checks the book: served on 127.0.0.1, every other
host blocked. A page with the book's own MathJax passes; the same page with MathJax from a CDN fails, as do
broken images, links, anchors, requests and scripts. These tests need Chromium (`apt-get install chromium`, or
CHROMIUM=/path/to/chrome; .ci/run installs it): without it they skip and say so, and under CI=true they fail.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from portable import skip_or_fail

ROOT = Path(__file__).resolve().parent.parent
CDN_MATHJAX = "https://cdn.jsdelivr.net/npm/mathjax@3/es5/tex-mml-chtml.js"


def _load_checker():
    spec = importlib.util.spec_from_file_location("browser_check", ROOT / ".ci" / "browser_check.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up here
    spec.loader.exec_module(module)
    return module


bc = _load_checker()


def chromium_or_skip() -> str:
    """The Chromium the checker finds; without one, the test skips (fails under CI=true) and says what to install."""
    try:
        return bc.find_chromium()
    except SystemExit as missing:
        skip_or_fail(f"{str(missing).split('. ')[0]}: apt-get install chromium, or set CHROMIUM=/path/to/chrome")


@pytest.fixture(scope="module")
def chromium() -> str:
    return chromium_or_skip()


def test_without_chromium_the_browser_tests_skip_and_say_what_to_install(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.setenv("CHROMIUM", "/nonexistent")
    with pytest.raises(pytest.skip.Exception, match=r"^Chromium not found at '/nonexistent': apt-get install chromium"):
        chromium_or_skip()
    monkeypatch.delenv("CHROMIUM")
    monkeypatch.setenv("PATH", "/nonexistent")
    with pytest.raises(pytest.skip.Exception, match=r"^No Chromium on this machine .*apt-get install chromium"):
        chromium_or_skip()
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="apt-get install chromium"):
        chromium_or_skip()


@pytest.fixture(scope="module")
def mathjax_dir() -> Path:
    spec = importlib.util.find_spec("sphinx-mathjax-offline")
    assert spec is not None and spec.origin, "sphinx-mathjax-offline is not installed: pip install -r requirements.txt"
    folder = Path(spec.origin).parent / "static" / "mathjax"
    assert (folder / "tex-chtml.js").is_file(), folder
    return folder


PAGE = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>{title}</title>
<script>window.MathJax = {{"options": {{"processHtmlClass": "tex2jax_process|math"}}}}</script>
{head}
</head><body>
<h1 id="top">{title}</h1>
{body}
</body></html>
"""

MATH = r"""<p>Inline <span class="math notranslate nohighlight">\(r_t(\theta) = \pi_\theta(a_t \mid s_t)\)</span>.</p>
<div class="math notranslate nohighlight">\[L(\theta) = \mathbb E_t\big[r_t(\theta)\,\hat A_t\big]\]</div>
"""


def _site(folder: Path, mathjax_dir: Path, mathjax_src: str = "_static/mathjax/tex-chtml.js",
          extra_body: str = "", extra_head: str = "") -> Path:
    """Two pages, like a built book: page.html with math, an image and links; other.html without math."""
    from PIL import Image

    (folder / "_static").mkdir(parents=True)
    (folder / "_static" / "mathjax").symlink_to(mathjax_dir, target_is_directory=True)
    pixels = np.zeros((8, 12, 3), dtype=np.uint8)
    pixels[:, :6] = 255
    Image.fromarray(pixels).save(folder / "_static" / "image.png")
    (folder / "page.html").write_text(PAGE.format(
        title="Page", head=f'<script defer src="{mathjax_src}"></script>' + extra_head,
        body=MATH + '<p><img alt="two squares" src="_static/image.png"></p>'
        '<p><a href="other.html">other</a>, <a href="other.html#section">its section</a>, '
        '<a href="#top">top</a>, <a href="https://example.org/">an external link</a></p>' + extra_body),
        encoding="utf-8")
    (folder / "other.html").write_text(PAGE.format(
        title="Other", head="", body='<h2 id="section">Section</h2><p><a href="page.html">back</a></p>'),
        encoding="utf-8")
    (folder / "page.md").write_text("# Page\n\nInline $r_t(\\theta)$.\n", encoding="utf-8")
    (folder / "other.md").write_text("# Other\n\nNo math; `$HOME` in code and a price of $5 and $10.\n",
                                     encoding="utf-8")
    return folder


def _check(site: Path, chromium: str, **kwargs) -> dict[str, list[str]]:
    results = bc.check_site(site, ["page", "other"], source_dir=site, chromium=chromium, timeout_s=30,
                            log=lambda line: None, **kwargs)
    return {r.page: r.problems for r in results} | {"_results": results}


def test_a_site_with_its_own_mathjax_passes(tmp_path, chromium, mathjax_dir):
    site = _site(tmp_path / "site", mathjax_dir)
    shots = tmp_path / "shots"
    out = _check(site, chromium, screenshots=shots)
    assert out["page"] == [] and out["other"] == [], out
    page, other = out["_results"]
    assert page.equations == 2 and other.equations == 0  # inline and display math typeset
    assert page.images == 1 and page.links >= 3
    assert (shots / "page.png").stat().st_size > 0 and (shots / "page.math.png").is_file()
    assert (shots / "other.png").is_file() and not (shots / "other.math.png").exists()


def test_mathjax_from_a_cdn_fails(tmp_path, chromium, mathjax_dir):
    site = _site(tmp_path / "site", mathjax_dir, mathjax_src=CDN_MATHJAX)
    out = _check(site, chromium)
    problems = "\n".join(out["page"])
    assert f"failed request {CDN_MATHJAX}" in problems
    assert f"MathJax is loaded from {CDN_MATHJAX}, not from the book" in problems
    assert "the page has TeX but MathJax did not load" in problems
    assert out["other"] == []


def test_broken_images_links_requests_and_scripts_fail_known_messages_do_not(tmp_path, chromium, mathjax_dir):
    site = _site(tmp_path / "site", mathjax_dir,
                 extra_head='<link rel="stylesheet" href="_static/missing.css">'
                            "<script>const once = 1;</script><script>const once = 2;</script>",
                 extra_body='<img alt="gone" src="_static/gone.png"><img alt="not an image" src="other.html">'
                            '<a href="nowhere.html">dead</a><a href="other.html#no-such-section">no anchor</a>'
                            r'<div class="math notranslate nohighlight">\[x^2^3\]</div>'
                            '<button class="search-button-field">Search</button><input type="search">'
                            "<script>console.error('something broke')</script>"
                            "<script>console.error('a known message')</script>")
    out = _check(site, chromium, known=[(r"^a known message", "accepted for this test")])
    problems = "\n".join(out["page"])
    assert "a known message" not in problems  # listed as known, not a problem
    [known] = out["_results"][0].known
    assert known.startswith("a known message") and known.endswith("(known: accepted for this test)")
    for expected in ("HTTP 404 for", "_static/missing.css", "_static/gone.png",
                     "image does not decode:", "/other.html",
                     "broken link", "nowhere.html", "no id 'no-such-section' in other.html",
                     "Identifier 'once' has already been declared", "console error: something broke",
                     "MathJax error: Double exponent", "2 search boxes in view at once"):
        assert expected in problems, (expected, problems)


def test_tex_in_a_source_is_found_outside_code():
    assert bc.source_has_tex("Inline $r_t(\\theta)$ here.")
    assert bc.source_has_tex("$$\nx^2\n$$")
    assert bc.source_has_tex("\\begin{align}a &= b\\end{align}")
    assert bc.source_has_tex("```{math}\nx\n```")
    assert not bc.source_has_tex("A price of $5 and $10, and `$x$` in code.")
    assert not bc.source_has_tex("```{code-cell} ipython3\nprint(f'${x}$')\n```\nNo math.")
    assert not bc.source_has_tex("````markdown\n```\n$x$\n```\n````")
