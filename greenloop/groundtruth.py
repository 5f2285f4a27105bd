"""Ground-truth loop closures: from camera poses, or from a file of loop pairs.

Get a sequence's ground truth with :func:`for_sequence` (every notebook does): it reads the
poses (``CameraTrajectory.txt``) where the folder has them, and the loop pairs
(``ground_truth.csv``) otherwise, and raises :class:`NoGroundTruthError` when it has neither.
Every function here that takes a folder takes a ``datasets.sequence.Sequence`` too (or opens the
folder once with ``sequence.open``), so the files are read once per folder.

The one definition every evaluation in greenloop uses
----------------------------------------------------
Frames i and j form a ground-truth loop when both hold:

1. they are far apart in time: ``|i - j| > exclude`` (default 150 frames, the Qi 2024 rule that
   ignores the trivially similar neighbours of a frame; always in original frame numbers), and
2. the folder's poses say they are close, or its loop-pair file lists them.

Loop pairs (``ground_truth.csv``, for sequences without poses, such as two traversals of one
route aligned frame by frame) are a header line, then ``i,j`` or ``i,j,tolerance`` per line:
0-based frame numbers, and a tolerance in frames (0 when absent): frame i is a loop with every
frame j' with ``|j' - j| <= tolerance``, and the relation is symmetric (j' with i as well). The
tolerance widens j only: list every i you want counted (see :func:`pair_matrix`).

Poses are close by one of two criteria:

* ``loop_matrix`` (Qi 2024, Eq. 5): ``e = ||T_i^-1 T_j - I||_F < threshold``, the Frobenius
  norm of the relative pose minus identity. It mixes units: the translation part is in metres,
  the rotation part is ``2*sqrt(2)*|sin(theta/2)|`` for a rotation by theta about one axis
  (0.5 is about 20 degrees at zero distance: 2*sqrt(2)*sin(10.2 deg) = 0.5; or 0.5 m at zero rotation).
* ``loop_matrix_metric``: translation distance < ``max_distance`` metres **and** viewing
  direction difference < ``max_angle`` degrees. Easier to argue about.

The matrix is symmetric with a False diagonal; evaluations count each unordered pair once.
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.spatial.distance import cdist

from greenloop.datasets import groundtruth_formats as gt_formats, sequence
from greenloop.util.checks import positive_int
from greenloop.util.files import write_atomic

DEFAULT_EXCLUDE = 150   # frames: the paper's neighbour window (Qi 2024, Eq. 5), GreenHouse's protocol; every default exclusion


class NoGroundTruthError(FileNotFoundError):
    """A sequence folder has neither poses (CameraTrajectory.txt) nor loop pairs (ground_truth.csv)."""


def _check(poses, threshold_name: str, threshold: float, exclude: int) -> np.ndarray:
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (N, 4, 4), got {poses.shape}; read them with "
                         f"greenloop.datasets.sequence.read_trajectory")
    if not threshold > 0:
        raise ValueError(f"{threshold_name} must be > 0, got {threshold}")
    if exclude < 0:
        raise ValueError(f"exclude must be >= 0 frames, got {exclude}")
    return poses


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
    trans2 = cdist(t, t, "sqeuclidean")
    e = np.sqrt(rot2 + trans2)
    np.fill_diagonal(e, 0.0)
    return e


def loop_matrix(poses, threshold: float = 0.5, exclude: int = DEFAULT_EXCLUDE) -> np.ndarray:
    """Ground-truth loops by Qi 2024 Eq. 5.

    poses: (N, 4, 4) camera-to-world matrices (metres).
    threshold: pairs with e = ||T_i^-1 T_j - I||_F below it are loops (mixed units, see module doc).
    exclude: pairs with |i - j| <= exclude frames are never loops.
    Returns (N, N) bool, symmetric, False on the diagonal.
    """
    poses = _check(poses, "threshold", threshold, exclude)
    return (pose_error(poses) < threshold) & far_in_time(len(poses), exclude)


def loop_matrix_metric(poses, max_distance: float = 1.0, max_angle: float = 30.0,
                       exclude: int = DEFAULT_EXCLUDE) -> np.ndarray:
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
    d2 = cdist(t, t, "sqeuclidean")
    cos = np.clip(z @ z.T, -1.0, 1.0)
    close = (d2 < max_distance ** 2) & (cos > np.cos(np.radians(max_angle)))
    return close & far_in_time(len(poses), exclude)


def _check_frames(frames, n_frames: int) -> np.ndarray:
    """frames -> (M,) int64 original frame numbers, strictly increasing, within 0..n_frames-1."""
    if frames is None:
        return np.arange(n_frames, dtype=np.int64)
    f = np.asarray(frames)
    if f.ndim != 1 or f.size == 0 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"frames must be a non-empty 1-D array of integer frame numbers (e.g. "
                         f"np.arange(0, N, step)), got shape {f.shape} dtype {f.dtype}")
    f = f.astype(np.int64)
    if f[0] < 0 or f[-1] >= n_frames or np.any(np.diff(f) <= 0):
        raise ValueError(f"frames must be strictly increasing frame numbers within 0..{n_frames - 1}, "
                         f"got {f[:3].tolist()} ... {f[-3:].tolist()}")
    return f


def far_in_time(frames, exclude) -> np.ndarray:
    """The "far in time" rule of every ground truth and score: (M, M) bool, True at [a, b] iff
    |frames[a] - frames[b]| > exclude. The one implementation greenloop uses (ground truths,
    ``evaluate.pair_mask``, ``dictionary.declared_pairs``).

    frames: an int n (frames 0..n-1, one per row) or (M,) sorted original frame numbers (e.g.
        ``np.arange(0, N, step)``). exclude: an integer >= 0, in the units of ``frames``.
    Built from each row's band of near columns, without an (M, M) integer difference matrix
    (M = 7152 frames would need 400 MB for it)."""
    exclude = positive_int("exclude", exclude, 0, unit="original frames", whole_floats=True)
    frames = np.arange(int(frames)) if np.ndim(frames) == 0 else np.asarray(frames)
    lo = np.searchsorted(frames, frames - exclude, side="left")
    hi = np.searchsorted(frames, frames + exclude, side="right")
    cols = np.arange(len(frames))
    return (cols[None, :] < lo[:, None]) | (cols[None, :] >= hi[:, None])


def pair_matrix(pairs, n_frames: int, frames=None, exclude: int = DEFAULT_EXCLUDE) -> np.ndarray:
    """Ground-truth loops from loop pairs (module doc), over a chosen subset of frames.

    pairs: (P, 2) or (P, 3) integers (i, j[, tolerance]), 0-based frame numbers, tolerance in
        frames (>= 0), as ``greenloop.datasets.sequence.read_loop_pairs`` returns them.
    n_frames: frames in the sequence (every i, j must lie in 0..n_frames-1).
    frames: (M,) strictly increasing original frame numbers of the described frames (default:
        all). A pair counts when its i is among them; its j' are those of them within the
        tolerance of j.
    exclude: pairs of frames at most ``exclude`` original frames apart are never loops.
    Returns (M, M) bool, symmetric, False on the diagonal (the kind ``loop_matrix`` returns).
    """
    f = _check_frames(frames, n_frames)
    far = far_in_time(f, exclude)
    p = np.asarray(pairs, dtype=np.int64)
    if p.size == 0:
        p = p.reshape(0, 3)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"pairs must have shape (P, 2) or (P, 3) (i, j[, tolerance]), got {p.shape}")
    i, j = p[:, 0], p[:, 1]
    tol = p[:, 2] if p.shape[1] == 3 else np.zeros_like(i)
    if np.any((p[:, :2] < 0) | (p[:, :2] >= n_frames)):
        raise ValueError(f"pairs name frames outside 0..{n_frames - 1}: frame numbers are 0-based")
    if np.any(tol < 0):
        raise ValueError("tolerances must be >= 0 frames")
    pos = np.minimum(np.searchsorted(f, i), len(f) - 1)
    keep = f[pos] == i                                  # pairs whose i is a described frame
    lo = np.searchsorted(f, j - tol, side="left")
    hi = np.searchsorted(f, j + tol, side="right")
    G = np.zeros((len(f), len(f)), dtype=bool)
    for a, l, h in zip(pos[keep], lo[keep], hi[keep]):
        G[a, l:h] = True
    return (G | G.T) & far


def for_sequence(folder, frames=None, threshold: float = 0.5, exclude: int = DEFAULT_EXCLUDE) -> np.ndarray:
    """The ground-truth loop matrix of a sequence folder: the one call notebooks and users make.

    folder: a sequence folder or a ``sequence.Sequence`` (read once: ``sequence.open``). Its poses
        (CameraTrajectory.txt, one per frame) are used where they exist (``loop_matrix``, Qi 2024 Eq. 5 < ``threshold``), its loop
        pairs (ground_truth.csv, ``pair_matrix``) otherwise.
    frames: (M,) strictly increasing original frame numbers of the described frames, e.g.
        ``np.arange(0, N, step)``; None = every frame.
    threshold: the Eq. 5 threshold (mixed units, module doc); unused for loop pairs.
    exclude: pairs at most ``exclude`` ORIGINAL frames apart are never loops, whatever the subset.
    Returns (M, M) bool, symmetric, False on the diagonal; row/column a is frame frames[a].
    Raises NoGroundTruthError (a FileNotFoundError) when the folder has neither file, and
    ValueError for a malformed file or a trajectory that does not match the frames.
    """
    seq = sequence.open(folder)
    kind, n = _kind(seq), seq.n_frames
    if kind is None:
        raise NoGroundTruthError(
            f"{seq.path} has no ground truth: add {sequence.TRAJECTORY_NAMES[0]} (TUM poses, one per frame) "
            f"or {sequence.GROUND_TRUTH_NAME} (a header line, then `i,j[,tolerance]` loop pairs of 0-based "
            f"frame numbers) to the folder, `ground_truth: aligned` to its {sequence.DESCRIPTION_NAME} "
            f"(traversals aligned frame by frame), or import another format with "
            f"`python -m greenloop import-gt FILE`")
    f = _check_frames(frames, n)
    if kind == "poses":
        _, poses = seq.poses()
        return loop_matrix(poses[f], threshold, 0) & far_in_time(f, exclude)
    return pair_matrix(seq.loop_pairs(), n, f, exclude)


def _kind(seq: sequence.Sequence) -> str | None:
    """'poses', 'pairs' or None: the ground truth a Sequence carries."""
    return None if seq.ground_truth is None else seq.ground_truth.kind


class Described(NamedTuple):
    """What :func:`described_frames` returns (the prelude of the descriptor notebooks)."""
    frames: np.ndarray   # (M,) original frame numbers of the described frames, 0, step, 2 step, ...
    exclude_steps: int              # exclude in steps of frame_step: exclude // frame_step
    gt: np.ndarray       # (M, M) bool ground truth of those frames (for_sequence)
    summary: str         # one line naming the frames, the exclusion band and the ground truth


def described_frames(folder, frame_step: int, threshold: float = 0.5, exclude: int = DEFAULT_EXCLUDE) -> Described:
    """Every frame_step-th frame of a sequence, its exclusion band in steps and its ground truth.

    folder: a sequence folder or Sequence. frame_step: describe frames 0, frame_step, 2 frame_step, ...
    (an integer >= 1). threshold, exclude: as :func:`for_sequence` (exclude in ORIGINAL frames).
    Returns Described(frames, exclude_steps, gt, summary): ``exclude_steps = exclude // frame_step`` is the band the
    scoring functions take for the described frames, ``gt = for_sequence(folder, frames,
    threshold, exclude)`` and ``summary`` the line the notebooks print (frames, band in steps and
    original frames, the ground-truth definition, its loop pairs and revisit frames).
    """
    step = positive_int("frame_step", frame_step, whole_floats=True)
    seq = sequence.open(folder)
    frames = np.arange(0, seq.n_frames, step)
    exclude_steps = int(exclude) // step
    gt = for_sequence(seq, frames, threshold, exclude)
    summary = (f"{len(frames)} frames (frame_step {frame_step}), exclusion band {exclude_steps} steps = {exclude_steps * step} original "
               f"frames; ground truth ({definition(seq, threshold, exclude)}): {len(loop_pairs(gt))} loop pairs, "
               f"{int(revisit_frames(gt).sum())} revisit frames")
    return Described(frames, exclude_steps, gt, summary)


def variants(folder, frames=None, thresholds=(0.3, 0.4, 0.5, 0.6, 0.7, 0.8), exclude: int = DEFAULT_EXCLUDE,
             max_distance: float = 1.0, max_angle: float = 30.0) -> dict:
    """The ground truths a pose-tracked sequence admits, to show how scores move with the definition.

    folder, frames, exclude: as :func:`for_sequence`. thresholds: Qi 2024 Eq. 5 thresholds
    (mixed units, module doc). max_distance (metres), max_angle (degrees): the metric variant
    (:func:`loop_matrix_metric`).
    Returns {label: (M, M) bool}: "Eq. 5 < t" for every t, then "metric: < d m, < a deg";
    an empty dict for a folder without poses (its loop pairs admit one ground truth only).
    """
    seq = sequence.open(folder)
    if _kind(seq) != "poses":
        return {}
    f = _check_frames(frames, seq.n_frames)
    _, poses = seq.poses()
    far = far_in_time(f, exclude)
    out = {f"Eq. 5 < {t:g}": loop_matrix(poses[f], t, 0) & far for t in thresholds}
    out[f"metric: < {max_distance:g} m, < {max_angle:g} deg"] = (
        loop_matrix_metric(poses[f], max_distance, max_angle, 0) & far)
    return out


def definition(folder, threshold: float = 0.5, exclude: int = DEFAULT_EXCLUDE) -> str:
    """One line saying which ground truth ``for_sequence(folder, ..., threshold, exclude)`` uses,
    for table notes and printouts (names the file and, for pairs, their count and tolerances)."""
    seq = sequence.open(folder)
    kind = _kind(seq)
    if kind == "poses":
        return (f"Qi 2024 Eq. 5 on the poses ({sequence.TRAJECTORY_NAMES[0]}): ||T_i^-1 T_j - I||_F < "
                f"{threshold}, |i - j| > {exclude} frames")
    if kind == "pairs":
        p = sequence.read_loop_pairs(seq)
        tol = f"{p[:, 2].min()}" if len(p) and p[:, 2].min() == p[:, 2].max() else (
            f"{p[:, 2].min()}-{p[:, 2].max()}" if len(p) else "-")
        return (f"loop pairs from {seq.ground_truth.label} ({len(p)} rows, tolerance "
                f"{tol} frames), |i - j| > {exclude} frames")
    return "none: the folder has no poses and no loop-pair file"


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


def relative_poses(poses, pairs) -> np.ndarray:
    """The true relative pose of every pair, T_i^-1 T_j: pose j in camera i's frame.

    poses: (N, 4, 4) camera-to-world (metres; any one world frame, e.g. the days' stream's);
    pairs: (P, 2) frame numbers (i, j). Returns (P, 4, 4) float64, the motion a loop closure
    between i and j should estimate (score one with :func:`relative_pose_error`).
    """
    T = np.asarray(poses, dtype=np.float64)
    p = np.asarray(pairs)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (N, 4, 4), got {T.shape}; read them with "
                         f"greenloop.datasets.sequence.read_trajectory")
    if p.ndim != 2 or p.shape[1] != 2 or not np.issubdtype(p.dtype, np.integer) or \
            (p.size and (p.min() < 0 or p.max() >= len(T))):
        raise ValueError(f"pairs must be (P, 2) integer frame numbers within 0..{len(T) - 1}, got shape {p.shape}")
    return np.linalg.inv(T[p[:, 0]]) @ T[p[:, 1]]


def relative_pose_error(estimated, true) -> tuple[np.ndarray, np.ndarray]:
    """How far estimated relative poses are from the true ones (:func:`relative_poses`).

    estimated, true: (P, 4, 4) rigid transforms (metres). Returns (translation error (P,) metres,
    rotation error (P,) degrees) of E = true^-1 estimated: ||t_E|| and the angle of R_E.
    """
    E = np.linalg.inv(np.asarray(true, dtype=np.float64)) @ np.asarray(estimated, dtype=np.float64)
    cos = np.clip((np.trace(E[:, :3, :3], axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return np.linalg.norm(E[:, :3, 3], axis=1), np.degrees(np.arccos(cos))


class Imported(NamedTuple):
    """An imported ground-truth file: pairs (P, 3) int64 loop pairs written to ``out``; fmt its format
    (``groundtruth_formats.FORMATS``); n_frames, n_reference: the frames of out's folder they were
    checked against (None: not a sequence folder)."""
    pairs: np.ndarray
    out: Path
    fmt: str
    n_frames: int | None
    n_reference: int | None


def import_file(src, out=None, fmt: str = "auto", threshold_m: float | None = None,
                reference_frames: int | None = None) -> Imported:
    """Read a ground-truth file of another format (``datasets.groundtruth_formats``) and write it as
    ground_truth.csv loop pairs at ``out`` (default beside ``src``), its frame numbers checked against
    the frames of out's folder where it is a sequence folder. reference_frames: VPR-Bench's reference
    images before the queries (default: the folder's first traversal)."""
    src = Path(src)
    out = Path(out) if out else src.parent / sequence.GROUND_TRUTH_NAME
    n_frames = n_ref = None
    try:
        n_frames = len(sequence.list_frames(out.parent))
        ts = sequence.traversals(out.parent)
        n_ref = ts[0].stop if sequence.layout(out.parent) in ("traversals", "reference/query") else None
    except (FileNotFoundError, ValueError):
        pass                                   # not a sequence folder: nothing to check against
    n_ref = reference_frames if reference_frames is not None else n_ref
    fmt = gt_formats.detect_format(src) if fmt == "auto" else fmt
    pairs = gt_formats.read(src, fmt, n_frames=n_frames, n_reference=n_ref, threshold_m=threshold_m)
    write_atomic(out, lambda p: sequence.write_loop_pairs(p, pairs))
    return Imported(pairs, out, fmt, n_frames, n_ref)
