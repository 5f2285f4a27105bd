"""The spot classifier's errors (main paper Tables 2 and 4): precision, recall and F1 per spot,
misclassified and adjacent-spot errors, errors between frames of one place.
"""
from __future__ import annotations

import numpy as np
from sklearn.metrics import classification_report

# ------------------------------------------------------- the spot classifier (main paper)
def per_spot(y_true, y_pred, n_classes: int):
    """Per-spot precision, recall, F1 and support (sklearn's classification_report).

    y_true, y_pred: (N,) int spot labels 0..n_classes-1. Returns a DataFrame with one row per spot:
    class (1-based, as the paper numbers them), precision, recall, f1 (rounded to 2 decimals, as
    the paper prints them), support (frames of that spot in y_true). Spots absent from both get 0.
    """
    import pandas as pd

    y_true, y_pred = np.asarray(y_true), np.asarray(y_pred)
    if y_true.shape != y_pred.shape or y_true.ndim != 1:
        raise ValueError(f"y_true and y_pred must be (N,) arrays of one length, got {y_true.shape} and {y_pred.shape}")
    rep = classification_report(y_true, y_pred, labels=np.arange(n_classes), output_dict=True, zero_division=0)
    return pd.DataFrame([{"class": c + 1, "precision": round(rep[str(c)]["precision"], 2),
                          "recall": round(rep[str(c)]["recall"], 2), "f1": round(rep[str(c)]["f1-score"], 2),
                          "support": int(rep[str(c)]["support"])} for c in range(n_classes)])


def spot_errors(y_true, y_pred) -> dict:
    """Misclassifications and how many fall on an adjacent spot (|predicted - true| = 1).

    Returns {'frames', 'misclassified', 'accuracy', 'adjacent', 'adjacent_share' (None if no
    errors)}.
    """
    y_true, y_pred = np.asarray(y_true), np.asarray(y_pred)
    wrong = y_pred != y_true
    adj = int((np.abs(y_pred - y_true)[wrong] == 1).sum())
    return {"frames": int(len(y_true)), "misclassified": int(wrong.sum()),
            "accuracy": float(1 - wrong.mean()) if len(y_true) else float("nan"),
            "adjacent": adj, "adjacent_share": adj / int(wrong.sum()) if wrong.any() else None}


def same_place_errors(frames, y_pred, labels, gt) -> int:
    """Errors that name the spot of the same place seen at another time.

    frames: (M,) frame indices that were classified; y_pred: (M,) predicted spots; labels: (N,)
    spot of every frame; gt: (N, N) bool ground-truth loops (greenloop.groundtruth). Counts the
    misclassified frames f whose predicted spot holds a ground-truth loop partner of f: with spots
    made by frame index, a revisit is a different class from the place it revisits, so these
    "errors" are the classifier recognising the place.
    """
    frames, y_pred, labels = np.asarray(frames), np.asarray(y_pred), np.asarray(labels)
    gt = np.asarray(gt, dtype=bool)
    wrong = y_pred != labels[frames]
    return int(sum(gt[f, labels == c].any() for f, c in zip(frames[wrong], y_pred[wrong])))
