#!/usr/bin/env python3
"""Open every page of the built book in a real browser, offline, and check what a reader would see.

Run from the repository root after `jupyter-book build .` (`.ci/run` does, after .ci/check_book.py):

    .venv/bin/python .ci/browser_check.py            # _build/html, pages from _toc.yml
    .venv/bin/python .ci/browser_check.py --help

It serves `_build/html/` with Python's http.server on 127.0.0.1 and drives Debian's Chromium (`apt-get install
chromium`) through Playwright (`pip install playwright`, in requirements.txt; it uses the system browser, so no
`playwright install` download). Every request that does not go to that loopback server is blocked and counted as
a failed request, so the check means the same with or without internet access: a page that needs a CDN fails.

For every page of _toc.yml it fails on

- a failed request (blocked, refused, aborted) or a response with status >= 400;
- a console error or an uncaught exception, other than those in KNOWN_CONSOLE_ERRORS (none at present);
- an <img> that does not decode (naturalWidth 0);
- a page with TeX (in its source, or math elements in its HTML) where MathJax did not load from the book itself,
  left math untypeset, or reported an error (<mjx-merror>);
- an internal link (same site) to a file that does not exist, or to an #anchor the target page does not have;
- more than one search box in view (a header bar's on top of the sidebar's);

and saves a screenshot of the top of each page, plus one of its first equation where it has math, under
`_build/browser/`. The exit status is 0 when every page passes, 1 otherwise; each problem is printed.
tests/test_browser_check.py runs the same checks on two tiny generated sites: one with the book's local MathJax
passes, the same page with MathJax from a CDN fails.
"""

from __future__ import annotations

import argparse
import functools
import html.parser
import http.server
import os
import re
import shutil
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote, urldefrag, urljoin, urlsplit

sys.path.insert(0, str(Path(__file__).resolve().parent))
from check_book import toc_pages  # noqa: E402 (the one reader of _toc.yml, shared with the book check)

ROOT = Path(__file__).resolve().parent.parent
HTML = ROOT / "_build" / "html"
SCREENSHOTS = ROOT / "_build" / "browser"

# Console errors that are known and accepted, as (regular expression, why). Jupyter Book 1.0 used to log
# "Identifier 'THEBE_JS_URL' has already been declared" on every page; _ext/dedupe_scripts.py removes its cause,
# so the list is empty and that message now fails the check like any other.
KNOWN_CONSOLE_ERRORS: list[tuple[str, str]] = []

# Where Chromium may be; the CHROMIUM environment variable or --chromium comes first.
CHROMIUM_CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
INSTALL_HINT = ("Install Debian's Chromium (sudo apt-get install chromium; .ci/run does) or point --chromium or the "
                "CHROMIUM environment variable at a Chromium or Chrome executable.")

# TeX in a MyST Markdown source, outside code: $$...$$, $...$ (dollarmath's rule: no space inside the dollars),
# \begin{env} (amsmath), or a {math} role or directive.
_TEX = re.compile(r"\$\$|(?<![\\$\w])\$[^\s$](?:[^$\n]*?[^\s$\\])?\$(?![\w$])|\\begin\{[a-zA-Z*]+\}|\{math\}")
_FENCE = re.compile(r"^(\s*)(`{3,}|~{3,}|:{3,})(.*)$")


def find_chromium(explicit: str | None = None) -> str:
    """The Chromium executable to drive: ``explicit``, else $CHROMIUM, else the first on PATH."""
    for candidate in (explicit, os.environ.get("CHROMIUM")):
        if candidate:
            path = shutil.which(candidate) or (candidate if Path(candidate).is_file() else None)
            if path is None:
                raise SystemExit(f"Chromium not found at {candidate!r}. {INSTALL_HINT}")
            return path
    for name in CHROMIUM_CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    raise SystemExit(f"No Chromium on this machine (looked for {', '.join(CHROMIUM_CANDIDATES)}). {INSTALL_HINT}")


