"""greenloop.experiments.leaderboard.rows: notebook 13's rows and tables on small hand-made data (the detectors' own
knobs, scores and streams: tests/test_detectors.py)."""
import math

import numpy as np
import pandas as pd
import pytest

from greenloop import evaluate
from greenloop.experiments.leaderboard import rows as lb
from greenloop.methods.greenloop_seq import seqmatch, seqstream

N0, REPEAT, EX, DIM = 80, 40, 20, 16


@pytest.fixture(scope="module")
def revisit():
    rng = np.random.default_rng(0)
    w = np.cumsum(rng.normal(size=(N0, DIM)), 0).astype(np.float32) * 0.3
    X = np.concatenate([w, w[:REPEAT] + rng.normal(scale=0.3, size=(REPEAT, DIM)).astype(np.float32)])
    n = len(X)
    GT = np.zeros((n, n), bool)
    for k in range(REPEAT):
        GT[max(k - 2, 0):k + 3, N0 + k] = True
    return X, GT | GT.T


def test_reference_mask():
    assert lb.reference_mask([0, 4, 8, 12], None) is None
    assert lb.reference_mask([0, 4, 8, 12], 8).tolist() == [True, True, False, False]
    with pytest.raises(ValueError, match="split"):
        lb.reference_mask([0, 4], 100)






def _hand_gt():
    """10 frames, loops (0,5) (1,6) (2,9) and (3,4), the last inside a band of 2 steps."""
    GT = np.zeros((10, 10), bool)
    for i, j in ((0, 5), (1, 6), (2, 9), (3, 4)):
        GT[i, j] = GT[j, i] = True
    return GT


def test_query_counts_equal_a_hand_count():
    GT, q = _hand_gt(), np.arange(10) >= 4             # queries 4..9, exclude 2 steps
    # loop closure: 4..9 all have an earlier frame more than 2 back; partners: 5 (0), 6 (1), 9 (2), not 4 (3 is inside)
    assert lb.query_counts(GT, 2, q) == {"queries": 6, "revisit_queries": 3}
    assert lb.query_counts(GT, 2, None) == {"queries": 7, "revisit_queries": 3}     # frames 3..9; 3 has no partner
    assert lb.query_counts(GT, 3, q) == {"queries": 6, "revisit_queries": 3}        # 9 - 2 = 7 > 3 still
    assert lb.query_counts(GT, 4, q) == {"queries": 5, "revisit_queries": 3}        # 4 has no candidate (4 - 0 = 4)
    assert lb.query_counts(GT, 5, q) == {"queries": 4, "revisit_queries": 1}        # 6..9; only 9 - 2 = 7 > 5
    # place recognition, database {0, 1, 3} (no exclusion band): 4 (3), 5 (0), 6 (1) have a partner in it, 9 (2) not
    ref = np.isin(np.arange(10), [0, 1, 3])
    assert lb.query_counts(GT, 2, q, ref) == {"queries": 6, "revisit_queries": 3}
    assert np.flatnonzero(evaluate.revisit_queries(GT, 2, q, ref)).tolist() == [4, 5, 6]
    assert np.flatnonzero(evaluate.revisit_queries(GT, 2)).tolist() == [5, 6, 9]     # the old call, unchanged


def test_query_counts_are_what_the_metrics_average_over(revisit):
    X, GT = revisit
    S = seqstream.score_matrix(X, EX, 5, contrast_window=0)
    q = np.arange(len(X)) >= N0 - 10
    for ref in (None, np.arange(len(X)) < N0):
        m = evaluate.per_query(S, GT, EX, queries=q, reference=ref, ks=(1,))
        assert lb.query_counts(GT, EX, q, ref) == {"queries": m["queries"], "revisit_queries": m["revisits"]}
    assert lb.query_counts(GT, EX, q) == {"queries": 50, "revisit_queries": REPEAT}    # frames 70..119; 80..119 revisit


