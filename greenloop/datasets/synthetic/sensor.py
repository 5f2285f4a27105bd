"""The sensor model: what the camera makes of a clean render (``_sensor``).

Smooth brightness / white-balance drift along the route, seeded per-frame exposure flicker, mild
Gaussian blur, optional per-pixel Gaussian noise (``noise``, default 0: i.i.d. noise does not
compress, so it makes the sequence much larger on disk); depth from quantised disparity (1/8 px,
50 mm baseline) with a smooth seeded error field, no reading beyond 10 m, nearer than 0.2 m or in
the occlusion shadow right of depth edges.
"""
from __future__ import annotations

import cv2
import numpy as np

from greenloop.datasets.sequence import DEPTH_SCALE
from greenloop.datasets.synthetic.render import _Grid
from greenloop.datasets.synthetic.scene import Scene

DEFAULT_NOISE = 0.0       # per-pixel sensor noise std (grey levels); see make_greenhouse
MAX_DEPTH = 10.0          # metres; the D435i gives no reading beyond (written as 0)
MIN_DEPTH = 0.2           # metres; nor closer than this


def _sensor(scene: Scene, img: np.ndarray, depth: np.ndarray, s_m: float, g: _Grid, rng,
            noise: float = 0.0):
    """Camera effects on a clean render: lighting drift, exposure flicker, blur, noise; and
    D435i-like depth.

    img (H, W, 3) uint8 clean render, depth (H, W) metres, s_m the route position in metres,
    rng the frame's generator, noise the per-pixel Gaussian noise std in grey levels.
    Returns (bgr (H, W, 3) uint8, depth (H, W) uint16 in 1/5000 m, 0 = no reading).
    """
    ph = scene.light_phase
    bright = (1.0 + 0.12 * np.sin(2 * np.pi * s_m / 23.0 + ph[0])
              + 0.06 * np.sin(2 * np.pi * s_m / 8.3 + ph[1]))
    wb = 1.0 + 0.045 * np.sin(2 * np.pi * s_m / np.array([31.0, 19.0, 27.0]) + ph[2:5])
    gain = bright * wb * rng.normal(1.0, 0.01) * (1.0 + rng.normal(0.0, 0.005, 3))
    out = cv2.GaussianBlur(img, (0, 0), 0.7 * g.w / 640.0)
    if noise > 0:
        f = out.astype(np.float32) * gain.astype(np.float32)
        f += rng.standard_normal(f.shape, dtype=np.float32) * np.float32(noise)
        bgr = np.clip(f + 0.5, 0, 255).astype(np.uint8)
    else:
        bgr = cv2.multiply(out, tuple(float(v) for v in gain) + (0.0,))

    # depth: disparity (fx * 50 mm baseline) with a smooth error field, quantised to 1/8 px
    fb = g.fx * 0.05
    disp = fb / np.maximum(depth, 1e-3)
    wobble = cv2.resize(rng.standard_normal((6, 8)).astype(np.float32), (g.w, g.h),
                        interpolation=cv2.INTER_CUBIC)
    step = 0.125 * g.w / 640.0
    disp = np.maximum(np.round((disp + wobble * np.float32(0.05 * g.w / 640.0)) / step) * step, step)
    z = fb / disp
    # no reading right of near-to-far jumps (occlusion shadow of the stereo pair), too near/far
    jump = np.zeros(depth.shape, np.uint8)
    jump[:, 1:] = depth[:, 1:] > depth[:, :-1] * 1.15
    jump = cv2.dilate(jump, np.ones((1, max(1, g.w // 160)), np.uint8), anchor=(0, 0))
    valid = (z >= MIN_DEPTH) & (z <= MAX_DEPTH) & (jump == 0)
    d16 = np.where(valid, np.rint(z * DEPTH_SCALE), 0).astype(np.uint16)
    return bgr, d16
