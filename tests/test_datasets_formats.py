"""Other layouts and ground-truth formats: traversal folders, sequence.yaml, the importers
(VPR-Bench, loop matrices, positions / GPS), the parameters a folder implies, the CLI, and the
Gardens Point builder (on a tiny fake source, and on the real one where ../shared has it)."""
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import scipy.io
from sklearn.metrics.pairwise import haversine_distances

from greenloop import groundtruth
from greenloop.datasets import gardenspoint, groundtruth_formats as fmts, sequence
from greenloop.study import params
from greenloop.cli import main as cli_main

from conftest import HANG_S, run_cli as _cli

ROOT = Path(__file__).resolve().parents[1]
REAL_GP = ROOT.parent / "shared" / "real" / "gardenspoint"


def _images(folder: Path, n: int, size=(16, 8), start=0) -> Path:
    """n frames k.png in folder; pixel [0, 0] encodes start + k."""
    folder.mkdir(parents=True, exist_ok=True)
    for k in range(n):
        img = np.zeros((size[1], size[0], 3), np.uint8)
        img[0, 0] = (start + k) % 256
        cv2.imwrite(str(folder / f"{k}.png"), img)
    return folder


def _codes(paths) -> list[int]:
    return [int(cv2.imread(str(p))[0, 0, 0]) for p in paths]


# ------------------------------------------------------------------------------ layouts
def test_traversal_folders_read_as_one_stream_in_the_stated_order(tmp_path):
    f = tmp_path / "seq"
    _images(f / "traversals" / "night", 4, start=100)
    _images(f / "traversals" / "day", 4, start=0)
    assert _codes(sequence.list_frames(f)) == [0, 1, 2, 3, 100, 101, 102, 103]   # sorted by name
    (f / "sequence.yaml").write_text("traversals: [night, day]\nground_truth: aligned\ntolerance: 1\n")
    assert _codes(sequence.list_frames(f)) == [100, 101, 102, 103, 0, 1, 2, 3]
    assert sequence.traversals(f) == [("night", 0, 4), ("day", 4, 8)]
    assert sequence.traversal_index(f).tolist() == [0, 0, 0, 0, 1, 1, 1, 1]
    assert sequence.reference_frames(f).tolist() == [True] * 4 + [False] * 4
    info = sequence.folder_info(f)
    assert (info["layout"], info["n_frames"], info["ground_truth"]) == ("traversals", 8, "pairs")
    assert info["traversals"] == "night 0-3, day 4-7"
    assert sequence.load_frames(f, size=None).shape == (8, 8, 16, 1)
    # frame k of night is frame k of day, +- 1, never within one traversal
    gt = groundtruth.for_sequence(f, exclude=0)
    k = np.arange(4)
    ref = np.zeros((8, 8), bool)
    ref[:4, 4:] = np.abs(k[:, None] - k[None, :]) <= 1
    assert (gt == (ref | ref.T)).all()
    assert "sequence.yaml: traversals aligned" in groundtruth.definition(f, exclude=0)
    before = sequence.fingerprint(f)
    (f / "sequence.yaml").write_text("traversals: [night, day]\nground_truth: aligned\ntolerance: 0\n")
    assert sequence.fingerprint(f) != before                       # the ground truth changed
    (f / "sequence.yaml").write_text("traversals: [night, dusk]\n")
    with pytest.raises(ValueError, match=r"lists traversals \['dusk'\]"):
        sequence.list_frames(f)


def test_reference_and_query_folders_and_rgb_boundaries(tmp_path):
    f = tmp_path / "vpr"
    _images(f / "ref", 3, start=0)
    _images(f / "query", 2, start=50)
    assert sequence.layout(f) == "reference/query"
    assert _codes(sequence.list_frames(f)) == [0, 1, 2, 50, 51]
    assert sequence.traversals(f) == [("reference", 0, 3), ("query", 3, 5)]
    assert sequence.reference_frames(f).tolist() == [True, True, True, False, False]
    g = tmp_path / "stream"
    _images(g / "rgb", 10)
    assert sequence.traversals(g) == [("all", 0, 10)]
    (g / "sequence.yaml").write_text("traversals: {summer: [0, 4], winter: [5, 9]}\n")
    assert sequence.traversal_index(g).tolist() == [0] * 4 + [-1] + [1] * 4 + [-1]
    (g / "sequence.yaml").write_text("traversals: {a: [0, 6], b: [5, 10]}\n")
    with pytest.raises(ValueError, match="traversal a: .* not overlapping"):
        sequence.traversals(g)


