"""The intrinsics verification uses: a folder's camera.yaml record, or a stated default.

A camera is the record ``datasets.sequence.read_camera`` returns: {'fx', 'fy', 'cx', 'cy'
(pixels, float), 'width', 'height' (int, the image size they belong to), ...}. Where a folder
has no camera.yaml / D435i.yaml, :func:`default_camera` states one from the image size: a
pinhole with a DEFAULT_HFOV_DEG (60 degree) horizontal field of view, square pixels and the
principal point at the image centre (fx = fy = width / (2 tan 30 deg) = 0.866 width). A frame
whose size differs from the record's is handled by scaling the intrinsics linearly to it
(:func:`matrix`), as the synthetic greenhouse scales the D435i's.
"""
from __future__ import annotations

import math

import numpy as np

from greenloop.datasets import sequence

DEFAULT_HFOV_DEG = 60.0   # degrees: the horizontal field of view assumed without camera.yaml
KEYS = ("fx", "fy", "cx", "cy", "width", "height")


def default_camera(width: int, height: int) -> dict:
    """The stated default intrinsics for a width x height image (pixels): fx = fy =
    width / (2 tan(DEFAULT_HFOV_DEG / 2)), cx = width / 2, cy = height / 2.
    Returns the read_camera record {'fx', 'fy', 'cx', 'cy' (float), 'width', 'height' (int)}."""
    if not (int(width) > 0 and int(height) > 0):
        raise ValueError(f"image size must be positive, got {width}x{height}")
    f = width / (2.0 * math.tan(math.radians(DEFAULT_HFOV_DEG) / 2.0))
    return {"fx": f, "fy": f, "cx": width / 2.0, "cy": height / 2.0,
            "width": int(width), "height": int(height)}


def camera_for(folder) -> dict:
    """The intrinsics of a sequence folder (path or ``sequence.Sequence``): its camera.yaml /
    D435i.yaml where it has one, else :func:`default_camera` of its frames' size. The record
    says which under 'source' ('camera.yaml' or 'default (60 deg horizontal field of view)')."""
    seq = sequence.open(folder)
    if seq.has_camera:
        return dict(seq.camera(), source="camera.yaml")
    return dict(default_camera(seq.width, seq.height),
                source=f"default ({DEFAULT_HFOV_DEG:g} deg horizontal field of view)")


def matrix(camera, shape) -> np.ndarray:
    """(3, 3) float64 pinhole matrix K of ``camera`` (a read_camera record) for an image of
    ``shape`` (H, W[, C]): the record's fx, cx scaled by W / width and fy, cy by H / height
    (identity scaling when the frame has the record's size)."""
    if not isinstance(camera, dict) or any(k not in camera for k in KEYS):
        raise ValueError(f"camera must be a dict with {', '.join(KEYS)} (datasets.sequence.read_camera "
                         f"or verification.default_camera), got {camera!r}")
    h, w = int(shape[0]), int(shape[1])
    sx, sy = w / float(camera["width"]), h / float(camera["height"])
    return np.array([[camera["fx"] * sx, 0.0, camera["cx"] * sx],
                     [0.0, camera["fy"] * sy, camera["cy"] * sy],
                     [0.0, 0.0, 1.0]], dtype=np.float64)
