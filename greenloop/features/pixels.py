"""The pixel extractor family: raw 32x32 pixels, SeqSLAM patch-normalised pixels, gradient histograms.

Each ``extract_*`` follows the extractor protocol (``registry.Options``); its seconds per image
cover loading, preprocessing and the descriptor.
"""
from __future__ import annotations

import time

import cv2
import numpy as np

from greenloop.features.frames import gray_frames
from greenloop.features.registry import Backbone, GRADIENT_BINS, GRADIENT_CELL, Options, PATCH

_EPS = 1e-6


def patch_normalise(gray, patch: int = PATCH) -> np.ndarray:
    """SeqSLAM patch normalisation: every ``patch`` x ``patch`` block to zero mean, unit std.

    gray: (N, H, W) float images, H and W multiples of ``patch``. A flat block becomes 0.
    Returns (N, H * W) float32, the normalised images flattened row-major.
    """
    g = np.asarray(gray, dtype=np.float32)
    if g.ndim != 3 or g.shape[1] % patch or g.shape[2] % patch:
        raise ValueError(f"patch_normalise needs (N, H, W) images with H, W multiples of {patch}, "
                         f"got shape {g.shape}")
    n, h, w = g.shape
    b = g.reshape(n, h // patch, patch, w // patch, patch)
    mu = b.mean(axis=(2, 4), keepdims=True)
    sd = b.std(axis=(2, 4), keepdims=True)
    z = np.where(sd > _EPS, (b - mu) / np.maximum(sd, _EPS), 0.0)
    return z.reshape(n, h * w).astype(np.float32)


def gradient_histograms(gray, cell: int = GRADIENT_CELL, bins: int = GRADIENT_BINS) -> np.ndarray:
    """A HOG-like layout-keeping descriptor: per-cell histograms of gradient orientation.

    gray: (N, H, W) float images, H and W multiples of ``cell``. Gradients are 3x3 Sobel
    (``cv2.Sobel``, border reflected; ``cv2.cartToPolar``); each pixel adds its gradient magnitude to the bin of its
    unsigned orientation (angle mod pi, ``bins`` equal bins, hard assignment) of its cell; each
    cell's histogram is then L2-normalised (a flat cell stays 0), which removes the cell's
    contrast and so most of an illumination change (Dalal and Triggs 2005, without blocks).
    Returns (N, (H / cell) * (W / cell) * bins) float32, cells row-major, bins innermost.
    """
    g = np.asarray(gray, dtype=np.float32)
    if g.ndim != 3 or g.shape[1] % cell or g.shape[2] % cell:
        raise ValueError(f"gradient_histograms needs (N, H, W) images with H, W multiples of {cell}, "
                         f"got shape {g.shape}")
    n, h, w = g.shape
    polar = [cv2.cartToPolar(cv2.Sobel(x, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(x, cv2.CV_32F, 0, 1, ksize=3),
                             angleInDegrees=True) for x in g]
    mag = np.stack([p[0] for p in polar])
    ang = np.stack([p[1] for p in polar])                      # degrees in [0, 360), ~0.3 degree accuracy
    ang = np.where(ang >= 180.0, ang - 180.0, ang)
    b = np.minimum((ang * np.float32(bins / 180.0)).astype(np.int64), bins - 1)
    cells = (np.arange(h)[:, None] // cell) * (w // cell) + np.arange(w)[None, :] // cell     # (H, W)
    m = (h // cell) * (w // cell) * bins
    idx = (np.arange(n)[:, None, None] * m + cells[None] * bins + b).ravel()
    hist = np.bincount(idx, weights=mag.ravel(), minlength=n * m).reshape(n, h // cell, w // cell, bins)
    norm = np.linalg.norm(hist, axis=3, keepdims=True)
    hist = np.where(norm > _EPS, hist / np.maximum(norm, _EPS), 0.0)
    return hist.reshape(n, -1).astype(np.float32)


def _timed_gray(frames_or_folder, size, opt: Options, post):
    """post(gray frames (N, H, W) float32 in [0, 1]) -> (features (N, D) float32, s/image, {})."""
    t0 = time.perf_counter()
    g = gray_frames(frames_or_folder, size, opt.limit, opt.step, as_float=True, progress=opt.progress,
                    color=opt.color)
    X = post(g)
    dt = time.perf_counter() - t0
    return X.reshape(len(X), -1).astype(np.float32), dt / len(X), {}


def extract_pixels(b: Backbone, frames_or_folder, source, size, opt: Options):
    """'pixels': the gray frame in [0, 1], flattened (N, W * H)."""
    return _timed_gray(frames_or_folder, size, opt, lambda g: g)


def extract_patchnorm(b: Backbone, frames_or_folder, source, size, opt: Options):
    """'pixels-patchnorm': :func:`patch_normalise` of the gray frames (N, W * H)."""
    return _timed_gray(frames_or_folder, size, opt, patch_normalise)


def extract_gradients(b: Backbone, frames_or_folder, source, size, opt: Options):
    """'gradients': :func:`gradient_histograms` of the gray frames (N, cells * bins)."""
    return _timed_gray(frames_or_folder, size, opt, gradient_histograms)
