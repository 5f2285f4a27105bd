"""greenloop.exclusion: the one exclusion rule make and `detect` share, on folders a user
could bring (no ground truth, a frame rate, GPS positions, loop pairs, poses), and the CLI's use
of it (printed rule, the warning, --matches)."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from greenloop import exclusion
from greenloop.datasets import sequence
from greenloop.methods.greenloop_seq import seqmatch
from greenloop.study import params

from conftest import run_cli as _cli

ROOT = Path(__file__).resolve().parents[1]


def _frames(folder: Path, n: int) -> Path:
    (folder / "rgb").mkdir(parents=True, exist_ok=True)
    for k in range(n):
        cv2.imwrite(str(folder / "rgb" / f"{k}.png"), np.full((8, 8, 3), k % 256, np.uint8))
    return folder


def test_without_ground_truth_a_fraction_of_the_recording_within_bounds(tmp_path):
    assert exclusion.exclusion(_frames(tmp_path / "a", 84)).frames == exclusion.MIN_EXCLUDE      # 8 -> 20
    e = exclusion.exclusion(_frames(tmp_path / "b", 600))
    assert (e.frames, e.source) == (60, "fraction") and "10% of the 600 frames" in e.rule
    assert exclusion.exclusion(_frames(tmp_path / "c", 3000)).frames == exclusion.DEFAULT_EXCLUDE  # 300 -> 150


def test_sequence_yaml_then_frame_rate(tmp_path):
    f = _frames(tmp_path / "s", 100)
    (f / "sequence.yaml").write_text("frame_rate: 3\n")
    e = exclusion.exclusion(f)
    assert (e.frames, e.source) == (30, "frame rate") and "10 s at the 3 frames/s" in e.rule
    (f / "sequence.yaml").write_text("frame_rate: 3\nexclude: 7\n")
    assert exclusion.exclusion(f) == (7, "sequence.yaml", f"exclude 7 frames, from {f / 'sequence.yaml'}")


def test_same_place_runs_count_the_unbroken_partners_after_each_frame():
    a = np.array([0, 0, 0, 0, 1, 3, 3])
    d = np.array([1, 2, 3, 9, 2, 1, 2])
    assert exclusion.same_place_runs(a, d, 5).tolist() == [3, 0, 0, 2, 0]


def _gps_survey(folder: Path, laps: int = 2, per_lap: int = 60, step_m: float = 8.0) -> Path:
    """A field flown `laps` times along one 60-frame line: frames 8 m apart, so GPS within 25 m
    calls 3 following frames the same place; lap 2 revisits lap 1's places 60 frames later."""
    _frames(folder, laps * per_lap)
    x = np.tile(np.arange(per_lap) * step_m, laps)
    rows = "\n".join(f"{k},{xk:.1f},0" for k, xk in enumerate(x))
    (folder / "positions.csv").write_text("frame,x,y\n" + rows + "\n")
    return folder


def test_gps_survey_follows_the_motion_not_a_frame_count(tmp_path):
    f = _gps_survey(tmp_path / "drone")
    assert sequence.ground_truth_kind(f) == "pairs"
    a, d, n = exclusion.partner_offsets(f)
    assert exclusion.same_place_runs(a, d, n).max() == 3           # 24 m < 25 m: three frames on
    e = exclusion.exclusion(f)
    # revisits lie 57..63 frames apart, all inside the paper's 150: half the closest revisit
    assert (e.frames, e.source) == (28, "ground truth") and "leaves a place within 3 frames" in e.rule
    assert "would leave 0 of" in e.rule
    p, notes = params.sequence_parameters(f)
    assert p["exclude"] == 28 and e.rule in notes[0]                 # make reads the same rule


def test_loops_far_apart_keep_the_papers_window(tmp_path):
    f = _frames(tmp_path / "two", 400)
    sequence.write_loop_pairs(f / sequence.GROUND_TRUTH_NAME, [(k, 200 + k, 2) for k in range(200)])
    e = exclusion.exclusion(f)
    assert e.frames == exclusion.DEFAULT_EXCLUDE and "the paper's window" in e.rule
    # a corridor driven twice, loops 109..113 frames apart: the paper's window would hide them all
    g = _frames(tmp_path / "corridor", 222)
    sequence.write_loop_pairs(g / sequence.GROUND_TRUTH_NAME, [(k, 111 + k, 2) for k in range(111)])
    assert exclusion.exclusion(g).frames == 109 // 2


