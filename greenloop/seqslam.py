"""SeqSLAM as a baseline of its own (Milford & Wyeth 2012), at OpenSeqSLAM's published parameters.

M. J. Milford and G. F. Wyeth, "SeqSLAM: Visual route-based navigation for sunny summer days and
stormy winter nights", ICRA 2012, pp. 1643-1649; parameters as in OpenSeqSLAM, N. Sünderhauf's
open implementation of it (2013, ``defaultParameters.m`` and ``doFindMatches.m``; the Python ports
pySeqSLAM and others carry the same values). The 2012 paper's own parameter table was not among
the texts searchable here, so the values below are OpenSeqSLAM's defaults:

    downsampled gray frames   64 x 32 pixels (width x height; ``params.downsample.size = [32 64]``)
    patch normalisation       P = 8 pixels (``params.normalization.sideLength``)
    frame difference          mean absolute difference of the patch-normalised frames (SAD / pixels)
    contrast enhancement      R_window = 10 database templates (``params.contrastEnhancement.R``):
                              D^_i = (D_i - mean) / std over rows i - 5 .. i + 5
    sequence length           ds = 10 (a trajectory spans ds + 1 query columns)
    velocities                V_min 0.8 .. V_max 1.2, step 0.1: v = (V_min ds .. V_max ds) / ds;
                              row offsets floor(k v), k = 0 .. ds

What differs from OpenSeqSLAM, and why (the causal stream of a loop-closure detector)
    * The trajectory looks back only: query j uses the columns j - ds .. j (OpenSeqSLAM centres it
      on j and so needs ds / 2 future frames). Candidates are the stored frames i with
      j - i > exclude; a trajectory point before the first stored frame counts as the column's
      mean (seqmatch's rule) instead of OpenSeqSLAM's infinite cost.
    * Scores are higher = more similar: the similarity is the negated difference, so contrast
      enhancement gives -D^ and a trajectory's score is the mean of -D^ along it (the best
      velocity's); the best candidate is OpenSeqSLAM's minimum-cost template.
    * Per query, the score is the best trajectory's score, not OpenSeqSLAM's uniqueness ratio
      (best / second best outside R_window); the candidates' ranking (and so Recall@K) is the same.
    * Patch normalisation keeps float z-scores (OpenSeqSLAM rounds them to integers around 127), and
      the contrast std is the population std (``seqmatch.contrast_normalise``; OpenSeqSLAM: sample).

How it relates to greenloop-seq (``greenloop.seqmatch``): the same stages after the similarity
(contrast normalisation ``seqmatch.contrast_normalise``, the ring of normalised columns and the
trajectory search of ``seqmatch.Detector``), reused here by subclassing; it differs in more than
knobs: the similarity (mean absolute difference of unnormalised 64x32 patch-normalised frames,
not the cosine of L2-normalised descriptors), the frame size and the floor-rounded offsets over
ds + 1 columns. Frame indices, ``exclude`` and ``ds`` are in frames of the stream fed to it.

Memory per stored frame: 64 * 32 float32 = 8192 bytes plus one float32 in each of the ds + 1
buffered columns: 8192 + 4 (ds + 1) bytes.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.distance import cdist

from greenloop import evaluate, seqmatch
from greenloop.datasets.sequence import load_frames, preprocess_image
from greenloop.util.checks import positive_int

SIZE = (64, 32)                 # (width, height) of the downsampled frames
PATCH = 8                       # patch-normalisation side length (pixels)
R_WINDOW = 10                   # contrast enhancement: database templates
DS = 10                         # sequence length (a trajectory spans DS + 1 columns)
V_MIN, V_MAX, V_STEP = 0.8, 1.2, 0.1

__all__ = ["SIZE", "PATCH", "R_WINDOW", "DS", "V_MIN", "V_MAX", "V_STEP", "velocities", "offsets",
           "describe", "describe_frames", "difference_similarity", "similarity_matrix", "Detector",
           "score_matrix", "tune_knobs"]


def velocities(ds: int = DS, v_min: float = V_MIN, v_max: float = V_MAX) -> tuple:
    """OpenSeqSLAM's velocities: every integer move from v_min ds to v_max ds, divided by ds.
    For ds = 10: (0.8, 0.9, 1.0, 1.1, 1.2); ds = 0 (one frame, no trajectory): (1.0,).
    Returns a tuple of floats."""
    if positive_int("ds", ds, 0) == 0:
        return (1.0,)
    lo, hi = int(math.ceil(v_min * ds - 1e-9)), int(math.floor(v_max * ds + 1e-9))
    if not 0 < lo <= hi:
        raise ValueError(f"need 0 < v_min <= v_max with at least one integer move in "
                         f"[v_min ds, v_max ds]; got v_min {v_min}, v_max {v_max}, ds {ds}")
    return tuple(m / ds for m in range(lo, hi + 1))


def offsets(ds: int = DS, vs=None) -> np.ndarray:
    """Row offsets of the trajectories: (V, ds + 1) int64, row v = floor(k v), k = 0..ds (distinct
    rows only; OpenSeqSLAM's ``floor(idx_add .* v)``). vs: velocities (default :func:`velocities`)."""
    vs = velocities(ds) if vs is None else tuple(float(v) for v in vs)
    rows = sorted({tuple(int(math.floor(v * k + 1e-9)) for k in range(ds + 1)) for v in vs})
    return np.asarray(rows, dtype=np.int64)


def describe_frames(frames, color: str = "bgr") -> np.ndarray:
    """Decoded frames -> SeqSLAM descriptors (M, 2048) float32: gray (``preprocess_image``), 64x32,
    in [0, 1], patch-normalised (``seqmatch.patch_normalise``, P = 8), flattened row-major.
    frames: list of (H, W, 3) uint8 BGR (RGB with color="rgb") or (H, W) gray uint8."""
    g = np.stack([preprocess_image(f, SIZE, gray=True, color=color) for f in frames])
    return seqmatch.patch_normalise(g.astype(np.float32) / np.float32(255.0), PATCH)


def describe(folder, step: int = 1) -> np.ndarray:
    """The SeqSLAM descriptors (N, 2048) float32 of every step-th frame of a sequence folder, the
    same values :func:`describe_frames` gives frame by frame (``load_frames`` decodes in colour
    and calls ``preprocess_image``, as the stream does)."""
    g = load_frames(folder, size=SIZE, gray=True, step=step, progress=False)[..., 0]
    return seqmatch.patch_normalise(g, PATCH)


def difference_similarity(db, y) -> np.ndarray:
    """Negated mean absolute difference of one descriptor y (D,) to each stored row of db (C, D):
    (C,) float32, 0 for identical frames, lower = more different (OpenSeqSLAM's D, negated)."""
    db = np.asarray(db, dtype=np.float32)
    if not len(db):
        return np.zeros(0, np.float32)
    y = np.asarray(y, dtype=np.float32).reshape(1, -1)
    return (-cdist(db, y, "cityblock")[:, 0] / y.shape[1]).astype(np.float32)


def similarity_matrix(X) -> np.ndarray:
    """(N, N) float32 :func:`difference_similarity` of every pair of rows of X (N, D); entry
    [i, j] is exactly what the stream computes between stored frame i and query j."""
    X = np.asarray(X, dtype=np.float32)
    return (-cdist(X, X, "cityblock") / X.shape[1]).astype(np.float32)


class Detector(seqmatch.Detector):
    """Streaming SeqSLAM: one decoded frame (or SeqSLAM descriptor) in, an event or None out.

    threshold: declare a closure at query j when its best trajectory score (mean of -D^ along it)
        is >= threshold (any finite float); None only scores. exclude: stored frames i with
        j - i > exclude are candidates. ds, contrast_window (R_window), vs (velocities): SeqSLAM's
        parameters, the published ones by default. color: "bgr" or "rgb".
    Attributes as ``seqmatch.Detector`` (``events``, ``last_scores``, ``bytes_per_frame``, ...).
    """

    def __init__(self, threshold=None, exclude: int = 150, ds: int = DS,
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


def score_matrix(X, exclude: int = 150, ds: int = DS, contrast_window: int = R_WINDOW,
                 vs=None) -> np.ndarray:
    """The (N, N) score matrix the streaming :class:`Detector` thresholds, for greenloop.evaluate.

    X: (N, 2048) SeqSLAM descriptors in stream order (:func:`describe`). Other arguments as the
    Detector's. S[i, j] (j - i > exclude) = the best trajectory score of database frame i at query
    j, column j computed from frames 0..j only; non-candidates hold the smallest filled score.
    Returns (N, N) float32.
    """
    X = np.asarray(X, dtype=np.float32)
    if X.ndim != 2 or not np.all(np.isfinite(X)):
        raise ValueError(f"X must be (N, D) finite SeqSLAM descriptors, got shape {X.shape}")
    det = Detector(None, exclude, ds, contrast_window, vs)
    if not len(X):
        return np.zeros((0, 0), np.float32)
    return seqmatch.columns_to_scores(det, X, similarity_matrix(X))


def tune_knobs(X, GT, exclude: int, tune, seq_lens, contrast_windows) -> list[dict]:
    """SeqSLAM on the tuning grid of ``seqmatch.tune_knobs`` (the same criterion, the same rows).

    X: (N, 2048) SeqSLAM descriptors; GT, exclude, tune as ``seqmatch.tune_knobs``. seq_lens:
    frames per trajectory L (ds = L - 1); contrast_windows: R_window candidates (0 = off).
    Returns one dict per (seq_len, contrast_window): descriptor "seqslam", whitening "none",
    seq_len, contrast_window, AUC-PR_tune_% and R@1_tune_% (``evaluate.per_query`` on the tuning
    queries, in %, 2 decimals), for ``seqmatch.pick_knobs``.
    """
    S0 = similarity_matrix(X)
    rows = []
    for L in seq_lens:
        for cw in contrast_windows:
            det = Detector(None, exclude, positive_int("seq_len", L, 1) - 1, cw)
            q = evaluate.per_query(seqmatch.columns_to_scores(det, X, S0), GT, exclude, queries=tune, ks=(1,))
            rows.append({"descriptor": "seqslam", "whitening": "none", "seq_len": int(L), "contrast_window": int(cw),
                         "AUC-PR_tune_%": round(100 * q["AUC-PR"], 2), "R@1_tune_%": round(100 * q["R@1"], 2)})
    return rows