def test_metric_and_chance_rows_are_the_evaluate_functions(revisit):
    X, GT = revisit
    S = seqstream.score_matrix(X, EX, 5, contrast_window=0)
    q = np.zeros(len(X), bool)
    q[N0 - 10:] = True
    ref = np.arange(len(X)) < N0
    rows = lb.metric_rows(S, GT, EX, q, ref)
    assert [r["mode"] for r in rows] == ["loop closure", "place recognition"]
    a = evaluate.per_query(S, GT, EX, queries=q, ks=(1, 5))
    b = evaluate.per_query(S, GT, EX, queries=q, reference=ref, ks=(1, 5))
    assert rows[0]["R@1_%"] == 100 * a["R@1"] and rows[0]["AUC-PR_%"] == 100 * a["AUC-PR"]
    assert {k: rows[0][k] for k in lb.SPREADS} == lb.spread(S, GT, EX, q)
    assert rows[1]["R@5_%"] == 100 * b["R@5"] and rows[1]["R@100P_%"] == 100 * b["R@100P"]
    assert rows[0]["pair_AP_%"] == 100 * evaluate.average_precision(S, GT, EX, queries=q)
    assert math.isnan(rows[1]["pair_AP_%"]) and len(lb.metric_rows(S, GT, EX, q)) == 1
    assert [(r["queries"], r["revisit_queries"]) for r in rows] == [(a["queries"], a["revisits"]),
                                                                     (b["queries"], b["revisits"])]
    c = lb.chance_rows(GT, EX, q, None, "evaluation queries")
    ch = evaluate.query_chance(GT, EX, queries=q, ks=(1, 5))
    assert len(c) == 1 and c[0]["R@1_%"] == 100 * ch["R@1"] and c[0]["scored_on"] == "evaluation queries"
    assert c[0]["pair_AP_%"] == 100 * evaluate.chance_level(GT, EX, queries=q)
    assert (c[0]["queries"], c[0]["revisit_queries"]) == (rows[0]["queries"], rows[0]["revisit_queries"])
    assert rows[0]["R@1_%"] > c[0]["R@1_%"] + 30


def test_rounded_is_the_written_form_and_write_writes_it(tmp_path):
    board = lb.table([{"method": "m", "mode": "loop closure", "R@1_%": 100 / 3, "AUC-PR_lo_%": 2 / 3, "threshold": 1 / 7,
                       "fps_median": 1234.56, "decode_ms": 0.1234},
                      {"method": "d", "mode": "loop closure", "threshold": 70}])
    r = lb.rounded(board)
    assert r.loc[0, "R@1_%"] == 33.33 and r.loc[0, "AUC-PR_lo_%"] == 0.67 and r.loc[0, "threshold"] == 0.1429
    assert r.loc[0, "fps_median"] == 1234.6 and r.loc[0, "decode_ms"] == 0.12 and r.loc[1, "threshold"] == 70
    assert math.isnan(r.loc[1, "R@1_%"]) and board.loc[0, "R@1_%"] == 100 / 3          # the input stays unrounded
    csv = lb.write(board, tmp_path / "13", tmp_path, "T", "n")[0]
    assert pd.read_csv(csv).loc[0, "R@1_%"] == 33.33


def test_thresholds_and_closures(revisit):
    X, GT = revisit
    S = {"seq": seqstream.score_matrix(X, EX, 5, contrast_window=0)}
    tune, ev = evaluate.split_mask(len(X), 0.5, gt=GT, gap=5)
    t = lb.thresholds(S, GT, EX, tune, "f1")
    assert t["seq"] == seqmatch.choose_threshold(S["seq"], GT, EX, queries=tune)
    assert math.isnan(lb.thresholds(S, GT, EX, None, "f1")["seq"])
    assert lb.thresholds(S, GT, EX, tune, "f1", fixed={"seq": 1.8}) == {"seq": 1.8}      # a fixed threshold is kept
    assert lb.thresholds(S, GT, EX, None, "f1", fixed={"seq": 1.8}) == {"seq": 1.8}
    c = lb.closure_columns(S["seq"], GT, t["seq"], EX, ev, 4)
    ref = seqmatch.closures(S["seq"], GT, t["seq"], EX, queries=ev)
    assert c["closures_declared"] == ref["declared"] and c["first_revisit_delay_frames"] == 4 * ref["first_delay"]
    assert lb.closure_columns(S["seq"], GT, float("nan"), EX, ev, 4)["closures_declared"] is None


