"""The documentation site (``make docs``) in a real browser.

Builds the site of every notebook, as ``make docs`` does: the reader's-mode executions that
tests/test_notebooks.py keeps (``outputs/cache/notebooks``, on whichever worker ran them) are
copied, and a notebook not kept yet (the test run alone, or one still running on the other worker)
is executed here (about 3 min for all ten).

The site is served on 127.0.0.1 and every HTML page is opened in Debian's Chromium driven by
playwright, with every request that leaves 127.0.0.1 blocked and counted (the site must work
offline). Skipped, with the reason, where /usr/bin/chromium or playwright is missing.
"""

import functools
import http.server
import importlib.util
import re
import threading
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path

import pytest


CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run"]

_WAIT_FOR_IMAGES = """() => Promise.all(Array.from(document.images).map(img => img.complete ? null :
    new Promise(done => { img.addEventListener('load', done); img.addEventListener('error', done); })))"""
_IMAGES = "() => Array.from(document.images).map(img => [img.currentSrc || img.src, img.naturalWidth])"
_LINKS = "() => Array.from(document.querySelectorAll('a[href]')).map(a => a.href)"
_PLOTLY_RENDERED = """() => Array.from(document.querySelectorAll('.plotly-graph-div'))
    .filter(div => div.querySelector('svg.main-svg, canvas')).length"""
_MATH_RENDERED = "() => document.querySelectorAll('.MathJax, .MathJax_Display, mjx-container').length"
# Tables wider than the page's column (they would need a sideways scroll), as (first header, width, column).
_WIDE_TABLES = """() => { const column = document.querySelector('.md-content__inner').getBoundingClientRect().width;
    return Array.from(document.querySelectorAll('.md-content table'))
        .filter(t => t.scrollWidth > column + 1 || t.getBoundingClientRect().width > column + 1)
        .map(t => [(t.querySelector('th') || {}).textContent || '', Math.round(t.scrollWidth), Math.round(column)]); }"""
_STDERR_BLOCKS = "() => document.querySelectorAll('[data-mime-type=\"application/vnd.jupyter.stderr\"]').length"
# Figures of a notebook page: (shown width, natural width, column width).
_FIGURES = """() => { const column = document.querySelector('.md-content__inner').getBoundingClientRect().width;
    return Array.from(document.querySelectorAll('.jp-RenderedImage img'))
        .map(img => [img.getBoundingClientRect().width, img.naturalWidth, column]); }"""
VIEWPORT = {"width": 1600, "height": 1000}
# Entries of a page's table of contents whose anchor is not on the page.
_TOC_BROKEN = """() => Array.from(document.querySelectorAll('.md-sidebar--secondary a[href^="#"]'))
    .filter(a => !document.getElementById(decodeURIComponent(a.hash.slice(1)))).map(a => a.textContent.trim())"""
# What a notebook page says (its prose and outputs), without the code it shows.
_SHOWN_TEXT = """() => { const page = document.querySelector('.md-content').cloneNode(true);
    page.querySelectorAll('.jp-InputArea, .jp-InputPrompt, pre, code').forEach(e => e.remove());
    return page.innerText; }"""


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture
def served(tmp_path):
    """An HTTP server on 127.0.0.1 for a folder: ``served(folder) -> base URL``."""
    servers = []

    def serve(folder):
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0),
                                                 functools.partial(_QuietHandler, directory=str(folder)))
        threading.Thread(target=server.serve_forever, daemon=True).start()
        servers.append(server)
        return f"http://127.0.0.1:{server.server_address[1]}/"

    yield serve
    for server in servers:
        server.shutdown()
        server.server_close()


def _has_math(notebook: Path) -> bool:
    import nbformat

    cells = nbformat.read(notebook, as_version=4).cells
    return any(cell.cell_type == "markdown" and re.search(r"\$[^$\n]+\$", cell.source) for cell in cells)


def _status(url: str) -> int:
    try:
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.status
    except urllib.error.HTTPError as exc:
        return exc.code


