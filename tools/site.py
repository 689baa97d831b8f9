"""Build the documentation site: README, docs/ and the executed notebooks as one static site.

``python -m tools.site [--notebooks DIR] [--output DIR]`` (``make docs``) assembles a
temporary MkDocs source folder and builds it with mkdocs-material + mkdocs-jupyter (settings in the
repository's ``mkdocs.yml``) in strict mode:

- ``index.md``: the README, its links rewritten for the site (``docs/x.md`` -> ``x.md``,
  ``notebooks/NN_x.ipynb`` -> the executed notebook's page, a file outside the site -> its path as
  text);
- every ``docs/*.md`` page (and the other files under ``docs/``, e.g. pictures), as they are at
  build time;
- every notebook of ``notebooks/`` as executed by :mod:`tools.notebooks` into the
  notebooks folder (not executed again); a notebook executed in reader's mode carries a warning at
  its top. A missing executed notebook fails the build with one line saying what to run.

The site is published to ``destination`` through :func:`tpvp.io.publish.staged_folder`: an
interrupted or failed build leaves the previous site whole. It needs no network: no web fonts,
plotly.js ships once as ``assets/plotly/plotly-<version>.js`` (the notebooks' outputs carry it inline;
:func:`share_plotly` replaces each identical copy with a ``<script src>`` at the same place), search
runs in the browser, and MathJax is a local
copy (:func:`tools.notebooks.mathjax_folder`) or, where none is installed, math stays
as TeX text.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import posixpath
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tpvp.errors import ConfigError, run_command
from tpvp.experiments.notebooks import published_results
from tools.notebooks import MANIFEST, NOTEBOOKS, ROOT, copy_mathjax, mathjax_folder, notebook_paths
from tpvp.io.publish import staged_folder

DOCS = ROOT / "docs"
README = ROOT / "README.md"
CONFIG = ROOT / "mkdocs.yml"
MATHJAX_DIR = "assets/mathjax"
PLOTLY_DIR = "assets/plotly"
MATHJAX_CONFIG = "TeX-AMS-MML_HTMLorMML-full,Safe,local/tpvp"
# the copy of MathJax 2.7 in jupyter-server-mathjax ships the STIX web fonts only
_MATHJAX_LOCAL_CONFIG = """MathJax.Hub.Config({
  "HTML-CSS": {availableFonts: ["STIX"], preferredFont: "STIX", webFont: "STIX-Web", imageFont: null},
  menuSettings: {zoom: "None"}
});
MathJax.Ajax.loadComplete("[MathJax]/config/local/tpvp.js");
"""
_RUN_NOTEBOOKS = "python -m tools.notebooks"


# --------------------------------------------------------------------------------------------------
# links: repository paths -> site pages
# --------------------------------------------------------------------------------------------------

_LINK = re.compile(r"(!?)\[((?:[^\[\]]|\[[^\[\]]*\])*)\]\(\s*<?([^()\s<>]*)>?(\s+\"[^\"]*\")?\s*\)")
_CODE_SPAN = re.compile(r"(`+)[^`]*?\1")
_FENCE = re.compile(r"^\s{0,3}(`{3,}|~{3,})")


class SiteLinks:
    """Where each repository file lives in the site: ``{repository path: site path}``."""

    def __init__(self, pages: dict[str, str]):
        self.pages = pages

    def target(self, source_dir: str, link: str, html: bool) -> str | None:
        """The site-relative target of ``link`` (written in the repository file ``source_dir/...``),
        ``link`` itself when it needs no change, or None when it points outside the site."""
        if not link or link.startswith("#") or re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", link):
            return link  # an anchor in the page, or an absolute URL (http:, mailto:, data:)
        path, sep, fragment = link.partition("#")
        repo_path = posixpath.normpath(posixpath.join(source_dir, path)) if not path.startswith("/") \
            else posixpath.normpath(path.lstrip("/"))
        site = self.pages.get(repo_path.rstrip("/"))
        if site is None:
            return None
        if html:
            site = re.sub(r"\.(md|ipynb)$", ".html", site)
        return site + sep + fragment

    def rewrite(self, text: str, source_dir: str, html: bool = False) -> str:
        """Rewrite the Markdown links of ``text`` (outside code) for the site."""
        out, prose, fenced = [], [], None
        for line in text.splitlines(keepends=True):
            fence = _FENCE.match(line)
            if fenced:
                if fence and fence.group(1)[0] == fenced[0] and len(fence.group(1)) >= len(fenced):
                    fenced = None
                out.append(line)
            elif fence:
                out.append(self._rewrite_links("".join(prose), source_dir, html))
                prose, fenced = [], fence.group(1)
                out.append(line)
            else:
                prose.append(line)
        out.append(self._rewrite_links("".join(prose), source_dir, html))
        return "".join(out)

    def _rewrite_links(self, text: str, source_dir: str, html: bool) -> str:
        code = [span.span() for span in _CODE_SPAN.finditer(text)]

        def one(match):
            if any(start <= match.start() < end for start, end in code):
                return match.group(0)  # inside `code`
            bang, label, link, title = match.group(1), match.group(2), match.group(3), match.group(4) or ""
            target = self.target(source_dir, link, html)
            if target is not None:
                return f"{bang}[{label}]({target}{title})"
            shown = posixpath.normpath(posixpath.join(source_dir, link.partition("#")[0]))
            if bang:  # a picture that is not part of the site: its description
                return f"*{label or shown}*"
            if shown in label:
                return label
            return f"{label} (`{shown}` in the repository)"

        return _LINK.sub(one, text)


# --------------------------------------------------------------------------------------------------
# the executed notebooks
# --------------------------------------------------------------------------------------------------


def executed_notebooks(folder, allow_missing: bool = False) -> list[tuple[Path, dict]]:
    """The executed copies of the repository's notebooks in ``folder``, in order, each with its
    manifest entry (mode, seconds, executed_utc). A missing one is an error naming the command that
    makes it, unless ``allow_missing`` (then at least one must be there)."""
    folder = Path(folder)
    manifest_path = folder / MANIFEST
    found, missing = [], []
    manifest = {}
    if manifest_path.is_file():
        try:
            manifest = json.loads(manifest_path.read_text())
        except ValueError:
            raise ConfigError(f"{manifest_path} is not valid JSON; run {_RUN_NOTEBOOKS} --output {folder} again") from None
    for stored in notebook_paths():
        executed = folder / f"{stored.stem}.ipynb"
        if executed.is_file():
            found.append((executed, manifest.get(stored.stem, {})))
        else:
            missing.append(stored.stem)
    if missing and not (allow_missing and found):
        what = "no executed notebooks" if not found else f"no executed notebook {', '.join(missing)}"
        names = "" if not found else " " + " ".join(missing)
        full = f"make notebooks OUT={folder.parent}" if folder.name == "notebooks" else \
            f"{_RUN_NOTEBOOKS} --full --output {folder}{names}"
        raise ConfigError(f"{folder} has {what}; run `{full}` (the paper's protocol) or "
                     f"`{_RUN_NOTEBOOKS} --output {folder}{names}` (reader's mode) first")
    return found


def _first_heading(text: str) -> str | None:
    match = re.search(r"^#\s+(.+?)\s*#*\s*$", text, flags=re.M)
    return match.group(1).strip() if match else None


def _mode_banner(entry: dict) -> str | None:
    """A note at the top of a notebook page saying how it was executed: none for the full protocol,
    a note for reader's mode (its tables from the full protocol's rows), a warning for an unknown mode."""
    mode = entry.get("mode")
    when = entry.get("executed_utc", "")
    when = f" on {when.replace('T', ' ')[:16]} UTC" if when else ""
    took = f" in {entry['seconds']:.0f} s" if isinstance(entry.get("seconds"), (int, float)) else ""
    if mode == "full":
        return None
    if mode == "reader":
        return (f'<div class="admonition note"><p class="admonition-title">This page was executed in reader\'s '
                f"mode</p><p>With <code>full = False</code>{when}{took}: the paper's tables come from the full "
                f"protocol's result rows (each table says where its rows come from); the cells that explain a "
                f"step run on one case. <code>make notebooks</code> runs the whole protocol.</p></div>")
    return (f'<div class="admonition warning"><p class="admonition-title">This page was executed in an unknown '
            f"mode</p><p>Its manifest entry says neither reader's mode nor the full protocol{when}{took}. "
            f"<code>make notebooks</code> followed by <code>make docs</code> builds the pages from the "
            f"paper's protocol.</p></div>")


def _plain_headings(markdown: str) -> str:
    """Headings without inline-code marks: mkdocs-jupyter's table of contents drops a heading's code
    (its entry would read "A new day: , then plan it" and link to an anchor that does not exist)."""
    return re.sub(r"(?m)^(#{1,6}\s.*)$", lambda m: m.group(1).replace("`", ""), markdown)


def _title_first(notebook, stored: Path) -> None:
    """The page's title above its parameters: a first code cell (the parameters) moves below the
    title, and shows the stored notebook's ``output`` line, not the build machine's path."""
    import nbformat

    cells = notebook.cells
    if len(cells) > 1 and cells[0].cell_type == "code" and cells[1].cell_type == "markdown" and \
            cells[1].source.lstrip().startswith("#"):
        cells[0], cells[1] = cells[1], cells[0]
    parameters = next((c for c in cells if c.cell_type == "code"), None)
    if parameters is None or not stored.is_file():
        return
    original = next((c for c in nbformat.read(stored, as_version=4).cells if c.cell_type == "code"), None)
    stored_output = [line for line in (original.source if original else "").splitlines()
                     if re.match(r"output\s*=", line)]
    if stored_output:
        parameters.source = "\n".join(stored_output[0] if re.match(r"output\s*=", line) else line
                                      for line in parameters.source.splitlines())


def _notebook_page(executed: Path, entry: dict, links: SiteLinks, target: Path) -> str:
    """Write the site's copy of one executed notebook (links rewritten, the mode banner on top);
    returns its title."""
    import nbformat

    notebook = nbformat.read(executed, as_version=4)
    # Widgets (tqdm's progress bars) would load their renderer from a CDN, and their text is the
    # bar's first state (0 %): a static page leaves them out.
    notebook.metadata.pop("widgets", None)
    for cell in notebook.cells:
        if cell.cell_type == "markdown":
            cell.source = links.rewrite(_plain_headings(cell.source), "notebooks", html=True)
        elif "outputs" in cell:
            cell.outputs = [output for output in cell.outputs
                            if "application/vnd.jupyter.widget-view+json" not in output.get("data", {})]
            for output in cell.outputs:  # Markdown a cell displays (e.g. the paper gaps' links into docs/)
                data = output.get("data", {})
                if "text/markdown" in data:
                    text = data["text/markdown"]
                    data["text/markdown"] = links.rewrite("".join(text) if isinstance(text, list) else text,
                                                          "notebooks", html=True)
    _title_first(notebook, NOTEBOOKS / executed.name)
    first_markdown = next((c for c in notebook.cells if c.cell_type == "markdown"), None)
    title = (_first_heading(first_markdown.source) if first_markdown is not None else None) or executed.stem
    banner = _mode_banner(entry)
    if banner:
        at = 1 if notebook.cells and notebook.cells[0] is first_markdown and \
            first_markdown.source.lstrip().startswith("#") else 0
        notebook.cells.insert(at, nbformat.v4.new_markdown_cell(banner))
    for cell in notebook.cells:
        cell.pop("id", None)  # nbformat 4.5 ids are optional; the inserted cell has none to clash with
    notebook.nbformat_minor = min(notebook.nbformat_minor, 4)
    target.write_text(nbformat.writes(notebook), encoding="utf-8")
    return title


# --------------------------------------------------------------------------------------------------
# MathJax
# --------------------------------------------------------------------------------------------------


def _copy_mathjax(source: Path, target: Path) -> None:
    """MathJax with the site's local configuration (the STIX web fonts the copy ships)."""
    copy_mathjax(source, target)
    local = target / "config" / "local"
    local.mkdir(parents=True, exist_ok=True)
    (local / "tpvp.js").write_text(_MATHJAX_LOCAL_CONFIG)


