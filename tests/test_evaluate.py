"""Unit tests of greenloop.evaluate: hand-made examples plus the real GreenHouse trajectory."""
from pathlib import Path

import numpy as np
import pytest

from greenloop import evaluate as ev
from greenloop.groundtruth import loop_matrix, pose_error

GREENHOUSE = Path(__file__).resolve().parents[2] / "shared" / "greenhouse"

# --------------------------------------------------------------------- a hand-made example
# 7 frames, exclude = 2: the counted pairs are i < j with j - i >= 3 (10 pairs).
N, EXCL = 7, 2
PAIRS = {  # (i, j): (score, is_loop)   ranked by score: + - + + - - - + - -
    (0, 3): (0.95, True),
    (1, 4): (0.90, False),
    (0, 4): (0.85, True),
    (1, 5): (0.80, True),
    (2, 5): (0.70, False),
    (0, 5): (0.60, False),
    (1, 6): (0.50, False),
    (3, 6): (0.40, True),
    (0, 6): (0.30, False),
    (2, 6): (0.20, False),
}


def hand_example():
    S = np.zeros((N, N))
    GT = np.zeros((N, N), dtype=bool)
    for (i, j), (s, y) in PAIRS.items():
        S[i, j] = S[j, i] = s
        GT[i, j] = GT[j, i] = y
    # inside the exclusion window: a "loop" with the top score, which must be ignored
    S[2, 3] = S[3, 2] = 0.99
    GT[2, 3] = GT[3, 2] = True
    S[4, 5] = S[5, 4] = 0.98
    return S, GT


def stepwise_ap_by_hand(scores, labels):
    """AP = sum over ranks n of (R_n - R_{n-1}) P_n, distinct scores, highest first."""
    order = np.argsort(scores)[::-1]
    lab = np.asarray(labels)[order]
    tp = np.cumsum(lab)
    precision = tp / np.arange(1, len(lab) + 1)
    recall = tp / lab.sum()
    prev = np.concatenate([[0.0], recall[:-1]])
    return float(np.sum((recall - prev) * precision))


def test_pair_scores_counts_each_far_pair_once_and_ignores_the_window():
    S, GT = hand_example()
    y, s = ev.pair_samples(S, GT, exclude=EXCL)
    assert len(y) == len(PAIRS) == 10
    assert sorted(s.tolist()) == sorted(v[0] for v in PAIRS.values())
    assert 0.99 not in s and 0.98 not in s
    assert y.sum() == 4
    # the order is the row-major order of pair_mask
    m = ev.pair_mask(N, EXCL)
    assert np.array_equal(s, S[m]) and m.sum() == 10 and not np.any(np.tril(m))


def test_average_precision_is_stepwise_not_trapezoid():
    S, GT = hand_example()
    scores, labels = zip(*PAIRS.values())
    by_hand = stepwise_ap_by_hand(scores, labels)
    # + - + + - - - + - - : precisions at the hits 1/1, 2/3, 3/4, 4/8
    assert by_hand == pytest.approx((1 + 2 / 3 + 3 / 4 + 4 / 8) / 4)
    ap = ev.average_precision(S, GT, exclude=EXCL)
    assert ap == pytest.approx(by_hand, abs=1e-12)
    p, r, _ = ev.pr_curve(S, GT, exclude=EXCL)
    trapezoid = float(-np.trapezoid(p, r))
    assert abs(trapezoid - ap) > 1e-3          # the two definitions differ on this example


def test_recall_at_100_precision_hand_examples():
    S, GT = hand_example()
    assert ev.recall_at_100_precision(S, GT, exclude=EXCL) == pytest.approx(1 / 4)
    S2 = S.copy()
    S2[1, 4] = S2[4, 1] = 0.99                  # a false pair on top
    assert ev.recall_at_100_precision(S2, GT, exclude=EXCL) == 0.0
    S3 = S.copy()
    S3[1, 4] = S3[4, 1] = 0.95                  # a false pair tied with the top true pair
    assert ev.recall_at_100_precision(S3, GT, exclude=EXCL) == 0.0
    S4 = S.copy()
    S4[1, 4] = S4[4, 1] = 0.1                   # now the first three ranks are all true
    assert ev.recall_at_100_precision(S4, GT, exclude=EXCL) == pytest.approx(3 / 4)


