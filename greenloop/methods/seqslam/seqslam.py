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

Where it streams: ``greenloop.methods.seqslam.seqslam_stream`` (streaming code lives in ``speed/``) holds the
streaming ``Detector`` and the ``score_matrix`` / ``tune_knobs`` computed by streaming it; this
module holds its parameters, descriptors and similarity.

How it relates to greenloop-seq (``greenloop.methods.greenloop_seq.seqmatch``): the same stages after the similarity
(contrast normalisation ``seqmatch.contrast_normalise``, the ring of normalised columns and the
trajectory search of ``seqstream.Detector``), reused by subclassing; it differs in more than
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

from greenloop import features
from greenloop.util.checks import positive_int

SIZE = (64, 32)                 # (width, height) of the downsampled frames
PATCH = features.PATCH          # patch-normalisation side length (pixels), the registry's
DESCRIPTOR = features.get("pixels-patchnorm", input_size=SIZE)   # SeqSLAM's descriptor, 2048-d
R_WINDOW = 10                   # contrast enhancement: database templates
DS = 10                         # sequence length (a trajectory spans DS + 1 columns)
V_MIN, V_MAX, V_STEP = 0.8, 1.2, 0.1

__all__ = ["SIZE", "PATCH", "R_WINDOW", "DS", "V_MIN", "V_MAX", "V_STEP", "velocities", "offsets",
           "describe", "describe_frames", "difference_similarity", "similarity_matrix"]


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
    """Decoded frames -> SeqSLAM descriptors (M, 2048) float32: the features registry's
    "pixels-patchnorm" (gray in [0, 1], ``features.patch_normalise`` with P = 8, flattened
    row-major) at SeqSLAM's 64x32 instead of 32x32.
    frames: list of (H, W, 3) uint8 BGR (RGB with color="rgb") or (H, W) gray uint8."""
    return DESCRIPTOR(features.stack_frames(frames), color=color)


def describe(folder, step: int = 1) -> np.ndarray:
    """The SeqSLAM descriptors (N, 2048) float32 of every step-th frame of a sequence folder, the
    same values :func:`describe_frames` gives frame by frame (both are :data:`DESCRIPTOR`)."""
    return DESCRIPTOR.extract(folder, step=step)[0]


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
