"""A recording's odometry and its loop closures to a corrected trajectory on disk (``python -m
greenloop slam``): read, optimise, write, and measure against the folder's ground truth if it has one.

Closures come from a CSV with a header (``read_closures``): ``query`` (or detect's ``frame``),
``match``, the relative pose ``rx ry rz`` (rotation vector, radians) ``tx ty tz`` (metres, or a
direction when ``metric`` is 0) of T_match_query = inv(T_w_match) @ T_w_query (the query camera's pose
in the match camera's frame, as detect's ``--matches`` and ``methods.verification`` give it; the loop
factor holds its inverse: ``posegraph.loop_from_closure``), and ``metric`` (1 or 0; default 1). Rows whose
``closure`` column (detect's ``--matches``) is 0, or whose match or pose is empty, are skipped and
counted.

Odometry (``datasets.odometry.read_odometry``): a bag's ``nav_msgs/Odometry`` topic, a TUM or a
KITTI file, given each frame's pose by ``datasets.odometry.associate`` (:func:`frame_odometry`):

* a bag or a video recording: its frames' times (``datasets.recording.open_frames``: header
  stamps, or frame k / rate) against the odometry's times in seconds, interpolated, a frame
  without a message within ``max_dt`` seconds being a ValueError; a KITTI file (no times) is
  refused for these;
* a sequence folder: the folder's convention, a trajectory's t is the frame number (its
  CameraTrajectory.txt, the days' odometry.txt; a KITTI file's line k is frame k), so frame k
  takes the odometry's pose stamped k; a folder without frames takes every pose the file holds.
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import NamedTuple

import numpy as np

from greenloop.datasets import odometry as odometry_io
from greenloop.datasets import recording as recordings
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
    T = tj.make_poses([pose[:3]], [pose[3:]])[0]
    return posegraph.loop_from_closure(i, j, T[:3, :3], T[:3, 3], metric)


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


def frame_odometry(recording, odometry, topic: str | None = None, camera_topic: str | None = None,
                   max_dt: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's odometry pose (module doc: times for a bag or video, frame numbers for a folder).

    recording: a sequence folder, a bag or a video. odometry: a bag (``topic``: its Odometry topic)
    or a TUM / KITTI file. camera_topic: the bag recording's image topic. max_dt: seconds, the
    farthest a frame's nearest odometry message may be. Returns (stamps (N,) float64: frame times
    in seconds, or frame numbers for a folder; poses (N, 4, 4) float64), one per frame.
    """
    o_stamps, o_poses = odometry_io.read_odometry(odometry, topic)
    order = np.argsort(o_stamps, kind="stable")
    o_stamps, o_poses = o_stamps[order], o_poses[order]
    kind = recordings.kind_of(recording)
    if kind == "folder" and odometry_io.format_of(odometry) == "bag":
        raise ValueError(f"{recording} is an image folder (frame numbers) and {odometry} a bag (seconds): give "
                         f"the folder's odometry as a frame-numbered TUM or KITTI file, or the bag as the recording")
    if kind == "folder":
        if not (Path(recording) / "rgb").is_dir():
            return o_stamps, o_poses
        n = len(sequence.list_frames(recording))
        stamps = np.arange(n, dtype=np.float64)
        poses, ok = odometry_io.associate(stamps, o_stamps, o_poses, max_dt=0.5)     # frame numbers
    else:
        if odometry_io.format_of(odometry) == "kitti":
            raise ValueError(f"{odometry} is a KITTI file (no times) and {recording} a {kind} timed in seconds: "
                             f"give the odometry as a bag topic or a TUM file with times")
        stamps = recordings.open_frames(recording, camera_topic).stamps
        if stamps is None:
            raise ValueError(f"{recording} has no frame times: give its odometry as a sequence folder's "
                             f"frame-numbered file, or a recording with times")
        poses, ok = odometry_io.associate(stamps, o_stamps, o_poses, max_dt)
    if not ok.all():
        raise ValueError(f"{int((~ok).sum())} of {len(ok)} frames of {recording} have no odometry pose within "
                         f"{max_dt} (odometry {odometry}: {len(o_stamps)} poses, stamps {o_stamps[0]:g}.."
                         f"{o_stamps[-1]:g}): give odometry covering the recording, or a larger max_dt")
    return stamps, poses


def closure_loops(closures) -> list[posegraph.Loop]:
    """The loop factors of ``interface.Closure``-like records (query, match, R, t as T_match_query,
    metric): one per closure with a pose (``posegraph.loop_from_closure``); unverified ones are left out."""
    return [posegraph.loop_from_closure(c.query, c.match, c.R, c.t, c.metric) for c in closures if c.R is not None]


def correct(recording, odometry, out, closures=None, weights_out=None, method: str = "gnc",
            noise: posegraph.Noise = posegraph.Noise(), planar: bool = False, topic: str | None = None,
            camera_topic: str | None = None, max_dt: float = 0.1) -> Corrected:
    """Optimise the recording's pose graph and write it.

    recording: a sequence folder (its CameraTrajectory.txt, if any, is the ground truth), a bag or a
    video. odometry: a bag (``topic``: its Odometry topic) or a TUM / KITTI file, given to each frame
    by :func:`frame_odometry` (camera_topic, max_dt seconds: as there). closures: a closures CSV
    (module doc), a list of ``interface.Closure``-like records (:func:`closure_loops`), or None
    (odometry alone). out: the TUM file to write (the frames' stamps).
    weights_out: the loop weights' CSV (default: ``out`` with ``_loops.csv``). method: a back end
    of posegraph.METHODS. planar: Pose2 (posegraph's module doc). Returns :class:`Corrected`.
    """
    recording = Path(recording)
    if not recording.exists():
        raise FileNotFoundError(f"recording {recording} not found: give the sequence folder, bag or video")
    stamps, odo = frame_odometry(recording, odometry, topic, camera_topic, max_dt)
    if closures is None or isinstance(closures, (str, Path)):
        loops, skipped = read_closures(closures) if closures is not None else ([], 0)
    else:
        loops = closure_loops(closures)
        skipped = len(closures) - len(loops)
    result = posegraph.optimize(odo, loops, method, noise, planar)
    out = tj.write_tum(out, stamps, result.poses)
    weights_out = Path(weights_out) if weights_out else out.with_name(out.stem + "_loops.csv")
    write_weights(weights_out, posegraph.check_loops(loops, len(odo)), result.weights)
    errors = _errors(recording, stamps, odo, result.poses) if recording.is_dir() else None
    return Corrected(result, odo, stamps, loops, skipped, out, weights_out, errors)
