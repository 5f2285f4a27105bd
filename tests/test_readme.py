"""The findings (docs/findings.md) hold only numbers that a committed table under results/ holds, and
neither they nor the README claim an order ("ahead", "best", "higher", ...) that no comparison backs."""
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
NUMBER = re.compile(r"(?<![\w.])\d+(?:\.\d+)?")


FINDINGS = ROOT / "docs" / "findings.md"
# a word that claims an order between methods, arms or settings
COMPARISON = re.compile(r"\b(ahead|best|highest|lowest|higher than|lower than|outperform\w*|beats?|better|worse|"
                        r"superior|first|wins?)\b", re.I)
# what may follow "best"/"first" without claiming an order: a definition, not a finding
NOT_AN_ORDER = re.compile(r"\b(best match\w*|best[- ]layer|best of the study's descriptors|first[- ]traversal|"
                          r"first \w+ frames|first walk|first half|first seed|first epoch|first revisit|first "
                          r"screen|first import|at first|first,|first \d)", re.I)
# what backs an order: a table of paired comparisons or verdicts it names, or the words saying it is not one
BACKED = re.compile(r"comparisons\.(md|csv)|verdict\.(md|csv)|not resolved|not a ranking|no order|"
                    r"is not ranked|do not separate|overlap", re.I)


def section(text: str, title: str = "## Findings") -> str:
    """The raw body of one '## ' section of a Markdown text."""
    if title not in text:
        raise ValueError(f"no section {title!r}")
    return re.split(r"^## ", text.split(title, 1)[1], maxsplit=1, flags=re.M)[0]


def paragraphs(body: str) -> list[tuple[list[str], str]]:
    """The findings of a section: one per paragraph or bullet, as (the code spans it names, its
    text without code spans and link targets: file names are not results)."""
    out = []
    for block in re.split(r"\n\s*\n|\n(?=\* )|\n(?=\| )", body):
        names = re.findall(r"`([^`]*)`", block)
        text = re.sub(r"\]\([^)]*\)", "]", re.sub(r"`[^`]*`", " ", block))
        if text.strip():
            out.append((names, text))
    return out


def tables_named(names, tables) -> list[Path]:
    """The tables a finding names (a code span that is part of a table's path under the repo:
    `13_leaderboard`, `01_spot_grouping/table1.md`, `results/nordland/`); every table if it
    names none."""
    keys = [n.strip("/").removesuffix(".md").removesuffix(".csv") for n in names]
    rel = {p: p.relative_to(ROOT).as_posix() for p in tables}
    hit = [p for p in tables if any(k and k in rel[p] for k in keys)]
    return hit or list(tables)


def numbers(text: str) -> list[tuple[str, float, int]]:
    """Every number in a text as (as written, value, decimals shown)."""
    return [(m, float(m), len(m.split(".")[1]) if "." in m else 0) for m in NUMBER.findall(text)]


def table_values(paths) -> np.ndarray:
    """Every number in the given csv/md files, sorted (float64)."""
    vals = [float(m) for p in paths for m in NUMBER.findall(Path(p).read_text(errors="replace"))]
    return np.unique(np.asarray(vals, dtype=np.float64))


def unmatched(found, values: np.ndarray) -> list[str]:
    """The written numbers that no table value gives when rounded to the shown decimals (the
    value itself, or a fraction x 100 for a number the README writes in %)."""
    out = []
    for text, x, d in found:
        tol = 0.5 * 10.0 ** -d + 1e-9
        hit = False
        for target in (x, x / 100):
            t = tol if target == x else tol / 100
            i = np.searchsorted(values, target - t)
            hit |= bool(i < len(values) and values[i] <= target + t)
        if not hit:
            out.append(text)
    return out


def committed_tables() -> list[Path]:
    try:
        listed = subprocess.run(["git", "ls-files", "results"], cwd=ROOT, capture_output=True, text=True,
                                check=True).stdout.split()
        files = [ROOT / p for p in listed]
    except (OSError, subprocess.CalledProcessError):     # not a git checkout: every table on disk
        files = list((ROOT / "results").rglob("*"))
    return [p for p in files if p.suffix in (".csv", ".md") and p.is_file()]