def test_timing_window_and_methods(revisit):
    X, _ = revisit
    ev = np.zeros(10, bool)
    ev[6:] = True
    assert lb.timing_window(ev, 3) == (6, 9) and lb.timing_window(ev, 30) == (6, 10)
    assert lb.timing_window(np.ones(10, bool), 4) == (6, 10)             # no split: the last frames
    knobs = {"seq": {"descriptor": "cnn", "whitening": "none", "seq_len": 3, "contrast_window": 0}}
    dets = {"seq": seqstream.Detector(None, seq_len=3, exclude=EX, contrast_window=0)}
    m, pre = lb.timing_methods(knobs, dets, {"seq": lambda f: f}, {"cnn": X}, 50)
    assert [x.name for x in m] == ["seq"] and len(pre["seq"]) == 50
    assert m[0].start(pre["seq"]).frame_index == 50


def _board():
    spread = {"R@1_lo_%": 85.0, "R@1_hi_%": 95.0, "AUC-PR_lo_%": 70.0, "AUC-PR_hi_%": 90.0}
    return lb.table([
        {"method": "greenloop-seq", "mode": "loop closure", "R@1_%": 90.0, "AUC-PR_%": 80.0, "R@100P_%": 40.0,
         "fps_median": 1000.0, "fps_min": 950.0, "fps_max": 1100.0, **spread},
        {"method": "pixels (single frame)", "mode": "loop closure", "R@1_%": 70.0, "AUC-PR_%": 85.0, "R@100P_%": 10.0,
         "fps_median": 900.0, "fps_min": 800.0, "fps_max": 960.0,
         "R@1_lo_%": 60.0, "R@1_hi_%": 80.0, "AUC-PR_lo_%": 75.0, "AUC-PR_hi_%": 95.0},
        {"method": "SeqSLAM (published)", "mode": "loop closure", "R@1_%": 50.0, "AUC-PR_%": 30.0, "R@100P_%": 0.0,
         "fps_median": 100.0, "fps_min": 90.0, "fps_max": 110.0,
         "R@1_lo_%": 40.0, "R@1_hi_%": 60.0, "AUC-PR_lo_%": 20.0, "AUC-PR_hi_%": 40.0},
        {"method": "chance (random scores)", "mode": "loop closure", "R@1_%": 5.0, "AUC-PR_%": 1.0, "R@100P_%": 0.0}])


def _comparisons(resolved_r1=True):
    """The paired comparisons of _board's greenloop-seq with its two other rows (as lb.comparisons writes them)."""
    rows = [("pixels (single frame)", "R@1", 20.0, 12.0, 28.0, True), ("pixels (single frame)", "AUC-PR", -5.0, -12.0, 2.0, False),
            ("SeqSLAM (published)", "R@1", 40.0, 30.0, 50.0, resolved_r1), ("SeqSLAM (published)", "AUC-PR", 50.0, 40.0, 60.0, True)]
    return pd.DataFrame([dict(zip(lb.COMPARISON_COLUMNS, ("greenloop-seq",) + r + (60,))) for r in rows])


