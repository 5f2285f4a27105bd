"""The rendered study (greenloop.study.book): built from executed notebooks without running them, every
page reachable from the landing page, and, in a real headless Chromium, every link resolves and every
figure loads."""
import json
import shutil
from pathlib import Path
from urllib.parse import unquote, urlparse

import nbformat
import pytest

from greenloop.study import book

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM, DRIVER = shutil.which("chromium"), shutil.which("chromedriver")
PNG = ("iVBORw0KGgoAAAANSUhEUgAAAAIAAAACCAIAAAD91JpzAAAAFklEQVR4nGP8z8DAwMDAxMDAwMDAAAANHQEDasKb6QAAAABJRU5ErkJggg==")


def executed(folder: Path, stem: str, dataset: str, stale: bool = False) -> None:
    """A small executed notebook (a title, a figure output) with the manifest its folder's notebooks
    write; ``stale``: also an old rendered page beside it, which the book must not read (results
    folders hold no rendered pages: the book renders the .ipynb)."""
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell(f"# {stem} on {dataset}"),
                                         nbformat.v4.new_code_cell("fig", outputs=[nbformat.v4.new_output(
                                             "display_data", data={"image/png": PNG, "text/plain": "<Figure>"})])])
    folder.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, folder / f"{stem}.ipynb")
    (folder / stem).mkdir(exist_ok=True)
    (folder / stem / "manifest.json").write_text(json.dumps({"dataset": f"data/{dataset}"}))
    if stale:
        (folder / f"{stem}.html").write_text("<html><body><h1>a stale page</h1></body></html>")


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A book of two datasets (two notebooks on the first, one on the second, one with a stale page
    beside it) and the generated pages, one linking a file in a subfolder and another page."""
    results = tmp_path_factory.mktemp("results")
    executed(results, "00_dataset", "synthetic-greenhouse", stale=True)
    executed(results, "13_leaderboard", "synthetic-greenhouse")
    executed(results / "nordland", "00_dataset", "nordland")
    (results / "verdict.md").write_text("# Verdict\n\n| claim | synthetic |\n| --- | --- |\n| 920 frames/s | **holds** |\n")
    (results / "bench").mkdir()
    (results / "bench" / "scale.md").write_text("# Scale\n\n![plot](scale.png)\n")
    (results / "bench" / "scale.png").write_bytes(__import__("base64").b64decode(PNG))
    (results / "summary.md").write_text("# Summary\n\nSee [the scale benchmark](bench/scale.md).\n")
    return book.build([results, results / "nordland"], tmp_path_factory.mktemp("book") / "book")


def test_every_notebook_of_every_dataset_has_a_page_with_its_navigation(site):
    out = site.parent
    pages = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.html"))
    assert pages == ["bench/scale.html", "index.html", "nordland/00_dataset.html", "summary.html",
                     "synthetic-greenhouse/00_dataset.html", "synthetic-greenhouse/13_leaderboard.html", "verdict.html"]
    first = (out / "synthetic-greenhouse" / "00_dataset.html").read_text()
    assert 'href="13_leaderboard.html"' in first and 'href="../nordland/00_dataset.html"' in first
    assert "previous:" not in first and 'href="../index.html"' in first
    assert "00_dataset on synthetic-greenhouse" in first and "a stale page" not in first   # the .ipynb, rendered
    assert "13_leaderboard on synthetic-greenhouse" in (out / "synthetic-greenhouse" / "13_leaderboard.html").read_text()
    landing = site.read_text()
    assert "<table>" in landing and "holds" in landing                 # the verdict table is the landing page
    assert 'href="bench/scale.html"' in (out / "summary.html").read_text()      # a .md link follows its page


def _links_and_images(driver):
    hrefs = [a.get_attribute("href") for a in driver.find_elements("css selector", "a[href]")]
    broken = [img.get_attribute("src")[:60] for img in driver.find_elements("css selector", "img")
              if not driver.execute_script("return arguments[0].complete && arguments[0].naturalWidth > 0", img)]
    return hrefs, broken


@pytest.mark.skipif(not (CHROMIUM and DRIVER), reason="no chromium/chromedriver: `make test` installs Debian's")
def test_in_a_headless_browser_every_link_resolves_and_every_figure_loads(site):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-dev-shm-usage"):
        opts.add_argument(flag)
    driver = webdriver.Chrome(service=Service(DRIVER), options=opts)
    try:
        seen, todo, checked = set(), [site.resolve().as_uri()], 0
        while todo:
            url = todo.pop()
            if url in seen:
                continue
            seen.add(url)
            driver.get(url)
            hrefs, broken = _links_and_images(driver)
            assert not broken, f"{url}: figures that did not load: {broken}"
            for h in hrefs:
                target = Path(unquote(urlparse(h).path))
                if urlparse(h).scheme == "file":
                    assert target.is_file(), f"{url} links to a missing {target}"
                    if target.suffix == ".html":
                        todo.append(target.as_uri())
            checked += 1
        assert checked == 7                                   # every page reached from the landing page
    finally:
        driver.quit()
