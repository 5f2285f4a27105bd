"""The camera: an Intel D435i's colour intrinsics, scaled linearly to the rendered size.

``camera_intrinsics(size)`` gives fx, fy, cx, cy in pixels for ``size`` = (width, height) pixels
(at least MIN_SIZE); ``write_camera_yaml`` writes them as the sequence folder's camera.yaml
(ORB-SLAM / D435i layout).
"""
from __future__ import annotations

from pathlib import Path

from greenloop.datasets.sequence import DEPTH_SCALE

# (width, height) and intrinsics in pixels
DEFAULT_SIZE = (640, 480)
MIN_SIZE = (160, 120)
D435I_640x480 = {"fx": 602.897, "fy": 602.837, "cx": 328.28, "cy": 241.4}


def camera_intrinsics(size=DEFAULT_SIZE) -> dict:
    """D435i colour intrinsics scaled linearly to ``size`` = (width, height) pixels.

    Returns {'fx', 'fy', 'cx', 'cy' (pixels, float), 'width', 'height' (int)}.
    """
    w, h = _check_size(size)
    sx, sy = w / 640.0, h / 480.0
    k = D435I_640x480
    return {"fx": k["fx"] * sx, "fy": k["fy"] * sy, "cx": k["cx"] * sx, "cy": k["cy"] * sy,
            "width": w, "height": h}


def _check_size(size) -> tuple[int, int]:
    """``size`` as (width, height) ints, or ValueError unless it is a pair >= MIN_SIZE pixels."""
    try:
        w, h = (int(v) for v in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height) in pixels, got {size!r}") from None
    if w < MIN_SIZE[0] or h < MIN_SIZE[1]:
        raise ValueError(f"size {w}x{h} is too small: use at least {MIN_SIZE[0]}x{MIN_SIZE[1]} "
                         f"(e.g. size=(160, 120) or --size 160x120)")
    return w, h


def write_camera_yaml(path, size=DEFAULT_SIZE) -> None:
    """Write an ORB-SLAM style camera.yaml (D435i layout) for ``size`` = (width, height)."""
    k = camera_intrinsics(size)
    text = (
        "%YAML:1.0\n"
        "# greenloop synthetic greenhouse: Intel D435i colour intrinsics scaled to "
        f"{k['width']}x{k['height']}\n"
        f"Camera.fx: {k['fx']:.6f}\nCamera.fy: {k['fy']:.6f}\n"
        f"Camera.cx: {k['cx']:.6f}\nCamera.cy: {k['cy']:.6f}\n\n"
        "Camera.k1: 0.0\nCamera.k2: 0.0\nCamera.p1: 0.0\nCamera.p2: 0.0\n\n"
        f"Camera.width: {k['width']}\nCamera.height: {k['height']}\n\n"
        "# Camera frames per second\nCamera.fps: 30.0\n\n"
        "# IR projector baseline times fx (aprox.)\nCamera.bf: 40.0\n\n"
        "# Color order of the images (0: BGR, 1: RGB)\nCamera.RGB: 1\n\n"
        "# Close/Far threshold. Baseline times.\nThDepth: 40.0\n\n"
        f"# Depthmap values factor (metres = value / {DEPTH_SCALE:g})\n"
        f"DepthMapFactor: {DEPTH_SCALE:.1f}\n")
    Path(path).write_text(text)
