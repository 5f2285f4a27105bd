"""The greenhouse over days on disk: ``make_greenhouse_days(folder)`` (its command line:
``python -m greenloop data greenhouse-days FOLDER [--days 5] [--tiny]``).

Writes, for the days of ``days.design_days``::

    days/day-00/ ...            one sequence folder per day: rgb/, depth/, CameraTrajectory.txt,
                                odometry.txt, camera.yaml, sequence.yaml (exclude, frame_step)
    rgb/, depth/                the stream: every day's frames one after the other, renumbered
                                (hard links to the days' files where the file system allows)
    CameraTrajectory.txt        TUM, t = frame number, camera-to-world, OpenCV camera axes, in ONE
                                world frame for all days: the first camera of day-00 (its pose is
                                the identity), as the single-day sequence's file
    odometry.txt                TUM, the same frame and convention: each day's wheel odometry
                                (``datasets.odometry.simulate_odometry``, seeded per day), started
                                at the day's true first pose, at the nominal camera height, pitch
                                and zero roll (odometry measures the floor plane only)
    camera.yaml                 the scaled D435i intrinsics
    sequence.yaml               traversals: {day-00: [0, n0], ...}; exclude, frame_step (frames)
    greenhouse_days.json        the arguments, the hall, the days' records, the drift model

``exclude`` is the paper's 150 frames scaled to the frame spacing (150 frames of the single-day
sequence are ~4.1 m of route), so the neighbour window stays the same distance at any spacing;
``frame_step`` likewise keeps the notebooks' described frames ~0.11 m apart, as notebook 13's
every 4th frame of the single-day sequence: at the default 0.10 m spacing it is 1 (every frame
rendered is described, none is rendered in vain), at 0.027 m it would be 4.
"""
from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml

from greenloop.datasets import odometry, sequence
from greenloop.datasets.sequence import DEPTH_SCALE, write_trajectory
from greenloop.datasets.synthetic.camera import _check_size, write_camera_yaml
from greenloop.datasets.synthetic.days import day_route, DaysHall, design_days, TINY_HALL
from greenloop.datasets.synthetic.dayscene import build_day_scene
from greenloop.datasets.synthetic.hall import _check_seed
from greenloop.datasets.synthetic.make import (_check_noise_workers, _check_output, _move_into_place,
                                               _write_frame)
from greenloop.datasets.synthetic.render import _grid
from greenloop.datasets.synthetic.route import (_look_rotation, CAM_HEIGHT, CAM_PITCH_DEG, DEFAULT_FRAMES,
                                                route_length)
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

SPACING = 0.10            # metres between frames of the full benchmark: 5 days, ~8,000 frames
TINY_SPACING = 0.25       # metres, --tiny
TINY_SIZE = (160, 120)
FULL_SIZE = (640, 480)
EXCLUDE_M = 150 * route_length() / (DEFAULT_FRAMES - 1)   # metres: the paper's 150-frame window
DESCRIBED_M = 4 * route_length() / (DEFAULT_FRAMES - 1)   # metres: the leaderboard's every 4th frame
META = "greenhouse_days.json"

_WORKER: dict = {}


def build_days(n_days: int = 5, tiny: bool = False, seed: int = 0, spacing: float | None = None):
    """The days, their hall and their true poses, without rendering anything.

    Returns (hall, days (list of ``days.Day``), poses: list of (N_k, 4, 4) camera-to-world in the
    one world frame (day-00's first camera), arc: list of (N_k,) route metres, hall_to_world
    (4, 4): the world-from-hall transform).
    """
    hall = TINY_HALL if tiny else DaysHall()
    spacing = (TINY_SPACING if tiny else SPACING) if spacing is None else float(spacing)
    days = design_days(n_days, hall, seed)
    routes = [day_route(d, hall, spacing, seed, k) for k, d in enumerate(days)]
    to_world = np.linalg.inv(routes[0][0][0])
    return hall, days, [to_world @ p for p, _ in routes], [s for _, s in routes], to_world


