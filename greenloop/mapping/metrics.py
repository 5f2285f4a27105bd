"""A trajectory's error as the field measures it, by evo's definitions (written here: evo is GPL-3.0).

Definitions (M. Grupp, evo, github.com/MichaelGrupp/evo: ``core/metrics.py``, ``core/geometry.py``,
``core/filters.py``, ``core/sync.py``; after Sturm et al., IROS 2012, the TUM RGB-D benchmark):

- **ATE** (evo's APE, translation part): the estimate's positions aligned to the reference's by
  the least-squares rigid motion (Umeyama, PAMI 1991, with no scale: evo's ``--align``), then the
  RMSE of the position differences, ``sqrt(mean ||p_ref,k - p_est,k||^2)``, metres.
- **End-point error**: unaligned, the distance between the last positions after the estimate's
  first pose is put on the reference's first pose (evo's ``--align_origin``): the drift at the end.
- **RPE** (evo's RPE): for index pairs (i, j), ``E = inv(inv(Q_i) Q_j) @ inv(P_i) P_j`` (Q the
  reference, P the estimate); translation error ``||E[:3, 3]||`` metres, rotation error the angle
  of ``E[:3, :3]`` (degrees); the RMSE over the pairs. Pairs (evo's ``filters``): a delta in frames,
  (0, d), (d, 2d), ... (``all_pairs``: every (i, i + d)); a delta in metres, consecutive indices at
  which the travelled distance since the last one first reaches ``delta`` (``all_pairs``: for each
  i, the j whose distance from i is nearest ``delta``, within 10 %), the distance travelled along
  the estimate unless ``pairs_from_reference`` (evo's default, its ``--pairs_from_reference``).
- **Association** by timestamps (evo's ``matching_time_indices``): each stamp of the shorter
  trajectory to the nearest of the other's, kept within ``max_diff``.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from greenloop.mapping import trajectory as tj


class RPE(NamedTuple):
    """RPE RMSEs: translation_m (metres), rotation_deg (degrees), pairs (how many pairs)."""
    translation_m: float
    rotation_deg: float
    pairs: int


def _pair(reference, estimate) -> tuple[np.ndarray, np.ndarray]:
    """Both trajectories checked as (N, 4, 4) poses of the same N (ValueError otherwise)."""
    ref, est = tj.check_poses(reference, "reference"), tj.check_poses(estimate, "estimate")
    if len(ref) != len(est):
        raise ValueError(f"the reference has {len(ref)} poses and the estimate {len(est)}: associate them "
                         f"first (metrics.associate)")
    return ref, est


def umeyama(x, y, with_scale: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """The similarity (R, t, c) minimising sum ||y_k - (c R x_k + t)||^2 (Umeyama 1991, Eqs. 34-43; evo's
    ``umeyama_alignment``, here with points as rows). x, y: (N, m) points (N >= 2). Returns R (m, m)
    a rotation (det +1), t (m,), c (1.0 unless ``with_scale``). ValueError for a degenerate set."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or len(x) < 2:
        raise ValueError(f"umeyama needs two (N, m) point sets of one shape, N >= 2; got {x.shape}, {y.shape}")
    m = x.shape[1]
    mx, my = x.mean(axis=0), y.mean(axis=0)
    var_x = np.mean(np.sum((x - mx) ** 2, axis=1))
    cov = (y - my).T @ (x - mx) / len(x)
    u, d, vt = np.linalg.svd(cov)
    if np.count_nonzero(d > np.finfo(float).eps * max(d[0], 1.0)) < m - 1:
        raise ValueError("the positions are degenerate (all on one point or, in 3-D, a line): "
                         "no unique alignment")
    s = np.eye(m)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[-1, -1] = -1
    r = u @ s @ vt
    c = float(np.trace(np.diag(d) @ s) / var_x) if with_scale else 1.0
    return r, my - c * r @ mx, c


def align(reference, estimate) -> np.ndarray:
    """The estimate (N, 4, 4) moved by the rigid motion (no scale) that best aligns its positions to
    the reference's (:func:`umeyama`), (N, 4, 4)."""
    ref, est = _pair(reference, estimate)
    r, t, _ = umeyama(est[:, :3, 3], ref[:, :3, 3])
    g = np.eye(4)
    g[:3, :3], g[:3, 3] = r, t
    return g @ est


def ate(reference, estimate, aligned: bool = True) -> float:
    """ATE RMSE in metres of estimate against reference, both (N, 4, 4): after SE(3) Umeyama
    alignment of the positions (``aligned``; evo_ape --align) or as given."""
    ref, est = _pair(reference, estimate)
    if aligned:
        est = align(ref, est)
    return float(np.sqrt(np.mean(np.sum((ref[:, :3, 3] - est[:, :3, 3]) ** 2, axis=1))))


def end_point_error(reference, estimate) -> float:
    """Metres between the last positions, unaligned but for the estimate's first pose put on the
    reference's (evo's align_origin); reference, estimate (N, 4, 4)."""
    ref, est = _pair(reference, estimate)
    moved = ref[0] @ tj.inverse(est[0]) @ est[-1]
    return float(np.linalg.norm(moved[:3, 3] - ref[-1, :3, 3]))


