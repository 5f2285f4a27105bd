import numpy as np
import pytest

from greenloop import dictionary


def test_threshold_derivation_matches_paper_arithmetic():
    t = dictionary.threshold(60, 0.10, 10)
    assert t["expected_correct"] == pytest.approx(54.0) and t["tau"] == 70
    with pytest.raises(ValueError):
        dictionary.threshold(0, 0.1, 10)
    with pytest.raises(ValueError, match="tau"):
        dictionary.threshold(5, 0.1, -5)


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


def test_detector_rejects_bad_input():
    with pytest.raises(ValueError, match="threshold"):
        dictionary.LoopDetector(3, 0)
    det = dictionary.LoopDetector(3, 2)
    with pytest.raises(ValueError, match="unknown label 3"):
        det.update(3)
    with pytest.raises(ValueError):
        dictionary.run([0, 5], 3, 2)


def test_score_closures_against_ground_truth():
    # 40 frames, spots of 10; frames 30..39 revisit frames 0..9 (spot 0)
    n = 40
    ref = np.arange(n) // 10
    gt = np.zeros((n, n), bool)
    for k in range(10):
        gt[k, 30 + k] = gt[30 + k, k] = True
    pred = ref.copy()
    pred[30:] = 0                    # a loop-aware classifier: the revisit is spot 0
    pred[15] = 2                     # one error
    s = dictionary.score_closures(pred, ref, gt, threshold=12, exclude=5)
    assert s["true_events"] == 1 and s["false_events"] == 0
    assert s["event_list"][0]["frame"] == 31  # 10 + 2 more counts of spot 0
    assert s["delays"] == [1] and s["revisit_frames"] == 10 and s["true_frames"] == 9
    s2 = dictionary.score_closures(pred, ref, gt, threshold=3, exclude=5)
    assert s2["false_events"] == 3  # spots 0, 1, 2 fire on their own first traversal