def test_sequence_yaml_is_checked(tmp_path):
    f = _images(tmp_path / "s" / "rgb", 3).parent
    assert sequence.read_description(f) == dict.fromkeys(sequence.DESCRIPTION_KEYS)
    (f / "sequence.yaml").write_text("exclude: 20\nframe_rate: 15\nframe_step: 2\n")
    d = sequence.read_description(f)
    assert (d["exclude"], d["frame_rate"], d["frame_step"], d["tolerance"]) == (20, 15, 2, None)
    for text, match in (("exlude: 20\n", r"unknown key\(s\) \['exlude'\]"), ("exclude: -1\n", "exclude must be"),
                        ("frame_rate: 0\n", "frame_rate must be a number > 0"), ("[1, 2]\n", "must be a mapping"),
                        ("ground_truth: missing.csv\n", None)):
        (f / "sequence.yaml").write_text(text)
        if match is None:
            with pytest.raises(FileNotFoundError, match="names ground_truth: missing.csv"):
                sequence.ground_truth_kind(f)
        else:
            with pytest.raises(ValueError, match=match):
                sequence.read_description(f)


def test_aligned_pairs_clip_every_window_to_its_traversal():
    """Three traversals of 5 frames, tolerance 2: a window never reaches another traversal."""
    ranges = [(0, 5), (5, 10), (10, 15)]
    G = groundtruth.pair_matrix(sequence.aligned_pairs(ranges, 2), 15, exclude=0)
    k = np.arange(5)
    band = np.abs(k[:, None] - k[None, :]) <= 2
    ref = np.zeros((15, 15), bool)
    for a, b in ((0, 1), (0, 2), (1, 2)):
        ref[5 * a:5 * a + 5, 5 * b:5 * b + 5] = band
    assert (G == (ref | ref.T)).all()
    with pytest.raises(ValueError, match="one length"):
        sequence.aligned_pairs([(0, 5), (5, 9)], 1)


# ------------------------------------------------------------------------------ importers
def test_vpr_bench_ground_truth_auto_detected_and_imported(tmp_path):
    f = tmp_path / "vpr"
    _images(f / "reference", 3)
    _images(f / "query", 2)
    gt = np.empty((2, 2), dtype=object)
    gt[0, 0], gt[0, 1] = 0, np.array([1, 2])            # query 0 (frame 3) shows references 1 and 2
    gt[1, 0], gt[1, 1] = 1, np.array([0])               # query 1 (frame 4) shows reference 0
    np.save(f / "ground_truth_new.npy", gt, allow_pickle=True)
    assert sequence.ground_truth_kind(f) == "pairs"
    assert sequence.read_loop_pairs(f, n_frames=5).tolist() == [[1, 3, 0], [2, 3, 0], [0, 4, 0]]
    G = groundtruth.for_sequence(f, exclude=0)
    assert sorted(map(tuple, groundtruth.loop_pairs(G).tolist())) == [(0, 4), (1, 3), (2, 3)]
    assert "VPR-Bench" in groundtruth.definition(f, exclude=0)
    r = _cli(["import-gt", str(f / "ground_truth_new.npy")])
    assert r.returncode == 0, r.stderr
    assert "3 loop pairs" in r.stdout and "3 reference frames first" in r.stdout
    assert sequence.read_loop_pairs(f / "ground_truth.csv").tolist() == [[1, 3, 0], [2, 3, 0], [0, 4, 0]]
    bad = np.empty((1, 2), dtype=object)
    bad[0, 0], bad[0, 1] = 0, np.array([7])
    np.save(tmp_path / "bad.npy", bad, allow_pickle=True)
    with pytest.raises(ValueError, match=r"bad.npy: entry 0 \(query 0\): .* within 0..2"):
        fmts.read(tmp_path / "bad.npy", n_reference=3)
    with pytest.raises(ValueError, match="number of reference images is needed"):
        fmts.read(tmp_path / "bad.npy")