def test_mean_per_class_accuracy_hand_example():
    S, GT = hand_example()
    # declaring the top four (0.95 .. 0.80; + - + +): 3 of 4 loops, 5 of 6 non-loops
    assert ev.mean_per_class_accuracy(S, GT, 0.80, exclude=EXCL) == pytest.approx((3 / 4 + 5 / 6) / 2)
    # everything declared: all loops, no non-loop; nothing declared: the reverse (chance, 0.5)
    assert ev.mean_per_class_accuracy(S, GT, 0.0, exclude=EXCL) == pytest.approx(0.5)
    assert ev.mean_per_class_accuracy(S, GT, 1.0, exclude=EXCL) == pytest.approx(0.5)
    # the best threshold over the ten pairs is the fourth score (the pairs inside the window,
    # scored 0.99 and 0.98, must not move it)
    assert ev.mpca_threshold(S, GT, exclude=EXCL) == pytest.approx(0.80)
    # a query mask: only pairs whose later frame is 6 (scores .50 -, .40 +, .30 -, .20 -)
    q = np.arange(N) == 6
    assert ev.mpca_threshold(S, GT, exclude=EXCL, queries=q) == pytest.approx(0.40)
    assert ev.mean_per_class_accuracy(S, GT, 0.40, exclude=EXCL, queries=q) == pytest.approx((1 + 2 / 3) / 2)


def naive_recall_at_k(S, GT, k, exclude, queries=None):
    hits, total = 0, 0
    for j in range(len(S)):
        if queries is not None and not queries[j]:
            continue
        cand = [i for i in range(j) if j - i > exclude]
        if not any(GT[i, j] for i in cand):
            continue
        total += 1
        ranked = sorted(cand, key=lambda i: (-S[i, j], i))   # ties: earlier frame first
        hits += any(GT[i, j] for i in ranked[:k])
    return hits / total


def test_recall_at_k_hand_example():
    S, GT = hand_example()
    # queries with a loop: 3 (cand 0: loop), 4 (cand 0 .85 loop, 1 .90 no),
    # 5 (cand 0 .60 no, 1 .80 loop, 2 .70 no), 6 (0 .30, 1 .50, 2 .20, 3 .40 loop)
    assert ev.recall_at_k(S, GT, k=1, exclude=EXCL) == pytest.approx(2 / 4)   # 3, 5
    assert ev.recall_at_k(S, GT, k=2, exclude=EXCL) == pytest.approx(4 / 4)
    q = np.zeros(N, dtype=bool)
    q[[4, 6]] = True
    assert ev.recall_at_k(S, GT, k=1, exclude=EXCL, queries=q) == 0.0
    assert ev.recall_at_k(S, GT, k=2, exclude=EXCL, queries=q) == 1.0


@pytest.mark.parametrize("seed", range(4))
def test_recall_at_k_matches_naive_loop_with_ties(seed):
    rng = np.random.default_rng(seed)
    n, exclude = 40, 5
    S = np.round(rng.random((n, n)), 1)         # many ties
    G = rng.random((n, n)) < 0.08
    G = np.triu(G | G.T, exclude + 1)
    G = G | G.T
    q = rng.random(n) < 0.7
    for k in (1, 2, 5):
        got = ev.recall_at_k(S, G, k, exclude)
        assert got == pytest.approx(naive_recall_at_k(S, G, k, exclude))
        assert ev.recall_at_k(S, G, k, exclude, queries=q) == pytest.approx(
            naive_recall_at_k(S, G, k, exclude, q))


def test_queries_mask_restricts_pairs_by_later_frame():
    S, GT = hand_example()
    q = np.zeros(N, dtype=bool)
    q[[5, 6]] = True
    y, s = ev.pair_samples(S, GT, exclude=EXCL, queries=q)
    keep = [(i, j) for (i, j) in PAIRS if q[j]]
    assert sorted(s.tolist()) == sorted(PAIRS[p][0] for p in keep)
    ap = ev.average_precision(S, GT, exclude=EXCL, queries=q)
    scores, labels = zip(*(PAIRS[p] for p in keep))
    assert ap == pytest.approx(stepwise_ap_by_hand(scores, labels))
    with pytest.raises(ValueError, match="queries"):
        ev.average_precision(S, GT, exclude=EXCL, queries=np.ones(N + 1, dtype=bool))


