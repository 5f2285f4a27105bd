"""Ground-truth loop closures from camera poses.

The one definition every evaluation in greenloop uses
----------------------------------------------------
Frames i and j form a ground-truth loop when both hold:

1. they are far apart in time: ``|i - j| > exclude`` (default 150 frames, the Qi 2024 rule that
   ignores the trivially similar neighbours of a frame), and
2. their poses are close, by one of two criteria:

   * ``loop_matrix`` (Qi 2024, Eq. 5): ``e = ||T_i^-1 T_j - I||_F < threshold``, the Frobenius
     norm of the relative pose minus identity. It mixes units: the translation part is in metres,
     the rotation part is ``2*sqrt(2)*|sin(theta/2)|`` for a rotation by theta about one axis
     (0.5 is about 10 degrees, or 0.5 m).
   * ``loop_matrix_metric``: translation distance < ``max_distance`` metres **and** viewing
     direction difference < ``max_angle`` degrees. Easier to argue about.

The matrix is symmetric with a False diagonal; evaluations count each unordered pair once.
"""
from __future__ import annotations

import numpy as np


def _check(poses, threshold_name: str, threshold: float, exclude: int) -> np.ndarray:
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (N, 4, 4), got {poses.shape}; read them with "
                         f"greenloop.data.read_trajectory")
    if not threshold > 0:
        raise ValueError(f"{threshold_name} must be > 0, got {threshold}")
    if exclude < 0:
        raise ValueError(f"exclude must be >= 0 frames, got {exclude}")
    return poses


def _far_in_time(n: int, exclude: int) -> np.ndarray:
    idx = np.arange(n)
    return np.abs(idx[:, None] - idx[None, :]) > exclude


def pose_error(poses) -> np.ndarray:
    """Qi 2024 Eq. 5 for every pair: e[i, j] = ||T_i^-1 T_j - I||_F.

    poses: (N, 4, 4) camera-to-world. Returns (N, N) float64, symmetric, zero diagonal.
    Computed without forming N^2 4x4 products: for rigid T_i^-1 T_j = [R_i^T R_j, R_i^T (t_j - t_i)],
    ||R_i^T R_j - I||_F^2 = 6 - 2 tr(R_i^T R_j) and ||R_i^T (t_j - t_i)|| = ||t_j - t_i||.
    """
    poses = np.asarray(poses, dtype=np.float64)
    R = poses[:, :3, :3].reshape(len(poses), 9)
    t = poses[:, :3, 3]
    trace = R @ R.T                      # tr(R_i^T R_j) = sum of elementwise products
    rot2 = np.maximum(6.0 - 2.0 * trace, 0.0)
    sq = np.einsum("ij,ij->i", t, t)
    trans2 = np.maximum(sq[:, None] + sq[None, :] - 2.0 * t @ t.T, 0.0)
    e = np.sqrt(rot2 + trans2)
    np.fill_diagonal(e, 0.0)
    return e


def loop_matrix(poses, threshold: float = 0.5, exclude: int = 150) -> np.ndarray:
    """Ground-truth loops by Qi 2024 Eq. 5.

    poses: (N, 4, 4) camera-to-world matrices (metres).
    threshold: pairs with e = ||T_i^-1 T_j - I||_F below it are loops (mixed units, see module doc).
    exclude: pairs with |i - j| <= exclude frames are never loops.
    Returns (N, N) bool, symmetric, False on the diagonal.
    """
    poses = _check(poses, "threshold", threshold, exclude)
    return (pose_error(poses) < threshold) & _far_in_time(len(poses), exclude)


def loop_matrix_metric(poses, max_distance: float = 1.0, max_angle: float = 30.0,
                       exclude: int = 150) -> np.ndarray:
    """Ground-truth loops by camera distance and viewing angle.

    poses: (N, 4, 4) camera-to-world matrices (metres).
    max_distance: metres between camera centres. max_angle: degrees between optical axes (+z).
    exclude: pairs with |i - j| <= exclude frames are never loops.
    Returns (N, N) bool, symmetric, False on the diagonal.
    """
    poses = _check(poses, "max_distance", max_distance, exclude)
    if not max_angle > 0:
        raise ValueError(f"max_angle must be > 0 degrees, got {max_angle}")
    t = poses[:, :3, 3]
    z = poses[:, :3, 2]
    sq = np.einsum("ij,ij->i", t, t)
    d2 = np.maximum(sq[:, None] + sq[None, :] - 2.0 * t @ t.T, 0.0)
    cos = np.clip(z @ z.T, -1.0, 1.0)
    close = (d2 < max_distance ** 2) & (cos > np.cos(np.radians(max_angle)))
    return close & _far_in_time(len(poses), exclude)


def loop_pairs(gt: np.ndarray) -> np.ndarray:
    """Unordered loop pairs (i < j) of a ground-truth matrix, shape (P, 2) int."""
    i, j = np.nonzero(np.triu(np.asarray(gt, dtype=bool), 1))
    return np.stack([i, j], 1)


def revisit_frames(gt: np.ndarray) -> np.ndarray:
    """Frames that revisit an earlier place: j with some loop (i, j), i < j. Shape (N,) bool."""
    return np.triu(np.asarray(gt, dtype=bool), 1).any(0)


def path_length(poses) -> float:
    """Length of the camera path in metres (sum of frame-to-frame translation)."""
    t = np.asarray(poses)[:, :3, 3]
    return float(np.linalg.norm(np.diff(t, axis=0), axis=1).sum())
