"""Spots: the main paper's classes, groups of L consecutive frames (and a loop-aware variant)."""
from __future__ import annotations

import numpy as np

from greenloop.util.checks import positive_int


def group(n_frames: int, frames_per_spot: int) -> np.ndarray:
    """Spot label of every frame: frames [k*L, (k+1)*L) form spot k; the remainder forms the last,
    smaller spot, as in the paper (2260 frames give 46 / 38 / 33 spots for L = 50 / 60 / 70).

    n_frames: N >= 1. frames_per_spot: L >= 1 frames.
    Returns labels (N,) int64 in 0 .. ceil(N / L) - 1.
    """
    frames_per_spot = positive_int("frames_per_spot", frames_per_spot, whole_floats=True)
    n_frames = positive_int("n_frames", n_frames, whole_floats=True)
    return np.arange(n_frames, dtype=np.int64) // frames_per_spot


def n_spots(n_frames: int, frames_per_spot: int) -> int:
    """Number of spots ``group`` makes: ceil(N / L)."""
    return int(group(n_frames, frames_per_spot)[-1]) + 1


def by_place(frames_per_spot: int, gt: np.ndarray) -> np.ndarray:
    """Loop-aware spot labels: like ``group``, but a frame that revisits an earlier place takes the
    label of that place instead of a new one.

    frames_per_spot: L. gt: (N, N) bool ground-truth loop matrix (greenloop.groundtruth).
    A frame j with loop partners i < j gets the label of its partner nearest in time to the centre
    of the partners (processed in capture order, so chains of revisits resolve); spots left empty
    are dropped and labels renumbered 0 .. K-1 in order of first appearance.
    Returns labels (N,) int64.
    """
    gt = np.asarray(gt, dtype=bool)
    if gt.ndim != 2 or gt.shape[0] != gt.shape[1]:
        raise ValueError(f"gt must be a square (N, N) loop matrix, got shape {gt.shape}")
    labels = group(len(gt), frames_per_spot)
    earlier = np.tril(gt, -1)  # earlier[j, i]: i < j is a loop partner of j
    for j in np.flatnonzero(earlier.any(1)):
        partners = np.flatnonzero(earlier[j])
        labels[j] = labels[partners[len(partners) // 2]]
    _, first = np.unique(labels, return_index=True)
    order = np.argsort(first)
    remap = np.empty(labels.max() + 1, dtype=np.int64)
    remap[np.unique(labels)[order]] = np.arange(len(order))
    return remap[labels]


def first_revisit(gt: np.ndarray) -> int:
    """The first frame that revisits an earlier one: min j such that gt[j, i] for some i < j.

    gt: (N, N) bool ground-truth loop matrix (neighbours already excluded, as
    greenloop.groundtruth makes it). Frames 0 .. first_revisit(gt) - 1 are the *first traversal*:
    every place the robot can later recognise was first seen there.
    Raises ValueError when the sequence has no revisit.
    """
    gt = np.asarray(gt, dtype=bool)
    if gt.ndim != 2 or gt.shape[0] != gt.shape[1]:
        raise ValueError(f"gt must be a square (N, N) loop matrix, got shape {gt.shape}")
    later = np.flatnonzero(np.tril(gt, -1).any(1))
    if not later.size:
        raise ValueError("the ground truth has no loop pairs: the sequence never revisits a place, "
                         "so there is no first traversal to learn places from")
    return int(later[0])


def first_traversal(gt: np.ndarray, frames_per_spot: int, end: int | None = None) -> tuple[int, np.ndarray]:
    """The first traversal a classifier learns its places from: (n_ref, labels (n_ref,) int64).

    gt: (N, N) bool loop matrix (neighbours excluded). end: the first frame after the first
    traversal, None for :func:`first_revisit`. frames_per_spot: L; the traversal's frames form
    ``group(n_ref, L)``'s spots. Raises ValueError naming the fix where the traversal holds fewer
    than 2 spots (a classifier of one class learns nothing) or ``end`` leaves no frame after it.
    """
    n = len(gt)
    n_ref = first_revisit(gt) if end is None else int(end)
    if not 0 < n_ref < n:
        raise ValueError(f"first_traversal_end={n_ref} must lie in 1..{n - 1} (the sequence has {n} frames)")
    L = positive_int("frames_per_spot", frames_per_spot, whole_floats=True)
    if n_ref <= L:
        where = "before the first revisit" if end is None else "before first_traversal_end"
        raise ValueError(f"the first traversal (frames 0..{n_ref - 1}, {where}) holds 1 spot of frames_per_spot={L} "
                         f"frames: a classifier needs at least 2 places to tell apart; to run it, pass frames_per_spot "
                         f"<= {max(n_ref // 2, 1)} (PARAMS='-p frames_per_spot {max(n_ref // 2, 1)}') or a later "
                         f"first_traversal_end")
    return n_ref, group(n_ref, L)


def revisit_targets(labels: np.ndarray, gt: np.ndarray, n_reference: int):
    """Which spots a revisiting frame may be named: the spots of its loop partners.

    labels: (n_reference,) spot labels of the reference frames 0 .. n_reference - 1 (the first
    traversal, e.g. ``group(n_reference, L)``). gt: (N, N) bool loop matrix of the whole sequence,
    N > n_reference. A *query* is a frame t >= n_reference with at least one loop partner among
    the reference frames.
    Returns (queries (Q,) int64 frame indices in capture order, acceptable (Q, K) bool with
    K = labels.max() + 1: acceptable[q, c] is True when spot c holds a loop partner of query q).
    A prediction for query q is correct when ``acceptable[q, pred[q]]``.
    """
    labels = np.asarray(labels, dtype=np.int64)
    gt = np.asarray(gt, dtype=bool)
    if gt.ndim != 2 or gt.shape[0] != gt.shape[1]:
        raise ValueError(f"gt must be a square (N, N) loop matrix, got shape {gt.shape}")
    if labels.shape != (n_reference,) or not 0 < n_reference < len(gt):
        raise ValueError(f"labels must be (n_reference,) with 0 < n_reference < N={len(gt)}, got "
                         f"labels {labels.shape}, n_reference={n_reference}")
    partners = gt[n_reference:, :n_reference]                 # (N - n_ref, n_ref)
    queries = np.flatnonzero(partners.any(1))
    if not queries.size:
        raise ValueError(f"no frame after frame {n_reference} has a loop partner before it: the "
                         f"sequence does not revisit its first traversal")
    K = int(labels.max()) + 1
    onehot = np.zeros((n_reference, K), dtype=bool)
    onehot[np.arange(n_reference), labels] = True
    acceptable = (partners[queries].astype(np.int32) @ onehot.astype(np.int32)) > 0
    return queries + n_reference, acceptable