def test_operating_point_hand_example():
    S, GT = hand_example()
    P = np.zeros((N, N), dtype=bool)
    P[3, 0] = True          # tp, declared in the lower triangle (row = query)
    P[4, 1] = True          # fp
    P[1, 5] = P[5, 1] = True  # tp, both triangles: one pair
    P[6, 0] = True          # fp
    P[3, 2] = True          # inside the window: ignored
    out = ev.operating_point(P, GT, exclude=EXCL)
    assert out == dict(precision=0.5, recall=0.5, tp=2, fp=2, fn=2, ignored=1)
    flat = np.triu(P | P.T, 1)[ev.pair_mask(N, EXCL)]
    out1 = ev.operating_point(flat, GT, exclude=EXCL)
    assert {k: out1[k] for k in ("tp", "fp", "fn")} == dict(tp=2, fp=2, fn=2)
    none = ev.operating_point(np.zeros((N, N), dtype=bool), GT, exclude=EXCL)
    assert np.isnan(none["precision"]) and none["recall"] == 0 and none["fn"] == 4
    with pytest.raises(ValueError, match="bool"):
        ev.operating_point(P.astype(int), GT, exclude=EXCL)
    with pytest.raises(ValueError, match=r"\(10,\)"):
        ev.operating_point(np.ones(3, dtype=bool), GT, exclude=EXCL)


