"""A recording's odometry and its loop closures to a corrected trajectory on disk (``python -m
greenloop slam``): read, optimise, write, and measure against the folder's ground truth if it has one.

Closures come from a CSV with a header (``read_closures``): ``query`` (or detect's ``frame``),
``match``, the relative pose ``rx ry rz`` (rotation vector, radians) ``tx ty tz`` (metres, or a
direction when ``metric`` is 0) of ``T = inv(T_w_query) @ T_w_match`` (the match camera's pose in
the query camera's frame: ``posegraph.Loop``), and ``metric`` (1 or 0; default 1). Rows whose
``closure`` column (detect's ``--matches``) is 0, or whose match or pose is empty, are skipped and
counted. Odometry: one pose per frame, pose k = frame k (a TUM or KITTI file).
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import NamedTuple

import numpy as np

from greenloop.datasets import sequence
from greenloop.mapping import metrics, posegraph
from greenloop.mapping import trajectory as tj
from greenloop.util.files import write_atomic

POSE_COLUMNS = ("rx", "ry", "rz", "tx", "ty", "tz")
KEPT = 0.5          # a loop factor whose final weight exceeds this is counted as kept


class Corrected(NamedTuple):
    """What :func:`correct` did: the result (posegraph.Result), the odometry (N, 4, 4), its stamps
    (N,), the loops used, rows skipped in the closures file, the files written, and (when the
    recording has ground truth) ``errors``: {'odometry'|'corrected': {'ate_m', 'end_point_m'}}."""
    result: posegraph.Result
    odometry: np.ndarray
    stamps: np.ndarray
    loops: list
    skipped: int
    out: Path
    weights_out: Path
    errors: dict | None


def _row_loop(row: dict, where: str) -> posegraph.Loop | None:
    """One CSV row as a Loop, None when it is no verified closure with a pose (module doc)."""
    if str(row.get("closure", "1")).strip() in ("0", "False", "false"):
        return None
    query = row.get("query", row.get("frame"))
    vals = [row.get(c) for c in ("match",) + POSE_COLUMNS]
    if query in (None, "") or any(v in (None, "") for v in vals):
        return None
    try:
        i, j = int(query), int(vals[0])
        pose = [float(v) for v in vals[1:]]
        metric = str(row.get("metric", "1")).strip().lower() not in ("0", "false", "no")
    except ValueError:
        raise ValueError(f"{where}: expected integer frames and numbers for {', '.join(POSE_COLUMNS)}, "
                         f"got {row}; fix or remove that line") from None
    return posegraph.Loop(i, j, tj.make_poses([pose[:3]], [pose[3:]])[0], metric)


def read_closures(path) -> tuple[list[posegraph.Loop], int]:
    """Loop closures from a CSV (module doc) -> (loops, rows skipped). FileNotFoundError when absent,
    ValueError when the header lacks a column or a row is malformed."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"closures file {path} not found")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        header = [c.strip() for c in (reader.fieldnames or [])]
        missing = [c for c in ("match",) + POSE_COLUMNS if c not in header]
        if missing or not ({"query", "frame"} & set(header)):
            raise ValueError(f"{path}: the header needs query (or frame), match, {', '.join(POSE_COLUMNS)} "
                             f"[, metric]; it lacks {', '.join(missing) or 'query'}")
        loops, skipped = [], 0
        for k, row in enumerate(reader, 2):
            loop = _row_loop({key.strip(): v for key, v in row.items() if key}, f"{path}:{k}")
            skipped += loop is None
            if loop is not None:
                loops.append(loop)
    return loops, skipped


def write_weights(path, loops, weights) -> Path:
    """CSV of each loop factor: query, match, metric (1/0), its final weight and kept (weight > KEPT),
    written atomically."""
    lines = ["query,match,metric,weight,kept"]
    lines += [f"{lp.i},{lp.j},{int(lp.metric)},{w:.6g},{int(w > KEPT)}" for lp, w in zip(loops, weights)]
    return write_atomic(path, "\n".join(lines) + "\n")


def _errors(recording: Path, stamps, odometry, corrected) -> dict | None:
    """ATE and end-point error of odometry and corrected against the recording's CameraTrajectory.txt,
    associated by frame number; None when the folder has none."""
    gt_file = recording / sequence.TRAJECTORY_NAMES[0]
    if not gt_file.is_file():
        return None
    ids, gt = sequence.read_trajectory(gt_file)
    i_gt, i_est = metrics.associate(ids, stamps, max_diff=0.01)
    out = {}
    for name, traj in (("odometry", odometry), ("corrected", corrected)):
        out[name] = dict(ate_m=metrics.ate(gt[i_gt], traj[i_est]),
                         end_point_m=metrics.end_point_error(gt[i_gt], traj[i_est]))
    return out


def correct(recording, odometry, out, closures=None, weights_out=None, method: str = "gnc",
            noise: posegraph.Noise = posegraph.Noise(), planar: bool = False) -> Corrected:
    """Optimise the recording's pose graph and write it.

    recording: the sequence folder (its CameraTrajectory.txt, if any, is the ground truth; its frame
    count, if it holds frames, must equal the odometry's poses). odometry: a TUM or KITTI file, one
    pose per frame. closures: a closures CSV (module doc) or None (odometry alone). out: the TUM
    file to write (the odometry's stamps). weights_out: the loop weights' CSV (default: ``out`` with
    ``_loops.csv``). method: a back end of posegraph.METHODS. planar: Pose2 (posegraph's module doc).
    Returns :class:`Corrected`.
    """
    recording = Path(recording)
    if not recording.is_dir():
        raise FileNotFoundError(f"recording folder {recording} not found: give the sequence folder")
    stamps, odo = tj.read_poses(odometry)
    frames = sequence.list_frames(recording) if (recording / "rgb").is_dir() else []
    if frames and len(frames) != len(odo):
        raise ValueError(f"{odometry} holds {len(odo)} poses but {recording} has {len(frames)} frames: "
                         f"give one odometry pose per frame")
    loops, skipped = read_closures(closures) if closures is not None else ([], 0)
    result = posegraph.optimize(odo, loops, method, noise, planar)
    out = tj.write_tum(out, stamps, result.poses)
    weights_out = Path(weights_out) if weights_out else out.with_name(out.stem + "_loops.csv")
    write_weights(weights_out, posegraph.check_loops(loops, len(odo)), result.weights)
    return Corrected(result, odo, stamps, loops, skipped, out, weights_out,
                     _errors(recording, stamps, odo, result.poses))
