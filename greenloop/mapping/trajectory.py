"""SE(3) poses as (N, 4, 4) float64 arrays, writing a TUM file, and the wheel-odometry drift of
``datasets.odometry`` on SE(3) poses.

A pose T is a homogeneous camera-to-world (body-to-world) matrix: ``T[:3, :3]`` rotation,
``T[:3, 3]`` position in metres. The relative motion from pose a to pose b is ``inv(T_a) @ T_b``
(b expressed in a's frame; GTSAM's ``between`` and evo's ``relative_se3``).

Files: odometry (a bag's topic, TUM or KITTI) is read by ``datasets.odometry.read_odometry``, a
sequence folder's CameraTrajectory.txt by ``datasets.sequence.read_trajectory``; a TUM file is
written atomically here (:func:`write_tum`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from greenloop.datasets import odometry, sequence
from greenloop.util.files import write_atomic

def check_poses(poses, name: str = "poses") -> np.ndarray:
    """``poses`` as (N, 4, 4) float64 (N >= 1), finite, last row (0, 0, 0, 1); ValueError otherwise."""
    a = np.asarray(poses, dtype=np.float64)
    if a.ndim != 3 or a.shape[1:] != (4, 4) or len(a) == 0:
        raise ValueError(f"{name} must be an (N, 4, 4) array of homogeneous poses, got shape {a.shape}")
    if not np.all(np.isfinite(a)) or not np.allclose(a[:, 3], [0, 0, 0, 1]):
        raise ValueError(f"{name} must be finite homogeneous matrices with last row (0, 0, 0, 1)")
    return a


def inverse(poses) -> np.ndarray:
    """Inverse of each (N, 4, 4) rigid transform (R^T, -R^T t), (N, 4, 4)."""
    p = np.asarray(poses, dtype=np.float64)
    out = np.zeros_like(p)
    rt = np.swapaxes(p[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, p[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def relative(a, b) -> np.ndarray:
    """``inv(a) @ b`` per pose: b expressed in a's frame; a, b (N, 4, 4) (or (4, 4)), same shape."""
    return inverse(a) @ np.asarray(b, dtype=np.float64)


def steps(poses) -> np.ndarray:
    """Consecutive relative motions ``inv(T_k) @ T_{k+1}`` of (N, 4, 4) poses: (N-1, 4, 4)."""
    p = check_poses(poses)
    return relative(p[:-1], p[1:])


def integrate(first, motions) -> np.ndarray:
    """Chain relative motions from a first pose: (4, 4) first, (M, 4, 4) motions -> (M+1, 4, 4) poses
    with ``T_{k+1} = T_k @ motions[k]`` (the inverse of :func:`steps`)."""
    m = np.asarray(motions, dtype=np.float64).reshape(-1, 4, 4)
    out = np.empty((len(m) + 1, 4, 4))
    out[0] = first
    for k in range(len(m)):
        out[k + 1] = out[k] @ m[k]
    return out


