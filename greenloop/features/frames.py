"""Input checks and preprocessing of frame arrays (folders are read by greenloop.datasets.sequence).

Grayscale inputs go through ``sequence.preprocess_image``, the one preprocessing path of greenloop;
``rgb_batch`` keeps its own float resize on purpose (see there).
"""
from __future__ import annotations

import os

import cv2
import numpy as np

from greenloop.datasets import sequence
from greenloop.features.registry import DEPTH_MAX_M

def check_frames(frames) -> np.ndarray:
    """Validate an image array: (N, H, W), (N, H, W, 1) or (N, H, W, 3); uint8 0..255 or float in
    [0, 1]. Returns it as an ndarray (not copied)."""
    a = np.asarray(frames)
    if a.ndim not in (3, 4) or (a.ndim == 4 and a.shape[-1] not in (1, 3)) or a.shape[0] == 0:
        raise ValueError(
            f"frames must be an array (N, H, W, 3) RGB, (N, H, W, 1) or (N, H, W) single-channel "
            f"with N >= 1, or a sequence folder; got shape {a.shape}")
    if a.ndim == 3 and a.shape[-1] <= 4:
        raise ValueError(
            f"frames of shape {a.shape} would be {a.shape[0]} images {a.shape[2]} pixels wide: "
            f"for one image pass frames[None] (N, H, W, C); single-channel frames are (N, H, W)")
    if min(a.shape[1:3]) < 1:
        raise ValueError(f"frames have an empty image size: shape {a.shape}")
    if a.dtype == np.uint8:
        return a
    if np.issubdtype(a.dtype, np.floating):
        lo, hi = float(np.nanmin(a)), float(np.nanmax(a))
        if not np.isfinite(a).all():
            raise ValueError("frames contain NaN or infinite values")
        if lo < -1e-6 or hi > 1 + 1e-6:
            raise ValueError(
                f"float frames must lie in [0, 1] (got values in [{lo:.3g}, {hi:.3g}]); pass uint8 "
                f"0..255 images, divide by 255, or for depth in metres use depth_to_uint8()")
        return a
    raise ValueError(f"frames must be uint8 (0..255) or float in [0, 1], got dtype {a.dtype} "
                     f"(for uint16 depth use greenloop.datasets.sequence.load_depth and depth_to_uint8)")


def stack_frames(frames) -> np.ndarray:
    """A list of M same-sized decoded frames -> one (M, ...) array for ``extract``; one frame (a
    stream's case) as a (1, ...) view, so a large camera frame is not copied before it is shrunk."""
    frames = list(frames)
    return np.asarray(frames[0])[None] if len(frames) == 1 else np.stack(frames)


def _resize(img: np.ndarray, size) -> np.ndarray:
    """(h, w[, c]) -> size (W, H), INTER_AREA when shrinking, INTER_LINEAR when enlarging, keeping
    the dtype: unlike ``sequence.preprocess_image`` (uint8 only) it resizes float frames in float."""
    if size is None:
        return img
    h, w = img.shape[:2]
    if (w, h) == tuple(size):
        return img
    interp = cv2.INTER_AREA if w > size[0] else cv2.INTER_LINEAR
    out = cv2.resize(img, tuple(size), interpolation=interp)
    return out[..., None] if img.ndim == 3 and out.ndim == 2 else out


def rgb_batch(a: np.ndarray, size, color: str = "rgb") -> np.ndarray:
    """A slice of checked frames -> float32 RGB 0..255 (b, h, w, 3) at size (w, h).

    color: "rgb", or "bgr" for 3-channel frames as ``cv2.imread`` decodes them (the channels are
    swapped after the resize, which treats each channel alike, so the values are those of
    ``sequence.preprocess_image(im, size, gray=False, color="bgr")``).
    Differs from ``sequence.preprocess_image`` on purpose: float frames are scaled and resized in
    float32 (no rounding to uint8), and single-channel frames are resized before replication."""
    x = a if a.dtype == np.uint8 else a.astype(np.float32) * np.float32(255.0)
    if x.ndim == 3:
        x = x[..., None]
    if size is not None:
        x = np.stack([_resize(im, size) for im in x])
    if x.shape[-1] == 1:   # depth / grayscale: replicate to 3 channels (Qi 2024)
        x = np.repeat(x, 3, axis=-1)
    elif color == "bgr":
        x = x[..., ::-1]
    return np.ascontiguousarray(x, dtype=np.float32)