def missing_numbers(text: str, tables) -> list[str]:
    """Every number of the README's results section that no table its finding names holds."""
    out = []
    for names, body in paragraphs(section(text)):
        out += unmatched(numbers(body), table_values(tables_named(names, tables)))
    return out


def test_the_matcher_fails_a_number_no_table_holds(tmp_path, monkeypatch):
    (tmp_path / "results" / "a").mkdir(parents=True)
    (tmp_path / "results" / "b").mkdir(parents=True)
    (tmp_path / "results" / "a" / "t.csv").write_text("method,AP_%\nx,44.63\ny,0.872\n")
    (tmp_path / "results" / "b" / "u.md").write_text("| q | 12 |\n| r | 7.5 |\n")
    monkeypatch.setattr(__import__(__name__), "ROOT", tmp_path)
    tables = sorted((tmp_path / "results").rglob("*.*"))
    vals = table_values(tables[:1])
    found = numbers("AP 44.6 %, R@1 87.2 %, AP 44.7 %, 12 closures")
    assert [f[0] for f in found] == ["44.6", "1", "87.2", "44.7", "12"]      # R@1's "1" is a number too
    assert unmatched(found, vals) == ["44.7", "12"]                          # 0.872 shown as 1 or 87.2: held
    readme = ("## Findings\n\nAP 44.6 % (`a/t.csv`, [x](docs/b1.md)).\n\n"
              "* 7.5 and 44.6 in `b/u.md`\n* 12 in any table\n## Next\n9.9\n")
    assert missing_numbers(readme, tables) == ["44.6"]           # b/u.md holds 7.5, not 44.6; 9.9 is outside
    assert [n for n, _ in paragraphs(section(readme))] == [["a/t.csv"], ["b/u.md"], []]


def test_every_number_of_the_findings_is_in_a_committed_table():
    missing = missing_numbers(FINDINGS.read_text(), committed_tables())
    assert not missing, f"numbers in docs/findings.md found in no table its finding names: {missing}"


def unbacked_orders(text: str) -> list[str]:
    """Each paragraph of a Markdown text (generated blocks left out) that claims an order no comparison
    backs: it holds a :data:`COMPARISON` word, outside :data:`NOT_AN_ORDER`, and nothing :data:`BACKED`."""
    text = re.sub(r"<!-- (\w+):start -->.*?<!-- \1:end -->", "", text, flags=re.S)
    out = []
    for names, body in paragraphs(text):
        claims = COMPARISON.findall(NOT_AN_ORDER.sub(" ", body))
        if claims and not BACKED.search(body + " ".join(names)):
            out.append(" ".join(body.split())[:160])
    return out


def test_the_order_check_fails_an_unbacked_comparison():
    assert unbacked_orders("* A is ahead of B (`x/leaderboard.csv`).\n") != []
    assert unbacked_orders("* A is ahead of B (`x/comparisons.md`: +3 [1, 5]).\n") == []
    assert unbacked_orders("* A and B: the order is not resolved.\n* the best match of each query.\n") == []
    assert unbacked_orders("<!-- verdict:start -->\nbest\n<!-- verdict:end -->\n") == []


@pytest.mark.parametrize("name", ["README.md", "docs/findings.md"])
def test_no_order_is_claimed_without_a_comparison_behind_it(name):
    unbacked = unbacked_orders((ROOT / name).read_text())
    assert not unbacked, f"{name}: orders claimed with no comparisons/verdict table named: {unbacked}"


def test_the_readme_is_a_front_page():
    """At most 150 lines, the verdict table and the two commands on it; findings live in docs/findings.md."""
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 150, f"README.md has {len(text.splitlines())} lines (a front page: at most 150)"
    assert "<!-- verdict:start -->" in text and "make all" in text and "make test" in text