def test_loop_matrices_npy_mat_and_image_give_the_same_pairs(tmp_path):
    m = np.zeros((6, 6), np.uint8)
    m[4, 0] = m[5, 1] = m[5, 0] = 1                     # one triangle, as the City Centre file
    np.save(tmp_path / "loops.npy", m)
    scipy.io.savemat(tmp_path / "CityCentreGroundTruth.mat", {"truth": m.astype(float)})
    cv2.imwrite(str(tmp_path / "loops.png"), m * 255)
    expected = [[0, 4, 0], [0, 5, 0], [1, 5, 0]]
    for name in ("loops.npy", "CityCentreGroundTruth.mat", "loops.png"):
        assert fmts.detect_format(tmp_path / name) == "matrix"
        assert fmts.read(tmp_path / name, n_frames=6).tolist() == expected, name
    with pytest.raises(ValueError, match="matrix is 6x6 but the sequence has 5 frames"):
        fmts.read(tmp_path / "loops.npy", n_frames=5)
    np.save(tmp_path / "rect.npy", np.zeros((3, 4)))
    with pytest.raises(ValueError, match=r"rect.npy: a loop matrix must be square .* \(3, 4\)"):
        fmts.read(tmp_path / "rect.npy")
    nan = np.zeros((3, 3))
    nan[1, 2] = np.nan
    np.save(tmp_path / "nan.npy", nan)
    with pytest.raises(ValueError, match=r"nan.npy: entry \[1, 2\] is nan"):
        fmts.read(tmp_path / "nan.npy")
    # auto-detected in a sequence folder without ground_truth.csv (New College's naming)
    f = _images(tmp_path / "seq" / "rgb", 6).parent
    scipy.io.savemat(f / "NewCollegeGroundTruth.mat", {"truth": m.astype(float)})
    assert groundtruth.loop_pairs(groundtruth.for_sequence(f, exclude=0)).tolist() == [[0, 4], [0, 5], [1, 5]]
    np.save(f / "ground_truth.npy", m)
    with pytest.raises(ValueError, match="several ground-truth files"):
        sequence.ground_truth_kind(f)


