"""Odometry: a recording's, and wheel odometry simulated from true poses.

Reading: a bag's ``nav_msgs/Odometry`` topic or a trajectory file, and its pose at each frame's time.

:func:`read_odometry` reads

* a ROS 1 .bag or ROS 2 bag (greenloop.datasets.recording): the messages of one Odometry topic
  (``topic``; needed when the bag has several), ``pose.pose`` as the pose, the header stamp as the
  time (the log time where a stamp is zero, as the frames' :func:`recording.header_stamps`);
* a TUM file, ``t tx ty tz qx qy qz qw`` a line (``sequence.read_tum``; t in seconds);
* a KITTI file, 12 numbers a line: the 3 x 4 pose matrix row by row. KITTI has no times in the
  file: the stamps are the line numbers 0, 1, ... (frame k of the sequence; KITTI's times.txt is
  elsewhere), so associate them with frame numbers, not seconds.

Poses are (N, 4, 4) float64 homogeneous body-to-world (odom) matrices, translation in metres.
:func:`associate` gives each frame the odometry pose at its time: between the two messages around
it, translation interpolated linearly and rotation by slerp (the geodesic on SO(3); quaternions
are never averaged); before the first or after the last message the nearest pose, never
extrapolated; none (NaN) where the nearest message is more than ``max_dt`` away.

Simulating: wheel odometry from true planar poses, ``simulate_odometry`` (a pure function; the
greenhouse days write it beside each day's poses).

The drift model, per step i from pose i-1 to pose i (true planar poses (x, z, yaw)):

* the true motion in the robot's frame at i-1 (forward, sideways, turn dθ) and its length d;
* the wheels read the translation scaled by ``1 + scale_error + slip * sqrt(d) * e_i / d`` (a
  constant wheel-radius error, a fraction, plus a random slip of std ``slip`` metres per
  sqrt(metre) driven);
* the turn reads ``dθ + heading_bias * d + heading_noise * sqrt(d) * h_i`` (a constant heading
  bias in radians per metre driven, from unequal wheels, plus random noise of std
  ``heading_noise`` radians per sqrt(metre));
* e_i, h_i ~ N(0, 1) from ``numpy.random.default_rng(seed)``; the read motions are composed
  from the first true pose on, so the error grows with the distance driven: the heading error
  by ``heading_bias`` per metre, the position error about quadratically in the distance through it.

The same (poses, seed, parameters) give the same odometry. All zero gives back the true poses.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from greenloop.datasets import recording, sequence

ODOMETRY_TYPES = ("nav_msgs/msg/Odometry",)
FORMATS = ("bag", "tum", "kitti")


def read_odometry(path, topic: str | None = None, fmt: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """The odometry of a bag or a trajectory file (module doc).

    path: a ROS 1 .bag, a ROS 2 bag folder, or a TUM / KITTI text file. topic: the bag's Odometry
    topic (needed when it has several). fmt: "auto" (a bag by its path, else TUM for 8 numbers a
    line, KITTI for 12), or one of FORMATS.
    Returns (stamps (N,) float64 seconds (KITTI: line numbers), poses (N, 4, 4) float64), in the
    order recorded. Raises FileNotFoundError for a missing path, ValueError naming the problem.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"odometry {path} does not exist: give a bag with a nav_msgs/Odometry topic, "
                                f"or a TUM (`t tx ty tz qx qy qz qw`) or KITTI (12 numbers a line) file")
    if fmt == "auto":
        fmt = format_of(path)
    if fmt not in FORMATS:
        raise ValueError(f"odometry format {fmt!r} unknown: give one of {', '.join(FORMATS)} or 'auto'")
    if topic is not None and fmt != "bag":
        raise ValueError(f"an odometry topic ({topic}) was given for {path}, a {fmt} file: drop it")
    if fmt == "bag":
        return _bag_odometry(path, topic)
    return sequence.read_tum(path) if fmt == "tum" else _read_kitti(path)