# --------------------------------------------------------------------------------------------------
# plotly.js: one shared copy
# --------------------------------------------------------------------------------------------------

# an inline script whose text starts with plotly.js' license banner (the version in group 2)
_PLOTLY_SCRIPT = re.compile(rb"<script\b([^>]*)>(?=/\*\*\n\* plotly\.js v([0-9][0-9A-Za-z.+-]{0,40})\b)")
_SRC = re.compile(rb"\bsrc\s*=", re.IGNORECASE)


def _plotly_scripts(html: bytes):
    """``(start, end, attributes, version, body)`` of each inline plotly.js ``<script>`` of a page (bytes)."""
    for match in _PLOTLY_SCRIPT.finditer(html):
        if _SRC.search(match.group(1)):
            continue
        close = html.find(b"</script>", match.end())
        if close >= 0:
            yield match.start(), close + len(b"</script>"), match.group(1), match.group(2), html[match.end():close]


def share_plotly(site) -> dict:
    """Ship plotly.js once: the copy inlined in the most pages (the first page's, sorted by path, on a
    tie) goes to ``PLOTLY_DIR/plotly-<version>.js``, and every inline copy byte-identical to it becomes a
    synchronous ``<script src>`` at the same place in its page (so it still runs before the figures'
    ``Plotly.newPlot``); a copy that differs (another version) stays inline. Returns
    ``{"asset": site path or None, "shared": scripts replaced, "inline": scripts left inline}``."""
    site = Path(site)
    pages = sorted((p for p in site.rglob("*.html") if "assets" not in p.relative_to(site).parts),
                   key=lambda p: p.relative_to(site).as_posix())
    copies = {}  # sha256 of a copy -> [pages inlining it, order first seen, version, the copy]
    for page in pages:
        for *_, version, body in _plotly_scripts(page.read_bytes()):
            copies.setdefault(hashlib.sha256(body).hexdigest(), [0, len(copies), version, body])[0] += 1
    if not copies:
        return {"asset": None, "shared": 0, "inline": 0}
    _, _, version, shared = max(copies.values(), key=lambda c: (c[0], -c[1]))
    asset = f"{PLOTLY_DIR}/plotly-{version.decode('ascii')}.js"
    (site / asset).parent.mkdir(parents=True, exist_ok=True)
    (site / asset).write_bytes(shared)
    replaced = inline = 0
    for page in pages:
        html = page.read_bytes()
        parts, at = [], 0
        for start, end, attributes, _, body in _plotly_scripts(html):
            if body != shared:
                inline += 1
                continue
            src = posixpath.relpath(asset, page.parent.relative_to(site).as_posix() or ".")
            parts += [html[at:start], b"<script", attributes, b' src="', src.encode(), b'"></script>']
            at = end
            replaced += 1
        if parts:
            page.write_bytes(b"".join(parts) + html[at:])
    return {"asset": asset, "shared": replaced, "inline": inline}


