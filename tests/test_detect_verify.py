"""detect.run with a geometric verifier: each candidate the detector declares is checked
on its two frames, rejected ones are not declared, and every declared closure carries exactly the
verifier's inliers and relative pose in the printed lines, the --matches CSV and the Closure records.
The verifier here is a fake that knows each frame by its bytes: what detect does with its answer is
under test, not the geometry."""

import cv2
import numpy as np
import pandas as pd
import pytest

from greenloop import detect
from greenloop.datasets import sequence
from greenloop.methods import registry
from greenloop.methods.interface import Closure
from greenloop.methods.verification import PairCheck, Verification

from conftest import run_cli
from test_seqdetect import _revisit_folder

KNOBS = dict(descriptor="pixels-patchnorm", seq_len=3, contrast_window=0)
RVEC = np.array([0.1, -0.2, 0.3])                 # rad: 21.4 degrees
T = np.array([0.6, 0.0, 0.8])


def _fake(folder):
    """A verifier that rejects queries q = 0 mod 3, accepts q = 1 mod 3 (inliers 100 + q, RVEC, T, metric
    where depth is given) and cannot check q = 2 mod 3 ('too-small'); it records (q, m, depth_q, depth_m)."""
    known = {cv2.imread(str(p)).tobytes(): k for k, p in enumerate(sequence.list_frames(folder))}
    calls = []

    def verify(query, match, fq, fm, dq, dm):
        q, m = known[fq.tobytes()], known[fm.tobytes()]
        assert (query, match) == (q, m), "detect must pass the candidate's frame numbers with its frames"
        calls.append((q, m, dq, dm))
        if q % 3 == 0:
            return Verification(False, 4, 0.1, 40, "essential", None, None, False, "4 inliers < 15")
        if q % 3 == 1:
            return Verification(True, 100 + q, 0.8, 200, "pnp" if dq is not None else "essential",
                                cv2.Rodrigues(RVEC)[0], T, dq is not None, "accepted")
        return Verification(None, 0, 0.0, 3, "too-small", None, None, False, "frames too small")
    return verify, calls


def _run(folder, **kw):
    p = detect.plan(folder, "greenloop-seq", threshold=0.8, exclude=10, **KNOBS)
    lines = []
    return detect.run(p, folder, window=7, out=lines.append, **kw), lines


def test_only_accepted_or_unchecked_candidates_are_declared_with_the_verifiers_pose(tmp_path):
    folder = _revisit_folder(tmp_path / "rec")
    plain, plain_lines = _run(folder)
    candidates = [(c.query, c.match) for c in plain.closures]
    assert len(candidates) >= 10 and all(m == q - 30 for q, m in candidates)     # matches older than the window
    assert all(c.verified is None and c.model == "none" and c.R is None for c in plain.closures)
    verify, calls = _fake(folder)
    r, lines = _run(folder, verifier=verify, matches=tmp_path / "m.csv")
    assert [(q, m) for q, m, _, _ in calls] == candidates                       # each candidate's own two frames
    assert [(c.query, c.match) for c in r.closures] == [(q, m) for q, m in candidates if q % 3]
    assert r.rejected == sum(q % 3 == 0 for q, _ in candidates) > 0
    for c in r.closures:
        assert isinstance(c, Closure)
        if c.query % 3 == 1:
            assert c.verified is True and c.inliers == 100 + c.query and c.model == "essential" and not c.metric
            assert np.allclose(cv2.Rodrigues(c.R)[0].ravel(), RVEC) and np.allclose(c.t, T)
        else:
            assert c.verified is None and c.model == "too-small" and c.R is None and c.t is None
    printed = [ln.split("\t") for ln in lines if ln[:1].isdigit()]
    assert [int(x[0]) for x in printed] == [c.query for c in r.closures]
    one = next(x for x in printed if int(x[0]) % 3 == 1)
    assert one[-5:] == ["yes", str(100 + int(one[0])), "essential", "21.4 deg about (0.27,-0.53,0.80)", "(0.600,0.000,0.800) dir"]
    csv = pd.read_csv(tmp_path / "m.csv").set_index("frame")
    assert list(csv.columns[-10:]) == list(detect.VERIFY_COLUMNS)
    for q, _ in candidates:
        row = csv.loc[q]
        assert row.closure == (q % 3 != 0) and row.model == ("too-small" if q % 3 == 2 else "essential")
        if q % 3 == 1:
            assert row.verified == 1 and row.inliers == 100 + q and row.metric == 0
            assert np.allclose(row[["rx", "ry", "rz"]].astype(float), RVEC, atol=1e-5)
            assert np.allclose(row[["tx", "ty", "tz"]].astype(float), T)
        else:
            assert (row.verified == 0) if q % 3 == 0 else np.isnan(row.verified)
    unchecked = csv.drop(index=[q for q, _ in candidates])
    assert unchecked.closure.eq(0).all() and unchecked.model.isna().all()
    assert plain_lines[0] == "\t".join(["frame", "match", "score", "file", "match_file"])


