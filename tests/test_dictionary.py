import numpy as np
import pytest

from conftest import revisit_example
from greenloop.methods.dictionary import dictionary


def test_threshold_derivation_matches_paper_arithmetic():
    t = dictionary.threshold(60, 0.10, 10)
    assert t["expected_correct"] == pytest.approx(54.0) and t["tau"] == 70
    with pytest.raises(ValueError):
        dictionary.threshold(0, 0.1, 10)
    with pytest.raises(ValueError, match="tau"):
        dictionary.threshold(5, 0.1, -5)
    with pytest.raises(ValueError, match="margin must be an integer >= 0"):
        dictionary.threshold(60, 0.1, -5)           # tau = 55 < L would be silently below the paper's rule
    assert dictionary.threshold(60, 0.1, 0)["tau"] == 60


def test_detector_on_hand_made_stream():
    det = dictionary.LoopDetector(3, threshold=3)
    stream = [0, 0, 1, 0, 2, 0, 1, 1]
    flags = [det.update(c) for c in stream]
    assert flags == [False, False, False, True, False, True, False, True]
    assert det.counts.tolist() == [4, 3, 1]
    assert det.nbytes == 12 and dictionary.LoopDetector(38, 70).nbytes == 152
    assert (dictionary.run(stream, 3, 3) == np.array(flags)).all()
    ev = dictionary.closure_events(stream, 3, 3)
    assert [(e["frame"], e["spot"]) for e in ev] == [(3, 0), (7, 1)]
    det.reset()
    assert det.counts.sum() == 0


def test_threshold_none_counts_but_declares_nothing():
    det = dictionary.LoopDetector(3, threshold=None)
    stream = [0, 0, 1, 0, 2, 0, 1, 1]
    assert det.threshold is None
    assert [det.update(c) for c in stream] == [False] * len(stream)
    assert det.counts.tolist() == [4, 3, 1]
    with pytest.raises(ValueError, match="unknown label 3"):
        det.update(3)

def test_detector_rejects_bad_input():
    with pytest.raises(ValueError, match="threshold"):
        dictionary.LoopDetector(3, 0)
    det = dictionary.LoopDetector(3, 2)
    with pytest.raises(ValueError, match="unknown label 3"):
        det.update(3)
    with pytest.raises(ValueError):
        dictionary.run([0, 5], 3, 2)


def test_score_closures_against_ground_truth():
    pred, ref, gt = revisit_example()
    s = dictionary.score_closures(pred, ref, gt, threshold=12, exclude=5)
    assert s["true_events"] == 1 and s["false_events"] == 0
    assert s["event_list"][0]["frame"] == 31  # 10 + 2 more counts of spot 0
    assert s["delays"] == [1] and s["revisit_frames"] == 10 and s["true_frames"] == 9
    s2 = dictionary.score_closures(pred, ref, gt, threshold=3, exclude=5)
    assert s2["false_events"] == 3  # spots 0, 1, 2 fire on their own first traversal


def test_score_closures_on_a_query_mask_and_choose_threshold():
    # spots 0, 1 of 3 frames; frames 6..11 revisit 0..5 and are predicted correctly
    n = 12
    gt = np.zeros((n, n), bool)
    for k in range(6):
        gt[k, 6 + k] = gt[6 + k, k] = True
    ref = np.r_[np.repeat([0, 1], 3), -np.ones(6, int)]
    pred = np.r_[np.repeat([0, 1], 3), np.repeat([0, 1], 3)]
    full = dictionary.score_closures(pred, ref, gt, 5, exclude=2)   # flags frames 7, 8, 10, 11
    assert full["flagged"] == 4 and full["true_frames"] == 4 and full["precision"] == 1.0
    assert full["recall"] == pytest.approx(4 / 6)
    late = np.arange(n) >= 9
    part = dictionary.score_closures(pred, ref, gt, 5, exclude=2, queries=late)
    assert part["flagged"] == 2 and part["revisit_frames"] == 3 and part["recall"] == pytest.approx(2 / 3)
    assert part["flags"].sum() == 4                  # the stream itself is not cut
    tau, rows = dictionary.choose_threshold(pred, ref, gt, [2, 3, 4, 7], np.arange(n) < 9, exclude=2)
    # tau = 2, 3 flag first-traversal frames (false), tau = 7 never fires: tau = 4 wins
    assert [r["tau"] for r in rows] == [2, 3, 4, 7] and rows[-1]["f1"] == 0.0
    assert tau == 4
    with pytest.raises(ValueError, match="queries"):
        dictionary.score_closures(pred, ref, gt, 4, queries=np.ones(3, bool))
    with pytest.raises(ValueError, match="taus"):
        dictionary.choose_threshold(pred, ref, gt, [], late)