def source_has_tex(text: str) -> bool:
    """Whether MyST Markdown ``text`` has TeX outside code fences (code-cell, ```` ``` ````) and inline code."""
    prose: list[str] = []
    fence: str | None = None
    for line in text.splitlines():
        match = _FENCE.match(line)
        if fence is None:
            if match and match.group(2)[0] in "`~":
                if "{math}" in match.group(3):  # ```{math} is TeX
                    return True
                fence = match.group(2)
                continue
            prose.append(re.sub(r"`[^`]*`", "", line))
        elif match and match.group(2).startswith(fence) and not match.group(3).strip():
            fence = None
    return bool(_TEX.search("\n".join(prose)))


class _Anchors(html.parser.HTMLParser):
    """Collects every id= and <a name=> of an HTML document."""

    def __init__(self) -> None:
        super().__init__()
        self.anchors: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for key, value in attrs:
            if value and (key == "id" or (key == "name" and tag == "a")):
                self.anchors.add(value)


@functools.lru_cache(maxsize=None)
def _anchors_of(path: Path) -> frozenset[str]:
    parser = _Anchors()
    parser.feed(path.read_text(encoding="utf-8", errors="replace"))
    return frozenset(parser.anchors)


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:  # noqa: A002 (http.server's name)
        pass


class LocalSite:
    """``directory`` served over HTTP on 127.0.0.1 (a free port) in a background thread."""

    def __init__(self, directory: Path) -> None:
        handler = functools.partial(_QuietHandler, directory=str(directory))
        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def __enter__(self) -> LocalSite:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.shutdown()
        self.server.server_close()


@dataclass
class PageResult:
    page: str
    problems: list[str] = field(default_factory=list)
    known: list[str] = field(default_factory=list)
    images: int = 0
    equations: int = 0
    links: int = 0
    screenshots: list[Path] = field(default_factory=list)


# Runs in the page after it loaded: the images, the math and the links it has.
_INSPECT = """async (timeoutMs) => {
    const timeout = () => new Promise(resolve => setTimeout(() => resolve("timeout"), timeoutMs));
    const images = [...document.images];
    for (const img of images) { img.loading = "eager"; }
    await Promise.race([Promise.all(images.map(img => img.decode().catch(() => null))), timeout()]);
    const result = {
        images: images.map(img => ({src: img.currentSrc || img.src, ok: img.complete && img.naturalWidth > 0})),
        mathElements: document.querySelectorAll(".math").length,
        mathjaxScripts: [...document.scripts].map(s => s.src).filter(src => /mathjax/i.test(src)),
        mathjaxLoaded: !!(window.MathJax && window.MathJax.startup && window.MathJax.version),
        links: [...document.querySelectorAll("a[href]")].map(a => a.href),
        searchBoxes: [...document.querySelectorAll(".search-button-field, form.bd-search, input[type=search]")]
            .filter(el => el.getClientRects().length > 0 && el.getBoundingClientRect().height > 0).length,
    };
    if (result.mathjaxLoaded) {
        result.typesetTimedOut = (await Promise.race([window.MathJax.startup.promise, timeout()])) === "timeout";
        result.mathjaxVersion = window.MathJax.version;
        result.typeset = document.querySelectorAll("mjx-container").length;
        result.untypeset = [...document.querySelectorAll(".math")]
            .filter(el => !el.querySelector("mjx-container")).map(el => el.textContent.trim().slice(0, 80));
        result.errors = [...document.querySelectorAll("mjx-merror")]
            .map(el => (el.getAttribute("data-mjx-error") || el.textContent).slice(0, 120));
    }
    return result;
}"""


# Scrolls to the first visible equation (display math first) and says whether there is one.
_SCROLL_TO_MATH = """() => {
    const visible = el => el.getClientRects().length > 0 && el.getBoundingClientRect().height > 0;
    const first = [...document.querySelectorAll("div.math mjx-container")].find(visible)
        || [...document.querySelectorAll("mjx-container")].find(visible);
    if (!first) { return false; }
    window.scrollTo(0, window.scrollY + first.getBoundingClientRect().top - 120);
    return true;
}"""


def _is_local(url: str, base: str) -> bool:
    return url.startswith(base) or url.startswith(("data:", "blob:", "about:"))