def test_real_greenhouse_poses_keep_the_papers_150(real_trajectory, tmp_path):
    f = _frames(tmp_path / "gh", 2261)
    (f / "CameraTrajectory.txt").write_bytes(real_trajectory.read_bytes())
    e = exclusion.exclusion(f)
    assert e.frames == 150 and "leaves a place within 61 frames" in e.rule


def test_candidate_share():
    assert exclusion.candidate_share(100, 20) == 0.79 and exclusion.candidate_share(10, 50) == 0.0


# ------------------------------------------------------------------------------------ the CLI
def _revisit_rgb(folder: Path, n0: int = 60, back: int = 30) -> Path:
    """n0 smooth random frames, then frames 0..back-1 again with a little noise, under rgb/."""
    rng = np.random.default_rng(0)
    base = [cv2.GaussianBlur(rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), (9, 9), 3) for _ in range(n0)]
    (folder / "rgb").mkdir(parents=True)
    frames = base + [np.clip(f.astype(int) + rng.integers(-4, 5, f.shape), 0, 255).astype(np.uint8)
                     for f in base[:back]]
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / "rgb" / f"{i}.png"), f)
    return folder


def test_detect_with_no_flags_matches_csv_and_the_warning(tmp_path):
    f = _revisit_rgb(tmp_path / "walk")
    out = tmp_path / "m.csv"
    r = _cli(["detect", str(f), "--matches", str(out)])
    assert r.returncode == 0, r.stderr
    assert "# exclude 20 (fraction)" in r.stdout and "warning" not in r.stderr
    closures = [line.split("\t")[:3] for line in r.stdout.splitlines() if line[:1].isdigit()]
    assert len(closures) >= 15 and all(int(m) == int(q) - 60 for q, m, _ in closures)
    rows = [line.split(",") for line in out.read_text().splitlines()]
    assert tuple(rows[0]) == ("frame", "file", "match", "match_file", "score", "closure", "verified", "inliers",
                              "model", "rx", "ry", "rz", "tx", "ty", "tz", "metric")     # detect verifies by default
    rows = rows[1:]
    assert [int(r_[0]) for r_ in rows] == list(range(90)) and rows[5][1] == "5.png"
    assert all(r_[2] == "" and r_[5] == "0" for r_ in rows[:21])            # frames 0..20: no candidate yet
    assert all(r_[2] != "" for r_ in rows[21:])
    declared = [r_ for r_ in rows if r_[5] == "1"]
    assert [[r_[0], r_[2]] for r_ in declared] == [c[:2] for c in closures]
    thr = seqmatch.DEFAULT_THRESHOLD
    assert all(float(r_[4]) >= thr for r_ in declared)
    assert all(float(r_[4]) < thr for r_ in rows[21:] if r_[5] == "0")
    assert rows[80][3] == f"{rows[80][2]}.png"
    # an exclusion that leaves fewer than half of the frames a candidate is said on stderr
    (f / "sequence.yaml").write_text("exclude: 60\n")
    w = _cli(["detect", str(f)])
    assert w.returncode == 0 and "# exclude 60 (sequence.yaml)" in w.stdout
    assert "warning: exclude 60 leaves only 29 of the 90 streamed frames" in w.stderr


def test_detect_matches_for_a_registered_stream_and_not_for_the_dictionary(tmp_path):
    f = _revisit_rgb(tmp_path / "walk", n0=40, back=20)
    out = tmp_path / "s.csv"
    r = _cli(["detect", str(f), "--method", "seqslam", "--threshold", "0.5", "--exclude", "10", "--matches", str(out)])
    assert r.returncode == 0, r.stderr
    rows = [line.split(",") for line in out.read_text().splitlines()[1:]]
    assert len(rows) == 60 and rows[0][2] == "" and rows[-1][2] != ""
    closures = [line.split("\t")[:2] for line in r.stdout.splitlines() if line[:1].isdigit()]
    assert [[r_[0], r_[2]] for r_ in rows if r_[5] == "1"] == closures
    bad = _cli(["detect", str(f), "--method", "dictionary", "--model", "x.keras", "--matches", str(out)])
    assert bad.returncode == 2 and "--matches needs a method that matches frames" in bad.stderr
