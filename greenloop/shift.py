"""Robustness perturbations: pixel shifts (the main paper's Table 3) and small rotations."""
from __future__ import annotations

import cv2
import numpy as np


def shift(X: np.ndarray, dx: int = 1, dy: int = 0) -> np.ndarray:
    """Move image content by (dx, dy) pixels, zero-filling the vacated rows/columns.

    X: (N, H, W, C) images. dx > 0 moves content right (the paper: dx=1, leftmost column set to
    zero), dy > 0 moves it down. Returns a new array of the same shape and dtype.
    """
    X = np.asarray(X)
    if X.ndim != 4:
        raise ValueError(f"X must have shape (N, H, W, C), got {X.shape}")
    dx, dy = int(dx), int(dy)
    H, W = X.shape[1:3]
    out = np.zeros_like(X)
    if abs(dx) >= W or abs(dy) >= H:
        return out
    src_y = slice(max(0, -dy), H - max(0, dy))
    dst_y = slice(max(0, dy), H - max(0, -dy))
    src_x = slice(max(0, -dx), W - max(0, dx))
    dst_x = slice(max(0, dx), W - max(0, -dx))
    out[:, dst_y, dst_x] = X[:, src_y, src_x]
    return out


def changed_pixels(X: np.ndarray, Y: np.ndarray, atol: float = 0.0) -> np.ndarray:
    """Number of pixels per image that differ between X and Y (any channel), shape (N,) int."""
    d = np.abs(np.asarray(X, dtype=np.float32) - np.asarray(Y, dtype=np.float32)) > atol
    return d.reshape(len(d), -1, d.shape[-1]).any(-1).sum(1)


def rotate(X: np.ndarray, degrees: float) -> np.ndarray:
    """Rotate images about their centre by ``degrees`` (counter-clockwise), zero-filling corners.

    X: (N, H, W, C) float images. Returns the same shape and dtype.
    """
    X = np.asarray(X)
    if X.ndim != 4:
        raise ValueError(f"X must have shape (N, H, W, C), got {X.shape}")
    H, W, C = X.shape[1:]
    M = cv2.getRotationMatrix2D(((W - 1) / 2, (H - 1) / 2), float(degrees), 1.0)
    out = np.empty_like(X)
    for k in range(len(X)):
        r = cv2.warpAffine(X[k], M, (W, H), flags=cv2.INTER_LINEAR, borderValue=0)
        out[k] = r.reshape(H, W, C)
    return out