def format_of(path) -> str:
    """"bag" (a ROS 1 .bag, a ROS 2 bag folder or its storage file), else "tum" or "kitti" by the
    count of numbers on a text file's first data line; ValueError for another count."""
    path = Path(path)
    if path.is_dir() or path.suffix.lower() in recording.BAG_SUFFIXES + recording.ROS2_FILES:
        return "bag"
    return _text_format(path)


def _data_lines(path: Path) -> list[tuple[int, str]]:
    """(line number, text) of the lines that are neither blank nor ``#`` comments."""
    lines = [(k, ln.strip()) for k, ln in enumerate(path.read_text().splitlines(), 1)]
    return [(k, ln) for k, ln in lines if ln and not ln.startswith("#")]


def _text_format(path: Path) -> str:
    """"tum" or "kitti" by the count of numbers on the first data line (ValueError for another)."""
    lines = _data_lines(path)
    n = len(lines[0][1].replace(",", " ").split()) if lines else 0
    if n not in (8, 12):
        raise ValueError(f"{path}: {n} numbers on its first line; an odometry file is TUM (8: `t tx ty tz qx qy "
                         f"qz qw`) or KITTI (12: a 3 x 4 pose row by row)")
    return "tum" if n == 8 else "kitti"


def _read_kitti(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A KITTI pose file -> (line numbers (N,) float64, poses (N, 4, 4)); ValueError naming a bad line."""
    rows = sequence.number_rows(path, 12, "(a 3 x 4 pose row by row)", "lines of 12 numbers (KITTI)")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = np.asarray(rows).reshape(-1, 3, 4)
    return np.arange(len(rows), dtype=np.float64), poses


def _bag_odometry(path, topic) -> tuple[np.ndarray, np.ndarray]:
    """One Odometry topic of a bag -> (header stamps (N,) s, pose.pose as (N, 4, 4))."""
    with recording.open_bag(path) as reader:
        topic = recording.pick_topic(path, reader, ODOMETRY_TYPES, topic, "odometry")
        conns = [c for c in reader.connections if c.topic == topic]
        rows, vals = [], []
        for conn, ns, raw in reader.messages(conns):
            pose = reader.deserialize(raw, conn.msgtype).pose.pose
            p, q = pose.position, pose.orientation
            rows.append((bytes(raw[:12]), ns))
            vals.append((p.x, p.y, p.z, q.x, q.y, q.z, q.w))
        stamps = recording.header_stamps(rows, reader.is2)
    a = np.asarray(vals, np.float64).reshape(-1, 7)
    if np.any(np.linalg.norm(a[:, 3:], axis=1) < 1e-9):
        raise ValueError(f"{path}: topic {topic} has a message with a zero quaternion (an unset orientation)")
    poses = np.tile(np.eye(4), (len(a), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(a[:, 3:]).as_matrix()
    poses[:, :3, 3] = a[:, :3]
    return stamps, poses


def associate(frame_stamps, odom_stamps, odom_poses, max_dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The odometry pose at each frame's time (module doc: linear translation and slerp between the two
    messages around it, the nearest pose beyond the ends, none beyond ``max_dt``).

    frame_stamps: (N,) seconds. odom_stamps: (M,) seconds, increasing. odom_poses: (M, 4, 4).
    max_dt: seconds (>= 0): the farthest the nearest message may be from a frame.
    Returns (poses (N, 4, 4) float64, NaN for a frame without one; ok (N,) bool: the frame has one).
    """
    t, s = np.asarray(frame_stamps, np.float64).reshape(-1), np.asarray(odom_stamps, np.float64).reshape(-1)
    P = np.asarray(odom_poses, np.float64)
    if P.shape != (len(s), 4, 4) or not len(s):
        raise ValueError(f"odom_poses must be ({len(s)}, 4, 4) for {len(s)} stamps (at least one), got {P.shape}")
    if np.any(np.diff(s) <= 0):
        raise ValueError("odometry stamps must increase strictly: sort the messages and drop repeated stamps")
    if not max_dt >= 0:
        raise ValueError(f"max_dt must be >= 0 seconds, got {max_dt}")
    hi = np.clip(np.searchsorted(s, t, "left"), 1, len(s) - 1) if len(s) > 1 else np.zeros(len(t), np.int64)
    lo = np.maximum(hi - 1, 0)
    near = np.minimum(np.abs(t - s[lo]), np.abs(t - s[hi]))
    span = np.where(s[hi] > s[lo], s[hi] - s[lo], 1.0)
    alpha = np.clip((t - s[lo]) / span, 0.0, 1.0)
    r0 = Rotation.from_matrix(P[lo, :3, :3])
    rel = (r0.inv() * Rotation.from_matrix(P[hi, :3, :3])).as_rotvec()
    out = np.tile(np.eye(4), (len(t), 1, 1))
    out[:, :3, :3] = (r0 * Rotation.from_rotvec(rel * alpha[:, None])).as_matrix()
    out[:, :3, 3] = (1 - alpha)[:, None] * P[lo, :3, 3] + alpha[:, None] * P[hi, :3, 3]
    ok = near <= max_dt
    out[~ok] = np.nan
    return out, ok

SCALE_ERROR = 0.01        # fraction: wheels read 1 % long
SLIP = 0.01               # metres of random slip per sqrt(metre) driven (std)
HEADING_BIAS = 0.005      # radians per metre driven (0.29 degrees per metre)
HEADING_NOISE = 0.002     # radians per sqrt(metre) driven (std)


def simulate_odometry(planar, seed: int = 0, scale_error: float = SCALE_ERROR, slip: float = SLIP,
                      heading_bias: float = HEADING_BIAS, heading_noise: float = HEADING_NOISE) -> np.ndarray:
    """Wheel odometry of a robot that drove the true ``planar`` poses (module doc: drift model).

    planar: (N, 3) true poses (x, z, yaw) in metres and radians, yaw = atan2(dz, dx) of the
    heading in the floor plane; seed: an integer >= 0; the drift parameters as the module doc
    (units: fraction, m / sqrt(m), rad / m, rad / sqrt(m)). Returns (N, 3) odometry poses in the
    same units and frame, equal to the true one at index 0.
    """
    p = np.asarray(planar, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 1 or not np.all(np.isfinite(p)):
        raise ValueError(f"planar must be a finite (N, 3) array of (x, z, yaw) metres and radians, got shape {p.shape}")
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if slip < 0 or heading_noise < 0:
        raise ValueError(f"slip and heading_noise are standard deviations and must be >= 0, got {slip}, {heading_noise}")
    rng = np.random.default_rng(int(seed))
    e, h = rng.standard_normal(len(p) - 1), rng.standard_normal(len(p) - 1)
    c, s = np.cos(p[:-1, 2]), np.sin(p[:-1, 2])
    dx, dz = np.diff(p[:, 0]), np.diff(p[:, 1])
    fwd, side = c * dx + s * dz, -s * dx + c * dz              # true motion in the robot's frame
    d = np.hypot(fwd, side)
    turn = np.angle(np.exp(1j * np.diff(p[:, 2])))
    k = 1.0 + scale_error + slip * e / np.sqrt(np.maximum(d, 1e-12))
    k = np.where(d > 0, k, 1.0)
    turn_read = turn + heading_bias * d + heading_noise * np.sqrt(d) * h
    out = np.empty_like(p)
    out[0] = p[0]
    yaw = p[0, 2] + np.concatenate([[0.0], np.cumsum(turn_read)])
    cy, sy = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    out[1:, 0] = p[0, 0] + np.cumsum(k * (cy * fwd - sy * side))
    out[1:, 1] = p[0, 1] + np.cumsum(k * (sy * fwd + cy * side))
    out[:, 2] = yaw
    return out
