"""Realistic long recordings from real frames: photometric and geometric augmentation.

A long recording (10^5 .. 10^6 frames) is made of *passes* over a real route (e.g. Nordland's
summer + winter frames, in order): pass p shows every source frame once, in route order, under
its own condition (a brightness offset, a contrast gain and a blur drawn once per pass) plus a
per-frame jitter (a shift and zoom of the crop, a small brightness change, pixel noise). Frame t of
the recording is source frame t mod M of pass t // M, so the passes revisit the route: the loops of
the recording are the frames of other passes that show the same or a neighbouring source frame.

Augmentation of one frame (uint8, (H, W) gray or (H, W, 3)), in this order:
  1. geometry: an affine crop, zoom z ~ U(1, 1 + zoom) about the centre, shift (dx, dy) ~ U(-shift,
     shift) pixels each, resampled bilinearly to the same size (border replicated);
  2. blur: Gaussian, sigma = the pass's blur (pixels; 0 = none);
  3. photometry: x -> gain * (x - 128) + 128 + offset + jitter, gain and offset per pass,
     jitter ~ U(-brightness_jitter, +) per frame;
  4. noise: N(0, noise^2) per pixel (grey levels); clipped to 0..255, rounded to uint8.
Every draw comes from ``numpy.random.default_rng((seed, pass))`` so a frame is the same whatever
chunk it is made in.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from greenloop.datasets import nordland
from greenloop.util.checks import positive_int
from greenloop.util.progress import bar

__all__ = ["nordland_route", "write_recording", "pass_condition", "augment_frame", "recording"]

DEFAULTS = dict(shift=3.0, zoom=0.10, gain=(0.7, 1.3), offset=30.0, blur=1.2,
                brightness_jitter=8.0, noise=4.0)


def pass_condition(seed: int, p: int, gain=DEFAULTS["gain"], offset: float = DEFAULTS["offset"],
                   blur: float = DEFAULTS["blur"]) -> dict:
    """The condition of pass p: dict(gain ~ U(gain), offset ~ U(-offset, offset) grey levels,
    blur ~ U(0, blur) pixels). Pass 0 is the source as recorded (gain 1, offset 0, blur 0)."""
    if p == 0:
        return dict(gain=1.0, offset=0.0, blur=0.0)
    r = np.random.default_rng((seed, p, 0))
    return dict(gain=float(r.uniform(*gain)), offset=float(r.uniform(-offset, offset)),
                blur=float(r.uniform(0.0, blur)))




def augment_frame(img, cond: dict, rng, shift: float = DEFAULTS["shift"], zoom: float = DEFAULTS["zoom"],
                  brightness_jitter: float = DEFAULTS["brightness_jitter"],
                  noise: float = DEFAULTS["noise"]) -> np.ndarray:
    """One augmented frame (module doc, steps 1-4): img uint8 (H, W[, 3]); cond from
    :func:`pass_condition`; rng a numpy Generator (4 + H*W*C draws). Returns the same shape, uint8."""
    img = np.asarray(img)
    if img.dtype != np.uint8 or img.ndim not in (2, 3):
        raise ValueError(f"img must be a (H, W) or (H, W, 3) uint8 frame, got {img.dtype} {img.shape}")
    h, w = img.shape[:2]
    z = rng.uniform(1.0, 1.0 + zoom)
    dx, dy = rng.uniform(-shift, shift, 2)
    A = cv2.getRotationMatrix2D((w / 2, h / 2), 0.0, z)
    A[:, 2] += (dx, dy)
    out = cv2.warpAffine(img, A, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    if cond["blur"] > 0:
        out = cv2.GaussianBlur(out, (0, 0), cond["blur"])
    x = out.astype(np.float32)
    x = cond["gain"] * (x - 128.0) + 128.0 + cond["offset"] + rng.uniform(-brightness_jitter, brightness_jitter)
    x += rng.standard_normal(x.shape, dtype=np.float32) * noise
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


def recording(source, start: int, stop: int, seed: int = 0, **options):
    """Frames start .. stop - 1 of the augmented recording over ``source`` (module doc).

    source: (M, H, W[, 3]) uint8 real frames in route order. options: those of
    :func:`augment_frame` (and gain / offset / blur of :func:`pass_condition`).
    Yields (t, source index t mod M, augmented frame) in order; pass 0 (t < M) is augmented too
    (shift, zoom, jitter, noise) except for its condition.
    """
    src = np.asarray(source)
    m = len(src)
    if m == 0:
        raise ValueError("source is empty: pass the real frames of a route")
    start, stop = positive_int("start", start, 0), positive_int("stop", stop, 0)
    pc = {k: options.pop(k) for k in ("gain", "offset", "blur") if k in options}
    for p in range(start // m, (stop - 1) // m + 1 if stop > start else start // m):
        cond, rng = pass_condition(seed, p, **pc), np.random.default_rng((seed, p, 1))
        for i in range(m):
            t = p * m + i
            frame = augment_frame(src[i], cond, rng, **options)    # draw every frame of the pass
            if start <= t < stop:
                yield t, i, frame


def nordland_route(src, gray: bool = True) -> np.ndarray:
    """Nordland's summer then winter frames in route order: (7152, 32, 64) uint8 gray, or
    (7152, 32, 64, 3) BGR with gray False. src: the source folder (summer/, winter/) or a clone
    of the source repository; FileNotFoundError naming the fix without it."""
    summer, winter, _ = nordland.check_source(nordland.source_folder(src))
    flag = cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_COLOR
    return np.stack([cv2.imread(str(p), flag) for p in summer + winter])


def write_recording(src, out, n_frames: int, seed: int = 0, progress: bool = True) -> Path:
    """Write frames 0..n_frames-1 of the augmented recording over Nordland (colour) as
    out/0.png ... (a folder ``python -m greenloop detect`` reads). Returns Path(out)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    route = nordland_route(src, gray=False)
    for t, _, f in bar(recording(route, 0, positive_int("n_frames", n_frames, 1), seed), total=n_frames,
                       desc="recording", unit="frame", disable=not progress):
        cv2.imwrite(str(out / f"{t}.png"), f)
    return out
