"""The rendered study: a static site of the executed notebooks, built without re-executing them.

``python -m greenloop book [--out build/book] RESULTS...`` (``make book``) writes one folder of
plain HTML that opens from disk or any static host:

* ``index.html``: the landing page: the verdict table (``results/verdict.md``), the headline figure,
  and for each results folder (dataset) the list of its executed notebooks;
* ``<dataset>/<NN_name>.html``: each executed notebook as nbconvert's HTML exporter renders the
  executed ``.ipynb`` (no cell runs; the results folders hold no rendered pages), with a navigation bar on top: the landing page, the previous and next notebook of the same
  dataset, and the same notebook on the other datasets;
* the generated pages (``verdict``, ``summary``, ``coverage``, ``PROVENANCE``, ``datasets``) as HTML,
  every relative link of theirs rewritten to the page or file it names, copied beside it.

The HTML is nbconvert's and mistune's (both pinned dependencies of the notebooks' toolchain); figures
are inside the notebooks' HTML (base64 images) or copied files, so the site has no network access.
"""
from __future__ import annotations

import html
import re
import shutil
from pathlib import Path

import mistune

from greenloop.study import provenance
from greenloop.util.files import write_atomic

PAGES = ("verdict", "summary", "coverage", "PROVENANCE", "datasets")     # generated pages at results/
STYLE = ("<style>nav.gl{font:14px sans-serif;background:#f3f5f7;border-bottom:1px solid #ccd;padding:6px 12px;"
         "position:sticky;top:0;z-index:10}nav.gl a{margin-right:14px}body.gl-page{font:15px/1.45 sans-serif;"
         "max-width:1100px;margin:0 auto;padding:0 16px 40px}table{border-collapse:collapse;font-size:13px}"
         "td,th{border:1px solid #ccd;padding:3px 6px;vertical-align:top}img{max-width:100%}</style>")
_MD = mistune.create_markdown(plugins=["table"], escape=False)
_LINK = re.compile(r'(href|src)="([^"#:]+?)(#[^"]*)?"')


def notebooks(folder: Path) -> list[str]:
    """The stems of a results folder's executed notebooks (``NN_name.ipynb``), in order."""
    return sorted(p.stem for p in Path(folder).glob("[0-9][0-9]_*.ipynb"))


def dataset_key(folder: Path) -> str:
    """The book's folder for a results folder: its dataset's name (else the folder's name)."""
    return provenance.dataset_name(folder) or Path(folder).name


def notebook_html(folder: Path, stem: str) -> str:
    """The rendered HTML of an executed notebook: nbconvert's export of ``folder/stem.ipynb`` (nothing
    executed; a stale ``.html`` left beside it is not read)."""
    import nbconvert        # here, not at the top: its import would slow the start of every command-line call
    body, _ = nbconvert.HTMLExporter().from_filename(str(Path(folder) / f"{stem}.ipynb"))
    return body


def nav(home: str, links: list[tuple[str, str]]) -> str:
    """A navigation bar: the landing page (relative URL ``home``), then each (label, relative URL)."""
    items = [f'<a href="{home}">greenloop: the study</a>'] + [
        f'<a href="{html.escape(url)}">{html.escape(label)}</a>' for label, url in links]
    return f'<nav class="gl">{"".join(items)}</nav>'


def with_nav(page: str, bar: str) -> str:
    """``page`` (an HTML document) with ``bar`` and the book's style right after its ``<body>`` tag."""
    m = re.search(r"<body[^>]*>", page)
    if m is None:
        return f"<html><head>{STYLE}</head><body>{bar}{page}</body></html>"
    return page[:m.end()] + STYLE + bar + page[m.end():]


