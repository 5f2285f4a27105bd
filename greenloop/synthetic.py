"""The embedded default dataset: a rendered stand-in for the real GreenHouse sequence.

``make_greenhouse(folder)`` renders a camera run through a 3D greenhouse hall (a plant factory
like the one of the real set: rows of raised cultivation beds with lettuce-like plants, blank
beds, posts, overhead pipes, LED bars, roof trusses, an irrigation gantry, a water tank, a
cabinet, fans, doors) and writes it as a sequence folder (see ``greenloop.data``)::

    rgb/0.png ...            8-bit colour, 640x480 by default
    depth/0.png ...          uint16, metres = value / 5000, 0 = no reading (beyond 10 m, edges)
    CameraTrajectory.txt     TUM, t = frame number, camera-to-world, OpenCV camera axes
                             (x right, y down, z forward), relative to the first camera
    camera.yaml              ORB-SLAM / D435i layout (Camera.fx ... DepthMapFactor)
    synthetic.json           the generator's arguments (marks the folder as synthetic)

The route (``route``) is a fixed polyline through the aisles, rounded at the corners,
arc-length parametrised and sampled uniformly, so every ``n_frames`` gives the same ~61 m path:
up aisle A1, down aisle A3, up aisle A2, down aisle A3 again (a same-direction revisit in the
middle of the run) and back into aisle A1, retracing the first ~4.5 m (the end-to-start revisit
of the real set, whose frames ~2068-2260 return to frames ~0-138).

Coordinates: the hall ("world") frame has x across the hall, y up, z along the beds, in metres,
origin at a floor corner. Files use the first camera's frame, as ORB-SLAM writes them.

Rendering is a painter's algorithm with OpenCV: the hall box (floor, walls, roof) is ray-cast per
pixel and textured from an atlas; boxes, beams and prisms are convex polygons clipped at the
near plane and filled far-to-near; plant leaves are projected 3D ellipses. Depth comes from the
same painter pass (a primitive-id buffer plus each primitive's plane equation).

Sensor model: smooth brightness / white-balance drift along the route, seeded per-frame exposure
flicker, mild Gaussian blur, optional per-pixel Gaussian noise (``noise``, default 0: i.i.d.
noise does not compress, so it makes the sequence much larger on disk); depth from quantised
disparity (1/8 px, 50 mm baseline) with a smooth seeded error field, no reading beyond 10 m,
nearer than 0.2 m or in the occlusion shadow right of depth edges.

Public: ``make_greenhouse`` (and the CLI ``python -m greenloop.synthetic``), ``route``,
``route_world``, ``route_waypoints``, ``route_length``, ``camera_intrinsics``,
``write_camera_yaml``, ``build_scene``, ``render_frame``.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter1d

from .data import DEPTH_SCALE, write_trajectory

# ---------------------------------------------------------------------------------------------
# constants (metres, degrees, pixels at 640x480)
# ---------------------------------------------------------------------------------------------
DEFAULT_FRAMES = 2260
DEFAULT_SIZE = (640, 480)
MIN_FRAMES = 200
MIN_SIZE = (160, 120)
D435I_640x480 = {"fx": 602.897, "fy": 602.837, "cx": 328.28, "cy": 241.4}
DEFAULT_NOISE = 0.0       # per-pixel sensor noise std (grey levels); see make_greenhouse
MAX_DEPTH = 10.0          # metres; the D435i gives no reading beyond (written as 0)
MIN_DEPTH = 0.2           # metres; nor closer than this
NEAR = 0.1                # near clipping plane (metres)
FAR = 30.0                # primitives farther than this are culled (metres)

HALL_WIDTH = 13.6         # x extent
HALL_HEIGHT = 4.2         # y of the roof plane (ceiling of the ray-cast box)
BED_PITCH = 2.0
BED_WIDTH = 1.1
BED_TOP = 0.62
BED_X = tuple(1.8 + BED_PITCH * k for k in range(6))   # bed centre lines
BED_Z0 = 4.0
BED_LENGTH = 8.5
FRONT_AISLE_Z = 1.8       # cross aisle in front of the beds (route line)
BACK_AISLE_Z = BED_Z0 + BED_LENGTH + 1.4
HALL_DEPTH = BACK_AISLE_Z + 2.4
AISLE_A1, AISLE_A2, AISLE_A3 = 4.8, 6.8, 8.8
TURN_RADIUS = 0.95
CAM_HEIGHT = 0.95
CAM_PITCH_DEG = -6.0
RETRACE = 4.6             # metres of aisle A1 driven again at the end
TEX_RES = 0.02            # metres per texel of the hall textures
FOG_DIST = 28.0           # metres: haze, contrast halves every ~19 m
FOG_COLOR = np.array([205, 210, 205], np.float32)
LIGHT = np.array([0.35, 1.0, 0.25]) / np.linalg.norm([0.35, 1.0, 0.25])
PNG_LEVEL = 5             # zlib level: 5 is ~10% smaller than 3 at about the same speed
SHIFT = 4                 # sub-pixel bits for OpenCV drawing
ONE = 1 << SHIFT


# ---------------------------------------------------------------------------------------------
# camera
# ---------------------------------------------------------------------------------------------
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
    try:
        w, h = (int(v) for v in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height) in pixels, got {size!r}") from None
    if w < MIN_SIZE[0] or h < MIN_SIZE[1]:
        raise ValueError(f"size {w}x{h} is too small: use at least {MIN_SIZE[0]}x{MIN_SIZE[1]} "
                         f"(e.g. size=(160, 120) or --size 160x120)")
    return w, h


def _check_frames(n_frames) -> int:
    if isinstance(n_frames, bool) or int(n_frames) != n_frames:
        raise ValueError(f"n_frames must be an integer, got {n_frames!r}")
    n = int(n_frames)
    if n < MIN_FRAMES:
        raise ValueError(f"n_frames={n} is too few for the route to close its loop: use "
                         f"n_frames >= {MIN_FRAMES} (the real set has {DEFAULT_FRAMES})")
    return n


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or int(seed) != seed or int(seed) < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


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


# ---------------------------------------------------------------------------------------------
# route
# ---------------------------------------------------------------------------------------------
def route_waypoints() -> np.ndarray:
    """Corner points of the route in the hall frame, shape (K, 2) as (x, z) metres.

    A1 up, across the back, A3 down, A2 up, A3 down again, across the front, A1 up again
    (the last leg starts where the first one did, 4 cm further right, and runs RETRACE metres).
    """
    f = FRONT_AISLE_Z
    b = BACK_AISLE_Z
    start = f + TURN_RADIUS
    d = 0.04
    return np.array([
        (AISLE_A1, start), (AISLE_A1, b), (AISLE_A3, b), (AISLE_A3, f), (AISLE_A2, f),
        (AISLE_A2, b), (AISLE_A3, b), (AISLE_A3, f), (AISLE_A1 + d, f),
        (AISLE_A1 + d, start + RETRACE)], dtype=np.float64)


def _filleted_path(points: np.ndarray, radius: float, step: float = 0.005):
    """Polyline with circular arcs of ``radius`` at the corners, sampled every ``step`` metres.

    points: (K, 2) corner points (x, z). Returns (s (M,), xz (M, 2), heading (M,)) with s the
    arc length in metres and heading the tangent angle atan2(dz, dx) in radians (unwrapped).
    """
    pts = np.asarray(points, dtype=np.float64)
    seg = np.diff(pts, axis=0)
    lens = np.linalg.norm(seg, axis=1)
    if np.any(lens <= 0):
        raise ValueError("route waypoints must be distinct")
    dirs = seg / lens[:, None]
    k = len(pts)
    tl = np.zeros(k)
    rad = np.zeros(k)
    turn = np.zeros(k)
    for i in range(1, k - 1):
        din, dout = dirs[i - 1], dirs[i]
        ang = math.atan2(din[0] * dout[1] - din[1] * dout[0], float(din @ dout))
        if abs(ang) < 1e-9:
            continue
        t = radius * math.tan(abs(ang) / 2)
        avail_in = lens[i - 1] * (1.0 if i == 1 else 0.5)
        avail_out = lens[i] * (1.0 if i == k - 2 else 0.5)
        t = min(t, avail_in, avail_out)
        tl[i], rad[i], turn[i] = t, t / math.tan(abs(ang) / 2), ang
    xs, hs = [], []
    for i in range(k - 1):
        a = pts[i] + dirs[i] * tl[i]
        b = pts[i + 1] - dirs[i] * tl[i + 1]
        h = math.atan2(dirs[i][1], dirs[i][0])
        n = max(2, int(np.ceil(np.linalg.norm(b - a) / step)) + 1)
        u = np.linspace(0.0, 1.0, n)[:-1, None]
        xs.append(a + (b - a) * u)
        hs.append(np.full(len(u), h))
        if i + 1 < k - 1 and tl[i + 1] > 0:
            ang, r = turn[i + 1], rad[i + 1]
            sgn = 1.0 if ang > 0 else -1.0
            nrm = np.array([-dirs[i][1], dirs[i][0]]) * sgn
            c = b + nrm * r
            a0 = math.atan2(b[1] - c[1], b[0] - c[0])
            m = max(2, int(np.ceil(abs(ang) * r / step)) + 1)
            phi = np.linspace(0.0, ang, m)[:-1]
            xs.append(c + r * np.stack([np.cos(a0 + phi), np.sin(a0 + phi)], 1))
            hs.append(h + phi)
    xs.append(pts[-1][None])
    hs.append(np.array([math.atan2(dirs[-1][1], dirs[-1][0])]))
    xz = np.concatenate(xs)
    heading = np.unwrap(np.concatenate(hs))
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xz, axis=0), axis=1))])
    return s, xz, heading


def route_length() -> float:
    """Length of the route in metres (the same for every n_frames)."""
    s, _, _ = _filleted_path(route_waypoints(), TURN_RADIUS)
    return float(s[-1])


def _look_rotation(yaw, pitch, roll) -> np.ndarray:
    """Camera-to-hall rotations (N, 3, 3), OpenCV camera axes (x right, y down, z forward).

    yaw: (N,) heading angle atan2(dz, dx) of the optical axis in the floor plane (radians);
    pitch: (N,) elevation of the optical axis (radians, negative = looking down);
    roll: (N,) rotation about the optical axis (radians).
    """
    cp = np.cos(pitch)
    fwd = np.stack([cp * np.cos(yaw), np.sin(pitch), cp * np.sin(yaw)], 1)
    up = np.array([0.0, 1.0, 0.0])
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right, axis=1, keepdims=True)
    down = np.cross(fwd, right)
    cr, sr = np.cos(roll)[:, None], np.sin(roll)[:, None]
    x = cr * right + sr * down
    y = -sr * right + cr * down
    return np.stack([x, y, fwd], axis=2)


def route_world(n_frames: int = DEFAULT_FRAMES, seed: int = 0):
    """Camera poses along the route in the hall frame.

    n_frames: number of poses (>= 200), sampled uniformly in arc length over the same route.
    seed: seeds the small smoothed jitter (sub-cm position, ~0.3 degree rotation) and the slow
        height / heading wander, both defined per metre of route so they do not depend on
        n_frames.
    Returns (poses (N, 4, 4) float64 camera-to-hall, OpenCV camera axes; s (N,) arc length in
    metres of each pose along the route).
    """
    n = _check_frames(n_frames)
    seed = _check_seed(seed)
    s_d, xz_d, head_d = _filleted_path(route_waypoints(), TURN_RADIUS)
    step = s_d[1] - s_d[0]
    head_d = gaussian_filter1d(head_d, 0.2 / step, mode="nearest")   # smooth yaw rate
    length = s_d[-1]
    s = np.linspace(0.0, length, n)
    x = np.interp(s, s_d, xz_d[:, 0])
    z = np.interp(s, s_d, xz_d[:, 1])
    yaw = np.interp(s, s_d, head_d)

    # jitter on a 1 cm grid along the route, smoothed over ~8 cm: independent of n_frames
    rng = np.random.default_rng([seed, 0x5EED])
    grid = np.arange(0.0, length + 0.02, 0.01)
    noise = gaussian_filter1d(rng.standard_normal((len(grid), 5)), 8.0, axis=0, mode="wrap")
    noise /= noise.std(axis=0, keepdims=True)
    jit = np.stack([np.interp(s, grid, noise[:, c]) for c in range(5)], 1)
    ph = rng.uniform(0, 2 * np.pi, 6)
    lateral = 0.004 * jit[:, 0] + 0.03 * np.sin(2 * np.pi * s / 9.1 + ph[0])
    height = (CAM_HEIGHT + 0.004 * jit[:, 1] + 0.02 * np.sin(2 * np.pi * s / 3.3 + ph[1])
              + 0.015 * np.sin(2 * np.pi * s / 7.7 + ph[2]))
    yaw = (yaw + np.radians(0.3) * jit[:, 2] + np.radians(1.0) * np.sin(2 * np.pi * s / 6.1 + ph[3]))
    pitch = (np.radians(CAM_PITCH_DEG) + np.radians(0.3) * jit[:, 3]
             + np.radians(0.8) * np.sin(2 * np.pi * s / 5.3 + ph[4]))
    roll = np.radians(0.25) * jit[:, 4] + np.radians(0.3) * np.sin(2 * np.pi * s / 4.4 + ph[5])

    tang = np.stack([np.interp(s, s_d, np.cos(head_d)), np.interp(s, s_d, np.sin(head_d))], 1)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    left = np.stack([-tang[:, 1], tang[:, 0]], 1)
    x = x + lateral * left[:, 0]
    z = z + lateral * left[:, 1]

    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = _look_rotation(yaw, pitch, roll)
    poses[:, :3, 3] = np.stack([x, height, z], 1)
    return poses, s


def route(n_frames: int = DEFAULT_FRAMES, seed: int = 0) -> np.ndarray:
    """Ground-truth camera poses as written to CameraTrajectory.txt.

    Returns (N, 4, 4) float64 camera-to-world matrices in metres, OpenCV camera axes
    (x right, y down, z forward), expressed in the first camera's frame (pose 0 = identity),
    like ORB-SLAM's output for the real set. See ``route_world`` for the arguments.
    """
    poses, _ = route_world(n_frames, seed)
    return np.linalg.inv(poses[0])[None] @ poses


# ---------------------------------------------------------------------------------------------
# scene
# ---------------------------------------------------------------------------------------------
@dataclass
class Scene:
    """Everything a frame needs; hall frame (x across, y up, z along), metres, colours BGR 0..255.

    quads (Q, 4, 3) polygon corners; quad_color (Q, 3) shaded colour; quad_normal (Q, 3) outward
    unit normals; quad_obj (Q,) object index; obj_lo / obj_hi (O, 3) object bounding boxes;
    obj_far (O,) draw order key: True = farthest corner (beds: drawn before what stands on them),
    False = nearest point. leaf_center / leaf_a1 / leaf_a2 (L, 3) leaf ellipse centre and
    semi-axis vectors; leaf_color (L, 3); plant_center (P, 3), plant_radius (P,),
    plant_color (P, 3), plant_flat (P,) (0 = rosette, 1 = flat disc), plant_leaves (P + 1,) CSR
    offsets into the leaf arrays. atlas (Ha, Wa, 3) uint8 hall textures; atlas_rows (6,) first
    atlas row of floor, roof, left, right, front, back. light_phase (6,): phases (radians) of the lighting drift.
    """
    quads: np.ndarray
    quad_color: np.ndarray
    quad_normal: np.ndarray
    quad_obj: np.ndarray
    obj_lo: np.ndarray
    obj_hi: np.ndarray
    obj_far: np.ndarray
    leaf_center: np.ndarray
    leaf_a1: np.ndarray
    leaf_a2: np.ndarray
    leaf_color: np.ndarray
    plant_center: np.ndarray
    plant_radius: np.ndarray
    plant_color: np.ndarray
    plant_flat: np.ndarray
    plant_leaves: np.ndarray
    atlas: np.ndarray
    atlas_rows: np.ndarray
    light_phase: np.ndarray


def _new_builder() -> dict:
    """Empty scene accumulator: lists of polygons, colours, object ids and object boxes."""
    return {"quads": [], "color": [], "obj": [], "lo": [], "hi": [], "far": [], "emit": []}


def _add_object(sb: dict, quads, color, far=False, emissive=False) -> None:
    """Append a convex object given as a list of (k<=4, 3) polygons (triangles padded)."""
    quads = [np.asarray(q, dtype=np.float64) for q in quads]
    quads = [np.vstack([q, q[-1:]]) if len(q) == 3 else q for q in quads]
    allv = np.concatenate(quads)
    oid = len(sb["lo"])
    sb["lo"].append(allv.min(0))
    sb["hi"].append(allv.max(0))
    sb["far"].append(far)
    for q in quads:
        sb["quads"].append(q)
        sb["color"].append(color)
        sb["obj"].append(oid)
        sb["emit"].append(emissive)


def _box(sb, lo, hi, color, far=False, emissive=False) -> None:
    """Axis-aligned box from corner ``lo`` to ``hi`` (x, y, z metres)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    c = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]])
    faces = [(0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (3, 2, 6, 7), (0, 3, 7, 4), (1, 2, 6, 5)]
    _add_object(sb, [c[list(f)] for f in faces], color, far, emissive)


def _beam(sb, p0, p1, width, color, sides=4, emissive=False) -> None:
    """Prism of ``sides`` faces and across-size ``width`` between 3D points p0 and p1."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    ax = p1 - p0
    ax /= np.linalg.norm(ax)
    ref = np.array([0.0, 1.0, 0.0]) if abs(ax[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(ax, ref)
    u /= np.linalg.norm(u)
    v = np.cross(ax, u)
    ang = np.pi / sides + 2 * np.pi * np.arange(sides) / sides
    r = width / 2 / np.cos(np.pi / sides)
    ring = r * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v)
    quads = [np.array([p0 + ring[i], p0 + ring[(i + 1) % sides], p1 + ring[(i + 1) % sides],
                       p1 + ring[i]]) for i in range(sides)]
    _add_object(sb, quads, color, False, emissive)


def _prism(sb, cx, cz, radius, y0, y1, color, sides=16) -> None:
    """Vertical cylinder (``sides``-gon prism) with a top, centre (cx, cz), floor-standing."""
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = np.stack([cx + radius * np.cos(ang), np.zeros(sides), cz + radius * np.sin(ang)], 1)
    lo, hi = ring + [0, y0, 0], ring + [0, y1, 0]
    quads = [np.array([lo[i], lo[(i + 1) % sides], hi[(i + 1) % sides], hi[i]])
             for i in range(sides)]
    for i in range(1, sides - 1, 2):   # top as a fan of quads (last may be a triangle)
        quads.append(hi[[0, i, i + 1, min(i + 2, sides - 1)]])
    _add_object(sb, quads, color)


def _smooth_noise(rng, shape, cell) -> np.ndarray:
    """Smooth random field of ``shape`` (rows, cols), feature size ~``cell`` texels, std ~1."""
    h, w = shape
    gh, gw = max(2, int(h / cell) + 2), max(2, int(w / cell) + 2)
    g = rng.standard_normal((gh, gw)).astype(np.float32)
    big = cv2.resize(g, (int(gw * cell), int(gh * cell)), interpolation=cv2.INTER_CUBIC)
    out = big[:h, :w]
    return out / max(float(out.std()), 1e-6)


def _texture_floor(rng) -> np.ndarray:
    """Concrete floor texture (rows = z, cols = x, TEX_RES m per texel), BGR uint8 (Hz, Wx, 3)."""
    s = 1.0 / TEX_RES
    h, w = int(round(HALL_DEPTH * s)), int(round(HALL_WIDTH * s))
    base = np.array([112, 117, 120], np.float32)
    n = 14 * _smooth_noise(rng, (h, w), 60) + 8 * _smooth_noise(rng, (h, w), 14)
    tex = base[None, None] + n[..., None] * np.array([1.0, 1.0, 0.95], np.float32)
    shade = np.ones((h, w), np.float32)
    for xc in BED_X:   # damp, darker floor around and under the beds (algae, shadow)
        x0, x1 = int((xc - BED_WIDTH / 2 - 0.12) * s), int((xc + BED_WIDTH / 2 + 0.12) * s)
        z0, z1 = int((BED_Z0 - 0.1) * s), int((BED_Z0 + BED_LENGTH + 0.1) * s)
        shade[z0:z1, x0:x1] = 0.55
    shade = cv2.GaussianBlur(shade, (0, 0), 6)
    tex *= shade[..., None]
    greenish = np.clip(1.0 - shade, 0, 1)[..., None] * np.array([-10, 8, -8], np.float32)
    tex += greenish
    # sunlit patches from the roof glazing
    sun = np.clip(_smooth_noise(rng, (h, w), 90) - 0.9, 0, None)
    tex *= (1.0 + 0.35 * np.minimum(sun, 1.2))[..., None]
    tex = np.clip(tex, 0, 255).astype(np.uint8)
    # expansion joints across the hall every 2.5 m, a drain grate in front, safety lines
    for zj in np.arange(2.5, HALL_DEPTH, 2.5):
        cv2.line(tex, (0, int(zj * s)), (w, int(zj * s)), (70, 72, 74), 2, cv2.LINE_AA)
    zg = int(0.9 * s)
    cv2.rectangle(tex, (int(2.5 * s), zg - 8), (int(11.0 * s), zg + 8), (60, 62, 64), -1)
    for xg in range(int(2.5 * s), int(11.0 * s), 5):
        cv2.line(tex, (xg, zg - 8), (xg, zg + 8), (110, 112, 115), 1)
    for z_line in (0.45, HALL_DEPTH - 0.5):
        cv2.line(tex, (int(0.3 * s), int(z_line * s)), (int((HALL_WIDTH - 0.3) * s), int(z_line * s)),
                 (40, 190, 215), 5, cv2.LINE_AA)
    # a garden hose lying in the back cross aisle, a puddle in the front one
    t = np.linspace(0, 1, 60)
    hx = (2.2 + 3.5 * t + 0.25 * np.sin(9 * t)) * s
    hz = (BACK_AISLE_Z + 0.55 + 0.3 * np.sin(5 * t + 1)) * s
    cv2.polylines(tex, [np.stack([hx, hz], 1).astype(np.int32)], False, (40, 120, 30), 3, cv2.LINE_AA)
    cv2.ellipse(tex, (int(10.2 * s), int(2.6 * s)), (int(0.7 * s), int(0.35 * s)), 10, 0, 360,
                (85, 82, 78), -1, cv2.LINE_AA)
    # fallen leaves and debris
    for _ in range(500):
        x, z = rng.uniform(0, w), rng.uniform(0, h)
        col = (40, int(rng.uniform(90, 150)), 60) if rng.random() < 0.6 else (60, 80, 100)
        cv2.circle(tex, (int(x), int(z)), int(rng.integers(1, 3)), col, -1)
    return cv2.GaussianBlur(tex, (0, 0), 0.8)


def _texture_roof(rng) -> np.ndarray:
    """Glazed roof with glazing bars and a shade screen (rows = z, cols = x), BGR uint8."""
    s = 1.0 / TEX_RES
    h, w = int(round(HALL_DEPTH * s)), int(round(HALL_WIDTH * s))
    tex = np.full((h, w, 3), (238, 240, 236), np.float32)
    tex += 6 * _smooth_noise(rng, (h, w), 50)[..., None]
    # a shade screen pulled over part of the roof
    tex[int(6.0 * s):int(11.0 * s), int(1.0 * s):int(7.5 * s)] *= np.array([0.86, 0.88, 0.9])
    tex = np.clip(tex, 0, 255).astype(np.uint8)
    for x in np.arange(0.0, HALL_WIDTH, 0.8):
        cv2.line(tex, (int(x * s), 0), (int(x * s), h), (150, 152, 150), 3)
    for z in np.arange(0.0, HALL_DEPTH, 2.5):
        cv2.line(tex, (0, int(z * s)), (w, int(z * s)), (140, 142, 140), 4)
    return cv2.GaussianBlur(tex, (0, 0), 1.0)


def _wall_base(rng, length: float, outside_seed_scale: float) -> np.ndarray:
    """Greenhouse wall: concrete knee wall, translucent panels, mullions. Rows from the top."""
    s = 1.0 / TEX_RES
    h, w = int(round(HALL_HEIGHT * s)), int(round(length * s))
    tex = np.full((h, w, 3), (222, 226, 220), np.float32)
    # vegetation outside seen through the panels: soft dark green blobs low on the wall
    veg = np.clip(_smooth_noise(rng, (h, w), outside_seed_scale) * 0.8 + 0.2, 0, None)
    rows = np.linspace(HALL_HEIGHT, 0, h)[:, None]
    veg *= np.clip((2.6 - rows) / 1.4, 0, 1)
    tex -= (veg[..., None] * np.array([70, 45, 70], np.float32))
    tex += 5 * _smooth_noise(rng, (h, w), 20)[..., None]
    knee = int((HALL_HEIGHT - 0.8) * s)
    tex[knee:] = 150 + 8 * _smooth_noise(rng, (h - knee, w), 10)[..., None]
    tex = np.clip(tex, 0, 255).astype(np.uint8)
    for x in np.arange(0.0, length, 1.25):
        cv2.line(tex, (int(x * s), 0), (int(x * s), knee), (140, 142, 138), 4)
    for y in (2.2, 3.4):
        r = int((HALL_HEIGHT - y) * s)
        cv2.line(tex, (0, r), (w, r), (135, 137, 133), 5)
    for y in (0.3, 0.5):   # heating pipes along the wall
        r = int((HALL_HEIGHT - y) * s)
        cv2.line(tex, (0, r), (w, r), (228, 230, 230), 4)
        cv2.line(tex, (0, r + 3), (w, r + 3), (120, 120, 120), 1)
    return tex


def _rect(tex, x0, y0, x1, y1, color, border=None):
    """Fill a wall rectangle given in metres (x along the wall, y = height above the floor)."""
    s = 1.0 / TEX_RES
    h = tex.shape[0]
    p0 = (int(x0 * s), int(h - y1 * s))
    p1 = (int(x1 * s), int(h - y0 * s))
    cv2.rectangle(tex, p0, p1, color, -1)
    if border is not None:
        cv2.rectangle(tex, p0, p1, border, 3)


def _texture_walls(rng) -> list[np.ndarray]:
    """Left (x=0), right (x=W), front (z=0) and back (z=D) wall textures, rows from the top."""
    s = 1.0 / TEX_RES
    left = _wall_base(rng, HALL_DEPTH, 70)
    right = _wall_base(rng, HALL_DEPTH, 45)
    front = _wall_base(rng, HALL_WIDTH, 55)
    back = _wall_base(rng, HALL_WIDTH, 80)
    # left wall: a wet cooling pad, an electrical box with signs, a hose reel
    _rect(left, 6.0, 0.8, 11.0, 2.0, (70, 125, 165))
    for x in np.arange(6.0, 11.0, 0.06):
        cv2.line(left, (int(x * s), int(left.shape[0] - 2.0 * s)),
                 (int((x + 0.05) * s), int(left.shape[0] - 0.8 * s)), (55, 100, 140), 1)
    _rect(left, 2.4, 1.1, 3.2, 2.0, (205, 205, 200), (90, 90, 90))
    _rect(left, 2.55, 1.6, 3.05, 1.8, (40, 200, 230))
    cv2.circle(left, (int(13.0 * s), int(left.shape[0] - 1.2 * s)), int(0.35 * s), (40, 140, 60), -1)
    cv2.circle(left, (int(13.0 * s), int(left.shape[0] - 1.2 * s)), int(0.1 * s), (60, 60, 60), -1)
    # right wall: a roll-up vent open to the sky and trees, a fire extinguisher, a poster
    _rect(right, 3.5, 1.2, 9.5, 2.1, (225, 200, 170))
    vent = right[int(right.shape[0] - 2.1 * s):int(right.shape[0] - 1.2 * s), int(3.5 * s):int(9.5 * s)]
    trees = np.clip(_smooth_noise(rng, vent.shape[:2], 12), -1, 2)
    mask = (trees > 0.1)[..., None]
    vent[:] = np.where(mask, np.array([50, 105, 60], np.uint8), vent)
    _rect(right, 3.5, 2.1, 9.5, 2.25, (90, 95, 100))
    _rect(right, 12.2, 0.9, 12.45, 1.5, (30, 30, 200))
    _rect(right, 1.0, 1.3, 1.9, 2.3, (160, 90, 30), (240, 240, 240))
    # front wall: a big sliding door with an exit sign, a control panel
    _rect(front, 5.9, 0.0, 8.7, 2.7, (118, 104, 92), (70, 65, 60))
    for y in np.arange(0.2, 2.7, 0.3):
        _rect(front, 6.0, y, 8.6, y + 0.04, (95, 85, 75))
    _rect(front, 7.25, 0.0, 7.35, 2.7, (60, 58, 56))
    _rect(front, 6.3, 1.5, 7.0, 2.2, (200, 190, 170), (60, 60, 60))
    _rect(front, 6.9, 2.85, 7.7, 3.1, (60, 170, 40))
    _rect(front, 9.8, 1.1, 10.6, 1.9, (230, 232, 232), (100, 100, 100))
    for i, col in enumerate([(40, 40, 220), (40, 200, 40), (40, 200, 230)]):
        cv2.circle(front, (int((9.95 + 0.15 * i) * s), int(front.shape[0] - 1.7 * s)), 3, col, -1)
    # back wall: three exhaust fans, a door
    for xc in (2.6, 7.0, 11.4):
        c = (int(xc * s), int(back.shape[0] - 1.9 * s))
        cv2.rectangle(back, (c[0] - 32, c[1] - 32), (c[0] + 32, c[1] + 32), (185, 188, 190), -1)
        cv2.circle(back, c, 29, (45, 48, 50), -1)
        for a in np.arange(0, 360, 15):
            e = (int(c[0] + 29 * np.cos(np.radians(a))), int(c[1] + 29 * np.sin(np.radians(a))))
            cv2.line(back, c, e, (150, 150, 150), 1, cv2.LINE_AA)
        cv2.circle(back, c, 5, (170, 170, 170), -1)
    _rect(back, 4.3, 0.0, 5.3, 2.1, (80, 120, 60), (50, 60, 50))
    return [cv2.GaussianBlur(t, (0, 0), 0.8) for t in (left, right, front, back)]


def _plants_for_bed(rng, k: int, xc: float):
    """Plant list for bed ``k``: rows of (x, z, kind) with kind a key of PLANT_KINDS or 'hole'."""
    zs = np.arange(BED_Z0 + 0.18, BED_Z0 + BED_LENGTH - 0.1, 0.25)
    rows = np.array([-0.42, -0.15, 0.15, 0.42]) * (BED_WIDTH / 1.1)
    out = []
    for j, dx in enumerate(rows):
        for i, z in enumerate(zs):
            z = z + (0.125 if j % 2 else 0.0)
            if z > BED_Z0 + BED_LENGTH - 0.1:
                continue
            f = (z - BED_Z0) / BED_LENGTH
            if k == 0:
                kind = "hole"
            elif k == 1:
                kind = "green_large"
            elif k == 2:
                kind = "red" if f < 0.5 else "green"
            elif k == 3:
                kind = "seedling" if f < 0.4 else "yellow"
            elif k == 4:
                kind = "hole" if f < 0.35 else "dark"
            else:
                kind = "green" if (int(f * 7) % 3) else "yellow"
            if kind != "hole" and rng.random() < (0.04 if k != 5 else 0.12):
                kind = "hole"   # a missing plant leaves its hole
            out.append((xc + dx + rng.normal(0, 0.012), z + rng.normal(0, 0.012), kind))
    return out


# kind: (radius m, radius spread, leaves, tilt deg, outer BGR, heart BGR, leaf length, height)
PLANT_KINDS = {
    "green_large": (0.135, 0.18, 11, 28, (55, 160, 80), (95, 215, 160), 0.62, 1.0),
    "green": (0.105, 0.2, 9, 30, (60, 170, 95), (100, 220, 170), 0.6, 0.9),
    "yellow": (0.10, 0.2, 9, 32, (60, 190, 155), (110, 230, 205), 0.6, 0.9),
    "red": (0.11, 0.2, 10, 30, (70, 55, 120), (80, 160, 120), 0.6, 0.9),
    "dark": (0.12, 0.15, 8, 55, (45, 105, 50), (75, 160, 95), 0.75, 1.4),
    "seedling": (0.045, 0.25, 5, 35, (80, 190, 110), (110, 225, 170), 0.65, 0.8),
}


def _make_plants(rng):
    """Leaves of every plant. Returns the plant_* and leaf_* arrays of ``Scene`` (see there)."""
    centers, radii, colors, flats, offsets = [], [], [], [], [0]
    lc, la1, la2, lcol = [], [], [], []
    for k, xc in enumerate(BED_X):
        for x, z, kind in _plants_for_bed(rng, k, xc):
            if kind == "hole":
                c = np.array([x, BED_TOP + 0.003, z])
                r = 0.022
                centers.append(c)
                radii.append(r)
                colors.append((58, 62, 60))
                flats.append(1)
                lc.append(c)
                la1.append((r, 0, 0))
                la2.append((0, 0, r))
                lcol.append((58, 62, 60))
                offsets.append(len(lc))
                continue
            R0, spread, nl, tilt, outer, heart, llen, hfac = PLANT_KINDS[kind]
            R = R0 * float(np.exp(rng.normal(0, spread)))
            nl = max(3, int(nl + rng.integers(-1, 2)))
            base = np.array([x, BED_TOP, z])
            tone = rng.uniform(0.85, 1.1) * np.array(outer, float)
            phi0 = rng.uniform(0, 2 * np.pi)
            cols = []
            for i in range(nl + 2):
                inner = i >= nl
                phi = phi0 + i * 2.39996 + rng.normal(0, 0.2)
                rho = R * (rng.uniform(0.05, 0.2) if inner else rng.uniform(0.35, 0.6))
                alpha = np.radians(tilt + (25 if inner else 0) + rng.normal(0, 8))
                L1 = R * llen * (0.6 if inner else 1.0) * rng.uniform(0.85, 1.15)
                L2 = L1 * rng.uniform(0.6, 0.8)
                d = np.array([np.cos(phi), 0.0, np.sin(phi)])
                p = np.array([-np.sin(phi), 0.0, np.cos(phi)])
                hgt = R * hfac * (0.25 + 0.55 * (1 - rho / R)) + np.sin(alpha) * L1 * 0.4
                lc.append(base + rho * d + [0, hgt, 0])
                la1.append(L1 * (np.cos(alpha) * d + [0, np.sin(alpha), 0]))
                la2.append(L2 * p)
                mix = 0.75 if inner else rng.uniform(0.0, 0.3)
                col = (1 - mix) * tone + mix * np.array(heart, float)
                col *= rng.uniform(0.8, 1.12) * (0.85 + 0.25 * np.sin(alpha))
                lcol.append(np.clip(col, 0, 255))
                cols.append(col)
            centers.append(base + [0, R * hfac * 0.45, 0])
            radii.append(R)
            colors.append(np.mean(cols, 0) * 0.92)
            flats.append(0)
            offsets.append(len(lc))
    f32 = lambda a: np.asarray(a, np.float32)   # noqa: E731
    return (f32(centers), f32(radii), f32(colors), np.asarray(flats, np.int8),
            np.asarray(offsets, np.int64), f32(lc), f32(la1), f32(la2), f32(lcol))


def build_scene(seed: int = 0) -> Scene:
    """Build the greenhouse hall for ``seed`` (plant sizes/colours, textures, lighting drift).

    The layout (beds, aisles, equipment) is fixed; the seed varies the details. Returns a
    ``Scene``.
    """
    seed = _check_seed(seed)
    rng = np.random.default_rng([seed, 0x5CE4E])
    sb = _new_builder()
    _add_beds(sb)
    truss_z = np.arange(3.0, HALL_DEPTH - 0.5, 3.0)
    _add_posts(sb, truss_z)
    _add_roof_structure(sb, truss_z)
    _add_pipes_and_lights(sb)
    _add_gantry(sb)
    _add_equipment(sb)
    # the random draws below keep their order: quad colours, plants, textures, lighting phases
    quads, n, color, obj, lo, hi = _finish_quads(sb, rng)
    plants = _make_plants(rng)
    atlas, rows = _texture_atlas(rng)
    return Scene(quads=quads, quad_color=color.astype(np.float32), quad_normal=n, quad_obj=obj,
                 obj_lo=lo, obj_hi=hi, obj_far=np.asarray(sb["far"]),
                 plant_center=plants[0], plant_radius=plants[1], plant_color=plants[2],
                 plant_flat=plants[3], plant_leaves=plants[4], leaf_center=plants[5],
                 leaf_a1=plants[6], leaf_a2=plants[7], leaf_color=plants[8],
                 atlas=atlas, atlas_rows=np.asarray(rows, np.float32),
                 light_phase=rng.uniform(0, 2 * np.pi, 6))


def _add_beds(sb: dict) -> None:
    """Cultivation beds (tray, growing surface, stand), split into 1 m modules along z so the
    painter's order stays right. Draws no random numbers."""
    tops = [(215, 220, 218), (60, 72, 88), (218, 222, 220), (215, 220, 218), (60, 72, 88),
            (210, 215, 215)]
    for k, xc in enumerate(BED_X):
        edges = np.linspace(BED_Z0, BED_Z0 + BED_LENGTH, int(round(BED_LENGTH)) + 1)
        for z0, z1 in zip(edges[:-1], edges[1:]):
            _box(sb, (xc - BED_WIDTH / 2, BED_TOP - 0.13, z0), (xc + BED_WIDTH / 2, BED_TOP, z1),
                 (200, 202, 200), far=True)
            # the growing surface, a hair above the tray
            top = np.array([[xc - BED_WIDTH / 2 + 0.04, BED_TOP + 0.001, z0],
                            [xc + BED_WIDTH / 2 - 0.04, BED_TOP + 0.001, z0],
                            [xc + BED_WIDTH / 2 - 0.04, BED_TOP + 0.001, z1],
                            [xc - BED_WIDTH / 2 + 0.04, BED_TOP + 0.001, z1]])
            _add_object(sb, [top], tops[k], far=True)
            _box(sb, (xc - BED_WIDTH / 2 + 0.1, 0.0, z0), (xc + BED_WIDTH / 2 - 0.1, BED_TOP - 0.13, z1),
                 (62, 64, 66), far=True)


def _add_posts(sb: dict, truss_z: np.ndarray) -> None:
    """Posts along the walls and through every other bed, on the truss lines ``truss_z`` (T,)
    (z metres)."""
    for zt in truss_z:
        for xp in (0.12, HALL_WIDTH - 0.12) + tuple(BED_X[1::2]):
            inside_bed = BED_Z0 < zt < BED_Z0 + BED_LENGTH
            if xp in BED_X and not inside_bed:
                continue
            _box(sb, (xp - 0.05, 0.0, zt - 0.05), (xp + 0.05, HALL_HEIGHT, zt + 0.05), (190, 192, 188))


def _add_roof_structure(sb: dict, truss_z: np.ndarray) -> None:
    """Roof trusses on ``truss_z`` (T,) and at both end walls (z metres): bottom and top chords
    in 2.3 m pieces, verticals and diagonals; then the purlins along the hall."""
    W, D = HALL_WIDTH, HALL_DEPTH
    grey = (175, 177, 172)
    for zt in np.concatenate([truss_z, [0.3, D - 0.3]]):
        xs = np.linspace(0.0, W, 7)
        for x0, x1 in zip(xs[:-1], xs[1:]):
            _box(sb, (x0, 3.35, zt - 0.04), (x1, 3.43, zt + 0.04), grey)
            _box(sb, (x0, 3.97, zt - 0.04), (x1, 4.05, zt + 0.04), grey)
        xw = np.linspace(0.0, W, 11)
        for i, (x0, x1) in enumerate(zip(xw[:-1], xw[1:])):
            _beam(sb, (x0, 3.43, zt), (x0, 3.97, zt), 0.04, grey)
            a, b = ((x0, 3.43, zt), (x1, 3.97, zt)) if i % 2 == 0 else ((x0, 3.97, zt), (x1, 3.43, zt))
            _beam(sb, a, b, 0.035, grey)
    for xp in np.arange(1.2, W, 2.4):
        for z0 in np.arange(0.0, D - 0.01, 2.5):
            _box(sb, (xp - 0.03, 3.9, z0), (xp + 0.03, 3.97, min(z0 + 2.5, D)), grey)


def _add_pipes_and_lights(sb: dict) -> None:
    """Irrigation pipes over the beds, LED bars (emissive) with their housings over the beds, and
    a big air duct above aisle A2."""
    D = HALL_DEPTH
    z_lo, z_hi = 0.6, D - 0.6
    for xc in BED_X:
        for z0 in np.arange(z_lo, z_hi, 2.0):
            _beam(sb, (xc + 0.3, 2.45, z0), (xc + 0.3, 2.45, min(z0 + 2.0, z_hi)), 0.045,
                  (170, 165, 160))
        for z0 in np.arange(BED_Z0 + 0.2, BED_Z0 + BED_LENGTH - 0.5, 1.6):
            _box(sb, (xc - 0.07, 1.95, z0), (xc + 0.07, 2.0, z0 + 1.2), (235, 225, 250), emissive=True)
            _box(sb, (xc - 0.09, 2.0, z0), (xc + 0.09, 2.05, z0 + 1.2), (120, 120, 125))
    for z0 in np.arange(0.0, D - 0.01, 2.0):
        _beam(sb, (AISLE_A2, 3.0, z0), (AISLE_A2, 3.0, min(z0 + 2.0, D)), 0.45, (225, 228, 230), sides=8)


def _add_gantry(sb: dict) -> None:
    """The automated irrigation gantry across the beds, on rails along the walls, with its
    carriage and nozzles."""
    W = HALL_WIDTH
    zg = BED_Z0 + 0.55 * BED_LENGTH
    orange = (30, 135, 235)
    xs = np.linspace(0.35, W - 0.35, 7)
    for x0, x1 in zip(xs[:-1], xs[1:]):
        _box(sb, (x0, 2.1, zg - 0.12), (x1, 2.35, zg + 0.12), orange)
        _beam(sb, (x0, 1.7, zg), (x1, 1.7, zg), 0.04, (90, 90, 95))
    for xl in (0.35, W - 0.35):
        _box(sb, (xl - 0.08, 0.0, zg - 0.15), (xl + 0.08, 2.35, zg + 0.15), orange)
    _box(sb, (AISLE_A3 - 0.9, 1.85, zg - 0.2), (AISLE_A3 - 0.4, 2.1, zg + 0.2), (80, 80, 85))
    for xn in np.arange(0.8, W - 0.5, 0.5):
        _beam(sb, (xn, 1.7, zg), (xn, 1.55, zg), 0.03, (40, 40, 40))


def _add_equipment(sb: dict) -> None:
    """Front area: water tank, electrical cabinet, crates; back area: dosing unit with canisters,
    a cart with plant trays; a robot in the aisle between the last two beds."""
    D = HALL_DEPTH
    _prism(sb, 11.9, 1.15, 0.6, 0.0, 1.7, (170, 115, 45))
    _box(sb, (1.0, 0.0, 0.02), (2.0, 1.9, 0.5), (175, 182, 186))
    _box(sb, (1.05, 0.15, 0.5), (1.48, 1.8, 0.52), (150, 158, 162))
    _box(sb, (1.52, 0.15, 0.5), (1.95, 1.8, 0.52), (150, 158, 162))
    for i in range(3):
        for j in range(2):
            _box(sb, (10.0 + 0.62 * j, 0.3 * i, 0.3), (10.55 + 0.62 * j, 0.3 * i + 0.28, 0.7),
                 (40, 40, 190) if (i + j) % 2 else (30, 60, 200))
    _box(sb, (9.4, 0.0, D - 0.75), (11.0, 1.35, D - 0.02), (228, 228, 226))
    for i, col in enumerate([(40, 40, 200), (200, 90, 30), (40, 160, 40)]):
        _prism(sb, 9.75 + 0.5 * i, D - 0.4, 0.17, 1.35, 1.85, col, sides=10)
    _box(sb, (1.6, 0.15, BACK_AISLE_Z - 0.2), (2.9, 0.85, BACK_AISLE_Z + 0.5), (60, 110, 150))
    for i in range(3):
        _box(sb, (1.7 + 0.4 * i, 0.85, BACK_AISLE_Z - 0.1), (2.05 + 0.4 * i, 1.15, BACK_AISLE_Z + 0.4),
             (50, 150, 60))
    _box(sb, (10.5, 0.05, BED_Z0 + 2.0), (11.1, 1.25, BED_Z0 + 2.8), (30, 200, 235))
    _box(sb, (10.55, 1.25, BED_Z0 + 2.1), (11.05, 1.3, BED_Z0 + 2.7), (40, 40, 40))


def _finish_quads(sb: dict, rng):
    """Stack the builder's polygons, orient their normals outwards and shade them.

    Returns (quads (Q, 4, 3) float64 metres, normals (Q, 3) outward unit vectors, colour (Q, 3)
    float64 BGR 0..255 after Lambert shading (emissive quads unshaded) and a seeded +-4 %
    brightness per quad, obj (Q,) object index, lo / hi (O, 3) object bounding boxes in metres).
    Draws Q uniforms from ``rng``.
    """
    quads = np.stack(sb["quads"]).astype(np.float64)
    obj = np.asarray(sb["obj"])
    lo, hi = np.stack(sb["lo"]), np.stack(sb["hi"])
    centre = (lo + hi)[obj] / 2
    n = np.cross(quads[:, 1] - quads[:, 0], quads[:, 3] - quads[:, 0])
    bad = np.linalg.norm(n, axis=1) < 1e-12
    n[bad] = np.cross(quads[bad, 1] - quads[bad, 0], quads[bad, 2] - quads[bad, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    flip = np.einsum("ij,ij->i", n, quads.mean(1) - centre) < 0
    n[flip] *= -1
    color = np.asarray(sb["color"], np.float64)
    emit = np.asarray(sb["emit"])
    shade = 0.5 + 0.55 * np.clip(n @ LIGHT, 0, None)
    color = np.where(emit[:, None], color, color * shade[:, None])
    color = np.clip(color * rng.uniform(0.96, 1.04, (len(color), 1)), 0, 255)
    return quads, n, color, obj, lo, hi


def _texture_atlas(rng):
    """Floor, roof and the four wall textures stacked into one atlas, each followed by two rows
    repeating its last row (so bilinear lookups never bleed into the next texture).

    Returns (atlas (Ha, Wa, 3) uint8 BGR, rows (6,) int first atlas row of floor, roof, left,
    right, front, back). Draws the textures' random numbers from ``rng`` in that order.
    """
    floor, roof = _texture_floor(rng), _texture_roof(rng)
    walls = _texture_walls(rng)
    faces = [floor, roof] + walls
    width = max(t.shape[1] for t in faces)
    rows = np.cumsum([0] + [t.shape[0] + 2 for t in faces])[:-1]
    atlas = np.zeros((rows[-1] + faces[-1].shape[0] + 2, width, 3), np.uint8)
    for r, t in zip(rows, faces):
        atlas[r:r + t.shape[0], :t.shape[1]] = t
        atlas[r + t.shape[0]:r + t.shape[0] + 2, :t.shape[1]] = t[-1:]
    return atlas, rows


# ---------------------------------------------------------------------------------------------
# rendering
# ---------------------------------------------------------------------------------------------
def _clip_near(poly: np.ndarray, near: float = NEAR) -> np.ndarray:
    """Sutherland-Hodgman clip of a camera-frame polygon (k, 3) against z >= near."""
    out = []
    k = len(poly)
    for i in range(k):
        a, b = poly[i], poly[(i + 1) % k]
        ina, inb = a[2] >= near, b[2] >= near
        if ina:
            out.append(a)
        if ina != inb:
            t = (near - a[2]) / (b[2] - a[2])
            out.append(a + t * (b - a))
    return np.array(out) if len(out) >= 3 else np.zeros((0, 3))


@dataclass
class _Grid:
    """Per-size precomputations: normalised ray grid and post-processing helpers."""
    fx: float
    fy: float
    cx: float
    cy: float
    w: int
    h: int
    xg: np.ndarray        # (H, W) float32 (u - cx) / fx
    yg: np.ndarray        # (H, W) float32 (v - cy) / fy


def _grid(size) -> _Grid:
    k = camera_intrinsics(size)
    w, h = k["width"], k["height"]
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    xg = (u - k["cx"]) / k["fx"]
    yg = (v - k["cy"]) / k["fy"]
    return _Grid(k["fx"], k["fy"], k["cx"], k["cy"], w, h, xg, yg)


def _render_hall(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray):
    """Ray-cast the hall box (floor, roof, four walls) with distance fog.

    R (3, 3), o (3,): camera-to-hall rotation and camera centre. Returns (bgr (H, W, 3) uint8,
    depth (H, W) float32 metres along the optical axis).
    """
    r = R.astype(np.float32)
    xg, yg = g.xg, g.yg
    ox, oy, oz = (float(v) for v in o)
    d = [r[i, 0] * xg + r[i, 1] * yg + r[i, 2] for i in range(3)]   # hall-frame ray, camera z = 1
    # inverse ray parameter to the wall each ray reaches: the larger, the nearer
    inv = [np.maximum(d[0] * (1.0 / (HALL_WIDTH - ox)), d[0] * (-1.0 / ox)),
           np.maximum(d[1] * (1.0 / (HALL_HEIGHT - oy)), d[1] * (-1.0 / oy)),
           np.maximum(d[2] * (1.0 / (HALL_DEPTH - oz)), d[2] * (-1.0 / oz))]
    best = np.maximum(np.maximum(inv[0], inv[1]), inv[2])
    t = 1.0 / best
    is_y = inv[1] >= best
    is_x = ~is_y & (inv[0] >= best)
    rows = scene.atlas_rows
    off = np.where(is_y, np.where(d[1] < 0, rows[0], rows[1]),
                   np.where(is_x, np.where(d[0] < 0, rows[2], rows[3]),
                            np.where(d[2] < 0, rows[4], rows[5])))
    s = 1.0 / TEX_RES
    px = (ox + t * d[0]) * s
    pz = (oz + t * d[2]) * s
    mu = np.where(is_x, pz, px)
    mv = np.where(is_y, pz, (HALL_HEIGHT - oy) * s - t * d[1] * s) + off
    img = cv2.remap(scene.atlas, mu.astype(np.float32), mv.astype(np.float32), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    keep = cv2.exp(t * np.float32(-1.0 / FOG_DIST))
    fog = np.float32(1.0) - keep
    img = (img * keep[..., None] + fog[..., None] * FOG_COLOR).astype(np.uint8)
    return img, t.astype(np.float32)


def _draw_list(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray):
    """Visible primitives, clipped, projected and sorted far-to-near.

    R (3, 3), o (3,): camera-to-hall rotation and camera centre (metres).
    Returns (items, planes) with items a list of draw commands and planes (K + 1, 3) float64
    inverse-depth coefficients (A, B, C): 1/z = A*(u-cx)/fx + B*(v-cy)/fy + C for primitive id
    1..K (row 0 unused: the hall).
    """
    pkeys, pplanes, polys, pcol = _draw_polygons(scene, g, R, o)
    C, rpx, detail, blob = _plant_visibility(scene, g, R, o)
    leaves = _leaf_ellipses(scene, g, R, o, detail)
    blobs = _blob_ellipses(scene, g, C, rpx, blob)
    return _sorted_items(pkeys, pplanes, polys, pcol, leaves, blobs)


def _draw_polygons(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray):
    """The scene's polygons that face the camera and reach into the view, near-clipped and
    projected.

    R (3, 3), o (3,): camera-to-hall rotation and camera centre (metres).
    Returns (keys (K,) float64 painter's distance in metres (their object's nearest or farthest
    point, see ``Scene.obj_far``), planes (K, 3) float64 inverse-depth coefficients (see
    ``_draw_list``), polys (list of K (k, 2) int32 image corners in 1/ONE pixels, or None where
    clipping left nothing), colours (list of K BGR triples, fogged)).
    """
    fx, fy, cx, cy, w, h = g.fx, g.fy, g.cx, g.cy, g.w, g.h
    V = (scene.quads - o) @ R                      # (Q, 4, 3) camera frame
    x, y, z = V[..., 0], V[..., 1], V[..., 2]
    m = 4.0
    facing = np.einsum("ij,ij->i", scene.quad_normal, o - scene.quads[:, 0]) > 1e-9
    vis = (facing & (z.max(1) > NEAR) & (z.min(1) < FAR)
           & ~np.all(fx * x - (w - cx + m) * z > 0, 1) & ~np.all(fx * x + (cx + m) * z < 0, 1)
           & ~np.all(fy * y - (h - cy + m) * z > 0, 1) & ~np.all(fy * y + (cy + m) * z < 0, 1))
    qi = np.nonzero(vis)[0]
    lo, hi = scene.obj_lo, scene.obj_hi
    near_d = np.linalg.norm(np.clip(o, lo, hi) - o, axis=1)
    far_d = np.linalg.norm(np.maximum(np.abs(o - lo), np.abs(o - hi)), axis=1)
    okey = np.where(scene.obj_far, far_d, near_d)
    pkeys = okey[scene.quad_obj[qi]]
    nc = scene.quad_normal[qi] @ R
    dpl = np.einsum("ij,ij->i", nc, V[qi, 0])
    pplanes = nc / dpl[:, None]
    Vq = V[qi]
    zq = Vq[..., 2]
    clipped = zq.min(1) < NEAR
    with np.errstate(divide="ignore", invalid="ignore"):
        U = np.stack([fx * Vq[..., 0] / zq + cx, fy * Vq[..., 1] / zq + cy], -1)
    P = np.clip(np.rint(U * ONE), -2**24, 2**24).astype(np.int32)
    polys = []
    for j in range(len(qi)):
        if clipped[j]:
            c = _clip_near(Vq[j])
            if len(c) == 0:
                polys.append(None)
                continue
            uv = np.stack([fx * c[:, 0] / c[:, 2] + cx, fy * c[:, 1] / c[:, 2] + cy], -1)
            polys.append(np.clip(np.rint(uv * ONE), -2**24, 2**24).astype(np.int32))
        else:
            polys.append(P[j])
    pcol = _fog(scene.quad_color[qi], pkeys).tolist()
    return pkeys, pplanes, polys, pcol


def _plant_visibility(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray):
    """Which plants are drawn, and how: leaf by leaf when near, as one blob when far.

    R (3, 3), o (3,): camera-to-hall rotation and camera centre (metres).
    Returns (C (P, 3) plant centres in the camera frame (metres), rpx (P,) plant radius in
    pixels, detail (P,) bool drawn leaf by leaf (radius >= 6 px), blob (P,) bool drawn as one
    ellipse (visible but smaller); holes vanish below 0.6 px).
    """
    fx, fy, cx, cy, w, h = g.fx, g.fy, g.cx, g.cy, g.w, g.h
    m = 4.0
    C = (scene.plant_center - o) @ R
    pz = C[:, 2]
    rpx = fx * scene.plant_radius / np.maximum(pz, 1e-3)
    rr = scene.plant_radius * 1.5
    pvis = ((pz > 0.15) & (pz < FAR)
            & (fx * C[:, 0] - (w - cx + m) * pz < fx * rr) & (fx * C[:, 0] + (cx + m) * pz > -fx * rr)
            & (fy * C[:, 1] - (h - cy + m) * pz < fy * rr) & (fy * C[:, 1] + (cy + m) * pz > -fy * rr)
            & ((rpx > 0.6) | (scene.plant_flat == 0)))     # holes vanish below a pixel
    detail = pvis & (rpx >= 6.0)
    blob = pvis & ~detail
    return C, rpx, detail, blob


def _leaf_ellipses(scene: Scene, g: _Grid, R: np.ndarray, o: np.ndarray, detail: np.ndarray):
    """Image ellipses of the leaves of the plants marked in ``detail`` (P,) bool, leaves nearer
    than 0.12 m dropped.

    Returns (centre (L, 2) pixels, axes (L, 2) semi-axes in pixels, angle (L,) degrees,
    colour (L, 3) BGR before fog, key (L,) distance to the camera in metres, depth (L,) metres
    along the optical axis).
    """
    fx, fy, cx, cy = g.fx, g.fy, g.cx, g.cy
    counts = np.diff(scene.plant_leaves)
    pid = np.nonzero(detail)[0]
    if len(pid):
        cnt = counts[pid]
        lidx = np.repeat(scene.plant_leaves[pid] - (np.cumsum(cnt) - cnt), cnt) + np.arange(cnt.sum())
    else:
        lidx = np.zeros(0, np.int64)
    Lc = (scene.leaf_center[lidx] - o) @ R
    lz = Lc[:, 2]
    keep = lz > 0.12
    lidx, Lc, lz = lidx[keep], Lc[keep], lz[keep]
    A1 = scene.leaf_a1[lidx] @ R
    A2 = scene.leaf_a2[lidx] @ R
    e_c = np.stack([fx * Lc[:, 0] / lz + cx, fy * Lc[:, 1] / lz + cy], 1)
    e_ax, e_ang = _project_ellipses(Lc, A1, A2, fx, fy)
    return e_c, e_ax, e_ang, scene.leaf_color[lidx], np.linalg.norm(Lc, axis=1), lz


def _blob_ellipses(scene: Scene, g: _Grid, C: np.ndarray, rpx: np.ndarray, blob: np.ndarray):
    """One image ellipse per far plant marked in ``blob`` (P,) bool, squashed by the viewing
    elevation; C (P, 3) camera-frame centres (metres), rpx (P,) radii in pixels.

    Returns the same six arrays as ``_leaf_ellipses`` (angle 0, the plant's mean colour).
    """
    fx, fy, cx, cy = g.fx, g.fy, g.cx, g.cy
    bid = np.nonzero(blob)[0]
    Cb = C[bid]
    bz = Cb[:, 2]
    elev = np.abs(Cb[:, 1]) / np.linalg.norm(Cb, axis=1)
    squash = np.where(scene.plant_flat[bid] == 1, np.clip(elev, 0.05, 1), np.clip(elev + 0.55, 0, 1))
    b_r = rpx[bid] * 0.95
    b_ax = np.stack([b_r, b_r * squash], 1)
    b_c = np.stack([fx * Cb[:, 0] / bz + cx, fy * Cb[:, 1] / bz + cy], 1)
    b_key = np.linalg.norm(Cb, axis=1)
    return b_c, b_ax, np.zeros(len(bid)), scene.plant_color[bid], b_key, bz


def _sorted_items(pkeys, pplanes, polys, pcol, leaves, blobs):
    """Merge polygons (from ``_draw_polygons``) and ellipses (``leaves`` then ``blobs``, each the
    six arrays of ``_leaf_ellipses``) into one far-to-near draw list.

    Returns (items, planes) as ``_draw_list``: items are (0, polygon, colour, id) or
    (1, (centre, axes, angle) in 1/ONE pixels and degrees, colour, id), ids 1..K in input order
    (polygons first); planes (K + 1, 3) with 1/z = C (A = B = 0) for the ellipses.
    """
    ec, eax, eang, ecol, ekey, edepth = (np.concatenate([a, b]) for a, b in zip(leaves, blobs))
    ecol = _fog(ecol, ekey).tolist()
    eci = np.rint(ec * ONE).astype(np.int64).tolist()
    eai = np.maximum(np.rint(eax * ONE), 1).astype(np.int64).tolist()
    eang = eang.tolist()

    npoly = len(polys)
    keys = np.concatenate([pkeys, ekey])
    order = np.argsort(-keys, kind="stable")
    planes = np.zeros((1 + len(keys), 3))
    planes[1:npoly + 1] = pplanes
    planes[npoly + 1:, 2] = 1.0 / edepth
    items = []
    for k in order.tolist():
        if k < npoly:
            if polys[k] is not None:
                items.append((0, polys[k], pcol[k], k + 1))
        else:
            e = k - npoly
            items.append((1, (eci[e], eai[e], eang[e]), ecol[e], k + 1))
    return items, planes


def _fog(color: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Colours (K, 3) seen through ``dist`` (K,) metres of haze (one value per primitive)."""
    keep = np.exp(-np.asarray(dist, np.float64) / FOG_DIST)[:, None]
    return color * keep + FOG_COLOR * (1.0 - keep)


def _project_ellipses(Cc, A1, A2, fx, fy):
    """Image ellipses of small 3D ellipses (centre Cc, semi-axis vectors A1, A2; camera frame).

    All (L, 3). Uses the projection's Jacobian at the centre. Returns (axes (L, 2) semi-axes in
    pixels, angle (L,) degrees for cv2.ellipse).
    """
    x, y, z = Cc[:, 0], Cc[:, 1], Cc[:, 2]

    def jac(a):
        return np.stack([fx * (a[:, 0] - x * a[:, 2] / z) / z, fy * (a[:, 1] - y * a[:, 2] / z) / z], 1)

    u, v = jac(A1), jac(A2)
    a = u[:, 0] ** 2 + v[:, 0] ** 2
    b = u[:, 0] * u[:, 1] + v[:, 0] * v[:, 1]
    c = u[:, 1] ** 2 + v[:, 1] ** 2
    root = np.sqrt(((a - c) / 2) ** 2 + b ** 2)
    l1 = np.sqrt(np.maximum((a + c) / 2 + root, 0))
    l2 = np.sqrt(np.maximum((a + c) / 2 - root, 0))
    ang = np.degrees(0.5 * np.arctan2(2 * b, a - c))
    return np.stack([l1, l2], 1), ang


def render_frame(scene: Scene, pose: np.ndarray, size=DEFAULT_SIZE, grid: _Grid | None = None):
    """Render one clean frame (no sensor effects).

    scene: from ``build_scene``; pose: (4, 4) camera-to-hall (from ``route_world``);
    size: (width, height) pixels. Returns (bgr (H, W, 3) uint8, depth (H, W) float32 metres
    along the optical axis, every pixel valid).
    """
    g = grid if grid is not None else _grid(size)
    R = np.asarray(pose[:3, :3], np.float64)
    o = np.asarray(pose[:3, 3], np.float64)
    img, hall_depth = _render_hall(scene, g, R, o)
    items, planes = _draw_list(scene, g, R, o)
    ids = np.zeros((g.h, g.w), np.int32)
    fill, ell = cv2.fillConvexPoly, cv2.ellipse
    aa, l8 = cv2.LINE_AA, cv2.LINE_8
    for kind, geom, col, pid in items:
        if kind == 0:
            fill(img, geom, col, aa, SHIFT)
            fill(ids, geom, pid, l8, SHIFT)
        else:
            c, ax, ang = geom
            ell(img, c, ax, ang, 0, 360, col, -1, l8, SHIFT)
            ell(ids, c, ax, ang, 0, 360, pid, -1, l8, SHIFT)
    depth = hall_depth
    hit = ids > 0
    if hit.any():
        pl = planes[ids[hit]]
        inv = pl[:, 0] * g.xg[hit] + pl[:, 1] * g.yg[hit] + pl[:, 2]
        depth = depth.copy()
        depth[hit] = np.where(inv > 1e-6, 1.0 / np.maximum(inv, 1e-6), hall_depth[hit])
    return img, depth


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


# ---------------------------------------------------------------------------------------------
# sequence writing (multiprocessing over frame chunks)
# ---------------------------------------------------------------------------------------------
_WORKER: dict = {}


def _worker_init(seed: int, n_frames: int, size, out: str, noise: float) -> None:
    """Per-process state: scene, pixel grid, poses (N, 4, 4) and arc lengths (N,) metres."""
    poses, s = route_world(n_frames, seed)
    _WORKER.update(scene=build_scene(seed), grid=_grid(size), poses=poses, s=s, seed=seed,
                   out=Path(out), size=size, noise=noise)


def _render_chunk(frames) -> int:
    """Render and write the frames (list of int indices); returns how many were written."""
    wk = _WORKER
    for i in frames:
        img, depth = render_frame(wk["scene"], wk["poses"][i], wk["size"], wk["grid"])
        rng = np.random.default_rng([wk["seed"], int(i), 0xF4A3E])
        bgr, d16 = _sensor(wk["scene"], img, depth, float(wk["s"][i]), wk["grid"], rng, wk["noise"])
        if not cv2.imwrite(str(wk["out"] / "rgb" / f"{i}.png"), bgr, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL]):
            raise OSError(f"could not write {wk['out'] / 'rgb' / f'{i}.png'}")
        if not cv2.imwrite(str(wk["out"] / "depth" / f"{i}.png"), d16, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL]):
            raise OSError(f"could not write {wk['out'] / 'depth' / f'{i}.png'}")
    return len(frames)


def make_greenhouse(folder, n_frames: int = DEFAULT_FRAMES, size=DEFAULT_SIZE, seed: int = 0,
                    progress: bool = True, workers: int | None = None,
                    overwrite: bool = False, noise: float = DEFAULT_NOISE) -> Path:
    """Render the synthetic GreenHouse sequence into ``folder`` (a sequence folder).

    n_frames: frames along the same ~61 m route (>= 200; 2260 like the paper's run).
    size: (width, height) pixels (>= 160x120); intrinsics are the D435i's scaled linearly.
    seed: seeds plant details, textures, route jitter, lighting drift and sensor noise; the
        output is byte-identical for the same arguments (each frame's noise is seeded by
        (seed, frame index), so the worker count does not matter).
    workers: processes (default os.cpu_count(); 1 renders in this process).
    overwrite: replace an existing non-empty ``folder`` (otherwise FileExistsError).
    noise: std of the per-pixel Gaussian sensor noise in grey levels (0..255). Every frame also
        gets a seeded exposure / white-balance flicker, and depth a smooth seeded error field.
        Per-pixel noise is incompressible, so it makes the PNG files much larger.
    Writes into a temporary folder beside ``folder`` and renames it at the end, so an
    interrupted run leaves nothing half-written. Returns the folder as a Path.
    """
    n = _check_frames(n_frames)
    size = _check_size(size)
    seed = _check_seed(seed)
    noise, workers = _check_noise_workers(noise, workers)
    folder = Path(folder)
    _check_output(folder, overwrite)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = folder.parent / f".{folder.name}.tmp-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        (tmp / "rgb").mkdir(parents=True)
        (tmp / "depth").mkdir()
        _render_frames(tmp, f"render {folder.name}", n, size, seed, noise, workers, progress)
        _write_metadata(tmp, n, size, seed, noise)
        _move_into_place(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


def _check_noise_workers(noise, workers) -> tuple[float, int]:
    """Validated (noise std in grey levels, 0..50; worker processes, >= 1, None = all cores)."""
    if not (isinstance(noise, (int, float)) and 0 <= noise <= 50):
        raise ValueError(f"noise must be a std in grey levels between 0 and 50, got {noise!r}")
    if workers is None:
        workers = os.cpu_count() or 1
    if isinstance(workers, bool) or int(workers) != workers or int(workers) < 1:
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    return float(noise), int(workers)


def _check_output(folder: Path, overwrite: bool) -> None:
    """FileExistsError unless ``folder`` is absent, an empty folder, or may be overwritten."""
    if folder.exists() and not folder.is_dir():
        raise FileExistsError(f"{folder} exists and is not a folder: choose another output path")
    if folder.is_dir() and any(folder.iterdir()) and not overwrite:
        raise FileExistsError(f"{folder} already exists and is not empty: delete it, choose another "
                              f"folder, or pass overwrite=True (CLI: --overwrite)")


def _render_frames(tmp: Path, desc: str, n: int, size, seed: int, noise: float, workers: int,
                   progress: bool) -> None:
    """Render frames 0..n-1 into tmp/rgb and tmp/depth, in chunks of 8 frames over ``workers``
    processes (1: in this process), with a progress bar labelled ``desc``."""
    chunk = 8
    chunks = [list(range(i, min(i + chunk, n))) for i in range(0, n, chunk)]
    from .progress import bar as tqdm  # in the terminal, not in the notebook
    bar = tqdm(total=n, desc=desc, unit="frame", disable=not progress)
    try:
        if workers == 1:
            _worker_init(seed, n, size, str(tmp), noise)
            for c in chunks:
                bar.update(_render_chunk(c))
        else:
            import multiprocessing as mp
            with mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn").Pool(
                    workers, _worker_init, (seed, n, size, str(tmp), noise)) as pool:
                for done in pool.imap_unordered(_render_chunk, chunks):
                    bar.update(done)
    finally:
        bar.close()
        _WORKER.clear()


def _write_metadata(tmp: Path, n: int, size, seed: int, noise: float) -> None:
    """CameraTrajectory.txt (n poses, TUM, first camera's frame), camera.yaml and synthetic.json."""
    poses = route(n, seed)
    write_trajectory(tmp / "CameraTrajectory.txt", np.arange(n), poses)
    write_camera_yaml(tmp / "camera.yaml", size)
    meta = {"generator": "greenloop.synthetic", "format": 1, "n_frames": n,
            "width": size[0], "height": size[1], "seed": seed, "noise": noise,
            "route_length_m": round(route_length(), 3), "depth_scale": DEPTH_SCALE}
    (tmp / "synthetic.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")


def _move_into_place(tmp: Path, folder: Path) -> None:
    """Rename the finished ``tmp`` to ``folder``, moving an existing ``folder`` aside first and
    deleting it afterwards."""
    if folder.exists():
        old = folder.parent / f".{folder.name}.old-{os.getpid()}"
        folder.rename(old)
        tmp.rename(folder)
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(folder)


def _parse_size(text: str) -> tuple[int, int]:
    """'640x480' -> (640, 480) for argparse."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 640x480, got {text!r}") from None
    return w, h


def main(argv=None) -> int:
    """CLI: ``python -m greenloop.synthetic OUT_FOLDER [--frames N] [--size WxH] [--seed S]``."""
    ap = argparse.ArgumentParser(prog="python -m greenloop.synthetic",
                                 description="Render the synthetic GreenHouse sequence folder.")
    ap.add_argument("out", help="output sequence folder (created; must not exist unless --overwrite)")
    ap.add_argument("--frames", type=int, default=DEFAULT_FRAMES, help="number of frames (>= 200)")
    ap.add_argument("--size", type=_parse_size, default=DEFAULT_SIZE, help="WxH, e.g. 640x480")
    ap.add_argument("--seed", type=int, default=0, help="random seed (>= 0)")
    ap.add_argument("--noise", type=float, default=DEFAULT_NOISE,
                    help="per-pixel Gaussian noise std in grey levels (default %(default)s; "
                         "1.0 looks like a real sensor but doubles the disk size)")
    ap.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    ap.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    try:
        out = make_greenhouse(a.out, a.frames, a.size, a.seed, progress=not a.quiet,
                              workers=a.workers, overwrite=a.overwrite, noise=a.noise)
    except (ValueError, FileExistsError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {a.frames} frames to {out} in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