def rpe_pairs(poses, delta: float, unit: str = "frames", all_pairs: bool = False) -> np.ndarray:
    """(P, 2) int index pairs of the RPE (module doc) along a trajectory (N, 4, 4): delta frames
    (an integer >= 1) or metres (> 0) of travelled distance; ValueError when none."""
    ref = tj.check_poses(poses, "poses")
    n = len(ref)
    if unit == "frames":
        if delta != int(delta) or delta < 1:
            raise ValueError(f"delta in frames must be an integer >= 1, got {delta}")
        d = int(delta)
        i = np.arange(n - d) if all_pairs else np.arange(0, n, d)[:-1]
        pairs = np.column_stack([i, i + d])
    elif unit == "m":
        if not delta > 0:
            raise ValueError(f"delta in metres must be > 0, got {delta}")
        pairs = _metre_pairs(tj.distances(ref), float(delta), all_pairs)
    else:
        raise ValueError(f"unit must be 'frames' or 'm', got {unit!r}")
    if not len(pairs):
        raise ValueError(f"delta = {delta} {unit} gives no pair on {n} poses: use a smaller delta")
    return pairs.astype(np.int64).reshape(-1, 2)


def _metre_pairs(dist: np.ndarray, delta: float, all_pairs: bool) -> np.ndarray:
    """Index pairs by travelled distance (evo's ``filter_pairs_by_path``), dist (N,) cumulative metres."""
    if all_pairs:
        out = []
        for i in range(len(dist) - 1):
            ahead = dist[i + 1:] - dist[i]
            k = int(np.argmin(np.abs(ahead - delta)))
            if abs(ahead[k] - delta) <= 0.1 * delta:
                out.append((i, i + 1 + k))
        return np.asarray(out).reshape(-1, 2)
    ids, since = [], 0.0
    step = np.concatenate([[0.0], np.diff(dist)])
    for k, s in enumerate(step):
        since += s
        if since >= delta:
            ids.append(k)
            since = 0.0
    return np.column_stack([ids[:-1], ids[1:]]) if len(ids) > 1 else np.zeros((0, 2))


def rpe(reference, estimate, delta: float = 1, unit: str = "frames", all_pairs: bool = False,
        pairs_from_reference: bool = False) -> RPE:
    """RPE (module doc) of estimate against reference, both (N, 4, 4), over pairs ``delta`` frames or
    metres apart (:func:`rpe_pairs` of the estimate, or of the reference when
    ``pairs_from_reference``): translation RMSE (metres) and rotation RMSE (degrees)."""
    ref, est = _pair(reference, estimate)
    p = rpe_pairs(ref if pairs_from_reference else est, delta, unit, all_pairs)
    q_rel = tj.relative(ref[p[:, 0]], ref[p[:, 1]])
    p_rel = tj.relative(est[p[:, 0]], est[p[:, 1]])
    e = tj.relative(q_rel, p_rel)
    trans = np.linalg.norm(e[:, :3, 3], axis=1)
    rot = np.degrees(tj.rotation_angle(e))
    return RPE(float(np.sqrt(np.mean(trans ** 2))), float(np.sqrt(np.mean(rot ** 2))), len(p))


def associate(stamps_a, stamps_b, max_diff: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs matching two stamp lists (evo's ``matching_time_indices``): each stamp of the
    shorter list to the nearest stamp of the other, kept where they differ by at most max_diff (the
    stamps' unit, seconds or frames). Returns (ia, ib), int arrays of one length."""
    a, b = np.asarray(stamps_a, dtype=np.float64), np.asarray(stamps_b, dtype=np.float64)
    swap = len(b) < len(a)
    short, long_ = (b, a) if swap else (a, b)
    order = np.argsort(long_, kind="stable")
    pos = np.clip(np.searchsorted(long_[order], short), 1, max(len(long_) - 1, 1))
    left, right = order[pos - 1], order[np.minimum(pos, len(long_) - 1)]
    near = np.where(np.abs(long_[left] - short) <= np.abs(long_[right] - short), left, right)
    keep = np.abs(long_[near] - short) <= max_diff
    i_short, i_long = np.flatnonzero(keep), near[keep]
    if not len(i_short):
        raise ValueError(f"no stamps of the two trajectories lie within {max_diff} of each other: "
                         f"check their time bases (frame numbers vs seconds)")
    return (i_long, i_short) if swap else (i_short, i_long)


def plot_trajectories(ground_truth=None, odometry=None, corrected=None, loops=(), weights=None, ax=None):
    """A top-down figure: ground truth (black), odometry (grey dashed), corrected (blue), each loop
    (pairs (i, j), drawn between the corrected poses) coloured by its final weight (0 red .. 1
    green). Trajectories (N, 4, 4) or None; the plane is the two axes of largest extent. Returns the
    Figure (a new one unless ``ax`` is given)."""
    import matplotlib.pyplot as plt
    fig, ax = (plt.subplots(figsize=(6, 6)) if ax is None else (ax.figure, ax))
    a, b = tj.plane_axes(ground_truth, odometry, corrected)
    styles = (("ground truth", ground_truth, dict(color="black", lw=1.5)),
              ("odometry", odometry, dict(color="0.5", ls="--", lw=1.2)),
              ("corrected", corrected, dict(color="tab:blue", lw=1.2)))
    for label, traj, style in styles:
        if traj is not None:
            ax.plot(np.asarray(traj)[:, a, 3], np.asarray(traj)[:, b, 3], label=label, **style)
    base = corrected if corrected is not None else odometry
    w = np.ones(len(loops)) if weights is None else np.asarray(weights, dtype=np.float64)
    cmap = plt.get_cmap("RdYlGn")
    for k, ((i, j, *_), wk) in enumerate(zip(loops, w)):
        if base is not None:
            p = np.asarray(base)[[int(i), int(j)], :3, 3]
            ax.plot(p[:, a], p[:, b], color=cmap(float(np.clip(wk, 0, 1))), lw=0.8, alpha=0.8,
                    label="loops (weight: red 0 .. green 1)" if k == 0 else None)
    ax.set_xlabel(f"{'xyz'[a]} (m)")
    ax.set_ylabel(f"{'xyz'[b]} (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    return fig