def _check_link(href: str, html_dir: Path) -> str | None:
    """None if a same-site link resolves (file and #anchor), else why not."""
    target, fragment = urldefrag(href)
    path = unquote(urlsplit(target).path)
    file = html_dir / path.lstrip("/")
    if path.endswith("/") or file.is_dir():
        file = file / "index.html"
    if not file.is_file():
        return f"broken link {href} (no {file.relative_to(html_dir) if file.is_relative_to(html_dir) else file})"
    if fragment and file.suffix == ".html" and unquote(fragment) not in _anchors_of(file):
        return f"broken link {href} (no id {unquote(fragment)!r} in {file.relative_to(html_dir)})"
    return None


def check_page(context, site_url: str, html_dir: Path, page: str, source: Path | None, shots: Path | None,
               known: list[tuple[str, str]], timeout_s: float) -> PageResult:
    result = PageResult(page)
    url = urljoin(site_url, f"{page}.html")
    html_file = html_dir / f"{page}.html"
    if not html_file.is_file():
        result.problems.append(f"{html_file.relative_to(html_dir)} does not exist")
        return result
    events: list[str] = []
    console: list[str] = []

    def on_console(message) -> None:
        if message.type == "error":
            where = message.location.get("url", "") if isinstance(message.location, dict) else ""
            console.append(message.text + (f" ({where})" if where else ""))

    tab = context.new_page()
    tab.on("console", on_console)
    tab.on("pageerror", lambda error: console.append(f"uncaught {error.name}: {error.message}"))
    tab.on("requestfailed", lambda request: events.append(f"failed request {request.url} (" + (
        str(request.failure) if _is_local(request.url, site_url) else "blocked: not the local server") + ")"))
    tab.on("response", lambda response: response.status >= 400 and events.append(
        f"HTTP {response.status} for {response.url}"))
    try:
        tab.goto(url, wait_until="load", timeout=timeout_s * 1000)
        try:
            tab.wait_for_load_state("networkidle", timeout=timeout_s * 1000)
        except Exception:  # a page that keeps the network busy is not a failure by itself
            pass
        info = tab.evaluate(_INSPECT, timeout_s * 1000)
        if shots is not None:
            shot = shots / f"{page}.png"
            shot.parent.mkdir(parents=True, exist_ok=True)
            tab.screenshot(path=str(shot))
            result.screenshots.append(shot)
            if tab.evaluate(_SCROLL_TO_MATH):
                shot = shots / f"{page}.math.png"
                tab.screenshot(path=str(shot))
                result.screenshots.append(shot)
        tab.wait_for_timeout(100)  # let late console messages arrive
    except Exception as error:  # noqa: BLE001 (a page that cannot even be opened is one problem)
        result.problems.append(f"could not check the page: {type(error).__name__}: {error}")
        return result
    finally:
        tab.close()

    result.problems.extend(dict.fromkeys(events))
    for message in dict.fromkeys(console):
        why = next((why for pattern, why in known if re.search(pattern, message)), None)
        if why is None:
            result.problems.append(f"console error: {message}")
        else:
            result.known.append(f"{message} (known: {why})")

    if info["searchBoxes"] > 1:
        result.problems.append(f"{info['searchBoxes']} search boxes in view at once (the theme's header bar and the "
                               "sidebar each have one: keep the sidebar's)")
    result.images = len(info["images"])
    result.problems.extend(f"image does not decode: {img['src']}" for img in info["images"] if not img["ok"])

    has_tex = info["mathElements"] > 0 or (source is not None and source.is_file()
                                            and source.suffix == ".md"
                                            and source_has_tex(source.read_text(encoding="utf-8")))
    for src in info["mathjaxScripts"]:
        if not _is_local(src, site_url):
            result.problems.append(f"MathJax is loaded from {src}, not from the book")
    if has_tex:
        if not info["mathjaxLoaded"]:
            result.problems.append("the page has TeX but MathJax did not load (scripts: "
                                   + (", ".join(info["mathjaxScripts"]) or "none") + ")")
        else:
            result.equations = info["typeset"]
            if info["typesetTimedOut"]:
                result.problems.append(f"MathJax had not finished typesetting after {timeout_s:g} s")
            if info["typeset"] == 0:
                result.problems.append("the page has TeX but MathJax typeset nothing")
            result.problems.extend(f"math left untypeset: {text!r}" for text in info["untypeset"][:5])
            result.problems.extend(f"MathJax error: {text}" for text in info["errors"][:5])

    internal = sorted({link for link in info["links"] if link.startswith(site_url)})
    result.links = len(internal)
    for link in internal:
        why = _check_link(link, html_dir)
        if why:
            result.problems.append(why)
    return result


