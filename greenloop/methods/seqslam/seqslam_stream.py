"""SeqSLAM's streaming detector (Milford & Wyeth 2012, at OpenSeqSLAM's parameters), and what is
computed by streaming it: the score matrix and the tuning grid (the speed path).

``Detector`` (moved here from ``greenloop.methods.seqslam.seqslam``: streaming code lives in ``speed/``) is
``seqstream.Detector`` with SeqSLAM's similarity (negated mean absolute difference of the
patch-normalised 64x32 frames) and floor-rounded trajectory offsets; ``greenloop.methods.seqslam.seqslam`` holds
the parameters, descriptors and similarity and says what differs from OpenSeqSLAM and why;
``greenloop.methods.seqslam.entry`` registers it.
"""
from __future__ import annotations

import math

import numpy as np

from greenloop import evaluate
from greenloop.methods.greenloop_seq import seqmatch
from greenloop.methods.seqslam.seqslam import (DS, R_WINDOW, describe_frames, difference_similarity, offsets, similarity_matrix,
                               velocities)
from greenloop.groundtruth import DEFAULT_EXCLUDE
from greenloop.methods.greenloop_seq import seqstream
from greenloop.util.checks import positive_int

__all__ = ["Detector", "score_matrix", "tune_knobs"]


class Detector(seqstream.Detector):
    """Streaming SeqSLAM: one decoded frame (or SeqSLAM descriptor) in, an event or None out.

    threshold: declare a closure at query j when its best trajectory score (mean of -D^ along it)
        is >= threshold (any finite float); None only scores. exclude: stored frames i with
        j - i > exclude are candidates. ds, contrast_window (R_window), vs (velocities): SeqSLAM's
        parameters, the published ones by default. color: "bgr" or "rgb".
    Attributes as ``seqstream.Detector`` (``events``, ``last_scores``, ``bytes_per_frame``, ...).
    """

    def __init__(self, threshold=None, exclude: int = DEFAULT_EXCLUDE, ds: int = DS,
                 contrast_window: int = R_WINDOW, vs=None, color: str = "bgr"):
        vs = velocities(ds) if vs is None else tuple(vs)
        super().__init__(None, descriptor="pixels", seq_len=positive_int("ds", ds, 0) + 1,
                         velocities=vs, exclude=exclude, contrast_window=contrast_window, color=color)
        if threshold is not None and not math.isfinite(float(threshold)):
            raise ValueError(f"threshold must be a finite number or None, got {threshold!r}")
        self.threshold = None if threshold is None else float(threshold)
        off = offsets(ds, vs)
        self._margin = int(off.max())
        self._base = self._margin - off
        self.reset()

    def update_descriptor(self, x) -> dict | None:
        """Match one SeqSLAM descriptor x (D,) (:func:`describe_frames`) against the candidates,
        then store it. Returns the closure event {'frame', 'match', 'score'} or None."""
        x = np.asarray(x, dtype=np.float32).ravel()
        if x.size == 0 or not np.all(np.isfinite(x)):
            raise ValueError(f"descriptor {self.frame_index} is empty or has NaN/inf values")
        if self._db is not None and x.size != self._db.shape[1]:
            raise ValueError(f"descriptor {self.frame_index} has {x.size} dims, the stream's first "
                             f"had {self._db.shape[1]}")
        c = max(self.frame_index - self.exclude, 0)
        s = difference_similarity(self._db[:c], x) if c else np.zeros(0, np.float32)
        return self._match(x, s)

    def _update_frames(self, frames) -> list:
        if not frames:
            return []
        for k, f in enumerate(frames):
            self._check_frame(f, self.frame_index + k)
        return [self.update_descriptor(x) for x in describe_frames(frames, self.color)]


def score_matrix(X, exclude: int = DEFAULT_EXCLUDE, ds: int = DS, contrast_window: int = R_WINDOW,
                 vs=None, S0=None) -> np.ndarray:
    """The (N, N) score matrix the streaming :class:`Detector` thresholds, for greenloop.evaluate.

    X: (N, 2048) SeqSLAM descriptors in stream order (:func:`describe`). Other arguments as the
    Detector's. S0: ``seqslam.similarity_matrix(X)`` where the caller already has it (it is the
    costly part: one SAD per pair of frames). S[i, j] (j - i > exclude) = the best trajectory score
    of database frame i at query j, column j computed from frames 0..j only; non-candidates hold
    the smallest filled score. Returns (N, N) float32.
    """
    X = np.asarray(X, dtype=np.float32)
    if X.ndim != 2 or not np.all(np.isfinite(X)):
        raise ValueError(f"X must be (N, D) finite SeqSLAM descriptors, got shape {X.shape}")
    det = Detector(None, exclude, ds, contrast_window, vs)
    if not len(X):
        return np.zeros((0, 0), np.float32)
    return seqmatch.columns_to_scores(det, X, similarity_matrix(X) if S0 is None else S0)


def tune_knobs(X, GT, exclude: int, tune, seq_lens, contrast_windows, S0=None) -> list[dict]:
    """SeqSLAM on the tuning grid of ``seqstream.tune_knobs`` (the same criterion, the same rows).

    X: (N, 2048) SeqSLAM descriptors; GT, exclude, tune as ``seqstream.tune_knobs``. seq_lens:
    frames per trajectory L (ds = L - 1); contrast_windows: R_window candidates (0 = off); S0: as
    :func:`score_matrix`. Returns one dict per (seq_len, contrast_window): descriptor "seqslam", whitening "none",
    seq_len, contrast_window, AUC-PR_tune_% and R@1_tune_% (``evaluate.per_query`` on the tuning
    queries, in %, 2 decimals), for ``seqmatch.pick_knobs``.
    """
    S0 = similarity_matrix(X) if S0 is None else S0
    rows = []
    for L in seq_lens:
        for cw in contrast_windows:
            det = Detector(None, exclude, positive_int("seq_len", L, 1) - 1, cw)
            q = evaluate.per_query(seqmatch.columns_to_scores(det, X, S0), GT, exclude, queries=tune, ks=(1,))
            rows.append({"descriptor": "seqslam", "whitening": "none", "seq_len": int(L), "contrast_window": int(cw),
                         "AUC-PR_tune_%": round(100 * q["AUC-PR"], 2), "R@1_tune_%": round(100 * q["R@1"], 2)})
    return rows
