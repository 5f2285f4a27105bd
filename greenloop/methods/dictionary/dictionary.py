"""The main paper's frequency-count dictionary: a closure is declared when a class count reaches tau.

D(f_t) <- D(f_t) + 1 for the class f_t predicted for frame t; closure when exists c: D(c) >= tau.
Counters never decay (as in the paper), so misclassifications accumulate over a long run.

One counting rule: the running count of frame t is the number of frames 0..t (t included) with
its label, plus the counter's value before the stream (:func:`running_count`). ``counts`` (every
spot's count after every frame), ``run`` (the state D(f_t) >= tau), ``LoopDetector`` (one frame at
a time) and ``greenloop.methods.dictionary.stream.Detector`` (raw frames; its events are the frames where the count
EQUALS tau, once per spot) all follow it; tests/test_dictionary.py checks them against each
other on random label streams.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from greenloop.evaluate import closure_counts, operating_point
from greenloop.groundtruth import DEFAULT_EXCLUDE, far_in_time, revisit_frames
from greenloop.methods.dictionary import cnn, spots
from greenloop.util.checks import positive_int


def threshold(frames_per_spot: int, error_rate: float, margin: int) -> dict:
    """The paper's threshold derivation.

    frames_per_spot: L frames per spot. error_rate: eps, the expected misclassification rate
    (0.10 in the paper's worst case). margin: Delta frames of safety buffer.
    Returns {'frames_per_spot': L, 'error_rate': eps, 'margin': Delta,
             'expected_correct': (1 - eps) * L  (54 for L = 60, eps = 0.10),
             'tau': L + Delta  (70 for Delta = 10)}.
    """
    positive_int("frames_per_spot", frames_per_spot, whole_floats=True)
    if not 0 <= error_rate < 1:
        raise ValueError(f"error_rate must be in [0, 1), got {error_rate}")
    positive_int("margin", margin, 0, whole_floats=True,
                 unit="the paper's tau = L + margin is at least L: a spot must be seen more often "
                      "than its own L frames")
    tau = int(frames_per_spot + margin)
    return {"frames_per_spot": int(frames_per_spot), "error_rate": float(error_rate),
            "margin": int(margin), "expected_correct": (1 - error_rate) * frames_per_spot, "tau": tau}


class LoopDetector:
    """Frequency-count loop detector (the paper's key-value dictionary), O(1) per frame.

    n_classes: number of spots N (labels 0 .. N-1). threshold: tau >= 1 detections, or None to
    count without ever declaring a closure (``update`` always returns False; for timing the
    counting alone).
    ``update(label)`` returns True when that label's count has reached tau (at that frame and every
    later frame of the class: a closure is a STATE, D >= tau, not an edge). Not to be confused
    with ``greenloop.methods.dictionary.stream.Detector.update(frame)``, which returns an EVENT dict only at the one
    frame where a spot's count becomes equal to tau (else None). ``add``/``add_many`` count and
    return the new running counts. ``counts`` is the (N,) int32 array D, ``nbytes`` its memory
    (4 bytes per counter, the paper's 152 bytes for 38 classes).
    """

    def __init__(self, n_classes: int, threshold: int | None):
        positive_int("n_classes", n_classes, whole_floats=True)
        if threshold is not None:
            positive_int("threshold tau", threshold, unit="detections", whole_floats=True)
        self.n_classes = int(n_classes)
        self.threshold = None if threshold is None else int(threshold)
        self.counts = np.zeros(self.n_classes, dtype=np.int32)

    def update(self, label: int) -> bool:
        """Count one prediction; True if D(label) >= tau afterwards (the closure state; never
        when tau is None)."""
        count = self.add(label)
        return self.threshold is not None and count >= self.threshold

    def add(self, label: int) -> int:
        """Count one prediction; returns D(label) afterwards (the frame's running count)."""
        label = int(label)
        if not 0 <= label < self.n_classes:
            raise ValueError(f"unknown label {label}: the detector has classes 0..{self.n_classes - 1}")
        self.counts[label] += 1
        return int(self.counts[label])

    def add_many(self, labels) -> np.ndarray:
        """Count a window of predictions in order; returns each frame's running count (T,) int64,
        what ``add`` returns frame by frame (:func:`running_count` from the current counters)."""
        running = running_count(labels, self.n_classes, start=self.counts)
        np.add.at(self.counts, np.asarray(labels, dtype=np.int64), 1)
        return running

    def reset(self) -> None:
        """Set every counter back to zero."""
        self.counts[:] = 0

    @property
    def nbytes(self) -> int:
        """Memory of the counters in bytes (int32 each)."""
        return int(self.counts.nbytes)


def _check_labels(labels, n_classes: int) -> np.ndarray:
    labels = np.asarray(labels, dtype=np.int64)
    if labels.ndim != 1:
        raise ValueError(f"labels must be 1-D (T,), got {labels.shape}")
    if len(labels) and (labels.min() < 0 or labels.max() >= n_classes):
        raise ValueError(f"labels must lie in 0..{n_classes - 1}, got {labels.min()}..{labels.max()}")
    return labels


def running_count(labels, n_classes: int, start=None) -> np.ndarray:
    """The counting rule: each frame's own running count D(labels[t]) after frame t.

    labels: (T,) int in 0..n_classes-1. start: optional (n_classes,) counts before the stream
    (a ``LoopDetector``'s ``counts``); zeros by default. Returns (T,) int64: start[c] + the number
    of frames 0..t labelled c = labels[t] (t included). Without a (T, n_classes) matrix: one
    stable sort, the rank of each frame among the frames of its label.
    """
    labels = _check_labels(labels, n_classes)
    T = len(labels)
    if T == 0:
        return np.zeros(0, np.int64)
    order = np.argsort(labels, kind="stable")
    sorted_l = labels[order]
    first = np.r_[0, np.flatnonzero(sorted_l[1:] != sorted_l[:-1]) + 1]
    rank = np.arange(T) - np.repeat(first, np.diff(np.r_[first, T]))
    running = np.empty(T, np.int64)
    running[order] = rank + 1 + (0 if start is None else np.asarray(start, np.int64)[sorted_l])
    return running


def counts(labels, n_classes: int) -> np.ndarray:
    """The dictionary's running counts D(c) of every spot over a stream of predicted labels.

    labels: (T,) int in 0..n_classes-1. Returns (T, n_classes) int32: row t holds every spot's
    count after frame t (itself included), what ``LoopDetector`` holds after t + 1 updates;
    ``counts(l, n)[t, l[t]] == running_count(l, n)[t]``.
    """
    labels = _check_labels(labels, n_classes)
    onehot = np.zeros((len(labels), n_classes), dtype=np.int32)
    onehot[np.arange(len(labels)), labels] = 1
    return np.cumsum(onehot, axis=0, dtype=np.int32)


def run(labels, n_classes: int, threshold: int) -> np.ndarray:
    """Run a fresh detector over a stream of predicted labels (T,) -> closure flags (T,) bool.

    Vectorised equivalent of calling ``LoopDetector.update`` frame by frame: frame t is flagged when
    the running count of labels[t] (itself included, :func:`running_count`) is >= threshold.
    """
    positive_int("threshold tau", threshold, unit="detections", whole_floats=True)
    return running_count(labels, n_classes) >= threshold


def declared_pairs(pred, reference_labels, threshold: int, exclude: int = DEFAULT_EXCLUDE) -> np.ndarray:
    """The loop pairs the dictionary declares: (T, T) bool, True at [t, i] when frame t is flagged
    (:func:`run` at ``threshold``) and frame i belongs to the spot predicted for t
    (reference_labels[i] == pred[t]) with |i - t| > exclude (``groundtruth.far_in_time``).

    pred, reference_labels: (T,) labels of frames 0..T-1 in capture order (as
    :func:`score_closures`; reference_labels may hold -1 for frames of no spot).
    Score it with ``evaluate.operating_point`` (pairs) or :func:`query_closures` (per query).
    """
    pred = np.asarray(pred, dtype=np.int64)
    ref = np.asarray(reference_labels, dtype=np.int64)
    if pred.shape != ref.shape or pred.ndim != 1:
        raise ValueError(f"pred {pred.shape} and reference_labels {ref.shape} must be (T,) labels of the same frames")
    flags = run(pred, int(max(pred.max(), ref.max()) + 1), threshold)
    return flags[:, None] & (ref[None, :] == pred[:, None]) & far_in_time(len(pred), exclude)


def query_closures(declared, gt, queries=None) -> dict:
    """Per-query closures of a detector's declared pairs (the dictionary's on described frames).

    declared: (M, M) bool, row = query t, column = frames it declares a loop with (e.g.
    ``declared_pairs(...)[np.ix_(frames, frames)]``). gt: (M, M) bool ground truth of the same
    frames. queries: optional (M,) bool mask of the queries counted (every frame if None).
    A query is declared when its row holds a pair; correct when one of them is a loop in gt.
    Returns ``evaluate.closure_counts`` of it: dict(declared, false, correct, revisits,
    precision, recall, f1, first_delay), revisits = revisit frames (groundtruth.revisit_frames)
    among the queries, first_delay in frames from the first of them to the first correct query.
    """
    D = np.asarray(declared, dtype=bool)
    G = np.asarray(gt, dtype=bool)
    q = np.ones(len(D), dtype=bool) if queries is None else np.asarray(queries, dtype=bool)
    dec = D.any(1) & q
    return closure_counts(dec, (D & G).any(1) & dec, revisit_frames(G) & q)


def closure_events(labels, n_classes: int, threshold: int) -> list[dict]:
    """First closure of each class: [{'frame': t, 'spot': c, 'count': tau}] in frame order."""
    flags = run(labels, n_classes, threshold)
    events, seen = [], set()
    for t in np.flatnonzero(flags):
        c = int(labels[t])
        if c not in seen:
            seen.add(c)
            events.append({"frame": int(t), "spot": c, "count": int(threshold)})
    return events


def score_closures(pred, reference_labels, gt, threshold: int, exclude: int = DEFAULT_EXCLUDE,
                   queries=None) -> dict:
    """Score the detector's closures against pose ground truth.

    pred: (T,) labels predicted for frames 0..T-1 in capture order.
    reference_labels: (T,) the spot each frame belongs to (the labels the CNN was trained on).
    gt: (T, T) bool ground-truth loop matrix (greenloop.groundtruth).
    A flagged frame t with predicted spot c is a TRUE closure when some frame i of spot c with
    |i - t| > exclude is a ground-truth loop partner of t, else FALSE. The first flag of each spot is
    a closure event. Detection delay: for each maximal run of revisit frames (frames with an earlier
    loop partner), frames from its start to its first true closure.
    reference_labels may hold -1 for frames that belong to no spot (e.g. frames after the first
    traversal when the places were learnt from it).
    queries: optional (T,) bool mask; the counts, precision and recall then cover only the frames
    in it (the stream, and so the running counts, still start at frame 0): tune tau on one part,
    score on another (greenloop.evaluate.split_mask).
    Returns {'tau', 'flagged', 'true_frames', 'false_frames', 'events', 'true_events',
    'false_events', 'revisit_frames', 'revisits_detected', 'delays' (list), 'event_list',
    'flags' (T,), 'precision' (true / flagged frames, NaN when none flagged),
    'recall' (revisit frames flagged true / revisit frames)}.
    """
    pred = np.asarray(pred, dtype=np.int64)
    ref = np.asarray(reference_labels, dtype=np.int64)
    gt = np.asarray(gt, dtype=bool)
    if not (len(pred) == len(ref) == len(gt)) or gt.shape != (len(pred), len(pred)):
        raise ValueError(f"pred {pred.shape}, reference_labels {ref.shape} and gt {gt.shape} "
                         f"must describe the same frames")
    n_classes = int(max(pred.max(), ref.max()) + 1)
    flags = run(pred, n_classes, threshold)
    # true[t] (read only where t is flagged): a loop partner of t, far in time, lies in its predicted spot
    true_at = (gt & declared_pairs(pred, ref, threshold, exclude)).any(1)
    revisit = np.tril(gt, -1).any(1)
    q = np.ones(len(pred), dtype=bool) if queries is None else np.asarray(queries, dtype=bool)
    if q.shape != pred.shape:
        raise ValueError(f"queries must be a (T,) bool mask, got shape {q.shape} for T={len(pred)}")
    events = [e for e in closure_events(pred, n_classes, threshold) if q[e["frame"]]]
    for e in events:
        e["true"] = bool(true_at[e["frame"]])
    flags_all, flags = flags, flags & q
    revisit = revisit & q
    starts = np.flatnonzero(revisit & ~np.r_[False, revisit[:-1]])
    delays = []
    for s in starts:
        e = s
        while e < len(revisit) and revisit[e]:
            e += 1
        hits = np.flatnonzero(flags[s:e] & true_at[s:e])
        delays.append(int(hits[0]) if len(hits) else None)
    return {"tau": int(threshold), "flagged": int(flags.sum()),
            "true_frames": int((flags & true_at).sum()), "false_frames": int((flags & ~true_at).sum()),
            "events": len(events), "true_events": sum(e["true"] for e in events),
            "false_events": sum(not e["true"] for e in events),
            "revisit_frames": int(revisit.sum()), "revisits_detected": int((flags & true_at & revisit).sum()),
            "delays": delays, "event_list": events, "flags": flags_all,
            "precision": float((flags & true_at).sum() / flags.sum()) if flags.any() else float("nan"),
            "recall": float((flags & true_at & revisit).sum() / max(int(revisit.sum()), 1))}


def choose_threshold(pred, reference_labels, gt, taus, tune, exclude: int = DEFAULT_EXCLUDE):
    """Pick tau on a tuning part only: the tau with the highest frame-level F1 there.

    pred, reference_labels, gt, exclude: as in :func:`score_closures`. taus: candidate thresholds
    (ints >= 1). tune: (T,) bool mask of the tuning frames (greenloop.evaluate.split_mask); the
    scoring frames must not be in it. F1 = 2PR / (P + R) of :func:`score_closures`' frame-level
    precision and recall on the tuning frames (0 where nothing is flagged); ties go to the larger
    tau (the more conservative detector).
    Returns (tau, rows): the chosen tau and one dict per candidate (tau, precision, recall, f1).
    """
    taus = [int(t) for t in taus]
    if not taus or min(taus) < 1:
        raise ValueError(f"taus must be a non-empty list of thresholds >= 1, got {taus}")
    rows = []
    for tau in taus:
        s = score_closures(pred, reference_labels, gt, tau, exclude, queries=tune)
        p, r = s["precision"], s["recall"]
        f1 = 0.0 if not np.isfinite(p) or p + r == 0 else 2 * p * r / (p + r)
        rows.append({"tau": tau, "precision": p, "recall": r, "f1": f1})
    best = max(rows, key=lambda row: (row["f1"], row["tau"]))
    return best["tau"], rows



# --------------------------------------------- the detector trained, run and scored (07, 13)
class SpotDetector(NamedTuple):
    """The main paper's detector of :func:`operating_points`. run: ``cnn.run_seeds``' record of
    the spot CNN (model, seed, history, split, test_accuracy, test_pred). labels: (T,) int64 spot
    of every frame (``spots.group``). pred: (T,) int64 spot the CNN predicts for every frame.
    n_train: frames 0..n_train-1 it was trained on (split at random 80/20 by ``cnn.train``)."""
    run: dict
    labels: np.ndarray
    pred: np.ndarray
    n_train: int


def operating_points(X, frames_per_spot: int, taus, frames, gt, exclude: int = DEFAULT_EXCLUDE, exclude_steps: int | None = None,
                     n_train: int | None = None, queries=None, seed: int = 0, progress: bool = True,
                     **train_kw) -> tuple[SpotDetector, list[dict]]:
    """Train the spot CNN on the first frames, predict every frame, score the dictionary at each tau.

    X: (T, H, W, C) every frame of the sequence in capture order (``sequence.load_frames``).
    frames_per_spot: L. taus: thresholds (ints >= 1). frames: (M,) original indices of the
    described frames, gt: (M, M) bool their ground truth; exclude: band in original frames (the
    declared pairs, :func:`declared_pairs`), exclude_steps: the same band in steps of ``frames``
    (scoring; default exclude). n_train: train on frames 0..n_train-1 only (e.g. the frames
    before an evaluation part; default every frame). queries: optional (M,) bool mask of the
    scored queries. seed, progress, train_kw (epochs, batch_size, ...): ``cnn.run_seeds``.
    Returns (detector, points): one dict per tau with tau, flagged_frames (frames flagged over the
    whole stream), closures (:func:`query_closures`) and op (``evaluate.operating_point`` of the
    declared pairs among the described frames).
    """
    X = np.asarray(X)
    n_train = len(X) if n_train is None else positive_int("n_train", n_train, 1, len(X), unit="frames")
    y = spots.group(len(X), frames_per_spot)
    run_ = cnn.run_seeds(X[:n_train], y[:n_train], [seed], progress=progress, **train_kw)[0]
    pred = cnn.predict(run_["model"], X)
    f = np.asarray(frames)
    exclude_steps = exclude if exclude_steps is None else exclude_steps
    points = []
    for tau in taus:
        D = declared_pairs(pred, y, tau, exclude)[np.ix_(f, f)]
        points.append({"tau": tau, "flagged_frames": int(run(pred, int(max(y.max(), pred.max()) + 1), tau).sum()),
                       "closures": query_closures(D, gt, queries=queries), "op": operating_point(D, gt, exclude_steps, queries=queries)})
    return SpotDetector(run_, y, pred, n_train), points