def test_positions_in_metres_and_gps_by_haversine(tmp_path):
    (tmp_path / "xy.csv").write_text("x,y,z\n0,0,0\n3,4,0\n0,0.9,0\n10,0,0\n3,4,1\n")
    # distances: 0-1 = 5, 0-2 = 0.9, 1-4 = 1, 1-2 = sqrt(18.61), 2-4 = sqrt(19.61), 0-4 = sqrt(26), 3: > 6
    assert fmts.read_positions(tmp_path / "xy.csv", 1.0).tolist() == [[0, 2, 0], [1, 4, 0]]
    assert fmts.read_positions(tmp_path / "xy.csv", 5.0).tolist() == [[0, 1, 0], [0, 2, 0], [1, 2, 0], [1, 4, 0],
                                                                      [2, 4, 0]]       # at most 5 m: 0-1 counts
    rng = np.random.default_rng(0)
    ll = np.column_stack([51.75 + rng.uniform(0, 5e-4, 40), -1.25 + rng.uniform(0, 8e-4, 40)])
    (tmp_path / "gps.csv").write_text("frame,lat,lon\n" + "".join(f"{k},{float(a)!r},{float(b)!r}\n" for k, (a, b) in enumerate(ll)))
    d = haversine_distances(np.radians(ll)) * fmts.EARTH_RADIUS_M
    i, j = np.nonzero(np.triu(d <= 20.0, 1))
    assert 0 < len(i) < 40 * 39 / 2
    assert fmts.read(tmp_path / "gps.csv", threshold_m=20.0).tolist() == np.column_stack([i, j, 0 * i]).tolist()
    # the track's length, its points in frame order: consecutive distances, haversine for lat/lon
    assert fmts.track_length(tmp_path / "xy.csv") == pytest.approx(5 + np.sqrt(18.61) + np.sqrt(100.81) + np.sqrt(66))
    (tmp_path / "shuffled.csv").write_text("frame,x,y\n2,6,8\n0,0,0\n1,3,4\n")
    assert fmts.track_length(tmp_path / "shuffled.csv") == pytest.approx(10.0)
    assert fmts.track_length(tmp_path / "gps.csv") == pytest.approx(np.diagonal(d, 1).sum(), rel=1e-9)
    (tmp_path / "broken.csv").write_text("lat,lon\n51.7,-1.2\n\n51.7,north\n")
    with pytest.raises(ValueError, match=r"broken.csv:4: expected numbers for lat, lon"):
        fmts.read(tmp_path / "broken.csv")
    (tmp_path / "what.csv").write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match=r"what.csv:1: cannot tell the format"):
        fmts.read(tmp_path / "what.csv")
    f = _images(tmp_path / "seq" / "rgb", 5).parent
    (f / "positions.csv").write_text((tmp_path / "xy.csv").read_text())
    (f / "sequence.yaml").write_text("threshold_m: 1.0\n")
    assert groundtruth.loop_pairs(groundtruth.for_sequence(f, exclude=0)).tolist() == [[0, 2], [1, 4]]
    r = _cli(["import-gt", str(tmp_path / "xy.csv"), "--out", str(f / "ground_truth.csv"), "--threshold-m", "5"])
    assert r.returncode == 0 and "within 5 m" in r.stdout and "5 frames" in r.stdout, r.stderr
    assert len(sequence.read_loop_pairs(f / "ground_truth.csv")) == 5
    bad = _cli(["import-gt", str(tmp_path / "broken.csv")])
    assert bad.returncode == 2 and "broken.csv:4" in bad.stderr


# -------------------------------------------------------------- parameters a folder implies
def test_sequence_yaml_becomes_notebook_parameters_that_params_override(tmp_path):
    f = _images(tmp_path / "s" / "traversals" / "a", 5).parent.parent
    _images(f / "traversals" / "b", 5)
    (f / "sequence.yaml").write_text("exclude: 3\nframe_step: 2\nground_truth: aligned\n")
    p, notes = params.sequence_parameters(f)
    assert p == {"exclude": 3, "frame_step": 2, "first_traversal_end": 5} and len(notes) == 3
    params.write_parameters(f, tmp_path / "r" / params.PARAMS_NAME)
    nb = ROOT / "notebooks" / "07_feature_baselines.ipynb"
    seq = tmp_path / "r" / params.PARAMS_NAME
    (tmp_path / "budget.yaml").write_text("frame_step: 1\n")
    e = params.effective_parameters(nb, [seq])
    assert (e["exclude"], e["frame_step"], e["input_size"]) == (3, 2, 128)       # 128: the notebook's default
    assert "first_traversal_end" not in e                                        # 07 does not declare it
    e = params.effective_parameters(nb, [seq], ["-f", str(tmp_path / "budget.yaml"), "-p", "exclude", "4"])
    assert (e["exclude"], e["frame_step"]) == (4, 1)                             # later files and -p win


def test_loops_inside_the_default_window_get_a_fitting_exclude(tiny_near_loop_sequence, capsys):
    assert params.loop_distances(tiny_near_loop_sequence) == (99, 101)
    p, notes = params.sequence_parameters(tiny_near_loop_sequence)
    assert p == {"exclude": 49, "first_traversal_end": 100}
    assert "half the closest revisit" in notes[0] and "revisits 99..101 frames apart" in notes[0]
    assert "would leave 0 of 200 frames of revisit pairs" in notes[0]