def markdown_page(md: Path, out: Path, book: Path, title: str, depth: int = 2) -> Path:
    """Render the Markdown file ``md`` to ``out`` (under ``book``): every relative link or image it
    names is copied beside ``out`` at the same relative path (a ``.md`` rendered as ``.html`` the same
    way, up to ``depth`` links away), so that the page's links resolve inside the book."""
    body = _MD(md.read_text())

    def fix(m: re.Match) -> str:
        attr, target, frag = m.group(1), m.group(2), m.group(3) or ""
        src = (md.parent / target).resolve()
        if not src.is_file():
            return m.group(0)
        dest = (out.parent / target).resolve()
        if not dest.is_relative_to(book.resolve()):          # a link out of the results: leave it as written
            return m.group(0)
        if src.suffix == ".md" and depth > 1:
            if not dest.with_suffix(".html").exists():
                markdown_page(src, dest.with_suffix(".html"), book, src.stem, depth - 1)
            return f'{attr}="{Path(target).with_suffix(".html").as_posix()}{frag}"'
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dest)
        return m.group(0)
    return write_atomic(out, _document(title, _LINK.sub(fix, body), _home(out, book)))


def _home(page: Path, book: Path) -> str:
    """The relative URL of ``book/index.html`` from ``page``."""
    depth = len(page.resolve().relative_to(book.resolve()).parts) - 1
    return "../" * depth + "index.html"


def _document(title: str, body: str, home: str) -> str:
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>{STYLE}</head>"
            f"<body class='gl-page'>{nav(home, [])}{body}</body></html>")


def notebook_pages(folders: list[Path], book: Path) -> dict[str, list[str]]:
    """Write every executed notebook of every folder under ``book/<dataset>/`` with its navigation
    bar. Returns {dataset: [stems]}."""
    keys = {dataset_key(f): f for f in folders}
    done = {}
    for key, folder in keys.items():
        stems = notebooks(folder)
        for i, stem in enumerate(stems):
            links = [("previous: " + stems[i - 1], f"{stems[i - 1]}.html")] if i else []
            links += [("next: " + stems[i + 1], f"{stems[i + 1]}.html")] if i + 1 < len(stems) else []
            links += [(f"on {k}", f"../{k}/{stem}.html") for k, f in keys.items()
                      if k != key and (f / f"{stem}.ipynb").is_file()]
            write_atomic(book / key / f"{stem}.html", with_nav(notebook_html(folder, stem), nav("../index.html", links)))
        done[key] = stems
    return done


def landing(results: Path, book: Path, done: dict[str, list[str]]) -> Path:
    """``book/index.html``: the verdict table, the headline figure, the generated pages and every
    notebook of every dataset."""
    parts = ["<h1>greenloop: does each paper's claim hold here?</h1>"]
    verdict = results / "verdict.md"
    if verdict.is_file():
        parts.append(_MD(verdict.read_text().split("\n", 1)[1]))    # its own title replaced by the page's
    figure = results / "nordland" / "13_leaderboard" / "r1_bars.png"
    if figure.is_file():
        shutil.copyfile(figure, book / "r1_bars.png")
        parts.append('<p><img src="r1_bars.png" alt="Recall@1 of every method on Nordland"></p>')
    pages = [p for p in PAGES if (results / f"{p}.md").is_file()]
    for p in pages:
        markdown_page(results / f"{p}.md", book / f"{p}.html", book, p)
    parts.append("<h2>Generated pages</h2><ul>" + "".join(f'<li><a href="{p}.html">{p}</a></li>' for p in pages)
                 + "</ul>")
    for key, stems in done.items():
        parts.append(f"<h2>Notebooks on {html.escape(key)}</h2><ol start='0'>"
                     + "".join(f'<li><a href="{key}/{s}.html">{s}</a></li>' for s in stems) + "</ol>")
    return write_atomic(book / "index.html", _document("greenloop", "".join(parts), "index.html"))


def build(results_dirs, out) -> Path:
    """The whole book of ``results_dirs`` (the first is the top results folder, holding the generated
    pages) in a fresh folder ``out``. Returns the landing page's path."""
    folders, book = [Path(d) for d in results_dirs], Path(out)
    if book.exists():
        shutil.rmtree(book)
    book.mkdir(parents=True)
    done = notebook_pages(folders, book)
    return landing(folders[0], book, done)