def test_table_targets_and_statement():
    b, c = _board(), _comparisons()
    assert list(b.columns) == lb.COLUMNS
    t = lb.targets(b, ["greenloop-seq"], c)
    assert t == {"greenloop-seq": {"highest_R@1": True, "highest_AUC-PR": False, "fps_min_at_least_920": True}}
    s = lb.statement(b, c, ["greenloop-seq"])
    assert "R@1 90.00 % [85.00, 95.00]" in s and "vs pixels (single frame) (R@1 70.00 %, AUC-PR 85.00 %;" in s
    assert ("R@1 higher than it (difference 20.00 [12.00, 28.00]), AUC-PR not resolved (difference -5.00 [-12.00, 2.00]), "
            "speed not resolved against it (900 frames/s") in s
    assert "vs SeqSLAM (published)" in s and "speed faster than it (100 frames/s" in s and "chance: R@1 5.00 %" in s
    assert "R@1 above 2, below 0, not resolved against 0 of the 2 other rows; AUC-PR above 1, below 0" in s
    b.loc[1, "fps_max"], b.loc[1, "R@1_hi_%"] = 900.0, 86.0        # the rows' R@1 intervals now overlap: the table rules
    s = lb.statement(b, c, ["greenloop-seq"])
    assert "R@1 higher than it (difference 20.00" in s and "speed faster than it (900 frames/s" in s
    c.loc[0, "resolved"] = False
    assert "R@1 not resolved (difference 20.00 [12.00, 28.00])" in lb.statement(b, c, ["greenloop-seq"])
    assert lb.targets(b, ["greenloop-seq"], c)["greenloop-seq"]["highest_R@1"] is False
    assert lb.targets(b, ["greenloop-seq"], c[c.b != "pixels (single frame)"])["greenloop-seq"]["highest_R@1"] is False


def test_spread_brackets_the_metric_and_widens_with_fewer_queries(revisit):
    X, GT = revisit
    S = seqstream.score_matrix(X, EX, 5, contrast_window=0)
    q = np.zeros(len(X), bool)
    q[N0 - 10:] = True
    sp = lb.spread(S, GT, EX, q, block=5, n_boot=100)
    m = evaluate.per_query(S, GT, EX, queries=q, ks=(1,))
    assert sp["R@1_lo_%"] <= 100 * m["R@1"] <= sp["R@1_hi_%"] and sp["AUC-PR_lo_%"] <= 100 * m["AUC-PR"] <= sp["AUC-PR_hi_%"]
    assert sp == lb.spread(S, GT, EX, q, block=5, n_boot=100)          # seeded
    noisy = S + np.random.default_rng(3).normal(scale=0.05, size=S.shape).astype(np.float32)
    few = np.zeros(len(X), bool)
    few[N0 + 20:] = True
    a, b = lb.spread(noisy, GT, EX, q, block=5), lb.spread(noisy, GT, EX, few, block=5)
    assert b["R@1_hi_%"] - b["R@1_lo_%"] >= a["R@1_hi_%"] - a["R@1_lo_%"]


def test_write_makes_the_copy_from_one_serialisation(tmp_path, monkeypatch):
    b = _board()
    calls = []
    real = pd.DataFrame.to_csv
    monkeypatch.setattr(pd.DataFrame, "to_csv", lambda self, *a, **k: calls.append(1) or real(self, *a, **k))
    csv, md, copy = lb.write(b, tmp_path / "13_leaderboard", tmp_path, "T", "the note")
    assert calls == [1] and copy == tmp_path / "leaderboard.csv"
    assert csv.read_bytes() == copy.read_bytes() and pd.read_csv(copy).method.tolist() == b.method.tolist()
    assert md.read_text().startswith("### T\n") and md.read_text().rstrip().endswith("the note")


