"""The camera's route through the hall: poses along a fixed path, the same for every frame count.

The route (``route``) is a fixed polyline through the aisles, rounded at the corners,
arc-length parametrised and sampled uniformly, so every ``n_frames`` gives the same ~61 m path:
up aisle A1, down aisle A3, up aisle A2, down aisle A3 again (a same-direction revisit in the
middle of the run) and back into aisle A1, retracing the first ~4.5 m (the end-to-start revisit
of the real set, whose frames ~2068-2260 return to frames ~0-138).

``route_world`` gives the poses in the hall frame (see ``hall``), ``route`` in the first camera's
frame as CameraTrajectory.txt holds them: (N, 4, 4) camera-to-frame, OpenCV camera axes
(x right, y down, z forward), metres.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import gaussian_filter1d

from greenloop.datasets.synthetic.hall import (AISLE_A1, AISLE_A2, AISLE_A3, BACK_AISLE_Z,
                                               FRONT_AISLE_Z, _check_seed)

# frames; the route's corner radius and the camera's height (metres) and pitch (degrees)
DEFAULT_FRAMES = 2260
MIN_FRAMES = 200
TURN_RADIUS = 0.95
CAM_HEIGHT = 0.95
CAM_PITCH_DEG = -6.0
RETRACE = 4.6             # metres of aisle A1 driven again at the end


def _check_frames(n_frames) -> int:
    """``n_frames`` as an int, or ValueError unless it is an integer >= MIN_FRAMES."""
    if isinstance(n_frames, bool) or int(n_frames) != n_frames:
        raise ValueError(f"n_frames must be an integer, got {n_frames!r}")
    n = int(n_frames)
    if n < MIN_FRAMES:
        raise ValueError(f"n_frames={n} is too few for the route to close its loop: use "
                         f"n_frames >= {MIN_FRAMES} (the real set has {DEFAULT_FRAMES})")
    return n


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
    return _path_poses(route_waypoints(), n, np.random.default_rng([seed, 0x5EED]))


def _path_poses(waypoints: np.ndarray, n: int, rng):
    """Camera poses on the rounded path through ``waypoints`` (K, 2) (x, z) metres, hall frame.

    n: poses, uniform in arc length; rng: draws the smoothed jitter and the wander's phases
    (``route_world``). Returns (poses (n, 4, 4) float64 camera-to-hall, OpenCV camera axes;
    s (n,) arc length in metres).
    """
    s_d, xz_d, head_d = _filleted_path(waypoints, TURN_RADIUS)
    step = s_d[1] - s_d[0]
    head_d = gaussian_filter1d(head_d, 0.2 / step, mode="nearest")   # smooth yaw rate
    length = s_d[-1]
    s = np.linspace(0.0, length, n)
    x = np.interp(s, s_d, xz_d[:, 0])
    z = np.interp(s, s_d, xz_d[:, 1])
    yaw = np.interp(s, s_d, head_d)

    # jitter on a 1 cm grid along the route, smoothed over ~8 cm: independent of n_frames
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