# --------------------------------------------------------------------------------------------------
# building
# --------------------------------------------------------------------------------------------------


def assemble_sources(notebooks_folder, source: Path, *, docs=DOCS, readme=README, allow_missing: bool = False,
                     mathjax: Path | None | bool = True) -> dict:
    """Write the MkDocs source folder ``source/docs`` and its ``source/mkdocs.yml``. Returns what
    went in: ``{"config": path, "notebooks": [(stem, mode)], "pages": [...], "mathjax": path|None}``."""
    import yaml

    docs, readme = Path(docs), Path(readme)
    docs_dir = source / "docs"
    docs_dir.mkdir(parents=True)
    notebooks = executed_notebooks(notebooks_folder, allow_missing)

    pages = {"README.md": "index.md"}
    doc_pages = sorted(p for p in docs.glob("*.md")) if docs.is_dir() else []
    for page in doc_pages:
        pages[f"docs/{page.name}"] = page.name if page.name != "index.md" else "reference.md"
    if docs.is_dir():  # pictures and other files the docs pages link to, at the same relative places
        for item in docs.rglob("*"):
            relative = item.relative_to(docs).as_posix()
            if item.is_file() and item.suffix != ".md" and not relative.startswith("."):
                pages[f"docs/{relative}"] = relative
                (docs_dir / relative).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(item, docs_dir / relative)
    for executed, _ in notebooks:
        pages[f"notebooks/{executed.name}"] = executed.name
    links = SiteLinks(pages)

    (docs_dir / "index.md").write_text(links.rewrite(readme.read_text(encoding="utf-8"), ""), encoding="utf-8")
    reference = []
    for page in doc_pages:
        name = pages[f"docs/{page.name}"]
        text = page.read_text(encoding="utf-8")
        (docs_dir / name).write_text(links.rewrite(text, "docs"), encoding="utf-8")
        reference.append({_first_heading(text) or page.stem.replace("_", " "): name})
    tutorials, modes = [], []
    for executed, entry in notebooks:
        title = _notebook_page(executed, entry, links, docs_dir / executed.name)
        tutorials.append({title: executed.name})
        modes.append((executed.stem, entry.get("mode", "unknown")))

    config = yaml.safe_load(CONFIG.read_text())
    config["docs_dir"] = "docs"
    config["site_dir"] = "site"
    nav = [{"Home": "index.md"}, {"Tutorials": tutorials}]
    if reference:
        nav.append({"Reference": reference})
    config["nav"] = nav
    mathjax = mathjax_folder() if mathjax is True else (mathjax or None)
    mathjax_url = None
    if mathjax is not None:
        _copy_mathjax(Path(mathjax), docs_dir / MATHJAX_DIR)
        mathjax_url = f"{MATHJAX_DIR}/MathJax.js?config={MATHJAX_CONFIG}"  # every page is at the top level
    for plugin in config.get("plugins", []):
        if isinstance(plugin, dict) and "mkdocs-jupyter" in plugin:
            # empty: a script without a source, nothing fetched; math stays as TeX text
            plugin["mkdocs-jupyter"]["custom_mathjax_url"] = mathjax_url or ""
    config_path = source / "mkdocs.yml"
    config_path.write_text(yaml.safe_dump(config, sort_keys=False, allow_unicode=True))
    return {"config": config_path, "notebooks": modes, "pages": [next(iter(p.values())) for p in reference],
            "mathjax": mathjax}