def make_poses(rotvecs, translations) -> np.ndarray:
    """(N, 3) rotation vectors (axis times angle, radians) and (N, 3) translations (metres) ->
    (N, 4, 4) poses."""
    r = np.asarray(rotvecs, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(translations, dtype=np.float64).reshape(-1, 3)
    out = np.tile(np.eye(4), (len(r), 1, 1))
    out[:, :3, :3] = Rotation.from_rotvec(r).as_matrix()
    out[:, :3, 3] = t
    return out


def rotvecs(poses) -> np.ndarray:
    """(N, 3) rotation vectors (radians) of (N, 4, 4) poses."""
    return Rotation.from_matrix(np.asarray(poses)[..., :3, :3].reshape(-1, 3, 3)).as_rotvec()


def rotation_angle(poses) -> np.ndarray:
    """(N,) rotation angle in radians, in [0, pi], of each (N, 4, 4) pose (or (N, 3, 3) rotation),
    from its trace (clipped against rounding)."""
    r = np.asarray(poses, dtype=np.float64)[..., :3, :3]
    return np.arccos(np.clip((np.trace(r, axis1=-2, axis2=-1) - 1) / 2, -1.0, 1.0))


def distances(poses) -> np.ndarray:
    """(N,) distance travelled in metres from the first pose to each pose along (N, 4, 4) poses (the
    sum of consecutive position differences; evo's ``accumulated_distances``)."""
    p = np.asarray(poses)[:, :3, 3]
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def plane_axes(*trajectories) -> tuple[int, int]:
    """The two coordinate axes (indices 0..2, ascending) of largest extent over the given (N, 4, 4)
    trajectories (None ones skipped): (0, 1) x-y, or (0, 2) x-z for a camera's axes (y down)."""
    p = np.concatenate([np.asarray(t)[:, :3, 3] for t in trajectories if t is not None])
    extent = np.ptp(p, axis=0)
    return tuple(sorted(int(k) for k in np.argsort(-extent, kind="stable")[:2]))


def to_planar(poses, axes: tuple[int, int]) -> np.ndarray:
    """(N, 4, 4) poses (or relative poses) -> (N, 3) planar (u, v, theta): the position's components
    on the axes (a, b), and the yaw theta (radians) about n = e_a x e_b, the angle of R e_a within
    the plane. Exact for motion that rotates about n only."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    a, b = axes
    return np.column_stack([p[:, a, 3], p[:, b, 3], np.arctan2(p[:, b, a], p[:, a, a])])


def from_planar(planar, axes: tuple[int, int]) -> np.ndarray:
    """(N, 3) planar (u, v, theta) -> (N, 4, 4) poses rotating by theta about n = e_a x e_b, at
    (u, v) on the axes (a, b) and 0 on the third axis (the inverse of :func:`to_planar` there)."""
    q = np.asarray(planar, dtype=np.float64).reshape(-1, 3)
    a, b = axes
    n = np.cross(np.eye(3)[a], np.eye(3)[b])
    out = np.tile(np.eye(4), (len(q), 1, 1))
    out[:, :3, :3] = _axis_rotations(n, q[:, 2])
    out[:, a, 3], out[:, b, 3] = q[:, 0], q[:, 1]
    return out


def _axis_rotations(axis, angles) -> np.ndarray:
    """(M, 3, 3) rotations by ``angles`` (M,) radians about the unit ``axis`` (3,)."""
    axis = np.asarray(axis, dtype=np.float64)
    n = np.linalg.norm(axis)
    if not n > 0:
        raise ValueError(f"up must be a nonzero 3-vector, got {axis}")
    return Rotation.from_rotvec(np.outer(angles, axis / n)).as_matrix()


FLOOR = (0, 2)     # the floor plane's axes in a camera's frame with OpenCV axes (x right, y down, z forward)


def drift_poses(poses, seed: int = 0, floor: tuple[int, int] = FLOOR, **drift) -> np.ndarray:
    """Wheel odometry of a robot that drove the true ``poses`` (N, 4, 4): the ONE drift model,
    ``datasets.odometry.simulate_odometry`` (seeded; scale error, slip, heading bias and noise, its
    module doc), applied to SE(3) poses.

    The poses are projected on the floor plane ``floor`` (two axis indices; default FLOOR, the x-z
    plane of OpenCV camera axes with y down, as CameraTrajectory.txt holds poses): position on those
    axes and yaw about their normal (:func:`to_planar`). The planar model drifts them; each true
    pose is then moved by its planar error (in-plane shift and yaw, :func:`from_planar`), so its
    height, pitch and roll stay the truth's: wheels measure the floor only. The model depends on
    the yaw only through its changes, so the yaw's zero (here the angle of the pose's first axis)
    does not matter. drift: keyword arguments of ``simulate_odometry`` (scale_error, slip,
    heading_bias, heading_noise). Returns (N, 4, 4) float64, the true first pose at index 0.
    """
    p = check_poses(poses)
    planar = to_planar(p, floor)
    moved = odometry.simulate_odometry(planar, seed, **drift)
    return from_planar(moved, floor) @ inverse(from_planar(planar, floor)) @ p


def rectangle_route(width_m: float, length_m: float, step_m: float, laps: int = 1) -> np.ndarray:
    """A known-answer route: ``laps`` times around a width_m x length_m rectangle in the x-z plane,
    a pose every step_m metres, turning 90 degrees in place (one pose) at each corner, starting at
    the identity; OpenCV camera axes (z forward, y down: the turns are about y). The last pose
    is back at the start. Returns (N, 4, 4) float64."""
    if not (width_m > 0 and length_m > 0 and step_m > 0 and laps >= 1):
        raise ValueError(f"width_m, length_m, step_m must be > 0 and laps >= 1; got {width_m}, "
                         f"{length_m}, {step_m}, {laps}")
    fwd = make_poses([[0, 0, 0]], [[0, 0, step_m]])[0]
    turn = make_poses([[0, np.pi / 2, 0]], [[0, 0, 0]])[0]
    side = lambda metres: [fwd] * int(round(metres / step_m)) + [turn]
    lap = side(length_m) + side(width_m) + side(length_m) + side(width_m)
    return integrate(np.eye(4), (lap * int(laps))[:-1])


def write_tum(path, stamps, poses) -> Path:
    """Write (N,) stamps and (N, 4, 4) poses as a TUM file, atomically (``util.files.write_atomic``;
    the lines as ``datasets.sequence.write_trajectory`` formats them). Returns the path."""
    p = check_poses(poses)
    stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
    if len(stamps) != len(p):
        raise ValueError(f"{len(stamps)} stamps for {len(p)} poses: give one stamp per pose")
    return write_atomic(path, lambda tmp: sequence.write_trajectory(tmp, stamps, p))