def test_a_notebook_without_any_counted_loop_is_skipped_with_the_reason(tiny_near_loop_sequence, tmp_path, capsys):
    from greenloop.study import report
    nb = ROOT / "notebooks" / "07_feature_baselines.ipynb"
    out = tmp_path / "res" / ".tmp-07.ipynb"
    args = [str(nb), str(tiny_near_loop_sequence), str(tmp_path / "res"), "--out", str(out)]
    assert cli_main(["notebook-params"] + args + ["--", "-p", "exclude", "120"]) == 0
    printed = capsys.readouterr().out
    assert "no loop pair more than exclude=120" in printed and "-p exclude 49" in printed
    assert "exclude 49 frames (the longer of" in printed         # the rule, printed once per run
    assert "07_feature_baselines: skipped" in "".join(json.loads(out.read_text())["cells"][0]["source"])
    assert "exclude=120" in (tmp_path / "res" / "07_feature_baselines" / "skipped.md").read_text()
    assert "07_feature_baselines: skipped" in report.assemble_tables(tmp_path / "res").read_text()
    out.unlink()
    assert cli_main(["notebook-params"] + args) == 0 and not out.exists()                 # exclude 49: it runs
    assert "exclude 49" not in capsys.readouterr().out                 # the same rule: not printed again
    assert cli_main(["notebook-params", str(ROOT / "notebooks" / "04_shift_robustness.ipynb")] + args[1:] + ["--", "-p", "exclude", "120"]) == 0
    assert not out.exists()                                            # 04 scores no loops: never skipped


def test_make_passes_the_folder_parameters_first_and_builds_gardenspoint(tmp_path):
    venv, target = Path(sys.prefix), tmp_path / "gardenspoint"
    r = subprocess.run(["make", "-n", "all", f"DATASET={target}", f"GARDENSPOINT={target}", f"VENV={venv}",
                        f"RESULTS={tmp_path / 'res'}", "GARDENSPOINT_SRC=/some/copy", "PARAMS=-p exclude 7"],
                       cwd=ROOT, capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr
    text = r.stdout.replace("\\\n", " ")
    lines = text.splitlines()
    build = [k for k, ln in enumerate(lines) if f"greenloop data gardenspoint {target}" in ln]
    check = [k for k, ln in enumerate(lines) if "greenloop notebook-params" in ln]
    runs = [k for k, ln in enumerate(lines) if "papermill" in ln]
    assert build and check and runs and build[0] < check[0] < runs[0]
    assert "--src /some/copy" in lines[build[0]]
    # the check merges sequence_params.yaml, the budget and PARAMS into the one file papermill reads
    run = " ".join(lines[runs[0]].split())
    assert f"-f {tmp_path / 'res'}/.tmp-00_dataset.yaml" in run and "exclude" not in run and "sequence_params" not in run
    assert f"--params-out {tmp_path / 'res'}/.tmp-00_dataset.yaml" in lines[check[0]]
    assert lines[check[0]].rstrip().endswith("-p exclude 7")


# ------------------------------------------------------------------------------ the CLI
def test_detect_prints_tuned_knobs_keeps_every_frame_and_honours_sequence_yaml(tmp_path):
    f = _images(tmp_path / "rec" / "rgb", 24, size=(32, 24)).parent
    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"frame_step": 8, "exclude_steps": 2, "thresholds": {"greenloop-seq-fast": 0.9},
                                   "knobs": {"greenloop-seq-fast": {"descriptor": "pixels", "seq_len": 3,
                                                                    "contrast_window": 0}}}))
    cmd = ["detect", str(f), "--method", "greenloop-seq", "--tuned", str(summary)]
    r = _cli(cmd)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    for line in ("# descriptor pixels (--tuned)", "# seq_len 3 (--tuned)", "# contrast_window 0 (--tuned)",
                 "# threshold 0.9 (--tuned)", "# step 1 (default)", "# exclude 16 (--tuned)"):
        assert line in out, (line, out)
    assert "--step 8" in out and "# 24 frames" in out and "summary: 24 frames" in out
    (f / "sequence.yaml").write_text("exclude: 6\nframe_step: 2\n")
    r = _cli(cmd)
    assert "# step 2 (sequence.yaml)" in r.stdout and "# exclude 3 (sequence.yaml)" in r.stdout, r.stdout
    assert "# 12 frames" in r.stdout
    r = _cli(cmd + ["--step", "1", "--exclude", "5"])
    assert "# step 1 (--step)" in r.stdout and "# exclude 5 (--exclude)" in r.stdout and "# 24 frames" in r.stdout


