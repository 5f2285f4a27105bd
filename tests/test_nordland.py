"""The Nordland builder on tiny fake copies of the source layout (and the real sample file)."""
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from greenloop import groundtruth
from greenloop.datasets import nordland, sequence
from greenloop.cli import main as cli_main
from conftest import HANG_S

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "real" / "nordland"
NAMES = [10, 20, 30, 90, 100, 110, 1000]        # images-00010.png ...: the source's naming


def _fake_source(root: Path, names=NAMES, size=(16, 8)) -> Path:
    """summer/ and winter/ with one frame per name; a frame's pixels encode (season, name)."""
    for s, season in enumerate(nordland.SEASONS):
        (root / season).mkdir(parents=True)
        for v in reversed(names):                    # written out of order on purpose
            img = np.zeros((size[1], size[0], 3), np.uint8)
            img[..., 0], img[..., 1], img[..., 2] = s, v % 256, v // 256
            cv2.imwrite(str(root / season / f"images-{v:05d}.png"), img)
    return root


def _code(path: Path) -> tuple[int, int]:
    img = cv2.imread(str(path))
    return int(img[0, 0, 0]), int(img[0, 0, 1]) + 256 * int(img[0, 0, 2])


def test_build_order_ground_truth_and_metadata(tmp_path):
    src = _fake_source(tmp_path / "src")
    out = nordland.build(tmp_path / "nordland", src, tolerance=2, progress=False)
    n = len(NAMES)
    frames = sequence.list_frames(out)
    assert [p.name for p in frames] == [f"{k}.png" for k in range(2 * n)]
    # summer in numeric order of the names, then winter: winter frame k is frame n + k
    assert [_code(p) for p in frames] == [(0, v) for v in NAMES] + [(1, v) for v in NAMES]
    # (k, n + k, 2), the first two windows clipped at the start of winter: [n, n + 2], [n, n + 3]
    assert sequence.read_loop_pairs(out, n_frames=2 * n).tolist() == (
        [[0, n + 1, 1], [1, n + 1, 1], [1, n + 3, 0]] + [[k, n + k, 2] for k in range(2, n)])
    meta = json.loads((out / "nordland.json").read_text())
    assert meta["frames_per_season"] == n and meta["n_frames"] == 2 * n
    assert meta["traversals"] == {"summer": [0, n], "winter": [n, 2 * n]}
    assert meta["ground_truth"]["tolerance_frames"] == 2 and (meta["width"], meta["height"]) == (16, 8)
    info = sequence.folder_info(out)
    assert info["ground_truth"] == "pairs" and info["n_frames"] == 2 * n and not info["depth"]
    gt = groundtruth.for_sequence(out, exclude=1)
    assert gt[0, n] and gt[0, n + 2] and not gt[0, n + 3] and gt[n + 1, 0]
    assert not gt[:n, :n].any() and not gt[n:, n:].any()        # loops only across the seasons
    k = np.arange(n)[:, None]
    assert (gt[:n, n:] == (np.abs(np.arange(n)[None, :] - k) <= 2)).all()
    assert not list(tmp_path.glob(".nordland.tmp*")), "temporary folder left behind"
    # sequence.yaml says only the targets' protocol: no traversals, exclude or frame_step of its own
    seq = sequence.open(out)
    assert {k for k, v in seq.description.items() if v is not None} == {"protocol"}
    assert seq.traversals == [sequence.Traversal("all", 0, 2 * n)]
    (stream,) = seq.protocol.streams
    assert seq.protocol.targets == "nordland" and stream.name == "every frame, +- 2 frames"
    assert stream.traversals == (sequence.Traversal("summer", 0, n), sequence.Traversal("winter", n, 2 * n))
    assert stream.tolerance == nordland.TARGET_TOLERANCE == 2
    # --describe writes the same file into a folder built before it existed, frames untouched
    text = (out / "sequence.yaml").read_text()
    (out / "sequence.yaml").unlink()
    assert sequence.open(out).protocol.targets == "generic"
    assert cli_main(["data", "nordland", str(out), "--describe"]) == 0 and (out / "sequence.yaml").read_text() == text
    assert sequence.open(out).protocol.streams == (stream,)


def test_build_from_a_repository_clone_layout(tmp_path):
    _fake_source(tmp_path / "seqslam" / nordland.SOURCE_SUBDIR, names=[10, 20])
    out = nordland.build(tmp_path / "out", tmp_path / "seqslam", progress=False)
    gt = groundtruth.for_sequence(out, exclude=0)
    assert gt[0, 2] and gt[0, 3] and gt[1, 2] and gt[1, 3] and not gt[0, 1] and not gt[2, 3]