def test_dictionary_row():
    r = lb.dictionary_row("dict", 70, 500, {"declared": 3, "false": 1, "first_delay": 2}, {"precision": 0.5, "recall": 0.25},
                          {"fps_median": 10.0, "fps_min": 9.0, "fps_max": 11.0, "decode_ms": 1.0}, 4, "evaluation queries")
    assert r["first_revisit_delay_frames"] == 8 and r["threshold"] == 70 and "0..499" in r["knobs"]
    assert r["scored_on"].startswith("evaluation queries; decisions only") and r["bytes_per_stored_frame"] == 0
    assert "queries" not in r
    counts = lb.query_counts(_hand_gt(), 2, np.arange(10) >= 4)
    r = lb.dictionary_row("dict", 70, 500, {"declared": 3, "false": 1, "first_delay": 2}, {"precision": 0.5, "recall": 0.25},
                          {}, 4, "evaluation queries", counts)
    assert (r["queries"], r["revisit_queries"]) == (6, 3)
    assert lb.table([r]).loc[0, lb.COUNTS].tolist() == [6, 3]


def test_method_rows_one_per_mode_with_closures_in_loop_closure_only(revisit):
    X, GT = revisit
    S = {"seq": seqstream.score_matrix(X, EX, 5, contrast_window=0)}
    tune, ev = evaluate.split_mask(len(X), 0.5, gt=GT, gap=5)
    thr = lb.thresholds(S, GT, EX, tune, "f1")
    meta = {"seq": {"weights": "none", "knobs": "k", "bytes_per_stored_frame": 80}}
    speed = {"seq": {"fps_median": 10.0, "fps_min": 9.0, "fps_max": 12.0, "decode_ms": 0.5}}
    ref = np.arange(len(X)) < N0
    rows = lb.method_rows(S, meta, GT, EX, ev, ref, thr, speed, 2, "evaluation queries")
    assert [r["mode"] for r in rows] == ["loop closure", "place recognition"]
    assert rows[0]["closures_declared"] == lb.closure_columns(S["seq"], GT, thr["seq"], EX, ev, 2)["closures_declared"]
    assert rows[1]["closures_declared"] is None and math.isnan(rows[1]["threshold"])
    assert rows[0]["fps_min"] == rows[1]["fps_min"] == 9.0 and rows[0]["bytes_per_stored_frame"] == 80
    assert rows[1]["R@1_%"] == lb.metric_rows(S["seq"], GT, EX, ev, ref)[1]["R@1_%"]



def test_targets_table_judges_the_named_target_set_and_refuses_a_folder_name():
    board = pd.DataFrame([{"method": "greenloop-seq-grad", "mode": "loop closure", "R@1_%": 50.0}])
    t = lb.targets_table(board, "generic", 1)                    # a user's folder: the generic targets
    assert t.target.str.startswith("R@1 not below the best row").any() and not t.target.str.startswith("frame step").any()
    with pytest.raises(ValueError, match="none of the target sets"):
        lb.targets_table(board, "data/my-indoor-walk", 1)
    t = lb.targets_table(board, "nordland", 8)
    step = t[t.target.str.startswith("frame step")].iloc[0]
    assert step.measured == 8 and step.met is False or step.met == False   # noqa: E712 (numpy bool)


def test_targets_table_judges_each_named_configuration_on_its_own_sequence_length(monkeypatch):
    """Each named configuration on the board gets its rows, its "frames of sequence" from its own knobs:
    one with 20 frames fails Nordland's <= 10 while the named default (10) meets it."""
    from greenloop.methods.greenloop_seq import seqmatch
    long = dict(seqmatch.CNN_KNOBS, seq_len=20)
    monkeypatch.setattr(seqmatch, "NAMED", {**seqmatch.NAMED, seqmatch.CNN_NAME: (long, seqmatch.CNN_THRESHOLD)})
    board = pd.DataFrame([{"method": m, "mode": "loop closure", "R@1_%": 50.0}
                          for m in (seqmatch.DEFAULT_NAME, seqmatch.CNN_NAME)])
    t = lb.targets_table(board, "nordland", 1)
    seq = t[t.target == "frames of sequence"].set_index("configuration")
    assert seq.loc[seqmatch.DEFAULT_NAME, "measured"] == 10 and bool(seq.loc[seqmatch.DEFAULT_NAME, "met"])
    assert seq.loc[seqmatch.CNN_NAME, "measured"] == 20 and not bool(seq.loc[seqmatch.CNN_NAME, "met"])
    only = lb.targets_table(board[board.method == seqmatch.DEFAULT_NAME], "nordland", 1)
    assert set(only.configuration) == {seqmatch.DEFAULT_NAME}