def test_counts_are_the_detectors_running_counts():
    labels = np.array([0, 1, 1, 2, 1, 0])
    D = dictionary.counts(labels, 3)
    assert D.shape == (6, 3) and D[-1].tolist() == [2, 3, 1] and D[2].tolist() == [1, 2, 0]
    det = dictionary.LoopDetector(3, 2)
    for t, c in enumerate(labels):
        det.update(int(c))
        assert det.counts.tolist() == D[t].tolist()


def _brute_counts(labels, n, start=None):
    """The counting rule written out: a Python dict incremented frame by frame."""
    D = {c: (0 if start is None else int(start[c])) for c in range(n)}
    out = []
    for c in labels:
        D[int(c)] += 1
        out.append(D[int(c)])
    return np.array(out, np.int64)


@pytest.mark.parametrize("seed", range(6))
def test_one_counting_rule_on_random_label_streams(seed):
    from greenloop.methods.dictionary import stream

    rng = np.random.default_rng(seed)
    n, T, tau = int(rng.integers(1, 8)), int(rng.integers(0, 300)), int(rng.integers(1, 40))
    labels = rng.integers(0, n, T)
    want = _brute_counts(labels, n)
    assert dictionary.running_count(labels, n).tolist() == want.tolist()
    if T:
        assert dictionary.counts(labels, n)[np.arange(T), labels].tolist() == want.tolist()
    assert dictionary.run(labels, n, tau).tolist() == (want >= tau).tolist()
    det = dictionary.LoopDetector(n, tau)
    assert [det.update(c) for c in labels] == (want >= tau).tolist()       # the STATE, count >= tau
    one, win = dictionary.LoopDetector(n, tau), dictionary.LoopDetector(n, tau)
    assert [one.add(c) for c in labels] == want.tolist()
    cut = T // 3                                                            # two windows, counters carried over
    got = np.r_[win.add_many(labels[:cut]), win.add_many(labels[cut:])]
    assert got.tolist() == want.tolist() and win.counts.tolist() == one.counts.tolist()
    start = rng.integers(0, 5, n)
    assert dictionary.running_count(labels, n, start).tolist() == _brute_counts(labels, n, start).tolist()
    # the streaming detector's EVENTS (count == tau, once per spot), frame by frame and windowed
    events = dictionary.closure_events(labels, n, tau)
    assert [e["frame"] for e in events] == [t for t in range(T) if want[t] == tau]
    for windowed in (False, True):
        d = stream.Detector.__new__(stream.Detector)      # no network: labels fed directly
        d.dictionary, d.threshold, d.n_classes = dictionary.LoopDetector(n, tau), tau, n
        d.reset()
        if windowed:
            d.predict = lambda frames: np.asarray(frames, np.int64)
            got_ev = d.update_many(labels[:cut]) + d.update_many(labels[cut:])
        else:
            got_ev = [e for c in labels if (e := d._count(int(c))) is not None]
        assert got_ev == events and d.events == events


def test_declared_pairs_and_query_closures():
    rng = np.random.default_rng(3)
    T, ex = 60, 5
    ref = np.repeat(np.arange(6), 10)
    pred = np.where(rng.random(T) < 0.8, np.tile(ref[:30], 2), rng.integers(0, 6, T))
    tau = 4
    D = dictionary.declared_pairs(pred, ref, tau, ex)
    flags = dictionary.run(pred, 6, tau)
    for t in range(T):
        for i in range(T):
            assert D[t, i] == (flags[t] and ref[i] == pred[t] and abs(i - t) > ex)
    gt = np.zeros((T, T), bool)
    gt[np.arange(30), np.arange(30) + 30] = True
    gt |= gt.T
    q = np.arange(T) >= 20
    c = dictionary.query_closures(D, gt, queries=q)
    dec = D.any(1) & q
    ok = (D & gt).any(1) & dec
    rev = np.triu(gt, 1).any(0) & q
    assert c["declared"] == dec.sum() and c["false"] == (dec & ~ok).sum() and c["correct"] == ok.sum()
    assert c["revisits"] == rev.sum()
    hits = np.flatnonzero(ok)
    assert c["first_delay"] == (hits[0] - np.flatnonzero(rev)[0] if len(hits) else None)
    with pytest.raises(ValueError, match="same frames"):
        dictionary.declared_pairs(pred, ref[:-1], tau, ex)