def odometry_poses(world_poses: np.ndarray, to_world: np.ndarray, seed: int, index: int) -> np.ndarray:
    """A day's wheel odometry as camera poses: world_poses (N, 4, 4) the true camera-to-world
    poses, to_world (4, 4) world-from-hall; seeded by (seed, index). Returns (N, 4, 4)
    camera-to-world at CAM_HEIGHT metres, CAM_PITCH_DEG pitch and no roll."""
    hall = np.linalg.inv(to_world)[None] @ world_poses
    planar = np.stack([hall[:, 0, 3], hall[:, 2, 3], np.arctan2(hall[:, 2, 2], hall[:, 0, 2])], 1)
    odo = odometry.simulate_odometry(planar, seed=int(np.random.default_rng([seed, index, 0x0D0]).integers(2**31)))
    out = np.tile(np.eye(4), (len(odo), 1, 1))
    out[:, :3, :3] = _look_rotation(odo[:, 2], np.full(len(odo), np.radians(CAM_PITCH_DEG)), np.zeros(len(odo)))
    out[:, :3, 3] = np.stack([odo[:, 0], np.full(len(odo), CAM_HEIGHT), odo[:, 1]], 1)
    return to_world[None] @ out


def make_greenhouse_days(folder, n_days: int = 5, tiny: bool = False, seed: int = 0, size=None,
                         spacing: float | None = None, workers: int | None = None,
                         overwrite: bool = False, progress: bool = True) -> Path:
    """Render the days of the hall into ``folder`` (module doc: the files).

    n_days: >= 1 (>= 5 for the benchmark's design: sun, overcast, night, evening, after a harvest);
    tiny: the two-aisle hall at 160x120 every 0.25 m (tests); seed: everything (frames,
    odometry, objects, routes' jitter) is byte-identical for the same arguments and any worker
    count; size: (width, height) pixels (default 640x480, tiny 160x120); spacing: metres between
    frames (default SPACING, tiny TINY_SPACING); workers: processes (default all cores);
    overwrite: replace a non-empty folder. Renders into a temporary folder beside ``folder`` and
    renames it at the end. Returns the folder.
    """
    size, spacing = _resolve(tiny, size, spacing)
    seed = _check_seed(seed)
    _, workers = _check_noise_workers(0.0, workers)
    folder = Path(folder)
    _check_output(folder, overwrite)
    hall, days, poses, arcs, to_world = build_days(n_days, tiny, seed, spacing)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = folder.parent / f".{folder.name}.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        for d in days:
            (tmp / "days" / d.name / "rgb").mkdir(parents=True)
            (tmp / "days" / d.name / "depth").mkdir()
        _render(tmp, days, hall, poses, arcs, to_world, size, seed, workers, progress)
        desc = {"exclude": max(1, int(round(EXCLUDE_M / spacing))),
                "frame_step": max(1, int(round(DESCRIBED_M / spacing)))}
        odo = [odometry_poses(p, to_world, seed, k) for k, p in enumerate(poses)]
        for k, d in enumerate(days):
            _write_day(tmp / "days" / d.name, poses[k], odo[k], size, desc)
        _write_stream(tmp, days, poses, odo, size, desc)
        meta = {"generator": "greenloop.datasets.synthetic.daysmake", "format": 1, "n_days": len(days),
                "tiny": bool(tiny), "seed": seed, "width": size[0], "height": size[1],
                "spacing_m": spacing, **desc,
                "depth_scale": DEPTH_SCALE, "hall": dataclasses.asdict(hall),
                "days": [dataclasses.asdict(d) | {"frames": len(p)} for d, p in zip(days, poses)],
                "odometry": {"scale_error": odometry.SCALE_ERROR, "slip_m_per_sqrt_m": odometry.SLIP,
                             "heading_bias_rad_per_m": odometry.HEADING_BIAS,
                             "heading_noise_rad_per_sqrt_m": odometry.HEADING_NOISE}}
        (tmp / META).write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
        _move_into_place(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


def _resolve(tiny: bool, size, spacing) -> tuple[tuple[int, int], float]:
    """(size (width, height) pixels, spacing metres) with the defaults of ``tiny`` filled in, checked."""
    size = _check_size(size or (TINY_SIZE if tiny else FULL_SIZE))
    spacing = (TINY_SPACING if tiny else SPACING) if spacing is None else spacing
    if isinstance(spacing, bool) or not isinstance(spacing, (int, float)) or not 0.005 <= spacing <= 2.0:
        raise ValueError(f"spacing must be metres between frames, 0.005 to 2, got {spacing!r}")
    return size, float(spacing)


def up_to_date(folder, n_days: int = 5, tiny: bool = False, seed: int = 0, size=None,
               spacing: float | None = None) -> bool:
    """Whether ``folder`` holds a finished render of these arguments (its META says so): the
    cache of ``python -m greenloop data greenhouse-days``."""
    path = Path(folder) / META
    if not path.is_file():
        return False
    meta = json.loads(path.read_text())
    size, spacing = _resolve(tiny, size, spacing)
    return (meta.get("format") == 1 and meta.get("n_days") == n_days and meta.get("tiny") == bool(tiny)
            and meta.get("seed") == seed and [meta.get("width"), meta.get("height")] == list(size)
            and meta.get("spacing_m") == spacing)


class Places(NamedTuple):
    """Where every frame of a days folder's stream was taken, (N,) arrays over its frames: day (index
    into ``lights``, the traversal), aisle (``days.DaysHall.aisle_at``: 0 .. n_aisles - 1, -1 outside
    the aisles), direction (+1: the camera looks towards +z of the hall, the beds' far end; -1 the
    other way; 0 outside the aisles), x, z (metres, hall frame); lights: each day's light (days.LIGHTS);
    names: each day's name; offsets: each day's days since the first; hall: the ``days.DaysHall``."""
    day: np.ndarray
    aisle: np.ndarray
    direction: np.ndarray
    x: np.ndarray
    z: np.ndarray
    lights: tuple
    names: tuple
    offsets: tuple
    hall: DaysHall


def is_days(folder) -> bool:
    """Whether ``folder`` (a path or ``sequence.Sequence``) is a finished render of the days (holds META)."""
    return (Path(folder) / META).is_file()


def frame_places(folder) -> Places:
    """:class:`Places` of a days folder's stream (``make_greenhouse_days``' output): the hall and the
    days from its META, the hall frame from day-00's route rebuilt from the same arguments (the world
    frame is its first camera), the poses from its CameraTrajectory.txt. FileNotFoundError without META."""
    path = Path(folder) / META
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: {folder} is no render of the greenhouse days; make one with "
                                f"python -m greenloop data greenhouse-days FOLDER")
    meta = json.loads(path.read_text())
    hall = DaysHall(**meta["hall"])
    first = design_days(meta["n_days"], hall, meta["seed"])[0]
    from_world = day_route(first, hall, meta["spacing_m"], meta["seed"], 0)[0][0]    # hall <- world
    seq = sequence.open(folder)
    poses = from_world[None] @ seq.poses()[1]
    x, z = poses[:, 0, 3], poses[:, 2, 3]
    aisle = hall.aisle_at(x, z)
    direction = np.where(aisle >= 0, np.where(poses[:, 2, 2] >= 0, 1, -1), 0)
    return Places(seq.traversal_index(), aisle, direction, x, z, tuple(d["light"] for d in meta["days"]),
                  tuple(d["name"] for d in meta["days"]), tuple(int(d["offset_days"]) for d in meta["days"]),
                  hall)


