"""Robustness perturbations: pixel shifts (the main paper's Table 3) and small rotations.

A shift moves image content and fills the vacated rows/columns; which fill it uses (the border)
and whether the shift happens before or after the CNN's downsampling are the two controls of
notebook 04: ``shift(..., border=...)`` and ``shift_before_downsampling``. ``pixel_change``
measures what a perturbation did to the CNN's input. Scoring a classifier under them is notebook
04's study (``greenloop.experiments.shift_robustness``).
"""
from __future__ import annotations

import cv2
import numpy as np

from greenloop.datasets import sequence

BORDERS = ("zero", "replicate")
# unit (dx, dy) of each shift direction, in pixels (x to the right, y down)
DIRECTIONS = {"right": (1, 0), "left": (-1, 0), "down": (0, 1), "up": (0, -1)}


def shift(X: np.ndarray, dx: int = 1, dy: int = 0, border: str = "zero") -> np.ndarray:
    """Move image content by (dx, dy) pixels and fill the vacated rows/columns.

    X: (N, H, W, C) images, any dtype. dx > 0 moves content right (the paper: dx=1, leftmost
    column set to zero), dy > 0 moves it down; dx, dy are whole pixels of X.
    border: "zero" (the paper's) fills the vacated pixels with 0; "replicate" repeats the nearest
        edge row/column of the original image (a 1-px right shift copies column 0 into columns 0
        and 1), so the frame gets no artificial black edge.
    Returns a new array of the same shape and dtype.
    """
    X = np.asarray(X)
    if X.ndim != 4:
        raise ValueError(f"X must have shape (N, H, W, C), got {X.shape}")
    if border not in BORDERS:
        raise ValueError(f"border must be one of {BORDERS}, got {border!r}")
    dx, dy = int(dx), int(dy)
    H, W = X.shape[1:3]
    if border == "replicate":
        rows = np.clip(np.arange(H) - dy, 0, H - 1)
        cols = np.clip(np.arange(W) - dx, 0, W - 1)
        return X[:, rows][:, :, cols]
    out = np.zeros_like(X)
    if abs(dx) >= W or abs(dy) >= H:
        return out
    src_y = slice(max(0, -dy), H - max(0, dy))
    dst_y = slice(max(0, dy), H - max(0, -dy))
    src_x = slice(max(0, -dx), W - max(0, dx))
    dst_x = slice(max(0, dx), W - max(0, -dx))
    out[:, dst_y, dst_x] = X[:, src_y, src_x]
    return out


def full_resolution_offset(full_shape, dx: float, dy: float, size=(32, 32)) -> tuple[int, int]:
    """The shift at full resolution that equals (dx, dy) pixels of the downsampled frame.

    full_shape: (H, W) of the full-resolution frame in pixels. dx, dy: shift in pixels of the
    downsampled frame (fractions allowed). size: (width, height) of the downsampled frame.
    Returns (DX, DY) whole full-resolution pixels: dx * W / width and dy * H / height, rounded to
    the nearest integer (exact for 640x480 -> 32x32: 20 and 15 px per downsampled pixel).
    """
    H, W = int(full_shape[0]), int(full_shape[1])
    return int(round(dx * W / int(size[0]))), int(round(dy * H / int(size[1])))


def shift_before_downsampling(full: np.ndarray, dx: float = 1, dy: float = 0, size=(32, 32),
                              border: str = "zero") -> np.ndarray:
    """Shift full-resolution frames, then downsample them exactly as the CNN's input is made.

    full: (N, H, W, 1) uint8 gray frames at native resolution, as
        ``sequence.load_frames(folder, size=None, dtype=np.uint8)`` returns them.
    dx, dy: shift in pixels of the downsampled frame; the full frame moves by
        ``full_resolution_offset`` (e.g. 20 px for dx=1 at 640 -> 32 wide).
    size: (width, height) of the CNN input. border: as in ``shift``, applied at full resolution.
    Returns (N, size[1], size[0], 1) float32 in [0, 1]: ``sequence.preprocess_image`` (the one
    preprocessing path) on each shifted frame, scaled by 1/255 like ``sequence.load_frames``; with
    dx = dy = 0 it equals ``sequence.load_frames(folder, size)``.
    """
    full = np.asarray(full)
    if full.ndim != 4 or full.shape[-1] != 1 or full.dtype != np.uint8:
        raise ValueError(f"full must be (N, H, W, 1) uint8 gray frames, got {full.shape} {full.dtype}")
    DX, DY = full_resolution_offset(full.shape[1:3], dx, dy, size)
    out = np.empty((len(full), int(size[1]), int(size[0]), 1), np.float32)
    for k in range(len(full)):                 # one frame at a time: no second full-size copy
        moved = shift(full[k:k + 1], DX, DY, border)[0]
        out[k, ..., 0] = sequence.preprocess_image(moved, size, gray=True)
    return out / np.float32(255.0)


CONTROLS = ("zero border (paper)", "replicate border", "full-res shift, zero border",
            "full-res shift, replicate border")


def control_inputs(X: np.ndarray, full: np.ndarray, dx: int = 1, dy: int = 0) -> dict[str, np.ndarray]:
    """The CNN inputs of one shift under each control, keyed by the names in ``CONTROLS``.

    X: (N, h, w, 1) float32 in [0, 1], the CNN's inputs (``sequence.load_frames(folder)``).
    full: (N, H, W, 1) uint8, the same frames at native resolution
        (``sequence.load_frames(folder, size=None, dtype=np.uint8)``).
    dx, dy: the shift in pixels of X. Returns {name: (N, h, w, 1) float32 in [0, 1]}: the
    paper's shift of X (zero border), the same with a replicated border, and the full-resolution
    frames shifted by the equivalent amount with either border, then downsampled.
    """
    if len(full) != len(X):
        raise ValueError(f"full has {len(full)} frames but X has {len(X)}: load both with the same limit/step")
    size = (X.shape[2], X.shape[1])
    return {CONTROLS[0]: shift(X, dx, dy, "zero"), CONTROLS[1]: shift(X, dx, dy, "replicate"),
            CONTROLS[2]: shift_before_downsampling(full, dx, dy, size, "zero"),
            CONTROLS[3]: shift_before_downsampling(full, dx, dy, size, "replicate")}


def pixel_change(X: np.ndarray, Y: np.ndarray, atol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """How much Y differs from X, per image: how many pixels changed and by how much.

    X, Y: (N, H, W, C) images of one shape, e.g. the CNN's inputs, float in [0, 1].
    atol: a pixel counts as changed when any channel differs by more than atol.
    Returns (changed, mean_abs): changed (N,) int64, the number of pixels (of H * W) that changed;
    mean_abs (N,) float64, the absolute difference averaged over all H * W pixels and C channels,
    in the intensity units of X (for the CNN input: 0 = identical, 1 = black <-> white everywhere).
    """
    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    if X.shape != Y.shape or X.ndim != 4:
        raise ValueError(f"X and Y must be (N, H, W, C) of one shape, got {X.shape} and {Y.shape}")
    d = np.abs(X - Y).reshape(len(X), -1, X.shape[-1])
    return (d > atol).any(-1).sum(1).astype(np.int64), d.mean(axis=(1, 2))


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