# ------------------------------------------------------------------------------ Gardens Point
def _fake_gardenspoint(root: Path, n=6) -> Path:
    """day_left/, day_right/ (32x18) and night_right/ (16x9), Image000.jpg ...: a frame's colour
    encodes (traversal, k)."""
    for t, name in enumerate(gardenspoint.TRAVERSALS):
        (root / name).mkdir(parents=True)
        size = (16, 9) if name == "night_right" else (32, 18)
        for k in range(n):
            img = np.full((size[1], size[0], 3), (40 * t, 20 * k, 0), np.uint8)
            cv2.imwrite(str(root / name / f"Image{k:03d}.jpg"), img)
    return root


def test_gardenspoint_builder_on_a_fake_source(tmp_path):
    src = _fake_gardenspoint(tmp_path / "src")
    out = gardenspoint.build(tmp_path / "gp", src, size=(16, 9), tolerance=1, progress=False)
    frames = sequence.list_frames(out)
    assert len(frames) == 18 and {cv2.imread(str(p)).shape for p in frames} == {(9, 16, 3)}
    colours = [tuple(int(v) for v in cv2.imread(str(p))[4, 8, :2]) for p in frames]
    assert [(round(b / 40), round(g / 20)) for b, g in colours] == [(t, k) for t in range(3) for k in range(6)]
    assert (out / "traversals" / "night_right" / "3.jpg").read_bytes() == (src / "night_right" / "Image003.jpg").read_bytes()
    assert [t.name for t in sequence.traversals(out)] == list(gardenspoint.TRAVERSALS)
    gt = groundtruth.for_sequence(out, exclude=0)
    k = np.arange(6)
    band = np.abs(k[:, None] - k[None, :]) <= 1
    assert (gt[:6, 6:12] == band).all() and (gt[:6, 12:] == band).all() and (gt[6:12, 12:] == band).all()
    assert not gt[:6, :6].any() and not gt[6:12, 6:12].any()
    meta = json.loads((out / "gardenspoint.json").read_text())
    assert meta["traversals"] == {"day_left": [0, 6], "day_right": [6, 12], "night_right": [12, 18]}
    assert meta["source_sizes"]["night_right"] == [[16, 9]] and meta["source_sizes"]["day_left"] == [[32, 18]]
    # 6-frame traversals: every loop lies within 150 frames, the closest 5 apart (frame 1 and 6)
    assert params.sequence_parameters(out)[0] == {"exclude": 2, "frame_step": 1, "first_traversal_end": 6}
    protocol = sequence.open(out).protocol                # the targets' two streams, database first, +- 2
    assert protocol.targets == "gardenspoint" and [s.name for s in protocol.streams] == [
        f"{a} -> {b}" for a, b in gardenspoint.TARGET_PAIRS] == ["day_right -> night_right", "day_left -> night_right"]
    assert [(s.traversals[0].start, s.traversals[1].start, s.tolerance) for s in protocol.streams] == [(6, 12, 2), (0, 12, 2)]
    text = (out / "sequence.yaml").read_text()
    (out / "sequence.yaml").write_text(text.split("# how the detector")[0])    # a folder built before the protocol
    assert cli_main(["data", "gardenspoint", str(out), "--describe"]) == 0 and (out / "sequence.yaml").read_text() == text
    assert not list(tmp_path.glob(".gp.tmp*"))
    with pytest.raises(FileNotFoundError, match="GARDENSPOINT_SRC=path"):
        gardenspoint.build(tmp_path / "x", tmp_path / "missing", progress=False)
    (src / "day_right" / "Image002.jpg").unlink()
    with pytest.raises(ValueError, match=r"only in day_left/: \['Image002.jpg'\]"):
        gardenspoint.build(tmp_path / "x", src, progress=False)
    assert not (tmp_path / "x").exists()


