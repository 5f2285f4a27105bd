"""Short recordings (greenloop.short_recordings): the cuts carry their source's ground truth
re-indexed, and the scorer counts right and wrong closures and the targets as the detector's targets state them."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation
import pandas as pd
import pytest

from greenloop import groundtruth
from greenloop import short_recordings as sr
from greenloop.datasets import sequence
from greenloop.methods.interface import Closure


def _closure(q, m, R=None, t=None, metric=False):
    return Closure(q, m, 1.0, None if R is None else True, 0, "none", R, t, metric)


@pytest.fixture(scope="module")
def cuts(tiny_sequence, tiny_end_loop_sequence, tmp_path_factory):
    """The tiny greenhouse's cuts (poses) and a planted two-range cut of the end-loop folder (pairs)."""
    out = tmp_path_factory.mktemp("cuts")
    planted = sr.Cut("planted", ((0, 30), (170, 200)), "revisit")
    return dict(poses=sr.cuts_for(tiny_sequence, 40), out=out,
                planted=sr.build_cut(tiny_end_loop_sequence, planted, out))


def test_a_cut_of_loop_pairs_is_the_sources_ground_truth_reindexed(cuts, tiny_end_loop_sequence):
    """Frames 180..199 revisit 0..19 (tolerance 1) in the source; in the cut (0..29, then 170..199 as
    30..59) frame 40 + k revisits k, with the tolerance's neighbours, and nothing else is a loop."""
    gt = groundtruth.for_sequence(cuts["planted"], exclude=0)
    src = groundtruth.for_sequence(tiny_end_loop_sequence, exclude=0)
    f = np.r_[0:30, 170:200]
    assert gt.shape == (60, 60) and np.array_equal(gt, src[np.ix_(f, f)])
    assert gt[40, 0] and gt[59, 19] and gt[40, 1] and not gt[40, 5] and not gt[:30, :30].any()
    assert len(sequence.list_frames(cuts["planted"])) == 60
    assert sequence.open(cuts["planted"]).exclude is not None     # the run-time exclusion, without ground truth


def test_a_cut_of_poses_carries_the_cut_frames_poses(cuts, tiny_sequence):
    """The synthetic sequence's revisit cut: its trajectory is the source's rows, its depth the source's
    frames; the planted revisit (the second range) is found by its ground truth."""
    cut = next(c for c in cuts["poses"] if c.kind == "revisit")
    folder = sr.build_cut(tiny_sequence, cut, cuts["out"])
    _, poses = sequence.read_trajectory(folder)
    _, src = sequence.read_trajectory(tiny_sequence)
    assert np.allclose(poses, src[cut.frames], atol=1e-6)
    assert sequence.open(folder).has_depth
    rev = groundtruth.revisit_frames(groundtruth.for_sequence(folder, exclude=20))
    k = cut.ranges[0][1] - cut.ranges[0][0]
    assert not rev[:k].any() and rev[k:].mean() > 0.5


def test_the_synthetic_cuts_have_and_lack_revisits_as_named(cuts, tiny_sequence):
    """revisit: a revisit; no-revisit and aisles-once: no loop farther apart than MIN_EXCLUDE frames;
    neighbour: two legs driven the same way that are no loop."""
    kinds = {c.name: c for c in cuts["poses"]}
    assert set(kinds) == {"revisit", "no-revisit", "neighbour", "aisles-once"}
    _, poses = sequence.read_trajectory(tiny_sequence)
    far = groundtruth.loop_matrix(poses, 0.5, 0) & groundtruth.far_in_time(len(poses), sr.exclusion.MIN_EXCLUDE)
    for name in ("no-revisit", "aisles-once", "neighbour"):
        f = kinds[name].frames
        assert not far[np.ix_(f, f)].any(), name
    f = kinds["revisit"].frames
    assert far[np.ix_(f, f)].any()


def test_a_right_closure_counts_right_and_a_planted_wrong_one_wrong(cuts):
    """On the planted cut: (45 -> 5) is a loop pair, (45 -> 20) is not; recall counts revisit frames."""
    s = sr.score_closures(cuts["planted"], [_closure(45, 5), _closure(45, 20)], exclude=20)
    assert (s["closures"], s["right"], s["wrong"], s["precision"]) == (2, 1, 1, 0.5)
    assert s["revisits"] == 20 and s["found"] == 1 and s["recall"] == pytest.approx(1 / 20)