def test_weights_kind_names_each_kind_of_weights():
    assert lb.weights_kind("imagenet, tflite uint8") == "imagenet" and lb.weights_kind("random init") == "random init"
    assert lb.weights_kind("trained here") == "trained here"              # the Siamese row's network
    assert lb.weights_kind("none") == "none" and lb.weights_kind(None) == "none"


def test_threshold_check_without_an_honest_split_reports_the_fixed_threshold_only(revisit):
    """A recording without a tuning part (data.tune None, every query an evaluation query) has no
    p95 pick: the fixed threshold's closures are still counted, the pick's columns are NaN (this
    raised KeyError: 'precision' and stopped make quick on a user's recording)."""
    from greenloop.methods.interface import Data
    from greenloop.experiments import leaderboard as exp
    X, GT = revisit
    n, name = len(X), exp.NAMED[0]
    S = seqstream.score_matrix(X, exclude=EX, seq_len=5)
    data = Data("user-recording", 1, np.arange(n), GT, EX, None, np.ones(n, bool), {}, {}, {}, {})
    tuned = exp.Tuned(pd.DataFrame(), {name: {"fixed_threshold": 0.5}}, {}, {}, {}, {name: S})
    (row,) = exp.threshold_check(data, tuned)
    want = seqmatch.closures(S, GT, 0.5, EX, np.ones(n, bool))
    assert want["declared"] > 0
    assert row["declared_at_fixed"] == want["declared"]
    assert row["precision_at_fixed_%"] == round(100 * want["precision"], 2)
    assert math.isnan(row["threshold_tuning_p95"]) and math.isnan(row["declared_at_tuning_p95"])
    assert math.isnan(row["precision_at_tuning_p95_%"])
    assert (row["queries"], row["revisit_queries"]) == (n - EX - 1, REPEAT)    # frames 21..119; 80..119 revisit


def test_targets_table_says_how_many_queries_each_measured_target_rests_on():
    from greenloop.methods.greenloop_seq import seqmatch
    name = seqmatch.DEFAULT_NAME
    board = pd.DataFrame([{"method": name, "mode": "loop closure", "queries": 180, "revisit_queries": 150, "R@1_%": 80.0,
                           "R@100P_%": 40.0, "fps_min": 1000.0, "closures_declared": 10, "closures_false": 0},
                          {"method": name, "mode": "place recognition", "queries": 400, "revisit_queries": 380,
                           "R@1_%": 95.0, "R@100P_%": 60.0}])
    t = lb.targets_table(board, "gardenspoint", 1).set_index("target")
    assert t.loc["R@1 (%), place recognition", lb.COUNTS].tolist() == [400, 380]
    assert t.loc["closure precision at the threshold (%)", lb.COUNTS].tolist() == [180, 150]
    assert t.loc["frames/s (slowest repeat)", lb.COUNTS].isna().all()       # no query count bears on a frame rate
    n = lb.targets_table(board, "nordland", 8).set_index("target")
    assert n.loc["R@1 (%), loop closure", lb.COUNTS].tolist() == [180, 150]
    assert n.loc["frame step of the rows (1 = Nordland's full rate)", lb.COUNTS].isna().all()
    assert "180," in t.to_csv() and "180.0" not in t.to_csv()                # whole numbers, blank where not counted


