"""The committed results folders are each one run: one CPU and the pinned package set in every
notebook's manifest, and no copy of a table that differs from its source."""
import json
import re
import subprocess
from pathlib import Path

import pytest

from greenloop.study import report

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = [ROOT / "results", ROOT / "results" / "nordland", ROOT / "results" / "gardenspoint"]
NOTEBOOKS = sorted(p.stem for p in (ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))


def pins(path=ROOT / "environment.txt") -> dict:
    """environment.txt's `name==version` lines as {name: version}."""
    out = {}
    for line in path.read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9_.-]+)==([^\s#]+)", line.strip())
        if m:
            out[m.group(1).lower()] = m.group(2)
    return out


def manifests(folder: Path) -> dict:
    """{notebook stem: its manifest} of one results folder."""
    return {s: json.loads((folder / s / "manifest.json").read_text())
            for s in NOTEBOOKS if (folder / s / "manifest.json").is_file()}


def mixed(mans: dict) -> list[str]:
    """What differs between the manifests of one folder: the CPU, or any library version."""
    fields = [{"cpu": m.get("cpu"), **m.get("versions", {})} for m in mans.values()]
    names = sorted({k for f in fields for k in f}, key=lambda k: (k != "cpu", k))
    seen = {k: {f.get(k) for f in fields} for k in names}
    return [f"{k}: {sorted(map(str, v))}" for k, v in seen.items() if len(v) > 1]


def unpinned(mans: dict, pinned: dict) -> list[str]:
    """Versions a manifest records that differ from environment.txt's pin of the same package."""
    return sorted({f"{s}: {name} {v} (pinned {pinned[name]})" for s, m in mans.items()
                   for name, v in m.get("versions", {}).items()
                   if name.lower() in pinned and v != pinned[name.lower()]})


def test_mixed_and_unpinned_name_what_differs():
    a = {"cpu": "A (2 cores)", "versions": {"numpy": "2.4.6", "pandas": "3.1.1"}}
    b = {"cpu": "B (2 cores)", "versions": {"numpy": "2.4.6", "pandas": "3.0.0"}}
    assert mixed({"00": a, "01": dict(a)}) == []
    assert mixed({"00": a, "01": b}) == ["cpu: ['A (2 cores)', 'B (2 cores)']", "pandas: ['3.0.0', '3.1.1']"]
    assert unpinned({"01": b}, {"numpy": "2.4.6", "pandas": "3.1.1"}) == ["01: pandas 3.0.0 (pinned 3.1.1)"]
    assert "numpy" in pins() and "tensorflow" in pins()


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_each_results_folder_is_one_run_on_the_pinned_packages(folder):
    mans = manifests(folder)
    assert set(mans) == set(NOTEBOOKS), f"notebooks without a manifest: {sorted(set(NOTEBOOKS) - set(mans))}"
    assert not mixed(mans), f"{folder.name}: notebooks ran on different machines or packages: {mixed(mans)}"
    assert not unpinned(mans, pins()), unpinned(mans, pins())


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_copy_differs_from_its_source(folder, tmp_path):
    copy, source = folder / "leaderboard.csv", folder / "13_leaderboard" / "leaderboard.csv"
    assert copy.read_bytes() == source.read_bytes()
    # tables.md is what make assembles from the folder's tables now
    out = report.assemble_tables(folder, tmp_path / "tables.md")
    assert out.read_text() == (folder / "tables.md").read_text(), f"{folder}/tables.md is stale: make all RESULTS={folder}"


def rests_on(board) -> int:
    """The evaluation revisit queries of a leaderboard's loop-closure rows: its revisit_queries column,
    or, in a table written before that column existed, the evaluation part's revisit frames its
    scored_on names (loop closure, the same count: the ground truth already leaves out the band)."""
    lc = board[board["mode"] == "loop closure"].iloc[0]
    if "revisit_queries" in board.columns:
        return int(lc["revisit_queries"])
    return int(re.search(r"evaluation queries: frames \d+\.\.\d+ \((\d+) revisit frames\)", lc["scored_on"]).group(1))


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_the_step_rule_keeps_each_committed_leaderboards_frame_step(folder):
    """Notebook 13 keeps frame_step only where it leaves MIN_REVISIT_QUERIES evaluation revisit
    queries (experiments.leaderboard.choose_step): each committed run's step (synthetic 4, Nordland
    8, Gardens Point 1) leaves them, or is 1 already, so a rerun describes the same frames."""
    import pandas as pd

    from greenloop.experiments.leaderboard import MIN_REVISIT_QUERIES
    board = pd.read_csv(folder / "13_leaderboard" / "leaderboard.csv")
    params = json.loads((folder / "13_leaderboard" / "manifest.json").read_text())["parameters"]
    assert params["frame_step"] == 1 or rests_on(board) >= MIN_REVISIT_QUERIES, (params["frame_step"], rests_on(board))
    assert params.get("frame_step_requested", params["frame_step"]) == params["frame_step"]


# a path on the machine that ran a notebook (its checkout, home, scratch): it says nothing to a reader
# and names the machine; a warning's "file:line:" prefix is the usual way one gets into an output
ABSOLUTE = re.compile(r"(?<![\w.:/~-])/(?:work|home|root|tmp|Users|mnt|srv|scratch)/[^\s\"']*")


def absolute_paths(text: str) -> list[str]:
    """The absolute machine paths in a notebook's JSON text (:data:`ABSOLUTE`)."""
    return ABSOLUTE.findall(text)


def test_the_path_check_finds_a_warning_s_absolute_path():
    warned = '"text": ["/work/main/greenloop/features/descriptor.py:145: UserWarning: no keypoints\\n"]'
    assert absolute_paths(warned) == ["/work/main/greenloop/features/descriptor.py:145:"]
    assert absolute_paths('"dataset = \\"data/nordland\\"", "https://x.org/home/a", "results/tmp/x"') == []


def test_no_committed_notebook_holds_an_absolute_path():
    """Executed notebooks carry their outputs into the repository: none may name the machine's paths."""
    try:
        listed = subprocess.run(["git", "ls-files", "*.ipynb"], cwd=ROOT, capture_output=True, text=True,
                                check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):      # not a git checkout: every notebook on disk
        listed = [p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*.ipynb") if ".venv" not in p.parts]
    found = {p: absolute_paths((ROOT / p).read_text()) for p in listed if (ROOT / p).is_file()}
    found = {p: hits[:2] for p, hits in found.items() if hits}
    assert not found, f"absolute paths in committed notebooks (strip the outputs that print them): {found}"