@pytest.mark.skipif(gardenspoint.shutil.which("git") is None, reason="git is not installed")
def test_gardenspoint_offline_clone_fails_at_once_with_the_fix(tmp_path, capsys):
    rc = cli_main(["data", "gardenspoint", str(tmp_path / "out"), "--url", "http://127.0.0.1:9/loop-detection", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 1 and "could not" in err and "GARDENSPOINT_SRC=path" in err and not (tmp_path / "out").exists()


def test_gardenspoint_builder_on_the_real_source(tmp_path):
    if not (REAL_GP / "night_right").is_dir():
        pytest.skip(f"Gardens Point not found at {REAL_GP}")
    out = gardenspoint.build(tmp_path / "gp", REAL_GP, progress=False)
    info = sequence.folder_info(out)
    assert (info["n_frames"], info["width"], info["height"]) == (600, 640, 360)
    assert {cv2.imread(str(p)).shape for p in sequence.list_frames(out)[::37]} == {(360, 640, 3)}
    gt = groundtruth.for_sequence(out)                        # the default exclude of 150 keeps every loop
    assert np.flatnonzero(gt[100]).tolist() == [298, 299, 300, 301, 302, 498, 499, 500, 501, 502]
    assert np.flatnonzero(gt[0]).tolist() == [200, 201, 202, 400, 401, 402]     # clipped at each start
    assert len(groundtruth.loop_pairs(gt)) == 3 * (200 * 5 - 6)


def test_make_skips_a_notebook_without_counted_loops_and_carries_on(tiny_near_loop_sequence, tmp_path):
    """A real make run of 07 with PARAMS='-p exclude 120' (every loop is 99-101 frames apart): make
    prints the reason, writes the executed notebook that says so, and exits 0 (no page rendered: make book does)."""
    venv = Path(sys.prefix)
    if not (venv / ".installed").is_file():
        pytest.skip(f"{venv} was not set up by make venv")
    res = tmp_path / "res"
    (res / "07_feature_baselines").mkdir(parents=True)
    (res / "07_feature_baselines" / "older_version.png").write_bytes(b"")   # what an older notebook wrote
    r = subprocess.run(["make", f"{res}/07_feature_baselines.ipynb", f"DATASET={tiny_near_loop_sequence}",
                        f"RESULTS={res}", f"VENV={venv}", "PARAMS=-p exclude 120"], cwd=ROOT,
                       capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "closest loop is 99 frames apart" in r.stdout and "PARAMS='-p exclude 49'" in r.stdout
    assert "skipped" in (res / "07_feature_baselines.ipynb").read_text() and not list(res.glob("*.html"))
    assert json.loads((res / "07_feature_baselines" / "manifest.json").read_text())["skipped"].startswith("07")
    assert not (res / "07_feature_baselines" / "older_version.png").exists()      # the folder holds this run's files only
    assert not list(res.glob(".tmp-*"))


def test_a_coarse_step_that_hides_every_loop_is_refined_and_said(tiny_near_loop_sequence, tmp_path, capsys):
    """quick's every 8th frame on two 100-frame traversals (loops 99..101 frames apart: no multiple of
    8, 7 or 6 among them): 07 runs at step 5, the largest step that keeps loops, and make says so; 13
    keeps its requested step (it chooses its own, experiments.leaderboard.choose_step)."""
    import yaml
    res, out = tmp_path / "res", tmp_path / "res" / ".tmp.ipynb"
    for stem, want in (("07_feature_baselines", 5), ("13_leaderboard", 8)):
        nb = ROOT / "notebooks" / f"{stem}.ipynb"
        run = tmp_path / f"{stem}.yaml"
        args = [str(nb), str(tiny_near_loop_sequence), str(res), "--out", str(out), "--params-out", str(run)]
        assert cli_main(["notebook-params"] + args + ["--", "-p", "frame_step", "8"]) == 0 and not out.exists()
        assert yaml.safe_load(run.read_text())["frame_step"] == want
        printed = capsys.readouterr().out
        assert ("frame_step 5, not the requested 8" in printed) == (want == 5), printed
    assert params.loop_step(tiny_near_loop_sequence, {"exclude": 49, "frame_step": 8}) == 5
    assert params.loop_step(tiny_near_loop_sequence, {"exclude": 120, "frame_step": 8}) is None