def _two_traversals(n: int, tol: int, step: int, exclude: int):
    """The ground truth of every step-th frame of two aligned traversals of n frames (frame k of each
    the same place +- tol), pairs within ``exclude`` original frames left out, and the band in steps."""
    from greenloop import groundtruth
    from greenloop.datasets import sequence
    pairs = sequence.aligned_pairs([(0, n), (n, 2 * n)], tol)
    return groundtruth.pair_matrix(pairs, 2 * n, np.arange(0, 2 * n, step), exclude), exclude // step


def test_evaluation_revisits_count_the_revisit_queries_after_the_split():
    from greenloop.experiments import leaderboard as exp
    GT, ex = _two_traversals(40, 0, 1, 10)              # frames 40..79 revisit 0..39 exactly
    tune, evq = evaluate.split_mask(80, 0.5, gt=GT, gap=5)
    assert np.flatnonzero(evq)[0] == 65                 # revisits 40..59 tune, gap 60..64, evaluate 65..79
    assert exp.evaluation_revisits(GT, ex, 0.5, 5) == 15
    assert exp.evaluation_revisits(GT, ex, 0.5, 50) == 40    # no honest split: every query is scored
    assert exp.evaluation_revisits(np.zeros((80, 80), bool), ex, 0.5, 5) == 0


def test_largest_step_keeps_the_requested_step_or_the_largest_smaller_one_with_enough_revisits():
    from greenloop.experiments import leaderboard as exp
    counts = {8: 14, 7: 30, 6: 45, 5: 52, 4: 60, 3: 80, 2: 120, 1: 240}
    assert exp.largest_step(8, counts.get, 50) == (5, {8: 14, 7: 30, 6: 45, 5: 52})   # stops at the first that does
    assert exp.largest_step(4, counts.get, 50) == (4, {4: 60})
    assert exp.largest_step(8, counts.get, 500) == (1, counts)                      # none does: every frame
    assert exp.largest_step(1, counts.get, 500) == (1, {1: 240})


def test_step_rule_on_two_traversals_lowers_a_coarse_step_and_keeps_a_fine_one():
    """A 222-frame corridor walked twice: every 8th frame leaves 5 evaluation revisit queries, every
    frame 78; an 800-frame one: step 3 is the largest to leave 50 (step 4: 45); a 6000-frame drive
    keeps step 8."""
    from greenloop.experiments import leaderboard as exp

    def at(n, tol, exclude, tune, gap):
        return lambda s: exp.evaluation_revisits(*_two_traversals(n, tol, s, exclude), tune, gap)

    step, seen = exp.largest_step(8, at(111, 2, 50, 0.25, 5), 50)
    assert step == 1 and seen[8] == 5 and seen[2] == 36 and seen[1] == 78
    step, seen = exp.largest_step(8, at(400, 4, 50, 0.5, 5), 50)
    assert step == 3 and (seen[4], seen[3]) == (45, 62) and min(seen) == 3
    step, seen = exp.largest_step(8, at(3000, 15, 150, 0.5, 20), 50)
    assert step == 8 and list(seen) == [8] and seen[8] >= 50
    why = exp.step_text(3, 8, {8: 20, 4: 45, 3: 62}, 50)
    assert why.startswith("frame_step 3, not the requested 8") and "20 evaluation revisit queries (< 50)" in why


def test_choose_step_is_the_step_prepare_then_scores(tmp_path):
    """On a folder (222 frames, ground_truth.csv: two traversals +- 2 frames): the step chosen, and
    the revisit count it was chosen by, are those of the evaluation part prepare builds at it."""
    from conftest import write_frames
    from greenloop.datasets import sequence
    from greenloop.experiments import leaderboard as exp
    folder = write_frames(tmp_path / "corridor", 222, size=(8, 8))
    sequence.write_loop_pairs(folder / sequence.GROUND_TRUTH_NAME, sequence.aligned_pairs([(0, 111), (111, 222)], 2))
    params = {"seq_lens": [5], "fps_frames": 10}
    step = exp.choose_step(str(folder), 8, 0.5, 50, 0.25, params, 50)
    assert (step.step, step.requested, step.revisits[8], step.revisits[1]) == (1, 8, 5, 78)
    data, _ = exp.prepare(str(folder), step.step, 0.5, 50, 0.25, None, params)
    assert lb.query_counts(data.GT, data.exclude, data.evalq)["revisit_queries"] == 78
    assert exp.choose_step(str(folder), 8, 0.5, 50, 0.25, params, 5).step == 8      # 5 is enough: kept
    assert step.why.startswith("frame_step 1, not the requested 8: step 8 would leave 5")