def test_bad_sources_fail_clearly_and_leave_nothing(tmp_path):
    with pytest.raises(FileNotFoundError, match="NORDLAND_SRC=path"):
        nordland.build(tmp_path / "out", tmp_path / "missing", progress=False)
    src = _fake_source(tmp_path / "src")
    (src / "winter" / "images-00090.png").unlink()
    with pytest.raises(ValueError, match=r"only in summer/: \['images-00090.png'\]"):
        nordland.build(tmp_path / "out", src, progress=False)
    src2 = _fake_source(tmp_path / "src2")
    cv2.imwrite(str(src2 / "winter" / "images-00020.png"), np.zeros((9, 16, 3), np.uint8))
    with pytest.raises(ValueError, match=r"images-00020.png is 16x9 while .* is 16x8"):
        nordland.build(tmp_path / "out", src2, progress=False)
    with pytest.raises(ValueError, match="tolerance"):
        nordland.build(tmp_path / "out", _fake_source(tmp_path / "src3"), tolerance=-1)
    assert not (tmp_path / "out").exists() and not list(tmp_path.glob(".out*"))
    nordland.build(tmp_path / "out", tmp_path / "src3", progress=False)
    with pytest.raises(FileExistsError, match="overwrite"):
        nordland.build(tmp_path / "out", tmp_path / "src3", progress=False)


@pytest.mark.skipif(nordland.shutil.which("git") is None, reason="git is not installed")
def test_offline_clone_fails_at_once_with_the_fix(tmp_path, capsys, monkeypatch):
    """At once: the probe (git ls-remote) fails and no clone is started (its calls recorded, not timed)."""
    from greenloop.datasets import sources
    calls, git = [], sources._git
    monkeypatch.setattr(sources, "_git", lambda args, timeout: calls.append(args[0]) or git(args, timeout))
    rc = cli_main(["data", "nordland", str(tmp_path / "out"), "--url", "http://127.0.0.1:9/seqslam", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 1 and calls == ["ls-remote"]
    assert "could not" in err and "NORDLAND_SRC=path" in err
    assert not (tmp_path / "out").exists()


def test_make_all_builds_nordland_first(tmp_path):
    """`make all DATASET=data/nordland` must build the folder first when it is missing (dry run,
    nothing executed; NORDLAND points at a missing folder whatever this checkout holds)."""
    venv, target = Path(sys.prefix), tmp_path / "nordland"
    r = subprocess.run(["make", "-n", "all", f"DATASET={target}/", f"NORDLAND={target}", f"VENV={venv}",
                        f"RESULTS={tmp_path / 'results'}", "NORDLAND_SRC=/some/copy"],
                       cwd=ROOT, capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    build = [k for k, ln in enumerate(lines) if f"greenloop data nordland {target}" in ln]
    runs = [k for k, ln in enumerate(lines) if "papermill" in ln]
    assert build and runs and build[0] < runs[0]
    assert "--src /some/copy" in " ".join(lines[build[0]:build[0] + 2])


def test_default_tolerance_matches_the_source_sample():
    """The source's sample_ground_truth.csv: 358 rows q,q,15 over every 10th of 3576 images."""
    sample = SHARED / "sample_ground_truth.csv"
    if not sample.is_file():
        pytest.skip(f"Nordland sample ground truth not found at {sample}")
    rows = np.loadtxt(sample, delimiter=",", dtype=np.int64)
    n = len(sequence.list_frames(SHARED / "summer"))
    assert len(rows) == -(-n // nordland.SAMPLE_STEP)             # 358 = ceil(3576 / 10)
    assert (rows[:, 0] == rows[:, 1]).all() and (rows[:, 0] == np.arange(1, len(rows) + 1)).all()
    assert (rows[:, 2] == nordland.SAMPLE_TOLERANCE).all()
    assert nordland.TOLERANCE == nordland.SAMPLE_TOLERANCE


@pytest.mark.parametrize("n, tolerance", [(7, 2), (2, 150), (10, 3), (300, 150), (5, 0)])
def test_alignment_pairs_are_exactly_the_clipped_band(n, tolerance):
    """Summer k with winter n + k +- tolerance, never across the boundary into summer."""
    G = groundtruth.pair_matrix(nordland.alignment_pairs(n, tolerance), 2 * n, exclude=0)
    k = np.arange(n)
    ref = np.zeros((2 * n, 2 * n), bool)
    ref[:n, n:] = np.abs(k[None, :] - k[:, None]) <= tolerance
    assert (G == (ref | ref.T)).all()