def check_site(html_dir: Path, pages: list[str], source_dir: Path | None = None, screenshots: Path | None = None,
               chromium: str | None = None, known: list[tuple[str, str]] | None = None,
               timeout_s: float = 60.0, log=functools.partial(print, flush=True)) -> list[PageResult]:
    """Check ``pages`` (paths without suffix, as in _toc.yml) of the site in ``html_dir``; one result per page."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        raise SystemExit("Playwright is not installed: pip install -r requirements.txt (or pip install playwright).")
    executable = find_chromium(chromium)
    known = KNOWN_CONSOLE_ERRORS if known is None else known
    _anchors_of.cache_clear()
    if screenshots is not None and screenshots.is_dir():
        for old in screenshots.rglob("*.png"):  # screenshots of an earlier run, and nothing else
            old.unlink()
    results = []
    with LocalSite(html_dir) as site, sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=executable,
            # belt and braces next to the request filter below: no DNS for anything but the loopback server
            args=["--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1", "--disable-gpu"])
        try:
            for page in pages:
                started = time.monotonic()
                # a fresh context per page, as for a reader who opens this page first (no cache, no localStorage)
                context = browser.new_context(viewport={"width": 1280, "height": 900}, service_workers="block")
                context.route("**/*", lambda route: route.continue_() if _is_local(route.request.url, site.url)
                              else route.abort("blockedbyclient"))
                source = None
                if source_dir is not None:
                    source = next((source_dir / f"{page}{suffix}" for suffix in (".md", ".ipynb", ".rst")
                                   if (source_dir / f"{page}{suffix}").is_file()), None)
                try:
                    result = check_page(context, site.url, html_dir, page, source, screenshots, known, timeout_s)
                finally:
                    context.close()
                results.append(result)
                status = "ok" if not result.problems else f"{len(result.problems)} problem(s)"
                log(f"  {page}: {status}; {result.images} images, {result.equations} equations typeset, "
                    f"{result.links} internal links ({time.monotonic() - started:.1f} s)")
                for problem in result.problems:
                    log(f"      - {problem}")
                for message in result.known:
                    log(f"      known console message: {message}")
        finally:
            browser.close()
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--html", type=Path, default=HTML, help="the built site (default: _build/html)")
    parser.add_argument("--toc", type=Path, default=ROOT / "_toc.yml", help="the pages to check (default: _toc.yml)")
    parser.add_argument("--screenshots", type=Path, default=SCREENSHOTS, help="where to save the screenshots "
                        "(default: _build/browser; its old .png files are deleted first)")
    parser.add_argument("--chromium", help="the browser executable (default: $CHROMIUM, else chromium on PATH)")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds allowed to load one page (default: 60)")
    args = parser.parse_args(argv)

    import yaml

    html_dir = args.html.resolve()
    if not html_dir.is_dir():
        print(f"{html_dir} does not exist: build the book first (jupyter-book build .)", file=sys.stderr)
        return 1
    pages = toc_pages(yaml.safe_load(args.toc.read_text(encoding="utf-8")))
    print(f"Checking {len(pages)} pages of {args.toc.name} in {find_chromium(args.chromium)}, served from "
          f"{html_dir} on 127.0.0.1 (every other host blocked):", flush=True)
    results = check_site(html_dir, pages, source_dir=args.toc.resolve().parent, screenshots=args.screenshots,
                         chromium=args.chromium, timeout_s=args.timeout)
    failed = [r for r in results if r.problems]
    shots = sum(len(r.screenshots) for r in results)
    if failed:
        print(f"Browser check FAILED on {len(failed)} of {len(results)} pages "
              f"({sum(len(r.problems) for r in failed)} problems, listed above).", file=sys.stderr)
        return 1
    print(f"Browser check passed: {len(results)} pages, {sum(r.images for r in results)} images, "
          f"{sum(r.equations for r in results)} equations typeset, {sum(r.links for r in results)} internal links; "
          f"{shots} screenshots in {args.screenshots}.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
