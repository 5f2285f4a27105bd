"""Robust two-view geometry of matched points: the essential matrix, a homography, PnP with depth.

Every fit returns a :class:`Fit` whose R, t map query-camera points into the match camera
(X_match = R X_query + t, OpenCV camera axes: x right, y down, z forward), i.e. the pose
T_match_query = T_match^-1 T_query of two camera-to-world poses. The estimators are OpenCV's USAC
(MAGSAC++) for the essential matrix and the homography, and RANSAC PnP (solvePnPRansac) for the
metric pose.
"""
from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

PROB = 0.999          # RANSAC / USAC confidence
MIN_DEPTH, MAX_DEPTH = 0.1, 20.0   # metres: depth outside this range is no 3-D point
EDGE = 0.05          # a depth edge: the 3x3 neighbourhood spans more than this share of the depth
STILL = 0.01          # |t| / plane distance below which a homography says the camera only rotated


class Fit(NamedTuple):
    """One fitted model. model: 'essential' | 'homography' | 'pnp'; inliers: (P,) bool over the
    points it was fitted on; R: (3, 3) float64; t: (3,) float64 (metres for 'pnp', else a unit
    direction, or zeros where a homography says the camera only rotated); metric: t in metres."""
    model: str
    inliers: np.ndarray
    R: np.ndarray
    t: np.ndarray
    metric: bool


def _unit(t) -> np.ndarray:
    """(3,) float64 unit vector of t (zeros for a zero vector)."""
    t = np.asarray(t, np.float64).reshape(3)
    n = np.linalg.norm(t)
    return t / n if n > 0 else t


def essential(pq, pm, K, px: float) -> Fit | None:
    """Essential matrix by USAC MAGSAC++ and the pose by ``recoverPose``.

    pq, pm: (P, 2) float32 matched pixels in the query and the match frame; K: (3, 3) intrinsics;
    px: inlier threshold (pixels). Inliers are the points that fit E and pass the cheirality check
    (in front of both cameras). Returns None with fewer than 5 points or when no model is found.
    """
    if len(pq) < 5:
        return None
    E, mask = cv2.findEssentialMat(pq, pm, K, method=cv2.USAC_MAGSAC, prob=PROB, threshold=px)
    if E is None or E.shape[0] < 3 or mask is None:
        return None
    _, R, t, good = cv2.recoverPose(E[:3], pq, pm, K, mask=mask.copy())
    return Fit("essential", good.ravel() > 0, R, _unit(t), False)


def homography(pq, pm, K, px: float) -> Fit | None:
    """Homography (match = H query) by USAC MAGSAC++ and its decomposition into R, t.

    pq, pm, K, px: as :func:`essential`. Of the decompositions that keep the inliers in front of
    both cameras, the one whose plane normal is closest to the optical axis is taken (the plane
    faces the camera: a downward camera over a field, a wall ahead). t is the unit direction of
    t / d (d: the plane's distance), zeros where |t / d| < STILL (a rotation only).
    Returns None with fewer than 4 points or when no model is found.
    """
    if len(pq) < 4:
        return None
    H, mask = cv2.findHomography(pq, pm, cv2.USAC_MAGSAC, px, confidence=PROB)
    if H is None or mask is None:
        return None
    inl = mask.ravel() > 0
    _, Rs, ts, ns = cv2.decomposeHomographyMat(H, K)
    Kinv = np.linalg.inv(K)
    norm = lambda p: (np.c_[p, np.ones(len(p))] @ Kinv.T)[:, :2].reshape(-1, 1, 2).astype(np.float32)
    keep = cv2.filterHomographyDecompByVisibleRefpoints(Rs, ns, norm(pq[inl]), norm(pm[inl]))
    idx = list(range(len(Rs))) if keep is None else [int(i) for i in np.ravel(keep)]
    best = max(idx, key=lambda i: abs(float(ns[i][2, 0])))
    t = np.asarray(ts[best], np.float64).ravel()
    return Fit("homography", inl, np.asarray(Rs[best], np.float64),
               np.zeros(3) if np.linalg.norm(t) < STILL else _unit(t), False)


def back_project(points, depth, K):
    """3-D points (camera frame, metres) of pixels with valid depth.

    points: (P, 2) pixels x, y; depth: (H, W) metres; K: (3, 3). Depth is read at the nearest
    pixel; valid is finite, within [MIN_DEPTH, MAX_DEPTH], and off a depth edge (the 3x3
    neighbourhood's extremes within EDGE of it: a corner keypoint on an object's outline would
    take the background's depth). Returns (X (P, 3) float64 with nan rows where invalid,
    valid (P,) bool).
    """
    d = np.asarray(depth, np.float32)
    d = np.where(np.isfinite(d), d, 0.0).astype(np.float32)
    box = np.ones((3, 3), np.uint8)
    lo, hi = cv2.erode(d, box), cv2.dilate(d, box)
    h, w = d.shape
    u = np.clip(np.rint(points[:, 0]).astype(int), 0, w - 1)
    v = np.clip(np.rint(points[:, 1]).astype(int), 0, h - 1)
    z = d[v, u].astype(np.float64)
    valid = (z >= MIN_DEPTH) & (z <= MAX_DEPTH) & (hi[v, u] - lo[v, u] <= EDGE * z)
    X = np.stack([(points[:, 0] - K[0, 2]) * z / K[0, 0], (points[:, 1] - K[1, 2]) * z / K[1, 1], z], 1)
    X[~valid] = np.nan
    return X, valid


def pnp(p_img, X, K, px: float, image_is_query: bool) -> Fit | None:
    """Metric pose by RANSAC PnP: 3-D points of one frame against their pixels in the other.

    p_img: (P, 2) pixels in the frame without the 3-D points; X: (P, 3) those points in the other
    camera's frame (metres, from :func:`back_project`, all valid); K: (3, 3); px: reprojection
    threshold (pixels). image_is_query: the pixels are the query's (3-D points from the match
    frame's depth; PnP gives T_query_match, inverted here) or the match's (query depth).
    Returns a Fit with t in metres, or None with fewer than 6 points or no pose.
    """
    if len(p_img) < 6:
        return None
    ok, rvec, tvec, idx = cv2.solvePnPRansac(X.astype(np.float64), p_img.astype(np.float64), K, None,
                                             iterationsCount=1000, reprojectionError=px, confidence=PROB)
    if not ok or idx is None:
        return None
    inl = np.zeros(len(p_img), bool)
    inl[np.ravel(idx)] = True
    R, t = cv2.Rodrigues(rvec)[0], tvec.ravel()
    if image_is_query:                       # X_query = R X_match + t  ->  X_match = R^T (X_query - t)
        R, t = R.T, -R.T @ t
    return Fit("pnp", inl, R, np.asarray(t, np.float64), True)
