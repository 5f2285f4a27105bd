"""Spots: the main paper's classes, groups of L consecutive frames (and a loop-aware variant)."""
from __future__ import annotations

import numpy as np


def group(n_frames: int, frames_per_spot: int) -> np.ndarray:
    """Spot label of every frame: frames [k*L, (k+1)*L) form spot k; the remainder forms the last,
    smaller spot, as in the paper (2260 frames give 46 / 38 / 33 spots for L = 50 / 60 / 70).

    n_frames: N >= 1. frames_per_spot: L >= 1 frames.
    Returns labels (N,) int64 in 0 .. ceil(N / L) - 1.
    """
    if int(frames_per_spot) != frames_per_spot or frames_per_spot < 1:
        raise ValueError(f"frames_per_spot must be an integer >= 1, got {frames_per_spot}")
    if int(n_frames) != n_frames or n_frames < 1:
        raise ValueError(f"n_frames must be an integer >= 1, got {n_frames}")
    return np.arange(int(n_frames), dtype=np.int64) // int(frames_per_spot)


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