def _worker_init(days, hall, poses, arcs, to_world, size, seed, out) -> None:
    """Per-process state: the days, their hall-frame poses, the pixel grid; scenes built lazily."""
    hall_poses = [np.linalg.inv(to_world)[None] @ p for p in poses]
    _WORKER.update(days=days, hall=hall, poses=hall_poses, arcs=arcs, grid=_grid(size), seed=seed,
                   out=Path(out), scenes={})


def _render_chunk(task) -> int:
    """Render the frames of one (day index, [frame, ...]) task; returns how many were written."""
    k, frames = task
    wk = _WORKER
    if k not in wk["scenes"]:
        wk["scenes"].clear()   # one day's scene at a time (tasks come day by day)
        wk["scenes"][k] = build_day_scene(wk["days"][k], wk["hall"], wk["seed"])
    out = wk["out"] / "days" / wk["days"][k].name
    for i in frames:
        _write_frame(out, i, wk["scenes"][k], wk["poses"][k][i], float(wk["arcs"][k][i]), wk["grid"],
                     np.random.default_rng([wk["seed"], k, int(i), 0xF4A3E]), 0.0)
    return len(frames)


def _render(tmp: Path, days, hall, poses, arcs, to_world, size, seed: int, workers: int, progress: bool) -> None:
    """Every day's frames into tmp/days/<name>/{rgb,depth}, in tasks of 16 frames over ``workers``
    processes (1: in this process)."""
    tasks = [(k, list(range(i, min(i + 16, len(p))))) for k, p in enumerate(poses) for i in range(0, len(p), 16)]
    args = (days, hall, poses, arcs, to_world, size, seed, str(tmp))
    bar = tqdm(total=sum(len(p) for p in poses), desc=f"render {len(days)} days", unit="frame",
               disable=not progress)
    try:
        if workers == 1:
            _worker_init(*args)
            for t in tasks:
                bar.update(_render_chunk(t))
        else:
            import multiprocessing as mp
            with mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn").Pool(
                    workers, _worker_init, args) as pool:
                for done in pool.imap(_render_chunk, tasks):
                    bar.update(done)
    finally:
        bar.close()
        _WORKER.clear()