@pytest.mark.slow
def test_site_pages_load_with_their_figures_links_and_3d_views_offline(tmp_path, served):
    if not CHROMIUM.is_file():
        pytest.skip(f"no browser: {CHROMIUM} is missing (make system-deps installs the Debian package "
                    f"chromium as root)")
    if importlib.util.find_spec("playwright") is None:
        pytest.skip("the playwright package is missing (environment.txt)")
    from playwright.sync_api import sync_playwright

    from tools.notebooks import run_notebooks
    from tools.site import build_site

    executed_notebooks = tmp_path / "notebooks"
    run_notebooks(full=False, destination=executed_notebooks, progress=False)  # kept executions are copied
    summary = build_site(executed_notebooks, tmp_path / "site", progress=False)
    site = Path(summary["destination"])
    tutorials = {stem for stem, _ in summary["notebooks"]}
    assert len(tutorials) == 11 and all((site / f"{stem}.html").is_file() for stem in tutorials)
    pages = sorted(p.relative_to(site).as_posix() for p in site.rglob("*.html")
                   if "assets" not in p.relative_to(site).parts)
    assert "index.html" in pages
    # plotly.js ships once, as an asset every page with a 3D view references instead of an inline copy
    plotly_assets = list(site.rglob("plotly-*.js"))
    assert [p.relative_to(site).as_posix() for p in plotly_assets] == [summary["plotly"]["asset"]]
    assert summary["plotly"]["shared"] >= 1 and summary["plotly"]["inline"] == 0
    for name in pages:
        html = (site / name).read_text(encoding="utf-8")
        assert "* plotly.js v" not in html, f"{name} inlines plotly.js"
    assert any(f'src="{summary["plotly"]["asset"]}"' in (site / name).read_text(encoding="utf-8") for name in pages)
    base = served(site)

    external, problems, internal_links = [], [], set()
    plotly_rendered, math_rendered, banners, stderr_blocks = 0, 0, 0, 0
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        context = browser.new_context(viewport=VIEWPORT)

        def only_local(route):
            if route.request.url.startswith(base) or route.request.url.startswith(("data:", "blob:")):
                return route.continue_()
            external.append(route.request.url)
            return route.abort()

        context.route("**/*", only_local)
        page = context.new_page()
        errors = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        for name in pages:
            errors.clear()
            response = page.goto(base + name, wait_until="load")
            if response is None or response.status != 200:
                problems.append(f"{name}: HTTP {response.status if response else 'no response'}")
                continue
            page.evaluate(_WAIT_FOR_IMAGES)
            for src, width in page.evaluate(_IMAGES):
                if not width:
                    problems.append(f"{name}: image {src[:80]} has no width (not loaded)")
            for href in page.evaluate(_LINKS):
                if href.startswith(base):
                    internal_links.add(urllib.parse.urldefrag(href)[0])
            if Path(name).stem in tutorials:
                if page.locator(".plotly-graph-div").count():
                    page.wait_for_function(_PLOTLY_RENDERED, timeout=15000)
                    plotly_rendered += page.evaluate(_PLOTLY_RENDERED)
                if summary["mathjax"] and _has_math(executed_notebooks / f"{Path(name).stem}.ipynb"):
                    page.wait_for_function(_MATH_RENDERED, timeout=15000)
                    math_rendered += page.evaluate(_MATH_RENDERED)
                banners += page.get_by_text("executed in reader's mode").count()
                stderr_blocks += page.evaluate(_STDERR_BLOCKS)
                figures = page.evaluate(_FIGURES)
                for shown, natural, column in figures:
                    if shown < min(natural, column) - 2:
                        problems.append(f"{name}: a figure shown at {shown:.0f} px of {natural} (column {column:.0f})")
                if figures:  # a click opens a figure at full size, a second closes it
                    page.locator(".jp-RenderedImage img").first.click()
                    if page.locator(".tpvp-zoom img").count() != 1:
                        problems.append(f"{name}: a click on a figure does not open it at full size")
                    page.locator(".tpvp-zoom").click()
                if "reduced run" in page.evaluate(_SHOWN_TEXT).lower():  # every paper table's rows are shipped
                    problems.append(f"{name}: says 'reduced run'")
            problems.extend(f"{name}: table {header!r} is {width} px wide in a {column} px column"
                            for header, width, column in page.evaluate(_WIDE_TABLES))
            problems.extend(f"{name}: the table of contents' entry {entry!r} links to no heading"
                            for entry in page.evaluate(_TOC_BROKEN))
            problems.extend(f"{name}: page error {error}" for error in errors)
        browser.close()

    for url in sorted(internal_links):
        status = _status(url)
        if status != 200:
            problems.append(f"broken internal link {url[len(base):]}: HTTP {status}")
    assert not problems, "\n".join(problems)
    assert not external, f"the site asked the network for {sorted(set(external))[:5]}"
    assert plotly_rendered >= 1, "no plotly figure rendered on a tutorial page"
    assert not summary["mathjax"] or math_rendered, "MathJax is shipped but rendered no formula"
    reader = sum(mode != "full" for _, mode in summary["notebooks"])
    assert banners >= reader, "a reader's-mode page lacks its label"
    assert stderr_blocks == 0, f"{stderr_blocks} blocks of stderr on the notebook pages"


def test_share_plotly_ships_one_copy_and_keeps_a_differing_one_inline(tmp_path):
    from tools.site import share_plotly

    plotly = "/**\n* plotly.js v4.1.1\n* Copyright\n*/\n!function(){window.Plotly={}}();\r\n"
    other = plotly.replace("v4.1.1", "v2.0.0")
    page = ('<html><body><script type="text/javascript">window.PlotlyConfig = {};</script>'
            '<script type="text/javascript">{js}</script><div id="f"></div>'
            '<script type="text/javascript">Plotly.newPlot("f", []);</script></body></html>')
    (tmp_path / "assets").mkdir()
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.html").write_bytes(page.replace("{js}", plotly).encode())
    (tmp_path / "sub" / "b.html").write_bytes(page.replace("{js}", plotly).encode())
    (tmp_path / "c.html").write_bytes(page.replace("{js}", other).encode())
    (tmp_path / "plain.html").write_bytes(b"<html><script>var x;</script></html>")

    summary = share_plotly(tmp_path)

    assert summary == {"asset": "assets/plotly/plotly-4.1.1.js", "shared": 2, "inline": 1}
    assert (tmp_path / "assets" / "plotly" / "plotly-4.1.1.js").read_bytes() == plotly.encode()
    assert list(tmp_path.rglob("*.js")) == [tmp_path / "assets" / "plotly" / "plotly-4.1.1.js"]
    expected = page.replace('<script type="text/javascript">{js}</script>',
                            '<script type="text/javascript" src="{src}"></script>')
    assert (tmp_path / "a.html").read_text() == expected.replace("{src}", "assets/plotly/plotly-4.1.1.js")
    assert (tmp_path / "sub" / "b.html").read_text() == expected.replace("{src}", "../assets/plotly/plotly-4.1.1.js")
    assert (tmp_path / "c.html").read_bytes() == page.replace("{js}", other).encode()  # another version: inline
    assert (tmp_path / "plain.html").read_bytes() == b"<html><script>var x;</script></html>"
    assert share_plotly(tmp_path) == {"asset": "assets/plotly/plotly-2.0.0.js", "shared": 1, "inline": 0}
