"""greenloop.study.targets: the detector's targets judged from hand-made leaderboard rows, by the target
set a dataset's sequence.yaml names (its protocol; generic where it names none)."""
import math

import pandas as pd
import pytest

from greenloop.datasets import sequence
from greenloop.study import targets
from greenloop.study.targets import detector_targets, TARGET_SETS


def _met(out):
    return {r["target"].split(" (")[0]: r["met"] for r in out}


def test_nordland_targets_met_and_not_met():
    rows = [{"method": "greenloop-seq", "mode": "loop closure", "R@1_%": 96.0, "R@100P_%": 59.9, "fps_min": 919.0,
             "closures_declared": 100, "closures_false": 10, "R@1_lo_%": 93.0, "R@1_hi_%": 98.0},
            {"method": "SeqSLAM", "mode": "loop closure", "R@1_%": 96.5, "R@100P_%": 10.0, "R@1_lo_%": 94.0, "R@1_hi_%": 99.0}]
    out = detector_targets(rows, "nordland", seq_len=10)
    m = {r["target"]: r for r in out}
    assert m["R@1 (%), loop closure"]["met"] is True and m["R@1 (%), loop closure"]["measured"] == 96.0
    assert m["frames of sequence"]["met"] is True
    assert m["R@100P (%), loop closure"]["met"] is False                   # 59.9 < 60
    above = m["R@1 above SeqSLAM (96.5 %): the low end of its interval"]
    assert above["met"] is False and above["measured"] == 93.0 and above["required"] == "> 99.0"
    assert m["frames/s (slowest repeat)"]["met"] is False                  # 919 < 920
    assert m["closure precision at the threshold (%)"]["measured"] == 90.0
    assert m["closure precision at the threshold (%)"]["met"] is True      # 90 of 100 right: exactly 90 %
    assert {r["target"]: r for r in detector_targets(rows, "nordland", seq_len=11)}["frames of sequence"]["met"] is False
    step = {r["target"]: r for r in detector_targets(rows, "nordland", seq_len=10, frame_step=8)}
    assert step["frame step of the rows (1 = Nordland's full rate)"]["met"] is False
    assert m["frame step of the rows (1 = Nordland's full rate)"]["met"] is None   # not given: not measured
    for r1, met in ((92.0, True), (91.9, False)):                           # the target: R@1 >= 92
        rows[0]["R@1_%"] = r1
        assert _met(detector_targets(rows, "nordland", seq_len=10))["R@1"] is met


def test_gardenspoint_reads_place_recognition_and_absent_values_are_not_measured():
    rows = pd.DataFrame([{"method": "greenloop-seq", "mode": "loop closure", "R@1_%": 10.0, "R@100P_%": 5.0},
                         {"method": "greenloop-seq", "mode": "place recognition", "R@1_%": 94.0,
                          "R@100P_%": 72.0, "fps_min": math.nan}])
    m = _met(detector_targets(rows, "gardenspoint"))
    assert m["R@1"] is True and m["R@100P"] is True                        # the loop-closure 10 % is not read
    assert m["frames/s"] is None and m["closure precision at the threshold"] is None


def _spread(v, half):
    return {"R@1_%": v, "R@1_lo_%": v - half, "R@1_hi_%": v + half,
            "AUC-PR_%": v - 10, "AUC-PR_lo_%": v - 10 - half, "AUC-PR_hi_%": v - 10 + half}


