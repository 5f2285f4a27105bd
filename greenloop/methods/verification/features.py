"""Local features of two frames and their matches: ORB or SIFT, Lowe's ratio test and a mutual
nearest-neighbour check.

A match is kept when (1) its nearest neighbour in the other frame is closer than ``ratio`` times
the second nearest (Lowe's test), and (2) the two keypoints are each other's nearest neighbour
(cross-check). Descriptors are computed on the grey image at its native resolution.
"""
from __future__ import annotations

import cv2
import numpy as np

KINDS = ("orb", "sift")


def _detector(kind: str, n_features: int):
    """An OpenCV feature detector-descriptor and its matching norm."""
    if kind == "orb":
        return cv2.ORB_create(nfeatures=n_features), cv2.NORM_HAMMING
    if kind == "sift":
        return cv2.SIFT_create(nfeatures=n_features), cv2.NORM_L2
    raise ValueError(f"unknown feature kind {kind!r}: use one of {KINDS}")


def _grey(frame) -> np.ndarray:
    """(H, W, 3) BGR or (H, W) uint8 frame -> (H, W) uint8 grey; ValueError for anything else."""
    a = np.asarray(frame)
    if a.dtype != np.uint8 or a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (1, 3)):
        raise ValueError(f"a frame must be (H, W, 3) uint8 BGR (or (H, W) grey), got {a.shape} "
                         f"{a.dtype}; read it with cv2.imread")
    if a.ndim == 3 and a.shape[2] == 3:
        return cv2.cvtColor(a, cv2.COLOR_BGR2GRAY)
    return a.reshape(a.shape[0], a.shape[1])


def detect(frame, kind: str = "orb", n_features: int = 2000):
    """Keypoints and descriptors of one frame.

    frame: (H, W, 3) uint8 BGR (or (H, W) grey). kind: 'orb' or 'sift'; n_features: at most
    that many keypoints. Returns (points (K, 2) float32 pixel coordinates x, y; descriptors
    (K, D) uint8 for ORB or float32 for SIFT, or None when K == 0).
    """
    det, _ = _detector(kind, n_features)
    kps, desc = det.detectAndCompute(_grey(frame), None)
    pts = np.array([k.pt for k in kps], dtype=np.float32).reshape(-1, 2)
    return pts, desc


def match(desc_q, desc_m, kind: str = "orb", ratio: float = 0.8) -> np.ndarray:
    """Matches between two descriptor sets that pass the ratio test and the cross-check.

    desc_q: (Kq, D), desc_m: (Km, D) descriptors of :func:`detect` (None: no keypoints).
    ratio: Lowe's ratio (0 < ratio <= 1). Returns (P, 2) int64 rows (index into q, index into m).
    """
    if not 0 < ratio <= 1:
        raise ValueError(f"ratio must be in (0, 1], got {ratio}")
    if desc_q is None or desc_m is None or len(desc_q) < 2 or len(desc_m) < 2:
        return np.zeros((0, 2), np.int64)
    _, norm = _detector(kind, 1)
    bf = cv2.BFMatcher(norm)
    fwd = [p for p in bf.knnMatch(desc_q, desc_m, k=2) if len(p) == 2]
    pairs = np.asarray([(a.queryIdx, a.trainIdx) for a, b in fwd if a.distance < ratio * b.distance],
                       dtype=np.int64).reshape(-1, 2)
    if len(pairs) == 0:
        return pairs
    back = bf.match(desc_m[pairs[:, 1]], desc_q)       # the cross-check: only the rows that passed
    mutual = np.array([m.trainIdx for m in sorted(back, key=lambda m: m.queryIdx)]) == pairs[:, 0]
    return pairs[mutual]