def test_errors_size_mismatch_no_loops_bad_input():
    S, GT = hand_example()
    with pytest.raises(ValueError, match=r"\(7, 7\).*\(6, 6\)"):
        ev.average_precision(S, GT[:6, :6], exclude=EXCL)
    with pytest.raises(ValueError, match="no loops"):
        ev.average_precision(S, np.zeros_like(GT), exclude=EXCL)
    only_near = np.zeros_like(GT)
    only_near[2, 3] = only_near[3, 2] = True  # a loop, but inside the window
    for f in (ev.pair_samples, ev.pr_curve, ev.average_precision, ev.recall_at_100_precision,
              ev.recall_at_k):
        with pytest.raises(ValueError, match="no loops"):
            f(S, only_near, exclude=EXCL)
    with pytest.raises(ValueError, match="symmetric"):
        ev.average_precision(S, np.triu(GT), exclude=EXCL)
    with pytest.raises(ValueError, match="exclude"):
        ev.average_precision(S, GT, exclude=-1)
    with pytest.raises(ValueError, match="no pairs"):
        ev.average_precision(S, GT, exclude=N)
    S_nan = S.copy()
    S_nan[0, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        ev.average_precision(S_nan, GT, exclude=EXCL)
    with pytest.raises(ValueError, match="k must"):
        ev.recall_at_k(S, GT, k=0, exclude=EXCL)


def test_split_mask():
    tune, evl = ev.split_mask(10, 0.3)
    assert tune.tolist() == [True] * 3 + [False] * 7 and np.array_equal(evl, ~tune)
    tune, evl = ev.split_mask(10, 0.5, gap=2)
    assert tune.sum() == 5 and evl.sum() == 3 and not np.any(tune & evl)
    S, GT = hand_example()
    GT[2, 3] = GT[3, 2] = False              # loop_matrix never has pairs inside the window
    tune, evl = ev.split_mask(N, 0.5, gt=GT)  # revisit frames 3, 4, 5, 6 -> 3, 4 | 5, 6
    assert np.flatnonzero(tune).max() == 4 and np.flatnonzero(evl).min() == 5
    assert ev.average_precision(S, GT, EXCL, queries=tune) > 0
    with pytest.raises(ValueError, match="fraction"):
        ev.split_mask(10, 1.0)
    with pytest.raises(ValueError, match="revisit"):
        ev.split_mask(N, 0.5, gt=np.zeros((N, N), dtype=bool))


def _end_loop(n, first, last):
    """(n, n) ground truth whose revisit frames are first..last: frame j revisits frame j - first."""
    GT = np.zeros((n, n), dtype=bool)
    for j in range(first, last + 1):
        GT[j - first, j] = GT[j, j - first] = True
    return GT


def _check_honest(tune, evl, GT, gap):
    """Both parts hold revisit frames, they are disjoint, and the gap after the cut is free."""
    rev = np.flatnonzero(np.triu(GT, 1).any(0))
    cut = int(np.flatnonzero(tune)[-1]) + 1
    assert tune.tolist() == (np.arange(len(tune)) < cut).tolist()
    assert evl.tolist() == (np.arange(len(evl)) >= cut + gap).tolist()
    assert tune[rev].any() and evl[rev].any() and not np.any(tune & evl)
    assert not np.any((rev >= cut) & (rev < cut + gap) & evl[rev])   # nothing of the gap scored
    return cut


def test_split_mask_keeps_its_cut_where_the_requested_one_is_honest():
    GT = _end_loop(100, 60, 99)                  # 40 revisit frames 60..99
    tune, evl = ev.split_mask(100, 0.5, gt=GT, gap=5)
    assert _check_honest(tune, evl, GT, 5) == 80  # rev[20] = 80: 20 revisit frames tune, 95..99 scored
    assert evl.sum() == 15


def test_split_mask_moves_the_cut_down_for_revisits_clustered_at_the_end():
    # revisit frames 90..99, gap 5: the requested cut rev[5] = 95 leaves nothing after 95 + 5;
    # the latest honest cut is 99 - 5 = 94: revisit frames 90..93 tune, frame 99 scored
    GT = _end_loop(100, 90, 99)
    tune, evl = ev.split_mask(100, 0.5, gt=GT, gap=5)
    assert _check_honest(tune, evl, GT, 5) == 94
    assert np.flatnonzero(evl).tolist() == [99]
    # the span (6) just exceeds the gap (5): revisit frame 90 tunes, 96 is scored
    GT = _end_loop(100, 90, 96)
    tune, evl = ev.split_mask(100, 0.5, gt=GT, gap=5)
    assert _check_honest(tune, evl, GT, 5) == 91
    assert np.flatnonzero(tune & np.triu(GT, 1).any(0)).tolist() == [90]
    assert np.flatnonzero(evl & np.triu(GT, 1).any(0)).tolist() == [96]
    # a larger fraction asks for a later cut: the same honest limit
    assert _check_honest(*ev.split_mask(100, 0.9, gt=GT, gap=5), GT, 5) == 91
    # a small fraction whose requested cut is honest keeps it: rev[round(0.1 * 20)] = rev[2] = 82
    assert _check_honest(*ev.split_mask(100, 0.1, gt=_end_loop(100, 80, 99), gap=5),
                         _end_loop(100, 80, 99), 5) == 82


def test_split_mask_on_a_loop_pair_ground_truth_closing_at_the_end():
    # 600 frames, every 8th described, frames 560..599 revisit 0..39 (ground_truth.csv pairs):
    # the revisit frames among the described ones are 70..74 (original 560..592)
    from greenloop.groundtruth import pair_matrix
    pairs = [(k, 560 + k, 2) for k in range(40)]
    GT = pair_matrix(pairs, 600, np.arange(0, 600, 8), exclude=150)
    assert np.flatnonzero(np.triu(GT, 1).any(0)).tolist() == [70, 71, 72, 73, 74]
    assert _check_honest(*ev.split_mask(75, 0.5, gt=GT, gap=3), GT, 3) == 71
    with pytest.raises(ev.NoHonestSplit) as e:      # 08's gap: the largest median size, 15
        ev.split_mask(75, 0.5, gt=GT, gap=15)
    assert (e.value.revisits, e.value.first, e.value.last, e.value.span, e.value.gap) == (5, 70, 74, 4, 15)


def test_split_mask_raises_no_honest_split_when_the_revisits_fit_in_the_gap():
    for first in (95, 94):                         # spans 4 and 5, gap 5: no cut c with 94 < c <= 94
        with pytest.raises(ev.NoHonestSplit, match=rf"{100 - first} revisit frame\(s\).*within "
                           rf"{99 - first} frames \(frames {first}..99\).*gap of 5 frames"):
            ev.split_mask(100, 0.5, gt=_end_loop(100, first, 99), gap=5)
    with pytest.raises(ev.NoHonestSplit, match="1 revisit frame"):   # one revisit frame, no gap
        ev.split_mask(100, 0.5, gt=_end_loop(100, 99, 99), gap=0)
    assert issubclass(ev.NoHonestSplit, ValueError)
    with pytest.raises(ValueError, match="no revisit frame") as e:     # no loop at all: another error
        ev.split_mask(100, 0.5, gt=np.zeros((100, 100), dtype=bool))
    assert not isinstance(e.value, ev.NoHonestSplit)
    # without a ground truth: the cut moves down to n - 1 - gap, and n <= gap + 1 has no split
    tune, evl = ev.split_mask(10, 0.5, gap=6)
    assert np.flatnonzero(tune).tolist() == [0, 1, 2] and np.flatnonzero(evl).tolist() == [9]
    with pytest.raises(ev.NoHonestSplit, match="10 frames"):
        ev.split_mask(10, 0.5, gap=9)

# ------------------------------------------------------------------- real GreenHouse poses
@pytest.fixture(scope="module")
def greenhouse_poses():
    path = GREENHOUSE / "CameraTrajectory.txt"
    if not path.is_file():
        pytest.skip(f"real GreenHouse trajectory not found at {path}")
    from greenloop.datasets.sequence import read_trajectory
    _, poses = read_trajectory(path)
    return poses


def test_pose_similarity_is_perfect_on_greenhouse(greenhouse_poses):
    poses = greenhouse_poses
    GT = loop_matrix(poses, threshold=0.5, exclude=150)
    S = -pose_error(poses)                     # the pose error itself as a similarity
    assert ev.average_precision(S, GT, exclude=150) == pytest.approx(1.0)
    assert ev.recall_at_100_precision(S, GT, exclude=150) == pytest.approx(1.0)
    assert ev.recall_at_k(S, GT, k=1, exclude=150) == pytest.approx(1.0)
    y, _ = ev.pair_samples(S, GT, exclude=150)
    n = len(poses)
    assert len(y) == (n - 151) * (n - 150) // 2
    # a random similarity scores about the fraction of loop pairs
    rng = np.random.default_rng(0)
    R = rng.random((n, n)).astype(np.float32)
    assert ev.average_precision(R, GT, exclude=150) < 0.05
    # an honest split on the real set keeps loops on both sides
    tune, evl = ev.split_mask(n, 0.5, gt=GT, gap=10)
    assert ev.average_precision(S, GT, 150, queries=tune) == pytest.approx(1.0)
    assert ev.average_precision(S, GT, 150, queries=evl) == pytest.approx(1.0)
    assert np.flatnonzero(tune).max() > 2000      # the revisit is at the end of the sequence


def test_closure_counts_tally():
    dec = np.array([0, 1, 1, 0, 1, 1], bool)
    ok = np.array([0, 0, 1, 1, 1, 0], bool)          # the 4th is not declared: it does not count
    rev = np.array([0, 1, 1, 1, 1, 0], bool)
    c = ev.closure_counts(dec, ok, rev, at=np.array([10, 12, 14, 16, 18, 20]))
    assert (c["declared"], c["false"], c["correct"], c["revisits"]) == (4, 2, 2, 4)
    assert c["precision"] == 0.5 and c["recall"] == 0.5 and c["f1"] == 0.5 and c["first_delay"] == 2
    none = ev.closure_counts(np.zeros(3, bool), np.zeros(3, bool), np.zeros(3, bool))
    assert np.isnan(none["precision"]) and none["f1"] == 0.0 and none["first_delay"] is None


def test_false_closure_runs_group_consecutive_false_queries_and_measure_them():
    """20 frames, exclude 2: queries 10-12 match frames 1-3 wrongly (their partners are 5-7, 4 frames
    on), query 15 matches frame 0 wrongly with no partner, query 17 matches its partner 9 (right) and
    query 18 scores under the threshold; numbered x10, cameras 2 m apart sideways on the false matches."""
    n = 20
    S, GT = np.zeros((n, n)), np.zeros((n, n), bool)
    for j, i, p in ((10, 1, 5), (11, 2, 6), (12, 3, 7)):
        S[i, j], S[p, j], GT[p, j] = 0.9, 0.5, True
    S[0, 15], S[9, 17], GT[9, 17], S[4, 18] = 0.8, 0.95, True, 0.3
    GT |= GT.T
    poses = np.tile(np.eye(4), (n, 1, 1))            # optical axes +z everywhere
    poses[1:4, 0, 3] = 2.0
    frames = 10 * np.arange(n)
    runs = ev.false_closure_runs(S, GT, 0.7, exclude=2, frames=frames, poses=poses)
    assert [(r["first_query"], r["last_query"], r["first_match"], r["last_match"], r["closures"], r["with_partner"])
            for r in runs] == [(100, 120, 10, 30, 3, 3), (150, 150, 0, 0, 1, 0)]
    assert runs[0]["offset_frames"] == 40 and np.isnan(runs[1]["offset_frames"])
    assert runs[0]["distance_m"] == pytest.approx(2.0) and runs[0]["angle_deg"] == pytest.approx(0.0)
    assert runs[0]["max_score"] == pytest.approx(0.9)
    # the count is seqmatch.closures' false count; a threshold above every false score leaves none
    from greenloop.methods.greenloop_seq import seqmatch
    assert sum(r["closures"] for r in runs) == seqmatch.closures(S, GT, 0.7, 2)["false"]
    assert ev.false_closure_runs(S, GT, 0.92, exclude=2) == []


# ------------------------------------------------------------ the spot classifier
def test_per_spot_on_hand_made_labels():
    t = np.array([0, 0, 0, 1, 1, 2])
    p = np.array([0, 0, 1, 1, 1, 1])
    df = ev.per_spot(t, p, 4)
    assert df["class"].tolist() == [1, 2, 3, 4]
    assert df.loc[0, ["precision", "recall", "support"]].tolist() == [1.0, 0.67, 3]
    assert df.loc[1, "precision"] == 0.5 and df.loc[1, "recall"] == 1.0
    assert df.loc[2, "recall"] == 0 and df.loc[3, "support"] == 0
    with pytest.raises(ValueError):
        ev.per_spot(t, p[:3], 4)


def test_spot_errors_counts_adjacent_errors():
    s = ev.spot_errors([0, 1, 2, 3, 4], [0, 2, 2, 0, 4])
    assert s["misclassified"] == 2 and s["adjacent"] == 1 and s["adjacent_share"] == 0.5
    assert s["accuracy"] == pytest.approx(0.6)
    assert ev.spot_errors([1, 2], [1, 2])["adjacent_share"] is None


def test_same_place_errors():
    labels = np.array([0, 0, 1, 1, 2, 2])
    gt = np.zeros((6, 6), bool)
    gt[0, 5] = gt[5, 0] = True          # frame 5 (spot 2) revisits frame 0 (spot 0)
    frames = np.array([5, 4, 2])
    pred = np.array([0, 1, 1])          # 5 -> spot 0: same place; 4 -> spot 1: plain error; 2 right
    assert ev.same_place_errors(frames, pred, labels, gt) == 1


# ------------------------------------------------------ the notebooks' protocol (07-11)
def test_loop_scores_and_chance_level_on_the_hand_example():
    S, GT = hand_example()
    ap = (1 + 2 / 3 + 3 / 4 + 4 / 8) / 4
    assert ev.pair_metrics(S, GT, EXCL) == pytest.approx({"AP_%": 100 * ap, "R@100P_%": 25.0})
    assert list(ev.pair_metrics(S, GT, EXCL, tag="_RGB")) == ["AP_RGB_%", "R@100P_RGB_%"]
    assert ev.chance_level(GT, EXCL) == pytest.approx(4 / 10)      # 4 loops among 10 counted pairs
    q = np.zeros(N, bool); q[6] = True                              # pairs (0,6) (1,6) (2,6) (3,6): one loop
    assert ev.chance_level(GT, EXCL, queries=q) == pytest.approx(1 / 4)


def test_precision_at_recall_is_the_best_precision_at_that_recall_or_more():
    S, GT = hand_example()                      # ranked + - + + - - - + - -
    assert ev.precision_at_recall(S, GT, 0.5, EXCL) == pytest.approx(3 / 4)   # 3 of the first 4
    assert ev.precision_at_recall(S, GT, 1.0, EXCL) == pytest.approx(4 / 8)
    assert ev.precision_at_recall(S, GT, 0.0, EXCL) == pytest.approx(1.0)


def test_interpolated_precision_and_overlap_recall():
    p, r = np.array([0.5, 1.0, 1.0]), np.array([1.0, 0.5, 0.0])
    grid = np.array([0.0, 0.5, 0.75, 1.0])
    assert ev.interpolated_precision(p, r, grid).tolist() == [1.0, 1.0, 0.5, 0.5]
    assert ev.interpolated_precision(p, r[::-1] * 0.5, [0.9]).tolist() == [0.0]   # no point reaches 0.9
    assert ev.overlap_recall(p, r, p, r, grid, 0.02) == 1.0                       # the same curve
    p2, r2 = np.array([0.2, 1.0, 1.0]), np.array([1.0, 0.5, 0.0])                 # differs from recall 0.75 on
    assert ev.overlap_recall(p2, r2, p, r, grid, 0.02) == 0.5
    assert ev.overlap_recall(p2, r2, p, r, grid, 0.4) == 1.0                      # within a wide tolerance
    p3 = np.array([0.2, 0.6, 0.6])                                                # differs already at recall 0
    assert ev.overlap_recall(p3, r, p, r, grid, 0.02) == 0.0                      # no overlap at all


def test_relative_rates_and_loss_per_time_saved():
    R_a, R_t = ev.relative_rates(50.0, 0.5, 40.0, 1.0)
    assert (R_a, R_t) == pytest.approx((25.0, 50.0))
    R_a, R_t = ev.relative_rates(np.array([40.0, 30.0]), np.array([2.0, 1.0]), 40.0, 2.0)
    assert R_a.tolist() == pytest.approx([0.0, -25.0]) and R_t.tolist() == pytest.approx([0.0, 50.0])
    loss = ev.loss_per_time_saved([-10.0, 5.0, -3.0], [20.0, -5.0, 0.0])
    assert loss[0] == pytest.approx(0.5) and np.isnan(loss[1]) and np.isnan(loss[2])


def _revisiting(n_place=20, dim=12, seed=0):
    """2 n_place frames: the second half revisits the first (GT[i, i + n_place]), noisy descriptors."""
    rng = np.random.default_rng(seed)
    base = rng.standard_normal((n_place, dim))
    X = np.concatenate([base, base]) + 0.3 * rng.standard_normal((2 * n_place, dim))
    GT = np.zeros((2 * n_place, 2 * n_place), bool)
    i = np.arange(n_place)
    GT[i, i + n_place] = GT[i + n_place, i] = True
    return X, GT


def test_split_summary_names_the_two_parts():
    X, GT = _revisiting()                              # revisit frames 20..39
    tune, evq = ev.split_mask(40, 0.5, gt=GT, gap=3)
    assert ev.split_summary(tune, evq, GT, 3) == ("tuning queries: frames 0..29 (10 revisit frames); "
                                                  "evaluation queries: frames 33..39 (7 revisit frames); gap 3")


def test_revisit_queries_are_the_later_frames_of_counted_loop_pairs():
    S, GT = hand_example()                      # counted loops (0,3) (0,4) (1,5) (3,6); (2,3) is inside the band
    assert np.flatnonzero(ev.revisit_queries(GT, EXCL)).tolist() == [3, 4, 5, 6]
    assert np.flatnonzero(ev.revisit_queries(GT, 3)).tolist() == [4, 5]     # j - i > 3: (0,4) and (1,5)