def test_generic_not_below_the_best_row_ignores_chance_and_reads_the_best_point():
    """Rows alone: met where the method's R@1 interval reaches the best other row's point value."""
    rows = [{"method": "greenloop-seq", "mode": "loop closure", **_spread(80.0, 2.0)},
            {"method": "SeqSLAM", "mode": "loop closure", **_spread(70.0, 3.0)},
            {"method": "pixels (single frame)", "mode": "loop closure", **_spread(60.0, 5.0)},
            {"method": "chance (random scores)", "mode": "loop closure", "R@1_%": 99.0, "AUC-PR_%": 99.0}]
    out = detector_targets(rows)                                            # generic: the default set
    assert out[0]["met"] is True and out[0]["measured"] == 82.0 and out[0]["required"] == ">= 70.0"
    rows[1].update(_spread(81.0, 3.0))                                      # 81 > 80, and 82 reaches it
    assert detector_targets(rows, "generic")[0]["met"] is True
    rows[1].update(_spread(83.0, 1.0))                                      # 82 < 83: below the best row
    assert detector_targets(rows, "generic")[0]["met"] is False
    rows[0].pop("R@1_hi_%")                                                 # no interval: not measured
    assert detector_targets(rows, "generic")[0]["met"] is None
    missing = detector_targets(rows[1:], "generic")                       # no greenloop-seq row
    assert all(r["met"] is None for r in missing)


def test_an_unknown_target_set_names_the_accepted_ones_and_the_sets_are_the_protocols():
    with pytest.raises(ValueError, match="none of the target sets generic, nordland, gardenspoint"):
        detector_targets([], "data/nordland")                               # a folder name is no target set
    assert tuple(TARGET_SETS) == sequence.PROTOCOL_TARGETS                  # what sequence.yaml may name


def test_nordland_judges_every_seqslam_row_named():
    rows = [{"method": "greenloop-seq", "mode": "loop closure", **_spread(90.0, 4.0)},
            {"method": "SeqSLAM (published)", "mode": "loop closure", **_spread(70.0, 4.0)},
            {"method": "SeqSLAM (tuned)", "mode": "loop closure", **_spread(88.0, 4.0)}]
    m = {r["target"].split(":")[0]: r["met"] for r in
         detector_targets(rows, "nordland", seqslam=("SeqSLAM (published)", "SeqSLAM (tuned)"))}
    assert m["R@1 above SeqSLAM (published) (70.0 %)"] is True
    assert m["R@1 above SeqSLAM (tuned) (88.0 %)"] is False                # 90 > 88, but the intervals overlap
    absent = {r["target"].split(":")[0]: r["met"] for r in detector_targets(rows[:1], "nordland", seqslam=("SeqSLAM (tuned)",))}
    assert absent["R@1 above SeqSLAM (tuned) (not measured %)"] is None


def _paired(rows):
    """A comparisons table (experiments.leaderboard.rows.comparisons' columns) of greenloop-seq against each b."""
    return pd.DataFrame([{"a": "greenloop-seq", "b": b, "metric": m, "difference": d, "lo": lo, "hi": hi,
                          "resolved": lo > 0 or hi < 0, "queries": 100} for b, m, d, lo, hi in rows])