def test_the_r1_bars_carry_each_rows_interval_and_its_colour():
    """figure_r1: every loop-closure row one bar, best first, a whisker from R@1_lo to R@1_hi (none
    where the interval is missing), the colour method_colours gives it (figure_pr's)."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.colors import to_rgba
    from greenloop.experiments import leaderboard as exp
    t = pd.DataFrame({"method": ["a", "b", "chance (random scores)", "c"], "mode": ["loop closure"] * 4,
                      "R@1_%": [60.0, 80.0, 5.0, 70.0], "R@1_lo_%": [50.0, 75.0, 1.0, np.nan],
                      "R@1_hi_%": [65.0, 90.0, 9.0, np.nan]})
    fig = exp.figure_r1(t)
    ax = fig.axes[0]
    from matplotlib.container import BarContainer
    bars = next(c for c in ax.containers if isinstance(c, BarContainer))
    assert [p.get_width() for p in bars.patches] == [80.0, 70.0, 60.0, 5.0]
    colours = exp.method_colours(t.method)
    assert [p.get_facecolor() for p in bars.patches] == [to_rgba(colours[m]) for m in ["b", "c", "a", "chance (random scores)"]]
    segments = bars.errorbar.lines[2][0].get_segments()
    spans = [(round(s[0][0], 6), round(s[1][0], 6)) for s in segments]
    assert spans == [(75.0, 90.0), (70.0, 70.0), (50.0, 65.0), (1.0, 9.0)]
    assert len(set(colours.values())) == 4


def test_the_r1_bars_hatch_every_bar_tied_with_the_top_by_its_paired_interval():
    """Sorted bars suggest an order; the paired comparisons decide it: a bar whose paired R@1 interval
    with the top bar holds 0 is hatched as tied, one never compared with it dotted, a resolved one plain."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.container import BarContainer
    from greenloop.experiments import leaderboard as exp
    t = pd.DataFrame({"method": ["a", "b", "chance (random scores)", "c", "d"], "mode": ["loop closure"] * 5,
                      "R@1_%": [60.0, 80.0, 5.0, 79.0, 50.0], "R@1_lo_%": np.nan, "R@1_hi_%": np.nan})
    comp = pd.DataFrame([("b", "c", "R@1", 1.0, -2.0, 4.0, False, 50),       # b over c: a tie
                         ("a", "b", "R@1", -20.0, -30.0, -10.0, True, 50),   # a below b: resolved
                         ("b", "c", "AUC-PR", 9.0, 2.0, 12.0, True, 50)],    # another metric: not read
                        columns=lb.COMPARISON_COLUMNS)
    order = t[t["mode"] == "loop closure"].sort_values("R@1_%", ascending=False)
    assert exp.ties_with_top(order, comp) == {"b": "top", "c": "tie", "a": "below", "d": "not compared",
                                              "chance (random scores)": "not compared"}
    ax = exp.figure_r1(t, comp).axes[0]
    bars = next(c for c in ax.containers if isinstance(c, BarContainer))
    assert [p.get_hatch() for p in bars.patches] == ["", "///", None, "..", ".."]      # b, c, a, d, chance
    assert "1 of 4 bars tied with the top (b)" in ax.get_title()
    assert [x.get_text() for x in ax.texts] == ["top bar", "tied with the top", "not compared with the top",
                                                "not compared with the top"]
    assert exp.ties_with_top(order, None)["c"] == "not compared"