def test_the_verifier_gets_the_folders_depth_and_the_same_closures_without_matches(tmp_path):
    """With depth/ the verifier is given both frames' depth in metres (each depth frame here holds
    (k + 1) / 5000 m) and its metric pose is carried as metric; without --matches (update_many) the
    closures are those of the run with --matches (decide_many)."""
    folder = _revisit_folder(tmp_path / "rec")
    (folder / "rgb").mkdir()
    for p in sorted(folder.glob("*.png")):
        p.rename(folder / "rgb" / p.name)
    (folder / "depth").mkdir()
    for k in range(45):
        cv2.imwrite(str(folder / "depth" / f"{k}.png"), np.full((48, 64), k + 1, np.uint16))
    verify, calls = _fake(folder)
    r, _ = _run(folder, verifier=verify)
    assert calls and all(np.allclose(dq, (q + 1) / 5000) and np.allclose(dm, (m + 1) / 5000) for q, m, dq, dm in calls)
    assert all(c.metric and c.model == "pnp" for c in r.closures if c.verified)
    again, _ = _run(folder, verifier=_fake(folder)[0], matches=tmp_path / "m.csv")
    assert [c[:3] for c in again.closures] == [c[:3] for c in r.closures]


def test_verification_needs_a_matched_frame_and_the_registered_verifier_is_the_geometric_stage(tmp_path):
    folder = _revisit_folder(tmp_path / "rec")
    p = detect.plan(folder, "greenloop-seq", threshold=0.8, exclude=10, **KNOBS)
    with pytest.raises(ValueError, match="names no earlier frame"):
        detect.checker_for(p._replace(name="dictionary"), folder, _fake(folder)[0], ("spot", "count"))
    assert isinstance(registry.verifier(), PairCheck) and isinstance(detect.verifier_for(folder), PairCheck)
    assert registry.verifier() is not registry.verifier()          # a fresh consistency chain per run


def test_the_verify_flags(tmp_path):
    """By default detect verifies (a verifier is registered): on frames too small for local features
    (this folder's) every candidate is declared unverified, so the closures are --no-verify's, printed
    with 'unchecked' and no pose; --no-verify prints what detect printed before verification."""
    folder = _revisit_folder(tmp_path / "rec")
    cmd = ["detect", folder, "--method", "greenloop-seq", "--threshold", "0.8", "--exclude", "10", "--seq-len", "3",
           "--contrast-window", "0", "--descriptor", "pixels-patchnorm"]
    plain, off, on = run_cli(cmd), run_cli(cmd + ["--no-verify"]), run_cli(cmd + ["--verify"])
    assert plain.returncode == off.returncode == on.returncode == 0
    assert plain.stdout.splitlines()[:-1] == on.stdout.splitlines()[:-1] and "rotation" not in off.stdout and "rotation" in plain.stdout
    rows = lambda out: [ln.split("\t")[:3] for ln in out.splitlines() if ln[:1].isdigit()]
    assert rows(plain.stdout) == rows(off.stdout) and len(rows(off.stdout)) >= 10
    assert all("\tunchecked\t0\ttoo-small\t-\t-" in ln for ln in plain.stdout.splitlines() if ln[:1].isdigit())