def test_with_comparisons_above_and_highest_are_the_paired_differences_not_the_intervals():
    """SeqSLAM (tuned)'s interval overlaps greenloop-seq's, but their paired difference is resolved:
    above; SeqSLAM (published)'s intervals separate, but the table says not resolved: not above."""
    rows = [{"method": "greenloop-seq", "mode": "loop closure", **_spread(90.0, 4.0)},
            {"method": "SeqSLAM (published)", "mode": "loop closure", **_spread(70.0, 4.0)},
            {"method": "SeqSLAM (tuned)", "mode": "loop closure", **_spread(88.0, 4.0)}]
    comp = _paired([("SeqSLAM (published)", "R@1", 20.0, -0.5, 40.0), ("SeqSLAM (tuned)", "R@1", 2.0, 0.5, 3.5)])
    out = {r["target"].split(":")[0]: r for r in
           detector_targets(rows, "nordland", seqslam=("SeqSLAM (published)", "SeqSLAM (tuned)"), comparisons=comp)}
    pub, tuned = out["R@1 above SeqSLAM (published) (70.0 %)"], out["R@1 above SeqSLAM (tuned) (88.0 %)"]
    assert pub["met"] is False and pub["measured"] == -0.5
    assert tuned["met"] is True and tuned["measured"] == 0.5 and tuned["required"].startswith("> 0, each resolved")
    absent = detector_targets(rows, "nordland", seqslam=("SeqSLAM (tuned)",), comparisons=comp.iloc[:1])
    assert [r["met"] for r in absent if r["target"].startswith("R@1 above")] == [None]     # no such row: not measured
    comp = _paired([("SeqSLAM (published)", "R@1", 20.0, 10.0, 30.0), ("SeqSLAM (tuned)", "R@1", 2.0, 0.5, 3.5),
                    ("SeqSLAM (published)", "AUC-PR", 20.0, 10.0, 30.0), ("SeqSLAM (tuned)", "AUC-PR", 2.0, -1.0, 4.0)])
    first = detector_targets(rows, "generic", comparisons=comp)[0]
    assert first["target"].startswith("R@1 not below the best row")
    assert first["met"] is True and first["measured"] == 3.5                     # the lowest high end
    comp = _paired([("SeqSLAM (published)", "R@1", 20.0, 10.0, 30.0), ("SeqSLAM (tuned)", "R@1", -2.0, -3.5, -0.5)])
    below = detector_targets(rows, "generic", comparisons=comp)[0]
    assert below["met"] is False and below["measured"] == -0.5                   # resolved below the tuned row
    comp = _paired([("SeqSLAM (published)", "R@1", 20.0, 10.0, 30.0), ("SeqSLAM (tuned)", "R@1", -2.0, -3.5, 0.5)])
    assert detector_targets(rows, "generic", comparisons=comp)[0]["met"] is True  # behind, not resolved: not below


@pytest.mark.parametrize("lo, hi, word", [(0.5, 3.0, "resolved"), (-3.0, -0.5, "resolved"), (0.0, 0.0, "tie"),
                                          (-61.19, 0.0, "uninformative"), (0.0, 78.05, "uninformative"),
                                          (-3.5, 0.5, "not resolved")])
def test_a_paired_interval_is_worded_by_one_rule(lo, hi, word):
    assert targets.paired_word(lo, hi) == word
    assert word in targets.PAIRED_RULE


def test_a_paired_bound_of_exactly_zero_from_few_blocks_is_uninformative_not_met():
    """The synthetic set's ten-block bootstrap: greenloop-seq's paired high end against its best rival
    lands on exactly 0.0. "Not below the best row" is then neither met nor not met; both ends 0 (the
    same on every resample) is a tie, which is not below: met; a low end of 0 is not "above"."""
    rows = [{"method": "greenloop-seq", "mode": "loop closure", **_spread(80.0, 2.0)},
            {"method": "SeqSLAM (tuned)", "mode": "loop closure", **_spread(88.0, 4.0)}]
    first = detector_targets(rows, "generic", comparisons=_paired([("SeqSLAM (tuned)", "R@1", -8.0, -20.0, 0.0)]))[0]
    assert first["met"] is None and first["measured"] == 0.0 and "uninformative" in first["required"]
    assert targets.met_word({**first, "met": True}) == "uninformative"     # a row written before the rule
    tie = detector_targets(rows, "generic", comparisons=_paired([("SeqSLAM (tuned)", "R@1", 0.0, 0.0, 0.0)]))[0]
    assert tie["met"] is True                                            # the same on every resample: not below
    above = detector_targets(rows, "nordland", seqslam="SeqSLAM (tuned)",
                             comparisons=_paired([("SeqSLAM (tuned)", "R@1", 5.0, 0.0, 10.0)]))
    assert [r["met"] for r in above if r["target"].startswith("R@1 above")] == [None]


def test_a_paired_interval_without_an_end_is_refused():
    with pytest.raises(ValueError, match="both ends"):
        targets.paired_word(None, 1.0)