def _write_day(day_dir: Path, poses: np.ndarray, odo: np.ndarray, size, desc: dict) -> None:
    """A day's CameraTrajectory.txt, odometry.txt (N poses each, world frame), camera.yaml and
    sequence.yaml (``desc``: exclude and frame_step in frames)."""
    write_trajectory(day_dir / "CameraTrajectory.txt", np.arange(len(poses)), poses)
    write_trajectory(day_dir / "odometry.txt", np.arange(len(odo)), odo)
    write_camera_yaml(day_dir / "camera.yaml", size)
    (day_dir / "sequence.yaml").write_text(yaml.safe_dump(desc, sort_keys=False))


def _write_stream(tmp: Path, days, poses, odo, size, desc: dict) -> None:
    """The multi-day stream at tmp: rgb/ and depth/ (hard links, else copies, of the days'
    frames, renumbered), CameraTrajectory.txt, odometry.txt, camera.yaml and sequence.yaml with
    ``desc`` (exclude, frame_step) and the days as traversals {name: [start, stop]}."""
    (tmp / "rgb").mkdir()
    (tmp / "depth").mkdir()
    start, ranges = 0, {}
    for d, p in zip(days, poses):
        for i in range(len(p)):
            for sub in ("rgb", "depth"):
                src, dst = tmp / "days" / d.name / sub / f"{i}.png", tmp / sub / f"{start + i}.png"
                try:
                    os.link(src, dst)
                except OSError:
                    shutil.copyfile(src, dst)
        ranges[d.name] = [start, start + len(p)]
        start += len(p)
    write_trajectory(tmp / "CameraTrajectory.txt", np.arange(start), np.concatenate(poses))
    write_trajectory(tmp / "odometry.txt", np.arange(start), np.concatenate(odo))
    write_camera_yaml(tmp / "camera.yaml", size)
    (tmp / "sequence.yaml").write_text(yaml.safe_dump(desc | {"traversals": ranges}, sort_keys=False))