def test_a_closure_with_the_true_relative_pose_is_right_on_poses(cuts, tiny_sequence):
    """On a pose cut a non-loop pair is right when its relative pose is the true one (the neighbouring
    aisle's rule), wrong when the pose is off by 10 degrees."""
    cut = next(c for c in cuts["poses"] if c.name == "neighbour")
    folder = sr.build_cut(tiny_sequence, cut, cuts["out"])
    _, poses = sequence.read_trajectory(folder)
    q, m = len(poses) - 5, 5
    T = groundtruth.relative_poses(poses, np.array([[m, q]]))[0]
    off = Rotation.from_euler("y", 10, degrees=True).as_matrix() @ T[:3, :3]
    s = sr.score_closures(folder, [_closure(q, m, T[:3, :3], T[:3, 3], True),
                                   _closure(q, m, off, T[:3, 3], True)], exclude=20)
    assert (s["right"], s["wrong"], s["posed"], s["pose_ok"]) == (1, 1, 2, 1)
    assert s["rot_deg"] == pytest.approx(5.0, abs=0.01) and s["metric_m"] == pytest.approx(0.0, abs=1e-6)


def _row(**kw):
    base = dict(cut="c", kind="revisit", day=True, configuration="x", verify=True, closures=10, right=10,
                precision=1.0, revisits=20, found=10, recall=0.5, posed=0, rot_deg=np.nan, dir_deg=np.nan,
                metric_m=np.nan)
    return dict(base, **kw)


def test_targets_fail_a_closure_on_a_no_revisit_cut_and_low_precision_or_recall():
    t = sr.targets(pd.DataFrame([
        _row(),                                                                   # met
        _row(kind="no-revisit", closures=1, right=0, precision=0.0, revisits=0, found=0, recall=np.nan),
        _row(kind="no-revisit", closures=0, right=0, precision=np.nan, revisits=0, found=0, recall=np.nan),
        _row(right=9, precision=0.9),                                             # precision 90 %
        _row(found=9, recall=0.45),                                               # recall 45 %
        _row(found=9, recall=0.45, day=False),                                    # night: recall stated only
        _row(posed=3, rot_deg=3.0, dir_deg=5.0),                                  # rotation 3 degrees
    ]))
    assert t["met"].tolist() == [True, False, True, False, False, True, False]
    assert t["silent"].tolist()[1:3] == [False, True] and t["recall"][5] is None


def test_short_recordings_writes_one_row_per_cut_configuration_and_verification(cuts, tiny_end_loop_sequence):
    """The table notebook 13 writes: counts that add up, the targets beside them; None (the notebook's
    skip) for a folder that gives no cut (loop pairs, no traversals, no poses)."""
    planted = sr.Cut("planted", ((0, 30), (170, 200)), "revisit")
    out = cuts["out"] / "table"
    table = sr.short_recordings(tiny_end_loop_sequence, out, configurations=(sr.registry.DEFAULT,), cuts=[planted])
    assert len(table) == 2 and table["verify"].tolist() == [False, True]
    assert (table["right"] + table["wrong"] == table["closures"]).all()
    assert (table["verified"] + table["unverified"] == table["closures"]).all()
    assert (out / "short_recordings.md").is_file() and (out / "short_targets.csv").is_file()
    assert sr.short_recordings(tiny_end_loop_sequence, out / "none") is None


def test_traversal_cuts_pair_the_same_places_of_consecutive_walks(tiny_near_loop_sequence, tmp_path):
    """A two-traversal folder (first, second; frame k of each one place +- 1): the middle 30 places of
    each, then the first walk's middle 60 frames alone; in the revisit cut frame 30 + k revisits k."""
    revisit, once = sr.cuts_for(tiny_near_loop_sequence, 30)
    assert revisit == sr.Cut("first-second", ((35, 65), (135, 165)), "revisit", True)
    assert once.kind == "no-revisit" and once.ranges == ((20, 80),)
    gt = groundtruth.for_sequence(sr.build_cut(tiny_near_loop_sequence, revisit, tmp_path), exclude=0)
    k = np.arange(30)
    assert gt[30 + k, k].all() and gt[31, 0] and not gt[40, 0] and not gt[:30, :30].any()
    assert not groundtruth.for_sequence(sr.build_cut(tiny_near_loop_sequence, once, tmp_path), exclude=0).any()


def test_a_cut_outside_its_source_or_out_of_order_is_refused(tiny_end_loop_sequence, tmp_path):
    with pytest.raises(ValueError, match="not within"):
        sr.build_cut(tiny_end_loop_sequence, sr.Cut("bad", ((150, 250),), "revisit"), tmp_path)
    with pytest.raises(ValueError, match="increasing and disjoint"):
        sr.build_cut(tiny_end_loop_sequence, sr.Cut("bad", ((100, 150), (0, 50)), "revisit"), tmp_path)


def test_cuts_are_short_recordings(tiny_near_loop_sequence):
    """Every cut holds CUT_FRAMES[0]..CUT_FRAMES[1] frames: a visit of 20 frames gives none, and more than
    150 frames a visit is refused."""
    assert sr.cuts_for(tiny_near_loop_sequence, 20) == []
    with pytest.raises(ValueError, match="frames a visit"):
        sr.cuts_for(tiny_near_loop_sequence, 151)