def _mkdocs_build(config: Path, site_dir: Path, strict: bool) -> None:
    command = [sys.executable, "-m", "mkdocs", "build", "--config-file", str(config), "--site-dir", str(site_dir),
               "--quiet"] + (["--strict"] if strict else [])
    env = dict(os.environ, PYTHONWARNINGS="ignore", DISABLE_MKDOCS_2_WARNING="true", NO_MKDOCS_2_WARNING="1")
    result = subprocess.run(command, capture_output=True, text=True, cwd=config.parent, env=env)
    if result.returncode:
        lines = [line for line in (result.stderr + result.stdout).splitlines()
                 if line.startswith(("WARNING", "ERROR")) or "Aborted" in line or "Error" in line]
        shown = "; ".join(lines[:5]) or (result.stderr.strip().splitlines() or ["no output"])[-1]
        raise ConfigError(f"mkdocs build failed ({'strict mode: warnings are errors; ' if strict else ''}{shown})")


def build_site(notebooks_folder, destination, *, docs=DOCS, readme=README, allow_missing: bool = False,
               strict: bool = True, mathjax: Path | None | bool = True, progress: bool = True) -> dict:
    """Build the site from the executed notebooks in ``notebooks_folder`` (see the module docstring)
    and publish it to ``destination`` whole. ``allow_missing``: build from the notebooks that are
    there (at least one) instead of failing. ``mathjax``: True finds a local copy
    (:func:`tools.notebooks.mathjax_folder`), a folder uses that one, None leaves math as text. Returns a summary:
    seconds, notebooks with their modes, reference pages, mathjax folder, destination."""
    start = time.perf_counter()
    notebooks_folder = Path(notebooks_folder).absolute()
    destination = Path(destination).absolute()
    with tempfile.TemporaryDirectory(prefix="tpvp-site-") as temp:
        summary = assemble_sources(notebooks_folder, Path(temp), docs=docs, readme=readme,
                                   allow_missing=allow_missing, mathjax=mathjax)
        with staged_folder(destination, inputs=(notebooks_folder,), what="site folder") as stage:
            _mkdocs_build(summary["config"], stage.folder, strict)
            summary["plotly"] = share_plotly(stage.folder)
    summary.update(seconds=time.perf_counter() - start, destination=destination)
    summary.pop("config")
    if progress:
        reader = [stem for stem, mode in summary["notebooks"] if mode != "full"]
        print(f"site: {len(summary['notebooks'])} notebooks ({len(reader)} in reader's mode), "
              f"{len(summary['pages'])} reference pages, MathJax "
              f"{'from ' + str(summary['mathjax']) if summary['mathjax'] else 'not installed: math shown as TeX'}; "
              f"built in {summary['seconds']:.1f} s -> {destination / 'index.html'}", flush=True)
    return summary


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--notebooks", default=None,
                        help="the executed notebooks (default: outputs/notebooks, as make notebooks writes)")
    parser.add_argument("--output", default=str(ROOT / "outputs" / "site"), help="publish the site here")
    parser.add_argument("--allow-missing", action="store_true",
                        help="build from the executed notebooks that are there instead of failing")
    parser.add_argument("--no-strict", action="store_true", help="let mkdocs warnings (broken links) pass")
    args = parser.parse_args(argv)

    args.func = lambda a: build_site(a.notebooks or published_results(), a.output, allow_missing=a.allow_missing,
                                     strict=not a.no_strict) and 0
    return run_command(args, "site")


if __name__ == "__main__":
    sys.exit(main())