def rgb_uint8(a: np.ndarray, size, color: str = "rgb") -> np.ndarray:
    """A slice of checked frames -> uint8 RGB (b, h, w, 3) at size (w, h) (None: as they are): float
    frames rounded to uint8 first, single-channel ones replicated, BGR (color="bgr") swapped."""
    out = []
    for im in a:
        if im.dtype != np.uint8:
            im = np.clip(np.rint(im * 255.0), 0, 255).astype(np.uint8)
        im = _resize(im if im.ndim == 3 else im[..., None], size)
        out.append(np.repeat(im, 3, axis=-1) if im.shape[-1] == 1 else im[..., ::-1] if color == "bgr" else im)
    return np.ascontiguousarray(np.stack(out))


def gray_batch(a: np.ndarray, size, as_float: bool, color: str = "rgb") -> np.ndarray:
    """Checked frames (b, h, w[, 1 | 3]) RGB (or BGR with color="bgr") -> grayscale (b, H, W) at
    size (W, H): float32 in [0, 1] (as_float) or uint8. Float frames are rounded to uint8 first,
    then each frame goes through ``sequence.preprocess_image`` (gray first, then INTER_AREA /
    INTER_LINEAR), as folders do."""
    out = []
    for im in a:
        if im.dtype != np.uint8:
            im = np.clip(np.rint(im * 255.0), 0, 255).astype(np.uint8)
        out.append(sequence.preprocess_image(im, size, gray=True, color=color))
    g = np.stack(out)
    return g.astype(np.float32) / np.float32(255.0) if as_float else g


def load(frames_or_folder, size, gray: bool, limit, step=1):
    """Folder -> array via greenloop.datasets.sequence.load_frames (uint8); array -> checked array."""
    if isinstance(frames_or_folder, (str, os.PathLike)):
        return sequence.load_frames(frames_or_folder, size=size, gray=gray, limit=limit,
                                    dtype=np.uint8, step=step)
    a = check_frames(frames_or_folder)
    return a[::step][:limit]


def depth_to_uint8(depth_m, max_depth: float = DEPTH_MAX_M) -> np.ndarray:
    """Map depth in metres to 0..255 by a fixed linear range, for feeding depth to an RGB CNN.

    depth_m: (N, H, W) float metres (0 = no reading, as greenloop.datasets.sequence.load_depth returns).
    0 m -> 0, max_depth (default 10 m, beyond the D435i's useful range) or more -> 255; NaN -> 0.
    A fixed range (not per-frame min/max) keeps the same depth at the same grey level in every
    frame. Returns uint8 (N, H, W).
    """
    if max_depth <= 0:
        raise ValueError(f"max_depth must be > 0 metres, got {max_depth}")
    d = np.nan_to_num(np.asarray(depth_m, dtype=np.float32), nan=0.0, posinf=max_depth, neginf=0.0)
    return np.rint(np.clip(d / np.float32(max_depth), 0.0, 1.0) * 255.0).astype(np.uint8)


def gray_frames(frames_or_folder, size, limit, step, as_float: bool, progress=None,
                color: str = "rgb") -> np.ndarray:
    """A folder (``sequence.load_frames``) or an array (``check_frames`` + ``gray_batch``, channels
    in ``color`` order) -> grayscale (N, H, W) at size (W, H): float32 in [0, 1] (as_float) or uint8."""
    if isinstance(frames_or_folder, (str, os.PathLike)):
        return sequence.load_frames(frames_or_folder, size=size, gray=True, limit=limit,
                                    progress=progress, dtype=np.float32 if as_float else np.uint8,
                                    step=step)[..., 0]
    return gray_batch(load(frames_or_folder, size, True, limit, step), size, as_float, color)
