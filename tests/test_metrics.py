import numpy as np
import pytest

from greenloop import metrics


def test_per_class_on_hand_made_labels():
    t = np.array([0, 0, 0, 1, 1, 2])
    p = np.array([0, 0, 1, 1, 1, 1])
    df = metrics.per_class(t, p, 4)
    assert df["class"].tolist() == [1, 2, 3, 4]
    assert df.loc[0, ["precision", "recall", "support"]].tolist() == [1.0, 0.67, 3]
    assert df.loc[1, "precision"] == 0.5 and df.loc[1, "recall"] == 1.0
    assert df.loc[2, "recall"] == 0 and df.loc[3, "support"] == 0
    with pytest.raises(ValueError):
        metrics.per_class(t, p[:3], 4)


def test_error_summary_counts_adjacent_errors():
    s = metrics.error_summary([0, 1, 2, 3, 4], [0, 2, 2, 0, 4])
    assert s["misclassified"] == 2 and s["adjacent"] == 1 and s["adjacent_share"] == 0.5
    assert s["accuracy"] == pytest.approx(0.6)
    assert metrics.error_summary([1, 2], [1, 2])["adjacent_share"] is None


def test_same_place_errors():
    labels = np.array([0, 0, 1, 1, 2, 2])
    gt = np.zeros((6, 6), bool)
    gt[0, 5] = gt[5, 0] = True          # frame 5 (spot 2) revisits frame 0 (spot 0)
    frames = np.array([5, 4, 2])
    pred = np.array([0, 1, 1])          # 5 -> spot 0: same place; 4 -> spot 1: plain error; 2 right
    assert metrics.same_place_errors(frames, pred, labels, gt) == 1
